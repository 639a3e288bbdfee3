//! `CollisionMirror`: the double-buffered CPU copy of the coarse-map that collision reads.
//! Readers take an immutable snapshot and never wait for a writer's copy; writers apply
//! region updates, each with a version, off to the side and swap them in.
//!
//! Design: the front buffer is an `Arc<HeightField>` in an `arc_swap::ArcSwap`. A reader
//! takes a snapshot wait-free (no lock: a writer can never make it wait); the writer swaps
//! the pointer in O(1). The writer keeps the previous front as its back buffer, together
//! with the rects that buffer misses (the last update's pieces). Applying an update copies those
//! rects from the front into the back (unless the new update covers them), pastes the new
//! region and swaps: O(region) per update, not O(map). If a reader still holds the old buffer,
//! the writer clones the front instead (O(map), never blocking the reader). A snapshot is
//! never written after it is published, so no reader can see a torn update.

use crate::collider::HeightfieldCollider;
use crate::error::{PhysicsError, check_region};
use crate::field::{HeightField, min_max};
use glam::UVec2;
use std::sync::Arc;
use sync::{Front, WriterLock};
use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect};

/// One region of new heights: the stored values of `rect`, row-major in the rect's own
/// (unwrapped) coordinates, and the version they bring the mirror to.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionUpdate {
    /// The region, in texels; it may cross the map's edges (it wraps), at most one map in size.
    pub rect: Rect,
    /// The stored u16 heights of the region, `rect.size` in size.
    pub heights: Grid<u16>,
    /// The version the mirror has after this update; must exceed the mirror's version.
    pub version: u64,
}

/// The writer's side: the back buffer and the rects (map coordinates) it lacks.
#[derive(Debug, Default)]
struct Writer {
    back: Option<Arc<HeightField>>,
    stale: Vec<Rect>,
}

/// The double-buffered collision mirror. `Send + Sync`: share it with `Arc` between the thread
/// that applies readbacks and the threads that query.
#[derive(Debug)]
pub struct CollisionMirror {
    front: Front,
    writer: WriterLock<Writer>,
    size: UVec2,
    encoding: HeightEncoding,
    texel_size: f32,
}

impl CollisionMirror {
    /// A mirror starting from `field` (its version is the mirror's first version).
    pub fn new(field: HeightField) -> Self {
        Self {
            size: field.size(),
            encoding: field.encoding(),
            texel_size: field.texel_size(),
            front: Front::new(Arc::new(field)),
            writer: WriterLock::new(Writer::default()),
        }
    }

    /// A mirror of a copy of `map` (which must wrap) at version 0.
    pub fn from_map(map: &CoarseMap) -> Result<Self, PhysicsError> {
        Ok(Self::new(HeightField::from_map(map)?))
    }

    /// The current snapshot: consistent, immutable, tagged with its version. Wait-free: never
    /// waits for a writer.
    pub fn snapshot(&self) -> Arc<HeightField> {
        self.front.load()
    }

    /// A collider over the current snapshot, at the origin.
    pub fn collider(&self) -> HeightfieldCollider {
        HeightfieldCollider::new(self.snapshot())
    }

    /// The version of the current snapshot.
    pub fn version(&self) -> u64 {
        self.front.load().version()
    }

    /// Map size in texels.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// The height encoding of the mirrored map.
    pub fn encoding(&self) -> HeightEncoding {
        self.encoding
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// Applies `update` and publishes it as one new snapshot.
    ///
    /// Fails on a rect off the map (empty, larger than the map, or starting more than one
    /// period away), heights whose size differs from the rect's, or a version not newer than
    /// the mirror's. On failure the mirror is unchanged.
    pub fn apply(&self, update: &RegionUpdate) -> Result<(), PhysicsError> {
        let mut writer = self.writer.lock();
        let current = self.version();
        if update.version <= current {
            return Err(PhysicsError::StaleVersion {
                version: update.version,
                current,
            });
        }
        self.apply_locked(&mut writer, update.rect, &update.heights, update.version)
    }

    /// Applies the heights of `rect` as the next version (the current version + 1), and
    /// returns that version. Fails as [`CollisionMirror::apply`] does.
    pub fn apply_next(&self, rect: Rect, heights: &Grid<u16>) -> Result<u64, PhysicsError> {
        let mut writer = self.writer.lock();
        let version = self.version() + 1;
        self.apply_locked(&mut writer, rect, heights, version)?;
        Ok(version)
    }

    /// Publishes a snapshot with the cells `holes` marks cut away (`None`: no holes), the
    /// heights and the version unchanged (a hole is no height update: the readback versions
    /// stay the scheduler's). Holes change rarely, so the whole mask is passed; the caller
    /// keeps it (e.g. the mask it uploads to the GPU) and shares it through the `Arc`.
    ///
    /// Fails on a mask of another size than the map; the mirror is then unchanged.
    pub fn set_holes(&self, holes: Option<Arc<Grid<u8>>>) -> Result<(), PhysicsError> {
        if let Some(mask) = &holes
            && mask.size() != self.size
        {
            return Err(PhysicsError::SizeMismatch {
                expected: self.size,
                actual: mask.size(),
            });
        }
        let mut writer = self.writer.lock();
        self.publish(&mut writer, Vec::new(), |buf| buf.set_holes(holes));
        Ok(())
    }

    /// Copies the mirror's heights of `rect` (it may wrap) into `map`, a map of the mirror's
    /// size and encoding: how a CPU copy of the terrain (an overview, a save) follows the
    /// regions read back into the mirror, region by region, without deforming anything of its
    /// own. Pass the rects of [`crate::UpdateReport::applied_rects`].
    ///
    /// Fails on a `map` of another size or encoding and on a rect off the map; `map` is then
    /// unchanged.
    pub fn copy_into(&self, rect: Rect, map: &mut CoarseMap) -> Result<(), PhysicsError> {
        if map.size() != self.size {
            return Err(PhysicsError::SizeMismatch {
                expected: self.size,
                actual: map.size(),
            });
        }
        if map.encoding() != self.encoding {
            return Err(PhysicsError::OutOfRange {
                what: "map height scale (its encoding differs from the mirror's)",
                value: f64::from(map.encoding().scale),
                expected: "the mirror's encoding",
            });
        }
        check_region(rect, self.size)?;
        let front = self.snapshot();
        for piece in rect.split_toroidal(self.size) {
            copy_rect(front.heights(), map.grid_mut(), piece.map);
        }
        Ok(())
    }

    fn apply_locked(
        &self,
        writer: &mut Writer,
        rect: Rect,
        heights: &Grid<u16>,
        version: u64,
    ) -> Result<(), PhysicsError> {
        check_region(rect, self.size)?;
        if heights.size() != rect.size {
            return Err(PhysicsError::SizeMismatch {
                expected: rect.size,
                actual: heights.size(),
            });
        }
        let pieces = rect.split_toroidal(self.size);
        let replaced = pieces.iter().map(|p| p.map).collect();
        self.publish(writer, replaced, |buf| {
            let grid = buf.heights_mut();
            // The region's value range, taken row by row while each row is in cache.
            let (mut lo, mut hi) = (u16::MAX, 0u16);
            for piece in &pieces {
                let off = (piece.unwrapped.min - rect.min).as_uvec2();
                let (x0, w) = (piece.map.min.x as usize, piece.map.size.x as usize);
                for row in 0..piece.map.size.y {
                    let src = &heights.row(off.y + row)[off.x as usize..off.x as usize + w];
                    let dst = grid.row_mut(piece.map.min.y as u32 + row);
                    dst[x0..x0 + w].copy_from_slice(src);
                    let (l, h) = min_max(src);
                    lo = lo.min(l);
                    hi = hi.max(h);
                }
            }
            if rect.size == self.size {
                // Every texel was replaced: the bounds are exact again.
                buf.set_bounds(lo, hi);
            } else {
                buf.widen_bounds(lo, hi);
            }
            buf.set_version(version);
        });
        Ok(())
    }

    /// Publishes the next snapshot: the back buffer brought up to the front (what it lacks
    /// copied from the front, except inside `replaced`, the rects `edit` rewrites), with the
    /// front's bounds, holes and version, then changed by `edit` and swapped in. The old front
    /// becomes the back buffer, lacking `replaced`.
    fn publish(
        &self,
        writer: &mut Writer,
        replaced: Vec<Rect>,
        edit: impl FnOnce(&mut HeightField),
    ) {
        let front = self.snapshot();
        // The back buffer and what it lacks; without one, start from the front (cloned below).
        let (mut back, stale) = match writer.back.take() {
            Some(back) => (back, std::mem::take(&mut writer.stale)),
            None => (front.clone(), Vec::new()),
        };
        // Clones only if a reader still holds the back buffer (or it is the front itself).
        let buf = Arc::make_mut(&mut back);
        for r in stale {
            if !replaced.iter().any(|p| p.contains_rect(&r)) {
                copy_rect(front.heights(), buf.heights_mut(), r);
            }
        }
        buf.copy_bounds_from(&front);
        buf.set_version(front.version());
        edit(buf);
        let old = self.front.swap(back);
        drop(front);
        writer.back = Some(old);
        writer.stale = replaced;
    }
}

/// The front pointer and the writers' lock: `arc_swap` and `parking_lot` in a build, and
/// shuttle's instrumented primitives under the `shuttle` feature, so the randomized
/// concurrency test explores the interleavings of the mirror's own protocol.
#[cfg(not(feature = "shuttle"))]
mod sync {
    use super::HeightField;
    use std::sync::Arc;

    /// The published snapshot.
    #[derive(Debug)]
    pub struct Front(arc_swap::ArcSwap<HeightField>);

    impl Front {
        pub fn new(field: Arc<HeightField>) -> Self {
            Self(arc_swap::ArcSwap::new(field))
        }
        /// Wait-free.
        pub fn load(&self) -> Arc<HeightField> {
            self.0.load_full()
        }
        pub fn swap(&self, new: Arc<HeightField>) -> Arc<HeightField> {
            self.0.swap(new)
        }
    }

    /// Serialises writers.
    #[derive(Debug)]
    pub struct WriterLock<T>(parking_lot::Mutex<T>);

    impl<T> WriterLock<T> {
        pub fn new(v: T) -> Self {
            Self(parking_lot::Mutex::new(v))
        }
        pub fn lock(&self) -> parking_lot::MutexGuard<'_, T> {
            self.0.lock()
        }
    }
}

#[cfg(feature = "shuttle")]
mod sync {
    use super::HeightField;
    use std::sync::Arc;

    #[derive(Debug)]
    pub struct Front(shuttle::sync::Mutex<Arc<HeightField>>);

    impl Front {
        pub fn new(field: Arc<HeightField>) -> Self {
            Self(shuttle::sync::Mutex::new(field))
        }
        pub fn load(&self) -> Arc<HeightField> {
            self.0.lock().unwrap_or_else(|e| e.into_inner()).clone()
        }
        pub fn swap(&self, new: Arc<HeightField>) -> Arc<HeightField> {
            let mut g = self.0.lock().unwrap_or_else(|e| e.into_inner());
            std::mem::replace(&mut *g, new)
        }
    }

    #[derive(Debug)]
    pub struct WriterLock<T>(shuttle::sync::Mutex<T>);

    impl<T> WriterLock<T> {
        pub fn new(v: T) -> Self {
            Self(shuttle::sync::Mutex::new(v))
        }
        pub fn lock(&self) -> shuttle::sync::MutexGuard<'_, T> {
            self.0.lock().unwrap_or_else(|e| e.into_inner())
        }
    }
}

/// Copies `rect` (inside both grids, which have the same size) from `src` to `dst`.
fn copy_rect(src: &Grid<u16>, dst: &mut Grid<u16>, rect: Rect) {
    let (x0, w) = (rect.min.x as usize, rect.size.x as usize);
    for y in rect.min.y..rect.max().y {
        let y = y as u32;
        dst.row_mut(y)[x0..x0 + w].copy_from_slice(&src.row(y)[x0..x0 + w]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::IVec2;

    fn mirror() -> CollisionMirror {
        let g = Grid::from_fn(16, 12, |x, y| (x + 100 * y) as u16).expect("grid");
        let f =
            HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("field");
        CollisionMirror::new(f)
    }

    fn expected_after(updates: &[(Rect, u16)]) -> Grid<u16> {
        let mut g = Grid::from_fn(16, 12, |x, y| (x + 100 * y) as u16).expect("grid");
        for &(rect, v) in updates {
            for p in rect.split_toroidal(g.size()) {
                for y in p.map.min.y..p.map.max().y {
                    for x in p.map.min.x..p.map.max().x {
                        *g.get_mut(x as u32, y as u32).expect("inside") = v;
                    }
                }
            }
        }
        g
    }

    /// A CPU map follows the mirror through the applied rects only (one wraps a corner);
    /// a map of another size or encoding, or a rect off the map, is refused and left as it was.
    #[test]
    fn a_cpu_map_follows_the_mirror_through_copied_rects() {
        let m = mirror();
        let enc = HeightEncoding::new(0.01, 0.0).expect("enc");
        let start = Grid::from_fn(16, 12, |x, y| (x + 100 * y) as u16).expect("grid");
        let mut map = CoarseMap::coarse(start.clone(), enc, 1.0).expect("map");
        let rects = [
            Rect::new(IVec2::new(14, 10), UVec2::new(5, 4)),
            Rect::new(IVec2::new(3, 2), UVec2::new(2, 6)),
        ];
        for (i, &r) in rects.iter().enumerate() {
            let data = Grid::new(r.size.x, r.size.y, 7000 + i as u16).expect("grid");
            m.apply_next(r, &data).expect("apply");
            m.copy_into(r, &mut map).expect("copy");
        }
        assert_eq!(map.grid(), m.snapshot().heights());
        let before = map.clone();
        let off = Rect::new(IVec2::new(40, 0), UVec2::new(2, 2));
        assert!(m.copy_into(off, &mut map).is_err());
        let other = HeightEncoding::new(0.02, 0.0).expect("enc");
        let mut wrong = CoarseMap::coarse(start.clone(), other, 1.0).expect("map");
        assert!(m.copy_into(rects[1], &mut wrong).is_err());
        let mut small = CoarseMap::coarse(Grid::new(8, 8, 0).expect("g"), enc, 1.0).expect("m");
        assert!(m.copy_into(rects[1], &mut small).is_err());
        assert_eq!(map, before);
        assert_eq!(wrong.grid(), &start);
    }

    #[test]
    fn updates_accumulate_through_both_buffers() {
        let m = mirror();
        let rects = [
            Rect::new(IVec2::new(2, 3), UVec2::new(4, 2)),
            Rect::new(IVec2::new(10, 1), UVec2::new(3, 8)),
            Rect::new(IVec2::new(14, 10), UVec2::new(5, 4)), // wraps a corner
            Rect::new(IVec2::new(-2, 0), UVec2::new(3, 3)),  // wraps from the left
            Rect::new(IVec2::new(3, 3), UVec2::new(1, 1)),
        ];
        let mut done = Vec::new();
        for (i, &r) in rects.iter().enumerate() {
            let v = 1000 + i as u16;
            let data = Grid::new(r.size.x, r.size.y, v).expect("grid");
            let version = m.apply_next(r, &data).expect("apply");
            assert_eq!(version, i as u64 + 1);
            done.push((r, v));
            assert_eq!(m.snapshot().heights(), &expected_after(&done), "after {i}");
        }
    }

    #[test]
    fn a_reader_holding_the_back_buffer_keeps_its_snapshot() {
        let m = mirror();
        let r = Rect::new(IVec2::new(0, 0), UVec2::new(2, 2));
        let old = m.snapshot();
        m.apply_next(r, &Grid::new(2, 2, 7).expect("grid"))
            .expect("apply");
        // `old` is now the writer's back buffer: the next update must not write into it.
        m.apply_next(r, &Grid::new(2, 2, 9).expect("grid"))
            .expect("apply");
        assert_eq!(old.heights().get(0, 0), Some(0));
        assert_eq!(old.version(), 0);
        assert_eq!(m.snapshot().heights().get(1, 1), Some(9));
    }

    #[test]
    fn bad_updates_leave_the_mirror_unchanged() {
        let m = mirror();
        let size = m.size();
        let g = Grid::new(2, 2, 5u16).expect("grid");
        let off = Rect::new(IVec2::new(40, 0), UVec2::new(2, 2));
        assert!(matches!(
            m.apply_next(off, &g),
            Err(PhysicsError::RegionOffMap { rect, map_size }) if rect == off && map_size == size
        ));
        let big = Rect::new(IVec2::ZERO, UVec2::new(17, 2));
        assert!(
            m.apply_next(big, &Grid::new(17, 2, 0).expect("grid"))
                .is_err()
        );
        let empty = Rect::new(IVec2::ZERO, UVec2::new(0, 2));
        assert!(m.apply_next(empty, &g).is_err());
        let r = Rect::new(IVec2::ZERO, UVec2::new(3, 2));
        assert!(matches!(
            m.apply_next(r, &g),
            Err(PhysicsError::SizeMismatch { .. })
        ));
        let ok = Rect::new(IVec2::ZERO, UVec2::new(2, 2));
        m.apply(&RegionUpdate {
            rect: ok,
            heights: g.clone(),
            version: 5,
        })
        .expect("apply");
        assert!(matches!(
            m.apply(&RegionUpdate {
                rect: ok,
                heights: g,
                version: 5
            }),
            Err(PhysicsError::StaleVersion {
                version: 5,
                current: 5
            })
        ));
        assert_eq!(m.version(), 5);
    }

    #[test]
    fn bounds_stay_conservative() {
        let m = mirror();
        let r = Rect::new(IVec2::new(1, 1), UVec2::new(2, 2));
        m.apply_next(r, &Grid::new(2, 2, 60_000).expect("grid"))
            .expect("apply");
        let (_, hi) = m.snapshot().height_bounds();
        assert!(hi >= 600.0 - 1e-3);
        let full = Rect::from_size(m.size());
        m.apply_next(full, &Grid::new(16, 12, 10).expect("grid"))
            .expect("apply");
        let (lo, hi) = m.snapshot().height_bounds();
        assert!((lo - 0.1).abs() < 1e-6 && (hi - 0.1).abs() < 1e-6);
    }
}
