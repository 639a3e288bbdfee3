//! The detail layer under CDLOD and the adaptive tessellation: both shade a detail surface
//! with the clipmap's own fragment code (composite normals, parallax march, fade), so the
//! footprints that change the clipmap's frame change theirs, and a layer that adds nothing
//! (all zero tiles, or faded out before the nearest fragment) leaves the frame each draws over
//! the bare coarse-map. On whatever adapter the machine has (lavapipe in CI); without one they
//! skip, or fail under `TERRAIN_REQUIRE_GPU=1`.
//!
//! Tolerances: the detail and coarse pipelines are two shader modules of the same fragment
//! code; with nothing added by the layer they compute the same colour, up to a driver
//! contracting the two modules' arithmetic differently (one 8-bit step). The footprints are
//! 30 cm deep at 3 m from the camera: they must move many pixels a lot (as the clipmap test
//! asks), whatever the rasterizer.

#[path = "common/footprints.rs"]
mod footprints;
#[path = "common/scene.rs"]
#[allow(dead_code)] // the golden view's parts of the shared scene
mod scene;

use footprints::{
    assert_footprints_show, camera, cdlod_for, faded_shading, frame_diff, scene_with_footprints,
};
use glam::UVec2;
use scene::Scene;
use terrain_core::Grid;
use terrain_core::detail::DetailLayout;
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    Camera, CdlodDraw, CdlodRenderer, ClipmapSurface, DetailShading, GpuDetailTiles,
    GpuTessellation, OffscreenTarget, SkyColors, TargetFormat, TerrainStyle, TessDraw,
    TessRenderer, TessellationPass,
};
use terrain_lod::{CdlodTree, CdlodView, Frustum, TessConfig, TessHierarchy};

const SIZE: UVec2 = UVec2::new(256, 160);

/// The LOD modes under test, each with what it needs to draw the scene's map.
enum Lod {
    Cdlod(Box<(CdlodTree, CdlodRenderer)>),
    Tess(
        Box<(
            TessHierarchy,
            GpuTessellation,
            TessellationPass,
            TessRenderer,
        )>,
    ),
}

impl Lod {
    fn cdlod(scene: &Scene) -> Self {
        Lod::Cdlod(Box::new(cdlod_for(scene)))
    }

    fn tess(scene: &Scene) -> Self {
        let config = TessConfig {
            patch_size: 16,
            triangle_width_px: 6.0,
            ..TessConfig::default()
        };
        let tess = TessHierarchy::from_map(&scene.map, None, config).unwrap();
        let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
        let gpu = GpuTessellation::new(device, queue, &tess, 1 << 20).unwrap();
        let pass = TessellationPass::new(device).unwrap();
        let renderer = TessRenderer::new(device, &TargetFormat::CAPTURE).unwrap();
        Lod::Tess(Box::new((tess, gpu, pass, renderer)))
    }

    /// One frame of `camera` over the scene's map, with its detail layer when it has one.
    fn render(&mut self, scene: &Scene, camera: &Camera) -> Grid<[u8; 4]> {
        let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
        let aspect = SIZE.x as f32 / SIZE.y as f32;
        let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
        let view = CdlodView {
            camera: camera.position,
            frustum: Some(&frustum),
            viewport_width: SIZE.x as f32,
            hfov: 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan(),
        };
        let surface = match &scene.detail {
            Some((tiles, shading)) => ClipmapSurface::Detail {
                map: &scene.gpu_map,
                normals: &scene.normals,
                detail: tiles,
                shading,
            },
            None => ClipmapSurface::Coarse {
                map: &scene.gpu_map,
                normals: &scene.normals,
            },
        };
        let style = TerrainStyle {
            ramp: (0.0, scene::HEIGHT),
            ..TerrainStyle::default()
        };
        let sky = terrain_gpu::SkyPass::new(device, &TargetFormat::CAPTURE).unwrap();
        let view_proj = camera.view_proj_relative(aspect);
        sky.prepare(queue, view_proj, &SkyColors::default())
            .unwrap();
        let target = OffscreenTarget::new(device, SIZE).unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        match self {
            Lod::Cdlod(parts) => {
                let (tree, renderer) = &mut **parts;
                let frame = tree.select(&view).unwrap();
                let draw = CdlodDraw {
                    surface,
                    frame: &frame,
                    camera,
                    style: &style,
                    target_size: SIZE,
                };
                renderer.prepare(device, queue, &draw).unwrap();
                let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
                sky.draw(&mut pass);
                renderer.draw(&mut pass);
            }
            Lod::Tess(parts) => {
                let (tess, gpu, tess_pass, renderer) = &mut **parts;
                tess_pass
                    .encode(device, queue, &mut encoder, gpu, tess, &view)
                    .unwrap();
                let draw = TessDraw {
                    surface,
                    camera,
                    style: &style,
                    target_size: SIZE,
                };
                renderer.prepare(device, queue, &draw).unwrap();
                let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
                sky.draw(&mut pass);
                renderer.draw(&mut pass, gpu);
            }
        }
        queue.submit([encoder.finish()]);
        if let Lod::Tess(parts) = self {
            parts.2.recall();
        }
        let image = target.read_rgba8(device, queue).unwrap();
        scene.ctx.check().expect("no GPU validation errors");
        image
    }
}

fn footprints_show_and_a_faded_layer_draws_the_coarse_frame(
    name: &str,
    lod: impl Fn(&Scene) -> Lod,
) {
    let Some(ctx) = context_or_skip(name) else {
        return;
    };
    let (mut scene, _) = scene_with_footprints(ctx, 128);
    let mut lod = lod(&scene);
    let cam = camera(&scene);
    let with_detail = lod.render(&scene, &cam);
    let (tiles, _) = scene.detail.take().unwrap();
    let coarse = lod.render(&scene, &cam);
    scene.detail = Some((tiles, faded_shading()));
    let far = lod.render(&scene, &cam);
    assert_footprints_show(name, &with_detail, &coarse, &far);
}

fn zero_tiles_draw_the_coarse_frame(name: &str, lod: impl Fn(&Scene) -> Lod) {
    let Some(ctx) = context_or_skip(name) else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let mut lod = lod(&scene);
    let cam = camera(&scene);
    let coarse = lod.render(&scene, &cam);
    let layout = DetailLayout::new(scene.map.size(), 1.0, 3, 64).unwrap();
    let tiles = GpuDetailTiles::new(&scene.ctx.device, layout, 1).unwrap();
    scene.detail = Some((tiles, DetailShading::default()));
    let zero = lod.render(&scene, &cam);
    let (max, _) = frame_diff(&zero, &coarse);
    assert!(max <= 1, "{name}: zero detail changes the frame by {max}");
}

#[test]
fn cdlod_draws_the_detail_layers_footprints() {
    footprints_show_and_a_faded_layer_draws_the_coarse_frame("cdlod detail", Lod::cdlod);
}

#[test]
fn cdlod_over_zero_detail_tiles_draws_the_coarse_frame() {
    zero_tiles_draw_the_coarse_frame("cdlod zero detail", Lod::cdlod);
}

#[test]
fn the_tessellation_draws_the_detail_layers_footprints() {
    footprints_show_and_a_faded_layer_draws_the_coarse_frame("tess detail", Lod::tess);
}

#[test]
fn the_tessellation_over_zero_detail_tiles_draws_the_coarse_frame() {
    zero_tiles_draw_the_coarse_frame("tess zero detail", Lod::tess);
}
