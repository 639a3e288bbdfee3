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
    // packed-refs after a gc).
    let mut watched = vec!["HEAD".to_string(), "packed-refs".to_string()];
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watched.push(branch);
    }
    for name in watched {
        if let Some(path) = git(&["rev-parse", "--git-path", &name]) {
            println!("cargo:rerun-if-changed={path}");
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
}
