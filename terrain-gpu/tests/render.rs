//! Clipmap rendering: no cracks from grazing views across every level boundary, and a golden
//! image of a fixed view. Runs on the software adapter in CI.

#[path = "common/scene.rs"]
mod scene;

use glam::{UVec2, Vec2, Vec3};
use scene::Scene;
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{Camera, SkyColors};

/// Magenta: a colour the terrain's shading (greens, browns, greys, white, blue-grey fog)
/// cannot produce.
fn is_sky(p: [u8; 4]) -> bool {
    p[0] > 200 && p[1] < 70 && p[2] > 200
}

/// Counts sky pixels below the terrain's silhouette in each column. With a level camera (no
/// pitch, no roll) every image column is a vertical plane through the eye, and every ray below
/// one that hits a heightfield hits it too: a sky pixel under terrain is a hole in the mesh.
fn holes(image: &terrain_core::Grid<[u8; 4]>) -> (usize, usize) {
    let mut holes = 0;
    let mut terrain = 0;
    for x in 0..image.width() {
        let mut seen_terrain = false;
        for y in 0..image.height() {
            let sky = is_sky(image.get(x, y).unwrap());
            if !sky {
                seen_terrain = true;
                terrain += 1;
            } else if seen_terrain {
                holes += 1;
            }
        }
    }
    (holes, terrain)
}

#[test]
fn no_cracks_from_grazing_views_across_level_boundaries() {
    let Some(ctx) = context_or_skip("no_cracks_from_grazing_views") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let magenta = SkyColors {
        horizon: Vec3::new(1.0, 0.0, 1.0),
        zenith: Vec3::new(1.0, 0.0, 1.0),
    };
    let size = UVec2::new(320, 200);
    // Positions with every parity of the level origins (the L-shaped trims move to each side)
    // and headings along both axes and diagonals.
    let positions = [
        Vec2::new(100.0, 100.0),
        Vec2::new(101.3, 100.2),
        Vec2::new(103.7, 98.6),
        Vec2::new(97.1, 105.9),
        Vec2::new(7.5, 250.5), // near the map's wrap corner
    ];
    let headings = [0.0f32, 0.8, 1.6, 2.4, 3.9, 5.1];
    // The positions put the L-shaped trims on every side at some level.
    let mut sides = std::collections::HashSet::new();
    for xz in &positions {
        let frame = scene
            .layout
            .place(*xz, 1.0, (0.0, scene::HEIGHT), None)
            .unwrap();
        sides.extend(frame.levels.iter().filter_map(|l| l.trim));
    }
    assert_eq!(sides.len(), 4, "trim sides covered: {sides:?}");
    let mut checked = 0;
    for (i, xz) in positions.iter().enumerate() {
        for (j, yaw) in headings.iter().enumerate() {
            let eye = Vec3::new(xz.x, scene.ground(*xz) + 1.5 + i as f32, xz.y);
            let camera = Camera::looking(eye, Vec3::new(yaw.cos(), 0.0, yaw.sin()));
            let (image, triangles) = scene.render(&camera, size, &magenta);
            let (holes, terrain) = holes(&image);
            assert!(
                terrain > (size.x * size.y / 4) as usize,
                "view {i}/{j}: terrain must fill the lower half"
            );
            assert!(triangles > 0);
            if holes > 0 {
                let path = std::env::temp_dir().join(format!("crack_{i}_{j}.png"));
                let _ = terrain_core::io::write_png_rgba8(&path, &image);
                panic!(
                    "view {i}/{j}: {holes} sky pixels inside the terrain (image: {})",
                    path.display()
                );
            }
            checked += 1;
        }
    }
    assert_eq!(checked, positions.len() * headings.len());
}

#[test]
fn the_crack_detector_finds_a_hole() {
    // The detector itself must be able to fail: a terrain image with a sky pixel punched in.
    let mut image = terrain_core::Grid::new(8, 8, [255u8, 0, 255, 255]).unwrap();
    for y in 4..8 {
        for x in 0..8 {
            *image.get_mut(x, y).unwrap() = [90, 120, 60, 255];
        }
    }
    assert_eq!(holes(&image).0, 0);
    *image.get_mut(3, 6).unwrap() = [255, 0, 255, 255];
    assert_eq!(holes(&image).0, 1);
}

/// Golden comparison tolerance: software rasterisers differ slightly between versions and
/// backends, so allow a small mean difference and a few outlying pixels.
const GOLDEN_MEAN_TOLERANCE: f64 = 4.0;
const GOLDEN_OUTLIER_SHARE: f64 = 0.03;

#[test]
fn fixed_view_matches_the_golden_image() {
    let Some(ctx) = context_or_skip("fixed_view_matches_the_golden_image") else {
        return;
    };
    let golden_path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/golden_clipmap.png");
    let golden = terrain_core::io::read_png_rgba8(golden_path, &Default::default())
        .expect("golden image missing or unreadable: regenerate it with `cargo xtask golden`");
    let scene = Scene::new(ctx, 31, 5);
    let camera = scene::golden_camera(&scene);
    let (image, _) = scene.render(&camera, scene::GOLDEN_SIZE, &SkyColors::default());
    assert_eq!(golden.size(), image.size());
    let mut sum = 0.0;
    let mut outliers = 0usize;
    for (a, b) in golden.as_slice().iter().zip(image.as_slice()) {
        let d = (0..3)
            .map(|c| (i32::from(a[c]) - i32::from(b[c])).unsigned_abs())
            .max()
            .unwrap_or(0);
        sum += f64::from(d);
        outliers += usize::from(d > 32);
    }
    let n = image.as_slice().len() as f64;
    let mean = sum / n;
    let share = outliers as f64 / n;
    if mean > GOLDEN_MEAN_TOLERANCE || share > GOLDEN_OUTLIER_SHARE {
        let path = std::env::temp_dir().join("golden_actual.png");
        let _ = terrain_core::io::write_png_rgba8(&path, &image);
        panic!(
            "render differs from the golden: mean {mean:.2}, {:.2} % outliers (actual: {})",
            share * 100.0,
            path.display()
        );
    }
}
