//! The world scenario as a user runs it: a vehicle leaves granular trails on the streamed
//! world (through a granular window that moves with it), craters and a shockwave land beside
//! its path, a walker presses footprints into the world's detail tiles (`--detail parallax`);
//! the granular volume is exact at every frame, collision keeps the camera above ground, every
//! wanted tile is resident after the first second, and the world left by a GPU run (granular
//! steps, craters and footprints on the GPU, drawn by CDLOD from the tile atlas with the
//! detail layer) is the one a `--no-gpu` run leaves, file for file. Short GPU runs draw the
//! world with the streamed tessellation and with refined footprints.

mod common;

use std::path::Path;
use std::process::Command;

fn run(world: &Path, out: &Path, frames: u32, extra: &[&str]) -> serde_json::Value {
    let status = Command::new(env!("CARGO_BIN_EXE_terrain-demo"))
        .args(["--scenario", "world", "--size", "1024", "--speed", "40"])
        // The walker's footprints, by parallax unless the run asks otherwise.
        .args(if extra.contains(&"--detail") {
            &[][..]
        } else {
            &["--detail", "parallax"]
        })
        .args(extra)
        .args(["--ram-budget", "8", "--overview-size", "64", "-q"])
        .args(["--frames", &frames.to_string()])
        .arg("--world")
        .arg(world)
        .arg("--out")
        .arg(out)
        .status()
        .expect("demo runs");
    assert!(status.success(), "world scenario failed: {status}");
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    serde_json::from_str(&text).expect("valid report")
}

/// Checks every frame of `report` and returns the granular backend it ran on.
fn check_frames(report: &serde_json::Value) -> &str {
    let frames = report["frames"].as_array().expect("frames");
    let mut backend = None;
    let mut volumes = std::collections::BTreeSet::new();
    for f in frames {
        let i = f["index"].as_u64().expect("index");
        let volume = f["granular_volume"].as_u64();
        assert!(volume.is_some(), "frame {i}: no granular step: {f}");
        assert_eq!(volume, f["granular_volume_taken"].as_u64(), "frame {i}");
        volumes.insert(f["granular_volume_taken"].as_u64());
        let b = f["granular_backend"].as_str().expect("backend");
        assert!(backend.is_none_or(|x| x == b), "frame {i}: backend changed");
        backend = Some(b);
        assert!(f["camera_clearance_m"].as_f64() >= Some(0.0), "frame {i}");
        if i >= 30 {
            assert_eq!(f["cache"]["tiles_missing"].as_u64(), Some(0), "frame {i}");
        }
        // A footprint or two every frame (0.7 m strides at 40 m/s), each covering detail
        // texels.
        let steps = f["footprints"].as_u64().expect("footprints");
        assert!((1..=2).contains(&steps), "frame {i}: {steps} footprints");
        assert!(
            f["detail_dirty_texels"].as_u64() > Some(0),
            "frame {i}: {f}"
        );
    }
    // The vehicle drove out of its first window: at least two windows, each exact.
    assert!(volumes.len() >= 2, "the granular window never moved");
    assert_eq!(report["scenario"], "world");
    backend.expect("frames")
}

#[test]
fn trails_and_craters_persist_with_the_volume_exact_and_the_gpu_equal_to_the_cpu() {
    let gpu = terrain_gpu::testing::context_or_skip("world_scenario").is_some();
    let root = std::env::temp_dir().join(format!("terrain_world_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let cpu = run(
        &root.join("world_cpu"),
        &root.join("out_cpu"),
        45,
        &["--no-gpu"],
    );
    assert_eq!(check_frames(&cpu), "cpu");
    let craters: u64 = cpu["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .filter_map(|f| f["craters"].as_u64())
        .sum();
    assert!(craters >= 3, "craters: {craters}");
    let shocks: u64 = cpu["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .filter_map(|f| f["shockwaves"].as_u64())
        .sum();
    assert!(shocks >= 30, "shockwave stamps: {shocks}");
    let cpu_files = common::tile_files(&root.join("world_cpu"));
    // Trails and craters are in the world's files.
    run(
        &root.join("world_fresh"),
        &root.join("out_fresh"),
        1,
        &["--no-gpu"],
    );
    let fresh = common::tile_files(&root.join("world_fresh"));
    let changed = cpu_files
        .iter()
        .filter(|(k, v)| fresh.get(*k) != Some(v))
        .count();
    assert!(changed >= 2, "tiles changed: {changed}");
    let detail = cpu_files.keys().filter(|k| k.starts_with("detail")).count();
    assert!(detail >= 1, "no footprint reached the world's detail files");
    if gpu {
        let report = run(
            &root.join("world_gpu"),
            &root.join("out_gpu"),
            45,
            &[
                "--resolution",
                "96x64",
                "--vram-budget",
                "8",
                "--lod",
                "cdlod",
            ],
        );
        assert_eq!(check_frames(&report), "gpu");
        // Every window move waited for nothing: the areas stepped on the GPU and the craters
        // were back before the wheels reached the window's edge.
        let moves: Vec<bool> = report["frames"]
            .as_array()
            .expect("frames")
            .iter()
            .filter_map(|f| f["granular_move_waited"].as_bool())
            .collect();
        assert!(
            !moves.is_empty() && moves.iter().all(|w| !w),
            "moves: {moves:?}"
        );
        for f in report["frames"].as_array().expect("frames") {
            // CDLOD draws the streamed world from its atlas.
            assert_eq!(f["lod"], "cdlod", "{f}");
            assert!(f["triangles"].as_u64() > Some(0), "{f}");
            let steps = f["timings_ms"].as_object().expect("timings");
            assert!(
                !steps.contains_key("granular_cpu") && !steps.contains_key("stamp_cpu"),
                "a deformation ran on the CPU with a GPU: {f}"
            );
        }
        let gpu_files = common::tile_files(&root.join("world_gpu"));
        assert_eq!(
            gpu_files.keys().collect::<Vec<_>>(),
            cpu_files.keys().collect::<Vec<_>>()
        );
        let differ: Vec<&String> = gpu_files
            .iter()
            .filter(|(k, v)| cpu_files.get(*k) != Some(v))
            .map(|(k, _)| k)
            .collect();
        assert!(differ.is_empty(), "tiles that differ: {differ:?}");
        // The streamed tessellation (decided from the world's quadtree, heights from the
        // atlas) with the footprints as refined geometry, which it leaves the texels near the
        // camera.
        let tessellated = run(
            &root.join("world_tess"),
            &root.join("out_tess"),
            8,
            &[
                "--resolution",
                "96x64",
                "--vram-budget",
                "8",
                "--lod",
                "tessellated",
                "--detail",
                "refine",
            ],
        );
        for f in tessellated["frames"].as_array().expect("frames") {
            assert_eq!(f["lod"], "tessellated", "{f}");
            assert_eq!(f["refined"], true, "{f}");
            assert!(f["triangles"].as_u64() > Some(0), "{f}");
            assert!(f["camera_clearance_m"].as_f64() >= Some(0.0), "{f}");
            assert!(
                !f["timings_ms"]
                    .as_object()
                    .expect("timings")
                    .contains_key("stamp_cpu")
            );
        }
        // The footprints as refined geometry near the camera (the clipmap's finest cells).
        let refined = run(
            &root.join("world_refine"),
            &root.join("out_refine"),
            8,
            &[
                "--resolution",
                "96x64",
                "--vram-budget",
                "8",
                "--detail",
                "refine",
            ],
        );
        for f in refined["frames"].as_array().expect("frames") {
            assert_eq!(
                f["refined"], true,
                "the clipmap always leaves the cells out: {f}"
            );
            assert!(f["detail_dirty_texels"].as_u64() > Some(0), "{f}");
            assert!(
                !f["timings_ms"]
                    .as_object()
                    .expect("timings")
                    .contains_key("stamp_cpu")
            );
        }
        // CDLOD on this small, steep world: a frame whose LOD 0 may morph inside the refined
        // region (on frame 0 the quadtree's bounds near the camera are still whole tiles')
        // draws the region itself, and later frames refine it. (The run failed on frame 0.)
        let cdlod = run(
            &root.join("world_cdlod_refine"),
            &root.join("out_cdlod_refine"),
            12,
            &[
                "--resolution",
                "96x64",
                "--vram-budget",
                "8",
                "--lod",
                "cdlod",
                "--detail",
                "refine",
            ],
        );
        let frames = cdlod["frames"].as_array().expect("frames");
        assert!(frames.iter().all(|f| f["refined"].is_boolean()), "{cdlod}");
        assert_eq!(frames.last().expect("frames")["refined"], true, "{cdlod}");
    }
    let _ = std::fs::remove_dir_all(&root);
}
