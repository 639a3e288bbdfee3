//! Granular deformation on the GPU scene (Persson 2019): the snow scenario's field or a
//! streamed world's granular window, stepped on the GPU with its normals and volume, the
//! changed areas read back without a wait (a window moves on once they are back, or drains
//! them when the vehicle forces it); the passes outlive a window, so the next one compiles
//! nothing.

use super::*;
use terrain_gpu::QueuedReadback;
use terrain_gpu::granular::StepMeasures;

/// Granular areas read back: world-window rects and their fixed-point heights.
pub type ArrivedAreas = Vec<(Rect, Grid<u32>)>;

/// The GPU side of the snow scenario: the fixed-point map, the step, the normals and float
/// heights it is rendered from, the volume sum, and the readback of the areas a step changed.
pub(super) struct GranularScene {
    pub(super) map: GpuHeightMap<u32>,
    pub(super) step: GpuGranularStep,
    pub(super) normal_pass: GranularNormalsPass,
    pub(super) normals: GpuGranularNormals,
    pub(super) blur_iterations: u32,
    pub(super) volume: VolumePass,
    pub(super) readback: QueuedReadback,
    pub(super) params: GranularParams,
    /// The steps' volumes and removed material, on their way back.
    pub(super) measures: StepMeasures,
    /// The material layer the steps' trails paint (`enable_granular_trails`).
    pub(super) trail: Option<GpuMaterialLayer>,
}

/// What a granular scene keeps from one map to the next: its passes (pipelines compiled once)
/// and its readback ring (drained), for the same parameters.
pub(super) struct GranularPasses {
    pub(super) step: GpuGranularStep,
    pub(super) normal_pass: GranularNormalsPass,
    pub(super) volume: VolumePass,
    pub(super) readback: QueuedReadback,
    pub(super) params: GranularParams,
    pub(super) measures: StepMeasures,
}

/// What one GPU granular step did.
pub struct GranularFrame {
    /// The merged active areas the step ran over.
    pub areas: Vec<Rect>,
    /// The measures (volume after the step, material removed) of earlier steps that arrived,
    /// oldest first, tagged with their frames: this step's come in a later frame.
    pub measured: Vec<StepMeasure>,
    /// Regions of earlier steps that arrived on the CPU: (rect, fixed-point heights).
    pub arrived: Vec<(Rect, Grid<u32>)>,
}

/// What a granular scene still had on its way, handed over without a wait or drained.
pub struct GranularArrivals {
    /// Changed areas: (rect, fixed-point heights).
    pub areas: ArrivedAreas,
    /// Steps' measures, oldest first.
    pub measured: Vec<StepMeasure>,
    /// Whether anything (an area or a measure) is still on its way.
    pub in_flight: bool,
}

impl GpuScene {
    /// One granular step on the GPU with `objects`: the step, the normals of the changed
    /// areas, the volume sum, and readback requests for the changed areas (they arrive in a
    /// later frame's [`GranularFrame::arrived`]). Timed as [`Step::GranularGpu`] and
    /// [`Step::NormalsGpu`].
    pub fn granular_step(
        &mut self,
        objects: &[GranularObject<'_>],
        timings: &mut Timings,
    ) -> Result<GranularFrame> {
        self.granular_step_inner(objects, timings)
            .map_err(|e| self.lost_or(e))
    }

    /// The granular areas and measures of earlier steps that have arrived (never waits), and
    /// whether any is still on its way: a window that moves on once nothing is on its way
    /// drains without a wait.
    pub fn poll_granular(&mut self) -> Result<GranularArrivals> {
        self.poll_granular_inner().map_err(|e| self.lost_or(e))
    }

    fn poll_granular_inner(&mut self) -> Result<GranularArrivals> {
        let device = &self.ctx.device;
        let Some(g) = self.granular.as_mut() else {
            return Ok(GranularArrivals {
                areas: Vec::new(),
                measured: Vec::new(),
                in_flight: false,
            });
        };
        let areas = g
            .readback
            .poll(device)?
            .into_iter()
            .map(|r| (r.rect, r.raw))
            .collect();
        let measured = g.measures.poll(device)?;
        let in_flight = g.readback.in_flight() || g.measures.in_flight();
        Ok(GranularArrivals {
            areas,
            measured,
            in_flight,
        })
    }

    /// Ends granular deformation on the GPU: requests the changed areas still waiting for a
    /// ring slot and waits for every readback and measure in flight, so the CPU copy gets the
    /// last steps.
    pub fn drain_granular(&mut self) -> Result<GranularArrivals> {
        self.drain_granular_inner().map_err(|e| self.lost_or(e))
    }

    /// Drains granular deformation ([`drain_granular`](Self::drain_granular)) and frees its
    /// GPU map: a streamed world's granular window that moves on.
    pub fn disable_granular(&mut self) -> Result<GranularArrivals> {
        let arrived = self.drain_granular()?;
        // Nothing is in flight now: the passes and the rings serve the next map.
        self.granular_passes = self.granular.take().map(|g| GranularPasses {
            step: g.step,
            normal_pass: g.normal_pass,
            volume: g.volume,
            readback: g.readback,
            params: g.params,
            measures: g.measures,
        });
        Ok(arrived)
    }

    /// Moves granular deformation onto the GPU: uploads `map` once (after this, the GPU map is
    /// the one deformed and drawn), builds the passes and computes the first normals.
    pub fn enable_granular(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let gpu_map = GpuHeightMap::from_map(device, queue, map)?;
        let normals = GpuGranularNormals::for_map(device, &gpu_map)?;
        let passes = match self.granular_passes.take() {
            Some(p) if p.params == params => p,
            _ => GranularPasses {
                step: GpuGranularStep::new(device, params)?,
                normal_pass: GranularNormalsPass::new(device)?,
                volume: VolumePass::new(device)?,
                readback: QueuedReadback::new(device, 8)?,
                params,
                measures: StepMeasures::new(device)?,
            },
        };
        let mut normal_pass = passes.normal_pass;
        let full = Rect::from_size(map.size());
        let blur_iterations = params.num_iterations_blur_normals;
        let mut encoder = device.create_command_encoder(&Default::default());
        normal_pass.encode(device, queue, &mut encoder, &gpu_map, &normals, full)?;
        normal_pass.encode_blur(device, queue, &mut encoder, &normals, full, blur_iterations)?;
        queue.submit([encoder.finish()]);
        normal_pass.recall();
        // Culling boxes: granular material only moves where objects push it, so the surface
        // stays within a couple of metres of the initial heights.
        let enc = map.encoding();
        let (lo, hi) = map
            .grid()
            .as_slice()
            .iter()
            .fold((u32::MAX, 0), |(lo, hi), &h| (lo.min(h), hi.max(h)));
        // A streamed world's granular window is drawn through the atlas: its range stands.
        if self.atlas.is_none() {
            self.height_range = (
                enc.to_metres(f64::from(lo)) - 1.0,
                enc.to_metres(f64::from(hi)) + 2.0,
            );
            self.terrain.set_height_range(self.height_range);
        }
        self.granular = Some(GranularScene {
            step: passes.step,
            map: gpu_map,
            normal_pass,
            normals,
            blur_iterations,
            volume: passes.volume,
            readback: passes.readback,
            params,
            measures: passes.measures,
            trail: None,
        });
        Ok(())
    }

    fn granular_step_inner(
        &mut self,
        objects: &[GranularObject<'_>],
        timings: &mut Timings,
    ) -> Result<GranularFrame> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        // The frame being stepped (the scene counts the frames it renders).
        let frame = u64::from(self.frames);
        let Some(g) = self.granular.as_mut() else {
            anyhow::bail!("granular deformation was not enabled on the GPU scene");
        };
        let measured = g.measures.poll(device)?;
        // Regions requested by earlier frames that have arrived.
        let arrived: Vec<(Rect, Grid<u32>)> = g
            .readback
            .poll(device)?
            .into_iter()
            .map(|r| (r.rect, r.raw))
            .collect();
        let mut areas = Vec::new();
        let step_time = self
            .timer
            .time(device, queue, Step::GranularGpu, |encoder| {
                let trail = g.trail.as_ref().map(|layer| Trail {
                    layer,
                    effect: paint::TRAIL,
                });
                areas = g
                    .step
                    .encode_with_trail(device, queue, encoder, &g.map, objects, trail)?;
                Ok(())
            })?;
        g.step.recall();
        let areas: Vec<Rect> = areas.iter().map(|a| a.rect).collect();
        // Normals reach one texel past the heights a step changed, and the blur one more per
        // iteration.
        let full = Rect::from_size(g.map.size());
        let reach = 1 + g.blur_iterations;
        let normal_time = self
            .timer
            .time(device, queue, Step::NormalsGpu, |encoder| {
                for rect in &areas {
                    let Some(r) = rect.expand(reach).intersect(&full) else {
                        continue;
                    };
                    g.normal_pass
                        .encode(device, queue, encoder, &g.map, &g.normals, r)?;
                    g.normal_pass.encode_blur(
                        device,
                        queue,
                        encoder,
                        &g.normals,
                        r,
                        g.blur_iterations,
                    )?;
                }
                g.volume.encode(device, queue, encoder, &g.map)?;
                // The volume and removed material come back without a wait, a frame or more
                // later.
                g.measures
                    .request(device, encoder, frame, &g.volume, g.step.scratch())?;
                // The changed areas go to the CPU copy behind the overview and collision.
                g.readback
                    .request(device, encoder, &g.map, areas.iter().copied())
            })?;
        g.normal_pass.recall();
        g.volume.recall();
        step_time.record(timings);
        normal_time.record(timings);
        Ok(GranularFrame {
            areas,
            measured,
            arrived,
        })
    }

    fn drain_granular_inner(&mut self) -> Result<GranularArrivals> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let Some(g) = self.granular.as_mut() else {
            return Ok(GranularArrivals {
                areas: Vec::new(),
                measured: Vec::new(),
                in_flight: false,
            });
        };
        let arrived = g
            .readback
            .flush(device, queue, &g.map)?
            .into_iter()
            .map(|r| (r.rect, r.raw))
            .collect();
        Ok(GranularArrivals {
            areas: arrived,
            measured: g.measures.flush(device)?,
            in_flight: false,
        })
    }
}
