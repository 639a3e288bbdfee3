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
        Some("package") => package(),
        Some("golden") => golden(),
        _ => {
            eprintln!("usage: cargo xtask <ci|smoke|package|golden>");
            eprintln!("  ci      fmt, clippy, tests, docs, package, demo smoke (what CI runs)");
            eprintln!("  smoke   only the demo smoke runs (default backend, then GL)");
            eprintln!("  package package and verify the publishable crates (`cargo package`)");
            eprintln!("  golden  regenerate the render test's golden image (never done by tests)");
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
    let steps: [Step; 7] = [
        ("fmt", fmt),
        ("clippy", clippy),
        ("test", test),
        ("doc", doc),
        ("package", package),
        ("examples", examples),
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

/// Packages every publishable crate as crates.io would receive it and verifies that each
/// package builds on its own from its `.crate` (cargo >= 1.90 packages workspace members that
/// depend on one another through a local registry, without publishing them first).
///
/// Verification is kept: it builds the world again (the packaged manifests carry none of the
/// workspace's profiles), measured at 69 s from cold and about 10 s warm on the project's
/// 2-core machine. Resolving the packages' dependencies reads the crates.io index.
/// Removes cargo's extracted copies of earlier workspace packages. `cargo package` verifies
/// against a local registry of the freshly packaged crates, cached under
/// `$CARGO_HOME/registry/{src,cache}/-<hash>` by the registry's path; cargo does not extract a
/// package again when a copy of the same name and version is there, so a second run from the
/// same folder (or another checkout sharing the target folder) would verify against the old
/// sources. Only those overlay folders (their names start with `-`) are removed.
fn clear_package_overlays() -> Result<()> {
    let home = std::env::var_os("CARGO_HOME")
        .map(std::path::PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| std::path::PathBuf::from(h).join(".cargo")));
    let Some(home) = home else {
        return Ok(());
    };
    for kind in ["src", "cache", "index"] {
        let Ok(entries) = std::fs::read_dir(home.join("registry").join(kind)) else {
            continue;
        };
        for entry in entries.flatten() {
            if entry.file_name().to_string_lossy().starts_with('-') {
                std::fs::remove_dir_all(entry.path())
                    .with_context(|| format!("removing {}", entry.path().display()))?;
            }
        }
    }
    Ok(())
}

fn package() -> Result<()> {
    let crates = publishable_crates()?;
    if crates.is_empty() {
        bail!("no publishable crate found in `cargo metadata`");
    }
    clear_package_overlays()?;
    // Verification builds our packaged crates as registry crates, which cargo never rebuilds
    // for a changed source (registry packages are immutable to it): build them in a target
    // folder of their own and drop our crates' artifacts there first; wgpu and the other
    // dependencies stay built.
    let target = root().join("target").join("package-verify");
    for sub in ["deps", ".fingerprint", "build"] {
        let Ok(entries) = std::fs::read_dir(target.join("debug").join(sub)) else {
            continue;
        };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with("terrain") || name.starts_with("libterrain") {
                let path = entry.path();
                let removed = if path.is_dir() {
                    std::fs::remove_dir_all(&path)
                } else {
                    std::fs::remove_file(&path)
                };
                removed.with_context(|| format!("removing {}", path.display()))?;
            }
        }
    }
    let target_s = target.to_string_lossy().into_owned();
    let mut args = vec!["package", "--allow-dirty", "--target-dir", &target_s];
    for name in &crates {
        args.extend(["-p", name.as_str()]);
    }
    cargo(&args, &[])?;
    eprintln!("package: {} crates packaged and verified", crates.len());
    Ok(())
}

/// The workspace members without `publish = false`, from `cargo metadata`.
fn publishable_crates() -> Result<Vec<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--no-deps", "--locked"])
        .current_dir(root())
        .output()
        .context("could not start cargo metadata")?;
    if !output.status.success() {
        bail!(
            "`cargo metadata` exited with {}: {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let metadata: serde_json::Value =
        serde_json::from_slice(&output.stdout).context("cargo metadata is not valid JSON")?;
    // `publish` is null when publishing is allowed anywhere, `[]` for `publish = false`.
    Ok(metadata["packages"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|p| p["publish"].as_array().is_none_or(|r| !r.is_empty()))
        .filter_map(|p| p["name"].as_str().map(str::to_owned))
        .collect())
}

/// The library examples `examples` runs, with tiny arguments (`{out}`: a folder under target).
const EXAMPLES: [(&str, &str, &[&str]); 6] = [
    (
        "terrain-core",
        "stamp_heightmap",
        &["--size", "64", "--out", "{out}"],
    ),
    (
        "terrain-physics",
        "drop_spheres",
        &["--size", "64", "--spheres", "2", "--steps", "90"],
    ),
    ("terrain-gpu", "own_device", &["{out}/own_device.png"]),
    ("terrain-lod", "clipmap_frame", &["63", "4"]),
    ("terrain-cache", "build_world", &["512", "{out}/world"]),
    ("terrain-cache", "trace_sim", &[]),
];

/// Example files that are tools rather than examples, with why `examples` does not run them.
const NOT_EXAMPLES: [(&str, &str, &str); 1] = [(
    "terrain-gpu",
    "golden",
    "regenerates the render test's golden image in the repository: `cargo xtask golden`",
)];

/// Runs every example of the library crates once at a tiny size; fails on an example file that
/// `EXAMPLES` does not list, so none is left unrun.
fn examples() -> Result<()> {
    for krate in [
        "terrain-core",
        "terrain-physics",
        "terrain-gpu",
        "terrain-lod",
        "terrain-cache",
    ] {
        let dir = root().join(krate).join("examples");
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries {
            let path = entry?.path();
            let Some(name) = path.file_stem().and_then(|s| s.to_str()) else {
                continue;
            };
            if NOT_EXAMPLES
                .iter()
                .any(|(k, e, _)| *k == krate && *e == name)
            {
                continue;
            }
            if !EXAMPLES.iter().any(|(k, e, _)| *k == krate && *e == name) {
                bail!("{} is not listed in xtask's EXAMPLES", path.display());
            }
        }
    }
    let out = root().join("target").join("ci-examples");
    if out.exists() {
        std::fs::remove_dir_all(&out).with_context(|| format!("clearing {}", out.display()))?;
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let out = out.to_string_lossy();
    for (krate, example, args) in EXAMPLES {
        let mut cmd = vec!["run", "--locked", "-p", krate, "--example", example, "--"];
        let args: Vec<String> = args.iter().map(|a| a.replace("{out}", &out)).collect();
        cmd.extend(args.iter().map(String::as_str));
        cargo(&cmd, &[])?;
    }
    Ok(())
}

/// Regenerates `terrain-gpu/tests/data/golden_clipmap.png` on this machine's adapter.
fn golden() -> Result<()> {
    let path = root().join("terrain-gpu/tests/data/golden_clipmap.png");
    cargo(
        &[
            "run",
            "--locked",
            "-p",
            "terrain-gpu",
            "--example",
            "golden",
            "--",
            &path.to_string_lossy(),
        ],
        &[],
    )
}

/// Runs the demo at a tiny size on the default adapter (Vulkan in CI) and again on GL, so the
/// fallback formats stay honest, and checks frames, summary and report each time.
fn smoke() -> Result<()> {
    smoke_on(None)?;
    smoke_on(Some("gl"))?;
    smoke_snow()
}

/// The snow scenario at a tiny size: frames, and a granular volume that never changes.
fn smoke_snow() -> Result<()> {
    let gpu = snow_run("gpu", &[])?;
    let cpu = snow_run("cpu", &["--no-gpu"])?;
    if gpu != cpu {
        bail!("snow: the GPU run's volume {gpu} differs from the CPU run's {cpu}");
    }
    Ok(())
}

/// Runs the snow scenario (6 frames, 128^2) with `extra` flags; checks every frame reports
/// `backend` as its granular backend and the same granular volume; returns that volume.
fn snow_run(backend: &str, extra: &[&str]) -> Result<u64> {
    let out = root()
        .join("target")
        .join(format!("ci-smoke-snow-{backend}"));
    if out.exists() {
        std::fs::remove_dir_all(&out).context("could not clear the smoke output folder")?;
    }
    let out_s = out.to_string_lossy().into_owned();
    let mut args = vec![
        "run",
        "--locked",
        "-p",
        "terrain-demo",
        "--",
        "--scenario",
        "snow",
        "--size",
        "128",
        "--frames",
        "6",
        "--resolution",
        "160x96",
        "--out",
        &out_s,
    ];
    args.extend_from_slice(extra);
    cargo(&args, &[])?;
    let text = std::fs::read_to_string(out.join("report.json")).context("no snow report")?;
    let report: serde_json::Value = serde_json::from_str(&text).context("invalid report.json")?;
    let frames = report["frames"].as_array().cloned().unwrap_or_default();
    let volumes: Vec<u64> = frames
        .iter()
        .filter_map(|f| f["granular_volume"].as_u64())
        .collect();
    if volumes.len() != 6 || volumes.iter().any(|v| *v != volumes[0]) {
        bail!("snow ({backend}): granular volume must be reported and constant, got {volumes:?}");
    }
    if let Some(f) = frames
        .iter()
        .find(|f| f["granular_backend"].as_str() != Some(backend))
    {
        bail!(
            "snow: granular steps expected on the {backend}, frame {} reports {}",
            f["index"],
            f["granular_backend"]
        );
    }
    eprintln!(
        "smoke (snow on the {backend}): 6 frames, granular volume constant at {}",
        volumes[0]
    );
    Ok(volumes[0])
}

fn smoke_on(backend: Option<&str>) -> Result<()> {
    let name = backend.unwrap_or("default");
    let out = root().join("target").join(format!("ci-smoke-{name}"));
    if out.exists() {
        std::fs::remove_dir_all(&out).context("could not clear the smoke output folder")?;
    }
    let out_s = out.to_string_lossy().into_owned();
    let frames = 4;
    let env: Vec<(&str, &str)> = backend.map(|b| ("WGPU_BACKEND", b)).into_iter().collect();
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
            "--resolution",
            "160x96",
            "--out",
            &out_s,
        ],
        &env,
    )?;
    let report_path = out.join("report.json");
    let text = std::fs::read_to_string(&report_path)
        .with_context(|| format!("no report at {}", report_path.display()))?;
    let report: serde_json::Value =
        serde_json::from_str(&text).context("report.json is not valid JSON")?;
    let backend_found = report["backend"].as_str().unwrap_or("none");
    if backend_found == "none" {
        bail!("the demo found no GPU adapter ({name} backend): 3D frames were not rendered");
    }
    if let Some(b) = backend
        && backend_found != b
    {
        bail!("asked for the {b} backend, the demo ran on {backend_found}");
    }
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
        for step in ["stamp", "normals", "render"] {
            if !timings
                .get(step)
                .and_then(|v| v.as_f64())
                .is_some_and(|t| t >= 0.0)
            {
                bail!("frame {i} lacks a valid `{step}` timing: {timings:?}");
            }
        }
        if frame["triangles"].as_u64().unwrap_or(0) == 0 {
            bail!("frame {i} drew no triangles");
        }
        match frame["camera_clearance_m"].as_f64() {
            Some(c) if c >= 0.0 => {}
            other => {
                bail!("frame {i}: camera clearance {other:?} (must be present, never negative)")
            }
        }
        let file = frame["file"].as_str().unwrap_or_default();
        if !out.join(file).is_file() {
            bail!("frame {i}: image `{file}` is missing");
        }
    }
    let landed = report["frames"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|f| f["readback_ms"].as_f64().is_some())
        .count();
    if landed == 0 {
        bail!("no collision readback landed in {frames} frames");
    }
    for file in ["terrain.png", "terrain_final.png", "summary.png"] {
        if !out.join(file).is_file() {
            bail!("{file} is missing");
        }
    }
    eprintln!("smoke ({name}): {frames} frames on {backend_found} and a valid report in {out_s}");
    Ok(())
}
