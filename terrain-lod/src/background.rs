//! [`LodUpdater`]: LOD data derived from the heights (a [`CdlodTree`], a [`TessState`]) kept
//! current on a worker thread, so that a frame never pays for the per-texel work of their
//! `update_rect` (about 0.1 us per changed texel: a shockwave changing 850 k texels a frame
//! would cost the frame 60-100 ms).
//!
//! The caller hands over each changed rect with its heights ([`LodUpdater::submit`]: a copy
//! of the rect's rows, the only frame-thread cost). The worker keeps its own copy of the map,
//! writes the rects into it, updates its data and publishes a snapshot; the frame uses the
//! newest snapshot ([`LodUpdater::poll`], [`LodUpdater::state`]) and takes what the updates
//! changed ([`LodUpdater::take_changes`]: the tessellation's grid rows, to copy to the GPU).
//! The data therefore lags the heights by the worker's latency (a frame or two under a
//! shockwave): a node whose ground rose meanwhile may be culled or drawn at a coarser LOD for
//! those frames, as with any readback-fed LOD. [`LodUpdater::flush`] waits until every
//! submitted change is in; after it the data equals one updated in place.

use crate::error::LodError;
use crate::{CdlodTree, DensityMap, TessHierarchy};
use glam::UVec2;
use std::sync::Arc;
// crossbeam's receiver is `Sync` (std's is not), so an updater, and the renderers holding one, can
// live in an engine's shared resources (Bevy's `Resource` needs `Send + Sync`).
use crossbeam_channel::{Receiver, Sender, TryRecvError, unbounded as channel};
use std::thread::JoinHandle;
use terrain_core::{Grid, HeightMap, HeightSample, Rect, WrapMode};

/// LOD data derived from a map's heights that a change of a rect of the map updates in place
/// (what [`LodUpdater`] keeps current on its worker).
pub trait RectUpdate: Clone + Send + Sync + 'static {
    /// What an update reports to the frame (nothing for CDLOD; the grid rows to copy to the
    /// GPU for the tessellation).
    type Change: Send + 'static;

    /// The size of the map the data was built from.
    fn map_size(&self) -> UVec2;

    /// How the map wraps.
    fn wrap(&self) -> WrapMode;

    /// Whether `update_rect` can work on this data (a CDLOD tree built from leaf bounds holds
    /// no per-texel errors to update).
    fn check_updatable(&self) -> Result<(), LodError> {
        Ok(())
    }

    /// Brings the data up to date with `map` after its heights changed inside `rect`,
    /// pushing what changed onto `changes`.
    fn update_rect<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        rect: Rect,
        changes: &mut Vec<Self::Change>,
    ) -> Result<(), LodError>;
}

impl RectUpdate for CdlodTree {
    type Change = ();

    fn map_size(&self) -> UVec2 {
        self.map_size()
    }

    fn wrap(&self) -> WrapMode {
        self.wrap()
    }

    fn check_updatable(&self) -> Result<(), LodError> {
        if self.is_streamed() {
            return Err(LodError::InvalidCdlodParam {
                what: "a background update of a tree built from leaf bounds",
                value: 0.0,
                allowed: "a tree built from a map (CdlodTree::from_map)",
            });
        }
        Ok(())
    }

    fn update_rect<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        rect: Rect,
        _: &mut Vec<()>,
    ) -> Result<(), LodError> {
        CdlodTree::update_rect(self, map, rect)
    }
}

/// The adaptive tessellation's height-dependent data: the hierarchy and, when it is driven by
/// one, the density map (updated first: the hierarchy reads it).
#[derive(Debug, Clone, PartialEq)]
pub struct TessState {
    /// The saturated bounds the selection reads.
    pub hierarchy: TessHierarchy,
    /// The curvature density map, when the tessellation follows one.
    pub density: Option<DensityMap>,
}

impl RectUpdate for TessState {
    /// Grid rows of [`TessHierarchy::bounds`] whose values may have changed.
    type Change = std::ops::Range<u32>;

    fn map_size(&self) -> UVec2 {
        self.hierarchy.map_size()
    }

    fn wrap(&self) -> WrapMode {
        self.hierarchy.wrap()
    }

    fn update_rect<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        rect: Rect,
        changes: &mut Vec<Self::Change>,
    ) -> Result<(), LodError> {
        if let Some(d) = &mut self.density {
            d.update_rect(map, rect)?;
        }
        let rows = self
            .hierarchy
            .update_rect(map, self.density.as_ref(), rect)?;
        changes.extend(rows);
        Ok(())
    }
}

/// A changed rect of the map (inside it, or wrapping on a repeating map) with its heights.
struct Change<T> {
    rect: Rect,
    heights: Grid<T>,
}

/// What the worker is sent: a change, or a snapshot the frame no longer needs (freed there:
/// freeing a large snapshot costs the frame milliseconds).
enum Job<S, T> {
    Change(Change<T>),
    Retire(Arc<S>),
}

/// A snapshot of the worker's data, what its updates changed since the last snapshot, and how
/// many submitted changes it holds.
type Published<S> = Result<(Arc<S>, Vec<<S as RectUpdate>::Change>, u64), LodError>;

/// LOD data updated on a worker thread (see the module docs).
#[derive(Debug)]
pub struct LodUpdater<S: RectUpdate, T: HeightSample + Send + Sync + 'static> {
    state: Arc<S>,
    /// What the snapshots taken in changed, not yet taken by the caller.
    changed: Vec<S::Change>,
    map_size: UVec2,
    wrap: WrapMode,
    changes: Option<Sender<Job<S, T>>>,
    published: Receiver<Published<S>>,
    worker: Option<JoinHandle<()>>,
    /// Changes submitted, and changes the current snapshot holds.
    submitted: u64,
    applied: u64,
}

/// A CDLOD quadtree kept current on a worker thread.
pub type CdlodUpdater<T> = LodUpdater<CdlodTree, T>;

/// The tessellation's hierarchy and density map kept current on a worker thread.
pub type TessUpdater<T> = LodUpdater<TessState, T>;

impl<S: RectUpdate, T: HeightSample + Send + Sync + 'static> LodUpdater<S, T> {
    /// Starts the worker with `state`, built from `map` (the worker keeps its own copy of
    /// `map`, which `submit` keeps current). Fails when `state` was not built over a map of
    /// `map`'s size or cannot be updated by rects.
    pub fn spawn(state: S, map: &HeightMap<T>) -> Result<Self, LodError> {
        if state.map_size() != map.size() {
            return Err(LodError::SizeMismatch {
                expected: state.map_size(),
                actual: map.size(),
            });
        }
        state.check_updatable()?;
        let (changes, jobs) = channel::<Job<S, T>>();
        let (publish, published) = channel::<Published<S>>();
        let state = Arc::new(state);
        let (worker_state, worker_map) = (Arc::clone(&state), map.clone());
        let worker = std::thread::Builder::new()
            .name("lod-updater".into())
            .spawn(move || run(worker_state, worker_map, &jobs, &publish))
            .map_err(|_| LodError::UpdaterStopped("could not start"))?;
        Ok(Self {
            map_size: map.size(),
            wrap: state.wrap(),
            state,
            changed: Vec::new(),
            changes: Some(changes),
            published,
            worker: Some(worker),
            submitted: 0,
            applied: 0,
        })
    }

    /// The newest snapshot taken in by [`LodUpdater::poll`] or [`LodUpdater::flush`].
    pub fn state(&self) -> &Arc<S> {
        &self.state
    }

    /// What the snapshots taken in so far changed, since the last call.
    pub fn take_changes(&mut self) -> Vec<S::Change> {
        std::mem::take(&mut self.changed)
    }

    /// Changes submitted and not yet in [`LodUpdater::state`].
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
            .send(Job::Change(Change { rect, heights }))
            .map_err(|_| worker_gone())?;
        self.submitted += 1;
        Ok(())
    }

    /// Takes in the newest snapshot the worker published, without waiting; `true` when the
    /// data changed. A failed update is returned here.
    pub fn poll(&mut self) -> Result<bool, LodError> {
        let mut changed = false;
        loop {
            match self.published.try_recv() {
                Ok(snapshot) => {
                    self.take_in(snapshot)?;
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

    /// Waits until every submitted change is in [`LodUpdater::state`].
    pub fn flush(&mut self) -> Result<(), LodError> {
        self.poll()?;
        while self.applied < self.submitted {
            let snapshot = self.published.recv().map_err(|_| worker_gone())?;
            self.take_in(snapshot)?;
        }
        Ok(())
    }

    fn take_in(&mut self, snapshot: Published<S>) -> Result<(), LodError> {
        let (state, changed, applied) = snapshot?;
        let old = std::mem::replace(&mut self.state, state);
        if let Some(sender) = &self.changes {
            // A worker gone frees nothing: the old snapshot is dropped here instead.
            let _ = sender.send(Job::Retire(old));
        }
        self.changed.extend(changed);
        self.applied = applied;
        Ok(())
    }
}

impl<T: HeightSample + Send + Sync + 'static> LodUpdater<CdlodTree, T> {
    /// The newest quadtree taken in (the same as [`LodUpdater::state`]).
    pub fn tree(&self) -> &Arc<CdlodTree> {
        &self.state
    }
}

impl<S: RectUpdate, T: HeightSample + Send + Sync + 'static> Drop for LodUpdater<S, T> {
    fn drop(&mut self) {
        // Closing the channel ends the worker's loop.
        self.changes = None;
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}

fn worker_gone() -> LodError {
    LodError::UpdaterStopped("stopped (a panic in an update)")
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

/// The worker: takes every change waiting, writes them into its map, updates its data and
/// publishes a snapshot; until the caller's side is dropped.
fn run<S: RectUpdate, T: HeightSample>(
    mut state: Arc<S>,
    mut map: HeightMap<T>,
    jobs: &Receiver<Job<S, T>>,
    publish: &Sender<Published<S>>,
) {
    let mut applied = 0u64;
    while let Ok(first) = jobs.recv() {
        // Retired snapshots are dropped as they come.
        let batch: Vec<Change<T>> = std::iter::once(first)
            .chain(jobs.try_iter())
            .filter_map(|job| match job {
                Job::Change(change) => Some(change),
                Job::Retire(old) => {
                    drop(old);
                    None
                }
            })
            .collect();
        if batch.is_empty() {
            continue;
        }
        let mut changed = Vec::new();
        let result = (|| {
            for change in &batch {
                write_wrapped(&mut map, change);
            }
            // Copy-on-write: the caller holds the published snapshot.
            let state = Arc::make_mut(&mut state);
            for change in &batch {
                state.update_rect(&map, change.rect, &mut changed)?;
            }
            Ok(())
        })();
        applied += batch.len() as u64;
        let snapshot = result.map(|()| (Arc::clone(&state), changed, applied));
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
