//! Density maps: the curvature filters against analytic surfaces, the pipeline against a
//! brute-force evaluation of its definition, dirty-rect updates against a full rebuild, the
//! pyramid's borders, parameters, and thread-count independence.

use glam::{IVec2, UVec2};
use proptest::prelude::*;
use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
use terrain_lod::density::{DENSITY_DOWNSAMPLE, Neighbourhood, curvature, density_size};
use terrain_lod::{CurvatureFilter, DensityMap, DensityParams, LodError};

/// First and second derivatives of an analytic surface at a point: (hx, hy, hxx, hyy, hxy).
type Derivs = (f64, f64, f64, f64, f64);

struct Surface {
    name: &'static str,
    h: fn(f64, f64) -> f64,
    d: fn(f64, f64) -> Derivs,
}

const R: f64 = 20.0;

fn surfaces() -> Vec<Surface> {
    vec![
        Surface {
            name: "plane",
            h: |x, y| 0.3 * x - 0.2 * y + 4.0,
            d: |_, _| (0.3, -0.2, 0.0, 0.0, 0.0),
        },
        Surface {
            name: "paraboloid",
            h: |x, y| 0.05 * x * x + 0.02 * y * y,
            d: |x, y| (0.1 * x, 0.04 * y, 0.1, 0.04, 0.0),
        },
        Surface {
            name: "saddle",
            h: |x, y| 0.04 * x * x - 0.03 * y * y + 0.02 * x * y,
            d: |x, y| (0.08 * x + 0.02 * y, -0.06 * y + 0.02 * x, 0.08, -0.06, 0.02),
        },
        Surface {
            name: "sphere cap",
            h: |x, y| (R * R - x * x - y * y).sqrt(),
            d: |x, y| {
                let h = (R * R - x * x - y * y).sqrt();
                let h3 = h * h * h;
                (
                    -x / h,
                    -y / h,
                    -(R * R - y * y) / h3,
                    -(R * R - x * x) / h3,
                    -x * y / h3,
                )
            },
        },
    ]
}

/// What each filter estimates, from the analytic derivatives (1 / m).
fn analytic(filter: CurvatureFilter, (hx, hy, hxx, hyy, hxy): Derivs) -> f64 {
    let g = 1.0 + hx * hx + hy * hy;
    let mean =
        (hxx * (1.0 + hy * hy) - 2.0 * hxy * hx * hy + hyy * (1.0 + hx * hx)) / (2.0 * g.powf(1.5));
    match filter {
        CurvatureFilter::Laplace => (hxx + hyy).abs(),
        CurvatureFilter::Gaussian => ((hxx * hyy - hxy * hxy) / (g * g)).abs().sqrt(),
        _ => mean.abs(),
    }
}

fn neighbourhood(h: fn(f64, f64) -> f64, x: f64, y: f64, s: f64) -> Neighbourhood {
    let c = h(x, y);
    let at = |dx: f64, dy: f64| (h(x + dx * s, y + dy * s) - c) as f32;
    [
        at(-1.0, 0.0),
        at(1.0, 0.0),
        at(0.0, -1.0),
        at(0.0, 1.0),
        at(-1.0, -1.0),
        at(1.0, -1.0),
        at(-1.0, 1.0),
        at(1.0, 1.0),
    ]
}

/// The stated accuracy of each filter, relative to the largest analytic value on the surface
/// (floored at 1e-3 / m) at 0.25 m spacing: central differences are exact on quadratics up to
/// f32 rounding (measured <= 8e-6), the sphere cap's error is of order (spacing / R)^2
/// (measured <= 6e-5), and the cotangent Laplace-Beltrami filters measured <= 2e-4.
fn tolerance(filter: CurvatureFilter) -> f64 {
    match filter {
        CurvatureFilter::Laplace | CurvatureFilter::Gaussian | CurvatureFilter::Mean => 1e-4,
        CurvatureFilter::LaplaceBeltramiArea | CurvatureFilter::LaplaceBeltramiVoronoi => 1e-3,
    }
}

#[test]
fn filters_match_analytic_surfaces() {
    let spacing = 0.25;
    let mut worst = Vec::new();
    for surface in surfaces() {
        for filter in CurvatureFilter::ALL {
            let mut max_err = 0.0f64;
            let mut max_val = 1e-3f64; // a floor so the plane is judged absolutely
            for i in -6..=6 {
                for j in -6..=6 {
                    let (x, y) = (f64::from(i) * 0.9, f64::from(j) * 0.7);
                    let want = analytic(filter, (surface.d)(x, y));
                    let d = neighbourhood(surface.h, x, y, spacing);
                    let got = f64::from(curvature(filter, &d, spacing as f32));
                    max_err = max_err.max((got - want).abs());
                    max_val = max_val.max(want);
                }
            }
            let rel = max_err / max_val;
            worst.push(format!("{} {}: {rel:.2e}", surface.name, filter.name()));
            assert!(
                rel <= tolerance(filter),
                "{} with {}: error {max_err:e} against values up to {max_val:e} ({rel:.3} > {})",
                surface.name,
                filter.name(),
                tolerance(filter)
            );
        }
    }
    println!("relative errors: {}", worst.join(", "));
}

#[test]
fn the_sphere_cap_has_mean_curvature_one_over_r_everywhere() {
    let h = surfaces()
        .into_iter()
        .find(|s| s.name == "sphere cap")
        .unwrap()
        .h;
    for filter in [
        CurvatureFilter::Mean,
        CurvatureFilter::Gaussian,
        CurvatureFilter::LaplaceBeltramiArea,
        CurvatureFilter::LaplaceBeltramiVoronoi,
    ] {
        for (x, y) in [(0.0, 0.0), (5.0, -3.0), (-8.0, 6.0)] {
            let got = f64::from(curvature(filter, &neighbourhood(h, x, y, 0.2), 0.2));
            assert!(
                (got * R - 1.0).abs() < 0.05,
                "{filter:?} at ({x}, {y}): {got}"
            );
        }
    }
}

fn map_from(w: u32, h: u32, wrap: WrapMode, f: impl FnMut(u32, u32) -> u16) -> HeightMap<u16> {
    let grid = Grid::from_fn(w, h, f).unwrap();
    HeightMap::new(grid, HeightEncoding::new(0.01, -5.0).unwrap(), 0.5, wrap).unwrap()
}

fn bumpy(w: u32, h: u32, wrap: WrapMode, seed: u32) -> HeightMap<u16> {
    map_from(w, h, wrap, |x, y| {
        let v = (x.wrapping_mul(7919) ^ y.wrapping_mul(104_729) ^ seed).wrapping_mul(2_654_435_761);
        let smooth = ((x as f32 * 0.3).sin() * 900.0 + (y as f32 * 0.17).cos() * 700.0) as i32;
        (20_000 + smooth + (v >> 26) as i32) as u16
    })
}

/// A full-density bend that leaves `bumpy` maps' samples spread over the u8 range (at the
/// default 0.5 nearly every sample of such a rough map is 255, and a test comparing two
/// all-255 grids cannot tell which window or which sample a level used).
const SPREAD_BEND: f32 = 4.0;

/// Asserts that a level's samples take many values, so comparing it tells windows apart.
fn assert_spread(level: &Grid<u8>, what: &str) {
    let mut seen = [false; 256];
    for &v in level.as_slice() {
        seen[usize::from(v)] = true;
    }
    let distinct = seen.iter().filter(|&&s| s).count();
    let saturated = level.as_slice().iter().filter(|&&v| v == 255).count();
    assert!(
        distinct >= 16 && saturated * 4 < level.as_slice().len(),
        "{what}: {distinct} distinct values, {saturated} of {} saturated",
        level.as_slice().len()
    );
}

/// The density map's level 0 by its definition, sample by sample, with no shared work.
fn brute_force_raw(map: &HeightMap<u16>, filter: CurvatureFilter) -> Grid<f32> {
    let size = density_size(map.size());
    let g = map.grid();
    let wrap = map.wrap();
    let s = map.encoding().scale;
    let at = |x: i64, y: i64| {
        let col = wrap.resolve(x, g.width());
        let row = wrap.resolve(y, g.height());
        f32::from(g.get(col, row).unwrap())
    };
    Grid::from_fn(size.x, size.y, |i, j| {
        let mut m = 0.0f32;
        let d = i64::from(DENSITY_DOWNSAMPLE);
        for ty in (i64::from(j) * d - 1)..=(i64::from(j) * d + 4) {
            for tx in (i64::from(i) * d - 1)..=(i64::from(i) * d + 4) {
                let c = at(tx, ty);
                let n = [
                    (at(tx - 1, ty) - c) * s,
                    (at(tx + 1, ty) - c) * s,
                    (at(tx, ty - 1) - c) * s,
                    (at(tx, ty + 1) - c) * s,
                    (at(tx - 1, ty - 1) - c) * s,
                    (at(tx + 1, ty - 1) - c) * s,
                    (at(tx - 1, ty + 1) - c) * s,
                    (at(tx + 1, ty + 1) - c) * s,
                ];
                m = m.max(curvature(filter, &n, map.texel_size()));
            }
        }
        m * map.texel_size()
    })
    .unwrap()
}

#[test]
fn level_zero_is_the_windowed_maximum_of_the_filter() {
    for (w, h, wrap) in [
        (64, 48, WrapMode::Repeat),
        (30, 21, WrapMode::Repeat),
        (37, 19, WrapMode::Clamp),
    ] {
        let map = bumpy(w, h, wrap, 3);
        for filter in CurvatureFilter::ALL {
            let params = DensityParams {
                filter,
                ..Default::default()
            };
            let dm = DensityMap::from_map(&map, params).unwrap();
            assert_eq!(
                dm.raw(),
                &brute_force_raw(&map, filter),
                "{w}x{h} {wrap:?} {filter:?}"
            );
        }
    }
}

/// Level 0 after preprocessing and quantisation, by definition.
fn brute_force_level0(dm: &DensityMap, wrap: WrapMode) -> Grid<u8> {
    let raw = dm.raw();
    let p = dm.params();
    let (r, rb) = p.filter_radii();
    Grid::from_fn(raw.width(), raw.height(), |i, j| {
        let border = i % p.tile_size == 0 || j % p.tile_size == 0;
        let rad = i64::from(if border { rb } else { r });
        let mut m = 0.0f32;
        for y in i64::from(j) - rad..=i64::from(j) + rad {
            for x in i64::from(i) - rad..=i64::from(i) + rad {
                let v = raw
                    .get(wrap.resolve(x, raw.width()), wrap.resolve(y, raw.height()))
                    .unwrap();
                m = m.max(v);
            }
        }
        p.quantize(m)
    })
    .unwrap()
}

#[test]
fn preprocessing_widens_the_window_on_tile_borders() {
    let map = bumpy(96, 80, WrapMode::Repeat, 9);
    for (filter_size, skip, preprocess) in [(3, 1, true), (5, 0, true), (1, 2, true), (3, 1, false)]
    {
        let params = DensityParams {
            filter_size,
            border_lod_skip: skip,
            preprocess,
            tile_size: 8,
            full_density_bend: SPREAD_BEND,
            ..Default::default()
        };
        let dm = DensityMap::from_map(&map, params).unwrap();
        assert_spread(dm.level(0).unwrap(), "level 0");
        assert_eq!(
            dm.level(0).unwrap(),
            &brute_force_level0(&dm, WrapMode::Repeat),
            "size {filter_size} skip {skip}"
        );
    }
    let p = DensityParams {
        filter_size: 3,
        border_lod_skip: 2,
        ..Default::default()
    };
    // eq. 3.8: s_b = 3 * 2^2 = 12, a radius of 6.
    assert_eq!(p.filter_radii(), (1, 6));
}

#[test]
fn coarser_levels_are_maxima_inside_and_point_samples_on_borders() {
    let map = bumpy(256, 192, WrapMode::Repeat, 5);
    let params = DensityParams {
        tile_size: 4,
        full_density_bend: SPREAD_BEND,
        ..Default::default()
    };
    let dm = DensityMap::from_map(&map, params).unwrap();
    assert_eq!(dm.level_count(), 7); // 64x48, 32x24, 16x12, 8x6, 4x3, 2x2, 1x1
    for k in 0..3 {
        assert_spread(dm.level(k).unwrap(), &format!("level {k}"));
    }
    for k in 1..dm.level_count() {
        let (child, parent) = (dm.level(k - 1).unwrap(), dm.level(k).unwrap());
        assert_eq!(
            parent.size(),
            UVec2::new(child.width().div_ceil(2), child.height().div_ceil(2))
        );
        for j in 0..parent.height() {
            for i in 0..parent.width() {
                let (cx, cy) = (
                    (2 * i).min(child.width() - 1),
                    (2 * j).min(child.height() - 1),
                );
                let v = parent.get(i, j).unwrap();
                if i % 4 == 0 || j % 4 == 0 {
                    assert_eq!(
                        v,
                        child.get(cx, cy).unwrap(),
                        "border ({i}, {j}) of level {k}"
                    );
                } else {
                    let mut m = 0;
                    for y in cy.saturating_sub(1)..=(cy + 1).min(child.height() - 1) {
                        for x in cx.saturating_sub(1)..=(cx + 1).min(child.width() - 1) {
                            m = m.max(child.get(x, y).unwrap());
                        }
                    }
                    assert_eq!(v, m, "inner ({i}, {j}) of level {k}");
                    // A maximum never loses curvature the finer level had under it.
                    assert!(v >= child.get(cx, cy).unwrap());
                }
            }
        }
    }
    // Border samples of every level are the level-0 samples at the same place: neighbouring
    // tiles of different levels agree along their shared edge.
    let l0 = dm.level(0).unwrap();
    for k in 1..dm.level_count() {
        let lk = dm.level(k).unwrap();
        for j in 0..lk.height() {
            let (x0, y0) = (0u32, (j << k).min(l0.height() - 1));
            if (j << k) < l0.height() {
                assert_eq!(lk.get(0, j).unwrap(), l0.get(x0, y0).unwrap());
            }
        }
    }
}

fn stamp(map: &mut HeightMap<u16>, rect: Rect, seed: u32) {
    let size = map.size();
    for piece in rect.split_toroidal(size) {
        let r = piece.map;
        for y in r.min.y..r.max().y {
            for x in r.min.x..r.max().x {
                let v = map.grid_mut().get_mut(x as u32, y as u32).unwrap();
                let bump = ((x as u32 ^ seed).wrapping_mul(40_503) >> 20) as u16;
                *v = v.wrapping_add(bump % 3000);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// After any deformation (across the map's edges on a repeating map, clipped on a clamped
    /// one), updating the dirty rect gives the map a full rebuild gives.
    #[test]
    fn dirty_updates_equal_a_rebuild(
        w in 9u32..70, h in 9u32..70,
        x in -80i32..80, y in -80i32..80, sw in 1u32..40, sh in 1u32..40,
        repeat in any::<bool>(), filter in 0usize..5, seed in any::<u32>(), tile in 2u32..9,
    ) {
        let wrap = if repeat { WrapMode::Repeat } else { WrapMode::Clamp };
        let mut map = bumpy(w, h, wrap, seed);
        let params = DensityParams {
            filter: CurvatureFilter::ALL[filter],
            tile_size: tile,
            full_density_bend: SPREAD_BEND,
            ..Default::default()
        };
        let mut dm = DensityMap::from_map(&map, params).unwrap();
        let mut rect = Rect::new(IVec2::new(x, y), UVec2::new(sw, sh));
        if !repeat {
            // Clamped maps change only inside; the rect given may still reach past the edge.
            let inside = rect.intersect(&Rect::from_size(map.size()));
            match inside {
                Some(r) => stamp(&mut map, r, seed),
                None => rect = Rect::new(IVec2::ZERO, UVec2::ONE),
            }
        } else {
            stamp(&mut map, rect, seed);
        }
        dm.update_rect(&map, rect).unwrap();
        let fresh = DensityMap::from_map(&map, params).unwrap();
        prop_assert_eq!(dm, fresh);
    }
}

#[test]
fn a_crater_raises_the_density_where_it_lands_only() {
    let mut map = map_from(256, 256, WrapMode::Repeat, |_, _| 30_000);
    let mut dm = DensityMap::from_map(&map, DensityParams::default()).unwrap();
    assert!(
        dm.level(0).unwrap().as_slice().iter().all(|&v| v == 0),
        "flat is zero density"
    );
    let centre = (60.0f32, 100.0f32);
    for y in 80..120 {
        for x in 40..80 {
            let r2 = (x as f32 - centre.0).powi(2) + (y as f32 - centre.1).powi(2);
            let depth = 2000.0 * (-r2 / 60.0).exp();
            *map.grid_mut().get_mut(x, y).unwrap() -= depth as u16;
        }
    }
    let dirty = Rect::new(IVec2::new(40, 80), UVec2::new(40, 40));
    dm.update_rect(&map, dirty).unwrap();
    let l0 = dm.level(0).unwrap();
    let max = l0.as_slice().iter().copied().max().unwrap();
    assert!(
        max > 128,
        "a 20 m deep Gaussian crater asks for dense tessellation: {max}"
    );
    // Far from the crater the terrain is still flat.
    assert_eq!(dm.density_at_texel(0, IVec2::new(200, 200)), Some(0.0));
    assert!(dm.density_at_texel(0, IVec2::new(60, 100)).unwrap() > 0.5);
    // Wrapped lookups read the same samples.
    assert_eq!(
        dm.density_at_texel(0, IVec2::new(60 + 256, 100 - 512)),
        dm.density_at_texel(0, IVec2::new(60, 100))
    );
    assert_eq!(dm.density_at_texel(dm.level_count(), IVec2::ZERO), None);
}

#[test]
fn gain_and_exponent_shape_the_values() {
    let p = DensityParams::default();
    assert_eq!(p.quantize(0.0), 0);
    assert_eq!(p.quantize(p.full_density_bend), 255);
    assert_eq!(p.quantize(f32::INFINITY), 255);
    assert_eq!(p.quantize(f32::NAN), 0);
    assert_eq!(p.quantize(p.full_density_bend * 0.5), 128);
    let gained = DensityParams { gain: 2.0, ..p };
    assert_eq!(gained.quantize(p.full_density_bend * 0.5), 255);
    let shaped = DensityParams { exponent: 2.0, ..p };
    // 0.5^2 = 0.25, and 1 still maps to 1 (sec. 3.3.4).
    assert_eq!(shaped.quantize(p.full_density_bend * 0.5), 64);
    assert_eq!(shaped.quantize(p.full_density_bend), 255);
}

#[test]
fn bad_parameters_are_named() {
    let map = bumpy(16, 16, WrapMode::Repeat, 1);
    let cases: Vec<(DensityParams, &str)> = vec![
        (
            DensityParams {
                gain: f32::NAN,
                ..Default::default()
            },
            "gain",
        ),
        (
            DensityParams {
                gain: -1.0,
                ..Default::default()
            },
            "gain",
        ),
        (
            DensityParams {
                exponent: 0.0,
                ..Default::default()
            },
            "exponent",
        ),
        (
            DensityParams {
                exponent: f32::INFINITY,
                ..Default::default()
            },
            "exponent",
        ),
        (
            DensityParams {
                full_density_bend: 0.0,
                ..Default::default()
            },
            "full_density_bend",
        ),
        (
            DensityParams {
                filter_size: 0,
                ..Default::default()
            },
            "filter_size",
        ),
        (
            DensityParams {
                filter_size: 32,
                ..Default::default()
            },
            "filter_size",
        ),
        (
            DensityParams {
                border_lod_skip: 5,
                ..Default::default()
            },
            "border_lod_skip",
        ),
        (
            DensityParams {
                tile_size: 1,
                ..Default::default()
            },
            "tile_size",
        ),
        (
            DensityParams {
                tile_size: u32::MAX,
                ..Default::default()
            },
            "tile_size",
        ),
    ];
    for (params, name) in cases {
        match DensityMap::from_map(&map, params) {
            Err(LodError::InvalidDensityParam { what, .. }) => assert_eq!(what, name),
            other => panic!("{name}: {other:?}"),
        }
    }
    let mut dm = DensityMap::from_map(&map, DensityParams::default()).unwrap();
    let other = bumpy(20, 16, WrapMode::Repeat, 1);
    assert!(matches!(
        dm.update_rect(&other, Rect::new(IVec2::ZERO, UVec2::ONE)),
        Err(LodError::SizeMismatch { .. })
    ));
    // Rects far off the map (any i32) are fine: wrapped, or clipped to nothing.
    let before = dm.clone();
    dm.update_rect(
        &map,
        Rect::new(IVec2::splat(i32::MAX - 3), UVec2::splat(u32::MAX)),
    )
    .unwrap();
    assert_eq!(dm, before);
    let mut clamped =
        DensityMap::from_map(&bumpy(16, 16, WrapMode::Clamp, 1), DensityParams::default()).unwrap();
    let c0 = clamped.clone();
    clamped
        .update_rect(
            &bumpy(16, 16, WrapMode::Clamp, 1),
            Rect::new(IVec2::splat(-1_000_000), UVec2::splat(10)),
        )
        .unwrap();
    assert_eq!(clamped, c0);
}

#[test]
fn a_tiny_map_has_a_one_sample_pyramid() {
    let map = bumpy(1, 1, WrapMode::Repeat, 1);
    let dm = DensityMap::from_map(&map, DensityParams::default()).unwrap();
    assert_eq!(dm.level_count(), 1);
    assert_eq!(dm.level(0).unwrap().size(), UVec2::ONE);
}

/// Repeating maps smaller than a sample's window (sides 1 to 9): every window reads several
/// copies of a changed texel, and an update of any one texel still equals a rebuild.
#[test]
fn updates_of_maps_smaller_than_a_window_equal_a_rebuild() {
    for n in 1..=9u32 {
        for t in 0..n as i32 {
            let mut map = bumpy(n, 5, WrapMode::Repeat, n);
            let params = DensityParams {
                full_density_bend: SPREAD_BEND,
                tile_size: 2,
                ..Default::default()
            };
            let mut dm = DensityMap::from_map(&map, params).unwrap();
            let rect = Rect::new(IVec2::new(t, 1), UVec2::ONE);
            *map.grid_mut().get_mut(t as u32, 1).unwrap() += 700;
            dm.update_rect(&map, rect).unwrap();
            assert_eq!(
                dm,
                DensityMap::from_map(&map, params).unwrap(),
                "side {n}, texel {t}"
            );
        }
    }
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let mut map = bumpy(300, 260, WrapMode::Repeat, 11);
    for filter in CurvatureFilter::ALL {
        let params = DensityParams {
            filter,
            ..Default::default()
        };
        let run = |threads: usize, map: &HeightMap<u16>| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| DensityMap::from_map(map, params).unwrap())
        };
        let one = run(1, &map);
        assert_eq!(one, run(3, &map), "{filter:?}");
        stamp(
            &mut map,
            Rect::new(IVec2::new(250, 200), UVec2::new(90, 90)),
            4,
        );
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let mut updated = one.clone();
        pool.install(|| {
            updated
                .update_rect(&map, Rect::new(IVec2::new(250, 200), UVec2::new(90, 90)))
                .unwrap()
        });
        assert_eq!(updated, run(1, &map));
    }
}
