//! What a granular map stepped elsewhere (on a GPU) sends back to the CPU: the areas a step
//! changed and each step's measures. The contract between the crate that steps (terrain-gpu)
//! and those that keep the world's copy (terrain-cache's trails), which never name each other.

use crate::{Grid, Rect};

/// What one step measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepMeasure {
    /// The tag the step was requested with (the frame that stepped, say).
    pub tag: u64,
    /// The u64 sum of the map's heights after the step.
    pub volume: u64,
    /// Material the step's compression removed, in height units.
    pub removed: u64,
}

/// What came back from earlier steps of a granular map.
#[derive(Debug, Default)]
pub struct GranularArrivals {
    /// Changed areas, in request order: map texels and their fixed-point heights.
    pub areas: Vec<(Rect, Grid<u32>)>,
    /// Steps' measures (volume after the step, material removed), oldest first.
    pub measured: Vec<StepMeasure>,
    /// Whether anything (an area or a measure) is still on its way.
    pub in_flight: bool,
}
