//! The interactive viewer: a window over the procedural deformable terrain, a fly camera,
//! clicks that stamp craters and footprints, mode keys, wireframe, on-screen frame timings.
//!
//! ```sh
//! cargo run --release -p terrain-demo --bin terrain-viewer
//! viewer --frames 30 --screenshot shot.png --script-builtin --resolution 320x240
//! ```
//!
//! Keys: W A S D fly, Space or E up, Shift or Q down, drag with either button to look, wheel
//! changes the speed; left click a crater, right click a footprint; F wireframe, L LOD mode,
//! T detail mode, + and - clipmap levels, Escape quits. Built for X11 (Wayland desktops run it
//! through XWayland); runs on the software adapter (lavapipe) too.
//!
//! Glue over the library crates only: terrain-core makes the map and stamps it on the CPU,
//! terrain-gpu stamps, lights and draws it, terrain-lod places the clipmap.

#![forbid(unsafe_code)]

mod app;
mod fly_camera;
mod gpu;
mod input;
mod input_script;
mod modes;
mod overlay;
mod picking;
mod present;
mod terrain;

use anyhow::{Context, Result, anyhow, bail};
use clap::Parser;
use glam::UVec2;
use std::path::PathBuf;
use std::process::ExitCode;
use winit::event_loop::EventLoop;

/// Interactive viewer of the deformable terrain.
#[derive(Debug, Parser)]
#[command(name = "terrain-viewer", version)]
struct Args {
    /// Side of the procedural terrain in texels (0.1 m each).
    #[arg(long, default_value_t = 1024)]
    size: u32,
    /// Seed of the procedural terrain.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Window size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_resolution)]
    resolution: UVec2,
    /// Clipmap levels at start (+ and - change them).
    #[arg(long, default_value_t = 5)]
    levels: u32,
    /// Do not wait for the display's refresh.
    #[arg(long)]
    no_vsync: bool,
    /// Draw this many frames, then exit (with a fixed 1/30 s step per frame: scripted runs
    /// fly the same path at any frame rate). Prints the mean frame timings.
    #[arg(long)]
    frames: Option<u32>,
    /// Write the last frame as PNG (with --frames).
    #[arg(long, requires = "frames")]
    screenshot: Option<PathBuf>,
    /// Scripted input: a file of `FRAME EVENT ARGS` lines (see input_script.rs).
    #[arg(long, conflicts_with = "script_builtin")]
    script: Option<PathBuf>,
    /// The built-in input script: fly forward, turn, stamp a crater at the screen's centre.
    #[arg(long)]
    script_builtin: bool,
}

fn parse_resolution(s: &str) -> Result<UVec2, String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{s:?} is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("{v:?}: {e}"));
    let size = UVec2::new(parse(w)?, parse(h)?);
    if size.min_element() < 16 || size.max_element() > 8192 {
        return Err(format!("{s}: each side must lie in 16..=8192"));
    }
    Ok(size)
}

/// winit's error without the source location it prefixes (`os error at FILE:LINE: `).
fn os_message(e: &winit::error::EventLoopError) -> String {
    let text = e.to_string();
    match text.split_once(".rs:") {
        Some((_, rest)) => rest
            .split_once(": ")
            .map_or(text.clone(), |(_, msg)| msg.to_string()),
        None => text,
    }
}

fn run(args: Args) -> Result<()> {
    if !(16..=16_384).contains(&args.size) {
        bail!("--size must lie in 16..=16384, got {}", args.size);
    }
    let script = match (&args.script, args.script_builtin) {
        (Some(path), _) => {
            let text = read_script(path)
                .with_context(|| format!("cannot read the script {}", path.display()))?;
            Some(
                input_script::InputScript::parse(&text)
                    .with_context(|| format!("in {}", path.display()))?,
            )
        }
        (None, true) => Some(input_script::InputScript::parse(input_script::BUILTIN)?),
        (None, false) => None,
    };
    if let (Some(script), Some(frames)) = (&script, args.frames)
        && script.last_frame() >= frames
    {
        eprintln!(
            "viewer: warning: the script has events up to frame {}, past the {frames} frames run",
            script.last_frame()
        );
    }
    // The window system first: without a display there is nothing to do.
    let event_loop =
        EventLoop::new().map_err(|e| anyhow!("cannot open a window: {}", os_message(&e)))?;
    let terrain = terrain::Terrain::procedural(args.size, args.seed)?;
    let settings = app::Settings {
        resolution: args.resolution,
        frames: args.frames,
        screenshot: args.screenshot,
        script,
        gpu: gpu::GpuOptions {
            // Scripted runs draw as fast as they can.
            vsync: !args.no_vsync && args.frames.is_none(),
            levels: args.levels.clamp(2, terrain_lod::clipmap::MAX_LEVELS),
        },
    };
    let mut app = app::App::new(settings, terrain)?;
    event_loop.run_app(&mut app)?;
    match app.error.take() {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("viewer: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The largest input script read (a million events is about 30 MB).
const MAX_SCRIPT_BYTES: u64 = 256 << 20;

/// The text of a script file: a regular file (a named pipe would block, a device never end)
/// of at most [`MAX_SCRIPT_BYTES`], read through a bound in case it grows meanwhile.
fn read_script(path: &std::path::Path) -> Result<String> {
    use std::io::Read;
    // Opened without blocking (opening a named pipe would wait for a writer), then checked.
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // O_NONBLOCK, by value: std has no name for it.
        let nonblock = if cfg!(any(target_os = "linux", target_os = "android")) {
            0o4000
        } else {
            0x0004
        };
        options.custom_flags(nonblock);
    }
    let file = options.open(path)?;
    if !file.metadata()?.is_file() {
        bail!("not a regular file");
    }
    let mut bytes = Vec::new();
    file.take(MAX_SCRIPT_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_SCRIPT_BYTES {
        bail!("longer than {MAX_SCRIPT_BYTES} bytes");
    }
    Ok(String::from_utf8(bytes)?)
}
