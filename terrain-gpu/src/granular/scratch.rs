//! `GranularScratch`: the per-area GPU buffers of a granular step (depth from below,
//! penetration, seed grids, accumulator, slope amounts, iterative-displacement grids, removed
//! counter); `GranularArea`, the inputs every pass over one active area shares; and the uniform
//! block the integer passes share.

use crate::device::compute::dispatch_size;
use crate::device::download::{download_bytes, map_and_read};
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::resources::maps::GpuHeightMap;
use bytemuck::{Pod, Zeroable};
use terrain_core::Rect;
use terrain_core::granular::{GranularError, MAX_SIDE, Penetration};

/// The `Granular` uniform block of the granular WGSL files, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub(crate) struct GranularUniform {
    pub area_min: [u32; 2],
    pub area_size: [u32; 2],
    pub map_width: u32,
    pub step: u32,
    pub pass_index: u32,
    pub metric: u32,
    pub keep_q15: u32,
    pub margin: u32,
    pub threshold_orth: u32,
    pub threshold_diag: u32,
    pub roughness_q15: u32,
    pub parity: u32,
    pub _pad: [u32; 2],
}

// The WGSL struct's size: a mismatch fails the build, not a dispatch.
const _: () = assert!(std::mem::size_of::<GranularUniform>() == 64);

impl GranularUniform {
    /// The block for `area` (other fields zero).
    pub fn for_area(area: &GranularArea<'_>) -> Self {
        let rect = area.rect();
        Self {
            area_min: [rect.min.x as u32, rect.min.y as u32],
            area_size: rect.size.to_array(),
            map_width: area.map().size().x,
            ..Self::default()
        }
    }
}

/// The per-area buffers of a granular step, for areas of up to [`GranularScratch::capacity`]
/// columns (all area-local, row-major): the depth from below (u32), the penetration texture
/// (`Penetration`, 16 bytes), two seed grids (`[u32; 2]`, ping-pong), the scatter accumulator
/// (u32, zero between uses), the slope amounts (`[u32; 2]`), the iterative displacement's
/// distance and lower-neighbour count per column (`[u32; 2]`) and carried material (two u32
/// grids, ping-pong: grid 1 starts right after the area's columns), and the u64 removed counter
/// (low, high words) with its readback buffer. Made once, and again only for a larger area.
#[derive(Debug)]
pub struct GranularScratch {
    capacity: u64,
    pub(crate) depth: wgpu::Buffer,
    pub(crate) pen: wgpu::Buffer,
    pub(crate) seeds: [wgpu::Buffer; 2],
    pub(crate) acc: wgpu::Buffer,
    pub(crate) amounts: wgpu::Buffer,
    pub(crate) dist: wgpu::Buffer,
    pub(crate) carried: wgpu::Buffer,
    pub(crate) removed: wgpu::Buffer,
    removed_readback: wgpu::Buffer,
}

impl GranularScratch {
    /// Bytes of GPU memory its buffers take (every per-column buffer, the counter and its
    /// readback).
    pub fn memory_bytes(&self) -> u64 {
        let per_column = [&self.depth, &self.pen, &self.acc, &self.amounts, &self.dist];
        per_column.iter().map(|b| b.size()).sum::<u64>()
            + self.seeds.iter().map(|b| b.size()).sum::<u64>()
            + self.carried.size()
            + self.removed.size()
            + self.removed_readback.size()
    }

    /// Buffers for areas of up to `columns` columns.
    pub fn new(device: &wgpu::Device, columns: u64) -> Result<Self, GpuError> {
        let columns = columns.max(1);
        let limits = device.limits();
        let limit = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let pen_bytes = columns.saturating_mul(std::mem::size_of::<Penetration>() as u64);
        if pen_bytes > limit {
            return Err(GpuError::MapTooLarge {
                size: glam::UVec2::new(u32::try_from(columns).unwrap_or(u32::MAX), 1),
                bytes: pen_bytes,
                limit,
            });
        }
        scoped(device, "GranularScratch", || {
            let buf = |label: &'static str, bytes: u64| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes,
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_DST
                        | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                })
            };
            Self {
                capacity: columns,
                depth: buf("granular depth from below", columns * 4),
                pen: buf("granular penetration", pen_bytes),
                seeds: [
                    buf("granular seeds A", columns * 8),
                    buf("granular seeds B", columns * 8),
                ],
                acc: buf("granular accumulator", columns * 4),
                amounts: buf("granular slope amounts", columns * 8),
                dist: buf("granular distance and lower-neighbour count", columns * 8),
                carried: buf("granular carried material", columns * 8),
                removed: buf("granular removed", 8),
                removed_readback: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("granular removed readback"),
                    size: 8,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
            }
        })
    }

    /// Most columns an area may have.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// The depth-from-below buffer (one u32 per column of the area, row-major): what
    /// [`super::PenetrationPass`] reads. Write it with [`super::DepthFromBelowPass::encode`] or
    /// [`super::PenetrationPass::upload_depth`].
    pub fn depth(&self) -> &wgpu::Buffer {
        &self.depth
    }

    /// The penetration texture buffer.
    pub fn penetration(&self) -> &wgpu::Buffer {
        &self.pen
    }

    /// Seed grid `index` (0 or 1) of the ping-pong pair.
    pub fn seeds(&self, index: usize) -> &wgpu::Buffer {
        &self.seeds[index & 1]
    }

    /// Records zeroing the removed counter.
    pub fn clear_removed(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.removed, 0, None);
    }

    /// Reads the removed counter back through the scratch's own 8-byte readback buffer
    /// (submits a copy and waits for the GPU).
    pub fn read_removed(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<u64, GpuError> {
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&self.removed, 0, &self.removed_readback, 0, 8);
        queue.submit([encoder.finish()]);
        let bytes = map_and_read(device, &self.removed_readback)?;
        let w: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(w.iter().rev().fold(0u64, |a, &v| (a << 32) | u64::from(v)))
    }

    /// Records the copy of the removed counter (of the step recorded last) into `ring` (a
    /// [`crate::SmallReadback`] of 8 bytes), to be read without a wait by its later poll
    /// (little-endian u64, as [`crate::granular::VolumePass::sum_of`] decodes it). `None` when
    /// every buffer of the ring is in flight.
    pub fn request_removed(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        ring: &mut crate::device::small_readback::SmallReadback,
    ) -> Result<Option<u64>, GpuError> {
        ring.request(encoder, &self.removed, 0)
    }

    /// Downloads the first `columns` penetration texels (waits for the GPU).
    pub fn read_penetration(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        columns: u64,
    ) -> Result<Vec<Penetration>, GpuError> {
        let bytes = download_bytes(device, queue, &self.pen, 0, columns.min(self.capacity) * 16)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// Downloads the first `columns` entries of seed grid `index` (waits for the GPU).
    pub fn read_seeds(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        index: usize,
        columns: u64,
    ) -> Result<Vec<[u32; 2]>, GpuError> {
        let bytes = download_bytes(
            device,
            queue,
            &self.seeds[index & 1],
            0,
            columns.min(self.capacity) * 8,
        )?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}

/// What every pass over one active area works on: the map, the area (in map columns) and the
/// scratch buffers, checked once when made: the area is non-empty, inside the map, at most
/// [`MAX_SIDE`] a side (as the CPU reference), fits the scratch, and its dispatch fits the
/// device.
#[derive(Debug, Clone, Copy)]
pub struct GranularArea<'a> {
    map: &'a GpuHeightMap<u32>,
    rect: Rect,
    scratch: &'a GranularScratch,
    groups: (u32, u32),
}

impl<'a> GranularArea<'a> {
    /// Checks `rect` against `map`, `scratch` and the device.
    pub fn new(
        device: &wgpu::Device,
        map: &'a GpuHeightMap<u32>,
        rect: Rect,
        scratch: &'a GranularScratch,
    ) -> Result<Self, GpuError> {
        if rect.is_empty() || !Rect::from_size(map.size()).contains_rect(&rect) {
            return Err(GpuError::BadRegion {
                rect,
                map_size: map.size(),
            });
        }
        let side = rect.size.max_element();
        if side > MAX_SIDE {
            return Err(GranularError::TooLarge {
                side,
                limit: MAX_SIDE,
            }
            .into());
        }
        if rect.area() > scratch.capacity() {
            return Err(GpuError::Unsupported {
                what: "GranularArea",
                reason: "the active area has more columns than the scratch buffers hold",
            });
        }
        Ok(Self {
            map,
            rect,
            scratch,
            groups: dispatch_size(device, rect.size)?,
        })
    }

    /// The map.
    pub fn map(&self) -> &'a GpuHeightMap<u32> {
        self.map
    }

    /// The area in map columns.
    pub fn rect(&self) -> Rect {
        self.rect
    }

    /// The scratch buffers.
    pub fn scratch(&self) -> &'a GranularScratch {
        self.scratch
    }

    /// Workgroups covering the area.
    pub(crate) fn groups(&self) -> (u32, u32) {
        self.groups
    }
}
