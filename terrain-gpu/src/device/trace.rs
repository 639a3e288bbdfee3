//! The last GPU operations this process made at the points where it waits for the GPU
//! (submits of downloads, maps, blocking and non-blocking polls), kept only while a watchdog is
//! armed (`testing::arm_watchdog`, behind the `testing` feature): when a test stops making
//! progress, the watchdog prints them beside every thread's stack, which tells a hang inside a
//! poll from one in the test's own code.
//!
//! Recording costs one relaxed atomic load when no watchdog is armed, and nothing without the
//! `testing` feature (no watchdog can be armed then: `record` is empty).
#![cfg_attr(not(feature = "testing"), allow(dead_code))]

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// How many operations are kept.
const KEEP: usize = 64;

/// Whether operations are recorded.
static ON: AtomicBool = AtomicBool::new(false);
/// Milliseconds since [`start`] of the last recorded operation or progress mark.
static LAST_MS: AtomicU64 = AtomicU64::new(0);

/// One recorded operation.
#[derive(Debug, Clone)]
struct Op {
    at_ms: u64,
    thread: String,
    what: &'static str,
    detail: u64,
}

fn ring() -> &'static Mutex<VecDeque<Op>> {
    static RING: OnceLock<Mutex<VecDeque<Op>>> = OnceLock::new();
    RING.get_or_init(|| Mutex::new(VecDeque::with_capacity(KEEP)))
}

/// The time origin of the records.
pub(crate) fn start() -> Instant {
    static START: OnceLock<Instant> = OnceLock::new();
    *START.get_or_init(Instant::now)
}

fn now_ms() -> u64 {
    start().elapsed().as_millis() as u64
}

/// Starts recording.
pub(crate) fn enable() {
    start();
    LAST_MS.store(now_ms(), Ordering::Relaxed);
    ON.store(true, Ordering::Relaxed);
}

/// Without the `testing` feature nothing arms a watchdog, so nothing is recorded.
#[cfg(not(feature = "testing"))]
#[inline(always)]
pub(crate) fn record(_what: &'static str, _detail: u64) {}

/// Records `what` (a fixed label) with a number (a size, a submission, 0).
#[cfg(feature = "testing")]
pub(crate) fn record(what: &'static str, detail: u64) {
    if !ON.load(Ordering::Relaxed) {
        return;
    }
    let at_ms = now_ms();
    LAST_MS.store(at_ms, Ordering::Relaxed);
    let thread = std::thread::current()
        .name()
        .unwrap_or("unnamed")
        .to_owned();
    let mut ring = ring().lock().unwrap_or_else(|p| p.into_inner());
    if ring.len() == KEEP {
        ring.pop_front();
    }
    ring.push_back(Op {
        at_ms,
        thread,
        what,
        detail,
    });
}

/// Marks progress without an operation (a test starting).
#[cfg(feature = "blocking")]
pub(crate) fn progress() {
    LAST_MS.store(now_ms(), Ordering::Relaxed);
}

/// Milliseconds since the last operation or progress mark.
pub(crate) fn idle_ms() -> u64 {
    now_ms().saturating_sub(LAST_MS.load(Ordering::Relaxed))
}

/// The recorded operations, oldest first, one line each.
pub(crate) fn dump() -> Vec<String> {
    let ring = ring().lock().unwrap_or_else(|p| p.into_inner());
    ring.iter()
        .map(|op| {
            format!(
                "{:>9.3} s  [{}] {} {}",
                op.at_ms as f64 / 1000.0,
                op.thread,
                op.what,
                op.detail
            )
        })
        .collect()
}
