//! `cargo xtask ci`: every check CI runs, in order, naming the step that failed. The steps of
//! its own (fmt, clippy, test, doc) live here; tidy, package, examples and smoke are commands
//! of their own that ci runs too.

use crate::util::{cargo, cargo_exe, quiet_device_select, root};
use anyhow::{Context, Result, bail};
use std::process::{Command, Stdio};
use std::time::Instant;

/// One named check of `ci`.
type Step = (&'static str, fn() -> Result<()>);

pub fn ci() -> Result<()> {
    let steps: [Step; 9] = [
        ("tidy", crate::tidy::tidy),
        ("fmt", fmt),
        ("clippy", clippy),
        ("features", features),
        ("test", test),
        ("doc", doc),
        ("package", crate::package::package),
        ("examples", crate::examples::examples),
        ("smoke", crate::smoke::smoke),
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

/// The library crates, each checked alone with no default features and with all of them.
pub const LIBRARIES: [&str; 6] = [
    "terrain-core",
    "terrain-lod",
    "terrain-cache",
    "terrain-gpu",
    "terrain-physics",
    "terrain-shaders",
];

/// Every library crate builds (and passes clippy) with `--no-default-features` and with
/// `--all-features`: what an engine that picks its features gets. One run per feature choice
/// for all six libraries rather than one per library (twelve runs checked the dependencies
/// again for each feature set: 276 s of a cold CI run on 2 cores). Selecting them together
/// changes nothing about the libraries' own features: no library depends on another with a
/// feature turned on (terrain-core and terrain-lod are taken without default features, and
/// nothing depends on terrain-cache, terrain-gpu or terrain-physics), so each still builds with
/// only its own choice. Only external crates' features are unified between them.
fn features() -> Result<()> {
    for features in ["--no-default-features", "--all-features"] {
        let mut args = vec!["clippy"];
        for krate in LIBRARIES {
            args.extend(["-p", krate]);
        }
        args.extend([features, "--lib", "--locked", "--", "-D", "warnings"]);
        cargo(&args, &[]).with_context(|| format!("the libraries with {features}"))?;
    }
    Ok(())
}

fn fmt() -> Result<()> {
    cargo(&["fmt", "--all", "--", "--check"], &[])
}

/// The features of the workspace's optional adapters that the default build leaves out:
/// terrain-cache's S3 backend and terrain-physics's parry heightfields. Clippy, the tests and
/// rustdoc see them in the same run as the rest of the workspace rather than in runs of their
/// own. Each library without them, and with every feature, is the `features` step's.
pub const ADAPTERS: &str = "terrain-cache/aws,terrain-physics/parry";

fn clippy() -> Result<()> {
    cargo(
        &[
            "clippy",
            "--workspace",
            "--all-targets",
            "--features",
            ADAPTERS,
            "--locked",
            "--",
            "-D",
            "warnings",
        ],
        &[],
    )
}

fn test() -> Result<()> {
    // One build for every test: the workspace with the adapters' features, so terrain-cache's
    // S3 tests and terrain-physics's parry tests run in it instead of in single-crate runs that
    // resolved (and built) the dependencies again, 4-5 minutes of a cold run on 2 cores.
    // GPU tests fail instead of skipping when no adapter is found (DESIGN.md), and the S3
    // tests (against moto, the S3-compatible server .ci/run installs, behind a fault-injecting
    // proxy) when the server cannot be started.
    cargo(
        &["test", "--workspace", "--features", ADAPTERS, "--locked"],
        &[("TERRAIN_REQUIRE_GPU", "1"), ("TERRAIN_REQUIRE_S3", "1")],
    )?;
    gpu_tests_on_gl()?;
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
    )
}

/// terrain-gpu's tests again on the GL fallback (llvmpipe), which a machine without Vulkan
/// gets: its shader compiler has its own bugs (the atlas lookup once read wrong heights there).
///
/// The test binaries the workspace run built are run as they are (cargo lists them and builds
/// nothing new; the listing must name the same features as the run) rather than through
/// `cargo test -p terrain-gpu`: alone, terrain-gpu resolves
/// wgpu with other features than the workspace does, which rebuilt wgpu, naga and every crate
/// above them, 4.6 minutes of a cold CI run on 2 cores.
fn gpu_tests_on_gl() -> Result<()> {
    let output = Command::new(cargo_exe())
        .args([
            "test",
            "--workspace",
            "--features",
            ADAPTERS,
            "--locked",
            "--tests",
            "--no-run",
            "--message-format=json-render-diagnostics",
        ])
        .current_dir(root())
        .stderr(Stdio::inherit())
        .output()
        .context("could not start cargo test --no-run")?;
    if !output.status.success() {
        bail!("`cargo test --no-run` exited with {}", output.status);
    }
    let package = root().join("terrain-gpu");
    let mut binaries = Vec::new();
    for line in String::from_utf8_lossy(&output.stdout).lines() {
        let Ok(message) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let ours = message["reason"] == "compiler-artifact"
            && message["profile"]["test"] == true
            && message["manifest_path"]
                .as_str()
                .is_some_and(|p| std::path::Path::new(p).ends_with("terrain-gpu/Cargo.toml"));
        if let (true, Some(exe)) = (ours, message["executable"].as_str()) {
            binaries.push(exe.to_owned());
        }
    }
    // The library's unit tests and one binary per file in tests/.
    if binaries.len() < 2 {
        bail!(
            "cargo listed {} test binaries of terrain-gpu",
            binaries.len()
        );
    }
    for exe in &binaries {
        eprintln!("xtask ci: {exe} on GL");
        let mut cmd = Command::new(exe);
        cmd.current_dir(&package)
            .env("CARGO_MANIFEST_DIR", &package)
            .env("TERRAIN_REQUIRE_GPU", "1")
            .env("WGPU_BACKEND", "gl");
        quiet_device_select(&mut cmd);
        let status = cmd
            .status()
            .with_context(|| format!("could not start {exe}"))?;
        if !status.success() {
            bail!("{exe} on GL exited with {status}");
        }
    }
    Ok(())
}

fn doc() -> Result<()> {
    cargo(
        &[
            "doc",
            "--workspace",
            "--features",
            ADAPTERS,
            "--no-deps",
            "--locked",
        ],
        &[("RUSTDOCFLAGS", "-D warnings")],
    )
}
