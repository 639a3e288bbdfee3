//! One writer per world: a second run on a world in use exits 2 naming the owner, a run after
//! `kill -9` of the owner takes the world over (recovering an interrupted write-back), and
//! `verify-world` passes after each case.

mod common;

use common::{demo, fresh_dir, run_within};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const LIMIT: Duration = Duration::from_secs(180);

fn flyover(world: &Path, out: &Path, frames: u32) -> Command {
    let mut cmd = demo();
    cmd.args(["--scenario", "flyover", "--no-gpu", "--size", "1024"])
        .args(["--ram-budget", "4", "--overview-size", "64"])
        .args(["--frames", &frames.to_string()])
        .arg("--world")
        .arg(world)
        .arg("--out")
        .arg(out);
    cmd
}

fn verify_passes(world: &Path, dir: &Path, case: &str) {
    let mut cmd = demo();
    cmd.arg("verify-world").arg(world);
    let done = run_within(cmd, dir, LIMIT);
    assert!(
        done.status.success(),
        "verify-world after {case}: {}; {}",
        done.status,
        done.stderr
    );
}

/// Waits until the run in `out` has written `n` frames (so it holds the world and streams).
fn wait_for_frames(child: &mut Child, out: &Path, n: usize) {
    let started = Instant::now();
    loop {
        let lines = std::fs::read_to_string(out.join("frames.jsonl"))
            .map(|t| t.lines().count())
            .unwrap_or(0);
        if lines >= n {
            return;
        }
        if let Some(status) = child.try_wait().expect("wait") {
            panic!("the owner ended early: {status}");
        }
        if started.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the owner wrote no {n} frames in {LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_second_writer_is_refused_and_a_killed_owners_world_is_taken_over() {
    let dir = fresh_dir("world_lock");
    let world = dir.join("world");
    let mut owner = flyover(&world, &dir.join("owner"), 100_000)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("demo starts");
    wait_for_frames(&mut owner, &dir.join("owner"), 3);

    // A second run on the same world: refused up front, naming the owner.
    let second = run_within(flyover(&world, &dir.join("second"), 2), &dir, LIMIT);
    let pid = owner.id();
    assert_eq!(second.status.code(), Some(2), "{}", second.stderr);
    assert!(
        second
            .stderr
            .contains(&format!("in use by pid {pid} on host ")),
        "the error names the owner: {}",
        second.stderr
    );
    assert!(!dir.join("second/frames.jsonl").exists(), "nothing ran");
    // A reader needs no lock: the check runs while the owner writes (it may catch a parent
    // tile not yet rebuilt after a write-back in flight: exit 1, never the refusal's 2). A
    // repair writes: refused like the second run.
    let mut check = demo();
    check.arg("verify-world").arg(&world);
    let check = run_within(check, &dir, LIMIT);
    assert!(
        matches!(check.status.code(), Some(0 | 1)),
        "{}",
        check.stderr
    );
    let mut repair = demo();
    repair.arg("verify-world").arg(&world).arg("--repair");
    let repair = run_within(repair, &dir, LIMIT);
    assert_eq!(repair.status.code(), Some(2), "{}", repair.stderr);
    assert!(
        repair.stderr.contains(&format!("in use by pid {pid} ")),
        "{}",
        repair.stderr
    );

    // kill -9: the kernel drops the lock with the process.
    owner.kill().expect("kill -9");
    owner.wait().expect("reaped");
    // The next writer takes the world over, recovering a write-back the kill interrupted.
    let third = run_within(flyover(&world, &dir.join("third"), 5), &dir, LIMIT);
    assert!(
        third.status.success(),
        "the world is taken over: {}",
        third.stderr
    );
    let lock = std::fs::read_to_string(world.join(".terrain-lock")).expect("lock file");
    assert!(
        !lock.contains(&format!("pid {pid} ")),
        "the new owner named itself: {lock}"
    );
    verify_passes(&world, &dir, "the run that took over");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A folder without a manifest is built into only when it is empty, new, or holds an
/// unfinished build of the demo's (its marker): a user's folder, or a world whose manifest was
/// lost (its tiles hold deformations the rebuild would overwrite, its holes and paint would
/// stay), is refused untouched with exit code 2. A world smaller than a tile is refused before
/// anything is built.
#[test]
fn only_empty_folders_and_unfinished_builds_become_worlds() {
    let dir = fresh_dir("world_folders");
    let out = dir.join("out");
    let run = |world: &Path| run_within(flyover(world, &out, 1), &dir, LIMIT);
    // A user's folder.
    let user = dir.join("user");
    std::fs::create_dir_all(user.join("photos")).unwrap();
    std::fs::write(user.join("notes.txt"), "mine").unwrap();
    let done = run(&user);
    assert_eq!(done.status.code(), Some(2), "{}", done.stderr);
    assert!(done.stderr.contains("no manifest.json"), "{}", done.stderr);
    assert_eq!(
        std::fs::read_to_string(user.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(!user.join("height").exists() && !user.join("manifest.json").exists());
    assert!(!user.join(".terrain-lock").exists(), "not even a lock file");
    // A world whose manifest was lost.
    let world = dir.join("world");
    let done = run(&world);
    assert!(done.status.success(), "{}", done.stderr);
    // A marker a build killed after its manifest left is removed by the next run, so a later
    // loss of the manifest is not taken for a build of ours to clear.
    std::fs::write(world.join(".terrain-build"), "").unwrap();
    assert!(run(&world).status.success());
    assert!(!world.join(".terrain-build").exists());
    std::fs::remove_file(world.join("manifest.json")).unwrap();
    let done = run(&world);
    assert_eq!(done.status.code(), Some(2), "{}", done.stderr);
    assert!(world.join("height").is_dir(), "its tiles are kept");
    // An unfinished build: its leftovers are cleared and the world is built.
    let unfinished = dir.join("unfinished");
    std::fs::create_dir_all(unfinished.join("hole/00/0000")).unwrap();
    std::fs::write(unfinished.join("hole/00/0000/0000.tile"), "stale").unwrap();
    std::fs::write(unfinished.join(".terrain-build"), "").unwrap();
    let done = run(&unfinished);
    assert!(done.status.success(), "{}", done.stderr);
    assert!(!unfinished.join("hole/00/0000/0000.tile").exists());
    assert!(!unfinished.join(".terrain-build").exists());
    verify_passes(&unfinished, &dir, "an unfinished build");
    // Too small for a tile: refused before anything is built.
    let small = dir.join("small");
    let mut cmd = demo();
    cmd.args([
        "--scenario",
        "world",
        "--no-gpu",
        "--size",
        "100",
        "--frames",
        "1",
    ])
    .arg("--world")
    .arg(&small)
    .arg("--out")
    .arg(&out);
    let done = run_within(cmd, &dir, LIMIT);
    assert_eq!(done.status.code(), Some(2), "{}", done.stderr);
    assert!(done.stderr.contains("one tile"), "{}", done.stderr);
    assert!(!small.join("height").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A world a run would make worse is refused untouched with exit code 2: a lost level-0 tile
/// (read as flat, its ancestors and bounds would be rewritten over the last record of it) and a
/// missing bounds.bin (a write-back would record every other tile as empty); once repaired,
/// the run goes ahead.
#[test]
fn a_damaged_world_is_refused_before_it_is_written() {
    let dir = fresh_dir("world_damaged");
    let (world, out) = (dir.join("world"), dir.join("out"));
    let done = run_within(flyover(&world, &out, 1), &dir, LIMIT);
    assert!(done.status.success(), "{}", done.stderr);
    let bounds = world.join("height/00/bounds.bin");
    let level1 = world.join("height/01/0000/0000.tile");
    let before = (
        std::fs::read(&bounds).unwrap(),
        std::fs::read(&level1).unwrap(),
    );
    let tile = world.join("height/00/0000/0000.tile");
    let kept = std::fs::read(&tile).unwrap();
    std::fs::remove_file(&tile).unwrap();
    let done = run_within(flyover(&world, &out, 2), &dir, LIMIT);
    assert_eq!(done.status.code(), Some(2), "{}", done.stderr);
    assert!(
        done.stderr.contains("0000.tile: missing"),
        "{}",
        done.stderr
    );
    let after = (
        std::fs::read(&bounds).unwrap(),
        std::fs::read(&level1).unwrap(),
    );
    assert!(before == after, "nothing written");
    std::fs::write(&tile, kept).unwrap();
    std::fs::remove_file(&bounds).unwrap();
    let done = run_within(flyover(&world, &out, 2), &dir, LIMIT);
    assert_eq!(done.status.code(), Some(2), "{}", done.stderr);
    assert!(done.stderr.contains("--repair"), "{}", done.stderr);
    assert!(!bounds.exists());
    let mut repair = demo();
    repair.args(["verify-world", "--repair", "-q"]).arg(&world);
    assert!(run_within(repair, &dir, LIMIT).status.success());
    let done = run_within(flyover(&world, &out, 2), &dir, LIMIT);
    assert!(done.status.success(), "{}", done.stderr);
    verify_passes(&world, &dir, "a repaired world's run");
    let _ = std::fs::remove_dir_all(&dir);
}
