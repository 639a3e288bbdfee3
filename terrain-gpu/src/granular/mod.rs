//! GPU passes of volume-preserving granular deformation (Persson 2019 chapter 4), each the GPU side
//! of a step of `terrain_core::granular`.
//!
//! The integer passes ([`PenetrationPass`], [`JumpFloodPass`], [`DisplacePass`],
//! [`SlopePass`]) reproduce the CPU reference bit for bit; [`GranularNormalsPass`] is a float
//! pass that agrees within a tolerance; [`VolumePass`] sums a map exactly; [`TrailEffectPass`]
//! paints the columns a step presses down on a material layer. Heights live in a
//! [`crate::GpuHeightMap<u32>`] (one u32 per column); per-area buffers in a
//! [`GranularScratch`], which a [`GranularArea`] pairs with the map and an area.
//! [`GpuGranularStep`] chains the passes over the merged active areas of a list of objects, as
//! `terrain_core::granular::GranularSim`.
//!
//! [`GranularField`] composes them into what an application drives once per frame: a map
//! stepped, shaded and measured, the changed areas read back without a wait, moved on to the
//! next window without one. [`FieldStepper`] steps a streamed world's granular trails with it
//! (terrain-core's `GranularStepper`).
//!
//! Every pass is built once with `new(&wgpu::Device)` (one shader module, its pipelines, bind
//! group layouts and a uniform ring) and records with `encode(&mut self, device, queue,
//! encoder, ..)`, which writes uniforms into the next slots of its ring and records commands;
//! call `recall()` on it after the submit that carries them.

mod depth;
mod field;
mod measures;
mod normals;
mod passes;
mod scratch;
mod step;
mod stepper;
mod trail;
mod upload;
mod volume;

pub use depth::{
    DepthArea, DepthFromBelowPass, MAX_RECORDS_PER_DISPATCH, MAX_TILE_SIDE, RECORD_TILE,
};
pub use field::{GranularField, GranularPasses, RetiredField};
pub use measures::{StepMeasure, StepMeasures};
pub use normals::{GpuGranularNormals, GranularNormalsPass};
pub use passes::{
    DisplacePass, FloodedArea, JumpFloodPass, PenetrationPass, SlopePass, SlopeSettings,
};
pub use scratch::{GranularArea, GranularScratch};
pub use step::{DepthSource, GpuGranularStep, GpuStepReport};
pub use stepper::{FieldStepper, Submitting};
pub use terrain_core::granular::GranularArrivals;
pub use trail::{Trail, TrailEffectPass};
pub use volume::VolumePass;

// The shaders' codes are terrain-core's values: a mismatch fails the build.
const _: () = {
    use terrain_core::granular::{ColumnKind, NO_OBJECT, NO_SEED};
    use terrain_shaders::codes;
    assert!(codes::SEED == ColumnKind::Seed as i32);
    assert!(codes::OBSTACLE == ColumnKind::Obstacle as i32);
    assert!(codes::PENETRATING == ColumnKind::Penetrating as i32);
    assert!(codes::NO_SEED == NO_SEED);
    assert!(codes::NO_OBJECT == NO_OBJECT);
};
