//! Refined geometry (`--detail refine`, Flower 2010, sec. 2.4.3): `RefinePass`'s triangles against
//! the CPU reference `terrain_lod::refine` (same patterns, same positions, heights of coarse +
//! faded detail), no cracks from grazing views where the refined region meets the clipmap,
//! CDLOD or the tessellation, and
//! a refined region without detail drawing the coarse frame, and the layers (a hole mask) a
//! refine renderer adopts from the terrain it refines drawn on its cells. On whatever adapter the machine
//! has (lavapipe in CI); without one they skip, or fail under `TERRAIN_REQUIRE_GPU=1`.

#[path = "common/cracks.rs"]
mod cracks;
#[path = "common/scene.rs"]
#[allow(dead_code)] // the golden view's parts of the shared scene
mod scene;

use cracks::{assert_no_holes, holes};
use glam::{IVec2, UVec2, Vec2, Vec3};
use scene::{HEIGHT, Scene};
use terrain_core::detail::{DetailLayer, DetailLayout};
use terrain_core::{Blend, GaussianStamp, Grid, StampPlacement};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    Camera, ClipmapSurface, DetailShading, GpuDetailTiles, GpuError, OffscreenTarget, RefineDraw,
    RefinePass, RefineRenderer, SkyColors, SmallReadback, TargetFormat, TerrainRenderer,
    TerrainStyle, TerrainView,
};
use terrain_lod::refine::RefineView;
use terrain_lod::{CdlodConfig, TessConfig};

/// 256 x 256 coarse texels at 1 m refined x3, in 16 x 16 tiles of 48 detail texels.
fn layout(scene: &Scene) -> DetailLayout {
    DetailLayout::new(scene.map.size(), 1.0, 3, 48).unwrap()
}

/// Large footprints (1.6 x 2.4 m, 40 cm deep: the scene has 1 m texels) along two walks: one across tile edges in the middle of the map, one
/// across the map's wrap corner. Every touched tile is loaded on the GPU.
fn footprints(scene: &Scene) -> (DetailLayer, GpuDetailTiles) {
    let layout = layout(scene);
    let mut layer = DetailLayer::new(layout).unwrap();
    let mut foot = GaussianStamp::default();
    let mut touched = Vec::new();
    for (start, dir) in [
        (Vec2::new(88.0, 90.0), Vec2::new(0.8, 0.6)),
        (Vec2::new(250.0, 251.0), Vec2::new(0.7, 0.7)),
    ] {
        for i in 0..12 {
            let side = if i % 2 == 0 { -0.8 } else { 0.8 };
            let c = start + dir * (1.6 * i as f32) + dir.perp() * side;
            let c = c.rem_euclid(Vec2::splat(256.0));
            let p = StampPlacement::new(c, Vec2::new(1.6, 2.4), -0.4).unwrap();
            let change = layer
                .apply_stamp(&mut foot, &p, Blend::Min { base_m: 0.0 })
                .unwrap();
            touched.extend(change.tiles.iter().map(|(t, _)| *t));
        }
    }
    touched.sort_by_key(|t| (t.y, t.x));
    touched.dedup();
    assert!(touched.len() > 4, "the walks cross tile edges");
    let mut tiles = GpuDetailTiles::new(&scene.ctx.device, layout, touched.len() as u32).unwrap();
    for t in touched {
        tiles.load(&scene.ctx.queue, t, layer.tile(t)).unwrap();
    }
    (layer, tiles)
}

fn style() -> TerrainStyle {
    TerrainStyle {
        ramp: (0.0, HEIGHT),
        ..TerrainStyle::default()
    }
}

/// A magenta sky: a pixel of it where terrain should be is a crack (`cracks::is_sky`).
const MAGENTA_SKY: SkyColors = SkyColors {
    horizon: Vec3::new(1.0, 0.0, 1.0),
    zenith: Vec3::new(1.0, 0.0, 1.0),
};

/// The refined radius: the detail displaces vertices fully to 8 m, not at all from 16 m.
const RADIUS: f32 = 16.0;

/// The fragments' detail normals: faded out from 20 m to 30 m.
fn shading() -> DetailShading {
    DetailShading {
        fade_start_m: 20.0,
        fade_end_m: 30.0,
        parallax_steps: 0,
        ..DetailShading::default()
    }
}

/// The CPU reference's triangles for `camera`: the flags ask the same tile question as the
/// shader (any tile with a slot within one coarse texel and the differences' reach).
fn cpu_triangles(scene: &Scene, tiles: &GpuDetailTiles, camera: &Camera) -> Vec<[IVec2; 3]> {
    let layout = *tiles.layout();
    let xz = Vec2::new(camera.position.x, camera.position.z);
    let view = RefineView::new(xz, 1.0, RADIUS).unwrap();
    let size = scene.map.size().as_ivec2();
    let wrapped = IVec2::new(
        view.camera_texel.x.rem_euclid(size.x),
        view.camera_texel.y.rem_euclid(size.y),
    );
    let k = layout.refine() as i32;
    view.refine(|v| {
        let lo = (wrapped + v - IVec2::ONE) * k - IVec2::splat(3);
        let hi = (wrapped + v + IVec2::ONE) * k + IVec2::splat(3);
        layout.box_may_touch(lo, hi, |t| tiles.slot_of(t).is_some())
    })
}

fn sorted(mut tris: Vec<[IVec2; 3]>) -> Vec<[IVec2; 3]> {
    tris.sort_by_key(|t| t.map(|v| (v.x, v.y)));
    tris
}

#[test]
fn refined_triangles_equal_the_cpu_reference() {
    let Some(ctx) = context_or_skip("refine_cpu") else {
        return;
    };
    let scene = Scene::new(ctx, 63, 4);
    let (layer, tiles) = footprints(&scene);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let mut pass = RefinePass::new(device, 20).unwrap();
    let style = style();
    let shading = shading();
    // On the middle walk, on the wrap corner (both signs), far from the map (its repeats), and
    // where no tile has a slot.
    let cameras = [
        (Vec2::new(93.3, 94.6), true),
        (Vec2::new(1.7, 2.2), true),
        (Vec2::new(-3.4, 254.9), true),
        (Vec2::new(93.3 - 256.0 * 40.0, 94.6 + 256.0 * 90.0), false),
        (Vec2::new(180.5, 30.5), true),
    ];
    let mut refined_views = 0;
    for (i, (xz, check_heights)) in cameras.into_iter().enumerate() {
        let eye = Vec3::new(xz.x, scene.ground(xz) + 1.7, xz.y);
        let camera = Camera::looking(eye, Vec3::new(0.6, -0.3, 0.8));
        let draw = RefineDraw {
            surface: ClipmapSurface::Detail {
                map: &scene.gpu_map,
                normals: &scene.normals,
                detail: &tiles,
                shading: &shading,
            },
            radius_m: RADIUS,
            camera: &camera,
            style: &style,
            target_size: UVec2::new(64, 64),
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        let view = pass.encode(device, queue, &mut encoder, &draw).unwrap();
        assert!(pass.request_count(&mut encoder).unwrap());
        queue.submit([encoder.finish()]);
        let (gpu, overflow) = pass.read_triangles(device, queue).unwrap();
        assert!(!overflow);
        // The count that rode the submit arrived by the (blocking) read above.
        assert_eq!(
            pass.poll_count(device).unwrap(),
            Some((gpu.len() as u32, false)),
            "camera {i}: the asynchronous count is the written one"
        );
        let cpu = cpu_triangles(&scene, &tiles, &camera);
        let thirds: Vec<[IVec2; 3]> = gpu
            .iter()
            .map(|t| t.map(|v| (Vec2::new(v.x, v.y) * 3.0).round().as_ivec2()))
            .collect();
        assert_eq!(
            sorted(thirds),
            sorted(cpu.clone()),
            "camera {i}: the GPU's triangles are the CPU reference's"
        );
        let base = view.base_triangles() as usize;
        if cpu.len() > base {
            refined_views += 1;
        }
        if i == 4 {
            assert_eq!(
                cpu.len(),
                base,
                "no tile with a slot near camera 4: nothing refined"
            );
        }
        if !check_heights {
            continue;
        }
        // Drawn heights: bilinear coarse + detail faded with the distance from the eye.
        let size = scene.map.size().as_ivec2();
        let wrapped = IVec2::new(
            view.camera_texel.x.rem_euclid(size.x),
            view.camera_texel.y.rem_euclid(size.y),
        )
        .as_vec2();
        let (s, e) = (0.5 * RADIUS, RADIUS);
        let mut deep = 0;
        for v in gpu.iter().flatten() {
            let q = Vec2::new(v.x, v.y);
            let pos = wrapped + q;
            let coarse = terrain_core::bilinear(&scene.map, pos).unwrap();
            let rel = q - view.camera_frac;
            let dist = Vec3::new(rel.x, coarse - eye.y, rel.y).length();
            let t = ((dist - s) / (e - s)).clamp(0.0, 1.0);
            let w = 1.0 - t * t * (3.0 - 2.0 * t);
            let expected = coarse + w * layer.height_m(pos);
            assert!(
                (v.z - expected).abs() <= 2e-3,
                "camera {i} at {q}: drawn {} vs {expected}",
                v.z
            );
            deep += usize::from(expected < coarse - 0.1);
        }
        if cpu.len() > base {
            assert!(deep > 0, "camera {i}: some vertices lie in footprints");
        }
    }
    assert_eq!(refined_views, 4, "four views refine something");
    scene.ctx.check().expect("no GPU validation errors");
}

/// Renders `camera` with the clipmap (coarse surface) leaving the refined region to the
/// refined mesh.
fn render_refined(
    scene: &mut Scene,
    parts: &mut (RefinePass, RefineRenderer),
    tiles: &GpuDetailTiles,
    camera: &Camera,
    size: UVec2,
    sky: &SkyColors,
) -> (Grid<[u8; 4]>, usize, usize) {
    let (pass, renderer) = parts;
    let style = style();
    let shading = shading();
    let device = scene.ctx.device.clone();
    let queue = scene.ctx.queue.clone();
    let mut encoder = device.create_command_encoder(&Default::default());
    let draw = RefineDraw {
        surface: ClipmapSurface::Detail {
            map: &scene.gpu_map,
            normals: &scene.normals,
            detail: tiles,
            shading: &shading,
        },
        radius_m: RADIUS,
        camera,
        style: &style,
        target_size: size,
    };
    let view = pass.encode(&device, &queue, &mut encoder, &draw).unwrap();
    renderer.prepare(&device, &queue, &draw, pass).unwrap();
    scene.renderer.exclude(Some(view.region()));
    scene.prepare(camera, size, sky);
    let target = OffscreenTarget::new(&device, size).unwrap();
    {
        let mut rp = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
        scene.sky.draw(&mut rp);
        scene.renderer.draw(&mut rp);
        renderer.draw(&mut rp, pass);
    }
    queue.submit([encoder.finish()]);
    let image = target.read_rgba8(&device, &queue).unwrap();
    let (tris, overflow) = pass.read_triangles(&device, &queue).unwrap();
    assert!(!overflow);
    scene.ctx.check().expect("no GPU validation errors");
    (image, tris.len(), view.base_triangles() as usize)
}

fn refine_parts(scene: &Scene) -> (RefinePass, RefineRenderer) {
    let device = &scene.ctx.device;
    (
        RefinePass::new(device, 20).unwrap(),
        RefineRenderer::new(device, &TargetFormat::CAPTURE).unwrap(),
    )
}

#[test]
fn no_cracks_from_grazing_views_at_the_edge_of_the_refined_region() {
    let Some(ctx) = context_or_skip("refine_cracks") else {
        return;
    };
    let mut scene = Scene::new(ctx, 63, 4);
    let (_, tiles) = footprints(&scene);
    let mut parts = refine_parts(&scene);
    let magenta = MAGENTA_SKY;
    let size = UVec2::new(320, 200);
    let positions = [
        Vec2::new(93.3, 94.6),
        Vec2::new(96.9, 92.1),
        Vec2::new(1.7, 2.2),
    ];
    let headings = [0.0f32, 0.8, 1.6, 2.4, 3.9, 5.1];
    let mut checked = 0;
    for (i, xz) in positions.iter().enumerate() {
        for (j, yaw) in headings.iter().enumerate() {
            // Low over the ground: the region's edge (16 m away) seen at a grazing angle.
            let eye = Vec3::new(xz.x, scene.ground(*xz) + 0.8 + 0.4 * i as f32, xz.y);
            let camera = Camera::looking(eye, Vec3::new(yaw.cos(), 0.0, yaw.sin()));
            let (image, refined, base) =
                render_refined(&mut scene, &mut parts, &tiles, &camera, size, &magenta);
            assert!(refined > base, "view {i}/{j}: the region is refined");
            let (holes, terrain) = holes(&image);
            assert!(terrain > (size.x * size.y / 4) as usize);
            if holes > 0 {
                let path = std::env::temp_dir().join(format!("refine_crack_{i}_{j}.png"));
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

/// The largest channel difference of two frames and the pixels differing by more than 8.
fn frame_diff(a: &Grid<[u8; 4]>, b: &Grid<[u8; 4]>) -> (u8, usize) {
    let mut max = 0;
    let mut strong = 0;
    for (p, q) in a.as_slice().iter().zip(b.as_slice()) {
        let d = p
            .iter()
            .zip(q)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0);
        max = max.max(d);
        strong += usize::from(d > 8);
    }
    (max, strong)
}

#[test]
fn refined_footprints_change_the_frame_and_no_detail_draws_the_coarse_frame() {
    let Some(ctx) = context_or_skip("refine_frames") else {
        return;
    };
    let mut scene = Scene::new(ctx, 63, 4);
    let (_, tiles) = footprints(&scene);
    let mut parts = refine_parts(&scene);
    let sky = SkyColors::default();
    let size = UVec2::new(256, 160);
    let xz = Vec2::new(91.0, 91.5);
    let eye = Vec3::new(xz.x, scene.ground(xz) + 2.5, xz.y);
    let camera = Camera::looking(eye, Vec3::new(0.8, -0.5, 0.6));
    scene.renderer.exclude(None);
    let (coarse, _) = scene.render(&camera, size, &sky);
    let (refined, n, base) = render_refined(&mut scene, &mut parts, &tiles, &camera, size, &sky);
    assert!(n > base);
    let (max, strong) = frame_diff(&refined, &coarse);
    if !(max > 40 && strong > 250) {
        let dir = std::env::temp_dir();
        let _ = terrain_core::io::write_png_rgba8(dir.join("refine_footprints.png"), &refined);
        let _ = terrain_core::io::write_png_rgba8(dir.join("refine_coarse.png"), &coarse);
        panic!("the refined footprints hardly change the frame: max {max}, {strong} pixels");
    }
    // No tile with a slot: the refined region is the clipmap's own triangles, the join unseen
    // (a gap or an overlap at the region's edge would show), looking along every side.
    let empty = GpuDetailTiles::new(&scene.ctx.device, *tiles.layout(), 1).unwrap();
    for yaw in [0.3f32, 1.9, 3.4, 5.0] {
        let camera = Camera::looking(eye, Vec3::new(yaw.cos(), -0.25, yaw.sin()));
        scene.renderer.exclude(None);
        let (coarse, _) = scene.render(&camera, size, &sky);
        let (plain, n, base) = render_refined(&mut scene, &mut parts, &empty, &camera, size, &sky);
        assert_eq!(n, base, "nothing refined without detail");
        let (max, _) = frame_diff(&plain, &coarse);
        assert!(
            max <= 2,
            "yaw {yaw}: an unrefined region draws the coarse frame (max {max})"
        );
    }
}

#[test]
fn a_refine_renderer_draws_the_layers_it_adopts() {
    let Some(ctx) = context_or_skip("refine_adopt") else {
        return;
    };
    let mut scene = Scene::new(ctx, 63, 4);
    let (_, tiles) = footprints(&scene);
    let mut parts = refine_parts(&scene);
    let magenta = MAGENTA_SKY;
    let size = UVec2::new(256, 160);
    let xz = Vec2::new(91.0, 91.5);
    let eye = Vec3::new(xz.x, scene.ground(xz) + 2.5, xz.y);
    let camera = Camera::looking(eye, Vec3::new(0.8, -0.5, 0.6));
    let sky_pixels = |image: &Grid<[u8; 4]>| {
        let sky = image.as_slice().iter().filter(|&&p| cracks::is_sky(p));
        sky.count()
    };
    let (plain, ..) = render_refined(&mut scene, &mut parts, &tiles, &camera, size, &magenta);
    // The terrain the refined cells replace leaves every cell out: the refined cells that
    // adopt its layers leave them out too, so the sky shows where they were.
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let all_holes = Grid::new(256, 256, terrain_core::HOLE).unwrap();
    let mask = terrain_gpu::GpuHoleMask::new(device, queue, &all_holes).unwrap();
    let layout = terrain_lod::ClipmapLayout::new(63, 4).unwrap();
    let mut terrain =
        TerrainRenderer::clipmap(device, &TargetFormat::CAPTURE, layout, (0.0, HEIGHT)).unwrap();
    terrain.set_hole_mask(Some(&mask));
    parts.1.adopt_layers(&terrain);
    let (holed, ..) = render_refined(&mut scene, &mut parts, &tiles, &camera, size, &magenta);
    let (before, after) = (sky_pixels(&plain), sky_pixels(&holed));
    assert!(
        after > before + (size.x * size.y / 8) as usize,
        "the refined cells ignored the adopted hole mask: {before} -> {after} sky pixels"
    );
}

#[test]
fn refinement_that_does_not_fit_is_refused() {
    let Some(ctx) = context_or_skip("refine_refused") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 4);
    let (_, tiles) = footprints(&scene);
    let device = scene.ctx.device.clone();
    let queue = scene.ctx.queue.clone();
    assert!(RefinePass::new(&device, 0).is_err());
    assert!(RefinePass::new(&device, 257).is_err());
    let mut pass = RefinePass::new(&device, 8).unwrap();
    let mut renderer = RefineRenderer::new(&device, &TargetFormat::CAPTURE).unwrap();
    let style = style();
    let xz = Vec2::new(93.3, 94.6);
    let camera = Camera::looking(Vec3::new(xz.x, scene.ground(xz) + 2.0, xz.y), Vec3::X);
    let shading = shading();
    let draw = |radius_m| RefineDraw {
        surface: ClipmapSurface::Detail {
            map: &scene.gpu_map,
            normals: &scene.normals,
            detail: &tiles,
            shading: &shading,
        },
        radius_m,
        camera: &camera,
        style: &style,
        target_size: UVec2::new(64, 64),
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    // 17 half cells: more than 8.
    let err = pass
        .encode(&device, &queue, &mut encoder, &draw(RADIUS))
        .unwrap_err();
    assert!(matches!(err, GpuError::Unsupported { .. }), "{err}");
    // Drawing before the pass was encoded for this camera is refused.
    let err = renderer
        .prepare(&device, &queue, &draw(6.0), &pass)
        .unwrap_err();
    assert!(matches!(err, GpuError::Unsupported { .. }), "{err}");
    for bad in [f32::NAN, 0.0, -1.0, f32::INFINITY, 1e9] {
        assert!(
            pass.encode(&device, &queue, &mut encoder, &draw(bad))
                .is_err()
        );
    }
    let view = pass
        .encode(&device, &queue, &mut encoder, &draw(6.0))
        .unwrap();
    queue.submit([encoder.finish()]);
    renderer
        .prepare(&device, &queue, &draw(6.0), &pass)
        .unwrap();
    // Another camera than the pass's is refused.
    let moved = Camera::looking(camera.position + Vec3::new(3.0, 0.0, 0.0), Vec3::X);
    let other = RefineDraw {
        camera: &moved,
        ..draw(6.0)
    };
    assert!(renderer.prepare(&device, &queue, &other, &pass).is_err());
    // The clipmap of N = 31 morphs from 10 texels on: a region of 7 cells fits, 12 does not.
    scene.renderer.exclude(Some(view.region()));
    scene.prepare(&camera, UVec2::new(64, 64), &SkyColors::default());
    scene
        .renderer
        .exclude(Some((IVec2::splat(-12), IVec2::splat(12))));
    let frame = scene.layout.place(xz, 1.0, (0.0, HEIGHT), None).unwrap();
    let view = terrain_gpu::ClipmapView {
        surface: terrain_gpu::ClipmapSurface::Coarse {
            map: &scene.gpu_map,
            normals: &scene.normals,
        },
        frame: &frame,
        camera: &camera,
        style: &style,
        target_size: UVec2::new(64, 64),
    };
    let err = scene.renderer.prepare(&device, &queue, &view).unwrap_err();
    assert!(matches!(err, GpuError::CannotExclude { .. }), "{err}");
    scene
        .renderer
        .exclude(Some((IVec2::splat(3), IVec2::splat(3))));
    assert!(
        scene.renderer.prepare(&device, &queue, &view).is_err(),
        "empty"
    );
    scene.ctx.check().expect("no GPU validation errors");
}

#[test]
fn counts_ride_the_ring_without_a_wait_and_unsubmitted_requests_free_their_buffers() {
    let Some(ctx) = context_or_skip("refine small readback") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let source = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("counter"),
        size: 16,
        usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut ring = SmallReadback::new(device, 2, 8).unwrap();
    // Recorded but never submitted: the buffers come back, nothing arrives.
    for _ in 0..3 {
        let mut encoder = device.create_command_encoder(&Default::default());
        assert!(ring.request(&mut encoder, &source, 0).unwrap().is_some());
        drop(encoder);
        assert_eq!(ring.in_flight(), 0);
    }
    assert!(ring.poll(device).unwrap().is_empty());
    // Two values in flight fill the ring; a third request is skipped, not an error.
    let mut sent = Vec::new();
    for value in [7u32, 9] {
        queue.write_buffer(&source, 4, bytemuck::bytes_of(&[value, value + 1]));
        let mut encoder = device.create_command_encoder(&Default::default());
        sent.push(ring.request(&mut encoder, &source, 4).unwrap().unwrap());
        queue.submit([encoder.finish()]);
    }
    let mut encoder = device.create_command_encoder(&Default::default());
    assert_eq!(ring.request(&mut encoder, &source, 4).unwrap(), None);
    drop(encoder);
    let mut arrived = Vec::new();
    for _ in 0..1000 {
        arrived.extend(ring.poll(device).unwrap());
        if arrived.len() == 2 {
            break;
        }
        device.poll(terrain_gpu::wait_bounded()).unwrap();
    }
    let values: Vec<(u64, [u32; 2])> = arrived
        .iter()
        .map(|(seq, b)| (*seq, [0, 1].map(|i| bytemuck::cast_slice::<u8, u32>(b)[i])))
        .collect();
    assert_eq!(values, vec![(sent[0], [7, 8]), (sent[1], [9, 10])]);
    // Ranges outside the source or unaligned are refused.
    let mut encoder = device.create_command_encoder(&Default::default());
    assert!(ring.request(&mut encoder, &source, 12).is_err());
    assert!(ring.request(&mut encoder, &source, 2).is_err());
    assert!(SmallReadback::new(device, 0, 8).is_err());
    assert!(SmallReadback::new(device, 2, 6).is_err());
}

/// Renders `camera` with `terrain` (any LOD mode, detail surface) leaving the refined region
/// to the refined mesh through `TerrainRenderer::exclude`; the refined mesh is drawn only where
/// the terrain left its region out (`TerrainRenderer::excluding`), as an engine would.
fn render_refined_with(
    scene: &Scene,
    parts: &mut (RefinePass, RefineRenderer),
    tiles: &GpuDetailTiles,
    terrain: &mut TerrainRenderer,
    camera: &Camera,
    sky: &SkyColors,
) -> Result<(Grid<[u8; 4]>, usize, usize), GpuError> {
    let size = UVec2::new(320, 200);
    let (pass, renderer) = parts;
    let (style, shading) = (style(), shading());
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let mut encoder = device.create_command_encoder(&Default::default());
    let surface = ClipmapSurface::Detail {
        map: &scene.gpu_map,
        normals: &scene.normals,
        detail: tiles,
        shading: &shading,
    };
    let draw = RefineDraw {
        surface,
        radius_m: RADIUS,
        camera,
        style: &style,
        target_size: size,
    };
    let view = pass.encode(device, queue, &mut encoder, &draw)?;
    renderer.prepare(device, queue, &draw, pass)?;
    terrain.exclude(Some(view.region()));
    let frame = TerrainView {
        surface,
        camera,
        style: &style,
        target_size: size,
    };
    terrain.prepare(device, queue, &mut encoder, &frame)?;
    let aspect = size.x as f32 / size.y as f32;
    scene
        .sky
        .prepare(queue, camera.view_proj_relative(aspect), sky)?;
    let target = OffscreenTarget::new(device, size)?;
    {
        let mut rp = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
        scene.sky.draw(&mut rp);
        terrain.draw(&mut rp);
        if terrain.excluding() {
            renderer.draw(&mut rp, pass);
        }
    }
    queue.submit([encoder.finish()]);
    terrain.recall();
    let image = target.read_rgba8(device, queue)?;
    let (tris, overflow) = pass.read_triangles(device, queue)?;
    assert!(!overflow);
    scene.ctx.check().expect("no GPU validation errors");
    Ok((image, tris.len(), view.base_triangles() as usize))
}

/// The refined region meets CDLOD's LOD 0 and the tessellation (which draws the region at full
/// resolution, whatever its triangle width) as it meets the clipmap: no sky through the
/// terrain from grazing views across its edge. A tessellation whose triangles stop short of
/// the texels is refused, not drawn cracked.
#[test]
fn no_cracks_at_the_edge_of_the_refined_region_under_cdlod_and_the_tessellation() {
    let Some(ctx) = context_or_skip("refine_cracks_lod") else {
        return;
    };
    let scene = Scene::new(ctx, 63, 4);
    let (_, tiles) = footprints(&scene);
    let mut parts = refine_parts(&scene);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let map = &scene.map;
    let target = TargetFormat::CAPTURE;
    let cdlod = CdlodConfig::for_map(map.size(), map.wrap(), map.texel_size(), 300.0).unwrap();
    // The region's edge, up to 23 m away, is finer than the view asks at the default width
    // (texel-sized triangles reach about 7 m on this 320-pixel target): drawn at full
    // resolution all the same, also at a width that asks for almost nothing.
    let coarse = TessConfig {
        triangle_width_px: 500.0,
        ..TessConfig::default()
    };
    let magenta = MAGENTA_SKY;
    let mut lods = [
        TerrainRenderer::cdlod(device, &target, map, cdlod).unwrap(),
        TerrainRenderer::tessellated(device, queue, &target, map, TessConfig::default(), true)
            .unwrap(),
        TerrainRenderer::tessellated(device, queue, &target, map, coarse, true).unwrap(),
    ];
    for terrain in &mut lods {
        for (i, xz) in [Vec2::new(93.3, 94.6), Vec2::new(40.9, 180.1)]
            .iter()
            .enumerate()
        {
            for (j, yaw) in [0.0f32, 1.6, 3.9].iter().enumerate() {
                let eye = Vec3::new(xz.x, scene.ground(*xz) + 0.8 + 0.4 * i as f32, xz.y);
                let camera = Camera::looking(eye, Vec3::new(yaw.cos(), 0.0, yaw.sin()));
                let (image, refined, base) =
                    render_refined_with(&scene, &mut parts, &tiles, terrain, &camera, &magenta)
                        .unwrap();
                let mode = terrain.mode();
                assert!(refined >= base, "{mode} view {i}/{j}: the region is drawn");
                assert!(
                    terrain.excluding(),
                    "{mode} view {i}/{j}: left to the refined mesh"
                );
                assert_no_holes(&image, &format!("refine_crack_{mode}_{i}_{j}"));
            }
        }
    }
    // Where the region cannot be left out (tessellation triangles kept above 4 m cannot meet
    // the refined texels; CDLOD's LOD 0 morphing from 10.6 m, inside the 16 m radius, as it
    // does where a leaf's bounds span a cliff or a whole tile), the frame is drawn whole, no
    // refined mesh over it and no hole, and the next frame tries again.
    let capped = TessConfig {
        min_triangle_m: 4.0,
        ..TessConfig::default()
    };
    let short = CdlodConfig {
        finest_range: RADIUS,
        ..cdlod
    };
    let mut refused = [
        TerrainRenderer::tessellated(device, queue, &target, map, capped, true).unwrap(),
        TerrainRenderer::cdlod(device, &target, map, short).unwrap(),
    ];
    let xz = Vec2::new(93.3, 94.6);
    let camera = Camera::looking(Vec3::new(xz.x, scene.ground(xz) + 0.8, xz.y), Vec3::X);
    for terrain in &mut refused {
        let mode = terrain.mode();
        for frame in 0..2 {
            let (image, ..) =
                render_refined_with(&scene, &mut parts, &tiles, terrain, &camera, &magenta)
                    .unwrap();
            assert!(!terrain.excluding(), "{mode} frame {frame}: drawn whole");
            assert_no_holes(&image, &format!("refine_refused_{mode}_{frame}"));
        }
    }
    // A refusal keeps the region for the next frame: excluded once, a camera twice LOD 0's
    // range up (it morphs within its reach of every node) draws the region whole, and the
    // next, near the ground, leaves it out again without being told anew.
    let terrain = &mut lods[0];
    terrain.exclude(Some((IVec2::splat(-4), IVec2::splat(4))));
    let style = style();
    // Looking down at the region (culled from view, no node would meet it).
    let prepare = |terrain: &mut TerrainRenderer, eye: Vec3| {
        let camera = Camera::looking(eye, Vec3::new(0.3, -1.0, 0.0));
        let view = TerrainView {
            surface: ClipmapSurface::Coarse {
                map: &scene.gpu_map,
                normals: &scene.normals,
            },
            camera: &camera,
            style: &style,
            target_size: UVec2::new(320, 200),
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        terrain.prepare(device, queue, &mut encoder, &view).unwrap();
        terrain.recall();
        terrain.excluding()
    };
    let ground = scene.ground(xz);
    let high = ground + 2.0 * cdlod.finest_range;
    assert!(
        !prepare(terrain, Vec3::new(xz.x, high, xz.y)),
        "too high to leave out"
    );
    assert!(
        prepare(terrain, Vec3::new(xz.x, ground + 0.8, xz.y)),
        "left out again"
    );
}
