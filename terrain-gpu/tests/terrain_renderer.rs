//! `TerrainRenderer`: every LOD mode draws the scene through one interface (the clipmap's
//! frame equal to the plain `ClipmapRenderer`'s), and after a deformation handed over with
//! `heights_changed` and a flush, CDLOD's and the tessellation's frames (the GPU's triangles
//! included) equal those of renderers built from the deformed map.

#[path = "common/scene.rs"]
#[allow(dead_code)] // the parts of the shared scene other tests use
mod scene;

use glam::{UVec2, Vec2, Vec3};
use scene::{HEIGHT, Scene};
use std::collections::BTreeSet;
use terrain_core::{Blend, GaussianStamp, StampPlacement, apply_stamp};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    Camera, ClipmapSurface, GpuHeightMap, OffscreenTarget, SkyColors, TargetFormat, TerrainFrame,
    TerrainRenderer, TerrainStyle, TerrainView,
};
use terrain_lod::{CdlodConfig, LodMetric, TessConfig};

const SIZE: UVec2 = UVec2::new(320, 180);

fn camera() -> Camera {
    Camera::looking(Vec3::new(60.0, 55.0, 70.0), Vec3::new(1.0, -0.45, 0.6))
}

fn cdlod_config() -> CdlodConfig {
    CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 4,
        metric: LodMetric::Distance,
        ..CdlodConfig::default()
    }
}

/// The three modes over `scene`'s map.
fn renderers(scene: &Scene) -> Vec<TerrainRenderer> {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let f = TargetFormat::CAPTURE;
    let tess = TessConfig {
        triangle_width_px: 6.0,
        ..TessConfig::default()
    };
    vec![
        TerrainRenderer::clipmap(device, &f, scene.layout.clone(), (0.0, HEIGHT)).unwrap(),
        TerrainRenderer::cdlod(device, &f, &scene.map, cdlod_config()).unwrap(),
        TerrainRenderer::tessellated(device, queue, &f, &scene.map, tess, true).unwrap(),
    ]
}

/// Prepares and draws one frame of `renderer` (on `gpu_map`), returning its figures and image.
fn render(
    scene: &Scene,
    gpu_map: &GpuHeightMap<u16>,
    renderer: &mut TerrainRenderer,
) -> (TerrainFrame, terrain_core::Grid<[u8; 4]>) {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let style = TerrainStyle {
        ramp: (0.0, HEIGHT),
        ..TerrainStyle::default()
    };
    let camera = camera();
    let view = TerrainView {
        surface: ClipmapSurface::Coarse {
            map: gpu_map,
            normals: &scene.normals,
        },
        camera: &camera,
        style: &style,
        target_size: SIZE,
    };
    let target = OffscreenTarget::new(device, SIZE).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    renderer
        .prepare(device, queue, &mut encoder, &view)
        .unwrap();
    let frame = renderer.figures(&view).unwrap();
    {
        let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
        renderer.draw(&mut pass);
    }
    queue.submit([encoder.finish()]);
    renderer.recall();
    let image = target.read_rgba8(device, queue).unwrap();
    scene.ctx.check().expect("no GPU validation errors");
    (frame, image)
}

#[test]
fn every_mode_draws_the_scene_through_one_interface() {
    let Some(ctx) = context_or_skip("terrain renderer modes") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let (_, clipmap_triangles) = scene.render(&camera(), SIZE, &SkyColors::default());
    let scene = scene;
    let gpu_map = &scene.gpu_map;
    for mut renderer in renderers(&scene) {
        let (frame, image) = render(&scene, gpu_map, &mut renderer);
        assert_eq!(frame.mode, renderer.mode());
        assert!(frame.triangles > 100 && frame.vertices > 100, "{frame:?}");
        if frame.mode == "clipmap" {
            assert_eq!(
                frame.triangles, clipmap_triangles,
                "the plain clipmap's frame"
            );
        } else {
            assert!(frame.max_screen_error_px.is_some(), "{frame:?}");
        }
        // Drawn on black without a sky: the terrain covers most of the lower half.
        let lit = (SIZE.y / 2..SIZE.y)
            .flat_map(|y| (0..SIZE.x).map(move |x| (x, y)))
            .filter(|&(x, y)| image.get(x, y).is_some_and(|p| p[..3] != [0, 0, 0]))
            .count();
        assert!(
            lit * 10 > (SIZE.x * SIZE.y / 2) as usize * 8,
            "{}: {lit} lit pixels in the lower half",
            frame.mode
        );
        // Two frames make a popping figure for the modes that measure it.
        render(&scene, gpu_map, &mut renderer);
        let popping = renderer.popping_px(&scene.map, &camera(), SIZE);
        assert_eq!(popping.is_some(), frame.mode != "clipmap", "{}", frame.mode);
        assert!(
            popping.is_none_or(|p| p < 0.01),
            "same view twice: {popping:?}"
        );
    }
}

/// Triangles of the tessellation's last GPU output, by corners and drawn heights.
fn gpu_triangles(scene: &Scene, renderer: &TerrainRenderer) -> BTreeSet<[u32; 9]> {
    let gpu = renderer.tessellation().expect("a tessellating renderer");
    let (tris, overflow) = gpu
        .read_triangles(&scene.ctx.device, &scene.ctx.queue)
        .unwrap();
    assert!(!overflow);
    tris.iter()
        .map(|t| {
            let mut k = [0u32; 9];
            for (i, v) in t.iter().enumerate() {
                k[3 * i] = v.texel[0].to_bits();
                k[3 * i + 1] = v.texel[1].to_bits();
                k[3 * i + 2] = v.height.to_bits();
            }
            k
        })
        .collect()
}

#[test]
fn after_a_flush_the_lod_equals_one_built_from_the_deformed_map() {
    let Some(ctx) = context_or_skip("terrain renderer updates") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let mut updated = renderers(&scene);
    // A crater in view, on the CPU map and then on the GPU's copy of it.
    let crater = StampPlacement::new(Vec2::new(110.0, 120.0), Vec2::splat(30.0), -12.0).unwrap();
    let rects = apply_stamp(
        &mut scene.map,
        &mut GaussianStamp::default(),
        &crater,
        Blend::Add,
    )
    .unwrap();
    assert!(!rects.is_empty());
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let gpu_map = GpuHeightMap::from_map(device, queue, &scene.map).unwrap();
    let fresh = renderers(&scene);
    for (mut renderer, mut rebuilt) in updated.drain(..).zip(fresh) {
        renderer.heights_changed(queue, &scene.map, &rects).unwrap();
        renderer.flush(queue).unwrap();
        let (a, _) = render(&scene, &gpu_map, &mut renderer);
        let (b, _) = render(&scene, &gpu_map, &mut rebuilt);
        assert_eq!(a, b, "{}: updated against rebuilt", a.mode);
        if a.mode == "tessellated" {
            // The rows copied to the GPU: its triangles are the rebuilt renderer's.
            let (got, want) = (
                gpu_triangles(&scene, &renderer),
                gpu_triangles(&scene, &rebuilt),
            );
            let differ = got.symmetric_difference(&want).count();
            assert_eq!(differ, 0, "{differ} of {} GPU triangles differ", want.len());
        }
    }
}
