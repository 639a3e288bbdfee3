//! Which tiles to hold: the camera ([`CameraState`]), the tile layout a policy sees
//! ([`TileGrid`]) and the selection policies: [`SphericalSelection`] (Fikkan 2013, sec. 5.4.1, the
//! RAM pool's default), [`FrustumSelection`] with a motion-dependent field of view (Fikkan 2013, sec.
//! 5.4.2) and [`BandSelection`] (Flower 2010, sec. 2.4.2, fig. 2.4).
//!
//! Every policy first limits itself to a square of tiles around the camera, clamped to the
//! world, so its time is bounded by the world's tiles whatever the camera's coordinates.

use crate::CacheError;
use crate::manifest::Manifest;
use crate::tile::{Layer, TileId};
use glam::{DVec2, DVec3, UVec2, Vec3};
use std::fmt;
use terrain_core::WrapMode;

/// The camera as the policies see it (world metres, Y up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraState {
    /// Eye position.
    pub position: Vec3,
    /// View direction (need not be normalised; zero means "no direction").
    pub forward: Vec3,
    /// Vertical field of view in radians, `(0, pi)`.
    pub fov_y: f32,
    /// Width over height of the view.
    pub aspect: f32,
}

impl CameraState {
    /// A camera at `position` looking along +X with a 60 degree, 16:9 view.
    pub fn at(position: Vec3) -> Self {
        Self {
            position,
            forward: Vec3::X,
            fov_y: 60f32.to_radians(),
            aspect: 16.0 / 9.0,
        }
    }

    /// This camera looking along `forward` with a vertical field of view of `fov_y` radians
    /// and `aspect` (checked where the policies use it: [`Self::validate`]).
    pub fn looking(self, forward: Vec3, fov_y: f32, aspect: f32) -> Self {
        Self {
            forward,
            fov_y,
            aspect,
            ..self
        }
    }

    /// Checks for non-finite values and an out-of-range field of view.
    pub fn validate(&self) -> Result<(), CacheError> {
        let check = |what, v: f32, ok: bool| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err(CacheError::OutOfRange {
                    what,
                    value: f64::from(v),
                    expected: "finite (fov in (0, pi), aspect > 0)",
                })
            }
        };
        for v in self.position.to_array() {
            check("camera position", v, true)?;
        }
        for v in self.forward.to_array() {
            check("camera forward", v, true)?;
        }
        check(
            "camera fov_y",
            self.fov_y,
            self.fov_y > 0.0 && self.fov_y < std::f32::consts::PI,
        )?;
        check("camera aspect", self.aspect, self.aspect > 0.0)
    }

    /// Half of the horizontal field of view, in radians.
    pub fn half_fov_x(&self) -> f64 {
        ((f64::from(self.fov_y) * 0.5).tan() * f64::from(self.aspect)).atan()
    }
}

/// One level of the tile layout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelGrid {
    /// Tiles across and down.
    pub tiles: UVec2,
    /// Side of one tile in metres.
    pub tile_m: f64,
}

/// The tile layout of one layer, as the policies see it.
#[derive(Debug, Clone, PartialEq)]
pub struct TileGrid {
    /// Levels, finest first.
    pub levels: Vec<LevelGrid>,
    /// How the world wraps.
    pub wrap: WrapMode,
    /// Vertical extent of the terrain in metres (`min`, `max`), for 3D distances.
    pub height_range_m: (f32, f32),
}

impl TileGrid {
    /// The layout of `layer` of a world.
    pub fn from_manifest(m: &Manifest, layer: Layer) -> Self {
        let levels = (0..m.layer_levels(layer))
            .map(|l| LevelGrid {
                tiles: m.layer_tiles(layer, l),
                tile_m: m.tile_extent_m(layer, l),
            })
            .collect();
        let (lo, hi) = m.encoding.range::<u16>();
        Self {
            levels,
            wrap: if layer == Layer::Detail {
                WrapMode::Clamp
            } else {
                m.wrap
            },
            height_range_m: (lo.min(hi), lo.max(hi)),
        }
    }

    /// A flat single-level grid (tests, the simulator).
    pub fn flat(tiles: UVec2, tile_m: f64, wrap: WrapMode) -> Self {
        Self {
            levels: vec![LevelGrid { tiles, tile_m }],
            wrap,
            height_range_m: (0.0, 0.0),
        }
    }

    /// World extent in metres (level 0).
    pub fn extent_m(&self) -> DVec2 {
        self.levels
            .first()
            .map(|l| l.tiles.as_dvec2() * l.tile_m)
            .unwrap_or(DVec2::ZERO)
    }

    /// The camera's horizontal position brought into the world (modulo the extent when the
    /// world wraps).
    pub fn camera_xz(&self, position: Vec3) -> DVec2 {
        let p = DVec2::new(f64::from(position.x), f64::from(position.z));
        let e = self.extent_m();
        match self.wrap {
            WrapMode::Repeat if e.min_element() > 0.0 => {
                DVec2::new(p.x.rem_euclid(e.x), p.y.rem_euclid(e.y))
            }
            _ => p,
        }
    }

    /// Tiles of `level` whose square lies within `radius` metres (on each axis) of `xz`, each
    /// given once with the offset of its nearest periodic image (wrapping worlds), clamped to
    /// the world: at most the level's tile count, whatever `radius` is.
    pub fn square(&self, level: u32, xz: DVec2, radius: f64, mut f: impl FnMut(TileId, DVec2)) {
        let Some(g) = self.levels.get(level as usize) else {
            return;
        };
        if g.tiles.min_element() == 0 || radius.is_nan() || radius < 0.0 {
            return;
        }
        let t = g.tile_m;
        let r = radius.min(1e12);
        let lo = ((xz - r) / t).floor();
        let hi = ((xz + r) / t).floor();
        let n = g.tiles.as_dvec2();
        let c = xz / t;
        for axis_y in axis_range(lo.y, hi.y, n.y, c.y, self.wrap) {
            for axis_x in axis_range(lo.x, hi.x, n.x, c.x, self.wrap) {
                let (ix, ox) = axis_x;
                let (iy, oy) = axis_y;
                f(TileId::new(level, ix, iy), DVec2::new(ox, oy) * t);
            }
        }
    }

    /// 3D distance in metres from `eye` (x, y, z with `xz` already wrapped) to the box of tile
    /// `id` shifted by `offset` metres (its periodic image), spanning the height range.
    pub fn distance(&self, eye: DVec3, id: TileId, offset: DVec2) -> f64 {
        let Some(g) = self.levels.get(id.level as usize) else {
            return f64::INFINITY;
        };
        let min = DVec2::new(f64::from(id.x), f64::from(id.y)) * g.tile_m + offset;
        let max = min + g.tile_m;
        let dx = (min.x - eye.x).max(eye.x - max.x).max(0.0);
        let dz = (min.y - eye.z).max(eye.z - max.y).max(0.0);
        let (lo, hi) = (
            f64::from(self.height_range_m.0),
            f64::from(self.height_range_m.1),
        );
        let dy = (lo - eye.y).max(eye.y - hi).max(0.0);
        (dx * dx + dy * dy + dz * dz).sqrt()
    }

    /// Eviction score of a tile: its horizontal distance from the camera in tiles of its own
    /// level (far and fine tiles first; coarse tiles serve more views and stay longer).
    pub fn eviction_score(&self, camera: Vec3, id: TileId) -> f64 {
        let Some(g) = self.levels.get(id.level as usize) else {
            return f64::INFINITY;
        };
        let xz = self.camera_xz(camera);
        let eye = DVec3::new(xz.x, f64::from(camera.y), xz.y);
        let mut best = f64::INFINITY;
        let shifts: &[f64] = if self.wrap == WrapMode::Repeat {
            &[-1.0, 0.0, 1.0]
        } else {
            &[0.0]
        };
        let level_extent = g.tiles.as_dvec2() * g.tile_m;
        for &sy in shifts {
            for &sx in shifts {
                let off = DVec2::new(sx, sy) * level_extent;
                best = best.min(self.distance(
                    DVec3::new(eye.x, f64::from(self.height_range_m.0), eye.z),
                    id,
                    off,
                ));
            }
        }
        best / g.tile_m
    }
}

/// Tile indices `lo..=hi` on one axis (tile units), with the offset (in tiles) of the periodic
/// image each index stands for; clamped to `0..n` without wrap, at most `n` indices with wrap
/// (then each tile once, at its image nearest `centre`, the camera in tile units).
fn axis_range(lo: f64, hi: f64, n: f64, centre: f64, wrap: WrapMode) -> Vec<(u32, f64)> {
    let mut out = Vec::new();
    match wrap {
        WrapMode::Clamp => {
            let a = lo.max(0.0);
            let b = hi.min(n - 1.0);
            let mut i = a;
            while i <= b {
                out.push((i as u32, 0.0));
                i += 1.0;
            }
        }
        WrapMode::Repeat if hi - lo + 1.0 >= n => {
            let mut w = 0.0;
            while w < n {
                let shift = ((centre - (w + 0.5)) / n).round() * n;
                out.push((w as u32, shift));
                w += 1.0;
            }
        }
        WrapMode::Repeat => {
            let mut i = lo;
            while i <= hi {
                let wrapped = i.rem_euclid(n);
                out.push((wrapped as u32, i - wrapped));
                i += 1.0;
            }
        }
    }
    out
}

/// A tile a policy wants, with its priority: lower is more urgent, `[0, 1]` for tiles inside
/// the selection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Want {
    /// The tile.
    pub id: TileId,
    /// Lower loads first.
    pub priority: f32,
}

/// A selection policy: which tiles to hold for a camera.
pub trait SelectionPolicy: Send + Sync + fmt::Debug {
    /// Appends the tiles wanted for `camera` to `out` (each at most once).
    fn select(&mut self, camera: &CameraState, grid: &TileGrid, out: &mut Vec<Want>);
}

/// Fikkan 2013, sec. 5.4.1: a square of side `2 * view_distance` around the camera, then per level a
/// spherical distance threshold: level `l` is wanted within `lod0_range * lod_ratio^l` metres
/// (3D distance to the tile's box). Finer levels nest inside coarser ones, so every wanted fine
/// tile has its coarser fallbacks wanted too.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphericalSelection {
    /// Maximum line of sight in metres: the square's half side.
    pub view_distance: f64,
    /// Threshold of level 0 in metres.
    pub lod0_range: f64,
    /// Threshold ratio between successive levels (2: each level twice as far).
    pub lod_ratio: f64,
}

impl SphericalSelection {
    /// Thresholds scaled to a grid: level 0 within 1.5 of its tiles, doubling per level, the
    /// view distance the coarsest level's threshold.
    pub fn for_grid(grid: &TileGrid) -> Self {
        let t0 = grid.levels.first().map(|l| l.tile_m).unwrap_or(1.0);
        let top = grid.levels.len().saturating_sub(1) as i32;
        Self {
            view_distance: 1.5 * t0 * 2f64.powi(top),
            lod0_range: 1.5 * t0,
            lod_ratio: 2.0,
        }
    }

    /// The threshold of `level`.
    pub fn threshold(&self, level: u32) -> f64 {
        (self.lod0_range * self.lod_ratio.powi(level.min(64) as i32)).min(self.view_distance)
    }
}

impl SelectionPolicy for SphericalSelection {
    fn select(&mut self, camera: &CameraState, grid: &TileGrid, out: &mut Vec<Want>) {
        let xz = grid.camera_xz(camera.position);
        let eye = DVec3::new(xz.x, f64::from(camera.position.y), xz.y);
        for level in 0..grid.levels.len() as u32 {
            let thr = self.threshold(level);
            if thr.is_nan() || thr <= 0.0 {
                continue;
            }
            grid.square(level, xz, self.view_distance.min(thr), |id, off| {
                let d = grid.distance(eye, id, off);
                if d < thr {
                    push_unique(out, id, (d / thr) as f32);
                }
            });
        }
    }
}

/// Keeps the better priority if the policy reaches a tile through two periodic images.
fn push_unique(out: &mut Vec<Want>, id: TileId, priority: f32) {
    // Wrapped squares visit each tile once per level; duplicates only arise in tiny worlds.
    if let Some(w) = out.iter_mut().rev().take(64).find(|w| w.id == id) {
        w.priority = w.priority.min(priority);
    } else {
        out.push(Want { id, priority });
    }
}

/// Fikkan 2013, sec. 5.4.2: tiles of one level inside the view frustum (horizontal cone test on the
/// tile's bounding circle), widened by a margin that grows with the camera's turn rate, plus
/// every tile within `near` metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrustumSelection {
    /// The level selected.
    pub level: u32,
    /// Far distance in metres.
    pub far: f64,
    /// Tiles within this distance are always wanted (behind the camera too).
    pub near: f64,
    /// Extra half-angle in radians added to the camera's horizontal half field of view.
    pub fov_margin: f64,
    /// Radians of extra half-angle per radian per frame of turning (Fikkan 2013, fig. 5.5: a
    /// turning camera needs a wider view).
    pub turn_gain: f64,
    /// Forward direction of the previous frame (state for the turn rate).
    pub last_forward: Option<DVec2>,
}

impl FrustumSelection {
    /// A frustum selection of `level` out to `far` metres with a 15 degree margin.
    pub fn new(level: u32, far: f64) -> Self {
        Self {
            level,
            far,
            near: 0.0,
            fov_margin: 15f64.to_radians(),
            turn_gain: 8.0,
            last_forward: None,
        }
    }
}

impl SelectionPolicy for FrustumSelection {
    fn select(&mut self, camera: &CameraState, grid: &TileGrid, out: &mut Vec<Want>) {
        let Some(g) = grid.levels.get(self.level as usize) else {
            return;
        };
        let xz = grid.camera_xz(camera.position);
        let eye = DVec3::new(xz.x, f64::from(camera.position.y), xz.y);
        let fwd = DVec2::new(f64::from(camera.forward.x), f64::from(camera.forward.z));
        let fwd = fwd.try_normalize();
        let turn = match (fwd, self.last_forward) {
            (Some(f), Some(l)) => f.dot(l).clamp(-1.0, 1.0).acos(),
            _ => 0.0,
        };
        self.last_forward = fwd;
        let half = (camera.half_fov_x() + self.fov_margin + self.turn_gain * turn)
            .min(std::f64::consts::PI);
        let radius = g.tile_m * std::f64::consts::FRAC_1_SQRT_2;
        let far = self.far.max(0.0);
        grid.square(self.level, xz, far + g.tile_m, |id, off| {
            let d = grid.distance(eye, id, off);
            if d <= self.near {
                push_unique(out, id, 0.0);
                return;
            }
            if d > far {
                return;
            }
            let centre = (DVec2::new(f64::from(id.x), f64::from(id.y)) + 0.5) * g.tile_m + off;
            let to = centre - DVec2::new(eye.x, eye.z);
            let dist = to.length();
            let inside = match fwd {
                None => true,
                Some(_) if dist <= radius => true,
                Some(f) => {
                    let angle = (to / dist).dot(f).clamp(-1.0, 1.0).acos();
                    angle - (radius / dist).clamp(-1.0, 1.0).asin() <= half
                }
            };
            if inside {
                push_unique(out, id, (d / far.max(1e-9)) as f32);
            }
        });
    }
}

/// Flower 2010, sec. 2.4.2 (fig. 2.4): the camera's tile is split into nine regions by a horizontal
/// and a vertical band of `band_width` (fraction of the tile) across its centre. In a band both
/// neighbours across it are held; outside, only the neighbour on the camera's side; the
/// centre region holds all nine tiles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BandSelection {
    /// The level selected (the detail layer has one).
    pub level: u32,
    /// Band width as a fraction of the tile side, `[0, 1]` (1/3 gives nine equal regions).
    pub band_width: f64,
}

impl Default for BandSelection {
    fn default() -> Self {
        Self {
            level: 0,
            band_width: 1.0 / 3.0,
        }
    }
}

impl BandSelection {
    /// Neighbour offsets held on one axis for fractional position `f` in the tile.
    pub fn axis_offsets(&self, f: f64) -> &'static [i32] {
        let w = self.band_width.clamp(0.0, 1.0) * 0.5;
        if (f - 0.5).abs() < w {
            &[0, -1, 1]
        } else if f < 0.5 {
            &[0, -1]
        } else {
            &[0, 1]
        }
    }
}

impl SelectionPolicy for BandSelection {
    fn select(&mut self, camera: &CameraState, grid: &TileGrid, out: &mut Vec<Want>) {
        let Some(g) = grid.levels.get(self.level as usize) else {
            return;
        };
        if g.tiles.min_element() == 0 {
            return;
        }
        let xz = grid.camera_xz(camera.position) / g.tile_m;
        let cell = xz.floor();
        let frac = xz - cell;
        let n = g.tiles.as_dvec2();
        for &dy in self.axis_offsets(frac.y) {
            for &dx in self.axis_offsets(frac.x) {
                let p = cell + DVec2::new(f64::from(dx), f64::from(dy));
                let p = match grid.wrap {
                    WrapMode::Repeat => DVec2::new(p.x.rem_euclid(n.x), p.y.rem_euclid(n.y)),
                    WrapMode::Clamp => {
                        if p.x < 0.0 || p.y < 0.0 || p.x >= n.x || p.y >= n.y {
                            continue;
                        }
                        p
                    }
                };
                let prio = if dx == 0 && dy == 0 {
                    0.0
                } else {
                    0.5 + 0.25 * f32::from((dx != 0) as u8 + (dy != 0) as u8)
                };
                push_unique(out, TileId::new(self.level, p.x as u32, p.y as u32), prio);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid3() -> TileGrid {
        TileGrid {
            levels: vec![
                LevelGrid {
                    tiles: UVec2::splat(8),
                    tile_m: 10.0,
                },
                LevelGrid {
                    tiles: UVec2::splat(4),
                    tile_m: 20.0,
                },
                LevelGrid {
                    tiles: UVec2::splat(2),
                    tile_m: 40.0,
                },
            ],
            wrap: WrapMode::Clamp,
            height_range_m: (0.0, 0.0),
        }
    }

    #[test]
    fn spherical_nests_levels_and_is_bounded_for_any_camera() {
        let g = grid3();
        let mut p = SphericalSelection {
            view_distance: 60.0,
            lod0_range: 12.0,
            lod_ratio: 2.0,
        };
        let mut out = Vec::new();
        p.select(&CameraState::at(Vec3::new(35.0, 0.0, 35.0)), &g, &mut out);
        let l0: Vec<_> = out.iter().filter(|w| w.id.level == 0).collect();
        assert!(l0.len() >= 4 && l0.len() <= 16, "{}", l0.len());
        assert!(
            out.iter()
                .any(|w| w.id == TileId::new(0, 3, 3) && w.priority == 0.0)
        );
        // Every wanted level-0 tile has its parent wanted.
        for w in &l0 {
            assert!(out.iter().any(|v| Some(v.id) == w.id.parent()));
        }
        for pos in [
            Vec3::splat(f32::MAX),
            Vec3::splat(f32::MIN),
            Vec3::new(1e30, -1e30, 0.0),
        ] {
            out.clear();
            p.select(&CameraState::at(pos), &g, &mut out);
            assert!(out.len() <= 64 + 16 + 4);
        }
        let mut huge = SphericalSelection {
            view_distance: f64::MAX,
            lod0_range: f64::MAX,
            lod_ratio: 2.0,
        };
        out.clear();
        huge.select(&CameraState::at(Vec3::ZERO), &g, &mut out);
        assert_eq!(out.len(), 64 + 16 + 4);
        let mut wrapped = g.clone();
        wrapped.wrap = WrapMode::Repeat;
        out.clear();
        huge.select(&CameraState::at(Vec3::splat(-1e30)), &wrapped, &mut out);
        assert_eq!(out.len(), 64 + 16 + 4);
    }

    #[test]
    fn band_regions_hold_four_six_or_nine_tiles() {
        let g = TileGrid::flat(UVec2::splat(8), 10.0, WrapMode::Repeat);
        let mut b = BandSelection::default();
        let count = |b: &mut BandSelection, x: f32, z: f32| {
            let mut out = Vec::new();
            b.select(&CameraState::at(Vec3::new(x, 0.0, z)), &g, &mut out);
            out.len()
        };
        assert_eq!(count(&mut b, 35.0, 35.0), 9); // centre region
        assert_eq!(count(&mut b, 31.0, 31.0), 4); // corner
        assert_eq!(count(&mut b, 35.0, 31.0), 6); // vertical band, top third
        assert_eq!(count(&mut b, 1.0, 1.0), 4); // corner, wrapping to the far tiles
        b.band_width = 0.0;
        assert_eq!(count(&mut b, 35.0, 35.0), 4);
    }

    #[test]
    fn frustum_sees_ahead_not_behind_and_widens_when_turning() {
        let g = TileGrid::flat(UVec2::splat(32), 10.0, WrapMode::Clamp);
        let mut f = FrustumSelection::new(0, 80.0);
        let mut cam = CameraState::at(Vec3::new(160.0, 0.0, 160.0));
        let mut out = Vec::new();
        f.select(&cam, &g, &mut out);
        assert!(out.iter().any(|w| w.id == TileId::new(0, 22, 16)));
        assert!(!out.iter().any(|w| w.id == TileId::new(0, 10, 16)));
        let still = out.len();
        cam.forward = Vec3::new(0.9, 0.0, 0.44);
        out.clear();
        f.select(&cam, &g, &mut out);
        assert!(out.len() > still, "{} vs {still}", out.len());
    }
}
