//! Adaptive tessellation on the demo's default map (2048 x 2048 texels at 0.1 m, patches of 32
//! texels): building the hierarchy (with and without the density map), a frame's triangles
//! (edge size with the density map, and the error metric), the frame's screen-space error, and
//! bringing the hierarchy up to date after a crater (200 x 200 texels) and after a change of the
//! whole map; and the streamed world's form on the same map: its quadtree of 16-texel leaves
//! built, a frame's triangles decided from it, and a crater's leaves updated.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{IVec2, UVec2, Vec3};
use std::hint::black_box;
use terrain_core::{HeightEncoding, Rect, TerrainParams, generate_coarse_map};
use terrain_lod::{
    CdlodTree, CdlodView, DensityMap, DensityParams, Frustum, StreamedTessellation, TessConfig,
    TessHierarchy,
};

fn bench(c: &mut Criterion) {
    let params = TerrainParams {
        size: UVec2::splat(2048),
        ..TerrainParams::default()
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 12.0).expect("encoding");
    let map = generate_coarse_map(&params, enc, 0.1).expect("terrain");
    let density = DensityMap::from_map(&map, DensityParams::default()).expect("density");
    let mut group = c.benchmark_group("tessellation");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_millis(300));
    group.measurement_time(std::time::Duration::from_secs(2));
    let config = TessConfig::default();
    group.bench_function("build/2048", |b| {
        b.iter(|| TessHierarchy::from_map(black_box(&map), None, config).expect("build"))
    });
    group.bench_function("build_with_density/2048", |b| {
        b.iter(|| TessHierarchy::from_map(black_box(&map), Some(&density), config).expect("build"))
    });
    let mut tess = TessHierarchy::from_map(&map, Some(&density), config).expect("build");
    let camera = Vec3::new(100.0, 8.0, 100.0);
    let view = glam::camera::rh::view::look_to_mat4(
        camera,
        Vec3::new(1.0, -0.2, 0.3).normalize(),
        Vec3::Y,
    );
    let proj = glam::camera::rh::proj::directx::perspective(1.0, 16.0 / 9.0, 0.1, 5000.0);
    let frustum = Frustum::from_view_proj(proj * view);
    let v = CdlodView {
        camera,
        frustum: Some(&frustum),
        viewport_width: 1280.0,
        hfov: 1.5,
    };
    group.bench_function("select/2048", |b| {
        b.iter(|| tess.select(black_box(&v)).expect("select"))
    });
    let frame = tess.select(&v).expect("select");
    group.bench_function("max_screen_error_px/2048", |b| {
        b.iter(|| tess.max_screen_error_px(black_box(&frame), &v))
    });
    let error_metric = TessHierarchy::from_map(
        &map,
        None,
        TessConfig {
            max_error_px: Some(1.0),
            ..config
        },
    )
    .expect("build");
    group.bench_function("select_error_1px/2048", |b| {
        b.iter(|| error_metric.select(black_box(&v)).expect("select"))
    });
    let crater = Rect::new(IVec2::splat(900), UVec2::splat(200));
    group.bench_function("update_rect/200x200", |b| {
        b.iter(|| {
            tess.update_rect(black_box(&map), Some(&density), crater)
                .expect("update")
        })
    });
    group.bench_function("update_rect/2048x2048", |b| {
        b.iter(|| {
            tess.update_rect(black_box(&map), Some(&density), Rect::from_size(map.size()))
                .expect("update")
        })
    });
    // The streamed form: the map as a world the CPU would not hold whole.
    let mut leaf_bounds = terrain_test_support::heights::exact_bounds(&map);
    let tree_config = StreamedTessellation::tree_config(config.patch_size);
    let ts = map.texel_size();
    group.bench_function("streamed_tree/2048", |b| {
        b.iter(|| CdlodTree::from_leaf_bounds(tree_config, map.size(), ts, &mut leaf_bounds))
    });
    let mut tree =
        CdlodTree::from_leaf_bounds(tree_config, map.size(), ts, &mut leaf_bounds).expect("tree");
    let streamed = StreamedTessellation::new(config, &tree).expect("streamed");
    let height = |t: IVec2| {
        let c = t.clamp(IVec2::ZERO, map.size().as_ivec2() - 1);
        enc.to_metres(f64::from(
            map.grid().get(c.x as u32, c.y as u32).unwrap_or(0),
        ))
    };
    group.bench_function("streamed_select/2048", |b| {
        b.iter(|| {
            streamed
                .select(&tree, black_box(&v), &height)
                .expect("select")
        })
    });
    group.bench_function("streamed_update/200x200", |b| {
        b.iter(|| {
            tree.update_leaf_bounds(black_box(crater), &mut leaf_bounds)
                .expect("update")
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
