//! The integer passes of a granular step over one active area: `PenetrationPass`,
//! `JumpFloodPass`, `DisplacePass` and `SlopePass`, bit for bit as their CPU references in
//! `terrain_core::granular`.

use super::map::GpuGranularMap;
use super::scratch::{GranularScratch, GranularUniform, area_dispatch};
use crate::compute::compute_pipeline_entry;
use crate::compute::{bind_buffers, buffer_entry};
use crate::error::GpuError;
use terrain_core::granular::{DisplacementMethod, DistanceMetric, SlopeMethod, jfa_steps};
use terrain_core::{Grid, Rect};
use wgpu::util::DeviceExt;

/// Records one compute pass that runs `dispatches` (pipeline, bind group) over `groups`.
fn run(
    encoder: &mut wgpu::CommandEncoder,
    label: &'static str,
    groups: (u32, u32),
    dispatches: &[(&wgpu::ComputePipeline, &wgpu::BindGroup)],
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    for (pipeline, bind_group) in dispatches {
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, *bind_group, &[]);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
    }
}

fn layout(
    device: &wgpu::Device,
    label: &'static str,
    storage_read_only: &[bool],
) -> wgpu::BindGroupLayout {
    let mut entries = vec![buffer_entry(0, wgpu::BufferBindingType::Uniform)];
    for (i, &read_only) in storage_read_only.iter().enumerate() {
        entries.push(buffer_entry(
            i as u32 + 1,
            wgpu::BufferBindingType::Storage { read_only },
        ));
    }
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &entries,
    })
}

/// Computes the penetration texture of an area (seed 001 table 4.1) from the map and the
/// area's depth from below, as [`terrain_core::granular::penetration_texture`].
#[derive(Debug)]
pub struct PenetrationPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl PenetrationPass {
    /// Builds the pipeline.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let layout = layout(device, "PenetrationPass", &[true, true, false]);
        let pipeline = compute_pipeline_entry(
            device,
            "PenetrationPass",
            terrain_shaders::GRANULAR_PENETRATION,
            &layout,
            "main",
        )?;
        Ok(Self { pipeline, layout })
    }

    /// A storage buffer holding a depth grid (one u32 per column of the area, row-major, as
    /// [`terrain_core::granular::depth_from_below`] returns it).
    pub fn upload_depth(device: &wgpu::Device, depth: &Grid<u32>) -> wgpu::Buffer {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("granular depth"),
            contents: bytemuck::cast_slice(depth.as_slice()),
            usage: wgpu::BufferUsages::STORAGE,
        })
    }

    /// Records the penetration texture of `area` into `scratch`, from `depth` (a buffer of at
    /// least `area.area()` u32, area-local) and `obstacle_margin` in height units.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuGranularMap,
        depth: &wgpu::Buffer,
        area: Rect,
        obstacle_margin: u32,
        scratch: &GranularScratch,
    ) -> Result<(), GpuError> {
        let groups = area_dispatch(device, area, map.size())?;
        scratch.check(area)?;
        if depth.size() < area.area() * 4 {
            return Err(GpuError::Unsupported {
                what: "PenetrationPass",
                reason: "the depth buffer is smaller than the area",
            });
        }
        let uniform = GranularUniform {
            margin: obstacle_margin,
            ..GranularUniform::for_area(area, map.size().x)
        }
        .buffer(device);
        let bg = bind_buffers(
            device,
            "PenetrationPass",
            &self.layout,
            &[&uniform, map.buffer(), depth, &scratch.pen],
        );
        run(encoder, "PenetrationPass", groups, &[(&self.pipeline, &bg)]);
        Ok(())
    }
}

/// Jump flooding of the closest seed over an area (seed 001 sec 2.3.1) with the hashed
/// neighbour order, as [`terrain_core::granular::jump_flood`].
#[derive(Debug)]
pub struct JumpFloodPass {
    init: wgpu::ComputePipeline,
    pass: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// The value of a metric in the shaders' `metric` field.
fn metric_index(metric: DistanceMetric) -> u32 {
    match metric {
        DistanceMetric::Euclidean => 0,
        DistanceMetric::Manhattan => 1,
        DistanceMetric::Chebyshev => 2,
    }
}

impl JumpFloodPass {
    /// Builds the pipelines.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let layout = layout(device, "JumpFloodPass", &[true, true, false]);
        let src = terrain_shaders::GRANULAR_JFA;
        Ok(Self {
            init: compute_pipeline_entry(device, "JumpFloodPass init", src, &layout, "init")?,
            pass: compute_pipeline_entry(device, "JumpFloodPass", src, &layout, "main")?,
            layout,
        })
    }

    /// Records the seed initialisation from the penetration texture in `scratch` and every
    /// pass of [`jfa_steps`]`(area.size, extra_pass)`; returns the index of the seed grid of
    /// `scratch` ([`GranularScratch::seeds`]) that holds the closest seeds.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map_size: glam::UVec2,
        area: Rect,
        metric: DistanceMetric,
        extra_pass: bool,
        scratch: &GranularScratch,
    ) -> Result<usize, GpuError> {
        let groups = area_dispatch(device, area, map_size)?;
        scratch.check(area)?;
        let base = GranularUniform {
            metric: metric_index(metric),
            ..GranularUniform::for_area(area, map_size.x)
        };
        let [a, b] = &scratch.seeds;
        let init_u = base.buffer(device);
        let mut groups_list = vec![(
            &self.init,
            bind_buffers(
                device,
                "JumpFloodPass",
                &self.layout,
                &[&init_u, &scratch.pen, b, a],
            ),
        )];
        let steps = jfa_steps(area.size, extra_pass);
        for (p, &step) in steps.iter().enumerate() {
            let u = GranularUniform {
                step,
                pass_index: p as u32,
                ..base
            }
            .buffer(device);
            let (src, dst) = if p % 2 == 0 { (a, b) } else { (b, a) };
            groups_list.push((
                &self.pass,
                bind_buffers(
                    device,
                    "JumpFloodPass",
                    &self.layout,
                    &[&u, &scratch.pen, src, dst],
                ),
            ));
        }
        let dispatches: Vec<_> = groups_list.iter().map(|(p, g)| (*p, g)).collect();
        run(encoder, "JumpFloodPass", groups, &dispatches);
        Ok(steps.len() % 2)
    }
}

/// Displacement of intersected material to the contour (seed 001 sec 4.1.4):
/// [`DisplacementMethod::ClosestSeed`] as [`terrain_core::granular::displace_closest_seed`] and
/// [`DisplacementMethod::MultipleTargets`] as
/// [`terrain_core::granular::displace_multiple_targets`] by atomic scatter
/// ([`DisplacePass::encode`]), and [`DisplacementMethod::Iterative`] as
/// [`terrain_core::granular::displace_iterative`] by gather passes and a final atomic flush to
/// the seeds ([`DisplacePass::encode_iterative`], which also takes the iteration count and the
/// metric).
#[derive(Debug)]
pub struct DisplacePass {
    closest: wgpu::ComputePipeline,
    multiple: wgpu::ComputePipeline,
    iter_init: wgpu::ComputePipeline,
    iter_pass: wgpu::ComputePipeline,
    iter_flush: wgpu::ComputePipeline,
    writeback: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl DisplacePass {
    /// Builds the pipelines.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let layout = layout(
            device,
            "DisplacePass",
            &[false, true, true, false, false, false, false],
        );
        let src = terrain_shaders::GRANULAR_DISPLACE;
        let pipe = |label, entry| compute_pipeline_entry(device, label, src, &layout, entry);
        Ok(Self {
            closest: pipe("DisplacePass closest", "closest")?,
            multiple: pipe("DisplacePass multiple", "multiple")?,
            iter_init: pipe("DisplacePass iterative init", "iter_init")?,
            iter_pass: pipe("DisplacePass iterative pass", "iter_pass")?,
            iter_flush: pipe("DisplacePass iterative flush", "iter_flush")?,
            writeback: pipe("DisplacePass writeback", "writeback")?,
            layout,
        })
    }

    fn bind(
        &self,
        device: &wgpu::Device,
        map: &GpuGranularMap,
        uniform: &GranularUniform,
        seeds: usize,
        scratch: &GranularScratch,
    ) -> wgpu::BindGroup {
        bind_buffers(
            device,
            "DisplacePass",
            &self.layout,
            &[
                &uniform.buffer(device),
                map.buffer(),
                &scratch.pen,
                &scratch.seeds[seeds & 1],
                &scratch.acc,
                &scratch.removed,
                &scratch.dist,
                &scratch.carried,
            ],
        )
    }

    /// Records the displacement over `area` from the penetration texture and seed grid
    /// `seeds` of `scratch` (keep factor `keep_q15`, see
    /// [`terrain_core::granular::GranularParams::keep_q15`]); the removed material is added to
    /// the scratch's removed counter ([`GranularScratch::read_removed`]).
    /// [`DisplacementMethod::Iterative`] needs more settings: it is refused here
    /// ([`GpuError::Unsupported`]); use [`DisplacePass::encode_iterative`].
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuGranularMap,
        area: Rect,
        method: DisplacementMethod,
        keep_q15: u32,
        seeds: usize,
        scratch: &GranularScratch,
    ) -> Result<(), GpuError> {
        let groups = area_dispatch(device, area, map.size())?;
        scratch.check(area)?;
        let scatter = match method {
            DisplacementMethod::ClosestSeed => &self.closest,
            DisplacementMethod::MultipleTargets => &self.multiple,
            DisplacementMethod::Iterative => {
                return Err(GpuError::Unsupported {
                    what: "DisplacePass",
                    reason: "the iterative method needs its iteration count and metric: use \
                             DisplacePass::encode_iterative",
                });
            }
        };
        let u = GranularUniform {
            keep_q15,
            ..GranularUniform::for_area(area, map.size().x)
        };
        let bg = self.bind(device, map, &u, seeds, scratch);
        encoder.clear_buffer(&scratch.acc, 0, Some(area.area() * 4));
        run(
            encoder,
            "DisplacePass",
            groups,
            &[(scatter, &bg), (&self.writeback, &bg)],
        );
        Ok(())
    }

    /// Records the iterative method (listing 4.2) over `area`, bit for bit as
    /// [`terrain_core::granular::displace_iterative`]`(.., keep_q15, iterations, metric)`:
    /// distances to the seeds of grid `seeds` of `scratch` under `metric` (the metric the
    /// seeds were flooded with) and lower-neighbour counts, the displaced material of every
    /// penetrating column, `iterations` gather passes (integer shares, remainders stay), and a
    /// final atomic flush of the carried material to the seeds. The removed material is added
    /// to the scratch's removed counter.
    #[allow(clippy::too_many_arguments)]
    pub fn encode_iterative(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuGranularMap,
        area: Rect,
        keep_q15: u32,
        iterations: u32,
        metric: DistanceMetric,
        seeds: usize,
        scratch: &GranularScratch,
    ) -> Result<(), GpuError> {
        let groups = area_dispatch(device, area, map.size())?;
        scratch.check(area)?;
        let base = GranularUniform {
            keep_q15,
            metric: metric_index(metric),
            ..GranularUniform::for_area(area, map.size().x)
        };
        let bgs = [0, 1].map(|parity| {
            self.bind(
                device,
                map,
                &GranularUniform { parity, ..base },
                seeds,
                scratch,
            )
        });
        let mut dispatches = vec![(&self.iter_init, &bgs[0])];
        for k in 0..iterations {
            dispatches.push((&self.iter_pass, &bgs[(k & 1) as usize]));
        }
        let last = &bgs[(iterations & 1) as usize];
        dispatches.push((&self.iter_flush, last));
        dispatches.push((&self.writeback, last));
        encoder.clear_buffer(&scratch.acc, 0, Some(area.area() * 4));
        run(encoder, "DisplacePass iterative", groups, &dispatches);
        Ok(())
    }
}

/// Evening out steep slopes (seed 001 sec 4.1.5): [`SlopeMethod::Scatter`] as
/// [`terrain_core::granular::even_out_slopes_scatter`] (one atomic scatter per iteration) and
/// [`SlopeMethod::Interleaved`] as [`terrain_core::granular::even_out_slopes_interleaved`]
/// (amounts then gather per parity).
#[derive(Debug)]
pub struct SlopePass {
    scatter: wgpu::ComputePipeline,
    amounts: wgpu::ComputePipeline,
    apply: wgpu::ComputePipeline,
    writeback: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl SlopePass {
    /// Builds the pipelines.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let layout = layout(device, "SlopePass", &[false, true, false, false]);
        let src = terrain_shaders::GRANULAR_SLOPE;
        Ok(Self {
            scatter: compute_pipeline_entry(device, "SlopePass scatter", src, &layout, "scatter")?,
            amounts: compute_pipeline_entry(
                device,
                "SlopePass amounts",
                src,
                &layout,
                "amounts_pass",
            )?,
            apply: compute_pipeline_entry(device, "SlopePass apply", src, &layout, "apply")?,
            writeback: compute_pipeline_entry(
                device,
                "SlopePass writeback",
                src,
                &layout,
                "writeback",
            )?,
            layout,
        })
    }

    /// Records `iterations` iterations of `method` over `area`, with receivers limited to the
    /// seed columns of the penetration texture in `scratch`; `thresholds` are
    /// `(orthogonal, diagonal)` in height units
    /// ([`terrain_core::granular::GranularParams::slope_thresholds_units`]).
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuGranularMap,
        area: Rect,
        method: SlopeMethod,
        thresholds: [u32; 2],
        roughness_q15: u32,
        iterations: u32,
        scratch: &GranularScratch,
    ) -> Result<(), GpuError> {
        let groups = area_dispatch(device, area, map.size())?;
        scratch.check(area)?;
        if iterations == 0 {
            return Ok(());
        }
        let base = GranularUniform {
            threshold_orth: thresholds[0],
            threshold_diag: thresholds[1],
            roughness_q15,
            ..GranularUniform::for_area(area, map.size().x)
        };
        let bind = |u: &wgpu::Buffer| {
            bind_buffers(
                device,
                "SlopePass",
                &self.layout,
                &[
                    u,
                    map.buffer(),
                    &scratch.pen,
                    &scratch.acc,
                    &scratch.amounts,
                ],
            )
        };
        encoder.clear_buffer(&scratch.acc, 0, Some(area.area() * 4));
        match method {
            SlopeMethod::Scatter => {
                let bg = bind(&base.buffer(device));
                let mut dispatches = Vec::new();
                for _ in 0..iterations {
                    dispatches.push((&self.scatter, &bg));
                    dispatches.push((&self.writeback, &bg));
                }
                run(encoder, "SlopePass scatter", groups, &dispatches);
            }
            SlopeMethod::Interleaved => {
                let bgs =
                    [0, 1].map(|parity| bind(&GranularUniform { parity, ..base }.buffer(device)));
                let mut dispatches = Vec::new();
                for _ in 0..iterations {
                    for bg in &bgs {
                        dispatches.push((&self.amounts, bg));
                        dispatches.push((&self.apply, bg));
                        dispatches.push((&self.writeback, bg));
                    }
                }
                run(encoder, "SlopePass interleaved", groups, &dispatches);
            }
        }
        Ok(())
    }
}
