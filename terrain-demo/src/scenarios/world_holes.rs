//! Holes in a streamed world (`terrain_core::holes`, the world's hole tiles): a hole cut beside
//! the path is written into the world at once (atomically, tile by tile), and the hole masks
//! around the camera follow it, one for collision (the collision window's rect) and one the
//! GPU draws (a window of [`GPU_WINDOW`] cells, moved when the camera leaves its middle half).
//! A second run reads the holes back from the world.

use crate::gpu_scene::GpuScene;
use anyhow::Result;
use glam::{IVec2, UVec2, Vec2};
use terrain_cache::{World, read_holes, write_holes};
use terrain_core::{HoleOp, Rect, StampPlacement, WrapMode, apply_hole_stamp};
use terrain_physics::CollisionWindow;

/// Side of the hole window the GPU draws (cells): 1 MiB, holes within about 500 cells of the
/// camera.
pub const GPU_WINDOW: u32 = 1024;

/// The hole masks that follow the camera over a streamed world.
#[derive(Debug, Default)]
pub struct WorldHoles {
    /// The collision window's rect its holes were read for.
    collision: Option<Rect>,
    /// The GPU window's origin.
    gpu: Option<IVec2>,
}

impl WorldHoles {
    /// Cuts a hole at `placement` (world metres) into `world`'s hole tiles, and has both masks
    /// read again. Returns the tiles written.
    pub fn cut(&mut self, world: &World, placement: &StampPlacement) -> Result<u32> {
        let m = world.manifest();
        let footprint = placement.footprint(m.texel_size)?;
        // The footprint's cells on the world (clamped to a clamped world; a repeating world's
        // rect wraps in read_holes and write_holes).
        let rect = match m.wrap {
            WrapMode::Clamp => match footprint.intersect(&Rect::from_size(m.world_size)) {
                Some(r) => r,
                None => return Ok(0),
            },
            WrapMode::Repeat => footprint,
        };
        let mut region = read_holes(world, rect)?;
        // The placement in the region's own cells.
        let local = StampPlacement {
            center: placement.center - rect.min.as_vec2() * m.texel_size,
            ..*placement
        };
        local.validate()?;
        apply_hole_stamp(
            &mut region,
            WrapMode::Clamp,
            m.texel_size,
            &local,
            HoleOp::Cut,
        )?;
        let written = write_holes(world, rect, &region)?;
        self.collision = None;
        self.gpu = None;
        Ok(written)
    }

    /// Brings the masks to the camera at `xz` (world metres): the collision window's when its
    /// rect changed, the GPU's when the camera left its middle half.
    pub fn follow(
        &mut self,
        world: &World,
        window: &CollisionWindow,
        xz: Vec2,
        scene: Option<&mut GpuScene>,
    ) -> Result<()> {
        if let Some(rect) = window.window()
            && self.collision != Some(rect)
        {
            window.set_holes(Some(&read_holes(world, rect)?))?;
            self.collision = Some(rect);
        }
        let Some(scene) = scene else {
            return Ok(());
        };
        let m = world.manifest();
        let side = UVec2::splat(GPU_WINDOW.min(m.world_size.min_element()));
        let cell = (xz / m.texel_size).floor().as_ivec2();
        let centred = cell - (side / 2).as_ivec2();
        let moved = match self.gpu {
            None => true,
            Some(origin) => {
                let off = (cell - origin - (side / 2).as_ivec2()).abs();
                off.cmpgt((side / 4).as_ivec2()).any()
            }
        };
        if moved {
            // Inside a clamped world; anywhere on a repeating one (the rect wraps).
            let origin = match m.wrap {
                WrapMode::Clamp => centred
                    .max(IVec2::ZERO)
                    .min((m.world_size - side).as_ivec2()),
                WrapMode::Repeat => centred,
            };
            let mask = read_holes(world, Rect::new(origin, side))?;
            scene.move_hole_window(side.x, origin, &mask)?;
            self.gpu = Some(origin);
        }
        Ok(())
    }
}
