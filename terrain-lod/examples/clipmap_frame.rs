//! One frame of geometry-clipmap level of detail, as a renderer would use it: the shared mesh
//! of a layout (Flower 2010, eq. 3.1), the levels placed around a camera and the parts culled
//! against its view frustum, and the level morph near each level's outer edge.
//!
//! `cargo run -p terrain-lod --example clipmap_frame -- [N] [LEVELS]` (default 255 and 5).

use glam::{Mat4, Vec2, Vec3};
use terrain_lod::morph::{MorphLevel, default_morph_width, morphed_height};
use terrain_lod::{ClipmapLayout, Frustum};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let n: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(255);
    let levels: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(5);
    let layout = ClipmapLayout::new(n, levels)?;
    let mesh = layout.mesh();
    println!(
        "N = {n}, {levels} levels: {} vertices, {} indices shared by every level",
        mesh.vertices.len(),
        mesh.indices.len()
    );

    // A camera 2 m above ground at (100, 100) m looking along +X, on a map of 0.1 m texels.
    let eye = Vec3::new(100.0, 2.0, 100.0);
    let view: Mat4 =
        glam::camera::rh::view::look_to_mat4(eye, Vec3::new(1.0, -0.1, 0.2).normalize(), Vec3::Y);
    let proj: Mat4 =
        glam::camera::rh::proj::directx::perspective(60f32.to_radians(), 16.0 / 9.0, 0.1, 5000.0);
    let frustum = Frustum::from_view_proj(proj * view);
    let all = layout.place(Vec2::new(eye.x, eye.z), 0.1, (0.0, 12.0), None)?;
    let culled = layout.place(Vec2::new(eye.x, eye.z), 0.1, (0.0, 12.0), Some(&frustum))?;
    for level in &culled.levels {
        println!(
            "level {}: origin {} texels, {} texel(s) per grid step, L-trim {:?}",
            level.level, level.origin, level.scale, level.trim
        );
    }
    println!(
        "{} part instances ({} triangles) without culling, {} ({} triangles) in the frustum",
        all.draws.len(),
        all.triangle_count(mesh),
        culled.draws.len(),
        culled.triangle_count(mesh)
    );

    // The morph: a vertex on level 1's outer edge takes the coarser level's height exactly.
    let height = |t: glam::IVec2| (t.x as f32 * 0.05).sin() + (t.y as f32 * 0.03).cos();
    let level1 = &culled.levels[1.min(culled.levels.len() - 1)];
    let edge = level1.origin + glam::IVec2::new(level1.scale as i32, 0);
    let camera_texel = Vec2::new(eye.x, eye.z) / 0.1;
    let morphed = morphed_height(
        edge,
        camera_texel,
        &MorphLevel {
            scale: level1.scale,
            n,
            width: default_morph_width(n),
            coarsest: levels <= 2,
        },
        height,
    );
    println!(
        "vertex {edge} on level {}'s outer edge: height {:.4}, morphed {morphed:.4}",
        level1.level,
        height(edge)
    );
    Ok(())
}
