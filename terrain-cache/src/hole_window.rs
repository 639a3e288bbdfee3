//! [`HoleWindow`]: a streamed world's holes around the camera, for a renderer that draws them
//! from a window of cells (terrain-core's [`HoleWindowTarget`]; terrain-gpu's hole mask
//! window). The window is centred on the camera (inside a clamped world), moved only once the
//! place it should be is more than an eighth of its side away (so a walking camera re-reads
//! it every few hundred cells, not every frame), and kept current with the cuts
//! terrain-cache's `OverlayWriter` reports in between. Its edges inside the world stay about
//! three eighths of a side (less a cell) from the camera: make it wide enough that a hole
//! appearing there is lost in the fog.

use crate::overlays::read_holes;
use crate::{CacheError, World};
use glam::{I64Vec2, IVec2, UVec2, Vec2};
use terrain_core::{Grid, HoleWindowTarget, Rect, WrapMode};

/// The widest hole window, in cells (256 MiB of mask).
pub const MAX_HOLE_WINDOW_SIDE: u32 = 16_384;

/// Why [`HoleWindow::follow`] failed.
#[derive(Debug, thiserror::Error)]
pub enum HoleWindowError<E> {
    /// A bad camera position, or a hole tile that could not be read.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// The target refused a placement or an update; its error, unchanged.
    #[error("the hole window's target failed")]
    Target(#[source] E),
}

/// The holes around the camera (see the module docs).
#[derive(Debug, Clone)]
pub struct HoleWindow {
    side: u32,
    origin: Option<IVec2>,
}

impl HoleWindow {
    /// A window of `side` x `side` cells (at most the world's side), placed by the first
    /// [`HoleWindow::follow`]. Fails on a side outside `8 ..= MAX_HOLE_WINDOW_SIDE`.
    pub fn new(side: u32) -> Result<Self, CacheError> {
        if !(8..=MAX_HOLE_WINDOW_SIDE).contains(&side) {
            return Err(CacheError::OutOfRange {
                what: "hole window side (cells)",
                value: f64::from(side),
                expected: "8 ..= 16384",
            });
        }
        Ok(Self { side, origin: None })
    }

    /// The side, in cells, of the masks this window places on `world`: the side it was made
    /// with, or the world's shorter side where that is smaller. Make the target's window this
    /// size (terrain-gpu's `GpuHoleMask::window(device, side)`).
    pub fn side_on(&self, world: &World) -> u32 {
        self.side.min(world.manifest().world_size.min_element())
    }

    /// The world cells the window covers now (`None` before it is placed).
    pub fn rect(&self, world: &World) -> Option<Rect> {
        let side = self.side_on(world);
        self.origin.map(|o| Rect::new(o, UVec2::splat(side)))
    }

    /// One frame with the camera at `xz` (world metres): `cuts` are the rects the world's
    /// holes changed in since the last call, with their masks (the `OverlayChange::Holes` of
    /// an `OverlayWriter`). Places the window when it must move (reading its holes from the
    /// world: the cuts are in them), else writes the cuts into it. Returns whether it was
    /// placed. Fails on a camera position that is not finite, a hole tile that does not read,
    /// or the target's error: after a failed placement or update the next call places the
    /// window again (reading every cut from the world, so none is lost).
    pub fn follow<T: HoleWindowTarget>(
        &mut self,
        world: &World,
        xz: Vec2,
        cuts: &[(Rect, Grid<u8>)],
        target: &mut T,
    ) -> Result<bool, HoleWindowError<T::Error>> {
        if !xz.is_finite() {
            return Err(CacheError::OutOfRange {
                what: "camera position (m)",
                value: f64::from(if xz.x.is_finite() { xz.y } else { xz.x }),
                expected: "finite",
            }
            .into());
        }
        let m = world.manifest();
        let side = UVec2::splat(self.side_on(world));
        // In i64: a camera far off the world must not overflow the cell arithmetic.
        let cell = (xz.as_dvec2() / f64::from(m.texel_size)).floor();
        let limit = f64::from(i32::MAX / 2);
        let cell = cell.clamp(glam::DVec2::splat(-limit), glam::DVec2::splat(limit));
        let centred = cell.as_i64vec2() - I64Vec2::from(side / 2);
        let origin = match m.wrap {
            WrapMode::Clamp => {
                let last = (m.world_size - side).as_i64vec2();
                centred.max(I64Vec2::ZERO).min(last)
            }
            // Anywhere on a repeating world: the rect wraps.
            WrapMode::Repeat => centred,
        }
        .as_ivec2();
        // Moved once the place it should be is more than an eighth of a side away: near a
        // clamped world's edge that place stays put, so the window does too.
        let eighth = I64Vec2::from(side / 8);
        let moved = self.origin.is_none_or(|at| {
            let off = (origin.as_i64vec2() - at.as_i64vec2()).abs();
            off.cmpgt(eighth).any()
        });
        // On a repeating world a cut's rect and the window may be a period apart: read the
        // window again.
        let repeat = m.wrap == WrapMode::Repeat && !cuts.is_empty();
        if moved || repeat {
            // Until a placement succeeds the target may lack `cuts` (the caller has them no
            // more): the next call places the window again, reading them from the world.
            self.origin = None;
            let mask = read_holes(world, Rect::new(origin, side))?;
            target
                .place(origin, &mask)
                .map_err(HoleWindowError::Target)?;
            self.origin = Some(origin);
            return Ok(true);
        }
        for (rect, mask) in cuts {
            if let Err(e) = target.update(*rect, mask) {
                // The cuts after it are lost to the window: the next call reads it whole.
                self.origin = None;
                return Err(HoleWindowError::Target(e));
            }
        }
        Ok(false)
    }
}
