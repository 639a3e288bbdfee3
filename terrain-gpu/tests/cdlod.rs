//! CDLOD rendering: no cracks from grazing views across LOD edges (the morph of terrain-lod's
//! selection, in the vertex shader), the caller's pass, and the instance buffer's growth.

#[path = "common/cracks.rs"]
mod cracks;
#[path = "common/scene.rs"]
#[allow(dead_code)] // the clipmap parts of the shared scene
mod scene;
use cracks::holes;

use glam::{UVec2, Vec2, Vec3};
use scene::Scene;
use std::collections::HashSet;
use terrain_core::TileUploadTarget;
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    AtlasConfig, Camera, CdlodDraw, CdlodRenderer, ClipmapSurface, GpuTileAtlas, OffscreenTarget,
    SkyColors, TargetFormat, TerrainStyle,
};
use terrain_lod::{CdlodConfig, CdlodMesh, CdlodTree, CdlodView, Frustum};

fn render(
    scene: &mut Scene,
    renderer: &mut CdlodRenderer,
    tree: &CdlodTree,
    camera: &Camera,
    size: UVec2,
) -> (terrain_core::Grid<[u8; 4]>, HashSet<u32>) {
    render_on(scene, renderer, tree, camera, size, None)
}

/// [`render`] over `atlas` instead of the scene's coarse-map, when given.
fn render_on(
    scene: &mut Scene,
    renderer: &mut CdlodRenderer,
    tree: &CdlodTree,
    camera: &Camera,
    size: UVec2,
    atlas: Option<&GpuTileAtlas>,
) -> (terrain_core::Grid<[u8; 4]>, HashSet<u32>) {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let aspect = size.x as f32 / size.y as f32;
    let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
    let hfov = 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan();
    let view = CdlodView {
        camera: camera.position,
        frustum: Some(&frustum),
        viewport_width: size.x as f32,
        hfov,
    };
    let frame = tree.select(&view).unwrap();
    let lods = frame.instances.iter().map(|i| i.lod).collect();
    let magenta = SkyColors {
        horizon: Vec3::new(1.0, 0.0, 1.0),
        zenith: Vec3::new(1.0, 0.0, 1.0),
    };
    scene
        .sky
        .prepare(queue, camera.view_proj_relative(aspect), &magenta)
        .unwrap();
    let style = TerrainStyle {
        ramp: (0.0, scene::HEIGHT),
        ..TerrainStyle::default()
    };
    renderer
        .prepare(
            device,
            queue,
            &CdlodDraw {
                surface: match atlas {
                    Some(atlas) => ClipmapSurface::Atlas { atlas },
                    None => ClipmapSurface::Coarse {
                        map: &scene.gpu_map,
                        normals: &scene.normals,
                    },
                },
                frame: &frame,
                camera,
                style: &style,
                target_size: size,
            },
        )
        .unwrap();
    let target = OffscreenTarget::new(device, size).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
        scene.sky.draw(&mut pass);
        renderer.draw(&mut pass);
    }
    queue.submit([encoder.finish()]);
    let image = target.read_rgba8(device, queue).unwrap();
    scene.ctx.check().expect("no GPU validation errors");
    (image, lods)
}

/// The quadtree over the scene's map (leaves of `leaf` texels drawn by a `grid`-cell mesh,
/// `lods` LODs, the finest reaching `finest_range` metres) and a renderer for its mesh.
fn tree_and_renderer(
    scene: &Scene,
    leaf: u32,
    grid: u32,
    lods: u32,
    finest_range: f32,
) -> (CdlodTree, CdlodRenderer) {
    let config = CdlodConfig {
        leaf_size: leaf,
        grid_size: grid,
        lod_count: lods,
        finest_range,
        ..CdlodConfig::default()
    };
    let tree = CdlodTree::from_map(&scene.map, config).unwrap();
    let device = &scene.ctx.device;
    let renderer =
        CdlodRenderer::new(device, &TargetFormat::CAPTURE, &CdlodMesh::new(grid)).unwrap();
    (tree, renderer)
}

#[test]
fn no_cracks_from_grazing_views_across_lod_edges() {
    let Some(ctx) = context_or_skip("cdlod no_cracks_from_grazing_views") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let (tree, mut renderer) = tree_and_renderer(&scene, 16, 16, 5, 6.0);
    let size = UVec2::new(320, 200);
    let positions = [
        Vec2::new(100.0, 100.0),
        Vec2::new(101.3, 100.2),
        Vec2::new(63.9, 130.6),
        Vec2::new(7.5, 250.5), // near the map's wrap corner
    ];
    let mut all_lods = HashSet::new();
    for (i, xz) in positions.iter().enumerate() {
        for (j, yaw) in [0.0f32, 0.8, 1.6, 2.4, 3.9, 5.1].iter().enumerate() {
            let eye = Vec3::new(xz.x, scene.ground(*xz) + 1.5 + i as f32, xz.y);
            let camera = Camera::looking(eye, Vec3::new(yaw.cos(), 0.0, yaw.sin()));
            let (image, lods) = render(&mut scene, &mut renderer, &tree, &camera, size);
            let (holes, terrain) = holes(&image);
            assert!(
                terrain > (size.x * size.y / 4) as usize,
                "view {i}/{j}: terrain must fill the lower half"
            );
            if holes > 0 {
                let path = std::env::temp_dir().join(format!("cdlod_crack_{i}_{j}.png"));
                let _ = terrain_core::io::write_png_rgba8(&path, &image);
                panic!(
                    "view {i}/{j}: {holes} sky pixels inside the terrain (image: {})",
                    path.display()
                );
            }
            all_lods.extend(lods);
        }
    }
    assert!(
        all_lods.len() >= 4,
        "the views cross many LOD edges: {all_lods:?}"
    );
}

#[test]
fn the_instance_buffer_grows_for_a_large_frame() {
    let Some(ctx) = context_or_skip("cdlod the_instance_buffer_grows") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    // Tiny leaves and a long finest range: thousands of quadrants, past the first buffer.
    let (tree, mut renderer) = tree_and_renderer(&scene, 4, 4, 7, 120.0);
    let eye = Vec3::new(128.0, scene.ground(Vec2::splat(128.0)) + 60.0, 128.0);
    let camera = Camera::looking(eye, Vec3::new(0.3, -1.0, 0.2));
    let (image, _) = render(
        &mut scene,
        &mut renderer,
        &tree,
        &camera,
        UVec2::new(96, 64),
    );
    let (_, terrain) = holes(&image);
    assert!(
        terrain > 96 * 64 / 2,
        "looking down: terrain fills the view"
    );
}

/// A fully resident atlas of the scene's map (level 0 only, 32-texel tiles, the map's wrap).
fn full_atlas(scene: &Scene) -> GpuTileAtlas {
    let size = scene.map.size();
    let tiles = size / 32;
    let layout = terrain_core::TileLayout {
        world_size: size,
        tile_size: 32,
        levels: 1,
        texel_size: scene.map.texel_size(),
        encoding: scene.map.encoding(),
        wrap: scene.map.wrap(),
        fill: 0,
    };
    let config = AtlasConfig {
        slots: tiles.x * tiles.y,
        world: layout,
    };
    let mut atlas = GpuTileAtlas::new(&scene.ctx.device, &scene.ctx.queue, &config).unwrap();
    for y in 0..tiles.y {
        for x in 0..tiles.x {
            let t = UVec2::new(x, y);
            let rect = terrain_core::Rect::new((t * 32).as_ivec2(), UVec2::splat(32));
            let tile = scene.map.grid().copy_rect(rect).unwrap();
            let slot = y * tiles.x + x;
            atlas.upload(slot, 0, t, &tile).unwrap();
            atlas.map(0, t, Some(slot)).unwrap();
        }
    }
    atlas
}

/// CDLOD over a streamed world's atlas against CDLOD over the same heights as a coarse-map.
/// Geometry: both read the same u16 heights into the same vertex shader code, so the outline
/// against the sky matches; a few pixels are allowed where a driver contracts the two shader
/// modules' arithmetic differently (an FMA moves a vertex by an ulp, a pixel centre on an edge
/// flips): 0 on lavapipe.
const OUTLINE_TOLERANCE_PX: usize = 24;
/// Shading: the atlas is lit by central differences, the coarse-map by its 4th-order
/// derivative map, so colours differ where the slope changes fast; near-ground views magnify
/// it. A mean of 6 levels of 255 (lavapipe: 3.3; the clipmap's golden view 1.7).
const SHADING_TOLERANCE: f64 = 6.0;

#[test]
fn cdlod_over_a_tile_atlas_draws_like_cdlod_over_the_coarse_map_without_cracks() {
    let Some(ctx) = context_or_skip("cdlod over an atlas") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let (tree, mut renderer) = tree_and_renderer(&scene, 16, 16, 5, 6.0);
    let atlas = full_atlas(&scene);
    let size = UVec2::new(240, 160);
    let (mut worst, mut worst_outline) = (0.0f64, 0usize);
    for (i, xz) in [Vec2::new(100.0, 100.0), Vec2::new(63.9, 130.6)]
        .iter()
        .enumerate()
    {
        for (j, yaw) in [0.0f32, 1.6, 3.9].iter().enumerate() {
            let eye = Vec3::new(xz.x, scene.ground(*xz) + 1.5 + i as f32, xz.y);
            let camera = Camera::looking(eye, Vec3::new(yaw.cos(), -0.05, yaw.sin()));
            let (coarse, _) = render_on(&mut scene, &mut renderer, &tree, &camera, size, None);
            let (on_atlas, lods) = render_on(
                &mut scene,
                &mut renderer,
                &tree,
                &camera,
                size,
                Some(&atlas),
            );
            let (cracks, terrain) = holes(&on_atlas);
            assert_eq!(cracks, 0, "view {i}/{j}: sky through the atlas surface");
            assert!(terrain > (size.x * size.y / 4) as usize, "view {i}/{j}");
            assert!(lods.len() >= 2, "view {i}/{j}: one LOD only");
            // Geometry: the sky shows through the same pixels.
            let sky = |p: &[u8; 4]| p[0] > 250 && p[1] < 5 && p[2] > 250;
            let outline = coarse
                .as_slice()
                .iter()
                .zip(on_atlas.as_slice())
                .filter(|(a, b)| sky(a) != sky(b))
                .count();
            worst_outline = worst_outline.max(outline);
            // Shading: the mean colour difference.
            let sum: f64 = coarse
                .as_slice()
                .iter()
                .zip(on_atlas.as_slice())
                .map(|(a, b)| {
                    let d = (0..3).map(|c| (i32::from(a[c]) - i32::from(b[c])).unsigned_abs());
                    f64::from(d.max().unwrap_or(0))
                })
                .sum();
            worst = worst.max(sum / coarse.as_slice().len() as f64);
        }
    }
    eprintln!(
        "cdlod atlas vs coarse: worst mean colour difference {worst:.2}, \
         worst outline difference {worst_outline} px"
    );
    assert!(
        worst_outline <= OUTLINE_TOLERANCE_PX,
        "outline differs by {worst_outline} px"
    );
    assert!(worst <= SHADING_TOLERANCE, "mean difference {worst:.2}");
    scene.ctx.check().expect("no GPU validation errors");
}
