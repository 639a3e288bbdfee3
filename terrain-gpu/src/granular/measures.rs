//! [`StepMeasures`]: each granular step's volume sum and removed material, read back without
//! a wait. The step's submit copies both counters into two rings of small staging buffers, and
//! a later poll hands them over in step order, tagged as the caller asked (its frame, say). A
//! blocking read of each ([`VolumePass::read`], [`GranularScratch::read_removed`]) would stall
//! every frame on the GPU.

use crate::device::small_readback::SmallReadback;
use crate::error::GpuError;
use crate::granular::{GranularScratch, VolumePass};
use std::collections::{HashMap, VecDeque};
pub use terrain_core::granular::StepMeasure;

/// Steps whose counters may be on their way at once.
const RING: usize = 16;

/// The two rings and the steps on their way (see the module docs): [`StepMeasures::request`]
/// in each step's submit, [`StepMeasures::poll`] any time after, [`StepMeasures::flush`] at the
/// end of a map's steps.
#[derive(Debug)]
pub struct StepMeasures {
    volume: SmallReadback,
    removed: SmallReadback,
    /// Steps requested, oldest first: tag, volume request, removed request (`None`: a step
    /// without a scratch removes nothing).
    steps: VecDeque<(u64, u64, Option<u64>)>,
    volumes: HashMap<u64, u64>,
    removals: HashMap<u64, u64>,
}

impl StepMeasures {
    /// The two rings (16 steps may be on their way), made now.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        Ok(Self {
            volume: SmallReadback::new(device, RING, 8)?,
            removed: SmallReadback::new(device, RING, 8)?,
            steps: VecDeque::new(),
            volumes: HashMap::new(),
            removals: HashMap::new(),
        })
    }

    /// Records the copies of a step's counters (the volume pass's last sum, the scratch's
    /// removed counter; `None`: nothing removed) into `encoder`, after the step and the volume
    /// pass were recorded; `tag` comes back with them. With every ring buffer on its way (16
    /// steps unread) it waits for the GPU first, so no step goes unmeasured.
    pub fn request(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        tag: u64,
        volume: &VolumePass,
        scratch: Option<&GranularScratch>,
    ) -> Result<(), GpuError> {
        let v = loop {
            match volume.request(encoder, &mut self.volume)? {
                Some(seq) => break seq,
                None => self.wait(device)?,
            }
        };
        let r = match scratch {
            Some(s) => Some(loop {
                match s.request_removed(encoder, &mut self.removed)? {
                    Some(seq) => break seq,
                    None => self.wait(device)?,
                }
            }),
            None => None,
        };
        self.steps.push_back((tag, v, r));
        Ok(())
    }

    /// Whether a step's counters are still on their way.
    pub fn in_flight(&self) -> bool {
        !self.steps.is_empty()
    }

    /// The steps whose counters have both arrived, oldest first, never waiting.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<StepMeasure>, GpuError> {
        self.take_in(device)?;
        let mut out = Vec::new();
        while let Some(&(tag, v, r)) = self.steps.front() {
            let removed = match r {
                Some(r) if !self.removals.contains_key(&r) => break,
                Some(r) => self.removals.get(&r).copied().unwrap_or(0),
                None => 0,
            };
            let Some(volume) = self.volumes.remove(&v) else {
                break;
            };
            if let Some(r) = r {
                self.removals.remove(&r);
            }
            self.steps.pop_front();
            out.push(StepMeasure {
                tag,
                volume,
                removed,
            });
        }
        Ok(out)
    }

    /// Waits (bounded: 60 s a wait) for every step on its way and hands them over, at the end
    /// of a map's steps. Fails when some never arrive (a lost device).
    pub fn flush(&mut self, device: &wgpu::Device) -> Result<Vec<StepMeasure>, GpuError> {
        let mut out = Vec::new();
        // Bounded: each wait lands every submitted copy.
        for _ in 0..2 {
            out.extend(self.poll(device)?);
            if !self.in_flight() {
                return Ok(out);
            }
            self.wait(device)?;
        }
        out.extend(self.poll(device)?);
        if self.in_flight() {
            return Err(GpuError::SmallReadbackFailed);
        }
        Ok(out)
    }

    /// Waits for the GPU and takes in what arrived (the rings' buffers are free again).
    fn wait(&mut self, device: &wgpu::Device) -> Result<(), GpuError> {
        device.poll(crate::device::download::wait_bounded())?;
        self.take_in(device)
    }

    /// Keeps the counters that have arrived (freeing their ring buffers), never waiting.
    fn take_in(&mut self, device: &wgpu::Device) -> Result<(), GpuError> {
        for (seq, bytes) in self.volume.poll(device)? {
            self.volumes.insert(seq, VolumePass::sum_of(&bytes));
        }
        for (seq, bytes) in self.removed.poll(device)? {
            self.removals.insert(seq, VolumePass::sum_of(&bytes));
        }
        Ok(())
    }
}
