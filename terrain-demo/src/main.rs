//! The demo: deforms a terrain with a scripted scenario and writes offline frame captures plus
//! `report.json` with per-frame timings. Everything it does is glue over the library crates.

mod camera_rig;
mod capture;
mod cli;
mod gpu_scene;
mod images;
mod report;
mod scenario;
mod snow;

use anyhow::{Context, Result, bail};
use capture::Capture;
use clap::Parser;
use cli::{Cli, ScenarioKind};
use glam::UVec2;
use gpu_scene::GpuScene;
use report::{FrameReport, Report};
use scenario::StampKind;
use std::collections::{BTreeMap, HashMap};
use std::time::Duration;
use std::time::Instant;
use terrain_core::io::{self, ReadLimits};
use terrain_core::{
    CoarseMap, DerivativeMap, HeightEncoding, HillshadeParams, TerrainParams, TextureStamp,
    generate_coarse_map, hillshade,
};
use terrain_physics::{
    CollisionMirror, CpuRegionSource, ReadbackScheduler, RequestId, SchedulerConfig,
};

/// Side of the default scenario's procedural terrain in texels (205 m at 0.1 m).
const DEFAULT_SIZE: u32 = 2048;

/// Seconds of scenario time per frame (30 frames per second).
const FRAME_DT: f64 = 1.0 / 30.0;

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help and --version.
            let _ = e.print();
            return;
        }
        Err(e) => {
            let msg = e.to_string();
            let first = msg.lines().next().unwrap_or("invalid arguments");
            eprintln!("{first} (see --help)");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(&cli) {
        // One line: the error and its causes, skipping a cause whose text is already shown
        // (library errors often include their source in their own message).
        let mut line = e.to_string();
        for cause in e.chain().skip(1) {
            let text = cause.to_string();
            if !line.contains(&text) {
                line.push_str(": ");
                line.push_str(&text);
            }
        }
        eprintln!("error: {line}");
        std::process::exit(2);
    }
}

/// Milliseconds since `t`.
fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn load_map(cli: &Cli) -> Result<(CoarseMap, String)> {
    if !(cli.texel_size.is_finite() && cli.texel_size > 0.0) {
        bail!(
            "--texel-size must be a positive number of metres, got {}",
            cli.texel_size
        );
    }
    if !(cli.max_height.is_finite() && cli.max_height > 0.0) {
        bail!(
            "--max-height must be a positive number of metres, got {}",
            cli.max_height
        );
    }
    let encoding = HeightEncoding::spanning::<u16>(0.0, cli.max_height)?;
    let limits = ReadLimits::default();
    match &cli.heightmap {
        None => {
            let defaults = TerrainParams::default();
            // Octaves whose lattice cells are finer than ~16 texels only add noise that hides
            // the deformations, so stop there.
            let size = cli.size.unwrap_or(DEFAULT_SIZE);
            let cells = (size / 16 / defaults.base_period).max(1);
            let octaves = (u32::BITS - cells.leading_zeros()).clamp(1, defaults.octaves);
            let params = TerrainParams {
                size: UVec2::splat(size),
                seed: cli.seed,
                octaves,
                // Gentler small scales than the library default: a walkable landscape.
                persistence: 0.4,
                ..defaults
            };
            let map = generate_coarse_map(&params, encoding, cli.texel_size)?;
            Ok((map, "procedural".into()))
        }
        Some(path) => {
            let grid = match cli.raw_size {
                Some(size) => io::read_raw16(path, size, &limits),
                None => io::read_png16(path, &limits),
            }
            .with_context(|| format!("cannot use heightmap {}", path.display()))?;
            let min = grid.size().min_element();
            if min < 16 {
                bail!(
                    "heightmap {} is {}: at least 16x16 needed",
                    path.display(),
                    grid.size()
                );
            }
            let map = CoarseMap::coarse(grid, encoding, cli.texel_size)?;
            Ok((map, path.display().to_string()))
        }
    }
}

fn run(cli: &Cli) -> Result<()> {
    match cli.scenario {
        ScenarioKind::Default => run_default(cli),
        ScenarioKind::Snow => run_snow(cli),
    }
}

/// The default scenario: footprints, craters and a shockwave on the coarse-map.
fn run_default(cli: &Cli) -> Result<()> {
    std::fs::create_dir_all(&cli.out)
        .with_context(|| format!("cannot create output folder {}", cli.out.display()))?;
    let t = Instant::now();
    let (mut map, source) = load_map(cli)?;
    let load_ms = ms(t);
    io::write_png16(cli.out.join("terrain.png"), map.grid())?;

    let t = Instant::now();
    let mut normals = DerivativeMap::from_map(&map);
    let initial_normals_ms = ms(t);

    let mut scenario = scenario::Scenario::new(map.extent_m(), cli.seed)?;
    let mut gpu = open_gpu(cli, &map, Some(scenario.footprint()));
    let (adapter, backend) = gpu
        .as_ref()
        .map_or(("none".into(), "none".into()), GpuScene::adapter);

    let size = map.size();
    let overview_scale = cli.overview_size as f32 / size.max_element() as f32;
    let overview_px = (size.as_vec2() * overview_scale)
        .round()
        .as_uvec2()
        .max(UVec2::ONE);
    let shade = HillshadeParams::with_size(overview_px);

    // Collision: the mirror follows the map through the readback scheduler (from the GPU map
    // via RegionReadback, or from the CPU map without a GPU); the camera is a body on it.
    let encoding = map.encoding();
    let mirror = CollisionMirror::from_map(&map)?;
    let mut scheduler = ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default())?;
    let mut cpu_source = gpu.is_none().then(|| CpuRegionSource::new(map.clone()));
    let mut requested_at: HashMap<RequestId, Instant> = HashMap::new();
    let start_xz = scenario.walker_start();
    let mut rig = camera_rig::CameraRig::new(start_xz, terrain_core::bilinear(&map, start_xz)?);
    // Simulated time: the scenario runs at 30 frames per second whatever the render speed.
    let sim_start = Instant::now();

    let mut capture = Capture::new(&cli.out, cli.frames);
    for index in 0..cli.frames {
        let mut timings = BTreeMap::new();
        let mut timestamps = BTreeMap::new();
        let mut plan = scenario.plan_next_frame()?;
        // Collision first: 33 ms of scenario time after the last frame's deformations the quiet
        // gap has passed, so the scheduler requests their regions now; arrivals apply here too.
        let now = sim_start + Duration::from_secs_f64(f64::from(index) * FRAME_DT);
        let t = Instant::now();
        let report = match (gpu.as_mut(), cpu_source.as_mut()) {
            (Some(scene), _) => scene.update_collision(&mut scheduler, &mirror, now)?,
            (None, Some(source)) => {
                *source.map_mut() = map.clone();
                scheduler.update(now, source, &mirror)?
            }
            (None, None) => anyhow::bail!("no region source"),
        };
        for (id, _) in &report.requested {
            requested_at.insert(*id, Instant::now());
        }
        let readback_ms = report
            .applied
            .iter()
            .filter_map(|(id, _)| requested_at.remove(id))
            .map(ms)
            .reduce(f64::max);
        let mut physics_ms = ms(t);

        // The deformations: on the GPU map (rendered) and on the CPU map (overview).
        if let Some(scene) = gpu.as_mut() {
            let deformed = scene.deform(&plan, scenario.crater())?;
            let (stamp, normals) = (deformed.stamp, deformed.normals);
            for (i, rect) in deformed.rects {
                let bound = scenario::Scenario::bound(&plan.deformations[i], encoding)?;
                scheduler.note_deformation(rect, bound, now)?;
            }
            for (step, t) in [("stamp", stamp), ("normals", normals)] {
                timings.insert(step.to_string(), t.ms);
                if let Some(ts) = t.timestamp_ms {
                    timestamps.insert(step.to_string(), ts);
                }
            }
        }
        let t = Instant::now();
        let dirty_by_deformation = scenario.apply_cpu(&mut map, &mut plan)?;
        let dirty: Vec<_> = dirty_by_deformation.iter().flatten().copied().collect();
        for rect in &dirty {
            normals.update_rect(&map, *rect)?;
        }
        let cpu_ms = ms(t);
        let cpu_key = if gpu.is_some() { "cpu_mirror" } else { "stamp" };
        timings.insert(cpu_key.to_string(), cpu_ms);

        // Without a GPU the CPU map is the source; its deformations are noted here.
        if gpu.is_none() {
            for (d, rects) in plan.deformations.iter().zip(&dirty_by_deformation) {
                let bound = scenario::Scenario::bound(d, encoding)?;
                for rect in rects {
                    scheduler.note_deformation(*rect, bound, now)?;
                }
            }
        }
        let t = Instant::now();
        let collider = mirror.collider();
        let ground = scheduler.ground(&collider);
        let camera = rig.step(plan.walker, FRAME_DT as f32, &ground, |p| {
            terrain_core::bilinear(&map, p).unwrap_or(0.0)
        })?;
        let eye = rig.eye();
        let camera_clearance_m =
            eye.y - terrain_core::bilinear(&map, glam::Vec2::new(eye.x, eye.z))?;
        physics_ms += ms(t);
        timings.insert("physics".to_string(), physics_ms);

        let t = Instant::now();
        let overview = hillshade(&map, &normals, &shade)?;
        timings.insert("overview".to_string(), ms(t));

        let (image, triangles) = render_frame(
            gpu.as_mut(),
            &camera,
            overview,
            map.extent_m(),
            &mut timings,
            &mut timestamps,
        )?;

        capture.push(
            &image,
            FrameReport {
                index,
                file: String::new(),
                footprints: plan.count(StampKind::Footprint),
                craters: plan.count(StampKind::Crater),
                shockwaves: plan.count(StampKind::Shockwave),
                dirty_texels: dirty.iter().map(|r| r.area()).sum(),
                triangles,
                camera_clearance_m,
                readback_ms,
                timings_ms: timings,
                gpu_timestamps_ms: timestamps,
                granular_volume: None,
                granular_removed: None,
            },
        )?;
    }
    io::write_png16(cli.out.join("terrain_final.png"), map.grid())?;
    let resolution = if gpu.is_some() {
        cli.resolution
    } else {
        overview_px
    };
    let report = capture.finish(Report {
        source,
        scenario: "default".into(),
        size: [size.x, size.y],
        texel_size_m: map.texel_size(),
        seed: cli.seed,
        adapter,
        backend,
        resolution: resolution.to_array(),
        load_ms,
        initial_normals_ms,
        frames: Vec::new(),
        totals_ms: BTreeMap::new(),
    })?;
    print_done(cli, &report);
    Ok(())
}

/// The GPU scene for `map`, or `None` (after saying why) with `--no-gpu` or without an adapter:
/// the run then writes top-down overview frames.
fn open_gpu(cli: &Cli, map: &CoarseMap, footprint: Option<&TextureStamp>) -> Option<GpuScene> {
    if cli.no_gpu {
        return None;
    }
    match GpuScene::new(map, footprint, cli.resolution) {
        Ok(scene) => Some(scene),
        Err(e) => {
            eprintln!("warning: {e:#}; writing top-down overview frames only");
            None
        }
    }
}

/// The frame image: the 3D render from `camera` with `overview` inset when there is a GPU
/// scene (its timings go into `timings` / `timestamps`), else `overview` itself; and the
/// triangles drawn.
fn render_frame(
    gpu: Option<&mut GpuScene>,
    camera: &terrain_gpu::Camera,
    overview: images::Image,
    extent: glam::Vec2,
    timings: &mut BTreeMap<String, f64>,
    timestamps: &mut BTreeMap<String, f64>,
) -> Result<(images::Image, u64)> {
    let Some(scene) = gpu else {
        return Ok((overview, 0));
    };
    let mut frame = scene.render(camera)?;
    timings.insert("render".to_string(), frame.render.ms);
    if let Some(ts) = frame.render.timestamp_ms {
        timestamps.insert("render".to_string(), ts);
    }
    timings.insert("lod".to_string(), frame.lod_ms);
    timings.insert("capture".to_string(), frame.capture_ms);
    let uv = glam::Vec2::new(camera.position.x, camera.position.z) / extent;
    images::inset_overview(&mut frame.image, &overview, uv);
    Ok((frame.image, frame.triangles))
}

/// The closing line of a run.
fn print_done(cli: &Cli, report: &Report) {
    eprintln!(
        "wrote {} frames of {}x{} to {} on {} ({})",
        report.frames.len(),
        report.resolution[0],
        report.resolution[1],
        cli.out.display(),
        report.adapter,
        report.backend,
    );
}

/// Side of the snow field in texels by default (25.6 m at 0.05 m).
const SNOW_SIZE: u32 = 512;

/// The snow scenario: a vehicle and a walker cross a snow field; the granular simulation
/// (terrain-core's reference) deforms it, the clipmap renders it, the camera walks on it.
fn run_snow(cli: &Cli) -> Result<()> {
    if cli.heightmap.is_some() {
        bail!("--heightmap is not used by the snow scenario (it generates its snow field)");
    }
    std::fs::create_dir_all(&cli.out)
        .with_context(|| format!("cannot create output folder {}", cli.out.display()))?;
    let size = cli.size.unwrap_or(SNOW_SIZE);
    let t = Instant::now();
    let params = terrain_core::granular::GranularParams::snow();
    let mut snow = snow::SnowScenario::new(size, cli.seed, params)?;
    let mut coarse = snow.coarse_map()?;
    let load_ms = ms(t);
    io::write_png16(cli.out.join("terrain.png"), coarse.grid())?;

    let mut gpu = open_gpu(cli, &coarse, None);
    if let Some(scene) = gpu.as_mut() {
        // A snow field is white at any height; only steep rims shade to rock.
        scene.set_ramp(-20.0, -10.0);
    }
    let (adapter, backend) = gpu
        .as_ref()
        .map_or(("none".into(), "none".into()), GpuScene::adapter);
    let overview_px = UVec2::splat(cli.overview_size.min(size));
    let shade = HillshadeParams::with_size(overview_px);
    // The field is deformed on the CPU here, so the collision mirror takes each frame's map
    // directly (no readback needed); the camera walks on it behind the vehicle.
    let mirror = CollisionMirror::from_map(&coarse)?;
    let start = glam::Vec2::new(coarse.extent_m().x * 0.45, 0.5);
    let mut rig = camera_rig::CameraRig::new(start, terrain_core::bilinear(&coarse, start)?);
    let mut capture = Capture::new(&cli.out, cli.frames);
    for _ in 0..cli.frames {
        let mut timings = BTreeMap::new();
        let mut timestamps = BTreeMap::new();
        let t = Instant::now();
        let frame = snow.step()?;
        timings.insert("granular".to_string(), ms(t));
        coarse = snow.coarse_map()?;
        let t = Instant::now();
        mirror.apply_next(terrain_core::Rect::from_size(coarse.size()), coarse.grid())?;
        let collider = mirror.collider();
        let camera = rig.step(frame.vehicle, FRAME_DT as f32, &collider, |p| {
            snow.height(p)
        })?;
        let eye = rig.eye();
        let camera_clearance_m =
            eye.y - terrain_core::bilinear(&coarse, glam::Vec2::new(eye.x, eye.z))?;
        timings.insert("physics".to_string(), ms(t));

        let t = Instant::now();
        let normals = DerivativeMap::from_map(&coarse);
        let overview = hillshade(&coarse, &normals, &shade)?;
        timings.insert("overview".to_string(), ms(t));
        if let Some(scene) = gpu.as_mut() {
            let upload = scene.upload(&coarse)?;
            timings.insert("normals".to_string(), upload.ms);
        }
        let (image, triangles) = render_frame(
            gpu.as_mut(),
            &camera,
            overview,
            coarse.extent_m(),
            &mut timings,
            &mut timestamps,
        )?;
        capture.push(
            &image,
            FrameReport {
                index: 0,
                file: String::new(),
                footprints: 0,
                craters: 0,
                shockwaves: 0,
                dirty_texels: frame
                    .report
                    .active_areas
                    .iter()
                    .map(|a| a.rect.area())
                    .sum(),
                triangles,
                camera_clearance_m,
                readback_ms: None,
                timings_ms: timings,
                gpu_timestamps_ms: timestamps,
                granular_volume: Some(frame.report.volume),
                granular_removed: Some(snow.removed()),
            },
        )?;
    }
    io::write_png16(cli.out.join("terrain_final.png"), coarse.grid())?;
    let resolution = if gpu.is_some() {
        cli.resolution
    } else {
        overview_px
    };
    let report = capture.finish(Report {
        source: "procedural snow field".into(),
        scenario: "snow".into(),
        size: [size, size],
        texel_size_m: coarse.texel_size(),
        seed: cli.seed,
        adapter,
        backend,
        resolution: resolution.to_array(),
        load_ms,
        initial_normals_ms: 0.0,
        frames: Vec::new(),
        totals_ms: BTreeMap::new(),
    })?;
    print_done(cli, &report);
    Ok(())
}
