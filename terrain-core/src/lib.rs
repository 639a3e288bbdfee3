//! CPU reference of the deformable terrain workspace: grids and height encodings, PNG / RAW16 /
//! R32 I/O, DEM import (GeoTIFF included), sampling, partial-derivative normal maps, stamps and
//! a procedural default terrain.
//!
//! Conventions (stated once for the whole workspace): world units are metres, Y is up,
//! right-handed. Heightmap column `x` maps to world X and row `y` to world Z; sample `(x, y)`
//! stands at `(x * texel_size, height, y * texel_size)`. Heights are stored as integers and
//! converted with a [`HeightEncoding`] (`metres = offset + scale * stored`).
//!
//! ```
//! use glam::Vec2;
//! use terrain_core::{
//!     generate_coarse_map, Blend, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams,
//!     apply_stamp, DerivativeMap,
//! };
//!
//! // A 128 x 128 procedural coarse-map at 0.5 m per texel, heights 0..50 m.
//! let params = TerrainParams { size: glam::UVec2::splat(128), ..TerrainParams::default() };
//! let encoding = HeightEncoding::spanning::<u16>(0.0, 50.0)?;
//! let mut map = generate_coarse_map(&params, encoding, 0.5)?;
//! let mut normals = DerivativeMap::from_map(&map);
//!
//! // A 10 m crater, 2 m deep, centred across the wrap corner: it lands on all four corners.
//! let mut crater = GaussianStamp::default();
//! let placement = StampPlacement::new(Vec2::new(1.0, 1.0), Vec2::splat(10.0), -2.0)?;
//! let dirty = apply_stamp(&mut map, &mut crater, &placement, Blend::Add)?;
//! for rect in &dirty {
//!     normals.update_rect(&map, *rect)?;
//! }
//! assert_eq!(dirty.len(), 4);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// docs.rs: label feature-gated items with the features they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]
#![warn(clippy::unwrap_used)]

#[cfg(feature = "cpu-work")]
pub mod cpu_work;
pub mod dem;
pub mod detail;
pub mod detail_spill;
pub mod error;
pub mod geotiff;
pub mod granular;
pub mod grid;
pub mod hillshade;
pub mod holes;
pub mod io;
pub mod map;
pub mod material;
pub mod material_effect;
pub mod normals;
pub mod overlay_atlas;
pub mod overview;
#[doc(hidden)]
pub mod par;
pub mod readback;
pub mod rect;
pub mod sample;
pub mod shockwave;
pub mod slope_code;
pub mod stamp;
pub mod terrain_gen;
pub mod tile_atlas;
pub mod tile_deformer;
pub mod tile_upload;
pub mod window_source;

pub use error::CoreError;
pub use grid::{Grid, WrapMode};
pub use hillshade::{
    HillshadeMaterials, HillshadeParams, hillshade, hillshade_from_heights, hillshade_range,
    update_hillshade, update_hillshade_from_heights,
};
pub use holes::{GROUND, HOLE, HoleOp, HoleWindowTarget, apply_hole_stamp, count_holes, is_hole};
pub use io::MapIoError;
pub use map::{
    CoarseMap, DEFAULT_FIXED_POINT_UNITS_PER_M, DETAIL_MAX_RANGE_M, DetailTile, FixedPointMap,
    HeightEncoding, HeightMap, HeightSample,
};
pub use material::{
    AutoshadeParams, MATERIALS, MaterialImages, MaterialTextures, autoshade_weights,
    curvature_from_gradients, curvature_from_heights,
};
pub use material_effect::{
    EffectFrame, MaterialEffect, apply_material_effect, apply_trail_effect, effect_amount,
    paint_texel,
};
pub use normals::{
    DEFAULT_SNORM_MAX_SLOPE, DERIVATIVE_APRON, DerivativeMap, composite_normal, derivative_at,
    derivative_region, normal_from_derivatives,
};
pub use overlay_atlas::{OverlayAtlas, OverlayUploadTarget};
pub use overview::{HOLE_COLOUR, HillshadeOverview};
pub use readback::{ArrivedRegion, RegionSource, RequestId};
pub use rect::{DirtyRect, Rect, WrappedPiece};
pub use sample::bilinear;
pub use shockwave::{MAX_SHOCKWAVE_GAMMA, Shockwave, ShockwaveParams};
pub use slope_code::{SlopeCodec, decode_slope};
pub use stamp::{
    Blend, DEFAULT_GAUSSIAN_EPSILON_M, GaussianStamp, Stamp, StampKernel, StampPlacement,
    StampRegion, TextureStamp, apply_stamp, apply_stamp_reference, apply_stamp_window,
    gaussian_rounding_bound, stamp_region,
};
pub use terrain_gen::{TerrainParams, generate_coarse_map, generate_heights};
pub use tile_atlas::TileAtlas;
pub use tile_deformer::{RamDeformer, TileDeformer, TileStamp};
pub use tile_upload::{INVALID_SLOT, MAX_TILE_LEVELS, TileLayout, TileUploadTarget};
pub use window_source::WindowSource;

/// The README's code blocks, compiled and run as doc tests so that they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

/// The glam of this crate's public API (its vectors), so callers use the same version.
pub use glam;
