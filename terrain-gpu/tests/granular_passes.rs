//! GPU-vs-CPU tests of the granular deformation passes: penetration, jump flooding,
//! displacement and slope evening bit for bit, normals within a tolerance, and the chained step.

use glam::{IVec2, UVec2, Vec3};
use terrain_core::granular::*;
use terrain_core::{FixedPointMap, Grid, Rect};
use terrain_gpu::GpuContext;
use terrain_gpu::granular::{
    DisplacePass, GpuGranularMap, GranularNormalsPass, GranularScratch, JumpFloodPass,
    PenetrationPass, SlopePass,
};
use terrain_gpu::testing::context_or_skip;

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

fn empty_pen(size: UVec2) -> Grid<Penetration> {
    Grid::new(
        size.x,
        size.y,
        Penetration {
            seed_x: 0,
            seed_y: 0,
            kind: 0,
            penetration: 0,
        },
    )
    .expect("grid")
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

/// Uploads the fixture and records penetration + JFA; returns (gpu map, scratch, seeds index).
fn gpu_front(
    ctx: &GpuContext,
    f: &Fixture,
    metric: DistanceMetric,
    extra: bool,
) -> (GpuGranularMap, GranularScratch, usize) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let gmap = GpuGranularMap::from_map(device, queue, &f.map).expect("upload");
    let scratch = GranularScratch::new(device, f.area.area()).expect("scratch");
    let pen_pass = PenetrationPass::new(device).expect("pen pass");
    let jfa = JumpFloodPass::new(device).expect("jfa");
    let depth = PenetrationPass::upload_depth(device, &f.depth);
    let mut enc = device.create_command_encoder(&Default::default());
    pen_pass
        .encode(device, &mut enc, &gmap, &depth, f.area, 5000, &scratch)
        .expect("encode pen");
    let idx = jfa
        .encode(
            device,
            &mut enc,
            gmap.size(),
            f.area,
            metric,
            extra,
            &scratch,
        )
        .expect("encode jfa");
    queue.submit([enc.finish()]);
    (gmap, scratch, idx)
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
        let (_, scratch, _) = gpu_front(&ctx, &f, DistanceMetric::Euclidean, true);
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
                let (_, scratch, idx) = gpu_front(&ctx, &f, metric, extra);
                let gpu = scratch
                    .read_seeds(&ctx.device, &ctx.queue, idx, f.area.area())
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
    let pass = DisplacePass::new(device).expect("pass");
    for (mw, mh, x, y, w, h) in AREAS {
        let f = fixture(
            UVec2::new(mw, mh),
            Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
        );
        let (gmap, scratch, idx) = gpu_front(&ctx, &f, DistanceMetric::Euclidean, true);
        let mut enc = device.create_command_encoder(&Default::default());
        scratch.clear_removed(&mut enc);
        pass.encode(device, &mut enc, &gmap, f.area, method, keep, idx, &scratch)
            .expect("encode");
        queue.submit([enc.finish()]);
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
    pass: &DisplacePass,
    f: &Fixture,
    metric: DistanceMetric,
    runs: &[(u32, u32)],
) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let (_, scratch, idx) = gpu_front(ctx, f, metric, true);
    let seeds = jump_flood(&f.pen, f.area, metric, true).expect("jfa");
    for &(keep, iterations) in runs {
        let gmap = GpuGranularMap::from_map(device, queue, &f.map).expect("upload");
        let mut enc = device.create_command_encoder(&Default::default());
        scratch.clear_removed(&mut enc);
        pass.encode_iterative(
            device, &mut enc, &gmap, f.area, keep, iterations, metric, idx, &scratch,
        )
        .expect("encode");
        queue.submit([enc.finish()]);
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
    let pass = DisplacePass::new(&ctx.device).expect("pass");
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
            check_iterative(&ctx, &pass, &f, metric, &ITERATIVE_RUNS);
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
    let pass = DisplacePass::new(&ctx.device).expect("pass");
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
        &pass,
        &f,
        DistanceMetric::Euclidean,
        &[(32768, 10), (12345, 3)],
    );
}

#[test]
fn displace_encode_refuses_iterative_without_its_settings() {
    let Some(ctx) = context_or_skip("displace_encode_refuses_iterative_without_its_settings")
    else {
        return;
    };
    let f = fixture(UVec2::new(64, 64), Rect::from_size(UVec2::new(64, 64)));
    let (gmap, scratch, idx) = gpu_front(&ctx, &f, DistanceMetric::Euclidean, true);
    let pass = DisplacePass::new(&ctx.device).expect("pass");
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    let r = pass.encode(
        &ctx.device,
        &mut enc,
        &gmap,
        f.area,
        DisplacementMethod::Iterative,
        32768,
        idx,
        &scratch,
    );
    assert!(r.is_err());
    ctx.check().expect("validation");
}

fn run_slope(method: SlopeMethod) {
    let Some(ctx) = context_or_skip("slope") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let pass = SlopePass::new(device).expect("pass");
    for (mw, mh, x, y, w, h) in AREAS {
        // Steep noise so that many columns flow.
        let mut f = fixture(
            UVec2::new(mw, mh),
            Rect::new(IVec2::new(x, y), UVec2::new(w, h)),
        );
        f.map = bumpy_map(mw, mh, 6000);
        penetration_texture(&f.map, &f.depth, f.area, 5000, &mut f.pen).expect("pen");
        let (gmap, scratch, _) = gpu_front(&ctx, &f, DistanceMetric::Euclidean, true);
        let thresholds = [300, 424];
        let mut enc = device.create_command_encoder(&Default::default());
        pass.encode(
            device, &mut enc, &gmap, f.area, method, thresholds, 19661, 5, &scratch,
        )
        .expect("encode");
        queue.submit([enc.finish()]);
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
    let gmap = GpuGranularMap::from_map(device, queue, &map).expect("upload");
    let pass = GranularNormalsPass::new(device).expect("pass");
    let normals = GranularNormalsPass::normal_buffer(device, &gmap).expect("buf");
    let scratch = GranularNormalsPass::normal_buffer(device, &gmap).expect("buf");
    for blur in [0u32, 1, 3] {
        let mut enc = device.create_command_encoder(&Default::default());
        enc.clear_buffer(&normals, 0, None);
        pass.encode(device, &mut enc, &gmap, &normals, &scratch, area, blur)
            .expect("encode");
        queue.submit([enc.finish()]);
        let bytes =
            terrain_gpu::download::download_bytes(device, queue, &normals, 0, normals.size())
                .expect("download");
        ctx.check().expect("validation");
        let gpu: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
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
