//! [`FieldStepper`]: terrain-core's `GranularStepper` over [`GranularField`]s, so that granular
//! trails on a streamed world (terrain-cache's `GranularTrails`) step on the GPU with no code
//! of the application's: plain submits, each window's map moved on to the next without a wait
//! ([`GranularField::shift`]), the compiled passes kept from one window to the next. An
//! application that times its submits steps through [`FieldStepper::submitting`], with its
//! own [`Submit`].

use super::{DepthSource, GranularField, GranularPasses, RetiredField};
use crate::{GpuError, PlainSubmit, Submit};
use glam::IVec2;
use terrain_core::FixedPointMap;
use terrain_core::granular::{GranularArrivals, GranularObject, GranularParams, GranularStepper};

/// Steps a granular window on the GPU for its CPU owner (module docs).
#[derive(Debug)]
pub struct FieldStepper {
    device: wgpu::Device,
    queue: wgpu::Queue,
    field: Option<GranularField>,
    passes: Option<GranularPasses>,
    retired: Option<RetiredField>,
    depth_source: DepthSource,
}

const NOT_STARTED: GpuError = GpuError::Unsupported {
    what: "FieldStepper",
    reason: "no window was started",
};

impl FieldStepper {
    /// A stepper on `device` and `queue` (the application's own), no window yet.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Self {
        Self {
            device: device.clone(),
            queue: queue.clone(),
            field: None,
            passes: None,
            retired: None,
            depth_source: DepthSource::default(),
        }
    }

    /// Where the steps' depth from below comes from, for this window and the next ones
    /// (`DepthSource::Cpu` makes them equal the CPU simulation bit for bit).
    pub fn set_depth_source(&mut self, source: DepthSource) {
        self.depth_source = source;
        if let Some(f) = self.field.as_mut() {
            f.step_pass_mut().depth_source = source;
        }
    }

    /// The field of the window being stepped, if any (to draw it, say).
    pub fn field(&self) -> Option<&GranularField> {
        self.field.as_ref()
    }

    /// This stepper with its steps' two submits made through `submit` (to time them, say:
    /// [`GranularField::step_with`]), for a frame's calls.
    pub fn submitting<S: Submit>(&mut self, submit: S) -> Submitting<'_, S> {
        Submitting {
            stepper: self,
            submit,
        }
    }

    /// Hands the retired field, all its readbacks arrived, back to the field for its next
    /// shift; one the field will not take (or without a field) is dropped.
    fn recycle(&mut self) {
        if let (Some(r), Some(field)) = (self.retired.take(), self.field.as_mut()) {
            drop(field.recycle(r));
        }
    }

    fn field_mut(&mut self) -> Result<&mut GranularField, GpuError> {
        self.field.as_mut().ok_or(NOT_STARTED)
    }

    /// What arrived, then one step through `submit`.
    fn step_via(
        &mut self,
        submit: &mut dyn Submit,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<GranularArrivals, GpuError> {
        let (device, queue) = (self.device.clone(), self.queue.clone());
        let field = self.field_mut()?;
        let arrived = field.poll(&device)?;
        field.step_with(&device, &queue, submit, objects, tag)?;
        Ok(arrived)
    }
}

/// A [`FieldStepper`] whose steps submit through `S` ([`FieldStepper::submitting`]).
#[derive(Debug)]
pub struct Submitting<'a, S: Submit> {
    stepper: &'a mut FieldStepper,
    submit: S,
}

impl<S: Submit> GranularStepper for Submitting<'_, S> {
    type Error = GpuError;

    fn start(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<(), GpuError> {
        self.stepper.start(map, params)
    }

    fn step(
        &mut self,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<GranularArrivals, GpuError> {
        self.stepper.step_via(&mut self.submit, objects, tag)
    }

    fn poll(&mut self) -> Result<GranularArrivals, GpuError> {
        self.stepper.poll()
    }

    fn stop(&mut self) -> Result<GranularArrivals, GpuError> {
        self.stepper.stop()
    }

    fn shifts(&self) -> bool {
        self.stepper.shifts()
    }

    fn shift(&mut self, map: &FixedPointMap, offset: IVec2, tag: u64) -> Result<bool, GpuError> {
        self.stepper.shift(map, offset, tag)
    }

    fn poll_retired(&mut self) -> Result<GranularArrivals, GpuError> {
        self.stepper.poll_retired()
    }

    fn drain_retired(&mut self) -> Result<GranularArrivals, GpuError> {
        self.stepper.drain_retired()
    }
}

impl GranularStepper for FieldStepper {
    type Error = GpuError;

    fn start(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<(), GpuError> {
        if self.field.is_some() {
            return Err(GpuError::Unsupported {
                what: "FieldStepper::start",
                reason: "a window is being stepped: stop it first, or its readbacks are lost",
            });
        }
        let passes = self.passes.take();
        let mut field = GranularField::new(&self.device, &self.queue, map, params, passes)?;
        field.step_pass_mut().depth_source = self.depth_source;
        self.field = Some(field);
        Ok(())
    }

    fn step(
        &mut self,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<GranularArrivals, GpuError> {
        let (device, queue) = (self.device.clone(), self.queue.clone());
        self.step_via(
            &mut PlainSubmit {
                device: &device,
                queue: &queue,
            },
            objects,
            tag,
        )
    }

    fn poll(&mut self) -> Result<GranularArrivals, GpuError> {
        let device = self.device.clone();
        match self.field.as_mut() {
            Some(f) => f.poll(&device),
            None => Ok(GranularArrivals::default()),
        }
    }

    fn stop(&mut self) -> Result<GranularArrivals, GpuError> {
        let Some(field) = self.field.take() else {
            return Ok(GranularArrivals::default());
        };
        let (arrived, passes) = field.finish(&self.device, &self.queue)?;
        self.passes = Some(passes);
        Ok(arrived)
    }

    fn shifts(&self) -> bool {
        true
    }

    fn shift(&mut self, map: &FixedPointMap, offset: IVec2, tag: u64) -> Result<bool, GpuError> {
        if self.retired.is_some() {
            return Err(GpuError::Unsupported {
                what: "FieldStepper::shift",
                reason: "the last shift's readbacks are still on their way: poll or drain them",
            });
        }
        let (device, queue) = (self.device.clone(), self.queue.clone());
        let field = self.field_mut()?;
        let (retired, _) = field.shift(&device, &queue, map, offset, tag)?;
        self.retired = Some(retired);
        Ok(true)
    }

    fn poll_retired(&mut self) -> Result<GranularArrivals, GpuError> {
        let Some(r) = self.retired.as_mut() else {
            return Ok(GranularArrivals::default());
        };
        let arrived = r.poll(&self.device, &self.queue)?;
        if !arrived.in_flight {
            self.recycle();
        }
        Ok(arrived)
    }

    fn drain_retired(&mut self) -> Result<GranularArrivals, GpuError> {
        let Some(r) = self.retired.as_mut() else {
            return Ok(GranularArrivals::default());
        };
        let arrived = r.drain(&self.device, &self.queue);
        self.recycle();
        arrived
    }
}
