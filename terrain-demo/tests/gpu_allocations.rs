//! Steady-state frames allocate nothing on the GPU: 100 frames of the default and the snow
//! scenario (run as a user runs the demo), and wgpu's internal counters of live buffers,
//! textures, bind groups, shader modules and pipelines, reported per frame in report.json,
//! stop changing after the first frames.

use std::path::Path;
use std::process::Command;
use terrain_gpu::testing::context_or_skip;

/// Frames after which nothing new may be made: the first frames build each pass's bind groups
/// over the buffers it meets, grow uniform rings and staging buffers to their working size.
const WARM_UP_FRAMES: usize = 5;
const FRAMES: usize = 100;

fn run_demo(scenario: &str, out: &Path) -> serde_json::Value {
    let status = Command::new(env!("CARGO_BIN_EXE_terrain-demo"))
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
        .arg(out)
        .status()
        .expect("demo runs");
    assert!(status.success(), "{scenario}: demo failed with {status}");
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    serde_json::from_str(&text).expect("report.json parses")
}

fn check_steady(scenario: &str) {
    let out = std::env::temp_dir().join(format!("terrain_alloc_{scenario}_{}", std::process::id()));
    let report = run_demo(scenario, &out);
    let frames = report["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), FRAMES);
    let objects: Vec<&serde_json::Value> = frames
        .iter()
        .map(|f| {
            f.get("gpu_objects")
                .expect("gpu_objects on every GPU frame")
        })
        .collect();
    let steady = objects[WARM_UP_FRAMES];
    // (wgpu's Vulkan backend does not count textures: they are compared, not required.)
    for kind in ["buffers", "bind_groups", "shader_modules", "pipelines"] {
        assert!(
            steady[kind].as_i64().unwrap_or(0) > 0,
            "{scenario}: the counters are on and count {kind}"
        );
    }
    for (i, o) in objects.iter().enumerate().skip(WARM_UP_FRAMES) {
        assert_eq!(
            *o, steady,
            "{scenario}: live GPU objects changed at frame {i} (frame {WARM_UP_FRAMES}: {steady})"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn default_and_snow_frames_allocate_nothing_after_warm_up() {
    // The demo needs an adapter to render; the context check fails under
    // TERRAIN_REQUIRE_GPU=1 (CI) and skips otherwise.
    let Some(_ctx) = context_or_skip("default_and_snow_frames_allocate_nothing") else {
        return;
    };
    check_steady("default");
    check_steady("snow");
}
