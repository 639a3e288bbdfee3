//! The terrain point under the cursor: a ray from the camera through the cursor's pixel,
//! marched against the CPU copy of the map (terrain-core's bilinear heights, the surface the
//! clipmap draws, repeats included) and refined by bisection.

use glam::{Vec2, Vec3, Vec4};
use terrain_core::{CoarseMap, bilinear};
use terrain_gpu::Camera;

/// How far a ray looks for the ground (metres).
const MAX_DISTANCE: f32 = 2_000.0;
/// Bisection steps after the march brackets the crossing.
const REFINE_STEPS: u32 = 24;

/// The unit direction (world) of the ray from `camera` through `cursor` (pixels from the top
/// left of a `size` window).
pub fn cursor_ray(camera: &Camera, cursor: Vec2, size: Vec2) -> Option<Vec3> {
    let ndc = Vec2::new(2.0 * cursor.x / size.x - 1.0, 1.0 - 2.0 * cursor.y / size.y);
    // Camera-relative matrix: the eye is at the origin, so the far point is the direction.
    let inv = camera.view_proj_relative(size.x / size.y).inverse();
    let far = inv * Vec4::new(ndc.x, ndc.y, 1.0, 1.0);
    let near = inv * Vec4::new(ndc.x, ndc.y, 0.0, 1.0);
    let dir = far.truncate() / far.w - near.truncate() / near.w;
    let dir = dir.normalize_or_zero();
    (dir != Vec3::ZERO && dir.is_finite()).then_some(dir)
}

/// The first point where the ray from `origin` along unit `dir` meets the map's surface, or
/// `None` within [`MAX_DISTANCE`].
pub fn hit_terrain(map: &CoarseMap, origin: Vec3, dir: Vec3) -> Option<Vec3> {
    let above = |t: f32| {
        let p = origin + dir * t;
        bilinear(map, Vec2::new(p.x, p.z)).map(|h| p.y - h).ok()
    };
    if above(0.0)? <= 0.0 {
        return Some(origin);
    }
    let step = map.texel_size() * 0.5;
    let mut t0 = 0.0;
    let mut t = step;
    while t <= MAX_DISTANCE {
        if above(t)? <= 0.0 {
            let mut t1 = t;
            for _ in 0..REFINE_STEPS {
                let mid = 0.5 * (t0 + t1);
                if above(mid)? <= 0.0 {
                    t1 = mid;
                } else {
                    t0 = mid;
                }
            }
            return Some(origin + dir * t1);
        }
        t0 = t;
        // Coarser steps far away, where a texel is a fraction of a pixel.
        t += step.max(t * 0.002);
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use terrain_core::{Grid, HeightEncoding};

    #[test]
    fn the_centre_ray_hits_a_flat_map_where_the_camera_looks() {
        let enc = HeightEncoding::new(0.01, 0.0).unwrap();
        let map = CoarseMap::coarse(Grid::new(64, 64, 100u16).unwrap(), enc, 0.5).unwrap();
        let camera = Camera::looking(Vec3::new(10.0, 3.0, 10.0), Vec3::new(1.0, -1.0, 0.0));
        let size = Vec2::new(320.0, 240.0);
        let dir = cursor_ray(&camera, size * 0.5, size).unwrap();
        assert!((dir - Vec3::new(1.0, -1.0, 0.0).normalize()).length() < 1e-3);
        let hit = hit_terrain(&map, camera.position, dir).unwrap();
        // Ground at 1 m: 2 m down, so 2 m along +X.
        assert!((hit - Vec3::new(12.0, 1.0, 10.0)).length() < 0.01, "{hit}");
        // Looking up: no hit.
        assert!(hit_terrain(&map, camera.position, Vec3::Y).is_none());
    }
}
