//! GPU passes of volume-preserving granular deformation (seed 001 chapter 4), each the GPU side
//! of a step of `terrain_core::granular`.
//!
//! The integer passes ([`PenetrationPass`], [`JumpFloodPass`], [`DisplacePass`],
//! [`SlopePass`]) reproduce the CPU reference bit for bit; [`GranularNormalsPass`] is a float
//! pass that agrees within a tolerance. Heights live in a [`GpuGranularMap`] (one u32 per
//! column); per-area textures in a [`GranularScratch`]. [`GpuGranularStep`] chains the passes
//! over the merged active areas of a list of objects, as `terrain_core::granular::GranularSim`.

pub mod depth;
mod map;
mod normals;
mod passes;
mod scratch;
mod step;

pub use depth::DepthFromBelowPass;
pub use map::GpuGranularMap;
pub use normals::GranularNormalsPass;
pub use passes::{DisplacePass, JumpFloodPass, PenetrationPass, SlopePass};
pub use scratch::GranularScratch;
pub use step::{DepthSource, GpuGranularStep, GpuStepReport};
