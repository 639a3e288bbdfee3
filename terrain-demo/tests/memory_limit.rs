//! Bounded memory: the demo estimates what a run needs from its flags before allocating and
//! refuses a run above `--max-memory` (one line, exit 2); a run it accepts stays within the
//! limit, measured as the peak resident memory of the whole process (GPU driver included)
//! that the demo reads from /proc/self/status (VmHWM) into report.json.

mod common;

use common::{demo, fresh_dir, report, run_within};
use std::path::Path;
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(300);

/// Runs the demo with `args` into `dir/out` and returns the exit code, stderr and report
/// (when one was written).
fn run(dir: &Path, args: &[&str]) -> (Option<i32>, String, Option<serde_json::Value>) {
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&out);
    let mut cmd = demo();
    cmd.args(args).arg("--out").arg(&out);
    let done = run_within(cmd, dir, LIMIT);
    let report = out.join("report.json").is_file().then(|| report(&out));
    (done.status.code(), done.stderr, report)
}

/// The memory section of a report: (limit, estimate, measured peak), in bytes.
fn memory(report: &serde_json::Value) -> (u64, u64, u64) {
    let m = &report["memory"];
    (
        m["limit_bytes"].as_u64().expect("limit_bytes"),
        m["estimate_bytes"].as_u64().expect("estimate_bytes"),
        m["peak_rss_bytes"]
            .as_u64()
            .expect("peak_rss_bytes (Linux)"),
    )
}

/// Runs `args` under `max`: it must be accepted and stay within the limit and within its own
/// estimate (whose parts add up). Returns the estimate and the report.
fn accepted(name: &str, dir: &Path, args: &[&str], max: &str) -> (u64, serde_json::Value) {
    let mut with_limit: Vec<&str> = args.to_vec();
    with_limit.extend(["--max-memory", max]);
    let (code, stderr, report) = run(dir, &with_limit);
    assert_eq!(code, Some(0), "{name}: {stderr}");
    let report = report.expect("report.json");
    let (limit, estimate, peak) = memory(&report);
    eprintln!(
        "{name}: estimate {} MiB, measured peak {} MiB, limit {} MiB",
        estimate >> 20,
        peak >> 20,
        limit >> 20
    );
    assert!(estimate <= limit, "{name}: accepted above the limit");
    assert!(
        peak <= estimate,
        "{name}: peak resident memory {peak} above the estimate {estimate}"
    );
    assert!(peak <= limit, "{name}: peak {peak} above the limit {limit}");
    let components = report["memory"]["estimate"].as_object().expect("estimate");
    let sum: u64 = components.values().filter_map(|v| v.as_u64()).sum();
    assert_eq!(sum, estimate, "{name}: the components add up");
    (estimate, report)
}

/// The same flags under a limit one MiB below `estimate` are refused with exit 2, one line,
/// before any frame.
fn refused_below(name: &str, dir: &Path, args: &[&str], estimate: u64) {
    let below = format!("{}", estimate - (1 << 20));
    let mut refused_args: Vec<&str> = args.to_vec();
    refused_args.extend(["--max-memory", &below]);
    let (code, stderr, report) = run(dir, &refused_args);
    assert_eq!(code, Some(2), "{name}: {stderr}");
    assert_eq!(stderr.lines().count(), 1, "{name}: one line: {stderr}");
    assert!(stderr.contains("--max-memory"), "{name}: {stderr}");
    assert!(report.is_none(), "{name}: refused before any frame");
    assert!(!dir.join("out/frame_0000.png").exists(), "{name}");
}

/// A run accepted under `max` stays within it and within its own estimate; the same flags
/// under a limit one MiB below the estimate are refused with exit 2 before any frame.
fn accepted_then_refused(name: &str, args: &[&str], max: &str) {
    let dir = fresh_dir(name);
    let (estimate, _) = accepted(name, &dir, args, max);
    refused_below(name, &dir, args, estimate);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cpu_runs_stay_within_their_estimate() {
    accepted_then_refused(
        "mem_default_cpu",
        &["--no-gpu", "--size", "512", "--frames", "3"],
        "1G",
    );
    accepted_then_refused(
        "mem_snow_cpu",
        &[
            "--no-gpu",
            "--scenario",
            "snow",
            "--size",
            "256",
            "--frames",
            "3",
        ],
        "1G",
    );
}

#[test]
fn gpu_runs_stay_within_their_estimate_driver_included() {
    let Some(ctx) = terrain_gpu::testing::context_or_skip("gpu_runs_stay_within_their_estimate")
    else {
        return;
    };
    // The child makes its own device; this one only told us there is an adapter.
    drop(ctx);
    accepted_then_refused(
        "mem_default_gpu",
        &["--size", "512", "--resolution", "320x180", "--frames", "3"],
        "2G",
    );
    accepted_then_refused(
        "mem_snow_gpu",
        &[
            "--scenario",
            "snow",
            "--size",
            "256",
            "--resolution",
            "320x180",
            "--frames",
            "3",
        ],
        "2G",
    );
}

#[test]
fn the_flyover_estimate_covers_its_budgets() {
    let dir = fresh_dir("mem_flyover");
    let args = |world: &Path| -> Vec<String> {
        [
            "--no-gpu",
            "--scenario",
            "flyover",
            "--size",
            "1024",
            "--ram-budget",
            "4",
            "--overview-size",
            "64",
            "--frames",
            "10",
            "--world",
            &world.display().to_string(),
        ]
        .map(String::from)
        .to_vec()
    };
    let built = args(&dir.join("world"));
    let built: Vec<&str> = built.iter().map(String::as_str).collect();
    // Building the world, then opening it: both within their estimates.
    let (build_estimate, report) = accepted("mem_flyover_build", &dir, &built, "1G");
    assert!(report["memory"]["estimate"]["world_build"].as_u64() > Some(0));
    let (open_estimate, report) = accepted("mem_flyover_open", &dir, &built, "1G");
    let components = &report["memory"]["estimate"];
    assert!(components.get("world_build").is_none(), "{components}");
    assert!(
        components["ram_pool"].as_u64() >= Some(4 << 20),
        "the RAM budget is counted: {components}"
    );
    refused_below("mem_flyover_open", &dir, &built, open_estimate);
    // A world that would be built is refused before it is.
    let fresh = dir.join("world_fresh");
    let unbuilt = args(&fresh);
    let unbuilt: Vec<&str> = unbuilt.iter().map(String::as_str).collect();
    refused_below("mem_flyover_build", &dir, &unbuilt, build_estimate);
    assert!(!fresh.join("manifest.json").exists(), "not built");
    // A RAM budget beyond any machine is refused at once.
    let world = dir.join("world").display().to_string();
    let (code, stderr, _) = run(
        &dir,
        &[
            "--no-gpu",
            "--scenario",
            "flyover",
            "--world",
            &world,
            "--ram-budget",
            "1048576",
            "--max-memory",
            "8G",
        ],
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("ram_pool"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn extreme_flags_are_refused_before_allocating() {
    let dir = fresh_dir("mem_extreme");
    // A 65536^2 map would need tens of GiB: refused in well under a second, not after
    // minutes of generating it.
    let (code, stderr, report) = run(&dir, &["--no-gpu", "--size", "65536", "--max-memory", "8G"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    assert!(
        stderr.contains("--max-memory") && stderr.contains("8.0 GiB"),
        "{stderr}"
    );
    assert!(report.is_none());
    // The largest frames with a GPU are refused under a small limit.
    let (code, stderr, _) = run(
        &dir,
        &[
            "--size",
            "64",
            "--resolution",
            "8192x8192",
            "--max-memory",
            "256M",
        ],
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("frames"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_long_thin_heightmap_makes_a_small_summary() {
    let dir = fresh_dir("mem_thin");
    // 16 x 4096 texels: the overview is 16 x 4096 pixels, and so is each frame without a GPU.
    let raw = dir.join("thin.r16");
    let samples: Vec<u8> = (0..16 * 4096u32)
        .flat_map(|i| ((i * 37) as u16).to_le_bytes())
        .collect();
    std::fs::write(&raw, samples).expect("write raw");
    let raw = raw.display().to_string();
    let (code, stderr, report) = run(
        &dir,
        &[
            "--no-gpu",
            "--heightmap",
            &raw,
            "--raw-size",
            "16x4096",
            "--overview-size",
            "4096",
            "--frames",
            "2",
        ],
    );
    assert_eq!(code, Some(0), "{stderr}");
    let summary = terrain_core::io::read_png_rgba8(
        dir.join("out/summary.png"),
        &terrain_core::io::ReadLimits::default(),
    )
    .expect("summary.png");
    // Thumbnails fit a 320 x 320 box: the sheet of 2 frames is a few hundred pixels tall (it
    // was 81 920 thumbnail pixels tall, 400 MiB, before thumbnails were bounded).
    assert!(
        summary.width() <= 1400 && summary.height() <= 1400,
        "summary.png is {}x{}",
        summary.width(),
        summary.height()
    );
    let (_, estimate, peak) = memory(&report.expect("report"));
    assert!(
        peak <= estimate,
        "peak {peak} above the estimate {estimate}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
