//! Workspace commands. `cargo xtask ci` runs every check CI runs, in order, and names the step
//! that failed.
//!
//! `cargo xtask fuzz --seconds N [--target NAME] [--seed S]` runs the fuzz targets (the
//! `tests/fuzz.rs` files of terrain-core, terrain-cache, terrain-physics and terrain-lod, listed
//! in [`FUZZ_TARGETS`]) for N seconds each, in release mode, and prints a table of every input
//! class: cases run and result. CI has no fuzz step of its own: its `test` step runs every
//! target already, for the default 2 seconds each (`TERRAIN_FUZZ_SECONDS` unset), which is the
//! short run of each that CI makes.
//!
//! `cargo xtask mutants [--shard K/N] [--crate NAME]` runs cargo-mutants over the algorithm
//! files of [`MUTANT_CRATES`] (listed in `.cargo/mutants.toml`), then prints caught / missed /
//! timeout / unviable and the mutation score per crate (docs/testing.md). A shard is a
//! round-robin sample; each run keeps its results in `target/mutants/<crate>-<K>of<N>`, and
//! `cargo xtask mutants --summary` adds up every stored run. Not part of `ci`.

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
        Some("examples") => examples(),
        Some("golden") => golden(),
        Some("bench-report") => bench_report(&args[1..]),
        Some("fuzz") => fuzz(&args[1..]),
        Some("mutants") => mutants(&args[1..]),
        _ => {
            eprintln!(
                "usage: cargo xtask <ci|smoke|package|examples|golden|bench-report [--quick] [--readme]|fuzz --seconds N [--target NAME] [--seed S]|mutants [--shard K/N] [--crate NAME] | --summary>"
            );
            eprintln!(
                "  ci      fmt, clippy, tests, docs, package, examples, demo smoke (what CI runs)"
            );
            eprintln!("  examples  run every library example once at a tiny size");
            eprintln!("  smoke   only the demo smoke runs (default backend, then GL)");
            eprintln!("  package package and verify the publishable crates (`cargo package`)");
            eprintln!("  golden  regenerate the render test's golden image (never done by tests)");
            eprintln!(
                "  bench-report  run the headline CPU benches (all cores, then one); write target/bench-report.{{json,md}}; --readme also regenerates README's table"
            );
            eprintln!(
                "  fuzz    run the fuzz targets N seconds each (release), print cases and results per input class"
            );
            eprintln!(
                "          (ci's `test` step already runs each target for 2 s; targets: {})",
                FUZZ_TARGETS.map(|t| t.1).join(", ")
            );
            eprintln!(
                "  mutants run cargo-mutants on the algorithm files; print caught / missed / score per crate"
            );
            eprintln!(
                "          (crates: {}; not part of ci)",
                MUTANT_CRATES.join(", ")
            );
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
    // Mesa's Vulkan device-select layer prints `XDG_RUNTIME_DIR is invalid or not set` for
    // every GPU test on a machine without a desktop session; it only reorders adapters, which
    // terrain-gpu ranks itself (the demo turns it off the same way).
    if std::env::var_os("MESA_VK_DEVICE_SELECT").is_none() {
        cmd.env("NODEVICE_SELECT", "1");
    }
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

/// Runs the demo binary as the test step built it: `cargo test --workspace` builds it with the
/// workspace's unified features, and a `cargo run -p terrain-demo` would resolve the demo's own
/// and rebuild wgpu and its dependencies (minutes on two cores). `cargo test --no-run` makes it
/// current first (nothing to do right after the test step).
fn demo(args: &[&str], env: &[(&str, &str)]) -> Result<()> {
    cargo(&["test", "--workspace", "--locked", "--no-run"], &[])?;
    let exe = root()
        .join("target")
        .join("debug")
        .join(format!("terrain-demo{}", std::env::consts::EXE_SUFFIX));
    let mut cmd = Command::new(&exe);
    cmd.args(args).current_dir(root());
    if std::env::var_os("MESA_VK_DEVICE_SELECT").is_none() {
        cmd.env("NODEVICE_SELECT", "1");
    }
    for (k, v) in env {
        cmd.env(k, v);
    }
    let status = cmd
        .status()
        .with_context(|| format!("could not start {}", exe.display()))?;
    if !status.success() {
        bail!("`terrain-demo {}` exited with {status}", args.join(" "));
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
    )?;
    // terrain-physics's optional parry adapter (its module, test, bench and example).
    cargo(
        &[
            "clippy",
            "-p",
            "terrain-physics",
            "--features",
            "parry",
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
    )?;
    // The GPU passes again on the GL fallback (llvmpipe), which a machine without Vulkan gets:
    // its shader compiler has its own bugs (the atlas lookup once read wrong heights there).
    cargo(
        &["test", "-p", "terrain-gpu", "--locked", "--tests"],
        &[("TERRAIN_REQUIRE_GPU", "1"), ("WGPU_BACKEND", "gl")],
    )?;
    // The collision mirror under shuttle's randomized scheduler: its own feature (shuttle's
    // primitives replace the real ones), so only that test runs with it.
    cargo(
        &[
            "test",
            "-p",
            "terrain-physics",
            "--features",
            "shuttle",
            "--test",
            "shuttle_mirror",
            "--locked",
        ],
        &[],
    )?;
    // The optional parry adapter: the crate's tests and doc tests with it compiled in.
    cargo(
        &[
            "test",
            "-p",
            "terrain-physics",
            "--features",
            "parry",
            "--locked",
        ],
        &[],
    )
}

fn doc() -> Result<()> {
    cargo(
        &["doc", "--workspace", "--no-deps", "--locked"],
        &[("RUSTDOCFLAGS", "-D warnings")],
    )?;
    cargo(
        &[
            "doc",
            "-p",
            "terrain-physics",
            "--features",
            "parry",
            "--no-deps",
            "--locked",
        ],
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
const EXAMPLES: [(&str, &str, &[&str]); 10] = [
    (
        "terrain-core",
        "stamp_heightmap",
        &["--size", "64", "--out", "{out}"],
    ),
    (
        "terrain-core",
        "edt_masks",
        &["--size", "48", "--repeat", "1", "--out", "{out}"],
    ),
    (
        "terrain-physics",
        "drop_spheres",
        &["--size", "64", "--spheres", "2", "--steps", "90"],
    ),
    ("terrain-gpu", "own_device", &["{out}/own_device.png"]),
    ("terrain-lod", "clipmap_frame", &["63", "4"]),
    (
        "terrain-lod",
        "density_map",
        &["--size", "64", "--out", "{out}/density"],
    ),
    ("terrain-lod", "tessellation_ratio", &["--size", "256"]),
    ("terrain-cache", "build_world", &["512", "{out}/world"]),
    ("terrain-cache", "trace_sim", &[]),
    // The whole frame an engine runs: it joins every library crate, so it lives in the demo.
    (
        "terrain-demo",
        "engine_frame",
        &["{out}/engine_frame", "24"],
    ),
];

/// Library examples behind a feature of their crate (`required-features`), which the
/// workspace build of `examples` skips: each is built with its feature, then run like the
/// others.
const FEATURE_EXAMPLES: [(&str, &str, &str, &[&str]); 1] = [(
    "terrain-physics",
    "parry_drop",
    "parry",
    &["--size", "64", "--tile", "16", "--steps", "60"],
)];

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
        "terrain-demo",
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
            if !EXAMPLES.iter().any(|(k, e, _)| *k == krate && *e == name)
                && !FEATURE_EXAMPLES
                    .iter()
                    .any(|(k, e, _, _)| *k == krate && *e == name)
            {
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
    // One build of every example with the workspace's features (what the test step built
    // already), then each binary runs: `cargo run -p` would resolve each crate's features on
    // its own and rebuild the dependencies for it.
    cargo(&["build", "--locked", "--workspace", "--examples"], &[])?;
    for (krate, example, feature, _) in FEATURE_EXAMPLES {
        cargo(
            &[
                "build",
                "--locked",
                "-p",
                krate,
                "--features",
                feature,
                "--example",
                example,
            ],
            &[],
        )?;
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| root().join("target"));
    let feature_examples = FEATURE_EXAMPLES.map(|(k, e, _, a)| (k, e, a));
    for (krate, example, args) in EXAMPLES.into_iter().chain(feature_examples) {
        let args: Vec<String> = args.iter().map(|a| a.replace("{out}", &out)).collect();
        let exe = target
            .join("debug")
            .join("examples")
            .join(format!("{example}{}", std::env::consts::EXE_SUFFIX));
        let status = Command::new(&exe)
            .args(&args)
            .current_dir(root())
            .status()
            .with_context(|| format!("could not start {krate}'s example {}", exe.display()))?;
        if !status.success() {
            bail!(
                "{krate}'s example `{example} {}` exited with {status}",
                args.join(" ")
            );
        }
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
    demo(&args, &[])?;
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
    demo(
        &[
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
        for step in ["stamp_gpu", "normals_gpu", "render"] {
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

/// One headline figure of `bench-report`: a criterion benchmark id (`group/function/param`),
/// the thesis figure it is compared with (milliseconds, and where it comes from), and the ids
/// of the plain copies of the same bytes measured in the same run: contiguous, and (for the
/// stamp benches) in place in the map's rows.
struct Headline {
    id: String,
    thesis_ms: Option<f64>,
    thesis: String,
    copy_id: String,
    map_copy_id: Option<String>,
}

/// The figures `bench-report` reports. Thesis figures: seed 000 table 4.3 (GTX295, deform and
/// normal generation at 0.1 m per texel: 50 m = 500^2 texels, 100 m = 1000^2, 200 m =
/// 2000^2), seed 001 tables 5.4 (iterative approach) and 5.5 (SSBO approach) at heightmapSize
/// 4096 (241 591 columns).
fn headlines() -> Vec<Headline> {
    let mut out = Vec::new();
    // (side, GTX295 deform ms, GTX295 normal generation ms, region in metres)
    let table_4_3 = [
        (500, 0.971, 0.828, "50 m"),
        (1000, 1.192, 0.953, "100 m"),
        (2000, 1.875, 1.329, "200 m"),
    ];
    for (side, deform, normals, metres) in table_4_3 {
        let stamps = [
            ("stamp", "Gaussian"),
            ("stamp_reference", "Gaussian, per-texel reference"),
            ("stamp_gaussian_rotated", "rotated Gaussian"),
            ("stamp_texture_rotated", "rotated texture"),
            ("stamp_min_max", "min / max blend"),
            ("normals", "normals"),
        ];
        for (bench, what) in stamps {
            // The per-texel reference runs at the small sizes only (it is slow).
            if bench == "stamp_reference" && side > 500 {
                continue;
            }
            let (thesis_ms, figure) = if bench == "normals" {
                (normals, "Normal Gen")
            } else {
                (deform, "Deform")
            };
            out.push(Headline {
                id: format!("stamp_normals/{bench}/{side}"),
                thesis_ms: Some(thesis_ms),
                thesis: format!("seed 000 table 4.3, {figure} {metres}, GTX295 ({what})"),
                copy_id: format!("stamp_normals/memcpy/{side}"),
                map_copy_id: Some(format!("stamp_normals/memcpy_in_map/{side}")),
            });
        }
    }
    let granular = [
        (
            "granular/jump_flood/4096",
            10.692,
            "seed 001 table 5.4, Jump flooding, 4096",
        ),
        (
            "granular/jump_flood_reference/4096",
            10.692,
            "seed 001 table 5.4, Jump flooding (sequential reference)",
        ),
        (
            "granular/exact_nearest_seed/4096",
            10.692,
            "seed 001 table 5.4, Jump flooding (scipy EDT: 13.4 ms)",
        ),
        (
            "granular/displace_iterative10/4096",
            11.864,
            "seed 001 table 5.4, Displace material, 4096",
        ),
        (
            "granular/slopes_scatter10/4096",
            5.486,
            "seed 001 table 5.5, Even out steep slopes, 4096",
        ),
        (
            "granular/step_jfa_iterative10_scatter10/4096",
            38.08,
            "seed 001 table 5.4, depth + penetration + JFA + displace + slopes",
        ),
        (
            "granular/step_exact_iterative10_scatter10/4096",
            38.08,
            "seed 001 table 5.4, the same steps",
        ),
        (
            "granular_step/jfa_iterative10_scatter10/4096",
            38.08,
            "seed 001 table 5.4, the same steps (GranularSim::step, volume included)",
        ),
        (
            "granular_step/exact_iterative10_scatter10/4096",
            38.08,
            "seed 001 table 5.4, the same steps (GranularSim::step, exact transform)",
        ),
    ];
    for (id, ms, thesis) in granular {
        out.push(Headline {
            id: id.into(),
            thesis_ms: Some(ms),
            thesis: thesis.into(),
            copy_id: "granular/memcpy_u32/4096".into(),
            map_copy_id: None,
        });
    }
    out
}

/// Reads criterion's median estimate (ns) of `id` from `criterion_dir`.
fn criterion_median_ns(criterion_dir: &Path, id: &str) -> Result<f64> {
    let path = criterion_dir.join(id).join("new").join("estimates.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    v["median"]["point_estimate"]
        .as_f64()
        .with_context(|| format!("no median in {}", path.display()))
}

/// Where README.md's generated "Measured" table starts and ends.
const README_BEGIN: &str = "<!-- bench-report:begin (cargo xtask bench-report --readme) -->";
const README_END: &str = "<!-- bench-report:end -->";

/// `readme` with the text between [`README_BEGIN`] and [`README_END`] replaced by `table`;
/// an error if the markers are missing or out of order.
fn splice_readme(readme: &str, table: &str) -> Result<String> {
    let (Some(a), Some(b)) = (readme.find(README_BEGIN), readme.find(README_END)) else {
        bail!("README.md has no {README_BEGIN} ... {README_END} markers");
    };
    if b < a {
        bail!("README.md's bench-report markers are out of order");
    }
    let head = &readme[..a + README_BEGIN.len()];
    Ok(format!("{head}\n{}\n{}", table.trim_end(), &readme[b..]))
}

/// Writes `bytes` to `path` through a temporary file beside it (fsynced, then renamed over
/// `path`), so an interrupted run leaves the old file or the new one, never half of one.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let tmp = path.with_extension("tmp-bench-report");
    let mut f =
        std::fs::File::create(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    f.write_all(bytes)?;
    f.sync_all()?;
    drop(f);
    std::fs::rename(&tmp, path).with_context(|| format!("renaming over {}", path.display()))
}

/// Runs the headline CPU benches briefly (criterion's `--quick` mode with `--quick`), on all
/// cores and then on one (`RAYON_NUM_THREADS=1`, its own criterion folder), and writes
/// `target/bench-report.json` and `target/bench-report.md`: each figure, the thesis figure it
/// is compared with, and its ratio to plain copies of the same bytes measured in the same run.
/// With `--readme` the table also replaces README.md's generated "Measured" table.
fn bench_report(args: &[String]) -> Result<()> {
    let quick = args.iter().any(|a| a == "--quick");
    let readme = args.iter().any(|a| a == "--readme");
    if let Some(bad) = args
        .iter()
        .find(|a| !matches!(a.as_str(), "--quick" | "--readme"))
    {
        bail!("bench-report: unknown argument {bad} (expected --quick, --readme)");
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"));
    let one_core_dir = target.join("criterion-1-thread");
    let benches: [(&str, &str); 2] = [
        (
            "stamp_normals",
            "^stamp_normals/(stamp|stamp_reference|stamp_gaussian_rotated|stamp_texture_rotated|stamp_min_max|normals|memcpy|memcpy_in_map)/(500|1000|2000)$",
        ),
        (
            "granular",
            "^granular/(jump_flood|jump_flood_reference|exact_nearest_seed|displace_iterative10|slopes_scatter10|step_jfa_iterative10_scatter10|step_exact_iterative10_scatter10|memcpy_u32)/4096$|^granular_step/",
        ),
    ];
    let one_core = one_core_dir.to_string_lossy().into_owned();
    let runs: [&[(&str, &str)]; 2] = [
        &[],
        &[("RAYON_NUM_THREADS", "1"), ("CRITERION_HOME", &one_core)],
    ];
    for env in runs {
        for (bench, filter) in benches {
            let mut args = vec![
                "bench",
                "--locked",
                "-p",
                "terrain-core",
                "--bench",
                bench,
                "--",
            ];
            if quick {
                args.push("--quick");
            }
            args.push(filter);
            cargo(&args, env)?;
        }
    }
    let criterion_dir = target.join("criterion");
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut rows = Vec::new();
    let mut md = format!(
        "| benchmark | {threads} cores (ms) | 1 core (ms) | thesis (ms) | thesis figure | x thesis | x copy | x copy in the map |\n|---|---|---|---|---|---|---|---|\n",
    );
    for h in headlines() {
        let ns = criterion_median_ns(&criterion_dir, &h.id)?;
        let one_ns = criterion_median_ns(&one_core_dir, &h.id)?;
        let copy_ns = criterion_median_ns(&criterion_dir, &h.copy_id)?;
        let map_copy_ns = match &h.map_copy_id {
            Some(id) => Some(criterion_median_ns(&criterion_dir, id)?),
            None => None,
        };
        let ms = ns / 1e6;
        let vs_thesis = h.thesis_ms.map(|t| ms / t);
        md.push_str(&format!(
            "| `{}` | {:.3} | {:.3} | {} | {} | {} | {:.1} ({:.1} us) | {} |\n",
            h.id,
            ms,
            one_ns / 1e6,
            h.thesis_ms.map_or("-".into(), |t| format!("{t:.3}")),
            h.thesis,
            vs_thesis.map_or("-".into(), |r| format!("{r:.2}")),
            ns / copy_ns,
            copy_ns / 1e3,
            map_copy_ns.map_or("-".into(), |c| format!("{:.1} ({:.1} us)", ns / c, c / 1e3)),
        ));
        rows.push(serde_json::json!({
            "id": h.id,
            "median_ms": ms,
            "one_core_median_ms": one_ns / 1e6,
            "thesis_ms": h.thesis_ms,
            "thesis": h.thesis,
            "ratio_to_thesis": vs_thesis,
            "copy_id": h.copy_id,
            "copy_ms": copy_ns / 1e6,
            "ratio_to_copy": ns / copy_ns,
            "map_copy_id": h.map_copy_id,
            "map_copy_ms": map_copy_ns.map(|c| c / 1e6),
            "ratio_to_map_copy": map_copy_ns.map(|c| ns / c),
        }));
    }
    md.push_str(&format!(
        "\nCriterion medians{}, on {threads} CPU threads and on 1 (`RAYON_NUM_THREADS=1`). \
         \"x copy\": the figure over a plain `copy_from_slice` of the same bytes (the region's \
         u16 heights, or the area's u32 columns) between two buffers of that size; \"x copy in \
         the map\": over copying the region's rows in place in the 4096^2 map (the strided, \
         cache-missing access a stamp makes). Both copies run on one thread, in the same run. \
         Figures from a shared machine are noisy; compare ratios measured in the same run.\n",
        if quick { " (--quick)" } else { "" },
    ));
    let json = serde_json::json!({ "quick": quick, "threads": threads, "figures": rows });
    std::fs::create_dir_all(&target)?;
    let json_path = target.join("bench-report.json");
    let md_path = target.join("bench-report.md");
    std::fs::write(&json_path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", json_path.display()))?;
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    println!("{md}");
    eprintln!("wrote {} and {}", json_path.display(), md_path.display());
    if readme {
        let path = root().join("README.md");
        let text = std::fs::read_to_string(&path).context("reading README.md")?;
        let spliced = splice_readme(&text, &md)?;
        write_atomically(&path, spliced.as_bytes())?;
        eprintln!("updated the generated table in {}", path.display());
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// fuzz

/// The fuzz targets: crate, target name (as the target prints it), test function in the crate's
/// `tests/fuzz.rs`.
const FUZZ_TARGETS: [(&str, &str, &str); 9] = [
    ("terrain-core", "png16", "fuzz_png16"),
    ("terrain-core", "png8", "fuzz_png8"),
    ("terrain-core", "raw16", "fuzz_raw16"),
    ("terrain-core", "geotiff", "fuzz_geotiff"),
    ("terrain-cache", "tile", "fuzz_tile"),
    ("terrain-cache", "manifest", "fuzz_manifest"),
    ("terrain-cache", "bounds", "fuzz_bounds"),
    ("terrain-physics", "physics", "fuzz_physics"),
    ("terrain-lod", "lod", "fuzz_lod"),
];

/// What `fuzz` learned of one input class from the target's output.
#[derive(Debug, Clone, PartialEq)]
struct FuzzRow {
    target: String,
    class: String,
    /// Cases run (`None` for a disabled class).
    cases: Option<u64>,
    /// `ok`, `FAILED (...)`, or `disabled (...)`.
    result: String,
    notes: u64,
}

/// One line of a target's output, as `fuzz/harness.rs` prints it.
#[derive(Debug, Clone, PartialEq)]
enum FuzzLine {
    Class(FuzzRow),
    Notes {
        target: String,
        class: String,
        notes: u64,
    },
    Total {
        target: String,
        cases: u64,
        seed: String,
    },
}

/// Parses a line of a fuzz target's output; `None` for any other line. With `--nocapture` the
/// test harness prints `test <name> ... ` without a newline before the test's first line.
fn parse_fuzz_line(line: &str) -> Option<FuzzLine> {
    let line = match line.strip_prefix("test ") {
        Some(rest) => rest.split_once(" ... ").map_or(line, |(_, r)| r),
        None => line,
    };
    let rest = line.strip_prefix("fuzz ")?;
    let (target, rest) = rest.split_once(": ")?;
    let target = target.to_owned();
    if let Some(rest) = rest.strip_prefix("class ") {
        let (class, tail) = rest.split_once(": ")?;
        let class = class.to_owned();
        if let Some(why) = tail.strip_prefix("disabled") {
            return Some(FuzzLine::Class(FuzzRow {
                target,
                class,
                cases: None,
                result: format!("disabled{why}"),
                notes: 0,
            }));
        }
        if let Some((n, _)) = tail.split_once(" notes, first: ") {
            return Some(FuzzLine::Notes {
                target,
                class,
                notes: n.parse().ok()?,
            });
        }
        let (n, after) = tail.split_once(" cases in ")?;
        let (_, result) = after.split_once(": ")?;
        return Some(FuzzLine::Class(FuzzRow {
            target,
            class,
            cases: Some(n.parse().ok()?),
            result: result.to_owned(),
            notes: 0,
        }));
    }
    let (n, after) = rest.split_once(" cases in ")?;
    let seed = after
        .split_once("(seed ")
        .map(|(_, s)| s.trim_end_matches(')').to_owned())
        .unwrap_or_default();
    Some(FuzzLine::Total {
        target,
        cases: n.parse().ok()?,
        seed,
    })
}

/// `cargo xtask fuzz --seconds N [--target NAME] [--seed S]`: see the module docs.
fn fuzz(args: &[String]) -> Result<()> {
    let mut seconds: Option<f64> = None;
    let mut only: Option<String> = None;
    let mut seed: Option<String> = None;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |flag: &str| {
            it.next()
                .cloned()
                .with_context(|| format!("{flag} needs a value"))
        };
        match a.as_str() {
            "--seconds" => {
                let v = value("--seconds")?;
                let s: f64 = v
                    .parse()
                    .with_context(|| format!("--seconds {v:?} is not a number"))?;
                if !(s.is_finite() && s > 0.0) {
                    bail!("--seconds must be a positive number of seconds, got {v}");
                }
                seconds = Some(s);
            }
            "--target" => only = Some(value("--target")?),
            "--seed" => seed = Some(value("--seed")?),
            other => bail!(
                "unknown argument {other:?}: cargo xtask fuzz --seconds N [--target NAME] [--seed S]"
            ),
        }
    }
    let seconds = seconds.context("cargo xtask fuzz needs --seconds N (seconds per target)")?;
    let targets: Vec<(&str, &str, &str)> = FUZZ_TARGETS
        .into_iter()
        .filter(|t| only.as_deref().is_none_or(|o| o == t.1 || o == t.2))
        .collect();
    if targets.is_empty() {
        bail!(
            "no fuzz target named {:?}; targets: {}",
            only.unwrap_or_default(),
            FUZZ_TARGETS.map(|t| t.1).join(", ")
        );
    }
    let started = Instant::now();
    let mut rows: Vec<FuzzRow> = Vec::new();
    let mut totals: Vec<(String, u64, String)> = Vec::new();
    let mut failed_runs = Vec::new();
    let mut crates: Vec<&str> = targets.iter().map(|t| t.0).collect();
    crates.dedup();
    let seconds_s = seconds.to_string();
    for krate in crates {
        let tests: Vec<&str> = targets
            .iter()
            .filter(|t| t.0 == krate)
            .map(|t| t.2)
            .collect();
        // One test at a time, so each target has the machine to itself for its N seconds.
        let mut args = vec![
            "test",
            "--release",
            "--locked",
            "-p",
            krate,
            "--test",
            "fuzz",
            "--",
            "--nocapture",
            "--test-threads=1",
            "--exact",
        ];
        args.extend(&tests);
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.args(&args)
            .current_dir(root())
            .env("TERRAIN_FUZZ_SECONDS", &seconds_s)
            .stdout(std::process::Stdio::piped());
        if let Some(s) = &seed {
            cmd.env("TERRAIN_FUZZ_SEED", s);
        }
        eprintln!("fuzz: cargo {}", args.join(" "));
        let mut child = cmd
            .spawn()
            .with_context(|| format!("could not start cargo {}", args.join(" ")))?;
        let stdout = child.stdout.take().context("no stdout from cargo test")?;
        // Echo the targets' output as it comes, and keep the lines the table is made of.
        for line in std::io::BufRead::lines(std::io::BufReader::new(stdout)) {
            let line = line.context("reading the fuzz targets' output")?;
            println!("{line}");
            match parse_fuzz_line(&line) {
                Some(FuzzLine::Class(row)) => rows.push(row),
                Some(FuzzLine::Notes {
                    target,
                    class,
                    notes,
                }) => {
                    if let Some(r) = rows
                        .iter_mut()
                        .rev()
                        .find(|r| r.target == target && r.class == class)
                    {
                        r.notes = notes;
                    }
                }
                Some(FuzzLine::Total {
                    target,
                    cases,
                    seed,
                }) => totals.push((target, cases, seed)),
                None => {}
            }
        }
        let status = child.wait().context("waiting for cargo test")?;
        if !status.success() {
            failed_runs.push(format!("{krate} ({status})"));
        }
    }

    let mut table = format!(
        "\n| target | input class | cases ({seconds} s per target) | result |\n|---|---|---|---|\n"
    );
    let mut failed = false;
    for (_, target, _) in &targets {
        let total = totals.iter().find(|t| t.0 == *target);
        for r in rows.iter().filter(|r| r.target == *target) {
            let notes = if r.notes > 0 {
                format!(" ({} notes)", r.notes)
            } else {
                String::new()
            };
            failed |= r.result.starts_with("FAILED");
            table.push_str(&format!(
                "| {target} | {} | {} | {}{notes} |\n",
                r.class,
                r.cases.map_or("-".into(), |n| n.to_string()),
                r.result
            ));
        }
        match total {
            Some((_, cases, seed)) => table.push_str(&format!(
                "| **{target}** | all | **{cases}** | seed {seed} |\n"
            )),
            None => {
                failed = true;
                table.push_str(&format!(
                    "| **{target}** | all | - | no report: the test process crashed or was not run |\n"
                ));
            }
        }
    }
    println!("{table}");
    eprintln!(
        "fuzz: {} target(s) in {:.0} s",
        targets.len(),
        started.elapsed().as_secs_f64()
    );
    if failed || !failed_runs.is_empty() {
        bail!(
            "fuzz: a target failed (see the table; replay a case with the TERRAIN_FUZZ_REPLAY its \
             line prints){}",
            if failed_runs.is_empty() {
                String::new()
            } else {
                format!("; cargo test failed for {}", failed_runs.join(", "))
            }
        );
    }
    Ok(())
}

/// The crates `cargo xtask mutants` mutates (their algorithm files: `.cargo/mutants.toml`).
const MUTANT_CRATES: [&str; 4] = [
    "terrain-core",
    "terrain-physics",
    "terrain-lod",
    "terrain-cache",
];

/// Outcome counts of one crate's mutants.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct MutantCounts {
    caught: u64,
    missed: u64,
    timeout: u64,
    unviable: u64,
}

impl MutantCounts {
    /// The mutation score: caught / (caught + missed + timeout); `None` with nothing tested.
    fn score(&self) -> Option<f64> {
        let tested = self.caught + self.missed + self.timeout;
        (tested > 0).then(|| self.caught as f64 / tested as f64)
    }

    fn add(&mut self, summary: &str) -> bool {
        match summary {
            "CaughtMutant" => self.caught += 1,
            "MissedMutant" => self.missed += 1,
            "Timeout" => self.timeout += 1,
            "Unviable" => self.unviable += 1,
            _ => return false,
        }
        true
    }
}

/// The crate of a mutant from its package name or, failing that, the first component of its
/// file path (`terrain-core/src/...`).
fn mutant_crate(package: Option<&str>, file: &str) -> String {
    package
        .map(str::to_owned)
        .unwrap_or_else(|| file.split(['/', '\\']).next().unwrap_or(file).to_owned())
}

/// One mutant's outcome from cargo-mutants' `outcomes.json`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct MutantRecord {
    /// What identifies the mutant across runs: its file, place and replacement.
    key: String,
    krate: String,
    summary: String,
}

/// The mutants' outcomes in cargo-mutants' `outcomes.json` (the baseline is skipped).
fn mutant_records(json: &str) -> Result<Vec<MutantRecord>> {
    let v: serde_json::Value =
        serde_json::from_str(json).context("outcomes.json is not valid JSON")?;
    let outcomes = v
        .get("outcomes")
        .and_then(|o| o.as_array())
        .context("outcomes.json has no `outcomes` array")?;
    let mut out = Vec::new();
    for o in outcomes {
        let Some(m) = o.get("scenario").and_then(|s| s.get("Mutant")) else {
            continue; // the baseline
        };
        let file = m.get("file").and_then(|f| f.as_str()).unwrap_or("");
        out.push(MutantRecord {
            key: m.to_string(),
            krate: mutant_crate(m.get("package").and_then(|p| p.as_str()), file),
            summary: o
                .get("summary")
                .and_then(|s| s.as_str())
                .unwrap_or("")
                .to_owned(),
        });
    }
    Ok(out)
}

/// Counts per crate of `records`, sorted by crate.
fn count_records<'a>(
    records: impl IntoIterator<Item = &'a MutantRecord>,
) -> Vec<(String, MutantCounts)> {
    let mut out: Vec<(String, MutantCounts)> = Vec::new();
    for r in records {
        let i = match out.iter().position(|(k, _)| *k == r.krate) {
            Some(i) => i,
            None => {
                out.push((r.krate.clone(), MutantCounts::default()));
                out.len() - 1
            }
        };
        if !out[i].1.add(&r.summary) {
            eprintln!(
                "mutants: outcomes.json: unknown mutant outcome {:?} (not counted)",
                r.summary
            );
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// Counts per crate from cargo-mutants' `outcomes.json` (the baseline is skipped).
fn parse_mutants_outcomes(json: &str) -> Result<Vec<(String, MutantCounts)>> {
    Ok(count_records(&mutant_records(json)?))
}

/// The runs' records merged, oldest run first: a mutant tested in several runs (a shard run
/// again after new tests) counts once, with its latest outcome.
fn merge_runs(runs: &[Vec<MutantRecord>]) -> Vec<MutantRecord> {
    let mut merged: Vec<MutantRecord> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for r in runs.iter().flatten() {
        match index.get(&r.key) {
            Some(&i) => merged[i] = r.clone(),
            None => {
                index.insert(r.key.clone(), merged.len());
                merged.push(r.clone());
            }
        }
    }
    merged
}

/// Counts per crate from the `caught.txt`, `missed.txt`, `timeout.txt` and `unviable.txt`
/// lists (one mutant a line, `path:line:col: description`), as `(summary, text)` pairs.
fn parse_mutants_lists(lists: &[(&str, &str)]) -> Vec<(String, MutantCounts)> {
    let records: Vec<MutantRecord> = lists
        .iter()
        .flat_map(|&(summary, text)| {
            text.lines()
                .filter(|l| !l.trim().is_empty())
                .map(move |line| MutantRecord {
                    key: line.to_owned(),
                    krate: mutant_crate(None, line.split(':').next().unwrap_or(line)),
                    summary: summary.to_owned(),
                })
        })
        .collect();
    count_records(&records)
}

/// The table `cargo xtask mutants` prints.
fn mutants_table(rows: &[(String, MutantCounts)]) -> String {
    let mut t = String::from(
        "| crate | caught | missed | timeout | unviable | score |\n|---|---|---|---|---|---|\n",
    );
    let mut total = MutantCounts::default();
    let pct = |c: &MutantCounts| {
        c.score()
            .map_or("-".into(), |s| format!("{:.1} %", 100.0 * s))
    };
    for (krate, c) in rows {
        t.push_str(&format!(
            "| {krate} | {} | {} | {} | {} | {} |\n",
            c.caught,
            c.missed,
            c.timeout,
            c.unviable,
            pct(c)
        ));
        total.caught += c.caught;
        total.missed += c.missed;
        total.timeout += c.timeout;
        total.unviable += c.unviable;
    }
    t.push_str(&format!(
        "| **all** | {} | {} | {} | {} | {} |\n",
        total.caught,
        total.missed,
        total.timeout,
        total.unviable,
        pct(&total)
    ));
    t
}

/// The folder under `target/mutants` that keeps one run's results: the crate (or `all`) and
/// the shard (`3of8`, or `all`), so that runs of other shards or crates do not overwrite it.
fn mutants_run_dir(krate: Option<&str>, shard: Option<&str>) -> String {
    format!(
        "{}-{}",
        krate.unwrap_or("all"),
        shard.map_or("all".into(), |s| s.replace('/', "of"))
    )
}

/// Every run kept under `target/mutants`, oldest first, merged (see [`merge_runs`]).
fn stored_mutant_runs(dir: &Path) -> Result<Vec<MutantRecord>> {
    let mut runs = Vec::new();
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("no mutants runs in {}", dir.display()))?;
    for e in entries.flatten() {
        let path = e.path().join("mutants.out").join("outcomes.json");
        let Ok(meta) = std::fs::metadata(&path) else {
            continue;
        };
        let json = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let records =
            mutant_records(&json).with_context(|| format!("parsing {}", path.display()))?;
        runs.push((meta.modified().ok(), path, records));
    }
    runs.sort_by(|a, b| (a.0, &a.1).cmp(&(b.0, &b.1)));
    for (_, path, records) in &runs {
        eprintln!("mutants: {} mutants in {}", records.len(), path.display());
    }
    let runs: Vec<_> = runs.into_iter().map(|r| r.2).collect();
    Ok(merge_runs(&runs))
}

/// `cargo xtask mutants [--shard K/N] [--crate NAME] | --summary`: see the module docs.
fn mutants(args: &[String]) -> Result<()> {
    let mut shard: Option<String> = None;
    let mut krate: Option<String> = None;
    let mut summary = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |flag: &str| {
            it.next()
                .cloned()
                .with_context(|| format!("{flag} needs a value"))
        };
        match a.as_str() {
            "--shard" => {
                let v = value("--shard")?;
                let ok = v.split_once('/').is_some_and(|(k, n)| {
                    matches!((k.parse::<u32>(), n.parse::<u32>()), (Ok(k), Ok(n)) if k < n)
                });
                if !ok {
                    bail!("--shard {v:?}: expected K/N with 0 <= K < N, e.g. 0/8");
                }
                shard = Some(v);
            }
            "--crate" => {
                let v = value("--crate")?;
                if !MUTANT_CRATES.contains(&v.as_str()) {
                    bail!(
                        "--crate {v:?}: expected one of {}",
                        MUTANT_CRATES.join(", ")
                    );
                }
                krate = Some(v);
            }
            "--summary" => summary = true,
            other => bail!(
                "unknown argument {other:?}: cargo xtask mutants [--shard K/N] [--crate NAME] | --summary"
            ),
        }
    }
    let runs_dir = root().join("target").join("mutants");
    if summary {
        if shard.is_some() || krate.is_some() {
            bail!("--summary reads the stored runs; it takes no --shard or --crate");
        }
        let merged = stored_mutant_runs(&runs_dir)?;
        println!("\n{}", mutants_table(&count_records(&merged)));
        return Ok(());
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let installed = Command::new(&cargo)
        .args(["mutants", "--version"])
        .current_dir(root())
        .output()
        .is_ok_and(|o| o.status.success());
    if !installed {
        eprintln!("mutants: cargo-mutants is not installed; install it with");
        eprintln!("  cargo install --locked cargo-mutants");
        std::process::exit(1);
    }
    // Each run keeps its results in its own folder under target/mutants (ignored by git), so
    // that `--summary` can add up shards run one at a time; the file list and exclusions come
    // from .cargo/mutants.toml.
    let out_dir = runs_dir.join(mutants_run_dir(krate.as_deref(), shard.as_deref()));
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let out_str = out_dir.to_string_lossy().into_owned();
    // Each mutant builds in a fresh copy of the tree: copying target/ does not help (cargo's
    // fingerprints hold the path, so the copy rebuilds everything anyway) and costs gigabytes.
    let mut cmd_args = vec![
        "mutants",
        "--output",
        out_str.as_str(),
        "--copy-target=false",
    ];
    if let Some(s) = &shard {
        // Round-robin: a shard is a sample spread over every examined file, not one slice of
        // them, so that one shard already estimates the whole crate's score.
        cmd_args.extend(["--shard", s.as_str(), "--sharding", "round-robin"]);
    }
    if let Some(k) = &krate {
        cmd_args.extend(["--package", k.as_str()]);
    }
    eprintln!("mutants: cargo {}", cmd_args.join(" "));
    let started = Instant::now();
    // cargo-mutants exits non-zero when a mutant is missed (2) or times out (3): the table
    // still comes from its output; other failures (1: bad usage, 4: the baseline failed) stop.
    // The fuzz tests run for a wall-clock budget (2 s each by default): a quarter second per
    // mutant keeps their smoke value while the deterministic tests do the pinning. The soak
    // test of terrain-core's granular step runs 300 frames instead of 5000 for the same reason.
    let status = Command::new(&cargo)
        .args(&cmd_args)
        .env("TERRAIN_FUZZ_SECONDS", "0.25")
        .env("TERRAIN_SOAK_FRAMES", "300")
        .current_dir(root())
        .status()
        .with_context(|| format!("could not start cargo {}", cmd_args.join(" ")))?;
    let code = status.code();
    if !matches!(code, Some(0 | 2 | 3)) {
        bail!("`cargo {}` exited with {status}", cmd_args.join(" "));
    }
    let dir = out_dir.join("mutants.out");
    let rows = match std::fs::read_to_string(dir.join("outcomes.json")) {
        Ok(json) => parse_mutants_outcomes(&json)?,
        Err(_) => {
            let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap_or_default();
            let lists = [
                ("CaughtMutant", read("caught.txt")),
                ("MissedMutant", read("missed.txt")),
                ("Timeout", read("timeout.txt")),
                ("Unviable", read("unviable.txt")),
            ];
            let refs: Vec<(&str, &str)> = lists.iter().map(|(s, t)| (*s, t.as_str())).collect();
            parse_mutants_lists(&refs)
        }
    };
    println!("\n{}", mutants_table(&rows));
    eprintln!(
        "mutants: {} in {:.0} s; missed mutants are listed in {}; `cargo xtask mutants --summary` adds up every stored run",
        shard.map_or("all shards".into(), |s| format!("shard {s}")),
        started.elapsed().as_secs_f64(),
        dir.join("missed.txt").display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn splice_readme_replaces_only_the_generated_table() {
        let readme = format!("# T\n\nbefore\n{README_BEGIN}\nold | table\n{README_END}\nafter\n");
        let out = splice_readme(&readme, "| new |\n\n").unwrap();
        assert_eq!(
            out,
            format!("# T\n\nbefore\n{README_BEGIN}\n| new |\n{README_END}\nafter\n")
        );
        // Idempotent, and the markers are required in order.
        assert_eq!(splice_readme(&out, "| new |").unwrap(), out);
        assert!(splice_readme("no markers", "x").is_err());
        assert!(splice_readme(&format!("{README_END}{README_BEGIN}"), "x").is_err());
    }

    #[test]
    fn headlines_name_their_copies_and_thesis_figures() {
        let h = headlines();
        assert!(
            h.iter()
                .all(|h| h.thesis_ms.is_some() && !h.copy_id.is_empty())
        );
        for side in [500, 1000, 2000] {
            let id = format!("stamp_normals/stamp_texture_rotated/{side}");
            let t = h.iter().find(|h| h.id == id).unwrap();
            assert_eq!(t.copy_id, format!("stamp_normals/memcpy/{side}"));
            assert_eq!(
                t.map_copy_id.as_deref(),
                Some(&*format!("stamp_normals/memcpy_in_map/{side}"))
            );
        }
        let ids: std::collections::HashSet<_> = h.iter().map(|h| &h.id).collect();
        assert_eq!(ids.len(), h.len(), "no figure twice");
    }

    use super::*;

    #[test]
    fn mutant_runs_merge_with_the_latest_outcome_of_each_mutant() {
        let rec = |key: &str, krate: &str, summary: &str| MutantRecord {
            key: key.into(),
            krate: krate.into(),
            summary: summary.into(),
        };
        let first = vec![
            rec("a", "terrain-core", "MissedMutant"),
            rec("b", "terrain-core", "CaughtMutant"),
        ];
        let rerun = vec![
            rec("a", "terrain-core", "CaughtMutant"),
            rec("c", "terrain-lod", "Timeout"),
        ];
        let merged = merge_runs(&[first, rerun]);
        assert_eq!(
            merged,
            vec![
                rec("a", "terrain-core", "CaughtMutant"),
                rec("b", "terrain-core", "CaughtMutant"),
                rec("c", "terrain-lod", "Timeout"),
            ]
        );
        let rows = count_records(&merged);
        assert_eq!(rows[0].0, "terrain-core");
        assert_eq!(rows[0].1.caught, 2);
        assert_eq!(rows[1].0, "terrain-lod");
        assert_eq!(rows[1].1.timeout, 1);
        assert_eq!(
            mutants_run_dir(Some("terrain-lod"), Some("3/24")),
            "terrain-lod-3of24"
        );
        assert_eq!(mutants_run_dir(None, None), "all-all");
    }

    #[test]
    fn mutant_outcomes_parse_and_score() {
        let json = r#"{"outcomes": [
            {"scenario": "Baseline", "summary": "Success"},
            {"scenario": {"Mutant": {"package": "terrain-core", "file": "terrain-core/src/granular/jfa.rs"}}, "summary": "CaughtMutant"},
            {"scenario": {"Mutant": {"package": "terrain-core", "file": "terrain-core/src/granular/jfa.rs"}}, "summary": "CaughtMutant"},
            {"scenario": {"Mutant": {"package": "terrain-core", "file": "terrain-core/src/stamp.rs"}}, "summary": "MissedMutant"},
            {"scenario": {"Mutant": {"file": "terrain-physics/src/ray.rs"}}, "summary": "Timeout"},
            {"scenario": {"Mutant": {"package": "terrain-physics", "file": "terrain-physics/src/ray.rs"}}, "summary": "Unviable"},
            {"scenario": {"Mutant": {"package": "terrain-physics", "file": "terrain-physics/src/ray.rs"}}, "summary": "CaughtMutant"}
        ], "total_mutants": 6}"#;
        let rows = parse_mutants_outcomes(json).expect("parse");
        let core = MutantCounts {
            caught: 2,
            missed: 1,
            timeout: 0,
            unviable: 0,
        };
        let physics = MutantCounts {
            caught: 1,
            missed: 0,
            timeout: 1,
            unviable: 1,
        };
        assert_eq!(
            rows,
            vec![
                ("terrain-core".to_owned(), core),
                ("terrain-physics".to_owned(), physics)
            ]
        );
        assert_eq!(core.score(), Some(2.0 / 3.0));
        // Unviable mutants do not count; a timeout counts as not caught.
        assert_eq!(physics.score(), Some(0.5));
        assert_eq!(MutantCounts::default().score(), None);
        let table = mutants_table(&rows);
        assert!(
            table.contains("| terrain-core | 2 | 1 | 0 | 0 | 66.7 % |"),
            "{table}"
        );
        assert!(
            table.contains("| **all** | 3 | 1 | 1 | 1 | 60.0 % |"),
            "{table}"
        );
        assert!(parse_mutants_outcomes("{}").is_err());
        // An outcome this version does not know is not counted (and not fatal).
        let odd =
            r#"{"outcomes": [{"scenario": {"Mutant": {"file": "a/b.rs"}}, "summary": "Odd"}]}"#;
        assert_eq!(
            parse_mutants_outcomes(odd).expect("parse"),
            vec![("a".to_owned(), MutantCounts::default())]
        );
        // The plain lists give the same counts.
        let lists = [
            (
                "CaughtMutant",
                "terrain-core/src/granular/jfa.rs:222:51: replace + with - in jfa_pass_reference\n\
                 terrain-core/src/granular/jfa.rs:12:5: replace pcg_hash -> u32 with 0\n",
            ),
            (
                "MissedMutant",
                "terrain-core/src/stamp.rs:285:9: replace GaussianStamp::beta -> f32 with 1.0\n",
            ),
            ("Timeout", "terrain-physics/src/ray.rs:1:1: x\n"),
            ("Unviable", "terrain-physics/src/ray.rs:1:1: y\n\n"),
        ];
        let mut from_lists = parse_mutants_lists(&lists);
        from_lists[1].1.caught = 1; // the JSON above has one more caught physics mutant
        assert_eq!(from_lists, rows);
    }

    /// Every line-anchored exclusion of .cargo/mutants.toml still names the line it was
    /// written for (its `# at:` text), so a moved line cannot silently hide another mutant.
    #[test]
    fn mutants_exclusions_point_at_their_lines() {
        let config =
            std::fs::read_to_string(root().join(".cargo/mutants.toml")).expect("mutants.toml");
        let mut checked = 0;
        for line in config.lines() {
            let Some((entry, at)) = line.split_once("# at: ") else {
                continue;
            };
            let re = entry.trim().trim_end_matches(',').trim_matches('\'');
            let (path, rest) = re.split_once(':').expect("path:line: in the regex");
            let path = path.replace("\\.", ".");
            let line_no: usize = rest
                .split(':')
                .next()
                .and_then(|n| n.parse().ok())
                .expect("a line number after the path");
            let text = std::fs::read_to_string(root().join(&path)).expect("excluded file");
            let src = text.lines().nth(line_no - 1).unwrap_or("");
            assert!(
                src.contains(at.trim()),
                "{path}:{line_no} is now {src:?}, not {:?}: update .cargo/mutants.toml",
                at.trim()
            );
            checked += 1;
        }
        assert!(checked >= 5, "only {checked} exclusions checked");
        assert!(config.contains("examine_globs"));
        for krate in MUTANT_CRATES {
            assert!(
                config.contains(&format!("\"{krate}/src/")),
                "{krate} has no examined files"
            );
        }
    }

    #[test]
    fn fuzz_lines_parse() {
        let ok = "fuzz png16: class truncated: 396397 cases in 5.5 s: ok";
        assert_eq!(
            parse_fuzz_line(ok),
            Some(FuzzLine::Class(FuzzRow {
                target: "png16".into(),
                class: "truncated".into(),
                cases: Some(396_397),
                result: "ok".into(),
                notes: 0,
            }))
        );
        let skipped = "fuzz physics: class ray_near_map: 1015270 cases in 2.1 s (6840 drawn \
                       outside the class skipped): FAILED (panic: x: y) at case 3; replay with \
                       TERRAIN_FUZZ_REPLAY=ray_near_map:0x1";
        match parse_fuzz_line(skipped) {
            Some(FuzzLine::Class(r)) => {
                assert_eq!(r.cases, Some(1_015_270));
                assert!(r.result.starts_with("FAILED (panic: x: y)"), "{}", r.result);
            }
            other => panic!("{other:?}"),
        }
        let disabled = "fuzz physics: class ray_long_walk: disabled (defect 1: hangs)";
        match parse_fuzz_line(disabled) {
            Some(FuzzLine::Class(r)) => {
                assert_eq!(r.cases, None);
                assert_eq!(r.result, "disabled (defect 1: hangs)");
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            parse_fuzz_line("fuzz physics: class a_b: 12 notes, first: x: y"),
            Some(FuzzLine::Notes {
                target: "physics".into(),
                class: "a_b".into(),
                notes: 12
            })
        );
        assert_eq!(
            parse_fuzz_line("fuzz lod: 18549739 cases in 12.0 s (seed 0x26412cac14b888c7)"),
            Some(FuzzLine::Total {
                target: "lod".into(),
                cases: 18_549_739,
                seed: "0x26412cac14b888c7".into()
            })
        );
        assert_eq!(parse_fuzz_line("test fuzz_lod ... ok"), None);
        assert!(matches!(
            parse_fuzz_line(
                "test fuzz_lod ... fuzz lod: class layout_new_any: 3 cases in 0.2 s: ok"
            ),
            Some(FuzzLine::Class(FuzzRow { cases: Some(3), .. }))
        ));
        assert_eq!(parse_fuzz_line("fuzz: cargo test"), None);
    }

    /// Every crate's copy of the fuzz harness is the same file, and every target xtask runs
    /// is a test of its crate's `tests/fuzz.rs` (and every such test is listed).
    #[test]
    fn fuzz_targets_and_harness_copies_agree() {
        let read = |p: &Path| {
            std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        };
        let mut crates: Vec<&str> = FUZZ_TARGETS.iter().map(|t| t.0).collect();
        crates.dedup();
        let first = read(&root().join(crates[0]).join("tests/fuzz/harness.rs"));
        for krate in &crates {
            let harness = read(&root().join(krate).join("tests/fuzz/harness.rs"));
            assert!(
                harness == first,
                "{krate}/tests/fuzz/harness.rs differs from {}'s copy: keep the copies identical",
                crates[0]
            );
            let targets = read(&root().join(krate).join("tests/fuzz.rs"));
            let listed: Vec<&str> = FUZZ_TARGETS
                .iter()
                .filter(|t| t.0 == *krate)
                .map(|t| t.2)
                .collect();
            for test in &listed {
                assert!(
                    targets.contains(&format!("fn {test}()")),
                    "{krate}/tests/fuzz.rs has no fn {test}()"
                );
            }
            for line in targets.lines() {
                if let Some(name) = line.trim().strip_prefix("fn fuzz_")
                    && let Some((name, _)) = name.split_once("()")
                {
                    let test = format!("fuzz_{name}");
                    assert!(
                        listed.contains(&test.as_str()),
                        "{krate}/tests/fuzz.rs: {test} is not in xtask's FUZZ_TARGETS"
                    );
                }
            }
        }
        // No other crate has fuzz targets xtask does not know of.
        for entry in std::fs::read_dir(root()).expect("workspace root") {
            let dir = entry.expect("entry").path();
            let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if dir.join("tests/fuzz.rs").is_file() {
                assert!(
                    crates.contains(&name),
                    "{name}/tests/fuzz.rs exists but no target of it is in FUZZ_TARGETS"
                );
            }
        }
    }
}
