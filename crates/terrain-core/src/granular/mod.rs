//! Volume-preserving granular deformation (seed 001 chapter 4): the CPU reference (being written).
