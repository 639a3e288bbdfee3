//! Exit statuses: 2 for usage errors (bad flags, unreadable input), found before any frame;
//! 1 for failures while the run goes on (here a frame that cannot be written), after which
//! the frames already done are still listed in `frames.jsonl`, `report.json` and
//! `summary.png`.

mod common;

use common::{demo, fresh_dir, run_within};
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(120);

fn status_of(name: &str, args: &[&str]) -> (Option<i32>, String) {
    let dir = fresh_dir(name);
    let mut cmd = demo();
    cmd.args(args).arg("--out").arg(dir.join("out"));
    let done = run_within(cmd, &dir, LIMIT);
    let _ = std::fs::remove_dir_all(&dir);
    (done.status.code(), done.stderr)
}

#[test]
fn usage_errors_exit_with_2() {
    let dir = fresh_dir("usage_inputs");
    let missing = dir.join("missing.png").display().to_string();
    let garbage = dir.join("garbage.png");
    std::fs::write(&garbage, b"this is not a PNG file at all").expect("write");
    let garbage = garbage.display().to_string();
    let cases: [&[&str]; 17] = [
        &["--scenario", "snow", "--lod", "cdlod", "--no-gpu"],
        &["--scenario", "snow", "--detail", "parallax", "--no-gpu"],
        &["--lod", "cdlod", "--detail", "refine", "--no-gpu"],
        &["--lod", "tessellated", "--detail", "refine", "--no-gpu"],
        &["--lod", "cdlod", "--target-error", "0", "--no-gpu"],
        &["--target-error", "2", "--no-gpu"],
        &["--no-morph", "--no-gpu"],
        &["--density-map", "off", "--no-gpu"],
        &["--lod", "cdlod", "--triangle-width", "4", "--no-gpu"],
        &["--lod", "tessellated", "--triangle-width", "0", "--no-gpu"],
        &["--no-such-flag"],
        &["--frames", "0"],
        &["--texel-size", "-1", "--no-gpu"],
        &["--max-height", "NaN", "--no-gpu"],
        &["--heightmap", &missing, "--no-gpu"],
        &["--heightmap", &garbage, "--no-gpu"],
        &["--scenario", "snow", "--heightmap", &garbage, "--no-gpu"],
    ];
    for args in cases {
        let (code, stderr) = status_of("usage", args);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{args:?}: one line: {stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_failure_during_the_run_exits_with_1_and_keeps_the_frames_done() {
    let dir = fresh_dir("runtime_failure");
    let out = dir.join("out");
    // The second frame's file is taken by a folder that is not empty: writing it fails.
    std::fs::create_dir_all(out.join("frame_0001.png/inside")).expect("folder");
    let mut cmd = demo();
    cmd.args(["--no-gpu", "--size", "32", "--overview-size", "32"])
        .args(["--frames", "4"])
        .arg("--out")
        .arg(&out);
    let done = run_within(cmd, &dir, LIMIT);
    assert_eq!(done.status.code(), Some(1), "{}", done.stderr);
    assert!(done.stderr.contains("frame_0001.png"), "{}", done.stderr);
    // The first frame is done and listed; no temp file of the failed write is left.
    assert!(out.join("frame_0000.png").is_file());
    let lines = std::fs::read_to_string(out.join("frames.jsonl")).expect("frames.jsonl");
    let frames: Vec<serde_json::Value> = lines
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is a frame"))
        .collect();
    assert_eq!(frames.len(), 1, "{lines}");
    assert_eq!(frames[0]["index"].as_u64(), Some(0));
    // report.json and summary.png are still written, over the frame done, with the error.
    let report = common::report(&out);
    assert_eq!(report["frames"].as_array().map(Vec::len), Some(1));
    let error = report["error"].as_str().expect("error in report.json");
    assert!(error.contains("frame_0001.png"), "{error}");
    assert!(out.join("summary.png").is_file());
    let temps: Vec<String> = std::fs::read_dir(&out)
        .expect("out")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(temps.is_empty(), "temp files left: {temps:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
