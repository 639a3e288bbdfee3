//! GPU-vs-CPU tests of the granular deformation passes: penetration, jump flooding,
//! displacement and slope evening bit for bit, normals within a tolerance, the volume sum
//! exactly.

use glam::{IVec2, UVec2, Vec3};
use terrain_core::granular::*;
use terrain_core::{FixedPointMap, Grid, Rect};
use terrain_gpu::granular::{
    DisplacePass, FloodedArea, GpuGranularNormals, GranularArea, GranularNormalsPass,
    GranularScratch, JumpFloodPass, PenetrationPass, SlopePass, SlopeSettings, VolumePass,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{GpuContext, GpuError, GpuHeightMap};
use terrain_test_support::granular::empty_pen;

const UNITS: u32 = 10_000;

/// Asserts equality of two slices, reporting the number of differing entries and the first.
fn assert_same<T: PartialEq + std::fmt::Debug>(gpu: &[T], cpu: &[T], what: &str) {
    assert_eq!(gpu.len(), cpu.len(), "{what}: lengths");
    let bad: Vec<usize> = (0..gpu.len()).filter(|&i| gpu[i] != cpu[i]).collect();
    if let Some(&i) = bad.first() {
        panic!(
            "{what}: {} of {} entries differ; first at {i}: GPU {:?}, CPU {:?}",
            bad.len(),
            gpu.len(),
            gpu[i],
            cpu[i]
        );
    }
}

fn bumpy_map(w: u32, h: u32, amp: u32) -> FixedPointMap {
    let grid =
        Grid::from_fn(w, h, |x, y| 10_000 + pcg_hash(x * 7919 + y * 104_729) % amp).expect("grid");
    FixedPointMap::fixed_point(grid, UNITS, 0.05).expect("map")
}

/// A depth grid of `area`: a sunken disc (penetrating), a ring just above the terrain
/// (obstacles) and nothing elsewhere, plus a second small blob.
fn depth_of(map: &FixedPointMap, area: Rect) -> Grid<u32> {
    let c = area.size.as_vec2() * glam::Vec2::new(0.4, 0.55);
    let r = area.size.min_element() as f32 * 0.2;
    Grid::from_fn(area.size.x, area.size.y, |i, j| {
        let h = map.grid().as_slice()[map
            .grid()
            .index(area.min.x as u32 + i, area.min.y as u32 + j)];
        let d = (glam::Vec2::new(i as f32, j as f32) - c).length();
        let d2 = (glam::Vec2::new(i as f32, j as f32) - area.size.as_vec2() * 0.85).length();
        if d < r {
            h.saturating_sub(1500 + (pcg_hash(i * 31 + j) % 3000))
        } else if d < r + 2.0 {
            h + 2000
        } else if d2 < 2.5 {
            h - 700
        } else {
            NO_OBJECT
        }
    })
    .expect("depth")
}

struct Fixture {
    map: FixedPointMap,
    area: Rect,
    depth: Grid<u32>,
    pen: Grid<Penetration>,
}

fn fixture(map_size: UVec2, area: Rect) -> Fixture {
    let map = bumpy_map(map_size.x, map_size.y, 400);
    let depth = depth_of(&map, area);
    let mut pen = empty_pen(area.size);
    penetration_texture(&map, &depth, area, 5000, &mut pen).expect("pen");
    Fixture {
        map,
        area,
        depth,
        pen,
    }
}

const AREAS: [(u32, u32, i32, i32, u32, u32); 3] = [
    (64, 64, 0, 0, 64, 64),
    (80, 70, 7, 5, 53, 41),
    (100, 90, 30, 12, 37, 70),
];

/// The fixture's map on the GPU and scratch buffers for its area.
fn upload(ctx: &GpuContext, f: &Fixture) -> (GpuHeightMap<u32>, GranularScratch) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let gmap = GpuHeightMap::from_map(device, queue, &f.map).expect("upload");
    let scratch = GranularScratch::new(device, f.area.area()).expect("scratch");
    (gmap, scratch)
}

/// Records the depth upload, penetration and JFA of the fixture's area and submits them;
/// returns the flooded area.
fn gpu_front<'a>(
    ctx: &GpuContext,
    f: &Fixture,
    area: &GranularArea<'a>,
    metric: DistanceMetric,
    extra: bool,
) -> FloodedArea<'a> {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pen_pass = PenetrationPass::new(device).expect("pen pass");
    let mut jfa = JumpFloodPass::new(device).expect("jfa");
    let mut enc = device.create_command_encoder(&Default::default());
    pen_pass
        .upload_depth(device, queue, &mut enc, area, &f.depth)
        .expect("upload depth");
    pen_pass
        .encode(device, queue, &mut enc, area, 5000)
        .expect("encode pen");
    let flooded = jfa
        .encode(device, queue, &mut enc, area, metric, extra)
        .expect("encode jfa");
    queue.submit([enc.finish()]);
    pen_pass.recall();
    jfa.recall();
    flooded
}

/// The fixture's area over `gmap` and `scratch`.
fn area_of<'a>(
    ctx: &GpuContext,
    f: &Fixture,
    gmap: &'a GpuHeightMap<u32>,
    scratch: &'a GranularScratch,
) -> GranularArea<'a> {
    GranularArea::new(&ctx.device, gmap, f.area, scratch).expect("area")
}

#[test]
fn penetration_matches_cpu_bit_for_bit() {
    let Some(ctx) = context_or_skip("penetration_matches_cpu_bit_for_bit") else {
        return;
    };
    for (mw, mh, x, y, w, h) in AREAS {
        let f = fixture(
            UVec2::new(mw, mh),
            Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
        );
        let (gmap, scratch) = upload(&ctx, &f);
        gpu_front(
            &ctx,
            &f,
            &area_of(&ctx, &f, &gmap, &scratch),
            DistanceMetric::Euclidean,
            true,
        );
        let gpu = scratch
            .read_penetration(&ctx.device, &ctx.queue, f.area.area())
            .expect("read");
        ctx.check().expect("validation");
        assert_same(&gpu, f.pen.as_slice(), &format!("area {:?}", f.area));
        let kinds = |k: ColumnKind| gpu.iter().filter(|p| p.column_kind() == k).count();
        assert!(kinds(ColumnKind::Penetrating) > 0 && kinds(ColumnKind::Obstacle) > 0);
    }
}

#[test]
fn jump_flood_matches_cpu_bit_for_bit() {
    let Some(ctx) = context_or_skip("jump_flood_matches_cpu_bit_for_bit") else {
        return;
    };
    for metric in [
        DistanceMetric::Euclidean,
        DistanceMetric::Manhattan,
        DistanceMetric::Chebyshev,
    ] {
        for extra in [true, false] {
            for (mw, mh, x, y, w, h) in AREAS {
                let f = fixture(
                    UVec2::new(mw, mh),
                    Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
                );
                let (gmap, scratch) = upload(&ctx, &f);
                let area = area_of(&ctx, &f, &gmap, &scratch);
                let flooded = gpu_front(&ctx, &f, &area, metric, extra);
                assert_eq!(flooded.metric(), metric);
                let gpu = scratch
                    .read_seeds(&ctx.device, &ctx.queue, flooded.seed_grid(), f.area.area())
                    .expect("read");
                ctx.check().expect("validation");
                let cpu = jump_flood(&f.pen, f.area, metric, extra).expect("cpu");
                assert_same(&gpu, cpu.as_slice(), &format!("{metric:?} extra {extra}"));
            }
        }
    }
}

fn run_displace(method: DisplacementMethod, keep: u32) {
    let Some(ctx) = context_or_skip("displace") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = DisplacePass::new(device).expect("pass");
    for (mw, mh, x, y, w, h) in AREAS {
        let f = fixture(
            UVec2::new(mw, mh),
            Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
        );
        let (gmap, scratch) = upload(&ctx, &f);
        let area = area_of(&ctx, &f, &gmap, &scratch);
        let flooded = gpu_front(&ctx, &f, &area, DistanceMetric::Euclidean, true);
        let mut enc = device.create_command_encoder(&Default::default());
        scratch.clear_removed(&mut enc);
        pass.encode(device, queue, &mut enc, &flooded, method, keep)
            .expect("encode");
        queue.submit([enc.finish()]);
        pass.recall();
        let gpu = gmap.read(device, queue).expect("read");
        let removed = scratch.read_removed(device, queue).expect("removed");
        ctx.check().expect("validation");
        let seeds = jump_flood(&f.pen, f.area, DistanceMetric::Euclidean, true).expect("jfa");
        let mut cpu = f.map.clone();
        let cpu_removed = match method {
            DisplacementMethod::ClosestSeed => {
                displace_closest_seed(&mut cpu, &f.pen, &seeds, f.area, keep)
            }
            _ => displace_multiple_targets(&mut cpu, &f.pen, &seeds, f.area, keep),
        }
        .expect("cpu");
        assert_ne!(cpu, f.map, "nothing displaced");
        assert_same(
            gpu.grid().as_slice(),
            cpu.grid().as_slice(),
            &format!("{method:?} keep {keep} area {:?}", f.area),
        );
        assert_eq!(removed, cpu_removed);
        if keep == 32768 {
            assert_eq!(gpu.raw_sum(), f.map.raw_sum());
        }
    }
}

#[test]
fn displace_closest_seed_matches_cpu_bit_for_bit() {
    run_displace(DisplacementMethod::ClosestSeed, 32768);
    run_displace(DisplacementMethod::ClosestSeed, 12345);
}

#[test]
fn displace_multiple_targets_matches_cpu_bit_for_bit() {
    run_displace(DisplacementMethod::MultipleTargets, 32768);
    run_displace(DisplacementMethod::MultipleTargets, 20000);
}

/// Runs the iterative method on the GPU and on the CPU from the same penetration texture and
/// seeds, for every `(keep, iterations)`, and asserts equal maps and removed amounts.
fn check_iterative(
    ctx: &GpuContext,
    pass: &mut DisplacePass,
    f: &Fixture,
    metric: DistanceMetric,
    runs: &[(u32, u32)],
) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let (gmap, scratch) = upload(ctx, f);
    let area = area_of(ctx, f, &gmap, &scratch);
    let flooded = gpu_front(ctx, f, &area, metric, true);
    let seeds = jump_flood(&f.pen, f.area, metric, true).expect("jfa");
    for &(keep, iterations) in runs {
        // Every run starts from the fixture's map (the seeds stay in the scratch).
        gmap.write(queue, &f.map).expect("upload");
        let mut enc = device.create_command_encoder(&Default::default());
        scratch.clear_removed(&mut enc);
        let method = DisplacementMethod::Iterative { iterations };
        pass.encode(device, queue, &mut enc, &flooded, method, keep)
            .expect("encode");
        queue.submit([enc.finish()]);
        pass.recall();
        let gpu = gmap.read(device, queue).expect("read");
        let removed = scratch.read_removed(device, queue).expect("removed");
        ctx.check().expect("validation");
        let mut cpu = f.map.clone();
        let cpu_removed =
            displace_iterative(&mut cpu, &f.pen, &seeds, f.area, keep, iterations, metric)
                .expect("cpu");
        // Without seeds, nothing moves unless material is removed.
        let has_seed = f.pen.as_slice().iter().any(|p| p.seed_x != NO_SEED);
        assert!(
            (cpu != f.map) == (has_seed || keep < 32768),
            "nothing displaced"
        );
        let what = format!(
            "Iterative {metric:?} keep {keep} iterations {iterations} area {:?}",
            f.area
        );
        assert_same(gpu.grid().as_slice(), cpu.grid().as_slice(), &what);
        assert_eq!(removed, cpu_removed, "{what}");
        if keep == 32768 {
            assert_eq!(gpu.raw_sum(), f.map.raw_sum(), "{what}");
        }
    }
}

/// Keep factors of the other displacement tests, with even and odd iteration counts (the
/// final carried grid is either ping-pong buffer).
const ITERATIVE_RUNS: [(u32, u32); 6] = [
    (32768, 10),
    (32768, 1),
    (32768, 33),
    (12345, 10),
    (20000, 7),
    (12345, 0),
];

#[test]
fn displace_iterative_matches_cpu_bit_for_bit() {
    let Some(ctx) = context_or_skip("displace_iterative_matches_cpu_bit_for_bit") else {
        return;
    };
    let mut pass = DisplacePass::new(&ctx.device).expect("pass");
    for metric in [
        DistanceMetric::Euclidean,
        DistanceMetric::Manhattan,
        DistanceMetric::Chebyshev,
    ] {
        for (mw, mh, x, y, w, h) in AREAS {
            let f = fixture(
                UVec2::new(mw, mh),
                Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
            );
            // The passes really move material: more iterations give another map.
            let seeds = jump_flood(&f.pen, f.area, metric, true).expect("jfa");
            let moved = |it| {
                let mut m = f.map.clone();
                displace_iterative(&mut m, &f.pen, &seeds, f.area, 32768, it, metric).expect("cpu");
                m
            };
            assert_ne!(moved(0), moved(10), "{metric:?}: the passes moved nothing");
            check_iterative(&ctx, &mut pass, &f, metric, &ITERATIVE_RUNS);
        }
    }
}

/// An area without any seed (every column penetrates): the carried material stays on its
/// column, as on the CPU.
#[test]
fn displace_iterative_without_seeds_matches_cpu() {
    let Some(ctx) = context_or_skip("displace_iterative_without_seeds_matches_cpu") else {
        return;
    };
    let mut pass = DisplacePass::new(&ctx.device).expect("pass");
    let map = bumpy_map(40, 30, 400);
    let area = Rect::new(IVec2::new(3, 2), UVec2::new(20, 17));
    let depth = Grid::from_fn(area.size.x, area.size.y, |i, j| {
        map.grid().as_slice()[map.grid().index(3 + i, 2 + j)] - 800 - (i * 37 + j * 11) % 500
    })
    .expect("depth");
    let mut pen = empty_pen(area.size);
    penetration_texture(&map, &depth, area, 5000, &mut pen).expect("pen");
    assert!(
        pen.as_slice()
            .iter()
            .all(|p| p.column_kind() == ColumnKind::Penetrating)
    );
    let f = Fixture {
        map,
        area,
        depth,
        pen,
    };
    check_iterative(
        &ctx,
        &mut pass,
        &f,
        DistanceMetric::Euclidean,
        &[(32768, 10), (12345, 3)],
    );
}

/// The iterative method carries its iteration count; a count over the bound is refused
/// before anything is recorded, by the GPU pass as by the CPU step.
#[test]
fn displace_refuses_too_many_iterations() {
    let Some(ctx) = context_or_skip("displace_refuses_too_many_iterations") else {
        return;
    };
    let f = fixture(UVec2::new(64, 64), Rect::from_size(UVec2::new(64, 64)));
    let (gmap, scratch) = upload(&ctx, &f);
    let area = area_of(&ctx, &f, &gmap, &scratch);
    let flooded = gpu_front(&ctx, &f, &area, DistanceMetric::Euclidean, true);
    let mut pass = DisplacePass::new(&ctx.device).expect("pass");
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    let method = DisplacementMethod::Iterative {
        iterations: MAX_ITERATIONS + 1,
    };
    let r = pass.encode(&ctx.device, &ctx.queue, &mut enc, &flooded, method, 32768);
    assert!(matches!(
        r,
        Err(GpuError::Granular(GranularError::ParamOutOfRange { .. }))
    ));
    ctx.check().expect("validation");
}

/// Areas that are empty, off the map or larger than the scratch are refused when the area is
/// made, before any pass sees them.
#[test]
fn bad_areas_are_refused() {
    let Some(ctx) = context_or_skip("bad_areas_are_refused") else {
        return;
    };
    let f = fixture(UVec2::new(64, 64), Rect::from_size(UVec2::new(64, 64)));
    let (gmap, _) = upload(&ctx, &f);
    let small = GranularScratch::new(&ctx.device, 100).expect("scratch");
    for rect in [
        Rect::new(IVec2::new(3, 3), UVec2::new(0, 5)),
        Rect::new(IVec2::new(60, 0), UVec2::new(8, 8)),
        Rect::new(IVec2::new(-1, 0), UVec2::new(8, 8)),
        Rect::new(IVec2::ZERO, UVec2::new(11, 10)),
    ] {
        assert!(
            GranularArea::new(&ctx.device, &gmap, rect, &small).is_err(),
            "{rect:?}"
        );
    }
    GranularArea::new(
        &ctx.device,
        &gmap,
        Rect::new(IVec2::ZERO, UVec2::new(10, 10)),
        &small,
    )
    .expect("an area that fits");
}

fn run_slope(method: SlopeMethod) {
    let Some(ctx) = context_or_skip("slope") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = SlopePass::new(device).expect("pass");
    for (mw, mh, x, y, w, h) in AREAS {
        // Steep noise so that many columns flow.
        let mut f = fixture(
            UVec2::new(mw, mh),
            Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
        );
        f.map = bumpy_map(mw, mh, 6000);
        penetration_texture(&f.map, &f.depth, f.area, 5000, &mut f.pen).expect("pen");
        let (gmap, scratch) = upload(&ctx, &f);
        let area = area_of(&ctx, &f, &gmap, &scratch);
        gpu_front(&ctx, &f, &area, DistanceMetric::Euclidean, true);
        let thresholds = [300, 424];
        let settings = SlopeSettings {
            thresholds,
            roughness_q15: 19661,
            iterations: 5,
        };
        let mut enc = device.create_command_encoder(&Default::default());
        pass.encode(device, queue, &mut enc, &area, method, &settings)
            .expect("encode");
        queue.submit([enc.finish()]);
        pass.recall();
        let gpu = gmap.read(device, queue).expect("read");
        ctx.check().expect("validation");
        let mut cpu = f.map.clone();
        match method {
            SlopeMethod::Scatter => {
                even_out_slopes_scatter(&mut cpu, &f.pen, f.area, thresholds, 19661, 5)
            }
            SlopeMethod::Interleaved => {
                even_out_slopes_interleaved(&mut cpu, &f.pen, f.area, thresholds, 19661, 5)
            }
        }
        .expect("cpu");
        assert_ne!(cpu, f.map, "no slope moved");
        assert_same(
            gpu.grid().as_slice(),
            cpu.grid().as_slice(),
            &format!("{method:?} area {:?}", f.area),
        );
        assert_eq!(gpu.raw_sum(), f.map.raw_sum());
    }
}

#[test]
fn slope_scatter_matches_cpu_bit_for_bit() {
    run_slope(SlopeMethod::Scatter);
}

#[test]
fn slope_interleaved_matches_cpu_bit_for_bit() {
    run_slope(SlopeMethod::Interleaved);
}

#[test]
fn normals_match_cpu_within_tolerance() {
    let Some(ctx) = context_or_skip("normals_match_cpu_within_tolerance") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = bumpy_map(70, 60, 3000);
    let area = Rect::new(IVec2::new(0, 5), UVec2::new(50, 55));
    let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut pass = GranularNormalsPass::new(device).expect("pass");
    let normals = GpuGranularNormals::for_map(device, &gmap).expect("normals");
    for blur in [0u32, 1, 3] {
        let mut enc = device.create_command_encoder(&Default::default());
        enc.clear_buffer(normals.buffer(), 0, None);
        pass.encode(device, queue, &mut enc, &gmap, &normals, area)
            .expect("encode");
        pass.encode_blur(device, queue, &mut enc, &normals, area, blur)
            .expect("blur");
        queue.submit([enc.finish()]);
        pass.recall();
        let grid = normals.read(device, queue).expect("download");
        ctx.check().expect("validation");
        let gpu: Vec<[f32; 4]> = grid.as_slice().iter().map(|v| v.to_array()).collect();
        let mut cpu = Grid::new(70, 60, Vec3::ZERO).expect("grid");
        symmetric_normals(&map, area, &mut cpu).expect("cpu");
        blur_normals(&mut cpu, area, blur).expect("blur");
        let mut worst = 0f32;
        for (g, c) in gpu.iter().zip(cpu.as_slice()) {
            worst = worst.max((Vec3::new(g[0], g[1], g[2]) - *c).abs().max_element());
        }
        assert!(worst < 1e-5, "blur {blur}: max error {worst}");
        // w holds the float copy of the heights (metres) inside the area, after any blur.
        let mut floats = Grid::new(70, 60, 0.0f32).expect("grid");
        float_heights(&map, area, &mut floats).expect("floats");
        for y in area.min.y..area.max().y {
            for x in area.min.x..area.max().x {
                let i = (y * 70 + x) as usize;
                let want = floats.as_slice()[i];
                assert!(
                    (gpu[i][3] - want).abs() <= 1e-6 * want.abs().max(1.0),
                    "height at {x},{y}: {} vs {want}",
                    gpu[i][3]
                );
            }
        }
    }
}

/// Checks the areas used by the tests are inside their maps (guards the fixture itself).
#[test]
fn fixture_areas_are_valid() {
    for (mw, mh, x, y, w, h) in AREAS {
        let r = Rect::new(IVec2::new(x, y), UVec2::new(w, h));
        assert!(Rect::from_size(UVec2::new(mw, mh)).contains_rect(&r));
    }
}

/// Random heights over the whole u32 range, with runs near `u32::MAX`.
fn random_heights(w: u32, h: u32, seed: u32) -> FixedPointMap {
    let grid = Grid::from_fn(w, h, |x, y| {
        let r = pcg_hash(pcg_hash(x + seed) ^ (y.wrapping_mul(0x9e37_79b9)));
        match r % 4 {
            0 => u32::MAX - (r >> 8) % 1000,
            1 => r,
            2 => r % 10_000,
            _ => u32::MAX,
        }
    })
    .expect("grid");
    FixedPointMap::fixed_point(grid, UNITS, 0.05).expect("map")
}

/// The GPU sum equals the u64 sum on the CPU and the sum of the whole map downloaded, on
/// random maps with values near `u32::MAX` and sizes that are not multiples of the workgroup
/// (including one that needs several rounds per invocation).
#[test]
fn volume_sum_is_exact() {
    let Some(ctx) = context_or_skip("volume_sum_is_exact") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut volume = VolumePass::new(device).expect("pass");
    let sizes = [
        (1, 1),
        (7, 3),
        (255, 1),
        (16, 16),
        (257, 3),
        (100, 91),
        (513, 511),
        (1100, 1003),
    ];
    for (k, (w, h)) in sizes.into_iter().enumerate() {
        let map = random_heights(w, h, k as u32);
        let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
        let gpu = volume.sum(device, queue, &gmap).expect("sum");
        ctx.check().expect("validation");
        let cpu: u64 = map.grid().as_slice().iter().map(|&v| u64::from(v)).sum();
        assert_eq!(gpu, cpu, "{w} x {h}");
        assert_eq!(map.raw_sum(), cpu);
        // The whole-map download agrees (the check this pass replaces).
        let downloaded = gmap.read(device, queue).expect("read").raw_sum();
        assert_eq!(gpu, downloaded, "{w} x {h}");
    }
    // Every value u32::MAX: the high word carries on every add.
    let full =
        FixedPointMap::fixed_point(Grid::new(2048, 1031, u32::MAX).expect("grid"), UNITS, 0.05)
            .expect("map");
    let gmap = GpuHeightMap::from_map(device, queue, &full).expect("upload");
    assert_eq!(
        volume.sum(device, queue, &gmap).expect("sum"),
        2048 * 1031 * u64::from(u32::MAX)
    );
    // Several sums recorded into one encoder before one read: the last one is read.
    let zeros = GpuHeightMap::from_map(
        device,
        queue,
        &FixedPointMap::fixed_point(Grid::new(9, 9, 0).expect("grid"), UNITS, 0.05).expect("map"),
    )
    .expect("upload");
    let mut enc = device.create_command_encoder(&Default::default());
    volume
        .encode(device, queue, &mut enc, &gmap)
        .expect("encode");
    volume
        .encode(device, queue, &mut enc, &zeros)
        .expect("encode");
    queue.submit([enc.finish()]);
    volume.recall();
    assert_eq!(volume.read(device).expect("read"), 0);
    ctx.check().expect("validation");
}
