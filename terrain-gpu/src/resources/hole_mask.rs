//! [`GpuHoleMask`]: a hole mask (`terrain_core::holes`) on the GPU, bound by every renderer at
//! binding 15 (`set_hole_mask`), whose fragments discard over a hole.
//!
//! The mask is authored on the CPU and uploaded by rect ([`GpuHoleMask::write`]): collision
//! needs it on the CPU anyway, it is one byte per cell and it changes rarely, so an upload of
//! the cells a stamp changed costs less than a compute pass and a readback would.

use crate::device::scope::scoped;
use crate::error::GpuError;
use glam::UVec2;
use terrain_core::{CoreError, Grid, Rect};

/// A hole mask on the GPU: an R8 texture of one texel per map cell, nonzero where the ground
/// is cut away. Cloning shares the texture.
#[derive(Debug, Clone)]
pub struct GpuHoleMask {
    pub(crate) texture: wgpu::Texture,
    pub(crate) view: wgpu::TextureView,
    pub(crate) size: UVec2,
}

impl GpuHoleMask {
    /// Uploads `mask` (row-major, one byte per map cell, 0 for ground). Fails on a side above
    /// the device's `max_texture_dimension_2d`.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mask: &Grid<u8>,
    ) -> Result<Self, GpuError> {
        let size = mask.size();
        let max = device.limits().max_texture_dimension_2d;
        if size.max_element() > max {
            return Err(CoreError::OutOfRange {
                what: "hole mask side",
                value: f64::from(size.max_element()),
                expected: "at most the device's max_texture_dimension_2d",
            }
            .into());
        }
        let texture = scoped(device, "hole mask", || {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("hole mask"),
                size: wgpu::Extent3d {
                    width: size.x,
                    height: size.y,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        })?;
        let view = texture.create_view(&Default::default());
        let out = Self {
            texture,
            view,
            size,
        };
        out.write(queue, mask, Rect::from_size(size))?;
        Ok(out)
    }

    /// The mask's size in cells (the map's it is drawn over).
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// GPU bytes: one per cell.
    pub fn bytes(&self) -> u64 {
        u64::from(self.size.x) * u64::from(self.size.y)
    }

    /// Uploads `rect` of `mask` (the whole mask, as the CPU holds it; e.g. a rect that
    /// `terrain_core::apply_hole_stamp` returned), drawn from the next submission on. Fails,
    /// with nothing uploaded, on a mask of another size or a rect not inside it.
    pub fn write(&self, queue: &wgpu::Queue, mask: &Grid<u8>, rect: Rect) -> Result<(), GpuError> {
        if mask.size() != self.size {
            return Err(CoreError::SizeMismatch {
                expected: self.size,
                actual: mask.size(),
            }
            .into());
        }
        if !Rect::from_size(self.size).contains_rect(&rect) {
            return Err(CoreError::RegionOutOfBounds {
                rect,
                map_size: self.size,
            }
            .into());
        }
        if rect.is_empty() {
            return Ok(());
        }
        let offset = u64::from(rect.min.y as u32) * u64::from(self.size.x) + rect.min.x as u64;
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: rect.min.x as u32,
                    y: rect.min.y as u32,
                    z: 0,
                },
                aspect: wgpu::TextureAspect::All,
            },
            mask.as_slice(),
            wgpu::TexelCopyBufferLayout {
                offset,
                bytes_per_row: Some(self.size.x),
                rows_per_image: Some(rect.size.y),
            },
            wgpu::Extent3d {
                width: rect.size.x,
                height: rect.size.y,
                depth_or_array_layers: 1,
            },
        );
        Ok(())
    }
}
