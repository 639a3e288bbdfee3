//! Granular deformation CPU reference: each step over one active area at map sizes 512 to
//! 4096 (Persson 2019, table 5.4 setting: 3 774, 15 100, 60 398 and 241 591 columns, here squares
//! of 61, 123, 246 and 492 texels a side), and whole steps with 1 to 8 vehicles, active areas
//! versus the full 2048 map (table 5.7).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{Affine3A, IVec2, UVec2, Vec3};
use std::hint::black_box;
use std::time::Duration;
use terrain_core::granular::*;
use terrain_core::{FixedPointMap, Grid, Rect};

const SIZES: [(u32, u32); 4] = [(512, 61), (1024, 123), (2048, 246), (4096, 492)];

fn snow(size: u32, texel: f32) -> FixedPointMap {
    FixedPointMap::fixed_point(Grid::new(size, size, 10_000).expect("grid"), 10_000, texel)
        .expect("map")
}

fn steps(c: &mut Criterion) {
    let mut g = c.benchmark_group("granular");
    g.sample_size(10);
    g.warm_up_time(Duration::from_millis(300));
    g.measurement_time(Duration::from_secs(1));
    let params = GranularParams::default();
    for (size, side) in SIZES {
        // terrainSize 200 m (table 5.3).
        let texel = 200.0 / size as f32;
        let map = snow(size, texel);
        let min = IVec2::splat(((size - side) / 2) as i32);
        let area = Rect::new(min, UVec2::splat(side));
        let centre = (min.as_vec2() + side as f32 * 0.5) * texel;
        // A wheel filling about half the area, sunk a quarter of its radius.
        let r = side as f32 * texel * 0.25;
        let wheel = TriMesh::wheel(r, r * 0.5, 32).expect("wheel");
        let obj = [GranularObject::new(
            &wheel,
            Affine3A::from_translation(Vec3::new(centre.x, 1.0 + 0.75 * r, centre.y)),
        )];
        g.throughput(Throughput::Elements(area.area()));
        let depth = depth_from_below(&obj, &map, area).expect("depth");
        let mut pen = Grid::new(
            side,
            side,
            Penetration {
                seed_x: 0,
                seed_y: 0,
                kind: 0,
                penetration: 0,
            },
        )
        .expect("grid");
        penetration_texture(&map, &depth, area, 5000, &mut pen).expect("pen");
        let seeds = jump_flood(&pen, area, params.metric, true).expect("jfa");
        let t = params.slope_thresholds_units(texel, 10_000.0);
        let r15 = params.roughness_q15();
        g.bench_function(BenchmarkId::new("depth_from_below", size), |b| {
            b.iter(|| depth_from_below(black_box(&obj), &map, area).expect("depth"))
        });
        let mut out = pen.clone();
        g.bench_function(BenchmarkId::new("penetration", size), |b| {
            b.iter(|| {
                penetration_texture(&map, black_box(&depth), area, 5000, &mut out).expect("pen")
            })
        });
        g.bench_function(BenchmarkId::new("jump_flood", size), |b| {
            b.iter(|| jump_flood(black_box(&pen), area, params.metric, true).expect("jfa"))
        });
        // Before: the sequential pass with the hashed order computed for every column.
        if size == 4096 {
            g.bench_function(BenchmarkId::new("jump_flood_reference", size), |b| {
                b.iter(|| {
                    jump_flood_reference(black_box(&pen), area, params.metric, true).expect("jfa")
                })
            });
        }
        for (name, metric) in [
            ("exact_nearest_seed", DistanceMetric::Euclidean),
            ("exact_nearest_seed_manhattan", DistanceMetric::Manhattan),
            ("exact_nearest_seed_chebyshev", DistanceMetric::Chebyshev),
        ] {
            g.bench_function(BenchmarkId::new(name, size), |b| {
                b.iter(|| exact_nearest_seed(black_box(&pen), area, metric).expect("edt"))
            });
        }
        // One whole step over the area as GranularSim::step runs it (depth, penetration,
        // nearest seeds, closest-seed displacement, 10 scatter slope passes): Persson 2019's
        // SSBO pair (table 5.1), whose steps table 5.5 times.
        for (name, exact) in [
            ("step_jfa_closest_seed_scatter10", false),
            ("step_exact_closest_seed_scatter10", true),
        ] {
            g.bench_function(BenchmarkId::new(name, size), |b| {
                b.iter_batched_ref(
                    || map.clone(),
                    |m| {
                        let depth = depth_from_below(&obj, m, area).expect("depth");
                        let mut pen = pen.clone();
                        penetration_texture(m, &depth, area, 5000, &mut pen).expect("pen");
                        let seeds = if exact {
                            exact_nearest_seed(&pen, area, params.metric).expect("edt")
                        } else {
                            jump_flood(&pen, area, params.metric, true).expect("jfa")
                        };
                        displace_closest_seed(m, &pen, &seeds, area, 32768).expect("displace");
                        even_out_slopes_scatter(m, &pen, area, t, r15, 10).expect("slope");
                    },
                    criterion::BatchSize::LargeInput,
                )
            });
        }
        // The baseline: copying the area's u32 heights once.
        let src = vec![7u32; area.area() as usize];
        let mut dst = vec![0u32; area.area() as usize];
        g.bench_function(BenchmarkId::new("memcpy_u32", size), |b| {
            b.iter(|| dst.copy_from_slice(black_box(&src)))
        });
        // Table 5.6 compares the methods with one iterative pass; table 5.4 runs ten.
        for (name, method) in [
            ("displace_iterative10", DisplacementMethod::iterative()),
            (
                "displace_iterative1",
                DisplacementMethod::Iterative { iterations: 1 },
            ),
            ("displace_closest_seed", DisplacementMethod::ClosestSeed),
            (
                "displace_multiple_targets",
                DisplacementMethod::MultipleTargets,
            ),
        ] {
            g.bench_function(BenchmarkId::new(name, size), |b| {
                b.iter_batched_ref(
                    || map.clone(),
                    |m| {
                        match method {
                            DisplacementMethod::Iterative { iterations } => displace_iterative(
                                m,
                                &pen,
                                &seeds,
                                area,
                                32768,
                                iterations,
                                params.metric,
                            ),
                            DisplacementMethod::ClosestSeed => {
                                displace_closest_seed(m, &pen, &seeds, area, 32768)
                            }
                            DisplacementMethod::MultipleTargets => {
                                displace_multiple_targets(m, &pen, &seeds, area, 32768)
                            }
                        }
                        .expect("displace")
                    },
                    criterion::BatchSize::LargeInput,
                )
            });
        }
        let mut displaced = map.clone();
        displace_closest_seed(&mut displaced, &pen, &seeds, area, 32768).expect("displace");
        for (name, method) in [
            ("slopes_interleaved10", SlopeMethod::Interleaved),
            ("slopes_scatter10", SlopeMethod::Scatter),
        ] {
            g.bench_function(BenchmarkId::new(name, size), |b| {
                b.iter_batched_ref(
                    || displaced.clone(),
                    |m| {
                        match method {
                            SlopeMethod::Interleaved => {
                                even_out_slopes_interleaved(m, &pen, area, t, r15, 10)
                            }
                            SlopeMethod::Scatter => {
                                even_out_slopes_scatter(m, &pen, area, t, r15, 10)
                            }
                        }
                        .expect("slope")
                    },
                    criterion::BatchSize::LargeInput,
                )
            });
        }
        let mut normals = Grid::new(size, size, Vec3::Y).expect("grid");
        g.bench_function(BenchmarkId::new("normals_blur1", size), |b| {
            b.iter(|| {
                symmetric_normals(&displaced, area, &mut normals).expect("normals");
                blur_normals(&mut normals, area, 1).expect("blur");
            })
        });
    }
    g.finish();
}

fn vehicles(c: &mut Criterion) {
    let mut g = c.benchmark_group("granular_vehicles_2048");
    g.sample_size(10);
    g.warm_up_time(Duration::from_millis(300));
    g.measurement_time(Duration::from_secs(2));
    // Table 5.8: 2048 texels over 300 m, one slope iteration; each car's area about 163^2 =
    // 26 569 columns (margin included). The SSBO combination (closest seed + scatter).
    let texel = 300.0 / 2048.0;
    let params = GranularParams {
        num_iterations_even_out_slopes: 1,
        active_area_margin: 40,
        ..GranularParams::default()
    };
    let car = TriMesh::cuboid(Vec3::new(2.0, 0.8, 4.0)).expect("car");
    let sim0 = GranularSim::new(snow(2048, texel), params).expect("sim");
    for cars in 1..=8u32 {
        let objs: Vec<GranularObject<'_>> = (0..cars)
            .map(|i| {
                GranularObject::new(
                    &car,
                    Affine3A::from_translation(Vec3::new(30.0 + 33.0 * i as f32, 1.7, 150.0)),
                )
            })
            .collect();
        let modes: &[AreaMode] = if cars == 1 || cars == 8 {
            &[AreaMode::ActiveAreas, AreaMode::FullMap]
        } else {
            &[AreaMode::ActiveAreas]
        };
        for &mode in modes {
            let mut sim = sim0.clone().with_area_mode(mode);
            let name = match mode {
                AreaMode::ActiveAreas => "active_areas",
                AreaMode::FullMap => "full_map",
            };
            g.bench_function(BenchmarkId::new(name, cars), |b| {
                b.iter(|| sim.step(black_box(&objs)).expect("step"))
            });
        }
    }
    g.finish();
}

/// The whole CPU step of `GranularSim` on the 4096 map (200 m, table 5.3 settings) over one
/// 492^2 = 242 064-column active area (a drum 23.2 m wide and long, sunk 0.25 m, plus the
/// 8-texel margin), volume included, with each method pair Persson 2019 ran (table 5.1): the
/// iterative pair (10 iterative displacement passes, 10 interleaved slope passes; table 5.4)
/// and the SSBO pair (closest-seed displacement, 10 scatter slope passes; table 5.5), with jump
/// flooding as the thesis; the SSBO pair also with the exact transform.
fn full_step(c: &mut Criterion) {
    let mut g = c.benchmark_group("granular_step");
    g.sample_size(10);
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(3));
    let texel = 200.0 / 4096.0;
    let half = 237.25 * texel;
    let centre = 2048.5 * texel;
    let drum = TriMesh::wheel(half, half, 64).expect("drum");
    let obj = [GranularObject::new(
        &drum,
        Affine3A::from_translation(Vec3::new(centre, 1.0 + half - 0.25, centre)),
    )];
    for (name, displacement, slopes, distance) in [
        (
            "jfa_iterative10_interleaved10",
            DisplacementMethod::iterative(),
            SlopeMethod::Interleaved,
            DistanceTransform::JumpFlood,
        ),
        (
            "jfa_closest_seed_scatter10",
            DisplacementMethod::ClosestSeed,
            SlopeMethod::Scatter,
            DistanceTransform::JumpFlood,
        ),
        (
            "exact_closest_seed_scatter10",
            DisplacementMethod::ClosestSeed,
            SlopeMethod::Scatter,
            DistanceTransform::Exact,
        ),
    ] {
        let mut sim = GranularSim::new(snow(4096, texel), GranularParams::default())
            .expect("sim")
            .with_methods(displacement, slopes)
            .with_distance_transform(distance);
        let areas = sim.active_areas(&obj).expect("areas");
        assert_eq!(areas.len(), 1);
        assert_eq!(areas[0].columns(), 242_064, "{:?}", areas[0]);
        g.throughput(Throughput::Elements(areas[0].columns()));
        g.bench_function(BenchmarkId::new(name, 4096), |b| {
            b.iter(|| sim.step(black_box(&obj)).expect("step"))
        });
    }
    g.finish();
}

criterion_group!(benches, steps, vehicles, full_step);
criterion_main!(benches);
