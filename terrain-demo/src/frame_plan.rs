//! What one frame of the default scenario deforms: the stamps in order and the shockwave's
//! change. Shared by the scenario that plans it and the GPU scene that applies it, so neither
//! imports the other.

use glam::Vec2;
use terrain_core::{StampPlacement, TextureStamp};

/// Which pattern a deformation uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StampKind {
    /// The footprint texture stamp.
    Footprint,
    /// The Gaussian crater.
    Crater,
    /// The shockwave's change since the last frame (a dynamic texture stamp).
    Shockwave,
}

/// One stamp to apply this frame (always an additive blend).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deformation {
    /// The pattern.
    pub kind: StampKind,
    /// Where.
    pub placement: StampPlacement,
}

/// Everything one frame deforms.
#[derive(Debug, Default)]
pub struct FramePlan {
    /// Stamps in order.
    pub deformations: Vec<Deformation>,
    /// The shockwave's change this frame, used by [`StampKind::Shockwave`].
    pub shock_delta: Option<TextureStamp>,
    /// The walker's position (metres, X Z) and unit heading after this frame's steps.
    pub walker: (Vec2, Vec2),
    /// A hole cut into the ground this frame (`terrain_core::holes`: the cells inside the
    /// placement's ellipse).
    pub hole: Option<StampPlacement>,
}

impl FramePlan {
    /// Number of stamps of `kind`.
    pub fn count(&self, kind: StampKind) -> u32 {
        self.deformations.iter().filter(|d| d.kind == kind).count() as u32
    }
}
