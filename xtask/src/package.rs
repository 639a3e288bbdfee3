//! `cargo xtask package`: packages every publishable crate as crates.io would receive it and
//! verifies that each package builds on its own from its `.crate`, so a crate that only builds
//! inside the workspace is caught before a release. It first checks that CHANGELOG.md has a
//! section for every version being packaged.

use crate::util::{cargo, root, workspace_metadata};
use anyhow::{Context, Result, bail};

/// Packages the publishable crates and verifies that they build from their `.crate` files
/// alone (cargo >= 1.90 packages workspace members that depend on one another through a local
/// registry, without publishing them first).
///
/// Verification is a `cargo check` of the unpacked packages, not `cargo package`'s own build:
/// what a package can lack (a file it includes, a build script's input, a dependency or feature
/// its manifest does not declare) fails type-checking as it fails a build, and a check skips
/// code generation and linking. cargo's verification built every dependency again without the
/// workspace's profiles: 283 s of a cold CI run on 2 cores, 216 s of it the demo's.
pub fn package() -> Result<()> {
    let crates = publishable_crates()?;
    if crates.is_empty() {
        bail!("no publishable crate found in `cargo metadata`");
    }
    let changelog = std::fs::read_to_string(root().join("CHANGELOG.md"))
        .context("reading CHANGELOG.md (every release has a section there)")?;
    for (name, version) in &crates {
        if !has_section(&changelog, version) {
            bail!("CHANGELOG.md has no `## {version}` section, but {name} {version} is packaged");
        }
    }
    clear_package_overlays()?;
    let target = root().join("target").join("package-verify");
    let target_s = target.to_string_lossy().into_owned();
    let mut args = vec![
        "package",
        "--no-verify",
        "--allow-dirty",
        "--locked",
        "--target-dir",
        &target_s,
    ];
    for (name, _) in &crates {
        args.extend(["-p", name.as_str()]);
    }
    cargo(&args, &[])?;
    let unpacked = unpack(&target, &crates)?;
    // The workspace's lock file, so that the check sees the dependency versions the tests ran
    // with (cargo's own verification starts from it too), and its target folder: dependencies
    // checked by the clippy step with the same features are not checked again.
    std::fs::copy(root().join("Cargo.lock"), unpacked.join("Cargo.lock"))
        .context("copying Cargo.lock next to the unpacked packages")?;
    let manifest = unpacked.join("Cargo.toml").to_string_lossy().into_owned();
    let main_target = crate::util::target_dir().to_string_lossy().into_owned();
    cargo(
        &[
            "check",
            "--workspace",
            "--manifest-path",
            &manifest,
            "--target-dir",
            &main_target,
        ],
        &[],
    )?;
    eprintln!("package: {} crates packaged and verified", crates.len());
    Ok(())
}

/// Unpacks each crate's `.crate` file under `target/package-verify/unpacked` and writes a
/// workspace around them in which their dependencies on one another resolve to the unpacked
/// copies (`[patch.crates-io]`, as they would resolve to the published ones), with this
/// workspace's profiles.
fn unpack(target: &std::path::Path, crates: &[(String, String)]) -> Result<std::path::PathBuf> {
    let unpacked = target.join("unpacked");
    if unpacked.exists() {
        std::fs::remove_dir_all(&unpacked)
            .with_context(|| format!("removing {}", unpacked.display()))?;
    }
    std::fs::create_dir_all(&unpacked)
        .with_context(|| format!("creating {}", unpacked.display()))?;
    let mut members = String::new();
    let mut patches = String::new();
    for (name, version) in crates {
        let file = target
            .join("package")
            .join(format!("{name}-{version}.crate"));
        // `-m`: the files get the time of extraction. A `.crate` stores one fixed time for every
        // file, older than any check of an earlier run, whose stale artifacts cargo would then
        // take as current (the unpacked folders have the same paths every run).
        let status = std::process::Command::new("tar")
            .arg("-xzmf")
            .arg(&file)
            .arg("-C")
            .arg(&unpacked)
            .status()
            .with_context(|| format!("could not start tar for {}", file.display()))?;
        if !status.success() {
            bail!("unpacking {} exited with {status}", file.display());
        }
        members.push_str(&format!("\"{name}-{version}\", "));
        patches.push_str(&format!("{name} = {{ path = \"{name}-{version}\" }}\n"));
    }
    let ours = std::fs::read_to_string(root().join("Cargo.toml")).context("reading Cargo.toml")?;
    // The `[profile.*]` tables, whatever follows them.
    let mut profiles = String::new();
    let mut in_profile = false;
    for line in ours.lines() {
        if line.starts_with('[') {
            in_profile = line.starts_with("[profile.");
        }
        if in_profile {
            profiles.push_str(line);
            profiles.push('\n');
        }
    }
    let manifest = format!(
        "[workspace]\nmembers = [{members}]\nresolver = \"3\"\n\n[patch.crates-io]\n{patches}\n{profiles}"
    );
    std::fs::write(unpacked.join("Cargo.toml"), manifest)
        .context("writing the packages' workspace")?;
    Ok(unpacked)
}

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

/// Whether `changelog` has a level-2 heading for `version`: `## 0.1.0`, `## [0.1.0]`, followed
/// by the end of the line or a space (`## 0.1.0 (unreleased)`, `## 0.1.0 - 2027-01-10`).
fn has_section(changelog: &str, version: &str) -> bool {
    changelog.lines().any(|line| {
        let Some(title) = line.strip_prefix("## ") else {
            return false;
        };
        let title = title.trim_start();
        let rest = match title.strip_prefix('[') {
            Some(bracketed) => bracketed
                .strip_prefix(version)
                .and_then(|r| r.strip_prefix(']')),
            None => title.strip_prefix(version),
        };
        rest.is_some_and(|r| r.is_empty() || r.starts_with(' '))
    })
}

/// The workspace members without `publish = false`, with their versions, from `cargo metadata`.
fn publishable_crates() -> Result<Vec<(String, String)>> {
    let metadata = workspace_metadata()?;
    // `publish` is null when publishing is allowed anywhere, `[]` for `publish = false`.
    Ok(metadata["packages"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|p| p["publish"].as_array().is_none_or(|r| !r.is_empty()))
        .filter_map(|p| {
            Some((
                p["name"].as_str()?.to_owned(),
                p["version"].as_str()?.to_owned(),
            ))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::has_section;

    #[test]
    fn a_release_needs_its_own_heading() {
        let log = "# Changelog\n\n## 0.2.0 (unreleased)\n- new\n\n## [0.1.0] - 2027-01-10\n";
        assert!(has_section(log, "0.2.0"));
        assert!(has_section(log, "0.1.0"));
        // Mentions, prefixes and other heading levels are not sections.
        assert!(!has_section(log, "0.1"));
        assert!(!has_section(log, "0.2.0.1"));
        assert!(!has_section("## 0.1.00\n", "0.1.0"));
        assert!(!has_section("### 0.3.0\n", "0.3.0"));
        assert!(!has_section("since 0.3.0\n", "0.3.0"));
        assert!(!has_section("", "0.1.0"));
    }
}
