//! Adaptive tessellation by longest-edge bisection: the mesh is conforming (every edge shared
//! by exactly two triangles, or on the map's border) for every view, the saturated bounds nest,
//! updates equal rebuilds, the morph keeps popping under a pixel, and the density map trades
//! triangles for error where the terrain is flat.

use glam::camera::rh::{proj::directx, view::look_at_mat4};
use glam::{IVec2, UVec2, Vec2, Vec3};
use proptest::prelude::*;
use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
use terrain_lod::{
    CdlodView, DensityMap, DensityParams, Frustum, LodError, TessConfig, TessFrame, TessHierarchy,
};

mod common;

use common::{area, assert_conforming, view};

const TS: f32 = 0.5;

/// Hills on one half, a plane on the other: `w x h` texels of 0.5 m, heights about 0 to 60 m.
fn map(w: u32, h: u32, wrap: WrapMode) -> HeightMap<u16> {
    let grid = Grid::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32, y as f32);
        let hills = if x < w / 2 {
            8_000.0 * ((fx * 0.11).sin() * (fy * 0.07).cos() + 0.4 * (fx * 0.31 + fy * 0.23).sin())
        } else {
            0.0
        };
        (30_000.0 + hills + 10.0 * fy) as u16
    })
    .unwrap();
    HeightMap::new(grid, HeightEncoding::new(0.001, 0.0).unwrap(), TS, wrap).unwrap()
}

#[test]
fn the_mesh_is_conforming_and_covers_the_patches_from_every_view() {
    for wrap in [WrapMode::Clamp, WrapMode::Repeat] {
        let m = map(256, 192, wrap);
        let density = DensityMap::from_map(&m, DensityParams::default()).unwrap();
        for (use_density, morph) in [(true, true), (false, true), (true, false)] {
            let config = TessConfig {
                use_density,
                morph,
                triangle_width_px: 6.0,
                ..TessConfig::default()
            };
            let tess = TessHierarchy::from_map(&m, Some(&density), config).unwrap();
            let extent = tess.patches() * config.patch_size;
            for camera in [
                Vec3::new(10.0, 31.0, 10.0),
                Vec3::new(64.0, 45.0, 48.0),
                Vec3::new(120.0, 80.0, 90.0),
                Vec3::new(-50.0, 200.0, 300.0),
                Vec3::new(127.5, 30.5, 95.5),
            ] {
                let frame = tess.select(&view(camera)).unwrap();
                assert_conforming(&frame, extent);
                let expected = f64::from(extent.x) * f64::from(extent.y);
                assert!(
                    (area(&frame) - expected).abs() < 1e-6 * expected,
                    "{wrap:?}: the triangles cover {} texels, the patches {expected}",
                    area(&frame)
                );
                assert!(frame.triangle_count() > 2 * u64::from(tess.patches().element_product()));
            }
        }
    }
}

#[test]
fn near_the_camera_the_mesh_reaches_the_texels_and_far_away_stays_coarse() {
    let m = map(256, 256, WrapMode::Clamp);
    // Edges of 40 px: about 6 m at the far corner, 150 m away.
    let config = TessConfig {
        triangle_width_px: 40.0,
        ..TessConfig::default()
    };
    let tess = TessHierarchy::from_map(&m, None, config).unwrap();
    let frame = tess.select(&view(Vec3::new(20.0, 32.0, 20.0))).unwrap();
    let hyp =
        |t: &terrain_lod::TessTriangle| Vec2::from(t[0].texel).distance(Vec2::from(t[1].texel));
    let near = frame
        .triangles
        .iter()
        .filter(|t| Vec2::from(t[2].texel).distance(Vec2::splat(40.0)) < 4.0)
        .map(hyp)
        .fold(f32::INFINITY, f32::min);
    let far = frame
        .triangles
        .iter()
        .filter(|t| Vec2::from(t[2].texel).distance(Vec2::splat(250.0)) < 8.0)
        .map(hyp)
        .fold(0.0, f32::max);
    assert!(
        near <= std::f32::consts::SQRT_2 + 1e-4,
        "near hypotenuse {near} texels"
    );
    assert!(far >= 8.0, "far hypotenuse {far} texels");
}

/// No vertex asks for more than the vertex whose triangles split it in: the split decisions
/// are nested, which is what makes the mesh conforming.
#[test]
fn the_split_ratio_never_grows_from_a_vertex_to_the_vertices_it_splits_in() {
    for wrap in [WrapMode::Clamp, WrapMode::Repeat] {
        let m = map(128, 96, wrap);
        let density = DensityMap::from_map(&m, DensityParams::default()).unwrap();
        let tess = TessHierarchy::from_map(&m, Some(&density), TessConfig::default()).unwrap();
        let g = tess.grid_size().as_ivec2();
        let mut pairs = 0;
        for camera in [
            Vec3::new(3.0, 31.0, 40.0),
            Vec3::new(70.0, 90.0, -20.0),
            Vec3::new(32.0, 29.0, 24.0),
        ] {
            let d = tess.decision(&view(camera)).unwrap();
            for y in 0..g.y {
                for x in 0..g.x {
                    let v = IVec2::new(x, y);
                    let rv = tess.ratio(&d, v);
                    for c in tess.children(v) {
                        let rc = tess.ratio(&d, c);
                        assert!(
                            rc <= rv,
                            "{wrap:?}: {c} asks {rc}, its parent {v} only {rv}"
                        );
                        pairs += 1;
                    }
                }
            }
        }
        assert!(pairs > 3 * 128 * 96, "{pairs} pairs");
    }
}

fn frustum_view(camera: Vec3, target: Vec3) -> (glam::Mat4, Frustum) {
    let vp =
        directx::perspective(1.0, 16.0 / 9.0, 0.1, 2000.0) * look_at_mat4(camera, target, Vec3::Y);
    (vp, Frustum::from_view_proj(vp))
}

#[test]
fn culling_drops_what_the_frustum_misses_and_keeps_what_it_sees() {
    let m = map(256, 256, WrapMode::Clamp);
    let tess = TessHierarchy::from_map(&m, None, TessConfig::default()).unwrap();
    let camera = Vec3::new(10.0, 40.0, 10.0);
    let (_, frustum) = frustum_view(camera, Vec3::new(60.0, 30.0, 10.0));
    let all = tess.select(&view(camera)).unwrap();
    let v = CdlodView {
        frustum: Some(&frustum),
        ..view(camera)
    };
    let seen = tess.select(&v).unwrap();
    assert!(seen.culled > 0 && seen.triangle_count() < all.triangle_count() / 2);
    // Every triangle with a corner inside the frustum is still drawn.
    let inside = |t: &terrain_lod::TessTriangle| {
        t.iter()
            .any(|p| frustum.contains_point(Vec3::new(p.texel[0] * TS, p.height, p.texel[1] * TS)))
    };
    let kept: std::collections::HashSet<[u32; 6]> = seen.triangles.iter().map(key6).collect();
    for t in all.triangles.iter().filter(|t| inside(t)) {
        assert!(kept.contains(&key6(t)), "{t:?} is seen but was culled");
    }
}

fn key6(t: &terrain_lod::TessTriangle) -> [u32; 6] {
    [
        t[0].texel[0].to_bits(),
        t[0].texel[1].to_bits(),
        t[1].texel[0].to_bits(),
        t[1].texel[1].to_bits(),
        t[2].texel[0].to_bits(),
        t[2].texel[1].to_bits(),
    ]
}

/// The popping metric on a camera moving at constant speed (0.25 m per frame) low over the
/// hills: under a pixel with the morph, and far over it without (so the test can fail).
#[test]
fn vertices_move_in_instead_of_popping_in() {
    let m = map(256, 256, WrapMode::Clamp);
    let density = DensityMap::from_map(&m, DensityParams::default()).unwrap();
    let mut worst = [0.0f32; 2];
    for (i, morph) in [true, false].into_iter().enumerate() {
        let tess = TessHierarchy::from_map(
            &m,
            Some(&density),
            TessConfig {
                morph,
                ..TessConfig::default()
            },
        )
        .unwrap();
        for step in 0..24 {
            let eye = |s: i32| Vec3::new(8.0 + 0.25 * s as f32, 40.0, 20.0 + 0.1 * s as f32);
            let (now, then) = (eye(step + 1), eye(step));
            let (vp, _) = frustum_view(now, now + Vec3::new(1.0, -0.35, 0.2));
            let frame = tess.select(&view(now)).unwrap();
            let mut probes: Vec<Vec2> = frame
                .triangles
                .iter()
                .flatten()
                .map(|v| Vec2::from(v.texel))
                .step_by(7)
                .collect();
            probes.extend(
                tess.select(&view(then))
                    .unwrap()
                    .triangles
                    .iter()
                    .flatten()
                    .map(|v| Vec2::from(v.texel))
                    .step_by(7),
            );
            let jump = tess.max_height_jump(
                &view(now),
                &view(then),
                &probes,
                vp,
                Vec2::new(1280.0, 720.0),
            );
            worst[i] = worst[i].max(jump);
        }
    }
    eprintln!(
        "popping: {:.3} px with the morph, {:.3} px without",
        worst[0], worst[1]
    );
    assert!(worst[0] < 1.0, "morph on: {} px", worst[0]);
    assert!(worst[1] > 2.0, "morph off: {} px", worst[1]);
}

/// On the plane half the density map asks for almost nothing, so at one triangle width it
/// draws far fewer triangles there (the plane is drawn exactly either way).
#[test]
fn the_density_map_saves_triangles_where_the_terrain_is_flat() {
    let m = map(256, 256, WrapMode::Clamp);
    let density = DensityMap::from_map(&m, DensityParams::default()).unwrap();
    let camera = Vec3::new(64.0, 60.0, 64.0);
    let frames: Vec<(TessFrame, f32)> = [false, true]
        .into_iter()
        .map(|use_density| {
            let tess = TessHierarchy::from_map(
                &m,
                Some(&density),
                TessConfig {
                    use_density,
                    ..TessConfig::default()
                },
            )
            .unwrap();
            let f = tess.select(&view(camera)).unwrap();
            let e = tess.max_screen_error_px(&f, &view(camera));
            (f, e)
        })
        .collect();
    let flat = |f: &TessFrame| f.triangles.iter().filter(|t| t[2].texel[0] > 140.0).count();
    assert!(
        flat(&frames[1].0) * 8 < flat(&frames[0].0),
        "flat half: {} with the density map, {} without",
        flat(&frames[1].0),
        flat(&frames[0].0)
    );
    assert!(frames[1].0.vertex_count() < frames[0].0.vertex_count());
    assert!(frames[0].1 > 0.0 && frames[1].1 > 0.0);
}

#[test]
fn the_screen_error_falls_as_the_triangles_shrink() {
    let m = map(256, 256, WrapMode::Clamp);
    let camera = Vec3::new(30.0, 45.0, 30.0);
    let mut last = f32::INFINITY;
    let mut last_count = 0;
    for width in [64.0, 16.0, 4.0] {
        let tess = TessHierarchy::from_map(
            &m,
            None,
            TessConfig {
                triangle_width_px: width,
                ..TessConfig::default()
            },
        )
        .unwrap();
        let f = tess.select(&view(camera)).unwrap();
        let e = tess.max_screen_error_px(&f, &view(camera));
        assert!(e < last, "width {width}: error {e} px, before {last}");
        assert!(f.triangle_count() > last_count);
        last = e;
        last_count = f.triangle_count();
    }
    // Everything at the texels: the mesh is the map.
    let full = TessHierarchy::from_map(
        &m,
        None,
        TessConfig {
            triangle_width_px: 0.01,
            ..TessConfig::default()
        },
    )
    .unwrap();
    let f = full.select(&view(camera)).unwrap();
    assert_eq!(f.triangle_count(), 2 * 256 * 256);
    assert_eq!(f.vertex_count(), 257 * 257);
    assert!(full.max_screen_error_px(&f, &view(camera)) < 1e-3);
}

/// With the error metric (and the morph off) no texel of the drawn mesh projects further than
/// the bound from the map, for every view: the saturated error bounds the triangles' error.
#[test]
fn the_error_metric_keeps_every_texel_within_the_bound() {
    for wrap in [WrapMode::Clamp, WrapMode::Repeat] {
        let m = map(256, 192, wrap);
        for tau in [0.25f32, 1.0, 4.0] {
            let tess = TessHierarchy::from_map(
                &m,
                None,
                TessConfig {
                    max_error_px: Some(tau),
                    morph: false,
                    ..TessConfig::default()
                },
            )
            .unwrap();
            let mut drawn = 0;
            for camera in [
                Vec3::new(10.0, 31.0, 10.0),
                Vec3::new(64.0, 45.0, 48.0),
                Vec3::new(-50.0, 200.0, 300.0),
                Vec3::new(127.5, 30.5, 95.5),
            ] {
                let frame = tess.select(&view(camera)).unwrap();
                let e = tess.max_screen_error_px(&frame, &view(camera));
                assert!(e <= tau, "{wrap:?} bound {tau} px from {camera}: {e} px");
                assert_conforming(&frame, tess.patches() * 32);
                drawn += frame.triangle_count();
            }
            // Not the full map: the bound is met with fewer triangles.
            assert!(drawn < 4 * 2 * 256 * 192, "{drawn}");
        }
    }
}

#[test]
fn bad_parameters_and_views_are_refused() {
    let m = map(64, 64, WrapMode::Clamp);
    for config in [
        TessConfig {
            patch_size: 0,
            ..TessConfig::default()
        },
        TessConfig {
            patch_size: 48,
            ..TessConfig::default()
        },
        TessConfig {
            patch_size: 512,
            ..TessConfig::default()
        },
        TessConfig {
            triangle_width_px: f32::NAN,
            ..TessConfig::default()
        },
        TessConfig {
            triangle_width_px: 0.0,
            ..TessConfig::default()
        },
        TessConfig {
            min_triangle_m: -1.0,
            ..TessConfig::default()
        },
        TessConfig {
            min_triangle_m: f32::INFINITY,
            ..TessConfig::default()
        },
        TessConfig {
            morph_range: 0.0,
            ..TessConfig::default()
        },
        TessConfig {
            max_triangles: 0,
            ..TessConfig::default()
        },
    ] {
        assert!(matches!(
            TessHierarchy::from_map(&m, None, config),
            Err(LodError::InvalidTessParam { .. })
        ));
    }
    // A repeating map whose sides the patch does not divide is tessellated past its side,
    // over whole patches, with wrapped heights.
    let odd = map(48, 70, WrapMode::Repeat);
    let t = TessHierarchy::from_map(&odd, None, TessConfig::default()).unwrap();
    assert_eq!(t.patches(), UVec2::new(2, 3));
    let f = t.select(&view(Vec3::new(10.0, 40.0, 10.0))).unwrap();
    assert_conforming(&f, UVec2::new(64, 96));
    // A density map of another size.
    let other =
        DensityMap::from_map(&map(32, 32, WrapMode::Clamp), DensityParams::default()).unwrap();
    assert!(matches!(
        TessHierarchy::from_map(&m, Some(&other), TessConfig::default()),
        Err(LodError::SizeMismatch { .. })
    ));
    let tess = TessHierarchy::from_map(&m, None, TessConfig::default()).unwrap();
    for camera in [Vec3::NAN, Vec3::new(f32::INFINITY, 0.0, 0.0)] {
        assert!(matches!(
            tess.select(&view(camera)),
            Err(LodError::NonFinite { .. })
        ));
    }
    let bad_fov = CdlodView {
        hfov: 4.0,
        ..view(Vec3::ONE)
    };
    assert!(tess.select(&bad_fov).is_err());
    // A bound on the triangles: every view answers in bounded memory.
    let small = TessHierarchy::from_map(
        &m,
        None,
        TessConfig {
            triangle_width_px: 0.01,
            max_triangles: 1000,
            ..TessConfig::default()
        },
    )
    .unwrap();
    assert!(matches!(
        small.select(&view(Vec3::new(16.0, 31.0, 16.0))),
        Err(LodError::SelectionTooLarge { limit: 1000 })
    ));
    // Tiny maps still tessellate.
    for (w, h) in [(1, 1), (2, 1), (1, 7)] {
        let tiny =
            TessHierarchy::from_map(&map(w, h, WrapMode::Clamp), None, TessConfig::default())
                .unwrap();
        let f = tiny.select(&view(Vec3::new(0.0, 40.0, 0.0))).unwrap();
        assert!(f.triangle_count() >= 2);
    }
    // The minimum size stops the splits.
    let coarse = TessHierarchy::from_map(
        &m,
        None,
        TessConfig {
            min_triangle_m: 1e6,
            ..TessConfig::default()
        },
    )
    .unwrap();
    assert_eq!(
        coarse
            .select(&view(Vec3::new(16.0, 31.0, 16.0)))
            .unwrap()
            .triangle_count(),
        8
    );
}

/// After a crater, updating the rect gives the bounds a rebuild gives.
fn check_update(wrap: WrapMode, at: IVec2, size: UVec2, depth: u16, with_density: bool) {
    check_update_on(UVec2::new(128, 96), wrap, at, size, depth, with_density);
    if wrap == WrapMode::Repeat {
        // Sides the patch does not divide: the grid goes past the map with wrapped heights.
        check_update_on(UVec2::new(120, 90), wrap, at, size, depth, with_density);
    }
}

fn check_update_on(
    msize: UVec2,
    wrap: WrapMode,
    at: IVec2,
    size: UVec2,
    depth: u16,
    with_density: bool,
) {
    let mut m = map(msize.x, msize.y, wrap);
    let params = DensityParams::default();
    let mut density = DensityMap::from_map(&m, params).unwrap();
    let d0 = with_density.then(|| density.clone());
    let d = with_density.then_some(&density);
    let mut tess = TessHierarchy::from_map(&m, d, TessConfig::default()).unwrap();
    let rect = Rect::new(at, size);
    // The rect's texels: wrapped (each once) on a repeating map, clipped on a clamped one.
    let pieces: Vec<Rect> = match wrap {
        WrapMode::Repeat => rect
            .split_toroidal(m.size())
            .into_iter()
            .map(|p| p.map)
            .collect(),
        WrapMode::Clamp => rect
            .intersect(&Rect::from_size(m.size()))
            .into_iter()
            .collect(),
    };
    for piece in pieces {
        for y in piece.min.y..piece.max().y {
            for x in piece.min.x..piece.max().x {
                let s = m.grid_mut().get_mut(x as u32, y as u32).unwrap();
                *s = s.saturating_sub(depth);
            }
        }
    }
    density.update_rect(&m, rect).unwrap();
    let d = with_density.then_some(&density);
    let rows = tess.update_rect(&m, d, rect).unwrap();
    let rebuilt = TessHierarchy::from_map(&m, d, TessConfig::default()).unwrap();
    let g = tess.grid_size().x as usize;
    let first = |a: &[[f32; 3]], b: &[[f32; 3]]| a.iter().zip(b).position(|(x, y)| x != y);
    if let Some(i) = tess
        .heights()
        .iter()
        .zip(rebuilt.heights())
        .position(|(x, y)| x != y)
    {
        panic!(
            "{wrap:?} {rect:?}: height of vertex {} {} differs",
            i % g,
            i / g
        );
    }
    if let Some(i) = first(tess.bounds(), rebuilt.bounds()) {
        panic!(
            "{wrap:?} {rect:?} density {with_density}: bounds of vertex ({}, {}) are {:?}, rebuilt {:?}",
            i % g,
            i / g,
            tess.bounds()[i],
            rebuilt.bounds()[i]
        );
    }
    assert!(
        tess.patch_bounds() == rebuilt.patch_bounds(),
        "patch bounds"
    );
    // The rows reported are grid rows, each reported once (disjoint ranges).
    let grid_rows = tess.grid_size().y;
    let mut seen = vec![false; grid_rows as usize];
    for r in &rows {
        assert!(
            r.start < r.end && r.end <= grid_rows,
            "{r:?} of {grid_rows} rows"
        );
        for y in r.clone() {
            assert!(!seen[y as usize], "row {y} reported twice in {rows:?}");
            seen[y as usize] = true;
        }
    }
    // Every vertex that changed lies in the rows reported (what a GPU copy must cover).
    let before = TessHierarchy::from_map(
        &map(msize.x, msize.y, wrap),
        d0.as_ref(),
        TessConfig::default(),
    )
    .unwrap();
    for (i, (a, b)) in before.bounds().iter().zip(tess.bounds()).enumerate() {
        let row = (i / g) as u32;
        if a != b || before.heights()[i] != tess.heights()[i] {
            assert!(
                rows.iter().any(|r| r.contains(&row)),
                "row {row} changed, not in {rows:?}"
            );
        }
    }
}

/// Repeating maps smaller than a patch (the grid holds several copies of them) and rects
/// covering everything there is: updates still equal rebuilds, and nothing overflows.
#[test]
fn updates_of_small_maps_and_huge_rects_equal_rebuilds() {
    for (w, h, wrap) in [
        (12, 12, WrapMode::Repeat),
        (20, 40, WrapMode::Repeat),
        (64, 64, WrapMode::Repeat),
        (30, 50, WrapMode::Clamp),
    ] {
        for (at, size) in [
            (IVec2::new(3, 5), UVec2::new(4, 4)),
            (IVec2::new(-7, 11), UVec2::new(9, 30)),
            (IVec2::ZERO, UVec2::MAX),
            (IVec2::splat(i32::MIN), UVec2::MAX),
            (IVec2::splat(i32::MAX - 3), UVec2::splat(3)),
        ] {
            check_update_on(UVec2::new(w, h), wrap, at, size, 5000, true);
        }
    }
}

#[test]
fn updates_at_the_edges_equal_rebuilds() {
    for wrap in [WrapMode::Clamp, WrapMode::Repeat] {
        for with_density in [false, true] {
            check_update(
                wrap,
                IVec2::new(120, 90),
                UVec2::new(12, 10),
                3000,
                with_density,
            );
            check_update(
                wrap,
                IVec2::new(-3, -2),
                UVec2::new(5, 5),
                3000,
                with_density,
            );
            check_update(
                wrap,
                IVec2::new(31, 31),
                UVec2::new(2, 2),
                9000,
                with_density,
            );
        }
    }
}

/// Rects whose last texel is the map's last (the vertices past it repeat it), rects one
/// texel wide at the first column and at a patch boundary (the patches either side hold the
/// vertex on their shared edge), with and without the density map.
#[test]
fn updates_ending_at_the_last_texel_or_on_a_patch_edge_equal_rebuilds() {
    for wrap in [WrapMode::Clamp, WrapMode::Repeat] {
        for with_density in [false, true] {
            for (at, size) in [
                (IVec2::new(120, 90), UVec2::new(8, 6)),
                (IVec2::new(127, 95), UVec2::ONE),
                (IVec2::new(0, 40), UVec2::new(1, 3)),
                (IVec2::new(40, 0), UVec2::new(3, 1)),
                (IVec2::new(32, 40), UVec2::ONE),
                (IVec2::new(40, 32), UVec2::ONE),
                (IVec2::new(64, 64), UVec2::ONE),
            ] {
                check_update(wrap, at, size, 7000, with_density);
            }
        }
    }
}

/// The grid's shape: a repeating map whose sides the patch divides is its own grid (wrapping);
/// any other map gets the cells between its texels, rounded up to whole patches, clamped.
#[test]
fn the_grid_wraps_only_for_repeating_maps_the_patch_tiles() {
    for (w, h, wrap, grid, grid_wrap, patches) in [
        (
            128,
            96,
            WrapMode::Repeat,
            (128, 96),
            WrapMode::Repeat,
            (4, 3),
        ),
        (128, 96, WrapMode::Clamp, (129, 97), WrapMode::Clamp, (4, 3)),
        (
            120,
            90,
            WrapMode::Repeat,
            (129, 97),
            WrapMode::Clamp,
            (4, 3),
        ),
        (33, 20, WrapMode::Clamp, (33, 33), WrapMode::Clamp, (1, 1)),
    ] {
        let m = map(w, h, wrap);
        let tess = TessHierarchy::from_map(&m, None, TessConfig::default()).unwrap();
        assert_eq!(
            tess.grid_size(),
            UVec2::new(grid.0, grid.1),
            "{w}x{h} {wrap:?}"
        );
        assert_eq!(tess.grid_wrap(), grid_wrap, "{w}x{h} {wrap:?}");
        assert_eq!(
            tess.patches(),
            UVec2::new(patches.0, patches.1),
            "{w}x{h} {wrap:?}"
        );
        assert_eq!(tess.wrap(), wrap);
        assert_eq!(tess.texel_size(), TS);
        // One (lowest, highest) per patch, holding the heights of its closed square.
        let pb = tess.patch_bounds();
        assert_eq!(pb.len() as u32, patches.0 * patches.1);
        let g = tess.grid_size();
        for (k, &[lo, hi]) in pb.iter().enumerate() {
            let (px, py) = (k as u32 % patches.0 * 32, k as u32 / patches.0 * 32);
            for y in py..=(py + 32).min(g.y - 1) {
                for x in px..=(px + 32).min(g.x - 1) {
                    let v = tess.heights()[(y * g.x + x) as usize];
                    assert!(lo <= v && v <= hi, "patch {k}: {v} outside {lo} ..= {hi}");
                }
            }
        }
        // 2 log2 P + 1 levels; no children off the grid on either axis.
        assert_eq!(tess.level_count(), 11);
        for v in [
            IVec2::new(-16, 16),
            IVec2::new(16, -16),
            IVec2::new(g.x as i32 + 15, 16),
            IVec2::new(16, g.y as i32 + 15),
        ] {
            assert!(tess.children(v).is_empty(), "{v}");
        }
        assert!(!tess.children(IVec2::new(16, 16)).is_empty());
    }
}

/// The minimum triangle size stops the splitting where the children's hypotenuse
/// (`P sqrt(2)^-l` texels at level `l + 1`) would fall below it: 32 texels of 0.5 m are 16 m,
/// and `16 / sqrt(2)^8 = 1 m`, so a minimum just under 1 m splits 9 levels of the 10 (1 m itself
/// sits on the rounding of `sqrt(2)^-8`).
#[test]
fn the_minimum_triangle_size_caps_the_split_levels() {
    let m = map(64, 64, WrapMode::Clamp);
    for (min_m, levels) in [
        (0.0, 10),
        (0.9, 9),
        (0.99, 9),
        (1.1, 8),
        (16.0, 1),
        (17.0, 0),
    ] {
        let config = TessConfig {
            min_triangle_m: min_m,
            ..TessConfig::default()
        };
        let tess = TessHierarchy::from_map(&m, None, config).unwrap();
        let d = tess.decision(&view(Vec3::new(10.0, 30.0, 10.0))).unwrap();
        assert_eq!(d.split_levels, levels, "minimum {min_m} m");
    }
}

/// A vertex's split ratio falls as the camera rises straight above it, and rises as it comes
/// down towards it (the distance is measured from the vertex's true height).
#[test]
fn the_split_ratio_falls_with_the_height_above_the_vertex() {
    let m = map(64, 64, WrapMode::Clamp);
    let config = TessConfig {
        use_density: false,
        ..TessConfig::default()
    };
    let tess = TessHierarchy::from_map(&m, None, config).unwrap();
    let v = IVec2::new(4, 4);
    let g = tess.grid_size();
    let h = tess.heights()[(v.y as u32 * g.x + v.x as u32) as usize];
    let above = |dy: f32| {
        let camera = Vec3::new(v.x as f32 * TS, h + dy, v.y as f32 * TS);
        let d = tess.decision(&view(camera)).unwrap();
        tess.ratio(&d, v)
    };
    let ratios: Vec<f32> = [10.0, 20.0, 40.0, 80.0, 160.0].map(above).to_vec();
    assert!(ratios.windows(2).all(|w| w[1] < w[0] * 0.75), "{ratios:?}");
    // Below the vertex as far as above it: the same distance, the same ratio.
    assert!(
        (above(-20.0) - above(20.0)).abs() <= 1e-6 * above(20.0),
        "{ratios:?}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn an_update_equals_a_rebuild(
        x in -20i32..140, y in -20i32..110, w in 1u32..40, h in 1u32..40,
        depth in 1u16..20_000, repeat in any::<bool>(), with_density in any::<bool>(),
    ) {
        let wrap = if repeat { WrapMode::Repeat } else { WrapMode::Clamp };
        check_update(wrap, IVec2::new(x, y), UVec2::new(w, h), depth, with_density);
    }

    #[test]
    fn every_view_gives_a_conforming_mesh(
        cx in -100.0f32..200.0, cy in 20.0f32..300.0, cz in -100.0f32..200.0,
        width in 1.0f32..64.0, use_density in any::<bool>(), morph in any::<bool>(),
        patch in 1u32..7,
    ) {
        let m = map(128, 64, WrapMode::Clamp);
        let density = DensityMap::from_map(&m, DensityParams::default()).unwrap();
        let config = TessConfig {
            patch_size: 1 << patch,
            triangle_width_px: width,
            use_density,
            morph,
            ..TessConfig::default()
        };
        let tess = TessHierarchy::from_map(&m, Some(&density), config).unwrap();
        let frame = tess.select(&view(Vec3::new(cx, cy, cz))).unwrap();
        assert_conforming(&frame, tess.patches() * config.patch_size);
    }
}

/// The popping metric by its definition: the largest distance in pixels between the two
/// surface heights at a probe, each projected with `view_proj` (glam's own projection here).
#[test]
fn the_height_jump_is_the_pixel_distance_of_the_two_projections() {
    let m = map(256, 256, WrapMode::Clamp);
    let tess = TessHierarchy::from_map(&m, None, TessConfig::default()).unwrap();
    let (now, then) = (Vec3::new(20.0, 45.0, 30.0), Vec3::new(60.0, 70.0, 30.0));
    let (vp, _) = frustum_view(now, Vec3::new(50.0, 25.0, 40.0));
    let target = Vec2::new(1280.0, 720.0);
    let probes: Vec<Vec2> = (0..40)
        .map(|i| Vec2::new(60.0 + 3.3 * i as f32, 50.0 + 2.1 * (i % 13) as f32))
        .collect();
    let mut want = 0.0f32;
    let mut counted = 0;
    for &p in &probes {
        let (a, b) = (
            tess.surface_height(&view(now), p).unwrap(),
            tess.surface_height(&view(then), p).unwrap(),
        );
        let pixel = |h: f32| {
            let ndc = vp.project_point3(Vec3::new(p.x * TS, h, p.y * TS));
            (ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0 && ndc.z >= 0.0)
                .then(|| (Vec2::new(ndc.x, -ndc.y) * 0.5 + 0.5) * target)
        };
        if let (Some(pa), Some(pb)) = (pixel(a), pixel(b)) {
            want = want.max(pa.distance(pb));
            counted += 1;
        }
    }
    assert!(
        counted > 20 && want > 0.5,
        "{counted} probes on screen, {want} px"
    );
    let got = tess.max_height_jump(&view(now), &view(then), &probes, vp, target);
    assert!((got - want).abs() <= 1e-3 * want, "{got} px vs {want} px");
}

/// Seen from afar nothing splits: each patch is its two base triangles, whose shared
/// hypotenuse alternates between the patch's diagonals like a checkerboard (so the diamonds
/// across patch edges pair up).
#[test]
fn base_triangles_alternate_their_diagonal_like_a_checkerboard() {
    let m = map(128, 128, WrapMode::Clamp);
    let config = TessConfig {
        triangle_width_px: 10_000.0,
        ..TessConfig::default()
    };
    let tess = TessHierarchy::from_map(&m, None, config).unwrap();
    let frame = tess.select(&view(Vec3::new(32.0, 500.0, 32.0))).unwrap();
    let n = tess.patches();
    assert_eq!(frame.triangle_count(), 2 * u64::from(n.x * n.y));
    for t in &frame.triangles {
        let c: Vec<Vec2> = t.iter().map(|v| Vec2::from(v.texel)).collect();
        let (px, py) = {
            let lo = c.iter().fold(Vec2::splat(f32::MAX), |a, &b| a.min(b));
            ((lo.x / 32.0) as i32, (lo.y / 32.0) as i32)
        };
        // The longest edge is the hypotenuse.
        let edges = [(c[0], c[1]), (c[1], c[2]), (c[2], c[0])];
        let (a, b) = edges
            .into_iter()
            .max_by(|x, y| x.0.distance(x.1).total_cmp(&y.0.distance(y.1)))
            .unwrap();
        let o = Vec2::new(px as f32, py as f32) * 32.0;
        let main = [o, o + 32.0];
        let anti = [o + Vec2::new(32.0, 0.0), o + Vec2::new(0.0, 32.0)];
        let want = if (px + py) % 2 == 0 { main } else { anti };
        assert!(
            (a == want[0] && b == want[1]) || (a == want[1] && b == want[0]),
            "patch ({px}, {py}): hypotenuse {a} - {b}"
        );
    }
}

/// A triangle budget of exactly what a view draws is enough: one patch of 32 texels seen from
/// just above, split down to the texels, is 2 * 32^2 = 2048 triangles; 2047 refuses.
#[test]
fn a_budget_of_exactly_the_drawn_triangles_is_enough() {
    let m = map(33, 33, WrapMode::Clamp);
    let budget = |max_triangles: usize| TessConfig {
        triangle_width_px: 0.01,
        use_density: false,
        morph: false,
        max_triangles,
        ..TessConfig::default()
    };
    let camera = Vec3::new(8.0, 40.0, 8.0);
    let full = TessHierarchy::from_map(&m, None, budget(1 << 22)).unwrap();
    assert_eq!(full.select(&view(camera)).unwrap().triangle_count(), 2048);
    let exact = TessHierarchy::from_map(&m, None, budget(2048)).unwrap();
    assert_eq!(exact.select(&view(camera)).unwrap().triangle_count(), 2048);
    let short = TessHierarchy::from_map(&m, None, budget(2047)).unwrap();
    assert!(short.select(&view(camera)).is_err());
}
