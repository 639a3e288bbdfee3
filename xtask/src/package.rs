//! `cargo xtask package`: packages every publishable crate as crates.io would receive it and
//! verifies that each package builds on its own from its `.crate`, so a crate that only builds
//! inside the workspace is caught before a release. It first checks that CHANGELOG.md has a
//! section for every version being packaged.

use crate::util::{cargo, root, workspace_metadata};
use anyhow::{Context, Result, bail};

/// Packages and verifies the publishable crates (cargo >= 1.90 packages workspace members that
/// depend on one another through a local registry, without publishing them first).
///
/// Verification is kept: it builds the world again (the packaged manifests carry none of the
/// workspace's profiles). The libraries took 69 s from cold and about 10 s warm on the
/// project's 2-core machine; the demo (packaged too, so that `cargo install` from its package
/// is checked) adds its own dependencies. Resolving the packages' dependencies reads the
/// crates.io index.
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
    for (name, _) in &crates {
        args.extend(["-p", name.as_str()]);
    }
    // Verification only has to build: without debug info it builds faster (its own target
    // folder, so the workspace's builds are untouched).
    cargo(&args, &[("CARGO_PROFILE_DEV_DEBUG", "false")])?;
    eprintln!("package: {} crates packaged and verified", crates.len());
    Ok(())
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
