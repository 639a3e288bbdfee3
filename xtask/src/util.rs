//! What every command shares: where the workspace is, how cargo and the demo binary are run,
//! and how a generated file is written without leaving half of it behind.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The workspace root (xtask lives one level below it).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// Cargo's target folder: `CARGO_TARGET_DIR` when set, else `target/` in the workspace root.
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
}

/// The cargo that runs xtask (`CARGO`), else the one on the path.
pub fn cargo_exe() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

/// Runs `cargo` with `args` (and extra environment) in the workspace root.
pub fn cargo(args: &[&str], env: &[(&str, &str)]) -> Result<()> {
    let mut cmd = Command::new(cargo_exe());
    cmd.args(args).current_dir(root());
    quiet_device_select(&mut cmd);
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

/// The workspace's members as `cargo metadata --no-deps` describes them (JSON).
pub fn workspace_metadata() -> Result<serde_json::Value> {
    let output = Command::new(cargo_exe())
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
    serde_json::from_slice(&output.stdout).context("cargo metadata is not valid JSON")
}

/// Runs the demo binary as the test step built it: `cargo test --workspace` builds it with the
/// workspace's unified features, and a `cargo run -p terrain-demo` would resolve the demo's own
/// and rebuild wgpu and its dependencies (minutes on two cores). `cargo test --no-run` with the
/// test step's features makes it current first (nothing to do right after the test step).
pub fn demo(args: &[&str], env: &[(&str, &str)]) -> Result<()> {
    cargo(
        &[
            "test",
            "--workspace",
            "--features",
            crate::ci::ADAPTERS,
            "--locked",
            "--no-run",
        ],
        &[],
    )?;
    let exe = root()
        .join("target")
        .join("debug")
        .join(format!("terrain-demo{}", std::env::consts::EXE_SUFFIX));
    let mut cmd = Command::new(&exe);
    cmd.args(args).current_dir(root());
    quiet_device_select(&mut cmd);
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

/// Mesa's Vulkan device-select layer prints `XDG_RUNTIME_DIR is invalid or not set` for every
/// GPU test on a machine without a desktop session; it only reorders adapters, which
/// terrain-gpu ranks itself (the demo turns it off the same way).
pub fn quiet_device_select(cmd: &mut Command) {
    if std::env::var_os("MESA_VK_DEVICE_SELECT").is_none() {
        cmd.env("NODEVICE_SELECT", "1");
    }
}

/// Writes `bytes` to `path` through a temporary file beside it (fsynced, then renamed over
/// `path`), so an interrupted run leaves the old file or the new one, never half of one. The
/// file need not exist yet; its folder is created when missing.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let tmp = path.with_extension("tmp-xtask");
    let mut f =
        std::fs::File::create(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    f.write_all(bytes)?;
    f.sync_all()?;
    drop(f);
    std::fs::rename(&tmp, path).with_context(|| format!("renaming over {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_atomically_creates_a_missing_file_and_replaces_it() {
        let dir = std::env::temp_dir().join(format!("xtask-atomic-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("docs").join("OUT.md");
        write_atomically(&path, b"first").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "first");
        write_atomically(&path, b"second").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "second");
        let left: Vec<_> = std::fs::read_dir(dir.join("docs")).unwrap().collect();
        assert_eq!(left.len(), 1, "no temporary file is left behind");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
