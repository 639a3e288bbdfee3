//! Adaptive tessellation on the GPU (Cervin 2012, sec. 2.3, algorithm 3.1) as compute work: wgpu
//! has no tessellation stage, so [`TessellationPass`] refines every patch's two triangles by
//! longest-edge bisection in a compute shader (`tessellate.wgsl`), appends the triangles it
//! keeps to a vertex buffer and writes the indirect draw arguments; [`TessRenderer`] draws them
//! into the caller's pass with `draw_indirect`, shaded exactly as the clipmap. The CPU
//! reference is [`terrain_lod::TessHierarchy::select`]: same decisions, same f32 operations.
//!
//! The refinement runs breadth first, one dispatch per level: Cervin refines in a hardware
//! tessellator, and the compute equivalent of the CPU's depth-first walk (one invocation per
//! base triangle with a private stack) leaves a real GPU nearly idle (two invocations per
//! patch, long divergent loops, large private arrays that cut occupancy). Level 0 runs two
//! invocations per patch; each later level one per triangle its predecessor queued (the
//! visible children of the triangles it split, in a ping-pong pair of queues), dispatched
//! indirectly from that count, which a one-invocation pass turns into the dispatch size.
//!
//! [`GpuTessellation`] holds the persistent resources: the hierarchy's per-vertex bounds
//! (height, saturated radius, density and error), the patch bounds, the output triangles, the
//! two level queues, the counters with the draw arguments and the per-level dispatch
//! arguments. Nothing is allocated per frame.

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, shader_module, wrap_code,
};
use crate::device::download::download_bytes;
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::render::camera::RenderView;
use crate::render::clipmap::{
    ClipmapSurface, SurfacePipeline, TerrainStyle, VertexShape, check_view, check_wireframe,
    frame_uniform,
};
use crate::render::surface::{BoundBuffers, DetailUniform, fragment_reach, with_surface_weights};
use crate::render::target::TargetFormat;
use crate::resources::atlas::GpuTileAtlas;
use crate::resources::materials::{GpuColorLayer, GpuMaterials, MaterialSlot};
use buffers::Source;
use bytemuck::{Pod, Zeroable};
use glam::UVec2;
use terrain_core::WrapMode;
use terrain_lod::tessellation::MAX_LEVELS;
use terrain_lod::tessellation::{TessDecision, descendant_reach};
use terrain_lod::{CdlodView, StreamedTessellation, TessHierarchy, TessTriangle, TessVertex};

mod buffers;
mod renderer;

pub use buffers::GpuTessellation;
pub use renderer::{TessDraw, TessRenderer};

/// The uniform block of `tessellate.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, Default)]
struct Params {
    camera: [f32; 4],
    planes: [[f32; 4]; 6],
    texel_size: f32,
    scale: f32,
    inv_morph_range: f32,
    use_density: u32,
    split_levels: u32,
    patch_size: u32,
    capacity: u32,
    cull: u32,
    patches: [u32; 2],
    grid: [u32; 2],
    wrap: u32,
    error_metric: u32,
    queue_capacity: u32,
    max_groups: u32,
    /// TessDecision::full_resolution's corners, and whether there is one.
    full_lo: [i32; 2],
    full_hi: [i32; 2],
    full: u32,
    _pad: [u32; 3],
    /// descendant_reach of each level, four to a vector.
    reach: [[u32; 4]; 4],
}

const _: () = assert!(std::mem::size_of::<Params>() == 272);

/// Bytes of the counter block: count, overflow, the level, a pad, the four `draw_indirect`
/// arguments, the two queues' counts and two pads.
const STATE_BYTES: u64 = 48;
/// Where the draw arguments start in the counter block.
const ARGS_OFFSET: u64 = 16;
/// Bytes per grid vertex: height, radius, density, error.
const VERTEX_BYTES: u64 = 16;
/// Bytes per triangle in the output (three [`TessVertex`]).
const TRIANGLE_BYTES: u64 = std::mem::size_of::<TessTriangle>() as u64;
/// Bytes per triangle in a level queue: the apex, three heights, the patch and the direction
/// of a leg.
const QUEUED_BYTES: u64 = 24;
/// Patches a level queue's entry can name (28 bits).
const MAX_PATCHES: u64 = 1 << 28;
/// Bytes of the `dispatch_workgroups_indirect` arguments of one level (three counts, a pad).
const DISPATCH_BYTES: u64 = 16;
/// Invocations per workgroup of `generate`.
const GROUP: u64 = 64;

/// A streamed world as [`TessellationPass::encode_streamed`] tessellates it: the decisions
/// and the atlas the heights are read from.
#[derive(Debug, Clone, Copy)]
pub struct TessWorld<'a> {
    /// The tessellation (terrain-lod), made for the world's quadtree.
    pub tess: &'a StreamedTessellation,
    /// The world's tile atlas.
    pub atlas: &'a GpuTileAtlas,
}

/// The compute pass that tessellates a [`GpuTessellation`] for a view, one dispatch per
/// level: of a map's hierarchy ([`TessellationPass::encode`]) or of a streamed world
/// ([`TessellationPass::encode_streamed`], its pipelines built on first use). Build it once
/// per device.
#[derive(Debug)]
pub struct TessellationPass {
    hierarchy: Pipelines,
    streamed: Option<Pipelines>,
    /// See [`TessellationPass::set_full_resolution`].
    full_resolution: Option<(glam::IVec2, glam::IVec2)>,
}

/// The pipelines of one source (`tess_source_*.wgsl`) and their bindings.
#[derive(Debug)]
struct Pipelines {
    /// `generate`'s bindings: the decision data, the output, the counters and the queues (and
    /// a streamed world's atlas).
    bindings: PassBindings<Params>,
    /// `advance`'s: the same and the dispatch arguments, which `generate` reads as indirect
    /// arguments and so must not have bound.
    advance_bindings: PassBindings<Params>,
    generate: wgpu::ComputePipeline,
    advance: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
}

/// The bindings of `generate` after the uniform: decision data and table, output, counters,
/// queues; `advance` adds the dispatch arguments.
const READ: StorageBinding = StorageBinding::compute(true);
const WRITE: StorageBinding = StorageBinding::compute(false);
const GENERATE_BINDINGS: [(u32, StorageBinding); 5] =
    [(1, READ), (2, READ), (3, WRITE), (4, WRITE), (5, WRITE)];
/// A streamed world's atlas (`tile_atlas_bind_high.wgsl`).
const ATLAS_BINDINGS: [(u32, StorageBinding); 3] = [(20, READ), (21, READ), (22, READ)];
const DISPATCH_BINDING: (u32, StorageBinding) = (6, WRITE);

impl Pipelines {
    fn new(
        device: &wgpu::Device,
        label: &'static str,
        source: &str,
        extra: &[(u32, StorageBinding)],
    ) -> Result<Self, GpuError> {
        let compute = wgpu::ShaderStages::COMPUTE;
        let mut storage = GENERATE_BINDINGS.to_vec();
        storage.extend_from_slice(extra);
        let bindings = PassBindings::numbered(device, label, compute, &storage);
        storage.push(DISPATCH_BINDING);
        let advance_bindings = PassBindings::numbered(device, label, compute, &storage);
        let module = shader_module(device, label, source)?;
        let pipeline = |layout, entry| compute_pipeline(device, label, &module, layout, entry);
        Ok(Self {
            generate: pipeline(bindings.layout(), "generate")?,
            advance: pipeline(advance_bindings.layout(), "advance")?,
            finish: pipeline(bindings.layout(), "finish")?,
            bindings,
            advance_bindings,
        })
    }

    /// Records the pass: clears the counters, refines every patch level by level (level 0
    /// over the patches, then for each further level the dispatch size from the queue's count
    /// and the level over the queue), writes the draw arguments.
    fn record(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        gpu: &GpuTessellation,
        params: &Params,
        extra: &[&wgpu::Buffer],
    ) -> Result<(), GpuError> {
        let max_groups = params.max_groups;
        // Level 0: two invocations per patch, over two dimensions past the device's limit.
        let threads = 2 * u64::from(gpu.patches.x) * u64::from(gpu.patches.y);
        let groups = threads.div_ceil(GROUP);
        let x = groups.min(u64::from(max_groups));
        let y = groups.div_ceil(x.max(1));
        if y > u64::from(max_groups) {
            return Err(GpuError::Unsupported {
                what: "TessellationPass",
                reason: "more patches than one dispatch of the device covers: use larger patches",
            });
        }
        let mut buffers = vec![
            &gpu.vertices,
            &gpu.patch_bounds,
            &gpu.output,
            &gpu.state,
            &gpu.queues,
        ];
        buffers.extend_from_slice(extra);
        let (group, offset) = self.bindings.bind(device, queue, params, &buffers)?;
        buffers.push(&gpu.dispatch);
        let (advance_group, advance_offset) = self
            .advance_bindings
            .bind(device, queue, params, &buffers)?;
        encoder.clear_buffer(&gpu.state, 0, None);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("TessellationPass"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &group, &[offset]);
        pass.set_pipeline(&self.generate);
        pass.dispatch_workgroups(x as u32, y as u32, 1);
        for level in 1..=params.split_levels {
            pass.set_bind_group(0, &advance_group, &[advance_offset]);
            pass.set_pipeline(&self.advance);
            pass.dispatch_workgroups(1, 1, 1);
            pass.set_bind_group(0, &group, &[offset]);
            pass.set_pipeline(&self.generate);
            pass.dispatch_workgroups_indirect(&gpu.dispatch, u64::from(level) * DISPATCH_BYTES);
        }
        pass.set_pipeline(&self.finish);
        pass.dispatch_workgroups(1, 1, 1);
        Ok(())
    }

    fn recall(&mut self) {
        self.bindings.recall();
        self.advance_bindings.recall();
    }
}

/// The uniform of a frame: the decision `d` for `view`, with the tessellation's sizes.
fn frame_params(
    device: &wgpu::Device,
    gpu: &GpuTessellation,
    d: &TessDecision,
    view: &CdlodView<'_>,
    texel_size: f32,
    patch_size: u32,
    wrap: WrapMode,
) -> Params {
    let mut planes = [[0.0f32; 4]; 6];
    if let Some(f) = view.frustum {
        for (p, q) in planes.iter_mut().zip(f.planes()) {
            *p = q.to_array();
        }
    }
    let (full_lo, full_hi) = d.full_resolution.unwrap_or_default();
    let mut reach = [[0u32; 4]; 4];
    for (l, r) in reach.iter_mut().flatten().enumerate() {
        *r = descendant_reach(patch_size, l as u32);
    }
    Params {
        full_lo: full_lo.to_array(),
        full_hi: full_hi.to_array(),
        full: u32::from(d.full_resolution.is_some()),
        _pad: [0; 3],
        reach,
        camera: d.camera.extend(0.0).to_array(),
        planes,
        texel_size,
        scale: d.scale,
        inv_morph_range: d.inv_morph_range,
        use_density: u32::from(d.use_density),
        // 2 log2(patch_size) <= MAX_LEVELS: the dispatch arguments have a slot per level.
        split_levels: d.split_levels.min(MAX_LEVELS),
        patch_size,
        capacity: gpu.capacity,
        cull: u32::from(view.frustum.is_some()),
        patches: gpu.patches.to_array(),
        grid: gpu.grid.to_array(),
        wrap: wrap_code(wrap),
        error_metric: u32::from(d.error_metric),
        queue_capacity: gpu.queue_capacity,
        max_groups: device.limits().max_compute_workgroups_per_dimension,
    }
}

impl TessellationPass {
    /// Compiles the map's shader and builds its pipelines.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        Ok(Self {
            hierarchy: Pipelines::new(device, "tessellate.wgsl", terrain_shaders::TESSELLATE, &[])?,
            streamed: None,
            full_resolution: None,
        })
    }

    /// Draws the texels from the first to the last corner of `region` (map texels, both
    /// included) at full resolution whatever the view asks, in the tessellations encoded from
    /// now on (terrain-lod's `TessDecision::full_resolution`; the CPU references'
    /// `select_with`); `None` for none.
    pub fn set_full_resolution(&mut self, region: Option<(glam::IVec2, glam::IVec2)>) {
        self.full_resolution = region;
    }

    /// Records the tessellation of `gpu` (uploaded from `hierarchy`) for `view` into
    /// `encoder`. Checks the view as [`TessHierarchy::select`] does.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        gpu: &GpuTessellation,
        hierarchy: &TessHierarchy,
        view: &CdlodView<'_>,
    ) -> Result<(), GpuError> {
        if gpu.source != Source::Hierarchy
            || hierarchy.grid_size() != gpu.grid
            || hierarchy.patches() != gpu.patches
        {
            return Err(GpuError::SizeMismatch {
                expected: gpu.grid,
                actual: hierarchy.grid_size(),
            });
        }
        let d = TessDecision {
            full_resolution: self.full_resolution,
            ..hierarchy.decision(view)?
        };
        let c = hierarchy.config();
        let params = frame_params(
            device,
            gpu,
            &d,
            view,
            hierarchy.texel_size(),
            c.patch_size,
            hierarchy.grid_wrap(),
        );
        self.hierarchy
            .record(device, queue, encoder, gpu, &params, &[])
    }

    /// Records the tessellation of a streamed world for `view` into `encoder`: `gpu` made by
    /// [`GpuTessellation::streamed`] from `world.tess` and the tree (its bounds uploaded since
    /// the tree last changed), heights read from `world.atlas` (the world's: the tree's size).
    /// Checks the view as [`StreamedTessellation::select`] does.
    pub fn encode_streamed(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        gpu: &GpuTessellation,
        world: &TessWorld<'_>,
        view: &CdlodView<'_>,
    ) -> Result<(), GpuError> {
        let TessWorld { tess, atlas } = *world;
        let world = &atlas.config().world;
        if gpu.source != Source::Streamed
            || world.world_size != gpu.grid
            || tess.patches() != gpu.patches
        {
            return Err(GpuError::SizeMismatch {
                expected: gpu.grid,
                actual: world.world_size,
            });
        }
        let d = TessDecision {
            full_resolution: self.full_resolution,
            ..tess.decision(view)?
        };
        let params = frame_params(
            device,
            gpu,
            &d,
            view,
            world.texel_size,
            tess.config().patch_size,
            WrapMode::Clamp,
        );
        if self.streamed.is_none() {
            self.streamed = Some(Pipelines::new(
                device,
                "tessellate streamed",
                terrain_shaders::TESSELLATE_STREAMED,
                &ATLAS_BINDINGS,
            )?);
        }
        let Some(pipelines) = self.streamed.as_mut() else {
            return Ok(());
        };
        let atlas_buffers = [
            atlas.info_buffer(),
            atlas.heights_buffer(),
            atlas.table_buffer(),
        ];
        pipelines.record(device, queue, encoder, gpu, &params, &atlas_buffers)
    }

    /// Frees the uniform rings' slots: call after the submit carrying the encoded work.
    pub fn recall(&mut self) {
        self.hierarchy.recall();
        if let Some(s) = self.streamed.as_mut() {
            s.recall();
        }
    }
}
