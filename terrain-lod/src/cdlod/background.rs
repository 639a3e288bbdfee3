//! [`CdlodUpdater`]: a [`CdlodTree`] kept current on a worker thread, so that a frame never
//! pays for the per-texel work of [`CdlodTree::update_rect`] (about 0.1 us per changed texel:
//! a shockwave changing 850 k texels a frame would cost the frame 60-100 ms).
//!
//! The caller hands over each changed rect with its heights ([`CdlodUpdater::submit`]: a copy
//! of the rect's rows, the only frame-thread cost). The worker keeps its own copy of the map,
//! writes the rects into it, updates its tree and publishes a snapshot; the frame selects with
//! the newest snapshot ([`CdlodUpdater::poll`], [`CdlodUpdater::tree`]). Bounds therefore lag
//! the heights by the worker's latency (a frame or two under a shockwave): a node whose
//! ground rose meanwhile may be culled or drawn at a coarser LOD for those frames, as with any
//! readback-fed LOD. [`CdlodUpdater::flush`] waits until every submitted change is in the
//! tree (tests, the end of a run); after it the tree equals one updated in place.

use crate::cdlod::CdlodTree;
use crate::error::LodError;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::thread::JoinHandle;
use terrain_core::{Grid, HeightMap, HeightSample, Rect, WrapMode};

/// A changed rect of the map (inside it, or wrapping on a repeating map) with its heights.
struct Change<T> {
    rect: Rect,
    heights: Grid<T>,
}

/// A snapshot of the worker's tree, and how many changes it holds.
type Published = Result<(Arc<CdlodTree>, u64), LodError>;

/// A CDLOD quadtree updated on a worker thread (see the module docs).
#[derive(Debug)]
pub struct CdlodUpdater<T: HeightSample + Send + Sync + 'static> {
    tree: Arc<CdlodTree>,
    map_size: glam::UVec2,
    wrap: WrapMode,
    changes: Option<Sender<Change<T>>>,
    published: Receiver<Published>,
    worker: Option<JoinHandle<()>>,
    /// Changes submitted, and changes the current snapshot holds.
    submitted: u64,
    applied: u64,
}

impl<T: HeightSample + Send + Sync + 'static> CdlodUpdater<T> {
    /// Starts the worker with `tree`, built from `map` (the worker keeps its own copy of
    /// `map`, which `submit` keeps current). Fails when the tree was not built over a map of
    /// `map`'s size, or was built from leaf bounds (it holds no per-texel errors to update).
    pub fn spawn(tree: CdlodTree, map: &HeightMap<T>) -> Result<Self, LodError> {
        if tree.map_size != map.size() {
            return Err(LodError::SizeMismatch {
                expected: tree.map_size,
                actual: map.size(),
            });
        }
        if tree.streamed {
            return Err(LodError::InvalidCdlodParam {
                what: "CdlodUpdater over a tree built from leaf bounds",
                value: 0.0,
                allowed: "a tree built from a map (CdlodTree::from_map)",
            });
        }
        let (changes, jobs) = channel::<Change<T>>();
        let (publish, published) = channel::<Published>();
        let tree = Arc::new(tree);
        let (worker_tree, worker_map) = (Arc::clone(&tree), map.clone());
        let worker = std::thread::Builder::new()
            .name("cdlod-updater".into())
            .spawn(move || run(worker_tree, worker_map, &jobs, &publish))
            .map_err(|e| LodError::InvalidCdlodParam {
                what: "CdlodUpdater worker thread",
                value: f64::from(e.raw_os_error().unwrap_or(0)),
                allowed: "a thread the system can start",
            })?;
        Ok(Self {
            map_size: map.size(),
            wrap: tree.wrap,
            tree,
            changes: Some(changes),
            published,
            worker: Some(worker),
            submitted: 0,
            applied: 0,
        })
    }

    /// The newest snapshot taken in by [`CdlodUpdater::poll`] or [`CdlodUpdater::flush`].
    pub fn tree(&self) -> &Arc<CdlodTree> {
        &self.tree
    }

    /// Changes submitted and not yet in [`CdlodUpdater::tree`].
    pub fn pending(&self) -> u64 {
        self.submitted - self.applied
    }

    /// Hands `rect` of `map` (the caller's map, already holding the new heights) to the
    /// worker: its rows are copied now (wrapping on a repeating map; clipped to a clamped
    /// one). An empty rect is nothing to do.
    pub fn submit(&mut self, map: &HeightMap<T>, rect: Rect) -> Result<(), LodError> {
        if map.size() != self.map_size {
            return Err(LodError::SizeMismatch {
                expected: self.map_size,
                actual: map.size(),
            });
        }
        let rect = match self.wrap {
            // A rect wider than the map covers it once.
            WrapMode::Repeat => Rect::new(rect.min, rect.size.min(self.map_size)),
            WrapMode::Clamp => match rect.intersect(&Rect::from_size(self.map_size)) {
                Some(r) => r,
                None => return Ok(()),
            },
        };
        if rect.is_empty() {
            return Ok(());
        }
        let heights = copy_wrapped(map, rect)?;
        let sender = self.changes.as_ref().ok_or_else(worker_gone)?;
        sender
            .send(Change { rect, heights })
            .map_err(|_| worker_gone())?;
        self.submitted += 1;
        Ok(())
    }

    /// Takes in the newest snapshot the worker published, without waiting; `true` when the
    /// tree changed. A failed update is returned here.
    pub fn poll(&mut self) -> Result<bool, LodError> {
        let mut changed = false;
        loop {
            match self.published.try_recv() {
                Ok(snapshot) => {
                    let (tree, applied) = snapshot?;
                    self.tree = tree;
                    self.applied = applied;
                    changed = true;
                }
                Err(TryRecvError::Empty) => return Ok(changed),
                Err(TryRecvError::Disconnected) => {
                    return if self.applied == self.submitted {
                        Ok(changed)
                    } else {
                        Err(worker_gone())
                    };
                }
            }
        }
    }

    /// Waits until every submitted change is in [`CdlodUpdater::tree`].
    pub fn flush(&mut self) -> Result<(), LodError> {
        self.poll()?;
        while self.applied < self.submitted {
            let (tree, applied) = self.published.recv().map_err(|_| worker_gone())??;
            self.tree = tree;
            self.applied = applied;
        }
        Ok(())
    }
}

impl<T: HeightSample + Send + Sync + 'static> Drop for CdlodUpdater<T> {
    fn drop(&mut self) {
        // Closing the channel ends the worker's loop.
        self.changes = None;
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}

fn worker_gone() -> LodError {
    LodError::InvalidCdlodParam {
        what: "CdlodUpdater worker",
        value: 0.0,
        allowed: "a running worker (it stopped: a panic in an update)",
    }
}

/// The heights of `rect` of `map`, wrapping on a repeating map (the rect lies inside a clamped
/// one): whole rows copied where they do not cross the edge.
fn copy_wrapped<T: HeightSample>(map: &HeightMap<T>, rect: Rect) -> Result<Grid<T>, LodError> {
    let grid = map.grid();
    if Rect::from_size(map.size()).contains_rect(&rect) {
        return Ok(grid.copy_rect(rect)?);
    }
    let (w, h) = (map.size().x, map.size().y);
    let wrap = map.wrap();
    let mut data = Vec::with_capacity(rect.area() as usize);
    for y in 0..i64::from(rect.size.y) {
        let row = grid.row(wrap.resolve(i64::from(rect.min.y) + y, h));
        for x in 0..i64::from(rect.size.x) {
            data.push(row[wrap.resolve(i64::from(rect.min.x) + x, w) as usize]);
        }
    }
    Ok(Grid::from_vec(rect.size.x, rect.size.y, data)?)
}

/// The worker: takes every change waiting, writes them into its map, updates its tree and
/// publishes a snapshot; until the caller's side is dropped.
fn run<T: HeightSample>(
    mut tree: Arc<CdlodTree>,
    mut map: HeightMap<T>,
    jobs: &Receiver<Change<T>>,
    publish: &Sender<Published>,
) {
    let mut applied = 0u64;
    while let Ok(first) = jobs.recv() {
        let mut batch = vec![first];
        batch.extend(jobs.try_iter());
        let result = (|| {
            for change in &batch {
                write_wrapped(&mut map, change);
            }
            // Copy-on-write: the caller holds the published snapshot.
            let tree = Arc::make_mut(&mut tree);
            for change in &batch {
                tree.update_rect(&map, change.rect)?;
            }
            Ok(())
        })();
        applied += batch.len() as u64;
        let snapshot = result.map(|()| (Arc::clone(&tree), applied));
        if publish.send(snapshot).is_err() {
            return;
        }
    }
}

/// Writes a change's heights into `map` (wrapping on a repeating map).
fn write_wrapped<T: HeightSample>(map: &mut HeightMap<T>, change: &Change<T>) {
    let (w, h) = (map.size().x, map.size().y);
    let wrap = map.wrap();
    let rect = change.rect;
    let grid = map.grid_mut();
    for y in 0..rect.size.y {
        let src = change.heights.row(y);
        let row = grid.row_mut(wrap.resolve(i64::from(rect.min.y) + i64::from(y), h));
        for (x, v) in src.iter().enumerate() {
            row[wrap.resolve(i64::from(rect.min.x) + x as i64, w) as usize] = *v;
        }
    }
}
