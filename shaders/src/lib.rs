//! Every WGSL shader of the deformable terrain workspace, as `&'static str` constants, one file
//! per pass (the file sits under the pass's name in `src/wgsl/`, in the folder of terrain-gpu's
//! group: `passes/`, `render/`, `resources/` for the shared lookups of GPU data, `granular/`).
//!
//! ```
//! // Shaders are plain WGSL text, ready for `wgpu::ShaderSource::Wgsl`.
//! assert!(terrain_shaders::STAMP.contains("@compute"));
//! assert!(terrain_shaders::ALL.iter().all(|(name, src)| !name.is_empty() && !src.is_empty()));
//! ```

// docs.rs: label feature-gated items with the features they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]

/// Declares codes shared by Rust and WGSL once: each becomes a Rust `pub const` in [`codes`] and
/// a WGSL `const` in the prelude that every shader of this crate starts with, so the two
/// languages cannot drift apart.
macro_rules! shared_codes {
    ($($(#[doc = $doc:literal])* $name:ident: $ty:ident = $value:literal $suffix:literal;)*) => {
        /// Codes shared by Rust and WGSL (wrap modes, blends, stamp kinds, distance metrics,
        /// column kinds, sentinels). Shaders see the same names as WGSL `const`s.
        pub mod codes {
            $($(#[doc = $doc])* pub const $name: $ty = $value;)*
        }
        /// The WGSL text declaring every code of [`codes`] (already in front of each shader).
        macro_rules! wgsl_prelude {
            () => {
                concat!(
                    "// Generated from terrain_shaders::codes: edit the Rust side.\n",
                    $("const ", stringify!($name), ": ", stringify!($ty), " = ",
                      stringify!($value), $suffix, ";\n",)*
                )
            };
        }
    };
}

shared_codes! {
    /// `WrapMode::Repeat`: toroidal addressing.
    WRAP_REPEAT: u32 = 0 "u";
    /// `WrapMode::Clamp`: edges clamp.
    WRAP_CLAMP: u32 = 1 "u";
    /// `Blend::Add`: the stamp is added.
    BLEND_ADD: u32 = 0 "u";
    /// `Blend::Min`: the lower of map and base + stamp.
    BLEND_MIN: u32 = 1 "u";
    /// `Blend::Max`: the higher of map and base + stamp.
    BLEND_MAX: u32 = 2 "u";
    /// Stamp kind: the Gaussian of Flower 2010, eq. 3.5.
    STAMP_GAUSSIAN: u32 = 0 "u";
    /// Stamp kind: a texture stamp (also the shockwave).
    STAMP_TEXTURE: u32 = 1 "u";
    /// Stamp kind: a user procedural function.
    STAMP_USER: u32 = 2 "u";
    /// `DistanceMetric::Euclidean`.
    METRIC_EUCLIDEAN: u32 = 0 "u";
    /// `DistanceMetric::Manhattan`.
    METRIC_MANHATTAN: u32 = 1 "u";
    /// `DistanceMetric::Chebyshev`.
    METRIC_CHEBYSHEV: u32 = 2 "u";
    /// Column kind (Persson 2019, table 4.1): material that may receive displaced material.
    SEED: i32 = -3 "i";
    /// Column kind: an object rests on or near it; it receives nothing.
    OBSTACLE: i32 = -2 "i";
    /// Column kind: an object penetrates it; its material is displaced.
    PENETRATING: i32 = -1 "i";
    /// No seed found (`terrain_core::granular::NO_SEED`).
    NO_SEED: u32 = 0xffffffff "u";
    /// No object above this column (`terrain_core::granular::NO_OBJECT`).
    NO_OBJECT: u32 = 0xffffffff "u";
    /// An indirection table entry of a tile that is not resident (`terrain_core::INVALID_SLOT`).
    INVALID_SLOT: u32 = 0xffffffff "u";
    /// The raw detail value of 0 m (`terrain_core::detail::DETAIL_ZERO_RAW`).
    DETAIL_ZERO_RAW: u32 = 128 "u";
    /// The slope angle of slope code 127, in degrees
    /// (`terrain_core::slope_code::SLOPE_CODE_MAX_DEGREES`).
    SLOPE_CODE_MAX_DEGREES: u32 = 85 "u";
}

/// The WGSL `const` declarations of [`codes`], as every shader here starts with them.
pub const PRELUDE: &str = wgsl_prelude!();

/// `StampPass`: one stamp (Gaussian, texture or user procedural) applied in place.
pub const STAMP: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/packed.wgsl"),
    include_str!("wgsl/passes/stamp.wgsl")
);

/// `DensityPass`: curvature density maps and their max pyramid (Cervin 2012, ch. 3).
pub const DENSITY: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/packed.wgsl"),
    include_str!("wgsl/passes/density.wgsl")
);

/// `NormalPass`: partial-derivative normals (Flower 2010, eq. 3.3) over a region.
pub const NORMALS: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/packed.wgsl"),
    include_str!("wgsl/passes/normals.wgsl")
);

/// `SkyPass`: a full-screen gradient by view-ray elevation.
pub const SKY: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/render/target_color.wgsl"),
    include_str!("wgsl/render/sky.wgsl")
);

// The renderers' shaders are stacks of the same pieces; each stack that several shaders start
// with is written once below. They are macros because `concat!` joins only literals and macro
// calls (not `const`s), and the shaders stay `&'static str` constants.

/// The start of every clipmap-style renderer: the prelude, packed texel access, the target's
/// colour conversion and the detail sample type the fragment shader takes.
macro_rules! renderer_head {
    () => {
        concat!(
            wgsl_prelude!(),
            include_str!("wgsl/resources/packed.wgsl"),
            include_str!("wgsl/render/target_color.wgsl"),
            include_str!("wgsl/resources/detail_sample.wgsl"),
            include_str!("wgsl/render/materials_common.wgsl"),
            include_str!("wgsl/render/materials.wgsl"),
            include_str!("wgsl/resources/overlay_atlas.wgsl"),
            include_str!("wgsl/render/surface_weights.wgsl")
        )
    };
}

/// [`CLIPMAP`]'s text: the clipmap frame and shading over a coarse-map without detail.
macro_rules! clipmap_coarse {
    () => {
        concat!(
            renderer_head!(),
            include_str!("wgsl/render/clipmap_no_detail.wgsl"),
            include_str!("wgsl/render/clipmap.wgsl"),
            include_str!("wgsl/render/clipmap_surface_coarse.wgsl"),
            include_str!("wgsl/render/surface_curvature_heights.wgsl")
        )
    };
}

/// [`CLIPMAP_ATLAS`]'s text: the clipmap frame and shading over a tile atlas.
macro_rules! clipmap_atlas {
    () => {
        concat!(
            renderer_head!(),
            include_str!("wgsl/render/clipmap_no_detail.wgsl"),
            include_str!("wgsl/render/clipmap.wgsl"),
            include_str!("wgsl/resources/tile_atlas.wgsl"),
            include_str!("wgsl/resources/tile_atlas_bind.wgsl"),
            include_str!("wgsl/render/clipmap_surface_atlas.wgsl"),
            include_str!("wgsl/render/surface_curvature_atlas.wgsl")
        )
    };
}

/// [`CLIPMAP_DETAIL`]'s text: the clipmap frame over a coarse-map, shaded with a detail layer
/// (parallax, composite normals, fade).
macro_rules! clipmap_detail {
    () => {
        concat!(
            renderer_head!(),
            include_str!("wgsl/resources/detail_tiles.wgsl"),
            include_str!("wgsl/render/clipmap_detail_parallax.wgsl"),
            include_str!("wgsl/render/clipmap.wgsl"),
            include_str!("wgsl/render/clipmap_surface_coarse.wgsl"),
            include_str!("wgsl/render/surface_curvature_heights.wgsl")
        )
    };
}

/// [`CLIPMAP_ATLAS_DETAIL`]'s text: the clipmap frame over a tile atlas, shaded with a detail
/// layer (parallax, composite normals, fade) as [`CLIPMAP_DETAIL`].
macro_rules! clipmap_atlas_detail {
    () => {
        concat!(
            renderer_head!(),
            include_str!("wgsl/resources/detail_tiles.wgsl"),
            include_str!("wgsl/render/clipmap_detail_parallax.wgsl"),
            include_str!("wgsl/render/clipmap.wgsl"),
            include_str!("wgsl/resources/tile_atlas.wgsl"),
            include_str!("wgsl/resources/tile_atlas_bind_high.wgsl"),
            include_str!("wgsl/render/clipmap_surface_atlas.wgsl"),
            include_str!("wgsl/render/surface_curvature_atlas.wgsl")
        )
    };
}

/// [`GRANULAR_COMMON`]'s text, which the granular passes start with.
macro_rules! granular_common {
    () => {
        concat!(
            wgsl_prelude!(),
            include_str!("wgsl/granular/granular_common.wgsl")
        )
    };
}

/// `ClipmapRenderer`: displaced, morphed, lit clipmap blocks.
pub const CLIPMAP: &str = clipmap_coarse!();

/// `CdlodRenderer`: CDLOD quadrants with the per-vertex morph, lit and coloured as the clipmap
/// (its frame, coarse-map surface and fragment shader).
pub const CDLOD: &str = concat!(clipmap_coarse!(), include_str!("wgsl/render/cdlod.wgsl"));

/// `CdlodRenderer` over a tile atlas (`GpuTileAtlas`): the CDLOD vertex shader on the atlas
/// surface of [`CLIPMAP_ATLAS`], so a streamed world is drawn by CDLOD as by the clipmap.
pub const CDLOD_ATLAS: &str = concat!(clipmap_atlas!(), include_str!("wgsl/render/cdlod.wgsl"));

/// `CdlodRenderer` over a coarse-map with a detail layer: the CDLOD vertex shader on the
/// coarse surface, shaded as [`CLIPMAP_DETAIL`] (composite normals, parallax, fade).
pub const CDLOD_DETAIL: &str = concat!(clipmap_detail!(), include_str!("wgsl/render/cdlod.wgsl"));

/// `CdlodRenderer` over a tile atlas with a detail layer: a streamed world's level 0 drawn by
/// CDLOD and shaded as [`CLIPMAP_ATLAS_DETAIL`].
pub const CDLOD_ATLAS_DETAIL: &str = concat!(
    clipmap_atlas_detail!(),
    include_str!("wgsl/render/cdlod.wgsl")
);

/// `TessellationPass`: adaptive tessellation by longest-edge bisection (Cervin 2012, sec. 2.3),
/// writing triangles and indirect draw arguments.
pub const TESSELLATE: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/render/tess_source_hierarchy.wgsl"),
    include_str!("wgsl/render/tessellate.wgsl")
);

/// `TessellationPass` over a streamed world: the same bisection, decided from a streamed CDLOD
/// tree's node bounds with heights from the tile atlas (terrain-lod's `StreamedTessellation`).
pub const TESSELLATE_STREAMED: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/packed.wgsl"),
    include_str!("wgsl/resources/tile_atlas.wgsl"),
    include_str!("wgsl/resources/tile_atlas_bind_high.wgsl"),
    include_str!("wgsl/render/tess_source_streamed.wgsl"),
    include_str!("wgsl/render/tessellate.wgsl")
);

/// `TessRenderer`: the tessellation pass's triangles, lit and coloured as the clipmap (its
/// frame, coarse-map surface and fragment shader).
pub const TESSELLATED: &str = concat!(
    clipmap_coarse!(),
    include_str!("wgsl/render/tessellated.wgsl")
);

/// `TessRenderer` over a coarse-map with a detail layer: the tessellation's triangles shaded
/// as [`CLIPMAP_DETAIL`] (composite normals, parallax, fade).
pub const TESSELLATED_DETAIL: &str = concat!(
    clipmap_detail!(),
    include_str!("wgsl/render/tessellated.wgsl")
);

/// `TessRenderer` over a tile atlas: a streamed world's tessellated triangles shaded as
/// [`CLIPMAP_ATLAS`].
pub const TESSELLATED_ATLAS: &str = concat!(
    clipmap_atlas!(),
    include_str!("wgsl/render/tessellated.wgsl")
);

/// `TessRenderer` over a tile atlas with a detail layer, shaded as [`CLIPMAP_ATLAS_DETAIL`].
pub const TESSELLATED_ATLAS_DETAIL: &str = concat!(
    clipmap_atlas_detail!(),
    include_str!("wgsl/render/tessellated.wgsl")
);

/// `ClipmapRenderer` over a granular map: the clipmap drawn from the granular normals pass's
/// output (unit normal and float height per texel), so nothing is uploaded per frame.
pub const CLIPMAP_GRANULAR: &str = concat!(
    renderer_head!(),
    include_str!("wgsl/render/clipmap_no_detail.wgsl"),
    include_str!("wgsl/render/clipmap.wgsl"),
    include_str!("wgsl/render/clipmap_surface_granular.wgsl"),
    include_str!("wgsl/render/surface_curvature_heights.wgsl")
);

/// `ClipmapRenderer` over a tile atlas (`GpuTileAtlas`): heights from the finest resident level
/// of the tile pyramid through the indirection table, normals by central differences.
pub const CLIPMAP_ATLAS: &str = clipmap_atlas!();

/// `ClipmapRenderer` over a coarse-map with a detail layer (`GpuDetailTiles`, Flower 2010, sec.
/// 2.3): the coarse surface, shaded with the composite normal of eq. 3.4 at the point a
/// parallax march through the detail heights finds, the detail faded out with distance.
pub const CLIPMAP_DETAIL: &str = clipmap_detail!();

/// `ClipmapRenderer` over a tile atlas with a detail layer (a streamed world's footprints,
/// Flower 2010, sec. 2.3): the atlas surface of [`CLIPMAP_ATLAS`], shaded as [`CLIPMAP_DETAIL`].
pub const CLIPMAP_ATLAS_DETAIL: &str = clipmap_atlas_detail!();

/// `RefinePass` and `RefineRenderer`: the coarse cells around the camera split by the
/// refinement patterns of Flower 2010, sec. 2.4.3 into triangles displaced by coarse + detail height
/// (a compute pass with indirect draw arguments), drawn with the clipmap's frame, surface and
/// fragment shader, shaded with eq. 3.4's composite normal.
pub const REFINE: &str = concat!(
    renderer_head!(),
    include_str!("wgsl/resources/detail_tiles.wgsl"),
    include_str!("wgsl/render/clipmap_detail_refined.wgsl"),
    include_str!("wgsl/render/clipmap.wgsl"),
    include_str!("wgsl/render/clipmap_surface_coarse.wgsl"),
    include_str!("wgsl/render/surface_curvature_heights.wgsl"),
    include_str!("wgsl/render/refine.wgsl")
);

/// `RefinePass` and `RefineRenderer` over a tile atlas with a detail layer: the refinement of
/// [`REFINE`] on the atlas surface of [`CLIPMAP_ATLAS_DETAIL`] (a streamed world's footprints
/// as geometry near the camera).
pub const REFINE_ATLAS: &str = concat!(
    renderer_head!(),
    include_str!("wgsl/resources/detail_tiles.wgsl"),
    include_str!("wgsl/render/clipmap_detail_refined.wgsl"),
    include_str!("wgsl/render/clipmap.wgsl"),
    include_str!("wgsl/resources/tile_atlas.wgsl"),
    include_str!("wgsl/resources/tile_atlas_bind_high.wgsl"),
    include_str!("wgsl/render/clipmap_surface_atlas.wgsl"),
    include_str!("wgsl/render/surface_curvature_atlas.wgsl"),
    include_str!("wgsl/render/refine.wgsl")
);

/// `DetailProbe`: the detail layer's height, gradient and composite normal at a list of points
/// (the same functions the detail clipmap shades with).
pub const DETAIL_PROBE: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/packed.wgsl"),
    include_str!("wgsl/resources/detail_sample.wgsl"),
    include_str!("wgsl/resources/detail_tiles.wgsl"),
    include_str!("wgsl/passes/detail_probe.wgsl")
);

/// `AtlasProbe`: the atlas surface's stored height, height and gradient at a list of texels
/// (the same functions the clipmap draws with).
pub const ATLAS_PROBE: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/packed.wgsl"),
    include_str!("wgsl/resources/tile_atlas.wgsl"),
    include_str!("wgsl/resources/tile_atlas_bind.wgsl"),
    include_str!("wgsl/render/clipmap_surface_atlas.wgsl"),
    include_str!("wgsl/resources/atlas_probe.wgsl")
);

/// The declarations every granular pass shares (uniform block, penetration texel, column
/// kinds); already joined in front of [`GRANULAR_PENETRATION`], [`GRANULAR_JFA`],
/// [`GRANULAR_DISPLACE`] and [`GRANULAR_SLOPE`].
pub const GRANULAR_COMMON: &str = granular_common!();

/// Granular deformation (Persson 2019, ch. 4): penetration texture from depth and heights.
pub const GRANULAR_PENETRATION: &str = concat!(
    granular_common!(),
    include_str!("wgsl/granular/granular_penetration.wgsl")
);
/// Granular deformation: jump flooding passes (closest seed per column).
pub const GRANULAR_JFA: &str = concat!(
    granular_common!(),
    include_str!("wgsl/granular/granular_jfa.wgsl")
);
/// Granular deformation: displacement of intersected material (the three methods).
pub const GRANULAR_DISPLACE: &str = concat!(
    granular_common!(),
    include_str!("wgsl/granular/granular_displace.wgsl")
);
/// Granular deformation: evening out slopes (interleaved and scatter).
pub const GRANULAR_SLOPE: &str = concat!(
    granular_common!(),
    include_str!("wgsl/granular/granular_slope.wgsl")
);
/// Granular deformation: a trail painted on a material layer where the step presses the
/// material down (`TrailEffectPass`).
pub const GRANULAR_TRAIL: &str = concat!(
    granular_common!(),
    include_str!("wgsl/passes/paint.wgsl"),
    include_str!("wgsl/granular/granular_trail.wgsl")
);
/// Granular deformation: symmetric-difference normals and their blur, float heights.
pub const GRANULAR_NORMALS: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/granular/granular_normals.wgsl")
);
/// Granular deformation: depth of objects seen from below (an exact integer rasterizer in a
/// compute pass).
pub const GRANULAR_DEPTH: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/granular/granular_depth.wgsl")
);
/// Granular deformation: the exact u64 sum of a height map (the conserved volume), reduced on
/// the GPU.
pub const GRANULAR_VOLUME: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/granular/granular_volume.wgsl")
);

/// `SpillPass`: the excess of a detail stamp moved into the coarse-map (terrain-core's
/// `detail_spill` rule).
pub const SPILL: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/packed.wgsl"),
    include_str!("wgsl/passes/spill.wgsl")
);

/// The markers around the default user procedural stamp function in [`STAMP`]; a user stamp
/// replaces the text between them with its own `fn user_stamp_value(local: vec2<f32>) -> f32`.
pub const USER_STAMP_MARKERS: (&str, &str) = ("// USER_STAMP_BEGIN", "// USER_STAMP_END");

/// The autoshader's weights and curvature at a list of points (the functions every renderer
/// shades with), for the GPU == CPU test against `terrain_core::material`.
pub const MATERIAL_PROBE: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/render/materials_common.wgsl"),
    include_str!("wgsl/passes/material_probe.wgsl")
);

/// A streamed layer's lookup (`GpuOverlayAtlas`, the function every renderer draws a streamed
/// world's paint and colour with) at a list of points, for the GPU == CPU test against
/// `terrain_core::OverlayAtlas::sample`.
pub const OVERLAY_PROBE: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/resources/overlay_atlas.wgsl"),
    include_str!("wgsl/passes/overlay_probe.wgsl")
);

/// `MaterialEffectPass`: a stamp's material effect painted on a material layer.
pub const MATERIAL_EFFECT: &str = concat!(
    wgsl_prelude!(),
    include_str!("wgsl/passes/paint.wgsl"),
    include_str!("wgsl/passes/material_effect.wgsl")
);

/// The markers around `surface_weights` in every renderer's shader: an engine's own WGSL
/// function `fn surface_weights(p: SurfacePoint) -> vec4<f32>` replaces what lies between them.
pub const USER_SURFACE_MARKERS: (&str, &str) = ("// USER_SURFACE_BEGIN", "// USER_SURFACE_END");

/// Every shader with its name, for validation and tooling.
pub const ALL: &[(&str, &str)] = &[
    ("stamp", STAMP),
    ("spill", SPILL),
    ("normals", NORMALS),
    ("density", DENSITY),
    ("cdlod", CDLOD),
    ("cdlod_atlas", CDLOD_ATLAS),
    ("cdlod_detail", CDLOD_DETAIL),
    ("cdlod_atlas_detail", CDLOD_ATLAS_DETAIL),
    ("tessellate", TESSELLATE),
    ("tessellated", TESSELLATED),
    ("tessellated_detail", TESSELLATED_DETAIL),
    ("tessellate_streamed", TESSELLATE_STREAMED),
    ("tessellated_atlas", TESSELLATED_ATLAS),
    ("tessellated_atlas_detail", TESSELLATED_ATLAS_DETAIL),
    ("sky", SKY),
    ("clipmap", CLIPMAP),
    ("clipmap_granular", CLIPMAP_GRANULAR),
    ("clipmap_atlas", CLIPMAP_ATLAS),
    ("clipmap_detail", CLIPMAP_DETAIL),
    ("clipmap_atlas_detail", CLIPMAP_ATLAS_DETAIL),
    ("refine", REFINE),
    ("refine_atlas", REFINE_ATLAS),
    ("atlas_probe", ATLAS_PROBE),
    ("detail_probe", DETAIL_PROBE),
    ("material_probe", MATERIAL_PROBE),
    ("overlay_probe", OVERLAY_PROBE),
    ("material_effect", MATERIAL_EFFECT),
    ("granular_penetration", GRANULAR_PENETRATION),
    ("granular_jfa", GRANULAR_JFA),
    ("granular_displace", GRANULAR_DISPLACE),
    ("granular_slope", GRANULAR_SLOPE),
    ("granular_trail", GRANULAR_TRAIL),
    ("granular_normals", GRANULAR_NORMALS),
    ("granular_depth", GRANULAR_DEPTH),
    ("granular_volume", GRANULAR_VOLUME),
];

/// The README's code blocks, compiled and run as doc tests so that they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
