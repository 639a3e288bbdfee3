//! [`WindowFill`]: a window that follows the camera over the world (a collision window, say)
//! filled from the RAM pool, and filled again where level 0 has loaded since: a texel whose
//! tile was not in RAM is filled from the finest coarser level loaded (Fikkan 2013, sec. 4.3:
//! coarser data stands in for a tile on its way), and must not stay that way once the tile
//! is in. Also the pool's queries a frame asks of what is loaded: the ground at a point
//! ([`RamPool::ground_m`]), the level-0 tiles missing around it ([`RamPool::missing_near`]),
//! and a changed rect reduced to a coarser level ([`RamPool::read_reduced`]).

use super::RamPool;
use crate::tile::TileId;
use crate::{CacheError, Manifest};
use glam::{IVec2, UVec2, Vec2};
use std::collections::HashSet;
use terrain_core::{Grid, Rect, WindowSource};

/// Fills a moving window from a [`RamPool`] and remembers which level-0 tiles it filled with
/// coarser stand-ins (see the module docs).
#[derive(Debug, Clone)]
pub struct WindowFill {
    tile_size: u32,
    stand_ins: HashSet<TileId>,
}

impl WindowFill {
    /// For a window over the world of `manifest`.
    pub fn new(manifest: &Manifest) -> Self {
        Self {
            tile_size: manifest.tile_size,
            stand_ins: HashSet::new(),
        }
    }

    /// Fills `out` with the level-0 heights of `rect` ([`RamPool::read_region`]) and
    /// remembers the tiles it touched that are not in RAM.
    pub fn fill(
        &mut self,
        pool: &RamPool,
        rect: Rect,
        out: &mut Grid<u16>,
    ) -> Result<(), CacheError> {
        pool.read_region(rect, out)?;
        if rect.is_empty() {
            return Ok(());
        }
        let ts = self.tile_size;
        let (lo, hi) = (rect.min.as_uvec2() / ts, (rect.max().as_uvec2() - 1) / ts);
        for ty in lo.y..=hi.y {
            for tx in lo.x..=hi.x {
                let id = TileId::new(0, tx, ty);
                if pool.tile(id).is_none() {
                    self.stand_ins.insert(id);
                }
            }
        }
        Ok(())
    }

    /// This fill over `pool` as terrain-core's [`WindowSource`], for a window that fills
    /// itself (terrain-physics' `CollisionWindow::follow`).
    pub fn over<'a>(&'a mut self, pool: &'a RamPool) -> PoolWindowSource<'a> {
        PoolWindowSource { fill: self, pool }
    }

    /// Level-0 tiles the window holds stand-ins for.
    pub fn stand_ins(&self) -> usize {
        self.stand_ins.len()
    }

    /// Whether the window holds stand-ins for the level-0 tile of `texel`.
    pub fn is_stand_in(&self, texel: UVec2) -> bool {
        let t = texel / self.tile_size;
        self.stand_ins.contains(&TileId::new(0, t.x, t.y))
    }

    /// The level-0 tiles (whole, world texels) to fill again now: those with stand-ins whose
    /// tile is in RAM, forgotten as returned (filling them through [`Self::fill`] lists them
    /// again if they left RAM meanwhile). Stand-ins outside `window` are forgotten.
    pub fn ready(&mut self, pool: &RamPool, window: Option<Rect>) -> Vec<Rect> {
        let ts = self.tile_size;
        let rect_of =
            |id: &TileId| Rect::new((UVec2::new(id.x, id.y) * ts).as_ivec2(), UVec2::splat(ts));
        self.stand_ins
            .retain(|id| window.is_some_and(|w| w.intersect(&rect_of(id)).is_some()));
        let mut ready: Vec<TileId> = self
            .stand_ins
            .iter()
            .copied()
            .filter(|&id| pool.tile(id).is_some())
            .collect();
        ready.sort_unstable_by_key(|id| (id.y, id.x));
        for id in &ready {
            self.stand_ins.remove(id);
        }
        ready.iter().map(rect_of).collect()
    }
}

/// A [`WindowFill`] over its [`RamPool`]: terrain-core's [`WindowSource`] contract
/// ([`WindowFill::over`]).
#[derive(Debug)]
pub struct PoolWindowSource<'a> {
    fill: &'a mut WindowFill,
    pool: &'a RamPool,
}

impl WindowSource for PoolWindowSource<'_> {
    type Error = CacheError;

    fn fill(&mut self, rect: Rect, out: &mut Grid<u16>) -> Result<(), CacheError> {
        self.fill.fill(self.pool, rect, out)
    }

    fn improved(&mut self, window: Option<Rect>) -> Vec<Rect> {
        self.fill.ready(self.pool, window)
    }

    fn is_stand_in(&self, texel: UVec2) -> bool {
        self.fill.is_stand_in(texel)
    }
}

impl RamPool {
    /// The ground at `xz` (metres, clamped to the world) in metres, bilinear over the finest
    /// tile in RAM under it; `None` when no level of it is loaded.
    pub fn ground_m(&self, xz: Vec2) -> Option<f32> {
        let m = *self.world.manifest();
        let extent = m.world_size.as_vec2() * m.texel_size;
        let texel = xz.clamp(Vec2::ZERO, extent) / m.texel_size;
        let ts = m.tile_size;
        let t = texel.as_uvec2().min(m.world_size - 1) / ts;
        let (found, data) = self.best_available(TileId::new(0, t.x, t.y))?;
        let grid = data.as_u16()?;
        let scale = (1u64 << found.level.min(63)) as f32;
        let local = texel / scale - UVec2::new(found.x, found.y).as_vec2() * ts as f32;
        Some(m.encoding.to_metres(bilinear_clamped(grid, local)))
    }

    /// The level-0 tiles within `reach_m` metres of `xz` (nearest point of the tile) that are
    /// not in RAM: what a frame needs now and draws or collides with from coarser data. At
    /// most the 3 x 3 tiles around `xz` are looked at (`reach_m` is capped at a tile's side).
    pub fn missing_near(&self, xz: Vec2, reach_m: f32) -> usize {
        let m = *self.world.manifest();
        let tile_m = m.tile_size as f32 * m.texel_size;
        let tiles =
            (m.world_size.saturating_add(UVec2::splat(m.tile_size - 1)) / m.tile_size).as_ivec2();
        if !xz.is_finite() {
            return 0;
        }
        // Clamped first: a point far off the world looks at no tile, without overflow.
        let bound = tiles.as_vec2() + 1.0;
        let here = (xz / tile_m)
            .floor()
            .clamp(Vec2::splat(-2.0), bound)
            .as_ivec2();
        let reach = reach_m.min(tile_m);
        let mut missing = 0;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let t = here + IVec2::new(dx, dy);
                if t.x < 0 || t.y < 0 || t.x >= tiles.x || t.y >= tiles.y {
                    continue;
                }
                let lo = t.as_vec2() * tile_m;
                let nearest = xz.clamp(lo, lo + tile_m);
                let id = TileId::new(0, t.x as u32, t.y as u32);
                if nearest.distance(xz) <= reach && self.tile(id).is_none() {
                    missing += 1;
                }
            }
        }
        missing
    }
}

impl RamPool {
    /// The level-`level` texels over the level-0 `rect` (world texels; grown to whole
    /// level-`level` texels, cut to those wholly inside the world) reduced from what is in RAM
    /// as the pyramid is built (`crate::reduce_levels`): where a world's changed rect reaches a
    /// coarser level (an overview, a minimap) without reading its files. Returns the rect at
    /// that level and its heights; `None` when no whole texel is left. A tile not in RAM gives
    /// its coarser stand-in ([`RamPool::read_region`]).
    pub fn read_reduced(
        &self,
        rect: Rect,
        level: u32,
    ) -> Result<Option<(Rect, Grid<u16>)>, CacheError> {
        let m = *self.world.manifest();
        if level >= m.levels {
            return Err(CacheError::OutOfRange {
                what: "level to reduce to",
                value: f64::from(level),
                expected: "below the world's levels",
            });
        }
        let step = 1i32 << level;
        let full = (m.world_size.as_ivec2() / step) * step;
        let lo = rect.min.div_euclid(IVec2::splat(step)) * step;
        let hi = rect.max().saturating_add(IVec2::splat(step - 1));
        let hi = (hi.div_euclid(IVec2::splat(step)) * step).min(full);
        let lo = lo.max(IVec2::ZERO);
        if hi.cmple(lo).any() {
            return Ok(None);
        }
        let block = Rect::from_min_max(lo, hi);
        let mut level0 = Grid::new(block.size.x, block.size.y, 0u16)?;
        self.read_region(block, &mut level0)?;
        let reduced = crate::reduce_levels(&level0, level)?;
        Ok(Some((Rect::new(block.min / step, reduced.size()), reduced)))
    }
}

/// Bilinear sample of `grid` at `p` (texels), edges clamped.
fn bilinear_clamped(grid: &Grid<u16>, p: Vec2) -> f64 {
    let max = (grid.size() - 1).as_vec2();
    let p = p.clamp(Vec2::ZERO, max);
    let p0 = p.floor().as_uvec2();
    let p1 = (p0 + 1).min(grid.size() - 1);
    let f = p - p0.as_vec2();
    let at = |x: u32, y: u32| f64::from(grid.get(x, y).unwrap_or(0));
    let top = at(p0.x, p0.y) * f64::from(1.0 - f.x) + at(p1.x, p0.y) * f64::from(f.x);
    let bottom = at(p0.x, p1.y) * f64::from(1.0 - f.x) + at(p1.x, p1.y) * f64::from(f.x);
    top * f64::from(1.0 - f.y) + bottom * f64::from(f.y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_sampling_clamps_at_tile_edges() {
        let g = Grid::from_vec(2, 2, vec![0u16, 100, 200, 300]).unwrap();
        assert_eq!(bilinear_clamped(&g, Vec2::new(0.5, 0.5)), 150.0);
        assert_eq!(bilinear_clamped(&g, Vec2::new(-5.0, -5.0)), 0.0);
        assert_eq!(bilinear_clamped(&g, Vec2::new(9.0, 9.0)), 300.0);
    }
}
