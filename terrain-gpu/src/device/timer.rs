//! `GpuTimer`: time of a span of recorded GPU work, as the wall time of its submission with a
//! blocking wait, and as GPU timestamps where the device has them.
//!
//! Why wall time first: on lavapipe (CI's software adapter) timestamps around compute passes
//! measurably miss work (a 850 000-texel stamp read 0.06 ms by timestamps and 13-19 ms by a
//! blocking wait), so the wall time of submit-and-wait is the figure reported; it is an upper
//! bound of the GPU time that includes one submission's overhead (about 0.1 ms).

use crate::device::download::map_and_read;
use crate::error::GpuError;
use std::time::Instant;

/// A timed submission longer than this (milliseconds) is logged at info level: a frame at 30
/// frames per second has 33 ms in all.
const SLOW_SUBMIT_MS: f64 = 100.0;

/// One measured span.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpuTiming {
    /// Milliseconds from submit until the work had finished (blocking wait).
    pub ms: f64,
    /// Milliseconds between GPU timestamps around the work, where the device has them.
    pub timestamp_ms: Option<f64>,
}

/// Brackets recorded work with two timestamps (two empty compute passes that write them).
#[derive(Debug)]
pub struct GpuTimer {
    /// The query set, the buffer its timestamps resolve into, and the staging buffer they are
    /// read back through (all made once).
    queries: Option<(wgpu::QuerySet, wgpu::Buffer, wgpu::Buffer)>,
    /// Whether timestamps can be written between passes (`TIMESTAMP_QUERY_INSIDE_ENCODERS`),
    /// which brackets the work exactly; else they come from empty compute passes.
    inside_encoders: bool,
    period_ns: f64,
}

impl GpuTimer {
    /// A timer for `device`; without `TIMESTAMP_QUERY` it measures wall time.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Self {
        let queries = device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
            .then(|| {
                let set = device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("GpuTimer"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2,
                });
                let resolve = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("GpuTimer resolve"),
                    size: 16,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                });
                let staging = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("GpuTimer staging"),
                    size: 16,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                (set, resolve, staging)
            });
        Self {
            queries,
            inside_encoders: device
                .features()
                .contains(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS),
            period_ns: f64::from(queue.get_timestamp_period()),
        }
    }

    /// Whether timings carry GPU timestamps too.
    pub fn has_timestamps(&self) -> bool {
        self.queries.is_some()
    }

    /// Writes timestamp `index` from an empty compute pass: the opening one at the beginning of
    /// its pass, the closing one at the end. The end matters: a beginning-of-pass timestamp may
    /// be taken once earlier work has *started* (Vulkan's top of pipe), so a closing
    /// beginning-of-pass stamp can land before the timed dispatches finish.
    fn stamp(&self, encoder: &mut wgpu::CommandEncoder, index: u32, closing: bool) {
        if let Some((set, ..)) = &self.queries {
            if self.inside_encoders {
                encoder.write_timestamp(set, index);
                return;
            }
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("GpuTimer"),
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: (!closing).then_some(index),
                    end_of_pass_write_index: closing.then_some(index),
                }),
            });
        }
    }

    /// Records `work` into a fresh encoder between two timestamps, submits it, waits for it, and
    /// returns the wall time of submit and wait, with the timestamps' span where available.
    #[tracing::instrument(level = "trace", name = "gpu_timed_submit", skip_all)]
    pub fn time(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        work: impl FnOnce(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<GpuTiming, GpuError> {
        let mut encoder = device.create_command_encoder(&Default::default());
        self.stamp(&mut encoder, 0, false);
        work(&mut encoder)?;
        self.stamp(&mut encoder, 1, true);
        if let Some((set, resolve, staging)) = &self.queries {
            encoder.resolve_query_set(set, 0..2, resolve, 0);
            encoder.copy_buffer_to_buffer(resolve, 0, staging, 0, 16);
        }
        let start = Instant::now();
        queue.submit([encoder.finish()]);
        crate::device::trace::record("timer: submitted, blocking poll", 0);
        device.poll(crate::device::download::wait_bounded())?;
        let wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let timestamp_ms = match &self.queries {
            Some((_, _, staging)) => {
                let bytes = map_and_read(device, staging)?;
                let t: &[u64] = bytemuck::cast_slice(&bytes);
                Some(t[1].saturating_sub(t[0]) as f64 * self.period_ns / 1e6)
            }
            None => None,
        };
        if wall_ms > SLOW_SUBMIT_MS {
            tracing::info!(
                wall_ms,
                ?timestamp_ms,
                "slow GPU submission (submit and wait)"
            );
        } else {
            tracing::trace!(wall_ms, ?timestamp_ms, "GPU submission");
        }
        Ok(GpuTiming {
            ms: wall_ms,
            timestamp_ms,
        })
    }
}
