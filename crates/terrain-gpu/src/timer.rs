//! `GpuTimer`: GPU time of a span of recorded work, from timestamp queries where the device
//! has them, else wall time of the submission with a blocking poll.

use crate::download::download_bytes;
use crate::error::GpuError;
use std::time::Instant;

/// Where a timing came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimingSource {
    /// GPU timestamp queries around the work.
    Timestamps,
    /// Wall time of submit + blocking poll (no timestamp queries on this device).
    WallClock,
}

/// One measured span.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpuTiming {
    /// Milliseconds.
    pub ms: f64,
    /// How it was measured.
    pub source: TimingSource,
}

/// Brackets recorded work with two timestamps (two empty compute passes that write them).
#[derive(Debug)]
pub struct GpuTimer {
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
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
                (set, resolve)
            });
        Self {
            queries,
            period_ns: f64::from(queue.get_timestamp_period()),
        }
    }

    /// Whether timings come from GPU timestamps.
    pub fn source(&self) -> TimingSource {
        if self.queries.is_some() {
            TimingSource::Timestamps
        } else {
            TimingSource::WallClock
        }
    }

    fn stamp(&self, encoder: &mut wgpu::CommandEncoder, index: u32) {
        if let Some((set, _)) = &self.queries {
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("GpuTimer"),
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(index),
                    end_of_pass_write_index: None,
                }),
            });
        }
    }

    /// Records `work` into a fresh encoder between two timestamps, submits it, waits, and
    /// returns the GPU time (or the wall time of submit and wait without timestamps).
    pub fn time(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        work: impl FnOnce(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<GpuTiming, GpuError> {
        let mut encoder = device.create_command_encoder(&Default::default());
        self.stamp(&mut encoder, 0);
        work(&mut encoder)?;
        self.stamp(&mut encoder, 1);
        if let Some((set, resolve)) = &self.queries {
            encoder.resolve_query_set(set, 0..2, resolve, 0);
        }
        let start = Instant::now();
        queue.submit([encoder.finish()]);
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let wall_ms = start.elapsed().as_secs_f64() * 1e3;
        match &self.queries {
            Some((_, resolve)) => {
                let bytes = download_bytes(device, queue, resolve, 0, 16)?;
                let t: &[u64] = bytemuck::cast_slice(&bytes);
                let ticks = t[1].saturating_sub(t[0]);
                Ok(GpuTiming {
                    ms: ticks as f64 * self.period_ns / 1e6,
                    source: TimingSource::Timestamps,
                })
            }
            None => Ok(GpuTiming {
                ms: wall_ms,
                source: TimingSource::WallClock,
            }),
        }
    }
}
