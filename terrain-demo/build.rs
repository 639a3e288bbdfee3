//! Records the git commit the demo is built from, for report.json's `tool.git_revision`.

use std::process::Command;

/// `git args...` in the package's folder, trimmed, or `None` when git or the checkout is absent.
fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    let text = String::from_utf8(out.stdout).ok()?;
    (out.status.success() && !text.trim().is_empty()).then(|| text.trim().to_string())
}

/// The commit a packaged copy (`cargo install terrain-demo`) was made from: `cargo package`
/// records it in `.cargo_vcs_info.json` as `"sha1": "<40 hex digits>"`.
fn packaged_revision() -> Option<String> {
    let text = std::fs::read_to_string(".cargo_vcs_info.json").ok()?;
    let after = text.split("\"sha1\"").nth(1)?;
    let hex: String = after
        .chars()
        .skip_while(|c| !c.is_ascii_hexdigit())
        .take_while(char::is_ascii_hexdigit)
        .take(12)
        .collect();
    (hex.len() == 12).then_some(hex)
}

fn main() {
    let revision = packaged_revision()
        .or_else(|| git(&["rev-parse", "--short=12", "HEAD"]))
        .unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=TERRAIN_DEMO_GIT_REVISION={revision}");
    // Built again when HEAD moves: a checkout (HEAD) or a commit on the branch (its ref, or
    // packed-refs after a gc). Only files that exist are watched: cargo runs a build script
    // again on every build while a watched file is missing, which rebuilt the demo and all its
    // tests at each cargo command of a CI run (a checkout without packed-refs). A branch whose
    // ref lives only in packed-refs has its folder watched, where its next commit writes it.
    let mut watched = vec![
        ("HEAD".to_string(), false),
        ("packed-refs".to_string(), false),
    ];
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watched.push((branch, true));
    }
    for (name, or_folder) in watched {
        let Some(path) = git(&["rev-parse", "--git-path", &name]) else {
            continue;
        };
        let path = std::path::Path::new(&path);
        if path.exists() {
            println!("cargo:rerun-if-changed={}", path.display());
        } else if let Some(folder) = path.parent().filter(|f| or_folder && f.is_dir()) {
            println!("cargo:rerun-if-changed={}", folder.display());
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
}
