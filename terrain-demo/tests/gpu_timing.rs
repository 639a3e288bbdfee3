//! GPU timing in timestamp mode (`gpu_scene::frame_timer`), forced on whatever adapter the
//! tests have (`TERRAIN_DEMO_GPU_TIMING=timestamps`; hardware adapters choose it themselves):
//! the steps are submitted without a wait per step, their timestamps come back later and are
//! credited to their own frames, and the frames still allocate nothing on the GPU once warm.

mod common;

use std::time::Duration;
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::wgpu;

const FRAMES: usize = 30;
const WARM_UP_FRAMES: usize = 5;

fn run(scenario: &str) -> serde_json::Value {
    let out = common::fresh_dir(&format!("gpu_timing_{scenario}"));
    let mut cmd = common::demo();
    cmd.env("TERRAIN_DEMO_GPU_TIMING", "timestamps")
        .args([
            "--scenario",
            scenario,
            "--size",
            "128",
            "--resolution",
            "64x48",
        ])
        .args(["--overview-size", "32", "--frames", &FRAMES.to_string()])
        .arg("--out")
        .arg(&out);
    let done = common::run_within(cmd, &out, Duration::from_secs(300));
    assert!(
        done.status.success(),
        "{scenario}: demo failed with {}: {}",
        done.status,
        done.stderr
    );
    let report = common::report(&out);
    let _ = std::fs::remove_dir_all(&out);
    report
}

fn check(scenario: &str, gpu_steps: &[&str]) {
    let report = run(scenario);
    assert_eq!(report["gpu_timing"], "timestamps", "{scenario}");
    let frames = report["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), FRAMES);
    let steady = &frames[WARM_UP_FRAMES]["gpu_objects"];
    let mut with_render = 0;
    for (i, f) in frames.iter().enumerate() {
        // No per-frame GPU objects in timestamp mode either.
        if i >= WARM_UP_FRAMES {
            assert_eq!(
                &f["gpu_objects"], steady,
                "{scenario}: live GPU objects changed at frame {i}"
            );
        }
        // The wall figures (recording and submitting) of every GPU step.
        for step in gpu_steps {
            let ms = f["timings_ms"][step].as_f64();
            assert!(
                ms.is_some_and(|ms| ms >= 0.0),
                "{scenario} frame {i} {step}"
            );
        }
        // GPU figures only of steps the frame timed, never negative or made up.
        let gpu = f["gpu_timestamps_ms"]
            .as_object()
            .expect("gpu_timestamps_ms");
        for (step, ms) in gpu {
            assert!(
                f["timings_ms"].get(step).is_some(),
                "{scenario} frame {i}: GPU figure of {step}, a step it did not time"
            );
            assert!(
                ms.as_f64().is_some_and(|ms| ms.is_finite() && ms >= 0.0),
                "{scenario} frame {i} {step}: {ms}"
            );
        }
        with_render += usize::from(gpu.contains_key("render"));
    }
    // Timestamps that arrive a frame or more late are credited to their own frame, and the
    // run's end waits for the last ones: every frame has its render's GPU time.
    assert_eq!(
        with_render, FRAMES,
        "{scenario}: only {with_render} of {FRAMES} frames got their render's GPU time"
    );
}

#[test]
fn timestamp_mode_credits_each_frame_its_gpu_times_and_allocates_nothing() {
    let Some(ctx) = context_or_skip("timestamp_mode_credits_each_frame") else {
        return;
    };
    if !ctx
        .device
        .features()
        .contains(wgpu::Features::TIMESTAMP_QUERY)
    {
        eprintln!("skipped: the adapter has no timestamp queries (wall time only)");
        return;
    }
    check("default", &["stamp_gpu", "normals_gpu", "render"]);
    check("snow", &["granular_gpu", "normals_gpu", "render"]);
}
