//! Granular trails on a streamed world: a [`GranularWindow`] takes the level-0 columns of a
//! square around moving objects from the resident tiles into a fixed-point scratch map, where
//! volume-preserving granular deformation (Persson 2019, ch. 4) steps them on the CPU or the
//! GPU, and hands every changed area back into the tiles (which become dirty and are written
//! back by the pool, and re-uploaded to VRAM by the VRAM pool).
//!
//! **The encoding rule that makes the volume exact.** The scratch map holds each column in the
//! world's own stored units (`u = h`, a hand-over of `k = 1`, see
//! [`terrain_core::granular::Handover`]). A granular step only moves whole units between
//! columns, so any rect of the scratch map can be handed back on its own, column by column,
//! with nothing to round: the tiles hold, at every moment, exactly the units taken (the sum
//! over the window is checked when it is released). A larger `k` would give the step finer
//! heights but would make the hand-back of one area round against the others (the
//! largest-remainder rule needs the whole window), so trails could not reach the tiles while
//! the window lives.
//!
//! **Protocol.** While a window is taken, its level-0 tiles are pinned in RAM (the hand-backs
//! need them resident) and nothing else may write into its rect: a tile stamp there would be
//! overwritten by the next hand-back. [`GranularWindow::rect`] says where it is so callers keep
//! other deformations out until [`GranularWindow::release`] (and out of
//! [`GranularWindow::retiring_rect`] while a window retires, below).
//!
//! **Moving on while the GPU's areas are on their way.** A window stepped on the GPU may move
//! on without waiting for its last steps' areas ([`GranularWindow::shift`]): the new window's
//! map is read from the tiles, and the GPU copies its own columns over the part the two
//! windows share (terrain-gpu's `GranularField::shift`). The old window then retires: its
//! tiles stay pinned, its late areas land only where it does not overlap the new window
//! (the shared part's tiles get the new window's areas, newer), and the volume stays exact
//! across the hand-over: with `V` the units the old window held less compression's, `S` the
//! GPU's sum of the new map right after the copy and `N` the units of the new window's strips
//! read from the tiles, `S - N` units crossed over, and once its last area has landed,
//! [`GranularWindow::retire`] checks that the old window's tiles outside the new one hold
//! `V - (S - N)`: no unit lost or counted twice.

use crate::error::CacheError;
use crate::manifest::Manifest;
use crate::pool::RamPool;
use crate::tile::TileId;
use glam::{Affine3A, IVec2, UVec2, Vec2, Vec3};
use terrain_core::granular::Handover;
use terrain_core::{FixedPointMap, Grid, HeightEncoding, HeightMap, Rect, WrapMode};

/// Largest side of a granular window in texels (4 x 4 tiles of 256 at most is plenty; it keeps
/// the pins and the scratch map bounded).
pub const MAX_WINDOW_SIDE: u32 = 1024;

/// A taken window: where, which tiles it pins, how many units it holds.
#[derive(Debug, Clone)]
struct Taken {
    rect: Rect,
    tiles: Vec<TileId>,
    volume: u64,
}

/// A window's pinned tiles and its columns in scratch units, as read from them.
type Pinned = (Vec<TileId>, Grid<u32>);

/// A window that moved on while its map's last areas were on their way: it keeps its tiles
/// pinned, and the parts outside the taken window take those areas, until it retires.
#[derive(Debug, Clone)]
struct Retiring {
    old: Taken,
    /// The old window less the new one (level-0 texels): where its areas still land.
    leaving: Vec<Rect>,
    /// Units of the new window outside the shared texels, read from the tiles.
    strips: u64,
    /// Units of the shared texels at the shift: the new window's sum less `strips`.
    shared_units: Option<u64>,
}

/// A square of a streamed world's level 0 handed to granular deformation (see the module
/// docs for the encoding rule and the protocol).
#[derive(Debug)]
pub struct GranularWindow {
    manifest: Manifest,
    side: u32,
    handover: Handover,
    scratch: HeightEncoding,
    taken: Option<Taken>,
    retiring: Option<Retiring>,
}

impl GranularWindow {
    /// Windows of `side` texels (at least 16, at most [`MAX_WINDOW_SIDE`] and the world) on
    /// the world of `manifest`.
    pub fn new(manifest: &Manifest, side: u32) -> Result<Self, CacheError> {
        let max = MAX_WINDOW_SIDE.min(manifest.world_size.min_element());
        if !(16..=max).contains(&side) {
            return Err(CacheError::OutOfRange {
                what: "granular window side",
                value: f64::from(side),
                expected: "16 texels up to 1024 and the world's shorter side",
            });
        }
        let handover = Handover::new(1)?;
        let scratch = handover.scratch_encoding(manifest.encoding)?;
        Ok(Self {
            manifest: *manifest,
            side,
            handover,
            scratch,
            taken: None,
            retiring: None,
        })
    }

    /// The window's side in texels.
    pub fn side(&self) -> u32 {
        self.side
    }

    /// The taken window's rect (level-0 texels), `None` when none is taken.
    pub fn rect(&self) -> Option<Rect> {
        self.taken.as_ref().map(|t| t.rect)
    }

    /// The stored units the taken window held when it was taken (0 when none is).
    pub fn volume_taken(&self) -> u64 {
        self.taken.as_ref().map_or(0, |t| t.volume)
    }

    /// The window of this side centred as near `center` (metres, X Z) as the world allows.
    pub fn placement(&self, center: Vec2) -> Rect {
        let size = self.manifest.world_size.as_ivec2();
        let texel = center / self.manifest.texel_size;
        let half = (self.side / 2) as i32;
        // Saturating float-to-int casts: any finite or infinite centre lands inside.
        let c = IVec2::new(texel.x as i32, texel.y as i32);
        let min = c
            .saturating_sub(IVec2::splat(half))
            .clamp(IVec2::ZERO, size - self.side as i32);
        Rect::new(min, UVec2::splat(self.side))
    }

    /// Whether the taken window holds the square of `margin_m` metres around each of `points`
    /// (metres, X Z) inside it: `false` when there is no window or one point is nearer its
    /// edge (the caller then releases it and takes one around the points). An edge on the
    /// world's edge needs no margin: no window reaches further (else objects beside the
    /// world's edge would move the window every frame).
    pub fn covers(&self, points: &[Vec2], margin_m: f32) -> bool {
        let Some(t) = &self.taken else {
            return false;
        };
        let ts = self.manifest.texel_size;
        let world = self.manifest.world_size.as_ivec2();
        let (min, max) = (t.rect.min, t.rect.max());
        let at_min = min.cmple(IVec2::ZERO);
        let lo = Vec2::select(at_min, Vec2::NEG_INFINITY, min.as_vec2() * ts + margin_m);
        let hi = Vec2::select(
            max.cmpge(world),
            Vec2::INFINITY,
            max.as_vec2() * ts - margin_m,
        );
        points
            .iter()
            .all(|p| p.cmpge(lo).all() && p.cmple(hi).all())
    }

    /// Takes the window `rect` (from [`placement`](Self::placement)) from the pool: pins its
    /// level-0 tiles and returns the scratch map (the world's stored units, clamped edges,
    /// the world's texel size; its origin at `rect.min`). `None`, with nothing pinned, while
    /// one of those tiles is not in RAM yet (try again next frame).
    pub fn take(
        &mut self,
        pool: &mut RamPool,
        rect: Rect,
    ) -> Result<Option<FixedPointMap>, CacheError> {
        if self.taken.is_some() || self.retiring.is_some() {
            return Err(CacheError::OutOfRange {
                what: "granular windows taken at once",
                value: 2.0,
                expected: "one: release the window before taking another",
            });
        }
        let Some((tiles, fixed)) = self.pin_and_read(pool, rect)? else {
            return Ok(None);
        };
        let volume = fixed.as_slice().iter().map(|&u| u64::from(u)).sum();
        self.taken = Some(Taken {
            rect,
            tiles,
            volume,
        });
        self.scratch_map(fixed).map(Some)
    }

    /// Moves the taken window to `rect` while its map stays on the GPU (module docs, "Moving
    /// on"): pins `rect`'s tiles and returns its scratch map, read from the tiles (where it
    /// overlaps the old window the GPU copies its own columns over these), and its origin's
    /// offset from the old one's. The old window retires: its tiles stay pinned and the parts
    /// outside `rect` still take its areas ([`Self::hand_back_retired`]) until
    /// [`Self::retire`]. `None`, nothing changed, while a tile of `rect` is not in RAM.
    pub fn shift(
        &mut self,
        pool: &mut RamPool,
        rect: Rect,
    ) -> Result<Option<(FixedPointMap, IVec2)>, CacheError> {
        let (Some(old), None) = (&self.taken, &self.retiring) else {
            return Err(CacheError::OutOfRange {
                what: "granular windows retiring at once",
                value: 2.0,
                expected: "a taken window, none retiring: retire the last one first",
            });
        };
        let Some((tiles, fixed)) = self.pin_and_read(pool, rect)? else {
            return Ok(None);
        };
        let mut strips = 0u64;
        for part in rect.minus(&old.rect) {
            let local = Rect::new(part.min - rect.min, part.size);
            let units = fixed.copy_rect(local)?;
            strips += units.as_slice().iter().map(|&u| u64::from(u)).sum::<u64>();
        }
        let offset = rect.min - old.rect.min;
        let old = self.taken.replace(Taken {
            rect,
            tiles,
            volume: strips,
        });
        self.retiring = old.map(|old| Retiring {
            leaving: old.rect.minus(&rect),
            strips,
            shared_units: None,
            old,
        });
        self.scratch_map(fixed).map(|map| Some((map, offset)))
    }

    /// Undoes the last [`Self::shift`], before anything arrived for it (its stepper could not
    /// move): the new window's tiles unpinned, the old one taken again.
    pub fn undo_shift(&mut self, pool: &mut RamPool) {
        if let Some(r) = self.retiring.take_if(|r| r.shared_units.is_none())
            && let Some(new) = self.taken.replace(r.old)
        {
            for &id in &new.tiles {
                pool.unpin(id);
            }
        }
    }

    /// The moved window's sum right after [`Self::shift`] (the GPU's, the first measure after
    /// the shift): the window holds `sum` units from now on, and the retiring window's shared
    /// part the units beyond the strips read from the tiles. Refused when `sum` is less than
    /// those strips (the hand-over lost units).
    pub fn shifted_sum(&mut self, sum: u64) -> Result<(), CacheError> {
        let (Some(t), Some(r)) = (self.taken.as_mut(), self.retiring.as_mut()) else {
            return Err(CacheError::OutOfRange {
                what: "granular windows retiring",
                value: 0.0,
                expected: "one: a sum only follows a shift",
            });
        };
        let Some(shared) = sum.checked_sub(r.strips) else {
            return Err(CacheError::OutOfRange {
                what: "units in the moved granular window",
                value: sum as f64,
                expected: "at least those of the strips read from the tiles",
            });
        };
        t.volume = sum;
        r.shared_units = Some(shared);
        Ok(())
    }

    /// The retiring window (level-0 texels), whose tiles outside the taken window still take
    /// its areas: keep other writes out of it too.
    pub fn retiring_rect(&self) -> Option<Rect> {
        self.retiring.as_ref().map(|r| r.old.rect)
    }

    /// The units the retiring window held when taken (or moved onto).
    pub fn retiring_volume(&self) -> Option<u64> {
        self.retiring.as_ref().map(|r| r.old.volume)
    }

    /// Whether [`Self::shifted_sum`] is still awaited.
    pub fn awaits_sum(&self) -> bool {
        self.retiring
            .as_ref()
            .is_some_and(|r| r.shared_units.is_none())
    }

    /// Hands the retiring window's `area` (its own texels) with its `heights` back into the
    /// tiles, where it lies outside the taken window (the taken window's map holds the rest,
    /// newer); returns the parts written, in world texels with their stored heights.
    pub fn hand_back_retired(
        &self,
        pool: &mut RamPool,
        area: Rect,
        heights: &Grid<u32>,
    ) -> Result<Vec<(Rect, Grid<u16>)>, CacheError> {
        let Some(r) = &self.retiring else {
            return Err(CacheError::OutOfRange {
                what: "granular windows retiring",
                value: 0.0,
                expected: "one: shift the window before handing its old areas back",
            });
        };
        check_area(r.old.rect, area, heights)?;
        let world = Rect::new(r.old.rect.min + area.min, area.size);
        let mut out = Vec::new();
        for part in r.leaving.iter().filter_map(|l| l.intersect(&world)) {
            let local = Rect::new(part.min - world.min, part.size);
            let stored = self.handover.from_fixed(&heights.copy_rect(local)?)?;
            self.write(pool, part, &stored)?;
            out.push((part, stored));
        }
        Ok(out)
    }

    /// Releases the retiring window once every area of its map is back and the moved
    /// window's sum is known: unpins its tiles and checks the hand-over, exactly: the units
    /// its tiles now hold outside the taken window, and those the taken window received where
    /// they overlap, add up to the units it held less `removed` (by compression). Returns the
    /// units; [`CacheError::OutOfRange`] when they differ (the window retires anyway).
    pub fn retire(&mut self, pool: &mut RamPool, removed: u64) -> Result<u64, CacheError> {
        let Some(r) = self.retiring.take_if(|r| r.shared_units.is_some()) else {
            return Err(CacheError::OutOfRange {
                what: "granular windows ready to retire",
                value: 0.0,
                expected: "one, whose moved window's sum has arrived",
            });
        };
        let mut leaving = 0u64;
        let mut read = Ok(());
        for part in &r.leaving {
            let mut heights = Grid::new(part.size.x, part.size.y, 0u16)?;
            match pool.read_region(*part, &mut heights) {
                Ok(_) => {
                    leaving += heights
                        .as_slice()
                        .iter()
                        .map(|&h| u64::from(h))
                        .sum::<u64>()
                }
                Err(e) => read = Err(e),
            }
        }
        for &id in &r.old.tiles {
            pool.unpin(id);
        }
        read?;
        let now = leaving + r.shared_units.unwrap_or(0);
        if Some(now) != r.old.volume.checked_sub(removed) {
            return Err(CacheError::OutOfRange {
                what: "stored units handed over by the retired granular window",
                value: now as f64,
                expected: "the units it held less those removed: every unit in one window or its tiles",
            });
        }
        Ok(now)
    }

    /// Checks `rect` as a window, pins the tiles it touches and reads it from them, in
    /// scratch units (`None`, nothing pinned, while one is not resident).
    fn pin_and_read(&self, pool: &mut RamPool, rect: Rect) -> Result<Option<Pinned>, CacheError> {
        let world = Rect::from_size(self.manifest.world_size);
        if rect.size != UVec2::splat(self.side) || !world.contains_rect(&rect) {
            return Err(terrain_core::CoreError::RegionOutOfBounds {
                rect,
                map_size: self.manifest.world_size,
            }
            .into());
        }
        let tiles = self.tiles_of(rect);
        if tiles.iter().any(|&id| pool.tile(id).is_none()) {
            return Ok(None);
        }
        let mut heights = Grid::new(rect.size.x, rect.size.y, 0u16)?;
        if pool.read_region(rect, &mut heights)? != 0 {
            return Ok(None);
        }
        for &id in &tiles {
            pool.pin(id);
        }
        Ok(Some((tiles, self.handover.to_fixed(&heights))))
    }

    /// The scratch map over `fixed` (clamped edges, the world's texel size).
    fn scratch_map(&self, fixed: Grid<u32>) -> Result<FixedPointMap, CacheError> {
        Ok(HeightMap::new(
            fixed,
            self.scratch,
            self.manifest.texel_size,
            WrapMode::Clamp,
        )?)
    }

    /// `transform` of an object in world metres (X Z over the world, Y the world's heights) in
    /// the scratch map's frame: X Z from the window's corner, Y in the scratch encoding. The
    /// scratch map's unit is `1 / round(1 / scale)` metres, within 0.5 / round(1 / scale) of
    /// the world's: the object's height is placed exactly in units, its shape not rescaled.
    pub fn to_local(&self, transform: Affine3A) -> Affine3A {
        let Some(t) = &self.taken else {
            return transform;
        };
        let corner = t.rect.min.as_vec2() * self.manifest.texel_size;
        let enc = self.manifest.encoding;
        let mut local = transform;
        let p = Vec3::from(transform.translation);
        let units = (p.y - enc.offset) / enc.scale;
        local.translation =
            Vec3::new(p.x - corner.x, units * self.scratch.scale, p.z - corner.y).into();
        local
    }

    /// Hands the scratch map's `area` (window texels) with its `heights` back into the tiles
    /// and returns it in world texels with its stored heights (for collision and overviews).
    pub fn hand_back(
        &self,
        pool: &mut RamPool,
        area: Rect,
        heights: &Grid<u32>,
    ) -> Result<(Rect, Grid<u16>), CacheError> {
        let Some(t) = &self.taken else {
            return Err(CacheError::OutOfRange {
                what: "granular windows taken",
                value: 0.0,
                expected: "one: take a window before handing areas back",
            });
        };
        check_area(t.rect, area, heights)?;
        let stored = self.handover.from_fixed(heights)?;
        let world = Rect::new(t.rect.min + area.min, area.size);
        self.write(pool, world, &stored)?;
        Ok((world, stored))
    }

    /// Releases the window: unpins its tiles and checks that they hold exactly the units taken
    /// less `removed` (what compression removed while the window lived; 0 for the
    /// volume-preserving default): every area the steps changed handed back, nothing else
    /// written there. Returns the units; [`CacheError::OutOfRange`] when they differ (the
    /// window is released anyway). With a window still retiring both are released, unchecked,
    /// and an error returned.
    pub fn release(&mut self, pool: &mut RamPool, removed: u64) -> Result<u64, CacheError> {
        if let Some(r) = self.retiring.take() {
            // Its check can no longer be made: its tiles are freed all the same.
            for &id in &r.old.tiles {
                pool.unpin(id);
            }
            let _ = self.release(pool, removed);
            return Err(CacheError::OutOfRange {
                what: "granular windows retiring at the release",
                value: 1.0,
                expected: "none: retire the last one first (both were released unchecked)",
            });
        }
        let Some(t) = self.taken.take() else {
            return Ok(0);
        };
        let mut heights = Grid::new(t.rect.size.x, t.rect.size.y, 0u16)?;
        let read = pool.read_region(t.rect, &mut heights);
        for &id in &t.tiles {
            pool.unpin(id);
        }
        read?;
        let now: u64 = heights.as_slice().iter().map(|&h| u64::from(h)).sum();
        if Some(now) != t.volume.checked_sub(removed) {
            return Err(CacheError::OutOfRange {
                what: "stored units in the released granular window",
                value: now as f64,
                expected: "the units taken less those removed: only handed-back areas may change the window",
            });
        }
        Ok(now)
    }

    /// The level-0 tiles `rect` touches.
    fn tiles_of(&self, rect: Rect) -> Vec<TileId> {
        let ts = self.manifest.tile_size;
        let lo = rect.min.as_uvec2() / ts;
        let hi = (rect.max().as_uvec2() - UVec2::ONE) / ts;
        let mut tiles = Vec::new();
        for ty in lo.y..=hi.y {
            for tx in lo.x..=hi.x {
                tiles.push(TileId::new(0, tx, ty));
            }
        }
        tiles
    }

    /// Writes `heights` at `world` (level-0 texels) into the pinned tiles it crosses.
    fn write(
        &self,
        pool: &mut RamPool,
        world: Rect,
        heights: &Grid<u16>,
    ) -> Result<(), CacheError> {
        let ts = self.manifest.tile_size as i32;
        for id in self.tiles_of(world) {
            let origin = IVec2::new(id.x as i32, id.y as i32) * ts;
            let tile = Rect::new(origin, UVec2::splat(ts as u32));
            let Some(part) = world.intersect(&tile) else {
                continue;
            };
            let piece = heights.copy_rect(Rect::new(part.min - world.min, part.size))?;
            pool.write_rect(id, Rect::new(part.min - origin, part.size), &piece)?;
        }
        Ok(())
    }
}

/// Checks that `area` (window texels) with `heights` lies in a window at `rect`.
fn check_area(rect: Rect, area: Rect, heights: &Grid<u32>) -> Result<(), CacheError> {
    let local = Rect::from_size(rect.size);
    if heights.size() != area.size || !local.contains_rect(&area) {
        return Err(terrain_core::CoreError::RegionOutOfBounds {
            rect: area,
            map_size: rect.size,
        }
        .into());
    }
    Ok(())
}
