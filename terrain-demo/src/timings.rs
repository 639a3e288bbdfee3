//! The steps a frame is timed in ([`Step`], named once for the report and the plot) and one
//! frame's measurements ([`Timings`]).

use std::collections::BTreeMap;
use std::time::Instant;

/// One timed step of a frame. [`Step::name`] is its key in `report.json`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Step {
    /// Stamps on the GPU: the map's, a streamed world's tiles', the detail tiles' footprints
    /// (recording, submit and, in wall-time mode, the wait).
    StampGpu,
    /// Stamps on the CPU map, without a GPU.
    StampCpu,
    /// Normal regeneration on the GPU (after stamps, or after a granular step).
    NormalsGpu,
    /// Normal regeneration on the CPU, without a GPU.
    NormalsCpu,
    /// Sky and terrain passes.
    Render,
    /// Clipmap placement and culling on the CPU.
    Lod,
    /// Copying the rendered image back.
    Capture,
    /// Collision readback scheduling and the camera body.
    Physics,
    /// The hillshade overview.
    Overview,
    /// Writing the frame's PNG.
    Write,
    /// One granular deformation step (snow) on the GPU.
    GranularGpu,
    /// One granular deformation step (snow) on the CPU.
    GranularCpu,
    /// The frame thread's work with the tile cache (flyover): craters on resident tiles and
    /// the pool's update; the loading happens on worker threads.
    Cache,
    /// The detail layer (`--detail`) on the CPU: the detail cache's update, its tiles
    /// streamed to the GPU's slots and the stamped rects read back into it (the footprints'
    /// GPU stamps are [`Step::StampGpu`]).
    Detail,
}

impl Step {
    /// Every step, in the order the plot stacks them (bottom first).
    pub const ALL: [Step; 14] = [
        Step::StampGpu,
        Step::StampCpu,
        Step::NormalsGpu,
        Step::NormalsCpu,
        Step::GranularGpu,
        Step::GranularCpu,
        Step::Detail,
        Step::Cache,
        Step::Physics,
        Step::Lod,
        Step::Render,
        Step::Capture,
        Step::Overview,
        Step::Write,
    ];

    /// The report key: where a step can run on either side, the key says which
    /// (`stamp_gpu`, `stamp_cpu`).
    pub const fn name(self) -> &'static str {
        match self {
            Step::StampGpu => "stamp_gpu",
            Step::StampCpu => "stamp_cpu",
            Step::NormalsGpu => "normals_gpu",
            Step::NormalsCpu => "normals_cpu",
            Step::Render => "render",
            Step::Lod => "lod",
            Step::Capture => "capture",
            Step::Physics => "physics",
            Step::Overview => "overview",
            Step::Write => "write",
            Step::GranularGpu => "granular_gpu",
            Step::GranularCpu => "granular_cpu",
            Step::Cache => "cache",
            Step::Detail => "detail",
        }
    }
}

/// In report.json's schema a step is its name: one of [`Step::ALL`]'s.
impl schemars::JsonSchema for Step {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "step".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "A timed step of a frame. Where a step can run on either side its \
                name says which: stamp_gpu / stamp_cpu, normals_gpu / normals_cpu, granular_gpu \
                / granular_cpu.",
            "enum": Step::ALL.map(Step::name),
        })
    }
}

/// Milliseconds since `t`.
pub fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// A GPU timestamp figure of `step` in frame `frame` that arrived in a later frame (GPU timing
/// in timestamp mode: see `gpu_scene::frame_timer`), to be credited to its own frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpuFigure {
    /// The frame's index.
    pub frame: u64,
    /// The step.
    pub step: Step,
    /// Milliseconds between its timestamps.
    pub ms: f64,
}

/// A granular step's measures that arrived in a later frame (GPU steps are read back without
/// a wait: see `gpu_scene::measures`), to be credited to the frame that stepped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GranularFigure {
    /// The frame's index.
    pub frame: u64,
    /// The map's volume after the step (the report's `granular_volume`).
    pub volume: u64,
    /// The world scenario's `granular_volume_taken`.
    pub volume_taken: Option<u64>,
    /// The snow scenario's `granular_removed` (so far).
    pub removed: Option<u64>,
}

/// One frame's timings: wall-clock milliseconds per step (a step timed twice adds up), and GPU
/// timestamp spans where the adapter has them; and the GPU figures of earlier frames that
/// arrived during this one.
#[derive(Debug, Default)]
pub struct Timings {
    wall: BTreeMap<Step, f64>,
    gpu: BTreeMap<Step, f64>,
    late_gpu: Vec<GpuFigure>,
    late_granular: Vec<GranularFigure>,
}

impl Timings {
    /// Adds `ms` to `step`.
    pub fn add(&mut self, step: Step, ms: f64) {
        *self.wall.entry(step).or_default() += ms;
    }

    /// Runs `f`, adding its wall time to `step`.
    pub fn time<T>(&mut self, step: Step, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let out = f();
        self.add(step, ms_since(t));
        out
    }

    /// Records a GPU measurement of `step`: its wall time (submit and wait) and, if the adapter
    /// has timestamp queries, its timestamp span.
    pub fn add_gpu(&mut self, step: Step, wall_ms: f64, timestamp_ms: Option<f64>) {
        self.add(step, wall_ms);
        if let Some(ts) = timestamp_ms {
            self.add_gpu_timestamp(step, ts);
        }
    }

    /// Adds a GPU timestamp span of `step` (no wall time).
    pub fn add_gpu_timestamp(&mut self, step: Step, ms: f64) {
        *self.gpu.entry(step).or_default() += ms;
    }

    /// Keeps a GPU figure of an earlier frame that arrived in this one.
    pub fn add_late_gpu(&mut self, figure: GpuFigure) {
        self.late_gpu.push(figure);
    }

    /// The GPU figures of earlier frames that arrived in this one, for the capture to credit
    /// to their frames.
    pub fn take_late_gpu(&mut self) -> Vec<GpuFigure> {
        std::mem::take(&mut self.late_gpu)
    }

    /// Keeps a granular step's measures of an earlier frame that arrived in this one.
    pub fn add_late_granular(&mut self, figure: GranularFigure) {
        self.late_granular.push(figure);
    }

    /// The granular measures of earlier frames that arrived in this one, for the capture to
    /// credit to their frames.
    pub fn take_late_granular(&mut self) -> Vec<GranularFigure> {
        std::mem::take(&mut self.late_granular)
    }

    /// Wall-clock milliseconds by report key.
    pub fn wall_by_name(&self) -> BTreeMap<&'static str, f64> {
        self.wall.iter().map(|(s, v)| (s.name(), *v)).collect()
    }

    /// GPU timestamp milliseconds by report key.
    pub fn gpu_by_name(&self) -> BTreeMap<&'static str, f64> {
        self.gpu.iter().map(|(s, v)| (s.name(), *v)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_add_up_under_their_names() {
        let mut t = Timings::default();
        t.add(Step::Physics, 1.0);
        t.add(Step::Physics, 2.0);
        t.add_gpu(Step::StampGpu, 4.0, Some(0.5));
        t.add_gpu(Step::Render, 3.0, None);
        let wall = t.wall_by_name();
        assert_eq!(wall.get("physics"), Some(&3.0));
        assert_eq!(wall.get("stamp_gpu"), Some(&4.0));
        assert_eq!(t.gpu_by_name().len(), 1);
        let names: std::collections::BTreeSet<_> = Step::ALL.map(Step::name).into_iter().collect();
        assert_eq!(names.len(), Step::ALL.len(), "names are distinct");
    }
}
