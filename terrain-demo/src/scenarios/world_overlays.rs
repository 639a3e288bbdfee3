//! What a streamed world lays over its heights: holes (`terrain_core::holes`, the world's hole
//! tiles) and paint (`terrain_core::material_effect`, its material tiles). A hole cut beside
//! the path, or a crater's dirt, is written into the world by terrain-cache's `OverlayWriter`
//! (on a thread of its own, in order, atomically tile by tile), and what draws and collides
//! follows: the collision window's holes and the GPU's hole window of [`GPU_WINDOW`] cells
//! around the camera, and the paint tiles the scenario's paint stream must read again
//! (`terrain_cache::OverlayStream::reload`). A second run reads them back from the world.

use crate::gpu_scene::GpuScene;
use anyhow::Result;
use glam::{IVec2, UVec2, Vec2};
use terrain_cache::{OverlayChange, OverlayJob, OverlayWriter, TileId, World, read_holes};
use terrain_core::{MaterialEffect, Rect, StampPlacement, WrapMode};
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
    /// The GPU hole window's origin.
    gpu: Option<IVec2>,
    writer: OverlayWriter,
}

impl WorldOverlays {
    /// The layers of `world`, nothing read yet, and the thread that writes into it.
    pub fn new(world: &World) -> Result<Self> {
        Ok(Self {
            collision: None,
            gpu: None,
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
