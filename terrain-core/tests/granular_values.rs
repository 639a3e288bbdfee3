//! Tests that pin what the granular passes compute, not only that volume is kept: material at
//! every map edge and corner, where displaced material goes, which of two tied seeds jump
//! flooding keeps, footprints, normals along Z and diagonals, mesh shapes, and the fields of
//! every error. Each one was written against a mutant (cargo-mutants) that survived the
//! volume-only tests; see docs/testing.md.

use glam::{Affine3A, IVec2, UVec2, Vec2, Vec3};
use terrain_core::granular::*;
use terrain_core::{
    CoreError, DEFAULT_GAUSSIAN_EPSILON_M, FixedPointMap, GaussianStamp, Grid, Rect, Stamp,
    StampPlacement,
};

const UNITS: u32 = 10_000;

fn flat_map(w: u32, h: u32, raw: u32, texel: f32) -> FixedPointMap {
    FixedPointMap::fixed_point(Grid::new(w, h, raw).expect("grid"), UNITS, texel).expect("map")
}

fn seed_at(x: u32, y: u32) -> Penetration {
    Penetration {
        seed_x: x,
        seed_y: y,
        kind: ColumnKind::Seed as i32,
        penetration: 0,
    }
}

fn penetrating(units: u32) -> Penetration {
    Penetration {
        seed_x: NO_SEED,
        seed_y: NO_SEED,
        kind: ColumnKind::Penetrating as i32,
        penetration: units,
    }
}

/// A penetration texture over a whole `w x h` map: columns in `block` penetrate by a
/// position-dependent amount, the rest are seeds at their own columns.
fn block_pen(w: u32, h: u32, block: Rect) -> Grid<Penetration> {
    Grid::from_fn(w, h, |x, y| {
        if block.contains(IVec2::new(x as i32, y as i32)) {
            penetrating(1_000 + 37 * x + 101 * y)
        } else {
            seed_at(x, y)
        }
    })
    .expect("grid")
}

/// Blocks of 3 x 3 columns touching every edge and corner of a `w x h` map (and one inside).
fn edge_blocks(w: u32, h: u32) -> Vec<Rect> {
    let (w, h) = (w as i32, h as i32);
    let xs = [0, w / 2 - 1, w - 3];
    let ys = [0, h / 2 - 1, h - 3];
    let mut out = Vec::new();
    for y in ys {
        for x in xs {
            out.push(Rect::new(IVec2::new(x, y), UVec2::splat(3)));
        }
    }
    out
}

const METRICS: [DistanceMetric; 3] = [
    DistanceMetric::Euclidean,
    DistanceMetric::Manhattan,
    DistanceMetric::Chebyshev,
];

/// The iterative method rebuilt from the public reference pass ([`iterative_pass`] and
/// [`lower_neighbour_counts`]) as its documentation describes it.
fn iterative_by_reference(
    map: &FixedPointMap,
    pen: &Grid<Penetration>,
    seeds: &Grid<[u32; 2]>,
    iterations: u32,
    metric: DistanceMetric,
) -> (Vec<u32>, u64) {
    let area = Rect::from_size(map.size());
    let dist = distance_grid(seeds, area, metric);
    let counts = lower_neighbour_counts(&dist);
    let mut heights = map.grid().as_slice().to_vec();
    let mut carried = pen.map(|_| 0u32);
    for (i, p) in pen.as_slice().iter().enumerate() {
        if p.column_kind() == ColumnKind::Penetrating {
            heights[i] -= p.penetration;
            carried.as_mut_slice()[i] = p.penetration;
        }
    }
    let total: u64 = carried.as_slice().iter().map(|&c| u64::from(c)).sum();
    let mut next = carried.clone();
    for _ in 0..iterations {
        iterative_pass(&dist, &counts, &carried, &mut next);
        std::mem::swap(&mut carried, &mut next);
        let now: u64 = carried.as_slice().iter().map(|&c| u64::from(c)).sum();
        assert_eq!(now, total, "the reference pass lost or made material");
    }
    let w = map.size().x;
    for (i, (&c, p)) in carried.as_slice().iter().zip(pen.as_slice()).enumerate() {
        let s = seeds.as_slice()[i];
        let t = if p.column_kind() == ColumnKind::Seed || s[0] == NO_SEED {
            i
        } else {
            (s[1] * w + s[0]) as usize
        };
        heights[t] += c;
    }
    (heights, total)
}

#[test]
fn iterative_pass_keeps_material_at_every_edge_and_corner() {
    let (w, h) = (12u32, 10u32);
    let map = flat_map(w, h, 10_000, 0.1);
    let area = Rect::from_size(map.size());
    for block in edge_blocks(w, h) {
        let pen = block_pen(w, h, block);
        for metric in METRICS {
            let seeds = exact_nearest_seed(&pen, area, metric).expect("seeds");
            for iterations in [1, 3, 8] {
                let (reference, _) = iterative_by_reference(&map, &pen, &seeds, iterations, metric);
                let ref_sum: u64 = reference.iter().map(|&v| u64::from(v)).sum();
                assert_eq!(ref_sum, map.raw_sum(), "{block:?} {metric:?}");
                let mut fast = map.clone();
                let removed =
                    displace_iterative(&mut fast, &pen, &seeds, area, 32_768, iterations, metric)
                        .expect("displace");
                assert_eq!(removed, 0);
                assert_eq!(fast.raw_sum(), map.raw_sum(), "{block:?} {metric:?}");
                assert_eq!(
                    fast.grid().as_slice(),
                    &reference[..],
                    "{block:?} {metric:?} {iterations} iterations: fast and reference differ"
                );
            }
        }
    }
}

#[test]
fn lower_neighbour_counts_at_edges() {
    // Distances growing away from the corner (0, 0): every column's lower neighbours are the
    // ones towards the corner that exist.
    let dist = Grid::from_fn(4, 3, |x, y| x + y).expect("grid");
    let n = lower_neighbour_counts(&dist);
    assert_eq!(n.get(0, 0), Some(0));
    assert_eq!(n.get(1, 0), Some(1)); // (0,0); (0,1) ties
    assert_eq!(n.get(0, 1), Some(1)); // (0,0); (1,0) ties
    assert_eq!(n.get(1, 1), Some(3)); // (0,0), (1,0), (0,1)
    assert_eq!(n.get(3, 2), Some(3));
    // And away from the far corner.
    let dist = Grid::from_fn(4, 3, |x, y| (3 - x) + (2 - y)).expect("grid");
    let n = lower_neighbour_counts(&dist);
    assert_eq!(n.get(3, 2), Some(0));
    assert_eq!(n.get(2, 2), Some(1));
    assert_eq!(n.get(3, 1), Some(1));
    assert_eq!(n.get(2, 1), Some(3));
    assert_eq!(n.get(0, 0), Some(3));
}

#[test]
fn sim_keeps_volume_with_a_box_at_every_edge_and_corner() {
    let cube = TriMesh::cuboid(Vec3::new(0.25, 0.3, 0.25)).expect("box");
    let methods = [
        DisplacementMethod::Iterative { iterations: 4 },
        DisplacementMethod::ClosestSeed,
        DisplacementMethod::MultipleTargets,
    ];
    // 24 x 24 columns of 1 m at 0.1 m per texel: the map spans [0, 2.3] m.
    let (size, ts) = (24u32, 0.1f32);
    let far = (size - 1) as f32 * ts;
    for method in methods {
        for (x, z) in [
            (0.0, 0.0),
            (far / 2.0, 0.0),
            (far, 0.0),
            (0.0, far / 2.0),
            (far, far / 2.0),
            (0.0, far),
            (far / 2.0, far),
            (far, far),
        ] {
            let map = flat_map(size, size, 10_000, ts);
            let before = map.raw_sum();
            let params = GranularParams {
                num_iterations_even_out_slopes: 2,
                ..GranularParams::snow()
            };
            let mut sim = GranularSim::new(map, params)
                .expect("sim")
                .with_methods(method, SlopeMethod::Interleaved);
            // The bottom at 0.85 m: 0.15 m into the material.
            let at = Affine3A::from_translation(Vec3::new(x, 1.15, z));
            let report = sim.step(&[GranularObject::new(&cube, at)]).expect("step");
            assert_eq!(report.volume, before, "{method:?} at ({x}, {z})");
            assert_eq!(sim.map().raw_sum(), before, "{method:?} at ({x}, {z})");
            // The box pressed in: the column under its centre is lower.
            let cx = (x / ts).round() as u32;
            let cz = (z / ts).round() as u32;
            let under = sim.map().grid().get(cx, cz).expect("column");
            assert!(under < 10_000, "{method:?} at ({x}, {z}): {under}");
        }
    }
}

/// A 9 x 12 area of 1 m, all seeds, with one penetrating column `c` whose seed is `s`.
fn one_column(c: (u32, u32), s: (u32, u32), units: u32) -> (FixedPointMap, Grid<Penetration>) {
    let map = flat_map(9, 12, 10_000, 0.1);
    let pen = Grid::from_fn(9, 12, |x, y| {
        if (x, y) == c {
            Penetration {
                seed_x: s.0,
                seed_y: s.1,
                ..penetrating(units)
            }
        } else {
            seed_at(x, y)
        }
    })
    .expect("grid");
    (map, pen)
}

/// The heights above 1 m after displacing, as `(x, y, units)`.
fn raised(map: &FixedPointMap) -> Vec<(u32, u32, u32)> {
    let mut out = Vec::new();
    for y in 0..map.size().y {
        for x in 0..map.size().x {
            let v = map.grid().get(x, y).expect("texel");
            if v > 10_000 {
                out.push((x, y, v - 10_000));
            }
        }
    }
    out
}

#[test]
fn multiple_targets_march_away_from_the_object() {
    let area = Rect::from_size(UVec2::new(9, 12));
    // Diagonal: from (3, 3) to its seed (4, 4), then on along (+1, +1).
    let (mut map, pen) = one_column((3, 3), (4, 4), 3_000);
    let seeds = jfa_init(&pen);
    displace_multiple_targets(&mut map, &pen, &seeds, area, 32_768).expect("displace");
    assert_eq!(
        raised(&map),
        vec![(4, 4, 1_000), (5, 5, 1_000), (6, 6, 1_000)]
    );
    assert_eq!(map.grid().get(3, 3), Some(7_000));
    // Straight down in y: from (4, 6) to (4, 5), then (4, 4), (4, 3).
    let (mut map, pen) = one_column((4, 6), (4, 5), 3_000);
    let seeds = jfa_init(&pen);
    displace_multiple_targets(&mut map, &pen, &seeds, area, 32_768).expect("displace");
    assert_eq!(
        raised(&map),
        vec![(4, 3, 1_000), (4, 4, 1_000), (4, 5, 1_000)]
    );
    // Mirrored: up in y and left in x, with a remainder (2 500 over 3 targets: 834, 833, 833).
    let (mut map, pen) = one_column((5, 4), (4, 5), 2_500);
    let seeds = jfa_init(&pen);
    displace_multiple_targets(&mut map, &pen, &seeds, area, 32_768).expect("displace");
    assert_eq!(raised(&map), vec![(4, 5, 834), (3, 6, 833), (2, 7, 833)]);
    // A knight's move (dx 2, dy 1): t_i = seed + (2i / 2, i / 2).
    let (mut map, pen) = one_column((2, 2), (4, 3), 4_000);
    let seeds = jfa_init(&pen);
    displace_multiple_targets(&mut map, &pen, &seeds, area, 32_768).expect("displace");
    assert_eq!(
        raised(&map),
        vec![(4, 3, 1_000), (5, 3, 1_000), (6, 4, 1_000), (7, 4, 1_000)]
    );
    // The march leaves the area after two targets: the rest lands on the last valid one.
    let (mut map, pen) = one_column((6, 6), (7, 7), 4_000);
    let seeds = jfa_init(&pen);
    displace_multiple_targets(&mut map, &pen, &seeds, area, 32_768).expect("displace");
    assert_eq!(raised(&map), vec![(7, 7, 1_000), (8, 8, 3_000)]);
}

#[test]
fn closest_seed_sends_material_to_the_seed() {
    let area = Rect::from_size(UVec2::new(9, 12));
    let (mut map, pen) = one_column((3, 3), (4, 1), 2_000);
    let seeds = jfa_init(&pen);
    displace_closest_seed(&mut map, &pen, &seeds, area, 32_768).expect("displace");
    assert_eq!(raised(&map), vec![(4, 1, 2_000)]);
    assert_eq!(map.grid().get(3, 3), Some(8_000));
}

#[test]
fn a_box_pressed_near_one_side_moves_material_to_its_sides() {
    // A box over texels x 10..=19, y 2..=5 of a 30 x 40 map, 0.15 m into 1 m: its material
    // goes to the free columns next to it. Rows 2 and 3 send theirs to row 1 (and, with
    // multiple targets, on to row 0); rows 4 and 5 to row 6 (and on to row 7).
    let cube = TriMesh::cuboid(Vec3::new(0.5, 0.3, 0.2)).expect("box");
    for method in [
        DisplacementMethod::ClosestSeed,
        DisplacementMethod::MultipleTargets,
        DisplacementMethod::Iterative { iterations: 8 },
    ] {
        let map = flat_map(30, 40, 10_000, 0.1);
        let before = map.raw_sum();
        let params = GranularParams {
            num_iterations_even_out_slopes: 0,
            ..GranularParams::snow()
        };
        let mut sim = GranularSim::new(map, params)
            .expect("sim")
            .with_methods(method, SlopeMethod::Interleaved)
            .with_distance_transform(DistanceTransform::Exact);
        let at = Affine3A::from_translation(Vec3::new(1.45, 1.15, 0.35));
        sim.step(&[GranularObject::new(&cube, at)]).expect("step");
        let g = sim.map().grid();
        assert_eq!(sim.map().raw_sum(), before);
        let row_sum = |y: u32| -> i64 {
            (0..30)
                .map(|x| i64::from(g.get(x, y).expect("texel")) - 10_000)
                .sum()
        };
        for y in 2..=5 {
            for x in 10..=19 {
                // The bottom at 0.85 m (f32): 8 499 or 8 500 units.
                let v = g.get(x, y).expect("texel");
                assert!((8_499..=8_500).contains(&v), "{method:?} ({x}, {y}): {v}");
            }
        }
        assert!(row_sum(1) > 0, "{method:?}");
        assert!(row_sum(6) > 0, "{method:?}");
        let spread = method == DisplacementMethod::MultipleTargets;
        assert_eq!(row_sum(0) > 0, spread, "{method:?}: row 0 {}", row_sum(0));
        assert_eq!(row_sum(7) > 0, spread, "{method:?}: row 7 {}", row_sum(7));
        for y in 9..40 {
            assert_eq!(row_sum(y), 0, "{method:?} row {y}");
        }
        // Columns far to the left and right of the box are untouched.
        for y in 0..40 {
            for x in (0..7).chain(23..30) {
                assert_eq!(g.get(x, y), Some(10_000), "{method:?} ({x}, {y})");
            }
        }
    }
}

#[test]
fn jump_flooding_keeps_the_first_tied_seed_in_the_hashed_order() {
    // A 3 x 3 area whose only seeds are (1, 0) and (1, 2): the centre is 1 from both. In
    // the first pass (step 2) the centre sees nothing; the last pass (step 1, index 1) reads
    // (1, 0) at offset [0, -1] (index 1) and (1, 2) at offset [0, 1] (index 6): the one that
    // comes first in jfa_neighbour_order(1, 1, 1) wins.
    let mut seen = [false; 2];
    for (ox, oy) in [(0u32, 0u32), (5, 7), (100, 3), (2, 40), (13, 13), (7, 1)] {
        let area = Rect::new(IVec2::new(ox as i32, oy as i32), UVec2::splat(3));
        let pen = Grid::from_fn(3, 3, |x, y| {
            if x == 1 && y != 1 {
                seed_at(ox + x, oy + y)
            } else {
                penetrating(1)
            }
        })
        .expect("grid");
        assert_eq!(jfa_steps(area.size, false), vec![2, 1]);
        let order = jfa_neighbour_order(ox + 1, oy + 1, 1);
        let pos = |k: u8| order.iter().position(|&o| o == k).expect("permutation");
        let expected = if pos(1) < pos(6) {
            [ox + 1, oy]
        } else {
            [ox + 1, oy + 2]
        };
        seen[usize::from(pos(1) > pos(6))] = true;
        for metric in METRICS {
            for got in [
                jump_flood(&pen, area, metric, false).expect("jfa"),
                jump_flood_reference(&pen, area, metric, false).expect("jfa"),
            ] {
                assert_eq!(got.get(1, 1), Some(expected), "area at ({ox}, {oy})");
            }
        }
        // Left and right ties: (0, 1) and (2, 1) as the seeds, offsets [-1, 0] (3), [1, 0] (4).
        let pen = Grid::from_fn(3, 3, |x, y| {
            if y == 1 && x != 1 {
                seed_at(ox + x, oy + y)
            } else {
                penetrating(1)
            }
        })
        .expect("grid");
        let expected = if pos(3) < pos(4) {
            [ox, oy + 1]
        } else {
            [ox + 2, oy + 1]
        };
        for metric in METRICS {
            for got in [
                jump_flood(&pen, area, metric, false).expect("jfa"),
                jump_flood_reference(&pen, area, metric, false).expect("jfa"),
            ] {
                assert_eq!(got.get(1, 1), Some(expected), "area at ({ox}, {oy})");
            }
        }
    }
    assert_eq!(seen, [true, true], "both outcomes are exercised");
}

/// One jump flooding pass exactly as the module documentation states it.
fn pass_by_the_book(
    prev: &Grid<[u32; 2]>,
    area: Rect,
    step: u32,
    pass: u32,
    metric: DistanceMetric,
) -> Grid<[u32; 2]> {
    let (w, h) = (area.size.x as i64, area.size.y as i64);
    Grid::from_fn(area.size.x, area.size.y, |i, j| {
        let col = [area.min.x as u32 + i, area.min.y as u32 + j];
        let mut best = prev.get(i, j).expect("texel");
        for o in jfa_neighbour_order(col[0], col[1], pass) {
            let [dx, dy] = JFA_OFFSETS[usize::from(o)];
            let ni = i64::from(i) + i64::from(dx) * i64::from(step);
            let nj = i64::from(j) + i64::from(dy) * i64::from(step);
            if ni < 0 || nj < 0 || ni >= w || nj >= h {
                continue;
            }
            let cand = prev.get(ni as u32, nj as u32).expect("texel");
            if seed_distance(metric, col, cand) < seed_distance(metric, col, best) {
                best = cand;
            }
        }
        best
    })
    .expect("grid")
}

#[test]
fn jump_flood_passes_match_the_documented_rule_seed_for_seed() {
    // Seeds on a lattice: many columns are tied between several seeds.
    let area = Rect::new(IVec2::new(4, 9), UVec2::new(23, 17));
    let pen = Grid::from_fn(23, 17, |i, j| {
        if (i % 6 == 0 && j % 4 == 0) || (i == 11 && j == 9) {
            seed_at(4 + i, 9 + j)
        } else {
            penetrating(1)
        }
    })
    .expect("grid");
    for metric in METRICS {
        let mut book = jfa_init(&pen);
        for (pass, step) in jfa_steps(area.size, true).into_iter().enumerate() {
            let next = pass_by_the_book(&book, area, step, pass as u32, metric);
            for f in [jfa_pass, jfa_pass_reference] {
                let mut out = book.clone();
                f(&book, &mut out, area, step, pass as u32, metric).expect("pass");
                assert!(out == next, "{metric:?} pass {pass} step {step}");
            }
            book = next;
        }
        assert!(book == jump_flood(&pen, area, metric, true).expect("jfa"));
        assert!(book == jump_flood_reference(&pen, area, metric, true).expect("jfa"));
    }
}

#[test]
fn object_footprint_extents_are_exact() {
    // Texel 0.25 m (exact in binary). A box 1 m x 1.75 m centred at (2, 3): X 1.5..2.5 is
    // texels 6..=10, Z 2.125..3.875 is 8.5..15.5, so floor 8 ..= ceil 16.
    let cube = TriMesh::cuboid(Vec3::new(0.5, 0.2, 0.875)).expect("box");
    let at = Affine3A::from_translation(Vec3::new(2.0, 5.0, 3.0));
    let fp = object_footprint(&GranularObject::new(&cube, at), 0.25).expect("footprint");
    assert_eq!(fp, Rect::new(IVec2::new(6, 8), UVec2::new(5, 9)));
    // Off the map's low corner (negative texels) and a wide, shallow box.
    let cube = TriMesh::cuboid(Vec3::new(1.375, 0.2, 0.25)).expect("box");
    let at = Affine3A::from_translation(Vec3::new(-1.0, 0.0, -0.5));
    let fp = object_footprint(&GranularObject::new(&cube, at), 0.25).expect("footprint");
    // X -2.375..0.375 is -9.5..1.5: floor -10 ..= ceil 2; Z -0.75..-0.25 is -3..-1.
    assert_eq!(fp, Rect::new(IVec2::new(-10, -3), UVec2::new(13, 3)));
    // The active area is the footprint grown by the margin, clipped to the map.
    let cube = TriMesh::cuboid(Vec3::new(0.5, 0.2, 0.875)).expect("box");
    let at = Affine3A::from_translation(Vec3::new(2.0, 5.0, 3.0));
    let fp = object_footprint(&GranularObject::new(&cube, at), 0.5).expect("footprint");
    // X 1.5..2.5 is 3..5, Z 2.125..3.875 is 4.25..7.75: 4 ..= 8.
    assert_eq!(fp, Rect::new(IVec2::new(3, 4), UVec2::new(3, 5)));
}

/// A map of `w x h` with heights `f(x, y)` units at `texel` metres per texel.
fn map_from(w: u32, h: u32, texel: f32, f: impl Fn(u32, u32) -> u32) -> FixedPointMap {
    FixedPointMap::fixed_point(Grid::from_fn(w, h, f).expect("grid"), UNITS, texel).expect("map")
}

fn normals_of(map: &FixedPointMap) -> Grid<Vec3> {
    let mut out = Grid::new(map.size().x, map.size().y, Vec3::ZERO).expect("grid");
    symmetric_normals(map, Rect::from_size(map.size()), &mut out).expect("normals");
    out
}

fn assert_close(got: Vec3, want: Vec3, what: &str) {
    assert!(
        (got - want).length() < 1e-5,
        "{what}: got {got}, want {want}"
    );
}

#[test]
fn normals_of_ramps_along_z_and_diagonals() {
    for texel in [0.5f32, 2.0, 0.1] {
        // Along Z: 0.02 m per row.
        let map = map_from(6, 7, texel, |_, y| 10_000 + 200 * y);
        let n = normals_of(&map);
        let slope = 0.02 / texel;
        let inner = Vec3::new(0.0, 1.0, -slope).normalize();
        for y in 1..6 {
            for x in 0..6 {
                assert_close(n.get(x, y).expect("n"), inner, &format!("z ramp ({x},{y})"));
            }
        }
        // Edges clamp: a one-sided difference halved.
        let edge = Vec3::new(0.0, 1.0, -slope / 2.0).normalize();
        assert_close(n.get(2, 0).expect("n"), edge, "z ramp row 0");
        assert_close(n.get(2, 6).expect("n"), edge, "z ramp last row");
        // Along X falling: 0.03 m per column.
        let map = map_from(6, 5, texel, |x, _| 10_000 - 300 * x);
        let n = normals_of(&map);
        let inner = Vec3::new(0.03 / texel, 1.0, 0.0).normalize();
        assert_close(n.get(3, 2).expect("n"), inner, "x ramp");
        assert_close(n.get(3, 0).expect("n"), inner, "x ramp row 0");
        // Diagonal: 0.01 m per column, 0.03 m per row.
        let map = map_from(7, 7, texel, |x, y| 10_000 + 100 * x + 300 * y);
        let n = normals_of(&map);
        let inner = Vec3::new(-0.01 / texel, 1.0, -0.03 / texel).normalize();
        for (x, y) in [(1, 1), (3, 4), (5, 5)] {
            assert_close(
                n.get(x, y).expect("n"),
                inner,
                &format!("diagonal ({x},{y})"),
            );
        }
        let corner = Vec3::new(-0.005 / texel, 1.0, -0.015 / texel).normalize();
        assert_close(n.get(0, 0).expect("n"), corner, "diagonal corner");
        assert_close(n.get(6, 6).expect("n"), corner, "diagonal far corner");
        // A constant field stays constant under blurring, and only inside the area.
        let mut b = n.clone();
        blur_normals(&mut b, Rect::new(IVec2::new(1, 1), UVec2::splat(5)), 2).expect("blur");
        assert_close(b.get(3, 3).expect("n"), inner, "blurred");
        assert_eq!(b.get(0, 0), n.get(0, 0));
    }
    // A peak: normals lean away from it on both axes.
    let map = map_from(5, 5, 0.5, |x, y| {
        10_000 - 100 * (x.abs_diff(2) + y.abs_diff(2))
    });
    let n = normals_of(&map);
    assert_close(
        n.get(2, 1).expect("n"),
        Vec3::new(0.0, 1.0, -0.02).normalize(),
        "north of the peak",
    );
    assert_close(
        n.get(2, 3).expect("n"),
        Vec3::new(0.0, 1.0, 0.02).normalize(),
        "south of the peak",
    );
    assert_close(n.get(2, 2).expect("n"), Vec3::Y, "the peak");
    // Float heights follow the same rows.
    let map = map_from(4, 3, 0.5, |x, y| 10_000 + 10 * x + 1_000 * y);
    let mut f = Grid::new(4, 3, -1.0f32).expect("grid");
    float_heights(&map, Rect::new(IVec2::new(1, 1), UVec2::new(2, 2)), &mut f).expect("f");
    assert_eq!(f.get(0, 0), Some(-1.0));
    assert!((f.get(2, 1).expect("f") - 1.102).abs() < 1e-6);
    assert!((f.get(1, 2).expect("f") - 1.201).abs() < 1e-6);
}

fn bounds(vs: &[Vec3]) -> (Vec3, Vec3) {
    vs.iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

#[test]
fn mesh_shapes_and_sizes() {
    // Foot: outline fractions x in [-0.8, 0.9] of width / 2, z in [-1, 1] of length / 2.
    let foot = TriMesh::foot(0.3, 0.12, 0.1).expect("foot");
    let (lo, hi) = bounds(foot.vertices());
    assert_close(lo, Vec3::new(-0.048, 0.0, -0.15), "foot min");
    assert_close(hi, Vec3::new(0.054, 0.1, 0.15), "foot max");
    assert_eq!(foot.vertices().len(), 20);
    assert_eq!(foot.triangles().len(), 2 * 8 + 2 * 10);
    // The heel (vertex 0) is centred at the back, the toe row at the front.
    assert_close(foot.vertices()[0], Vec3::new(0.0, 0.0, -0.15), "heel");
    assert_close(foot.vertices()[10], Vec3::new(0.0, 0.1, -0.15), "heel top");
    assert_close(foot.vertices()[5], Vec3::new(0.024, 0.0, 0.15), "toe");
    // Its sole lies at y = 0 and covers the outline: placed at (0.2, 0.9375, 0.2) over
    // 0.02 m texels, it spans X 0.152..0.254 (texels 7.6..12.7) and Z 0.05..0.35 (2.5..17.5).
    let map = flat_map(20, 20, 10_000, 0.02);
    let at = Affine3A::from_translation(Vec3::new(0.2, 0.9375, 0.2));
    let depth = depth_from_below(
        &[GranularObject::new(&foot, at)],
        &map,
        Rect::from_size(map.size()),
    )
    .expect("depth");
    for (x, y) in [(10, 10), (10, 3), (10, 17), (8, 10), (12, 10)] {
        assert_eq!(depth.get(x, y), Some(9_375), "inside at ({x}, {y})");
    }
    for (x, y) in [(10, 2), (10, 18), (7, 10), (13, 10), (8, 3), (12, 17)] {
        assert_eq!(depth.get(x, y), Some(NO_OBJECT), "outside at ({x}, {y})");
    }
    // Wheel: axle along X, vertex 0 at the bottom of the -X rim.
    let wheel = TriMesh::wheel(0.35, 0.15, 16).expect("wheel");
    let (lo, hi) = bounds(wheel.vertices());
    assert_close(lo, Vec3::new(-0.15, -0.35, -0.35), "wheel min");
    assert_close(hi, Vec3::new(0.15, 0.35, 0.35), "wheel max");
    assert_close(wheel.vertices()[0], Vec3::new(-0.15, -0.35, 0.0), "rim 0");
    assert_close(wheel.vertices()[16], Vec3::new(0.15, -0.35, 0.0), "rim 1");
    assert_close(
        wheel.vertices()[4],
        Vec3::new(-0.15, 0.0, 0.35),
        "quarter turn",
    );
    assert_close(wheel.vertices()[32], Vec3::new(-0.15, 0.0, 0.0), "hub 0");
    assert_close(wheel.vertices()[33], Vec3::new(0.15, 0.0, 0.0), "hub 1");
    assert_eq!(wheel.vertices().len(), 34);
    assert_eq!(wheel.triangles().len(), 64);
    // Box.
    let cube = TriMesh::cuboid(Vec3::new(0.4, 0.3, 0.25)).expect("box");
    let (lo, hi) = bounds(cube.vertices());
    assert_close(lo, Vec3::new(-0.4, -0.3, -0.25), "box min");
    assert_close(hi, Vec3::new(0.4, 0.3, 0.25), "box max");
    assert_eq!(cube.triangles().len(), 12);
}

#[test]
fn errors_carry_their_values() {
    let bad = |r: Result<TriMesh, GranularError>| r.expect_err("must fail");
    // A negative size reports the negative one; a too large one reports the large one.
    match bad(TriMesh::cuboid(Vec3::new(-1.0, 2.0, 3.0))) {
        GranularError::ParamOutOfRange { name, value, range } => {
            assert_eq!(name, "half_extents");
            assert_eq!(value, -1.0);
            assert_eq!(range, "(0, 1e6] m");
        }
        e => panic!("{e:?}"),
    }
    match bad(TriMesh::cuboid(Vec3::new(1.0, 2.0, 2.0e6))) {
        GranularError::ParamOutOfRange { value, .. } => assert_eq!(value, 2.0e6),
        e => panic!("{e:?}"),
    }
    match bad(TriMesh::cuboid(Vec3::new(1.0, f32::INFINITY, 2.0))) {
        GranularError::ParamOutOfRange { value, .. } => assert_eq!(value, f64::INFINITY),
        e => panic!("{e:?}"),
    }
    match bad(TriMesh::cuboid(Vec3::new(1.0, f32::NEG_INFINITY, 2.0))) {
        GranularError::ParamOutOfRange { value, .. } => assert_eq!(value, f64::NEG_INFINITY),
        e => panic!("{e:?}"),
    }
    match bad(TriMesh::foot(0.3, 0.0, 0.1)) {
        GranularError::ParamOutOfRange { name, value, .. } => {
            assert_eq!(name, "foot size");
            assert_eq!(value, 0.0);
        }
        e => panic!("{e:?}"),
    }
    match bad(TriMesh::wheel(0.5, -0.2, 16)) {
        GranularError::ParamOutOfRange { name, value, .. } => {
            assert_eq!(name, "radius / half_width");
            assert!((value + 0.2).abs() < 1e-7);
        }
        e => panic!("{e:?}"),
    }
    match bad(TriMesh::wheel(0.5, 0.2, 2)) {
        GranularError::ParamOutOfRange { name, value, range } => {
            assert_eq!((name, value, range), ("segments", 2.0, "3..=1024"));
        }
        e => panic!("{e:?}"),
    }
    assert!(matches!(
        bad(TriMesh::wheel(0.5, 0.2, 1025)),
        GranularError::ParamOutOfRange { value, .. } if value == 1025.0
    ));
    assert_eq!(
        bad(TriMesh::new(vec![], vec![[0, 0, 0]])),
        GranularError::EmptyMesh {
            vertices: 0,
            triangles: 1
        }
    );
    assert_eq!(
        bad(TriMesh::new(vec![Vec3::ZERO], vec![])),
        GranularError::EmptyMesh {
            vertices: 1,
            triangles: 0
        }
    );
    assert_eq!(
        bad(TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Z],
            vec![[0, 1, 2], [0, 3, 1]]
        )),
        GranularError::IndexOutOfRange {
            triangle: 1,
            index: 3,
            vertices: 3
        }
    );
    assert_eq!(
        bad(TriMesh::new(
            vec![Vec3::ZERO, Vec3::new(0.0, 2.0e6, 0.0), Vec3::Z],
            vec![[0, 1, 2]]
        )),
        GranularError::BadVertex {
            index: 1,
            value: [0.0, 2.0e6, 0.0],
            limit: MAX_COORDINATE_M
        }
    );
    // Regions and sizes.
    let map = flat_map(8, 6, 10_000, 0.1);
    let out = Rect::new(IVec2::new(4, 2), UVec2::new(5, 2));
    assert_eq!(
        depth_from_below(&[], &map, out).expect_err("outside"),
        GranularError::RegionOutsideMap {
            rect: out,
            map_size: UVec2::new(8, 6)
        }
    );
    let empty = Rect::new(IVec2::new(1, 1), UVec2::new(0, 2));
    assert!(matches!(
        depth_from_below(&[], &map, empty),
        Err(GranularError::RegionOutsideMap { rect, .. }) if rect == empty
    ));
    let area = Rect::new(IVec2::new(1, 1), UVec2::new(3, 2));
    let mut wrong = Grid::new(2, 3, 0u32).expect("grid");
    assert_eq!(
        depth_from_below_into(&[], map.encoding(), 0.1, area, &mut wrong).expect_err("size"),
        GranularError::SizeMismatch {
            expected: UVec2::new(3, 2),
            actual: UVec2::new(2, 3)
        }
    );
    let pen = Grid::new(3, 2, seed_at(0, 0)).expect("grid");
    let seeds = Grid::new(3, 3, [0u32; 2]).expect("grid");
    let mut m = map.clone();
    for f in [displace_closest_seed, displace_multiple_targets] {
        assert_eq!(
            f(&mut m, &pen, &seeds, area, 32_768).expect_err("size"),
            GranularError::SizeMismatch {
                expected: UVec2::new(3, 2),
                actual: UVec2::new(3, 3)
            }
        );
    }
    let prev = Grid::new(3, 2, [0u32; 2]).expect("grid");
    let mut next = Grid::new(2, 2, [0u32; 2]).expect("grid");
    assert_eq!(
        jfa_pass(&prev, &mut next, area, 1, 0, DistanceMetric::Euclidean).expect_err("size"),
        GranularError::SizeMismatch {
            expected: UVec2::new(3, 2),
            actual: UVec2::new(2, 2)
        }
    );
    let huge = Rect::new(IVec2::ZERO, UVec2::new(MAX_SIDE + 1, 1));
    let pen1 = Grid::new(1, 1, seed_at(0, 0)).expect("grid");
    assert_eq!(
        jump_flood(&pen1, huge, DistanceMetric::Euclidean, false).expect_err("side"),
        GranularError::TooLarge {
            side: MAX_SIDE + 1,
            limit: MAX_SIDE
        }
    );
    let mut normals = Grid::new(3, 3, Vec3::Y).expect("grid");
    assert_eq!(
        symmetric_normals(&map, Rect::from_size(map.size()), &mut normals).expect_err("size"),
        GranularError::SizeMismatch {
            expected: UVec2::new(8, 6),
            actual: UVec2::new(3, 3)
        }
    );
    // Parameters report the offending value.
    let p = GranularParams {
        roughness: 1.5,
        ..GranularParams::snow()
    };
    assert!(matches!(
        p.validate(),
        Err(GranularError::ParamOutOfRange { name: "roughness", value, .. }) if value == 1.5
    ));
    let p = GranularParams {
        roughness: f32::NAN,
        ..GranularParams::snow()
    };
    assert!(matches!(
        p.validate(),
        Err(GranularError::ParamOutOfRange { name: "roughness", value, .. }) if value.is_nan()
    ));
    let p = GranularParams {
        roughness: -0.5,
        ..GranularParams::snow()
    };
    assert!(matches!(
        p.validate(),
        Err(GranularError::ParamOutOfRange { name: "roughness", value, .. }) if value == -0.5
    ));
}

#[test]
fn gaussian_stamp_getters() {
    let mut g = GaussianStamp::new(0.002).expect("stamp");
    assert_eq!(g.epsilon_m(), 0.002);
    assert_eq!(g.beta(), 1.0);
    let p = StampPlacement::new(Vec2::new(1.0, 1.0), Vec2::splat(2.0), -1.0).expect("placement");
    g.prepare(&p).expect("prepare");
    let want = (1.0f32 / 0.002).ln();
    assert!((g.beta() - want).abs() < 1e-5, "{}", g.beta());
    assert_eq!(g.beta(), g.beta_for(-1.0));
    // A faint stamp holds beta at 1 (ln e).
    let faint = StampPlacement::new(Vec2::ZERO, Vec2::ONE, 0.004).expect("placement");
    g.prepare(&faint).expect("prepare");
    assert!((g.beta() - 1.0).abs() < 1e-6);
    let d = GaussianStamp::default();
    assert_eq!(d.epsilon_m(), DEFAULT_GAUSSIAN_EPSILON_M);
    assert_eq!(d.beta(), 1.0);
    assert!(matches!(
        GaussianStamp::new(-1.0),
        Err(CoreError::OutOfRange { value, .. }) if value == -1.0
    ));
}

/// Every primitive mesh is closed and oriented: each directed edge appears once and its
/// reverse once (no holes, no flipped triangle), and its signed volume is positive, so the
/// triangles face outwards (counter-clockwise seen from outside). A cuboid's and a wheel's
/// volumes are their solids' (the wheel a prism over its polygon).
#[test]
fn primitive_meshes_are_closed_and_face_outwards() {
    use std::collections::HashMap;
    let signed_volume = |m: &TriMesh| -> f64 {
        let v = m.vertices();
        m.triangles()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| v[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    };
    let n = 12u32;
    let (r, hw) = (0.4f64, 0.15f64);
    let polygon = 0.5 * f64::from(n) * r * r * (std::f64::consts::TAU / f64::from(n)).sin();
    let cases = [
        (
            "cuboid",
            TriMesh::cuboid(Vec3::new(0.5, 0.2, 0.3)).expect("cuboid"),
            Some(8.0 * 0.5 * 0.2 * 0.3),
        ),
        (
            "wheel",
            TriMesh::wheel(r as f32, hw as f32, n).expect("wheel"),
            Some(polygon * 2.0 * hw),
        ),
        ("foot", TriMesh::foot(0.3, 0.12, 0.1).expect("foot"), None),
    ];
    for (name, mesh, volume) in cases {
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        for t in mesh.triangles() {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &count) in &edges {
            assert_eq!(count, 1, "{name}: edge {a}->{b} appears {count} times");
            assert_eq!(
                edges.get(&(b, a)),
                Some(&1),
                "{name}: edge {a}->{b} has no twin"
            );
        }
        let got = signed_volume(&mesh);
        assert!(got > 0.0, "{name}: signed volume {got}");
        if let Some(want) = volume {
            assert!(
                (got - want).abs() < 1e-6 * want,
                "{name}: volume {got}, want {want}"
            );
        }
    }
}

/// One pass of the 3x3 blur spreads a single tilted normal over its eight neighbours with
/// the kernel's weights (4 centre, 2 edge, 1 corner, over 16), renormalised; the rest of
/// the area stays up.
#[test]
fn blurring_spreads_one_normal_with_the_kernels_weights() {
    let tilted = Vec3::new(0.6, 0.8, 0.0);
    let mut g = Grid::new(9, 7, Vec3::Y).expect("grid");
    *g.get_mut(4, 3).expect("inside") = tilted;
    let area = Rect::new(IVec2::new(1, 1), UVec2::new(7, 5));
    blur_normals(&mut g, area, 1).expect("blur");
    for y in 0..7i32 {
        for x in 0..9i32 {
            let (dx, dy) = (x - 4, y - 3);
            let inside = area.contains(IVec2::new(x, y));
            let want = if inside && dx.abs() <= 1 && dy.abs() <= 1 {
                let w = ((2 - dx.abs()) * (2 - dy.abs())) as f32;
                ((16.0 - w) * Vec3::Y + w * tilted).normalize()
            } else {
                Vec3::Y
            };
            let got = g.get(x as u32, y as u32).expect("inside");
            assert!((got - want).length() < 1e-6, "({x}, {y}): {got} vs {want}");
        }
    }
}

/// Both slope methods refuse a penetration grid of another size than the area and an
/// area off the map, naming the sizes, and leave the map as it was.
#[test]
fn slope_evening_refuses_a_wrong_size_or_an_area_off_the_map() {
    let map = flat_map(16, 16, 5 * UNITS, 0.1);
    let area = Rect::new(IVec2::new(2, 2), UVec2::new(8, 8));
    let wrong = Grid::new(7, 8, seed_at(0, 0)).expect("grid");
    let off = Rect::new(IVec2::new(12, 2), UVec2::new(8, 8));
    let pen = Grid::new(8, 8, seed_at(0, 0)).expect("grid");
    type Method = fn(
        &mut FixedPointMap,
        &Grid<Penetration>,
        Rect,
        [u32; 2],
        u32,
        u32,
    ) -> Result<(), GranularError>;
    let methods: [(&str, Method); 2] = [
        ("interleaved", even_out_slopes_interleaved),
        ("scatter", even_out_slopes_scatter),
    ];
    for (name, method) in methods {
        let mut m = map.clone();
        match method(&mut m, &wrong, area, [100, 100], 0, 2) {
            Err(GranularError::SizeMismatch { expected, actual }) => {
                assert_eq!(
                    (expected, actual),
                    (UVec2::new(8, 8), UVec2::new(7, 8)),
                    "{name}"
                );
            }
            other => panic!("{name}: {other:?}"),
        }
        match method(&mut m, &pen, off, [100, 100], 0, 2) {
            Err(GranularError::RegionOutsideMap { rect, map_size }) => {
                assert_eq!((rect, map_size), (off, UVec2::new(16, 16)), "{name}");
            }
            other => panic!("{name}: {other:?}"),
        }
        assert_eq!(m, map, "{name}: the map changed");
    }
}
