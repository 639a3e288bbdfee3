//! A named pipe, a directory or a device given as `--heightmap` is refused at once with a
//! clear one-line error and exit status 2: the demo never blocks opening or reading it.

mod common;

use common::{demo, fresh_dir, run_within};
use std::path::Path;
use std::time::Duration;

/// Far above the fraction of a second a refusal takes; a demo blocked on a pipe never ends.
const LIMIT: Duration = Duration::from_secs(30);

fn refused(name: &str, heightmap: &Path, extra: &[&str], kind: &str) {
    let dir = fresh_dir(name);
    let mut cmd = demo();
    cmd.arg("--heightmap")
        .arg(heightmap)
        .args(extra)
        .args(["--no-gpu", "--frames", "1"])
        .arg("--out")
        .arg(dir.join("out"));
    let done = run_within(cmd, &dir, LIMIT);
    assert_eq!(done.status.code(), Some(2), "{name}: {}", done.stderr);
    let lines: Vec<&str> = done.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{name}: one line: {}", done.stderr);
    assert!(
        lines[0].contains(kind) && lines[0].contains("not a regular file"),
        "{name}: {}",
        done.stderr
    );
    assert!(
        lines[0].contains(&heightmap.display().to_string()),
        "{name}: names the file: {}",
        done.stderr
    );
    assert!(!dir.join("out/report.json").exists(), "{name}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_named_pipe_is_refused_without_blocking() {
    let dir = fresh_dir("fifo_src");
    let fifo = dir.join("heights.png");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(made.success(), "mkfifo failed");
    // Nobody ever opens the pipe for writing: opening it to read would block for ever.
    refused("fifo_png", &fifo, &[], "named pipe");
    refused("fifo_raw", &fifo, &["--raw-size", "64x64"], "named pipe");
    refused(
        "fifo_flyover",
        &fifo,
        &[
            "--scenario",
            "flyover",
            "--world",
            &dir.join("world").display().to_string(),
        ],
        "named pipe",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_directory_is_refused() {
    let dir = fresh_dir("dir_src");
    refused("dir_png", &dir, &[], "directory");
    refused("dir_raw", &dir, &["--raw-size", "64x64"], "directory");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_device_is_refused() {
    let null = Path::new("/dev/null");
    assert!(
        null.exists(),
        "/dev/null exists on the systems the demo runs on"
    );
    refused("dev_png", null, &[], "device");
    refused("dev_raw", null, &["--raw-size", "64x64"], "device");
}

#[test]
fn a_world_whose_manifest_is_a_named_pipe_is_refused_without_blocking() {
    let dir = fresh_dir("fifo_manifest");
    let world = dir.join("world");
    std::fs::create_dir_all(&world).expect("world folder");
    let made = std::process::Command::new("mkfifo")
        .arg(world.join("manifest.json"))
        .status()
        .expect("mkfifo runs");
    assert!(made.success(), "mkfifo failed");
    for args in [
        vec!["verify-world".to_string(), world.display().to_string()],
        vec![
            "--scenario".into(),
            "flyover".into(),
            "--no-gpu".into(),
            "--world".into(),
            world.display().to_string(),
            "--out".into(),
            dir.join("out").display().to_string(),
        ],
    ] {
        let mut cmd = demo();
        cmd.args(&args);
        let done = run_within(cmd, &dir, LIMIT);
        assert_eq!(done.status.code(), Some(2), "{args:?}: {}", done.stderr);
        assert!(
            done.stderr.contains("not a manifest file"),
            "{args:?}: {}",
            done.stderr
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `frames.jsonl` that is a link (to a file outside `--out`) or a named pipe: refused with
/// exit status 2, the link's target untouched, no blocking on the pipe; a regular file of an
/// earlier run is replaced.
#[test]
fn an_output_that_is_a_link_or_a_pipe_is_refused_not_written_through() {
    let dir = fresh_dir("frames_jsonl");
    let outside = dir.join("precious.txt");
    std::fs::write(&outside, "keep me").expect("outside file");
    let run = |out: &Path| {
        let mut cmd = demo();
        cmd.args(["--no-gpu", "--frames", "2", "--size", "64", "-q", "--out"])
            .arg(out);
        run_within(cmd, &dir, LIMIT)
    };
    let linked = dir.join("linked");
    std::fs::create_dir_all(&linked).expect("out folder");
    std::os::unix::fs::symlink(&outside, linked.join("frames.jsonl")).expect("symlink");
    let done = run(&linked);
    assert_eq!(done.status.code(), Some(2), "{}", done.stderr);
    assert!(done.stderr.contains("symbolic link"), "{}", done.stderr);
    assert_eq!(std::fs::read_to_string(&outside).unwrap(), "keep me");

    let piped = dir.join("piped");
    std::fs::create_dir_all(&piped).expect("out folder");
    let made = std::process::Command::new("mkfifo")
        .arg(piped.join("frames.jsonl"))
        .status()
        .expect("mkfifo runs");
    assert!(made.success(), "mkfifo failed");
    let done = run(&piped);
    assert_eq!(done.status.code(), Some(2), "{}", done.stderr);
    assert!(done.stderr.contains("special file"), "{}", done.stderr);

    let earlier = dir.join("earlier");
    std::fs::create_dir_all(&earlier).expect("out folder");
    std::fs::write(earlier.join("frames.jsonl"), "an earlier run\n").expect("old lines");
    let done = run(&earlier);
    assert_eq!(done.status.code(), Some(0), "{}", done.stderr);
    let lines = std::fs::read_to_string(earlier.join("frames.jsonl")).unwrap();
    assert_eq!(lines.lines().count(), 2, "{lines}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A full standard stream (`/dev/full`) ends the run with its status, never with a panic
/// (exit 101): what was asked for on stdout fails with 1, messages on stderr are dropped.
#[test]
fn a_full_stdout_or_stderr_is_an_error_not_a_panic() {
    let full = || {
        std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .expect("/dev/full")
    };
    let status = demo()
        .arg("print-config")
        .stdout(full())
        .stderr(std::process::Stdio::null())
        .status()
        .expect("demo runs");
    assert_eq!(status.code(), Some(1), "print-config into /dev/full");
    let status = demo()
        .arg("--help")
        .stdout(full())
        .status()
        .expect("demo runs");
    assert_eq!(status.code(), Some(1), "--help into /dev/full");
    let status = demo()
        .args(["--frames", "abc"])
        .stderr(full())
        .status()
        .expect("demo runs");
    assert_eq!(status.code(), Some(2), "a usage error with stderr full");
    let dir = fresh_dir("full_stderr");
    let status = demo()
        .args(["--no-gpu", "--frames", "3", "--size", "64", "--out"])
        .arg(dir.join("out"))
        .stderr(full())
        .status()
        .expect("demo runs");
    assert_eq!(status.code(), Some(0), "a run with stderr full");
    assert!(dir.join("out/report.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
