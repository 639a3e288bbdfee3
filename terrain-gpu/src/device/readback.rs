//! `RegionReadback`: copies a rect of a GPU height map into one of a small ring of staging
//! buffers and maps it on submit; `poll` hands over the regions that have arrived without ever
//! waiting, so the frame is never stalled.

use crate::error::GpuError;
use crate::resources::maps::{GpuHeightMap, MapView};
use crate::resources::packing;
use glam::UVec2;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use terrain_core::{Grid, HeightEncoding, HeightSample, Rect, WrapMode};

/// Identifies one request; regions arrive with the ticket they were requested with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ReadbackTicket(pub u64);

/// A region that arrived: the stored values of `rect`, row-major in the rect's own (unwrapped)
/// coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionData {
    /// The request it answers.
    pub ticket: ReadbackTicket,
    /// The rect asked for (unwrapped on a repeating map).
    pub rect: Rect,
    /// Stored values.
    pub raw: Grid<u32>,
    /// The map's encoding, to turn values into metres.
    pub encoding: HeightEncoding,
}

impl RegionData {
    /// The rows as u16 (the coarse-map's own encoding).
    pub fn to_u16(&self) -> Grid<u16> {
        self.raw.map(|&v| stored_u16(v))
    }

    /// The rows as heights in metres.
    pub fn to_metres(&self) -> Grid<f32> {
        self.raw.map(|&v| stored_metres(self.encoding, v))
    }

    /// An owned copy of a region seen in the staging buffer.
    fn from_view(view: RegionView<'_>) -> Result<Self, GpuError> {
        Ok(Self {
            ticket: view.ticket,
            rect: view.rect,
            raw: view.to_grid(|&v| v)?,
            encoding: view.encoding,
        })
    }
}

/// A region that arrived, seen in its mapped staging buffer for the length of a
/// [`RegionReadback::poll_with`] conversion: the stored values of `rect`, row-major in the
/// rect's own (unwrapped) coordinates.
#[derive(Debug, Clone, Copy)]
pub struct RegionView<'a> {
    /// The request it answers.
    pub ticket: ReadbackTicket,
    /// The rect asked for.
    pub rect: Rect,
    /// Stored values, `rect.area()` of them.
    pub values: &'a [u32],
    /// The map's encoding, to turn values into metres.
    pub encoding: HeightEncoding,
}

impl RegionView<'_> {
    /// The region as a grid of `f(value)`, built in one pass over the mapped values; an error
    /// only for a view whose values do not fill its rect (a view made by hand).
    pub fn to_grid<U: Copy>(&self, f: impl FnMut(&u32) -> U) -> Result<Grid<U>, GpuError> {
        let values = self.values.iter().map(f).collect();
        Ok(Grid::from_vec(self.rect.size.x, self.rect.size.y, values)?)
    }

    /// The rows as u16 (the coarse-map's own encoding), as [`RegionData::to_u16`].
    pub fn to_u16(&self) -> Result<Grid<u16>, GpuError> {
        self.to_grid(|&v| stored_u16(v))
    }

    /// The rows as heights in metres, as [`RegionData::to_metres`].
    pub fn to_metres(&self) -> Result<Grid<f32>, GpuError> {
        self.to_grid(|&v| stored_metres(self.encoding, v))
    }

    /// The rows as u8, a detail tile's own values ([`RegionReadback::request_detail`] regions;
    /// saturating, as detail tiles never store more).
    pub fn to_u8(&self) -> Result<Grid<u8>, GpuError> {
        self.to_grid(|&v| v.min(255) as u8)
    }
}

/// A stored value as the coarse-map's u16 (u16 maps never store more; saturates otherwise).
fn stored_u16(v: u32) -> u16 {
    v.min(u32::from(u16::MAX)) as u16
}

/// A stored value as a height in metres.
fn stored_metres(encoding: HeightEncoding, v: u32) -> f32 {
    encoding.to_metres(f64::from(v))
}

pub(crate) const FREE: u8 = 0;
pub(crate) const PENDING: u8 = 1;
pub(crate) const MAPPED: u8 = 2;
pub(crate) const FAILED: u8 = 3;
/// The commands that would have mapped the slot were dropped without being submitted.
pub(crate) const ABANDONED: u8 = 4;

/// Travels with a request's map callback. wgpu drops the callback uncalled when the encoder
/// (or the command buffer) that carries it is dropped without submit; the guard then marks
/// the slot abandoned, so it is freed instead of waiting forever. Once the callback has run it
/// never touches the slot again (the slot may already serve a newer request by the time the
/// closure is dropped, on a thread that polls the device).
pub(crate) struct SubmitGuard {
    state: Arc<AtomicU8>,
    fired: bool,
}

impl SubmitGuard {
    /// A guard for the slot whose state is `state` (set to `PENDING` by the caller).
    pub(crate) fn new(state: Arc<AtomicU8>) -> Self {
        Self {
            state,
            fired: false,
        }
    }

    pub(crate) fn fire(&mut self, state: u8) {
        self.fired = true;
        self.state.store(state, Ordering::Release);
    }
}

impl Drop for SubmitGuard {
    fn drop(&mut self) {
        if !self.fired {
            let _ = self.state.compare_exchange(
                PENDING,
                ABANDONED,
                Ordering::AcqRel,
                Ordering::Acquire,
            );
        }
    }
}

#[derive(Debug)]
struct Slot {
    buffer: wgpu::Buffer,
    state: Arc<AtomicU8>,
    request: Option<Request>,
}

/// A request in flight: what was asked, and where its rows lie in the staging buffer.
#[derive(Debug)]
struct Request {
    ticket: ReadbackTicket,
    rect: Rect,
    encoding: HeightEncoding,
    copies: RegionCopies,
}

/// A ring of staging buffers for asynchronous region readback.
#[derive(Debug)]
pub struct RegionReadback {
    slots: Vec<Slot>,
    /// A failure to report on the next poll (regions that arrived with it went out first).
    failure: Option<Vec<Rect>>,
}

/// Bytes each staging buffer starts with (a 128 x 128 region of u32 heights).
const INITIAL_SLOT_BYTES: u64 = 128 * 128 * 4;

fn staging(device: &wgpu::Device, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("RegionReadback staging"),
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Most staging buffers a ring may have.
pub const MAX_READBACK_RING: usize = 16;

impl RegionReadback {
    /// A ring of `ring` staging buffers (1 to [`MAX_READBACK_RING`]), made now with room for a
    /// 128 x 128 region each; a slot's buffer is replaced by a larger one when a larger region is
    /// asked for, so the ring holds `ring` buffers from the start and never more.
    pub fn new(device: &wgpu::Device, ring: usize) -> Result<Self, GpuError> {
        if !(1..=MAX_READBACK_RING).contains(&ring) {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "readback ring size",
                value: ring as f64,
                expected: "1 to 16 buffers",
            }
            .into());
        }
        let slots = (0..ring)
            .map(|_| Slot {
                buffer: staging(device, INITIAL_SLOT_BYTES),
                state: Arc::new(AtomicU8::new(FREE)),
                request: None,
            })
            .collect();
        Ok(Self {
            slots,
            failure: None,
        })
    }

    /// Staging buffers in the ring: at most this many requests can be in flight.
    pub fn ring(&self) -> usize {
        self.slots.len()
    }

    /// Requests in flight (recorded, not yet handed over by `poll`). A request whose
    /// encoder was dropped without submit is not in flight: its slot is free again.
    pub fn in_flight(&self) -> usize {
        self.slots
            .iter()
            .filter(|s| s.request.is_some() && s.state.load(Ordering::Acquire) != ABANDONED)
            .count()
    }

    /// Records the copy of `rect` of `map` into `encoder` and arranges for the staging buffer to
    /// be mapped when the encoder's commands are submitted. The encoder must be submitted for the
    /// region to arrive. On a repeating map `rect` may cross the edges (at most one period per
    /// axis); on a clamped map it must lie inside.
    pub fn request<T: HeightSample>(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
        rect: Rect,
    ) -> Result<ReadbackTicket, GpuError> {
        self.request_view(device, encoder, map.view(), rect)
    }

    /// Records the copy of `rect` (tile texels, inside the tile) of the tile in `tile.slot` of
    /// `atlas`, a tile of level `tile.level`: how a tile deformed on the GPU
    /// ([`crate::StampPass::encode_tile`]) reaches the CPU, its changed rect only.
    pub fn request_tile(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        atlas: &crate::GpuTileAtlas,
        tile: crate::TileSlot,
        rect: Rect,
    ) -> Result<ReadbackTicket, GpuError> {
        let view = atlas.slot_view(tile)?;
        self.request_view(device, encoder, view, rect)
    }

    /// Records the copy of `rect` (tile texels, inside the tile) of the resident detail tile
    /// `tile` of `tiles`: how a detail stamp's changed rect reaches the CPU without a wait
    /// (its values arrive through [`RegionView::to_u8`]). Fails for a tile without a slot.
    pub fn request_detail(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        tiles: &crate::GpuDetailTiles,
        tile: glam::UVec2,
        rect: Rect,
    ) -> Result<ReadbackTicket, GpuError> {
        let view = tiles.slot_view(tile)?;
        self.request_view(device, encoder, view, rect)
    }

    fn request_view(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: MapView<'_>,
        rect: Rect,
    ) -> Result<ReadbackTicket, GpuError> {
        let size = map.size;
        let valid = !rect.is_empty()
            && match map.wrap {
                WrapMode::Repeat => rect.size.cmple(size).all() && rect.is_representable(),
                WrapMode::Clamp => Rect::from_size(size).contains_rect(&rect),
            };
        if !valid {
            return Err(GpuError::BadRegion {
                rect,
                map_size: size,
            });
        }
        let ring = self.slots.len();
        self.free_abandoned();
        let Some(slot) = self.slots.iter_mut().find(|s| s.request.is_none()) else {
            return Err(GpuError::ReadbackBusy { ring });
        };
        let copies = RegionCopies::plan(map, rect);
        let bytes = copies.words.max(1) * 4;
        // A slot keeps its staging buffer; it is only replaced by a larger one.
        if slot.buffer.size() < bytes {
            slot.buffer = staging(device, bytes);
        }
        let buffer = &slot.buffer;
        copies.record(encoder, map, buffer);
        slot.state.store(PENDING, Ordering::Release);
        let mut guard = SubmitGuard::new(slot.state.clone());
        encoder.map_buffer_on_submit(buffer, wgpu::MapMode::Read, 0..bytes, move |r| {
            guard.fire(if r.is_ok() { MAPPED } else { FAILED });
        });
        // Process-wide, so a ring made again never repeats a ticket an older one handed out.
        let ticket = ReadbackTicket(terrain_core::RequestId::fresh().0);
        slot.request = Some(Request {
            ticket,
            rect,
            encoding: map.encoding,
            copies,
        });
        Ok(ticket)
    }

    /// Hands over every region that has arrived, without waiting for the others.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<RegionData>, GpuError> {
        self.poll_with(device, RegionData::from_view)?
            .into_iter()
            .collect()
    }

    /// Waits until every request in flight has arrived and hands them over (tests, shutdown).
    pub fn wait(&mut self, device: &wgpu::Device) -> Result<Vec<RegionData>, GpuError> {
        self.wait_with(device, RegionData::from_view)?
            .into_iter()
            .collect()
    }

    /// [`Self::poll`], handing each region's stored values to `convert` straight from the
    /// mapped staging buffer: a caller that keeps u16 rows or metres builds them in one pass,
    /// with no u32 copy of the region in between (for a full 4096^2 map that copy is 64 MiB,
    /// and allocating and filling it cost more than the transfer). `convert` sees each region
    /// as a [`RegionView`]; the results come in ticket order. A conversion that can fail
    /// returns a `Result` for the caller to gather, as [`Self::poll`] does.
    pub fn poll_with<R>(
        &mut self,
        device: &wgpu::Device,
        convert: impl FnMut(RegionView<'_>) -> R,
    ) -> Result<Vec<R>, GpuError> {
        device.poll(wgpu::PollType::Poll)?;
        let arrived = self.collect(convert)?;
        crate::device::trace::record(
            "region readback: poll (regions arrived)",
            arrived.len() as u64,
        );
        if !arrived.is_empty() {
            tracing::debug!(regions = arrived.len(), "region readbacks arrived");
        }
        Ok(arrived)
    }

    /// [`Self::wait`] with [`Self::poll_with`]'s conversion.
    pub fn wait_with<R>(
        &mut self,
        device: &wgpu::Device,
        convert: impl FnMut(RegionView<'_>) -> R,
    ) -> Result<Vec<R>, GpuError> {
        crate::device::trace::record("region readback: blocking poll", 0);
        device.poll(crate::device::download::wait_bounded())?;
        crate::device::trace::record("region readback: blocking poll returned", 0);
        self.collect(convert)
    }

    /// Frees the slots of requests whose commands were dropped without submit (nothing was
    /// mapped, so the buffer is ready for the next request).
    fn free_abandoned(&mut self) {
        for slot in &mut self.slots {
            if slot.state.load(Ordering::Acquire) == ABANDONED {
                slot.request = None;
                slot.state.store(FREE, Ordering::Release);
            }
        }
    }

    /// Hands over the regions that arrived, each through `convert`, in ticket order. A failed
    /// mapping (device loss) is reported after the others are handed over: on the next call
    /// when regions came with it, so none is dropped.
    fn collect<R>(
        &mut self,
        mut convert: impl FnMut(RegionView<'_>) -> R,
    ) -> Result<Vec<R>, GpuError> {
        self.free_abandoned();
        if let Some(rects) = self.failure.take() {
            return Err(GpuError::ReadbackFailed { rects });
        }
        let mut arrived: Vec<(ReadbackTicket, R)> = Vec::new();
        let mut failures = Vec::new();
        for slot in &mut self.slots {
            let state = slot.state.load(Ordering::Acquire);
            if state != MAPPED && state != FAILED {
                continue;
            }
            let Some(Request {
                ticket,
                rect,
                encoding,
                copies,
            }) = slot.request.take()
            else {
                continue;
            };
            let buffer = &slot.buffer;
            slot.state.store(FREE, Ordering::Release);
            if state == FAILED {
                // Hand over what did arrive; report the failure on its own.
                failures.push(rect);
                continue;
            }
            // A region that cannot be viewed counts as failed, like a failed mapping: the
            // regions already collected are still handed over.
            let bytes = copies.words.max(1) * 4;
            let converted = buffer.get_mapped_range(0..bytes).ok().and_then(|view| {
                let words: &[u32] = bytemuck::try_cast_slice(&view).ok()?;
                let values = copies.unpack(words, rect);
                Some(convert(RegionView {
                    ticket,
                    rect,
                    values: &values,
                    encoding,
                }))
            });
            buffer.unmap();
            match converted {
                Some(r) => arrived.push((ticket, r)),
                None => failures.push(rect),
            }
        }
        arrived.sort_by_key(|(ticket, _)| *ticket);
        if !failures.is_empty() {
            if arrived.is_empty() {
                return Err(GpuError::ReadbackFailed { rects: failures });
            }
            self.failure = Some(failures);
        }
        Ok(arrived.into_iter().map(|(_, r)| r).collect())
    }
}

/// How a region's rows travel: per piece of the rect (one, or up to four across a repeating
/// map's edges), the packed words of its rows, copied one after the other into the staging
/// buffer, and unpacked into the rect's row-major texels when they arrive.
#[derive(Debug)]
struct RegionCopies {
    pieces: Vec<PieceCopy>,
    bits: u32,
    /// Words of the staging buffer used.
    words: u64,
}

/// One piece: `rows` rows of `pitch` words from word `at` of the staging buffer; its texel
/// `(0, 0)` is lane `lane0` of its first word and texel `offset` of the rect.
#[derive(Debug)]
struct PieceCopy {
    map: Rect,
    offset: UVec2,
    at: u64,
    pitch: u64,
    lane0: u32,
}

impl RegionCopies {
    fn plan(map: MapView<'_>, rect: Rect) -> Self {
        let pieces = match map.wrap {
            WrapMode::Repeat => rect.split_toroidal(map.size),
            WrapMode::Clamp => vec![terrain_core::WrappedPiece {
                map: rect,
                unwrapped: rect,
            }],
        };
        let lanes = packing::lanes(map.bits);
        let mut at = 0;
        let pieces = pieces
            .into_iter()
            .map(|p| {
                let (x0, x1) = (p.map.min.x as u32, p.map.max().x as u32);
                let pitch = u64::from(x1.div_ceil(lanes) - x0 / lanes);
                let piece = PieceCopy {
                    map: p.map,
                    offset: (p.unwrapped.min - rect.min).as_uvec2(),
                    at,
                    pitch,
                    lane0: x0 % lanes,
                };
                at += pitch * u64::from(p.map.size.y);
                piece
            })
            .collect();
        Self {
            pieces,
            bits: map.bits,
            words: at,
        }
    }

    /// Records the copies into `dst`.
    fn record(&self, encoder: &mut wgpu::CommandEncoder, map: MapView<'_>, dst: &wgpu::Buffer) {
        let map_pitch = u64::from(packing::pitch(map.size.x, self.bits));
        let lanes = packing::lanes(self.bits);
        let base = u64::from(map.base);
        for piece in &self.pieces {
            let first_word = u64::from(piece.map.min.x as u32 / lanes);
            let row0 = piece.map.min.y as u64;
            if piece.pitch == map_pitch {
                // Whole rows of the map: contiguous, so one copy instead of one a row (4096
                // commands for a full 4096^2 readback).
                let rows = u64::from(piece.map.size.y);
                let src = (base + row0 * map_pitch) * 4;
                encoder.copy_buffer_to_buffer(
                    map.buffer,
                    src,
                    dst,
                    piece.at * 4,
                    rows * map_pitch * 4,
                );
                continue;
            }
            for row in 0..u64::from(piece.map.size.y) {
                let src = (base + (row0 + row) * map_pitch + first_word) * 4;
                let at = (piece.at + row * piece.pitch) * 4;
                encoder.copy_buffer_to_buffer(map.buffer, src, dst, at, piece.pitch * 4);
            }
        }
    }

    /// The rect's texel values, row-major, from the staging buffer's `words`.
    fn unpack(&self, words: &[u32], rect: Rect) -> Vec<u32> {
        let mut out = vec![0u32; rect.area() as usize];
        let lanes = packing::lanes(self.bits);
        let mask = u32::MAX >> (32 - self.bits);
        let w = rect.size.x as usize;
        for piece in &self.pieces {
            for row in 0..piece.map.size.y {
                let start = (piece.at + u64::from(row) * piece.pitch) as usize;
                let src = &words[start..start + piece.pitch as usize];
                let o = (piece.offset.y + row) as usize * w + piece.offset.x as usize;
                for (i, d) in out[o..o + piece.map.size.x as usize].iter_mut().enumerate() {
                    let x = piece.lane0 + i as u32;
                    *d = (src[(x / lanes) as usize] >> ((x % lanes) * self.bits)) & mask;
                }
            }
        }
        out
    }
}
