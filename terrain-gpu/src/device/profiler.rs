//! [`GpuProfiler`]: GPU time of nested scopes of a frame's work from timestamp queries, read
//! back a frame or more later through a ring of staging buffers, so timing a frame never
//! stalls it (what wgpu-profiler does; [`crate::GpuTimer`] instead submits and waits per
//! span).
//!
//! A frame's scopes write their timestamps into one query set, which the frame's last encoder
//! resolves and copies into a free staging buffer of a [`SmallReadback`] ring, mapped on
//! submit. [`GpuProfiler::poll`] hands over the frames whose buffers have arrived. One query
//! set serves every frame: the queue runs a frame's resolve before the next frame's writes.
//! When every staging buffer is still on its way the frame goes untimed rather than waiting.
//!
//! Timestamps are only as good as the adapter's: on software adapters (lavapipe) they miss
//! deferred compute work, so callers there measure wall time instead
//! ([`GpuProfiler::trusted`] says which).

use crate::device::small_readback::{MAX_SMALL_READBACK_BYTES, SmallReadback};
use crate::error::GpuError;
use std::collections::VecDeque;

/// Most scopes one frame may time (two timestamps of 8 bytes each per scope fill one staging
/// buffer of the ring).
pub const MAX_PROFILER_SCOPES: u32 = (MAX_SMALL_READBACK_BYTES / 16) as u32;

/// Most frames whose timestamps may be on their way back at once.
pub const MAX_PROFILER_FRAMES: usize = crate::device::small_readback::MAX_SMALL_READBACK_RING;

/// One timed scope of a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ScopeTiming {
    /// The name it was opened with.
    pub name: &'static str,
    /// How many scopes enclose it (0 for a top-level scope).
    pub depth: u32,
    /// Milliseconds from the frame's first timestamp to the scope's opening one.
    pub start_ms: f64,
    /// Milliseconds between its two timestamps.
    pub ms: f64,
}

/// The timed scopes of one frame, in the order they were opened.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameProfile {
    /// The frame's number ([`GpuProfiler::begin_frame`] counts from 0).
    pub frame: u64,
    /// Its scopes.
    pub scopes: Vec<ScopeTiming>,
}

/// An open scope ([`GpuProfiler::begin_scope`]); close it with [`GpuProfiler::end_scope`].
#[derive(Debug)]
#[must_use = "a scope is timed once it is ended"]
pub struct Scope {
    /// Its index in the frame, or `None` when it is not timed (untimed frame, too many
    /// scopes).
    index: Option<u32>,
}

/// The names and depths of a frame's scopes, in the order they were opened.
type ScopeList = Vec<(&'static str, u32)>;

/// A frame being recorded: its number, its scopes, the open ones.
#[derive(Debug)]
struct Recording {
    frame: u64,
    scopes: ScopeList,
    open: Vec<u32>,
}

/// Timestamp queries of nested scopes, read back without waiting (see the module docs).
#[derive(Debug)]
pub struct GpuProfiler {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    ring: SmallReadback,
    max_scopes: u32,
    inside_encoders: bool,
    trusted: bool,
    period_ns: f64,
    next_frame: u64,
    recording: Option<Recording>,
    /// Frames handed to the ring: (ring sequence number, frame, scopes).
    in_flight: VecDeque<(u64, u64, ScopeList)>,
    /// Scopes opened beyond `max_scopes`, and frames that went untimed: a caller's figures
    /// are then incomplete, which it should know.
    dropped_scopes: u64,
    untimed_frames: u64,
}

impl GpuProfiler {
    /// A profiler timing up to `max_scopes` (1 to [`MAX_PROFILER_SCOPES`]) scopes per frame,
    /// with up to `frames_in_flight` (1 to [`MAX_PROFILER_FRAMES`]) frames on their way back.
    /// Fails with [`GpuError::Unsupported`] where the device has no timestamp queries
    /// (`wgpu::Features::TIMESTAMP_QUERY`): measure wall time there.
    pub fn new(
        adapter: &wgpu::AdapterInfo,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        max_scopes: u32,
        frames_in_flight: usize,
    ) -> Result<Self, GpuError> {
        if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return Err(GpuError::Unsupported {
                what: "GpuProfiler",
                reason: "the device has no timestamp queries (TIMESTAMP_QUERY): time with \
                         GpuTimer's wall time",
            });
        }
        if !(1..=MAX_PROFILER_SCOPES).contains(&max_scopes) {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "profiler scopes per frame",
                value: f64::from(max_scopes),
                expected: "1 to 256 scopes",
            }
            .into());
        }
        let bytes = u64::from(max_scopes) * 16;
        // The ring checks `frames_in_flight`.
        let ring = SmallReadback::new(device, frames_in_flight, bytes)?;
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("GpuProfiler"),
            ty: wgpu::QueryType::Timestamp,
            count: max_scopes * 2,
        });
        let resolve = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("GpuProfiler resolve"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Ok(Self {
            queries,
            resolve,
            ring,
            max_scopes,
            inside_encoders: device
                .features()
                .contains(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS),
            trusted: adapter.device_type != wgpu::DeviceType::Cpu,
            period_ns: f64::from(queue.get_timestamp_period()),
            next_frame: 0,
            recording: None,
            in_flight: VecDeque::new(),
            dropped_scopes: 0,
            untimed_frames: 0,
        })
    }

    /// Whether the adapter's timestamps can be taken as GPU time: not on a software adapter,
    /// whose timestamps miss deferred compute work.
    pub fn trusted(&self) -> bool {
        self.trusted
    }

    /// Starts frame number `n` (returned; counted from 0). The frame is timed unless every
    /// staging buffer is still on its way back (then its scopes record nothing: the frame is
    /// never made to wait). A frame still open is dropped untimed.
    pub fn begin_frame(&mut self) -> u64 {
        let frame = self.next_frame;
        self.next_frame += 1;
        if self.recording.take().is_some() {
            self.untimed_frames += 1;
        }
        if self.ring.in_flight() < self.ring.capacity() {
            self.recording = Some(Recording {
                frame,
                scopes: Vec::new(),
                open: Vec::new(),
            });
        } else {
            self.untimed_frames += 1;
        }
        frame
    }

    /// Opens a scope named `name` in `encoder`: its timestamp is written where the encoder's
    /// work reaches this point. Scopes nest; close each with [`GpuProfiler::end_scope`].
    pub fn begin_scope(&mut self, encoder: &mut wgpu::CommandEncoder, name: &'static str) -> Scope {
        let Some(rec) = self.recording.as_mut() else {
            return Scope { index: None };
        };
        let index = rec.scopes.len() as u32;
        if index >= self.max_scopes {
            self.dropped_scopes += 1;
            return Scope { index: None };
        }
        rec.scopes.push((name, rec.open.len() as u32));
        rec.open.push(index);
        write(
            &self.queries,
            self.inside_encoders,
            encoder,
            index * 2,
            false,
        );
        Scope { index: Some(index) }
    }

    /// Closes `scope` in `encoder` (its work recorded before this point). Scopes close in the
    /// reverse order of opening; closing another fails and writes nothing.
    pub fn end_scope(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        scope: Scope,
    ) -> Result<(), GpuError> {
        let (Some(index), Some(rec)) = (scope.index, self.recording.as_mut()) else {
            return Ok(());
        };
        if rec.open.last() != Some(&index) {
            return Err(GpuError::Unsupported {
                what: "GpuProfiler::end_scope",
                reason: "scopes close in the reverse order of opening",
            });
        }
        rec.open.pop();
        write(
            &self.queries,
            self.inside_encoders,
            encoder,
            index * 2 + 1,
            true,
        );
        Ok(())
    }

    /// Times `work` as a scope named `name`.
    pub fn scope<R>(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        name: &'static str,
        work: impl FnOnce(&mut Self, &mut wgpu::CommandEncoder) -> Result<R, GpuError>,
    ) -> Result<R, GpuError> {
        let scope = self.begin_scope(encoder, name);
        let result = work(self, encoder)?;
        self.end_scope(encoder, scope)?;
        Ok(result)
    }

    /// Ends the frame: resolves its timestamps in `encoder`, which must be submitted after
    /// every encoder the frame's scopes were written in, and requests them back (mapped on
    /// that submit). Fails, timing nothing, while a scope is still open.
    pub fn end_frame(&mut self, encoder: &mut wgpu::CommandEncoder) -> Result<(), GpuError> {
        let Some(rec) = self.recording.take() else {
            return Ok(());
        };
        if !rec.open.is_empty() {
            self.untimed_frames += 1;
            return Err(GpuError::Unsupported {
                what: "GpuProfiler::end_frame",
                reason: "a scope is still open",
            });
        }
        if rec.scopes.is_empty() {
            return Ok(());
        }
        let count = rec.scopes.len() as u32 * 2;
        encoder.resolve_query_set(&self.queries, 0..count, &self.resolve, 0);
        match self.ring.request(encoder, &self.resolve, 0)? {
            Some(seq) => {
                self.in_flight.push_back((seq, rec.frame, rec.scopes));
                // At most a ring's worth is really on its way: older entries were dropped
                // unsubmitted and will never arrive.
                while self.in_flight.len() > self.ring.capacity() {
                    self.in_flight.pop_front();
                }
            }
            None => self.untimed_frames += 1,
        }
        Ok(())
    }

    /// The frames whose timestamps have arrived, oldest first, without waiting for the
    /// others. Frames whose encoders were dropped unsubmitted are forgotten.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<FrameProfile>, GpuError> {
        let arrived = self.ring.poll(device)?;
        let mut out = Vec::with_capacity(arrived.len());
        for (seq, bytes) in arrived {
            // Requests the ring no longer holds (their encoders dropped) arrive never.
            while self.in_flight.front().is_some_and(|(s, ..)| *s < seq) {
                self.in_flight.pop_front();
            }
            let Some((_, frame, scopes)) = self.in_flight.pop_front() else {
                continue;
            };
            out.push(self.profile(frame, &scopes, &bytes));
        }
        Ok(out)
    }

    /// Waits (bounded) until every frame ended has arrived, and hands them over: the end of a
    /// run or a test, never inside a frame.
    pub fn flush(&mut self, device: &wgpu::Device) -> Result<Vec<FrameProfile>, GpuError> {
        crate::device::trace::record("profiler: flush, blocking poll", 0);
        device.poll(crate::device::download::wait_bounded())?;
        self.poll(device)
    }

    /// Scopes opened beyond the per-frame bound, and frames that went untimed, so far.
    pub fn dropped(&self) -> (u64, u64) {
        (self.dropped_scopes, self.untimed_frames)
    }

    fn profile(&self, frame: u64, scopes: &[(&'static str, u32)], bytes: &[u8]) -> FrameProfile {
        let ticks: Vec<u64> = bytes
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().unwrap_or_default()))
            .collect();
        let origin = ticks.first().copied().unwrap_or(0);
        let ms = |from: u64, to: u64| to.saturating_sub(from) as f64 * self.period_ns / 1e6;
        let scopes = scopes
            .iter()
            .enumerate()
            .map(|(i, &(name, depth))| {
                let tick = |j: usize| ticks.get(j).copied().unwrap_or(origin);
                let (open, close) = (tick(2 * i), tick(2 * i + 1));
                ScopeTiming {
                    name,
                    depth,
                    start_ms: ms(origin, open),
                    ms: ms(open, close),
                }
            })
            .collect();
        FrameProfile { frame, scopes }
    }
}

/// Writes timestamp `index`: between passes where the device allows it, else from an empty
/// compute pass (the closing one at its end: a beginning-of-pass timestamp may be taken once
/// earlier work has only *started*).
fn write(
    queries: &wgpu::QuerySet,
    inside_encoders: bool,
    encoder: &mut wgpu::CommandEncoder,
    index: u32,
    closing: bool,
) {
    if inside_encoders {
        encoder.write_timestamp(queries, index);
        return;
    }
    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some("GpuProfiler"),
        timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
            query_set: queries,
            beginning_of_pass_write_index: (!closing).then_some(index),
            end_of_pass_write_index: closing.then_some(index),
        }),
    });
}
