//! What every terrain renderer (clipmap, CDLOD, tessellation) does the same way for its
//! surface: the detail surface's uniform, written each frame and bound at 3 between the
//! coarse-map's buffers (1, 2) and the detail tiles' (4, 5), and how far beyond the drawn mesh
//! a fragment may read (the parallax march's reach). One place, so the three renderers shade
//! a detail layer identically.

use crate::error::GpuError;
use crate::render::clipmap::ClipmapSurface;
use crate::resources::detail::DetailInfo;
use glam::IVec2;

/// The detail surface's per-frame uniform of one renderer.
#[derive(Debug)]
pub(crate) struct DetailUniform {
    buffer: wgpu::Buffer,
}

impl DetailUniform {
    /// The (empty) uniform buffer; written by [`DetailUniform::surface_buffers`].
    pub(crate) fn new(device: &wgpu::Device, label: &'static str) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: std::mem::size_of::<DetailInfo>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }

    /// The buffers `surface` binds, with their bindings: for a surface with detail tiles this
    /// uniform, written for a camera at coarse texel `camera_texel`, goes at 3 beside the
    /// tiles' 4 and 5; other surfaces bind their own buffers only. Fails on shading out of
    /// range.
    pub(crate) fn surface_buffers(
        &self,
        queue: &wgpu::Queue,
        surface: &ClipmapSurface<'_>,
        texel_size: f32,
        camera_texel: IVec2,
    ) -> Result<Vec<(u32, wgpu::Buffer)>, GpuError> {
        let mut buffers = surface.buffers();
        if let Some((detail, shading)) = surface.detail() {
            let reach = shading.check(texel_size)?;
            let info = detail.info(camera_texel, shading, reach)?;
            queue.write_buffer(&self.buffer, 0, bytemuck::bytes_of(&info));
            buffers.push((3, self.buffer.clone()));
        }
        Ok(buffers)
    }
}

/// Whole coarse texels a fragment of `surface` may read beyond the drawn mesh's own texels:
/// the material shading's curvature stencil ([`MATERIAL_REACH`]), plus for a detail surface
/// the parallax march's reach and one for the bilinear neighbour.
pub(crate) fn fragment_reach(surface: &ClipmapSurface<'_>) -> i32 {
    MATERIAL_REACH
        + match surface {
            ClipmapSurface::Detail { shading, .. } | ClipmapSurface::AtlasDetail { shading, .. } => {
                shading.max_reach_texels.ceil() as i32 + 1
            }
            _ => 0,
        }
}

/// Texels the material shading reads around a fragment: its nearest texel (one past the
/// cell) and the curvature's neighbours at most [`MAX_CURVATURE_STEP`] beyond.
pub(crate) const MATERIAL_REACH: i32 = MAX_CURVATURE_STEP as i32 + 2;

/// The most texels between the heights the curvature is measured from.
pub(crate) const MAX_CURVATURE_STEP: f32 = 6.0;

/// `source` with an engine's `surface_weights` function (see
/// [`crate::TerrainRenderer::set_surface_shader`]) between its user markers, or `source` as it
/// is without one.
pub(crate) fn with_surface_weights(
    source: &'static str,
    user: Option<&str>,
) -> std::borrow::Cow<'static, str> {
    let Some(user) = user else {
        return source.into();
    };
    let (begin, end) = terrain_shaders::USER_SURFACE_MARKERS;
    // terrain-shaders' tests check every renderer's shader carries the markers once, in order;
    // a source without them is drawn as it is.
    match (source.find(begin), source.find(end)) {
        (Some(a), Some(b)) if a < b => {
            format!("{}{begin}\n{user}\n{}", &source[..a], &source[b..]).into()
        }
        _ => source.into(),
    }
}
