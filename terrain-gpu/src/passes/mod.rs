//! Compute passes that change or derive terrain data on the GPU: stamps and their spill,
//! normals, density maps, and the detail probe.

pub mod density;
pub mod detail_probe;
pub mod normals;
pub mod spill;
pub mod stamp;
