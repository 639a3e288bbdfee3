//! Each GPU granular step's volume sum and removed material, read back without a wait: the
//! step's submit copies both counters into two rings of small staging buffers, and a later
//! frame's poll hands them over in step order, tagged with the frame that stepped (the report
//! credits them there). A blocking read of each would stall every frame on the GPU.

use anyhow::Result;
use std::collections::{HashMap, VecDeque};
use terrain_gpu::granular::{GranularScratch, VolumePass};
use terrain_gpu::{GpuError, SmallReadback};

/// Steps whose counters may be on their way at once.
const RING: usize = 16;

/// What one step measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GranularMeasure {
    /// The scene frame that stepped.
    pub frame: u64,
    /// The u64 sum of the map's heights after the step.
    pub volume: u64,
    /// Material the step's compression removed, in height units.
    pub removed: u64,
}

/// The two rings and the steps on their way (see the module docs).
pub(super) struct Measures {
    volume: SmallReadback,
    removed: SmallReadback,
    /// Steps requested, oldest first: frame, volume request, removed request (`None`: a step
    /// without a scratch removes nothing).
    steps: VecDeque<(u64, u64, Option<u64>)>,
    volumes: HashMap<u64, u64>,
    removals: HashMap<u64, u64>,
}

impl Measures {
    pub(super) fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        Ok(Self {
            volume: SmallReadback::new(device, RING, 8)?,
            removed: SmallReadback::new(device, RING, 8)?,
            steps: VecDeque::new(),
            volumes: HashMap::new(),
            removals: HashMap::new(),
        })
    }

    /// Records the copies of the counters of the step of `frame` (the volume pass's last sum,
    /// the scratch's removed counter) into `encoder`. With every ring buffer on its way (16
    /// steps unread) it waits for the oldest first, so no step goes unmeasured.
    pub(super) fn request(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        frame: u64,
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
        self.steps.push_back((frame, v, r));
        Ok(())
    }

    /// Whether a step's counters are still on their way.
    pub(super) fn in_flight(&self) -> bool {
        !self.steps.is_empty()
    }

    /// The steps whose counters have both arrived, oldest first, never waiting.
    pub(super) fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<GranularMeasure>, GpuError> {
        for (seq, bytes) in self.volume.poll(device)? {
            self.volumes.insert(seq, VolumePass::sum_of(&bytes));
        }
        for (seq, bytes) in self.removed.poll(device)? {
            self.removals.insert(seq, VolumePass::sum_of(&bytes));
        }
        let mut out = Vec::new();
        while let Some(&(frame, v, r)) = self.steps.front() {
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
            out.push(GranularMeasure {
                frame,
                volume,
                removed,
            });
        }
        Ok(out)
    }

    /// Waits (bounded) for every step on its way and hands them over: the end of a window or
    /// of the run.
    pub(super) fn flush(&mut self, device: &wgpu::Device) -> Result<Vec<GranularMeasure>> {
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
        anyhow::ensure!(
            !self.in_flight(),
            "{} granular steps' volumes never came back from the GPU",
            self.steps.len()
        );
        Ok(out)
    }

    /// Waits for the GPU and takes in what arrived (the rings' buffers are free again).
    fn wait(&mut self, device: &wgpu::Device) -> Result<(), GpuError> {
        device.poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: Some(std::time::Duration::from_secs(60)),
        })?;
        for (seq, bytes) in self.volume.poll(device)? {
            self.volumes.insert(seq, VolumePass::sum_of(&bytes));
        }
        for (seq, bytes) in self.removed.poll(device)? {
            self.removals.insert(seq, VolumePass::sum_of(&bytes));
        }
        Ok(())
    }
}
