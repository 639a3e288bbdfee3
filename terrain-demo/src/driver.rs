//! The run every scenario shares: output folder, GPU scene (or none), overview, the frame loop
//! (advance the scenario, update the overview, render, capture), and at the end
//! `terrain_final.png`, `summary.png` and `report.json`. Ctrl-C ends the loop after the frame
//! in progress; the end is the same, over the frames done.

use crate::capture::{self, Capture};
use crate::cli::{Cli, LodArg, ScenarioKind};
use crate::config::DemoParams;
use crate::gpu_scene::GpuScene;
use crate::images;
use crate::interrupt;
use crate::memory_limit::format_bytes;
use crate::progress::Progress;
use crate::report::{FrameReport, MemoryReport, Report, SCHEMA_VERSION, ToolInfo};
use crate::scenarios::{FRAME_DT, FrameContext, Scenario, heightmap};
use crate::timings::{Step, Timings};
use crate::usage_error::UsageExt;
use anyhow::{Context, Result};
use glam::Vec2;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use terrain_core::HillshadeOverview;
use terrain_core::io;
use terrain_lod::{CdlodConfig, LodMetric};

/// Runs `scenario` for `cli.frames` frames (fewer after Ctrl-C) into `cli.out` and returns
/// the report written; `params` are the run's parameters (the GPU scene takes its style and
/// readback ring from them), `config_json` the configuration report.json records, `memory`
/// the limit and the estimate the run was accepted on.
pub fn run(
    cli: &Cli,
    params: &DemoParams,
    config_json: serde_json::Value,
    scenario: &mut dyn Scenario,
    memory: MemoryReport,
) -> Result<Report> {
    std::fs::create_dir_all(&cli.out)
        .with_context(|| format!("cannot create output folder {}", cli.out.display()))
        .usage()?;
    let removed = capture::remove_old_outputs(&cli.out)?;
    if removed > 0 {
        tracing::info!(removed, folder = %cli.out.display(), "removed the outputs of an earlier run");
    }
    let mut capture = Capture::new(&cli.out, cli.frames, cli.warmup)?;
    let terrain = cli.out.join("terrain.png");
    capture::write_file(&terrain, &io::encode_png16(scenario.map().grid())?)
        .with_context(|| format!("writing {}", terrain.display()))?;

    let mut gpu = open_gpu(cli, params, scenario)?;
    let (adapter, backend) = gpu
        .as_ref()
        .map_or(("none".into(), "none".into()), GpuScene::adapter);
    let overview_px = scenario.overview_size(cli.overview_size);
    // The overview (the frames without a GPU) shades like the frames: materials or the ramp.
    let materials = params.style.shading == crate::config::ShadingParam::Materials;
    let mut overview =
        crate::overview::overview(scenario.map(), overview_px, materials, scenario.holes())?;
    // Scenario time: 30 frames per second whatever the render speed.
    let sim_start = Instant::now();
    let mut progress = Progress::new(cli.frames, cli.quiet);
    // A failure during the run ends the loop; the report and the contact sheet of the frames
    // done are still written, then the error is returned.
    let mut failure: Option<anyhow::Error> = None;
    for index in 0..cli.frames {
        if interrupt::requested() {
            break;
        }
        let now = sim_start + Duration::from_secs_f64(f64::from(index) * FRAME_DT);
        let step = FrameStep {
            index,
            now,
            scenario: &mut *scenario,
            gpu: gpu.as_mut(),
            overview: &mut overview,
            capture: &mut capture,
        };
        if let Err(e) = step.run() {
            failure = Some(e.context(format!("frame {index}")));
            break;
        }
        progress.frames_done(index + 1);
    }
    progress.finish();
    let finish = match scenario.finish(gpu.as_mut()) {
        Ok(finish) => finish,
        Err(e) => {
            failure.get_or_insert(e.context("ending the run"));
            Default::default()
        }
    };
    // The last granular measures and the GPU timestamps still on their way go to the frames
    // they belong to.
    capture.credit_granular(&finish.granular);
    if let Some(scene) = gpu.as_mut() {
        match scene.flush_gpu_timings() {
            Ok(figures) => capture.credit_gpu(&figures),
            Err(e) => {
                failure.get_or_insert(e.context("ending the run"));
            }
        }
    }
    let terrain_final = cli.out.join("terrain_final.png");
    let written = io::encode_png16(scenario.map().grid())
        .and_then(|png| capture::write_file(&terrain_final, &png))
        .with_context(|| format!("writing {}", terrain_final.display()));
    if let Err(e) = written {
        failure.get_or_insert(e);
    }

    let done = capture.done();
    let info = scenario.info();
    let map = scenario.map();
    let resolution = if gpu.is_some() {
        cli.resolution
    } else {
        overview_px
    };
    let report = capture.finish(Report {
        schema_version: SCHEMA_VERSION,
        tool: ToolInfo::current(),
        config: config_json,
        source: info.source.clone(),
        scenario: info.name.into(),
        size: map.size().to_array(),
        texel_size_m: map.texel_size(),
        height_encoding: info.heights.as_ref().map(|h| h.encoding.clone()),
        heightmap: info.heights.as_ref().and_then(|h| h.heightmap.clone()),
        nodata: info.heights.as_ref().and_then(|h| h.nodata.clone()),
        camera: info.camera,
        seed: cli.seed,
        adapter,
        backend,
        gpu_timing: gpu.as_ref().map(GpuScene::gpu_timing),
        resolution: resolution.to_array(),
        load_ms: info.load_ms,
        initial_normals_ms: info.initial_normals_ms,
        written_back_tiles: finish.written_back_tiles,
        frames_requested: cli.frames,
        interrupted: failure.is_none() && done < cli.frames,
        error: failure.as_ref().map(|e| format!("{e:#}")),
        memory,
        frames: Vec::new(),
        totals_ms: BTreeMap::new(),
        warmup_frames: 0,
        steps_ms: BTreeMap::new(),
        frame_thread_cpu_ms: None,
    });
    let report = match (report, failure) {
        (Ok(_), Some(e)) => {
            crate::console::note!(
                "the run failed after {done} of {} frames: {} lists them, with summary.png",
                cli.frames,
                cli.out.join("report.json").display()
            );
            return Err(e);
        }
        (Err(written), Some(e)) => {
            crate::console::note!(
                "warning: the report of the failed run is incomplete: {written:#}"
            );
            return Err(e);
        }
        (Err(written), None) => return Err(written),
        (Ok(report), None) => report,
    };
    if !cli.quiet {
        crate::console::note!(
            "wrote {} frames of {}x{} to {} on {} ({})",
            report.frames.len(),
            report.resolution[0],
            report.resolution[1],
            cli.out.display(),
            report.adapter,
            report.backend,
        );
    }
    // The estimate is meant to bound the peak: say so where it did not.
    let m = &report.memory;
    if let Some(peak) = m.peak_rss_bytes
        && peak > m.estimate_bytes
    {
        crate::console::note!(
            "warning: peak resident memory {} above the estimate of {} (limit {})",
            format_bytes(peak),
            format_bytes(m.estimate_bytes),
            format_bytes(m.limit_bytes)
        );
    }
    Ok(report)
}

/// One frame of the loop: advance the scenario, update the overview, render (or take the
/// overview as the frame), capture.
struct FrameStep<'a, 'c> {
    index: u32,
    now: Instant,
    scenario: &'a mut dyn Scenario,
    gpu: Option<&'a mut GpuScene>,
    overview: &'a mut HillshadeOverview,
    capture: &'a mut Capture<'c>,
}

impl FrameStep<'_, '_> {
    fn run(self) -> Result<()> {
        let Self {
            index,
            now,
            scenario,
            mut gpu,
            overview,
            capture,
        } = self;
        // The frame thread's CPU clock, from here to the capture.
        let clock = crate::timings::Clock::start();
        let mut timings = Timings::default();
        let frame = scenario.advance(&mut FrameContext {
            now,
            gpu: gpu.as_deref_mut(),
            timings: &mut timings,
        })?;
        let overlaid = timings.time(Step::Overview, || {
            overview.update(scenario.map(), &frame.dirty, scenario.holes())?;
            anyhow::Ok(scenario.overlay(overview.image()))
        })?;
        let overview_image = overlaid.as_ref().unwrap_or(overview.image());
        let report = FrameReport {
            index,
            file: String::new(),
            stats: frame.stats,
            triangles: 0,
            lod: None,
            vertices: None,
            max_screen_error_px: None,
            max_vertex_jump_px: None,
            refined: None,
            camera_clearance_m: frame.camera_clearance_m,
            timings_ms: BTreeMap::new(),
            gpu_timestamps_ms: BTreeMap::new(),
            frame_thread_cpu_ms: None,
            gpu_objects: None,
        };
        match gpu {
            // The 3D frame with the overview inset, the camera marked on it.
            Some(scene) => {
                scene.update_lod(scenario.map(), &frame.dirty, &mut timings)?;
                let mut rendered = scene.render(&frame.camera, &mut timings)?;
                // The frame's work ends here: the popping probe and the inset are the
                // capture's.
                let frame_thread_cpu_ms = own_cpu_ms(clock, &timings);
                let max_vertex_jump_px = scene.lod_jump_px(scenario.map(), &frame.camera);
                let eye = frame.camera.position;
                let uv = Vec2::new(eye.x, eye.z) / scenario.map().extent_m();
                images::inset_overview(&mut rendered.image, overview_image, uv);
                let report = FrameReport {
                    triangles: rendered.triangles,
                    lod: Some(rendered.lod.mode),
                    vertices: Some(rendered.lod.vertices),
                    max_screen_error_px: rendered.lod.max_screen_error_px,
                    max_vertex_jump_px,
                    refined: rendered.lod.refined,
                    gpu_objects: Some(scene.live_objects()),
                    frame_thread_cpu_ms,
                    ..report
                };
                capture.push(&rendered.image, report, timings)
            }
            // Without a GPU the overview is the frame.
            None => {
                let report = FrameReport {
                    frame_thread_cpu_ms: own_cpu_ms(clock, &timings),
                    ..report
                };
                capture.push(overview_image, report, timings)
            }
        }
    }
}

/// The GPU scene for the scenario's map, prepared by the scenario; `None` (after saying why)
/// with `--no-gpu` or without an adapter: the run then writes top-down overview frames.
fn open_gpu(
    cli: &Cli,
    params: &DemoParams,
    scenario: &mut dyn Scenario,
) -> Result<Option<GpuScene>> {
    // The flags were checked together before the run (`validate::flags`).
    let tess_config = crate::validate::tess_config(cli).usage()?;
    // `--color` is read and checked even without a GPU: a wrong file is the user's to fix. A
    // streamed world took it into its colour tiles when it opened.
    let colors = match cli.scenario {
        ScenarioKind::Default => heightmap::color_layer(cli, scenario.map().size()).usage()?,
        _ => None,
    };
    if cli.no_gpu {
        return Ok(None);
    }
    let ring = params.scheduler.max_in_flight;
    let mut scene = match GpuScene::new(scenario.map(), cli.resolution, ring) {
        Ok(scene) => scene,
        Err(e) => {
            // A DEM larger than one GPU buffer is what the streamed flyover is for.
            let hint = if cli.heightmap.is_some() && cli.scenario == ScenarioKind::Default {
                " (a heightmap too large for the GPU's buffers is streamed by --scenario flyover)"
            } else {
                ""
            };
            crate::console::note!("warning: {e:#}; writing top-down overview frames only{hint}");
            return Ok(None);
        }
    };
    scenario.prepare_gpu(&mut scene)?;
    scene.apply_style(&params.style);
    match cli.lod {
        LodArg::Cdlod => {
            let reach = scene.clipmap_reach_m();
            let config = cdlod_config(cli, scenario.cdlod_extent(), reach)?;
            scenario.enable_cdlod(&mut scene, config)?;
        }
        LodArg::Tessellated => {
            // The error metric reads no density map.
            let density = !cli.no_density_map && cli.target_error.is_none();
            scenario.enable_tessellation(&mut scene, tess_config, density)?;
        }
        LodArg::Clipmap => {}
    }
    if let Some(colors) = &colors {
        scene.set_color_layer(colors)?;
    }
    // Craters and footprints paint dirt, and granular trails darken the snow, where the
    // frames shade with materials; a map too large for the layer's buffer keeps the
    // autoshader alone.
    if params.style.shading == crate::config::ShadingParam::Materials {
        let painted = match cli.scenario {
            ScenarioKind::Default => scene.enable_material_effects(),
            ScenarioKind::Snow => scene.enable_granular_trails(),
            ScenarioKind::Flyover | ScenarioKind::World => Ok(()),
        };
        if let Err(e) = painted {
            crate::console::note!("warning: no material effects: {e:#}");
        }
    }
    Ok(Some(scene))
}

/// The CDLOD quadtree for a heightfield of `size` texels that draws as far as `reach_m` (the clipmap's reach, so both
/// draw as far: terrain-lod's `CdlodConfig::for_map`), with the metric and morph of the flags.
fn cdlod_config(
    cli: &Cli,
    (size, wrap, texel_size): (glam::UVec2, terrain_core::WrapMode, f32),
    reach_m: f32,
) -> Result<CdlodConfig> {
    let config = CdlodConfig::for_map(size, wrap, texel_size, reach_m)
        .context("--lod cdlod")
        .usage()?;
    let config = CdlodConfig {
        metric: match cli.target_error {
            Some(tau_px) => LodMetric::ScreenSpace { tau_px },
            None => LodMetric::Distance,
        },
        morph: !cli.no_morph,
        ..config
    };
    config.validate().context("--target-error").usage()?;
    Ok(config)
}

/// The frame thread's own CPU milliseconds since `clock` started: its CPU time less what
/// `timings` holds of steps that are not its own work (report.json's `frame_thread_cpu_ms`).
fn own_cpu_ms(clock: crate::timings::Clock, timings: &Timings) -> Option<f64> {
    clock
        .cpu_ms()
        .map(|ms| (ms - timings.cpu_not_own_ms()).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::timings::{Clock, Step};

    /// The frame thread's own CPU time leaves out what it spent in GPU submits and the
    /// capture, and keeps its own steps.
    #[test]
    #[cfg(any(target_os = "linux", target_os = "android"))]
    fn the_frame_threads_own_cpu_leaves_out_gpu_submits() {
        let clock = Clock::start();
        let mut x = 0u64;
        while clock.cpu_ms().expect("thread CPU clock") < 20.0 {
            x = std::hint::black_box(x.wrapping_add(1));
        }
        let mut timings = Timings::default();
        timings.add_cpu(Step::Render, Some(12.0));
        timings.add_cpu(Step::Capture, Some(3.0));
        timings.add_cpu(Step::Cache, Some(4.0));
        let own = own_cpu_ms(clock, &timings).expect("thread CPU clock");
        assert!((5.0..12.0).contains(&own), "{own} ms: about 20 - 15");
    }
}
