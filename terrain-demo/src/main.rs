//! The demo: deforms a terrain with a scripted scenario and writes offline frame captures plus
//! `report.json` with per-frame timings. Everything it does is glue over the library crates:
//! `scenarios` says what happens, `driver` runs the frames, `gpu_scene` is the GPU side.

mod camera_rig;
mod capture;
mod cli;
mod config;
mod console;
mod driver;
mod frame_plan;
mod gpu_scene;
#[cfg(test)]
mod gpu_truth;
mod images;
mod interrupt;
mod logging;
mod memory_estimate;
mod memory_limit;
mod overview;
mod progress;
mod ranges;
mod report;
mod scenarios;
mod summary;
mod timings;
mod usage_error;
mod validate;
mod writable;

use anyhow::Result;
use clap::{CommandFactory, FromArgMatches};
use cli::{Cli, Command};
use memory_estimate::RunShape;
use report::MemoryReport;
use usage_error::{INTERRUPTED_EXIT, USAGE_EXIT, UsageExt};

fn main() {
    quiet_vulkan_device_select();
    // --help ends with the valid range of every numeric flag and config key.
    let mut command = Cli::command().after_help(ranges::help_table());
    let parsed = command
        .try_get_matches_from_mut(std::env::args_os())
        .and_then(|m| Cli::from_arg_matches(&m));
    let cli = match parsed {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help and --version; a closed or full stdout is a failure, not a panic.
            if e.print().is_err() {
                std::process::exit(usage_error::FAILURE_EXIT);
            }
            return;
        }
        Err(e) => {
            // clap's whole message: the error, its tips and the usage line. A closed or full
            // stderr loses it, not the exit status.
            let _ = cli::explain_replaced_flags(e, &mut command).print();
            std::process::exit(USAGE_EXIT);
        }
    };
    logging::install(cli.verbose);
    interrupt::install(match cli.command {
        Some(Command::VerifyWorld { .. }) => interrupt::Stops::Check,
        _ => interrupt::Stops::Run,
    });
    match run(&cli) {
        Ok(Ended::Done) => {}
        Ok(Ended::Interrupted { frames }) => {
            console::note!(
                "interrupted after {frames} of {} frames: report.json lists them",
                cli.frames
            );
            std::process::exit(INTERRUPTED_EXIT);
        }
        Err(e) => {
            // One line: the error and its causes, skipping a cause whose text is already
            // shown (library errors often include their source in their own message).
            let mut line = e.to_string();
            for cause in e.chain().skip(1) {
                let text = cause.to_string();
                if !line.contains(&text) {
                    line.push_str(": ");
                    line.push_str(&text);
                }
            }
            if interrupt::requested() {
                // Ctrl-C during setup (a world build cancelled, say): no frame, no report.
                console::note!("interrupted: {line}");
                std::process::exit(INTERRUPTED_EXIT);
            }
            console::note!("error: {line}");
            std::process::exit(usage_error::exit_status(&e));
        }
    }
}

/// Turns off Mesa's Vulkan device-selection layer (`NODEVICE_SELECT=1`) unless the user
/// configured it (`MESA_VK_DEVICE_SELECT`) or turned it off already. The layer only reorders
/// adapters, which terrain-gpu ranks itself, and on a machine without a desktop session it
/// prints `error: XDG_RUNTIME_DIR is invalid or not set` twice on every run while probing
/// for a Wayland display nobody asked for.
#[allow(unsafe_code)]
fn quiet_vulkan_device_select() {
    let configured = std::env::var_os("MESA_VK_DEVICE_SELECT").is_some()
        || std::env::var_os("NODEVICE_SELECT").is_some();
    if !configured {
        // SAFETY: `set_var` races with threads reading the environment. This is the first
        // statement of `main`: no thread of ours, of the GPU driver or of any library exists
        // yet.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

/// How a run ended without an error.
enum Ended {
    /// Every frame asked for.
    Done,
    /// Ctrl-C: `frames` frames were done and reported.
    Interrupted { frames: usize },
}

fn run(cli: &Cli) -> Result<Ended> {
    match &cli.command {
        Some(Command::VerifyWorld { dir, repair, quiet }) => {
            if scenarios::world_files::verify_command(dir, *repair, *quiet)? {
                return Ok(Ended::Done);
            }
            std::process::exit(usage_error::FAILURE_EXIT);
        }
        Some(Command::PrintConfig { config: file }) => {
            let params = config::DemoParams::load(file.as_deref()).usage()?;
            console::stdout(&params.to_toml()?)?;
            return Ok(Ended::Done);
        }
        None => {}
    }
    validate::flags(cli)?;
    let params = config::DemoParams::load(cli.config.as_deref()).usage()?;
    // Where the run writes, before anything long starts: its outputs, and the streamed
    // world it builds and writes deformations back into.
    writable::check_dir(&cli.out, "--out")?;
    if matches!(
        cli.scenario,
        cli::ScenarioKind::Flyover | cli::ScenarioKind::World
    ) {
        writable::check_dir(&cli.world, "--world")?;
    }
    // What the run needs, from its flags and input headers, before anything large exists.
    let limit = cli.max_memory.unwrap_or_else(memory_limit::default_limit);
    let shape = RunShape::of(cli)?.with_params(&params);
    let needed = shape.estimate();
    memory_limit::check(&needed, limit).usage()?;
    // The heightmap is read only as it was measured for the estimate (the default scenario's,
    // or the one a flyover builds its world from).
    let heightmap = match shape.flyover {
        Some(f) => match f.build {
            Some(scenarios::world_files::WorldBuild::Heightmap(planned)) => Some(planned),
            _ => None,
        },
        None => shape.heightmap,
    };
    let mut scenario = scenarios::open(cli, &params, heightmap)?;
    let config = serde_json::json!({ "flags": cli, "params": params });
    let report = driver::run(
        cli,
        &params,
        config,
        scenario.as_mut(),
        MemoryReport::new(limit, &needed),
    )?;
    Ok(if report.interrupted {
        Ended::Interrupted {
            frames: report.frames.len(),
        }
    } else {
        Ended::Done
    })
}
