//! [`StepTimer`]: times an application's GPU steps (named spans of a frame) in one of two
//! modes, chosen once for the adapter.
//!
//! - [`TimingMode::Timestamps`], on an adapter with trusted timestamp queries: each step is
//!   recorded in a [`GpuProfiler`] scope and submitted without waiting; a frame's profile
//!   comes back a frame or more later ([`StepTimer::poll`]), each figure tagged with its frame.
//!   A wait per step would stall a hardware frame once per step.
//! - [`TimingMode::Wall`], elsewhere: [`GpuTimer`]'s submit-and-wait per step. Software
//!   adapters (lavapipe) have timestamp queries, but their timestamps miss deferred compute
//!   work, so only the wall time of the wait means anything there.

use crate::device::profiler::{FrameProfile, GpuProfiler};
use crate::device::timer::GpuTimer;
use crate::error::GpuError;
use std::time::Instant;

/// Scopes per frame: a frame times a handful of steps (a streamed world's tile stamps one
/// each).
const SCOPES_PER_FRAME: u32 = 64;
/// Frames whose timestamps may be on their way back at once.
const FRAMES_IN_FLIGHT: usize = 4;

/// How a [`StepTimer`] times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimingMode {
    /// GPU timestamps, read back a frame or more later: no wait.
    Timestamps,
    /// The wall time of each step's submit and wait.
    Wall,
}

/// One timed step.
#[derive(Debug, Clone, Copy, PartialEq)]
#[must_use = "a span carries the step's time"]
pub struct TimedSpan {
    /// The step's name.
    pub name: &'static str,
    /// Wall mode: submit and wait. Timestamp mode: recording and submit.
    pub wall_ms: f64,
    /// Wall mode: the timestamps around the step, where the device has them. Timestamp mode:
    /// `None` (the figure comes later, from [`StepTimer::poll`]).
    pub timestamp_ms: Option<f64>,
    /// Whether `wall_ms` includes the recording (timestamp mode).
    pub includes_recording: bool,
}

impl TimedSpan {
    /// Takes `ms` of CPU work timed as another step out of the wall figure, where that figure
    /// includes the recording the work happened in (timestamp mode).
    pub fn excluding(mut self, ms: f64) -> Self {
        if self.includes_recording {
            self.wall_ms = (self.wall_ms - ms).max(0.0);
        }
        self
    }
}

/// A step's GPU time that came back: the frame it was recorded in, its name, milliseconds
/// (the step's top-level scopes of that frame, added up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepFigure {
    /// The frame ([`StepTimer::end_frame`] counts them from 0).
    pub frame: u64,
    /// The step's name.
    pub name: &'static str,
    /// Milliseconds of GPU time.
    pub ms: f64,
}

enum Mode {
    Timestamps {
        profiler: GpuProfiler,
        /// Whether the profiler's current frame has begun.
        open: bool,
    },
    Wall(GpuTimer),
}

/// Times GPU steps (module docs). Frames are counted by [`StepTimer::end_frame`].
pub struct StepTimer {
    mode: Mode,
}

impl std::fmt::Debug for StepTimer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StepTimer")
            .field("mode", &self.mode())
            .finish_non_exhaustive()
    }
}

impl StepTimer {
    /// Timestamps where `adapter` is trusted and `device` has timestamp queries, else wall
    /// time; `prefer` forces a mode (timestamps still need the queries).
    pub fn new(
        adapter: &wgpu::AdapterInfo,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        prefer: Option<TimingMode>,
    ) -> Self {
        let wall = || Self {
            mode: Mode::Wall(GpuTimer::new(device, queue)),
        };
        if prefer == Some(TimingMode::Wall) {
            return wall();
        }
        let forced = prefer == Some(TimingMode::Timestamps);
        match GpuProfiler::new(adapter, device, queue, SCOPES_PER_FRAME, FRAMES_IN_FLIGHT) {
            Ok(profiler) if profiler.trusted() || forced => Self {
                mode: Mode::Timestamps {
                    profiler,
                    open: false,
                },
            },
            _ => wall(),
        }
    }

    /// The mode it times in.
    pub fn mode(&self) -> TimingMode {
        match self.mode {
            Mode::Timestamps { .. } => TimingMode::Timestamps,
            Mode::Wall(_) => TimingMode::Wall,
        }
    }

    /// Records `work` into an encoder of its own and submits it, timed as `name`: waiting for
    /// it (wall mode), or inside a profiler scope without waiting (timestamp mode).
    pub fn time(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        name: &'static str,
        work: impl FnOnce(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<TimedSpan, GpuError> {
        let (profiler, open) = match &mut self.mode {
            Mode::Wall(timer) => {
                let t = timer.time(device, queue, work)?;
                return Ok(TimedSpan {
                    name,
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
        profiler.scope(&mut encoder, name, |_, encoder| work(encoder))?;
        queue.submit([encoder.finish()]);
        Ok(TimedSpan {
            name,
            wall_ms: start.elapsed().as_secs_f64() * 1e3,
            timestamp_ms: None,
            includes_recording: true,
        })
    }

    /// Ends the frame (after its last timed step): its timestamps are resolved and requested
    /// back in one more small submit. Nothing in wall mode.
    pub fn end_frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(), GpuError> {
        let Mode::Timestamps { profiler, open } = &mut self.mode else {
            return Ok(());
        };
        // One profiler frame per frame, timed steps or not.
        if !std::mem::take(open) {
            profiler.begin_frame();
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        profiler.end_frame(&mut encoder)?;
        queue.submit([encoder.finish()]);
        Ok(())
    }

    /// The figures of the frames whose timestamps have arrived, never waiting (none in wall
    /// mode). A frame whose profile never arrives has no figure (absent, not zero).
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<StepFigure>, GpuError> {
        match &mut self.mode {
            Mode::Timestamps { profiler, .. } => Ok(figures(&profiler.poll(device)?)),
            Mode::Wall(_) => Ok(Vec::new()),
        }
    }

    /// The end of a run: ends a frame still open and waits (bounded) for every profile on its
    /// way; returns their figures. Nothing in wall mode.
    pub fn flush(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<StepFigure>, GpuError> {
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
        Ok(figures(&profiles))
    }
}

/// The top-level scopes of `profiles`, a step timed twice in a frame added up; nested scopes
/// (parts of a step) are inside their step's figure already.
fn figures(profiles: &[FrameProfile]) -> Vec<StepFigure> {
    let mut out: Vec<StepFigure> = Vec::new();
    for profile in profiles {
        let first = out.len();
        for scope in profile.scopes.iter().filter(|s| s.depth == 0) {
            match out[first..].iter_mut().find(|f| f.name == scope.name) {
                Some(f) => f.ms += scope.ms,
                None => out.push(StepFigure {
                    frame: profile.frame,
                    name: scope.name,
                    ms: scope.ms,
                }),
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::profiler::ScopeTiming;

    fn scope(name: &'static str, depth: u32, ms: f64) -> ScopeTiming {
        ScopeTiming {
            name,
            depth,
            start_ms: 0.0,
            ms,
        }
    }

    #[test]
    fn figures_add_a_frames_top_level_scopes_per_step() {
        let profiles = [
            FrameProfile {
                frame: 5,
                scopes: vec![scope("stamp", 0, 1.0), scope("render", 0, 3.0)],
            },
            FrameProfile {
                frame: 7,
                scopes: vec![
                    scope("stamp", 0, 0.5),
                    scope("stamp", 0, 0.25),
                    scope("render", 0, 2.0),
                    // A part of the render: inside its figure already.
                    scope("sky", 1, 9.0),
                ],
            },
        ];
        let f = |frame, name, ms| StepFigure { frame, name, ms };
        assert_eq!(
            figures(&profiles),
            vec![
                f(5, "stamp", 1.0),
                f(5, "render", 3.0),
                f(7, "stamp", 0.75),
                f(7, "render", 2.0),
            ]
        );
    }
}
