//! What a streamed world lays over its heights: holes (`terrain_core::holes`, the world's hole
//! tiles) and paint (`terrain_core::material_effect`, its material tiles). A hole cut beside
//! the path, or a crater's dirt, is written into the world by terrain-cache's `OverlayWriter`
//! (on a thread of its own, in order, atomically tile by tile), and what draws and collides
//! follows: the collision window's holes and the GPU's hole window of [`GPU_WINDOW`] cells
//! around the camera (terrain-cache's `HoleWindow`), and the paint tiles the scenario's paint stream must read again
//! (`terrain_cache::OverlayStream::reload`). A second run reads them back from the world.

use crate::gpu_scene::GpuScene;
use anyhow::Result;
use glam::Vec2;
use terrain_cache::{
    HoleWindow, OverlayChange, OverlayJob, OverlayWriter, TileId, World, read_holes,
};
use terrain_core::{MaterialEffect, Rect, StampPlacement};
use terrain_physics::CollisionWindow;

/// Side of the hole window the GPU draws (cells): 4 MiB. It moves when the camera is more than
/// an eighth of a side off its centre, so its edges stay at least 768 cells away: 384 m at the
/// default world's 0.5 m, where the default fog (0.008 /m) hides 95 % of the ground, and a
/// hole appearing there barely shows.
pub const GPU_WINDOW: u32 = 2048;

/// The layers that follow the camera over a streamed world.
#[derive(Debug)]
pub struct WorldOverlays {
    /// The collision window's rect its holes were read for.
    collision: Option<Rect>,
    /// The GPU's hole window.
    gpu: HoleWindow,
    writer: OverlayWriter,
}

impl WorldOverlays {
    /// The layers of `world`, nothing read yet, and the thread that writes into it.
    pub fn new(world: &World) -> Result<Self> {
        Ok(Self {
            collision: None,
            gpu: HoleWindow::new(GPU_WINDOW)?,
            writer: OverlayWriter::start(world.clone())?,
        })
    }

    /// Cuts a hole at `placement` (world metres) into the world's hole tiles, off the frame
    /// thread; a later [`WorldOverlays::follow`] brings it to collision and the GPU.
    pub fn cut(&mut self, placement: &StampPlacement) -> Result<()> {
        Ok(self.writer.send(OverlayJob::Cut(*placement))?)
    }

    /// Paints `effect` over the footprint of a stamp at `placement` into the world's material
    /// tiles (the crater's dirt), off the frame thread, as [`WorldOverlays::cut`] cuts.
    pub fn paint(&mut self, placement: &StampPlacement, effect: &MaterialEffect) -> Result<()> {
        Ok(self.writer.send(OverlayJob::Paint(*placement, *effect))?)
    }

    /// Waits until every cut and paint is in the world's files (the end of a run).
    pub fn finish(&mut self) -> Result<()> {
        self.writer.finish()?;
        Ok(())
    }

    /// Brings the holes to the camera at `xz` (world metres): the collision window's when its
    /// rect changed, the GPU's window as `HoleWindow::follow` places it. Returns the paint
    /// tiles the writer rewrote since the last call.
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
        for done in self.writer.poll() {
            match done? {
                Some(OverlayChange::Holes(rect, mask)) => {
                    self.collision = None;
                    changed.push((rect, mask));
                }
                Some(OverlayChange::Paint(tiles)) => painted.extend(tiles),
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
        let mut target = scene.hole_window(self.gpu.side_on(world))?;
        self.gpu.follow(world, xz, &changed, &mut target)?;
        Ok(painted)
    }
}
