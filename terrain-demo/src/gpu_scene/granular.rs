//! Granular deformation in the GPU scene: terrain-gpu's `GranularField` (the snow scenario's
//! field, drawn) and `FieldStepper` (a streamed world's granular trails), their two submits
//! timed as the frame's steps through [`TimedSubmit`].

use super::*;
use terrain_core::granular::GranularArrivals;
use terrain_gpu::granular::{FieldStepper, GranularField, Submitting};

/// terrain-gpu's `Submit` through the scene's timer: each submit timed as the frame's step of
/// its name (a granular step's two as [`Step::GranularGpu`] and [`Step::NormalsGpu`], a tile
/// stamp's as [`Step::StampGpu`]; a name of no step is submitted untimed).
pub struct TimedSubmit<'a> {
    ctx: &'a GpuContext,
    timer: &'a mut FrameTimer,
    timings: &'a mut Timings,
    spent_ms: f64,
}

impl<'a> TimedSubmit<'a> {
    /// Submits on `ctx`, timed by `timer` into `timings`.
    pub fn new(ctx: &'a GpuContext, timer: &'a mut FrameTimer, timings: &'a mut Timings) -> Self {
        Self {
            ctx,
            timer,
            timings,
            spent_ms: 0.0,
        }
    }

    /// Wall milliseconds spent in its submits so far (work the frame thread did not do).
    pub fn spent_ms(&self) -> f64 {
        self.spent_ms
    }
}

impl terrain_gpu::Submit for TimedSubmit<'_> {
    fn submit(
        &mut self,
        name: &'static str,
        work: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> Result<(), terrain_gpu::GpuError>,
    ) -> Result<(), terrain_gpu::GpuError> {
        let step = match name {
            GranularField::STEP => Some(Step::GranularGpu),
            GranularField::FOLLOW_UP => Some(Step::NormalsGpu),
            terrain_gpu::AtlasStamper::STAMP => Some(Step::StampGpu),
            _ => Step::ALL.into_iter().find(|s| s.name() == name),
        };
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let t = std::time::Instant::now();
        match step {
            Some(step) => self
                .timer
                .time(device, queue, step, work)?
                .record(self.timings),
            None => terrain_gpu::Submit::submit(
                &mut terrain_gpu::PlainSubmit { device, queue },
                name,
                work,
            )?,
        }
        self.spent_ms += crate::timings::ms_since(t);
        Ok(())
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
        self.granular_step_inner(objects, tag, timings)
            .map_err(|e| self.lost_or(e))
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

    /// The world trails' GPU side (terrain-gpu's `FieldStepper`, made on first use), each
    /// step timed into `timings`.
    pub fn trails<'s>(&'s mut self, timings: &'s mut Timings) -> Submitting<'s, TimedSubmit<'s>> {
        let ctx = &self.ctx;
        let stepper =
            (self.trails).get_or_insert_with(|| FieldStepper::new(&ctx.device, &ctx.queue));
        stepper.submitting(TimedSubmit::new(ctx, &mut self.timer, timings))
    }

    /// Moves granular deformation onto the GPU: uploads `map` once (after this, the GPU map is
    /// the one deformed and drawn)
    pub fn enable_granular(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let field = GranularField::new(device, queue, map, params, None)?;
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
        let (ctx, timer) = (&self.ctx, &mut self.timer);
        let Some(g) = self.granular.as_mut() else {
            anyhow::bail!("granular deformation was not enabled on the GPU scene");
        };
        let arrivals = g.poll(&ctx.device)?;
        let mut timed = TimedSubmit::new(ctx, timer, timings);
        let areas = g.step_with(&ctx.device, &ctx.queue, &mut timed, objects, tag)?;
        Ok((areas, arrivals))
    }
}
