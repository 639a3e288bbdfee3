//! Helpers shared by the tests that run the demo as a child process: a fresh output folder,
//! and a run with a deadline, so a demo that hangs fails its test instead of blocking it.

#![allow(dead_code)] // Each test file uses its own subset.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The demo binary.
pub fn demo() -> Command {
    Command::new(env!("CARGO_BIN_EXE_terrain-demo"))
}

/// A fresh, empty folder under the system temp folder, unique to this process and `name`.
pub fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("terrain_demo_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp folder");
    dir
}

/// What a finished child left.
#[derive(Debug)]
pub struct Finished {
    pub status: ExitStatus,
    pub stderr: String,
    pub elapsed: Duration,
}

/// Runs `cmd` to its end, killing it (and failing) after `limit`. Its stderr goes to a file
/// beside `dir` (a pipe could fill up and stall a chatty child).
pub fn run_within(mut cmd: Command, dir: &Path, limit: Duration) -> Finished {
    let log = dir.join("stderr.txt");
    let file = std::fs::File::create(&log).expect("stderr file");
    let started = Instant::now();
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::from(file))
        .spawn()
        .expect("demo starts");
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "the demo ran longer than {limit:?} (a hang?); stderr: {}",
                std::fs::read_to_string(&log).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Finished {
        status,
        stderr: std::fs::read_to_string(&log).unwrap_or_default(),
        elapsed: started.elapsed(),
    }
}

/// Checks that `stderr` is one usage error and returns its first line: one line of the
/// demo's own (a flag out of range or out of place, an unreadable input), or clap's whole
/// message for a command line it cannot parse (the error line, any tips and usage line, and
/// the pointer to `--help`).
pub fn usage_error(stderr: &str) -> &str {
    let first = stderr.lines().next().unwrap_or_default();
    assert!(
        first.starts_with("error: "),
        "an error line first: {stderr}"
    );
    if stderr.trim_end().lines().count() > 1 {
        assert!(
            stderr
                .trim_end()
                .ends_with("For more information, try '--help'."),
            "clap's pointer to --help last: {stderr}"
        );
    }
    first
}

/// report.json of the run in `out`.
pub fn report(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    serde_json::from_str(&text).expect("report.json parses")
}

/// Every tile file of a world (heights, holes, paint): path under the world -> bytes.
pub fn tile_files(world: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    // The heights, the holes and paint laid over them and the footprints' detail tiles
    // (folders made on first write).
    let mut stack: Vec<_> = ["height", "hole", "material", "detail"]
        .iter()
        .map(|l| world.join(l))
        .filter(|d| d.is_dir())
        .collect();
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).expect("world folder") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let key = p
                    .strip_prefix(world)
                    .expect("under world")
                    .display()
                    .to_string();
                out.insert(key, std::fs::read(&p).expect("tile"));
            }
        }
    }
    out
}

/// Sends Ctrl-C (SIGINT) to `child` and waits for it to end, killing it (and failing) after
/// `limit`; returns its status and how long it took to end after the signal.
pub fn interrupt_and_wait(child: &mut Child, limit: Duration) -> (ExitStatus, Duration) {
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(sent.success());
    let interrupted = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return (status, interrupted.elapsed());
        }
        if interrupted.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the demo did not end within {limit:?} after Ctrl-C");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
