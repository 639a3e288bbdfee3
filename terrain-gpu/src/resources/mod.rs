//! GPU-resident terrain data that passes write and renderers read: height and derivative
//! maps, the tile atlas of a streamed world, and the detail layer's tiles.

pub mod atlas;
pub mod detail;
pub mod maps;
pub mod materials;
pub(crate) mod packing;
