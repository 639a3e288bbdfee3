//! `GranularScratch`: the per-area GPU textures of a granular step (penetration, seed grids,
//! accumulator, slope amounts, iterative-displacement grids, removed counter), and the uniform block the integer passes share.

use crate::compute::dispatch_size;
use crate::download::download_bytes;
use crate::error::GpuError;
use crate::scope::scoped;
use bytemuck::{Pod, Zeroable};
use terrain_core::Rect;
use terrain_core::granular::Penetration;
use wgpu::util::DeviceExt;

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
    /// The block for `area` of a map `map_width` columns wide (other fields zero).
    pub fn for_area(area: Rect, map_width: u32) -> Self {
        Self {
            area_min: [area.min.x as u32, area.min.y as u32],
            area_size: area.size.to_array(),
            map_width,
            ..Self::default()
        }
    }

    /// A uniform buffer holding `self`.
    pub fn buffer(&self, device: &wgpu::Device) -> wgpu::Buffer {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("GranularUniform"),
            contents: bytemuck::bytes_of(self),
            usage: wgpu::BufferUsages::UNIFORM,
        })
    }
}

/// Checks that `area` is non-empty and inside a map of `map_size`, and returns its dispatch.
pub(crate) fn area_dispatch(
    device: &wgpu::Device,
    area: Rect,
    map_size: glam::UVec2,
) -> Result<(u32, u32), GpuError> {
    if area.is_empty() || !Rect::from_size(map_size).contains_rect(&area) {
        return Err(GpuError::BadRegion {
            rect: area,
            map_size,
        });
    }
    dispatch_size(device, area.size)
}

/// The per-area buffers of a granular step, for areas of up to [`GranularScratch::capacity`]
/// columns (all area-local, row-major): the penetration texture (`Penetration`, 16 bytes), two
/// seed grids (`[u32; 2]`, ping-pong), the scatter accumulator (u32, zero between uses), the
/// slope amounts (`[u32; 2]`), the iterative displacement's distance and lower-neighbour
/// count per column (`[u32; 2]`) and carried material (two u32 grids, ping-pong: grid 1
/// starts right after the area's columns), and the u64 removed counter (low, high words).
#[derive(Debug)]
pub struct GranularScratch {
    capacity: u64,
    pub(crate) pen: wgpu::Buffer,
    pub(crate) seeds: [wgpu::Buffer; 2],
    pub(crate) acc: wgpu::Buffer,
    pub(crate) amounts: wgpu::Buffer,
    pub(crate) dist: wgpu::Buffer,
    pub(crate) carried: wgpu::Buffer,
    pub(crate) removed: wgpu::Buffer,
}

impl GranularScratch {
    /// Buffers for areas of up to `columns` columns.
    pub fn new(device: &wgpu::Device, columns: u64) -> Result<Self, GpuError> {
        let columns = columns.max(1);
        let limits = device.limits();
        let limit = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let pen_bytes = columns * std::mem::size_of::<Penetration>() as u64;
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
            }
        })
    }

    /// Most columns an area may have.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// Fails unless an area of `area` fits.
    pub(crate) fn check(&self, area: Rect) -> Result<(), GpuError> {
        if area.area() > self.capacity {
            return Err(GpuError::Unsupported {
                what: "GranularScratch",
                reason: "the active area has more columns than the scratch buffers hold",
            });
        }
        Ok(())
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

    /// Downloads the removed counter (waits for the GPU).
    pub fn read_removed(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<u64, GpuError> {
        let bytes = download_bytes(device, queue, &self.removed, 0, 8)?;
        let w: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(w.iter().rev().fold(0u64, |a, &v| (a << 32) | u64::from(v)))
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
