//! Compute passes that change or derive terrain data on the GPU: stamps (on a map, and on a
//! streamed world's atlas tiles with their readback) and their spill, normals, a map deformed
//! with its normals following, density maps, material effects, and the detail probe.

pub mod atlas_stamper;
pub mod deformable_map;
pub mod density;
pub mod detail_probe;
pub mod material_effect;
pub mod normals;
pub mod spill;
pub mod stamp;
