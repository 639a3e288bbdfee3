//! `OffscreenTarget`: a colour + depth target of any size, read back to RGBA8: the convenience
//! for frame captures (renderers draw into any caller's pass; writing the capture as PNG is
//! terrain-core's `io::write_png_rgba8`).

use crate::device::download::map_and_read;
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::render::target::TargetFormat;
use glam::UVec2;
use terrain_core::Grid;

/// Colour format of captures: plain 8-bit RGBA, no sRGB conversion, so shaders write the
/// bytes that end up in the PNG.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Depth format.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// An offscreen colour and depth target.
#[derive(Debug)]
pub struct OffscreenTarget {
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    /// Where captures land on their way to the CPU (rows padded to the copy alignment).
    staging: wgpu::Buffer,
    size: UVec2,
}

/// Bytes per row of a capture of `width` pixels, padded to wgpu's copy alignment.
fn padded_row(width: u32) -> u32 {
    (width * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

impl OffscreenTarget {
    /// A target of `size` pixels (each side 1 to the device's 2D texture limit).
    pub fn new(device: &wgpu::Device, size: UVec2) -> Result<Self, GpuError> {
        let max = device.limits().max_texture_dimension_2d;
        if size.x == 0 || size.y == 0 || size.max_element() > max {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "offscreen target side (pixels)",
                value: f64::from(size.max_element()),
                expected: "1 to the device's max_texture_dimension_2d",
            }
            .into());
        }
        let extent = wgpu::Extent3d {
            width: size.x,
            height: size.y,
            depth_or_array_layers: 1,
        };
        let (color, depth, staging) = scoped(device, "offscreen target", || {
            let texture = |label, format, usage| {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: extent,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
            };
            (
                texture(
                    "offscreen colour",
                    COLOR_FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                ),
                texture(
                    "offscreen depth",
                    DEPTH_FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT,
                ),
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("capture staging"),
                    size: u64::from(padded_row(size.x)) * u64::from(size.y),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
            )
        })?;
        Ok(Self {
            color_view: color.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            color,
            staging,
            size,
        })
    }

    /// Size in pixels.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// The colour view to render into.
    pub fn color_view(&self) -> &wgpu::TextureView {
        &self.color_view
    }

    /// The depth view.
    pub fn depth_view(&self) -> &wgpu::TextureView {
        &self.depth_view
    }

    /// The formats of this target, for building renderers that draw into it.
    pub fn format(&self) -> TargetFormat {
        TargetFormat::CAPTURE
    }

    /// Begins a render pass over this target that clears colour to `clear` and depth to 1; the
    /// sky and the terrain renderers then draw into it.
    pub fn begin_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        clear: wgpu::Color,
    ) -> wgpu::RenderPass<'e> {
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("OffscreenTarget"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &self.color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(clear),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }

    /// Copies the colour target to the CPU (blocking), as RGBA8 rows from the top.
    pub fn read_rgba8(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Grid<[u8; 4]>, GpuError> {
        let (w, h) = (self.size.x, self.size.y);
        let row = w * 4;
        let padded = padded_row(w);
        let staging = &self.staging;
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            self.color.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(h),
                },
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        queue.submit([encoder.finish()]);
        let bytes = map_and_read(device, staging)?;
        let pixels = (0..h as usize)
            .flat_map(|y| {
                let start = y * padded as usize;
                bytes[start..start + row as usize]
                    .chunks_exact(4)
                    .map(|p| [p[0], p[1], p[2], p[3]])
            })
            .collect();
        Ok(Grid::from_vec(w, h, pixels)?)
    }
}
