//! Height encodings (u16 coarse-map, u8 detail-map, u32 fixed point) and the `HeightMap` that
//! pairs a grid with its encoding, texel spacing and wrap mode.

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use glam::{UVec2, Vec2};

/// A stored integer height sample: `u16` (coarse-map), `u8` (detail-map) or `u32` (fixed point).
pub trait HeightSample: Copy + bytemuck::Pod + Send + Sync + 'static {
    /// The largest stored value, as `f64`.
    const MAX_RAW: f64;
    /// The stored value as `f64`.
    fn to_raw_f64(self) -> f64;
    /// The nearest stored value to `raw`, clamped to `0..=MAX_RAW` (NaN gives 0).
    fn from_raw_f64_clamped(raw: f64) -> Self;
    /// `floor(raw)` clamped to `0..=MAX_RAW` (NaN gives 0): one saturating cast, no call to
    /// `floor`, so loops over it vectorise. `from_raw_f64_floor_clamped(v + 0.5)` equals
    /// [`HeightSample::from_raw_f64_clamped`]`(v)` except where `v + 0.5` rounds (fractions
    /// within 2^-53 of one half).
    fn from_raw_f64_floor_clamped(raw: f64) -> Self {
        Self::from_raw_f64_clamped(raw.floor())
    }
}

macro_rules! impl_height_sample {
    ($t:ty) => {
        impl HeightSample for $t {
            const MAX_RAW: f64 = <$t>::MAX as f64;
            #[inline]
            fn to_raw_f64(self) -> f64 {
                f64::from(self)
            }
            #[inline]
            fn from_raw_f64_clamped(raw: f64) -> Self {
                // `as` saturates and maps NaN to 0, which is the clamp we want.
                raw.round() as $t
            }
            #[inline]
            fn from_raw_f64_floor_clamped(raw: f64) -> Self {
                // Branch-free and vectorisable without SSE4.1's `floor`: clamp (NaN gives 0),
                // round to an integer by adding and removing 2^52 (exact below 2^51), step
                // down where that rounded up, and read the integer from the mantissa bits.
                const MAGIC: f64 = 4_503_599_627_370_496.0; // 2^52
                let c = raw.max(0.0).min(Self::MAX_RAW);
                let r = (c + MAGIC) - MAGIC;
                let f = if r > c { r - 1.0 } else { r };
                (f + MAGIC).to_bits() as $t
            }
        }
    };
}
impl_height_sample!(u8);
impl_height_sample!(u16);
impl_height_sample!(u32);

/// How a stored integer becomes metres: `metres = offset + scale * stored`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeightEncoding {
    /// Metres per stored unit (positive).
    pub scale: f32,
    /// Metres at stored value 0.
    pub offset: f32,
}

/// The largest height range of a detail-map, in metres (the "range at most 1 m").
pub const DETAIL_MAX_RANGE_M: f32 = 1.0;

/// Fixed-point units per metre of granular heights by default (Persson 2019, sec. 4.3: x 10 000).
pub const DEFAULT_FIXED_POINT_UNITS_PER_M: u32 = 10_000;

impl HeightEncoding {
    /// An encoding from its scale and offset; both must be finite and the scale positive.
    pub fn new(scale: f32, offset: f32) -> Result<Self, CoreError> {
        if !scale.is_finite() {
            return Err(CoreError::NonFinite {
                what: "height scale",
                value: scale,
            });
        }
        if !offset.is_finite() {
            return Err(CoreError::NonFinite {
                what: "height offset",
                value: offset,
            });
        }
        if scale <= 0.0 {
            return Err(CoreError::OutOfRange {
                what: "height scale",
                value: f64::from(scale),
                expected: "greater than 0",
            });
        }
        Ok(Self { scale, offset })
    }

    /// An encoding that spans `min_m ..= max_m` over the full range of sample type `T`.
    pub fn spanning<T: HeightSample>(min_m: f32, max_m: f32) -> Result<Self, CoreError> {
        Self::new(((max_m - min_m) as f64 / T::MAX_RAW) as f32, min_m)
    }

    /// Fixed-point heights for granular deformation: `units_per_metre` stored units per metre,
    /// zero at 0 m (Persson 2019, sec. 4.3).
    pub fn fixed_point(units_per_metre: u32) -> Result<Self, CoreError> {
        if units_per_metre == 0 {
            return Err(CoreError::OutOfRange {
                what: "fixed-point units per metre",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Self::new((1.0 / f64::from(units_per_metre)) as f32, 0.0)
    }

    /// Metres for a stored value.
    #[inline]
    pub fn to_metres(&self, raw: f64) -> f32 {
        (f64::from(self.offset) + f64::from(self.scale) * raw) as f32
    }

    /// The stored value (unrounded, unclamped) for a height in metres.
    #[inline]
    pub fn to_raw(&self, metres: f32) -> f64 {
        (f64::from(metres) - f64::from(self.offset)) / f64::from(self.scale)
    }

    /// Heights representable with sample type `T`: `(lowest, highest)` in metres.
    pub fn range<T: HeightSample>(&self) -> (f32, f32) {
        (self.to_metres(0.0), self.to_metres(T::MAX_RAW))
    }
}

/// A heightmap: samples of type `T`, their encoding, their spacing and how they wrap.
///
/// Sample `(x, y)` stands at world `(x * texel_size, height, y * texel_size)`.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightMap<T> {
    grid: Grid<T>,
    encoding: HeightEncoding,
    texel_size: f32,
    wrap: WrapMode,
}

/// The 16-bit, toroidally addressed map of the macro geometry (Flower 2010, sec. 3.1.1).
pub type CoarseMap = HeightMap<u16>;
/// An 8-bit detail-map tile, clamped at its edges, spanning at most 1 m of height.
pub type DetailTile = HeightMap<u8>;
/// Heights in u32 fixed point for volume-preserving granular deformation (Persson 2019, sec. 4.3).
pub type FixedPointMap = HeightMap<u32>;

impl<T: HeightSample> HeightMap<T> {
    /// A map over `grid`. `texel_size` (metres per texel) must be finite and positive.
    pub fn new(
        grid: Grid<T>,
        encoding: HeightEncoding,
        texel_size: f32,
        wrap: WrapMode,
    ) -> Result<Self, CoreError> {
        check_texel_size(texel_size)?;
        // Re-validate: the fields are public and may have been set by hand.
        let encoding = HeightEncoding::new(encoding.scale, encoding.offset)?;
        Ok(Self {
            grid,
            encoding,
            texel_size,
            wrap,
        })
    }

    /// The stored samples.
    pub fn grid(&self) -> &Grid<T> {
        &self.grid
    }

    /// The stored samples, mutable.
    pub fn grid_mut(&mut self) -> &mut Grid<T> {
        &mut self.grid
    }

    /// Gives up the map and returns its samples.
    pub fn into_grid(self) -> Grid<T> {
        self.grid
    }

    /// The height encoding.
    pub fn encoding(&self) -> HeightEncoding {
        self.encoding
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// How the map is addressed outside its size.
    pub fn wrap(&self) -> WrapMode {
        self.wrap
    }

    /// Size in texels.
    pub fn size(&self) -> UVec2 {
        self.grid.size()
    }

    /// Size in metres (texels times spacing).
    pub fn extent_m(&self) -> Vec2 {
        self.size().as_vec2() * self.texel_size
    }

    /// Height in metres of texel `(x, y)`, or `None` outside the map.
    pub fn height_m(&self, x: u32, y: u32) -> Option<f32> {
        self.grid
            .get(x, y)
            .map(|v| self.encoding.to_metres(v.to_raw_f64()))
    }

    /// All heights in metres, as f32.
    pub fn to_metres_grid(&self) -> Grid<f32> {
        let e = self.encoding;
        self.grid.map(|v| e.to_metres(v.to_raw_f64()))
    }

    /// The u64 sum of all stored values: the conserved volume of integer maps.
    pub fn raw_sum(&self) -> u64 {
        // Integer sums for the built-in samples (a float conversion per texel is most of the
        // cost of summing a 4096^2 map), row-parallel.
        let w = self.grid.width().max(1) as usize;
        let rows: Vec<&[T]> = self.grid.as_slice().chunks(w).collect();
        use std::any::TypeId;
        let t = TypeId::of::<T>();
        crate::par::map_sum(&rows, |row: &&[T]| {
            if t == TypeId::of::<u32>()
                && let Ok(r) = bytemuck::try_cast_slice::<T, u32>(row)
            {
                r.iter().map(|&v| u64::from(v)).sum()
            } else if t == TypeId::of::<u16>()
                && let Ok(r) = bytemuck::try_cast_slice::<T, u16>(row)
            {
                r.iter().map(|&v| u64::from(v)).sum()
            } else {
                row.iter().map(|v| v.to_raw_f64() as u64).sum()
            }
        })
    }
}

impl HeightMap<u16> {
    /// A coarse-map: 16-bit, wrapping (toroidal addressing).
    pub fn coarse(
        grid: Grid<u16>,
        encoding: HeightEncoding,
        texel_size: f32,
    ) -> Result<Self, CoreError> {
        Self::new(grid, encoding, texel_size, WrapMode::Repeat)
    }
}

impl HeightMap<u8> {
    /// A detail-map tile: 8-bit, clamped, spanning at most [`DETAIL_MAX_RANGE_M`].
    pub fn detail(
        grid: Grid<u8>,
        encoding: HeightEncoding,
        texel_size: f32,
    ) -> Result<Self, CoreError> {
        let (lo, hi) = encoding.range::<u8>();
        if hi - lo > DETAIL_MAX_RANGE_M * (1.0 + f32::EPSILON) {
            return Err(CoreError::OutOfRange {
                what: "detail-map height range (m)",
                value: f64::from(hi - lo),
                expected: "at most 1 m (255 * scale <= 1)",
            });
        }
        Self::new(grid, encoding, texel_size, WrapMode::Clamp)
    }
}

impl HeightMap<u32> {
    /// A fixed-point granular map with `units_per_metre` (default
    /// [`DEFAULT_FIXED_POINT_UNITS_PER_M`]), clamped at its edges.
    pub fn fixed_point(
        grid: Grid<u32>,
        units_per_metre: u32,
        texel_size: f32,
    ) -> Result<Self, CoreError> {
        Self::new(
            grid,
            HeightEncoding::fixed_point(units_per_metre)?,
            texel_size,
            WrapMode::Clamp,
        )
    }
}

/// Checks a texel spacing in metres.
pub(crate) fn check_texel_size(texel_size: f32) -> Result<(), CoreError> {
    if !texel_size.is_finite() {
        return Err(CoreError::NonFinite {
            what: "texel size",
            value: texel_size,
        });
    }
    if texel_size <= 0.0 {
        return Err(CoreError::OutOfRange {
            what: "texel size",
            value: f64::from(texel_size),
            expected: "greater than 0 metres",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_round_and_clamp_at_the_encoding_limits() {
        assert_eq!(u16::from_raw_f64_clamped(-3.0), 0);
        assert_eq!(u16::from_raw_f64_clamped(70_000.0), u16::MAX);
        assert_eq!(u16::from_raw_f64_clamped(f64::NAN), 0);
        assert_eq!(u8::from_raw_f64_clamped(254.6), 255);
        assert_eq!(u8::from_raw_f64_clamped(12.49), 12);
        assert_eq!(u32::from_raw_f64_clamped(5e10), u32::MAX);
    }

    #[test]
    fn encodings_convert_both_ways() {
        let e = HeightEncoding::spanning::<u16>(-10.0, 100.0).unwrap();
        assert!((e.to_metres(0.0) + 10.0).abs() < 1e-5);
        assert!((e.to_metres(65535.0) - 100.0).abs() < 1e-3);
        assert!((e.to_raw(45.0) - 32767.5).abs() < 0.01);
        let f = HeightEncoding::fixed_point(10_000).unwrap();
        assert!((f.to_metres(12_345.0) - 1.2345).abs() < 1e-6);
    }

    #[test]
    fn bad_parameters_are_errors() {
        assert!(HeightEncoding::new(f32::NAN, 0.0).is_err());
        assert!(HeightEncoding::new(0.0, 0.0).is_err());
        assert!(HeightEncoding::new(1.0, f32::INFINITY).is_err());
        assert!(HeightEncoding::fixed_point(0).is_err());
        let g = Grid::new(2, 2, 0u16).unwrap();
        let e = HeightEncoding::new(0.01, 0.0).unwrap();
        assert!(CoarseMap::coarse(g.clone(), e, 0.0).is_err());
        assert!(CoarseMap::coarse(g, e, f32::NAN).is_err());
        let d = Grid::new(2, 2, 0u8).unwrap();
        let too_tall = HeightEncoding::new(0.01, 0.0).unwrap();
        assert!(DetailTile::detail(d.clone(), too_tall, 0.1).is_err());
        let ok = HeightEncoding::spanning::<u8>(-0.5, 0.5).unwrap();
        assert!(DetailTile::detail(d, ok, 0.1).is_ok());
    }

    #[test]
    fn raw_sum_counts_every_sample() {
        let g = Grid::from_fn(3, 3, |x, y| x + y).unwrap();
        let m = FixedPointMap::fixed_point(g, 10_000, 0.1).unwrap();
        assert_eq!(m.raw_sum(), 18);
    }
}
