//! What a streamed world lays over its heights: holes (`terrain_core::holes`, the world's hole
//! tiles) and paint (`terrain_core::material_effect`, its material tiles). A hole cut beside
//! the path, or a crater's dirt, is written into the world on a thread of its own (in order,
//! atomically, tile by tile, the paint's coarser levels with it), and what draws and collides
//! follows: the collision window's holes and the GPU's hole window of [`GPU_WINDOW`] cells
//! around the camera, and the paint tiles the scenario's paint stream must read again
//! (`terrain_cache::OverlayStream::reload`). A second run reads them back from the world.

use crate::gpu_scene::GpuScene;
use anyhow::{Result, anyhow};
use glam::{IVec2, UVec2, Vec2};
use std::sync::mpsc;
use terrain_cache::{TileId, World, read_holes, read_paint, write_holes, write_paint};
use terrain_core::{
    Grid, HoleOp, MaterialEffect, Rect, StampPlacement, WrapMode, apply_hole_stamp,
    apply_material_effect,
};
use terrain_physics::CollisionWindow;

/// Side of the hole window the GPU draws (cells): 4 MiB. It moves when the camera is more than
/// an eighth of a side off its centre, so its edges stay at least 768 cells away: 384 m at the
/// default world's 0.5 m, where the default fog (0.008 /m) hides 95 % of the ground, and a
/// hole appearing there barely shows.
pub const GPU_WINDOW: u32 = 2048;

/// A change to make to the world.
#[derive(Debug, Clone, Copy)]
enum Job {
    /// Cut a hole at the placement.
    Cut(StampPlacement),
    /// Paint the effect over the placement's footprint.
    Paint(StampPlacement, MaterialEffect),
}

/// What a job changed: the cells of a cut as the world now holds them, or the paint tiles
/// (every level) rewritten.
#[derive(Debug)]
enum Changed {
    Holes(Rect, Grid<u8>),
    Paint(Vec<TileId>),
}

/// The thread that writes the jobs into the world, one after the other: a job reads what the
/// ones before it wrote.
#[derive(Debug)]
struct Writer {
    jobs: Option<mpsc::Sender<Job>>,
    done: mpsc::Receiver<Result<Option<Changed>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Writer {
    fn start(world: World) -> Result<Self> {
        let (jobs, queue) = mpsc::channel::<Job>();
        let (report, done) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("world overlays".into())
            .spawn(move || {
                for job in queue {
                    if report.send(apply(&world, job)).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self {
            jobs: Some(jobs),
            done,
            thread: Some(thread),
        })
    }

    fn send(&self, job: Job) -> Result<()> {
        self.jobs
            .as_ref()
            .and_then(|jobs| jobs.send(job).ok())
            .ok_or_else(|| anyhow!("the world overlays' writer has stopped"))
    }

    /// Waits for every job sent and returns what they changed.
    fn finish(&mut self) -> Result<Vec<Changed>> {
        self.jobs = None;
        if let Some(thread) = self.thread.take() {
            thread
                .join()
                .map_err(|_| anyhow!("the world overlays' writer panicked"))?;
        }
        self.done.try_iter().filter_map(Result::transpose).collect()
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        // The queued jobs are written before the run ends (their errors were the run's).
        let _ = self.finish();
    }
}

/// Makes `job`'s change in `world`: reads the cells, changes them, writes them back.
fn apply(world: &World, job: Job) -> Result<Option<Changed>> {
    let ts = world.manifest().texel_size;
    let placement = match job {
        Job::Cut(p) | Job::Paint(p, _) => p,
    };
    let Some((rect, local)) = footprint(world, &placement)? else {
        return Ok(None);
    };
    Ok(Some(match job {
        Job::Cut(_) => {
            let mut region = read_holes(world, rect)?;
            apply_hole_stamp(&mut region, WrapMode::Clamp, ts, &local, HoleOp::Cut)?;
            write_holes(world, rect, &region)?;
            Changed::Holes(rect, region)
        }
        Job::Paint(_, effect) => {
            let mut region = read_paint(world, rect)?;
            apply_material_effect(&mut region, WrapMode::Clamp, ts, &local, &effect)?;
            Changed::Paint(write_paint(world, rect, &region)?)
        }
    }))
}

/// The layers that follow the camera over a streamed world.
#[derive(Debug)]
pub struct WorldOverlays {
    /// The collision window's rect its holes were read for.
    collision: Option<Rect>,
    /// The GPU hole window's origin.
    gpu: Option<IVec2>,
    writer: Writer,
}

/// The cells of a stamp's footprint on the world (clamped to a clamped world; a repeating
/// world's rect wraps in the region reads and writes), and the placement in those cells' own
/// frame; `None` for a footprint off a clamped world.
fn footprint(world: &World, placement: &StampPlacement) -> Result<Option<(Rect, StampPlacement)>> {
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

impl WorldOverlays {
    /// The layers of `world`, nothing read yet, and the thread that writes into it.
    pub fn new(world: &World) -> Result<Self> {
        Ok(Self {
            collision: None,
            gpu: None,
            writer: Writer::start(world.clone())?,
        })
    }

    /// Cuts a hole at `placement` (world metres) into the world's hole tiles, off the frame
    /// thread; a later [`WorldOverlays::follow`] brings it to collision and the GPU.
    pub fn cut(&mut self, placement: &StampPlacement) -> Result<()> {
        self.writer.send(Job::Cut(*placement))
    }

    /// Paints `effect` over the footprint of a stamp at `placement` into the world's material
    /// tiles (the crater's dirt), off the frame thread, as [`WorldOverlays::cut`] cuts.
    pub fn paint(&mut self, placement: &StampPlacement, effect: &MaterialEffect) -> Result<()> {
        self.writer.send(Job::Paint(*placement, *effect))
    }

    /// Waits until every cut and paint is in the world's files (the end of a run).
    pub fn finish(&mut self) -> Result<()> {
        self.writer.finish().map(|_| ())
    }

    /// Brings the holes to the camera at `xz` (world metres): the collision window's when its
    /// rect changed, the GPU's window when the place it should be (centred on the camera,
    /// inside a clamped world) is more than an eighth of its side from where it is. Returns
    /// the paint tiles the writer rewrote since the last call.
    pub fn follow(
        &mut self,
        world: &World,
        window: &CollisionWindow,
        xz: Vec2,
        scene: Option<&mut GpuScene>,
    ) -> Result<Vec<TileId>> {
        // What the writer has finished since the last frame (a failure ends the run).
        let mut changed = Vec::new();
        let mut painted = Vec::new();
        for done in self.writer.done.try_iter() {
            match done? {
                Some(Changed::Holes(rect, mask)) => {
                    self.collision = None;
                    changed.push((rect, mask));
                }
                Some(Changed::Paint(tiles)) => painted.extend(tiles),
                None => {}
            }
        }
        if let Some(rect) = window.window()
            && self.collision != Some(rect)
        {
            window.set_holes(Some(&read_holes(world, rect)?))?;
            self.collision = Some(rect);
        }
        let Some(scene) = scene else {
            return Ok(painted);
        };
        let m = world.manifest();
        let side = UVec2::splat(GPU_WINDOW.min(m.world_size.min_element()));
        let cell = (xz / m.texel_size).floor().as_ivec2();
        let centred = cell - (side / 2).as_ivec2();
        // Inside a clamped world; anywhere on a repeating one (the rect wraps).
        let origin = match m.wrap {
            WrapMode::Clamp => centred
                .max(IVec2::ZERO)
                .min((m.world_size - side).as_ivec2()),
            WrapMode::Repeat => centred,
        };
        // Moved once the place it should be is an eighth of a side away: near a clamped
        // world's edge that place stays put, so the window does too.
        let moved = self
            .gpu
            .is_none_or(|at| (origin - at).abs().cmpgt((side / 8).as_ivec2()).any());
        // On a repeating world a change's rect and the windows may be a period apart: read
        // the windows again.
        let repeat = m.wrap == WrapMode::Repeat && !changed.is_empty();
        if moved || repeat {
            changed.clear();
            let rect = Rect::new(origin, side);
            scene.move_hole_window(side.x, origin, &read_holes(world, rect)?)?;
            self.gpu = Some(origin);
        }
        // What was cut since: only its rect, written into the window (the part it covers).
        for (rect, mask) in changed {
            scene.update_hole_window(rect, &mask)?;
        }
        Ok(painted)
    }
}
