//! Tests of the granular deformation CPU reference: volume conservation, compression,
//! obstacles, rasterizer, jump flooding, slope evening, active areas, errors and presets.

use glam::{Affine3A, IVec2, Quat, UVec2, Vec3};
use terrain_core::granular::*;
use terrain_core::{FixedPointMap, Grid, Rect};
use terrain_test_support::granular::{
    UNITS, bumpy_map, empty_pen, meshes, objects_at, small_params,
};

fn flat_map(size: u32, metres: f32, texel: f32) -> FixedPointMap {
    let raw = (metres * UNITS as f32) as u32;
    FixedPointMap::fixed_point(Grid::new(size, size, raw).expect("grid"), UNITS, texel)
        .expect("map")
}

/// The iterative method with the 4 passes these tests use.
const ITERATIVE: DisplacementMethod = DisplacementMethod::Iterative { iterations: 4 };

const COMBOS: [(DisplacementMethod, SlopeMethod); 6] = [
    (ITERATIVE, SlopeMethod::Interleaved),
    (ITERATIVE, SlopeMethod::Scatter),
    (DisplacementMethod::ClosestSeed, SlopeMethod::Interleaved),
    (DisplacementMethod::ClosestSeed, SlopeMethod::Scatter),
    (
        DisplacementMethod::MultipleTargets,
        SlopeMethod::Interleaved,
    ),
    (DisplacementMethod::MultipleTargets, SlopeMethod::Scatter),
];

/// Frames of the soak test: 5000 (the seed's test), or `TERRAIN_SOAK_FRAMES` where a run
/// repeats the suite many times (`cargo xtask mutants` runs 300: every method combination
/// still gets its block of frames, and each mutant costs a second instead of ten).
fn soak_frames() -> u32 {
    std::env::var("TERRAIN_SOAK_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .filter(|&n| n >= 10)
        .unwrap_or(5000)
}

#[test]
fn volume_constant_over_5000_frames_three_objects() {
    let m = meshes();
    let map = bumpy_map(128, 0.05);
    let mut sim = GranularSim::new(map, small_params()).expect("sim");
    let v0 = sim.map().raw_sum();
    let start = sim.map().clone();
    let mut changed = 0u64;
    let frames = soak_frames();
    // Ten blocks of frames, each with the next method combination.
    let block = frames / 10;
    for frame in 0..frames {
        let (d, s) = COMBOS[(frame / block) as usize % COMBOS.len()];
        sim.displacement = d;
        sim.slope = s;
        let objs = objects_at(&m, frame, 6.4);
        let before = sim.map().grid().as_slice()[64 * 128 + 64];
        let r = sim.step(&objs).expect("step");
        assert_eq!(r.volume, v0, "frame {frame}");
        assert_eq!(r.removed, 0);
        changed += u64::from(before != sim.map().grid().as_slice()[64 * 128 + 64]);
    }
    assert_eq!(sim.map().raw_sum(), v0);
    assert_eq!(sim.total_removed(), 0);
    assert_ne!(sim.map(), &start, "nothing was deformed");
    assert!(changed > 0, "the centre column never changed");
}

#[test]
fn volume_conserved_per_method_combination_and_area_mode() {
    let m = meshes();
    for (d, s) in COMBOS {
        for mode in [AreaMode::ActiveAreas, AreaMode::FullMap] {
            for metric in [
                DistanceMetric::Euclidean,
                DistanceMetric::Manhattan,
                DistanceMetric::Chebyshev,
            ] {
                let params = GranularParams {
                    metric,
                    ..small_params()
                };
                let mut sim = GranularSim::new(bumpy_map(48, 0.1), params)
                    .expect("sim")
                    .with_methods(d, s)
                    .with_area_mode(mode);
                let v0 = sim.map().raw_sum();
                let start = sim.map().clone();
                for frame in 0..40 {
                    let r = sim.step(&objects_at(&m, frame * 7, 4.8)).expect("step");
                    assert_eq!(
                        r.volume, v0,
                        "{d:?} {s:?} {mode:?} {metric:?} frame {frame}"
                    );
                }
                assert_ne!(
                    sim.map(),
                    &start,
                    "{d:?} {s:?}: the objects deformed nothing"
                );
            }
        }
    }
}

#[test]
fn compression_removes_exactly_the_counted_amount() {
    let m = meshes();
    for (d, s) in COMBOS {
        for compression in [0.3f32, 0.9, 1.0] {
            let params = GranularParams {
                compression,
                ..small_params()
            };
            let mut sim = GranularSim::new(bumpy_map(48, 0.1), params)
                .expect("sim")
                .with_methods(d, s);
            let v0 = sim.map().raw_sum();
            let mut removed = 0;
            for frame in 0..20 {
                let r = sim.step(&objects_at(&m, frame * 11, 4.8)).expect("step");
                removed += r.removed;
                assert_eq!(r.volume + removed, v0, "{d:?} {s:?} c {compression}");
            }
            assert!(
                removed > 0,
                "{d:?} compression {compression} removed nothing"
            );
            assert_eq!(sim.total_removed(), removed);
        }
    }
}

#[test]
fn material_never_moves_into_obstacle_columns() {
    // A wheel pushes into the snow beside a box hovering 2 cm above it: the box's columns are
    // obstacles and must not rise, whatever the methods.
    let wheel = TriMesh::wheel(0.5, 0.3, 24).expect("wheel");
    let slab = TriMesh::cuboid(Vec3::new(0.6, 0.1, 0.6)).expect("box");
    for (d, s) in COMBOS {
        let params = GranularParams {
            slope_threshold: 0.5,
            roughness: 0.9,
            ..GranularParams::snow()
        };
        let mut sim = GranularSim::new(flat_map(64, 1.0, 0.05), params)
            .expect("sim")
            .with_methods(d, s);
        let objs = [
            GranularObject::new(
                &wheel,
                Affine3A::from_translation(Vec3::new(1.2, 1.5 - 0.3, 1.6)),
            ),
            GranularObject::new(
                &slab,
                Affine3A::from_translation(Vec3::new(2.0, 1.0 + 0.1 + 0.002, 1.6)),
            ),
        ];
        let area = Rect::from_size(sim.map().size());
        let depth = depth_from_below(&objs, sim.map(), area).expect("depth");
        let mut pen = empty_pen(area.size);
        penetration_texture(sim.map(), &depth, area, 5000, &mut pen).expect("pen");
        let obstacles: Vec<usize> = (0..pen.as_slice().len())
            .filter(|&i| pen.as_slice()[i].column_kind() == ColumnKind::Obstacle)
            .collect();
        assert!(obstacles.len() > 100, "{} obstacles", obstacles.len());
        let before = sim.map().clone();
        let mut moved = false;
        for _ in 0..5 {
            sim.step(&objs).expect("step");
            for &i in &obstacles {
                assert!(
                    sim.map().grid().as_slice()[i] <= before.grid().as_slice()[i],
                    "{d:?} {s:?}: obstacle column {i} rose"
                );
            }
            moved |= sim.map() != &before;
        }
        assert!(moved);
    }
}

#[test]
fn box_gives_a_flat_bottom_over_exactly_its_footprint() {
    let map = flat_map(32, 1.0, 0.5);
    // Box spanning X [2.5, 7.5) m = texels [5, 15), Z [1.0, 4.0) m = texels [2, 8), bottom at
    // 0.75 m.
    let cube = TriMesh::cuboid(Vec3::new(2.5, 0.5, 1.5)).expect("box");
    let obj = GranularObject::new(&cube, Affine3A::from_translation(Vec3::new(5.0, 1.25, 2.5)));
    let area = Rect::from_size(map.size());
    let depth = depth_from_below(&[obj], &map, area).expect("depth");
    for y in 0..32 {
        for x in 0..32 {
            let d = depth.get(x, y).expect("in");
            if (5..15).contains(&x) && (2..8).contains(&y) {
                assert_eq!(d, 7500, "({x}, {y})");
            } else {
                assert_eq!(d, NO_OBJECT, "({x}, {y})");
            }
        }
    }
    // A sub-area gives the same values.
    let sub = Rect::new(IVec2::new(3, 1), UVec2::new(8, 4));
    let part = depth_from_below(&[obj], &map, sub).expect("depth");
    assert_eq!(part, depth.copy_rect(sub).expect("copy"));
    // The penetration texture of a box sunk 0.25 m: 2500 units over the footprint.
    let mut pen = empty_pen(area.size);
    penetration_texture(&map, &depth, area, 0, &mut pen).expect("pen");
    assert_eq!(
        pen.get(5, 2).map(|p| (p.column_kind(), p.penetration)),
        Some((ColumnKind::Penetrating, 2500))
    );
    assert_eq!(
        pen.get(15, 2)
            .map(|p| (p.column_kind(), p.seed_x, p.seed_y)),
        Some((ColumnKind::Seed, 15, 2))
    );
}

#[test]
fn rotated_wheel_depth() {
    let map = flat_map(64, 1.0, 0.05);
    let wheel = TriMesh::wheel(0.5, 0.2, 64).expect("wheel");
    // Axle turned from X to Z: the wheel rolls along X, its contact line runs along Z.
    let tr = Affine3A::from_rotation_translation(
        Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
        Vec3::new(1.6, 1.4, 1.6),
    );
    let depth = depth_from_below(
        &[GranularObject::new(&wheel, tr)],
        &map,
        Rect::from_size(map.size()),
    )
    .expect("depth");
    // Lowest line at 0.9 m along Z through x = 32 texels, covering z in [1.4, 1.8) m.
    for y in 29..35 {
        let d = depth.get(32, y).expect("in");
        assert!(d.abs_diff(9000) <= 1, "row {y}: {d}");
    }
    assert_eq!(depth.get(32, 27), Some(NO_OBJECT));
    assert_eq!(depth.get(32, 37), Some(NO_OBJECT));
    // Along X the bottom is a circle: 0.25 m off the axis it is 1.4 - sqrt(0.5^2 - 0.25^2).
    let d = depth.get(32 + 5, 30).expect("in") as f32 / UNITS as f32;
    assert!((d - (1.4 - (0.25f32 - 0.0625).sqrt())).abs() < 0.005, "{d}");
    // Wheel footprint spans X [1.1, 2.1) m = texels 22..42.
    assert_ne!(depth.get(23, 30), Some(NO_OBJECT));
    assert_eq!(depth.get(21, 30), Some(NO_OBJECT));
    assert_eq!(depth.get(43, 30), Some(NO_OBJECT));
}

#[test]
fn user_mesh_depth_is_its_plane() {
    let map = flat_map(16, 0.0, 1.0);
    // A tetrahedron whose bottom face is the sloped plane y = 1 + 0.1 x over a right triangle.
    let mesh = TriMesh::new(
        vec![
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(8.0, 1.8, 0.0),
            Vec3::new(0.0, 1.0, 8.0),
            Vec3::new(0.0, 5.0, 0.0),
        ],
        vec![[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]],
    )
    .expect("mesh");
    let depth = depth_from_below(
        &[GranularObject::new(&mesh, Affine3A::IDENTITY)],
        &map,
        Rect::from_size(map.size()),
    )
    .expect("depth");
    let mut covered = 0;
    for y in 0..16u32 {
        for x in 0..16u32 {
            let d = depth.get(x, y).expect("in");
            if x + y < 8 {
                covered += 1;
                let want = 10_000 + 1000 * x;
                assert!(d.abs_diff(want) <= 1, "({x}, {y}) {d} vs {want}");
            } else if x + y > 8 {
                assert_eq!(d, NO_OBJECT, "({x}, {y})");
            }
        }
    }
    assert!(covered >= 36);
}

fn seed_pen(size: u32, seeds: &[(u32, u32)]) -> Grid<Penetration> {
    let mut pen = Grid::new(
        size,
        size,
        Penetration {
            seed_x: NO_SEED,
            seed_y: NO_SEED,
            kind: ColumnKind::Penetrating as i32,
            penetration: 1,
        },
    )
    .expect("grid");
    for &(x, y) in seeds {
        if let Some(p) = pen.get_mut(x, y) {
            *p = Penetration {
                seed_x: x,
                seed_y: y,
                kind: ColumnKind::Seed as i32,
                penetration: 0,
            };
        }
    }
    pen
}

const METRICS: [DistanceMetric; 3] = [
    DistanceMetric::Euclidean,
    DistanceMetric::Manhattan,
    DistanceMetric::Chebyshev,
];

#[test]
fn jfa_exact_on_small_cases() {
    for metric in METRICS {
        for extra in [false, true] {
            // One seed: jump flooding is exact.
            for seeds in [
                vec![(0u32, 0u32)],
                vec![(5, 9)],
                vec![(15, 15)],
                vec![(0, 13)],
            ] {
                let pen = seed_pen(16, &seeds);
                let area = Rect::from_size(UVec2::splat(16));
                let got = distance_grid(
                    &jump_flood(&pen, area, metric, extra).expect("jfa"),
                    area,
                    metric,
                );
                assert_eq!(
                    got,
                    brute_force_distance(&pen, area, metric),
                    "{metric:?} {seeds:?}"
                );
            }
            // Several seeds: seeds themselves are exact (0) and at most a few columns are off.
            for seeds in [vec![(2u32, 3u32), (12, 13)], vec![(0, 15), (15, 0), (8, 8)]] {
                let pen = seed_pen(16, &seeds);
                let area = Rect::from_size(UVec2::splat(16));
                let got = distance_grid(
                    &jump_flood(&pen, area, metric, extra).expect("jfa"),
                    area,
                    metric,
                );
                let exact = brute_force_distance(&pen, area, metric);
                let wrong = got
                    .as_slice()
                    .iter()
                    .zip(exact.as_slice())
                    .filter(|(g, e)| g != e)
                    .count();
                assert!(wrong <= 3, "{metric:?} {seeds:?}: {wrong} wrong");
                for &(x, y) in &seeds {
                    assert_eq!(got.get(x, y), Some(0));
                }
            }
        }
    }
    // The hash-driven order is a permutation and depends on the pass.
    let o = jfa_neighbour_order(3, 4, 0);
    let mut sorted = o;
    sorted.sort_unstable();
    assert_eq!(sorted, [0, 1, 2, 3, 4, 5, 6, 7]);
    assert!((0..8).any(|p| jfa_neighbour_order(3, 4, p) != o));
    assert_eq!(
        jfa_steps(UVec2::new(100, 60), true),
        vec![64, 32, 16, 8, 4, 2, 1, 1]
    );
}

#[test]
fn jfa_error_table_against_brute_force() {
    let size = 128u32;
    let area = Rect::from_size(UVec2::splat(size));
    println!("metric      extra  wrong %   max error (metric units; Euclidean in texels)");
    for metric in METRICS {
        for extra in [false, true] {
            let (mut wrong, mut total, mut max_err) = (0u64, 0u64, 0f64);
            for case in 0..4u32 {
                let seeds: Vec<(u32, u32)> = (0..(40 + case * 40))
                    .map(|i| {
                        (
                            pcg_hash(i * 2 + case * 977) % size,
                            pcg_hash(i * 2 + 1 + case * 977) % size,
                        )
                    })
                    .collect();
                let pen = seed_pen(size, &seeds);
                let got = distance_grid(
                    &jump_flood(&pen, area, metric, extra).expect("jfa"),
                    area,
                    metric,
                );
                let exact = brute_force_distance(&pen, area, metric);
                for (g, e) in got.as_slice().iter().zip(exact.as_slice()) {
                    total += 1;
                    assert!(g >= e, "JFA found a seed closer than the nearest");
                    if g != e {
                        wrong += 1;
                        let err = match metric {
                            DistanceMetric::Euclidean => {
                                f64::from(*g).sqrt() - f64::from(*e).sqrt()
                            }
                            _ => f64::from(g - e),
                        };
                        max_err = max_err.max(err);
                    }
                }
            }
            let share = wrong as f64 / total as f64 * 100.0;
            println!("{metric:<11?} {extra:<6} {share:7.4}   {max_err:.3}");
            assert!(share < 2.0, "{metric:?} extra {extra}: {share}% wrong");
            assert!(
                max_err < 4.0,
                "{metric:?} extra {extra}: max error {max_err}"
            );
        }
    }
}

fn max_excess(map: &FixedPointMap, t: [u32; 2]) -> u32 {
    let g = map.grid();
    let mut worst = 0;
    for y in 0..g.height() {
        for x in 0..g.width() {
            for [dx, dy] in JFA_OFFSETS {
                let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                if let Some(n) = g
                    .get(nx.max(-1) as u32, ny.max(-1) as u32)
                    .filter(|_| nx >= 0 && ny >= 0)
                {
                    let h = g.get(x, y).unwrap_or(0);
                    let thr = t[usize::from(dx != 0 && dy != 0)];
                    worst = worst.max(h.saturating_sub(n).saturating_sub(thr));
                }
            }
        }
    }
    worst
}

#[test]
fn slope_evening_reduces_steep_slopes_and_stops() {
    for method in [SlopeMethod::Interleaved, SlopeMethod::Scatter] {
        let mut map = flat_map(32, 1.0, 0.05);
        for y in 12..20 {
            for x in 12..20 {
                if let Some(h) = map.grid_mut().get_mut(x, y) {
                    *h += 5000 + 300 * (x + y);
                }
            }
        }
        let area = Rect::from_size(map.size());
        let mut pen = empty_pen(area.size);
        let depth = Grid::new(32, 32, NO_OBJECT).expect("grid");
        penetration_texture(&map, &depth, area, 0, &mut pen).expect("pen");
        let params = GranularParams::snow();
        let t = params.slope_thresholds_units(map.texel_size(), f64::from(UNITS));
        let v0 = map.raw_sum();
        let e0 = max_excess(&map, t);
        let mut settled_at = None;
        for i in 0..400 {
            let before = map.clone();
            match method {
                SlopeMethod::Interleaved => {
                    even_out_slopes_interleaved(&mut map, &pen, area, t, params.roughness_q15(), 1)
                }
                SlopeMethod::Scatter => {
                    even_out_slopes_scatter(&mut map, &pen, area, t, params.roughness_q15(), 1)
                }
            }
            .expect("slope");
            assert_eq!(map.raw_sum(), v0);
            if map == before {
                settled_at = Some(i);
                break;
            }
        }
        let e1 = max_excess(&map, t);
        println!(
            "{method:?}: excess over threshold {e0} -> {e1} units, settled after {settled_at:?} iterations"
        );
        assert!(settled_at.is_some(), "{method:?} never settled");
        assert!(e1 < e0 / 20, "{method:?}: {e0} -> {e1}");
        assert!(
            e1 <= 16,
            "{method:?}: {e1} units above the threshold at rest"
        );
    }
}

#[test]
fn active_area_merging() {
    let a = |x: i32, y: i32, w: u32, h: u32| ActiveArea {
        rect: Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
    };
    // Overlapping merge.
    assert_eq!(
        merge_active_areas(&[a(0, 0, 10, 10), a(5, 5, 10, 10)], 0),
        vec![a(0, 0, 15, 15)]
    );
    // Nearby (gap 3 < 4) merge; far apart stay separate.
    assert_eq!(
        merge_active_areas(&[a(0, 0, 10, 10), a(13, 0, 10, 10)], 4),
        vec![a(0, 0, 23, 10)]
    );
    assert_eq!(
        merge_active_areas(&[a(0, 0, 10, 10), a(40, 40, 10, 10)], 4),
        vec![a(0, 0, 10, 10), a(40, 40, 10, 10)]
    );
    // Chains merge transitively, independent of order.
    let chain = [
        a(0, 0, 10, 10),
        a(50, 0, 10, 10),
        a(25, 0, 10, 10),
        a(12, 0, 10, 10),
        a(37, 0, 10, 10),
    ];
    let mut rev = chain;
    rev.reverse();
    assert_eq!(merge_active_areas(&chain, 4), vec![a(0, 0, 60, 10)]);
    assert_eq!(merge_active_areas(&rev, 4), merge_active_areas(&chain, 4));
}

#[test]
fn merged_active_areas_give_the_full_map_displacement() {
    let cube = TriMesh::cuboid(Vec3::new(0.3, 0.3, 0.2)).expect("box");
    let wheel = TriMesh::wheel(0.3, 0.15, 16).expect("wheel");
    let map0 = bumpy_map(96, 0.05);
    let objs = [
        GranularObject::new(
            &cube,
            Affine3A::from_rotation_translation(
                Quat::from_rotation_y(0.6),
                Vec3::new(1.2, 1.2, 1.3),
            ),
        ),
        GranularObject::new(
            &wheel,
            Affine3A::from_translation(Vec3::new(1.9, 1.25, 1.5)),
        ),
        GranularObject::new(&cube, Affine3A::from_translation(Vec3::new(3.8, 1.15, 3.9))),
    ];
    let areas: Vec<ActiveArea> = objs
        .iter()
        .filter_map(|o| object_active_area(o, 0.05, map0.size(), 6).expect("area"))
        .collect();
    let merged = merge_active_areas(&areas, 4);
    assert_eq!(merged.len(), 2, "{merged:?}");
    let full = Rect::from_size(map0.size());
    let depth = depth_from_below(&objs, &map0, full).expect("depth");
    let mut pen = empty_pen(full.size);
    penetration_texture(&map0, &depth, full, 1000, &mut pen).expect("pen");
    for metric in METRICS {
        let seeds = jump_flood(&pen, full, metric, true).expect("jfa");
        for method in [
            DisplacementMethod::Iterative { iterations: 20 },
            DisplacementMethod::ClosestSeed,
            DisplacementMethod::MultipleTargets,
        ] {
            let run = |map: &mut FixedPointMap,
                       pen: &Grid<Penetration>,
                       seeds: &Grid<[u32; 2]>,
                       r: Rect| {
                match method {
                    DisplacementMethod::Iterative { iterations } => {
                        displace_iterative(map, pen, seeds, r, 32768, iterations, metric)
                    }
                    DisplacementMethod::ClosestSeed => {
                        displace_closest_seed(map, pen, seeds, r, 32768)
                    }
                    DisplacementMethod::MultipleTargets => {
                        displace_multiple_targets(map, pen, seeds, r, 32768)
                    }
                }
                .expect("displace")
            };
            let mut whole = map0.clone();
            run(&mut whole, &pen, &seeds, full);
            let mut parts = map0.clone();
            for area in &merged {
                let r = area.rect;
                run(
                    &mut parts,
                    &pen.copy_rect(r).expect("pen"),
                    &seeds.copy_rect(r).expect("seeds"),
                    r,
                );
            }
            assert_ne!(whole, map0);
            assert_eq!(whole, parts, "{method:?} {metric:?}");
        }
    }
}

#[test]
fn bad_parameters_and_meshes_are_errors() {
    let bad = [
        GranularParams {
            compression: -0.1,
            ..Default::default()
        },
        GranularParams {
            compression: 1.5,
            ..Default::default()
        },
        GranularParams {
            roughness: f32::NAN,
            ..Default::default()
        },
        GranularParams {
            slope_threshold: -1.0,
            ..Default::default()
        },
        GranularParams {
            slope_d: 0.0,
            ..Default::default()
        },
        GranularParams {
            num_iterations_even_out_slopes: 1_000_000,
            ..Default::default()
        },
        GranularParams {
            active_area_margin: u32::MAX,
            ..Default::default()
        },
    ];
    for p in bad {
        assert!(
            matches!(p.validate(), Err(GranularError::ParamOutOfRange { .. })),
            "{p:?}"
        );
        assert!(GranularSim::new(flat_map(8, 1.0, 0.1), p).is_err());
    }
    assert!(matches!(
        TriMesh::new(vec![], vec![]),
        Err(GranularError::EmptyMesh { .. })
    ));
    assert!(matches!(
        TriMesh::new(vec![Vec3::ZERO; 3], vec![]),
        Err(GranularError::EmptyMesh { .. })
    ));
    assert!(matches!(
        TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(f32::NAN, 0.0, 0.0)],
            vec![[0, 1, 2]]
        ),
        Err(GranularError::BadVertex { index: 2, .. })
    ));
    assert!(matches!(
        TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::splat(1e9)], vec![[0, 1, 2]]),
        Err(GranularError::BadVertex { .. })
    ));
    assert!(matches!(
        TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Z], vec![[0, 1, 3]]),
        Err(GranularError::IndexOutOfRange { index: 3, .. })
    ));
    assert!(TriMesh::cuboid(Vec3::new(1.0, 0.0, 1.0)).is_err());
    assert!(TriMesh::cuboid(Vec3::splat(f32::INFINITY)).is_err());
    assert!(TriMesh::wheel(0.5, 0.2, 2).is_err());
    assert!(TriMesh::foot(-1.0, 0.1, 0.1).is_err());
    // Non-finite and absurd transforms.
    let cube = TriMesh::cuboid(Vec3::ONE).expect("box");
    let mut sim = GranularSim::new(flat_map(8, 1.0, 0.1), GranularParams::default()).expect("sim");
    let before = sim.map().clone();
    let nan = GranularObject::new(
        &cube,
        Affine3A::from_translation(Vec3::new(f32::NAN, 0.0, 0.0)),
    );
    assert!(matches!(
        sim.step(&[nan]),
        Err(GranularError::NonFiniteTransform(_))
    ));
    let huge = GranularObject::new(&cube, Affine3A::from_scale(Vec3::splat(1e8)));
    assert!(matches!(
        sim.step(&[huge]),
        Err(GranularError::BadVertex { .. })
    ));
    assert_eq!(sim.map(), &before);
    // Too many iterative displacement passes: refused before the map is touched.
    let too_many = DisplacementMethod::Iterative {
        iterations: MAX_ITERATIONS + 1,
    };
    assert!(matches!(
        too_many.validate(),
        Err(GranularError::ParamOutOfRange { .. })
    ));
    let mut refused = GranularSim::new(flat_map(8, 1.0, 0.1), GranularParams::default())
        .expect("sim")
        .with_methods(too_many, SlopeMethod::Scatter);
    let untouched = refused.map().clone();
    assert!(matches!(
        refused.step(&[]),
        Err(GranularError::ParamOutOfRange { .. })
    ));
    assert_eq!(refused.map(), &untouched);
    // Regions outside the map.
    let map = flat_map(8, 1.0, 0.1);
    let outside = Rect::new(IVec2::new(4, 4), UVec2::new(8, 8));
    assert!(matches!(
        depth_from_below(&[], &map, outside),
        Err(GranularError::RegionOutsideMap { .. })
    ));
    // A map that is not fixed point.
    let enc = terrain_core::HeightEncoding::new(0.3, 1.0).expect("enc");
    let odd = terrain_core::HeightMap::new(
        Grid::new(8, 8, 0u32).expect("grid"),
        enc,
        0.1,
        terrain_core::WrapMode::Clamp,
    )
    .expect("map");
    assert!(matches!(
        GranularSim::new(odd, GranularParams::default()),
        Err(GranularError::NotFixedPoint { .. })
    ));
    // An object far away from the map does nothing.
    let far = GranularObject::new(
        &cube,
        Affine3A::from_translation(Vec3::new(500.0, 0.0, 500.0)),
    );
    let r = sim.step(&[far]).expect("step");
    assert!(r.active_areas.is_empty());
}

#[test]
fn presets_are_valid_and_match_the_captions() {
    for (p, c, r, s) in [
        (GranularParams::snow(), 0.0, 0.6, 3.1),
        (GranularParams::sand(), 0.0, 0.1, 1.1),
        (GranularParams::mud(), 0.95, 0.1, 8.0),
        (GranularParams::default(), 0.0, 0.6, 3.1),
    ] {
        p.validate().expect("valid preset");
        assert_eq!((p.compression, p.roughness, p.slope_threshold), (c, r, s));
    }
    assert_eq!(GranularParams::default().num_iterations_even_out_slopes, 10);
    assert_eq!(
        DisplacementMethod::iterative(),
        DisplacementMethod::Iterative { iterations: 10 }
    );
    DisplacementMethod::iterative()
        .validate()
        .expect("valid method");
    assert_eq!(GranularParams::mud().keep_q15(), 1638);
}

#[test]
fn normals_and_float_heights() {
    // A ramp rising 0.1 m per texel along X at 0.1 m spacing: 45 degrees.
    let grid = Grid::from_fn(16, 16, |x, _| 1000 * x).expect("grid");
    let map = FixedPointMap::fixed_point(grid, UNITS, 0.1).expect("map");
    let area = Rect::from_size(map.size());
    let mut n = Grid::new(16, 16, Vec3::ZERO).expect("grid");
    symmetric_normals(&map, area, &mut n).expect("normals");
    let want = Vec3::new(-1.0, 1.0, 0.0).normalize();
    assert!(n.get(8, 8).expect("in").abs_diff_eq(want, 1e-5));
    blur_normals(&mut n, area, 2).expect("blur");
    assert!(n.get(8, 8).expect("in").abs_diff_eq(want, 1e-5));
    let mut f = Grid::new(16, 16, 0.0f32).expect("grid");
    float_heights(&map, area, &mut f).expect("float");
    assert!((f.get(5, 3).expect("in") - 0.5).abs() < 1e-6);
}

/// A region of a u16 coarse-map (a 60 m world) handed to the granular step in fixed point
/// (`Handover::for_world`), rolled over by a wheel and a box without compression, and handed
/// back: the stored heights' sum is exactly what it was, every column within a stored unit of
/// its fixed-point share, and the wheel's track is in the coarse heights.
#[test]
fn a_coarse_region_handed_over_keeps_its_volume_exactly() {
    use terrain_core::{HeightEncoding, HeightMap};
    let world = HeightEncoding::spanning::<u16>(0.0, 60.0).expect("enc");
    let region = Grid::from_fn(96, 96, |x, y| {
        30_000 + (pcg_hash(x * 31 + y * 977) % 50) as u16
    })
    .expect("grid");
    let handover = Handover::for_world(world, UNITS).expect("handover");
    let enc = handover.scratch_encoding(world).expect("encoding");
    let units = (1.0 / f64::from(enc.scale)).round() as u32;
    let fixed = handover.to_fixed(&region);
    let map = FixedPointMap::fixed_point(fixed, units, 0.05).expect("map");
    let mut sim = GranularSim::new(map, small_params()).expect("sim");
    let wheel = TriMesh::wheel(0.35, 0.15, 16).expect("wheel");
    // Heights above the world's offset (0 here): the region lies near 27.5 m.
    let top = world.to_metres(30_000.0);
    for frame in 0..40 {
        let x = 1.0 + frame as f32 * 0.08;
        let tr = Affine3A::from_rotation_translation(
            Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
            Vec3::new(x, top + 0.25, 2.4),
        );
        sim.step(&[GranularObject::new(&wheel, tr)]).expect("step");
    }
    let back = handover.from_fixed(sim.map().grid()).expect("exact");
    let sum = |g: &Grid<u16>| g.as_slice().iter().map(|&v| u64::from(v)).sum::<u64>();
    assert_eq!(sum(&back), sum(&region));
    for (&u, &h) in sim.map().grid().as_slice().iter().zip(back.as_slice()) {
        assert!((f64::from(u) / f64::from(handover.k()) - f64::from(h)).abs() < 1.0);
    }
    assert_ne!(back, region, "the wheel left no track");
    let _ = HeightMap::new(back, world, 0.05, terrain_core::WrapMode::Clamp).expect("a map again");
}
