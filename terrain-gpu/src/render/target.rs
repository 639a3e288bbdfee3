//! `TargetFormat`: the formats of the caller's render pass that a renderer is built for, checked
//! before wgpu sees them.

use crate::error::GpuError;

/// The colour and depth formats and the sample count of the render pass a renderer draws into
/// (the caller's own pass, an engine's swap chain, or an [`crate::OffscreenTarget`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TargetFormat {
    /// Colour attachment format. On an sRGB format the renderers hand the hardware linear
    /// values, so the displayed bytes equal those of a plain `Rgba8Unorm` capture.
    pub color: wgpu::TextureFormat,
    /// Depth attachment format (any format with a depth aspect).
    pub depth: wgpu::TextureFormat,
    /// Samples per pixel (1, or 4 for MSAA).
    pub sample_count: u32,
}

impl TargetFormat {
    /// The formats of [`crate::OffscreenTarget`] captures: `Rgba8Unorm`, `Depth32Float`, 1 sample.
    pub const CAPTURE: Self = Self {
        color: crate::render::offscreen::COLOR_FORMAT,
        depth: crate::render::offscreen::DEPTH_FORMAT,
        sample_count: 1,
    };

    /// Checks that `device` can render to these formats with this sample count, using the
    /// features every adapter guarantees for them.
    pub fn validate(&self, device: &wgpu::Device) -> Result<(), GpuError> {
        let features = device.features();
        let color = self.color.guaranteed_format_features(features);
        if !self.color.has_color_aspect()
            || self.color.is_depth_stencil_format()
            || !color
                .allowed_usages
                .contains(wgpu::TextureUsages::RENDER_ATTACHMENT)
        {
            return Err(GpuError::UnsupportedTarget {
                format: *self,
                reason: "the colour format is not a renderable colour format",
            });
        }
        if !self.depth.has_depth_aspect() {
            return Err(GpuError::UnsupportedTarget {
                format: *self,
                reason: "the depth format has no depth aspect",
            });
        }
        let depth = self.depth.guaranteed_format_features(features);
        if !color.flags.sample_count_supported(self.sample_count)
            || !depth.flags.sample_count_supported(self.sample_count)
        {
            return Err(GpuError::UnsupportedTarget {
                format: *self,
                reason: "the sample count is not supported by both formats (1 and 4 are usual)",
            });
        }
        Ok(())
    }

    /// 1 when the colour target encodes to sRGB (the shaders' `srgb_target` flag).
    pub(crate) fn srgb_flag(&self) -> u32 {
        u32::from(self.color.is_srgb())
    }

    /// The pipeline's depth state with `write` and `compare`.
    pub(crate) fn depth_state(
        &self,
        write: bool,
        compare: wgpu::CompareFunction,
    ) -> wgpu::DepthStencilState {
        wgpu::DepthStencilState {
            format: self.depth,
            depth_write_enabled: Some(write),
            depth_compare: Some(compare),
            stencil: Default::default(),
            bias: Default::default(),
        }
    }

    /// The pipeline's multisample state.
    pub(crate) fn multisample(&self) -> wgpu::MultisampleState {
        wgpu::MultisampleState {
            count: self.sample_count,
            ..Default::default()
        }
    }
}
