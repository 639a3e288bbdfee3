//! Geometry clipmap placement: exact tiling, nesting, T-junction closure, trim alternation and
//! frustum culling, checked on the texel-space triangles the draws produce.

use glam::camera::rh::{proj::directx, view::look_to_mat4};
use glam::{DVec2, I64Vec2, Vec2, Vec3};
use proptest::prelude::*;
use std::collections::{HashMap, HashSet};
use terrain_lod::{
    ClipmapDraw, ClipmapFrame, ClipmapLayout, Frustum, LodError, PartKind, TrimSide,
};

type Tri = [I64Vec2; 3];

/// Twice the signed area of `(a, b, c)` in the (x, z) plane.
fn cross(a: I64Vec2, b: I64Vec2, c: I64Vec2) -> i64 {
    let e1 = b - a;
    let e2 = c - a;
    e1.x * e2.y - e1.y * e2.x
}

fn draw_tris<'a>(
    layout: &'a ClipmapLayout,
    frame: &'a ClipmapFrame,
    keep: impl Fn(&ClipmapDraw) -> bool + 'a,
) -> impl Iterator<Item = Tri> + 'a {
    frame
        .draws
        .iter()
        .filter(move |d| keep(d))
        .flat_map(|d| layout.mesh().draw_triangles(d))
}

fn level_side(layout: &ClipmapLayout, level: u32) -> i64 {
    layout.level_side_texels(level) as i64
}

/// The non-degenerate triangles of all draws tile the coarsest level's square exactly: total
/// area, and every sample point at a non-lattice position covered exactly once. Integer
/// arithmetic throughout (samples at (x + 0.37, z + 0.59), coordinates scaled by 100).
fn assert_tiles_coarsest_square(layout: &ClipmapLayout, frame: &ClipmapFrame) {
    let coarsest = frame.levels.last().unwrap();
    let side = level_side(layout, coarsest.level);
    let origin = coarsest.origin.as_i64vec2();
    let mut counts = vec![0u8; (side * side) as usize];
    let mut twice_area: i64 = 0;
    let mut triangles = 0u64;
    for tri in draw_tris(layout, frame, |d| d.part != PartKind::Degenerates) {
        let t = tri.map(|p| p - origin);
        let c = cross(t[0], t[1], t[2]);
        assert!(
            c != 0,
            "degenerate triangle outside the degenerate parts: {tri:?}"
        );
        twice_area += c.abs();
        triangles += 1;
        let lo = t[0].min(t[1]).min(t[2]);
        let hi = t[0].max(t[1]).max(t[2]);
        assert!(
            lo.cmpge(I64Vec2::ZERO).all() && hi.cmple(I64Vec2::splat(side)).all(),
            "triangle {tri:?} outside the coarsest square"
        );
        let s = t.map(|v| v * 100);
        for z in lo.y..hi.y {
            for x in lo.x..hi.x {
                let p = I64Vec2::new(100 * x + 37, 100 * z + 59);
                let d = [
                    cross(s[0], s[1], p),
                    cross(s[1], s[2], p),
                    cross(s[2], s[0], p),
                ];
                assert!(
                    d.iter().all(|&d| d != 0),
                    "sample {p} on an edge of {tri:?}"
                );
                if d.iter().all(|&d| d > 0) || d.iter().all(|&d| d < 0) {
                    counts[(z * side + x) as usize] += 1;
                }
            }
        }
    }
    assert_eq!(twice_area, 2 * side * side, "total area");
    assert_eq!(triangles, frame.triangle_count(layout.mesh()));
    for (i, &count) in counts.iter().enumerate() {
        let at = origin + I64Vec2::new(i as i64 % side, i as i64 / side);
        assert_eq!(count, 1, "texel {at} (+0.37, +0.59) covered {count} times");
    }
}

/// Origins snap to the next coarser grid; each level lies in the next one's hole with a gap of
/// exactly one coarse quad on one side per axis, which is the side the trim covers; the
/// camera is within one texel of the finest level's centre.
fn assert_nested(layout: &ClipmapLayout, frame: &ClipmapFrame, camera_texel: DVec2) {
    let m = i64::from(layout.m());
    assert_eq!(frame.levels.len(), layout.levels() as usize);
    for (l, level) in frame.levels.iter().enumerate() {
        assert_eq!(level.level as usize, l);
        assert_eq!(level.scale, 1 << l);
        let snap = 2i32 << l;
        assert_eq!(level.origin % snap, glam::IVec2::ZERO, "{level:?}");
        assert_eq!(level.trim.is_none(), l == 0);
    }
    let finest = &frame.levels[0];
    let centre = finest.origin.as_dvec2() + DVec2::splat(level_side(layout, 0) as f64 / 2.0);
    assert!((centre - camera_texel).abs().max_element() <= 1.0 + 1e-6);
    for pair in frame.levels.windows(2) {
        let (fine, coarse) = (&pair[0], &pair[1]);
        let s = i64::from(coarse.scale);
        let hole_lo = coarse.origin.as_i64vec2() + I64Vec2::splat((m - 1) * s);
        let hole_hi = coarse.origin.as_i64vec2() + I64Vec2::splat((3 * m - 1) * s);
        let fine_lo = fine.origin.as_i64vec2();
        let fine_hi = fine_lo + I64Vec2::splat(level_side(layout, fine.level));
        assert!(fine_lo.cmpge(hole_lo).all() && fine_hi.cmple(hole_hi).all());
        let gap_lo = fine_lo - hole_lo;
        let gap_hi = hole_hi - fine_hi;
        assert_eq!(
            gap_lo + gap_hi,
            I64Vec2::splat(s),
            "one coarse quad of trim per axis"
        );
        let trim = coarse.trim.unwrap();
        assert_eq!(trim.covers_min_x(), gap_lo.x == s, "{trim:?}");
        assert_eq!(trim.covers_min_z(), gap_lo.y == s, "{trim:?}");
        // The trim draw sits at the hole's min corner.
        let trim_draw = frame
            .draws
            .iter()
            .find(|d| d.part == PartKind::Trim(trim) && d.instance.level == coarse.level)
            .unwrap();
        assert_eq!(trim_draw.instance.offset, hole_lo.as_ivec2().to_array());
    }
}

fn boundary_of(lo: I64Vec2, hi: I64Vec2) -> impl Fn(I64Vec2) -> bool {
    move |p: I64Vec2| {
        let in_x = (lo.x..=hi.x).contains(&p.x);
        let in_z = (lo.y..=hi.y).contains(&p.y);
        ((p.x == lo.x || p.x == hi.x) && in_z) || ((p.y == lo.y || p.y == hi.y) && in_x)
    }
}

fn edge(a: I64Vec2, b: I64Vec2) -> (I64Vec2, I64Vec2) {
    if (a.x, a.y) <= (b.x, b.y) {
        (a, b)
    } else {
        (b, a)
    }
}

/// The T-junction rule between adjacent levels: every vertex of the finer level's outer
/// boundary coincides with a vertex of the coarser level's inner boundary, or is the middle
/// vertex of a degenerate triangle whose other two vertices are consecutive vertices of that
/// inner boundary (joined by an edge of a coarse triangle).
fn assert_level_seams_closed(layout: &ClipmapLayout, frame: &ClipmapFrame) {
    let n = i64::from(layout.n());
    for pair in frame.levels.windows(2) {
        let (fine, coarse) = (pair[0], pair[1]);
        let lo = fine.origin.as_i64vec2();
        let hi = lo + I64Vec2::splat(level_side(layout, fine.level));
        let on_boundary = boundary_of(lo, hi);
        let solid = |level: u32| {
            draw_tris(layout, frame, move |d| {
                d.instance.level == level && d.part != PartKind::Degenerates
            })
        };
        let fine_vertices: HashSet<I64Vec2> = solid(fine.level)
            .flatten()
            .filter(|&p| on_boundary(p))
            .collect();
        let coarse_vertices: HashSet<I64Vec2> = solid(coarse.level)
            .flatten()
            .filter(|&p| on_boundary(p))
            .collect();
        let coarse_edges: HashSet<_> = solid(coarse.level)
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .filter(|&(a, b)| on_boundary(a) && on_boundary(b))
            .map(|(a, b)| edge(a, b))
            .collect();
        let degenerates: Vec<Tri> = draw_tris(layout, frame, |d| {
            d.instance.level == fine.level && d.part == PartKind::Degenerates
        })
        .collect();
        assert_eq!(
            fine_vertices.len() as i64,
            4 * (n - 1),
            "fine boundary complete"
        );
        assert_eq!(
            coarse_vertices.len() as i64,
            4 * (n - 1) / 2,
            "coarse inner boundary"
        );
        for &v in &fine_vertices {
            if coarse_vertices.contains(&v) {
                continue;
            }
            let closed = degenerates.iter().any(|t| {
                t[1] == v
                    && t[0] + t[2] == v * 2
                    && coarse_vertices.contains(&t[0])
                    && coarse_vertices.contains(&t[2])
                    && (t[0] - t[2]).abs().max_element() == i64::from(coarse.scale)
                    && coarse_edges.contains(&edge(t[0], t[2]))
            });
            assert!(
                closed,
                "T-junction at {v} between levels {} and {}",
                fine.level, coarse.level
            );
        }
        for v in &coarse_vertices {
            assert!(
                fine_vertices.contains(v),
                "coarse vertex {v} not on the fine boundary"
            );
        }
    }
}

/// Anywhere in the frame: a vertex lying strictly inside an edge of a drawn triangle is the
/// middle vertex of a degenerate triangle spanning exactly that edge.
fn assert_no_open_t_junctions(layout: &ClipmapLayout, frame: &ClipmapFrame) {
    let solid: Vec<Tri> = draw_tris(layout, frame, |d| d.part != PartKind::Degenerates).collect();
    let vertices: HashSet<I64Vec2> = solid.iter().flatten().copied().collect();
    let mut closures: HashMap<(I64Vec2, I64Vec2), Vec<I64Vec2>> = HashMap::new();
    for t in draw_tris(layout, frame, |d| d.part == PartKind::Degenerates) {
        assert_eq!(
            cross(t[0], t[1], t[2]),
            0,
            "degenerate part with area: {t:?}"
        );
        closures.entry(edge(t[0], t[2])).or_default().push(t[1]);
    }
    for t in &solid {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let d = b - a;
            let steps = gcd(d.x.abs(), d.y.abs());
            let step = d / steps;
            for k in 1..steps {
                let p = a + step * k;
                if vertices.contains(&p) {
                    let closed = closures
                        .get(&edge(a, b))
                        .is_some_and(|mid| mid.contains(&p));
                    assert!(closed, "open T-junction: {p} inside edge {a} - {b}");
                }
            }
        }
    }
}

fn gcd(a: i64, b: i64) -> i64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

fn camera_texel(camera: Vec2, texel_size: f32) -> DVec2 {
    camera.as_dvec2() / f64::from(texel_size)
}

#[test]
fn vertex_count_is_eq_3_1() {
    for levels in 1..=11 {
        let layout = ClipmapLayout::new(255, levels).unwrap();
        assert_eq!(layout.vertex_count(), 71_418);
        assert_eq!(layout.mesh().vertices.len(), 71_418);
    }
    for n in [7u32, 15, 31, 63, 127, 255] {
        let m = (n + 1) / 4;
        let layout = ClipmapLayout::new(n, 4).unwrap();
        assert_eq!(
            layout.mesh().vertices.len(),
            (m * m + 12 * m + n * n + 6 * n - 1) as usize
        );
    }
    for n in [0, 8, 16, 2047, 3] {
        assert_eq!(
            ClipmapLayout::new(n, 4).unwrap_err(),
            LodError::InvalidClipmapSize { n }
        );
    }
    for levels in [0, 17] {
        assert_eq!(
            ClipmapLayout::new(31, levels).unwrap_err(),
            LodError::InvalidLevelCount { levels }
        );
    }
}

const CAMERAS: [(f32, f32); 6] = [
    (0.0, 0.0),
    (12.3, -7.9),
    (-1000.5, 333.3),
    (0.49, 1.51),
    (-3.0, -3.0),
    (98_765.4, -43_210.9),
];

#[test]
fn draws_tile_the_coarsest_square_exactly() {
    for (n, levels) in [(7, 3), (7, 6), (15, 1), (15, 4), (15, 5), (31, 3), (31, 6)] {
        let layout = ClipmapLayout::new(n, levels).unwrap();
        for (i, &(x, z)) in CAMERAS.iter().enumerate() {
            let texel_size = [1.0, 0.1, 0.37][i % 3];
            let frame = layout
                .place(Vec2::new(x, z), texel_size, (0.0, 10.0), None)
                .unwrap();
            assert_tiles_coarsest_square(&layout, &frame);
        }
    }
}

#[test]
fn levels_nest_and_seams_are_closed() {
    for (n, levels) in [(7, 5), (15, 4), (31, 6), (63, 3)] {
        let layout = ClipmapLayout::new(n, levels).unwrap();
        for &(x, z) in &CAMERAS {
            let camera = Vec2::new(x, z);
            let frame = layout.place(camera, 0.25, (0.0, 10.0), None).unwrap();
            assert_nested(&layout, &frame, camera_texel(camera, 0.25));
            assert_level_seams_closed(&layout, &frame);
            assert_no_open_t_junctions(&layout, &frame);
        }
    }
}

#[test]
fn trim_side_follows_the_camera() {
    // Moving the camera by 2^(l+1) texels moves level l by one quad of level l + 1, which
    // flips the side of level l + 1's trim on that axis.
    let layout = ClipmapLayout::new(15, 4).unwrap();
    let base = Vec2::new(0.5, 0.5);
    for l in 0..3 {
        let step = (2u32 << l) as f32;
        let mut seen = HashSet::new();
        for (dx, dz) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let camera = base + Vec2::new(dx, dz) * step;
            let frame = layout.place(camera, 1.0, (0.0, 1.0), None).unwrap();
            seen.insert(frame.levels[l + 1].trim.unwrap());
        }
        assert_eq!(seen.len(), 4, "level {}", l + 1);
    }
}

fn look_along_x(eye: Vec3) -> Frustum {
    let view = look_to_mat4(eye, Vec3::X, Vec3::Y);
    let proj = directx::perspective(70f32.to_radians(), 1.5, 0.5, 20_000.0);
    Frustum::from_view_proj(proj * view)
}

/// World box of a draw: x / z from its triangles, y from the height range.
fn world_box(layout: &ClipmapLayout, draw: &ClipmapDraw, ts: f32, h: (f32, f32)) -> (Vec3, Vec3) {
    let mut lo = I64Vec2::MAX;
    let mut hi = I64Vec2::MIN;
    for p in layout.mesh().draw_triangles(draw).flatten() {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let ts = f64::from(ts);
    let (lo, hi) = (lo.as_dvec2() * ts, hi.as_dvec2() * ts);
    (
        Vec3::new(lo.x as f32, h.0, lo.y as f32),
        Vec3::new(hi.x as f32, h.1, hi.y as f32),
    )
}

/// Brute force: a corner of the box or one of a lattice of points in it is in the frustum.
fn brute_force_visible(frustum: &Frustum, lo: Vec3, hi: Vec3) -> bool {
    const K: usize = 12;
    (0..=K).any(|i| {
        (0..=K).any(|j| {
            (0..=K).any(|k| {
                let t = Vec3::new(i as f32, j as f32, k as f32) / K as f32;
                frustum.contains_point(lo + (hi - lo) * t)
            })
        })
    })
}

fn draw_key(d: &ClipmapDraw) -> (PartKind, [i32; 2], u32) {
    (d.part, d.instance.offset, d.instance.level)
}

#[test]
fn frustum_culls_blocks_behind_and_keeps_visible_ones() {
    let layout = ClipmapLayout::new(31, 5).unwrap();
    let texel_size = 0.5;
    let heights = (-5.0, 30.0);
    for &(x, z) in &CAMERAS[..5] {
        let camera = Vec2::new(x, z);
        let eye = Vec3::new(camera.x, 20.0, camera.y);
        let frustum = look_along_x(eye);
        let all = layout.place(camera, texel_size, heights, None).unwrap();
        let kept = layout
            .place(camera, texel_size, heights, Some(&frustum))
            .unwrap();
        assert_eq!(all.culled, 0);
        assert_eq!(all.levels, kept.levels);
        assert_eq!(kept.culled as usize, all.draws.len() - kept.draws.len());
        let kept_keys: HashSet<_> = kept.draws.iter().map(draw_key).collect();
        let mut behind = 0;
        let mut visible = 0;
        for draw in &all.draws {
            let is_kept = kept_keys.contains(&draw_key(draw));
            if !draw.part.is_cullable() {
                assert!(is_kept, "{draw:?} must never be culled");
                continue;
            }
            let (lo, hi) = world_box(&layout, draw, texel_size, heights);
            if brute_force_visible(&frustum, lo, hi) {
                visible += 1;
                assert!(is_kept, "visible {:?} at {lo}..{hi} was culled", draw.part);
            }
            if hi.x < eye.x {
                behind += 1;
                assert!(
                    !is_kept,
                    "{:?} at {lo}..{hi} is behind the camera",
                    draw.part
                );
            }
        }
        assert!(
            behind >= 4 * 4,
            "the test needs blocks behind the camera: {behind}"
        );
        assert!(visible > 0);
        assert!(kept.culled >= behind);
        assert!(kept.triangle_count(layout.mesh()) < all.triangle_count(layout.mesh()));
    }
}

#[test]
fn finest_level_and_trims_survive_a_frustum_that_sees_nothing() {
    let layout = ClipmapLayout::new(15, 4).unwrap();
    // Looking straight up from far above the terrain: no block is in view.
    let eye = Vec3::new(0.0, 10_000.0, 0.0);
    let view = look_to_mat4(eye, Vec3::Y, Vec3::X);
    let proj = directx::perspective(30f32.to_radians(), 1.0, 1.0, 100.0);
    let frustum = Frustum::from_view_proj(proj * view);
    let frame = layout
        .place(Vec2::ZERO, 1.0, (0.0, 100.0), Some(&frustum))
        .unwrap();
    assert_eq!(frame.culled, 3 * (12 + 2));
    let kinds: Vec<PartKind> = frame.draws.iter().map(|d| d.part).collect();
    assert_eq!(
        kinds.iter().filter(|k| **k == PartKind::InnerGrid).count(),
        1
    );
    assert_eq!(
        kinds
            .iter()
            .filter(|k| matches!(k, PartKind::Trim(_)))
            .count(),
        3
    );
    assert_eq!(
        kinds
            .iter()
            .filter(|k| **k == PartKind::Degenerates)
            .count(),
        4
    );
    assert!(!kinds.iter().any(|k| k.is_cullable()));
}

#[test]
fn bad_placement_input_is_an_error() {
    let layout = ClipmapLayout::new(15, 3).unwrap();
    let h = (0.0, 1.0);
    assert!(matches!(
        layout.place(Vec2::new(f32::NAN, 1.0), 1.0, h, None),
        Err(LodError::NonFinite { .. })
    ));
    assert!(matches!(
        layout.place(Vec2::new(1.0, f32::NAN), 1.0, h, None),
        Err(LodError::NonFinite { .. })
    ));
    for ts in [0.0, -0.5] {
        assert_eq!(
            layout.place(Vec2::ZERO, ts, h, None),
            Err(LodError::InvalidTexelSize { texel_size: ts })
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// No T-junctions, exact nesting and exact tiling for random cameras and texel sizes.
    #[test]
    fn random_placements_are_watertight(
        x in -50_000.0f32..50_000.0,
        z in -50_000.0f32..50_000.0,
        texel_size in 0.01f32..4.0,
        n in prop::sample::select(vec![7u32, 15, 31]),
        levels in 2u32..=5,
    ) {
        let layout = ClipmapLayout::new(n, levels).unwrap();
        let camera = Vec2::new(x, z);
        let frame = layout.place(camera, texel_size, (0.0, 1.0), None).unwrap();
        assert_nested(&layout, &frame, camera_texel(camera, texel_size));
        assert_level_seams_closed(&layout, &frame);
        assert_no_open_t_junctions(&layout, &frame);
        assert_tiles_coarsest_square(&layout, &frame);
    }

    /// From any camera, the four cameras one level-(l+1) quad apart on each axis see all four
    /// trim orientations at level l + 1.
    #[test]
    fn every_trim_side_is_hit(
        cell in (-100_000i32..100_000, -100_000i32..100_000),
        frac in (1u8..8, 1u8..8),
        texel_size in prop::sample::select(vec![0.25f32, 0.5, 1.0, 2.0]),
        levels in 2u32..=6,
    ) {
        let layout = ClipmapLayout::new(15, levels).unwrap();
        let texel = Vec2::new(
            cell.0 as f32 + f32::from(frac.0) / 8.0,
            cell.1 as f32 + f32::from(frac.1) / 8.0,
        );
        for l in 0..levels - 1 {
            let step = (2u32 << l) as f32;
            let mut seen = HashSet::new();
            for (dx, dz) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                let camera = (texel + Vec2::new(dx, dz) * step) * texel_size;
                let frame = layout.place(camera, texel_size, (0.0, 1.0), None).unwrap();
                seen.insert(frame.levels[l as usize + 1].trim.unwrap());
            }
            prop_assert_eq!(seen.len(), 4);
        }
    }

    /// Over a batch of random camera positions every trim orientation occurs at every ring.
    #[test]
    fn random_cameras_hit_every_trim_side(
        cameras in prop::collection::vec((-1e4f32..1e4, -1e4f32..1e4), 256),
    ) {
        let layout = ClipmapLayout::new(31, 4).unwrap();
        let mut seen = vec![HashSet::new(); 4];
        for (x, z) in cameras {
            let frame = layout.place(Vec2::new(x, z), 0.1, (0.0, 1.0), None).unwrap();
            for level in &frame.levels[1..] {
                seen[level.level as usize].insert(level.trim.unwrap());
            }
        }
        for sides in &seen[1..] {
            prop_assert_eq!(sides.len(), TrimSide::ALL.len());
        }
    }
}
