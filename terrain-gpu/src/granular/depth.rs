//! `DepthFromBelowPass` (Persson 2019, sec. 4.1.2): the lowest object surface above each column
//! of an active area, in fixed-point height units, as seen by an orthographic camera looking up
//! from below the terrain; the GPU side of [`terrain_core::granular::depth_from_below_into`].
//!
//! A compute pass runs the CPU reference's integer program (see
//! [`terrain_core::granular::DepthTriangle`]): the CPU snaps every triangle once
//! ([`terrain_core::granular::depth_triangles`]) and uploads it as integer records, one per
//! triangle and 16 x 16 tile of the samples it may cover; one workgroup per record tests the
//! tile's samples with exact edge functions (64-bit values as two `u32`), interpolates the
//! height exactly and keeps the lowest with `atomicMin` into a `u32` per column. The result is
//! bit-identical to the CPU reference on any conforming GPU (no rasterizer, no float).
//!
//! # Resources
//!
//! The pipeline, its bind group layout and a uniform ring (one slot per dispatch of at most
//! [`MAX_RECORDS_PER_DISPATCH`] records) are made in [`DepthFromBelowPass::new`]. The buffer of
//! [`NO_OBJECT`](terrain_core::granular::NO_OBJECT)s the output is cleared from and the record buffer persist in the pass and are
//! replaced only by larger ones when an area or an object list needs more; records are written
//! with `queue.write_buffer` at the next free offset of the record buffer, so several areas can
//! be recorded into one encoder. Call [`DepthFromBelowPass::recall`] after the submit that
//! carries them.

use bytemuck::{Pod, Zeroable};
use terrain_core::granular::{DepthTriangle, GranularObject, depth_triangles};
use terrain_core::{CoreError, Grid, HeightEncoding, HeightSample, Rect};

use super::upload::UploadRing;
use crate::device::compute::{PassBindings, StorageBinding, compute_pipeline, shader_module};
use crate::device::download::download_bytes;
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::resources::maps::{GpuHeightMap, map_buffer};

/// Kept for callers of the render-pipeline pass, whose areas were drawn in tiles of this side:
/// the compute pass covers any area in one go (its records are tiled instead, by
/// [`RECORD_TILE`]).
pub const MAX_TILE_SIDE: u32 = 4096;

/// Side of the sample tile one record (one workgroup) covers.
pub const RECORD_TILE: u32 = 16;

/// Most records one dispatch takes (one workgroup each, on the x axis; further limited by the
/// device's `max_compute_workgroups_per_dimension`).
pub const MAX_RECORDS_PER_DISPATCH: u32 = 65_535;

/// One record: a triangle of the integer program over one tile of its samples (the WGSL
/// layout is listed in `granular_depth.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct DepthRecord {
    verts: [i32; 6],
    origin: [i32; 2],
    rel: [u32; 3],
    frac_bits: u32,
    base: [u32; 2],
    area2: [u32; 2],
    tile_min: [u32; 2],
    tile_max: [u32; 2],
}

/// The WGSL `Params` uniform.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(super) struct DepthParams {
    first: u32,
    count: u32,
    area_width: u32,
    _pad: u32,
}

// The WGSL layouts: a mismatch fails the build, not a dispatch.
const _: () = assert!(std::mem::size_of::<DepthParams>() == 16);
const _: () = assert!(std::mem::size_of::<DepthRecord>() == 80);

/// What a depth-from-below render looks at: a non-empty area (in map columns) and the map's
/// height encoding and texel size (positive and finite), checked when made. The arguments of
/// [`terrain_core::granular::depth_from_below_into`] besides the objects and the output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthArea {
    encoding: HeightEncoding,
    texel_size: f32,
    rect: Rect,
}

impl DepthArea {
    /// Checks the encoding, the texel size and the area.
    pub fn new(encoding: HeightEncoding, texel_size: f32, rect: Rect) -> Result<Self, GpuError> {
        check_params(encoding, texel_size)?;
        if rect.is_empty() {
            return Err(CoreError::EmptyGrid {
                width: rect.size.x,
                height: rect.size.y,
            }
            .into());
        }
        Ok(Self {
            encoding,
            texel_size,
            rect,
        })
    }

    /// `rect` of `map`, in its encoding and texel size.
    pub fn for_map<T: HeightSample>(map: &GpuHeightMap<T>, rect: Rect) -> Result<Self, GpuError> {
        Self::new(map.encoding(), map.texel_size(), rect)
    }

    /// The height encoding the depths are written in.
    pub fn encoding(&self) -> HeightEncoding {
        self.encoding
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// The area in map columns.
    pub fn rect(&self) -> Rect {
        self.rect
    }
}

/// Rasterizes [`GranularObject`]s from below over an active area into a `u32` per column
/// (Persson 2019, sec. 4.1.2); see the module docs for the method and its resources.
#[derive(Debug)]
pub struct DepthFromBelowPass {
    pipeline: wgpu::ComputePipeline,
    pub(super) bindings: PassBindings<DepthParams>,
    max_groups: u32,
    clear: Option<wgpu::Buffer>,
    uploads: UploadRing,
    triangles: Vec<DepthTriangle>,
    records: Vec<DepthRecord>,
}

/// A size that grows by half again at least, so an input that grows a little every frame
/// does not reallocate every frame.
fn grown(old: u64, need: u64) -> u64 {
    need.max(old + old / 2)
}

impl DepthFromBelowPass {
    /// Whether `adapter` can run this pass: a compute pass with storage buffers, which every
    /// adapter this crate runs on has (kept from the render-pipeline pass, which needed
    /// fragment-stage storage writes).
    pub fn is_supported(adapter: &wgpu::Adapter) -> bool {
        adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
    }

    /// Builds the pipeline, its bindings and uniform ring. Fails with
    /// [`GpuError::Unsupported`] on devices without storage buffers, or
    /// [`GpuError::Validation`] if the shader is rejected.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        if device.limits().max_storage_buffers_per_shader_stage < 2 {
            return Err(GpuError::Unsupported {
                what: "DepthFromBelowPass",
                reason: "the device has fewer than two storage buffers in the compute stage",
            });
        }
        let bindings = PassBindings::new(
            device,
            "DepthFromBelowPass",
            wgpu::ShaderStages::COMPUTE,
            &[
                StorageBinding::compute(true),
                StorageBinding::compute(false),
            ],
        );
        let module = shader_module(
            device,
            "granular_depth.wgsl",
            terrain_shaders::GRANULAR_DEPTH,
        )?;
        let pipeline = compute_pipeline(
            device,
            "DepthFromBelowPass",
            &module,
            bindings.layout(),
            "main",
        )?;
        Ok(Self {
            pipeline,
            bindings,
            max_groups: device
                .limits()
                .max_compute_workgroups_per_dimension
                .clamp(1, MAX_RECORDS_PER_DISPATCH),
            clear: None,
            uploads: UploadRing::new("DepthFromBelowPass records", wgpu::BufferUsages::STORAGE),
            triangles: Vec::new(),
            records: Vec::new(),
        })
    }

    /// Frees the uniform slots and record uploads recorded so far: call it after the submit
    /// that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
        self.uploads.recall();
    }

    /// A buffer for the depth of `area`: one `u32` per column, row-major, with the usages
    /// [`Self::encode`] and [`Self::read`] need (`STORAGE | COPY_DST | COPY_SRC`). A granular
    /// step renders into its scratch's [`super::GranularScratch::depth`] instead.
    pub fn create_output(device: &wgpu::Device, area: Rect) -> Result<wgpu::Buffer, GpuError> {
        let bytes = output_bytes(device, area)?;
        map_buffer(device, "DepthFromBelowPass output", area.size, bytes)
    }

    /// Makes the buffer of [`NO_OBJECT`](terrain_core::granular::NO_OBJECT)s the output is cleared from hold at least `bytes`.
    fn ensure_clear(&mut self, device: &wgpu::Device, bytes: u64) -> Result<(), GpuError> {
        let old = self.clear.as_ref().map_or(0, wgpu::Buffer::size);
        if old >= bytes {
            return Ok(());
        }
        // Whole u32s (so whole COPY_BUFFER_ALIGNMENT units, as mapping at creation needs).
        let size = (grown(old, bytes).min(device.limits().max_buffer_size.max(bytes)) / 4) * 4;
        let buffer = scoped(device, "DepthFromBelowPass clear", || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("DepthFromBelowPass clear"),
                size,
                usage: wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: true,
            })
        })?;
        // NO_OBJECT is all ones.
        buffer
            .slice(..)
            .get_mapped_range_mut()?
            .slice(..)
            .fill(0xff);
        buffer.unmap();
        self.clear = Some(buffer);
        Ok(())
    }

    /// Records the depth from below of `objects` over `area` into `out` (at least
    /// `4 * area.size.x * area.size.y` bytes, usages `STORAGE | COPY_DST`; see
    /// [`Self::create_output`]): element `j * area.size.x + i` is column `area.min + (i, j)`,
    /// in units of the area's encoding, or [`NO_OBJECT`](terrain_core::granular::NO_OBJECT) where no object covers it, exactly as
    /// [`terrain_core::granular::depth_from_below_into`] computes it. The whole area is
    /// overwritten.
    ///
    /// The objects' triangles are snapped on the CPU and written into the pass's record buffer
    /// on every call (triangles with zero area after snapping, or wholly outside the area, are
    /// dropped). Whether the area lies inside the map is the caller's concern, as with the CPU
    /// reference's `_into` form: any non-empty area is computed.
    ///
    /// Fails on an output buffer that is too small, an object that fails
    /// [`GranularObject::validate`] (non-finite transform, vertices beyond
    /// `MAX_COORDINATE_M`; reported as [`GpuError::Granular`]), a triangle the integer program
    /// refuses (see [`terrain_core::granular::depth_triangle`]), more records than the
    /// device's largest buffer holds, or a wgpu validation error.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        objects: &[GranularObject<'_>],
        area: &DepthArea,
        out: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let rect = area.rect;
        let bytes = output_bytes(device, rect)?;
        if out.size() < bytes {
            return Err(CoreError::OutOfRange {
                what: "DepthFromBelowPass output buffer size in bytes",
                value: out.size() as f64,
                expected: "at least 4 bytes per column of the area",
            }
            .into());
        }
        depth_triangles(
            objects,
            area.encoding,
            area.texel_size,
            rect,
            &mut self.triangles,
        )?;
        tile_records(&self.triangles, rect, &mut self.records);
        let record_bytes = std::mem::size_of_val(self.records.as_slice()) as u64;
        let limit = device
            .limits()
            .max_storage_buffer_binding_size
            .min(device.limits().max_buffer_size);
        if record_bytes > limit {
            return Err(CoreError::OutOfRange {
                what: "DepthFromBelowPass record bytes (80 per triangle and 16 x 16 tile)",
                value: record_bytes as f64,
                expected: "within the device's storage buffer binding size",
            }
            .into());
        }
        self.ensure_clear(device, bytes)?;
        if let Some(clear) = &self.clear {
            encoder.copy_buffer_to_buffer(clear, 0, out, 0, bytes);
        }
        if self.records.is_empty() {
            return Ok(());
        }
        let (buffer, offset) =
            self.uploads
                .push(device, queue, bytemuck::cast_slice(&self.records))?;
        let words = (std::mem::size_of::<DepthRecord>() / 4) as u32;
        let total = self.records.len() as u32;
        let mut groups = Vec::new();
        for start in (0..total).step_by(self.max_groups as usize) {
            let count = (total - start).min(self.max_groups);
            let params = DepthParams {
                first: (offset / 4) as u32 + start * words,
                count,
                area_width: rect.size.x,
                _pad: 0,
            };
            let (group, slot) = self
                .bindings
                .bind(device, queue, &params, &[&buffer, out])?;
            groups.push((group, slot, count));
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("DepthFromBelowPass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        for (group, slot, count) in &groups {
            pass.set_bind_group(0, group, &[*slot]);
            pass.dispatch_workgroups(*count, 1, 1);
        }
        Ok(())
    }

    /// Reads a depth buffer written by [`Self::encode`] for `area` into a grid of `area.size`
    /// (sample `(i, j)` is column `area.min + (i, j)`), waiting for the GPU. `out` needs
    /// `COPY_SRC`; submit the encoder first.
    pub fn read(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        out: &wgpu::Buffer,
        area: Rect,
    ) -> Result<Grid<u32>, GpuError> {
        let bytes = output_bytes(device, area)?;
        let data = download_bytes(device, queue, out, 0, bytes)?;
        let values: Vec<u32> = bytemuck::pod_collect_to_vec(&data);
        Ok(Grid::from_vec(area.size.x, area.size.y, values)?)
    }

    /// Convenience: allocates an output, encodes, submits, recalls and reads back; the GPU
    /// counterpart of [`terrain_core::granular::depth_from_below_into`] for tests and CPU-side
    /// users.
    pub fn run(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        objects: &[GranularObject<'_>],
        area: &DepthArea,
    ) -> Result<Grid<u32>, GpuError> {
        let out = Self::create_output(device, area.rect)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        let recorded = self.encode(device, queue, &mut encoder, objects, area, &out);
        if recorded.is_ok() {
            queue.submit([encoder.finish()]);
            crate::device::trace::record("granular depth: submitted", 0);
        }
        self.recall();
        recorded?;
        Self::read(device, queue, &out, area.rect)
    }
}

/// Bytes of the output of `area`, checked against emptiness and the storage binding limit.
fn output_bytes(device: &wgpu::Device, area: Rect) -> Result<u64, GpuError> {
    if area.size.x == 0 || area.size.y == 0 {
        return Err(CoreError::EmptyGrid {
            width: area.size.x,
            height: area.size.y,
        }
        .into());
    }
    let bytes = 4 * u64::from(area.size.x) * u64::from(area.size.y);
    let limit = device
        .limits()
        .max_storage_buffer_binding_size
        .min(device.limits().max_buffer_size);
    if bytes > limit {
        return Err(GpuError::MapTooLarge {
            size: area.size,
            bytes,
            limit,
        });
    }
    Ok(bytes)
}

fn check_params(encoding: HeightEncoding, texel_size: f32) -> Result<(), GpuError> {
    let checks = [
        ("texel_size", texel_size, texel_size > 0.0),
        (
            "height encoding scale",
            encoding.scale,
            encoding.scale > 0.0,
        ),
        ("height encoding offset", encoding.offset, true),
    ];
    for (what, value, positive) in checks {
        if !value.is_finite() {
            return Err(CoreError::NonFinite { what, value }.into());
        }
        if !positive {
            return Err(CoreError::OutOfRange {
                what,
                value: f64::from(value),
                expected: "> 0",
            }
            .into());
        }
    }
    Ok(())
}

/// Splits every triangle's samples (already clipped to `area`) into [`RECORD_TILE`]-sided
/// tiles, one record each, in area-relative coordinates.
fn tile_records(triangles: &[DepthTriangle], area: Rect, out: &mut Vec<DepthRecord>) {
    out.clear();
    let min = [i64::from(area.min.x), i64::from(area.min.y)];
    let side = RECORD_TILE as usize;
    for t in triangles {
        // `depth_triangle` clipped the samples to the area and bounded the triangle's span, so
        // these fit: samples in 0 .. area size, the origin within 2^15 texels of them.
        let s0 = [t.samples_min[0] - min[0], t.samples_min[1] - min[1]].map(|v| v as u32);
        let s1 = [t.samples_max[0] - min[0], t.samples_max[1] - min[1]].map(|v| v as u32);
        let mut record = DepthRecord {
            verts: [
                t.verts[0][0],
                t.verts[0][1],
                t.verts[1][0],
                t.verts[1][1],
                t.verts[2][0],
                t.verts[2][1],
            ],
            origin: [(t.origin[0] - min[0]) as i32, (t.origin[1] - min[1]) as i32],
            rel: t.rel,
            frac_bits: t.frac_bits,
            base: [t.base as u32, (t.base >> 32) as u32],
            area2: [t.area2 as u32, (t.area2 >> 32) as u32],
            tile_min: [0; 2],
            tile_max: [0; 2],
        };
        for y in (s0[1]..s1[1]).step_by(side) {
            for x in (s0[0]..s1[0]).step_by(side) {
                record.tile_min = [x, y];
                record.tile_max = [(x + RECORD_TILE).min(s1[0]), (y + RECORD_TILE).min(s1[1])];
                out.push(record);
            }
        }
    }
}
