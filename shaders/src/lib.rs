//! Every WGSL shader of the deformable terrain workspace, as `&'static str` constants, one file
//! per pass (the file sits in `src/wgsl/` under the pass's name).
//!
//! ```
//! // Shaders are plain WGSL text, ready for `wgpu::ShaderSource::Wgsl`.
//! assert!(terrain_shaders::STAMP.contains("@compute"));
//! assert!(terrain_shaders::ALL.iter().all(|(name, src)| !name.is_empty() && !src.is_empty()));
//! ```
#![warn(missing_docs)]

/// `StampPass`: one stamp (Gaussian, texture or user procedural) applied in place.
pub const STAMP: &str = include_str!("wgsl/stamp.wgsl");

/// `NormalPass`: partial-derivative normals (seed 000 eq. 3.3) over a region.
pub const NORMALS: &str = include_str!("wgsl/normals.wgsl");

/// `SkyPass`: a full-screen gradient by view-ray elevation.
pub const SKY: &str = include_str!("wgsl/sky.wgsl");

/// `ClipmapRenderer`: displaced, morphed, lit clipmap blocks.
pub const CLIPMAP: &str = include_str!("wgsl/clipmap.wgsl");

/// The declarations every granular pass shares (uniform block, penetration texel, column
/// kinds); already joined in front of [`GRANULAR_PENETRATION`], [`GRANULAR_JFA`],
/// [`GRANULAR_DISPLACE`] and [`GRANULAR_SLOPE`].
pub const GRANULAR_COMMON: &str = include_str!("wgsl/granular_common.wgsl");

/// Granular deformation (seed 001 ch. 4): penetration texture from depth and heights.
pub const GRANULAR_PENETRATION: &str = concat!(
    include_str!("wgsl/granular_common.wgsl"),
    include_str!("wgsl/granular_penetration.wgsl")
);
/// Granular deformation: jump flooding passes (closest seed per column).
pub const GRANULAR_JFA: &str = concat!(
    include_str!("wgsl/granular_common.wgsl"),
    include_str!("wgsl/granular_jfa.wgsl")
);
/// Granular deformation: displacement of intersected material (the three methods).
pub const GRANULAR_DISPLACE: &str = concat!(
    include_str!("wgsl/granular_common.wgsl"),
    include_str!("wgsl/granular_displace.wgsl")
);
/// Granular deformation: evening out slopes (interleaved and scatter).
pub const GRANULAR_SLOPE: &str = concat!(
    include_str!("wgsl/granular_common.wgsl"),
    include_str!("wgsl/granular_slope.wgsl")
);
/// Granular deformation: symmetric-difference normals and their blur, float heights.
pub const GRANULAR_NORMALS: &str = include_str!("wgsl/granular_normals.wgsl");
/// Granular deformation: depth of objects seen from below (render pipeline).
pub const GRANULAR_DEPTH: &str = include_str!("wgsl/granular_depth.wgsl");

/// The markers around the default user procedural stamp function in [`STAMP`]; a user stamp
/// replaces the text between them with its own `fn user_stamp_value(local: vec2<f32>) -> f32`.
pub const USER_STAMP_MARKERS: (&str, &str) = ("// USER_STAMP_BEGIN", "// USER_STAMP_END");

/// Every shader with its name, for validation and tooling.
pub const ALL: &[(&str, &str)] = &[
    ("stamp", STAMP),
    ("normals", NORMALS),
    ("sky", SKY),
    ("clipmap", CLIPMAP),
    ("granular_penetration", GRANULAR_PENETRATION),
    ("granular_jfa", GRANULAR_JFA),
    ("granular_displace", GRANULAR_DISPLACE),
    ("granular_slope", GRANULAR_SLOPE),
    ("granular_normals", GRANULAR_NORMALS),
    ("granular_depth", GRANULAR_DEPTH),
];
