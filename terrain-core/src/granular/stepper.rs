//! The contract between a granular map's CPU owner (terrain-cache's `GranularTrails`, which
//! keeps the world's tiles) and what steps it elsewhere (terrain-gpu's `FieldStepper`), which
//! never name each other: [`GranularStepper`].

use super::{GranularArrivals, GranularObject, GranularParams};
use crate::FixedPointMap;
use glam::IVec2;

/// The GPU side of terrain-cache's `GranularTrails`: a granular map stepped on the GPU, what
/// comes back read without a wait. terrain-gpu's `granular::FieldStepper` implements it over
/// its `GranularField`; an application that submits and times the GPU work its own way
/// implements it over the field's calls.
pub trait GranularStepper {
    /// What a failed call reports (an application may use `anyhow::Error`).
    type Error: std::fmt::Display + std::fmt::Debug;

    /// Uploads `map` (the window's scratch map): its steps run on the GPU from now on.
    fn start(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<(), Self::Error>;

    /// One step with `objects` (in the map's frame), its measures tagged `tag`; returns what
    /// has arrived of earlier steps, never waiting.
    fn step(
        &mut self,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<GranularArrivals, Self::Error>;

    /// What has arrived of earlier steps, never waiting.
    fn poll(&mut self) -> Result<GranularArrivals, Self::Error>;

    /// Waits (bounded) for everything on its way and frees the map.
    fn stop(&mut self) -> Result<GranularArrivals, Self::Error>;

    /// Whether [`shift`](Self::shift) moves the map on without a wait. `false` (the default):
    /// a window that moves on is stopped first, waiting for what is on its way.
    fn shifts(&self) -> bool {
        false
    }

    /// Moves the steps onto `map`, the next window, whose origin lies `offset` texels from the
    /// current map's, without a wait: the columns the two share become the GPU map's own
    /// (after every step so far), whatever `map` holds there. The first arrivals of the new
    /// map, before any step's: its sum (a measure tagged `tag`, nothing removed) and its shared
    /// texels. The old map's areas and measures arrive through [`poll_retired`](Self::poll_retired).
    /// Only called when [`shifts`](Self::shifts) says so and nothing of an earlier shift is
    /// still on its way; returns whether it moved (the default: never).
    fn shift(&mut self, map: &FixedPointMap, offset: IVec2, tag: u64) -> Result<bool, Self::Error> {
        let _ = (map, offset, tag);
        Ok(false)
    }

    /// What has arrived of the map the last [`shift`](Self::shift) moved away from (areas in
    /// its own frame), never waiting; `in_flight` false once all of it has.
    fn poll_retired(&mut self) -> Result<GranularArrivals, Self::Error> {
        Ok(GranularArrivals::default())
    }

    /// Waits (bounded) for everything of that map still on its way.
    fn drain_retired(&mut self) -> Result<GranularArrivals, Self::Error> {
        Ok(GranularArrivals::default())
    }
}

/// The tag of the measure a [`GranularStepper::shift`] returns first: the moved map's sum.
pub const SHIFT_TAG: u64 = u64::MAX;

/// The stepper type of trails that never step on a GPU: pass
/// `None::<&mut CpuOnly>`. Every call fails, as there is no GPU behind it.
#[derive(Debug, Default, Clone, Copy)]
pub struct CpuOnly;

impl GranularStepper for CpuOnly {
    type Error = &'static str;

    fn start(&mut self, _: &FixedPointMap, _: GranularParams) -> Result<(), Self::Error> {
        Err(CPU_ONLY)
    }

    fn step(&mut self, _: &[GranularObject<'_>], _: u64) -> Result<GranularArrivals, Self::Error> {
        Err(CPU_ONLY)
    }

    fn poll(&mut self) -> Result<GranularArrivals, Self::Error> {
        Err(CPU_ONLY)
    }

    fn stop(&mut self) -> Result<GranularArrivals, Self::Error> {
        Err(CPU_ONLY)
    }
}

const CPU_ONLY: &str = "CpuOnly has no GPU: pass None as the stepper";
