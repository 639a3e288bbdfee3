//! `DepthFromBelowPass` against the CPU rasterizer `terrain_core::granular::depth_from_below_into`
//! (Persson 2019, sec. 4.1.2) on whatever adapter the machine has (lavapipe in CI). Both run
//! one integer program, so every comparison asks for 0 differing columns.

use glam::{Affine3A, DVec3, IVec2, Quat, UVec2, Vec3};
use terrain_core::granular::{
    DepthTriangle, GranularObject, NO_OBJECT, TriMesh, depth_from_below_into, depth_triangles,
    rasterize_triangle,
};
use terrain_core::{Grid, HeightEncoding, Rect};
use terrain_gpu::GpuContext;
use terrain_gpu::granular::{DepthArea, DepthFromBelowPass};
use terrain_gpu::testing::context_or_skip;

fn enc() -> HeightEncoding {
    HeightEncoding::fixed_point(10_000).unwrap()
}

fn gpu_depth(
    ctx: &GpuContext,
    pass: &mut DepthFromBelowPass,
    objects: &[GranularObject<'_>],
    ts: f32,
    area: Rect,
) -> Grid<u32> {
    let grid = pass
        .run(
            &ctx.device,
            &ctx.queue,
            objects,
            &DepthArea::new(enc(), ts, area).unwrap(),
        )
        .unwrap();
    ctx.check().unwrap();
    grid
}

fn cpu_depth(objects: &[GranularObject<'_>], ts: f32, area: Rect) -> Grid<u32> {
    let mut out = Grid::new(area.size.x, area.size.y, 0).unwrap();
    depth_from_below_into(objects, enc(), ts, area, &mut out).unwrap();
    out
}

/// Columns covered by either side, after asserting that GPU and CPU agree on every column.
fn check(
    ctx: &GpuContext,
    pass: &mut DepthFromBelowPass,
    name: &str,
    objects: &[GranularObject<'_>],
    ts: f32,
    area: Rect,
) -> usize {
    let gpu = gpu_depth(ctx, pass, objects, ts, area);
    let cpu = cpu_depth(objects, ts, area);
    assert_same(name, &gpu, &cpu)
}

fn assert_same(name: &str, gpu: &Grid<u32>, cpu: &Grid<u32>) -> usize {
    assert_eq!(gpu.size(), cpu.size());
    let differing: Vec<(u32, u32, u32, u32)> = (0..cpu.height())
        .flat_map(|y| (0..cpu.width()).map(move |x| (x, y)))
        .filter_map(|(x, y)| {
            let (g, c) = (gpu.get(x, y).unwrap(), cpu.get(x, y).unwrap());
            (g != c).then_some((x, y, g, c))
        })
        .collect();
    assert!(
        differing.is_empty(),
        "{name}: {} columns differ, first (x, y, gpu, cpu): {:?}",
        differing.len(),
        &differing[..differing.len().min(8)]
    );
    let footprint = cpu.as_slice().iter().filter(|&&v| v != NO_OBJECT).count();
    println!("{name}: {footprint} columns covered, 0 differ");
    footprint
}

fn placements() -> Vec<Affine3A> {
    let mut v = Vec::new();
    for (k, (x, z)) in [(1.6, 1.6), (1.237, 1.913), (2.05, 1.31), (1.5003, 1.77)]
        .into_iter()
        .enumerate()
    {
        let yaw = 0.37 * k as f32 + 0.11;
        let tilt = 0.05 * k as f32;
        v.push(Affine3A::from_rotation_translation(
            Quat::from_rotation_y(yaw) * Quat::from_rotation_x(tilt),
            Vec3::new(x, 0.8 + 0.013 * k as f32, z),
        ));
    }
    v
}

#[test]
fn box_wheel_and_foot_match_the_cpu_rasterizer() {
    let Some(ctx) = context_or_skip("box_wheel_and_foot_match_the_cpu_rasterizer") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let cuboid = TriMesh::cuboid(Vec3::new(0.5, 0.2, 0.3)).unwrap();
    let wheel = TriMesh::wheel(0.5, 0.2, 24).unwrap();
    let foot = TriMesh::foot(0.9, 0.35, 0.1).unwrap();
    let area = Rect::new(IVec2::new(8, 5), UVec2::new(96, 80));
    let ts = 0.03;
    for (k, at) in placements().into_iter().enumerate() {
        for (mesh_name, mesh) in [("box", &cuboid), ("wheel", &wheel), ("foot", &foot)] {
            let footprint = check(
                &ctx,
                &mut pass,
                &format!("{mesh_name} #{k}"),
                &[GranularObject::new(mesh, at)],
                ts,
                area,
            );
            assert!(footprint > 50, "{mesh_name} #{k} should cover the area");
        }
    }
}

#[test]
fn flat_box_bottom_is_one_height() {
    let Some(ctx) = context_or_skip("flat_box_bottom_is_one_height") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let cuboid = TriMesh::cuboid(Vec3::new(0.4, 0.2, 0.25)).unwrap();
    let at =
        Affine3A::from_rotation_translation(Quat::from_rotation_y(0.4), Vec3::new(1.0, 0.7, 1.1));
    let area = Rect::new(IVec2::ZERO, UVec2::new(64, 64));
    let objects = [GranularObject::new(&cuboid, at)];
    let gpu = gpu_depth(&ctx, &mut pass, &objects, 0.04, area);
    let cpu = cpu_depth(&objects, 0.04, area);
    assert_same("flat box", &gpu, &cpu);
    // 0.5 m in units, within one unit of the f32 bottom's rounding; one height everywhere
    // (the bottom's vertices snap to the same 1/256 unit).
    let expected = cpu
        .as_slice()
        .iter()
        .copied()
        .find(|&v| v != NO_OBJECT)
        .unwrap();
    assert!(expected.abs_diff(5000) <= 1, "cpu bottom {expected}");
    assert!(
        cpu.as_slice()
            .iter()
            .all(|&v| v == NO_OBJECT || v == expected)
    );
}

#[test]
fn texel_aligned_box_matches_exactly() {
    let Some(ctx) = context_or_skip("texel_aligned_box_matches_exactly") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    // Corners on sample points (texel size a power of two): the half-open footprint [a, b) of
    // the top-left rule.
    let cuboid = TriMesh::cuboid(Vec3::new(1.0, 0.25, 0.75)).unwrap();
    let at = Affine3A::from_translation(Vec3::new(3.0, 1.0, 2.5));
    let area = Rect::new(IVec2::new(2, 1), UVec2::new(24, 20));
    let objects = [GranularObject::new(&cuboid, at)];
    let gpu = gpu_depth(&ctx, &mut pass, &objects, 0.25, area);
    let cpu = cpu_depth(&objects, 0.25, area);
    assert_same("texel-aligned box", &gpu, &cpu);
    // Box from x = 2 .. 4 m, z = 1.75 .. 3.25 m: columns 8..16, 7..13.
    let covered: Vec<(u32, u32)> = (0..20)
        .flat_map(|y| (0..24).map(move |x| (x, y)))
        .filter(|&(x, y)| cpu.get(x, y) != Some(NO_OBJECT))
        .collect();
    assert_eq!(covered.len(), 8 * 6);
    assert_eq!(covered[0], (8 - 2, 7 - 1));
    assert_eq!(cpu.get(6, 6), Some(7500));
}

#[test]
fn overlapping_objects_keep_the_lowest_surface() {
    let Some(ctx) = context_or_skip("overlapping_objects_keep_the_lowest_surface") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let cuboid = TriMesh::cuboid(Vec3::new(0.6, 0.1, 0.6)).unwrap();
    let wheel = TriMesh::wheel(0.4, 0.15, 32).unwrap();
    let objects = [
        GranularObject::new(
            &cuboid,
            Affine3A::from_translation(Vec3::new(1.213, 0.75, 1.187)),
        ),
        GranularObject::new(
            &wheel,
            Affine3A::from_rotation_translation(
                Quat::from_rotation_y(0.8),
                Vec3::new(1.4, 0.9, 1.3),
            ),
        ),
    ];
    let area = Rect::new(IVec2::ZERO, UVec2::new(80, 80));
    check(&ctx, &mut pass, "box + wheel", &objects, 0.03, area);
}

#[test]
fn objects_partly_or_wholly_outside_the_area() {
    let Some(ctx) = context_or_skip("objects_partly_or_wholly_outside_the_area") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let wheel = TriMesh::wheel(0.5, 0.2, 24).unwrap();
    let area = Rect::new(IVec2::new(20, 30), UVec2::new(40, 30));
    let ts = 0.05;
    // Centred on each corner of the area, and far away.
    let (x0, z0) = (20.0 * ts, 30.0 * ts);
    let (x1, z1) = (60.0 * ts, 60.0 * ts);
    for (k, (x, z)) in [(x0, z0), (x1, z0), (x0, z1), (x1, z1)]
        .into_iter()
        .enumerate()
    {
        let at = Affine3A::from_rotation_translation(
            Quat::from_rotation_y(0.3 + k as f32),
            Vec3::new(x + 0.011, 0.6, z - 0.007),
        );
        let footprint = check(
            &ctx,
            &mut pass,
            &format!("wheel at corner {k}"),
            &[GranularObject::new(&wheel, at)],
            ts,
            area,
        );
        assert!(footprint > 20 && footprint < 40 * 30);
    }
    let far = Affine3A::from_translation(Vec3::new(-5.0, 0.6, 40.0));
    let gpu = gpu_depth(
        &ctx,
        &mut pass,
        &[GranularObject::new(&wheel, far)],
        ts,
        area,
    );
    assert!(gpu.as_slice().iter().all(|&v| v == NO_OBJECT));
}

#[test]
fn empty_object_list_gives_no_object_everywhere() {
    let Some(ctx) = context_or_skip("empty_object_list_gives_no_object_everywhere") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let area = Rect::new(IVec2::new(3, 4), UVec2::new(17, 9));
    // A buffer holding an earlier result is overwritten.
    let out = DepthFromBelowPass::create_output(&ctx.device, area).unwrap();
    let cuboid = TriMesh::cuboid(Vec3::splat(1.0)).unwrap();
    let big = [GranularObject::new(
        &cuboid,
        Affine3A::from_translation(Vec3::new(0.5, 2.0, 0.5)),
    )];
    for objects in [&big[..], &[][..]] {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let view = DepthArea::new(enc(), 0.1, area).unwrap();
        pass.encode(&ctx.device, &ctx.queue, &mut encoder, objects, &view, &out)
            .unwrap();
        ctx.queue.submit([encoder.finish()]);
        pass.recall();
    }
    let grid = DepthFromBelowPass::read(&ctx.device, &ctx.queue, &out, area).unwrap();
    ctx.check().unwrap();
    assert_eq!(grid.size(), area.size);
    assert!(grid.as_slice().iter().all(|&v| v == NO_OBJECT));
}

#[test]
fn heights_clamp_like_the_cpu() {
    let Some(ctx) = context_or_skip("heights_clamp_like_the_cpu") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let area = Rect::new(IVec2::ZERO, UVec2::new(32, 32));
    let cuboid = TriMesh::cuboid(Vec3::new(0.5, 0.3, 0.5)).unwrap();
    // Below the encoding's zero: 0; above u32 units (1e6 m * 1e4): NO_OBJECT - 1.
    for (y, expected) in [(-2.0, 0), (999_990.0, NO_OBJECT - 1)] {
        let at = Affine3A::from_translation(Vec3::new(1.613, y, 1.587));
        let objects = [GranularObject::new(&cuboid, at)];
        let gpu = gpu_depth(&ctx, &mut pass, &objects, 0.1, area);
        let cpu = cpu_depth(&objects, 0.1, area);
        assert_same(&format!("box at {y} m"), &gpu, &cpu);
        assert!(cpu.as_slice().contains(&expected));
    }
    // A tilted box spanning the zero of the encoding: the base is negative, the sum is
    // clamped after the interpolation.
    let at = Affine3A::from_rotation_translation(
        Quat::from_rotation_z(0.5),
        Vec3::new(1.613, 0.1, 1.587),
    );
    let objects = [GranularObject::new(&cuboid, at)];
    check(&ctx, &mut pass, "box across zero", &objects, 0.1, area);
    let cpu = cpu_depth(&objects, 0.1, area);
    assert!(cpu.as_slice().contains(&0));
    assert!(cpu.as_slice().iter().any(|&v| v > 0 && v != NO_OBJECT));
}

#[test]
fn areas_wider_than_a_dispatch_tile() {
    let Some(ctx) = context_or_skip("areas_wider_than_a_dispatch_tile") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    // As wide as the render pipeline's tiles were, and a seam of those tiles.
    let side =
        terrain_gpu::granular::MAX_TILE_SIDE.min(ctx.device.limits().max_texture_dimension_2d);
    let area = Rect::new(IVec2::new(-3, 0), UVec2::new(side + 37, 6));
    let ts = 0.01;
    let seam = (side as f32 - 3.0) * ts;
    let cuboid = TriMesh::cuboid(Vec3::new(0.2, 0.1, 0.02)).unwrap();
    let at = Affine3A::from_rotation_translation(
        Quat::from_rotation_x(0.2) * Quat::from_rotation_y(0.05),
        Vec3::new(seam + 0.0013, 0.5, 0.031),
    );
    let footprint = check(
        &ctx,
        &mut pass,
        "box across the old tile seam",
        &[GranularObject::new(&cuboid, at)],
        ts,
        area,
    );
    assert!(footprint > 100);
}

#[test]
fn bad_inputs_are_errors() {
    let Some(ctx) = context_or_skip("bad_inputs_are_errors") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let device = &ctx.device;
    let area = Rect::new(IVec2::ZERO, UVec2::new(8, 8));
    let cuboid = TriMesh::cuboid(Vec3::splat(0.2)).unwrap();
    let mut nan = Affine3A::from_translation(Vec3::new(0.4, 0.5, 0.4));
    nan.translation.y = f32::NAN;
    let bad = [GranularObject::new(&cuboid, nan)];
    assert!(bad[0].validate().is_err());
    let mut cpu = Grid::new(8, 8, 0).unwrap();
    assert!(depth_from_below_into(&bad, enc(), 0.1, area, &mut cpu).is_err());
    let view = DepthArea::new(enc(), 0.1, area).unwrap();
    assert!(pass.run(device, &ctx.queue, &bad, &view).is_err());
    let far = Affine3A::from_translation(Vec3::new(2.0e6, 0.0, 0.0));
    assert!(
        pass.run(
            device,
            &ctx.queue,
            &[GranularObject::new(&cuboid, far)],
            &view
        )
        .is_err()
    );

    // Bad texel sizes, encodings and empty areas cannot make a `DepthArea`.
    for ts in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert!(DepthArea::new(enc(), ts, area).is_err());
    }
    let mut bad_enc = enc();
    bad_enc.scale = 0.0;
    assert!(DepthArea::new(bad_enc, 0.1, area).is_err());
    let empty = Rect::new(IVec2::ZERO, UVec2::new(0, 8));
    assert!(DepthArea::new(enc(), 0.1, empty).is_err());
    assert!(DepthFromBelowPass::create_output(device, empty).is_err());

    let small =
        DepthFromBelowPass::create_output(device, Rect::from_size(UVec2::new(4, 4))).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    assert!(
        pass.encode(device, &ctx.queue, &mut encoder, &[], &view, &small)
            .is_err()
    );
    pass.recall();
    // The pass still works after the refusals.
    assert!(
        pass.run(device, &ctx.queue, &[], &view)
            .unwrap()
            .as_slice()
            .iter()
            .all(|&v| v == NO_OBJECT)
    );
    ctx.check().unwrap();
}

#[test]
fn edges_a_hair_off_sample_points_snap_onto_them() {
    let Some(ctx) = context_or_skip("edges_a_hair_off_sample_points_snap_onto_them") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    // 0.6 / 0.03 in f32 inputs is 20.000001 texels: the f64 rasterizer left column 20 out,
    // the render pipeline (1/256 texel snapping on NVIDIA) took it in. Both sides now snap to
    // 1/256 texel, so the edges lie on the samples and the footprint is the half-open
    // [20, 60) x [20, 60).
    let cuboid = TriMesh::cuboid(Vec3::new(0.6, 0.1, 0.6)).unwrap();
    let objects = [GranularObject::new(
        &cuboid,
        Affine3A::from_translation(Vec3::new(1.2, 0.75, 1.2)),
    )];
    let area = Rect::new(IVec2::ZERO, UVec2::new(64, 64));
    let footprint = check(
        &ctx,
        &mut pass,
        "box with edges on samples",
        &objects,
        0.03,
        area,
    );
    assert_eq!(footprint, 40 * 40);
    let cpu = cpu_depth(&objects, 0.03, area);
    assert_ne!(cpu.get(20, 20), Some(NO_OBJECT));
    assert_eq!(cpu.get(60, 30), Some(NO_OBJECT));
}

/// A fan of triangles whose vertices all lie on sample points, sharing edges (horizontal,
/// vertical, diagonal) and a centre vertex: every sample of the fan's square is covered by
/// exactly one triangle (counted on the CPU triangle by triangle), and the GPU agrees.
#[test]
fn shared_edges_through_sample_points_are_covered_once() {
    let Some(ctx) = context_or_skip("shared_edges_through_sample_points_are_covered_once") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let ts = 0.25;
    // A 16 x 16 texel square from (4, 4) split at its centre (12, 12) into eight triangles
    // through the corners and edge midpoints; heights differ per vertex.
    let t = |x: f32, z: f32, h: f32| Vec3::new(x * ts, h, z * ts);
    let ring = [
        (4.0, 4.0),
        (12.0, 4.0),
        (20.0, 4.0),
        (20.0, 12.0),
        (20.0, 20.0),
        (12.0, 20.0),
        (4.0, 20.0),
        (4.0, 12.0),
    ];
    let mut vertices = vec![t(12.0, 12.0, 1.0)];
    vertices.extend(
        ring.iter()
            .enumerate()
            .map(|(k, &(x, z))| t(x, z, 1.1 + 0.03 * k as f32)),
    );
    let triangles: Vec<[u32; 3]> = (0..8u32).map(|k| [0, 1 + k, 1 + (k + 1) % 8]).collect();
    let mesh = TriMesh::new(vertices, triangles).unwrap();
    let objects = [GranularObject::new(&mesh, Affine3A::IDENTITY)];
    let area = Rect::new(IVec2::ZERO, UVec2::new(24, 24));
    let mut tris: Vec<DepthTriangle> = Vec::new();
    depth_triangles(&objects, enc(), ts, area, &mut tris).unwrap();
    assert_eq!(tris.len(), 8);
    let mut count = Grid::new(24, 24, 0u32).unwrap();
    for tri in &tris {
        let mut one = Grid::new(24, 24, NO_OBJECT).unwrap();
        rasterize_triangle(tri, area, &mut one);
        for (c, &v) in count.as_mut_slice().iter_mut().zip(one.as_slice()) {
            *c += u32::from(v != NO_OBJECT);
        }
    }
    for y in 0..24 {
        for x in 0..24 {
            let expected = u32::from((4..20).contains(&x) && (4..20).contains(&y));
            assert_eq!(count.get(x, y), Some(expected), "sample ({x}, {y})");
        }
    }
    let footprint = check(&ctx, &mut pass, "fan on sample points", &objects, ts, area);
    assert_eq!(footprint, 16 * 16);
    // The centre vertex's height, exactly: 1 m is 10 000 units.
    assert_eq!(cpu_depth(&objects, ts, area).get(12, 12), Some(10_000));
}

/// One tilted triangle far larger than the area and than a record's tile: the whole area is
/// covered, the plane's height exact to the unit at sample points where it is known exactly.
#[test]
fn large_ground_plane_triangle() {
    let Some(ctx) = context_or_skip("large_ground_plane_triangle") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let ts = 0.5;
    // 3000 texels a side, the plane rising 1 mm per metre in x (2 units a texel).
    let h = |x: f32| 2.0 + 0.001 * x;
    let mesh = TriMesh::new(
        vec![
            Vec3::new(-500.0, h(-500.0), -500.0),
            Vec3::new(1000.0, h(1000.0), -500.0),
            Vec3::new(-500.0, h(-500.0), 1000.0),
        ],
        vec![[0, 1, 2]],
    )
    .unwrap();
    let objects = [GranularObject::new(&mesh, Affine3A::IDENTITY)];
    let area = Rect::new(IVec2::new(-40, 7), UVec2::new(300, 200));
    let footprint = check(&ctx, &mut pass, "ground plane", &objects, ts, area);
    assert_eq!(footprint, 300 * 200);
    let cpu = cpu_depth(&objects, ts, area);
    // Column x stands at x / 2 m: 20 000 + 5 x units (within a unit of the f32 vertices).
    for (i, x) in [(0u32, -40i32), (140, 100), (299, 259)] {
        let expected = 20_000 + 5 * x;
        let got = cpu.get(i, 100).unwrap() as i32;
        assert!(
            (got - expected).abs() <= 1,
            "column {x}: {got}, expected {expected}"
        );
    }
}

/// A steep, tall triangle (heights spanning 10^9 units: the heights keep fewer fractional
/// bits) and one, beside it, high above the top of the encoding with its base beyond 32 bits:
/// the 64-bit paths of the program agree.
#[test]
fn tall_triangles_keep_fewer_height_bits() {
    let Some(ctx) = context_or_skip("tall_triangles_keep_fewer_height_bits") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let ts = 0.5;
    let mesh = TriMesh::new(
        vec![
            Vec3::new(-10.0, -50_000.0, -10.0),
            Vec3::new(90.0, 50_000.0, -5.0),
            Vec3::new(-7.0, 1.0, 80.0),
            Vec3::new(75.0, 990_000.0, 50.0),
            Vec3::new(105.0, 999_000.0, 50.0),
            Vec3::new(75.0, 980_000.0, 80.0),
        ],
        vec![[0, 1, 2], [3, 4, 5]],
    )
    .unwrap();
    let objects = [GranularObject::new(&mesh, Affine3A::IDENTITY)];
    let area = Rect::new(IVec2::new(-30, -30), UVec2::new(240, 220));
    let mut tris = Vec::new();
    depth_triangles(&objects, enc(), ts, area, &mut tris).unwrap();
    assert!(tris.iter().any(|t| t.frac_bits < 8), "{tris:?}");
    assert!(
        tris.iter().any(|t| t.base > i64::from(u32::MAX)),
        "{tris:?}"
    );
    let footprint = check(&ctx, &mut pass, "tall triangles", &objects, ts, area);
    assert!(footprint > 1000);
    let cpu = cpu_depth(&objects, ts, area);
    assert!(cpu.as_slice().contains(&0));
    assert!(cpu.as_slice().contains(&(NO_OBJECT - 1)));
}

/// Degenerate triangles (a repeated vertex, collinear vertices, a vertical face, and one
/// thinner than 1/512 texel, which snaps to zero area) cover nothing on either side.
#[test]
fn degenerate_and_vertical_triangles_cover_nothing() {
    let Some(ctx) = context_or_skip("degenerate_and_vertical_triangles_cover_nothing") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let ts = 0.1;
    let mesh = TriMesh::new(
        vec![
            Vec3::new(0.5, 1.0, 0.5),
            Vec3::new(2.0, 1.0, 0.5),
            Vec3::new(1.25, 1.5, 0.5),
            Vec3::new(0.5, 0.3, 0.5),
            Vec3::new(2.0, 0.3, 2.0),
            Vec3::new(1.0, 0.3, 1.0),
            Vec3::new(2.0, 0.4, 2.0 + 1.0e-4),
        ],
        vec![
            // Repeated vertex.
            [0, 0, 1],
            // Vertical face in the plane z = 0.5.
            [0, 1, 2],
            // Collinear in projection (the diagonal x = z).
            [3, 4, 5],
            // A sliver 1e-4 m = 1/1000 texel wide: snaps onto the diagonal.
            [3, 4, 6],
        ],
    )
    .unwrap();
    let objects = [GranularObject::new(&mesh, Affine3A::IDENTITY)];
    let area = Rect::new(IVec2::ZERO, UVec2::new(32, 32));
    let mut tris = Vec::new();
    depth_triangles(&objects, enc(), ts, area, &mut tris).unwrap();
    assert!(tris.is_empty(), "{tris:?}");
    assert_eq!(check(&ctx, &mut pass, "degenerate", &objects, ts, area), 0);
}

/// The integer program's bounds are errors, not overflow: a triangle spanning 2^15 texels or
/// more is refused on both sides with the same message.
#[test]
fn triangles_beyond_the_span_limit_are_refused() {
    let Some(ctx) = context_or_skip("triangles_beyond_the_span_limit_are_refused") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let ts = 0.01;
    // 400 m at 1 cm texels: 40 000 texels.
    let mesh = TriMesh::new(
        vec![
            Vec3::new(-200.0, 1.0, 0.0),
            Vec3::new(200.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.3),
        ],
        vec![[0, 1, 2]],
    )
    .unwrap();
    let objects = [GranularObject::new(&mesh, Affine3A::IDENTITY)];
    let area = Rect::new(IVec2::ZERO, UVec2::new(16, 16));
    let mut grid = Grid::new(16, 16, 0).unwrap();
    let cpu = depth_from_below_into(&objects, enc(), ts, area, &mut grid).unwrap_err();
    let view = DepthArea::new(enc(), ts, area).unwrap();
    let gpu = pass
        .run(&ctx.device, &ctx.queue, &objects, &view)
        .unwrap_err();
    assert!(cpu.to_string().contains("MAX_TRIANGLE_SPAN"), "{cpu}");
    assert!(gpu.to_string().contains("MAX_TRIANGLE_SPAN"), "{gpu}");
    // One just inside the limit is fine, and agrees.
    let p = [
        DVec3::new(-150.0, 1.0, 0.0),
        DVec3::new(150.0, 1.0, 0.0),
        DVec3::new(0.0, 1.0, 0.3),
    ];
    assert!(
        terrain_core::granular::depth_triangle(p, enc(), ts, area)
            .unwrap()
            .is_some()
    );
    let inside = TriMesh::new(p.iter().map(|v| v.as_vec3()).collect(), vec![[0, 1, 2]]).unwrap();
    let objects = [GranularObject::new(&inside, Affine3A::IDENTITY)];
    let area = Rect::new(IVec2::new(-40, 0), UVec2::new(80, 30));
    assert!(check(&ctx, &mut pass, "long sliver", &objects, ts, area) > 0);
    ctx.check().unwrap();
}
