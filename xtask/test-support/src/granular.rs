//! The granular test rig shared by terrain-core's CPU reference tests and terrain-gpu's GPU
//! step tests: the same bumpy map, moving objects and parameters on both sides, so that a GPU
//! test reproduces exactly the scene the CPU reference is checked on.

use glam::{Affine3A, Quat, UVec2, Vec3};
use terrain_core::granular::{GranularObject, GranularParams, Penetration, TriMesh, pcg_hash};
use terrain_core::{FixedPointMap, Grid};

/// Fixed-point units per metre of the rig's maps.
pub const UNITS: u32 = 10_000;

/// A `size` x `size` map of 1 m of material plus up to 4 cm of hashed bumps.
pub fn bumpy_map(size: u32, texel: f32) -> FixedPointMap {
    let grid = Grid::from_fn(size, size, |x, y| {
        10_000 + pcg_hash(x * 7919 + y * 104_729) % 400
    })
    .expect("grid");
    FixedPointMap::fixed_point(grid, UNITS, texel).expect("map")
}

/// A penetration grid with nothing in it.
pub fn empty_pen(size: UVec2) -> Grid<Penetration> {
    Grid::new(
        size.x,
        size.y,
        Penetration {
            seed_x: 0,
            seed_y: 0,
            kind: 0,
            penetration: 0,
        },
    )
    .expect("grid")
}

/// The three meshes the rig moves over the map.
#[derive(Debug)]
pub struct Meshes {
    /// A box 0.8 x 0.6 x 0.5 m.
    pub cube: TriMesh,
    /// A wheel of radius 0.35 m.
    pub wheel: TriMesh,
    /// A foot 0.3 m long.
    pub foot: TriMesh,
}

/// The rig's meshes.
pub fn meshes() -> Meshes {
    Meshes {
        cube: TriMesh::cuboid(Vec3::new(0.4, 0.3, 0.25)).expect("box"),
        wheel: TriMesh::wheel(0.35, 0.15, 16).expect("wheel"),
        foot: TriMesh::foot(0.3, 0.12, 0.1).expect("foot"),
    }
}

/// Three objects on pseudo-random smooth paths over a map of `extent` metres at `frame`,
/// sinking up to 0.2 m into 1 m of material.
pub fn objects_at(m: &Meshes, frame: u32, extent: f32) -> Vec<GranularObject<'_>> {
    let mut out = Vec::new();
    for (k, mesh) in [&m.cube, &m.wheel, &m.foot].into_iter().enumerate() {
        let k = k as u32;
        let t = frame as f32 * 0.01 + k as f32 * 2.1;
        let wob = (pcg_hash(frame / 50 + k * 1000) % 1000) as f32 / 1000.0;
        let x = extent * (0.5 + 0.38 * (t * (0.7 + 0.1 * k as f32)).sin());
        let z = extent * (0.5 + 0.38 * (t * 1.3 + wob * 0.2).cos());
        let bottom = 0.8 + 0.1 * (t * 3.0).sin();
        let lowest = mesh
            .vertices()
            .iter()
            .map(|v| v.y)
            .fold(f32::INFINITY, f32::min);
        let tr = Affine3A::from_rotation_translation(
            Quat::from_rotation_y(t),
            Vec3::new(x, bottom - lowest, z),
        );
        out.push(GranularObject::new(mesh, tr));
    }
    out
}

/// Snow with two slope passes and a 6-texel active-area margin: quick enough for thousands
/// of frames.
pub fn small_params() -> GranularParams {
    GranularParams {
        num_iterations_even_out_slopes: 2,
        active_area_margin: 6,
        ..GranularParams::snow()
    }
}
