//! The detail layer of Flower 2010 (sec. 2.3.1, eq. 2.1): a grid of 8-bit detail tiles laid over
//! the coarse-map at `refine` detail texels per coarse texel, each spanning 1 m of height
//! around the coarse surface, addressed through a tile-ID matrix in which a never-touched
//! tile is the shared zero tile.
//!
//! Stamps land on the layer as on one large map: [`DetailLayer::apply_stamp`] gathers the
//! footprint from every tile it touches (across tile edges and corners, and across the
//! coarse-map's wrap), stamps it in one window with [`apply_stamp_window`], and scatters it
//! back, so a stamp over a 4-tile corner gives the texels the same stamp gives on one large
//! tile (Flower 2010 leaves tile boundaries unhandled). Tiles are materialised on first write.
//!
//! A detail value is clamped to its tile's 1 m range, as Flower 2010's 8-bit detail-maps are,
//! by [`DetailLayer::apply_stamp`]; [`DetailLayer::apply_stamp_spilling`] moves what a stamp
//! pushes beyond the range into the coarse-map instead (the rule is in
//! [`crate::detail_spill`]), so a mark deeper than the tile's range is not clipped.
//!
//! The renderer reads the layer as [`DetailLayer::height_m`] (bilinear) and
//! [`DetailLayer::gradient_m`] (eq. 3.3 per texel, bilinear) define, across tile edges and the
//! wrap; [`DetailLayout::tiles_within`] is the band of tiles a camera reads. terrain-gpu's
//! `GpuDetailTiles` holds tiles in GPU slots, and its `DetailProbe` is tested against these.
//!
//! ```
//! use glam::{UVec2, Vec2};
//! use terrain_core::detail::{DetailLayer, DetailLayout};
//! use terrain_core::{Blend, GaussianStamp, StampPlacement};
//!
//! // Flower 2010's numbers: a 4096^2 coarse-map at 0.1 m, refined x3, 2048^2 detail tiles.
//! let layout = DetailLayout::new(UVec2::splat(4096), 0.1, 3, 2048).unwrap();
//! assert_eq!(layout.tiles(), UVec2::splat(6)); // eq. 2.1
//!
//! // A small layer: a footprint 5 cm deep pressed over the corner of four tiles.
//! let mut layer = DetailLayer::new(DetailLayout::new(UVec2::splat(64), 0.1, 3, 32).unwrap()).unwrap();
//! let p = StampPlacement::new(Vec2::splat(3.2), Vec2::splat(0.5), -0.05).unwrap();
//! let change = layer.apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add).unwrap();
//! assert_eq!(change.tiles.len(), 4);
//! assert!(layer.height_m(Vec2::splat(3.2)) < -0.04);
//! assert_eq!(layer.resident_tiles(), 4);
//! ```

use crate::detail_spill::{
    WIDE_SHIFT, check_spill_fits, spill_into_coarse, spill_rect, split_wide, wide_encoding,
};
use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::map::{HeightEncoding, HeightMap, HeightSample};
use crate::rect::{DirtyRect, Rect};
use crate::stamp::{Blend, Stamp, StampPlacement, apply_stamp_window};
use glam::{IVec2, UVec2, Vec2};

/// The stored value of 0 m in a detail tile: raw 128 of [`detail_encoding`].
pub const DETAIL_ZERO_RAW: u8 = 128;

/// The most detail texels per coarse texel a layout accepts (Flower 2010 uses 3).
pub const MAX_REFINE: u32 = 16;

/// The most tiles a layout accepts along each axis (the tile-ID matrix stays small).
pub const MAX_TILES_PER_SIDE: u32 = 4096;

/// The encoding of every detail tile: 1/255 m per unit, raw 128 at 0 m, so a tile spans
/// `[-128/255, 127/255]` m (1 m in all, Flower 2010, sec. 3.1.1's 4 mm steps) around the coarse
/// surface.
pub fn detail_encoding() -> HeightEncoding {
    HeightEncoding {
        scale: 1.0 / 255.0,
        offset: -f32::from(DETAIL_ZERO_RAW) / 255.0,
    }
}

/// Where the detail tiles lie over a coarse-map (Flower 2010, eq. 2.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetailLayout {
    coarse_size: UVec2,
    coarse_texel_m: f32,
    refine: u32,
    tile_size: u32,
}

impl DetailLayout {
    /// A layout over a coarse-map of `coarse_size` texels `coarse_texel_m` apart, refined by
    /// `refine` (the thesis's `1 / gamma`: detail texels per coarse texel along each axis),
    /// with square tiles of `tile_size` detail texels.
    ///
    /// Fails on an empty map, a texel size that is not positive and finite, `refine` outside
    /// `1 ..= MAX_REFINE`, a tile size of 0 or above 16 384, or more than
    /// [`MAX_TILES_PER_SIDE`] tiles along an axis.
    pub fn new(
        coarse_size: UVec2,
        coarse_texel_m: f32,
        refine: u32,
        tile_size: u32,
    ) -> Result<Self, CoreError> {
        if coarse_size.min_element() == 0 {
            return Err(CoreError::EmptyGrid {
                width: coarse_size.x,
                height: coarse_size.y,
            });
        }
        crate::map::check_texel_size(coarse_texel_m)?;
        if !(1..=MAX_REFINE).contains(&refine) {
            return Err(CoreError::OutOfRange {
                what: "detail refinement (detail texels per coarse texel)",
                value: f64::from(refine),
                expected: "1 to 16",
            });
        }
        if !(1..=16_384).contains(&tile_size) {
            return Err(CoreError::OutOfRange {
                what: "detail tile size (texels)",
                value: f64::from(tile_size),
                expected: "1 to 16 384",
            });
        }
        let layout = Self {
            coarse_size,
            coarse_texel_m,
            refine,
            tile_size,
        };
        let tiles = layout.tiles_u64();
        if tiles.0.max(tiles.1) > u64::from(MAX_TILES_PER_SIDE) {
            return Err(CoreError::OutOfRange {
                what: "detail tiles per side",
                value: tiles.0.max(tiles.1) as f64,
                expected: "at most 4096 (a larger tile size or a smaller refinement)",
            });
        }
        Ok(layout)
    }

    fn tiles_u64(&self) -> (u64, u64) {
        let d = self.detail_size_u64();
        let t = u64::from(self.tile_size);
        (d.0.div_ceil(t), d.1.div_ceil(t))
    }

    fn detail_size_u64(&self) -> (u64, u64) {
        let r = u64::from(self.refine);
        (
            u64::from(self.coarse_size.x) * r,
            u64::from(self.coarse_size.y) * r,
        )
    }

    /// The coarse-map's size in texels.
    pub fn coarse_size(&self) -> UVec2 {
        self.coarse_size
    }

    /// Tiles along each axis, eq. 2.1: `n = N_C / (gamma N_D)`, rounded up (the last tile
    /// of a row may reach past the map; its extra texels are never addressed).
    pub fn tiles(&self) -> UVec2 {
        let (x, y) = self.tiles_u64();
        UVec2::new(x as u32, y as u32)
    }

    /// Detail texels over the whole coarse-map (`refine` times its size). The layer repeats
    /// with this period, as the coarse-map does.
    pub fn detail_size(&self) -> UVec2 {
        let (x, y) = self.detail_size_u64();
        UVec2::new(
            x.min(u64::from(u32::MAX)) as u32,
            y.min(u64::from(u32::MAX)) as u32,
        )
    }

    /// Metres between detail texels: `gamma delta_C`.
    pub fn detail_texel_m(&self) -> f32 {
        self.coarse_texel_m / self.refine as f32
    }

    /// The coarse texel spacing.
    pub fn coarse_texel_m(&self) -> f32 {
        self.coarse_texel_m
    }

    /// Detail texels per coarse texel.
    pub fn refine(&self) -> u32 {
        self.refine
    }

    /// Detail texels along a tile's side.
    pub fn tile_size(&self) -> u32 {
        self.tile_size
    }

    /// The detail texels of `tile` that lie on the map, in detail texel coordinates.
    pub fn tile_rect(&self, tile: UVec2) -> Option<Rect> {
        if tile.cmpge(self.tiles()).any() {
            return None;
        }
        let min = tile * self.tile_size;
        let max = (min + UVec2::splat(self.tile_size)).min(self.detail_size());
        Some(Rect::from_min_max(min.as_ivec2(), max.as_ivec2()))
    }

    /// The coarse texels `tile` lies over (eq. 2.1's mapping): every coarse texel one of its
    /// detail texels falls in.
    pub fn coarse_texels_of_tile(&self, tile: UVec2) -> Option<Rect> {
        let r = self.tile_rect(tile)?;
        let k = self.refine as i32;
        let min = r.min / k;
        let max = (r.max() + (k - 1)) / k;
        Some(Rect::from_min_max(min, max))
    }

    /// The tile holding detail texel `p` (any integer coordinates: wrapped onto the map) and
    /// the texel's coordinates inside it.
    pub fn locate(&self, p: IVec2) -> (UVec2, UVec2) {
        let d = self.detail_size();
        let q = UVec2::new(
            WrapMode::Repeat.resolve(i64::from(p.x), d.x),
            WrapMode::Repeat.resolve(i64::from(p.y), d.y),
        );
        (q / self.tile_size, q % self.tile_size)
    }

    /// Whether the detail texels `lo ..= hi` (unwrapped) may touch a tile `has_tile` accepts.
    /// On a layer of whole tiles, a box narrower than a tile touches only its corners' tiles,
    /// so the answer is exact there; otherwise it is `true` (nothing is skipped). The detail
    /// shaders make the same test to skip the zero tiles (`detail_box_is_zero`).
    pub fn box_may_touch(&self, lo: IVec2, hi: IVec2, has_tile: impl Fn(UVec2) -> bool) -> bool {
        let d = self.detail_size();
        let side = i64::from(self.tile_size);
        let even = d.x.is_multiple_of(self.tile_size) && d.y.is_multiple_of(self.tile_size);
        let (w, h) = (
            i64::from(hi.x) - i64::from(lo.x),
            i64::from(hi.y) - i64::from(lo.y),
        );
        if !even || w >= side || h >= side {
            return true;
        }
        [lo, hi, IVec2::new(lo.x, hi.y), IVec2::new(hi.x, lo.y)]
            .into_iter()
            .any(|p| has_tile(self.locate(p).0))
    }

    /// A stamp footprint (detail texels, unwrapped) cut into one piece per tile it covers and
    /// per side of the map's wrap, in row-major tile order within each wrapped part. This is
    /// how a stamp reaches every tile it touches, on the CPU and on the GPU alike.
    ///
    /// Fails on a footprint larger than the layer (it would overlap itself) or above 16 M
    /// texels (a detail stamp is a fine mark; large deformations belong to the coarse-map).
    pub fn footprint_pieces(&self, footprint: Rect) -> Result<Vec<DetailPiece>, CoreError> {
        let d = self.detail_size();
        if footprint.size.cmpgt(d).any() || footprint.area() > MAX_STAMP_TEXELS {
            return Err(CoreError::OutOfRange {
                what: "detail stamp footprint (texels)",
                value: footprint.area() as f64,
                expected: "within the layer and at most 16 M texels (4096^2)",
            });
        }
        let t = self.tile_size as i32;
        // At most 2 tiles more than the footprint spans per axis (the wrap splits it once):
        // a bound on the pieces before any is made.
        let span = |n: u32| u64::from(n).div_ceil(u64::from(self.tile_size)) + 2;
        let most = span(footprint.size.x) * span(footprint.size.y);
        if most > MAX_FOOTPRINT_PIECES {
            return Err(CoreError::OutOfRange {
                what: "detail stamp footprint (tiles it may cover)",
                value: most as f64,
                expected: "at most 65 536 tile pieces (use larger tiles for larger marks)",
            });
        }
        let mut pieces = Vec::new();
        for wrapped in footprint.split_toroidal(d) {
            let m = wrapped.map;
            let to_unwrapped = wrapped.unwrapped.min - m.min;
            let (first, last) = (m.min / t, (m.max() - 1) / t);
            for ty in first.y..=last.y {
                for tx in first.x..=last.x {
                    let tile = UVec2::new(tx as u32, ty as u32);
                    let Some(inside) = self.tile_rect(tile).and_then(|r| r.intersect(&m)) else {
                        continue;
                    };
                    let origin = tile.as_ivec2() * t;
                    pieces.push(DetailPiece {
                        tile,
                        local: Rect::new(inside.min - origin, inside.size),
                        unwrapped: inside.min + to_unwrapped,
                    });
                }
            }
        }
        Ok(pieces)
    }
}

impl DetailLayout {
    /// The tiles within `radius_m` of `center_m` (metres on the coarse-map's plane) along each
    /// axis, across the layer's wrap, each once, in row-major order: the band of tiles a
    /// renderer near `center_m` reads (every tile when the square covers the layer).
    ///
    /// Fails on a centre or radius that is not finite, or a negative radius.
    pub fn tiles_within(&self, center_m: Vec2, radius_m: f32) -> Result<Vec<UVec2>, CoreError> {
        if !(center_m.is_finite() && radius_m.is_finite() && radius_m >= 0.0) {
            return Err(CoreError::OutOfRange {
                what: "detail tile band (centre, radius in metres)",
                value: f64::from(radius_m),
                expected: "a finite centre and a finite radius of at least 0",
            });
        }
        let ts = f64::from(self.detail_texel_m());
        let side = u64::from(self.tile_size);
        // One axis at a time: the detail texels of the band, wrapped onto the layer's period
        // (at most two ranges), and the tiles holding them, each once.
        let axis = |c: f32, period: u32| -> Vec<u32> {
            let period = u64::from(period);
            let lo = ((f64::from(c) - f64::from(radius_m)) / ts).floor();
            let hi = ((f64::from(c) + f64::from(radius_m)) / ts).floor();
            let all = || (0..period.div_ceil(side) as u32).collect();
            if hi - lo + 1.0 >= period as f64 {
                return all();
            }
            let len = (hi - lo) as u64 + 1;
            let a = lo.rem_euclid(period as f64) as u64;
            let mut ranges = vec![(a, (a + len).min(period))];
            if a + len > period {
                ranges.push((0, a + len - period));
            }
            let mut out: Vec<u32> = ranges
                .iter()
                .flat_map(|&(s, e)| (s / side) as u32..=((e - 1) / side) as u32)
                .collect();
            out.sort_unstable();
            out.dedup();
            out
        };
        let d = self.detail_size();
        let xs = axis(center_m.x, d.x);
        let ys = axis(center_m.y, d.y);
        Ok(ys
            .iter()
            .flat_map(|&y| xs.iter().map(move |&x| UVec2::new(x, y)))
            .collect())
    }

    /// The tiles a stamp at `placement` covers (its footprint's pieces), in row-major order:
    /// those that must be resident to stamp it. Fails as [`StampPlacement::footprint`] and
    /// [`DetailLayout::footprint_pieces`] do.
    pub fn tiles_under(&self, placement: &StampPlacement) -> Result<Vec<UVec2>, CoreError> {
        let footprint = placement.footprint(self.detail_texel_m())?;
        if footprint.is_empty() {
            return Ok(Vec::new());
        }
        let pieces = self.footprint_pieces(footprint)?;
        Ok(tiles_of_pieces(&pieces)
            .into_iter()
            .map(|(t, _)| t)
            .collect())
    }
}

/// The part of a stamp footprint inside one detail tile ([`DetailLayout::footprint_pieces`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DetailPiece {
    /// The tile.
    pub tile: UVec2,
    /// The texels it covers, in the tile's coordinates.
    pub local: Rect,
    /// Layer coordinates of `local.min` in the footprint's own, unwrapped frame (where the
    /// stamp's local coordinates are computed, so every piece gets the same arithmetic).
    pub unwrapped: IVec2,
}

/// The tiles `pieces` cover, each with the bounding rect of its pieces (tile coordinates), in
/// row-major tile order: what a stamp reports as its dirty tiles.
pub fn tiles_of_pieces(pieces: &[DetailPiece]) -> Vec<(UVec2, Rect)> {
    // Sorted by tile, then each run of one tile merged: n log n for any number of pieces.
    let mut sorted: Vec<(UVec2, Rect)> = pieces.iter().map(|p| (p.tile, p.local)).collect();
    sorted.sort_by_key(|t| (t.0.y, t.0.x));
    let mut tiles: Vec<(UVec2, Rect)> = Vec::with_capacity(sorted.len());
    for (tile, rect) in sorted {
        match tiles.last_mut() {
            Some(last) if last.0 == tile => last.1 = last.1.union(&rect),
            _ => tiles.push((tile, rect)),
        }
    }
    tiles
}

/// What one stamp changed on the layer.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DetailChange {
    /// The tiles the footprint covers, each with the rect of its texels it covers (tile
    /// coordinates), in row-major tile order; a shared zero tile the stamp left unchanged is
    /// listed but stays shared. These are the cache's dirty tiles.
    pub tiles: Vec<(UVec2, Rect)>,
    /// Texels whose value actually changed.
    pub changed_texels: u64,
}

/// The detail tiles over one coarse-map: the tile-ID matrix and the tiles in use.
#[derive(Debug, Clone, PartialEq)]
pub struct DetailLayer {
    layout: DetailLayout,
    /// Tile-ID matrix (Flower 2010, sec. 2.3.1): 0 is the shared zero tile, `k > 0` is
    /// `tiles[k - 1]`.
    ids: Grid<u32>,
    tiles: Vec<Grid<u8>>,
}

impl DetailLayer {
    /// A layer whose every tile is the shared zero tile (0 m of detail everywhere). Fails only
    /// where the tile-ID matrix cannot be allocated.
    pub fn new(layout: DetailLayout) -> Result<Self, CoreError> {
        let n = layout.tiles();
        Ok(Self {
            layout,
            ids: Grid::new(n.x, n.y, 0u32)?,
            tiles: Vec::new(),
        })
    }

    /// The layout.
    pub fn layout(&self) -> &DetailLayout {
        &self.layout
    }

    /// The tile-ID matrix: 0 for the shared zero tile, `k > 0` for the `k`-th materialised
    /// tile.
    pub fn tile_ids(&self) -> &Grid<u32> {
        &self.ids
    }

    /// Tiles that hold their own texels (not the shared zero tile).
    pub fn resident_tiles(&self) -> usize {
        self.tiles.len()
    }

    /// A tile's texels (`tile_size` a side), or `None` for the shared zero tile or a tile
    /// off the grid.
    pub fn tile(&self, tile: UVec2) -> Option<&Grid<u8>> {
        let id = self.ids.get(tile.x, tile.y)?;
        (id > 0).then(|| &self.tiles[id as usize - 1])
    }

    /// A tile as a detail height map (clamped, [`detail_encoding`], the layout's detail
    /// texel size): the zero tile materialised for a never-touched one. `None` off the grid.
    pub fn tile_map(&self, tile: UVec2) -> Option<HeightMap<u8>> {
        self.layout.tile_rect(tile)?;
        let t = self.layout.tile_size;
        let grid = match self.tile(tile) {
            Some(g) => g.clone(),
            None => Grid::new(t, t, DETAIL_ZERO_RAW).ok()?,
        };
        HeightMap::detail(grid, detail_encoding(), self.layout.detail_texel_m()).ok()
    }

    /// Replaces a tile's texels (a tile loaded from the cache). Fails on a tile off the grid
    /// or texels of the wrong size.
    pub fn set_tile(&mut self, tile: UVec2, texels: Grid<u8>) -> Result<(), CoreError> {
        let t = self.layout.tile_size;
        if texels.size() != UVec2::splat(t) {
            return Err(CoreError::SizeMismatch {
                expected: UVec2::splat(t),
                actual: texels.size(),
            });
        }
        let slot = self.slot(tile)?;
        *slot = texels;
        Ok(())
    }

    /// Returns a tile to the shared zero tile (an unloaded or reset tile), freeing its texels.
    pub fn clear_tile(&mut self, tile: UVec2) {
        let Some(id) = self.ids.get(tile.x, tile.y).filter(|&id| id > 0) else {
            return;
        };
        let last = self.tiles.len() as u32;
        self.tiles.swap_remove(id as usize - 1);
        // The tile that moved into the freed slot keeps its new index.
        if id != last
            && let Some(moved) = self.ids.as_mut_slice().iter_mut().find(|v| **v == last)
        {
            *moved = id;
        }
        if let Some(v) = self.ids.get_mut(tile.x, tile.y) {
            *v = 0;
        }
    }

    /// The detail texel at detail coordinates `p` (wrapped onto the map), raw.
    pub fn raw(&self, p: IVec2) -> u8 {
        let (tile, local) = self.layout.locate(p);
        match self.tile(tile) {
            Some(g) => g.get(local.x, local.y).unwrap_or(DETAIL_ZERO_RAW),
            None => DETAIL_ZERO_RAW,
        }
    }

    /// The detail height in metres at `pos` (metres on the coarse-map's plane): bilinear
    /// between the four nearest detail texels, across tile edges and the map's wrap.
    pub fn height_m(&self, pos: Vec2) -> f32 {
        let enc = detail_encoding();
        self.bilinear(pos, 0.0, |q| enc.to_metres(f64::from(self.raw(q))))
    }

    /// The detail gradient in metres per metre at `pos` (metres on the coarse-map's plane):
    /// eq. 3.3 (five-point differences, as the coarse-map's derivative normals) at the four
    /// nearest detail texels, bilinear between them, across tile edges and the map's wrap.
    /// What the renderer adds to the coarse gradient for the composite normal of eq. 3.4
    /// ([`crate::composite_normal`]).
    pub fn gradient_m(&self, pos: Vec2) -> Vec2 {
        let ts = self.layout.detail_texel_m();
        let k = f64::from(detail_encoding().scale) / (12.0 * f64::from(ts));
        let raw = |q: IVec2| f64::from(self.raw(q));
        self.bilinear(pos, Vec2::ZERO, |q| {
            let (x, z) = (IVec2::X, IVec2::Y);
            let dx = (raw(q - 2 * x) - raw(q + 2 * x)) + 8.0 * (raw(q + x) - raw(q - x));
            let dz = (raw(q - 2 * z) - raw(q + 2 * z)) + 8.0 * (raw(q + z) - raw(q - z));
            Vec2::new((dx * k) as f32, (dz * k) as f32)
        })
    }

    /// `at` (a value per detail texel, given wrapped coordinates) bilinear between the four
    /// detail texels around `pos` (metres); `none` for a position that is not finite.
    fn bilinear<T>(&self, pos: Vec2, none: T, at: impl Fn(IVec2) -> T) -> T
    where
        T: Copy
            + std::ops::Add<Output = T>
            + std::ops::Sub<Output = T>
            + std::ops::Mul<f32, Output = T>,
    {
        let p = pos / self.layout.detail_texel_m();
        if !p.is_finite() {
            return none;
        }
        let f = p.floor();
        let (fx, fz) = (p.x - f.x, p.y - f.y);
        let wrap = |v: f32, n: u32| (f64::from(v).rem_euclid(f64::from(n))) as i64 as i32;
        let d = self.layout.detail_size();
        let base = IVec2::new(wrap(f.x, d.x), wrap(f.y, d.y));
        let v = |dx: i32, dz: i32| at(base + IVec2::new(dx, dz));
        let top = v(0, 0) + (v(1, 0) - v(0, 0)) * fx;
        let bot = v(0, 1) + (v(1, 1) - v(0, 1)) * fx;
        top + (bot - top) * fz
    }

    /// The tile's texels, materialised from the zero tile on first use.
    fn slot(&mut self, tile: UVec2) -> Result<&mut Grid<u8>, CoreError> {
        let id = self
            .ids
            .get(tile.x, tile.y)
            .ok_or(CoreError::RegionOutOfBounds {
                rect: Rect::new(tile.as_ivec2(), UVec2::ONE),
                map_size: self.layout.tiles(),
            })?;
        let id = if id == 0 {
            let t = self.layout.tile_size;
            self.tiles.push(Grid::new(t, t, DETAIL_ZERO_RAW)?);
            let id = self.tiles.len() as u32;
            if let Some(v) = self.ids.get_mut(tile.x, tile.y) {
                *v = id;
            }
            id
        } else {
            id
        };
        Ok(&mut self.tiles[id as usize - 1])
    }

    /// Applies a stamp to the detail layer at `placement` (metres on the coarse-map's plane,
    /// as for the coarse-map), across every tile it touches and the map's wrap, exactly as
    /// the same stamp on one detail map as large as its footprint. Tiles it writes are
    /// materialised; a tile the stamp leaves unchanged stays the shared zero tile.
    ///
    /// Fails on an invalid placement or blend, on a footprint larger than the layer (it would
    /// overlap itself), or on one above 16 M texels (a detail stamp is a fine mark; large
    /// deformations belong to the coarse-map). Nothing is written on failure.
    pub fn apply_stamp<S: Stamp + ?Sized>(
        &mut self,
        stamp: &mut S,
        placement: &StampPlacement,
        blend: Blend,
    ) -> Result<DetailChange, CoreError> {
        #[cfg(feature = "cpu-work")]
        crate::cpu_work::count(|w| w.detail_stamps += 1);
        let ts = self.layout.detail_texel_m();
        let footprint = placement.footprint(ts)?;
        if footprint.is_empty() {
            // A mark smaller than a texel, or one clamped away by an absurd centre.
            crate::stamp::check_blend(blend)?;
            return Ok(DetailChange::default());
        }
        let pieces = self.layout.footprint_pieces(footprint)?;
        let window = self.gather(footprint)?;
        let before = window.clone();
        let mut map = HeightMap::new(window, detail_encoding(), ts, WrapMode::Clamp)?;
        if apply_stamp_window(&mut map, footprint.min, stamp, placement, blend)?.is_none() {
            return Ok(DetailChange::default());
        }
        let changed = self.scatter(&pieces, footprint.min, &before, map.grid())?;
        Ok(DetailChange {
            tiles: tiles_of_pieces(&pieces),
            changed_texels: changed,
        })
    }

    /// The detail texels of `footprint` (unwrapped coordinates, wrapped onto the layer) as one
    /// window.
    fn gather(&self, footprint: Rect) -> Result<Grid<u8>, CoreError> {
        let size = footprint.size;
        let mut window = Grid::new(size.x, size.y, DETAIL_ZERO_RAW)?;
        for y in 0..size.y {
            let gy = footprint.min.y + y as i32;
            for (x, v) in window.row_mut(y).iter_mut().enumerate() {
                *v = self.raw(IVec2::new(footprint.min.x + x as i32, gy));
            }
        }
        Ok(window)
    }

    /// Writes the texels of `after` that differ from `before` (windows of the footprint whose
    /// texel `(0, 0)` is detail texel `origin`) into the tiles of `pieces`; returns how many.
    fn scatter(
        &mut self,
        pieces: &[DetailPiece],
        origin: IVec2,
        before: &Grid<u8>,
        after: &Grid<u8>,
    ) -> Result<u64, CoreError> {
        let mut changed = 0u64;
        for piece in pieces {
            let w = (piece.unwrapped - origin).as_uvec2();
            for y in 0..piece.local.size.y {
                for x in 0..piece.local.size.x {
                    let (nv, ov) = (after.get(w.x + x, w.y + y), before.get(w.x + x, w.y + y));
                    if nv == ov {
                        continue;
                    }
                    changed += 1;
                    let local = piece.local.min.as_uvec2() + UVec2::new(x, y);
                    let slot = self.slot(piece.tile)?;
                    if let (Some(v), Some(nv)) = (slot.get_mut(local.x, local.y), nv) {
                        *v = nv;
                    }
                }
            }
        }
        Ok(changed)
    }

    /// Applies a stamp as [`DetailLayer::apply_stamp`] does, but what it pushes beyond a
    /// tile's 1 m range spills into `coarse` (the coarse-map under this layer) instead of being
    /// clipped: the rule of [`crate::detail_spill`]. The stamp is evaluated on a window of
    /// ±128 m in the tiles' units, so the texels it keeps within the range are within one unit
    /// of [`DetailLayer::apply_stamp`]'s. Returns the detail change and the coarse rects the
    /// excess changed (empty when nothing left the range).
    ///
    /// Fails, changing nothing, where [`DetailLayer::apply_stamp`] fails, on a coarse-map of
    /// another size or texel size than the layout's, or on a mark whose spill would reach
    /// around a repeating coarse-map.
    pub fn apply_stamp_spilling<T: HeightSample, S: Stamp + ?Sized>(
        &mut self,
        coarse: &mut HeightMap<T>,
        stamp: &mut S,
        placement: &StampPlacement,
        blend: Blend,
    ) -> Result<(DetailChange, Vec<DirtyRect>), CoreError> {
        if coarse.size() != self.layout.coarse_size {
            return Err(CoreError::SizeMismatch {
                expected: self.layout.coarse_size,
                actual: coarse.size(),
            });
        }
        if coarse.texel_size() != self.layout.coarse_texel_m {
            return Err(CoreError::OutOfRange {
                what: "coarse-map texel size under a detail layer (metres)",
                value: f64::from(coarse.texel_size()),
                expected: "the detail layout's coarse texel size",
            });
        }
        let ts = self.layout.detail_texel_m();
        let footprint = placement.footprint(ts)?;
        if footprint.is_empty() {
            crate::stamp::check_blend(blend)?;
            return Ok((DetailChange::default(), Vec::new()));
        }
        let pieces = self.layout.footprint_pieces(footprint)?;
        let spill = spill_rect(footprint, self.layout.refine);
        check_spill_fits(spill, coarse.size(), coarse.wrap())?;
        let before = self.gather(footprint)?;
        let wide = before.map(|&v| (i32::from(v) + WIDE_SHIFT) as u16);
        let mut map = HeightMap::new(wide, wide_encoding(), ts, WrapMode::Clamp)?;
        if apply_stamp_window(&mut map, footprint.min, stamp, placement, blend)?.is_none() {
            return Ok((DetailChange::default(), Vec::new()));
        }
        let excess = map.grid().map(|&w| split_wide(w).0);
        let after = map.grid().map(|&w| split_wide(w).1);
        let changed = self.scatter(&pieces, footprint.min, &before, &after)?;
        let rects = spill_into_coarse(coarse, &excess, footprint.min, self.layout.refine)?;
        Ok((
            DetailChange {
                tiles: tiles_of_pieces(&pieces),
                changed_texels: changed,
            },
            rects,
        ))
    }
}

/// The largest footprint a detail stamp may cover.
const MAX_STAMP_TEXELS: u64 = 1 << 24;
/// The most tile pieces a detail stamp's footprint may be cut into (tiny tiles under a large
/// mark would otherwise make millions).
const MAX_FOOTPRINT_PIECES: u64 = 1 << 16;
