//! GPU-resident terrain data that passes write and renderers read: height and derivative
//! maps, the tile atlas of a streamed world, the detail layer's tiles, and the material
//! images and layers the renderers shade with (a streamed world's paint and colour in overlay
//! atlases), and the hole mask they leave out.

pub mod atlas;
pub mod detail;
pub mod hole_mask;
pub mod maps;
pub mod material_layer;
pub mod materials;
pub mod overlay_atlas;
pub(crate) mod packing;
pub(crate) mod window;
