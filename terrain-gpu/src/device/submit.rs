//! [`Submit`]: how a library type's one-call forms submit the GPU work they record, so that an
//! application can time them (a [`crate::StepTimer`] step per submit, say) or count them
//! without re-implementing the type over its `encode_*` calls. [`PlainSubmit`] submits as is.

use crate::error::GpuError;

/// Records GPU work into an encoder and submits it (see the module docs).
pub trait Submit {
    /// Records `work` into an encoder and submits it, as the step `name` (each library type
    /// names its submits with constants, e.g. `GranularField::STEP`).
    fn submit(
        &mut self,
        name: &'static str,
        work: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<(), GpuError>;
}

/// Submits on `device` and `queue`, one encoder per call, untimed.
#[derive(Debug, Clone, Copy)]
pub struct PlainSubmit<'a> {
    /// The device the encoders are made on.
    pub device: &'a wgpu::Device,
    /// The queue they are submitted to.
    pub queue: &'a wgpu::Queue,
}

impl Submit for PlainSubmit<'_> {
    fn submit(
        &mut self,
        _: &'static str,
        work: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<(), GpuError> {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        work(&mut encoder)?;
        self.queue.submit([encoder.finish()]);
        Ok(())
    }
}

/// A borrowed submitter submits as the one it borrows (so `submitting(&mut mine)` keeps it).
impl<S: Submit + ?Sized> Submit for &mut S {
    fn submit(
        &mut self,
        name: &'static str,
        work: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<(), GpuError> {
        (**self).submit(name, work)
    }
}
