//! Adaptive tessellation of a streamed world on the GPU (`TessellationPass::encode_streamed`):
//! decided from a streamed CDLOD tree's node bounds with heights from the tile atlas, it emits
//! the triangles of terrain-lod's `StreamedTessellation::select` (the CPU reference, reading
//! the same tiles through `TileAtlas`), also after a deformation the tree and atlas follow,
//! and draws the world without cracks over an atlas whose tiles are of two levels. On
//! whatever adapter the machine has (lavapipe in CI); without one they skip, or fail under
//! `TERRAIN_REQUIRE_GPU=1`.
//!
//! Tolerances: the split decisions read only the tree's bounds, with the same f32 operations
//! on both sides, so the triangle sets agree but for a decision within rounding of its
//! threshold (a driver may fuse a multiply-add or round a square root differently): 0.1 %
//! allowed, as for a map's tessellation. Heights are `offset + scale * stored`, which a
//! driver may contract into one fused operation, and then morphed: a few ulps of heights
//! under 50 m, so 1e-4 m.

#[path = "common/cracks.rs"]
mod cracks;
#[path = "common/scene.rs"]
#[allow(dead_code)] // the clipmap parts of the shared scene
mod scene;

use cracks::assert_no_holes;
use glam::{IVec2, UVec2, Vec2, Vec3};
use scene::Scene;
use std::collections::HashMap;
use terrain_core::{CoarseMap, Grid, Rect, TileAtlas, TileLayout, TileUploadTarget, WrapMode};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    AtlasConfig, Camera, ClipmapSurface, GpuTessellation, GpuTileAtlas, OffscreenTarget, SkyColors,
    TargetFormat, TerrainStyle, TessDraw, TessRenderer, TessWorld, TessellationPass,
};
use terrain_lod::{
    CdlodConfig, CdlodTree, CdlodView, Frustum, StreamedTessellation, TessConfig, TessTriangle,
};
use terrain_test_support::heights::exact_bounds;

const TILE: u32 = 32;

fn world(map: &CoarseMap) -> TileLayout {
    TileLayout {
        world_size: map.size(),
        tile_size: TILE,
        levels: 4,
        texel_size: map.texel_size(),
        encoding: map.encoding(),
        wrap: WrapMode::Clamp,
        fill: 0,
    }
}

/// Uploads the tiles of `map` that `rect` touches into `atlas`: every level-1 tile (every
/// other texel), level-0 tiles only left of x = 128 (the right half reads level 1). Slots:
/// level 0 from 0, level 1 after them.
fn upload<A: TileUploadTarget>(atlas: &mut A, map: &CoarseMap, rect: Rect)
where
    A::Error: std::fmt::Debug,
{
    let tiles0 = map.size() / TILE;
    for level in 0..2u32 {
        let tiles = tiles0 >> level;
        for y in 0..tiles.y {
            for x in 0..tiles.x {
                let side = (TILE << level) as i32;
                let texels = Rect::new(
                    IVec2::new(x as i32, y as i32) * side,
                    UVec2::splat(side as u32),
                );
                if (level == 0 && x * TILE >= 128) || texels.intersect(&rect).is_none() {
                    continue;
                }
                let t = UVec2::new(x, y);
                let tile = Grid::from_fn(TILE, TILE, |i, j| {
                    let (gx, gy) = ((x * TILE + i) << level, (y * TILE + j) << level);
                    map.grid().get(gx, gy).unwrap()
                })
                .unwrap();
                let slot = level * tiles0.x * tiles0.y + y * tiles.x + x;
                atlas.upload(slot, level, t, &tile).unwrap();
                atlas.map(level, t, Some(slot)).unwrap();
            }
        }
    }
}

fn tree_config() -> CdlodConfig {
    CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 5,
        ..CdlodConfig::default()
    }
}

/// The world as the GPU and the CPU reference hold it.
struct World {
    gpu: GpuTileAtlas,
    cpu: TileAtlas,
    tree: CdlodTree,
}

impl World {
    fn new(scene: &Scene) -> World {
        let layout = world(&scene.map);
        let slots = 2 * (scene.map.size() / TILE).element_product();
        let config = AtlasConfig {
            slots,
            world: layout,
        };
        let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
        let mut gpu = GpuTileAtlas::new(device, queue, &config).unwrap();
        let mut cpu = TileAtlas::new(layout, slots).unwrap();
        let all = Rect::from_size(scene.map.size());
        upload(&mut gpu, &scene.map, all);
        upload(&mut cpu, &scene.map, all);
        let tree = CdlodTree::from_leaf_bounds(
            tree_config(),
            scene.map.size(),
            1.0,
            exact_bounds(&scene.map),
        )
        .unwrap();
        World { gpu, cpu, tree }
    }

    /// The height the GPU pass reads at a texel, computed as it computes it.
    fn height(&self) -> impl Fn(IVec2) -> f32 + Sync + '_ {
        let enc = self.cpu.layout().encoding;
        move |t: IVec2| enc.offset + enc.scale * self.cpu.stored_at(t) as f32
    }
}

fn view_of<'a>(camera: &Camera, size: UVec2, frustum: Option<&'a Frustum>) -> CdlodView<'a> {
    let aspect = size.x as f32 / size.y as f32;
    CdlodView {
        camera: camera.position,
        frustum,
        viewport_width: size.x as f32,
        hfov: 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan(),
    }
}

fn by_corners(tris: &[TessTriangle]) -> HashMap<[i32; 6], [f32; 3]> {
    tris.iter()
        .map(|t| {
            let c = t.map(|v| [v.texel[0] as i32, v.texel[1] as i32]);
            let k = [c[0][0], c[0][1], c[1][0], c[1][1], c[2][0], c[2][1]];
            (k, [t[0].height, t[1].height, t[2].height])
        })
        .collect()
}

/// Asserts the GPU's triangles are the CPU's (see the module docs); returns how many.
fn assert_same(cpu: &[TessTriangle], gpu: &[TessTriangle], what: &str) -> usize {
    let (a, b) = (by_corners(cpu), by_corners(gpu));
    let missing = a.keys().filter(|k| !b.contains_key(*k)).count();
    let extra = b.keys().filter(|k| !a.contains_key(*k)).count();
    assert!(
        (missing + extra) * 1000 <= a.len(),
        "{what}: {} CPU triangles, {} GPU, {missing} missing, {extra} extra",
        a.len(),
        b.len()
    );
    let mut worst = 0.0f32;
    for (k, h) in &a {
        if let Some(g) = b.get(k) {
            for i in 0..3 {
                worst = worst.max((h[i] - g[i]).abs());
            }
        }
    }
    assert!(worst <= 1e-4, "{what}: drawn heights differ by {worst} m");
    a.len()
}

fn tessellate(
    scene: &Scene,
    pass: &mut TessellationPass,
    gpu: &GpuTessellation,
    tess: &StreamedTessellation,
    atlas: &GpuTileAtlas,
    view: &CdlodView<'_>,
) -> Vec<TessTriangle> {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let mut encoder = device.create_command_encoder(&Default::default());
    pass.encode_streamed(
        device,
        queue,
        &mut encoder,
        gpu,
        &TessWorld { tess, atlas },
        view,
    )
    .unwrap();
    queue.submit([encoder.finish()]);
    pass.recall();
    let (tris, overflow) = gpu.read_triangles(device, queue).unwrap();
    assert!(!overflow);
    tris
}

#[test]
fn the_gpu_emits_the_cpu_reference_triangles_before_and_after_a_deformation() {
    let Some(ctx) = context_or_skip("streamed tessellation gpu == cpu") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let mut w = World::new(&scene);
    let mut pass = TessellationPass::new(&scene.ctx.device).unwrap();
    let size = UVec2::new(640, 360);
    let mut compared = 0;
    let views = [
        (Vec3::new(60.0, 45.0, 70.0), Vec3::new(1.0, -0.4, 0.3)),
        (Vec3::new(200.0, 60.0, 20.0), Vec3::new(-0.5, -0.6, 0.8)),
        (Vec3::new(128.0, 300.0, 128.0), Vec3::new(0.0, -1.0, 0.01)),
    ];
    for (morph, patch_size, triangle_width_px) in [
        (true, 32, 4.0),
        (false, 16, 4.0),
        (true, 64, 4.0),
        (true, 32, 12.0),
    ] {
        let config = TessConfig {
            morph,
            patch_size,
            triangle_width_px,
            ..TessConfig::default()
        };
        let tess = StreamedTessellation::new(config, &w.tree).unwrap();
        let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
        let enc = scene.map.encoding();
        let gpu = GpuTessellation::streamed(device, queue, &tess, &w.tree, enc, 1 << 20).unwrap();
        for (eye, dir) in views {
            let camera = Camera::looking(eye, dir);
            let aspect = size.x as f32 / size.y as f32;
            let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
            for culled in [false, true] {
                let view = view_of(&camera, size, culled.then_some(&frustum));
                let cpu = tess.select(&w.tree, &view, &w.height()).unwrap();
                let tris = tessellate(&scene, &mut pass, &gpu, &tess, &w.gpu, &view);
                compared += assert_same(&cpu.triangles, &tris, &format!("{config:?} {eye}"));
            }
        }
        scene.ctx.check().expect("no GPU validation errors");
    }
    assert!(compared > 50_000, "{compared} triangles compared");

    // A rect at full resolution (what another renderer takes over), far from the camera.
    let tess = StreamedTessellation::new(TessConfig::default(), &w.tree).unwrap();
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let enc = scene.map.encoding();
    let gpu = GpuTessellation::streamed(device, queue, &tess, &w.tree, enc, 1 << 20).unwrap();
    let full = (IVec2::new(170, 150), IVec2::new(206, 186));
    pass.set_full_resolution(Some(full));
    for (eye, dir) in views {
        let view = view_of(&Camera::looking(eye, dir), size, None);
        let cpu = tess
            .select_with(&w.tree, &view, &w.height(), Some(full))
            .unwrap();
        let tris = tessellate(&scene, &mut pass, &gpu, &tess, &w.gpu, &view);
        assert_same(&cpu.triangles, &tris, &format!("full resolution {eye}"));
        let plain = tess.select(&w.tree, &view, &w.height()).unwrap();
        assert!(cpu.triangle_count() > plain.triangle_count(), "{eye}");
    }
    pass.set_full_resolution(None);

    // A 30 m deep crater across both levels' tiles: the atlas and the tree follow it (the
    // tree's changed nodes uploaded alone), and the GPU still emits the CPU's triangles.
    let tess = StreamedTessellation::new(TessConfig::default(), &w.tree).unwrap();
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let enc = scene.map.encoding();
    let gpu = GpuTessellation::streamed(device, queue, &tess, &w.tree, enc, 1 << 20).unwrap();
    let camera = Camera::looking(Vec3::new(90.0, 50.0, 60.0), Vec3::new(1.0, -0.5, 0.4));
    let view = view_of(&camera, size, None);
    let before = tess.select(&w.tree, &view, &w.height()).unwrap();
    let crater = Rect::new(IVec2::new(110, 70), UVec2::new(40, 40));
    for y in 70..110 {
        for x in 110..150 {
            *scene.map.grid_mut().get_mut(x, y).unwrap() = 0;
        }
    }
    upload(&mut w.gpu, &scene.map, crater);
    upload(&mut w.cpu, &scene.map, crater);
    w.tree
        .update_leaf_bounds(crater, exact_bounds(&scene.map))
        .unwrap();
    gpu.upload_tree(queue, &w.tree, &[crater]).unwrap();
    let after = tess.select(&w.tree, &view, &w.height()).unwrap();
    assert_ne!(before.triangle_count(), after.triangle_count());
    let tris = tessellate(&scene, &mut pass, &gpu, &tess, &w.gpu, &view);
    assert_same(&after.triangles, &tris, "after the crater");
    scene.ctx.check().expect("no GPU validation errors");
}

#[test]
fn a_tree_or_atlas_of_another_world_is_refused() {
    let Some(ctx) = context_or_skip("streamed tessellation refused") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let w = World::new(&scene);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let tess = StreamedTessellation::new(TessConfig::default(), &w.tree).unwrap();
    let enc = scene.map.encoding();
    let gpu = GpuTessellation::streamed(device, queue, &tess, &w.tree, enc, 1 << 16).unwrap();
    let other =
        CdlodTree::from_leaf_bounds(tree_config(), UVec2::new(256, 200), 1.0, |_| (0.0, 1.0))
            .unwrap();
    assert!(
        gpu.upload_tree(queue, &other, &[Rect::from_size(UVec2::ONE)])
            .is_err()
    );
    let small = TileLayout {
        world_size: UVec2::splat(128),
        ..world(&scene.map)
    };
    let config = AtlasConfig {
        slots: 4,
        world: small,
    };
    let small = GpuTileAtlas::new(device, queue, &config).unwrap();
    let mut pass = TessellationPass::new(device).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    let view = view_of(
        &Camera::looking(Vec3::splat(50.0), Vec3::X),
        UVec2::splat(64),
        None,
    );
    assert!(
        pass.encode_streamed(
            device,
            queue,
            &mut encoder,
            &gpu,
            &TessWorld {
                tess: &tess,
                atlas: &small
            },
            &view
        )
        .is_err()
    );
}

#[test]
fn no_cracks_from_grazing_views_over_tiles_of_two_levels() {
    let Some(ctx) = context_or_skip("streamed tessellation no cracks") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let w = World::new(&scene);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let config = TessConfig {
        patch_size: 16,
        triangle_width_px: 10.0,
        ..TessConfig::default()
    };
    let tess = StreamedTessellation::new(config, &w.tree).unwrap();
    let enc = scene.map.encoding();
    let gpu = GpuTessellation::streamed(device, queue, &tess, &w.tree, enc, 1 << 20).unwrap();
    let mut pass = TessellationPass::new(device).unwrap();
    let mut renderer = TessRenderer::new(device, &TargetFormat::CAPTURE).unwrap();
    let size = UVec2::new(320, 200);
    let magenta = SkyColors {
        horizon: Vec3::new(1.0, 0.0, 1.0),
        zenith: Vec3::new(1.0, 0.0, 1.0),
    };
    let style = TerrainStyle {
        ramp: (0.0, scene::HEIGHT),
        ..TerrainStyle::default()
    };
    // Across the seam between level-0 and level-1 tiles (x = 128 m) and patch edges.
    for (i, xz) in [
        Vec2::new(100.0, 100.0),
        Vec2::new(127.9, 130.6),
        Vec2::new(150.2, 60.5),
    ]
    .iter()
    .enumerate()
    {
        for (j, yaw) in [0.0f32, 0.8, 2.4, 3.9, 5.1].iter().enumerate() {
            let eye = Vec3::new(xz.x, scene.ground(*xz) + 1.5 + i as f32, xz.y);
            let camera = Camera::looking(eye, Vec3::new(yaw.cos(), 0.0, yaw.sin()));
            let aspect = size.x as f32 / size.y as f32;
            let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
            let view = view_of(&camera, size, Some(&frustum));
            scene
                .sky
                .prepare(queue, camera.view_proj_relative(aspect), &magenta)
                .unwrap();
            let draw = TessDraw {
                surface: ClipmapSurface::Atlas { atlas: &w.gpu },
                camera: &camera,
                style: &style,
                target_size: size,
            };
            renderer.prepare(device, queue, &draw).unwrap();
            let target = OffscreenTarget::new(device, size).unwrap();
            let mut encoder = device.create_command_encoder(&Default::default());
            pass.encode_streamed(
                device,
                queue,
                &mut encoder,
                &gpu,
                &TessWorld {
                    tess: &tess,
                    atlas: &w.gpu,
                },
                &view,
            )
            .unwrap();
            {
                let mut rp = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
                scene.sky.draw(&mut rp);
                renderer.draw(&mut rp, &gpu);
            }
            queue.submit([encoder.finish()]);
            pass.recall();
            let image = target.read_rgba8(device, queue).unwrap();
            scene.ctx.check().expect("no GPU validation errors");
            assert_no_holes(&image, &format!("tess_streamed_crack_{i}_{j}"));
        }
    }
}
