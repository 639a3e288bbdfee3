//! Plumbing between the device and everything else: the context and the limits asked for,
//! error scopes, shared pipeline helpers, timing, and getting data back to the CPU.

pub mod compute;
pub mod context;
pub mod detail_readback;
pub mod detail_stream;
pub mod download;
pub mod limits;
pub mod profiler;
pub mod queued_readback;
pub mod readback;
pub mod region_source;
pub mod scope;
pub mod small_readback;
pub mod step_timer;
pub mod submit;
pub mod timer;
pub(crate) mod trace;
