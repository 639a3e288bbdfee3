//! What a streamed world lays over its heights: holes (`terrain_core::holes`, the world's hole
//! tiles) and paint (`terrain_core::material_effect`, its material tiles). A hole cut beside
//! the path, or a crater's dirt, is written into the world at once (atomically, tile by tile),
//! and the layers around the camera follow: the collision window's holes, and the GPU's hole,
//! paint and colour windows of [`GPU_WINDOW`] cells (colour where the world has it: an
//! orthophoto given with `--color`).
//! A second run reads both back from the world.

use crate::gpu_scene::GpuScene;
use anyhow::Result;
use glam::{IVec2, UVec2, Vec2};
use terrain_cache::{Layer, World, read_color, read_holes, read_paint, write_holes, write_paint};
use terrain_core::{
    HoleOp, MaterialEffect, Rect, StampPlacement, WrapMode, apply_hole_stamp, apply_material_effect,
};
use terrain_physics::CollisionWindow;

/// Side of the hole and paint windows the GPU draws (cells): 4 MiB of holes and 16 MiB of
/// paint. They move when the camera is more than an eighth of a side off their centre, so
/// their edges stay at least 768 cells away: 384 m at the default world's 0.5 m, where the
/// default fog (0.008 /m) hides 95 % of the ground, and a hole appearing there barely shows.
pub const GPU_WINDOW: u32 = 2048;

/// The layers that follow the camera over a streamed world.
#[derive(Debug)]
pub struct WorldOverlays {
    /// The collision window's rect its holes were read for.
    collision: Option<Rect>,
    /// The GPU windows' origin.
    gpu: Option<IVec2>,
    /// Whether the world has colour tiles (most have none: no colour window is read then).
    colored: bool,
    /// Rects cut or painted since the GPU's windows were last brought up to date, and which.
    changed: Vec<(Rect, Changed)>,
}

/// Which layer a change was made to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Changed {
    Holes,
    Paint,
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
    /// The layers of `world`, nothing read yet.
    pub fn new(world: &World) -> Result<Self> {
        let colored = !world.store().list(Layer::Color.folder())?.is_empty();
        Ok(Self {
            collision: None,
            gpu: None,
            colored,
            changed: Vec::new(),
        })
    }

    /// Cuts a hole at `placement` (world metres) into `world`'s hole tiles, and has the masks
    /// read again. Returns the tiles written.
    pub fn cut(&mut self, world: &World, placement: &StampPlacement) -> Result<u32> {
        let Some((rect, local)) = footprint(world, placement)? else {
            return Ok(0);
        };
        let mut region = read_holes(world, rect)?;
        let ts = world.manifest().texel_size;
        apply_hole_stamp(&mut region, WrapMode::Clamp, ts, &local, HoleOp::Cut)?;
        let written = write_holes(world, rect, &region)?;
        self.collision = None;
        self.changed.push((rect, Changed::Holes));
        Ok(written)
    }

    /// Paints `effect` over the footprint of a stamp at `placement` into `world`'s material
    /// tiles (the crater's dirt), and has the GPU's paint read again. Returns the tiles written.
    pub fn paint(
        &mut self,
        world: &World,
        placement: &StampPlacement,
        effect: &MaterialEffect,
    ) -> Result<u32> {
        let Some((rect, local)) = footprint(world, placement)? else {
            return Ok(0);
        };
        let mut region = read_paint(world, rect)?;
        let ts = world.manifest().texel_size;
        apply_material_effect(&mut region, WrapMode::Clamp, ts, &local, effect)?;
        let written = write_paint(world, rect, &region)?;
        self.changed.push((rect, Changed::Paint));
        Ok(written)
    }

    /// Brings the layers to the camera at `xz` (world metres): the collision window's holes
    /// when its rect changed, the GPU's holes, paint and colour when the place they should be
    /// (centred on the camera, inside a clamped world) is more than an eighth of their side
    /// from where they are.
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
            // Without a GPU there are no windows to bring up to date.
            self.changed.clear();
            return Ok(());
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
        let repeat = m.wrap == WrapMode::Repeat && !self.changed.is_empty();
        if moved || repeat {
            self.changed.clear();
            let rect = Rect::new(origin, side);
            scene.move_hole_window(side.x, origin, &read_holes(world, rect)?)?;
            scene.move_paint_window(side.x, origin, &read_paint(world, rect)?)?;
            if self.colored {
                scene.move_color_window(side.x, origin, &read_color(world, rect)?)?;
            }
            self.gpu = Some(origin);
        }
        // What was cut or painted since: only its rect, read again and written into the
        // windows (the parts they cover).
        for (rect, layer) in std::mem::take(&mut self.changed) {
            match layer {
                Changed::Holes => {
                    scene.update_windows(rect, Some(&read_holes(world, rect)?), None)?
                }
                Changed::Paint => {
                    scene.update_windows(rect, None, Some(&read_paint(world, rect)?))?
                }
            }
        }
        Ok(())
    }
}
