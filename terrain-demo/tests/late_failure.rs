//! A failure found during the run (here: the streamed world's finest tiles are corrupt, found
//! when the RAM pool loads them after the first frame) still leaves report.json and
//! summary.png for the frames done, with the error in the report, and the run exits with 1.

mod common;

use common::{demo, fresh_dir, report, run_within};
use std::path::Path;
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(300);

fn flyover(world: &Path, out: &Path, frames: &str, dir: &Path) -> common::Finished {
    let mut cmd = demo();
    cmd.args(["--scenario", "flyover", "--size", "2048", "--no-gpu"])
        .args([
            "--ram-budget",
            "8",
            "--overview-size",
            "64",
            "--frames",
            frames,
        ])
        .arg("--world")
        .arg(world)
        .arg("--out")
        .arg(out);
    run_within(cmd, dir, LIMIT)
}

#[test]
fn a_corrupt_tile_found_mid_run_still_writes_the_report_and_exits_1() {
    let dir = fresh_dir("late_failure");
    let world = dir.join("world");
    // Build the world (and check it runs cleanly).
    let built = flyover(&world, &dir.join("build"), "1", &dir);
    assert_eq!(built.status.code(), Some(0), "{}", built.stderr);
    // Corrupt every finest tile: the overview is made from a coarser level, so the run
    // starts, and fails when the pool first loads one of them.
    let level0 = world.join("height/00");
    let mut corrupted = 0;
    let mut stack = vec![level0];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("level 0") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "tile") {
                std::fs::write(&p, b"not a tile").expect("corrupt");
                corrupted += 1;
            }
        }
    }
    assert!(corrupted > 0, "no level-0 tiles found");
    let out = dir.join("out");
    let done = flyover(&world, &out, "60", &dir);
    assert_eq!(done.status.code(), Some(1), "{}", done.stderr);
    assert!(done.stderr.contains("tile"), "{}", done.stderr);
    let r = report(&out);
    let frames = r["frames"].as_array().expect("frames");
    assert!(
        !frames.is_empty() && frames.len() < 60,
        "{} frames",
        frames.len()
    );
    let error = r["error"]
        .as_str()
        .expect("the report says why the run ended");
    assert!(error.contains("tile"), "{error}");
    assert_eq!(r["interrupted"].as_bool(), Some(false));
    assert!(out.join("summary.png").is_file(), "summary.png is written");
    let lines = std::fs::read_to_string(out.join("frames.jsonl")).expect("frames.jsonl");
    assert_eq!(lines.lines().count(), frames.len());
    let _ = std::fs::remove_dir_all(&dir);
}
