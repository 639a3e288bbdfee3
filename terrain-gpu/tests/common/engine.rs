//! The engine's side of drawing into the caller's pass: a swap-chain-like colour target (sRGB,
//! 4x MSAA resolved into a single-sample texture) with its own depth buffer, and the engine's
//! main pass over them. Shared by the `own_device` example and the render test that compares
//! this path with the offscreen capture, so the test checks what the example shows.

use glam::UVec2;
use terrain_gpu::{DepthConvention, TargetFormat, wgpu};

/// The engine's formats: BGRA sRGB colour and 24-bit depth, 4x MSAA.
pub const FORMAT: TargetFormat = TargetFormat {
    color: wgpu::TextureFormat::Bgra8UnormSrgb,
    depth: wgpu::TextureFormat::Depth24Plus,
    sample_count: 4,
    depth_convention: DepthConvention::Forward,
};

/// The engine's frame textures of one size, in [`FORMAT`].
pub struct EngineTargets {
    msaa: wgpu::TextureView,
    depth: wgpu::TextureView,
    resolve: wgpu::TextureView,
    /// The single-sample colour the MSAA samples resolve into: what an engine presents (read
    /// back here).
    pub resolved: wgpu::Texture,
}

impl EngineTargets {
    pub fn new(device: &wgpu::Device, size: UVec2) -> Self {
        let texture = |label, format, samples, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: size.x,
                    height: size.y,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let attachment = wgpu::TextureUsages::RENDER_ATTACHMENT;
        let view = |t: wgpu::Texture| t.create_view(&Default::default());
        let resolved = texture(
            "resolved colour",
            FORMAT.color,
            1,
            attachment | wgpu::TextureUsages::COPY_SRC,
        );
        Self {
            msaa: view(texture("msaa colour", FORMAT.color, 4, attachment)),
            depth: view(texture("msaa depth", FORMAT.depth, 4, attachment)),
            resolve: resolved.create_view(&Default::default()),
            resolved,
        }
    }

    /// Begins the engine's main pass: colour and depth cleared; the MSAA samples and the depth
    /// are discarded after the pass (only the resolved colour is kept).
    pub fn begin_pass<'e>(&self, encoder: &'e mut wgpu::CommandEncoder) -> wgpu::RenderPass<'e> {
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("engine main pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &self.msaa,
                depth_slice: None,
                resolve_target: Some(&self.resolve),
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Discard,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            ..Default::default()
        })
    }
}
