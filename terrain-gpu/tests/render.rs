//! Clipmap rendering: no cracks from grazing views across every level boundary, and a golden
//! image of a fixed view. Runs on the software adapter in CI.

#[path = "common/cracks.rs"]
mod cracks;
#[path = "common/engine.rs"]
mod engine;
#[path = "common/scene.rs"]
mod scene;
use cracks::{holes, is_sky};

use glam::{UVec2, Vec2, Vec3};
use scene::Scene;
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    Camera, ClipmapRenderer, ClipmapSurface, ClipmapView, DepthConvention, GpuError, SkyColors,
    SkyPass, TargetFormat, TerrainStyle,
};

#[test]
fn no_cracks_from_grazing_views_across_level_boundaries() {
    let Some(ctx) = context_or_skip("no_cracks_from_grazing_views") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
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

#[test]
fn hiding_outside_the_map_draws_it_once() {
    let Some(ctx) = context_or_skip("hiding_outside_the_map_draws_it_once") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 6);
    let magenta = SkyColors {
        horizon: Vec3::new(1.0, 0.0, 1.0),
        zenith: Vec3::new(1.0, 0.0, 1.0),
    };
    // Straight down over the map's corner (0, 0): a quarter of the view is the map, the rest
    // its toroidal repeats.
    let camera = Camera::looking(Vec3::new(0.0, 260.0, 0.0), Vec3::new(0.0, -1.0, 0.0));
    let size = UVec2::new(160, 160);
    let sky_share = |image: &terrain_core::Grid<[u8; 4]>| {
        let sky = image.as_slice().iter().filter(|p| is_sky(**p)).count();
        sky as f64 / image.as_slice().len() as f64
    };
    let (repeated, _) = scene.render(&camera, size, &magenta);
    assert!(sky_share(&repeated) < 0.01, "repeats fill the view");
    scene.hide_outside = true;
    let (island, triangles) = scene.render(&camera, size, &magenta);
    let share = sky_share(&island);
    assert!(triangles > 0);
    assert!(
        (0.65..0.85).contains(&share),
        "three quarters of the view are outside the map: {share}"
    );
    // The quarter drawn is the map's, as before.
    let same = island
        .as_slice()
        .iter()
        .zip(repeated.as_slice())
        .filter(|(a, _)| !is_sky(**a))
        .all(|(a, b)| a == b);
    assert!(same, "the map itself is drawn unchanged");
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
    let mut scene = Scene::new(ctx, 31, 5);
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

/// The caller's-pass path against the offscreen capture: the mean per-pixel difference (largest
/// channel) may be at most this (8-bit rounding of the sRGB round trip, MSAA resolve)...
const CALLER_PASS_MEAN_TOLERANCE: f64 = 2.0;
/// ...and at most this share of pixels may differ by more than 24 (silhouette edges, which
/// 4x MSAA blends and the single-sample capture does not).
const CALLER_PASS_EDGE_SHARE: f64 = 0.04;

#[test]
fn renderers_draw_into_the_callers_msaa_srgb_pass_like_the_capture() {
    let Some(ctx) = context_or_skip("renderers_draw_into_the_callers_msaa_srgb_pass") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let camera = scene::golden_camera(&scene);
    let size = scene::GOLDEN_SIZE;
    let (capture, _) = scene.render(&camera, size, &SkyColors::default());

    // The engine's side, as the own_device example makes it: its own formats, its own
    // textures, its own pass.
    let format = engine::FORMAT;
    let device = &scene.ctx.device;
    let queue = &scene.ctx.queue;
    let sky = SkyPass::new(device, &format).unwrap();
    let mut renderer = ClipmapRenderer::new(device, &format, &scene.layout).unwrap();
    let targets = engine::EngineTargets::new(device, size);

    let aspect = size.x as f32 / size.y as f32;
    let frame = scene
        .layout
        .place(
            Vec2::new(camera.position.x, camera.position.z),
            1.0,
            (0.0, scene::HEIGHT),
            Some(&terrain_lod::Frustum::from_view_proj(
                camera.view_proj_world(aspect),
            )),
        )
        .unwrap();
    let style = TerrainStyle {
        ramp: (0.0, scene::HEIGHT),
        ..TerrainStyle::default()
    };
    sky.prepare(
        queue,
        camera.view_proj_relative(aspect),
        &SkyColors::default(),
    )
    .unwrap();
    let view = ClipmapView {
        surface: ClipmapSurface::Coarse {
            map: &scene.gpu_map,
            normals: &scene.normals,
        },
        frame: &frame,
        camera: &camera,
        style: &style,
        target_size: size,
    };
    renderer.prepare(device, queue, &view).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = targets.begin_pass(&mut encoder);
        sky.draw(&mut pass);
        renderer.draw(&mut pass);
    }
    queue.submit([encoder.finish()]);
    // The resolved BGRA target, as RGBA rows.
    let engine = terrain_gpu::read_texture_rgba8(device, queue, &targets.resolved).unwrap();
    scene.ctx.check().expect("no GPU validation errors");

    // Both paths must show terrain, not only sky (the same renderer drawing nothing would
    // otherwise pass).
    // Sky pixels are blue over red by 43 (horizon) to 133 (zenith); lit terrain (greens,
    // browns, rock, snow) is not.
    let terrain = capture
        .as_slice()
        .iter()
        .filter(|p| i32::from(p[2]) - i32::from(p[0]) < 30)
        .count();
    assert!(
        terrain as f64 > 0.3 * f64::from(size.x * size.y),
        "the capture shows terrain: {terrain} pixels"
    );
    let mut sum = 0.0;
    let mut edges = 0usize;
    for y in 0..size.y {
        for x in 0..size.x {
            let engine = engine.get(x, y).unwrap();
            let cap = capture.get(x, y).unwrap();
            let d = (0..3)
                .map(|c| (i32::from(engine[c]) - i32::from(cap[c])).unsigned_abs())
                .max()
                .unwrap_or(0);
            sum += f64::from(d);
            edges += usize::from(d > 24);
        }
    }
    let n = f64::from(size.x * size.y);
    let (mean, share) = (sum / n, edges as f64 / n);
    eprintln!(
        "caller's pass vs capture: mean {mean:.3}, {:.2} % of pixels differ by more than 24",
        share * 100.0
    );
    assert!(
        mean <= CALLER_PASS_MEAN_TOLERANCE && share <= CALLER_PASS_EDGE_SHARE,
        "caller's pass differs from the capture: mean {mean:.3}, edge share {share:.4}"
    );
}

#[test]
fn renderers_refuse_targets_they_cannot_draw_into() {
    let Some(ctx) = context_or_skip("renderers_refuse_targets_they_cannot_draw_into") else {
        return;
    };
    let layout = terrain_lod::ClipmapLayout::new(31, 3).unwrap();
    let bad = [
        TargetFormat {
            color: wgpu::TextureFormat::Depth32Float,
            ..TargetFormat::CAPTURE
        },
        TargetFormat {
            depth: wgpu::TextureFormat::Rgba8Unorm,
            ..TargetFormat::CAPTURE
        },
        TargetFormat {
            sample_count: 3,
            depth_convention: DepthConvention::Forward,
            ..TargetFormat::CAPTURE
        },
    ];
    for format in bad {
        let refused = |r: Result<(), GpuError>| {
            matches!(
                r,
                Err(GpuError::UnsupportedTarget { .. } | GpuError::UnsupportedSampleCount { .. })
            )
        };
        assert!(refused(
            ClipmapRenderer::new(&ctx.device, &format, &layout).map(|_| ())
        ));
        assert!(refused(SkyPass::new(&ctx.device, &format).map(|_| ())));
        assert!(refused(format.validate_on(&ctx.adapter, &ctx.device)));
    }
    let err = TargetFormat {
        sample_count: 3,
        depth_convention: DepthConvention::Forward,
        ..TargetFormat::CAPTURE
    }
    .validate_on(&ctx.adapter, &ctx.device)
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("3x multisampled into Rgba8Unorm with depth Depth32Float")
            && err.contains("sample counts [1, ")
            && err.contains("for Rgba8Unorm and [1, "),
        "the error names the formats, the count and what is allowed: {err}"
    );
    ctx.check().expect("refused before wgpu saw them");
}

/// The sample counts a format allows are the adapter's where the device may use them: a
/// count the adapter supports beyond the guaranteed ones (Rgba8Unorm x2 on lavapipe, where
/// every adapter guarantees only 1 and 4) is accepted and builds, one it does not is refused
/// with what it allows.
#[test]
fn target_sample_counts_follow_the_adapter() {
    let Some(ctx) = context_or_skip("target_sample_counts_follow_the_adapter") else {
        return;
    };
    let adapter_specific = ctx
        .device
        .features()
        .contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES);
    for color in [
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureFormat::Rgba16Float,
        wgpu::TextureFormat::Rgba8Unorm,
    ] {
        for count in [1, 2, 4, 8, 16] {
            let format = TargetFormat {
                color,
                depth: wgpu::TextureFormat::Depth32Float,
                sample_count: count,
                depth_convention: DepthConvention::Forward,
            };
            let features = |f: wgpu::TextureFormat| {
                if adapter_specific {
                    ctx.adapter.get_texture_format_features(f)
                } else {
                    f.guaranteed_format_features(ctx.device.features())
                }
            };
            let renderable = features(color)
                .allowed_usages
                .contains(wgpu::TextureUsages::RENDER_ATTACHMENT);
            let supported = renderable
                && features(color).flags.sample_count_supported(count)
                && features(format.depth).flags.sample_count_supported(count);
            let checked = format.validate_on(&ctx.adapter, &ctx.device);
            assert_eq!(
                checked.is_ok(),
                supported,
                "{color:?} x{count}: {checked:?}"
            );
            if supported {
                // Accepted means usable: the sky pipeline builds without a wgpu error.
                SkyPass::new(&ctx.device, &format).expect("a supported target");
            } else if renderable {
                let msg = checked.unwrap_err().to_string();
                assert!(
                    msg.contains(&format!("{count}x multisampled into {color:?}")),
                    "{msg}"
                );
            }
        }
    }
    ctx.check().expect("no wgpu error");
}

#[test]
fn wireframe_draws_edges_where_the_device_can_and_is_refused_where_it_cannot() {
    let Some(ctx) = context_or_skip("wireframe_draws_edges") else {
        return;
    };
    // The context's device asks for no POLYGON_MODE_LINE: wireframe is refused, not ignored.
    let layout = terrain_lod::ClipmapLayout::new(31, 4).unwrap();
    let mut plain = ClipmapRenderer::new(&ctx.device, &TargetFormat::CAPTURE, &layout).unwrap();
    assert!(!plain.has_wireframe());
    assert!(matches!(
        plain.set_wireframe(true),
        Err(GpuError::Unsupported { .. })
    ));
    assert!(plain.set_wireframe(false).is_ok());
    if !ctx
        .adapter
        .features()
        .contains(wgpu::Features::POLYGON_MODE_LINE)
    {
        eprintln!("skipping the wireframe drawing: the adapter lacks POLYGON_MODE_LINE");
        return;
    }
    // A device that asks for it: the same scene, filled and as wireframe.
    let (device, queue) = pollster::block_on(ctx.adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("wireframe test"),
        required_features: wgpu::Features::POLYGON_MODE_LINE,
        required_limits: ctx.adapter.limits(),
        ..Default::default()
    }))
    .unwrap();
    let enc = terrain_core::HeightEncoding::spanning::<u16>(0.0, 10.0).unwrap();
    let params = terrain_core::TerrainParams {
        size: UVec2::splat(128),
        seed: 3,
        ..Default::default()
    };
    let map = terrain_core::generate_coarse_map(&params, enc, 1.0).unwrap();
    let gpu_map = terrain_gpu::GpuHeightMap::from_map(&device, &queue, &map).unwrap();
    let normals = terrain_gpu::GpuDerivativeMap::for_map(&device, &gpu_map).unwrap();
    let mut normal_pass = terrain_gpu::NormalPass::new(&device).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    normal_pass
        .encode_full(&device, &queue, &mut encoder, &gpu_map, &normals)
        .unwrap();
    queue.submit([encoder.finish()]);
    let mut renderer = ClipmapRenderer::new(&device, &TargetFormat::CAPTURE, &layout).unwrap();
    assert!(renderer.has_wireframe());
    let sky = SkyPass::new(&device, &TargetFormat::CAPTURE).unwrap();
    let size = UVec2::new(160, 100);
    let xz = Vec2::new(64.0, 64.0);
    let eye = Vec3::new(xz.x, terrain_core::bilinear(&map, xz).unwrap() + 6.0, xz.y);
    let camera = Camera::looking(eye, Vec3::new(1.0, -1.2, 0.3));
    let magenta = SkyColors {
        horizon: Vec3::new(1.0, 0.0, 1.0),
        zenith: Vec3::new(1.0, 0.0, 1.0),
    };
    let target = terrain_gpu::OffscreenTarget::new(&device, size).unwrap();
    let style = TerrainStyle {
        ramp: (0.0, 10.0),
        ..TerrainStyle::default()
    };
    let render = |renderer: &mut ClipmapRenderer| {
        let frame = layout.place(xz, 1.0, (0.0, 10.0), None).unwrap();
        let aspect = size.x as f32 / size.y as f32;
        sky.prepare(&queue, camera.view_proj_relative(aspect), &magenta)
            .unwrap();
        let view = ClipmapView {
            surface: ClipmapSurface::Coarse {
                map: &gpu_map,
                normals: &normals,
            },
            frame: &frame,
            camera: &camera,
            style: &style,
            target_size: size,
        };
        renderer.prepare(&device, &queue, &view).unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
            sky.draw(&mut pass);
            renderer.draw(&mut pass);
        }
        queue.submit([encoder.finish()]);
        target.read_rgba8(&device, &queue).unwrap()
    };
    let sky_share = |image: &terrain_core::Grid<[u8; 4]>| {
        image.as_slice().iter().filter(|p| is_sky(**p)).count() as f64
            / image.as_slice().len() as f64
    };
    let filled = render(&mut renderer);
    renderer.set_wireframe(true).unwrap();
    assert!(renderer.wireframe());
    let lines = render(&mut renderer);
    // Looking down at the ground: filled, no sky shows; as wireframe, the sky shows between
    // the edges, and the edges are drawn.
    assert!(sky_share(&filled) < 0.01, "filled: {}", sky_share(&filled));
    let share = sky_share(&lines);
    assert!((0.2..0.95).contains(&share), "wireframe sky share {share}");
    renderer.set_wireframe(false).unwrap();
    assert_eq!(render(&mut renderer).as_slice(), filled.as_slice());
}
