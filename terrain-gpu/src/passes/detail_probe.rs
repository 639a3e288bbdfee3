//! `DetailProbe`: reads what the detail clipmap ([`crate::ClipmapSurface::Detail`]) shades with
//! at a list of points: the detail height, its eq. 3.3 gradient and the composite normal of
//! eq. 3.4 with a given coarse gradient, computed by the renderer's own WGSL functions. The CPU
//! reference is [`terrain_core::detail::DetailLayer::height_m`] and `gradient_m` with
//! [`terrain_core::composite_normal`].

use crate::device::compute::{buffer_entry, compute_pipeline, shader_module};
use crate::device::download::map_and_read;
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::resources::detail::{DETAIL_INFO_BYTES, DetailShading, GpuDetailTiles};
use crate::resources::maps::map_buffer;
use bytemuck::{Pod, Zeroable};
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::CoreError;

/// What the detail surface reads at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetailProbeSample {
    /// Detail height in metres (bilinear).
    pub height: f32,
    /// Detail gradient in metres per metre (eq. 3.3 at the texels, bilinear).
    pub gradient: Vec2,
    /// The composite normal with the point's coarse gradient (eq. 3.4).
    pub normal: Vec3,
}

/// One point to probe: `q` coarse texels past a base coarse texel, and the coarse gradient to
/// compose the normal with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetailProbePoint {
    /// Offset from the base texel, in coarse texels (as the renderer's fragments are addressed
    /// from the camera's whole texel); each component within ±[`MAX_PROBE_OFFSET`].
    pub q: Vec2,
    /// The coarse gradient at the point.
    pub coarse_gradient: Vec2,
}

fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// The farthest a probe point may lie from its base texel, in coarse texels.
pub const MAX_PROBE_OFFSET: f32 = 4096.0;

#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ProbeInfo {
    count: u32,
    pad: [u32; 3],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ProbePoint {
    q: [f32; 2],
    coarse_gradient: [f32; 2],
}

/// Made once for at most `capacity` points per call; each [`DetailProbe::read`] writes the
/// points, dispatches, and waits for the result.
#[derive(Debug)]
pub struct DetailProbe {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    probe: wgpu::Buffer,
    info: wgpu::Buffer,
    points: wgpu::Buffer,
    out: wgpu::Buffer,
    staging: wgpu::Buffer,
    capacity: u32,
}

impl DetailProbe {
    /// Builds the pipeline and buffers for up to `capacity` points per read.
    pub fn new(device: &wgpu::Device, capacity: u32) -> Result<Self, GpuError> {
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        if capacity == 0 || capacity.div_ceil(64) > max_groups {
            return Err(CoreError::OutOfRange {
                what: "DetailProbe capacity (points)",
                value: f64::from(capacity),
                expected: "1 ..= 64 x the device's max_compute_workgroups_per_dimension",
            }
            .into());
        }
        let module = shader_module(device, "detail_probe.wgsl", terrain_shaders::DETAIL_PROBE)?;
        let uniform = wgpu::BufferBindingType::Uniform;
        let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
        let layout = scoped(device, "DetailProbe", || {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("DetailProbe"),
                entries: &[
                    buffer_entry(0, uniform),
                    buffer_entry(3, uniform),
                    buffer_entry(4, storage(true)),
                    buffer_entry(5, storage(true)),
                    buffer_entry(6, storage(true)),
                    buffer_entry(7, storage(false)),
                ],
            })
        })?;
        let pipeline = compute_pipeline(device, "DetailProbe", &module, &layout, "probe_main")?;
        let n = u64::from(capacity);
        let size = UVec2::new(capacity, 1);
        let points = map_buffer(device, "DetailProbe points", size, n * 16)?;
        let out = map_buffer(device, "DetailProbe out", size, n * 32)?;
        let buffer = |label, size, usage| {
            scoped(device, label, || {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            })
        };
        let uniform_usage = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
        Ok(Self {
            pipeline,
            layout,
            probe: buffer("DetailProbe info", 16, uniform_usage)?,
            info: buffer("DetailProbe detail", DETAIL_INFO_BYTES, uniform_usage)?,
            points,
            out,
            staging: buffer(
                "DetailProbe staging",
                n * 32,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            )?,
            capacity,
        })
    }

    /// What the detail surface of `tiles` reads at each of `points`, addressed from coarse
    /// texel `base` (any: the layer repeats). Submits the tiles' pending uploads with the
    /// dispatch and waits for the GPU.
    pub fn read(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tiles: &GpuDetailTiles,
        base: IVec2,
        points: &[DetailProbePoint],
    ) -> Result<Vec<DetailProbeSample>, GpuError> {
        if points.is_empty() {
            return Ok(Vec::new());
        }
        if points.len() > self.capacity as usize {
            return Err(CoreError::OutOfRange {
                what: "DetailProbe points per read",
                value: points.len() as f64,
                expected: "at most the probe's capacity",
            }
            .into());
        }
        let mut packed = Vec::with_capacity(points.len());
        for p in points {
            let reach = p.q.abs().max_element();
            if !(p.q.is_finite() && reach <= MAX_PROBE_OFFSET && p.coarse_gradient.is_finite()) {
                return Err(CoreError::OutOfRange {
                    what: "DetailProbe point (offset in coarse texels, coarse gradient)",
                    value: f64::from(reach),
                    expected: "finite, offsets within ±4096",
                }
                .into());
            }
            packed.push(ProbePoint {
                q: p.q.to_array(),
                coarse_gradient: p.coarse_gradient.to_array(),
            });
        }
        let info = tiles.info(base, &DetailShading::default(), MAX_PROBE_OFFSET as u32 + 1)?;
        let probe = ProbeInfo {
            count: points.len() as u32,
            pad: [0; 3],
        };
        queue.write_buffer(&self.probe, 0, bytemuck::bytes_of(&probe));
        queue.write_buffer(&self.info, 0, bytemuck::bytes_of(&info));
        queue.write_buffer(&self.points, 0, bytemuck::cast_slice(&packed));
        let group = scoped(device, "DetailProbe", || {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("DetailProbe"),
                layout: &self.layout,
                entries: &[
                    entry(0, &self.probe),
                    entry(3, &self.info),
                    entry(4, tiles.table_buffer()),
                    entry(5, tiles.heights_buffer()),
                    entry(6, &self.points),
                    entry(7, &self.out),
                ],
            })
        })?;
        let bytes = points.len() as u64 * 32;

        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("DetailProbe"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups((points.len() as u32).div_ceil(64), 1, 1);
        }
        encoder.copy_buffer_to_buffer(&self.out, 0, &self.staging, 0, bytes);
        queue.submit([encoder.finish()]);
        let all = map_and_read(device, &self.staging)?;
        let values: Vec<f32> = bytemuck::pod_collect_to_vec(&all[..bytes as usize]);
        Ok(values
            .chunks_exact(8)
            .map(|c| DetailProbeSample {
                height: c[0],
                gradient: Vec2::new(c[1], c[2]),
                normal: Vec3::new(c[4], c[5], c[6]),
            })
            .collect())
    }
}
