//! `ParryTerrain` (feature `parry`): the mirror's snapshots as a grid of tiled
//! [`parry3d::shape::HeightField`]s, for a parry or rapier world, rebuilt tile by tile as
//! regions change.
//!
//! # Layout
//!
//! The map (`W x H` texels, `texel_size` metres apart) is cut into tiles of `tile_size x
//! tile_size` cells (the last tile on each axis may be narrower). Tile `(tx, tz)` covers cells
//! `tx * tile_size ..` along X and `tz * tile_size ..` along Z, and holds one more row and
//! column of vertices than cells: neighbouring tiles share their border vertices, so the tiles
//! meet without gaps. The last tile on each axis ends on the wrapped texel `0`, so the tiles
//! cover exactly one period of the toroidal map, `[0, W * texel_size) x [0, H * texel_size)`,
//! with the cell between texel `W - 1` and texel `0` included (as the crate's own surface has
//! it).
//!
//! Orientation: parry's heightfield is centred on its local origin, with the heights matrix's
//! rows along Z and its columns along X, and `scale = (cells_x * texel_size, 1, cells_z *
//! texel_size)` (heights are stored in metres). Each tile's [`Pose`] is a pure translation to
//! the tile's centre, so texel `(x, z)` stands at world `(x * texel_size, height, z *
//! texel_size)`, the workspace convention, and the tiles line up with
//! [`HeightfieldCollider`](crate::HeightfieldCollider) at the origin.
//!
//! The map repeats; [`ParryTerrain::shapes`] gives the one period of tiles (place copies
//! `k * extent` apart in your own world if bodies may leave it), while the adapter's own
//! queries ([`ParryTerrain::cast_ray`], [`ParryTerrain::contact`],
//! [`ParryTerrain::sphere_contact`]) wrap like every query of this crate.
//!
//! # Bilinear surface vs parry's triangles
//!
//! Parry splits each cell into two triangles; the crate's surface is the bilinear patch. At
//! every horizontal position they differ by at most `|h00 - h10 - h01 + h11| / 4` of the cell
//! ([`ParryTile::max_deviation`], [`ParryTerrain::max_deviation`]), and rays hit the two
//! within that bound (derived, with what it means for rays and contacts, in the repository's
//! `docs/derivations.md`, "Parry's triangles against the bilinear surface"). Parry's
//! triangles have no inside, so [`ParryTerrain::cast_ray`] only reports crossings of the
//! surface.
//!
//! # Updates
//!
//! A changed texel is a vertex of up to four cells, which may lie in up to four tiles (on a
//! tile border). [`ParryTerrain::update`] takes the new snapshot and the rects that changed
//! since the snapshot the terrain holds (the rects applied to the mirror, which
//! [`UpdateReport::applied_rects`](crate::UpdateReport::applied_rects) lists for the
//! scheduler's updates, or those a stamp reported), and rebuilds exactly the tiles holding a vertex inside them; the others keep
//! their shapes. A full rebuild of a 2048 x 2048 map costs what converting 4 M heights costs;
//! one 64-texel tile, a thousandth of it.
//!
//! ```
//! use glam::{IVec2, UVec2, Vec3};
//! use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect};
//! use terrain_physics::{CollisionMirror, ParryTerrain, read_region};
//!
//! // A flat 256 x 256 map at 0.5 m per texel, 10 m high, in 64-texel tiles.
//! let enc = HeightEncoding::spanning::<u16>(0.0, 50.0)?;
//! let mut map = CoarseMap::coarse(Grid::new(256, 256, enc.to_raw(10.0) as u16)?, enc, 0.5)?;
//! let mirror = CollisionMirror::from_map(&map)?;
//! let mut terrain = ParryTerrain::new(&mirror.snapshot(), 64)?;
//! assert_eq!(terrain.tile_count(), UVec2::new(4, 4));
//!
//! // A 4 x 4 texel change inside tile (1, 1) rebuilds that tile only.
//! let rect = Rect::new(IVec2::new(70, 70), UVec2::new(4, 4));
//! for y in 70..74 {
//!     for x in 70..74 {
//!         *map.grid_mut().get_mut(x, y).unwrap() = enc.to_raw(12.0) as u16;
//!     }
//! }
//! mirror.apply_next(rect, &read_region(&map, rect)?)?;
//! let rebuilt = terrain.update(&mirror.snapshot(), &[rect])?;
//! assert_eq!(rebuilt, vec![UVec2::new(1, 1)]);
//!
//! // Parry's answer, within the documented bound of the crate's own.
//! let hit = terrain.cast_ray(Vec3::new(35.75, 30.0, 35.75), Vec3::NEG_Y, 100.0)?.unwrap();
//! assert!((hit.point.y - 12.0).abs() <= terrain.max_deviation() + 1e-3);
//!
//! // The shapes, for a parry or rapier world of your own.
//! for (pose, shape) in terrain.shapes() {
//!     let _ = (pose.translation, shape.nrows());
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::contact::Contact;
use crate::error::{PhysicsError, check_finite, check_finite3, check_region};
use crate::field::HeightField;
use crate::ray::{Ray, RayHit, check_max_dist};
use glam::{DVec3, UVec2, Vec3};
use parry3d::bounding_volume::{Aabb, BoundingVolume};
use parry3d::math::{Pose, Vector as PVec3};
use parry3d::query::{self, Ray as PRay, RayCast};
use parry3d::shape::{Ball, HeightField as ParryHeightField, Shape};
use parry3d::utils::Array2;
use terrain_core::{HeightEncoding, Rect};

/// Largest tile side accepted, in cells.
pub const MAX_PARRY_TILE_SIZE: u32 = 4096;

/// Most tiles one terrain holds (a tiny tile size over a huge map is refused).
pub const MAX_PARRY_TILES: u64 = 1 << 22;

/// Most period copies of the map one [`ParryTerrain::contact`] query may overlap (a shape
/// much larger than the map is refused).
const MAX_CONTACT_COPIES: u64 = 16;

/// Slack on each side of a period copy's ray interval, in metres, so that a hit exactly on a
/// seam between copies is not lost to rounding in both.
const SEAM_SLACK: f64 = 1e-4;

/// One tile: a parry heightfield and where it stands.
#[derive(Debug, Clone)]
pub struct ParryTile {
    /// Tile coordinates.
    index: UVec2,
    /// The cells covered, in texels (map coordinates; the vertices run one further).
    cells: Rect,
    shape: ParryHeightField,
    pose: Pose,
    /// Largest `|d| / 4` over the tile's cells, in metres.
    max_deviation: f32,
    version: u64,
}

impl ParryTile {
    /// The tile's coordinates in the tile grid.
    pub fn index(&self) -> UVec2 {
        self.index
    }

    /// The cells the tile covers, in texels (map coordinates): cell `(x, z)` spans texels `x
    /// ..= x + 1` and `z ..= z + 1`, the last one wrapped onto texel 0.
    pub fn cells(&self) -> Rect {
        self.cells
    }

    /// The parry shape, centred on its local origin.
    pub fn shape(&self) -> &ParryHeightField {
        &self.shape
    }

    /// Where the shape stands in the world: a translation to the tile's centre (parry's
    /// types).
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// The tile's centre in world space, at height 0.
    pub fn translation(&self) -> Vec3 {
        let t = self.pose.translation;
        Vec3::new(t.x, t.y, t.z)
    }

    /// The bound of this tile: the largest height difference between parry's triangles and
    /// the bilinear surface over its cells, in metres (see the [module docs](self)).
    pub fn max_deviation(&self) -> f32 {
        self.max_deviation
    }

    /// The version of the snapshot the tile was last built from.
    pub fn version(&self) -> u64 {
        self.version
    }

    /// The tile's bounding box in world space.
    fn world_aabb(&self) -> Aabb {
        self.shape.root_aabb().transform_by(&self.pose)
    }
}

/// The map as a grid of parry heightfields, built from a [`HeightField`] snapshot and
/// updated tile by tile (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct ParryTerrain {
    size: UVec2,
    texel_size: f32,
    encoding: HeightEncoding,
    tile_size: u32,
    tiles_per_axis: UVec2,
    /// Row-major over the tile grid.
    tiles: Vec<ParryTile>,
    version: u64,
    /// The lowest and highest height of any tile, in metres.
    bounds: (f32, f32),
    max_deviation: f32,
}

impl ParryTerrain {
    /// Tiles of `tile_size x tile_size` cells over `snapshot`, all built now.
    ///
    /// Fails unless `1 <= tile_size <=` [`MAX_PARRY_TILE_SIZE`], or if that would make more
    /// than [`MAX_PARRY_TILES`] tiles. A tile size larger than the map gives one tile on that
    /// axis.
    pub fn new(snapshot: &HeightField, tile_size: u32) -> Result<Self, PhysicsError> {
        if !(1..=MAX_PARRY_TILE_SIZE).contains(&tile_size) {
            return Err(PhysicsError::OutOfRange {
                what: "parry tile size (cells)",
                value: f64::from(tile_size),
                expected: "1 to 4096 cells",
            });
        }
        let size = snapshot.size();
        let tiles_per_axis = UVec2::new(size.x.div_ceil(tile_size), size.y.div_ceil(tile_size));
        let count = u64::from(tiles_per_axis.x) * u64::from(tiles_per_axis.y);
        if count > MAX_PARRY_TILES {
            return Err(PhysicsError::OutOfRange {
                what: "parry tiles over the map",
                value: count as f64,
                expected: "at most 2^22 tiles: use larger tiles",
            });
        }
        let mut terrain = Self {
            size,
            texel_size: snapshot.texel_size(),
            encoding: snapshot.encoding(),
            tile_size,
            tiles_per_axis,
            tiles: Vec::with_capacity(tiles_per_axis.element_product() as usize),
            version: snapshot.version(),
            bounds: (0.0, 0.0),
            max_deviation: 0.0,
        };
        for tz in 0..tiles_per_axis.y {
            for tx in 0..tiles_per_axis.x {
                let tile = terrain.build_tile(snapshot, UVec2::new(tx, tz));
                terrain.tiles.push(tile);
            }
        }
        terrain.refresh_summary();
        Ok(terrain)
    }

    /// Brings the terrain to `snapshot`, which differs from the snapshot it holds only inside
    /// `rects` (texels, map coordinates; they may wrap): the rects applied to the mirror in
    /// between, such as those of [`UpdateReport::applied_rects`] of the scheduler's updates.
    /// Rebuilds exactly the tiles holding a vertex inside a rect and returns their
    /// coordinates, sorted by row then column.
    ///
    /// [`UpdateReport::applied_rects`]: crate::UpdateReport::applied_rects
    ///
    /// Fails, leaving the terrain unchanged, on a rect off the map (as the mirror checks
    /// them), a snapshot of another size, texel size or encoding, or one older than the
    /// terrain's. No rects rebuild nothing (and take the snapshot's version).
    pub fn update(
        &mut self,
        snapshot: &HeightField,
        rects: &[Rect],
    ) -> Result<Vec<UVec2>, PhysicsError> {
        self.check_snapshot(snapshot)?;
        let touched = self.tiles_touched(rects)?;
        for &t in &touched {
            let tile = self.build_tile(snapshot, t);
            let i = self.tile_slot(t);
            if let Some(slot) = self.tiles.get_mut(i) {
                *slot = tile;
            }
        }
        self.version = snapshot.version();
        self.refresh_summary();
        Ok(touched)
    }

    /// Rebuilds every tile from `snapshot`. Fails as [`ParryTerrain::update`] does.
    pub fn rebuild_all(&mut self, snapshot: &HeightField) -> Result<(), PhysicsError> {
        self.update(snapshot, &[Rect::from_size(self.size)])
            .map(|_| ())
    }

    /// The tiles holding a vertex inside one of `rects` (the tiles [`ParryTerrain::update`]
    /// rebuilds), sorted by row then column. Fails on a rect off the map.
    pub fn tiles_touched(&self, rects: &[Rect]) -> Result<Vec<UVec2>, PhysicsError> {
        for &r in rects {
            check_region(r, self.size)?;
        }
        let n = self.tiles_per_axis;
        let mut marked = vec![false; n.element_product() as usize];
        let mut xs = vec![false; n.x as usize];
        let mut zs = vec![false; n.y as usize];
        for &r in rects {
            for piece in r.split_toroidal(self.size) {
                xs.fill(false);
                zs.fill(false);
                self.mark_axis(&mut xs, piece.map.min.x, piece.map.size.x, self.size.x);
                self.mark_axis(&mut zs, piece.map.min.y, piece.map.size.y, self.size.y);
                for (tz, _) in zs.iter().enumerate().filter(|(_, m)| **m) {
                    for (tx, _) in xs.iter().enumerate().filter(|(_, m)| **m) {
                        if let Some(m) = marked.get_mut(tz * n.x as usize + tx) {
                            *m = true;
                        }
                    }
                }
            }
        }
        Ok(marked
            .iter()
            .enumerate()
            .filter(|(_, m)| **m)
            .map(|(i, _)| UVec2::new(i as u32 % n.x, i as u32 / n.x))
            .collect())
    }

    /// Marks the tiles along one axis whose cells have a vertex in texels `min .. min + len`
    /// (inside `0..n`): cells `min - 1 ..= min + len - 1`, wrapped.
    fn mark_axis(&self, tiles: &mut [bool], min: i32, len: u32, n: u32) {
        let (min, len) = (min.max(0) as u32, len.max(1));
        let last_cell = (min + len - 1).min(n - 1);
        let first_cell = if min == 0 {
            // Texel 0 is also the last vertex of the wrapped last cell.
            if let Some(t) = tiles.get_mut(((n - 1) / self.tile_size) as usize) {
                *t = true;
            }
            0
        } else {
            min - 1
        };
        for t in first_cell / self.tile_size..=last_cell / self.tile_size {
            if let Some(t) = tiles.get_mut(t as usize) {
                *t = true;
            }
        }
    }

    /// The tiles, row by row.
    pub fn tiles(&self) -> impl ExactSizeIterator<Item = &ParryTile> {
        self.tiles.iter()
    }

    /// Tile `index`, if inside the tile grid.
    pub fn tile(&self, index: UVec2) -> Option<&ParryTile> {
        if index.cmplt(self.tiles_per_axis).all() {
            self.tiles.get(self.tile_slot(index))
        } else {
            None
        }
    }

    /// Each tile's pose and shape, for a parry or rapier world of your own. They cover one
    /// period of the map, `[0, extent)` along X and Z.
    pub fn shapes(&self) -> impl ExactSizeIterator<Item = (Pose, &ParryHeightField)> {
        self.tiles.iter().map(|t| (t.pose, &t.shape))
    }

    /// Tiles along X and Z.
    pub fn tile_count(&self) -> UVec2 {
        self.tiles_per_axis
    }

    /// Cells per tile side (the last tile on an axis may have fewer).
    pub fn tile_size(&self) -> u32 {
        self.tile_size
    }

    /// The map's size in texels.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// The version of the snapshot the terrain was last brought to.
    pub fn version(&self) -> u64 {
        self.version
    }

    /// The bound of the whole map: the largest height difference between parry's triangles
    /// and the bilinear surface, in metres (see the [module docs](self)).
    pub fn max_deviation(&self) -> f32 {
        self.max_deviation
    }

    /// The first crossing of parry's surface by the ray from `origin` along `dir` within
    /// `max_dist` metres, or `None`; the normal points up (out of the ground).
    ///
    /// The map repeats: the ray is followed through the period copies it crosses within the
    /// tiles' height range. Fails on non-finite input, a zero direction or a negative
    /// distance, and, like the crate's own ray ([`PhysicsError::RayTooLong`]), on a nearly
    /// horizontal ray that would cross more than `4 (width + height) + 4096` cells within that
    /// range.
    pub fn cast_ray(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_dist: f32,
    ) -> Result<Option<RayHit>, PhysicsError> {
        let ray = Ray::new(origin, dir)?;
        check_max_dist(max_dist)?;
        let d = ray.dir().as_dvec3();
        let o = ray.origin().as_dvec3();
        // Only the stretch within the tiles' height range can hit.
        let (lo, hi) = (
            f64::from(self.bounds.0) - 1e-3,
            f64::from(self.bounds.1) + 1e-3,
        );
        let (mut t0, mut t1) = (0.0_f64, f64::from(max_dist));
        if d.y < 0.0 {
            t0 = t0.max((hi - o.y) / d.y);
            t1 = t1.min((lo - o.y) / d.y);
        } else if d.y > 0.0 {
            t0 = t0.max((lo - o.y) / d.y);
            t1 = t1.min((hi - o.y) / d.y);
        } else if o.y < lo || o.y > hi {
            return Ok(None);
        }
        if t0 > t1 {
            return Ok(None);
        }
        let ts = f64::from(self.texel_size);
        let cells = (t1 - t0) * (d.x.abs() + d.z.abs()) / ts;
        let cap = 4 * (u64::from(self.size.x) + u64::from(self.size.y)) + 4096;
        if cells.is_nan() || cells > cap as f64 {
            return Err(PhysicsError::RayTooLong {
                cells: if cells.is_finite() {
                    cells as u64
                } else {
                    u64::MAX
                },
            });
        }
        // Walk the period copies the stretch crosses, in order (a DDA with one period per
        // cell); the first copy with a hit holds the nearest one.
        let period = self.size.as_dvec2() * ts;
        let start = o + d * t0;
        let mut k = (start.x / period.x).floor();
        let mut l = (start.z / period.y).floor();
        let boundary = |p: f64, k: f64, dp: f64, per: f64| -> (f64, f64) {
            if dp == 0.0 {
                (f64::INFINITY, f64::INFINITY)
            } else {
                let b = if dp > 0.0 { (k + 1.0) * per } else { k * per };
                ((b - p) / dp, per / dp.abs())
            }
        };
        let (mut next_x, step_x) = boundary(start.x, k, d.x, period.x);
        let (mut next_z, step_z) = boundary(start.z, l, d.z, period.y);
        let mut t_in = t0;
        loop {
            let t_out = (t0 + next_x.min(next_z)).min(t1);
            let shift = DVec3::new(k * period.x, 0.0, l * period.y);
            if let Some(hit) = self.cast_in_copy(o, d, shift, t_in, t_out) {
                return Ok(Some(hit));
            }
            if t_out >= t1 {
                return Ok(None);
            }
            t_in = t_out;
            if next_x < next_z {
                k += d.x.signum();
                next_x += step_x;
            } else {
                l += d.z.signum();
                next_z += step_z;
            }
        }
    }

    /// The nearest hit of the ray `o + t d`, `t` in `[t_in, t_out]`, with the tiles moved by
    /// `shift` (one period copy), cast from the point at `t_in` so coordinates stay small.
    fn cast_in_copy(
        &self,
        o: DVec3,
        d: DVec3,
        shift: DVec3,
        t_in: f64,
        t_out: f64,
    ) -> Option<RayHit> {
        let t_start = (t_in - SEAM_SLACK).max(0.0);
        let local = o + d * t_start - shift;
        let ray = PRay::new(to_parry(local.as_vec3()), to_parry(d.as_vec3()));
        let max = t_out + SEAM_SLACK - t_start;
        // Walk the tiles the ray crosses in this copy, in order (a DDA over the tile grid):
        // a hit lies in its tile's footprint, so the first tile with one holds the nearest.
        let tile_m = f64::from(self.tile_size) * f64::from(self.texel_size);
        let n = self.tiles_per_axis.as_ivec2();
        let index =
            |p: f64, n: i32| ((p / tile_m).floor() as i64).clamp(0, i64::from(n) - 1) as i32;
        let (mut ix, mut iz) = (index(local.x, n.x), index(local.z, n.y));
        let boundary = |p: f64, i: i32, dp: f64| -> (f64, f64) {
            if dp == 0.0 {
                (f64::INFINITY, f64::INFINITY)
            } else {
                let b = f64::from(if dp > 0.0 { i + 1 } else { i }) * tile_m;
                (((b - p) / dp).max(0.0), tile_m / dp.abs())
            }
        };
        let (mut next_x, step_x) = boundary(local.x, ix, d.x);
        let (mut next_z, step_z) = boundary(local.z, iz, d.z);
        let mut best = None;
        while (0..n.x).contains(&ix) && (0..n.y).contains(&iz) {
            let slot = iz as usize * n.x as usize + ix as usize;
            if let Some(tile) = self.tiles.get(slot) {
                best = cast_tile(tile, &ray, max as f32);
                if best.is_some() {
                    break;
                }
            }
            if next_x.min(next_z) > max {
                break;
            }
            if next_x < next_z {
                ix += if d.x > 0.0 { 1 } else { -1 };
                next_x += step_x;
            } else {
                iz += if d.z > 0.0 { 1 } else { -1 };
                next_z += step_z;
            }
        }
        best.map(|(t, n)| {
            let distance = t_start + f64::from(t);
            let n = from_parry(n);
            RayHit {
                point: (o + d * distance).as_vec3(),
                distance: distance as f32,
                normal: if n.y < 0.0 { -n } else { n },
            }
        })
    }

    /// The deepest contact between `shape` at `pose` (parry's types, world space) and the
    /// terrain, within `prediction` metres, in parry's terms with the terrain as the second
    /// shape (`point2` on the terrain, `normal1` from the shape into it), world space.
    ///
    /// The map repeats: every period copy of the tiles the shape's bounding box overlaps is
    /// tested. Fails on a non-finite or negative prediction, a non-finite pose, a shape
    /// overlapping more than 16 period copies, or a shape pair parry does not support.
    pub fn contact(
        &self,
        pose: &Pose,
        shape: &dyn Shape,
        prediction: f32,
    ) -> Result<Option<query::Contact>, PhysicsError> {
        check_finite("contact prediction", prediction)?;
        if prediction < 0.0 {
            return Err(PhysicsError::OutOfRange {
                what: "contact prediction",
                value: f64::from(prediction),
                expected: "at least 0 metres",
            });
        }
        check_finite3("shape position", from_parry(pose.translation))?;
        let aabb = shape.compute_aabb(pose).loosened(prediction);
        let (amin, amax) = (from_parry(aabb.mins), from_parry(aabb.maxs));
        check_finite3("shape bounding box", amin)?;
        check_finite3("shape bounding box", amax)?;
        let period = self.size.as_dvec2() * f64::from(self.texel_size);
        let kx = (f64::from(amin.x) / period.x).floor()..=(f64::from(amax.x) / period.x).floor();
        let kz = (f64::from(amin.z) / period.y).floor()..=(f64::from(amax.z) / period.y).floor();
        let copies = (kx.end() - kx.start() + 1.0) * (kz.end() - kz.start() + 1.0);
        if copies > MAX_CONTACT_COPIES as f64 {
            return Err(PhysicsError::OutOfRange {
                what: "period copies of the map a contact query overlaps",
                value: copies,
                expected: "at most 16 (a shape smaller than the map)",
            });
        }
        let mut best: Option<query::Contact> = None;
        let mut kz_i = *kz.start();
        while kz_i <= *kz.end() {
            let mut kx_i = *kx.start();
            while kx_i <= *kx.end() {
                let shift = DVec3::new(kx_i * period.x, 0.0, kz_i * period.y);
                let mut local = *pose;
                local.translation =
                    to_parry((from_parry(pose.translation).as_dvec3() - shift).as_vec3());
                let local_aabb = shape.compute_aabb(&local).loosened(prediction);
                for tile in &self.tiles {
                    if !tile.world_aabb().intersects(&local_aabb) {
                        continue;
                    }
                    let found = query::contact(&local, shape, &tile.pose, &tile.shape, prediction)
                        .map_err(|_| PhysicsError::OutOfRange {
                            what: "parry shape kind (contact against a heightfield)",
                            value: f64::NAN,
                            expected: "a shape parry supports against a heightfield",
                        })?;
                    if let Some(mut c) = found
                        && best.is_none_or(|b| c.dist < b.dist)
                    {
                        let s = to_parry(shift.as_vec3());
                        c.point1 += s;
                        c.point2 += s;
                        best = Some(c);
                    }
                }
                kx_i += 1.0;
            }
            kz_i += 1.0;
        }
        Ok(best)
    }

    /// The contact of a sphere at `center` with `radius` against parry's surface, in the
    /// crate's terms (the surface point, the unit normal out of the ground, the depth), or
    /// `None` if they do not touch. Fails on non-finite input or a negative radius.
    pub fn sphere_contact(
        &self,
        center: Vec3,
        radius: f32,
    ) -> Result<Option<Contact>, PhysicsError> {
        check_finite3("sphere center", center)?;
        check_finite("sphere radius", radius)?;
        if radius < 0.0 {
            return Err(PhysicsError::NegativeRadius { radius });
        }
        let pose = Pose::from_translation(to_parry(center));
        let found = self.contact(&pose, &Ball::new(radius), 0.0)?;
        Ok(found.filter(|c| c.dist < 0.0).map(|c| Contact {
            point: from_parry(c.point2),
            normal: -from_parry(c.normal1),
            depth: -c.dist,
        }))
    }

    /// Refuses a snapshot that does not fit the terrain.
    fn check_snapshot(&self, snapshot: &HeightField) -> Result<(), PhysicsError> {
        if snapshot.size() != self.size {
            return Err(PhysicsError::SizeMismatch {
                expected: self.size,
                actual: snapshot.size(),
            });
        }
        if snapshot.texel_size() != self.texel_size {
            return Err(PhysicsError::SnapshotMismatch {
                what: "texel size",
                expected: f64::from(self.texel_size),
                actual: f64::from(snapshot.texel_size()),
            });
        }
        let (e, s) = (self.encoding, snapshot.encoding());
        if e.scale != s.scale {
            return Err(PhysicsError::SnapshotMismatch {
                what: "height encoding scale",
                expected: f64::from(e.scale),
                actual: f64::from(s.scale),
            });
        }
        if e.offset != s.offset {
            return Err(PhysicsError::SnapshotMismatch {
                what: "height encoding offset",
                expected: f64::from(e.offset),
                actual: f64::from(s.offset),
            });
        }
        if snapshot.version() < self.version {
            return Err(PhysicsError::StaleVersion {
                version: snapshot.version(),
                current: self.version,
            });
        }
        Ok(())
    }

    fn tile_slot(&self, t: UVec2) -> usize {
        t.y as usize * self.tiles_per_axis.x as usize + t.x as usize
    }

    /// Tile `t` built from `snapshot` (whose size is the terrain's).
    fn build_tile(&self, snapshot: &HeightField, t: UVec2) -> ParryTile {
        let first = t * self.tile_size;
        let cells = (self.size - first).min(UVec2::splat(self.tile_size));
        let grid = snapshot.heights();
        let e = snapshot.encoding();
        let (off, scale) = (f64::from(e.offset), f64::from(e.scale));
        let w = self.size.x;
        let h = self.size.y;
        let (nx, nz) = (cells.x as usize + 1, cells.y as usize + 1);
        // Column-major (parry's Array2): rows along Z, columns along X.
        let mut data = Vec::with_capacity(nx * nz);
        let raw = |x: usize, z: usize| -> u16 {
            let gx = (first.x + x as u32) % w;
            let gz = (first.y + z as u32) % h;
            grid.get(gx, gz).unwrap_or(0)
        };
        for x in 0..nx {
            for z in 0..nz {
                data.push((off + scale * f64::from(raw(x, z))) as f32);
            }
        }
        let heights = Array2::new(nz, nx, data);
        // The bound: the largest twist over the cells, from the f32 heights parry holds.
        let mut twist = 0.0_f64;
        for x in 0..cells.x as usize {
            for z in 0..cells.y as usize {
                let hh = |i: usize, j: usize| f64::from(heights[(j, i)]);
                let d = hh(x, z) - hh(x + 1, z) - hh(x, z + 1) + hh(x + 1, z + 1);
                twist = twist.max(d.abs());
            }
        }
        let ts = self.texel_size;
        let size_m = cells.as_vec2() * ts;
        let mut shape = ParryHeightField::new(heights, PVec3::new(size_m.x, 1.0, size_m.y));
        // Cells cut away (HeightField::with_holes) are removed cells for parry too: its queries
        // skip them as this crate's do.
        if snapshot.holes().is_some() {
            for z in 0..cells.y {
                for x in 0..cells.x {
                    let cell = (first + UVec2::new(x, z)).as_ivec2();
                    if snapshot.hole_cell(i64::from(cell.x), i64::from(cell.y)) {
                        shape.set_cell_status(
                            z as usize,
                            x as usize,
                            parry3d::shape::HeightFieldCellStatus::CELL_REMOVED,
                        );
                    }
                }
            }
        }
        let centre = first.as_vec2() * ts + size_m * 0.5;
        ParryTile {
            index: t,
            cells: Rect::new(first.as_ivec2(), cells),
            shape,
            pose: Pose::from_translation(PVec3::new(centre.x, 0.0, centre.y)),
            // Rounded up past the f32 rounding of the heights it came from.
            max_deviation: ((twist / 4.0) as f32).next_up(),
            version: snapshot.version(),
        }
    }

    /// Recomputes the height range and the bound of the whole map from the tiles.
    fn refresh_summary(&mut self) {
        let (mut lo, mut hi, mut dev) = (f32::INFINITY, f32::NEG_INFINITY, 0.0_f32);
        for t in &self.tiles {
            let a = t.world_aabb();
            lo = lo.min(a.mins.y);
            hi = hi.max(a.maxs.y);
            dev = dev.max(t.max_deviation);
        }
        self.bounds = (lo, hi);
        self.max_deviation = dev;
    }
}

/// The first hit of `ray` (in the world frame of one period copy) on `tile` within `max`:
/// its distance and parry's normal.
fn cast_tile(tile: &ParryTile, ray: &PRay, max: f32) -> Option<(f32, PVec3)> {
    // In the tile's frame, from where the ray enters its box: parry's heightfield walk starts
    // in the cell of its own entry point, and when rounding puts that point just outside the
    // box it starts in a corner cell instead and misses (parry3d 0.31). Clamping the entry
    // point onto the box (a shift of the rounding error only) avoids that.
    let aabb = tile.shape.root_aabb();
    let origin = ray.origin - tile.pose.translation;
    let (enter, _) = aabb.clip_ray_parameters(&PRay::new(origin, ray.dir))?;
    if enter > max {
        return None;
    }
    let mut q = origin + ray.dir * enter;
    q.x = q.x.clamp(aabb.mins.x, aabb.maxs.x);
    q.z = q.z.clamp(aabb.mins.z, aabb.maxs.z);
    let hit =
        tile.shape
            .cast_local_ray_and_get_normal(&PRay::new(q, ray.dir), max - enter, true)?;
    Some((enter + hit.time_of_impact, hit.normal))
}

/// glam (the workspace's version) to parry's vector.
#[inline]
fn to_parry(v: Vec3) -> PVec3 {
    PVec3::new(v.x, v.y, v.z)
}

/// Parry's vector to glam (the workspace's version).
#[inline]
fn from_parry(v: PVec3) -> Vec3 {
    Vec3::new(v.x, v.y, v.z)
}
