//! Adaptive tessellation of a streamed world (`StreamedTessellation`): decided from a streamed
//! CDLOD tree's node bounds, the mesh is conforming from every view and after deformation,
//! splits where the world is rough and near the camera, equals the hierarchy's on a flat map,
//! draws the heights it is given, and refuses bad trees, views and budgets.

mod common;

use common::{area, assert_conforming};
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
    CdlodTree::from_leaf_bounds(tree_config(), m.size(), m.texel_size(), leaf_bounds(m)).unwrap()
}

fn leaf_bounds(m: &HeightMap<u16>) -> impl FnMut(Rect) -> (f32, f32) + '_ {
    move |r: Rect| {
        let g = m.grid().copy_rect(r).unwrap();
        let lo = *g.as_slice().iter().min().unwrap();
        let hi = *g.as_slice().iter().max().unwrap();
        let enc = m.encoding();
        (enc.to_metres(f64::from(lo)), enc.to_metres(f64::from(hi)))
    }
}

/// The map's height at a texel, clamped at its edges (as the GPU's atlas addresses it).
fn heights(m: &HeightMap<u16>) -> impl Fn(IVec2) -> f32 + Sync + '_ {
    move |t: IVec2| {
        let c = t.clamp(IVec2::ZERO, m.size().as_ivec2() - 1);
        m.encoding()
            .to_metres(f64::from(m.grid().get_wrapped(c, WrapMode::Clamp)))
    }
}

fn view(camera: Vec3) -> CdlodView<'static> {
    CdlodView {
        camera,
        frustum: None,
        viewport_width: 1280.0,
        hfov: 1.2,
    }
}

#[test]
fn the_mesh_is_conforming_and_covers_the_patches_from_every_view() {
    let m = map(256, 192, true);
    let t = tree(&m);
    let h = heights(&m);
    for (morph, error) in [(true, None), (false, None), (true, Some(1.0))] {
        let config = TessConfig {
            morph,
            max_error_px: error,
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

#[test]
fn on_a_flat_map_the_spheres_are_the_hierarchys() {
    let m = map(257, 257, false);
    let t = tree(&m);
    let config = TessConfig {
        use_density: false,
        ..TessConfig::default()
    };
    let streamed = StreamedTessellation::new(config, &t).unwrap();
    let hierarchy = TessHierarchy::from_map(&m, None, config).unwrap();
    for camera in [Vec3::new(40.0, 33.0, 70.0), Vec3::new(100.0, 60.0, 20.0)] {
        let mut a = streamed
            .select(&t, &view(camera), &heights(&m))
            .unwrap()
            .triangles;
        let mut b = hierarchy.select(&view(camera)).unwrap().triangles;
        let key = |t: &terrain_lod::TessTriangle| t.map(|v| [v.texel[0] as i32, v.texel[1] as i32]);
        a.sort_by_key(key);
        b.sort_by_key(key);
        assert_eq!(a.len(), b.len(), "camera {camera}");
        assert!(a.iter().zip(&b).all(|(x, y)| key(x) == key(y)));
    }
}

#[test]
fn rough_ground_and_the_camera_split_and_a_deformation_is_followed() {
    let mut m = map(256, 192, true);
    let mut t = tree(&m);
    let tess = StreamedTessellation::new(TessConfig::default(), &t).unwrap();
    let camera = Vec3::new(64.0, 90.0, 48.0);
    let count = |t: &CdlodTree, m: &HeightMap<u16>, x: std::ops::Range<f32>| {
        let frame = tess.select(t, &view(camera), &heights(m)).unwrap();
        frame
            .triangles
            .iter()
            .filter(|tri| x.contains(&(tri[2].texel[0] * TS)))
            .count()
    };
    // The same distance from the camera: the hills left of x = 64 m split more than the
    // plane right of it.
    let (hills, plane) = (count(&t, &m, 32.0..64.0), count(&t, &m, 64.0..96.0));
    assert!(hills > plane, "hills {hills}, plane {plane}");
    // A crater on the plane: once the tree follows, the plane splits more there.
    let crater = Rect::new(IVec2::new(140, 80), UVec2::new(30, 30));
    for y in 80..110 {
        for x in 140..170 {
            *m.grid_mut().get_mut(x, y).unwrap() = 20_000;
        }
    }
    t.update_leaf_bounds(crater, leaf_bounds(&m)).unwrap();
    let deformed = count(&t, &m, 64.0..96.0);
    assert!(
        deformed > plane,
        "after the crater {deformed}, before {plane}"
    );
    let frame = tess.select(&t, &view(camera), &heights(&m)).unwrap();
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
