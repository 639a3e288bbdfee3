//! Level of detail for heightfield terrain: geometry clipmaps (GPU Gems 2 ch. 2, Flower 2010
//! sec. 2.3.2 and 3.1.3) with CPU frustum culling of their blocks (Flower 2010, sec. 2.4.3); CDLOD
//! (Cervin 2012, sec. 1.1.4: a quadtree with min / max heights, a LOD range table or a screen-space
//! error, partial selection and per-vertex morphing, [`cdlod`]); curvature density maps (seed
//! 002 ch. 3: five filters, max-downsampling, preprocessing, borders, a max pyramid,
//! [`density`]); adaptive tessellation (Cervin 2012, sec. 2.3, algorithm 3.1: per-edge splits from
//! the projected size of a sphere around the edge, scaled by the density map, or by a bound on
//! the projected geometric error; longest-edge bisection, conforming by construction, with a
//! vertex morph, [`tessellation`]).
//!
//! Conventions (those of the whole workspace): world units are metres, Y is up, right-handed.
//! Heightmap column `x` maps to world X and row `y` to world Z, so texel `(x, y)` stands at
//! world `(x * texel_size, height, y * texel_size)`. Clipmap geometry is flat: the renderer
//! takes each vertex's height from the coarse-map at its texel coordinates, wrapping them
//! toroidally. Triangles are wound counter-clockwise seen from above (+Y).
//!
//! ```
//! use glam::camera::rh::{proj::directx, view::look_to_mat4};
//! use glam::{Vec2, Vec3};
//! use terrain_lod::{ClipmapLayout, Frustum};
//!
//! // 5 levels of 255 x 255 vertices share one mesh of 71 418 vertices (Flower 2010, eq. 3.1).
//! let layout = ClipmapLayout::new(255, 5)?;
//! assert_eq!(layout.vertex_count(), 71_418);
//! assert_eq!(layout.mesh().vertices.len(), 71_418);
//!
//! // Camera 30 m up at (100 m, 40 m) over a 0.1 m per texel map with heights in 0..50 m,
//! // looking along +X.
//! let eye = Vec3::new(100.0, 30.0, 40.0);
//! let view = look_to_mat4(eye, Vec3::X, Vec3::Y);
//! // wgpu clip space: depth in [0, 1], as Direct3D.
//! let proj = directx::perspective(60f32.to_radians(), 16.0 / 9.0, 0.1, 1000.0);
//! let frustum = Frustum::from_view_proj(proj * view);
//! let frame = layout.place(Vec2::new(eye.x, eye.z), 0.1, (0.0, 50.0), Some(&frustum))?;
//! assert_eq!(frame.levels.len(), 5);
//! assert!(frame.culled > 0, "blocks behind the camera are dropped");
//!
//! // What a renderer records: per draw, the part's index range and base vertex, and the
//! // instance data that places it (texel = offset + pos * scale).
//! for draw in &frame.draws {
//!     let part = layout.mesh().part(draw.part).expect("every part kind is in the mesh");
//!     let _record = (part.indices.clone(), part.base_vertex, draw.instance);
//! }
//! let drawn = frame.triangle_count(layout.mesh());
//! assert!(drawn > 0);
//! # Ok::<(), terrain_lod::LodError>(())
//! ```
//!
//! CDLOD and the density map of a heightfield, kept current after a deformation:
//!
//! ```
//! use glam::{IVec2, UVec2, Vec3};
//! use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
//! use terrain_lod::{CdlodConfig, CdlodMesh, CdlodTree, CdlodView, DensityMap, DensityParams};
//!
//! // 256 x 256 texels of 0.5 m, gentle hills.
//! let grid = Grid::from_fn(256, 256, |x, y| {
//!     (30_000.0 + 4_000.0 * ((x as f32 * 0.05).sin() + (y as f32 * 0.04).cos())) as u16
//! })?;
//! let mut map = HeightMap::new(grid, HeightEncoding::new(0.001, 0.0)?, 0.5, WrapMode::Clamp)?;
//! let config = CdlodConfig { leaf_size: 16, grid_size: 16, lod_count: 5, ..Default::default() };
//! let mut tree = CdlodTree::from_map(&map, config)?;
//! let mut density = DensityMap::from_map(&map, DensityParams::default())?;
//!
//! // A crater: the map changes in a rect; the tree and the density follow it there only.
//! let crater = Rect::new(IVec2::new(100, 100), UVec2::new(12, 12));
//! for y in 100..112 {
//!     for x in 100..112 {
//!         *map.grid_mut().get_mut(x, y).unwrap() -= 3_000;
//!     }
//! }
//! tree.update_rect(&map, crater)?;
//! density.update_rect(&map, crater)?;
//! assert!(density.density_at_texel(0, IVec2::new(106, 100)).unwrap() > 0.0);
//!
//! // What a renderer draws from above the crater: one shared quadrant mesh per instance.
//! let view = CdlodView { camera: Vec3::new(53.0, 40.0, 53.0), frustum: None, viewport_width: 1280.0, hfov: 1.2 };
//! let frame = tree.select(&view)?;
//! let mesh = CdlodMesh::new(config.grid_size);
//! assert!(frame.triangle_count(&mesh) > 0);
//! assert!(frame.instances.iter().any(|i| i.lod == 0), "finest near the camera");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Adaptive tessellation of the same kind of map, as the GPU pass of terrain-gpu computes it:
//!
//! ```
//! use glam::Vec3;
//! use terrain_core::{Grid, HeightEncoding, HeightMap, WrapMode};
//! use terrain_lod::{CdlodView, DensityMap, DensityParams, TessConfig, TessHierarchy};
//!
//! let grid = Grid::from_fn(256, 256, |x, y| {
//!     (30_000.0 + 4_000.0 * ((x as f32 * 0.05).sin() + (y as f32 * 0.04).cos())) as u16
//! })?;
//! let map = HeightMap::new(grid, HeightEncoding::new(0.001, 0.0)?, 0.5, WrapMode::Clamp)?;
//! let density = DensityMap::from_map(&map, DensityParams::default())?;
//! let view = CdlodView { camera: Vec3::new(20.0, 40.0, 20.0), frustum: None, viewport_width: 1280.0, hfov: 1.2 };
//!
//! // Cervin 2012: edges of about 8 pixels, fewer where the density map says the terrain is flat.
//! let tess = TessHierarchy::from_map(&map, Some(&density), TessConfig::default())?;
//! let frame = tess.select(&view)?;
//! assert!(frame.triangle_count() > 2 * 64, "split beyond the 64 patches' two triangles");
//!
//! // A bound on the error instead: no texel of the drawn mesh is more than 1 pixel off.
//! let config = TessConfig { max_error_px: Some(1.0), morph: false, ..TessConfig::default() };
//! let tess = TessHierarchy::from_map(&map, None, config)?;
//! let frame = tess.select(&view)?;
//! assert!(tess.max_screen_error_px(&frame, &view) <= 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// docs.rs: label feature-gated items with the features they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]
#![warn(clippy::unwrap_used)]

pub mod background;
pub mod cdlod;
pub mod clipmap;
pub mod density;
pub mod error;
pub mod frustum;
pub mod morph;
pub mod popping;
pub mod reach;
pub mod refine;
pub mod tessellation;

// The row loops are terrain-core's (one copy for the workspace), reached as `crate::par`.
use terrain_core::par;

pub use background::{CdlodUpdater, LodUpdater, RectUpdate, TessState, TessUpdater};
pub use cdlod::{
    CdlodConfig, CdlodFrame, CdlodInstance, CdlodMesh, CdlodTree, CdlodView, LodMetric, LodRanges,
};
pub use clipmap::{
    ClipmapDraw, ClipmapFrame, ClipmapInstance, ClipmapLayout, ClipmapMesh, ClipmapVertex,
    LevelPlacement, MAX_DRAWS_PER_LEVEL, MeshPart, PartKind, TrimSide,
};
pub use density::{CurvatureFilter, DensityMap, DensityParams};
pub use error::LodError;
pub use frustum::Frustum;
pub use popping::{POPPING_PROBES_PER_SIDE, PoppingView};
pub use reach::clipmap_levels_to_reach;
pub use refine::RefineView;
pub use tessellation::{
    StreamedTessellation, TessConfig, TessFrame, TessHierarchy, TessTriangle, TessVertex,
};

/// The README's code blocks, compiled and run as doc tests so that they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

/// The glam of this crate's public API (its vectors), so callers use the same version.
pub use glam;
