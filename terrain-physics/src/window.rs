//! `CollisionWindow`: collision for a world larger than memory. A [`CollisionMirror`] of a
//! fixed square of level-0 texels that follows the camera over a streamed world (terrain-cache
//! fills it from the RAM pool) and still takes the dirty-region readbacks of deformations.
//!
//! Design: the mirror is addressed toroidally, world texel `(x, y)` at `(x mod w, y mod h)`,
//! like a clipmap level. Moving the window only fills the strips that come into it (the rest
//! stays where it is), and queries take world metres unchanged: the toroidal mirror answers
//! for world texel `(x, y)` exactly when the window covers it. The window's corner moves in
//! steps of [`WINDOW_STEP`] texels, so a walking camera refills a strip every few metres, not
//! a column every frame.

use crate::collider::HeightfieldCollider;
use crate::error::PhysicsError;
use crate::field::{HeightField, MAX_FIELD_SIDE};
use crate::mirror::CollisionMirror;
use glam::{IVec2, UVec2, Vec2};
use std::sync::Arc;
use terrain_core::{Grid, HeightEncoding, Rect, WindowSource};

/// The window's corner moves in multiples of this many texels.
pub const WINDOW_STEP: u32 = 16;

/// Longest window side accepted (texels): 8192^2 u16 is 128 MiB, twice with the back buffer.
pub const MAX_WINDOW_SIDE: u32 = 8192;

/// Why moving or refreshing the window failed: the mirror's own checks, or the fill
/// callback's failure in its own error type.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WindowError<E> {
    /// A bad position, or the mirror refused a region.
    #[error(transparent)]
    Physics(#[from] PhysicsError),
    /// The fill callback failed; its error, unchanged. The window keeps what it had.
    #[error("filling the collision window failed")]
    Fill(#[source] E),
}

/// A collision mirror over a moving square of a larger world (see the module docs).
#[derive(Debug)]
pub struct CollisionWindow {
    mirror: CollisionMirror,
    /// Mirror size: the window side, or the world's where the world is smaller.
    size: UVec2,
    world_size: UVec2,
    texel_size: f32,
    /// World texels the mirror holds now; `None` until the first [`recenter`](Self::recenter).
    window: Option<Rect>,
    /// Rects a [`WindowSource`] reported improved that [`follow`](Self::follow) has not filled
    /// again yet (a fill failed): still stand-ins, filled again by the next `follow`.
    pending: Vec<Rect>,
}

impl CollisionWindow {
    /// A window of `side` x `side` level-0 texels (at most the world's size per axis) over a
    /// world of `world_size` texels of `texel_size` metres, heights in `encoding`. Nothing is
    /// filled until the first [`recenter`](Self::recenter).
    pub fn new(
        side: u32,
        world_size: UVec2,
        encoding: HeightEncoding,
        texel_size: f32,
    ) -> Result<Self, PhysicsError> {
        if !(2 * WINDOW_STEP..=MAX_WINDOW_SIDE).contains(&side) {
            return Err(PhysicsError::OutOfRange {
                what: "collision window side (texels)",
                value: f64::from(side),
                expected: "32 to 8192 texels",
            });
        }
        if world_size.min_element() < 2 || world_size.max_element() > MAX_FIELD_SIDE {
            return Err(PhysicsError::OutOfRange {
                what: "world side (texels)",
                value: f64::from(world_size.min_element().min(world_size.max_element())),
                expected: "2 to 2^28 texels",
            });
        }
        let size = UVec2::splat(side).min(world_size);
        let grid = Grid::new(size.x, size.y, 0u16)?;
        let field = HeightField::new(grid, encoding, texel_size)?;
        Ok(Self {
            mirror: CollisionMirror::new(field),
            size,
            world_size,
            texel_size,
            window: None,
            pending: Vec::new(),
        })
    }

    /// The world texels the window holds, `None` before the first fill.
    pub fn window(&self) -> Option<Rect> {
        self.window
    }

    /// The mirror (snapshots for other threads; its version counts every fill and update).
    pub fn mirror(&self) -> &CollisionMirror {
        &self.mirror
    }

    /// The window a camera at `center` (world metres, X and Z) gets: the mirror's size, its
    /// corner on a [`WINDOW_STEP`] grid nearest to centring it, clamped inside the world.
    pub fn window_at(&self, center: Vec2) -> Result<Rect, PhysicsError> {
        if !center.is_finite() {
            return Err(PhysicsError::NonFinite {
                what: "collision window centre",
                value: if center.x.is_finite() {
                    center.y
                } else {
                    center.x
                },
            });
        }
        let texel = (
            f64::from(center.x) / f64::from(self.texel_size),
            f64::from(center.y) / f64::from(self.texel_size),
        );
        let axis = |t: f64, size: u32, world: u32| -> i32 {
            let step = f64::from(WINDOW_STEP);
            let corner = ((t - f64::from(size) / 2.0) / step).round() * step;
            // Clamped in f64 first: any finite centre gives a corner inside the world.
            corner.clamp(0.0, f64::from(world - size)) as i32
        };
        let min = IVec2::new(
            axis(texel.0, self.size.x, self.world_size.x),
            axis(texel.1, self.size.y, self.world_size.y),
        );
        Ok(Rect::new(min, self.size))
    }

    /// Moves the window to the camera at `center` (world metres). The world texels that come
    /// into it are filled by `fill(rect, out)` (world texels; `out` is `rect.size`), at most
    /// four strips, each applied to the mirror as one update; the rest is kept. Returns the
    /// texels filled (0 when the window did not move). On a failure the window keeps the
    /// strips already applied and reports the one that failed.
    pub fn recenter<E>(
        &mut self,
        center: Vec2,
        mut fill: impl FnMut(Rect, &mut Grid<u16>) -> Result<(), E>,
    ) -> Result<u64, WindowError<E>> {
        let new = self.window_at(center)?;
        if self.window == Some(new) {
            return Ok(0);
        }
        let strips = match self.window.and_then(|old| old.intersect(&new)) {
            Some(keep) => new.minus(&keep),
            None => vec![new],
        };
        // Until every strip is in, the window is what the old one and the new share.
        self.window = self.window.and_then(|old| old.intersect(&new));
        let mut filled = 0;
        for strip in strips {
            self.fill_rect(strip, &mut fill)?;
            filled += strip.area();
        }
        self.window = Some(new);
        Ok(filled)
    }

    /// Moves the window to the camera at `center` as [`recenter`](Self::recenter) does, filled
    /// by `source` (terrain-core's [`WindowSource`]: terrain-cache's RAM pool, say), then fills
    /// again what the source has improved since (a tile that arrived where coarser data stood
    /// in). Returns the texels filled. On a failed fill the window keeps what was filled; the
    /// improved rects not filled yet stay stand-ins for [`ground`](Self::ground) and are
    /// filled by the next call (after its move, with what the source has improved since).
    pub fn follow<S: WindowSource>(
        &mut self,
        center: Vec2,
        source: &mut S,
    ) -> Result<u64, WindowError<S::Error>> {
        let mut filled = self.recenter(center, |r, out| source.fill(r, out))?;
        // Each rect once, and only while it meets the window: at most the window's tiles.
        let window = self.window;
        let meets = |r: &Rect| window.is_some_and(|w| w.intersect(r).is_some());
        self.pending.retain(meets);
        for rect in source.improved(window) {
            if meets(&rect) && !self.pending.contains(&rect) {
                self.pending.push(rect);
            }
        }
        while let Some(&rect) = self.pending.last() {
            filled += self.refresh(rect, |r, out| source.fill(r, out))?;
            self.pending.pop();
        }
        Ok(filled)
    }

    /// Ground height at world `pos` (metres) where the window holds real data: `None` outside
    /// the window and where `stand_in` says a texel the lookup reads (the four around `pos`)
    /// was filled with a stand-in (its source's [`WindowSource::is_stand_in`]), or a failed
    /// [`follow`](Self::follow) left one; the caller asks something coarser there.
    pub fn ground(
        &self,
        pos: Vec2,
        stand_in: impl Fn(UVec2) -> bool,
    ) -> Result<Option<f32>, PhysicsError> {
        if !self.contains(pos) {
            return Ok(None);
        }
        // Every tap of the bilinear lookup (`cell` and `cell + 1` on each axis): a height
        // next to a stand-in is part stand-in.
        let last = self.world_size.saturating_sub(UVec2::ONE);
        let cell = (pos / self.texel_size).floor().max(Vec2::ZERO).as_uvec2();
        for d in [UVec2::ZERO, UVec2::X, UVec2::Y, UVec2::ONE] {
            let texel = cell.saturating_add(d).min(last);
            let waiting = self.pending.iter().any(|r| r.contains(texel.as_ivec2()));
            if waiting || stand_in(texel) {
                return Ok(None);
            }
        }
        self.height(pos)
    }

    /// Fills again the part of `rect` (world texels) inside the window: for data that got
    /// better (a level-0 tile loaded where a coarser one stood in). Returns the texels filled.
    pub fn refresh<E>(
        &mut self,
        rect: Rect,
        mut fill: impl FnMut(Rect, &mut Grid<u16>) -> Result<(), E>,
    ) -> Result<u64, WindowError<E>> {
        let Some(part) = self.window.and_then(|w| w.intersect(&rect)) else {
            return Ok(0);
        };
        self.fill_rect(part, &mut fill)?;
        Ok(part.area())
    }

    /// Applies new heights of `rect` (world texels; `heights` of its size), a readback of a
    /// deformed region, to the part inside the window. Returns whether any of it was.
    pub fn apply(&self, rect: Rect, heights: &Grid<u16>) -> Result<bool, PhysicsError> {
        if heights.size() != rect.size {
            return Err(PhysicsError::SizeMismatch {
                expected: rect.size,
                actual: heights.size(),
            });
        }
        let Some(part) = self.window.and_then(|w| w.intersect(&rect)) else {
            return Ok(false);
        };
        let piece = heights.copy_rect(Rect::new(part.min - rect.min, part.size))?;
        self.mirror.apply_next(self.mirror_rect(part), &piece)?;
        Ok(true)
    }

    /// Cuts the holes of `mask`, the hole mask (`terrain_core::holes`) of the window's rect
    /// ([`window`](Self::window)) row-major as `terrain_cache::read_holes` returns it, into the
    /// window, or none for `None`: over them rays pass through and bodies fall. Call it after a
    /// [`recenter`](Self::recenter) that moved the window and after a hole is cut inside it.
    /// Fails, with the window unchanged, before the first fill and on a mask of another size.
    pub fn set_holes(&self, mask: Option<&Grid<u8>>) -> Result<(), PhysicsError> {
        let Some(mask) = mask else {
            return self.mirror.set_holes(None);
        };
        let Some(w) = self.window else {
            return Err(PhysicsError::OutOfRange {
                what: "collision window holes",
                value: 0.0,
                expected: "a window filled by recenter first",
            });
        };
        if mask.size() != w.size {
            return Err(PhysicsError::SizeMismatch {
                expected: w.size,
                actual: mask.size(),
            });
        }
        // World cell (x, y) sits at (x mod w, y mod h) in the mirror, as its heights do.
        let (sw, sh) = (self.size.x as usize, self.size.y as usize);
        let mut toroidal = Grid::new(self.size.x, self.size.y, terrain_core::GROUND)?;
        let out = toroidal.as_mut_slice();
        for j in 0..w.size.y {
            let y = (w.min.y as usize + j as usize) % sh;
            for (i, &v) in mask.row(j).iter().enumerate() {
                out[y * sw + (w.min.x as usize + i) % sw] = v;
            }
        }
        self.mirror.set_holes(Some(Arc::new(toroidal)))
    }

    /// Whether world position `pos` (metres) can be answered: its cell lies inside the window
    /// (a query there reads no texel outside it).
    pub fn contains(&self, pos: Vec2) -> bool {
        let Some(w) = self.window else {
            return false;
        };
        if !pos.is_finite() {
            return false;
        }
        // The cell the lookup will read, found with the lookup's own arithmetic: f32 near the
        // origin (where the field samples in f32), f64 beyond 2^24 texels (where it reduces
        // the position in f64 first), so the test and the lookup never pick different cells.
        let t32 = pos / self.texel_size;
        let cell = if t32.is_finite() && t32.abs().max_element() < 16_777_216.0 {
            t32.floor().as_dvec2()
        } else {
            (pos.as_dvec2() / f64::from(self.texel_size)).floor()
        };
        // Both taps of the bilinear lookup, `cell` and `cell + 1`, inside the window.
        let (lo, hi) = (w.min.as_dvec2(), (w.max() - IVec2::ONE).as_dvec2());
        cell.x >= lo.x && cell.y >= lo.y && cell.x < hi.x && cell.y < hi.y
    }

    /// A collider over the current snapshot, taking world metres: valid where
    /// [`contains`](Self::contains) is true.
    pub fn collider(&self) -> HeightfieldCollider {
        self.mirror.collider()
    }

    /// Ground height at world `pos` (metres), `None` outside the window.
    pub fn height(&self, pos: Vec2) -> Result<Option<f32>, PhysicsError> {
        if !self.contains(pos) {
            return Ok(None);
        }
        self.collider().height(pos).map(Some)
    }

    /// The current snapshot.
    pub fn snapshot(&self) -> Arc<HeightField> {
        self.mirror.snapshot()
    }

    fn fill_rect<E>(
        &mut self,
        rect: Rect,
        fill: &mut impl FnMut(Rect, &mut Grid<u16>) -> Result<(), E>,
    ) -> Result<(), WindowError<E>> {
        let mut out = Grid::new(rect.size.x, rect.size.y, 0u16).map_err(PhysicsError::from)?;
        fill(rect, &mut out).map_err(WindowError::Fill)?;
        self.mirror.apply_next(self.mirror_rect(rect), &out)?;
        Ok(())
    }

    /// `rect` (world texels, inside the window) in the mirror's toroidal frame: the same rect
    /// moved by whole periods so its corner lies in the mirror.
    fn mirror_rect(&self, rect: Rect) -> Rect {
        let s = self.size.as_ivec2();
        Rect::new(
            IVec2::new(rect.min.x.rem_euclid(s.x), rect.min.y.rem_euclid(s.y)),
            rect.size,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The world's stored value at texel `(x, y)`.
    fn truth(x: i32, y: i32) -> u16 {
        ((x * 37 + y * 101) % 60_000) as u16
    }

    fn fill_truth(rect: Rect, out: &mut Grid<u16>) -> Result<(), std::convert::Infallible> {
        for y in 0..rect.size.y {
            for x in 0..rect.size.x {
                *out.get_mut(x, y).expect("inside") =
                    truth(rect.min.x + x as i32, rect.min.y + y as i32);
            }
        }
        Ok(())
    }

    fn enc() -> HeightEncoding {
        HeightEncoding::new(0.01, 0.0).expect("encoding")
    }

    /// Every texel of the window, read through the toroidal mirror, is the world's.
    fn assert_window_true(w: &CollisionWindow) {
        let rect = w.window().expect("filled");
        let snap = w.snapshot();
        for y in rect.min.y..rect.max().y {
            for x in rect.min.x..rect.max().x {
                let s = w.size.as_ivec2();
                let got = snap
                    .heights()
                    .get(x.rem_euclid(s.x) as u32, y.rem_euclid(s.y) as u32)
                    .expect("inside");
                assert_eq!(got, truth(x, y), "texel ({x}, {y}) of {rect:?}");
            }
        }
    }

    /// A source whose tiles of `TILE` texels are "loaded" or stand in with zeros until loaded.
    struct Tiles {
        loaded: std::collections::HashSet<(i32, i32)>,
        stand_ins: std::collections::HashSet<(i32, i32)>,
    }

    const TILE: i32 = 32;

    impl WindowSource for Tiles {
        type Error = std::convert::Infallible;

        fn fill(&mut self, rect: Rect, out: &mut Grid<u16>) -> Result<(), Self::Error> {
            fill_truth(rect, out)?;
            for y in 0..rect.size.y {
                for x in 0..rect.size.x {
                    let (wx, wy) = (rect.min.x + x as i32, rect.min.y + y as i32);
                    let tile = (wx / TILE, wy / TILE);
                    if !self.loaded.contains(&tile) {
                        *out.get_mut(x, y).expect("inside") = 0;
                        self.stand_ins.insert(tile);
                    }
                }
            }
            Ok(())
        }

        fn improved(&mut self, _window: Option<Rect>) -> Vec<Rect> {
            let ready: Vec<_> = (self.stand_ins.iter())
                .filter(|t| self.loaded.contains(t))
                .copied()
                .collect();
            ready
                .into_iter()
                .map(|t| {
                    self.stand_ins.remove(&t);
                    let side = TILE as u32;
                    Rect::new(IVec2::new(t.0, t.1) * TILE, UVec2::splat(side))
                })
                .collect()
        }

        fn is_stand_in(&self, texel: UVec2) -> bool {
            let t = texel.as_ivec2() / TILE;
            self.stand_ins.contains(&(t.x, t.y))
        }
    }

    #[test]
    fn following_a_source_refills_its_stand_ins_once_their_tiles_load() {
        let mut w = CollisionWindow::new(64, UVec2::new(1000, 700), enc(), 1.0).expect("window");
        let mut source = Tiles {
            loaded: std::collections::HashSet::new(),
            stand_ins: std::collections::HashSet::new(),
        };
        let at = Vec2::new(100.0, 100.0);
        assert_eq!(w.follow(at, &mut source).expect("follow"), 64 * 64);
        // Nothing is loaded: every texel is a stand-in, no ground is answered.
        assert_eq!(
            w.ground(at, |t| source.is_stand_in(t)).expect("ground"),
            None
        );
        assert!(w.height(at).expect("height").is_some());
        // Every tile arrives: the next follow, without a move, fills them all again.
        let rect = w.window().expect("filled");
        for ty in rect.min.y / TILE..=(rect.max().y - 1) / TILE {
            for tx in rect.min.x / TILE..=(rect.max().x - 1) / TILE {
                source.loaded.insert((tx, ty));
            }
        }
        assert_eq!(w.follow(at, &mut source).expect("follow"), 64 * 64);
        assert_window_true(&w);
        let ground = w
            .ground(at, |t| source.is_stand_in(t))
            .expect("ground")
            .expect("answered");
        assert_eq!(Some(ground), w.height(at).expect("height"));
        // Outside the window, and at positions no texel has, nothing is answered.
        for far in [Vec2::new(900.0, 600.0), Vec2::NAN, Vec2::splat(f32::MAX)] {
            assert_eq!(
                w.ground(far, |t| source.is_stand_in(t)).expect("ground"),
                None,
                "{far}"
            );
        }
    }

    #[test]
    fn no_ground_is_answered_where_the_lookup_reads_a_stand_in() {
        let mut w = CollisionWindow::new(64, UVec2::new(1000, 700), enc(), 1.0).expect("window");
        let mut source = Tiles {
            loaded: std::collections::HashSet::new(),
            stand_ins: std::collections::HashSet::new(),
        };
        // Every tile but the column x in 96..128 is loaded.
        for ty in 0..8 {
            for tx in (0..8).filter(|&tx| tx != 3) {
                source.loaded.insert((tx, ty));
            }
        }
        w.follow(Vec2::new(100.0, 100.0), &mut source)
            .expect("follow");
        let ground = |x: f32| w.ground(Vec2::new(x, 100.0), |t| source.is_stand_in(t));
        assert!(ground(94.5).expect("ground").is_some());
        // In the last texel of a real tile the lookup blends in the stand-in beside it.
        assert_eq!(ground(95.5).expect("ground"), None);
        assert_eq!(ground(96.5).expect("ground"), None);
    }

    /// A source whose fills fail (a tile that cannot be read) while `broken`.
    struct Flaky {
        tiles: Tiles,
        broken: bool,
    }

    impl WindowSource for Flaky {
        type Error = &'static str;

        fn fill(&mut self, rect: Rect, out: &mut Grid<u16>) -> Result<(), Self::Error> {
            if self.broken {
                return Err("unreadable");
            }
            let Ok(()) = self.tiles.fill(rect, out);
            Ok(())
        }

        fn improved(&mut self, window: Option<Rect>) -> Vec<Rect> {
            self.tiles.improved(window)
        }

        fn is_stand_in(&self, texel: UVec2) -> bool {
            self.tiles.is_stand_in(texel)
        }
    }

    #[test]
    fn a_failed_refill_stays_a_stand_in_until_the_next_follow_fills_it() {
        let mut w = CollisionWindow::new(64, UVec2::new(1000, 700), enc(), 1.0).expect("window");
        let mut source = Flaky {
            tiles: Tiles {
                loaded: std::collections::HashSet::new(),
                stand_ins: std::collections::HashSet::new(),
            },
            broken: false,
        };
        let at = Vec2::new(100.0, 100.0);
        w.follow(at, &mut source).expect("follow");
        let rect = w.window().expect("filled");
        for ty in rect.min.y / TILE..=(rect.max().y - 1) / TILE {
            for tx in rect.min.x / TILE..=(rect.max().x - 1) / TILE {
                source.tiles.loaded.insert((tx, ty));
            }
        }
        // The tiles arrived, but their refill fails: the source has forgotten them, the
        // window has not; they still answer no ground.
        source.broken = true;
        assert!(matches!(
            w.follow(at, &mut source),
            Err(WindowError::Fill("unreadable"))
        ));
        assert!(!source.is_stand_in(UVec2::new(100, 100)));
        assert_eq!(
            w.ground(at, |t| source.is_stand_in(t)).expect("ground"),
            None
        );
        // Readable again: the next follow fills them first.
        source.broken = false;
        assert_eq!(w.follow(at, &mut source).expect("follow"), 64 * 64);
        assert_window_true(&w);
        assert!(
            w.ground(at, |t| source.is_stand_in(t))
                .expect("ground")
                .is_some()
        );
    }

    #[test]
    fn moving_fills_only_the_strips_that_come_in_and_keeps_the_rest() {
        let mut w = CollisionWindow::new(64, UVec2::new(1000, 700), enc(), 0.5).expect("window");
        assert!(!w.contains(Vec2::new(100.0, 100.0)));
        let filled = w
            .recenter(Vec2::new(100.0, 100.0), fill_truth)
            .expect("fill");
        assert_eq!(filled, 64 * 64);
        assert_window_true(&w);
        // A small move stays on the same step grid: nothing to fill.
        assert_eq!(
            w.recenter(Vec2::new(101.0, 100.5), fill_truth)
                .expect("same"),
            0
        );
        // Diagonal move of one step: an L of two strips.
        let mut calls = Vec::new();
        let filled = w
            .recenter(Vec2::new(108.0, 108.0), |r, out| {
                calls.push(r);
                fill_truth(r, out)
            })
            .expect("move");
        assert_eq!(filled, 64 * 64 - 48 * 48);
        assert_eq!(calls.len(), 2, "{calls:?}");
        assert_window_true(&w);
        // A jump: the whole window; then to the far corner, clamped inside the world.
        w.recenter(Vec2::new(300.0, 20.0), fill_truth)
            .expect("jump");
        assert_window_true(&w);
        w.recenter(Vec2::new(1e30, 1e30), fill_truth).expect("far");
        assert_eq!(w.window().expect("w").max(), IVec2::new(1000, 700));
        assert_window_true(&w);
        // Far from the origin too, a query in world metres reads the world's texels.
        let h = w
            .height(Vec2::new(495.25, 345.0))
            .expect("h")
            .expect("inside");
        let want = 0.01 * (f32::from(truth(990, 690)) + f32::from(truth(991, 690))) / 2.0;
        assert!((h - want).abs() < 1e-3, "{h} vs {want}");
        w.recenter(Vec2::new(-1e30, 5.0), fill_truth).expect("far");
        assert_eq!(w.window().expect("w").min, IVec2::new(0, 0));
        assert_window_true(&w);
        // Queries in world metres read the world's heights.
        let h = w
            .height(Vec2::new(10.25, 10.0))
            .expect("h")
            .expect("inside");
        let want = 0.01 * (f32::from(truth(20, 20)) + f32::from(truth(21, 20))) / 2.0;
        assert!((h - want).abs() < 1e-3, "{h} vs {want}");
        assert_eq!(w.height(Vec2::new(40.0, 10.0)).expect("h"), None);
        assert!(w.height(Vec2::new(f32::NAN, 0.0)).expect("h").is_none());
        assert!(w.recenter(Vec2::new(f32::NAN, 0.0), fill_truth).is_err());
    }

    #[test]
    fn readbacks_and_refreshes_land_only_inside_the_window() {
        let mut w = CollisionWindow::new(64, UVec2::new(512, 512), enc(), 1.0).expect("window");
        w.recenter(Vec2::new(200.0, 200.0), fill_truth)
            .expect("fill");
        let win = w.window().expect("w");
        // Half inside: only that half changes.
        let rect = Rect::new(win.min - IVec2::new(4, 0), UVec2::new(8, 3));
        let heights = Grid::new(8, 3, 999u16).expect("grid");
        assert!(w.apply(rect, &heights).expect("apply"));
        let snap = w.snapshot();
        let at = |x: i32, y: i32| {
            snap.heights()
                .get(x.rem_euclid(64) as u32, y.rem_euclid(64) as u32)
                .expect("in")
        };
        assert_eq!(at(win.min.x, win.min.y), 999);
        assert_eq!(at(win.min.x + 3, win.min.y + 2), 999);
        assert_eq!(
            at(win.min.x + 4, win.min.y),
            truth(win.min.x + 4, win.min.y)
        );
        assert_eq!(
            at(win.max().x - 4, win.min.y),
            truth(win.max().x - 4, win.min.y)
        );
        // Off the window: nothing, no error; wrong sizes: an error, nothing changed.
        let v = w.mirror().version();
        assert!(
            !w.apply(Rect::new(IVec2::new(0, 0), UVec2::new(8, 3)), &heights)
                .expect("off")
        );
        assert!(
            w.apply(Rect::new(win.min, UVec2::new(2, 2)), &heights)
                .is_err()
        );
        assert_eq!(w.mirror().version(), v);
        // Refresh refills the overlap from the source.
        let n = w.refresh(rect, fill_truth).expect("refresh");
        assert_eq!(n, 4 * 3);
        assert_window_true(&w);
        // A failing fill is reported and the window keeps what it had.
        let r: Result<u64, WindowError<&str>> =
            w.recenter(Vec2::new(400.0, 400.0), |_, _| Err("disk gone"));
        assert!(matches!(r, Err(WindowError::Fill("disk gone"))));
        // (The jump shares nothing with the old window, so it holds nothing now.)
        assert_eq!(w.window(), None);
        assert!(!w.contains(Vec2::new(200.0, 200.0)));
        w.recenter(Vec2::new(400.0, 400.0), fill_truth)
            .expect("again");
        assert_window_true(&w);
    }

    #[test]
    fn absurd_sizes_are_refused_and_a_small_world_is_one_window() {
        for side in [0, 1, 31, MAX_WINDOW_SIDE + 1, u32::MAX] {
            assert!(
                CollisionWindow::new(side, UVec2::splat(1000), enc(), 1.0).is_err(),
                "{side}"
            );
        }
        assert!(CollisionWindow::new(64, UVec2::new(1, 100), enc(), 1.0).is_err());
        assert!(CollisionWindow::new(64, UVec2::splat(100), enc(), f32::NAN).is_err());
        let mut w = CollisionWindow::new(256, UVec2::new(100, 40), enc(), 1.0).expect("small");
        w.recenter(Vec2::new(50.0, 20.0), fill_truth).expect("fill");
        assert_eq!(w.window(), Some(Rect::from_size(UVec2::new(100, 40))));
        assert_window_true(&w);
        assert_eq!(
            w.recenter(Vec2::new(-1e9, 1e9), fill_truth).expect("same"),
            0
        );
    }

    /// A position is answered where both taps of its cell are in the window: the window's last
    /// column and row of texels start no cell of their own.
    #[test]
    fn the_last_texel_column_and_row_are_outside() {
        let mut w = CollisionWindow::new(64, UVec2::new(1000, 700), enc(), 0.5).expect("window");
        w.recenter(Vec2::new(100.0, 100.0), fill_truth)
            .expect("fill");
        let r = w.window().expect("filled");
        let at = |x: i32, y: i32| Vec2::new(x as f32 + 0.5, y as f32 + 0.5) * 0.5;
        let (last_x, last_y) = (r.max().x - 1, r.max().y - 1);
        assert!(w.contains(at(r.min.x, r.min.y)));
        assert!(w.contains(at(last_x - 1, last_y - 1)));
        assert!(!w.contains(at(last_x, r.min.y)));
        assert!(!w.contains(at(r.min.x, last_y)));
        assert!(!w.contains(at(r.min.x - 1, r.min.y)));
    }

    /// The cell the lookup reads, found the lookup's way: f32 division near the origin, f64
    /// beyond 2^24 texels. With a texel size that is not a power of two the two roundings
    /// pick different cells for some positions at a cell edge, and `contains` must follow
    /// the lookup's near the window's edges, near the origin and far from it.
    #[test]
    fn the_edge_cell_is_the_lookups_near_and_far() {
        let ts = 0.3f32;
        let world = UVec2::new(1 << 26, 64);
        let lookup_cell = |pos: f32| -> f64 {
            let t = pos / ts;
            if t.abs() < 16_777_216.0 {
                f64::from(t.floor())
            } else {
                (f64::from(pos) / f64::from(ts)).floor()
            }
        };
        // Window placements near the origin and at the far end of the world (where f32
        // positions are 2 m apart, so several placements are needed to put one near an edge).
        let near: Vec<u32> = (0..8).map(|j| 200 + 16 * j).collect();
        let far: Vec<u32> = (0..8).map(|j| world.x - 200 - 16 * j).collect();
        for (name, centres) in [("near", near), ("far", far)] {
            let mut answers_differ = 0;
            for centre_texel in centres {
                let mut w = CollisionWindow::new(32, world, enc(), ts).expect("window");
                let centre = Vec2::new(centre_texel as f32 * ts, 16.0 * ts);
                w.recenter(centre, |_, _| Ok::<(), std::convert::Infallible>(()))
                    .expect("fill");
                let r = w.window().expect("filled");
                let inside =
                    |cell: f64| cell >= f64::from(r.min.x) && cell < f64::from(r.max().x - 1);
                let mut checked = 0;
                for edge in [r.min.x, r.max().x - 1] {
                    // Every f32 position within eight texels of the edge.
                    let mut pos = (edge - 8) as f32 * ts;
                    while pos <= (edge + 8) as f32 * ts {
                        let cell = lookup_cell(pos);
                        let other = if (pos / ts).abs() < 16_777_216.0 {
                            (f64::from(pos) / f64::from(ts)).floor()
                        } else {
                            f64::from((pos / ts).floor())
                        };
                        answers_differ += usize::from(inside(cell) != inside(other));
                        let p = Vec2::new(pos, 16.0 * ts + 0.1);
                        assert_eq!(
                            w.contains(p),
                            inside(cell),
                            "x = {pos} (cell {cell}) of {r:?}"
                        );
                        checked += 1;
                        pos = f32::from_bits(pos.to_bits() + 1);
                    }
                }
                assert!(checked > 2, "{checked}");
            }
            assert!(
                answers_differ > 0,
                "no position {name} the origin where the other rounding changes the answer"
            );
        }
    }

    /// Beyond 2^24 texels from the origin the cell is found in f64: a window at the far end
    /// of a long world answers inside it and not outside.
    #[test]
    fn far_from_the_origin_the_cell_is_found_in_f64() {
        let world = UVec2::new(1 << 26, 64);
        let mut w = CollisionWindow::new(32, world, enc(), 0.5).expect("window");
        let far = Vec2::new((world.x - 100) as f32 * 0.5, 16.0);
        w.recenter(far, |_, _| Ok::<(), std::convert::Infallible>(()))
            .expect("fill");
        let r = w.window().expect("filled");
        assert!(r.min.x > 1 << 25, "{r:?}");
        let centre = (r.min.as_dvec2() + r.size.as_dvec2() * 0.5) * 0.5;
        assert!(w.contains(centre.as_vec2()));
        assert!(!w.contains((centre + glam::DVec2::new(64.0, 0.0)).as_vec2()));
    }
}
