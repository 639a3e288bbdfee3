//! Renderers that draw into the caller's render pass (sky, clipmap, CDLOD, tessellated and
//! refined geometry, with the compute passes that make their triangles), and the camera and
//! target formats they draw for.

pub mod camera;
pub mod cdlod;
pub mod clipmap;
pub(crate) mod frame;
pub mod offscreen;
pub mod refine;
pub mod sky;
pub(crate) mod surface;
pub mod target;
pub mod terrain;
pub mod tessellation;
