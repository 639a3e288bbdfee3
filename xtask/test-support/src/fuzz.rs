//! The time-bounded fuzz harness of the workspace's `tests/fuzz.rs` targets (terrain-core,
//! terrain-cache, terrain-physics, terrain-lod): one copy, so every target runs, selects,
//! replays and reports its classes the same way.
//!
//! A target is a list of input classes. A class is a function that makes one case from a
//! deterministic RNG (seeded from the run's seed, the class name and the case index), feeds it
//! to the code under test and checks what came back. [`run`] gives every selected class an
//! equal share of the target's time and runs its cases on a worker thread, while the test
//! thread watches for a case that hangs. A case fails when it panics (caught, with its message
//! and location), when its check returns an error, when it takes longer than the target's
//! per-case limit three times in a row (once could be the scheduler; an input that is slow is
//! slow every time), or when it hangs (the worker is abandoned and the next class starts on a new one).
//!
//! Output, one line each, read by `cargo xtask fuzz`:
//!
//! ```text
//! fuzz <target>: class <class>: <cases> cases in <s> s[ (<n> drawn outside the class skipped)]: ok
//! fuzz <target>: class <class>: <cases> cases in <s> s: FAILED (<why>) ...
//! fuzz <target>: class <class>: disabled (<reason>)
//! fuzz <target>: class <class>: <n> notes, first: <note>
//! fuzz <target>: <cases> cases in <s> s (seed 0x...)
//! ```
//!
//! Environment:
//! - `TERRAIN_FUZZ_SECONDS`: seconds per target (default 2, so `cargo test` stays quick).
//! - `TERRAIN_FUZZ_SEED`: the run's seed, decimal or `0x` hex (default: from the clock); every
//!   run prints it.
//! - `TERRAIN_FUZZ_CLASSES`: comma-separated class names to run; a disabled class runs when it
//!   is named here.
//! - `TERRAIN_FUZZ_REPLAY`: `class:case_seed` runs exactly that one case (a failure prints it),
//!   printing what the class shows of its inputs.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex, Once};
use std::time::{Duration, Instant};

/// Seconds per target when `TERRAIN_FUZZ_SECONDS` is not set.
pub const DEFAULT_SECONDS: f64 = 2.0;

/// One step of splitmix64: a good 64-bit mix, used to derive class and case seeds.
pub fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// FNV-1a of a name, so a class's seeds do not depend on its position in the list.
fn name_hash(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// A small deterministic RNG (splitmix64) with the draws the targets need.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// An RNG starting from `seed`.
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    /// Uniform in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            return 0;
        }
        // Multiply-shift: no modulo bias worth caring about for a fuzzer, and no division.
        ((u128::from(self.next_u64()) * u128::from(n)) >> 64) as u64
    }

    /// Uniform in `0..n` as a usize (0 when `n` is 0).
    pub fn index(&mut self, n: usize) -> usize {
        self.below(n as u64) as usize
    }

    /// Uniform in `lo..=hi` (`lo` when `hi < lo`).
    pub fn range_u32(&mut self, lo: u32, hi: u32) -> u32 {
        if hi <= lo {
            return lo;
        }
        lo + self.below(u64::from(hi - lo) + 1) as u32
    }

    /// Uniform in `lo..=hi` (`lo` when `hi < lo`).
    pub fn range_usize(&mut self, lo: usize, hi: usize) -> usize {
        if hi <= lo {
            return lo;
        }
        lo + self.index(hi - lo + 1)
    }

    /// True with probability `num / den`.
    pub fn chance(&mut self, num: u64, den: u64) -> bool {
        self.below(den) < num
    }

    /// A random element of a non-empty slice.
    pub fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.index(items.len())]
    }

    /// `n` random bytes.
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        let mut out = Vec::with_capacity(n + 8);
        while out.len() < n {
            out.extend_from_slice(&self.next_u64().to_le_bytes());
        }
        out.truncate(n);
        out
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Any finite f32: random bits, an edge value, or one uniform in `[-modest, modest)`, a
    /// third of the time each.
    pub fn f32_any(&mut self, modest: f64) -> f32 {
        match self.below(3) {
            0 => self.f32_bits(),
            1 => self.f32_edge(),
            _ => self.uniform(-modest, modest) as f32,
        }
    }

    /// Flips 1 to 16 random bits of `bytes` (none when it is empty).
    pub fn flip_bits(&mut self, bytes: &mut [u8]) {
        if bytes.is_empty() {
            return;
        }
        for _ in 0..self.range_u32(1, 16) {
            let i = self.index(bytes.len());
            bytes[i] ^= 1 << self.below(8);
        }
    }

    /// A finite f32 from random bits: every exponent equally likely, so the whole finite range
    /// (subnormals, 1e-30, 1e30, +-f32::MAX) is reached, not just values near 1.
    pub fn f32_bits(&mut self) -> f32 {
        loop {
            let v = f32::from_bits(self.next_u32());
            if v.is_finite() {
                return v;
            }
        }
    }

    /// A finite f32 that code tends to get wrong: zeros, the smallest and largest values,
    /// powers of two around integer limits, and values just beside them.
    pub fn f32_edge(&mut self) -> f32 {
        const EDGES: [f32; 24] = [
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            1e-45,
            f32::EPSILON,
            0.5,
            1.0,
            1e-6,
            1e3,
            1e6,
            16_777_216.0,
            2_147_483_648.0,
            4_294_967_296.0,
            9.223_372e18,
            1.844_674_4e19,
            1e20,
            1e30,
            3.0e38,
            f32::MAX,
            65_536.0,
            268_435_456.0,
            1.5,
            0.1,
            1e-30,
        ];
        let v = self.pick(&EDGES);
        let v = match self.below(4) {
            0 => next_up(v),
            1 => next_down(v),
            _ => v,
        };
        if self.chance(1, 2) { -v } else { v }
    }

    /// NaN, +infinity or -infinity.
    pub fn f32_non_finite(&mut self) -> f32 {
        self.pick(&[f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN])
    }

    /// A u32 that code tends to get wrong: 0, 1, powers of two and their neighbours, the top.
    pub fn u32_edge(&mut self) -> u32 {
        let p = 1u32 << self.below(32);
        match self.below(6) {
            0 => 0,
            1 => u32::MAX - self.below(3) as u32,
            2 => p.wrapping_sub(1),
            3 => p.wrapping_add(1),
            4 => p,
            _ => self.next_u32(),
        }
    }
}

/// The finite f32 nearest to `v`: NaN gives 0, infinities and overflow clamp to `+-f32::MAX`.
pub fn finite_f32(v: f64) -> f32 {
    if v.is_nan() {
        return 0.0;
    }
    v.clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
}

fn next_up(v: f32) -> f32 {
    if !v.is_finite() || v == f32::MAX {
        return v;
    }
    if v == 0.0 {
        return f32::from_bits(1);
    }
    let b = v.to_bits();
    f32::from_bits(if v > 0.0 { b + 1 } else { b - 1 })
}

fn next_down(v: f32) -> f32 {
    -next_up(-v)
}

/// One case: its RNG, and a place to leave a note (something odd but not a failure, such as
/// a query answering NaN for a finite input) that the class's line reports.
#[derive(Debug)]
pub struct Case {
    /// The case's RNG: every input of the case comes from it, so its seed replays the case.
    pub rng: Rng,
    want_note: bool,
    note: Option<String>,
    verbose: bool,
    /// Set by a class for a case drawn outside it (a class cut off from another by a bound
    /// the generator cannot hit exactly): the case is counted apart, not as a case run. A
    /// field, not a method, so that a class can set it while it holds `rng` borrowed.
    pub skipped: bool,
}

impl Case {
    /// Prints `what` (the case's inputs, say) when the case is replayed alone
    /// (`TERRAIN_FUZZ_REPLAY`); otherwise does nothing and never calls `what`.
    pub fn show(&self, what: impl FnOnce() -> String) {
        if self.verbose {
            eprintln!("{}", what());
        }
    }

    /// Whether the case is replayed alone (for a class that shows inputs while it holds
    /// `rng` borrowed).
    pub fn verbose(&self) -> bool {
        self.verbose
    }

    /// Records a note; `what` is only called for the first note of a class.
    pub fn note(&mut self, what: impl FnOnce() -> String) {
        if self.note.is_none() {
            self.note = Some(if self.want_note {
                what()
            } else {
                String::new()
            });
        }
    }
}

/// An input class: its name and the function that makes and checks one case.
pub struct Class<C> {
    /// The class's name (letters, digits and `_`), as printed and as `TERRAIN_FUZZ_CLASSES`
    /// and `TERRAIN_FUZZ_REPLAY` take it.
    pub name: &'static str,
    /// Makes one case from `case.rng`, runs it on the context and checks the result.
    pub run: fn(&C, &mut Case) -> Result<(), String>,
}

impl<C> std::fmt::Debug for Class<C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Class").field("name", &self.name).finish()
    }
}

/// A fuzz target: its classes, the ones disabled (with why) and the time one case may take.
pub struct Target<C> {
    /// The target's name, as printed (`fuzz <name>: ...`).
    pub name: &'static str,
    /// Longest a single case may take (three times in a row) before it fails as too slow.
    pub per_case_limit: Duration,
    /// Every class, in the order they run.
    pub classes: Vec<Class<C>>,
    /// Classes not run by default, each with the reason (`TERRAIN_FUZZ_CLASSES` runs them).
    pub disabled: &'static [(&'static str, &'static str)],
}

impl<C> std::fmt::Debug for Target<C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Target")
            .field("name", &self.name)
            .field("per_case_limit", &self.per_case_limit)
            .field("classes", &self.classes)
            .field("disabled", &self.disabled)
            .finish()
    }
}

/// How a case failed.
#[derive(Debug)]
enum Failure {
    Panic(String),
    Check(String),
    Slow(Vec<Duration>),
    Hang(Duration),
    WorkerLost,
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Failure::Panic(m) => write!(f, "panic: {m}"),
            Failure::Check(m) => write!(f, "check failed: {m}"),
            Failure::Slow(times) => {
                let ms: Vec<String> = times
                    .iter()
                    .map(|t| format!("{:.1} ms", t.as_secs_f64() * 1e3))
                    .collect();
                write!(
                    f,
                    "too slow: {} (every run over the limit)",
                    ms.join(", then ")
                )
            }
            Failure::Hang(d) => write!(f, "hang: still running after {:.1} s", d.as_secs_f64()),
            Failure::WorkerLost => write!(f, "the worker thread died outside a case"),
        }
    }
}

/// What a worker reports at the end of its class.
#[derive(Debug)]
struct ClassReport {
    cases: u64,
    skipped: u64,
    notes: u64,
    first_note: Option<String>,
    failure: Option<(u64, u64, Failure)>,
}

/// The case a worker is running, for the watchdog.
#[derive(Debug, Clone, Copy)]
struct Progress {
    case: u64,
    case_seed: u64,
    started: Instant,
}

thread_local! {
    /// Message and location of the last panic on this thread (set by the hook below).
    static LAST_PANIC: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

/// Installs (once) a panic hook that also records the panic's message and location for the
/// failure line, then calls the hook that was there before.
fn install_panic_hook() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let msg = if let Some(s) = info.payload().downcast_ref::<&str>() {
                (*s).to_owned()
            } else if let Some(s) = info.payload().downcast_ref::<String>() {
                s.clone()
            } else {
                "(non-string panic payload)".to_owned()
            };
            let at = info
                .location()
                .map(|l| format!(" at {}:{}:{}", l.file(), l.line(), l.column()))
                .unwrap_or_default();
            LAST_PANIC.with(|p| *p.borrow_mut() = Some(format!("{msg}{at}")));
            previous(info);
        }));
    });
}

/// Runs one case, catching a panic.
fn run_case<C>(ctx: &C, class: &Class<C>, case_seed: u64, case: &mut Case) -> Result<(), Failure> {
    case.rng = Rng::new(case_seed);
    match catch_unwind(AssertUnwindSafe(|| (class.run)(ctx, case))) {
        Ok(Ok(())) => Ok(()),
        Ok(Err(m)) => Err(Failure::Check(m)),
        Err(_) => Err(Failure::Panic(
            LAST_PANIC
                .with(|p| p.borrow_mut().take())
                .unwrap_or_else(|| "(no message)".into()),
        )),
    }
}

/// The seed of case `i` of a class.
fn case_seed(class_seed: u64, i: u64) -> u64 {
    splitmix(class_seed ^ splitmix(i))
}

fn env_seconds() -> f64 {
    std::env::var("TERRAIN_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s >= 0.0)
        .unwrap_or(DEFAULT_SECONDS)
}

fn parse_u64(s: &str) -> Option<u64> {
    let s = s.trim();
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16).ok(),
        None => s.parse().ok(),
    }
}

fn env_seed() -> u64 {
    if let Some(seed) = std::env::var("TERRAIN_FUZZ_SEED")
        .ok()
        .and_then(|s| parse_u64(&s))
    {
        return seed;
    }
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    splitmix(nanos ^ u64::from(std::process::id()).rotate_left(32))
}

/// Runs a target (see the module docs) and panics, after printing every class's line, if a
/// class failed.
pub fn run<C: Send + Sync + 'static>(target: Target<C>, ctx: C) {
    install_panic_hook();
    let ctx = Arc::new(ctx);
    let classes: Vec<Arc<Class<C>>> = target.classes.into_iter().map(Arc::new).collect();
    let name = target.name;
    for (d, _) in target.disabled {
        assert!(
            classes.iter().any(|c| c.name == *d),
            "fuzz {name}: disabled class {d} does not exist"
        );
    }
    let seed = env_seed();
    let selected: Option<Vec<String>> = std::env::var("TERRAIN_FUZZ_CLASSES")
        .ok()
        .map(|s| s.split(',').map(|c| c.trim().to_owned()).collect());
    let replay: Option<(String, u64)> = std::env::var("TERRAIN_FUZZ_REPLAY").ok().and_then(|s| {
        let (class, case) = s.split_once(':')?;
        Some((class.trim().to_owned(), parse_u64(case)?))
    });

    // Which classes run, and which are reported as disabled.
    let mut plan: Vec<Arc<Class<C>>> = Vec::new();
    let mut skipped: Vec<(&'static str, &'static str)> = Vec::new();
    for c in &classes {
        let disabled = target.disabled.iter().find(|(d, _)| *d == c.name);
        let run_it = match (&replay, &selected) {
            (Some((r, _)), _) => r == c.name,
            (None, Some(sel)) => sel.iter().any(|s| s == c.name),
            (None, None) => disabled.is_none(),
        };
        if run_it {
            plan.push(c.clone());
        } else if let (Some((_, why)), None, None) = (disabled, &replay, &selected) {
            skipped.push((c.name, why));
        }
    }
    if let Some((r, _)) = &replay {
        assert!(
            !plan.is_empty(),
            "fuzz {name}: no class named {r} to replay"
        );
    }

    let total = Duration::from_secs_f64(env_seconds());
    let share = total / plan.len().max(1) as u32;
    let limit = target.per_case_limit;
    let hang_after = limit * 4 + Duration::from_secs(1);
    let started = Instant::now();
    let mut all_cases = 0u64;
    let mut failed: Vec<String> = Vec::new();

    for class in plan {
        let class_seed = splitmix(seed ^ name_hash(class.name));
        let class_start = Instant::now();
        let progress = Arc::new(Mutex::new(Progress {
            case: 0,
            case_seed: 0,
            started: Instant::now(),
        }));
        let (tx, rx) = mpsc::channel::<ClassReport>();
        let worker = {
            let (ctx, class, progress) = (ctx.clone(), class.clone(), progress.clone());
            let only = replay.as_ref().map(|(_, s)| *s);
            std::thread::Builder::new()
                .name(format!("fuzz-{name}-{}", class.name))
                .spawn(move || {
                    let report = work(&*ctx, &class, class_seed, only, share, limit, &progress);
                    // The watchdog may have given up on this worker already: nobody listens.
                    let _ = tx.send(report);
                })
        };
        let report = match worker {
            Err(e) => ClassReport {
                cases: 0,
                skipped: 0,
                notes: 0,
                first_note: None,
                failure: Some((
                    0,
                    0,
                    Failure::Check(format!("could not start a worker: {e}")),
                )),
            },
            Ok(_) => loop {
                match rx.recv_timeout(Duration::from_millis(20)) {
                    Ok(r) => break r,
                    Err(RecvTimeoutError::Disconnected) => {
                        break ClassReport {
                            cases: 0,
                            skipped: 0,
                            notes: 0,
                            first_note: None,
                            failure: Some((0, 0, Failure::WorkerLost)),
                        };
                    }
                    Err(RecvTimeoutError::Timeout) => {
                        let p = *progress.lock().unwrap_or_else(|e| e.into_inner());
                        let running = p.started.elapsed();
                        if running > hang_after {
                            // The worker is stuck in a case: leave it and go on with the next
                            // class on a fresh thread.
                            break ClassReport {
                                cases: p.case,
                                skipped: 0,
                                notes: 0,
                                first_note: None,
                                failure: Some((p.case, p.case_seed, Failure::Hang(running))),
                            };
                        }
                    }
                }
            },
        };
        let secs = class_start.elapsed().as_secs_f64();
        all_cases += report.cases;
        let skipped = if report.skipped > 0 {
            format!(" ({} drawn outside the class skipped)", report.skipped)
        } else {
            String::new()
        };
        let head = format!(
            "fuzz {name}: class {}: {} cases in {secs:.1} s{skipped}",
            class.name, report.cases
        );
        match &report.failure {
            None => println!("{head}: ok"),
            Some((i, case_seed, why)) => {
                let line = format!(
                    "{head}: FAILED ({why}) at case {i}; replay with TERRAIN_FUZZ_REPLAY={}:{case_seed:#x}",
                    class.name
                );
                println!("{line}");
                failed.push(line);
            }
        }
        if report.notes > 0 {
            println!(
                "fuzz {name}: class {}: {} notes, first: {}",
                class.name,
                report.notes,
                report.first_note.unwrap_or_default()
            );
        }
    }
    for (c, why) in skipped {
        println!("fuzz {name}: class {c}: disabled ({why})");
    }
    println!(
        "fuzz {name}: {all_cases} cases in {:.1} s (seed {seed:#x})",
        started.elapsed().as_secs_f64()
    );
    assert!(
        failed.is_empty(),
        "fuzz {name}: {} class(es) failed (seed {seed:#x}):\n{}",
        failed.len(),
        failed.join("\n")
    );
}

/// The worker's loop over one class: cases until its share of the time is spent (at least
/// one), or exactly the replayed case.
fn work<C>(
    ctx: &C,
    class: &Class<C>,
    class_seed: u64,
    only: Option<u64>,
    share: Duration,
    limit: Duration,
    progress: &Mutex<Progress>,
) -> ClassReport {
    let end = Instant::now() + share;
    let mut report = ClassReport {
        cases: 0,
        skipped: 0,
        notes: 0,
        first_note: None,
        failure: None,
    };
    let mut case = Case {
        rng: Rng::new(0),
        want_note: true,
        note: None,
        verbose: only.is_some(),
        skipped: false,
    };
    let mut i = 0u64;
    loop {
        let seed = only.unwrap_or_else(|| case_seed(class_seed, i));
        let t = Instant::now();
        *progress.lock().unwrap_or_else(|e| e.into_inner()) = Progress {
            case: i,
            case_seed: seed,
            started: t,
        };
        case.want_note = report.first_note.is_none();
        let mut outcome = run_case(ctx, class, seed, &mut case);
        let took = t.elapsed();
        if outcome.is_ok() && took > limit {
            // Twice more: a loaded machine stalls a case now and then, a slow input is slow
            // every time.
            let mut times = vec![took];
            while outcome.is_ok() && times.len() < 3 && times.iter().all(|t| *t > limit) {
                let again = Instant::now();
                outcome = run_case(ctx, class, seed, &mut case);
                times.push(again.elapsed());
            }
            if outcome.is_ok() && times.iter().all(|t| *t > limit) {
                outcome = Err(Failure::Slow(times));
            }
        }
        if std::mem::take(&mut case.skipped) {
            report.skipped += 1;
            if only.is_some() {
                eprintln!("the replayed case lies outside its class: skipped");
            }
        }
        if let Some(note) = case.note.take() {
            report.notes += 1;
            if report.first_note.is_none() {
                report.first_note = Some(note);
            }
        }
        if let Err(f) = outcome {
            report.failure = Some((i, seed, f));
            report.cases = i + 1 - report.skipped;
            return report;
        }
        i += 1;
        if only.is_some() || Instant::now() >= end {
            report.cases = i - report.skipped;
            return report;
        }
    }
}
