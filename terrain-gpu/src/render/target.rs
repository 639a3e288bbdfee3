//! `TargetFormat`: the formats of the caller's render pass that a renderer is built for, checked
//! before wgpu sees them.

use crate::error::GpuError;
use crate::render::camera::DepthConvention;

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
    /// Whether the pass's depth grows (cleared to 1) or falls (cleared to 0, reverse-Z) with
    /// distance; every view drawn must project with the same convention.
    pub depth_convention: DepthConvention,
}

impl TargetFormat {
    /// The formats of [`crate::OffscreenTarget`] captures: `Rgba8Unorm`, `Depth32Float`, 1 sample.
    pub const CAPTURE: Self = Self {
        color: crate::render::offscreen::COLOR_FORMAT,
        depth: crate::render::offscreen::DEPTH_FORMAT,
        sample_count: 1,
        depth_convention: DepthConvention::Forward,
    };

    /// These formats with `convention`.
    pub fn with_depth_convention(self, convention: DepthConvention) -> Self {
        Self {
            depth_convention: convention,
            ..self
        }
    }

    /// Checks that `device` can render to these formats with this sample count, before wgpu
    /// sees them. Without the adapter at hand the formats' guaranteed features decide, which is
    /// exactly what wgpu allows on a device without
    /// `TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES`. On a device with it (as
    /// [`crate::GpuContext`] asks for where the adapter has it) a sample count beyond the
    /// guaranteed ones may still be allowed by the adapter: such a count (2, 4, 8 or 16) is
    /// let through, and the renderer's pipeline creation, which runs in an error scope, has
    /// the last word. [`validate_on`](Self::validate_on) answers exactly.
    pub fn validate(&self, device: &wgpu::Device) -> Result<(), GpuError> {
        let features = device.features();
        let color = self.color.guaranteed_format_features(features);
        let depth = self.depth.guaranteed_format_features(features);
        let adapter_decides =
            features.contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES);
        self.check(color, depth, "every adapter guarantees", adapter_decides)
    }

    /// Checks these formats against what `adapter` (the one `device` was created on) supports
    /// for them, the way wgpu will: the adapter's own per-format features where the device
    /// has `TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES`, the guaranteed ones otherwise. A sample
    /// count that is refused gets an error naming the formats, the count and the counts
    /// allowed.
    pub fn validate_on(
        &self,
        adapter: &wgpu::Adapter,
        device: &wgpu::Device,
    ) -> Result<(), GpuError> {
        let features = device.features();
        if !features.contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES) {
            return self.validate(device);
        }
        let color = adapter.get_texture_format_features(self.color);
        let depth = adapter.get_texture_format_features(self.depth);
        self.check(color, depth, "this adapter supports", false)
    }

    /// The checks of [`validate`](Self::validate) on the formats' `color` and `depth`
    /// features (`whose` says whose features they are, for the message). With
    /// `counts_may_be_more`, a power-of-two count up to 16 is not refused.
    fn check(
        &self,
        color: wgpu::TextureFormatFeatures,
        depth: wgpu::TextureFormatFeatures,
        whose: &'static str,
        counts_may_be_more: bool,
    ) -> Result<(), GpuError> {
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
        let allowed = |f: &wgpu::TextureFormatFeatures| -> Vec<u32> {
            [1, 2, 4, 8, 16]
                .into_iter()
                .filter(|&n| f.flags.sample_count_supported(n))
                .collect()
        };
        let (color_allows, depth_allows) = (allowed(&color), allowed(&depth));
        let count = self.sample_count;
        let supported = color_allows.contains(&count) && depth_allows.contains(&count);
        let maybe = counts_may_be_more && matches!(count, 2 | 4 | 8 | 16);
        if !supported && !maybe {
            return Err(GpuError::UnsupportedSampleCount {
                color: self.color,
                depth: self.depth,
                count,
                whose,
                color_allows,
                depth_allows,
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

    /// The terrain's depth state: written, and tested so the nearer fragment wins under the
    /// target's convention.
    pub(crate) fn terrain_depth_state(&self) -> wgpu::DepthStencilState {
        self.depth_state(true, self.depth_convention.compare())
    }

    /// The pipeline's multisample state.
    pub(crate) fn multisample(&self) -> wgpu::MultisampleState {
        wgpu::MultisampleState {
            count: self.sample_count,
            ..Default::default()
        }
    }
}
