//! Fuzz target `physics`: every public query of terrain-physics (HeightfieldCollider height,
//! normal, raycast and sphere contact; BoundedGround; CameraBody and SphereBody steps;
//! CameraPath and CameraRig; CollisionWindow; field construction) with inputs over the whole finite f32 range, NaN and
//! infinities, positions far outside the map, huge distances and radii, and texel sizes from
//! `f32::MIN_POSITIVE` to `f32::MAX`. Every call must return `Ok` or `Err` (`Err` whenever an
//! input is not finite) within [`CALL_LIMIT`]; a call that takes longer twice in a row fails,
//! and one that does not return is caught by the harness's watchdog. The target is
//! time-bounded (`TERRAIN_FUZZ_SECONDS`, default 2 s; `cargo xtask fuzz --seconds N` runs it
//! longer, in release mode); see `terrain_test_support::fuzz` for the seed, replay and class
//! selection variables.
//!
//! Input classes are cut along the known defects, so that the classes a defect hangs or
//! panics in can be switched off alone ([`DISABLED`]) while every other input keeps running;
//! the boundaries are [`WALK_CELLS`] (cells a ray may cross), [`REACH_TEXELS`] (how far a
//! sphere's search may reach) and [`FAR_TEXELS`] (coordinates in texels).

#[path = "fuzz/bodies.rs"]
mod bodies;
#[path = "fuzz/bounded.rs"]
mod bounded;
#[path = "fuzz/collider.rs"]
mod collider;
#[path = "fuzz/fields.rs"]
mod fields;
#[path = "fuzz/inputs.rs"]
mod inputs;
#[path = "fuzz/rigs.rs"]
mod rigs;
#[path = "fuzz/window.rs"]
mod window;

use fields::Ctx;
use std::time::Duration;
use terrain_test_support::fuzz::{self, Case, Class, Target};

/// The longest a single query may take. Queries take microseconds; a query over a bounded
/// input that takes 50 ms is a defect.
const CALL_LIMIT: Duration = Duration::from_millis(50);

/// Most cells a ray of the enabled classes may cross (`max_dist * (|d.x| + |d.z|) / texel`):
/// a few milliseconds of walking. Longer walks are the class `ray_long_walk`.
const WALK_CELLS: f64 = 1e5;

/// Largest reach of a sphere query of the enabled classes, in texels: the depth of a centre
/// below the ground, or the smaller of its height above the ground and its radius (the search
/// visits `(2 * reach + 1)^2` cells). Deeper or wider are `sphere_deep_below` and
/// `sphere_huge_radius`.
const REACH_TEXELS: f64 = 256.0;

/// Texel coordinates (local to the field) from this magnitude on are "far": cell indices of
/// this size are near the ends of `i64`. Far inputs are the `*_far*` classes.
const FAR_TEXELS: f64 = 4.611_686_018_427_388e18; // 2^62

/// Classes to skip, each with the defect that makes it hang or panic (a class is listed here
/// only while its defect is being fixed; `TERRAIN_FUZZ_CLASSES=<name>` runs it anyway).
const DISABLED: &[(&str, &str)] = &[
    // Empty: the three defects these classes found (a near-horizontal ray walking practically
    // forever, a sphere far below the ground visiting (2 depth / texel)^2 cells, far positions
    // overflowing cell indices) are fixed; every class runs.
];

#[test]
fn fuzz_physics() {
    fn c(name: &'static str, f: fn(&Ctx, &mut Case) -> Result<(), String>) -> Class<Ctx> {
        Class { name, run: f }
    }
    fuzz::run(
        Target {
            name: "physics",
            // A case makes up to about twenty calls, each within CALL_LIMIT.
            per_case_limit: CALL_LIMIT * 20,
            classes: vec![
                c("height_normal_whole_range", collider::height_normal),
                c("non_finite_inputs", collider::non_finite_inputs),
                c("ray_near_map", collider::ray_near_map),
                c("ray_whole_range", collider::ray_whole_range),
                c("ray_long_walk", collider::ray_long_walk),
                c("ray_far_origin", collider::ray_far_origin),
                c("sphere_near_surface", collider::sphere_near_surface),
                c("sphere_whole_range", collider::sphere_whole_range),
                c("sphere_deep_below", collider::sphere_deep_below),
                c("sphere_huge_radius", collider::sphere_huge_radius),
                c("sphere_far_center", collider::sphere_far_center),
                c("bounded_ground_near", bounded::bounded_ground_near),
                c("bounded_ground_far", bounded::bounded_ground_far),
                c("camera_body_whole_range", bodies::camera_body),
                c("camera_bounded_ground", bodies::camera_bounded_ground),
                c("sphere_body_near", bodies::sphere_body_near),
                c("sphere_body_whole_range", bodies::sphere_body_whole_range),
                c("camera_path", rigs::camera_path),
                c("camera_follower", rigs::camera_follower),
                c("collision_window", window::collision_window),
                c("field_construction", window::field_construction),
            ],
            disabled: DISABLED,
        },
        fields::Ctx::new(),
    );
}
