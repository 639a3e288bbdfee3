//! `GpuGranularMap`: the u32 fixed-point heights of a `FixedPointMap` in a storage buffer.

use crate::download::download_bytes;
use crate::error::GpuError;
use crate::maps::map_buffer;
use glam::UVec2;
use terrain_core::{FixedPointMap, Grid, HeightEncoding, WrapMode};

/// A [`FixedPointMap`] on the GPU: one u32 per column, row-major, in a storage buffer
/// (copyable both ways), with the map's encoding and texel size. Pairs with
/// [`terrain_core::FixedPointMap`].
#[derive(Debug)]
pub struct GpuGranularMap {
    buffer: wgpu::Buffer,
    size: UVec2,
    encoding: HeightEncoding,
    texel_size: f32,
    wrap: WrapMode,
}

impl GpuGranularMap {
    /// Uploads `map`.
    pub fn from_map(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &FixedPointMap,
    ) -> Result<Self, GpuError> {
        let size = map.size();
        let bytes = u64::from(size.x) * u64::from(size.y) * 4;
        if bytes == 0 {
            return Err(terrain_core::CoreError::EmptyGrid {
                width: size.x,
                height: size.y,
            }
            .into());
        }
        let buffer = map_buffer(device, "GpuGranularMap", size, bytes)?;
        let gpu = Self {
            buffer,
            size,
            encoding: map.encoding(),
            texel_size: map.texel_size(),
            wrap: map.wrap(),
        };
        gpu.write(queue, map)?;
        Ok(gpu)
    }

    /// Replaces the heights with those of `map` (same size).
    pub fn write(&self, queue: &wgpu::Queue, map: &FixedPointMap) -> Result<(), GpuError> {
        if map.size() != self.size {
            return Err(GpuError::SizeMismatch {
                expected: self.size,
                actual: map.size(),
            });
        }
        queue.write_buffer(&self.buffer, 0, bytemuck::cast_slice(map.grid().as_slice()));
        Ok(())
    }

    /// Downloads the heights as a [`FixedPointMap`] (waits for the GPU).
    pub fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<FixedPointMap, GpuError> {
        let data = self.read_raw(device, queue)?;
        let grid = Grid::from_vec(self.size.x, self.size.y, data)?;
        Ok(FixedPointMap::new(
            grid,
            self.encoding,
            self.texel_size,
            self.wrap,
        )?)
    }

    /// Downloads the raw heights, row-major (waits for the GPU).
    pub fn read_raw(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<u32>, GpuError> {
        let bytes = download_bytes(device, queue, &self.buffer, 0, self.buffer.size())?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// The u64 sum of all heights (the conserved volume), downloaded (waits for the GPU).
    pub fn raw_sum(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<u64, GpuError> {
        Ok(self
            .read_raw(device, queue)?
            .iter()
            .map(|&h| u64::from(h))
            .sum())
    }

    /// The storage buffer.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Size in columns.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// The height encoding (fixed point: scale `1 / units_per_metre`).
    pub fn encoding(&self) -> HeightEncoding {
        self.encoding
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// Fixed-point units per metre (`1 / scale`, rounded).
    pub fn units_per_metre(&self) -> f64 {
        (1.0 / f64::from(self.encoding.scale)).round()
    }
}
