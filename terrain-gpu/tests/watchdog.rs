//! The test watchdog: a GPU test that stops making progress fails with the last GPU
//! operations and every thread's stack, instead of hanging until an outer timeout kills it.
//! A child process (this binary, re-run with an environment variable) makes a download, then
//! blocks in a named thread; the watchdog, armed at 1 s, must abort it.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use terrain_gpu::testing::{WATCHDOG_ENV, context_or_skip};

const CHILD_ENV: &str = "TERRAIN_WATCHDOG_TEST_CHILD";

/// The child: a GPU operation, then no progress at all.
#[test]
fn watchdog_child() {
    if std::env::var(CHILD_ENV).is_err() {
        return;
    }
    let ctx = context_or_skip("watchdog_child").expect("the parent found an adapter");
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("watchdog test"),
        size: 256,
        usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    terrain_gpu::download_bytes(&ctx.device, &ctx.queue, &buffer, 0, 256).expect("download");
    std::thread::Builder::new()
        .name("stuck-in-test".into())
        .spawn(|| std::thread::sleep(Duration::from_secs(120)))
        .expect("thread")
        .join()
        .expect("joined");
}

#[test]
fn a_test_that_stops_making_progress_fails_with_stacks_and_gpu_operations() {
    if std::env::var(CHILD_ENV).is_ok() || context_or_skip("watchdog").is_none() {
        return;
    }
    let started = Instant::now();
    let out = Command::new(std::env::current_exe().expect("test binary"))
        .args([
            "watchdog_child",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, "1")
        .env(WATCHDOG_ENV, "1")
        .stdin(Stdio::null())
        .output()
        .expect("child runs");
    let elapsed = started.elapsed();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the stuck child passed: {stderr}");
    assert!(
        elapsed < Duration::from_secs(60),
        "the watchdog fired late ({elapsed:?})"
    );
    assert!(
        stderr.contains("terrain-gpu watchdog: no progress for"),
        "{stderr}"
    );
    // The last GPU operations: the download's submit and map.
    assert!(
        stderr.contains("download: submitted copy (bytes) 256"),
        "{stderr}"
    );
    assert!(stderr.contains("map_and_read: mapped and read"), "{stderr}");
    // Every thread, the stuck one by name (gdb, eu-stack or /proc all name it).
    assert!(stderr.contains("stuck-in-test"), "{stderr}");
}
