//! CDLOD: node bounds against brute force and after deformations, the selection's coverage
//! (every texel drawn exactly once), crack-freeness of the morph at every LOD edge, the
//! screen-space metric, and bad input.

use glam::{IVec2, Mat4, UVec2, Vec2, Vec3};
use proptest::prelude::*;
use std::collections::HashSet;
use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
use terrain_lod::cdlod::{JumpProbes, NodeBounds, morphed_vertex};
use terrain_lod::{
    CdlodConfig, CdlodInstance, CdlodMesh, CdlodTree, CdlodView, Frustum, LodError, LodMetric,
};

const TEXEL: f32 = 0.5;

fn hilly(w: u32, h: u32, wrap: WrapMode) -> HeightMap<u16> {
    let grid = Grid::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32, y as f32);
        let v = (fx * 0.05).sin() * 9000.0
            + (fy * 0.031).cos() * 7000.0
            + (fx * 0.21 + fy * 0.13).sin() * 900.0;
        (30_000.0 + v) as u16
    })
    .unwrap();
    HeightMap::new(grid, HeightEncoding::new(0.001, 0.0).unwrap(), TEXEL, wrap).unwrap()
}

fn config(leaf: u32, grid: u32, lods: u32, range: f32) -> CdlodConfig {
    CdlodConfig {
        leaf_size: leaf,
        grid_size: grid,
        lod_count: lods,
        finest_range: range,
        ..CdlodConfig::default()
    }
}

fn height_fn(map: &HeightMap<u16>) -> impl Fn(IVec2) -> f32 + '_ {
    move |t: IVec2| {
        let (w, h) = (map.size().x, map.size().y);
        let x = map.wrap().resolve(i64::from(t.x), w);
        let y = map.wrap().resolve(i64::from(t.y), h);
        map.height_m(x, y).unwrap()
    }
}

/// Bounds by definition: every texel of the node, far edges included.
fn brute_bounds(map: &HeightMap<u16>, tree: &CdlodTree, lod: u32, node: IVec2) -> (f32, f32) {
    let side = tree.node_size(lod) as i32;
    let h = height_fn(map);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for y in 0..=side {
        for x in 0..=side {
            let v = h(node * side + IVec2::new(x, y));
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    (lo, hi)
}

#[test]
fn node_bounds_hold_every_texel_and_errors_vanish_at_full_resolution() {
    for (w, h, wrap) in [(256, 128, WrapMode::Repeat), (200, 136, WrapMode::Clamp)] {
        let map = hilly(w, h, wrap);
        let tree = CdlodTree::from_map(&map, config(16, 16, 4, 10.0)).unwrap();
        for lod in 0..4 {
            let side = tree.node_size(lod) as u32;
            for y in 0..h.div_ceil(side) as i32 {
                for x in 0..w.div_ceil(side) as i32 {
                    let b = tree.bounds(lod, IVec2::new(x, y)).unwrap();
                    assert_eq!(
                        (b.min, b.max),
                        brute_bounds(&map, &tree, lod, IVec2::new(x, y))
                    );
                    if lod == 0 {
                        assert_eq!(b.error, 0.0, "one vertex per texel: no error");
                    } else {
                        assert!(b.error > 0.0 && b.error <= b.max - b.min);
                    }
                }
            }
        }
        if wrap == WrapMode::Clamp {
            assert_eq!(tree.bounds(0, IVec2::new(-1, 0)), None);
        } else {
            assert_eq!(
                tree.bounds(0, IVec2::new(-1, 0)),
                tree.bounds(0, IVec2::new(15, 0))
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// A deformation anywhere (across the edges of a repeating map) leaves the tree as a
    /// rebuild would: only the touched nodes are recomputed, and they are all of them.
    #[test]
    fn updates_equal_a_rebuild(
        x in -100i32..200, y in -100i32..200, w in 1u32..90, h in 1u32..90,
        repeat in any::<bool>(), raise in 1u16..3000,
    ) {
        let wrap = if repeat { WrapMode::Repeat } else { WrapMode::Clamp };
        let mut map = hilly(128, 64, wrap);
        let cfg = config(8, 8, 4, 5.0);
        let mut tree = CdlodTree::from_map(&map, cfg).unwrap();
        let rect = Rect::new(IVec2::new(x, y), UVec2::new(w, h));
        let size = map.size();
        let pieces: Vec<Rect> = if repeat {
            Rect::new(rect.min, rect.size.min(size)).split_toroidal(size).into_iter().map(|p| p.map).collect()
        } else {
            rect.intersect(&Rect::from_size(size)).into_iter().collect()
        };
        for p in pieces {
            for ty in p.min.y..p.max().y {
                for tx in p.min.x..p.max().x {
                    let v = map.grid_mut().get_mut(tx as u32, ty as u32).unwrap();
                    *v = v.saturating_add(raise);
                }
            }
        }
        tree.update_rect(&map, rect).unwrap();
        prop_assert_eq!(tree, CdlodTree::from_map(&map, cfg).unwrap());
    }

    /// The worker-thread updater, after a flush, holds the tree an update in place gives,
    /// for rects crossing the edges of a repeating map or off a clamped one.
    #[test]
    fn the_background_updater_equals_a_rebuild_after_a_flush(
        x in -100i32..200, y in -100i32..200, w in 1u32..90, h in 1u32..90,
        repeat in any::<bool>(), raise in 1u16..3000,
    ) {
        let wrap = if repeat { WrapMode::Repeat } else { WrapMode::Clamp };
        let mut map = hilly(128, 64, wrap);
        let cfg = config(8, 8, 4, 5.0);
        let mut updater =
            terrain_lod::CdlodUpdater::spawn(CdlodTree::from_map(&map, cfg).unwrap(), &map).unwrap();
        let before = updater.tree().clone();
        let rect = Rect::new(IVec2::new(x, y), UVec2::new(w, h));
        let size = map.size();
        for i in 0..i64::from(w.min(size.x)) {
            for j in 0..i64::from(h.min(size.y)) {
                let (tx, ty) = (i64::from(x) + i, i64::from(y) + j);
                if !repeat && (tx < 0 || ty < 0 || tx >= i64::from(size.x) || ty >= i64::from(size.y)) {
                    continue;
                }
                let (tx, ty) = (wrap.resolve(tx, size.x), wrap.resolve(ty, size.y));
                let v = map.grid_mut().get_mut(tx, ty).unwrap();
                *v = v.saturating_add(raise);
            }
        }
        updater.submit(&map, rect).unwrap();
        // Nothing waited for yet: the frame's tree is still the one it had.
        prop_assert_eq!(&**updater.tree(), &*before);
        updater.flush().unwrap();
        prop_assert_eq!(updater.pending(), 0);
        prop_assert_eq!(&**updater.tree(), &CdlodTree::from_map(&map, cfg).unwrap());
    }
}

fn view(camera: Vec3, look: Vec3, width: f32) -> (Frustum, f32) {
    let hfov = 70f32.to_radians();
    let aspect = 16.0 / 9.0;
    let vfov = 2.0 * ((hfov * 0.5).tan() / aspect).atan();
    let proj = glam::camera::rh::proj::directx::perspective(vfov, aspect, 0.1, 1e5);
    let v: Mat4 = glam::camera::rh::view::look_to_mat4(camera, look.normalize(), Vec3::Y);
    let _ = width;
    (Frustum::from_view_proj(proj * v), hfov)
}

/// The texel rect an instance covers (its vertices' extent).
fn instance_rect(i: &CdlodInstance, half: i32) -> (IVec2, IVec2) {
    let o = IVec2::from(i.origin);
    (o, o + IVec2::splat(half * i.step as i32))
}

#[test]
fn the_selection_draws_every_texel_once() {
    // A clamped map smaller than the view distance: the instances must tile it exactly.
    let map = hilly(256, 256, WrapMode::Clamp);
    let cfg = config(16, 16, 5, 12.0);
    let tree = CdlodTree::from_map(&map, cfg).unwrap();
    let h = height_fn(&map);
    for (x, z) in [(10.0f32, 10.0f32), (64.0, 100.0), (127.9, 0.5)] {
        let ground = h((Vec2::new(x, z) / TEXEL).as_ivec2().min(IVec2::splat(255)));
        let camera = Vec3::new(x, ground + 3.0, z);
        let v = CdlodView {
            camera,
            frustum: None,
            viewport_width: 1280.0,
            hfov: 1.2,
        };
        let frame = tree.select(&v).unwrap();
        let lods: HashSet<u32> = frame.instances.iter().map(|i| i.lod).collect();
        assert!(
            lods.len() >= 3,
            "mixed LODs near the camera: {lods:?}, camera {camera}, ranges {:?}",
            frame.ranges.range
        );
        let mut covered = vec![0u8; 256 * 256];
        for i in &frame.instances {
            let (lo, hi) = instance_rect(i, 8);
            for y in lo.y..hi.y {
                for x in lo.x..hi.x {
                    covered[y as usize * 256 + x as usize] += 1;
                }
            }
        }
        assert!(
            covered.iter().all(|&c| c == 1),
            "every texel cell exactly once"
        );
        let mesh = CdlodMesh::new(cfg.grid_size);
        assert_eq!(frame.vertex_count(&mesh), frame.instances.len() as u64 * 81);
        assert_eq!(
            frame.triangle_count(&mesh),
            frame.instances.len() as u64 * 128
        );
    }
}

/// Every vertex on an edge a finer instance shares with a coarser one lands, morphed, exactly
/// on the coarser instance's vertex there: no crack, no T-junction. Neighbours differ by at most
/// one LOD.
fn assert_crack_free(map: &HeightMap<u16>, tree: &CdlodTree, v: &CdlodView<'_>) -> usize {
    let frame = tree.select(v).unwrap();
    let half = (tree.config().grid_size / 2) as i32;
    let h = height_fn(map);
    let mut checked = 0;
    for f in &frame.instances {
        let (flo, fhi) = instance_rect(f, half);
        for c in frame.instances.iter().filter(|c| c.lod > f.lod) {
            let (clo, chi) = instance_rect(c, half);
            // Do they share a stretch of edge?
            let ov_x = flo.x.max(clo.x) < fhi.x.min(chi.x);
            let ov_y = flo.y.max(clo.y) < fhi.y.min(chi.y);
            let touch_x = fhi.x == clo.x || chi.x == flo.x;
            let touch_y = fhi.y == clo.y || chi.y == flo.y;
            if !((touch_x && ov_y) || (touch_y && ov_x)) {
                continue;
            }
            assert_eq!(
                c.lod,
                f.lod + 1,
                "neighbours {f:?} and {c:?} are two LODs apart"
            );
            for g in 0..=half {
                for gv in [
                    Vec2::new(g as f32, 0.0),
                    Vec2::new(g as f32, half as f32),
                    Vec2::new(0.0, g as f32),
                    Vec2::new(half as f32, g as f32),
                ] {
                    let t = IVec2::from(f.origin) + gv.as_ivec2() * f.step as i32;
                    let on_c = t.cmpge(clo).all()
                        && t.cmple(chi).all()
                        && (t.x == clo.x || t.x == chi.x || t.y == clo.y || t.y == chi.y);
                    if !on_c {
                        continue;
                    }
                    let (tf, hf) = morphed_vertex(f, gv, v.camera, &frame.ranges, TEXEL, &h);
                    let gc = (tf - IVec2::from(c.origin).as_vec2()) / c.step as f32;
                    assert_eq!(
                        gc,
                        gc.round(),
                        "{f:?} vertex {gv} morphs to {tf}, off {c:?}'s grid"
                    );
                    let (tc, hc) = morphed_vertex(c, gc, v.camera, &frame.ranges, TEXEL, &h);
                    assert_eq!((tf, hf), (tc, hc), "crack between {f:?} and {c:?} at {t}");
                    checked += 1;
                }
            }
        }
    }
    checked
}

#[test]
fn lod_edges_are_crack_free_from_every_view() {
    let map = hilly(512, 512, WrapMode::Repeat);
    for (leaf, grid, lods) in [(16, 16, 6), (32, 16, 5), (8, 8, 6)] {
        let tree = CdlodTree::from_map(&map, config(leaf, grid, lods, 6.0)).unwrap();
        let mut checked = 0;
        for k in 0..24 {
            let a = k as f32 * 0.7;
            let camera = Vec3::new(
                100.0 + 40.0 * a.cos(),
                31.0 + 3.0 * (k % 5) as f32,
                90.0 + 37.0 * a.sin(),
            );
            let look = Vec3::new(a.sin(), -0.3 - 0.05 * (k % 3) as f32, a.cos());
            let (frustum, hfov) = view(camera, look, 1280.0);
            let with = CdlodView {
                camera,
                frustum: Some(&frustum),
                viewport_width: 1280.0,
                hfov,
            };
            checked += assert_crack_free(&map, &tree, &with);
            let without = CdlodView {
                frustum: None,
                ..with
            };
            checked += assert_crack_free(&map, &tree, &without);
        }
        assert!(
            checked > 1000,
            "leaf {leaf}: only {checked} LOD-edge vertices seen"
        );
    }
}

#[test]
fn screen_space_error_refines_where_it_matters() {
    // Clamped: the test map is not periodic, and its seam would dominate every node's error.
    let map = hilly(512, 512, WrapMode::Clamp);
    let camera = Vec3::new(128.0, 35.0, 128.0);
    let v = CdlodView {
        camera,
        frustum: None,
        viewport_width: 1280.0,
        hfov: 1.2,
    };
    let mut last = 0usize;
    for tau in [8.0, 4.0, 2.0] {
        let cfg = CdlodConfig {
            metric: LodMetric::ScreenSpace { tau_px: tau },
            ..config(16, 16, 6, 20.0)
        };
        let tree = CdlodTree::from_map(&map, cfg).unwrap();
        let frame = tree.select(&v).unwrap();
        assert!(
            frame.instances.len() >= last,
            "a smaller tau never draws fewer quadrants"
        );
        last = frame.instances.len();
        // Ranges grow with the LOD; each LOD is used where its error is below tau.
        let r = &frame.ranges.range;
        assert!(r.windows(2).all(|w| w[1] > w[0]));
        for lod in 1..6 {
            let view_distance = 20.0 * 2f32.powi(5);
            let wanted = (tree.max_error(lod) * v.k() / tau).min(view_distance);
            assert!(
                r[lod as usize - 1] >= wanted * 0.999,
                "LOD {lod}: {} < {wanted}",
                r[lod as usize - 1]
            );
        }
        let err = tree.max_screen_error_px(&frame, &v);
        let capped = (1..6).any(|l| tree.max_error(l) * v.k() / tau >= 640.0);
        println!(
            "tau {tau}: {} quadrants, drawn error {err:.2} px, ranges capped: {capped}",
            frame.instances.len()
        );
        if !capped {
            assert!(err <= tau * 1.001, "tau {tau}: drawn error {err} px");
        }
        assert!(
            !capped || tau < 8.0,
            "tau 8 must fit the view distance, or the test means little"
        );
        assert_crack_free(&map, &tree, &v);
    }
}

#[test]
fn morph_factors_are_zero_inside_and_one_past_the_range() {
    let map = hilly(256, 256, WrapMode::Repeat);
    let tree = CdlodTree::from_map(&map, config(16, 16, 5, 10.0)).unwrap();
    let v = CdlodView {
        camera: Vec3::new(0.0, 30.0, 0.0),
        frustum: None,
        viewport_width: 800.0,
        hfov: 1.0,
    };
    let r = tree.ranges(&v);
    for lod in 0..4u32 {
        let (start, end) = r.morph[lod as usize];
        assert!(start < end && end == r.range[lod as usize]);
        assert_eq!(r.morph_k(lod, start * 0.99), 0.0);
        assert_eq!(r.morph_k(lod, end), 1.0);
        assert_eq!(r.morph_k(lod, end * 3.0), 1.0);
        let mid = r.morph_k(lod, (start + end) * 0.5);
        assert!((mid - 0.5).abs() < 1e-3);
    }
    // The coarsest LOD has nothing to morph to, and neither does anything with the morph off.
    assert_eq!(r.morph_k(4, 1e9), 0.0);
    let off = CdlodTree::from_map(
        &map,
        CdlodConfig {
            morph: false,
            ..config(16, 16, 5, 10.0)
        },
    )
    .unwrap();
    assert!(off.ranges(&v).morph.iter().all(|m| m.0.is_infinite()));
}

/// A selection stops at its node budget and is an error past it: the visits are counted (the
/// roots, every selected node, and the children that were out of their range), a budget of
/// exactly that many selects the same frame, and any smaller one refuses.
#[test]
fn a_selection_stops_at_its_node_budget() {
    let map = hilly(256, 256, WrapMode::Repeat);
    let view = CdlodView {
        camera: Vec3::new(10.0, 20.0, 10.0),
        frustum: None,
        viewport_width: 100.0,
        hfov: 1.0,
    };
    let tree = CdlodTree::from_map(&map, config(16, 16, 4, 20.0)).unwrap();
    let frame = tree.select(&view).unwrap();
    let visited = frame.visited;
    assert!(visited > frame.nodes.len(), "{visited} visited");
    assert_eq!(tree.select_bounded(&view, visited).unwrap(), frame);
    assert_eq!(tree.select_bounded(&view, usize::MAX).unwrap(), frame);
    for budget in [0, 1, visited / 2, visited - 1] {
        match tree.select_bounded(&view, budget) {
            Err(LodError::SelectionTooLarge { limit }) => assert_eq!(limit, budget),
            other => panic!("budget {budget}: {:?}", other.map(|f| f.visited)),
        }
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let map = hilly(64, 64, WrapMode::Repeat);
    let cases: Vec<(CdlodConfig, &str)> = vec![
        (config(16, 16, 4, 5.0), "lod_count"), // a root of 128 texels does not tile 64
        (config(3, 4, 4, 5.0), "leaf_size"),
        (config(2048, 32, 4, 5.0), "leaf_size"),
        (config(16, 32, 4, 5.0), "grid_size"),
        (config(16, 2, 4, 5.0), "grid_size"),
        (config(16, 16, 0, 5.0), "lod_count"),
        (config(16, 16, 17, 5.0), "lod_count"),
        (config(16, 16, 4, f32::NAN), "finest_range"),
        (config(16, 16, 4, -1.0), "finest_range"),
        (
            CdlodConfig {
                range_ratio: 1.0,
                ..config(16, 16, 4, 5.0)
            },
            "range_ratio",
        ),
        (
            CdlodConfig {
                morph_start_ratio: 1.0,
                ..config(16, 16, 4, 5.0)
            },
            "morph_start_ratio",
        ),
        (
            CdlodConfig {
                metric: LodMetric::ScreenSpace { tau_px: 0.0 },
                ..config(16, 16, 4, 5.0)
            },
            "tau_px",
        ),
    ];
    for (cfg, name) in cases {
        match CdlodTree::from_map(&map, cfg) {
            Err(LodError::InvalidCdlodParam { what, .. }) => assert_eq!(what, name),
            other => panic!("{name}: {other:?}"),
        }
    }
    let tree = CdlodTree::from_map(&map, config(16, 16, 3, 5.0)).unwrap();
    let nan = CdlodView {
        camera: Vec3::new(f32::NAN, 0.0, 0.0),
        frustum: None,
        viewport_width: 100.0,
        hfov: 1.0,
    };
    assert!(matches!(tree.select(&nan), Err(LodError::NonFinite { .. })));
    // Far cameras are answered (repeating map: the roots around it), absurd ones refused.
    let far = CdlodView {
        camera: Vec3::new(1e6, 10.0, -3e5),
        ..nan
    };
    assert!(!tree.select(&far).unwrap().instances.is_empty());
    let absurd = CdlodView {
        camera: Vec3::new(f32::MAX, 10.0, 0.0),
        ..nan
    };
    assert!(matches!(
        tree.select(&absurd),
        Err(LodError::CameraOutOfRange { .. })
    ));
    // A tiny map: one root, drawn whole from above.
    let tiny = hilly(5, 3, WrapMode::Clamp);
    let t = CdlodTree::from_map(&tiny, config(4, 4, 2, 1.0)).unwrap();
    let above = CdlodView {
        camera: Vec3::new(1.0, 40.0, 1.0),
        ..nan
    };
    assert!(!t.select(&above).unwrap().nodes.is_empty());
    assert_eq!(
        t.bounds(0, IVec2::new(1, 0))
            .map(|b: NodeBounds| b.min.is_finite()),
        Some(true)
    );
    let other = hilly(65, 64, WrapMode::Repeat);
    let mut tr = tree.clone();
    assert!(matches!(
        tr.update_rect(&other, Rect::from_size(UVec2::ONE)),
        Err(LodError::SizeMismatch { .. })
    ));
}

#[test]
fn the_drawn_surface_is_the_map_where_fully_refined_and_pops_without_the_morph() {
    let map = hilly(512, 512, WrapMode::Repeat);
    let h = height_fn(&map);
    let grid = 16;
    let jump = |morph: bool| -> f32 {
        let cfg = CdlodConfig {
            morph,
            ..config(16, grid, 6, 6.0)
        };
        let tree = CdlodTree::from_map(&map, cfg).unwrap();
        let mut worst = 0.0f32;
        let mut prev: Option<(terrain_lod::CdlodFrame, Vec3)> = None;
        // A camera moving at 0.1 m per frame (3 m/s at 30 fps), looking along its path: the
        // morph moves vertices in proportion to the camera's motion, a LOD switch all at once.
        for f in 0..150 {
            let xz = Vec2::new(60.0 + 0.1 * f as f32, 80.0);
            // The bilinear ground: a camera height that steps at texel edges would move the
            // morph in steps too.
            let ground = terrain_core::bilinear(&map, xz).unwrap();
            let camera = Vec3::new(xz.x, ground + 4.0, xz.y);
            let look = Vec3::new(1.0, -0.25, 0.1);
            let (frustum, hfov) = view(camera, look, 640.0);
            let v = CdlodView {
                camera,
                frustum: Some(&frustum),
                viewport_width: 640.0,
                hfov,
            };
            let frame = tree.select(&v).unwrap();
            // Every drawn texel of a LOD-0 quadrant far from its morph is the map itself.
            if f == 0 {
                let i = frame.instances.iter().find(|i| i.lod == 0).unwrap();
                let t = IVec2::from(i.origin) + IVec2::new(3, 5);
                let s = frame
                    .surface_height(t.as_vec2(), grid, camera, TEXEL, &h)
                    .unwrap();
                let k = frame.ranges.morph_k(
                    0,
                    Vec3::new(t.x as f32 * TEXEL, h(t), t.y as f32 * TEXEL).distance(camera),
                );
                if k == 0.0 {
                    assert_eq!(s, h(t));
                }
            }
            let proj = glam::camera::rh::proj::directx::perspective(0.9, 16.0 / 9.0, 0.1, 1e5)
                * glam::camera::rh::view::look_to_mat4(camera, look.normalize(), Vec3::Y);
            let probes: Vec<Vec2> = (0..32 * 32)
                .map(|k| {
                    (xz + Vec2::new((k % 32) as f32 * 3.0, ((k / 32) as f32 - 16.0) * 3.0)) / TEXEL
                })
                .collect();
            if let Some((pf, pc)) = &prev {
                let probes = JumpProbes {
                    probes: &probes,
                    view_proj: proj,
                    target: Vec2::new(640.0, 360.0),
                };
                let j = frame.max_height_jump(camera, (pf, *pc), &probes, grid, TEXEL, &h);
                worst = worst.max(j);
            }
            prev = Some((frame, camera));
        }
        worst
    };
    let (with, without) = (jump(true), jump(false));
    println!("largest jump: {with:.3} px with the morph, {without:.3} px without");
    assert!(with < 1.0, "morphing: {with} px");
    assert!(
        without > 2.0 * with.max(0.5),
        "without the morph LOD changes pop: {without} px"
    );
}

/// The range table by its definition: each LOD's range is the range it wants (distance: the
/// finest range times the ratio per LOD; screen space: where LOD `l + 1`'s largest error
/// projects to tau, never below the previous range nor past the view distance, which the
/// last LOD takes) or the morph's floor where that is larger,
/// `range_l >= range_{l-1} + diag_l / morph_start_ratio` with `diag_l` the 3D diagonal of a
/// node of LOD `l` over the map's whole height span; never more than the larger of the two.
#[test]
fn ranges_are_the_wanted_range_or_the_morph_floor() {
    let map = hilly(512, 512, WrapMode::Clamp);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for y in 0..512 {
        for x in 0..512 {
            let h = map.height_m(x, y).unwrap();
            lo = lo.min(h);
            hi = hi.max(h);
        }
    }
    let span = hi - lo;
    let v = CdlodView {
        camera: Vec3::new(128.0, 35.0, 128.0),
        frustum: None,
        viewport_width: 1280.0,
        hfov: 1.2,
    };
    let mut floors_bound = 0;
    for metric in [LodMetric::Distance, LodMetric::ScreenSpace { tau_px: 4.0 }] {
        for (ratio, finest) in [(2.0f32, 20.0f32), (1.5, 2.0)] {
            let cfg = CdlodConfig {
                metric,
                range_ratio: ratio,
                ..config(16, 16, 6, finest)
            };
            let tree = CdlodTree::from_map(&map, cfg).unwrap();
            let r = tree.ranges(&v).range;
            assert_eq!(r.len(), 6);
            let view_distance = finest * ratio.powi(5);
            for l in 0..6 {
                let prev = if l == 0 { 0.0 } else { r[l - 1] };
                let wanted = match metric {
                    LodMetric::Distance => finest * ratio.powi(l as i32),
                    LodMetric::ScreenSpace { .. } if l == 5 => view_distance,
                    LodMetric::ScreenSpace { tau_px } => (tree.max_error(l as u32 + 1) * v.k()
                        / tau_px)
                        .max(prev)
                        .min(view_distance),
                };
                let floor = if l == 0 {
                    0.0
                } else {
                    let side = tree.node_size(l as u32) as f32 * TEXEL;
                    prev + (2.0 * side * side + span * span).sqrt() / cfg.morph_start_ratio
                };
                let what = format!(
                    "{metric:?} ratio {ratio} LOD {l}: {r:?}, wanted {wanted}, floor {floor}"
                );
                assert!(r[l] >= wanted * (1.0 - 1e-6), "{what}");
                assert!(r[l] >= floor * (1.0 - 1e-6), "{what}");
                assert!(
                    r[l] <= wanted.max(floor * 1.0011).max(1e-3) * (1.0 + 1e-6),
                    "{what}"
                );
                if floor > wanted {
                    floors_bound += 1;
                }
            }
        }
    }
    assert!(
        floors_bound > 0,
        "no morph floor bound: the test means little"
    );
}

/// A LOD's largest error is the largest of its nodes' errors (0 past the roots).
#[test]
fn max_error_is_the_largest_node_error() {
    let map = hilly(256, 256, WrapMode::Clamp);
    let tree = CdlodTree::from_map(&map, config(16, 16, 4, 20.0)).unwrap();
    for lod in 0..4 {
        let n = (256 / tree.node_size(lod)) as i32;
        let mut max = 0.0f32;
        for y in 0..n {
            for x in 0..n {
                max = max.max(tree.bounds(lod, IVec2::new(x, y)).unwrap().error);
            }
        }
        assert_eq!(tree.max_error(lod), max, "LOD {lod}");
        assert!(
            lod == 0 || max > 0.0,
            "LOD {lod} of a hilly map has no error"
        );
    }
    assert_eq!(tree.max_error(4), 0.0);
    assert_eq!(tree.max_error(u32::MAX), 0.0);
}

/// A repeating map's roots repeat around the camera for at most 64 root sizes a side (a view
/// distance of 32 roots): exactly 64 is answered, 65 is refused.
#[test]
fn a_repeating_map_repeats_its_roots_64_times_a_side_at_most() {
    let map = hilly(64, 64, WrapMode::Repeat);
    // Roots of 8 texels (4 m); a view distance of 128 m (32 roots) or 129 m.
    let tree = |finest: f32| CdlodTree::from_map(&map, config(4, 4, 2, finest)).unwrap();
    let at = |x: f32| CdlodView {
        camera: Vec3::new(x, 40.0, 1.0),
        frustum: None,
        viewport_width: 100.0,
        hfov: 1.0,
    };
    let exact = tree(64.0);
    assert_eq!(exact.ranges(&at(0.0)).range[1], 128.0);
    for x in [0.0, 1.0, 2.0, 3.5, -7.0] {
        // floor((x + 128) / 4) - floor((x - 128) / 4) = 64 for every x.
        assert!(exact.select(&at(x)).is_ok(), "x {x}");
    }
    let wider = tree(64.5);
    assert_eq!(wider.ranges(&at(0.0)).range[1], 129.0);
    // x = 0: floor(32.25) - floor(-32.25) = 65 copies; x = 2: floor(32.75) - floor(-31.75) = 64.
    assert!(matches!(
        wider.select(&at(0.0)),
        Err(LodError::CameraOutOfRange { .. })
    ));
    assert!(wider.select(&at(2.0)).is_ok());
}

/// A budget of exactly the visits a selection makes selects the same frame when the last
/// node visited is drawn (a clamped map seen from over its far corner).
#[test]
fn a_budget_of_exactly_the_visits_keeps_the_last_node() {
    let map = hilly(256, 256, WrapMode::Clamp);
    let tree = CdlodTree::from_map(&map, config(16, 16, 4, 20.0)).unwrap();
    for camera in [Vec3::new(127.0, 30.0, 127.0), Vec3::new(100.0, 25.0, 120.0)] {
        let view = CdlodView {
            camera,
            frustum: None,
            viewport_width: 100.0,
            hfov: 1.0,
        };
        let frame = tree.select(&view).unwrap();
        assert_eq!(tree.select_bounded(&view, frame.visited).unwrap(), frame);
    }
}

/// The frame's screen error by its definition: per drawn quadrant its node's error over the
/// nearest distance from the camera to the quadrant's box (its child node's height bounds),
/// times K.
#[test]
fn the_screen_error_is_the_worst_quadrant_error_over_its_distance() {
    let map = hilly(512, 512, WrapMode::Clamp);
    let tree = CdlodTree::from_map(&map, config(16, 16, 5, 15.0)).unwrap();
    for camera in [
        Vec3::new(60.0, 32.0, 70.0),
        Vec3::new(200.0, 60.0, 10.0),
        Vec3::new(3.0, 28.0, 250.0),
    ] {
        let v = CdlodView {
            camera,
            frustum: None,
            viewport_width: 1280.0,
            hfov: 1.2,
        };
        let frame = tree.select(&v).unwrap();
        let mut want = 0.0f32;
        for i in &frame.instances {
            let o = IVec2::from(i.origin);
            let side = 8 * i.step as i32;
            let node = o.div_euclid(IVec2::splat(tree.node_size(i.lod) as i32));
            let error = tree.bounds(i.lod, node).unwrap().error;
            let child = if i.lod == 0 {
                tree.bounds(0, node)
            } else {
                tree.bounds(i.lod - 1, o.div_euclid(IVec2::splat(side)))
            }
            .unwrap();
            // The nearest point of the box, per axis.
            let near = |c: f32, a: f32, b: f32| c.clamp(a, b);
            let (x0, z0) = (o.x as f32 * TEXEL, o.y as f32 * TEXEL);
            let (x1, z1) = (x0 + side as f32 * TEXEL, z0 + side as f32 * TEXEL);
            let p = Vec3::new(
                near(camera.x, x0, x1),
                near(camera.y, child.min, child.max),
                near(camera.z, z0, z1),
            );
            want = want.max(error * v.k() / p.distance(camera).max(1e-3));
        }
        let got = tree.max_screen_error_px(&frame, &v);
        assert!(want > 0.0);
        assert!((got - want).abs() <= 1e-5 * want, "{got} vs {want}");
    }
}
