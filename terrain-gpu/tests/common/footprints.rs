//! The shared scene with footprints pressed into a detail layer, and a camera looking at
//! them: the view the detail surface tests draw under every renderer.

use super::scene::Scene;
use glam::{Vec2, Vec3};
use terrain_core::Grid;
use terrain_core::detail::{DetailLayer, DetailLayout};
use terrain_core::{Blend, GaussianStamp, StampPlacement};
use terrain_gpu::{Camera, DetailShading, GpuDetailTiles};

/// The shared scene's 256 m map with a detail layer refined x8 (12.5 cm texels) in tiles of
/// `tile` texels, footprints pressed 30 cm deep along a walk in front of `camera()` (starting at
/// the edge between tile rows 7 and 8 of 128-texel tiles), every touched tile on the GPU.
pub fn scene_with_footprints(ctx: terrain_gpu::GpuContext, tile: u32) -> (Scene, DetailLayer) {
    let scene = Scene::new(ctx, 31, 5);
    let layout = DetailLayout::new(scene.map.size(), 1.0, 8, tile).unwrap();
    let mut layer = DetailLayer::new(layout).unwrap();
    let mut foot = GaussianStamp::default();
    let mut touched = Vec::new();
    for i in 0..10 {
        let side = if i % 2 == 0 { -0.4 } else { 0.4 };
        // From z = 128 m on: in tile row 8 of 128-texel tiles (16 m), next to row 7's zeros.
        let c = Vec2::new(120.0 + side, 128.6 + 1.2 * i as f32);
        let p = StampPlacement::new(c, Vec2::new(0.8, 1.2), -0.3).unwrap();
        let change = layer
            .apply_stamp(&mut foot, &p, Blend::Min { base_m: 0.0 })
            .unwrap();
        touched.extend(change.tiles.iter().map(|(t, _)| *t));
    }
    assert!(!touched.is_empty());
    let mut tiles = GpuDetailTiles::new(&scene.ctx.device, layout, 16).unwrap();
    for t in touched {
        tiles.load(&scene.ctx.queue, t, layer.tile(t)).unwrap();
    }
    let mut scene = scene;
    scene.detail = Some((tiles, DetailShading::default()));
    (scene, layer)
}

/// Standing 3 m above the footprints' start, looking along the walk and down.
pub fn camera(scene: &Scene) -> Camera {
    let xz = Vec2::new(120.0, 124.0);
    let eye = Vec3::new(xz.x, scene.ground(xz) + 3.0, xz.y);
    Camera::looking(eye, Vec3::new(0.0, -0.6, 1.0))
}

/// A layer faded out before the nearest fragment of [`camera`]'s view: it must add nothing.
pub fn faded_shading() -> DetailShading {
    DetailShading {
        fade_start_m: 0.5,
        fade_end_m: 1.0,
        ..DetailShading::default()
    }
}

/// The largest channel difference and the pixels that differ by more than 8.
pub fn frame_diff(a: &Grid<[u8; 4]>, b: &Grid<[u8; 4]>) -> (u8, usize) {
    let d = a
        .as_slice()
        .iter()
        .zip(b.as_slice())
        .map(|(p, q)| (0..4).map(|c| p[c].abs_diff(q[c])).max().unwrap_or(0));
    d.fold((0, 0), |(max, strong), d| {
        (max.max(d), strong + usize::from(d > 8))
    })
}

/// The footprints (30 cm deep, 3 m from the camera) change the frame drawn `without` them
/// a lot, whatever the rasterizer; the `faded` layer's frame is `without`'s, up to a driver
/// contracting two shader modules' arithmetic differently (one 8-bit step).
pub fn assert_footprints_show(
    name: &str,
    with: &Grid<[u8; 4]>,
    without: &Grid<[u8; 4]>,
    faded: &Grid<[u8; 4]>,
) {
    let (max, strong) = frame_diff(with, without);
    assert!(
        max > 40 && strong > 250,
        "{name}: the footprints hardly change the frame: max {max}, {strong} pixels"
    );
    let (max, _) = frame_diff(faded, without);
    assert!(
        max <= 1,
        "{name}: a faded-out layer changes the frame by {max}"
    );
}

/// CDLOD over the scene's map, fine enough near [`camera`] to show the footprints: the tree and
/// its renderer.
pub fn cdlod_for(scene: &Scene) -> (terrain_lod::CdlodTree, terrain_gpu::CdlodRenderer) {
    let config = terrain_lod::CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 5,
        finest_range: 6.0,
        ..terrain_lod::CdlodConfig::default()
    };
    let tree = terrain_lod::CdlodTree::from_map(&scene.map, config).unwrap();
    let mesh = terrain_lod::CdlodMesh::new(16);
    let target = terrain_gpu::TargetFormat::CAPTURE;
    let renderer = terrain_gpu::CdlodRenderer::new(&scene.ctx.device, &target, &mesh).unwrap();
    (tree, renderer)
}
