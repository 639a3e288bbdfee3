//! A GPU device lost in the middle of a run (destroyed before a frame, while the collision
//! readbacks or the granular steps are in flight): the demo exits with status 1 and says the
//! device was lost, promptly, without a panic or a hang.

use std::process::Command;
use std::time::{Duration, Instant};

fn run_losing_the_device(scenario: &str, at_frame: u32) {
    let Some(_ctx) = terrain_gpu::testing::context_or_skip("demo_device_loss") else {
        return;
    };
    let out = std::env::temp_dir().join(format!(
        "terrain_device_loss_{scenario}_{}",
        std::process::id()
    ));
    let start = Instant::now();
    let output = Command::new(env!("CARGO_BIN_EXE_terrain-demo"))
        .args(["--scenario", scenario, "--size", "128", "--frames", "8"])
        .args(["--resolution", "64x48", "--out"])
        .arg(&out)
        .env("TERRAIN_DEMO_DESTROY_DEVICE_AT_FRAME", at_frame.to_string())
        .output()
        .expect("the demo runs");
    let took = start.elapsed();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{scenario}: {stderr}");
    assert!(stderr.contains("device was lost"), "{scenario}: {stderr}");
    assert!(!stderr.contains("panicked"), "{scenario}: {stderr}");
    assert!(took < Duration::from_secs(120), "{scenario}: took {took:?}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn losing_the_device_mid_run_exits_1_with_the_reason() {
    run_losing_the_device("default", 3);
    run_losing_the_device("snow", 2);
}
