//! The steps a frame is timed in ([`Step`], named once for the report and the plot), one
//! frame's measurements ([`Timings`]) and the frame thread's CPU clock ([`Clock`]).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

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

    /// Whether the step is the frame thread's own CPU work. Not so: GPU submits and the waits
    /// for them (`stamp_gpu`, `normals_gpu`, `granular_gpu`, `render`), the capture's readback
    /// and the frame's file write. The frame's `frame_thread_cpu_ms` leaves these out.
    pub const fn is_frame_thread_work(self) -> bool {
        !matches!(
            self,
            Step::StampGpu
                | Step::NormalsGpu
                | Step::GranularGpu
                | Step::Render
                | Step::Capture
                | Step::Write
        )
    }

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

/// The CPU time the calling thread has run, where the platform has a per-thread CPU clock
/// (Linux and Android; `None` elsewhere).
pub fn thread_cpu() -> Option<Duration> {
    #[cfg(any(target_os = "linux", target_os = "android"))]
    {
        use rustix::time::{ClockId, clock_gettime};
        let t = clock_gettime(ClockId::ThreadCPUTime);
        let secs = u64::try_from(t.tv_sec).ok()?;
        let nanos = u32::try_from(t.tv_nsec).ok()?;
        Some(Duration::new(secs, nanos))
    }
    #[cfg(not(any(target_os = "linux", target_os = "android")))]
    None
}

/// A start on both clocks a step is timed on: the wall clock, and the frame thread's CPU
/// clock. On a machine whose cores are shared (a software GPU adapter's threads run on the
/// same two cores as the frame thread) wall time counts the time the thread was preempted;
/// its CPU time does not.
#[derive(Debug, Clone, Copy)]
pub struct Clock {
    wall: Instant,
    cpu: Option<Duration>,
}

impl Clock {
    /// Now, on both clocks.
    pub fn start() -> Self {
        Self {
            wall: Instant::now(),
            cpu: thread_cpu(),
        }
    }

    /// Wall milliseconds since the start.
    pub fn wall_ms(&self) -> f64 {
        ms_since(self.wall)
    }

    /// Milliseconds of this thread's CPU time since the start (`None` without a thread CPU
    /// clock). Call it on the thread that started the clock.
    pub fn cpu_ms(&self) -> Option<f64> {
        let now = thread_cpu()?;
        Some(now.checked_sub(self.cpu?)?.as_secs_f64() * 1e3)
    }
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
    /// The frame thread's CPU milliseconds in steps that are not its own work
    /// ([`Step::is_frame_thread_work`]).
    cpu_not_own: f64,
    late_gpu: Vec<GpuFigure>,
    late_granular: Vec<GranularFigure>,
}

impl Timings {
    /// Adds `ms` to `step`.
    pub fn add(&mut self, step: Step, ms: f64) {
        *self.wall.entry(step).or_default() += ms;
    }

    /// Adds the time since `clock` started to `step`: its wall time, and its CPU time where
    /// the step is not the frame thread's own work.
    pub fn add_since(&mut self, step: Step, clock: Clock) {
        self.add(step, clock.wall_ms());
        self.add_cpu(step, clock.cpu_ms());
    }

    /// Records `ms` of the frame thread's CPU time in `step` (kept where the step is not the
    /// frame thread's own work, to be left out of its figure).
    pub fn add_cpu(&mut self, step: Step, ms: Option<f64>) {
        if !step.is_frame_thread_work() {
            self.cpu_not_own += ms.unwrap_or(0.0);
        }
    }

    /// The frame thread's CPU milliseconds in steps that are not its own work.
    pub fn cpu_not_own_ms(&self) -> f64 {
        self.cpu_not_own
    }

    /// Runs `f`, adding its time to `step` ([`Timings::add_since`]).
    pub fn time<T>(&mut self, step: Step, f: impl FnOnce() -> T) -> T {
        let clock = Clock::start();
        let out = f();
        self.add_since(step, clock);
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

    #[test]
    fn only_cpu_time_outside_the_frame_threads_work_is_kept() {
        let mut t = Timings::default();
        t.add_cpu(Step::Render, Some(2.0));
        t.add_cpu(Step::Capture, Some(0.5));
        t.add_cpu(Step::Cache, Some(7.0));
        t.add_cpu(Step::Write, None);
        assert_eq!(t.cpu_not_own_ms(), 2.5);
    }

    /// Where the platform has a thread CPU clock, a thread that sleeps spends no CPU time in
    /// the wait, and one that spins spends about its wall time.
    #[test]
    #[cfg(any(target_os = "linux", target_os = "android"))]
    fn the_cpu_clock_counts_work_not_waits() {
        let clock = Clock::start();
        std::thread::sleep(std::time::Duration::from_millis(30));
        let slept = clock.cpu_ms().expect("Linux has a thread CPU clock");
        assert!(clock.wall_ms() >= 30.0);
        assert!(slept < 10.0, "{slept} ms of CPU while asleep");
        let clock = Clock::start();
        let mut x = 0u64;
        while clock.cpu_ms().expect("thread CPU clock") < 20.0 {
            x = std::hint::black_box(x.wrapping_add(1));
        }
        assert!(
            clock.wall_ms() >= 20.0,
            "CPU time never exceeds wall time on one thread"
        );
    }
}
