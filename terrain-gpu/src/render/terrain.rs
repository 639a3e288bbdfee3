//! [`TerrainRenderer`]: one renderer for every LOD mode (geometry clipmaps, CDLOD, adaptive
//! tessellation; Cervin 2012) over every surface (a coarse-map with or without its detail
//! layer, a granular map, a streamed world's atlas with or without its detail layer; the
//! tessellation draws the map it was made of), driven the same way each frame:
//! [`TerrainRenderer::heights_changed`] after deformations, [`TerrainRenderer::prepare`],
//! [`TerrainRenderer::draw`] inside the caller's pass.
//!
//! The LOD data that depends on heights (CDLOD's quadtree, the tessellation's hierarchy and
//! density map) is updated on a worker thread (terrain-lod's `LodUpdater`) from the changed
//! rects the caller hands over (with a GPU, the rects read back: nothing is re-stamped to
//! learn the new heights). A frame takes in the newest finished update without waiting, so
//! the LOD lags the heights by a frame or two under heavy deformation.

use crate::clipmap::{ClipmapRenderer, ClipmapSurface, ClipmapView, TerrainStyle};
use crate::error::GpuError;
use crate::render::camera::{RenderView, ResolvedView};
use crate::render::cdlod::{CdlodDraw, CdlodRenderer};
use crate::render::clipmap::check_view;
use crate::render::target::TargetFormat;
use crate::render::tessellation::{
    GpuTessellation, TessDraw, TessRenderer, TessWorld, TessellationPass,
};
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::{CoarseMap, HeightEncoding, Rect};
use terrain_lod::{
    CdlodConfig, CdlodFrame, CdlodMesh, CdlodTree, CdlodUpdater, CdlodView, ClipmapLayout,
    DensityMap, DensityParams, Frustum, PoppingView, StreamedTessellation, TessConfig,
    TessHierarchy, TessState, TessUpdater,
};

/// Triangles a tessellated frame may hold (72 MiB of vertices).
pub const TESS_CAPACITY: u32 = 1 << 21;

/// Drawn vertices per frame the tessellation's popping metric probes.
const JUMP_PROBES: usize = 4096;

/// What a frame drew, for reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerrainFrame {
    /// `"clipmap"`, `"cdlod"` or `"tessellated"`.
    pub mode: &'static str,
    /// Triangles drawn.
    pub triangles: u64,
    /// Distinct vertices drawn.
    pub vertices: u64,
    /// The largest screen-space error of the drawn mesh in pixels, where the mode measures it
    /// (CDLOD over a map, the tessellation).
    pub max_screen_error_px: Option<f32>,
}

/// The view of one frame.
#[derive(Debug, Clone, Copy)]
pub struct TerrainView<'a> {
    /// What is drawn: CDLOD draws a coarse, detail, atlas or atlas-with-detail surface, the
    /// tessellation a coarse or detail surface (of the map it was made of), the clipmap any.
    pub surface: ClipmapSurface<'a>,
    /// The camera: a [`crate::Camera`], an engine's [`crate::ViewMatrices`], or any
    /// [`RenderView`].
    pub camera: &'a dyn RenderView,
    /// Lighting and colours.
    pub style: &'a TerrainStyle,
    /// The render target's size in pixels.
    pub target_size: UVec2,
}

/// The quadtree of a map (updated on a worker) or of a streamed world (kept current by its
/// owner through [`TerrainRenderer::streamed_tree_mut`]).
enum CdlodSource {
    Map(CdlodUpdater<u16>),
    Streamed(CdlodTree),
}

impl CdlodSource {
    fn tree(&self) -> &CdlodTree {
        match self {
            Self::Map(updater) => updater.tree(),
            Self::Streamed(tree) => tree,
        }
    }
}

struct Clipmap {
    layout: ClipmapLayout,
    renderer: ClipmapRenderer,
    /// Distinct vertices of each part of the layout's mesh.
    part_vertices: Vec<u64>,
    height_range: (f32, f32),
    /// The figures of the frame last prepared.
    last: Option<TerrainFrame>,
}

struct Cdlod {
    source: CdlodSource,
    renderer: CdlodRenderer,
    mesh: CdlodMesh,
    /// The last frame's selection with its camera, and the one before (the popping metric).
    last: Option<(CdlodFrame, Vec3)>,
    previous: Option<(CdlodFrame, Vec3)>,
}

struct Tessellated {
    updater: TessUpdater<u16>,
    gpu: GpuTessellation,
    pass: TessellationPass,
    renderer: TessRenderer,
    /// The last two frames' views (camera, width, hfov) and probes (the popping metric).
    last: Option<(Vec3, f32, f32)>,
    previous: Option<(Vec3, f32, f32)>,
    probes: Vec<Vec2>,
    previous_probes: Vec<Vec2>,
    /// The region left to another renderer (see [`TerrainRenderer::exclude`]).
    excluded: Option<(IVec2, IVec2)>,
    /// The last prepared frame's full-resolution rect (map texels): the excluded region.
    full: Option<(IVec2, IVec2)>,
}

/// The tessellation of a streamed world: decided from its quadtree (kept current by its owner
/// through [`TerrainRenderer::update_streamed_bounds`]), heights from the drawn atlas.
struct TessStreamed {
    tess: StreamedTessellation,
    tree: CdlodTree,
    encoding: HeightEncoding,
    gpu: GpuTessellation,
    pass: TessellationPass,
    renderer: TessRenderer,
    /// Rects whose node bounds changed since the last upload.
    dirty: Vec<Rect>,
    /// The region left to another renderer (see [`TerrainRenderer::exclude`]).
    excluded: Option<(IVec2, IVec2)>,
    /// The last prepared frame's full-resolution rect (map texels): the excluded region.
    full: Option<(IVec2, IVec2)>,
}

enum Lod {
    Clipmap(Clipmap),
    Cdlod(Cdlod),
    Tessellated(Box<Tessellated>),
    TessStreamed(Box<TessStreamed>),
}

/// Draws the terrain with one LOD mode (see the module docs).
pub struct TerrainRenderer {
    lod: Lod,
    /// The region left to another renderer ([`TerrainRenderer::exclude`]).
    excluded: Option<(IVec2, IVec2)>,
    /// Whether the last prepare left it out.
    excluding: bool,
    /// Frames in a row the region could not be left out (a warning at [`REFUSALS_WARNED`]).
    refused: u32,
}

/// Frames in a row whose refined region is drawn by the LOD before a warning says why: a
/// configuration that can never leave it out (a CDLOD finest range or a tessellation minimum
/// triangle too large for the radius) would otherwise refine nothing, silently.
const REFUSALS_WARNED: u32 = 120;

impl std::fmt::Debug for TerrainRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TerrainRenderer")
            .field("mode", &self.mode())
            .finish_non_exhaustive()
    }
}

impl TerrainRenderer {
    /// Geometry clipmaps of `layout`, placed each frame for heights within `height_range`
    /// (metres: what the frustum culling assumes).
    pub fn clipmap(
        device: &wgpu::Device,
        target: &TargetFormat,
        layout: ClipmapLayout,
        height_range: (f32, f32),
    ) -> Result<Self, GpuError> {
        let renderer = ClipmapRenderer::new(device, target, &layout)?;
        let mesh = layout.mesh();
        let part_vertices = mesh
            .parts
            .iter()
            .map(|p| {
                let used: std::collections::HashSet<u32> = mesh.indices
                    [p.indices.start as usize..p.indices.end as usize]
                    .iter()
                    .copied()
                    .collect();
                used.len() as u64
            })
            .collect();
        Ok(Self {
            excluded: None,
            excluding: false,
            refused: 0,
            lod: Lod::Clipmap(Clipmap {
                layout,
                renderer,
                part_vertices,
                height_range,
                last: None,
            }),
        })
    }

    /// CDLOD over `map` with `config`, its quadtree updated on a worker thread.
    pub fn cdlod(
        device: &wgpu::Device,
        target: &TargetFormat,
        map: &CoarseMap,
        config: CdlodConfig,
    ) -> Result<Self, GpuError> {
        let tree = CdlodTree::from_map(map, config)?;
        let updater = CdlodUpdater::spawn(tree, map)?;
        Self::with_cdlod(device, target, CdlodSource::Map(updater))
    }

    /// CDLOD over a streamed world: `tree` is built from the world's leaf bounds
    /// (`CdlodTree::from_leaf_bounds`) and kept current by the caller
    /// ([`TerrainRenderer::streamed_tree_mut`]).
    pub fn cdlod_streamed(
        device: &wgpu::Device,
        target: &TargetFormat,
        tree: CdlodTree,
    ) -> Result<Self, GpuError> {
        Self::with_cdlod(device, target, CdlodSource::Streamed(tree))
    }

    fn with_cdlod(
        device: &wgpu::Device,
        target: &TargetFormat,
        source: CdlodSource,
    ) -> Result<Self, GpuError> {
        let mesh = CdlodMesh::new(source.tree().config().grid_size);
        let renderer = CdlodRenderer::new(device, target, &mesh)?;
        Ok(Self {
            excluded: None,
            excluding: false,
            refused: 0,
            lod: Lod::Cdlod(Cdlod {
                source,
                renderer,
                mesh,
                last: None,
                previous: None,
            }),
        })
    }

    /// Adaptive tessellation of `map` with `config` (its triangle bound capped at
    /// [`TESS_CAPACITY`]), driven by the curvature density map when `density`; the hierarchy
    /// and density map are updated on a worker thread and their changed rows copied to the GPU.
    pub fn tessellated(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        target: &TargetFormat,
        map: &CoarseMap,
        config: TessConfig,
        density: bool,
    ) -> Result<Self, GpuError> {
        let density = density
            .then(|| DensityMap::from_map(map, DensityParams::default()))
            .transpose()?;
        // The CPU reference selects within the GPU's capacity: a view that needs more
        // triangles fails with a clear error instead of drawing holes.
        let config = TessConfig {
            max_triangles: config.max_triangles.min(TESS_CAPACITY as usize),
            ..config
        };
        let hierarchy = TessHierarchy::from_map(map, density.as_ref(), config)?;
        let gpu = GpuTessellation::new(device, queue, &hierarchy, config.max_triangles as u32)?;
        Ok(Self {
            excluded: None,
            excluding: false,
            refused: 0,
            lod: Lod::Tessellated(Box::new(Tessellated {
                updater: TessUpdater::spawn(TessState { hierarchy, density }, map)?,
                gpu,
                pass: TessellationPass::new(device)?,
                renderer: TessRenderer::new(device, target)?,
                last: None,
                previous: None,
                probes: Vec::new(),
                previous_probes: Vec::new(),
                excluded: None,
                full: None,
            })),
        })
    }

    /// Adaptive tessellation of a streamed world with `config` (its triangle bound capped at
    /// [`TESS_CAPACITY`]): `tree` is the world's quadtree (`CdlodTree::from_leaf_bounds`),
    /// kept current through [`TerrainRenderer::update_streamed_bounds`]; heights come from
    /// the atlas drawn ([`ClipmapSurface::Atlas`] or [`ClipmapSurface::AtlasDetail`]), whose
    /// stored heights are `encoding`'s. No density map (terrain-lod's
    /// `StreamedTessellation`).
    pub fn tessellated_streamed(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        target: &TargetFormat,
        tree: CdlodTree,
        config: TessConfig,
        encoding: HeightEncoding,
    ) -> Result<Self, GpuError> {
        let config = TessConfig {
            max_triangles: config.max_triangles.min(TESS_CAPACITY as usize),
            ..config
        };
        let tess = StreamedTessellation::new(config, &tree)?;
        let capacity = config.max_triangles as u32;
        let gpu = GpuTessellation::streamed(device, queue, &tess, &tree, encoding, capacity)?;
        Ok(Self {
            excluded: None,
            excluding: false,
            refused: 0,
            lod: Lod::TessStreamed(Box::new(TessStreamed {
                tess,
                tree,
                encoding,
                gpu,
                pass: TessellationPass::new(device)?,
                renderer: TessRenderer::new(device, target)?,
                dirty: Vec::new(),
                excluded: None,
                full: None,
            })),
        })
    }

    /// `"clipmap"`, `"cdlod"` or `"tessellated"`.
    pub fn mode(&self) -> &'static str {
        match self.lod {
            Lod::Clipmap(_) => "clipmap",
            Lod::Cdlod(_) => "cdlod",
            Lod::Tessellated(_) | Lod::TessStreamed(_) => "tessellated",
        }
    }

    /// Shades [`crate::SurfaceShading::Materials`] frames with `materials` (by default
    /// [`crate::GpuMaterials::procedural`]).
    pub fn set_materials(&mut self, materials: &crate::GpuMaterials) {
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.set_materials(materials),
            Lod::Cdlod(c) => c.renderer.set_materials(materials),
            Lod::Tessellated(t) => t.renderer.set_materials(materials),
            Lod::TessStreamed(t) => t.renderer.set_materials(materials),
        }
    }

    /// Binds the layers `previous` binds (materials, colour and material layers, hole mask, a
    /// streamed world's paint and colour) from the next prepare: for a renderer made to draw
    /// the same surface in another LOD mode (or with other clipmap levels), so switching
    /// modes keeps every layer. A surface shader set on `previous` is not carried over.
    pub fn adopt_layers(&mut self, previous: &TerrainRenderer) {
        let from = previous.layers();
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.layers_mut().adopt(from),
            Lod::Cdlod(c) => c.renderer.layers_mut().adopt(from),
            Lod::Tessellated(t) => t.renderer.layers_mut().adopt(from),
            Lod::TessStreamed(t) => t.renderer.layers_mut().adopt(from),
        }
    }

    /// The layers its LOD mode's renderer binds.
    pub(crate) fn layers(&self) -> &crate::resources::materials::MaterialSlot {
        match &self.lod {
            Lod::Clipmap(c) => c.renderer.layers(),
            Lod::Cdlod(c) => c.renderer.layers(),
            Lod::Tessellated(t) => t.renderer.layers(),
            Lod::TessStreamed(t) => t.renderer.layers(),
        }
    }

    /// Draws `color` (an orthophoto over the map) as the surface's albedo from the next
    /// prepare, `None` for none; its size must be the drawn surface's, else the prepare fails.
    pub fn set_color_layer(&mut self, color: Option<&crate::GpuColorLayer>) {
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.set_color_layer(color),
            Lod::Cdlod(c) => c.renderer.set_color_layer(color),
            Lod::Tessellated(t) => t.renderer.set_color_layer(color),
            Lod::TessStreamed(t) => t.renderer.set_color_layer(color),
        }
    }

    /// Blends `layer`'s painted weights ([`crate::GpuMaterialLayer`], painted by
    /// [`crate::MaterialEffectPass`]) over the autoshader's or the engine's in
    /// [`crate::SurfaceShading::Materials`] frames from the next prepare, `None` for none; its
    /// size must be the drawn surface's, else the prepare fails.
    pub fn set_material_layer(&mut self, layer: Option<&crate::GpuMaterialLayer>) {
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.set_material_layer(layer),
            Lod::Cdlod(c) => c.renderer.set_material_layer(layer),
            Lod::Tessellated(t) => t.renderer.set_material_layer(layer),
            Lod::TessStreamed(t) => t.renderer.set_material_layer(layer),
        }
    }

    /// Leaves out the cells `mask` marks as holes ([`crate::GpuHoleMask`]) in every LOD mode
    /// from the next prepare, `None` for none; its size must be the drawn surface's, else the
    /// prepare fails.
    pub fn set_hole_mask(&mut self, mask: Option<&crate::GpuHoleMask>) {
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.set_hole_mask(mask),
            Lod::Cdlod(c) => c.renderer.set_hole_mask(mask),
            Lod::Tessellated(t) => t.renderer.set_hole_mask(mask),
            Lod::TessStreamed(t) => t.renderer.set_hole_mask(mask),
        }
    }

    /// Draws a streamed world's paint and colour ([`crate::GpuOverlayAtlas`], filled by
    /// terrain-cache's `VramPool::update_overlay`) in every LOD mode from the next prepare,
    /// `None` for none, instead of the material and colour layers; their world must be the
    /// drawn surface's size, else the prepare fails.
    pub fn set_streamed_layers(
        &mut self,
        paint: Option<&crate::GpuOverlayAtlas>,
        color: Option<&crate::GpuOverlayAtlas>,
    ) {
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.set_streamed_layers(paint, color),
            Lod::Cdlod(c) => c.renderer.set_streamed_layers(paint, color),
            Lod::Tessellated(t) => t.renderer.set_streamed_layers(paint, color),
            Lod::TessStreamed(t) => t.renderer.set_streamed_layers(paint, color),
        }
    }

    /// Computes the material weights of [`crate::SurfaceShading::Materials`] with
    /// `wgsl_function`, an engine's `fn surface_weights(p: SurfacePoint) -> vec4<f32>`, or with
    /// the autoshader again for `None`. `SurfacePoint` holds the fragment's world position (x,
    /// z), height, ramp fraction, slope and curvature; the weights are those of grass, dirt,
    /// rock and snow (the [`crate::GpuMaterials`] layers), normalised by the blend. The
    /// function may read `frame` (the renderers' uniform) and call `autoshade_weights`. One
    /// that does not compile is [`GpuError::UserShader`], the renderer unchanged.
    pub fn set_surface_shader(
        &mut self,
        device: &wgpu::Device,
        wgsl_function: Option<&str>,
    ) -> Result<(), GpuError> {
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.set_surface_shader(device, wgsl_function),
            Lod::Cdlod(c) => c.renderer.set_surface_shader(device, wgsl_function),
            Lod::Tessellated(t) => t.renderer.set_surface_shader(device, wgsl_function),
            Lod::TessStreamed(t) => t.renderer.set_surface_shader(device, wgsl_function),
        }
    }

    /// The streamed world's quadtree, when this renderer draws one with CDLOD. (A streamed
    /// tessellation's is updated through [`TerrainRenderer::update_streamed_bounds`], which
    /// also copies the changed nodes to the GPU.)
    pub fn streamed_tree_mut(&mut self) -> Option<&mut CdlodTree> {
        match &mut self.lod {
            Lod::Cdlod(Cdlod {
                source: CdlodSource::Streamed(tree),
                ..
            }) => Some(tree),
            _ => None,
        }
    }

    /// The streamed world's quadtree, when this renderer draws one (CDLOD or tessellation).
    pub fn streamed_tree(&self) -> Option<&CdlodTree> {
        match &self.lod {
            Lod::Cdlod(Cdlod {
                source: CdlodSource::Streamed(tree),
                ..
            }) => Some(tree),
            Lod::TessStreamed(t) => Some(&t.tree),
            _ => None,
        }
    }

    /// Asks `leaf_bounds` again for the leaves of the streamed world's quadtree that `dirty`
    /// touches (`CdlodTree::update_leaf_bounds`), after a deformation or when finer tiles
    /// arrived; a streamed tessellation copies the changed nodes to the GPU at the next
    /// prepare. Nothing for a renderer that draws no streamed world.
    pub fn update_streamed_bounds(
        &mut self,
        dirty: Rect,
        leaf_bounds: impl FnMut(Rect) -> (f32, f32),
    ) -> Result<(), GpuError> {
        match &mut self.lod {
            Lod::Cdlod(Cdlod {
                source: CdlodSource::Streamed(tree),
                ..
            }) => tree.update_leaf_bounds(dirty, leaf_bounds)?,
            Lod::TessStreamed(t) => {
                t.tree.update_leaf_bounds(dirty, leaf_bounds)?;
                t.dirty.push(dirty);
            }
            _ => {}
        }
        Ok(())
    }

    /// The clipmap's layout, when this renderer is a clipmap.
    pub fn clipmap_layout(&self) -> Option<&ClipmapLayout> {
        match &self.lod {
            Lod::Clipmap(c) => Some(&c.layout),
            _ => None,
        }
    }

    /// The heights (metres) the clipmap's culling boxes span from now on (after the surface
    /// changed); nothing for the other modes, whose bounds follow the heights.
    pub fn set_height_range(&mut self, range: (f32, f32)) {
        if let Lod::Clipmap(c) = &mut self.lod {
            c.height_range = range;
        }
    }

    /// Leaves `region` to another renderer (the refined cells of a detail layer, relative to
    /// the camera's whole texel as [`crate::RefinePass::region`] gives them) from the next
    /// prepare on, in every mode: see [`ClipmapRenderer::exclude`] and
    /// [`crate::CdlodRenderer::exclude`]. The tessellation draws the region at full resolution
    /// whatever the view asks ([`TessellationPass::set_full_resolution`]), so its edge meets
    /// the other mesh. A frame where the region cannot be left out is drawn whole: see
    /// [`TerrainRenderer::excluding`].
    pub fn exclude(&mut self, region: Option<(IVec2, IVec2)>) {
        self.excluded = region;
        self.exclude_in_lod(region);
    }

    /// Whether the last [`TerrainRenderer::prepare`] left the excluded region out. Not so
    /// without a region, or where it could not be left out that frame
    /// ([`GpuError::CannotExclude`]: it reached where the LOD morphs, as near a cliff or where
    /// CDLOD's bounds are a tile's, or the tessellation's triangles stop short of the texels):
    /// the frame draws it with the rest, and the caller draws no refined cells over it.
    pub fn excluding(&self) -> bool {
        self.excluding
    }

    /// The region the LOD's renderer leaves out at its next prepare.
    fn lod_excluded(&self) -> Option<(IVec2, IVec2)> {
        match &self.lod {
            Lod::Clipmap(c) => c.renderer.excluded(),
            Lod::Cdlod(c) => c.renderer.excluded(),
            Lod::Tessellated(t) => t.excluded,
            Lod::TessStreamed(t) => t.excluded,
        }
    }

    fn exclude_in_lod(&mut self, region: Option<(IVec2, IVec2)>) {
        match &mut self.lod {
            Lod::Clipmap(c) => c.renderer.exclude(region),
            Lod::Cdlod(c) => c.renderer.exclude(region),
            Lod::Tessellated(t) => {
                t.renderer.exclude(region);
                t.excluded = region;
            }
            Lod::TessStreamed(t) => {
                t.renderer.exclude(region);
                t.excluded = region;
            }
        }
    }

    /// Hands the rects of `map` whose heights changed (already in `map`) to the LOD data's
    /// worker, and takes in what it has finished: the tessellation's changed rows are copied
    /// to the GPU here. The frame pays for copying the rects' rows, not for the update.
    /// Nothing to do for the clipmap or a streamed quadtree.
    pub fn heights_changed(
        &mut self,
        queue: &wgpu::Queue,
        map: &CoarseMap,
        rects: &[Rect],
    ) -> Result<(), GpuError> {
        match &mut self.lod {
            Lod::Clipmap(_) | Lod::TessStreamed(_) => {}
            Lod::Cdlod(c) => {
                if let CdlodSource::Map(updater) = &mut c.source {
                    updater.poll()?;
                    for r in rects {
                        updater.submit(map, *r)?;
                    }
                }
            }
            Lod::Tessellated(t) => {
                let updater = &mut t.updater;
                updater.poll()?;
                let rows = updater.take_changes();
                if !rows.is_empty() {
                    t.gpu.upload(queue, &updater.state().hierarchy, &rows)?;
                }
                for r in rects {
                    updater.submit(map, *r)?;
                }
            }
        }
        Ok(())
    }

    /// Waits until the worker has every change handed over, and copies the tessellation's
    /// changed rows: the LOD then equals one built from the current heights. For the end of a
    /// run and tests, never inside a frame.
    pub fn flush(&mut self, queue: &wgpu::Queue) -> Result<(), GpuError> {
        match &mut self.lod {
            Lod::Clipmap(_) | Lod::TessStreamed(_) => {}
            Lod::Cdlod(c) => {
                if let CdlodSource::Map(updater) = &mut c.source {
                    updater.flush()?;
                }
            }
            Lod::Tessellated(t) => {
                t.updater.flush()?;
                let rows = t.updater.take_changes();
                if !rows.is_empty() {
                    t.gpu.upload(queue, &t.updater.state().hierarchy, &rows)?;
                }
            }
        }
        Ok(())
    }

    /// The tessellation's GPU output (what the last prepared frame's compute pass writes),
    /// when this renderer tessellates.
    pub fn tessellation(&self) -> Option<&GpuTessellation> {
        match &self.lod {
            Lod::Tessellated(t) => Some(&t.gpu),
            Lod::TessStreamed(t) => Some(&t.gpu),
            _ => None,
        }
    }

    /// Selects this frame's geometry for `view` and writes what [`TerrainRenderer::draw`]
    /// draws; the tessellation's compute pass is recorded into `encoder` (submit it with, or
    /// before, the pass that draws). What a frame needs and no more: the figures a report
    /// wants are [`TerrainRenderer::figures`].
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        view: &TerrainView<'_>,
    ) -> Result<(), GpuError> {
        self.excluding = false;
        match self.prepare_lod(device, queue, encoder, view) {
            Ok(()) => {
                // What the LOD itself was told to leave out, not what was asked last: the two
                // differ only if a refusal failed to hand the region back.
                self.excluding = self.lod_excluded().is_some();
                self.refused = 0;
                Ok(())
            }
            // The region cannot be left out this frame: drawn whole (see `excluding`), and
            // tried again next frame. Nothing was recorded before the refusal (a streamed
            // tessellation's quadtree upload may have been: it is the same again).
            Err(GpuError::CannotExclude { what, reason }) if self.excluded.is_some() => {
                self.refused = self.refused.saturating_add(1);
                if self.refused == REFUSALS_WARNED {
                    tracing::warn!(
                        frames = REFUSALS_WARNED,
                        "{what}: {reason}; the refined region has been drawn by the LOD instead"
                    );
                }
                self.exclude_in_lod(None);
                let drawn = self.prepare_lod(device, queue, encoder, view);
                self.exclude_in_lod(self.excluded);
                drawn
            }
            Err(e) => Err(e),
        }
    }

    fn prepare_lod(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        view: &TerrainView<'_>,
    ) -> Result<(), GpuError> {
        let TerrainView {
            surface,
            camera,
            style,
            target_size,
        } = *view;
        let resolved = check_view(camera, None, target_size, "terrain target size (pixels)")?;
        let frustum = Frustum::from_view_proj(resolved.view_proj_world);
        let lod_view = lod_view(&resolved, target_size, &frustum);
        match &mut self.lod {
            Lod::Clipmap(c) => {
                let texel_size = match surface {
                    ClipmapSurface::Atlas { atlas } | ClipmapSurface::AtlasDetail { atlas, .. } => {
                        atlas.config().world.texel_size
                    }
                    ClipmapSurface::Coarse { map, .. } | ClipmapSurface::Detail { map, .. } => {
                        map.texel_size()
                    }
                    ClipmapSurface::Granular { map, .. } => map.texel_size(),
                };
                let eye = Vec2::new(resolved.eye.x, resolved.eye.z);
                let frame = c
                    .layout
                    .place(eye, texel_size, c.height_range, Some(&frustum))?;
                c.renderer.prepare(
                    device,
                    queue,
                    &ClipmapView {
                        surface,
                        frame: &frame,
                        camera,
                        style,
                        target_size,
                    },
                )?;
                // Counting what was placed is cheap: kept for `figures`.
                let vertices = frame
                    .draws
                    .iter()
                    .filter_map(|d| {
                        let part = c
                            .layout
                            .mesh()
                            .parts
                            .iter()
                            .position(|p| p.kind == d.part)?;
                        c.part_vertices.get(part).copied()
                    })
                    .sum();
                c.last = Some(TerrainFrame {
                    mode: "clipmap",
                    triangles: frame.triangle_count(c.layout.mesh()),
                    vertices,
                    max_screen_error_px: None,
                });
            }
            Lod::Cdlod(c) => {
                let frame = c.source.tree().select(&lod_view)?;
                let draw = CdlodDraw {
                    surface,
                    frame: &frame,
                    camera,
                    style,
                    target_size,
                };
                c.renderer.prepare(device, queue, &draw)?;
                c.previous = c.last.replace((frame, resolved.eye));
            }
            Lod::Tessellated(t) => {
                let hierarchy = &t.updater.state().hierarchy;
                t.full = t
                    .excluded
                    .map(|r| absolute(r, resolved.eye, hierarchy.texel_size()));
                if t.full.is_some() {
                    let levels = hierarchy.decision(&lod_view)?.split_levels;
                    check_full(levels + 1 == hierarchy.level_count())?;
                }
                t.pass.set_full_resolution(t.full);
                t.pass
                    .encode(device, queue, encoder, &t.gpu, hierarchy, &lod_view)?;
                let draw = TessDraw {
                    surface,
                    camera,
                    style,
                    target_size,
                };
                t.renderer.prepare(device, queue, &draw)?;
                let width = target_size.x as f32;
                t.previous = t.last.replace((resolved.eye, width, lod_view.hfov));
            }
            Lod::TessStreamed(t) => {
                let (ClipmapSurface::Atlas { atlas } | ClipmapSurface::AtlasDetail { atlas, .. }) =
                    surface
                else {
                    return Err(GpuError::Unsupported {
                        what: "TerrainRenderer (streamed tessellation)",
                        reason: "the surface must be the world's atlas, with or without detail",
                    });
                };
                if atlas.config().world.encoding != t.encoding {
                    return Err(GpuError::Unsupported {
                        what: "TerrainRenderer (streamed tessellation)",
                        reason: "the atlas stores heights in another encoding than the one the \
                                 tessellation was made for",
                    });
                }
                if !t.dirty.is_empty() {
                    t.gpu.upload_tree(queue, &t.tree, &t.dirty)?;
                    t.dirty.clear();
                }
                t.full = t
                    .excluded
                    .map(|r| absolute(r, resolved.eye, t.tree.texel_size()));
                if t.full.is_some() {
                    let levels = t.tess.decision(&lod_view)?.split_levels;
                    check_full(levels == 2 * t.tess.config().patch_size.trailing_zeros())?;
                }
                t.pass.set_full_resolution(t.full);
                t.pass.encode_streamed(
                    device,
                    queue,
                    encoder,
                    &t.gpu,
                    &TessWorld {
                        tess: &t.tess,
                        atlas,
                    },
                    &lod_view,
                )?;
                let draw = TessDraw {
                    surface,
                    camera,
                    style,
                    target_size,
                };
                t.renderer.prepare(device, queue, &draw)?;
            }
        }
        Ok(())
    }

    /// What the frame last prepared for `view` draws, for reports. CDLOD's screen error and
    /// the tessellation's figures come from terrain-lod's CPU reference (the tessellation's
    /// triangles are the GPU's), which costs CPU time a frame need not spend; it also fails
    /// when that frame needs more triangles than the tessellation's output holds (the GPU
    /// then drops the rest). The tessellation's popping metric probes the vertices found here.
    pub fn figures(&mut self, view: &TerrainView<'_>) -> Result<TerrainFrame, GpuError> {
        let resolved = check_view(
            view.camera,
            None,
            view.target_size,
            "terrain target size (pixels)",
        )?;
        let frustum = Frustum::from_view_proj(resolved.view_proj_world);
        let lod_view = lod_view(&resolved, view.target_size, &frustum);
        let not_prepared = GpuError::Unsupported {
            what: "TerrainRenderer::figures",
            reason: "no frame was prepared",
        };
        match &mut self.lod {
            Lod::Clipmap(c) => c.last.ok_or(not_prepared),
            Lod::Cdlod(c) => {
                let (frame, _) = c.last.as_ref().ok_or(not_prepared)?;
                let tree = c.source.tree();
                Ok(TerrainFrame {
                    mode: "cdlod",
                    triangles: frame.triangle_count(&c.mesh),
                    vertices: frame.vertex_count(&c.mesh),
                    // A streamed world's tree knows its errors only as height spans.
                    max_screen_error_px: match c.source {
                        CdlodSource::Streamed(_) => None,
                        CdlodSource::Map(_) => Some(tree.max_screen_error_px(frame, &lod_view)),
                    },
                })
            }
            Lod::Tessellated(t) => {
                let hierarchy = &t.updater.state().hierarchy;
                let frame = hierarchy.select_with(&lod_view, t.full)?;
                let max_screen_error_px = hierarchy.max_screen_error_px(&frame, &lod_view);
                let stride = (frame.triangles.len() / JUMP_PROBES).max(1);
                let probes = frame
                    .triangles
                    .iter()
                    .step_by(stride)
                    .map(|t| Vec2::from(t[2].texel))
                    .collect();
                t.previous_probes = std::mem::replace(&mut t.probes, probes);
                Ok(TerrainFrame {
                    mode: "tessellated",
                    triangles: frame.triangle_count(),
                    vertices: frame.vertex_count(),
                    max_screen_error_px: Some(max_screen_error_px),
                })
            }
            Lod::TessStreamed(t) => {
                // The decisions read only the tree: the CPU counts the GPU's triangles without
                // the heights (which only the atlas holds), and knows no screen error.
                let frame = t.tess.select_with(&t.tree, &lod_view, &|_| 0.0, t.full)?;
                Ok(TerrainFrame {
                    mode: "tessellated",
                    triangles: frame.triangle_count(),
                    vertices: frame.vertex_count(),
                    max_screen_error_px: None,
                })
            }
        }
    }

    /// Draws what [`TerrainRenderer::prepare`] wrote into `pass`.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        match &self.lod {
            Lod::Clipmap(c) => c.renderer.draw(pass),
            Lod::Cdlod(c) => c.renderer.draw(pass),
            Lod::Tessellated(t) => t.renderer.draw(pass, &t.gpu),
            Lod::TessStreamed(t) => t.renderer.draw(pass, &t.gpu),
        }
    }

    /// Lets the tessellation's per-frame buffers be reused once the frame's work was
    /// submitted (see [`TessellationPass::recall`]); nothing for the other modes.
    pub fn recall(&mut self) {
        match &mut self.lod {
            Lod::Tessellated(t) => t.pass.recall(),
            Lod::TessStreamed(t) => t.pass.recall(),
            _ => {}
        }
    }

    /// The popping metric of the last frame against the one before, in pixels: the largest
    /// screen-space jump of the drawn surface between the two frames' LOD decisions, both
    /// evaluated on `map` and projected with `camera` on a `target_size` target, so only a
    /// change of the mesh counts. `None` for the clipmap, a streamed quadtree, or before two
    /// frames, or for a view the renderers refuse.
    pub fn popping_px(
        &self,
        map: &CoarseMap,
        camera: &dyn RenderView,
        target_size: UVec2,
    ) -> Option<f32> {
        let size = target_size.as_vec2();
        let resolved = ResolvedView::new(camera, target_size).ok()?;
        let view_proj = resolved.view_proj_world;
        match &self.lod {
            Lod::Clipmap(_) | Lod::TessStreamed(_) => None,
            Lod::Cdlod(c) => {
                let CdlodSource::Map(_) = c.source else {
                    return None;
                };
                let ((now, eye), (then, then_eye)) = (c.last.as_ref()?, c.previous.as_ref()?);
                let view = PoppingView {
                    forward: resolved.forward,
                    view_proj,
                    target: size,
                };
                Some(
                    c.source
                        .tree()
                        .popping_px(map, (now, *eye), (then, *then_eye), &view),
                )
            }
            Lod::Tessellated(t) => {
                let ((eye, width, hfov), (then_eye, then_width, then_hfov)) =
                    (t.last?, t.previous?);
                let view = |camera, viewport_width, hfov| CdlodView {
                    camera,
                    frustum: None,
                    viewport_width,
                    hfov,
                };
                let probes: Vec<Vec2> =
                    t.probes.iter().chain(&t.previous_probes).copied().collect();
                Some(t.updater.state().hierarchy.max_height_jump(
                    &view(eye, width, hfov),
                    &view(then_eye, then_width, then_hfov),
                    &probes,
                    view_proj,
                    size,
                ))
            }
        }
    }
}

/// `region` (texels relative to the camera's whole texel, as the frame uniform has it) in
/// texels of the map.
fn absolute((lo, hi): (IVec2, IVec2), eye: Vec3, texel_size: f32) -> (IVec2, IVec2) {
    let base = (Vec2::new(eye.x, eye.z) / texel_size).floor().as_ivec2();
    (base.saturating_add(lo), base.saturating_add(hi))
}

/// Refuses to leave a region to another renderer when the tessellation's triangles stop short
/// of the texels (a minimum triangle size): its edge would not meet the other mesh.
fn check_full(reaches_texels: bool) -> Result<(), GpuError> {
    if reaches_texels {
        return Ok(());
    }
    Err(GpuError::CannotExclude {
        what: "TerrainRenderer::exclude",
        reason: "the tessellation's minimum triangle size keeps it from the texels the excluded \
                 region's edge must be drawn through",
    })
}

/// What CDLOD's and the tessellation's decisions are made for: the eye, the frustum and the
/// target's width and horizontal field of view (so the screen-space error follows the
/// engine's projection, whatever its depth convention).
fn lod_view<'a>(view: &ResolvedView, size: UVec2, frustum: &'a Frustum) -> CdlodView<'a> {
    CdlodView {
        camera: view.eye,
        frustum: Some(frustum),
        viewport_width: size.x as f32,
        hfov: view.hfov,
    }
}
