//! Volume-preserving granular deformation (Persson 2019 chapter 4): the CPU reference of every
//! pass, in integer, deterministic, order-independent form that a compute shader reproduces
//! bit for bit.
//!
//! Heights are a [`crate::FixedPointMap`] (u32, `x 10 000` by default, sec. 4.3). One step, per
//! [`ActiveArea`] (sec. 4.5), runs:
//! 1. [`depth_from_below`] (sec. 4.1.2): lowest object surface over each column, in height units.
//! 2. [`penetration_texture`] (sec. 4.1.3, table 4.1): [`ColumnKind`] and penetration per column.
//! 3. [`jump_flood`] (sec. 2.3.1, 4.1.4): closest seed per column, hashed neighbour order (or,
//!    on the CPU, the exact [`exact_nearest_seed`]; see [`DistanceTransform`]).
//! 4. displacement (sec. 4.1.4): [`displace_iterative`], [`displace_closest_seed`] or
//!    [`displace_multiple_targets`].
//! 5. slope evening (sec. 4.1.5): [`even_out_slopes_interleaved`] or [`even_out_slopes_scatter`].
//!
//! Then [`symmetric_normals`] / [`blur_normals`] and [`float_heights`] for rendering.
//! [`GranularSim`] chains the steps.
//!
//! ```
//! use glam::{Affine3A, Vec3};
//! use terrain_core::{FixedPointMap, Grid};
//! use terrain_core::granular::{GranularObject, GranularParams, GranularSim, TriMesh};
//!
//! // 64 x 64 columns of 1 m of snow at 0.1 m per texel.
//! let map = FixedPointMap::fixed_point(Grid::new(64, 64, 10_000)?, 10_000, 0.1)?;
//! let mut sim = GranularSim::new(map, GranularParams::snow())?;
//! let before = sim.map().raw_sum();
//! let wheel = TriMesh::wheel(0.5, 0.2, 24)?;
//! let at = Affine3A::from_translation(Vec3::new(3.2, 1.3, 3.2)); // sinks 0.2 m into the snow
//! let report = sim.step(&[GranularObject::new(&wheel, at)])?;
//! assert_eq!(report.volume, before); // compression 0 keeps the volume exactly
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod active;
mod arrivals;
mod depth;
mod displace;
mod edt;
mod error;
mod handover;
mod jfa;
mod mesh;
mod normals;
mod params;
mod penetration;
mod sim;
mod slope;
mod stepper;

pub use active::{ActiveArea, merge_active_areas, object_active_area};
pub use arrivals::{GranularArrivals, StepMeasure};
pub use depth::{
    DepthTriangle, MAX_HEIGHT_FRAC_BITS, MAX_TRIANGLE_SPAN, NO_OBJECT, SUBTEXEL_BITS,
    depth_from_below, depth_from_below_into, depth_triangle, depth_triangles, object_footprint,
    rasterize_triangle,
};
pub use displace::{
    MAX_TARGETS, MULTI_TARGET_CHUNK, displace_closest_seed, displace_iterative,
    displace_multiple_targets, iterative_pass, lower_neighbour_counts,
};
pub use edt::exact_nearest_seed;
pub use error::GranularError;
pub use handover::Handover;
pub use jfa::{
    JFA_OFFSETS, brute_force_distance, distance_grid, jfa_hash, jfa_init, jfa_neighbour_order,
    jfa_pass, jfa_pass_reference, jfa_steps, jump_flood, jump_flood_reference, pcg_hash,
    seed_distance,
};
pub use mesh::{GranularObject, MAX_COORDINATE_M, MAX_MESH_ELEMENTS, TriMesh};
pub use normals::{blur_normals, float_heights, symmetric_normals};
pub use params::{
    DisplacementMethod, DistanceMetric, DistanceTransform, GranularParams, MAX_ITERATIONS,
    MAX_MARGIN, SlopeMethod, mul_q15,
};
pub use penetration::{ColumnKind, NO_SEED, Penetration, penetration_texture};
pub use sim::{AreaMode, GranularSim, StepReport};
pub use slope::{
    column_outflow, even_out_slopes_interleaved, even_out_slopes_scatter, slope_amounts_pass,
    slope_apply_pass, slope_scatter_pass,
};
pub use stepper::{CpuOnly, GranularStepper, SHIFT_TAG};

use crate::Rect;
use glam::UVec2;

/// Largest side of a map or area in texels: squared Euclidean distances stay below 2^31.
pub const MAX_SIDE: u32 = 32_768;

/// Checks that `area` is non-empty, inside a map of `map_size` and at most [`MAX_SIDE`] a side.
pub(crate) fn check_area(area: Rect, map_size: UVec2) -> Result<(), GranularError> {
    if area.is_empty() || !Rect::from_size(map_size).contains_rect(&area) {
        return Err(GranularError::RegionOutsideMap {
            rect: area,
            map_size,
        });
    }
    jfa::check_side(area.size)
}
