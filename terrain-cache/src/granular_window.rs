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
//! other deformations out until [`GranularWindow::release`].

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

/// A square of a streamed world's level 0 handed to granular deformation (see the module
/// docs for the encoding rule and the protocol).
#[derive(Debug)]
pub struct GranularWindow {
    manifest: Manifest,
    side: u32,
    handover: Handover,
    scratch: HeightEncoding,
    taken: Option<Taken>,
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
    /// edge (the caller then releases it and takes one around the points).
    pub fn covers(&self, points: &[Vec2], margin_m: f32) -> bool {
        let Some(t) = &self.taken else {
            return false;
        };
        let ts = self.manifest.texel_size;
        let lo = t.rect.min.as_vec2() * ts + margin_m;
        let hi = t.rect.max().as_vec2() * ts - margin_m;
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
        if self.taken.is_some() {
            return Err(CacheError::OutOfRange {
                what: "granular windows taken at once",
                value: 2.0,
                expected: "one: release the window before taking another",
            });
        }
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
        let fixed = self.handover.to_fixed(&heights);
        let volume = fixed.as_slice().iter().map(|&u| u64::from(u)).sum();
        self.taken = Some(Taken {
            rect,
            tiles,
            volume,
        });
        Ok(Some(HeightMap::new(
            fixed,
            self.scratch,
            self.manifest.texel_size,
            WrapMode::Clamp,
        )?))
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
        let local = Rect::from_size(t.rect.size);
        if heights.size() != area.size || !local.contains_rect(&area) {
            return Err(terrain_core::CoreError::RegionOutOfBounds {
                rect: area,
                map_size: t.rect.size,
            }
            .into());
        }
        let stored = self.handover.from_fixed(heights)?;
        let world = Rect::new(t.rect.min + area.min, area.size);
        self.write(pool, world, &stored)?;
        Ok((world, stored))
    }

    /// Releases the window: unpins its tiles and checks that they hold exactly the units taken
    /// less `removed` (what compression removed while the window lived; 0 for the
    /// volume-preserving default): every area the steps changed handed back, nothing else
    /// written there. Returns the units; [`CacheError::OutOfRange`] when they differ (the
    /// window is released anyway).
    pub fn release(&mut self, pool: &mut RamPool, removed: u64) -> Result<u64, CacheError> {
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
