//! A ring of small staging buffers for reading a few bytes of a GPU buffer (a counter, an
//! indirect draw's arguments) back without waiting: the copy rides the submit that produced
//! the values, and the bytes are picked up by a later, non-blocking poll. The blocking
//! alternative (`download_bytes`) stalls the frame until the GPU is idle, which is what a
//! frame must never do (a count the report wants can arrive a frame late).

use crate::device::readback::{ABANDONED, FAILED, FREE, MAPPED, PENDING, SubmitGuard};
use crate::error::GpuError;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

/// Most staging buffers a [`SmallReadback`] ring may have.
pub const MAX_SMALL_READBACK_RING: usize = 16;

/// Most bytes one request may copy (a counter block, not a region: use `RegionReadback`).
pub const MAX_SMALL_READBACK_BYTES: u64 = 4096;

#[derive(Debug)]
struct Slot {
    buffer: wgpu::Buffer,
    state: Arc<AtomicU8>,
    /// The request's sequence number while one is recorded and not handed over.
    seq: Option<u64>,
}

/// A ring of `ring` staging buffers of `bytes` bytes each: [`SmallReadback::request`] records
/// a copy into a free one and maps it when the encoder is submitted;
/// [`SmallReadback::poll`] hands over what has arrived, oldest first, never waiting.
#[derive(Debug)]
pub struct SmallReadback {
    slots: Vec<Slot>,
    bytes: u64,
    next_seq: u64,
}

impl SmallReadback {
    /// A ring of `ring` (1 to [`MAX_SMALL_READBACK_RING`]) buffers of `bytes` (4 to
    /// [`MAX_SMALL_READBACK_BYTES`], a multiple of 4) each, made now.
    pub fn new(device: &wgpu::Device, ring: usize, bytes: u64) -> Result<Self, GpuError> {
        if !(1..=MAX_SMALL_READBACK_RING).contains(&ring) {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "small readback ring size",
                value: ring as f64,
                expected: "1 to 16 buffers",
            }
            .into());
        }
        if !(4..=MAX_SMALL_READBACK_BYTES).contains(&bytes) || !bytes.is_multiple_of(4) {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "small readback bytes",
                value: bytes as f64,
                expected: "4 to 4096, a multiple of 4",
            }
            .into());
        }
        let slots = (0..ring)
            .map(|_| Slot {
                buffer: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("SmallReadback staging"),
                    size: bytes,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                state: Arc::new(AtomicU8::new(FREE)),
                seq: None,
            })
            .collect();
        Ok(Self {
            slots,
            bytes,
            next_seq: 0,
        })
    }

    /// Records the copy of the ring's byte count from `source` at `offset` into `encoder`,
    /// to be mapped when the encoder is submitted. `None` when every buffer is in flight (the
    /// caller skips this reading: a later one will come). Fails when the range is outside
    /// `source` or `offset` is not a multiple of 4.
    pub fn request(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::Buffer,
        offset: u64,
    ) -> Result<Option<u64>, GpuError> {
        if !offset.is_multiple_of(4) || offset.saturating_add(self.bytes) > source.size() {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "small readback offset",
                value: offset as f64,
                expected: "a multiple of 4 with the ring's bytes inside the source buffer",
            }
            .into());
        }
        self.free_abandoned();
        let Some(slot) = self.slots.iter_mut().find(|s| s.seq.is_none()) else {
            return Ok(None);
        };
        encoder.copy_buffer_to_buffer(source, offset, &slot.buffer, 0, self.bytes);
        slot.state.store(PENDING, Ordering::Release);
        let mut guard = SubmitGuard::new(slot.state.clone());
        encoder.map_buffer_on_submit(&slot.buffer, wgpu::MapMode::Read, 0..self.bytes, move |r| {
            guard.fire(if r.is_ok() { MAPPED } else { FAILED });
        });
        let seq = self.next_seq;
        self.next_seq += 1;
        slot.seq = Some(seq);
        Ok(Some(seq))
    }

    /// How many requests may be in flight at once (the ring's buffers).
    pub fn capacity(&self) -> usize {
        self.slots.len()
    }

    /// Requests recorded and not yet handed over (one whose encoder was dropped unsubmitted
    /// is not counted: its buffer is free again).
    pub fn in_flight(&self) -> usize {
        self.slots
            .iter()
            .filter(|s| s.seq.is_some() && s.state.load(Ordering::Acquire) != ABANDONED)
            .count()
    }

    /// Hands over every request that has arrived, oldest first, as (sequence number, bytes),
    /// without waiting for the others. A failed mapping is an error (its buffer is freed).
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<(u64, Vec<u8>)>, GpuError> {
        device.poll(wgpu::PollType::Poll)?;
        crate::device::trace::record("small readback: poll (in flight)", self.in_flight() as u64);
        self.free_abandoned();
        let mut arrived = Vec::new();
        let mut failed = false;
        for slot in &mut self.slots {
            let Some(seq) = slot.seq else { continue };
            match slot.state.load(Ordering::Acquire) {
                MAPPED => {
                    let bytes = slot
                        .buffer
                        .slice(..)
                        .get_mapped_range()
                        .map(|view| view.to_vec());
                    slot.buffer.unmap();
                    match bytes {
                        Ok(bytes) => arrived.push((seq, bytes)),
                        Err(_) => failed = true,
                    }
                }
                FAILED => {
                    failed = true;
                    slot.buffer.unmap();
                }
                _ => continue,
            }
            slot.seq = None;
            slot.state.store(FREE, Ordering::Release);
        }
        if failed {
            return Err(GpuError::SmallReadbackFailed);
        }
        arrived.sort_by_key(|(seq, _)| *seq);
        Ok(arrived)
    }

    fn free_abandoned(&mut self) {
        for slot in &mut self.slots {
            if slot.state.load(Ordering::Acquire) == ABANDONED {
                slot.seq = None;
                slot.state.store(FREE, Ordering::Release);
            }
        }
    }
}
