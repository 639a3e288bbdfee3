//! 8-bit slope codes: how the GPU stores a partial-derivative normal map in two bytes per texel
//! (Flower 2010, sec. 3.1.2: two 8-bit components, `GL_RG8`), and their CPU reference.
//!
//! Flower 2010 stores `dh/du` linearly in 8 bits, which limits normals to a 45° cone. A code
//! here stands for a slope angle instead: code `c` in -127..=127 is the slope
//! `tan(c * SLOPE_CODE_STEP)`, steps of 85/127 ≈ 0.67° up to ±85°, so cliffs keep their
//! direction and gentle slopes their resolution (one step moves a normal by at most 0.67°).
//!
//! The code is computed from the integer 4th-order stencil of eq. 3.3 (`s = (h(x-2) - h(x+2)) +
//! 8 (h(x+1) - h(x-1))` in stored units, exact) by comparing `|s|` with 127 integer thresholds,
//! the stencils where the nearest angle step changes. Integer comparisons decide it, so the
//! GPU's codes equal [`SlopeCodec::codes`] bit for bit on every conforming device: no `atan`,
//! no division, no rounding mode is involved. Only the thresholds depend on the map (its height
//! scale and spacing), and they are computed once, here, in f64.

use crate::error::CoreError;
use crate::grid::Grid;
use crate::map::{HeightMap, HeightSample};

/// Codes per sign: a code lies in `-SLOPE_CODE_MAX..=SLOPE_CODE_MAX`.
pub const SLOPE_CODE_MAX: i8 = 127;

/// The steepest slope angle a code stands for, in degrees.
pub const SLOPE_CODE_MAX_DEGREES: u32 = 85;

/// The slope angle of one code step, in radians (85° / 127).
pub const SLOPE_CODE_STEP: f64 =
    (SLOPE_CODE_MAX_DEGREES as f64 / 127.0) * std::f64::consts::PI / 180.0;

/// The slope (metres per metre) code `c` stands for: `tan(c * SLOPE_CODE_STEP)`; -128 reads as
/// -127.
pub fn decode_slope(code: i8) -> f32 {
    (f64::from(code.max(-SLOPE_CODE_MAX)) * SLOPE_CODE_STEP).tan() as f32
}

/// Encodes a map's slopes: the thresholds of its height scale and spacing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlopeCodec {
    /// `thresholds[c - 1]`: the smallest `|s|` coded `c` or more (`u32::MAX`: never reached).
    thresholds: [u32; 127],
}

impl SlopeCodec {
    /// The codec of a map whose stored unit is `scale` metres and whose texels are
    /// `texel_size` metres apart. Fails for a non-finite or non-positive value.
    pub fn new(scale: f32, texel_size: f32) -> Result<Self, CoreError> {
        crate::map::check_texel_size(texel_size)?;
        if !scale.is_finite() || scale <= 0.0 {
            return Err(CoreError::OutOfRange {
                what: "height encoding scale",
                value: f64::from(scale),
                expected: "finite and greater than 0",
            });
        }
        // Slope = s k with k = scale / (12 xi) (eq. 3.3): code c from the half step below it.
        let k = f64::from(scale) / (12.0 * f64::from(texel_size));
        let thresholds = std::array::from_fn(|i| {
            let slope = ((i as f64 + 0.5) * SLOPE_CODE_STEP).tan();
            // At least 1, so a flat texel (s = 0) is code 0 whatever the scale.
            (slope / k).ceil().clamp(1.0, f64::from(u32::MAX)) as u32
        });
        Ok(Self { thresholds })
    }

    /// The codec of `map`'s encoding and spacing.
    pub fn for_map<T: HeightSample>(map: &HeightMap<T>) -> Self {
        // A HeightMap's scale and spacing were checked when it was made.
        Self::new(map.encoding().scale, map.texel_size()).unwrap_or(Self {
            thresholds: [u32::MAX; 127],
        })
    }

    /// The thresholds, in code order (what the GPU pass is given).
    pub fn thresholds(&self) -> &[u32; 127] {
        &self.thresholds
    }

    /// The code of an integer stencil `s` of eq. 3.3: the number of thresholds at or below
    /// `|s|`, with the sign of `s`.
    pub fn encode(&self, s: i64) -> i8 {
        // Below u32::MAX, which marks a threshold never reached.
        let a = s.unsigned_abs().min(u64::from(u32::MAX - 1)) as u32;
        let n = self.thresholds.partition_point(|&t| t <= a) as i8;
        if s < 0 { -n } else { n }
    }

    /// The codes `[dX, dZ]` of every texel of `map` (its wrap mode at the edges): what the GPU's
    /// normal pass stores, bit for bit.
    pub fn codes<T: HeightSample>(&self, map: &HeightMap<T>) -> Grid<[i8; 2]> {
        let h = map.grid();
        let wrap = map.wrap();
        let (w, hh) = (h.width(), h.height());
        let at = |x: i64, y: i64| {
            let row = h.row(wrap.resolve(y, hh));
            row[wrap.resolve(x, w) as usize].to_raw_f64() as i64
        };
        let stencil = |a: i64, b: i64, c: i64, d: i64| (a - d) + 8 * (c - b);
        let mut out = h.map(|_| [0i8; 2]);
        for y in 0..i64::from(hh) {
            for x in 0..i64::from(w) {
                let dx = stencil(at(x - 2, y), at(x - 1, y), at(x + 1, y), at(x + 2, y));
                let dz = stencil(at(x, y - 2), at(x, y - 1), at(x, y + 1), at(x, y + 2));
                let i = y as usize * w as usize + x as usize;
                out.as_mut_slice()[i] = [self.encode(dx), self.encode(dz)];
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_follow_the_slope_angle_within_half_a_step() {
        let codec = SlopeCodec::new(0.01, 0.5).unwrap();
        let k = 0.01 / (12.0 * 0.5);
        for s in (-2_000_000i64..2_000_000).step_by(997) {
            let angle = (s as f64 * k).atan();
            let c = codec.encode(s);
            assert_eq!(codec.encode(-s), -c);
            let max = f64::from(SLOPE_CODE_MAX_DEGREES).to_radians();
            if angle.abs() < max {
                let err = (f64::from(c) * SLOPE_CODE_STEP - angle).abs();
                assert!(err <= 0.5 * SLOPE_CODE_STEP + 1e-12, "s {s}: code {c}");
            } else {
                assert_eq!(c.abs(), SLOPE_CODE_MAX);
            }
        }
        assert_eq!(codec.encode(0), 0);
        assert!((decode_slope(127) - 85f32.to_radians().tan()).abs() < 1e-3);
        assert_eq!(decode_slope(-128), decode_slope(-127));
    }

    #[test]
    fn flat_stays_flat_and_extremes_are_accepted() {
        // A tiny texel makes every non-zero stencil steep, a huge one every stencil flat.
        let steep = SlopeCodec::new(1.0, 1e-6).unwrap();
        assert_eq!(
            (steep.encode(0), steep.encode(1), steep.encode(-1)),
            (0, 127, -127)
        );
        let flat = SlopeCodec::new(1e-6, 1e6).unwrap();
        assert_eq!(flat.encode(i64::MAX), 0);
        assert_eq!(flat.encode(i64::MIN), 0);
        assert!(SlopeCodec::new(f32::NAN, 1.0).is_err());
        assert!(SlopeCodec::new(1.0, 0.0).is_err());
        assert!(SlopeCodec::new(-1.0, 1.0).is_err());
    }
}
