//! [`FrameTimer`]: how [`super::GpuScene`] times its GPU steps, in one of two modes.
//!
//! - `timestamps`, on a hardware adapter with timestamp queries: each step's work is recorded
//!   in a [`GpuProfiler`] scope named after its [`Step`] and submitted without waiting; the
//!   frame's profile is read back a frame or more later and credited to the frame it belongs
//!   to ([`credit`]). A blocking wait per step would stall a hardware frame once per step.
//! - `wall`, elsewhere: [`GpuTimer`]'s submit-and-wait per step, as before. Software adapters
//!   (lavapipe) have timestamp queries, but their timestamps miss deferred compute work, so
//!   only the wall time of the wait means anything there.
//!
//! `TERRAIN_DEMO_GPU_TIMING=timestamps|wall` forces a mode (tests; `timestamps` still needs
//! timestamp queries).

use crate::report::GpuTiming;
use crate::timings::{GpuFigure, Step, Timings, ms_since};
use std::time::Instant;
use terrain_gpu::{FrameProfile, GpuContext, GpuError, GpuProfiler, GpuTimer};

/// The environment variable that forces a timing mode.
pub const GPU_TIMING_ENV: &str = "TERRAIN_DEMO_GPU_TIMING";

/// Scopes per frame: a frame times a handful of steps, the flyover's tile stamps one each.
const SCOPES_PER_FRAME: u32 = 64;
/// Frames whose timestamps may be on their way back at once.
const FRAMES_IN_FLIGHT: usize = 4;

/// One timed step, to record into the frame's [`Timings`] ([`Span::record`]).
#[derive(Debug, Clone, Copy)]
#[must_use = "a span is recorded into the frame's timings"]
pub struct Span {
    step: Step,
    /// Wall mode: submit and wait. Timestamp mode: recording and submit.
    wall_ms: f64,
    /// Wall mode: the timestamps' span, where the device has them (today's figure).
    timestamp_ms: Option<f64>,
    /// Whether `wall_ms` includes the recording (timestamp mode).
    includes_recording: bool,
}

impl Span {
    /// Takes `ms` of CPU work timed as another step out of the wall figure, where the wall
    /// figure includes the recording it happened in (timestamp mode).
    pub fn excluding(mut self, ms: f64) -> Self {
        if self.includes_recording {
            self.wall_ms = (self.wall_ms - ms).max(0.0);
        }
        self
    }

    /// Adds the span to `timings` (its GPU figure, in timestamp mode, comes later).
    pub fn record(self, timings: &mut Timings) {
        timings.add_gpu(self.step, self.wall_ms, self.timestamp_ms);
    }
}

enum Mode {
    Timestamps {
        profiler: GpuProfiler,
        /// Whether the profiler's current frame has begun.
        open: bool,
    },
    Wall(GpuTimer),
}

/// Times the scene's GPU steps (see the module docs). The profiler counts one frame per
/// [`FrameTimer::end_frame`], so its frame numbers are the scene's frame indices.
pub struct FrameTimer {
    mode: Mode,
}

impl FrameTimer {
    /// Timestamps where `ctx`'s adapter is trusted and has timestamp queries, else wall time.
    pub fn new(ctx: &GpuContext) -> Self {
        let forced = std::env::var(GPU_TIMING_ENV).ok();
        let wall = || Self {
            mode: Mode::Wall(GpuTimer::new(&ctx.device, &ctx.queue)),
        };
        if forced.as_deref() == Some("wall") {
            return wall();
        }
        let info = ctx.adapter.get_info();
        match GpuProfiler::new(
            &info,
            &ctx.device,
            &ctx.queue,
            SCOPES_PER_FRAME,
            FRAMES_IN_FLIGHT,
        ) {
            Ok(profiler) if profiler.trusted() || forced.as_deref() == Some("timestamps") => Self {
                mode: Mode::Timestamps {
                    profiler,
                    open: false,
                },
            },
            _ => wall(),
        }
    }

    /// Which mode it times in: report.json's `gpu_timing`.
    pub fn mode(&self) -> GpuTiming {
        match self.mode {
            Mode::Timestamps { .. } => GpuTiming::Timestamps,
            Mode::Wall(_) => GpuTiming::Wall,
        }
    }

    /// Records `work` into an encoder of its own and submits it, timed as `step`: waiting for
    /// it (wall mode), or inside a profiler scope without waiting (timestamp mode).
    pub fn time(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        step: Step,
        work: impl FnOnce(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<Span, GpuError> {
        let (profiler, open) = match &mut self.mode {
            Mode::Wall(timer) => {
                let t = timer.time(device, queue, work)?;
                return Ok(Span {
                    step,
                    wall_ms: t.ms,
                    timestamp_ms: t.timestamp_ms,
                    includes_recording: false,
                });
            }
            Mode::Timestamps { profiler, open } => (profiler, open),
        };
        let start = Instant::now();
        if !*open {
            profiler.begin_frame();
            *open = true;
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        profiler.scope(&mut encoder, step.name(), |_, encoder| work(encoder))?;
        queue.submit([encoder.finish()]);
        Ok(Span {
            step,
            wall_ms: ms_since(start),
            timestamp_ms: None,
            includes_recording: true,
        })
    }

    /// Ends the scene's frame (after its last timed step): its timestamps are resolved and
    /// requested back in one more small submit. Nothing in wall mode.
    pub fn end_frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(), GpuError> {
        let Mode::Timestamps { profiler, open } = &mut self.mode else {
            return Ok(());
        };
        // One profiler frame per scene frame, timed steps or not.
        if !std::mem::take(open) {
            profiler.begin_frame();
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        profiler.end_frame(&mut encoder)?;
        queue.submit([encoder.finish()]);
        Ok(())
    }

    /// Credits the profiles that have arrived, never waiting ([`credit`]); `current` is the
    /// scene's frame whose `timings` these are.
    pub fn poll(
        &mut self,
        device: &wgpu::Device,
        current: u64,
        timings: &mut Timings,
    ) -> Result<(), GpuError> {
        if let Mode::Timestamps { profiler, .. } = &mut self.mode {
            credit(&profiler.poll(device)?, current, timings);
        }
        Ok(())
    }

    /// The end of the run: ends a frame still open, waits (bounded) for every profile on its
    /// way and returns their figures. Nothing in wall mode.
    pub fn flush(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<GpuFigure>, GpuError> {
        if let Mode::Timestamps { open: true, .. } = self.mode {
            self.end_frame(device, queue)?;
        }
        let Mode::Timestamps { profiler, .. } = &mut self.mode else {
            return Ok(Vec::new());
        };
        let profiles = profiler.flush(device)?;
        let (scopes, frames) = profiler.dropped();
        if scopes + frames > 0 {
            tracing::info!(
                scopes,
                frames,
                "GPU timestamps: scopes over the per-frame bound, and frames left untimed"
            );
        }
        let mut late = Timings::default();
        credit(&profiles, u64::MAX, &mut late);
        Ok(late.take_late_gpu())
    }
}

/// Credits arrived `profiles` to their frames: the top-level scopes of frame `current` to its
/// `timings`, those of earlier frames to `timings`' late figures, which the capture credits
/// to the frames they belong to. Scopes of a step add up; nested scopes (parts of a step) and
/// names that are no step are left out. A frame whose profile never arrives gets no GPU
/// figure (absent, not zero).
pub fn credit(profiles: &[FrameProfile], current: u64, timings: &mut Timings) {
    for profile in profiles {
        for scope in profile.scopes.iter().filter(|s| s.depth == 0) {
            let Some(&step) = Step::ALL.iter().find(|s| s.name() == scope.name) else {
                continue;
            };
            if profile.frame == current {
                timings.add_gpu_timestamp(step, scope.ms);
            } else {
                timings.add_late_gpu(GpuFigure {
                    frame: profile.frame,
                    step,
                    ms: scope.ms,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use terrain_gpu::ScopeTiming;

    fn scope(name: &'static str, depth: u32, ms: f64) -> ScopeTiming {
        ScopeTiming {
            name,
            depth,
            start_ms: 0.0,
            ms,
        }
    }

    fn profile(frame: u64, scopes: Vec<ScopeTiming>) -> FrameProfile {
        FrameProfile { frame, scopes }
    }

    #[test]
    fn profiles_are_credited_to_their_own_frames() {
        // Frame 7's timings: its own profile arrived with frame 5's (late); frame 6's never
        // did (dropped, or still on its way).
        let mut timings = Timings::default();
        let arrived = [
            profile(5, vec![scope("stamp_gpu", 0, 1.0), scope("render", 0, 3.0)]),
            profile(
                7,
                vec![
                    scope("stamp_gpu", 0, 0.5),
                    scope("stamp_gpu", 0, 0.25),
                    // A part of the render: inside its step's figure already.
                    scope("render", 0, 2.0),
                    scope("sky", 1, 9.0),
                    scope("not a step", 0, 9.0),
                ],
            ),
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
        assert!(late.iter().all(|f| f.frame != 6), "frame 6 has no figure");
    }
}
