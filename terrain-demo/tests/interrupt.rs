//! Ctrl-C (SIGINT) ends a run after the frame in progress: `report.json` is written and
//! lists exactly the frames done (those of `frames.jsonl`, each line written as its frame
//! completed), marked `interrupted`, with `summary.png` beside it; the exit status is 130.

mod common;

use common::{demo, fresh_dir};
use std::process::Stdio;
use std::time::{Duration, Instant};

const LIMIT: Duration = Duration::from_secs(120);

fn lines_of(path: &std::path::Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line of frames.jsonl is a frame"))
        .collect()
}

#[test]
fn ctrl_c_leaves_a_valid_report_of_the_frames_done() {
    let dir = fresh_dir("interrupt");
    let out = dir.join("out");
    let mut child = demo()
        .args(["--no-gpu", "--size", "64", "--overview-size", "64"])
        .args(["--frames", "100000"])
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("demo starts");
    let started = Instant::now();
    let jsonl = out.join("frames.jsonl");
    // Wait for a few frames (a never-growing frames.jsonl fails here, not by blocking).
    while lines_of(&jsonl).len() < 3 {
        if started.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("no 3 frames in frames.jsonl after {LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let (status, _) = common::interrupt_and_wait(&mut child, LIMIT);
    assert_eq!(status.code(), Some(130), "{status}");

    let report = common::report(&out);
    assert_eq!(report["interrupted"].as_bool(), Some(true), "{report}");
    assert_eq!(report["frames_requested"].as_u64(), Some(100000));
    let frames = report["frames"].as_array().expect("frames");
    let listed = lines_of(&jsonl);
    assert!(frames.len() >= 3, "{} frames", frames.len());
    assert!(frames.len() < 100000);
    assert_eq!(frames.len(), listed.len(), "report and frames.jsonl agree");
    for (i, (f, l)) in frames.iter().zip(&listed).enumerate() {
        assert_eq!(f["index"].as_u64(), Some(i as u64));
        assert_eq!(f["index"], l["index"]);
        assert_eq!(f["file"], l["file"]);
        let file = f["file"].as_str().expect("file");
        assert!(out.join(file).is_file(), "{file}");
    }
    // No frame beyond those listed was written.
    assert!(!out.join(format!("frame_{:04}.png", frames.len())).exists());
    assert!(out.join("summary.png").is_file());
    assert!(out.join("terrain_final.png").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_while_a_world_is_built_cancels_the_build() {
    let dir = fresh_dir("interrupt_build");
    let world = dir.join("world");
    let log = dir.join("stderr.txt");
    // The default world (16384^2, 5461 tiles) takes far longer to build than this test waits.
    let mut child = demo()
        .args(["--no-gpu", "--scenario", "flyover", "--frames", "3"])
        .arg("--world")
        .arg(&world)
        .arg("--out")
        .arg(dir.join("out"))
        .stdout(Stdio::null())
        .stderr(Stdio::from(std::fs::File::create(&log).expect("log")))
        .spawn()
        .expect("demo starts");
    let started = Instant::now();
    while !std::fs::read_to_string(&log)
        .unwrap_or_default()
        .contains("building world")
    {
        if started.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the build never started");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let (status, after) = common::interrupt_and_wait(&mut child, LIMIT);
    let stderr = std::fs::read_to_string(&log).unwrap_or_default();
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(
        after < Duration::from_secs(20),
        "the build stopped {after:?} after Ctrl-C"
    );
    // No manifest: the next run builds the world again rather than opening half of it.
    assert!(!world.join("manifest.json").exists());
    assert!(!dir.join("out/report.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
