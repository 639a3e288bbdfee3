//! How much deformation the calling thread has done on the CPU (feature `cpu-work`): how a
//! test proves that a GPU path never deforms a CPU copy of the terrain (the GPU is the truth;
//! the CPU only receives read-back regions). Counted where a deformation enters the library:
//! coarse and detail stamps and granular steps. Per thread, so tests running side by side do
//! not see each other's work; the row loops a call spreads over rayon's pool count once, on
//! the calling thread.

use std::cell::Cell;

/// Deformations done on the calling thread since it started or since [`reset`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CpuWork {
    /// Stamps applied to a height map (`apply_stamp`, `apply_stamp_window`).
    pub stamps: u64,
    /// Stamps applied to a detail layer.
    pub detail_stamps: u64,
    /// Steps of the granular simulation.
    pub granular_steps: u64,
}

impl CpuWork {
    /// Whether nothing was deformed.
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }
}

thread_local! {
    static WORK: Cell<CpuWork> = const { Cell::new(CpuWork { stamps: 0, detail_stamps: 0, granular_steps: 0 }) };
}

/// The calling thread's counts.
pub fn cpu_work() -> CpuWork {
    WORK.with(Cell::get)
}

/// Sets the calling thread's counts to zero.
pub fn reset() {
    WORK.with(|w| w.set(CpuWork::default()));
}

pub(crate) fn count(add: impl FnOnce(&mut CpuWork)) {
    WORK.with(|w| {
        let mut work = w.get();
        add(&mut work);
        w.set(work);
    });
}
