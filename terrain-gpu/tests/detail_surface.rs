//! What the renderer shades a detail layer with, against the CPU: `DetailProbe` (the detail
//! clipmap's own WGSL functions) against `DetailLayer::height_m`, `gradient_m` and eq. 3.4's
//! `composite_normal`; and the detail clipmap's frames against the coarse one's. On whatever
//! adapter the machine has (lavapipe in CI); without one they skip, or fail under
//! `TERRAIN_REQUIRE_GPU=1`.

#[path = "common/footprints.rs"]
#[allow(dead_code)] // the frame comparisons of the LOD tests
mod footprints;
#[path = "common/scene.rs"]
#[allow(dead_code)] // the golden view's parts of the shared scene
mod scene;

use footprints::{camera, scene_with_footprints};
use glam::{IVec2, UVec2, Vec2};
use scene::Scene;
use terrain_core::detail::{DetailLayer, DetailLayout};
use terrain_core::{Grid, composite_normal};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    ClipmapSurface, ClipmapView, DetailProbe, DetailProbePoint, DetailShading, GpuDetailTiles,
    GpuError, SkyColors, TerrainStyle,
};

/// A 24 x 20 coarse-map at 0.75 m refined x3 (0.25 m detail texels: every probe position below
/// is exact in f32 on both sides), 72 x 60 detail texels in 5 x 4 tiles of 16 (the last column
/// and row reach past the map).
fn layout() -> DetailLayout {
    DetailLayout::new(UVec2::new(24, 20), 0.75, 3, 16).unwrap()
}

/// Smooth marks of up to ±40 units around 0 m, different per tile.
fn marks(tile: UVec2) -> Grid<u8> {
    Grid::from_fn(16, 16, |x, y| {
        let (fx, fy) = ((x + 16 * tile.x) as f32, (y + 16 * tile.y) as f32);
        let v = 40.0 * (fx * 0.37 + tile.y as f32).sin() * (fy * 0.23 - tile.x as f32).cos();
        (128.0 + v).round() as u8
    })
    .unwrap()
}

#[test]
fn the_shaders_detail_height_gradient_and_composite_normal_equal_the_cpu_reference() {
    let Some(ctx) = context_or_skip("detail_probe") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let layout = layout();
    let mut layer = DetailLayer::new(layout).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout, 8).unwrap();
    // Six tiles with marks (one of them then unloaded: drawn as 0 m, as the CPU layer without
    // it), the rest the zero tile; marks meet the map's wrap at the tiles of row 0 and column 0.
    let marked = [(0, 0), (1, 0), (4, 0), (0, 3), (2, 2), (3, 1)];
    for &(x, y) in &marked {
        let t = UVec2::new(x, y);
        tiles.load(queue, t, Some(&marks(t))).unwrap();
        if (x, y) == (3, 1) {
            tiles.unload(queue, t);
        } else {
            layer.set_tile(t, marks(t)).unwrap();
        }
    }
    let mut probe = DetailProbe::new(device, 4096).unwrap();
    let coarse = layout.coarse_size().as_ivec2();
    // Bases far from the map and negative: the layer repeats.
    for base in [
        IVec2::ZERO,
        IVec2::new(7, 13),
        IVec2::new(-1_000_003, 77),
        IVec2::new(123_456, -98_765),
    ] {
        let mut points = Vec::new();
        for i in 0..1500u32 {
            // Offsets in eighths of a coarse texel over two periods of the map, both signs.
            let h = i.wrapping_mul(0x9E37_79B9) ^ (i >> 3).wrapping_mul(0x85EB_CA6B);
            let q = Vec2::new(
                ((h % 400) as f32 - 200.0) / 8.0,
                (((h >> 9) % 340) as f32 - 170.0) / 8.0,
            );
            let coarse_gradient = Vec2::new(((h >> 20) % 9) as f32 * 0.1 - 0.4, 0.3);
            points.push(DetailProbePoint { q, coarse_gradient });
        }
        let got = probe.read(device, queue, &tiles, base, &points).unwrap();
        assert_eq!(got.len(), points.len());
        let wrapped = IVec2::new(base.x.rem_euclid(coarse.x), base.y.rem_euclid(coarse.y));
        let mut nonzero = 0;
        for (p, g) in points.iter().zip(&got) {
            let pos = (wrapped.as_vec2() + p.q) * layout.coarse_texel_m();
            let h = layer.height_m(pos);
            let d = layer.gradient_m(pos);
            let n = composite_normal(p.coarse_gradient, d);
            assert!(
                (g.height - h).abs() <= 1e-5,
                "base {base} q {}: height {} vs {h}",
                p.q,
                g.height
            );
            assert!(
                (g.gradient - d).abs().max_element() <= 1e-5 * (1.0 + d.abs().max_element()),
                "base {base} q {}: gradient {} vs {d}",
                p.q,
                g.gradient
            );
            assert!(
                (g.normal - n).abs().max_element() <= 1e-5,
                "base {base} q {}: normal {} vs {n}",
                p.q,
                g.normal
            );
            nonzero += usize::from(d != Vec2::ZERO);
        }
        assert!(nonzero > 300, "the points cross the marks ({nonzero})");
    }
    // Out of range points are refused.
    let far = DetailProbePoint {
        q: Vec2::new(5000.0, 0.0),
        coarse_gradient: Vec2::ZERO,
    };
    assert!(
        probe
            .read(device, queue, &tiles, IVec2::ZERO, &[far])
            .is_err()
    );
    let nan = DetailProbePoint {
        q: Vec2::new(f32::NAN, 0.0),
        coarse_gradient: Vec2::ZERO,
    };
    assert!(
        probe
            .read(device, queue, &tiles, IVec2::ZERO, &[nan])
            .is_err()
    );
    ctx.check().expect("no GPU validation errors");
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

const SIZE: UVec2 = UVec2::new(256, 160);

#[test]
fn detail_footprints_show_in_the_frame_and_fade_out_with_distance() {
    let Some(ctx) = context_or_skip("detail_render") else {
        return;
    };
    let (mut scene, _) = scene_with_footprints(ctx, 128);
    let sky = SkyColors::default();
    let cam = camera(&scene);
    let (with_detail, _) = scene.render(&cam, SIZE, &sky);
    let detail = scene.detail.take();
    let (coarse, _) = scene.render(&cam, SIZE, &sky);
    let (max, strong) = frame_diff(&with_detail, &coarse);
    if !(max > 40 && strong > 250) {
        let dir = std::env::temp_dir();
        let _ = terrain_core::io::write_png_rgba8(dir.join("detail_footprints.png"), &with_detail);
        let _ = terrain_core::io::write_png_rgba8(dir.join("detail_coarse.png"), &coarse);
        panic!(
            "the footprints hardly change the frame: max {max}, {strong} pixels (frames in the temp dir)"
        );
    }
    // Faded out before the nearest fragment (the camera is 3 m up): the coarse frame.
    let (tiles, _) = detail.unwrap();
    let faded = DetailShading {
        fade_start_m: 0.5,
        fade_end_m: 1.0,
        ..DetailShading::default()
    };
    scene.detail = Some((tiles, faded));
    let (far, _) = scene.render(&cam, SIZE, &sky);
    let (max, _) = frame_diff(&far, &coarse);
    assert!(
        max <= 1,
        "a faded-out detail layer draws the coarse frame (max {max})"
    );
}

/// The parallax hook skips fragments whose reads all fall in tiles without a slot, on layers
/// of whole tiles: the same marks in 128-texel tiles (16 a side: skipped) and in 120-texel
/// tiles (not whole: never skipped) draw the same frame.
#[test]
fn skipping_zero_tiles_changes_no_pixel() {
    let Some(ctx) = context_or_skip("detail_render_skip") else {
        return;
    };
    let (mut even, _) = scene_with_footprints(ctx, 128);
    let sky = SkyColors::default();
    let cam = camera(&even);
    let (a, _) = even.render(&cam, SIZE, &sky);
    let Some(ctx) = context_or_skip("detail_render_skip") else {
        return;
    };
    let (mut uneven, _) = scene_with_footprints(ctx, 120);
    let (b, _) = uneven.render(&cam, SIZE, &sky);
    let (max, _) = frame_diff(&a, &b);
    assert!(max <= 1, "the skip changes pixels by up to {max}");
}

#[test]
fn a_detail_layer_of_zero_tiles_draws_the_coarse_frame() {
    let Some(ctx) = context_or_skip("detail_render_zero") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let sky = SkyColors::default();
    let cam = camera(&scene);
    let (coarse, _) = scene.render(&cam, SIZE, &sky);
    let layout = DetailLayout::new(scene.map.size(), 1.0, 3, 64).unwrap();
    let tiles = GpuDetailTiles::new(&scene.ctx.device, layout, 1).unwrap();
    scene.detail = Some((tiles, DetailShading::default()));
    let (zero, _) = scene.render(&cam, SIZE, &sky);
    let (max, _) = frame_diff(&zero, &coarse);
    assert!(max <= 1, "zero detail changes nothing (max {max})");
}

#[test]
fn detail_surfaces_that_do_not_fit_the_map_or_bad_shading_are_refused() {
    let Some(ctx) = context_or_skip("detail_render_refused") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let cam = camera(&scene);
    let frame = scene
        .layout
        .place(
            Vec2::new(cam.position.x, cam.position.z),
            1.0,
            (0.0, 40.0),
            None,
        )
        .unwrap();
    let style = TerrainStyle::default();
    let other = DetailLayout::new(UVec2::new(128, 256), 1.0, 3, 64).unwrap();
    let spacing = DetailLayout::new(scene.map.size(), 0.5, 3, 64).unwrap();
    let fits = DetailLayout::new(scene.map.size(), 1.0, 3, 64).unwrap();
    let bad_shadings = [
        DetailShading {
            fade_end_m: 10.0,
            fade_start_m: 20.0,
            ..DetailShading::default()
        },
        DetailShading {
            fade_start_m: f32::NAN,
            ..DetailShading::default()
        },
        DetailShading {
            fade_end_m: f32::INFINITY,
            ..DetailShading::default()
        },
        DetailShading {
            parallax_steps: 100_000,
            ..DetailShading::default()
        },
        DetailShading {
            max_reach_texels: -1.0,
            ..DetailShading::default()
        },
        DetailShading {
            fade_end_m: 1e30,
            ..DetailShading::default()
        },
    ];
    let mut cases: Vec<(GpuDetailTiles, DetailShading)> = vec![
        (
            GpuDetailTiles::new(device, other, 1).unwrap(),
            DetailShading::default(),
        ),
        (
            GpuDetailTiles::new(device, spacing, 1).unwrap(),
            DetailShading::default(),
        ),
    ];
    for s in bad_shadings {
        cases.push((GpuDetailTiles::new(device, fits, 1).unwrap(), s));
    }
    for (tiles, shading) in &cases {
        let view = ClipmapView {
            surface: ClipmapSurface::Detail {
                map: &scene.gpu_map,
                normals: &scene.normals,
                detail: tiles,
                shading,
            },
            frame: &frame,
            camera: &cam,
            style: &style,
            target_size: SIZE,
        };
        let err = scene.renderer.prepare(device, queue, &view).unwrap_err();
        assert!(
            matches!(
                err,
                GpuError::SizeMismatch { .. } | GpuError::Unsupported { .. } | GpuError::Core(_)
            ),
            "{err}"
        );
    }
    scene.ctx.check().expect("no GPU validation errors");
}
