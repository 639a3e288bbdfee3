//! `DepthFromBelowPass` against the CPU rasterizer `terrain_core::granular::depth_from_below_into`
//! (Persson 2019, sec. 4.1.2) on whatever adapter the machine has (lavapipe in CI).

use glam::{Affine3A, IVec2, Quat, UVec2, Vec3};
use terrain_core::granular::{GranularObject, NO_OBJECT, TriMesh, depth_from_below_into};
use terrain_core::{Grid, HeightEncoding, Rect};
use terrain_gpu::GpuContext;
use terrain_gpu::granular::{DepthArea, DepthFromBelowPass};
use terrain_gpu::testing::context_or_skip;

/// Largest height difference, in units, between GPU and CPU on columns covered by both, where
/// the surface around them is gentle: f32 interpolation against f64 (steep slopes add a
/// share of their step, see [`compare_within`]).
const INTERIOR_BOUND_UNITS: u32 = 1;
/// Largest share of the footprint (columns covered by either) whose coverage differs: vertex
/// snapping at footprint edges.
const EDGE_SHARE_BOUND: f64 = 0.02;

fn enc() -> HeightEncoding {
    HeightEncoding::fixed_point(10_000).unwrap()
}

#[derive(Debug, Default)]
struct Agreement {
    footprint: usize,
    coverage_diff: usize,
    height_diff: usize,
    max_interior_diff: u32,
}

impl Agreement {
    /// The share of the footprint whose coverage differs (the rasterization rules' part;
    /// edge heights are checked column by column instead).
    fn share(&self) -> f64 {
        self.coverage_diff as f64 / self.footprint.max(1) as f64
    }
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

/// Compares GPU and CPU and asserts the bounds: heights within one unit plus what 1/64 texel
/// changes on the steepest slope around a column (at footprint edges: within the CPU's heights
/// around it, so widened), coverage differences only where the CPU footprint has an edge in
/// the 3x3 neighbourhood and on less than [`EDGE_SHARE_BOUND`] of the footprint.
fn compare(name: &str, gpu: &Grid<u32>, cpu: &Grid<u32>) -> Agreement {
    compare_within(name, gpu, cpu, EDGE_SHARE_BOUND)
}

fn compare_within(name: &str, gpu: &Grid<u32>, cpu: &Grid<u32>, share_bound: f64) -> Agreement {
    assert_eq!(gpu.size(), cpu.size());
    let (w, h) = (cpu.width() as i64, cpu.height() as i64);
    let covered = |x: i64, y: i64| -> Option<bool> {
        (x >= 0 && y >= 0 && x < w && y < h).then(|| cpu.get(x as u32, y as u32) != Some(NO_OBJECT))
    };
    let mut a = Agreement::default();
    for y in 0..h {
        for x in 0..w {
            let (g, c) = (
                gpu.get(x as u32, y as u32).unwrap(),
                cpu.get(x as u32, y as u32).unwrap(),
            );
            if g == NO_OBJECT && c == NO_OBJECT {
                continue;
            }
            a.footprint += 1;
            // Neighbours off the grid count as "same as the centre".
            let centre = c != NO_OBJECT;
            let interior = (-1..=1)
                .all(|dy| (-1..=1).all(|dx| covered(x + dx, y + dy).unwrap_or(centre) == centre));
            if (g == NO_OBJECT) != (c == NO_OBJECT) {
                a.coverage_diff += 1;
                assert!(
                    !interior,
                    "{name}: column ({x}, {y}) differs in coverage (gpu {g}, cpu {c}) away from \
                     any footprint edge"
                );
                continue;
            }
            // GPU and CPU sample the same piecewise-planar surface, but the rasterizer snaps
            // vertices to a sub-pixel grid (1/256 texel on NVIDIA; lavapipe measured exact) and
            // interpolates in f32. On a steep face that small shift moves the sampled height
            // by many units (up to 16 measured on an H200): at creases inside the footprint
            // and at its edges. So a height may differ by one unit plus what a shift of 1/64
            // texel changes on the steepest slope around the column (the largest CPU height
            // step to a covered neighbour, over at most sqrt 2 texels). At an edge the face
            // can be a sliver seen almost edge-on (a tilted box's side: under a texel wide,
            // decimetres high) that the CPU's samples around it miss, so its slope is not
            // known: there the height must lie within the CPU's heights around the column,
            // widened by the same allowance.
            let near = || {
                (-1..=1)
                    .flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy)))
                    .filter(|&(u, v)| covered(u, v) == Some(true))
                    .map(|(u, v)| cpu.get(u as u32, v as u32).unwrap())
            };
            let steepest = near().map(|n| n.abs_diff(c)).max().unwrap_or(0);
            let bound = INTERIOR_BOUND_UNITS + steepest / 64;
            let (lo, hi) = near().fold((c, c), |(lo, hi), n| (lo.min(n), hi.max(n)));
            let d = g.abs_diff(c);
            let on_surface = d <= bound
                || (!interior && g.saturating_add(bound) >= lo && g <= hi.saturating_add(bound));
            assert!(
                on_surface,
                "{name}: column ({x}, {y}): gpu {g}, cpu {c}, bound {bound}, cpu around it \
                 {lo}..={hi} ({})",
                if interior { "interior" } else { "at an edge" }
            );
            if d > INTERIOR_BOUND_UNITS {
                a.height_diff += 1;
            }
            if interior {
                a.max_interior_diff = a.max_interior_diff.max(d);
            }
        }
    }
    if std::env::var("DEPTH_DEBUG").is_ok() {
        for y in 0..h {
            let row: String = (0..w)
                .map(|x| {
                    let (g, c) = (
                        gpu.get(x as u32, y as u32).unwrap(),
                        cpu.get(x as u32, y as u32).unwrap(),
                    );
                    match (g == NO_OBJECT, c == NO_OBJECT) {
                        (true, true) => '.',
                        (false, true) => 'G',
                        (true, false) => 'C',
                        _ if g.abs_diff(c) > 1 => 'x',
                        _ => '#',
                    }
                })
                .collect();
            println!("{row}");
        }
    }
    println!(
        "{name}: footprint {} columns, coverage differs {}, height differs > {INTERIOR_BOUND_UNITS} \
         on {} columns (steep slopes), coverage share {:.3} %, max interior diff {} units",
        a.footprint,
        a.coverage_diff,
        a.height_diff,
        a.share() * 100.0,
        a.max_interior_diff
    );
    assert!(
        a.share() < share_bound,
        "{name}: the coverage of {:.3} % of the footprint differs",
        a.share() * 100.0
    );
    a
}

fn check(
    ctx: &GpuContext,
    pass: &mut DepthFromBelowPass,
    name: &str,
    objects: &[GranularObject<'_>],
    ts: f32,
    area: Rect,
) -> Agreement {
    let gpu = gpu_depth(ctx, pass, objects, ts, area);
    let cpu = cpu_depth(objects, ts, area);
    compare(name, &gpu, &cpu)
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
    let mut worst = 0.0f64;
    let mut total_footprint = 0;
    for (k, at) in placements().into_iter().enumerate() {
        for (mesh_name, mesh) in [("box", &cuboid), ("wheel", &wheel), ("foot", &foot)] {
            let a = check(
                &ctx,
                &mut pass,
                &format!("{mesh_name} #{k}"),
                &[GranularObject::new(mesh, at)],
                ts,
                area,
            );
            assert!(a.footprint > 50, "{mesh_name} #{k} should cover the area");
            worst = worst.max(a.share());
            total_footprint += a.footprint;
        }
    }
    println!(
        "worst share {:.3} % over {total_footprint} footprint columns",
        worst * 100.0
    );
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
    let expected = cpu
        .as_slice()
        .iter()
        .copied()
        .find(|&v| v != NO_OBJECT)
        .unwrap();
    // 0.5 m in units, within one unit of f32 rounding of the bottom.
    assert!(expected.abs_diff(5000) <= 1, "cpu bottom {expected}");
    for &v in gpu.as_slice() {
        assert!(v == NO_OBJECT || v.abs_diff(expected) <= 1, "gpu {v}");
    }
    compare("flat box", &gpu, &cpu);
}

#[test]
fn texel_aligned_box_matches_exactly() {
    let Some(ctx) = context_or_skip("texel_aligned_box_matches_exactly") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    // Corners on sample points (texel size a power of two): the half-open footprint [a, b) of
    // the CPU's top-left rule must come out identical if pixel centres are aligned.
    let cuboid = TriMesh::cuboid(Vec3::new(1.0, 0.25, 0.75)).unwrap();
    let at = Affine3A::from_translation(Vec3::new(3.0, 1.0, 2.5));
    let area = Rect::new(IVec2::new(2, 1), UVec2::new(24, 20));
    let objects = [GranularObject::new(&cuboid, at)];
    let gpu = gpu_depth(&ctx, &mut pass, &objects, 0.25, area);
    let cpu = cpu_depth(&objects, 0.25, area);
    assert_eq!(gpu, cpu);
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
        let a = check(
            &ctx,
            &mut pass,
            &format!("wheel at corner {k}"),
            &[GranularObject::new(&wheel, at)],
            ts,
            area,
        );
        assert!(a.footprint > 20 && a.footprint < 40 * 30);
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
        // Off the sample grid: edges exactly on sample points are the f32 snapping case.
        let at = Affine3A::from_translation(Vec3::new(1.613, y, 1.587));
        let objects = [GranularObject::new(&cuboid, at)];
        let gpu = gpu_depth(&ctx, &mut pass, &objects, 0.1, area);
        let cpu = cpu_depth(&objects, 0.1, area);
        assert_eq!(gpu, cpu);
        assert!(cpu.as_slice().contains(&expected));
    }
    // A tilted box spanning the zero of the encoding.
    let at = Affine3A::from_rotation_translation(
        Quat::from_rotation_z(0.5),
        Vec3::new(1.613, 0.1, 1.587),
    );
    check(
        &ctx,
        &mut pass,
        "box across zero",
        &[GranularObject::new(&cuboid, at)],
        0.1,
        area,
    );
}

#[test]
fn areas_wider_than_a_tile_are_rendered_in_tiles() {
    let Some(ctx) = context_or_skip("areas_wider_than_a_tile_are_rendered_in_tiles") else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    let side = terrain_gpu::granular::depth::MAX_TILE_SIDE
        .min(ctx.device.limits().max_texture_dimension_2d);
    let area = Rect::new(IVec2::new(-3, 0), UVec2::new(side + 37, 6));
    let ts = 0.01;
    let seam = (side as f32 - 3.0) * ts;
    let cuboid = TriMesh::cuboid(Vec3::new(0.2, 0.1, 0.02)).unwrap();
    let at = Affine3A::from_rotation_translation(
        Quat::from_rotation_x(0.2) * Quat::from_rotation_y(0.05),
        Vec3::new(seam + 0.0013, 0.5, 0.031),
    );
    let a = check(
        &ctx,
        &mut pass,
        "box across the tile seam",
        &[GranularObject::new(&cuboid, at)],
        ts,
        area,
    );
    assert!(a.footprint > 100);
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
fn edges_a_hair_off_sample_points_differ_only_at_the_edge() {
    let Some(ctx) = context_or_skip("edges_a_hair_off_sample_points_differ_only_at_the_edge")
    else {
        return;
    };
    let mut pass = DepthFromBelowPass::new(&ctx.device).unwrap();
    // 0.6 / 0.03 in f32 inputs is 20.000001 texels: the CPU leaves column 20 out, the GPU
    // (f32 position snapped to 1/256 texel) takes it in. A whole edge row or column of the
    // footprint may flip, never an interior column (`compare` asserts that).
    let cuboid = TriMesh::cuboid(Vec3::new(0.6, 0.1, 0.6)).unwrap();
    let objects = [GranularObject::new(
        &cuboid,
        Affine3A::from_translation(Vec3::new(1.2, 0.75, 1.2)),
    )];
    let area = Rect::new(IVec2::ZERO, UVec2::new(64, 64));
    let gpu = gpu_depth(&ctx, &mut pass, &objects, 0.03, area);
    let cpu = cpu_depth(&objects, 0.03, area);
    let a = compare_within("box with edges on sample points", &gpu, &cpu, 0.15);
    // At most the four edge lines of a 40 x 40 footprint.
    assert!(a.coverage_diff <= 4 * 41);
}

/// The comparison itself (no GPU): a height a little off on a steep slope passes, one
/// further off, or a little off on a gentle slope, fails; at an edge a height between the
/// CPU's around it passes.
#[test]
fn heights_must_stay_on_the_surface_around_them() {
    // A 6 x 6 footprint in an 8 x 8 grid, rising `step` units a column.
    let grid = |step: u32| {
        Grid::from_fn(8, 8, |x, y| {
            if (1..7).contains(&x) && (1..7).contains(&y) {
                1000 + step * x
            } else {
                NO_OBJECT
            }
        })
        .unwrap()
    };
    let with = |cpu: &Grid<u32>, (x, y): (u32, u32), g: u32| {
        let mut gpu = cpu.clone();
        *gpu.get_mut(x, y).unwrap() = g;
        gpu
    };
    let fails = |gpu: Grid<u32>, cpu: &Grid<u32>| {
        std::panic::catch_unwind(|| compare("off the surface", &gpu, cpu)).is_err()
    };
    // 400 units a column: 1 + 400 / 64 = 7 units pass, at the edge (6, 3) and inside (3, 3).
    let steep = grid(400);
    for at in [(6, 3), (3, 3)] {
        let c = steep.get(at.0, at.1).unwrap();
        compare("steep, 7 units up", &with(&steep, at, c + 7), &steep);
        assert!(fails(with(&steep, at, c + 8), &steep));
        assert!(fails(with(&steep, at, 9000), &steep));
    }
    // At the edge, a height between the CPU's around it passes; inside, it does not.
    compare("edge, 300 units down", &with(&steep, (6, 3), 3100), &steep);
    assert!(fails(with(&steep, (3, 3), 2200 - 300), &steep));
    // 10 units a column: one unit passes, two fail.
    let gentle = grid(10);
    compare("gentle, 1 unit up", &with(&gentle, (3, 3), 1031), &gentle);
    assert!(fails(with(&gentle, (3, 3), 1032), &gentle));
}
