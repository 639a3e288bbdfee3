//! Workspace commands. `cargo xtask ci` runs every check CI runs, in order, and names the step
//! that failed.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("ci") => ci(),
        Some("smoke") => smoke(),
        _ => {
            eprintln!("usage: cargo xtask <ci|smoke>");
            eprintln!("  ci     fmt, clippy, tests, docs and a demo smoke run (what CI runs)");
            eprintln!("  smoke  only the demo smoke run");
            std::process::exit(2);
        }
    }
}

/// The workspace root (xtask lives one level below it).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// Runs `cargo` with `args` (and extra environment) in the workspace root.
fn cargo(args: &[&str], env: &[(&str, &str)]) -> Result<()> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(args).current_dir(root());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let status = cmd
        .status()
        .with_context(|| format!("could not start cargo {}", args.join(" ")))?;
    if !status.success() {
        bail!("`cargo {}` exited with {status}", args.join(" "));
    }
    Ok(())
}

/// One named check of `ci`.
type Step = (&'static str, fn() -> Result<()>);

fn ci() -> Result<()> {
    let steps: [Step; 5] = [
        ("fmt", fmt),
        ("clippy", clippy),
        ("test", test),
        ("doc", doc),
        ("smoke", smoke),
    ];
    let total = Instant::now();
    for (name, step) in steps {
        let t = Instant::now();
        eprintln!("xtask ci: step `{name}` ...");
        step().with_context(|| format!("xtask ci: step `{name}` failed"))?;
        eprintln!(
            "xtask ci: step `{name}` ok in {:.1} s",
            t.elapsed().as_secs_f64()
        );
    }
    eprintln!(
        "xtask ci: all steps passed in {:.1} s",
        total.elapsed().as_secs_f64()
    );
    Ok(())
}

fn fmt() -> Result<()> {
    cargo(&["fmt", "--all", "--", "--check"], &[])
}

fn clippy() -> Result<()> {
    cargo(
        &[
            "clippy",
            "--workspace",
            "--all-targets",
            "--locked",
            "--",
            "-D",
            "warnings",
        ],
        &[],
    )
}

fn test() -> Result<()> {
    // GPU tests fail instead of skipping when no adapter is found (DESIGN.md).
    cargo(
        &["test", "--workspace", "--locked"],
        &[("TERRAIN_REQUIRE_GPU", "1")],
    )
}

fn doc() -> Result<()> {
    cargo(
        &["doc", "--workspace", "--no-deps", "--locked"],
        &[("RUSTDOCFLAGS", "-D warnings")],
    )
}

/// Runs the demo at a tiny size and checks that it wrote its frames and a sane report.
fn smoke() -> Result<()> {
    let out = root().join("target").join("ci-smoke");
    if out.exists() {
        std::fs::remove_dir_all(&out).context("could not clear the smoke output folder")?;
    }
    let out_s = out.to_string_lossy().into_owned();
    let frames = 4;
    cargo(
        &[
            "run",
            "--locked",
            "-p",
            "terrain-demo",
            "--",
            "--size",
            "96",
            "--frames",
            "4",
            "--seed",
            "7",
            "--out",
            &out_s,
        ],
        &[],
    )?;
    let report_path = out.join("report.json");
    let text = std::fs::read_to_string(&report_path)
        .with_context(|| format!("no report at {}", report_path.display()))?;
    let report: serde_json::Value =
        serde_json::from_str(&text).context("report.json is not valid JSON")?;
    let listed = report["frames"].as_array().map_or(0, Vec::len);
    if listed != frames {
        bail!("report.json lists {listed} frames, {frames} expected");
    }
    for (i, frame) in report["frames"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
    {
        let timings = frame["timings_ms"]
            .as_object()
            .with_context(|| format!("frame {i} has no timings_ms"))?;
        if timings.is_empty()
            || timings
                .values()
                .any(|v| !v.as_f64().is_some_and(|t| t >= 0.0))
        {
            bail!("frame {i} has empty or invalid timings: {timings:?}");
        }
        let file = frame["file"].as_str().unwrap_or_default();
        if !out.join(file).is_file() {
            bail!("frame {i}: image `{file}` is missing");
        }
    }
    if !out.join("terrain.png").is_file() {
        bail!("terrain.png is missing");
    }
    eprintln!("smoke: demo wrote {frames} frames and a valid report to {out_s}");
    Ok(())
}
