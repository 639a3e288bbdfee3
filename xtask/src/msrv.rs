//! `cargo xtask msrv`: builds the workspace with the Rust version the manifests declare
//! (`rust-version`), so the declaration is a checked fact rather than a hope. Not a step of
//! `cargo xtask ci`: it needs rustup to fetch that toolchain, which the CI machine cannot (it
//! has one toolchain and reaches no toolchain server), and a second compiler's build of the
//! dependencies would not fit CI's time budget. Run it before a release.

use crate::ci::LIBRARIES;
use crate::util::{root, target_dir, workspace_metadata};
use anyhow::{Context, Result, bail};
use std::process::Command;

/// Installs the declared toolchain (minimal, with clippy) and checks with it: the whole
/// workspace with every target, then each library crate with no default features under
/// clippy (what a user who turns the defaults off compiles).
pub fn msrv() -> Result<()> {
    let version = declared_rust_version()?;
    run(
        Command::new("rustup").args([
            "toolchain",
            "install",
            &version,
            "--profile",
            "minimal",
            "--component",
            "clippy",
        ]),
        "rustup (the MSRV check needs rustup to install the declared toolchain)",
    )?;
    // A folder of its own: the stable build's artifacts stay valid.
    let target = target_dir().join("msrv");
    let target = target.to_string_lossy();
    let with_msrv = |args: &[&str]| {
        let mut cmd = Command::new("rustup");
        cmd.args(["run", &version, "cargo"])
            .args(args)
            .args(["--locked", "--target-dir", &target]);
        cmd
    };
    run(
        &mut with_msrv(&["check", "--workspace", "--all-targets"]),
        "cargo check with the declared Rust version",
    )?;
    for krate in LIBRARIES {
        let mut cmd = with_msrv(&["clippy", "-p", krate, "--no-default-features", "--lib"]);
        cmd.args(["--", "-D", "warnings"]);
        run(
            &mut cmd,
            &format!("cargo clippy -p {krate} with Rust {version}"),
        )?;
    }
    eprintln!("msrv: the workspace builds with Rust {version}, the declared rust-version");
    Ok(())
}

/// The workspace's `rust-version` (every member inherits it), from `cargo metadata`.
fn declared_rust_version() -> Result<String> {
    let metadata = workspace_metadata()?;
    let mut versions: Vec<&str> = metadata["packages"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|p| p["rust_version"].as_str())
        .collect();
    versions.sort_unstable();
    versions.dedup();
    match versions.as_slice() {
        [one] => Ok((*one).to_owned()),
        [] => bail!("no workspace member declares a rust-version"),
        many => bail!(
            "members declare different rust-versions: {}",
            many.join(", ")
        ),
    }
}

/// Runs `cmd` in the workspace root; fails naming `what` when it cannot start or fails.
fn run(cmd: &mut Command, what: &str) -> Result<()> {
    let status = cmd
        .current_dir(root())
        .env_remove("RUSTUP_TOOLCHAIN")
        .env_remove("CARGO")
        .status()
        .with_context(|| format!("could not start {what}"))?;
    if !status.success() {
        bail!("{what} exited with {status}");
    }
    Ok(())
}
