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
use crate::resources::materials::{GpuColorLayer, GpuMaterials, MaterialSlot};
use bytemuck::{Pod, Zeroable};
use glam::UVec2;
use terrain_core::WrapMode;
use terrain_lod::tessellation::MAX_LEVELS;
use terrain_lod::{CdlodView, TessHierarchy, TessTriangle, TessVertex};

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
}

const _: () = assert!(std::mem::size_of::<Params>() == 176);

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

/// A [`TessHierarchy`] on the GPU, with room for `capacity` triangles of output and
/// `queue_capacity` triangles in each of the two level queues.
#[derive(Debug)]
pub struct GpuTessellation {
    vertices: wgpu::Buffer,
    patch_bounds: wgpu::Buffer,
    output: wgpu::Buffer,
    state: wgpu::Buffer,
    queues: wgpu::Buffer,
    dispatch: wgpu::Buffer,
    capacity: u32,
    queue_capacity: u32,
    grid: UVec2,
    patches: UVec2,
}

impl GpuTessellation {
    /// Uploads `hierarchy` and makes room for `capacity` triangles (at least 1), with level
    /// queues of as many triangles each (fewer where the device's storage buffer limit asks
    /// for it; 24 bytes a triangle, so the two add 48 bytes per triangle of capacity to the
    /// output's 36): a level queues only visible children of the triangles that split, each
    /// of which leads to at least one emitted triangle unless the frustum misses both of its
    /// own children. Fails when the buffers exceed the device's limits.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        hierarchy: &TessHierarchy,
        capacity: u32,
    ) -> Result<Self, GpuError> {
        let limit = device.limits().max_storage_buffer_binding_size;
        let fit = u32::try_from(limit / (2 * QUEUED_BYTES)).unwrap_or(u32::MAX);
        Self::with_queues(device, queue, hierarchy, capacity, capacity.min(fit))
    }

    /// As [`GpuTessellation::new`], with room for `queue_capacity` triangles (at least 1) in
    /// each of the two level queues. A view whose refinement queues more triangles in one
    /// level emits those that find no room unsplit and reports an overflow, as a full output
    /// does. Fails when the buffers exceed the device's limits.
    pub fn with_queues(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        hierarchy: &TessHierarchy,
        capacity: u32,
        queue_capacity: u32,
    ) -> Result<Self, GpuError> {
        let grid = hierarchy.grid_size();
        let patches = hierarchy.patches();
        let capacity = capacity.max(1);
        let queue_capacity = queue_capacity.max(1);
        let limit = device.limits().max_storage_buffer_binding_size;
        let vertex_bytes = u64::from(grid.x) * u64::from(grid.y) * VERTEX_BYTES;
        let output_bytes = u64::from(capacity) * TRIANGLE_BYTES;
        let queue_bytes = 2 * u64::from(queue_capacity) * QUEUED_BYTES;
        if vertex_bytes > limit {
            return Err(GpuError::MapTooLarge {
                size: grid,
                bytes: vertex_bytes,
                limit,
            });
        }
        if output_bytes > limit {
            return Err(GpuError::Unsupported {
                what: "GpuTessellation",
                reason: "the output for this many triangles exceeds the device's storage buffer \
                         limit (36 bytes per triangle): ask for fewer",
            });
        }
        if u64::from(patches.x) * u64::from(patches.y) > MAX_PATCHES {
            return Err(GpuError::Unsupported {
                what: "GpuTessellation",
                reason: "more than 2^28 patches: use larger patches",
            });
        }
        if queue_bytes > limit {
            return Err(GpuError::Unsupported {
                what: "GpuTessellation",
                reason: "the level queues for this many triangles exceed the device's storage \
                         buffer limit (48 bytes per triangle): ask for fewer",
            });
        }
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let indirect = storage | wgpu::BufferUsages::INDIRECT;
        let buffers = scoped(device, "GpuTessellation", || {
            let buffer = |label, size: u64, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: size.max(16),
                    usage,
                    mapped_at_creation: false,
                })
            };
            (
                buffer("tessellation vertices", vertex_bytes, storage),
                buffer(
                    "tessellation patch bounds",
                    u64::from(patches.x) * u64::from(patches.y) * 8,
                    storage,
                ),
                buffer(
                    "tessellation output",
                    output_bytes,
                    wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::VERTEX
                        | wgpu::BufferUsages::COPY_SRC,
                ),
                buffer(
                    "tessellation state",
                    STATE_BYTES,
                    indirect | wgpu::BufferUsages::COPY_SRC,
                ),
                buffer("tessellation queues", queue_bytes, storage),
                buffer(
                    "tessellation dispatch",
                    u64::from(MAX_LEVELS + 1) * DISPATCH_BYTES,
                    indirect,
                ),
            )
        })?;
        let (vertices, patch_bounds, output, state, queues, dispatch) = buffers;
        let out = Self {
            vertices,
            patch_bounds,
            output,
            state,
            queues,
            dispatch,
            capacity,
            queue_capacity,
            grid,
            patches,
        };
        out.upload(queue, hierarchy, std::slice::from_ref(&(0..grid.y)))?;
        Ok(out)
    }

    /// Copies the vertex rows `rows` (the ranges [`TessHierarchy::update_rect`] returns, of
    /// one or more updates) and all patch bounds of `hierarchy` to the GPU. Fails for a
    /// hierarchy of another size.
    pub fn upload(
        &self,
        queue: &wgpu::Queue,
        hierarchy: &TessHierarchy,
        rows: &[std::ops::Range<u32>],
    ) -> Result<(), GpuError> {
        if hierarchy.grid_size() != self.grid || hierarchy.patches() != self.patches {
            return Err(GpuError::SizeMismatch {
                expected: self.grid,
                actual: hierarchy.grid_size(),
            });
        }
        // Ranges of several updates overlap: each row is copied once. In pieces of at most
        // 256 rows, so the packed copy stays small.
        let pieces = merge_rows(rows, self.grid.y)
            .into_iter()
            .flat_map(|r| r.clone().step_by(256).map(move |y| y..(y + 256).min(r.end)));
        for rows in pieces {
            let w = self.grid.x as usize;
            let (a, b) = (rows.start as usize * w, rows.end as usize * w);
            let packed: Vec<[f32; 4]> = hierarchy.heights()[a..b]
                .iter()
                .zip(&hierarchy.bounds()[a..b])
                .map(|(&h, &[r, d, e])| [h, r, d, e])
                .collect();
            queue.write_buffer(
                &self.vertices,
                a as u64 * VERTEX_BYTES,
                bytemuck::cast_slice(&packed),
            );
        }
        queue.write_buffer(
            &self.patch_bounds,
            0,
            bytemuck::cast_slice(hierarchy.patch_bounds()),
        );
        Ok(())
    }

    /// Triangles the output holds.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Bytes of GPU memory the grid's vertices take (16 per vertex: height and bounds).
    pub fn vertex_bytes(&self) -> u64 {
        self.vertices.size()
    }

    /// Bytes of GPU memory of the output, the level queues and the small state buffers: what
    /// grows with the triangle capacity.
    pub fn triangle_bytes(&self) -> u64 {
        [
            &self.patch_bounds,
            &self.output,
            &self.state,
            &self.queues,
            &self.dispatch,
        ]
        .iter()
        .map(|b| b.size())
        .sum()
    }

    /// Triangles each of the two level queues holds.
    pub fn queue_capacity(&self) -> u32 {
        self.queue_capacity
    }

    /// Reads back what the last [`TessellationPass::encode`] wrote: its triangles (in no
    /// particular order) and whether more were generated than the output or a level queue
    /// holds. Blocking: for tests and tools.
    pub fn read_triangles(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(Vec<TessTriangle>, bool), GpuError> {
        let state = download_bytes(device, queue, &self.state, 0, STATE_BYTES)?;
        let words: &[u32] = bytemuck::cast_slice(&state);
        let count = words[0].min(self.capacity);
        let overflow = words[1] != 0;
        if count == 0 {
            return Ok((Vec::new(), overflow));
        }
        let bytes = download_bytes(
            device,
            queue,
            &self.output,
            0,
            u64::from(count) * TRIANGLE_BYTES,
        )?;
        let verts: &[TessVertex] = bytemuck::cast_slice(&bytes);
        let tris = verts.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Ok((tris, overflow))
    }
}

/// The compute pass that tessellates a [`GpuTessellation`] for a view, one dispatch per
/// level. Build it once per device.
#[derive(Debug)]
pub struct TessellationPass {
    /// `generate`'s bindings: the hierarchy, the output, the counters and the queues.
    bindings: PassBindings<Params>,
    /// `advance`'s: the same and the dispatch arguments, which `generate` reads as indirect
    /// arguments and so must not have bound.
    advance_bindings: PassBindings<Params>,
    generate: wgpu::ComputePipeline,
    advance: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
}

impl TessellationPass {
    /// Compiles the shader and builds the pipelines.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let mut storage = vec![
            StorageBinding::compute(true),
            StorageBinding::compute(true),
            StorageBinding::compute(false),
            StorageBinding::compute(false),
            StorageBinding::compute(false),
        ];
        let compute = wgpu::ShaderStages::COMPUTE;
        let bindings = PassBindings::new(device, "TessellationPass", compute, &storage);
        storage.push(StorageBinding::compute(false));
        let advance_bindings =
            PassBindings::new(device, "TessellationPass advance", compute, &storage);
        let module = shader_module(device, "tessellate.wgsl", terrain_shaders::TESSELLATE)?;
        let generate = compute_pipeline(
            device,
            "tessellate generate",
            &module,
            bindings.layout(),
            "generate",
        )?;
        let advance = compute_pipeline(
            device,
            "tessellate advance",
            &module,
            advance_bindings.layout(),
            "advance",
        )?;
        let finish = compute_pipeline(
            device,
            "tessellate finish",
            &module,
            bindings.layout(),
            "finish",
        )?;
        Ok(Self {
            bindings,
            advance_bindings,
            generate,
            advance,
            finish,
        })
    }

    /// Records the tessellation of `gpu` (uploaded from `hierarchy`) for `view` into
    /// `encoder`: clears the counters, refines every patch level by level (level 0 over the
    /// patches, then for each further level the dispatch size from the queue's count and
    /// the level over the queue), writes the draw arguments. Checks the view as
    /// [`TessHierarchy::select`] does.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        gpu: &GpuTessellation,
        hierarchy: &TessHierarchy,
        view: &CdlodView<'_>,
    ) -> Result<(), GpuError> {
        if hierarchy.grid_size() != gpu.grid || hierarchy.patches() != gpu.patches {
            return Err(GpuError::SizeMismatch {
                expected: gpu.grid,
                actual: hierarchy.grid_size(),
            });
        }
        let d = hierarchy.decision(view)?;
        let c = hierarchy.config();
        // 2 log2(patch_size) <= MAX_LEVELS: the dispatch arguments have a slot per level.
        let levels = d.split_levels.min(MAX_LEVELS);
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        let mut planes = [[0.0f32; 4]; 6];
        if let Some(f) = view.frustum {
            for (p, q) in planes.iter_mut().zip(f.planes()) {
                *p = q.to_array();
            }
        }
        let params = Params {
            camera: d.camera.extend(0.0).to_array(),
            planes,
            texel_size: hierarchy.texel_size(),
            scale: d.scale,
            inv_morph_range: d.inv_morph_range,
            use_density: u32::from(d.use_density),
            split_levels: levels,
            patch_size: c.patch_size,
            capacity: gpu.capacity,
            cull: u32::from(view.frustum.is_some()),
            patches: gpu.patches.to_array(),
            grid: gpu.grid.to_array(),
            wrap: wrap_code(hierarchy.grid_wrap()),
            error_metric: u32::from(d.error_metric),
            queue_capacity: gpu.queue_capacity,
            max_groups,
        };
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
        let (group, offset) = self.bindings.bind(device, queue, &params, &buffers)?;
        buffers.push(&gpu.dispatch);
        let (advance_group, advance_offset) = self
            .advance_bindings
            .bind(device, queue, &params, &buffers)?;
        encoder.clear_buffer(&gpu.state, 0, None);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("TessellationPass"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &group, &[offset]);
        pass.set_pipeline(&self.generate);
        pass.dispatch_workgroups(x as u32, y as u32, 1);
        for level in 1..=levels {
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

    /// Frees the uniform rings' slots: call after the submit carrying the encoded work.
    pub fn recall(&mut self) {
        self.bindings.recall();
        self.advance_bindings.recall();
    }
}

/// Everything one tessellated frame is drawn from.
#[derive(Debug, Clone, Copy)]
pub struct TessDraw<'a> {
    /// What the fragments are shaded from: [`ClipmapSurface::Coarse`] (the map the
    /// tessellation was made of, with its normals) or [`ClipmapSurface::Detail`] (the same
    /// with a detail layer, shaded as the clipmap shades it).
    pub surface: ClipmapSurface<'a>,
    /// The camera: a [`crate::Camera`], an engine's [`crate::ViewMatrices`], or any
    /// [`RenderView`].
    pub camera: &'a dyn RenderView,
    /// Lighting and colours.
    pub style: &'a TerrainStyle,
    /// The render target's size in pixels.
    pub target_size: UVec2,
}

/// Draws the triangles of a [`GpuTessellation`] into passes of one [`TargetFormat`]: build it
/// once, then per frame [`TessRenderer::prepare`] and [`TessRenderer::draw`] (after the
/// tessellation pass was encoded, and after [`crate::SkyPass`], as the clipmap).
#[derive(Debug)]
pub struct TessRenderer {
    pipeline: SurfacePipeline,
    /// The detail surface's pipeline, built on its first frame.
    detail: Option<SurfacePipeline>,
    /// The detail surface's uniform.
    detail_uniform: DetailUniform,
    /// Whether the bound group is the detail pipeline's.
    on_detail: bool,
    target: TargetFormat,
    uniform: wgpu::Buffer,
    bound: Option<(BoundBuffers, wgpu::BindGroup)>,
    wireframe: bool,
    /// The materials of [`crate::SurfaceShading::Materials`].
    materials: MaterialSlot,
    /// An engine's `surface_weights` ([`TessRenderer::set_surface_shader`]).
    user_surface: Option<String>,
}

impl TessRenderer {
    /// Builds the pipeline.
    pub fn new(device: &wgpu::Device, target: &TargetFormat) -> Result<Self, GpuError> {
        target.validate(device)?;
        let pipeline = tess_pipeline(device, target, false, None)?;
        let uniform = scoped(device, "TessRenderer", || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("tessellated frame"),
                size: std::mem::size_of::<crate::render::clipmap::FrameUniform>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        Ok(Self {
            pipeline,
            detail: None,
            detail_uniform: DetailUniform::new(device, "tessellated detail"),
            on_detail: false,
            target: *target,
            uniform,
            bound: None,
            wireframe: false,
            materials: MaterialSlot::default(),
            user_surface: None,
        })
    }

    /// Shades [`crate::SurfaceShading::Materials`] frames with `materials` from the next
    /// prepare (until then, and without a call, with [`GpuMaterials::procedural`]).
    pub fn set_materials(&mut self, materials: &GpuMaterials) {
        self.materials.set(materials);
    }

    /// Draws `color` as the surface's albedo from the next prepare (`None`: no colour layer).
    /// Its size must be the drawn surface's, else the prepare fails.
    pub fn set_color_layer(&mut self, color: Option<&GpuColorLayer>) {
        self.materials.set_color(color);
    }

    /// Blends `layer`'s painted weights over the surface's, as
    /// [`crate::ClipmapRenderer::set_material_layer`].
    pub fn set_material_layer(&mut self, layer: Option<&crate::GpuMaterialLayer>) {
        self.materials.set_paint(layer);
    }

    /// Leaves out the cells `mask` marks as holes, as [`crate::ClipmapRenderer::set_hole_mask`].
    pub fn set_hole_mask(&mut self, mask: Option<&crate::GpuHoleMask>) {
        self.materials.set_holes(mask);
    }

    /// Draws a streamed world's paint and colour, as
    /// [`crate::ClipmapRenderer::set_streamed_layers`].
    pub fn set_streamed_layers(
        &mut self,
        paint: Option<&crate::GpuOverlayAtlas>,
        color: Option<&crate::GpuOverlayAtlas>,
    ) {
        self.materials.set_streamed(paint, color);
    }

    /// Computes the material weights with an engine's `surface_weights` function, or the
    /// autoshader for `None` (as [`crate::ClipmapRenderer::set_surface_shader`]).
    pub fn set_surface_shader(
        &mut self,
        device: &wgpu::Device,
        wgsl_function: Option<&str>,
    ) -> Result<(), GpuError> {
        self.pipeline = tess_pipeline(device, &self.target, false, wgsl_function)
            .map_err(GpuError::user_shader)?;
        self.detail = None;
        self.on_detail = false;
        self.user_surface = wgsl_function.map(str::to_owned);
        self.bound = None;
        Ok(())
    }

    /// Draws triangle edges as lines from the next draw; fails without
    /// [`wgpu::Features::POLYGON_MODE_LINE`].
    pub fn set_wireframe(&mut self, on: bool) -> Result<(), GpuError> {
        check_wireframe(&self.pipeline, on, "TessRenderer wireframe")?;
        if let Some(detail) = &self.detail {
            check_wireframe(detail, on, "TessRenderer wireframe")?;
        }
        self.wireframe = on;
        Ok(())
    }

    /// Writes the frame uniform. Checks everything before wgpu sees it.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        draw: &TessDraw<'_>,
    ) -> Result<(), GpuError> {
        let view = check_view(
            draw.camera,
            Some(&self.target),
            draw.target_size,
            "tessellated target size (pixels)",
        )?;
        let surface = draw.surface;
        let on_detail = match surface {
            ClipmapSurface::Coarse { .. } => false,
            ClipmapSurface::Detail { .. } => true,
            _ => {
                return Err(GpuError::Unsupported {
                    what: "TessRenderer",
                    reason: "the surface must be the coarse-map the tessellation was made of, \
                             with or without a detail layer",
                });
            }
        };
        let info = surface.check()?;
        if on_detail && self.detail.is_none() {
            self.detail = Some(tess_pipeline(
                device,
                &self.target,
                true,
                self.user_surface.as_deref(),
            )?);
        }
        let wrap_offset = match info.wrap {
            // Vertices lie in 0 ..= the map size; fragments read a texel either side, and a
            // detail surface's parallax reach beyond.
            WrapMode::Repeat => {
                let reach = 2 + fragment_reach(&surface);
                crate::device::compute::wrap_offset(glam::IVec2::splat(-reach), info.size)?
            }
            WrapMode::Clamp => [0, 0],
        };
        let mut uniform =
            frame_uniform(&info, &view, draw.style, &self.target, (0, 0), wrap_offset)?;
        let (shading, new_shading) = self.materials.get(device, queue, info.size)?;
        uniform.set_layers(&shading);
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&uniform));
        let camera_texel = glam::IVec2::from(uniform.camera_texel);
        let buffers =
            self.detail_uniform
                .surface_buffers(queue, &surface, info.texel_size, camera_texel)?;
        if new_shading
            || self.on_detail != on_detail
            || self.bound.as_ref().is_none_or(|(b, _)| *b != buffers)
        {
            let group = self.pipeline_for(on_detail).bind_group(
                device,
                "TessRenderer",
                &self.uniform,
                &buffers,
                &[],
                &shading,
            )?;
            self.bound = Some((buffers, group));
            self.on_detail = on_detail;
        }
        Ok(())
    }

    fn pipeline_for(&self, detail: bool) -> &SurfacePipeline {
        match (&self.detail, detail) {
            (Some(d), true) => d,
            _ => &self.pipeline,
        }
    }

    /// Records the draw of `gpu`'s triangles (as many as the last tessellation wrote) into
    /// `pass`. Draws nothing before the first prepare.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, gpu: &GpuTessellation) {
        let Some((_, group)) = &self.bound else {
            return;
        };
        pass.set_pipeline(self.pipeline_for(self.on_detail).pick(self.wireframe));
        pass.set_bind_group(0, group, &[]);
        pass.set_vertex_buffer(0, gpu.output.slice(..));
        pass.draw_indirect(&gpu.state, ARGS_OFFSET);
    }
}

/// The tessellated pipeline over a coarse-map, or over a coarse-map with a detail layer.
fn tess_pipeline(
    device: &wgpu::Device,
    target: &TargetFormat,
    detail: bool,
    user: Option<&str>,
) -> Result<SurfacePipeline, GpuError> {
    const ATTRS: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];
    let fragment = wgpu::ShaderStages::FRAGMENT;
    let (label, source, storage, uniforms) = if detail {
        (
            "tessellated detail",
            terrain_shaders::TESSELLATED_DETAIL,
            vec![(fragment, 1), (fragment, 2), (fragment, 4), (fragment, 5)],
            vec![(fragment, 3)],
        )
    } else {
        (
            "tessellated.wgsl",
            terrain_shaders::TESSELLATED,
            vec![(fragment, 1), (fragment, 2)],
            vec![],
        )
    };
    SurfacePipeline::new(
        device,
        target,
        label,
        &with_surface_weights(source, user),
        &storage,
        &uniforms,
        &VertexShape {
            entry: "vs_tess",
            vertex_stride: std::mem::size_of::<TessVertex>() as u64,
            vertex_attrs: &ATTRS,
            instance_stride: 0,
            instance_attrs: &[],
            extra_uniforms: &[],
        },
    )
}

/// `rows` clipped to `0..grid_rows`, sorted and merged where they overlap or touch.
fn merge_rows(rows: &[std::ops::Range<u32>], grid_rows: u32) -> Vec<std::ops::Range<u32>> {
    let mut sorted: Vec<_> = rows
        .iter()
        .map(|r| r.start.min(grid_rows)..r.end.min(grid_rows))
        .filter(|r| !r.is_empty())
        .collect();
    sorted.sort_by_key(|r| r.start);
    let mut merged: Vec<std::ops::Range<u32>> = Vec::with_capacity(sorted.len());
    for r in sorted {
        match merged.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => merged.push(r),
        }
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::merge_rows;

    #[test]
    fn overlapping_and_touching_rows_merge_and_rows_past_the_grid_are_dropped() {
        let rows = [5..9, 0..2, 8..12, 2..3, 40..50, 20..20, 14..15];
        assert_eq!(merge_rows(&rows, 45), vec![0..3, 5..12, 14..15, 40..45]);
        assert_eq!(
            merge_rows(&[50..60, 45..70], 45),
            Vec::<std::ops::Range<u32>>::new()
        );
    }
}
