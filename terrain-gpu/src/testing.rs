//! Helpers for GPU tests: a context, or a skip with a printed reason, or a failure when
//! `TERRAIN_REQUIRE_GPU=1` (set by `cargo xtask ci`) and no adapter exists; and a watchdog,
//! armed by the first context, that turns a test which stops making progress into a failure
//! with every thread's stack and the last GPU operations (hangs seen on hardware only must be
//! found, not waited out).

#[cfg(feature = "blocking")]
use crate::device::context::GpuContext;

/// Environment variable that turns a missing adapter into a test failure.
pub const REQUIRE_GPU_ENV: &str = "TERRAIN_REQUIRE_GPU";

/// A headless context for `test`, or `None` (after printing why) when no adapter exists and
/// `TERRAIN_REQUIRE_GPU` is not `1`. Needs the `blocking` feature (it makes the context).
///
/// # Panics
/// When no adapter exists and `TERRAIN_REQUIRE_GPU=1`: CI must not silently skip GPU tests.
#[cfg(feature = "blocking")]
pub fn context_or_skip(test: &str) -> Option<GpuContext> {
    crate::device::trace::progress();
    match GpuContext::new_headless() {
        Ok(ctx) => {
            // Armed only where GPU work runs: a binary that skips has nothing to watch.
            arm_watchdog_from_env();
            Some(ctx)
        }
        Err(e) => {
            if std::env::var(REQUIRE_GPU_ENV).is_ok_and(|v| v == "1") {
                panic!("{test}: {REQUIRE_GPU_ENV}=1 but no GPU context: {e}");
            }
            eprintln!("skipping {test}: {e}");
            None
        }
    }
}

/// Environment variable: seconds without progress after which the watchdog fires (default
/// [`WATCHDOG_DEFAULT_SECS`]; `0` disarms it).
pub const WATCHDOG_ENV: &str = "TERRAIN_WATCHDOG_SECS";

/// The default watchdog limit: far beyond any GPU test's own time on a software adapter, and
/// beyond the 60 s a bounded poll waits before it reports an error.
pub const WATCHDOG_DEFAULT_SECS: u64 = 300;

/// Arms the watchdog with the limit of [`WATCHDOG_ENV`] (once per process).
#[cfg(feature = "blocking")]
fn arm_watchdog_from_env() {
    let secs = match std::env::var(WATCHDOG_ENV) {
        Ok(v) => v.trim().parse().unwrap_or(WATCHDOG_DEFAULT_SECS),
        Err(_) => WATCHDOG_DEFAULT_SECS,
    };
    if secs > 0 {
        arm_watchdog(std::time::Duration::from_secs(secs));
    }
}

/// Arms (once per process; later calls keep the first limit) a watchdog thread that fires when
/// neither a GPU operation at a waiting point (submits of downloads, maps, polls) nor a test
/// start ([`context_or_skip`]) happened for `limit`. [`context_or_skip`] arms it once a
/// context exists, so a binary whose tests all skip is never watched. It then prints, on stderr, the last GPU
/// operations and every thread's stack (through `gdb`, else `eu-stack`, else each thread's
/// name, state and kernel wait channel from `/proc`), and aborts the process, so the test
/// binary fails instead of hanging until an outer timeout kills it without a trace.
pub fn arm_watchdog(limit: std::time::Duration) {
    static ARMED: std::sync::Once = std::sync::Once::new();
    ARMED.call_once(|| {
        crate::device::trace::enable();
        let spawned = std::thread::Builder::new()
            .name("terrain-watchdog".into())
            .spawn(move || {
                let limit_ms = limit.as_millis().max(1) as u64;
                let tick = std::time::Duration::from_millis((limit_ms / 4).clamp(10, 1000));
                loop {
                    std::thread::sleep(tick);
                    let idle = crate::device::trace::idle_ms();
                    if idle >= limit_ms {
                        fire(idle);
                    }
                }
            });
        if let Err(e) = spawned {
            eprintln!("terrain-gpu watchdog: could not start its thread ({e}); running without");
        }
    });
}

/// How long one stack-dumping tool may take: attaching to a thread stuck in the kernel (a
/// driver call in uninterruptible sleep) may never complete.
const TOOL_LIMIT: std::time::Duration = std::time::Duration::from_secs(30);

/// Prints what the process was doing and aborts it (a backstop aborts anyway if printing
/// itself hangs).
fn fire(idle_ms: u64) -> ! {
    let _ = std::thread::Builder::new()
        .name("terrain-watchdog-backstop".into())
        .spawn(|| {
            std::thread::sleep(3 * TOOL_LIMIT);
            eprintln!("=== terrain-gpu watchdog: the dump itself hung; aborting ===");
            std::process::abort()
        });
    let pid = std::process::id();
    eprintln!(
        "\n=== terrain-gpu watchdog: no progress for {:.1} s (pid {pid}) ===",
        idle_ms as f64 / 1000.0
    );
    eprintln!("--- last GPU operations (oldest first; time since the process started) ---");
    for line in crate::device::trace::dump() {
        eprintln!("{line}");
    }
    eprintln!("--- every thread's stack ---");
    if !print_stacks(pid) {
        print_thread_states();
    }
    eprintln!("=== terrain-gpu watchdog: aborting the test process ===");
    std::process::abort()
}

/// Every thread's stack by a debugger attached to this process; false when none could.
fn print_stacks(pid: u32) -> bool {
    let pid = pid.to_string();
    let tools: [(&str, Vec<&str>); 2] = [
        (
            "gdb",
            vec![
                "--batch",
                "--nx",
                "-p",
                &pid,
                "-ex",
                "set pagination off",
                "-ex",
                "thread apply all bt",
            ],
        ),
        ("eu-stack", vec!["-p", &pid]),
    ];
    for (tool, args) in tools {
        let Some(out) = run_bounded(tool, &args) else {
            continue;
        };
        let text = String::from_utf8_lossy(&out.stdout);
        if text.contains("Thread") || text.contains("TID") || text.contains("#0") {
            eprintln!("({tool})\n{text}");
            return true;
        }
        eprintln!(
            "({tool} could not attach: {})",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    false
}

/// Runs `tool` with `args`, its output to temp files, killed after [`TOOL_LIMIT`]; `None` when
/// it could not start or did not finish.
fn run_bounded(tool: &str, args: &[&str]) -> Option<std::process::Output> {
    let dir = std::env::temp_dir();
    let tag = format!("terrain-watchdog-{}-{tool}", std::process::id());
    let (out_path, err_path) = (
        dir.join(format!("{tag}.out")),
        dir.join(format!("{tag}.err")),
    );
    let mut child = std::process::Command::new(tool)
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::fs::File::create(&out_path).ok()?)
        .stderr(std::fs::File::create(&err_path).ok()?)
        .spawn()
        .ok()?;
    let started = std::time::Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if started.elapsed() < TOOL_LIMIT => {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                eprintln!("({tool} did not finish within {} s)", TOOL_LIMIT.as_secs());
                return None;
            }
        }
    };
    let read = |p: &std::path::Path| {
        let bytes = std::fs::read(p).unwrap_or_default();
        let _ = std::fs::remove_file(p);
        bytes
    };
    Some(std::process::Output {
        status,
        stdout: read(&out_path),
        stderr: read(&err_path),
    })
}

/// Without a debugger: each thread's name, state and kernel wait channel (where it sleeps).
fn print_thread_states() {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        eprintln!("(no debugger and no /proc: no stacks)");
        return;
    };
    for task in tasks.flatten() {
        let read = |name: &str| {
            std::fs::read_to_string(task.path().join(name))
                .map(|s| s.trim().to_owned())
                .unwrap_or_default()
        };
        let state = read("stat")
            .rsplit_once(") ")
            .map(|(_, rest)| rest.chars().next().unwrap_or('?'))
            .unwrap_or('?');
        eprintln!(
            "thread {} '{}': state {state}, waiting in {}",
            task.file_name().to_string_lossy(),
            read("comm"),
            read("wchan")
        );
    }
}
