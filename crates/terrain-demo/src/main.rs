//! The demo: deforms a terrain with a scripted scenario and writes offline frame captures plus
//! `report.json` with per-frame timings. Everything it does is glue over the library crates.

mod camera_rig;
mod cli;
mod gpu_scene;
mod images;
mod report;
mod scenario;

use anyhow::{Context, Result, bail};
use clap::Parser;
use cli::Cli;
use glam::UVec2;
use gpu_scene::GpuScene;
use report::{FrameReport, Report};
use scenario::StampKind;
use std::collections::{BTreeMap, HashMap};
use std::time::Duration;
use std::time::Instant;
use terrain_core::io::{self, ReadLimits};
use terrain_core::{
    CoarseMap, DerivativeMap, HeightEncoding, HillshadeParams, TerrainParams, generate_coarse_map,
    hillshade,
};
use terrain_physics::{
    CollisionMirror, CpuRegionSource, ReadbackScheduler, RequestId, SchedulerConfig,
};

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
            let cells = (cli.size / 16 / defaults.base_period).max(1);
            let octaves = (u32::BITS - cells.leading_zeros()).clamp(1, defaults.octaves);
            let params = TerrainParams {
                size: UVec2::splat(cli.size),
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
    let mut gpu = if cli.no_gpu {
        None
    } else {
        match GpuScene::new(&map, scenario.footprint(), cli.resolution) {
            Ok(scene) => Some(scene),
            Err(e) => {
                eprintln!("warning: {e:#}; writing top-down overview frames only");
                None
            }
        }
    };
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

    let mut frames = Vec::with_capacity(cli.frames as usize);
    let mut thumbs = Vec::new();
    let thumb_every = cli.frames.div_ceil(12).max(1);
    let mut totals: BTreeMap<String, f64> = BTreeMap::new();
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

        let mut triangles = 0;
        let image = match gpu.as_mut() {
            Some(scene) => {
                let mut frame = scene.render(&camera)?;
                timings.insert("render".to_string(), frame.render.ms);
                if let Some(ts) = frame.render.timestamp_ms {
                    timestamps.insert("render".to_string(), ts);
                }
                timings.insert("lod".to_string(), frame.lod_ms);
                timings.insert("capture".to_string(), frame.capture_ms);
                triangles = frame.triangles;
                let uv = glam::Vec2::new(camera.position.x, camera.position.z) / map.extent_m();
                images::inset_overview(&mut frame.image, &overview, uv);
                frame.image
            }
            None => overview,
        };

        let t = Instant::now();
        let file = format!("frame_{index:04}.png");
        let path = cli.out.join(&file);
        io::write_png_rgba8(&path, &image)
            .with_context(|| format!("writing {}", path.display()))?;
        timings.insert("write".to_string(), ms(t));
        if index % thumb_every == thumb_every - 1 || index + 1 == cli.frames {
            let w = 320.min(image.width());
            let h = (u64::from(image.height()) * u64::from(w) / u64::from(image.width())) as u32;
            thumbs.push(images::downscale(&image, UVec2::new(w, h.max(1))));
        }

        for (k, v) in &timings {
            *totals.entry(k.clone()).or_default() += v;
        }
        frames.push(FrameReport {
            index,
            file,
            footprints: plan.count(StampKind::Footprint),
            craters: plan.count(StampKind::Crater),
            shockwaves: plan.count(StampKind::Shockwave),
            dirty_texels: dirty.iter().map(|r| r.area()).sum(),
            triangles,
            camera_clearance_m,
            readback_ms,
            timings_ms: timings,
            gpu_timestamps_ms: timestamps,
        });
    }
    io::write_png16(cli.out.join("terrain_final.png"), map.grid())?;
    write_summary(cli, &frames, &thumbs)?;

    let resolution = if gpu.is_some() {
        cli.resolution
    } else {
        overview_px
    };
    let report = Report {
        source,
        size: [size.x, size.y],
        texel_size_m: map.texel_size(),
        seed: cli.seed,
        adapter,
        backend,
        resolution: resolution.to_array(),
        load_ms,
        initial_normals_ms,
        frames,
        totals_ms: totals,
    };
    let json = serde_json::to_vec_pretty(&report)?;
    io::write_atomic(cli.out.join("report.json"), &json)?;
    eprintln!(
        "wrote {} frames of {}x{} to {} on {} ({})",
        cli.frames,
        resolution.x,
        resolution.y,
        cli.out.display(),
        report.adapter,
        report.backend,
    );
    Ok(())
}

/// Steps shown in the timing plot of `summary.png`, bottom to top.
const PLOTTED: [&str; 5] = ["stamp", "normals", "render", "capture", "write"];

/// `summary.png`: a contact sheet of frames above a stacked bar chart of the step timings.
fn write_summary(cli: &Cli, frames: &[FrameReport], thumbs: &[images::Image]) -> Result<()> {
    let series: Vec<Vec<f64>> = PLOTTED
        .iter()
        .map(|k| {
            frames
                .iter()
                .map(|f| f.timings_ms.get(*k).copied().unwrap_or(0.0))
                .collect()
        })
        .collect();
    let columns = 4;
    let plot = images::timing_plot(&series, UVec2::new(columns * 324 - 4, 160))?;
    let sheet = images::contact_sheet(thumbs, columns, 320, &plot)?;
    io::write_png_rgba8(cli.out.join("summary.png"), &sheet)?;
    Ok(())
}
