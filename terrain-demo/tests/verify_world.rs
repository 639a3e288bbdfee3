//! `verify-world DIR` and its `--repair`, run as a user runs them: exit 0 for a valid world, 1
//! with the defects listed on stdout (a stale coarser tile, a damaged bounds.bin, a corrupt
//! level-0 tile), `--repair` rebuilding what level 0 determines (exit 0 afterwards, 1 while
//! level-0 damage remains), 2 for a manifest promising billions of tiles (at once), no folder,
//! `--repair` without the command or run flags with it, and 130 when Ctrl-C interrupts a long
//! check.

mod common;

use common::{demo, fresh_dir};
use glam::UVec2;
use std::path::Path;
use std::process::{Output, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::manifest::MANIFEST_KEY;
use terrain_cache::{FsStore, Layer, Manifest, MapSource, TileId, TileStore, World, build_world};
use terrain_core::{CoarseMap, Grid, HeightEncoding, WrapMode};

const LIMIT: Duration = Duration::from_secs(120);

fn encoding() -> HeightEncoding {
    HeightEncoding::spanning::<u16>(0.0, 100.0).expect("encoding")
}

/// A 128 x 96 world in 32-texel tiles (4 x 3, 2 x 2, 1 x 1), built in `dir` (its store, and
/// the folder's lock, are dropped on return: the demo takes the lock).
fn build(dir: &Path) {
    let size = UVec2::new(128, 96);
    let grid = Grid::from_fn(size.x, size.y, |x, y| {
        ((x * 311 + y * 97) % 9000 + 1) as u16
    })
    .expect("grid");
    let map = CoarseMap::coarse(grid, encoding(), 1.0).expect("map");
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(dir).expect("store"));
    let m = Manifest::new(size, 32, 1.0, encoding(), WrapMode::Clamp).expect("manifest");
    build_world(store, m, &MapSource::new(&map), &|_| true).expect("build");
}

/// The world in `dir`, opened for `edit` and closed again.
fn with_world(dir: &Path, edit: impl FnOnce(&World)) {
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(dir).expect("store"));
    edit(&World::open(store).expect("world"));
}

fn verify(dir: &Path, extra: &[&str]) -> Output {
    demo()
        .arg("verify-world")
        .arg(dir)
        .args(extra)
        .output()
        .expect("the demo runs")
}

fn text(out: &Output) -> String {
    format!(
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn verify_and_repair_exit_codes() {
    let root = fresh_dir("verify_world");
    let dir = root.join("world");
    build(&dir);
    let ok = verify(&dir, &[]);
    assert_eq!(ok.status.code(), Some(0), "{}", text(&ok));
    assert!(String::from_utf8_lossy(&ok.stdout).contains("valid"));

    // A stale coarser tile and a damaged bounds.bin: listed, exit 1, repairable.
    let stale = TileId::new(1, 1, 0);
    with_world(&dir, |world| {
        let mut t = world
            .load_tile(Layer::Height, stale)
            .expect("tile")
            .as_ref()
            .clone();
        t.as_u16_mut().expect("heights").as_mut_slice()[17] ^= 3;
        world.write_tile(Layer::Height, stale, &t).expect("write");
    });
    let bounds = dir.join("height/02/bounds.bin");
    let mut b = std::fs::read(&bounds).expect("bounds.bin");
    b[20] ^= 1;
    std::fs::write(&bounds, &b).expect("damage bounds.bin");
    let bad = verify(&dir, &[]);
    assert_eq!(bad.status.code(), Some(1), "{}", text(&bad));
    let listed = String::from_utf8_lossy(&bad.stdout);
    assert!(
        listed.contains("height/01/0000/0001.tile: mismatch")
            && listed.contains("height/02/bounds.bin: bounds unreadable")
            && listed.contains("(repairable)"),
        "{}",
        text(&bad)
    );
    assert_eq!(listed.lines().count(), 2, "{}", text(&bad));

    let repaired = verify(&dir, &["--repair"]);
    assert_eq!(repaired.status.code(), Some(0), "{}", text(&repaired));
    let again = verify(&dir, &[]);
    assert_eq!(again.status.code(), Some(0), "{}", text(&again));

    // A corrupt level-0 tile cannot be repaired: exit 1 before and after --repair.
    let tile = dir.join("height/00/0001/0002.tile");
    std::fs::write(&tile, b"not a tile").expect("corrupt a tile");
    let broken = verify(&dir, &["--repair"]);
    assert_eq!(broken.status.code(), Some(1), "{}", text(&broken));
    let listed = String::from_utf8_lossy(&broken.stdout);
    assert!(
        listed.contains("height/00/0001/0002.tile: unreadable")
            && listed.contains("not repairable"),
        "{}",
        text(&broken)
    );
    assert_eq!(std::fs::read(&tile).expect("tile"), b"not a tile");

    // --repair without the command, the command without its folder, and run flags with it
    // are usage errors: clap's message, with the usage line.
    for args in [
        &["--repair"][..],
        &["verify-world"],
        &["verify-world", "--repair"],
        &["--frames", "2", "verify-world", "w"],
    ] {
        let wrong = demo().args(args).output().expect("runs");
        assert_eq!(wrong.status.code(), Some(2), "{args:?}: {}", text(&wrong));
        common::usage_error(&String::from_utf8_lossy(&wrong.stderr));
        assert!(
            String::from_utf8_lossy(&wrong.stderr).contains("Usage: terrain-demo"),
            "{args:?}: {}",
            text(&wrong)
        );
    }
    // -q goes with the command: the same verdict.
    let quiet = verify(&dir, &["-q"]);
    assert_eq!(quiet.status.code(), Some(1), "{}", text(&quiet));
    assert!(
        String::from_utf8_lossy(&quiet.stdout).contains("not repairable"),
        "{}",
        text(&quiet)
    );
    let _ = std::fs::remove_dir_all(&root);
}

/// A manifest promising `side`^2 texels in 16-texel tiles, and no tile.
fn crafted(dir: &Path, side: u32) {
    std::fs::create_dir_all(dir).expect("folder");
    let m = Manifest::new(UVec2::splat(side), 16, 1.0, encoding(), WrapMode::Clamp)
        .expect("a valid manifest");
    std::fs::write(dir.join(MANIFEST_KEY), m.to_json()).expect("manifest");
}

#[test]
fn a_manifest_promising_billions_of_tiles_is_refused_at_once() {
    let root = fresh_dir("verify_world_huge");
    let dir = root.join("world");
    // 4096^2 level-0 tiles (the most a manifest may have) and their levels: more than a
    // verification walks.
    crafted(&dir, 1 << 16);
    let started = Instant::now();
    let out = verify(&dir, &[]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("more than the"),
        "{}",
        text(&out)
    );
    // 65536^2 level-0 tiles: the manifest itself is refused.
    let text0 = std::fs::read_to_string(dir.join(MANIFEST_KEY)).expect("manifest");
    std::fs::write(dir.join(MANIFEST_KEY), text0.replace("65536", "1048576")).expect("write");
    let out = verify(&dir, &[]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("level-0 tiles"),
        "{}",
        text(&out)
    );
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "{:?}",
        started.elapsed()
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn ctrl_c_interrupts_a_long_verification() {
    let root = fresh_dir("verify_world_interrupt");
    let dir = root.join("world");
    // 1024^2 + 512^2 + ... = 1.4 M height tiles and 1024^2 of each of the hole, material and
    // colour layers: 4.5 M, under the limit, and tens of seconds of missing files to probe.
    crafted(&dir, 1 << 14);
    let mut child = demo()
        .arg("verify-world")
        .arg(&dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the demo starts");
    std::thread::sleep(Duration::from_millis(700));
    assert!(
        child.try_wait().expect("wait").is_none(),
        "the check ended within 0.7 s: nothing to interrupt"
    );
    let (status, after) = common::interrupt_and_wait(&mut child, LIMIT);
    assert_eq!(status.code(), Some(130), "{status}");
    assert!(after < Duration::from_secs(10), "{after:?}");
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().expect("piped"), &mut stderr)
        .expect("stderr");
    assert!(
        stderr.contains("ending the check before its next tile") && !stderr.contains("frame"),
        "the message speaks of the check: {stderr}"
    );
    let _ = std::fs::remove_dir_all(&root);
}
