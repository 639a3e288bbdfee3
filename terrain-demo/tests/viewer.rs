//! The interactive viewer under a virtual X server: `viewer --frames N --screenshot` with the
//! built-in input script draws terrain (not a blank or all-sky picture), and the crater its
//! click stamps shows against a run of the same script without the click. Also: without any
//! display the viewer fails with one clear line.
//!
//! Needs `Xvfb` (Debian: `xvfb`) and a GPU adapter that can present (lavapipe is enough).
//! Without Xvfb the test is skipped locally and fails where `CI` is set or
//! `TERRAIN_REQUIRE_GPU=1`.

#[path = "common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use terrain_core::Grid;
use terrain_core::io::{ReadLimits, decode_png_rgba8};

/// How long one viewer run may take (a debug-profile build on a busy two-core machine).
const RUN_LIMIT: Duration = Duration::from_secs(120);
/// The screenshot's size.
const SIZE: (u32, u32) = (320, 240);
/// The built-in script, as the viewer embeds it.
const BUILTIN: &str = include_str!("../src/bin/terrain-viewer/builtin_script.txt");

fn required() -> bool {
    std::env::var_os("CI").is_some_and(|v| !v.is_empty())
        || std::env::var("TERRAIN_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// Skips (returns `None`, printing why) locally, panics where the test is required.
fn skip<T>(test: &str, why: &str) -> Option<T> {
    if required() {
        panic!("{test}: {why} (CI or TERRAIN_REQUIRE_GPU=1 require this test to run)");
    }
    eprintln!("skipping {test}: {why}");
    None
}

/// A virtual X server of its own for the test, stopped on drop.
struct Xvfb {
    child: Child,
    number: u32,
    display: String,
}

/// The lock file and the socket of X display `n`.
fn display_files(n: u32) -> (PathBuf, PathBuf) {
    (
        PathBuf::from(format!("/tmp/.X{n}-lock")),
        PathBuf::from(format!("/tmp/.X11-unix/X{n}")),
    )
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        // SIGTERM, so the server removes its lock and socket; killed only if it lingers.
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        let (lock, socket) = display_files(self.number);
        let _ = std::fs::remove_file(lock);
        let _ = std::fs::remove_file(socket);
    }
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join(program).is_file()))
}

/// Whether display `n` is taken: its lock file names a running process (or cannot be read
/// yet: a server is starting).
fn taken(n: u32) -> bool {
    let (lock, _) = display_files(n);
    match std::fs::read_to_string(&lock) {
        Ok(text) => match text.trim().parse::<u32>() {
            Ok(pid) => Path::new(&format!("/proc/{pid}")).exists(),
            Err(_) => true,
        },
        Err(e) => e.kind() != std::io::ErrorKind::NotFound,
    }
}

/// Starts `Xvfb` on the first free display of :90 to :119 (the leftovers of a server that
/// died without cleaning up are removed first; a server that exits at once lost a race for
/// its display, and the next is tried).
fn start_xvfb(test: &str) -> Option<Xvfb> {
    if !on_path("Xvfb") {
        return skip(test, "Xvfb is not installed (Debian: apt-get install xvfb)");
    }
    for n in 90..120 {
        if taken(n) {
            continue;
        }
        let (lock, socket) = display_files(n);
        let _ = std::fs::remove_file(&lock);
        let _ = std::fs::remove_file(&socket);
        let mut child = Command::new("Xvfb")
            .args([
                &format!(":{n}"),
                "-screen",
                "0",
                "1280x720x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb starts");
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(10) {
            // Exited: another server took the display first (its socket is not ours).
            if child.try_wait().expect("wait").is_some() {
                break;
            }
            if socket.exists() {
                return Some(Xvfb {
                    child,
                    number: n,
                    display: format!(":{n}"),
                });
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
    }
    panic!("{test}: no display of :90 to :119 could be started with Xvfb");
}

/// What a finished viewer run left.
struct Run {
    success: bool,
    stdout: String,
    stderr: String,
    elapsed: Duration,
}

/// Runs the viewer with `args` on `display` (none: no display at all), killed after
/// [`RUN_LIMIT`]. Output goes to files in `dir` (a pipe could fill and stall it).
fn viewer(display: Option<&str>, args: &[&str], dir: &Path, name: &str) -> Run {
    let out = dir.join(format!("{name}.stdout"));
    let err = dir.join(format!("{name}.stderr"));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_terrain-viewer"));
    cmd.args(args)
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        // Mesa's device-select layer prints errors on machines without a desktop session.
        .env("NODEVICE_SELECT", "1")
        .stdout(std::fs::File::create(&out).expect("stdout file"))
        .stderr(std::fs::File::create(&err).expect("stderr file"));
    match display {
        Some(d) => cmd.env("DISPLAY", d),
        None => cmd.env_remove("DISPLAY"),
    };
    let started = Instant::now();
    let mut child = cmd.spawn().expect("the viewer starts");
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if started.elapsed() > RUN_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "viewer {args:?} ran longer than {RUN_LIMIT:?}; stderr: {}",
                std::fs::read_to_string(&err).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Run {
        success: status.success(),
        stdout: std::fs::read_to_string(&out).unwrap_or_default(),
        stderr: std::fs::read_to_string(&err).unwrap_or_default(),
        elapsed: started.elapsed(),
    }
}

fn read_shot(path: &Path) -> Grid<[u8; 4]> {
    let bytes = std::fs::read(path).expect("the screenshot was written");
    decode_png_rgba8(&bytes, &ReadLimits::default()).expect("the screenshot is a PNG")
}

/// The sky's colours: blue over green and red (the gradient of terrain-gpu's `SkyPass`).
fn is_sky(p: [u8; 4]) -> bool {
    p[2] > 150 && p[2] > p[1] && p[1] > p[0]
}

/// Mean absolute difference per channel between two images over the pixels `keep` selects.
fn mean_diff(a: &Grid<[u8; 4]>, b: &Grid<[u8; 4]>, keep: impl Fn(u32, u32) -> bool) -> f64 {
    let (mut sum, mut n) = (0u64, 0u64);
    for y in 0..a.height() {
        for x in 0..a.width() {
            if keep(x, y) {
                let (p, q) = (a.get(x, y).unwrap(), b.get(x, y).unwrap());
                sum += (0..3).map(|c| u64::from(p[c].abs_diff(q[c]))).sum::<u64>();
                n += 3;
            }
        }
    }
    sum as f64 / n.max(1) as f64
}

#[test]
fn scripted_run_draws_terrain_and_the_clicked_crater() {
    let test = "scripted_run_draws_terrain_and_the_clicked_crater";
    let Some(x) = start_xvfb(test) else {
        return;
    };
    let dir = common::fresh_dir("viewer");
    let resolution = format!("{}x{}", SIZE.0, SIZE.1);
    let shot = dir.join("shot.png");
    let common_args = ["--frames", "30", "--resolution", &resolution];

    let mut args = common_args.to_vec();
    args.extend(["--script-builtin", "--screenshot", shot.to_str().unwrap()]);
    let run = viewer(Some(&x.display), &args, &dir, "clicked");
    if !run.success && run.stderr.contains("no GPU adapter") {
        let why = format!(
            "no adapter can present to the window: {}",
            run.stderr.trim()
        );
        return skip(test, &why).unwrap_or(());
    }
    assert!(
        run.success,
        "viewer failed:\nstdout: {}\nstderr: {}",
        run.stdout, run.stderr
    );
    eprintln!("viewer run: {:?}\n{}", run.elapsed, run.stdout);
    assert!(
        run.stdout.contains("crater at"),
        "the script's click stamped: {}",
        run.stdout
    );

    // Not blank: many colours, terrain in most of the lower half, and shading in it.
    let image = read_shot(&shot);
    assert_eq!((image.width(), image.height()), SIZE);
    let colours: std::collections::HashSet<[u8; 4]> = image.as_slice().iter().copied().collect();
    assert!(colours.len() > 500, "{} distinct colours", colours.len());
    let lower: Vec<[u8; 4]> = (SIZE.1 / 2..SIZE.1)
        .flat_map(|y| (0..SIZE.0).map(move |x| (x, y)))
        .map(|(x, y)| image.get(x, y).unwrap())
        .collect();
    let terrain = lower.iter().filter(|p| !is_sky(**p)).count();
    assert!(
        terrain > lower.len() * 3 / 4,
        "the lower half is terrain: {terrain} of {}",
        lower.len()
    );
    let luma: Vec<f64> = lower
        .iter()
        .map(|p| 0.3 * f64::from(p[0]) + 0.59 * f64::from(p[1]) + 0.11 * f64::from(p[2]))
        .collect();
    let mean = luma.iter().sum::<f64>() / luma.len() as f64;
    let var = luma.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / luma.len() as f64;
    assert!(var > 20.0, "the terrain is shaded (luma variance {var:.1})");
    let sky = image.as_slice().iter().filter(|p| is_sky(**p)).count();
    assert!(sky < image.as_slice().len() * 9 / 10, "not all sky");

    // The same flight without the click: the difference is the crater, around the centre.
    let plain = dir.join("plain.png");
    let script = dir.join("no_click.txt");
    let no_click: String = BUILTIN
        .lines()
        .filter(|l| !l.contains("click"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&script, no_click).unwrap();
    let mut args = common_args.to_vec();
    args.extend([
        "--script",
        script.to_str().unwrap(),
        "--screenshot",
        plain.to_str().unwrap(),
    ]);
    let run = viewer(Some(&x.display), &args, &dir, "plain");
    assert!(run.success, "viewer failed: {}", run.stderr);
    assert!(!run.stdout.contains("crater at"));
    let plain = read_shot(&plain);
    // The overlay's text (timings differ between runs) covers the top-left corner only.
    let (w, h) = SIZE;
    let centre = |x: u32, y: u32| x.abs_diff(w / 2) < w / 6 && y.abs_diff(h / 2) < h / 6;
    let edges = |x: u32, y: u32| y > h * 3 / 4 && (x < w / 8 || x > w * 7 / 8);
    let at_centre = mean_diff(&image, &plain, centre);
    let at_edges = mean_diff(&image, &plain, edges);
    eprintln!("crater difference: {at_centre:.2} at the centre, {at_edges:.2} at the lower edges");
    assert!(
        at_centre > 8.0 && at_centre > 4.0 * at_edges,
        "the crater shows at the centre: mean difference {at_centre:.2} there, \
         {at_edges:.2} at the lower edges"
    );
    drop(x);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_a_display_the_viewer_fails_with_one_clear_line() {
    let dir = common::fresh_dir("viewer_no_display");
    let run = viewer(None, &["--frames", "1"], &dir, "no_display");
    assert!(!run.success, "no display must be an error");
    let lines: Vec<&str> = run.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "one line: {:?}", run.stderr);
    assert!(
        lines[0].starts_with("viewer: error: cannot open a window"),
        "{:?}",
        lines[0]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A script that is a named pipe or a device is refused at once (opening a pipe blocked until
/// a writer came; /dev/zero was read until memory ran out), before any window is opened.
#[test]
fn a_script_that_is_no_regular_file_is_refused_at_once() {
    let dir = common::fresh_dir("viewer_special_script");
    let pipe = dir.join("pipe");
    let made = Command::new("mkfifo").arg(&pipe).status();
    let mut specials = vec![PathBuf::from("/dev/zero")];
    if made.is_ok_and(|s| s.success()) {
        specials.push(pipe);
    }
    for (i, special) in specials.iter().enumerate() {
        let path = special.to_str().unwrap();
        let run = viewer(
            None,
            &["--frames", "1", "--script", path],
            &dir,
            &format!("s{i}"),
        );
        assert!(!run.success, "{path}");
        assert!(
            run.stderr.contains("not a regular file"),
            "{path}: {}",
            run.stderr
        );
        assert!(
            run.elapsed < Duration::from_secs(10),
            "{path}: {:?}",
            run.elapsed
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
