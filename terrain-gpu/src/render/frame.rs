//! The uniform block every terrain renderer's shaders share (`Frame` of `clipmap.wgsl`) and
//! how a view fills it.

use crate::error::GpuError;
use crate::render::camera::ResolvedView;
use crate::render::clipmap::SurfaceInfo;
use crate::render::clipmap::TerrainStyle;
use crate::render::target::TargetFormat;
use crate::resources::materials::{self, ShadingBindings};
use bytemuck::{Pod, Zeroable};
use glam::Vec4;
use terrain_core::WrapMode;
use terrain_shaders::codes::{WRAP_CLAMP, WRAP_REPEAT};

/// The uniform block `Frame` of `clipmap.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    pub(crate) camera_texel: [i32; 2],
    pub(crate) camera_frac: [f32; 2],
    camera_height: f32,
    texel_size: f32,
    height_scale: f32,
    height_offset: f32,
    map_size: [u32; 2],
    pub(crate) wrap_offset: [i32; 2],
    n: u32,
    levels: u32,
    morph_width: f32,
    ramp_low: f32,
    ramp_high: f32,
    srgb_target: u32,
    wrap: u32,
    hide_outside: u32,
    light_dir: [f32; 4],
    fog_color: [f32; 4],
    /// Texels (min x, min z, max x, max z, relative to the camera's whole texel) whose
    /// fragments are discarded: another renderer draws them. Empty ([`NOTHING_EXCLUDED`])
    /// unless set.
    pub(crate) excluded: [f32; 4],
    /// Material shading and the colour layer: see `resources::materials::frame_fields`.
    material: [[f32; 4]; 4],
    /// The cells the hole mask covers: origin (x, z) and size, in world cells.
    holes: [i32; 4],
    /// The cells the material layer covers, likewise.
    paint: [i32; 4],
    /// The cells the colour layer covers, likewise.
    color: [i32; 4],
}

impl FrameUniform {
    /// Marks which layers `shading` binds ([`crate::GpuColorLayer`],
    /// [`crate::GpuMaterialLayer`], [`crate::GpuHoleMask`]) and where the hole mask lies.
    pub(crate) fn set_layers(&mut self, shading: &ShadingBindings) {
        self.material[3] = shading.layer_flags();
        self.holes = shading.hole_window;
        self.paint = shading.paint_window;
        self.color = shading.color_window;
    }
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<FrameUniform>() == 304);

/// An exclusion rect with min above max: nothing is discarded.
pub(crate) const NOTHING_EXCLUDED: [f32; 4] = [1.0, 1.0, -1.0, -1.0];

/// The `excluded` rect of the texels from `lo` to `hi` (relative to the camera's whole
/// texel), shrunk by a thousandth of a texel: fragments on the region's edge stay drawn by both
/// renderers (the same surface there) rather than by neither. Fails for an empty region.
pub(crate) fn exclusion_rect(lo: glam::IVec2, hi: glam::IVec2) -> Result<[f32; 4], GpuError> {
    if lo.cmpge(hi).any() {
        return Err(GpuError::Unsupported {
            what: "exclude",
            reason: "the excluded region is empty",
        });
    }
    const EDGE: f32 = 1e-3;
    Ok([
        lo.x as f32 + EDGE,
        lo.y as f32 + EDGE,
        hi.x as f32 - EDGE,
        hi.y as f32 - EDGE,
    ])
}

/// The frame uniform of a view of `info` by `view` on `target`, with the clipmap's
/// `(n, levels)` (ignored by other renderers) and the wrap offset of the texels the frame
/// reads.
pub(crate) fn frame_uniform(
    info: &SurfaceInfo,
    view: &ResolvedView,
    style: &TerrainStyle,
    target: &TargetFormat,
    (n, levels): (u32, u32),
    wrap_offset: [i32; 2],
) -> Result<FrameUniform, GpuError> {
    let ts = info.texel_size;
    let cam_texel = glam::Vec2::new(view.eye.x, view.eye.z) / ts;
    let cam_int = cam_texel.floor();
    let enc = info.encoding;
    let wrap = match info.wrap {
        WrapMode::Repeat => WRAP_REPEAT,
        WrapMode::Clamp => WRAP_CLAMP,
    };
    let material = materials::frame_fields(
        style.shading,
        &style.materials,
        cam_int.as_ivec2().to_array(),
        ts,
    )?;
    Ok(FrameUniform {
        view_proj: view.view_proj_relative.to_cols_array_2d(),
        camera_texel: cam_int.as_ivec2().to_array(),
        camera_frac: (cam_texel - cam_int).to_array(),
        camera_height: view.eye.y,
        texel_size: ts,
        height_scale: enc.scale,
        height_offset: enc.offset,
        map_size: info.size.to_array(),
        wrap_offset,
        n,
        levels,
        morph_width: terrain_lod::morph::default_morph_width(n),
        ramp_low: style.ramp.0,
        ramp_high: style.ramp.1,
        srgb_target: target.srgb_flag(),
        wrap,
        hide_outside: u32::from(style.hide_outside_map),
        light_dir: style.light_dir.extend(0.0).to_array(),
        fog_color: Vec4::from((style.fog_color, style.fog_density)).to_array(),
        excluded: NOTHING_EXCLUDED,
        material,
        holes: [0; 4],
        paint: [0; 4],
        color: [0; 4],
    })
}
