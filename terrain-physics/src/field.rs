//! `HeightField`: an immutable snapshot of the coarse-map in its own u16 encoding, with the
//! bilinear height and normal queries in the field's local space.
//!
//! The surface model of the whole crate is defined here: over each cell `[x, x+1] x [z, z+1]`
//! (texel units) the surface is the bilinear patch through the cell's four texels, exactly the
//! interpolation of Flower 2010, listing 3.2 (`x0 = floor(p.x)`, `x1 = x0 + 1` wrapped). Heights,
//! normals, raycasts and sphere contacts all use that one surface.

use crate::error::PhysicsError;
use glam::{DVec3, UVec2, Vec2, Vec3};
use std::sync::Arc;
use terrain_core::{CoarseMap, Grid, HeightEncoding, WrapMode};

/// Largest side of a mirrored map, in texels: keeps every texel coordinate, wrapped or not,
/// well inside `i32`.
pub const MAX_FIELD_SIDE: u32 = 1 << 28;

/// An immutable snapshot of the coarse-map: u16 samples, their encoding, the texel spacing, and
/// the version of the last update it contains.
///
/// Addressing is toroidal (the coarse-map repeats in both directions). Local space: texel
/// `(x, y)` stands at `(x * texel_size, offset + scale * stored, y * texel_size)` metres, X and
/// Z horizontal, Y up. Heights stay in the map's own u16 encoding and are scaled at query time
/// (Flower 2010, table 4.5 lost 51 of 60.5 ms converting u16 to f32 on every update).
#[derive(Debug, Clone, PartialEq)]
pub struct HeightField {
    heights: Grid<u16>,
    encoding: HeightEncoding,
    texel_size: f32,
    version: u64,
    /// Conservative bounds of the stored values: every sample lies in `raw_min..=raw_max`.
    raw_min: u16,
    raw_max: u16,
    /// The cells cut away (`terrain_core::holes`), shared between snapshots.
    holes: Option<Arc<Grid<u8>>>,
}

/// The four corner heights of one cell, in metres, as the bilinear patch
/// `h(u, v) = a + b u + c v + d u v` with `u, v` in `[0, 1]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Patch {
    /// Cell column (unwrapped).
    pub ix: i64,
    /// Cell row (unwrapped).
    pub iz: i64,
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: f64,
    pub min: f64,
    pub max: f64,
}

impl Patch {
    /// Height of the patch at `(u, v)`.
    #[inline]
    pub fn height(&self, u: f64, v: f64) -> f64 {
        self.a + self.b * u + self.c * v + self.d * u * v
    }

    /// The unit upward normal at `(u, v)` for cells `ts` metres wide.
    #[inline]
    pub fn normal(&self, u: f64, v: f64, ts: f64) -> DVec3 {
        let dhdx = (self.b + self.d * v) / ts;
        let dhdz = (self.c + self.d * u) / ts;
        DVec3::new(-dhdx, 1.0, -dhdz).normalize()
    }
}

impl HeightField {
    /// A field over `heights` with `encoding` (metres = offset + scale * stored) and
    /// `texel_size` metres per texel, at version 0.
    ///
    /// Fails on a non-finite or non-positive texel size, an invalid encoding, or a side longer
    /// than [`MAX_FIELD_SIDE`].
    pub fn new(
        heights: Grid<u16>,
        encoding: HeightEncoding,
        texel_size: f32,
    ) -> Result<Self, PhysicsError> {
        // Let terrain-core validate spacing and encoding the way every map is validated.
        let map = CoarseMap::coarse(heights, encoding, texel_size)?;
        Self::from_coarse(map)
    }

    /// A field holding a copy of `map` (which must wrap: [`WrapMode::Repeat`]), at version 0.
    pub fn from_map(map: &CoarseMap) -> Result<Self, PhysicsError> {
        if map.wrap() != WrapMode::Repeat {
            return Err(PhysicsError::NotToroidal { wrap: map.wrap() });
        }
        Self::from_coarse(map.clone())
    }

    fn from_coarse(map: CoarseMap) -> Result<Self, PhysicsError> {
        let size = map.size();
        if size.max_element() > MAX_FIELD_SIDE {
            return Err(PhysicsError::OutOfRange {
                what: "mirrored map side (texels)",
                value: f64::from(size.max_element()),
                expected: "at most 2^28 texels",
            });
        }
        let encoding = map.encoding();
        let texel_size = map.texel_size();
        let heights = map.into_grid();
        let (raw_min, raw_max) = min_max(heights.as_slice());
        Ok(Self {
            heights,
            encoding,
            texel_size,
            version: 0,
            raw_min,
            raw_max,
            holes: None,
        })
    }

    /// The same field with the cells `holes` marks cut away (`terrain_core::holes`: mask
    /// texel `(x, z)` nonzero removes the cell whose lower corner is texel `(x, z)`), or with
    /// none for `None`. Over a hole rays pass through, spheres find no contact and
    /// [`GroundQuery::ground_height`](crate::GroundQuery::ground_height) is `-inf`; heights and
    /// normals still describe the surface the hole was cut from. A hole has no walls: a body
    /// in it touches only the top surface of the ground around it.
    ///
    /// Fails on a mask of another size than the field.
    pub fn with_holes(mut self, holes: Option<Arc<Grid<u8>>>) -> Result<Self, PhysicsError> {
        if let Some(mask) = &holes
            && mask.size() != self.size()
        {
            return Err(PhysicsError::SizeMismatch {
                expected: self.size(),
                actual: mask.size(),
            });
        }
        self.set_holes(holes);
        Ok(self)
    }

    /// The hole mask, if the field has a hole.
    pub fn holes(&self) -> Option<&Arc<Grid<u8>>> {
        self.holes.as_ref()
    }

    /// Whether local position `pos = (X, Z)` lies over a hole (the field repeats; a
    /// non-finite position is over none).
    pub fn is_hole_local(&self, pos: Vec2) -> bool {
        if self.holes.is_none() || !pos.is_finite() {
            return false;
        }
        let (px, pz) = self.period_m();
        let (x, _) = reduce(f64::from(pos.x), px);
        let (z, _) = reduce(f64::from(pos.y), pz);
        let ts = f64::from(self.texel_size);
        self.hole_cell((x / ts).floor() as i64, (z / ts).floor() as i64)
    }

    /// Whether cell `(ix, iz)` (unwrapped cell coordinates) is cut away.
    #[inline]
    pub(crate) fn hole_cell(&self, ix: i64, iz: i64) -> bool {
        let Some(mask) = &self.holes else {
            return false;
        };
        let (x, _) = self.wrap_pair_x(ix);
        let (z, _) = self.wrap_pair_z(iz);
        mask.get(x, z).is_some_and(terrain_core::is_hole)
    }

    /// The stored samples (the coarse-map's own u16 encoding).
    pub fn heights(&self) -> &Grid<u16> {
        &self.heights
    }

    /// The height encoding: metres = offset + scale * stored.
    pub fn encoding(&self) -> HeightEncoding {
        self.encoding
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// Size in texels.
    pub fn size(&self) -> UVec2 {
        self.heights.size()
    }

    /// Size in metres: one period of the toroidal surface.
    pub fn extent_m(&self) -> Vec2 {
        self.size().as_vec2() * self.texel_size
    }

    /// The version of the last region update this snapshot contains (0 for a fresh field).
    pub fn version(&self) -> u64 {
        self.version
    }

    /// Bounds `(lowest, highest)` in metres that every height of the field lies within. They
    /// are exact for a fresh field and may only be wider (never narrower) after region updates.
    pub fn height_bounds(&self) -> (f32, f32) {
        (
            self.encoding.to_metres(f64::from(self.raw_min)),
            self.encoding.to_metres(f64::from(self.raw_max)),
        )
    }

    /// A coarse-map holding a copy of the field's samples.
    pub fn to_map(&self) -> Result<CoarseMap, PhysicsError> {
        Ok(CoarseMap::coarse(
            self.heights.clone(),
            self.encoding,
            self.texel_size,
        )?)
    }

    /// Height in metres at local position `pos = (X, Z)`: the bilinear interpolation of
    /// listing 3.2 with wrap addressing, scaled from u16 at query time.
    ///
    /// Bit-identical to `terrain_core::bilinear` on the same map. The input must be finite
    /// (the world-space wrapper checks it); a non-finite one gives an unspecified height but
    /// never panics.
    #[inline]
    pub fn height_local(&self, pos: Vec2) -> f32 {
        // Far away `pos / texel_size` can overflow f32 (or the cell index i64): move such a
        // position into the first period first (the field repeats). Nearer, nothing changes,
        // so the result stays bit-identical to terrain_core's sampler.
        let p = pos / self.texel_size;
        let pos = if p.is_finite() && p.abs().max_element() < NEAR_TEXELS {
            pos
        } else {
            let (px, pz) = self.period_m();
            let (x, _) = reduce(f64::from(pos.x), px);
            let (z, _) = reduce(f64::from(pos.y), pz);
            Vec2::new(x as f32, z as f32)
        };
        let p = pos / self.texel_size;
        // The same arithmetic as terrain_core::sample, so results agree to the bit.
        let fx0 = p.x.floor();
        let fz0 = p.y.floor();
        let fx = f64::from(p.x - fx0);
        let fz = f64::from(p.y - fz0);
        let (x0, x1) = self.wrap_pair_x(fx0 as i64);
        let (z0, z1) = self.wrap_pair_z(fz0 as i64);
        let w = self.heights.width() as usize;
        let data = self.heights.as_slice();
        let r0 = z0 as usize * w;
        let r1 = z1 as usize * w;
        let h = |i: usize| f64::from(data.get(i).copied().unwrap_or(0));
        let top = (1.0 - fx) * h(r0 + x0 as usize) + fx * h(r0 + x1 as usize);
        let bot = (1.0 - fx) * h(r1 + x0 as usize) + fx * h(r1 + x1 as usize);
        self.encoding.to_metres((1.0 - fz) * top + fz * bot)
    }

    /// Unit surface normal (Y up) at local position `pos = (X, Z)`: the normal of the bilinear
    /// patch of the cell holding `pos` (the cell to the +X / +Z side on a cell edge).
    pub fn normal_local(&self, pos: Vec2) -> Vec3 {
        let (px, pz) = self.period_m();
        let (x, _) = reduce(f64::from(pos.x), px);
        let (z, _) = reduce(f64::from(pos.y), pz);
        let p = glam::DVec2::new(x, z) / f64::from(self.texel_size);
        let (ix, iz) = (p.x.floor(), p.y.floor());
        let patch = self.patch(ix as i64, iz as i64);
        patch
            .normal(p.x - ix, p.y - iz, f64::from(self.texel_size))
            .as_vec3()
    }

    /// The bilinear patch of cell `(ix, iz)` (unwrapped cell coordinates).
    #[inline]
    pub(crate) fn patch(&self, ix: i64, iz: i64) -> Patch {
        let (x0, x1) = self.wrap_pair_x(ix);
        let (z0, z1) = self.wrap_pair_z(iz);
        let w = self.heights.width() as usize;
        let data = self.heights.as_slice();
        let e = self.encoding;
        let (off, scale) = (f64::from(e.offset), f64::from(e.scale));
        let m = |x: u32, z: u32| {
            let raw = data.get(z as usize * w + x as usize).copied().unwrap_or(0);
            off + scale * f64::from(raw)
        };
        let (h00, h10, h01, h11) = (m(x0, z0), m(x1, z0), m(x0, z1), m(x1, z1));
        Patch {
            ix,
            iz,
            a: h00,
            b: h10 - h00,
            c: h01 - h00,
            d: h00 - h10 - h01 + h11,
            min: h00.min(h10).min(h01).min(h11),
            max: h00.max(h10).max(h01).max(h11),
        }
    }

    /// Column `i` and its right neighbour, wrapped.
    #[inline]
    fn wrap_pair_x(&self, i: i64) -> (u32, u32) {
        wrap_pair(i, self.heights.width())
    }

    /// Row `i` and the one below, wrapped.
    #[inline]
    fn wrap_pair_z(&self, i: i64) -> (u32, u32) {
        wrap_pair(i, self.heights.height())
    }

    /// The field's period in metres along X and Z (it repeats).
    pub(crate) fn period_m(&self) -> (f64, f64) {
        let ts = f64::from(self.texel_size);
        (
            f64::from(self.heights.width()) * ts,
            f64::from(self.heights.height()) * ts,
        )
    }

    /// The samples, mutable, for the mirror's writer (which owns this snapshot exclusively).
    pub(crate) fn heights_mut(&mut self) -> &mut Grid<u16> {
        &mut self.heights
    }

    /// Sets the version after an update.
    pub(crate) fn set_version(&mut self, version: u64) {
        self.version = version;
    }

    /// Widens the bounds to hold `lo..=hi`.
    pub(crate) fn widen_bounds(&mut self, lo: u16, hi: u16) {
        self.raw_min = self.raw_min.min(lo);
        self.raw_max = self.raw_max.max(hi);
    }

    /// Sets exact bounds (after an update that replaced every texel).
    pub(crate) fn set_bounds(&mut self, lo: u16, hi: u16) {
        self.raw_min = lo;
        self.raw_max = hi;
    }

    /// The bounds and the holes of `other` (when the writer rebuilds a buffer from it).
    pub(crate) fn copy_bounds_from(&mut self, other: &HeightField) {
        self.raw_min = other.raw_min;
        self.raw_max = other.raw_max;
        self.holes.clone_from(&other.holes);
    }

    /// Replaces the holes (the mask's size already checked); a mask without a hole is kept as
    /// none, so it costs the queries nothing.
    pub(crate) fn set_holes(&mut self, holes: Option<Arc<Grid<u8>>>) {
        self.holes = holes.filter(|m| m.as_slice().iter().any(|&v| terrain_core::is_hole(v)));
    }
}

/// `i` wrapped onto `0..n`, and `i + 1` wrapped (listing 3.2's `x1 = x0 < N - 1 ? x0 + 1 : 0`).
#[inline]
fn wrap_pair(i: i64, n: u32) -> (u32, u32) {
    let i0 = if (0..i64::from(n)).contains(&i) {
        i as u32
    } else {
        WrapMode::Repeat.resolve(i, n)
    };
    // From the wrapped index, never `i + 1`: `i` may be i64::MAX (a saturated cast).
    let i1 = if i0 + 1 < n { i0 + 1 } else { 0 };
    (i0, i1)
}

/// Texel coordinates beyond which f32 has no fraction left: queries farther away are moved
/// into the first period before sampling.
const NEAR_TEXELS: f32 = 16_777_216.0;

/// `v` moved by a whole number of periods into `[0, period)`, and the shift taken off
/// (`v = reduced + shift`). The field repeats, so a query far from the origin is the same
/// query near it; reducing first keeps cell indices small and walks short.
pub(crate) fn reduce(v: f64, period: f64) -> (f64, f64) {
    let r = v.rem_euclid(period);
    (r, v - r)
}

/// Smallest and largest value of a slice (`(u16::MAX, 0)` for an empty one).
pub(crate) fn min_max(values: &[u16]) -> (u16, u16) {
    // A plain fold: LLVM vectorises it (measured 5x faster than a hand-chunked loop on SSE2,
    // which has no unsigned 16-bit min/max instruction).
    values
        .iter()
        .fold((u16::MAX, 0u16), |(lo, hi), &v| (lo.min(v), hi.max(v)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use terrain_core::bilinear;

    fn map() -> CoarseMap {
        let g = Grid::from_fn(5, 4, |x, y| (x * 1000 + y * 300 + (x * y) % 7 * 50) as u16)
            .expect("grid");
        let e = HeightEncoding::new(0.01, -3.0).expect("encoding");
        CoarseMap::coarse(g, e, 0.5).expect("map")
    }

    /// Heights at positions around the map (negative and beyond the first period too) are
    /// terrain_core's bilinear ones, to the bit.
    fn assert_near_heights_are_cores(m: &CoarseMap, f: &HeightField) {
        for i in -40..80 {
            for j in -30..60 {
                let p = Vec2::new(i as f32 * 0.137, j as f32 * 0.171);
                let core = bilinear(m, p).expect("finite");
                assert_eq!(f.height_local(p).to_bits(), core.to_bits(), "at {p}");
            }
        }
    }

    #[test]
    fn height_is_bit_identical_to_core_bilinear_including_wrap() {
        let m = map();
        let f = HeightField::from_map(&m).expect("field");
        assert_near_heights_are_cores(&m, &f);
    }

    /// With a texel size that is not a power of two, near positions (negative ones and
    /// ones beyond the first period included) are still sampled as terrain_core samples
    /// them, to the bit; far ones (beyond 2^24 texels) equal the position moved into the
    /// first period in f64.
    #[test]
    fn near_and_far_positions_with_an_inexact_texel_size() {
        let ts = 0.3f32;
        let g = Grid::from_fn(5, 4, |x, y| (x * 1000 + y * 300 + (x * y) % 7 * 50) as u16)
            .expect("grid");
        let m =
            CoarseMap::coarse(g, HeightEncoding::new(0.01, -3.0).expect("enc"), ts).expect("map");
        let f = HeightField::from_map(&m).expect("field");
        assert_near_heights_are_cores(&m, &f);
        let (px, pz) = f.period_m();
        let mut differs = 0;
        for k in 0..200u32 {
            let far = Vec2::new(6.0e6 + k as f32 * 37.5, -(5.2e6 + k as f32 * 21.0));
            let moved = Vec2::new(
                f64::from(far.x).rem_euclid(px) as f32,
                f64::from(far.y).rem_euclid(pz) as f32,
            );
            let want = bilinear(&m, moved).expect("finite");
            assert_eq!(f.height_local(far).to_bits(), want.to_bits(), "at {far}");
            let direct = bilinear(&m, far).expect("finite");
            differs += usize::from(direct.to_bits() != want.to_bits());
        }
        assert!(
            differs > 0,
            "f32 sampling far away never picked another cell"
        );
    }

    #[test]
    fn listing_3_2_wraps_the_last_column_onto_the_first() {
        // Texel 4 (last column) at 4 * 0.5 = 2 m; halfway to the wrapped texel 0 at 2.25 m.
        let m = map();
        let f = HeightField::from_map(&m).expect("field");
        let h4 = m.height_m(4, 0).expect("texel");
        let h0 = m.height_m(0, 0).expect("texel");
        let mid = f.height_local(Vec2::new(2.25, 0.0));
        assert!((mid - 0.5 * (h4 + h0)).abs() < 1e-4, "{mid} vs {h4} {h0}");
        // One full period away (5 x 0.5 m, 4 x 0.5 m) is the same point.
        let a = f.height_local(Vec2::new(0.3, 0.7));
        let b = f.height_local(Vec2::new(0.3 - 2.5, 0.7 + 2.0));
        assert!((a - b).abs() < 1e-4);
    }

    #[test]
    fn patch_agrees_with_height_and_bounds_hold() {
        let m = map();
        let f = HeightField::from_map(&m).expect("field");
        let (lo, hi) = f.height_bounds();
        for i in 0..50 {
            let p = Vec2::new(i as f32 * 0.213 - 3.0, i as f32 * 0.097 - 1.0);
            let q = p.as_dvec2() / 0.5;
            let patch = f.patch(q.x.floor() as i64, q.y.floor() as i64);
            let h = patch.height(q.x - q.x.floor(), q.y - q.y.floor());
            assert!((h as f32 - f.height_local(p)).abs() < 1e-4);
            assert!(h >= f64::from(lo) - 1e-4 && h <= f64::from(hi) + 1e-4);
        }
    }

    #[test]
    fn rejects_clamped_maps_and_bad_spacing() {
        let g = Grid::new(4, 4, 0u16).expect("grid");
        let e = HeightEncoding::new(0.01, 0.0).expect("encoding");
        let clamped =
            terrain_core::HeightMap::new(g.clone(), e, 1.0, WrapMode::Clamp).expect("map");
        assert!(matches!(
            HeightField::from_map(&clamped),
            Err(PhysicsError::NotToroidal { .. })
        ));
        assert!(matches!(
            HeightField::new(g, e, f32::NAN),
            Err(PhysicsError::Core(_))
        ));
    }

    #[test]
    fn min_max_of_odd_lengths() {
        let v: Vec<u16> = (0..37).map(|i| (i * 7919 % 1000) as u16).collect();
        let (lo, hi) = min_max(&v);
        assert_eq!(lo, *v.iter().min().expect("non-empty"));
        assert_eq!(hi, *v.iter().max().expect("non-empty"));
    }
}
