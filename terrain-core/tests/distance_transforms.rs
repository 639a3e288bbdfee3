//! The nearest-seed transforms: the parallel jump flooding equals the sequential reference (what
//! the GPU is compared with) bit for bit; the exact transform's distances equal brute force for
//! every metric, and every seed it returns is a seed at that distance (among equally near seeds
//! it may pick another than brute force); both identical for 1 and 4 threads.

use glam::{IVec2, UVec2};
use proptest::prelude::*;
use terrain_core::granular::*;
use terrain_core::{Grid, Rect};

const METRICS: [DistanceMetric; 3] = [
    DistanceMetric::Euclidean,
    DistanceMetric::Manhattan,
    DistanceMetric::Chebyshev,
];

/// A penetration texture over `area` (map coordinates) with seeds where `is_seed` says.
fn pen_from(area: Rect, is_seed: impl Fn(u32, u32) -> bool) -> Grid<Penetration> {
    Grid::from_fn(area.size.x, area.size.y, |i, j| {
        let (x, y) = (area.min.x as u32 + i, area.min.y as u32 + j);
        if is_seed(i, j) {
            Penetration {
                seed_x: x,
                seed_y: y,
                kind: ColumnKind::Seed as i32,
                penetration: 0,
            }
        } else {
            Penetration {
                seed_x: NO_SEED,
                seed_y: NO_SEED,
                kind: ColumnKind::Penetrating as i32,
                penetration: 1,
            }
        }
    })
    .unwrap()
}

fn in_pool<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Checks `seeds` against brute force: equal distances, and every returned seed is a seed.
fn check_exact(
    pen: &Grid<Penetration>,
    area: Rect,
    metric: DistanceMetric,
    seeds: &Grid<[u32; 2]>,
) {
    let exact = brute_force_distance(pen, area, metric);
    let got = distance_grid(seeds, area, metric);
    assert_eq!(got, exact, "{metric:?}");
    for s in seeds.as_slice() {
        if s[0] != NO_SEED {
            let (i, j) = (s[0] - area.min.x as u32, s[1] - area.min.y as u32);
            assert_ne!(
                pen.get(i, j).unwrap().seed_x,
                NO_SEED,
                "{metric:?}: {s:?} is no seed"
            );
        }
    }
}

/// The exact transform's answer by its tie rules, by brute force: per column the nearest seed
/// (the upper of two equally near), then the leftmost column whose seed is nearest under
/// `metric` (`dx^2 + g^2`, `dx + g`, `max(dx, g)` with `g` the distance along the column).
fn by_the_tie_rules(pen: &Grid<Penetration>, area: Rect, metric: DistanceMetric) -> Grid<[u32; 2]> {
    let (w, h) = (area.size.x, area.size.y);
    let column_nearest = |i: u32, y: u32| -> Option<(u64, u32)> {
        (0..h)
            .filter(|&j| pen.get(i, j).unwrap().seed_x != NO_SEED)
            .map(|j| (u64::from(j.abs_diff(y)), j))
            .min()
    };
    Grid::from_fn(w, h, |x, y| {
        let mut best: Option<(u64, [u32; 2])> = None;
        for i in 0..w {
            if let Some((g, j)) = column_nearest(i, y) {
                let dx = u64::from(x.abs_diff(i));
                let f = match metric {
                    DistanceMetric::Euclidean => dx * dx + g * g,
                    DistanceMetric::Manhattan => dx + g,
                    DistanceMetric::Chebyshev => dx.max(g),
                };
                if best.is_none_or(|(b, _)| f < b) {
                    let seed = [area.min.x as u32 + i, area.min.y as u32 + j];
                    best = Some((f, seed));
                }
            }
        }
        best.map_or([NO_SEED; 2], |(_, s)| s)
    })
    .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Random masks (sparse to dense, with empty rows and columns, or no seed at all), up to
    /// three column bands of the first phase wide (64 columns each) with a partial last one.
    #[test]
    fn exact_transform_equals_brute_force(
        w in 1u32..160, h in 1u32..40, density in 0u32..100, salt in any::<u32>(),
        mx in 0i32..50, my in 0i32..50,
    ) {
        let area = Rect::new(IVec2::new(mx, my), UVec2::new(w, h));
        let pen = pen_from(area, |i, j| pcg_hash(i ^ pcg_hash(j ^ salt)) % 1000 < density * density / 10);
        for metric in METRICS {
            let seeds = exact_nearest_seed(&pen, area, metric).unwrap();
            check_exact(&pen, area, metric, &seeds);
        }
    }

    /// The seed the exact transform returns, not only its distance: along a column the nearest
    /// seed with the one above winning ties, then along the row the leftmost column whose seed
    /// is nearest (the documented tie rules), on lattices and stripes full of ties.
    #[test]
    fn exact_transform_returns_the_documented_seed(
        w in 1u32..80, h in 1u32..24, step_x in 1u32..9, step_y in 1u32..9, holes in 0u32..4,
        salt in any::<u32>(), mx in 0i32..20, my in 0i32..20,
    ) {
        let area = Rect::new(IVec2::new(mx, my), UVec2::new(w, h));
        let pen = pen_from(area, |i, j| {
            i % step_x == 0 && j % step_y == 0 && pcg_hash(i ^ pcg_hash(j ^ salt)) % 4 >= holes
        });
        for metric in METRICS {
            let seeds = exact_nearest_seed(&pen, area, metric).unwrap();
            prop_assert!(seeds == by_the_tie_rules(&pen, area, metric), "{:?}", metric);
        }
    }

    /// The parallel jump flooding pass equals the sequential one (the GPU's reference) bit for
    /// bit, pass by pass, for 1 and 4 threads.
    #[test]
    fn parallel_jump_flood_equals_the_sequential_reference(
        w in 1u32..70, h in 1u32..70, density in 0u32..40, salt in any::<u32>(),
        mx in 0i32..90, my in 0i32..90, extra in any::<bool>(),
    ) {
        let area = Rect::new(IVec2::new(mx, my), UVec2::new(w, h));
        let pen = pen_from(area, |i, j| pcg_hash(i ^ pcg_hash(j ^ salt)) % 1000 < density * density / 4);
        for metric in METRICS {
            let reference = jump_flood_reference(&pen, area, metric, extra).unwrap();
            for threads in [1, 4] {
                let fast = in_pool(threads, || jump_flood(&pen, area, metric, extra).unwrap());
                prop_assert!(fast == reference, "{metric:?}, {threads} threads");
            }
        }
    }
}

/// Symmetric seed layouts where many columns have several nearest seeds: distances still
/// equal brute force; the exact transform for 1 and 4 threads is identical.
#[test]
fn ties_and_thread_counts() {
    // One band of the first phase, and several (bands are 64 columns) with a partial last one.
    for area in [
        Rect::new(IVec2::new(3, 5), UVec2::new(61, 40)),
        Rect::new(IVec2::new(7, 2), UVec2::new(151, 40)),
    ] {
        let r = area.size.x - 1;
        let layouts: [&dyn Fn(u32, u32) -> bool; 4] = [
            &|i, j| i % 10 == 0 && j % 10 == 0,
            &|i, j| (i == 0 || i == r) && j == 20,
            &|i, j| i == r / 2 && (j == 0 || j == 39),
            &|i, j| (i + j) % 17 == 0,
        ];
        for layout in layouts {
            let pen = pen_from(area, layout);
            for metric in METRICS {
                let one = in_pool(1, || exact_nearest_seed(&pen, area, metric).unwrap());
                let four = in_pool(4, || exact_nearest_seed(&pen, area, metric).unwrap());
                assert!(one == four);
                check_exact(&pen, area, metric, &one);
            }
        }
    }
}

/// Pins of the exact transform's documented choices and of rows its fast paths must not take.
#[test]
fn exact_transform_ties_along_a_column_and_seedless_edge_columns() {
    // Two seeds equally far along a column: the one above wins (the documented tie rule).
    let column = Rect::new(IVec2::new(2, 3), UVec2::new(1, 5));
    let pen = pen_from(column, |_, j| j == 0 || j == 4);
    for metric in METRICS {
        let seeds = exact_nearest_seed(&pen, column, metric).unwrap();
        assert_eq!(seeds.get(0, 2), Some([2, 3]), "{metric:?}");
        assert_eq!(seeds.get(0, 3), Some([2, 7]), "{metric:?}");
    }
    // A column without any seed at the left (or right) edge of rows that are otherwise all
    // seeds: the row has a column with no distance, which only the envelope handles.
    for edge in [0, 4] {
        let area = Rect::new(IVec2::new(1, 1), UVec2::new(5, 6));
        let pen = pen_from(area, |i, _| i != edge);
        for metric in METRICS {
            let seeds = exact_nearest_seed(&pen, area, metric).unwrap();
            check_exact(&pen, area, metric, &seeds);
        }
    }
}

/// A seed texel that names another column is an error, not a wrong answer; sizes are checked.
#[test]
fn bad_inputs_are_errors() {
    let area = Rect::from_size(UVec2::new(8, 8));
    let mut pen = pen_from(area, |i, _| i == 2);
    assert!(
        exact_nearest_seed(
            &pen,
            Rect::from_size(UVec2::new(8, 9)),
            DistanceMetric::Euclidean
        )
        .is_err()
    );
    pen.get_mut(2, 3).unwrap().seed_x = 5;
    assert!(matches!(
        exact_nearest_seed(&pen, area, DistanceMetric::Euclidean),
        Err(GranularError::SeedNotAtColumn { .. })
    ));
    // Both coordinates wrong is as wrong as one.
    let mut pen = pen_from(area, |i, _| i == 2);
    pen.get_mut(2, 3).unwrap().seed_x = 5;
    pen.get_mut(2, 3).unwrap().seed_y = 7;
    assert_eq!(
        exact_nearest_seed(&pen, area, DistanceMetric::Manhattan),
        Err(GranularError::SeedNotAtColumn {
            column: [2, 3],
            seed: [5, 7],
        })
    );
    // A wrong seed in a later column band is found and named too.
    let wide = Rect::new(IVec2::new(4, 1), UVec2::new(150, 6));
    let mut pen = pen_from(wide, |i, _| i % 3 == 0);
    pen.get_mut(129, 4).unwrap().seed_y = 2;
    assert_eq!(
        exact_nearest_seed(&pen, wide, DistanceMetric::Euclidean),
        Err(GranularError::SeedNotAtColumn {
            column: [133, 5],
            seed: [133, 2],
        })
    );
}

/// The scatter slope pass as it was written before its gather form: sequential, from
/// `column_outflow`.
fn scatter_reference(
    heights: &[u32],
    pen: &[Penetration],
    area: Rect,
    t: [u32; 2],
    r: u32,
) -> Vec<u32> {
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let mut acc = vec![0u32; heights.len()];
    for y in 0..h {
        for x in 0..w {
            let me = y * w + x;
            let (a, mask) = column_outflow(heights, pen, (w, h), (x, y), t, r);
            acc[me] = acc[me].wrapping_add(heights[me] - a * mask.count_ones());
            for (k, [ox, oy]) in JFA_OFFSETS.iter().enumerate() {
                if mask & (1 << k) != 0 {
                    let q = (y as i64 + i64::from(*oy)) as usize * w
                        + (x as i64 + i64::from(*ox)) as usize;
                    acc[q] = acc[q].wrapping_add(a);
                }
            }
        }
    }
    acc
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The row-parallel slope pass equals the sequential scatter bit for bit; whole granular
    /// steps (both transforms, every displacement and slope method) are identical for 1 and 4
    /// threads and conserve the volume.
    #[test]
    fn slopes_and_steps_do_not_depend_on_threads(
        w in 2u32..40, h in 2u32..40, salt in any::<u32>(), density in 1u32..30,
    ) {
        let area = Rect::new(IVec2::new(1, 2), UVec2::new(w, h));
        let pen = pen_from(area, |i, j| pcg_hash(i ^ pcg_hash(j ^ salt)) % 100 > density);
        let heights: Vec<u32> = (0..w * h).map(|i| 10_000 + pcg_hash(i ^ salt) % 3000).collect();
        let t = [200, 280];
        for threads in [1, 4] {
            let mut acc = vec![0u32; heights.len()];
            in_pool(threads, || slope_scatter_pass(&heights, pen.as_slice(), area, t, 20_000, &mut acc));
            prop_assert_eq!(&acc, &scatter_reference(&heights, pen.as_slice(), area, t, 20_000));
        }
        let map = terrain_core::FixedPointMap::fixed_point(
            Grid::from_fn(64, 64, |x, y| 10_000 + pcg_hash(x * 31 + y * 977 + salt) % 2000).unwrap(),
            10_000,
            0.1,
        ).unwrap();
        let wheel = TriMesh::wheel(0.8, 0.4, 16).unwrap();
        let at = glam::Affine3A::from_translation(glam::Vec3::new(3.2, 1.6, 3.1));
        for distance in [DistanceTransform::JumpFlood, DistanceTransform::Exact] {
            for displacement in [DisplacementMethod::iterative(), DisplacementMethod::ClosestSeed, DisplacementMethod::MultipleTargets] {
                for slope in [SlopeMethod::Scatter, SlopeMethod::Interleaved] {
                    let run = |threads| in_pool(threads, || {
                        let mut sim = GranularSim::new(map.clone(), GranularParams::default())
                            .unwrap()
                            .with_methods(displacement, slope)
                            .with_distance_transform(distance);
                        let r = sim.step(&[GranularObject::new(&wheel, at)]).unwrap();
                        (sim.into_map(), r)
                    });
                    let (one, r1) = run(1);
                    let (four, r4) = run(4);
                    prop_assert!(one == four);
                    prop_assert_eq!(&r1, &r4);
                    prop_assert_eq!(r1.volume, map.raw_sum());
                }
            }
        }
    }
}
