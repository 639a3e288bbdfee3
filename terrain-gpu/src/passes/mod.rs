//! Compute passes that change or derive terrain data on the GPU: stamps and their spill,
//! normals, density maps, material effects, and the detail probe.

pub mod density;
pub mod detail_probe;
pub mod material_effect;
pub mod normals;
pub mod spill;
pub mod stamp;
