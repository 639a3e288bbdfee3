//! Adaptive tessellation on the GPU: the compute pass emits the triangles of terrain-lod's CPU
//! reference (same set, same drawn heights), also where a view refines through every level,
//! draws them without cracks from grazing views across patch edges, and bounds its output and
//! its level queues.

#[path = "common/cracks.rs"]
mod cracks;
#[path = "common/scene.rs"]
#[allow(dead_code)] // the clipmap parts of the shared scene
mod scene;
use cracks::assert_no_holes;

use glam::{UVec2, Vec2, Vec3};
use scene::Scene;
use std::collections::HashMap;
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    Camera, ClipmapSurface, GpuTessellation, OffscreenTarget, SkyColors, TargetFormat,
    TerrainStyle, TessDraw, TessRenderer, TessellationPass,
};
use terrain_lod::{
    CdlodView, DensityMap, DensityParams, Frustum, TessConfig, TessHierarchy, TessTriangle,
};

fn view_of<'a>(camera: &Camera, size: UVec2, frustum: Option<&'a Frustum>) -> CdlodView<'a> {
    let aspect = size.x as f32 / size.y as f32;
    CdlodView {
        camera: camera.position,
        frustum,
        viewport_width: size.x as f32,
        hfov: 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan(),
    }
}

/// Triangles by their corners (exact integers), with their drawn heights.
fn by_corners(tris: &[TessTriangle]) -> HashMap<[i32; 6], [f32; 3]> {
    tris.iter()
        .map(|t| {
            let k = [
                t[0].texel[0] as i32,
                t[0].texel[1] as i32,
                t[1].texel[0] as i32,
                t[1].texel[1] as i32,
                t[2].texel[0] as i32,
                t[2].texel[1] as i32,
            ];
            (k, [t[0].height, t[1].height, t[2].height])
        })
        .collect()
}

/// Runs the pass for `view` and reads its triangles back, with whether it overflowed.
fn tessellate(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    pass: &mut TessellationPass,
    gpu: &GpuTessellation,
    tess: &TessHierarchy,
    view: &CdlodView<'_>,
) -> (Vec<TessTriangle>, bool) {
    let mut encoder = device.create_command_encoder(&Default::default());
    pass.encode(device, queue, &mut encoder, gpu, tess, view)
        .unwrap();
    queue.submit([encoder.finish()]);
    pass.recall();
    gpu.read_triangles(device, queue).unwrap()
}

#[test]
fn the_gpu_emits_the_cpu_reference_triangles() {
    let Some(ctx) = context_or_skip("tessellation gpu == cpu") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let density = DensityMap::from_map(&scene.map, DensityParams::default()).unwrap();
    let mut pass = TessellationPass::new(device).unwrap();
    let size = UVec2::new(640, 360);
    let mut compared = 0;
    for (use_density, morph, patch_size, max_error_px) in [
        (true, true, 32, None),
        (false, true, 16, None),
        (true, false, 64, None),
        (false, true, 32, Some(0.5)),
    ] {
        let config = TessConfig {
            use_density,
            morph,
            patch_size,
            triangle_width_px: 4.0,
            max_error_px,
            ..TessConfig::default()
        };
        let tess = TessHierarchy::from_map(&scene.map, Some(&density), config).unwrap();
        let gpu = GpuTessellation::new(device, queue, &tess, 1 << 20).unwrap();
        for (eye, dir) in [
            (Vec3::new(60.0, 45.0, 70.0), Vec3::new(1.0, -0.4, 0.3)),
            (Vec3::new(200.0, 80.0, 20.0), Vec3::new(-0.5, -0.6, 0.8)),
            (Vec3::new(128.0, 300.0, 128.0), Vec3::new(0.0, -1.0, 0.01)),
        ] {
            let camera = Camera::looking(eye, dir);
            let frustum =
                Frustum::from_view_proj(camera.view_proj_world(size.x as f32 / size.y as f32));
            for culled in [false, true] {
                let view = view_of(&camera, size, culled.then_some(&frustum));
                let cpu = tess.select(&view).unwrap();
                let (tris, overflow) = tessellate(device, queue, &mut pass, &gpu, &tess, &view);
                assert!(!overflow);
                let (a, b) = (by_corners(&cpu.triangles), by_corners(&tris));
                // The same f32 operations on both sides; a decision exactly at its threshold
                // may still differ by the rounding of a square root: allow 0.1 %.
                let missing = a.keys().filter(|k| !b.contains_key(*k)).count();
                let extra = b.keys().filter(|k| !a.contains_key(*k)).count();
                assert!(
                    (missing + extra) * 1000 <= a.len(),
                    "{config:?} {eye}: {} CPU triangles, {} GPU, {missing} missing, {extra} extra",
                    a.len(),
                    b.len()
                );
                eprintln!(
                    "{} CPU triangles: {missing} missing on the GPU, {extra} extra",
                    a.len()
                );
                let mut worst = 0.0f32;
                for (k, h) in &a {
                    if let Some(g) = b.get(k) {
                        for i in 0..3 {
                            worst = worst.max((h[i] - g[i]).abs());
                        }
                    }
                }
                assert!(worst <= 1e-4, "drawn heights differ by {worst} m");
                compared += a.len();
            }
        }
        scene.ctx.check().expect("no GPU validation errors");
    }
    assert!(compared > 100_000, "{compared} triangles compared");
}

/// The number of missing and extra triangles of the GPU's `gpu` against the CPU's `cpu`, and
/// the largest difference of the drawn heights of the triangles both have.
fn compare(cpu: &[TessTriangle], gpu: &[TessTriangle]) -> (usize, usize, f32) {
    let (a, b) = (by_corners(cpu), by_corners(gpu));
    let missing = a.keys().filter(|k| !b.contains_key(*k)).count();
    let extra = b.keys().filter(|k| !a.contains_key(*k)).count();
    let mut worst = 0.0f32;
    for (k, h) in &a {
        if let Some(g) = b.get(k) {
            for i in 0..3 {
                worst = worst.max((h[i] - g[i]).abs());
            }
        }
    }
    (missing, extra, worst)
}

/// The squared hypotenuse of a triangle in texels: `2 patch_size^2 / 2^level`.
fn hypotenuse2(t: &TessTriangle) -> u32 {
    Vec2::from(t[0].texel).distance_squared(Vec2::from(t[1].texel)) as u32
}

/// A camera half a metre above the ground refines down to the texels near it: triangles of
/// the finest of the 16 levels of 256-texel patches (of the 12 of 64-texel ones) and of
/// coarser levels further off, every level its own dispatch, and the GPU still emits the
/// CPU's triangles.
#[test]
fn deep_refinement_emits_the_cpu_reference_triangles() {
    let Some(ctx) = context_or_skip("tessellation deep refinement") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let density = DensityMap::from_map(&scene.map, DensityParams::default()).unwrap();
    let mut pass = TessellationPass::new(device).unwrap();
    let size = UVec2::new(640, 360);
    for patch_size in [256, 64] {
        let config = TessConfig {
            patch_size,
            triangle_width_px: 16.0,
            ..TessConfig::default()
        };
        let tess = TessHierarchy::from_map(&scene.map, Some(&density), config).unwrap();
        let gpu = GpuTessellation::new(device, queue, &tess, 1 << 20).unwrap();
        let xz = Vec2::new(120.5, 90.3);
        let eye = Vec3::new(xz.x, scene.ground(xz) + 0.5, xz.y);
        let camera = Camera::looking(eye, Vec3::new(0.6, -0.3, 0.8));
        let frustum =
            Frustum::from_view_proj(camera.view_proj_world(size.x as f32 / size.y as f32));
        for culled in [false, true] {
            let view = view_of(&camera, size, culled.then_some(&frustum));
            let cpu = tess.select(&view).unwrap();
            let levels: std::collections::HashSet<u32> =
                cpu.triangles.iter().map(hypotenuse2).collect();
            let finest = levels.iter().copied().min().unwrap();
            assert!(
                finest == 2 && levels.len() >= 5,
                "patch {patch_size}: the view must refine deeply: {} levels, finest {finest}",
                levels.len()
            );
            let (tris, overflow) = tessellate(device, queue, &mut pass, &gpu, &tess, &view);
            assert!(!overflow);
            let (missing, extra, worst) = compare(&cpu.triangles, &tris);
            assert!(
                (missing + extra) * 1000 <= cpu.triangles.len(),
                "patch {patch_size} culled {culled}: {} CPU triangles, {} GPU, {missing} \
                 missing, {extra} extra",
                cpu.triangles.len(),
                tris.len()
            );
            assert!(worst <= 1e-4, "drawn heights differ by {worst} m");
            eprintln!(
                "patch {patch_size} culled {culled}: {} CPU triangles over {} levels, {missing} \
                 missing on the GPU, {extra} extra",
                cpu.triangles.len(),
                levels.len()
            );
        }
        scene.ctx.check().expect("no GPU validation errors");
    }
}

/// Level queues too small for a view: the pass ends, reports the overflow, writes no more
/// than the output holds, and emits the children that found no room unsplit, so that the
/// triangles still cover the whole map once (without culling). A queue large enough for the
/// view reports nothing.
#[test]
fn a_full_level_queue_reports_overflow_and_still_covers_the_map() {
    let Some(ctx) = context_or_skip("tessellation queue overflow") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let config = TessConfig {
        patch_size: 64,
        ..TessConfig::default()
    };
    let tess = TessHierarchy::from_map(&scene.map, None, config).unwrap();
    let mut pass = TessellationPass::new(device).unwrap();
    let camera = Camera::looking(Vec3::new(128.0, 30.0, 128.0), Vec3::new(1.0, -0.5, 0.0));
    let view = view_of(&camera, UVec2::new(640, 360), None);
    let cpu = tess.select(&view).unwrap();
    let area = |tris: &[TessTriangle]| -> f64 {
        tris.iter()
            .map(|t| {
                let [l, r, a] = t.map(|v| glam::DVec2::new(v.texel[0].into(), v.texel[1].into()));
                (r - l).perp_dot(a - l).abs() / 2.0
            })
            .sum()
    };
    let side = (tess.patches() * config.patch_size).as_dvec2();
    assert_eq!(area(&cpu.triangles), side.x * side.y);
    for queue_capacity in [1, 64, 1000] {
        let gpu =
            GpuTessellation::with_queues(device, queue, &tess, 1 << 20, queue_capacity).unwrap();
        assert_eq!(gpu.queue_capacity(), queue_capacity);
        let (tris, overflow) = tessellate(device, queue, &mut pass, &gpu, &tess, &view);
        assert!(overflow, "queues of {queue_capacity}");
        assert!(
            tris.len() < cpu.triangles.len(),
            "queues of {queue_capacity}"
        );
        assert_eq!(area(&tris), side.x * side.y, "queues of {queue_capacity}");
        scene.ctx.check().expect("no GPU validation errors");
    }
    let gpu = GpuTessellation::with_queues(device, queue, &tess, 1 << 20, 1 << 17).unwrap();
    let (tris, overflow) = tessellate(device, queue, &mut pass, &gpu, &tess, &view);
    assert!(!overflow);
    let (missing, extra, _) = compare(&cpu.triangles, &tris);
    assert!((missing + extra) * 1000 <= cpu.triangles.len());
    // With a small output too, both bounds hold at once.
    let gpu = GpuTessellation::with_queues(device, queue, &tess, 500, 64).unwrap();
    let (tris, overflow) = tessellate(device, queue, &mut pass, &gpu, &tess, &view);
    assert!(overflow && tris.len() == 500);
    scene.ctx.check().expect("no GPU validation errors");
}

/// After deformations (one across the repeating map's corner) the rows `update_rect` reports
/// are all the GPU needs: its triangles equal the CPU's again, on a map the patches tile and on
/// one whose sides they do not divide.
#[test]
fn uploaded_updates_keep_the_gpu_equal_to_the_cpu() {
    let Some(ctx) = context_or_skip("tessellation updates") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = TessellationPass::new(device).unwrap();
    let size = UVec2::new(640, 360);
    for side in [UVec2::splat(256), UVec2::new(200, 150)] {
        let grid = terrain_core::Grid::from_fn(side.x, side.y, |x, y| {
            (20_000.0 + 6_000.0 * ((x as f32 * 0.07).sin() * (y as f32 * 0.05).cos())) as u16
        })
        .unwrap();
        let mut map = terrain_core::HeightMap::new(
            grid,
            terrain_core::HeightEncoding::new(0.002, 0.0).unwrap(),
            0.5,
            terrain_core::WrapMode::Repeat,
        )
        .unwrap();
        let mut density = DensityMap::from_map(&map, DensityParams::default()).unwrap();
        let mut tess =
            TessHierarchy::from_map(&map, Some(&density), TessConfig::default()).unwrap();
        let gpu = GpuTessellation::new(device, queue, &tess, 1 << 20).unwrap();
        let mut rows = Vec::new();
        for (at, r) in [(glam::IVec2::new(40, 50), 9), (side.as_ivec2() - 4, 12)] {
            let rect = terrain_core::Rect::new(at - r, UVec2::splat(2 * r as u32));
            for piece in rect.split_toroidal(side) {
                let p = piece.map;
                for y in p.min.y..p.max().y {
                    for x in p.min.x..p.max().x {
                        let s = map.grid_mut().get_mut(x as u32, y as u32).unwrap();
                        *s = s.saturating_sub(5_000);
                    }
                }
            }
            density.update_rect(&map, rect).unwrap();
            rows.extend(tess.update_rect(&map, Some(&density), rect).unwrap());
        }
        gpu.upload(queue, &tess, &rows).unwrap();
        let camera = Camera::looking(Vec3::new(20.0, 60.0, 25.0), Vec3::new(1.0, -0.6, 0.8));
        let view = view_of(&camera, size, None);
        let cpu = tess.select(&view).unwrap();
        let (tris, _) = tessellate(device, queue, &mut pass, &gpu, &tess, &view);
        let (a, b) = (by_corners(&cpu.triangles), by_corners(&tris));
        let differ = a.keys().filter(|k| !b.contains_key(*k)).count()
            + b.keys().filter(|k| !a.contains_key(*k)).count();
        assert!(
            differ * 1000 <= a.len() && a.len() > 1000,
            "{side}: {} CPU triangles, {} GPU, {differ} differ",
            a.len(),
            b.len()
        );
        ctx.check().expect("no GPU validation errors");
    }
}

/// The constants the shader repeats from terrain-lod.
#[test]
fn the_shader_repeats_the_libraries_constants() {
    use terrain_lod::tessellation::{FORCED_RATIO, MAX_LEVELS, NEAR_M, SPLIT_MARGIN};
    let src = terrain_shaders::TESSELLATE;
    assert_eq!(NEAR_M, 1e-3);
    assert_eq!(SPLIT_MARGIN, 1e-4);
    assert_eq!(MAX_LEVELS, 16);
    assert_eq!(FORCED_RATIO, 1e30);
    for line in [
        "const NEAR_M: f32 = 1e-3;",
        "const SPLIT_MARGIN: f32 = 1e-4;",
        "const MAX_LEVELS: u32 = 16u;",
        "const FORCED_RATIO: f32 = 1e30;",
    ] {
        assert!(src.contains(line), "tessellate.wgsl lacks `{line}`");
    }
}

#[test]
fn the_output_is_bounded_and_says_when_it_overflows() {
    let Some(ctx) = context_or_skip("tessellation output bound") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let tess = TessHierarchy::from_map(&scene.map, None, TessConfig::default()).unwrap();
    let gpu = GpuTessellation::new(device, queue, &tess, 1000).unwrap();
    let mut pass = TessellationPass::new(device).unwrap();
    let camera = Camera::looking(Vec3::new(128.0, 50.0, 128.0), Vec3::new(1.0, -0.5, 0.0));
    let view = view_of(&camera, UVec2::new(640, 360), None);
    let (tris, overflow) = tessellate(device, queue, &mut pass, &gpu, &tess, &view);
    assert!(overflow && tris.len() == 1000);
    // Another hierarchy's size is refused before wgpu sees it.
    let small = terrain_core::HeightMap::new(
        terrain_core::Grid::new(64, 64, 0u16).unwrap(),
        terrain_core::HeightEncoding::new(0.01, 0.0).unwrap(),
        1.0,
        terrain_core::WrapMode::Clamp,
    )
    .unwrap();
    let other = TessHierarchy::from_map(&small, None, TessConfig::default()).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    assert!(
        pass.encode(device, queue, &mut encoder, &gpu, &other, &view)
            .is_err()
    );
    assert!(
        gpu.upload(queue, &other, std::slice::from_ref(&(0..4)))
            .is_err()
    );
    scene.ctx.check().expect("no GPU validation errors");
}

#[test]
fn no_cracks_from_grazing_views_across_patch_edges() {
    let Some(ctx) = context_or_skip("tessellation no_cracks_from_grazing_views") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let density = DensityMap::from_map(&scene.map, DensityParams::default()).unwrap();
    let config = TessConfig {
        patch_size: 16,
        triangle_width_px: 10.0,
        ..TessConfig::default()
    };
    let tess = TessHierarchy::from_map(&scene.map, Some(&density), config).unwrap();
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let gpu = GpuTessellation::new(device, queue, &tess, 1 << 20).unwrap();
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
    let mut levels_seen = 0;
    for (i, xz) in [
        Vec2::new(100.0, 100.0),
        Vec2::new(63.9, 130.6),
        Vec2::new(32.2, 200.5),
    ]
    .iter()
    .enumerate()
    {
        for (j, yaw) in [0.0f32, 0.8, 2.4, 3.9, 5.1].iter().enumerate() {
            let eye = Vec3::new(xz.x, scene.ground(*xz) + 1.5 + i as f32, xz.y);
            // Looking into the map (the tessellation draws the map once).
            let camera = Camera::looking(eye, Vec3::new(yaw.cos(), 0.0, yaw.sin()));
            let aspect = size.x as f32 / size.y as f32;
            let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
            let view = view_of(&camera, size, Some(&frustum));
            let cpu = tess.select(&view).unwrap();
            let sizes: std::collections::HashSet<u32> = cpu
                .triangles
                .iter()
                .map(|t| Vec2::from(t[0].texel).distance_squared(Vec2::from(t[1].texel)) as u32)
                .collect();
            levels_seen = levels_seen.max(sizes.len());
            scene
                .sky
                .prepare(queue, camera.view_proj_relative(aspect), &magenta)
                .unwrap();
            renderer
                .prepare(
                    device,
                    queue,
                    &TessDraw {
                        surface: ClipmapSurface::Coarse {
                            map: &scene.gpu_map,
                            normals: &scene.normals,
                        },
                        camera: &camera,
                        style: &style,
                        target_size: size,
                    },
                )
                .unwrap();
            let target = OffscreenTarget::new(device, size).unwrap();
            let mut encoder = device.create_command_encoder(&Default::default());
            pass.encode(device, queue, &mut encoder, &gpu, &tess, &view)
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
            assert_no_holes(&image, &format!("tess_crack_{i}_{j}"));
        }
    }
    assert!(
        levels_seen >= 5,
        "the views cross many levels: {levels_seen}"
    );
}
