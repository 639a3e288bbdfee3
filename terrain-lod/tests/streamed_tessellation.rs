//! Adaptive tessellation of a streamed world (`StreamedTessellation`): decided from a streamed
//! CDLOD tree's node bounds, the mesh is conforming from every view and after deformation,
//! splits near the camera and where the world rises towards it, matches the hierarchy's on a
//! flat map,
//! draws the heights it is given, and refuses bad trees, views and budgets.

mod common;

use terrain_test_support::heights::exact_bounds;

use common::{area, assert_conforming, view};
use glam::camera::rh::{proj::directx, view::look_at_mat4};
use glam::{IVec2, UVec2, Vec3};
use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
use terrain_lod::{
    CdlodConfig, CdlodTree, CdlodView, Frustum, LodError, StreamedTessellation, TessConfig,
    TessHierarchy,
};

const TS: f32 = 0.5;

/// Hills on the left half (0 to about 60 m), a plane rising gently on the right.
fn map(w: u32, h: u32, hills: bool) -> HeightMap<u16> {
    let grid = Grid::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32, y as f32);
        let bumps = if hills && x < w / 2 {
            8_000.0 * ((fx * 0.11).sin() * (fy * 0.07).cos() + 0.4 * (fx * 0.31 + fy * 0.23).sin())
        } else {
            0.0
        };
        let slope = if hills { 10.0 * fy } else { 0.0 };
        (30_000.0 + bumps + slope) as u16
    })
    .unwrap();
    HeightMap::new(
        grid,
        HeightEncoding::new(0.001, 0.0).unwrap(),
        TS,
        WrapMode::Clamp,
    )
    .unwrap()
}

fn tree_config() -> CdlodConfig {
    CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 5,
        ..CdlodConfig::default()
    }
}

/// The streamed tree of `m`, its leaves bounded exactly (as resident tiles give them).
fn tree(m: &HeightMap<u16>) -> CdlodTree {
    CdlodTree::from_leaf_bounds(tree_config(), m.size(), m.texel_size(), exact_bounds(m)).unwrap()
}

/// The map's height at a texel, clamped at its edges (as the GPU's atlas addresses it).
fn heights(m: &HeightMap<u16>) -> impl Fn(IVec2) -> f32 + Sync + '_ {
    move |t: IVec2| {
        let c = t.clamp(IVec2::ZERO, m.size().as_ivec2() - 1);
        m.encoding()
            .to_metres(f64::from(m.grid().get_wrapped(c, WrapMode::Clamp)))
    }
}

#[test]
fn the_mesh_is_conforming_and_covers_the_patches_from_every_view() {
    let m = map(256, 192, true);
    let t = tree(&m);
    let h = heights(&m);
    for (morph, patch_size) in [(true, 32), (false, 32), (true, 64)] {
        let config = TessConfig {
            morph,
            patch_size,
            triangle_width_px: 6.0,
            ..TessConfig::default()
        };
        let tess = StreamedTessellation::new(config, &t).unwrap();
        let extent = tess.patches() * config.patch_size;
        for camera in [
            Vec3::new(10.0, 31.0, 10.0),
            Vec3::new(64.0, 45.0, 48.0),
            Vec3::new(120.0, 80.0, 90.0),
            Vec3::new(-50.0, 200.0, 300.0),
            Vec3::new(127.5, 30.5, 95.5),
        ] {
            let frame = tess.select(&t, &view(camera), &h).unwrap();
            assert_conforming(&frame, extent);
            let expected = f64::from(extent.x) * f64::from(extent.y);
            assert!((area(&frame) - expected).abs() < 1e-6 * expected);
            assert!(frame.triangle_count() > 2 * u64::from(tess.patches().element_product()));
            if !morph {
                for v in frame.triangles.iter().flatten() {
                    let p = IVec2::new(v.texel[0] as i32, v.texel[1] as i32);
                    assert_eq!(v.height, h(p), "vertex {p} draws the height it was given");
                }
            }
        }
    }
}

/// On a flat map the boxes' distances are about the hierarchy's spheres': the same
/// triangle sizes at the same distances, to within a percent of the count.
#[test]
fn on_a_flat_map_the_triangles_are_about_the_hierarchys() {
    let m = map(513, 513, false);
    let t = tree(&m);
    let config = TessConfig {
        use_density: false,
        ..TessConfig::default()
    };
    let streamed = StreamedTessellation::new(config, &t).unwrap();
    let hierarchy = TessHierarchy::from_map(&m, None, config).unwrap();
    for camera in [Vec3::new(40.0, 33.0, 70.0), Vec3::new(100.0, 60.0, 20.0)] {
        let a = streamed.select(&t, &view(camera), &heights(&m)).unwrap();
        let b = hierarchy.select(&view(camera)).unwrap();
        let (a, b) = (a.triangle_count() as f64, b.triangle_count() as f64);
        assert!((a - b).abs() < 0.01 * b, "camera {camera}: {a} against {b}");
    }
}

/// A block raised towards the camera above it (as a deformation, the tree updated over it) is
/// nearer: its triangles split further, and the mesh stays conforming.
#[test]
fn ground_raised_towards_the_camera_splits_further() {
    let mut m = map(512, 512, false);
    let mut t = tree(&m);
    let config = TessConfig {
        triangle_width_px: 32.0,
        ..TessConfig::default()
    };
    let tess = StreamedTessellation::new(config, &t).unwrap();
    // 45 m above the block's 20 m square, 10 m once it is raised.
    let camera = Vec3::new(58.0, 75.0, 118.0);
    let block = Rect::new(IVec2::new(96, 216), UVec2::new(40, 40));
    let count = |t: &CdlodTree, m: &HeightMap<u16>| {
        let frame = tess.select(t, &view(camera), &heights(m)).unwrap();
        let inside = frame
            .triangles
            .iter()
            .filter(|tri| {
                block.contains(IVec2::new(tri[2].texel[0] as i32, tri[2].texel[1] as i32))
            })
            .count();
        (inside, frame)
    };
    let (before, _) = count(&t, &m);
    for y in 216..256 {
        for x in 96..136 {
            *m.grid_mut().get_mut(x, y).unwrap() = 65_000;
        }
    }
    t.update_leaf_bounds(block, exact_bounds(&m)).unwrap();
    let (after, frame) = count(&t, &m);
    assert!(
        after > before,
        "raised by 35 m: {after} triangles, {before} before"
    );
    assert_conforming(&frame, tess.patches() * 32);
}

#[test]
fn culling_drops_what_the_frustum_misses() {
    let m = map(256, 192, true);
    let t = tree(&m);
    let tess = StreamedTessellation::new(TessConfig::default(), &t).unwrap();
    let eye = Vec3::new(10.0, 60.0, 10.0);
    let proj = directx::perspective(1.0, 16.0 / 9.0, 0.1, 1000.0);
    let look = look_at_mat4(eye, Vec3::new(40.0, 30.0, 40.0), Vec3::Y);
    let frustum = Frustum::from_view_proj(proj * look);
    let culled_view = CdlodView {
        frustum: Some(&frustum),
        ..view(eye)
    };
    let all = tess.select(&t, &view(eye), &heights(&m)).unwrap();
    let seen = tess.select(&t, &culled_view, &heights(&m)).unwrap();
    assert!(seen.culled > 0 && seen.triangle_count() < all.triangle_count());
    assert!(seen.triangle_count() > 0);
}

#[test]
fn bad_trees_views_and_budgets_are_refused() {
    let m = map(256, 192, true);
    let t = tree(&m);
    let h = heights(&m);
    let error_metric = TessConfig {
        max_error_px: Some(1.0),
        ..TessConfig::default()
    };
    assert!(StreamedTessellation::new(error_metric, &t).is_err());
    // A tree of the map (not streamed) is the hierarchy's business.
    let from_map = CdlodTree::from_map(&m, tree_config()).unwrap();
    assert!(StreamedTessellation::new(TessConfig::default(), &from_map).is_err());
    // Patches whose first split looks past the tree's roots (256 texels).
    let big = TessConfig {
        patch_size: 128,
        ..TessConfig::default()
    };
    assert!(matches!(
        StreamedTessellation::new(big, &t),
        Err(LodError::InvalidTessParam {
            what: "patch_size",
            ..
        })
    ));
    let tess = StreamedTessellation::new(TessConfig::default(), &t).unwrap();
    // A tree of another world.
    let other = map(200, 256, true);
    assert!(matches!(
        tess.select(&tree(&other), &view(Vec3::splat(10.0)), &h),
        Err(LodError::SizeMismatch { .. })
    ));
    for bad in [f32::NAN, f32::INFINITY] {
        assert!(
            tess.select(&t, &view(Vec3::new(bad, 1.0, 1.0)), &h)
                .is_err()
        );
    }
    // A budget the view needs more than: an error, not a truncated mesh.
    let small = StreamedTessellation::new(
        TessConfig {
            max_triangles: 500,
            ..TessConfig::default()
        },
        &t,
    )
    .unwrap();
    assert!(matches!(
        small.select(&t, &view(Vec3::new(64.0, 31.0, 48.0)), &h),
        Err(LodError::SelectionTooLarge { limit: 500 })
    ));
    // Far cameras and huge coordinates answer (coarse, bounded).
    let far = tess
        .select(&t, &view(Vec3::new(1e30, 1e30, -1e30)), &h)
        .unwrap();
    assert_eq!(
        far.triangle_count(),
        2 * u64::from(tess.patches().element_product())
    );
}

/// A rect another mesh takes over (refined geometry near the camera) is drawn at full
/// resolution whatever the view asks: every texel on its edge is a vertex at its true height
/// (so the two meshes meet), 60 m away and at a huge triangle width too, and the mesh stays
/// conforming; the hierarchy does the same.
#[test]
fn a_full_resolution_rect_is_drawn_through_every_texel() {
    let m = map(256, 192, true);
    let t = tree(&m);
    let h = heights(&m);
    let config = TessConfig {
        triangle_width_px: 500.0,
        ..TessConfig::default()
    };
    let hierarchy = TessHierarchy::from_map(&m, None, config).unwrap();
    let streamed = StreamedTessellation::new(config, &t).unwrap();
    let camera = Vec3::new(45.2, 40.0, 35.1);
    let (lo, hi) = (IVec2::new(200, 150), IVec2::new(218, 168));
    let assert_edge_drawn = |frame: &terrain_lod::TessFrame| {
        let mut at = std::collections::HashMap::new();
        for v in frame.triangles.iter().flatten() {
            at.insert(IVec2::new(v.texel[0] as i32, v.texel[1] as i32), v.height);
        }
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                let p = IVec2::new(x, y);
                if x == lo.x || x == hi.x || y == lo.y || y == hi.y {
                    assert_eq!(at.get(&p), Some(&h(p)), "edge texel {p}");
                }
            }
        }
    };
    let extent = streamed.patches() * 32;
    let plain = streamed.select(&t, &view(camera), &h).unwrap();
    let full = streamed
        .select_with(&t, &view(camera), &h, Some((lo, hi)))
        .unwrap();
    assert!(full.triangle_count() > plain.triangle_count() + 600);
    assert_edge_drawn(&full);
    assert_conforming(&full, extent);
    let full = hierarchy
        .select_with(&view(camera), Some((lo, hi)))
        .unwrap();
    assert_edge_drawn(&full);
    assert_conforming(&full, extent);
}

/// The quadtree `tree_config` proposes holds every patch size's first split, and is small.
#[test]
fn the_proposed_tree_fits_every_patch_size() {
    for patch_size in [2u32, 8, 32, 128, 256] {
        let config = StreamedTessellation::tree_config(patch_size);
        let size = UVec2::splat(4096);
        let t = CdlodTree::from_leaf_bounds(config, size, 0.5, |_| (0.0, 10.0)).unwrap();
        let tess = TessConfig {
            patch_size,
            ..TessConfig::default()
        };
        assert!(
            StreamedTessellation::new(tess, &t).is_ok(),
            "patch {patch_size}"
        );
        assert_eq!(config.leaf_size, 16);
    }
}

/// The forced rect's test and the reach answer for every integer input, without overflow.
#[test]
fn the_full_resolution_test_takes_any_integers() {
    use terrain_lod::tessellation::descendant_reach;
    assert_eq!(descendant_reach(32, 0), 46);
    assert_eq!(descendant_reach(32, 9), 0);
    assert_eq!(descendant_reach(32, 40), 0);
    assert!(descendant_reach(1 << 31, 0) > 0);
    let m = map(256, 192, true);
    let t = tree(&m);
    let tess = StreamedTessellation::new(TessConfig::default(), &t).unwrap();
    let extreme = IVec2::new(i32::MIN, i32::MAX);
    let d = terrain_lod::tessellation::TessDecision {
        full_resolution: Some((IVec2::MIN, IVec2::MAX)),
        ..tess.decision(&view(Vec3::ONE)).unwrap()
    };
    for v in [IVec2::MIN, IVec2::MAX, IVec2::ZERO, extreme] {
        let _ = d.forces(v, 0, 32);
    }
    assert!(d.forces(IVec2::new(-5, 5), 3, 32), "inside the rect");
}
