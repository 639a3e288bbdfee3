//! Granular deformation in the GPU scene: terrain-gpu's `GranularField` (the snow scenario's
//! field, or a streamed world's granular window), its two submits timed as the frame's steps,
//! and terrain-cache's `GranularStepper` over it for the world's trails.

use super::*;
use terrain_core::granular::GranularArrivals;
use terrain_gpu::granular::GranularField;

/// The scene as the world trails' GPU side, each step timed into `timings`.
pub struct TimedGranular<'a> {
    /// The scene whose granular field steps.
    pub scene: &'a mut GpuScene,
    /// The frame's timings.
    pub timings: &'a mut Timings,
}

impl terrain_cache::GranularStepper for TimedGranular<'_> {
    type Error = anyhow::Error;

    fn start(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<()> {
        self.scene.enable_granular(map, params)
    }

    fn step(&mut self, objects: &[GranularObject<'_>], tag: u64) -> Result<GranularArrivals> {
        let (_, arrivals) = self
            .scene
            .granular_step_tagged(objects, tag, self.timings)?;
        Ok(arrivals)
    }

    fn poll(&mut self) -> Result<GranularArrivals> {
        self.scene.poll_granular()
    }

    fn stop(&mut self) -> Result<GranularArrivals> {
        self.scene.disable_granular()
    }

    fn shifts(&self) -> bool {
        true
    }

    fn shift(&mut self, map: &FixedPointMap, offset: glam::IVec2, tag: u64) -> Result<bool> {
        self.scene.shift_granular(map, offset, tag)?;
        Ok(true)
    }

    fn poll_retired(&mut self) -> Result<GranularArrivals> {
        self.scene.retired_granular(false)
    }

    fn drain_retired(&mut self) -> Result<GranularArrivals> {
        self.scene.retired_granular(true)
    }
}

impl GpuScene {
    /// One granular step on the GPU with `objects` (terrain-gpu's `GranularField`), timed as
    /// [`Step::GranularGpu`] and [`Step::NormalsGpu`]: its active areas, and what arrived of
    /// earlier steps (this step's come in a later frame).
    pub fn granular_step(
        &mut self,
        objects: &[GranularObject<'_>],
        timings: &mut Timings,
    ) -> Result<(Vec<Rect>, GranularArrivals)> {
        // The frame being stepped (the scene counts the frames it renders).
        let tag = u64::from(self.frames);
        self.granular_step_tagged(objects, tag, timings)
    }

    fn granular_step_tagged(
        &mut self,
        objects: &[GranularObject<'_>],
        tag: u64,
        timings: &mut Timings,
    ) -> Result<(Vec<Rect>, GranularArrivals)> {
        self.granular_step_inner(objects, tag, timings)
            .map_err(|e| self.lost_or(e))
    }

    /// The granular areas and measures of earlier steps that have arrived (never waits), and
    /// whether any is still on its way.
    pub fn poll_granular(&mut self) -> Result<GranularArrivals> {
        let device = &self.ctx.device;
        let polled = match self.granular.as_mut() {
            Some(g) => g.poll(device),
            None => Ok(GranularArrivals::default()),
        };
        polled.map_err(|e| self.lost_or(e.into()))
    }

    /// Waits for every granular area and measure still on its way, so the CPU copy gets the
    /// last steps; the field stays drawn.
    pub fn drain_granular(&mut self) -> Result<GranularArrivals> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let drained = match self.granular.as_mut() {
            Some(g) => g.drain(device, queue),
            None => Ok(GranularArrivals::default()),
        };
        drained.map_err(|e| self.lost_or(e.into()))
    }

    /// Drains the granular field and frees its GPU map, keeping its passes for the next one:
    /// a streamed world's granular window that moves on.
    pub fn disable_granular(&mut self) -> Result<GranularArrivals> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let Some(field) = self.granular.take() else {
            return Ok(GranularArrivals::default());
        };
        match field.finish(device, queue) {
            Ok((arrivals, passes)) => {
                self.granular_passes = Some(passes);
                Ok(arrivals)
            }
            Err(e) => Err(self.lost_or(e.into())),
        }
    }

    /// Moves the granular field onto the next window of a world's trails without a wait
    /// (terrain-gpu's `GranularField::shift`); the old map's readbacks go on arriving through
    /// [`Self::retired_granular`].
    pub fn shift_granular(
        &mut self,
        map: &FixedPointMap,
        offset: glam::IVec2,
        tag: u64,
    ) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let Some(g) = self.granular.as_mut() else {
            anyhow::bail!("granular deformation was not enabled on the GPU scene");
        };
        match g.shift(device, queue, map, offset, tag) {
            Ok((retired, _)) => {
                self.granular_retired = Some(retired);
                Ok(())
            }
            Err(e) => Err(self.lost_or(e.into())),
        }
    }

    /// What arrived of the map the granular field moved away from (`wait`: all of it); the
    /// readbacks are freed once nothing is in flight.
    pub fn retired_granular(&mut self, wait: bool) -> Result<GranularArrivals> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let Some(r) = self.granular_retired.as_mut() else {
            return Ok(GranularArrivals::default());
        };
        let arrived = match wait {
            true => r.drain(device, queue),
            false => r.poll(device),
        };
        let arrived = arrived.map_err(|e| self.lost_or(e.into()))?;
        if !arrived.in_flight {
            self.granular_retired = None;
        }
        Ok(arrived)
    }

    /// Moves granular deformation onto the GPU: uploads `map` once (after this, the GPU map is
    /// the one deformed and drawn) with the passes kept from the last field if they fit.
    pub fn enable_granular(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let passes = self.granular_passes.take();
        let field = GranularField::new(device, queue, map, params, passes)?;
        // Culling boxes: granular material only moves where objects push it, so the surface
        // stays within a couple of metres of the initial heights. A streamed world's granular
        // window is drawn through the atlas: its range stands.
        if self.atlas.is_none() {
            let enc = map.encoding();
            let (lo, hi) = map
                .grid()
                .as_slice()
                .iter()
                .fold((u32::MAX, 0), |(lo, hi), &h| (lo.min(h), hi.max(h)));
            self.height_range = (
                enc.to_metres(f64::from(lo)) - 1.0,
                enc.to_metres(f64::from(hi)) + 2.0,
            );
            self.terrain.set_height_range(self.height_range);
        }
        self.granular = Some(field);
        Ok(())
    }

    fn granular_step_inner(
        &mut self,
        objects: &[GranularObject<'_>],
        tag: u64,
        timings: &mut Timings,
    ) -> Result<(Vec<Rect>, GranularArrivals)> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let Some(g) = self.granular.as_mut() else {
            anyhow::bail!("granular deformation was not enabled on the GPU scene");
        };
        let arrivals = g.poll(device)?;
        let mut areas = Vec::new();
        let step_time = self
            .timer
            .time(device, queue, Step::GranularGpu, |encoder| {
                areas = g.encode_step(device, queue, encoder, objects)?;
                Ok(())
            })?;
        g.recall_step();
        let normal_time = self
            .timer
            .time(device, queue, Step::NormalsGpu, |encoder| {
                g.encode_follow_up(device, queue, encoder, &areas, tag)
            })?;
        g.recall_follow_up();
        step_time.record(timings);
        normal_time.record(timings);
        Ok((areas, arrivals))
    }
}
