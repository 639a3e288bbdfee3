//! The integer passes of a granular step over one active area: `PenetrationPass`,
//! `JumpFloodPass`, `DisplacePass` and `SlopePass`, bit for bit as their CPU references in
//! `terrain_core::granular`.
//!
//! Each is built once (`new`: one shader module, its pipelines, a bind group layout and a
//! uniform ring) and records with `encode(&mut self, device, queue, encoder, ..)`, which only
//! writes the pass's uniforms into the next ring slots and records dispatches; bind groups are
//! made on first use of a set of buffers and kept. Call `recall()` on every pass after the
//! submit that carries what it recorded.

use super::scratch::{GranularArea, GranularUniform};
use super::upload::UploadRing;
use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, shader_module,
};
use crate::error::GpuError;
use terrain_core::Grid;
use terrain_core::granular::{
    DisplacementMethod, DistanceMetric, GranularError, GranularParams, MAX_ITERATIONS, SlopeMethod,
    jfa_steps,
};
use terrain_shaders::codes::{METRIC_CHEBYSHEV, METRIC_EUCLIDEAN, METRIC_MANHATTAN};

/// The bindings of a granular pass: the `Granular` uniform block, then `storage` in order
/// (`true`: read-only).
fn granular_bindings(
    device: &wgpu::Device,
    label: &'static str,
    storage_read_only: &[bool],
) -> PassBindings<GranularUniform> {
    let storage: Vec<StorageBinding> = storage_read_only
        .iter()
        .map(|&read_only| StorageBinding::compute(read_only))
        .collect();
    PassBindings::new(device, label, wgpu::ShaderStages::COMPUTE, &storage)
}

/// Computes the penetration texture of an area (Persson 2019, table 4.1) from the map and the
/// area's depth from below in the scratch, as [`terrain_core::granular::penetration_texture`].
#[derive(Debug)]
pub struct PenetrationPass {
    pipeline: wgpu::ComputePipeline,
    pub(super) bindings: PassBindings<GranularUniform>,
    depth_upload: UploadRing,
}

impl PenetrationPass {
    /// Builds the pipeline, its bindings and uniform ring.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = granular_bindings(device, "PenetrationPass", &[true, true, false]);
        let module = shader_module(
            device,
            "granular_penetration.wgsl",
            terrain_shaders::GRANULAR_PENETRATION,
        )?;
        let pipeline = compute_pipeline(
            device,
            "PenetrationPass",
            &module,
            bindings.layout(),
            "main",
        )?;
        Ok(Self {
            pipeline,
            bindings,
            depth_upload: UploadRing::new(
                "PenetrationPass depth upload",
                wgpu::BufferUsages::COPY_SRC,
            ),
        })
    }

    /// Frees the uniform slots and depth uploads recorded so far: call it after the submit that
    /// carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
        self.depth_upload.recall();
    }

    /// Records the upload of a depth grid computed on the CPU (one u32 per column of the area,
    /// row-major, as [`terrain_core::granular::depth_from_below_into`] writes it) into the
    /// area's [`super::GranularScratch::depth`]. The grid goes through the pass's upload buffer
    /// at its own offset, so several areas can be uploaded into one encoder.
    pub fn upload_depth(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        area: &GranularArea<'_>,
        depth: &Grid<u32>,
    ) -> Result<(), GpuError> {
        if depth.size() != area.rect().size {
            return Err(GpuError::SizeMismatch {
                expected: area.rect().size,
                actual: depth.size(),
            });
        }
        let data: &[u8] = bytemuck::cast_slice(depth.as_slice());
        let (buffer, offset) = self.depth_upload.push(device, queue, data)?;
        encoder.copy_buffer_to_buffer(&buffer, offset, &area.scratch().depth, 0, data.len() as u64);
        Ok(())
    }

    /// Records the penetration texture of `area` into its scratch, from the depth from below in
    /// [`super::GranularScratch::depth`] and `obstacle_margin` in height units (columns whose
    /// object is at most that far above the terrain are obstacles).
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        area: &GranularArea<'_>,
        obstacle_margin: u32,
    ) -> Result<(), GpuError> {
        let uniform = GranularUniform {
            margin: obstacle_margin,
            ..GranularUniform::for_area(area)
        };
        let scratch = area.scratch();
        let (group, offset) = self.bindings.bind(
            device,
            queue,
            &uniform,
            &[area.map().buffer(), &scratch.depth, &scratch.pen],
        )?;
        dispatch(
            encoder,
            "PenetrationPass",
            area.groups(),
            &[(&self.pipeline, &group, offset)],
        );
        Ok(())
    }
}

/// The value of a metric in the shaders' `metric` field.
fn metric_code(metric: DistanceMetric) -> u32 {
    match metric {
        DistanceMetric::Euclidean => METRIC_EUCLIDEAN,
        DistanceMetric::Manhattan => METRIC_MANHATTAN,
        DistanceMetric::Chebyshev => METRIC_CHEBYSHEV,
    }
}

/// An area whose closest seeds a [`JumpFloodPass`] has recorded into its scratch: which seed
/// grid holds them and the metric they were flooded with. The displacement that follows takes
/// it, so it reads the right grid and measures distances with the same metric. Commands run
/// in recording order: record the displacement before flooding another area into the same
/// scratch.
#[derive(Debug, Clone, Copy)]
pub struct FloodedArea<'a> {
    area: GranularArea<'a>,
    seed_grid: usize,
    metric: DistanceMetric,
}

impl<'a> FloodedArea<'a> {
    /// The area.
    pub fn area(&self) -> &GranularArea<'a> {
        &self.area
    }

    /// The index of the seed grid of the scratch that holds the closest seeds
    /// ([`super::GranularScratch::seeds`], [`super::GranularScratch::read_seeds`]).
    pub fn seed_grid(&self) -> usize {
        self.seed_grid
    }

    /// The metric the seeds were flooded with.
    pub fn metric(&self) -> DistanceMetric {
        self.metric
    }
}

/// Jump flooding of the closest seed over an area (Persson 2019, sec. 2.3.1) with the hashed
/// neighbour order, as [`terrain_core::granular::jump_flood`].
#[derive(Debug)]
pub struct JumpFloodPass {
    init: wgpu::ComputePipeline,
    pass: wgpu::ComputePipeline,
    pub(super) bindings: PassBindings<GranularUniform>,
}

impl JumpFloodPass {
    /// Builds the pipelines, their bindings and uniform ring.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = granular_bindings(device, "JumpFloodPass", &[true, true, false]);
        let module = shader_module(device, "granular_jfa.wgsl", terrain_shaders::GRANULAR_JFA)?;
        let layout = bindings.layout();
        Ok(Self {
            init: compute_pipeline(device, "JumpFloodPass init", &module, layout, "init")?,
            pass: compute_pipeline(device, "JumpFloodPass", &module, layout, "main")?,
            bindings,
        })
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records the seed initialisation from the penetration texture in the area's scratch and
    /// every pass of [`jfa_steps`]`(area size, extra_pass)` under `metric`; returns the flooded
    /// area for the displacement.
    pub fn encode<'a>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        area: &GranularArea<'a>,
        metric: DistanceMetric,
        extra_pass: bool,
    ) -> Result<FloodedArea<'a>, GpuError> {
        let base = GranularUniform {
            metric: metric_code(metric),
            ..GranularUniform::for_area(area)
        };
        let scratch = area.scratch();
        let [a, b] = &scratch.seeds;
        let steps = jfa_steps(area.rect().size, extra_pass);
        let mut groups = Vec::with_capacity(steps.len() + 1);
        groups.push(
            self.bindings
                .bind(device, queue, &base, &[&scratch.pen, b, a])?,
        );
        for (p, &step) in steps.iter().enumerate() {
            let uniform = GranularUniform {
                step,
                pass_index: p as u32,
                ..base
            };
            let (src, dst) = if p % 2 == 0 { (a, b) } else { (b, a) };
            groups.push(
                self.bindings
                    .bind(device, queue, &uniform, &[&scratch.pen, src, dst])?,
            );
        }
        let dispatches: Vec<_> = groups
            .iter()
            .enumerate()
            .map(|(k, (group, offset))| {
                let pipeline = if k == 0 { &self.init } else { &self.pass };
                (pipeline, group, *offset)
            })
            .collect();
        dispatch(encoder, "JumpFloodPass", area.groups(), &dispatches);
        Ok(FloodedArea {
            area: *area,
            seed_grid: steps.len() % 2,
            metric,
        })
    }
}

/// Displacement of intersected material to the contour (Persson 2019, sec. 4.1.4), one method per
/// [`DisplacementMethod`] variant: [`DisplacementMethod::ClosestSeed`] as
/// [`terrain_core::granular::displace_closest_seed`] and
/// [`DisplacementMethod::MultipleTargets`] as
/// [`terrain_core::granular::displace_multiple_targets`] by atomic scatter, and
/// [`DisplacementMethod::Iterative`] as [`terrain_core::granular::displace_iterative`] by
/// gather passes and a final atomic flush to the seeds.
#[derive(Debug)]
pub struct DisplacePass {
    closest: wgpu::ComputePipeline,
    multiple: wgpu::ComputePipeline,
    iter_init: wgpu::ComputePipeline,
    iter_pass: wgpu::ComputePipeline,
    iter_flush: wgpu::ComputePipeline,
    writeback: wgpu::ComputePipeline,
    pub(super) bindings: PassBindings<GranularUniform>,
}

impl DisplacePass {
    /// Builds the pipelines, their bindings and uniform ring.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = granular_bindings(
            device,
            "DisplacePass",
            &[false, true, true, false, false, false, false],
        );
        let module = shader_module(
            device,
            "granular_displace.wgsl",
            terrain_shaders::GRANULAR_DISPLACE,
        )?;
        let layout = bindings.layout();
        let pipe = |label, entry| compute_pipeline(device, label, &module, layout, entry);
        Ok(Self {
            closest: pipe("DisplacePass closest", "closest")?,
            multiple: pipe("DisplacePass multiple", "multiple")?,
            iter_init: pipe("DisplacePass iterative init", "iter_init")?,
            iter_pass: pipe("DisplacePass iterative pass", "iter_pass")?,
            iter_flush: pipe("DisplacePass iterative flush", "iter_flush")?,
            writeback: pipe("DisplacePass writeback", "writeback")?,
            bindings,
        })
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records `method` over the flooded area, from its penetration texture and closest seeds
    /// (keep factor `keep_q15`, see [`GranularParams::keep_q15`]); the removed material is added
    /// to the scratch's removed counter ([`super::GranularScratch::read_removed`]). The
    /// iterative method measures distances with the metric the seeds were flooded with and
    /// runs its `iterations` gather passes (integer shares, remainders stay), bit for bit as
    /// [`terrain_core::granular::displace_iterative`]`(.., keep_q15, iterations, metric)`.
    ///
    /// Fails with [`GpuError::Granular`] when the method's settings are out of range
    /// ([`DisplacementMethod::validate`]).
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        seeds: &FloodedArea<'_>,
        method: DisplacementMethod,
        keep_q15: u32,
    ) -> Result<(), GpuError> {
        method.validate()?;
        let area = seeds.area();
        let scratch = area.scratch();
        let base = GranularUniform {
            keep_q15,
            metric: metric_code(seeds.metric()),
            ..GranularUniform::for_area(area)
        };
        let buffers = [
            area.map().buffer(),
            &scratch.pen,
            &scratch.seeds[seeds.seed_grid() & 1],
            &scratch.acc,
            &scratch.removed,
            &scratch.dist,
            &scratch.carried,
        ];
        // The other seed grid's bind group is made now too (a ping-pong pair built once), so
        // which grid a flood ends on never makes a bind group in a later frame.
        let mut other = buffers;
        other[2] = &scratch.seeds[(seeds.seed_grid() & 1) ^ 1];
        self.bindings.warm(device, &other)?;
        encoder.clear_buffer(&scratch.acc, 0, Some(area.rect().area() * 4));
        match method {
            DisplacementMethod::ClosestSeed | DisplacementMethod::MultipleTargets => {
                let scatter = if method == DisplacementMethod::ClosestSeed {
                    &self.closest
                } else {
                    &self.multiple
                };
                let (group, offset) = self.bindings.bind(device, queue, &base, &buffers)?;
                dispatch(
                    encoder,
                    "DisplacePass",
                    area.groups(),
                    &[(scatter, &group, offset), (&self.writeback, &group, offset)],
                );
            }
            DisplacementMethod::Iterative { iterations } => {
                let even = self.bindings.bind(device, queue, &base, &buffers)?;
                let odd = self.bindings.bind(
                    device,
                    queue,
                    &GranularUniform { parity: 1, ..base },
                    &buffers,
                )?;
                let by_parity = |k: u32| if k & 1 == 0 { &even } else { &odd };
                let mut dispatches = Vec::with_capacity(iterations as usize + 3);
                dispatches.push((&self.iter_init, &even.0, even.1));
                for k in 0..iterations {
                    let (group, offset) = by_parity(k);
                    dispatches.push((&self.iter_pass, group, *offset));
                }
                let (last, offset) = by_parity(iterations);
                dispatches.push((&self.iter_flush, last, *offset));
                dispatches.push((&self.writeback, last, *offset));
                dispatch(
                    encoder,
                    "DisplacePass iterative",
                    area.groups(),
                    &dispatches,
                );
            }
        }
        Ok(())
    }
}

/// The settings of slope evening over an area, in the integer form the passes and their CPU
/// references take (Persson 2019, sec. 4.1.5, eq. 4.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlopeSettings {
    /// `(orthogonal, diagonal)` height differences, in height units, above which material
    /// flows ([`GranularParams::slope_thresholds_units`]).
    pub thresholds: [u32; 2],
    /// The roughness in Q15 ([`GranularParams::roughness_q15`]).
    pub roughness_q15: u32,
    /// Iterations (`numIterations-EvenOutSlopes`).
    pub iterations: u32,
}

impl SlopeSettings {
    /// The settings of `params` on a map of `texel_size` metres per texel and
    /// `units_per_metre` height units per metre.
    pub fn from_params(params: &GranularParams, texel_size: f32, units_per_metre: f64) -> Self {
        Self {
            thresholds: params.slope_thresholds_units(texel_size, units_per_metre),
            roughness_q15: params.roughness_q15(),
            iterations: params.num_iterations_even_out_slopes,
        }
    }
}

/// Evening out steep slopes (Persson 2019, sec. 4.1.5): [`SlopeMethod::Scatter`] as
/// [`terrain_core::granular::even_out_slopes_scatter`] (one atomic scatter per iteration) and
/// [`SlopeMethod::Interleaved`] as [`terrain_core::granular::even_out_slopes_interleaved`]
/// (amounts then gather per parity).
#[derive(Debug)]
pub struct SlopePass {
    scatter: wgpu::ComputePipeline,
    amounts: wgpu::ComputePipeline,
    apply: wgpu::ComputePipeline,
    writeback: wgpu::ComputePipeline,
    pub(super) bindings: PassBindings<GranularUniform>,
}

impl SlopePass {
    /// Builds the pipelines, their bindings and uniform ring.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = granular_bindings(device, "SlopePass", &[false, true, false, false]);
        let module = shader_module(
            device,
            "granular_slope.wgsl",
            terrain_shaders::GRANULAR_SLOPE,
        )?;
        let layout = bindings.layout();
        let pipe = |label, entry| compute_pipeline(device, label, &module, layout, entry);
        Ok(Self {
            scatter: pipe("SlopePass scatter", "scatter")?,
            amounts: pipe("SlopePass amounts", "amounts_pass")?,
            apply: pipe("SlopePass apply", "apply")?,
            writeback: pipe("SlopePass writeback", "writeback")?,
            bindings,
        })
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records `settings.iterations` iterations of `method` over `area`, with receivers limited
    /// to the seed columns of the penetration texture in the area's scratch. Fails with
    /// [`GpuError::Granular`] for more than [`MAX_ITERATIONS`] iterations.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        area: &GranularArea<'_>,
        method: SlopeMethod,
        settings: &SlopeSettings,
    ) -> Result<(), GpuError> {
        if settings.iterations > MAX_ITERATIONS {
            return Err(GranularError::ParamOutOfRange {
                name: "numIterationsEvenOutSlopes",
                value: f64::from(settings.iterations),
                range: "0..=1024",
            }
            .into());
        }
        if settings.iterations == 0 {
            return Ok(());
        }
        let base = GranularUniform {
            threshold_orth: settings.thresholds[0],
            threshold_diag: settings.thresholds[1],
            roughness_q15: settings.roughness_q15,
            ..GranularUniform::for_area(area)
        };
        let scratch = area.scratch();
        let buffers = [
            area.map().buffer(),
            &scratch.pen,
            &scratch.acc,
            &scratch.amounts,
        ];
        encoder.clear_buffer(&scratch.acc, 0, Some(area.rect().area() * 4));
        let iterations = settings.iterations as usize;
        match method {
            SlopeMethod::Scatter => {
                let (group, offset) = self.bindings.bind(device, queue, &base, &buffers)?;
                let mut dispatches = Vec::with_capacity(2 * iterations);
                for _ in 0..iterations {
                    dispatches.push((&self.scatter, &group, offset));
                    dispatches.push((&self.writeback, &group, offset));
                }
                dispatch(encoder, "SlopePass scatter", area.groups(), &dispatches);
            }
            SlopeMethod::Interleaved => {
                let parities = [
                    self.bindings.bind(device, queue, &base, &buffers)?,
                    self.bindings.bind(
                        device,
                        queue,
                        &GranularUniform { parity: 1, ..base },
                        &buffers,
                    )?,
                ];
                let mut dispatches = Vec::with_capacity(6 * iterations);
                for _ in 0..iterations {
                    for (group, offset) in &parities {
                        dispatches.push((&self.amounts, group, *offset));
                        dispatches.push((&self.apply, group, *offset));
                        dispatches.push((&self.writeback, group, *offset));
                    }
                }
                dispatch(encoder, "SlopePass interleaved", area.groups(), &dispatches);
            }
        }
        Ok(())
    }
}
