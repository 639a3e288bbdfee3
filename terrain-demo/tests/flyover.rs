//! The flyover over a streamed world, run as a user runs it (without a GPU, so it needs no
//! adapter): the world is built on first use, the RAM pool stays within its budget and has
//! every wanted tile after the first second, the craters are written back and the next run
//! starts from them, the hole cut beside the path is saved in the world's hole tiles and kept
//! by the next run, and `verify-world` tells a valid world from one with a corrupt tile.

mod common;

use common::tile_files;
use std::path::Path;
use std::process::Command;

/// The hole cells the world's level-0 hole tiles hold.
fn hole_cells(world: &Path) -> u64 {
    use terrain_cache::{FsStore, World, read_holes};
    let store = std::sync::Arc::new(FsStore::open_read_only(world).expect("store"));
    let world = World::open(store).expect("world");
    let size = world.manifest().world_size;
    let mask = read_holes(&world, terrain_core::Rect::from_size(size)).expect("holes");
    terrain_core::count_holes(&mask)
}

/// The texels the world's level-0 material tiles hold paint on.
fn painted_texels(world: &Path) -> usize {
    use terrain_cache::{FsStore, World, read_paint};
    let store = std::sync::Arc::new(FsStore::open_read_only(world).expect("store"));
    let world = World::open(store).expect("world");
    let size = world.manifest().world_size;
    let paint = read_paint(&world, terrain_core::Rect::from_size(size)).expect("paint");
    paint.as_slice().iter().filter(|t| **t != [0; 4]).count()
}

fn demo() -> Command {
    Command::new(env!("CARGO_BIN_EXE_terrain-demo"))
}

fn run(world: &Path, out: &Path, frames: u32) -> serde_json::Value {
    run_with(world, out, frames, &["--no-gpu"])
}

fn run_with(world: &Path, out: &Path, frames: u32, extra: &[&str]) -> serde_json::Value {
    let status = demo()
        .args(["--scenario", "flyover", "--size", "1024"])
        .args(extra)
        .args(["--ram-budget", "4", "--overview-size", "64"])
        .args(["--frames", &frames.to_string()])
        .arg("--world")
        .arg(world)
        .arg("--out")
        .arg(out)
        .status()
        .expect("demo runs");
    assert!(status.success(), "flyover failed: {status}");
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    serde_json::from_str(&text).expect("valid report")
}

#[test]
fn flyover_streams_within_budget_and_craters_persist() {
    let root = std::env::temp_dir().join(format!("terrain_flyover_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let world = root.join("world");
    let first = run(&world, &root.join("run1"), 60);
    assert!(world.join("manifest.json").is_file(), "the world was built");

    let frames = first["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 60);
    for f in frames {
        // The camera stands on the ground it can see: never below it, even on the first
        // frames, before the tiles under it are in RAM.
        let clearance = f["camera_clearance_m"].as_f64();
        assert!(
            clearance >= Some(0.0),
            "frame {}: {clearance:?}",
            f["index"]
        );
        let cache = &f["cache"];
        let (ram, budget) = (
            cache["ram_bytes"].as_u64(),
            cache["ram_budget_bytes"].as_u64(),
        );
        assert!(
            ram.is_some() && ram <= budget,
            "frame {}: {cache}",
            f["index"]
        );
        // After the first second every tile the selection wants is resident.
        if f["index"].as_u64() >= Some(30) {
            assert_eq!(
                cache["tiles_missing"].as_u64(),
                Some(0),
                "frame {}: {cache}",
                f["index"]
            );
        }
    }
    let craters: u64 = frames.iter().filter_map(|f| f["craters"].as_u64()).sum();
    assert!(craters >= 5, "craters stamped: {craters}");
    assert!(
        first["written_back_tiles"].as_u64() >= Some(1),
        "craters written back"
    );

    // The hole cut on frame 8 is in the world's hole tiles, the craters' dirt in its
    // material tiles.
    let holes = hole_cells(&world);
    assert!(holes > 50, "hole cells saved: {holes}");
    let painted = painted_texels(&world);
    assert!(painted > 100, "painted texels saved: {painted}");

    // The second run starts from the deformed world, and keeps the hole.
    let start1 = std::fs::read(root.join("run1/terrain.png")).expect("terrain.png");
    run(&world, &root.join("run2"), 2);
    assert_eq!(hole_cells(&world), holes, "the second run keeps the hole");
    assert_eq!(
        painted_texels(&world),
        painted,
        "the second run keeps the paint"
    );
    let start2 = std::fs::read(root.join("run2/terrain.png")).expect("terrain.png");
    assert_ne!(
        start1, start2,
        "the craters of the first run persist in the world"
    );

    // verify-world: valid, then one corrupt tile is listed and the exit status is 1.
    let ok = demo()
        .arg("verify-world")
        .arg(&world)
        .output()
        .expect("runs");
    assert_eq!(
        ok.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&ok.stdout)
    );
    let tile = world.join("height/00/0000/0001.tile");
    assert!(tile.is_file());
    std::fs::write(&tile, b"not a tile").expect("corrupt a tile");
    let bad = demo()
        .arg("verify-world")
        .arg(&world)
        .output()
        .expect("runs");
    assert_eq!(bad.status.code(), Some(1));
    let listed = String::from_utf8_lossy(&bad.stdout);
    assert!(listed.contains("height/00/0000/0001.tile"), "{listed}");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn with_a_gpu_the_vram_pool_streams_the_world_within_its_budgets() {
    let Some(_ctx) = terrain_gpu::testing::context_or_skip("flyover_vram") else {
        return;
    };
    let root = std::env::temp_dir().join(format!("terrain_flyover_gpu_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let report = run_with(
        &root.join("world"),
        &root.join("out"),
        45,
        &["--resolution", "96x64", "--vram-budget", "8"],
    );
    for f in report["frames"].as_array().expect("frames") {
        let cache = &f["cache"];
        let vram = cache["vram_bytes"].as_u64().expect("vram_bytes with a GPU");
        assert!(vram <= 8 << 20, "frame {}: {cache}", f["index"]);
        let upload = cache["upload_bytes"].as_u64().expect("upload_bytes");
        assert!(
            upload <= 2 << 20,
            "frame {}: over the upload budget: {cache}",
            f["index"]
        );
        // Paint streams with the heights, within the same VRAM budget (the slots above) and
        // its own 2 MiB a frame.
        let overlay = cache["overlay_upload_bytes"]
            .as_u64()
            .expect("overlay uploads");
        assert!(overlay <= 2 << 20, "frame {}: {cache}", f["index"]);
        if f["index"].as_u64() >= Some(30) {
            assert_eq!(
                cache["tiles_missing"].as_u64(),
                Some(0),
                "frame {}: {cache}",
                f["index"]
            );
            assert_eq!(
                cache["material_tiles_missing"].as_u64(),
                Some(0),
                "frame {}: {cache}",
                f["index"]
            );
        }
        assert!(f["triangles"].as_u64() > Some(0));
    }
    // The craters were stamped on the GPU in the atlas slots and read back: the world they
    // leave is the one the same run leaves with every crater stamped on the CPU, file for file.
    let frames = report["frames"].as_array().expect("frames");
    let last = &frames[frames.len() - 1]["cache"];
    assert!(
        last["gpu_tile_stamps"].as_u64() >= Some(3),
        "tiles stamped on the GPU: {last}"
    );
    assert_eq!(last["tile_readbacks_in_flight"].as_u64(), Some(0), "{last}");
    let cpu = run(&root.join("world_cpu"), &root.join("out_cpu"), 45);
    let cpu_last = &cpu["frames"][44]["cache"];
    assert_eq!(cpu_last["gpu_tile_stamps"].as_u64(), Some(0));
    let gpu_files = tile_files(&root.join("world"));
    assert!(gpu_files.len() > 20, "{}", gpu_files.len());
    assert_eq!(
        gpu_files.keys().collect::<Vec<_>>(),
        tile_files(&root.join("world_cpu"))
            .keys()
            .collect::<Vec<_>>()
    );
    let cpu_files = tile_files(&root.join("world_cpu"));
    let differ: Vec<&String> = gpu_files
        .iter()
        .filter(|(k, v)| cpu_files.get(*k) != Some(v))
        .map(|(k, _)| k)
        .collect();
    assert!(differ.is_empty(), "tiles that differ: {differ:?}");
    // And the craters are in it: the world differs from a freshly built one.
    run(&root.join("world_fresh"), &root.join("out_fresh"), 1);
    let fresh = tile_files(&root.join("world_fresh"));
    assert!(
        gpu_files.iter().any(|(k, v)| fresh.get(k) != Some(v)),
        "no tile changed"
    );
    let _ = std::fs::remove_dir_all(&root);
}
