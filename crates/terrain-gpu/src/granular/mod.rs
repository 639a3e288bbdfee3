//! GPU passes of volume-preserving granular deformation (seed 001 chapter 4), each the GPU side
//! of a step of `terrain_core::granular` (being written).

pub mod depth;
