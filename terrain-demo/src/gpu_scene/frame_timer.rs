//! [`FrameTimer`]: how [`super::GpuScene`] times its GPU steps, through terrain-gpu's
//! `StepTimer` (timestamps read back a frame or more later where the adapter has trusted
//! ones, else the wall time of submit and wait per step), each figure credited to the frame
//! it belongs to ([`credit`]).
//!
//! `TERRAIN_DEMO_GPU_TIMING=timestamps|wall` forces a mode (tests; `timestamps` still needs
//! timestamp queries).

use crate::report::GpuTiming;
use crate::timings::{Clock, GpuFigure, Step, Timings};
use terrain_gpu::{GpuContext, GpuError, StepFigure, StepTimer, TimedSpan, TimingMode};

/// The environment variable that forces a timing mode.
pub const GPU_TIMING_ENV: &str = "TERRAIN_DEMO_GPU_TIMING";

/// One timed step, to record into the frame's [`Timings`] ([`Span::record`]).
#[derive(Debug, Clone, Copy)]
#[must_use = "a span is recorded into the frame's timings"]
pub struct Span {
    step: Step,
    span: TimedSpan,
    /// The frame thread's CPU milliseconds in the span (`None` without a thread CPU clock).
    cpu_ms: Option<f64>,
}

impl Span {
    /// Takes work timed as another step out of the figures, where they include the recording
    /// it happened in: `ms` of wall time (timestamp mode) and `cpu_ms` of the frame thread's
    /// CPU time.
    pub fn excluding(self, ms: f64, cpu_ms: Option<f64>) -> Self {
        Self {
            span: self.span.excluding(ms),
            cpu_ms: self.cpu_ms.map(|c| (c - cpu_ms.unwrap_or(0.0)).max(0.0)),
            ..self
        }
    }

    /// Adds the span to `timings` (its GPU figure, in timestamp mode, comes later).
    pub fn record(self, timings: &mut Timings) {
        timings.add_gpu(self.step, self.span.wall_ms, self.span.timestamp_ms);
        timings.add_cpu(self.step, self.cpu_ms);
    }
}

/// Times the scene's GPU steps (see the module docs). The timer counts one frame per
/// [`FrameTimer::end_frame`], so its frame numbers are the scene's frame indices.
pub struct FrameTimer {
    timer: StepTimer,
}

impl FrameTimer {
    /// Timestamps where `ctx`'s adapter is trusted and has timestamp queries, else wall time.
    pub fn new(ctx: &GpuContext) -> Self {
        let prefer = match std::env::var(GPU_TIMING_ENV).ok().as_deref() {
            Some("wall") => Some(TimingMode::Wall),
            Some("timestamps") => Some(TimingMode::Timestamps),
            _ => None,
        };
        let info = ctx.adapter.get_info();
        Self {
            timer: StepTimer::new(&info, &ctx.device, &ctx.queue, prefer),
        }
    }

    /// Which mode it times in: report.json's `gpu_timing`.
    pub fn mode(&self) -> GpuTiming {
        match self.timer.mode() {
            TimingMode::Timestamps => GpuTiming::Timestamps,
            TimingMode::Wall => GpuTiming::Wall,
        }
    }

    /// Records `work` into an encoder of its own and submits it, timed as `step`.
    pub fn time(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        step: Step,
        work: impl FnOnce(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<Span, GpuError> {
        let clock = Clock::start();
        let span = self.timer.time(device, queue, step.name(), work)?;
        Ok(Span {
            step,
            span,
            cpu_ms: clock.cpu_ms(),
        })
    }

    /// Ends the scene's frame (after its last timed step).
    pub fn end_frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(), GpuError> {
        self.timer.end_frame(device, queue)
    }

    /// Credits the figures that have arrived, never waiting ([`credit`]); `current` is the
    /// scene's frame whose `timings` these are.
    pub fn poll(
        &mut self,
        device: &wgpu::Device,
        current: u64,
        timings: &mut Timings,
    ) -> Result<(), GpuError> {
        credit(&self.timer.poll(device)?, current, timings);
        Ok(())
    }

    /// The end of the run: waits (bounded) for every figure on its way and returns them.
    pub fn flush(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<GpuFigure>, GpuError> {
        let mut late = Timings::default();
        credit(&self.timer.flush(device, queue)?, u64::MAX, &mut late);
        Ok(late.take_late_gpu())
    }
}

/// Credits arrived `figures` to their frames: those of frame `current` to its `timings`,
/// those of earlier frames to `timings`' late figures, which the capture credits to the frames
/// they belong to. Names that are no step are left out.
pub fn credit(figures: &[StepFigure], current: u64, timings: &mut Timings) {
    for figure in figures {
        let Some(&step) = Step::ALL.iter().find(|s| s.name() == figure.name) else {
            continue;
        };
        if figure.frame == current {
            timings.add_gpu_timestamp(step, figure.ms);
        } else {
            timings.add_late_gpu(GpuFigure {
                frame: figure.frame,
                step,
                ms: figure.ms,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_are_credited_to_their_own_frames() {
        // Frame 7's timings: its own figures arrived with frame 5's (late); frame 6's never
        // did (dropped, or still on its way).
        let mut timings = Timings::default();
        let f = |frame, name, ms| StepFigure { frame, name, ms };
        let arrived = [
            f(5, "stamp_gpu", 1.0),
            f(5, "render", 3.0),
            f(7, "stamp_gpu", 0.75),
            f(7, "render", 2.0),
            f(7, "not a step", 9.0),
        ];
        credit(&arrived, 7, &mut timings);
        let own = timings.gpu_by_name();
        assert_eq!(own.get("stamp_gpu"), Some(&0.75));
        assert_eq!(own.get("render"), Some(&2.0));
        assert_eq!(own.len(), 2);
        // The GPU figures are no wall time.
        assert!(timings.wall_by_name().is_empty());
        let late = timings.take_late_gpu();
        assert_eq!(
            late,
            vec![
                GpuFigure {
                    frame: 5,
                    step: Step::StampGpu,
                    ms: 1.0
                },
                GpuFigure {
                    frame: 5,
                    step: Step::Render,
                    ms: 3.0
                },
            ]
        );
    }
}
