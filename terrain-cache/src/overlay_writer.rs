//! [`OverlayWriter`]: holes cut and paint laid into a world's overlay tiles (`terrain_core`'s
//! holes and material effects, [`crate::write_holes`], [`crate::write_paint`]) on a thread of
//! its own, in the order they were sent, so a frame never waits on the files: each job reads
//! the cells the ones before it wrote, changes them, writes them back atomically tile by tile
//! (the paint's coarser levels with it), and reports what changed for the caller to bring to
//! what draws and collides (the hole cells, the paint tiles to read again).

use crate::{CacheError, TileId, World, read_holes, read_paint, write_holes, write_paint};
use std::sync::mpsc;
use terrain_core::{
    Grid, HoleOp, MaterialEffect, Rect, StampPlacement, WrapMode, apply_hole_stamp,
    apply_material_effect,
};

/// A change to make to the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OverlayJob {
    /// Cut a hole over the placement's footprint (world metres).
    Cut(StampPlacement),
    /// Paint the effect over the placement's footprint.
    Paint(StampPlacement, MaterialEffect),
}

/// What a job changed.
#[derive(Debug, Clone, PartialEq)]
pub enum OverlayChange {
    /// The cells of a cut (level-0 texels) as the world now holds them.
    Holes(Rect, Grid<u8>),
    /// The paint tiles rewritten, every level.
    Paint(Vec<TileId>),
}

/// The thread that writes [`OverlayJob`]s into a world (module docs).
#[derive(Debug)]
pub struct OverlayWriter {
    jobs: Option<mpsc::Sender<OverlayJob>>,
    done: mpsc::Receiver<Result<Option<OverlayChange>, CacheError>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl OverlayWriter {
    /// Starts the thread writing into `world`.
    pub fn start(world: World) -> Result<Self, CacheError> {
        let (jobs, queue) = mpsc::channel::<OverlayJob>();
        let (report, done) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("world overlays".into())
            .spawn(move || {
                for job in queue {
                    if report.send(apply(&world, job)).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| stopped(e.to_string()))?;
        Ok(Self {
            jobs: Some(jobs),
            done,
            thread: Some(thread),
        })
    }

    /// Queues `job`; fails once the thread has stopped.
    pub fn send(&self, job: OverlayJob) -> Result<(), CacheError> {
        self.jobs
            .as_ref()
            .and_then(|jobs| jobs.send(job).ok())
            .ok_or_else(|| stopped("it has stopped".into()))
    }

    /// What the jobs finished since the last call changed, in order, never waiting (`None`: a
    /// footprint off a clamped world, nothing changed); a job's failure is its entry's error.
    pub fn poll(&self) -> Vec<Result<Option<OverlayChange>, CacheError>> {
        self.done.try_iter().collect()
    }

    /// Waits for every job sent and returns what those not yet polled changed (the first
    /// failure ends it); the writer takes no job after this.
    pub fn finish(&mut self) -> Result<Vec<OverlayChange>, CacheError> {
        self.jobs = None;
        if let Some(thread) = self.thread.take() {
            thread.join().map_err(|_| stopped("it panicked".into()))?;
        }
        self.done.try_iter().filter_map(Result::transpose).collect()
    }
}

impl Drop for OverlayWriter {
    fn drop(&mut self) {
        // The queued jobs are written before the writer goes (their errors were the caller's
        // to take).
        let _ = self.finish();
    }
}

fn stopped(reason: String) -> CacheError {
    CacheError::Worker {
        what: "world overlays",
        reason,
    }
}

/// Makes `job`'s change in `world`: reads the cells, changes them, writes them back.
fn apply(world: &World, job: OverlayJob) -> Result<Option<OverlayChange>, CacheError> {
    let ts = world.manifest().texel_size;
    let placement = match job {
        OverlayJob::Cut(p) | OverlayJob::Paint(p, _) => p,
    };
    let Some((rect, local)) = footprint(world, &placement)? else {
        return Ok(None);
    };
    Ok(Some(match job {
        OverlayJob::Cut(_) => {
            let mut region = read_holes(world, rect)?;
            apply_hole_stamp(&mut region, WrapMode::Clamp, ts, &local, HoleOp::Cut)?;
            write_holes(world, rect, &region)?;
            OverlayChange::Holes(rect, region)
        }
        OverlayJob::Paint(_, effect) => {
            let mut region = read_paint(world, rect)?;
            apply_material_effect(&mut region, WrapMode::Clamp, ts, &local, &effect)?;
            OverlayChange::Paint(write_paint(world, rect, &region)?)
        }
    }))
}

/// The cells of a stamp's footprint on the world (clamped to a clamped world; a repeating
/// world's rect wraps in the region reads and writes), and the placement in those cells' own
/// frame; `None` for a footprint off a clamped world.
fn footprint(
    world: &World,
    placement: &StampPlacement,
) -> Result<Option<(Rect, StampPlacement)>, CacheError> {
    let m = world.manifest();
    let footprint = placement.footprint(m.texel_size)?;
    let rect = match m.wrap {
        WrapMode::Clamp => match footprint.intersect(&Rect::from_size(m.world_size)) {
            Some(r) => r,
            None => return Ok(None),
        },
        WrapMode::Repeat => footprint,
    };
    let local = StampPlacement {
        center: placement.center - rect.min.as_vec2() * m.texel_size,
        ..*placement
    };
    local.validate()?;
    Ok(Some((rect, local)))
}
