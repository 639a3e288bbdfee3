//! `cargo xtask fuzz --engine libfuzzer [--seconds N] [--target NAME] [--seed S]`: runs the
//! decoders' coverage-guided targets (the fuzz crate in `xtask/fuzz/`, cargo-fuzz and
//! libFuzzer on the nightly toolchain) for N seconds each (default 60) and prints, per target,
//! the executions, their rate, the coverage reached and any crash with the file that
//! reproduces it. Not part of `cargo xtask ci`: CI runs the same target bodies briefly under
//! `cargo test` (test-support's `tests/fuzz.rs`).
//!
//! Everything lives under `target/fuzz/`: `build/` (the instrumented build), `seeds/<target>/`
//! (written afresh each run by test-support's `fuzz_seeds` example from the decoders' seed
//! functions), `corpus/<target>/` (what libFuzzer keeps: it grows from run to run) and
//! `artifacts/<target>/` (crash inputs).

use crate::util::{cargo, root, target_dir};
use anyhow::{Context, Result, bail};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The libFuzzer targets: the fuzz crate's binaries, one per function of
/// `terrain_test_support::decoders` of the same name.
pub const LIBFUZZER_TARGETS: [&str; 8] = [
    "png16", "png8", "raw16", "r32", "geotiff", "manifest", "bounds", "tile",
];

/// libFuzzer's options for every target: a single input over 10 s is a hang, a single
/// allocation over 512 MiB (the decoders' limits allow a few MiB) or 2 GiB in all is a crash.
const LIBFUZZER_OPTIONS: [&str; 4] = [
    "-timeout=10",
    "-malloc_limit_mb=512",
    "-rss_limit_mb=2048",
    "-print_final_stats=1",
];

/// What one target's run reported.
#[derive(Debug, Clone, Default, PartialEq)]
struct RunStats {
    /// Inputs executed (`stat::number_of_executed_units`).
    execs: Option<u64>,
    /// Executions per second (`stat::average_exec_per_sec`).
    per_second: Option<u64>,
    /// Coverage counters and features at the last status line (`cov:`, `ft:`).
    cov: Option<u64>,
    ft: Option<u64>,
    /// Inputs in the corpus at the last status line (`corp:`).
    corpus: Option<u64>,
    /// Peak resident memory in MB (`stat::peak_rss_mb`).
    peak_rss_mb: Option<u64>,
    /// The input that crashed the target (`Test unit written to PATH`).
    crash: Option<String>,
    /// libFuzzer's own words for the crash (`==...== ERROR: libFuzzer: ...`, `panicked at`).
    why: Option<String>,
}

impl RunStats {
    /// Takes in one line of libFuzzer's output.
    fn read(&mut self, line: &str) {
        // The number after `key` (`corp: 64/10Kb` gives 64).
        let value = |key: &str| -> Option<u64> {
            let at = line.find(key)? + key.len();
            let digits = line[at..].split(|c: char| !c.is_ascii_digit()).next()?;
            digits.parse().ok()
        };
        if let Some(rest) = line.strip_prefix("stat::") {
            let (key, v) = rest.split_once(':').unwrap_or_default();
            let v = v.trim().parse().ok();
            match key {
                "number_of_executed_units" => self.execs = v,
                "average_exec_per_sec" => self.per_second = v,
                "peak_rss_mb" => self.peak_rss_mb = v,
                _ => {}
            }
        } else if line.starts_with('#') && line.contains("cov: ") {
            self.cov = value("cov: ");
            self.ft = value("ft: ");
            self.corpus = value("corp: ").or(self.corpus);
        } else if let Some((_, path)) = line.split_once("Test unit written to ") {
            self.crash = Some(path.trim().to_owned());
        } else if self.why.is_none()
            && (line.contains("ERROR: libFuzzer:") || line.contains("panicked at"))
        {
            self.why = Some(line.trim().to_owned());
        }
    }
}

/// Options of the libFuzzer engine.
#[derive(Debug)]
pub struct Options {
    pub seconds: u64,
    pub target: Option<String>,
    pub seed: Option<String>,
}

/// The nightly cargo, with the toolchain and tool variables of the cargo that runs xtask
/// (stable) removed, so that `+nightly` picks the toolchain.
fn nightly_cargo() -> Command {
    let mut cmd = Command::new("cargo");
    cmd.arg("+nightly").current_dir(root());
    for var in [
        "RUSTUP_TOOLCHAIN",
        "CARGO",
        "RUSTC",
        "RUSTDOC",
        "RUSTC_WRAPPER",
    ] {
        cmd.env_remove(var);
    }
    cmd
}

/// The fuzz crate's arguments for cargo-fuzz: its folder and its build folder.
fn fuzz_dirs(fuzz: &Path) -> Vec<String> {
    let build = fuzz.join("build");
    vec![
        "--fuzz-dir".into(),
        fuzz_crate().to_string_lossy().into_owned(),
        "--target-dir".into(),
        build.to_string_lossy().into_owned(),
    ]
}

/// Runs the libFuzzer engine (see the module docs).
pub fn run(opts: &Options) -> Result<()> {
    let targets: Vec<&str> = LIBFUZZER_TARGETS
        .into_iter()
        .filter(|t| opts.target.as_deref().is_none_or(|o| o == *t))
        .collect();
    if targets.is_empty() {
        bail!(
            "no libFuzzer target named {:?}; targets: {}",
            opts.target.clone().unwrap_or_default(),
            LIBFUZZER_TARGETS.join(", ")
        );
    }
    let version = nightly_cargo().args(["fuzz", "--version"]).output();
    if !version.is_ok_and(|o| o.status.success()) {
        bail!(
            "`cargo +nightly fuzz` is not available: the libFuzzer engine needs the nightly \
             toolchain (`rustup toolchain install nightly`) and cargo-fuzz (`cargo install \
             cargo-fuzz`)"
        );
    }
    let fuzz = target_dir().join("fuzz");
    let seeds = fuzz.join("seeds");
    let seeds_s = seeds.to_string_lossy().into_owned();
    cargo(
        &[
            "run",
            "--quiet",
            "--locked",
            "-p",
            "terrain-test-support",
            "--example",
            "fuzz_seeds",
            "--",
            &seeds_s,
        ],
        &[],
    )?;
    let mut build = nightly_cargo();
    build.args(["fuzz", "build"]).args(fuzz_dirs(&fuzz));
    if let [only] = targets[..] {
        build.arg(only);
    }
    eprintln!(
        "fuzz: cargo +nightly fuzz build (instrumented, into {})",
        fuzz.display()
    );
    let status = build
        .status()
        .context("could not start cargo +nightly fuzz build")?;
    if !status.success() {
        bail!("`cargo +nightly fuzz build` exited with {status}");
    }
    let mut rows = Vec::new();
    for t in &targets {
        let stats = run_target(t, &fuzz, opts)?;
        rows.push((*t, stats));
    }
    println!("{}", table(&rows, opts.seconds));
    let crashed: Vec<&str> = rows
        .iter()
        .filter(|(_, s)| s.crash.is_some() || s.why.is_some())
        .map(|(t, _)| *t)
        .collect();
    if !crashed.is_empty() {
        bail!(
            "fuzz: libFuzzer found a crash in {} (inputs listed above; fix it and keep the \
             input as a regression test)",
            crashed.join(", ")
        );
    }
    Ok(())
}

/// Runs one target for `opts.seconds`, echoing libFuzzer's output but for its per-input lines.
fn run_target(t: &str, fuzz: &Path, opts: &Options) -> Result<RunStats> {
    let corpus = fuzz.join("corpus").join(t);
    let artifacts = fuzz.join("artifacts").join(t);
    for dir in [&corpus, &artifacts] {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut cmd = nightly_cargo();
    cmd.args(["fuzz", "run"])
        .args(fuzz_dirs(fuzz))
        .arg(t)
        .arg(&corpus)
        .arg(fuzz.join("seeds").join(t))
        .arg("--")
        .arg(format!("-max_total_time={}", opts.seconds))
        .arg(format!("-artifact_prefix={}/", artifacts.display()))
        .args(LIBFUZZER_OPTIONS)
        .stderr(Stdio::piped());
    if let Some(seed) = &opts.seed {
        cmd.arg(format!("-seed={seed}"));
    }
    eprintln!("fuzz: libFuzzer target {t} for {} s", opts.seconds);
    let mut child = cmd
        .spawn()
        .context("could not start cargo +nightly fuzz run")?;
    let stderr = child
        .stderr
        .take()
        .context("no stderr from cargo fuzz run")?;
    let mut stats = RunStats::default();
    for line in BufReader::new(stderr).lines() {
        let line = line.context("reading libFuzzer's output")?;
        let per_input =
            line.starts_with('#') && (line.contains("NEW ") || line.contains("REDUCE "));
        if !per_input {
            eprintln!("{line}");
        }
        stats.read(&line);
    }
    let status = child.wait().context("waiting for cargo fuzz run")?;
    if !status.success() && stats.why.is_none() {
        stats.why = Some(format!("cargo fuzz run exited with {status}"));
    }
    Ok(stats)
}

/// The results as a Markdown table, a crash's reproducing input under it.
fn table(rows: &[(&str, RunStats)], seconds: u64) -> String {
    let n = |v: Option<u64>| v.map_or("-".to_owned(), |v| v.to_string());
    let mut out = format!(
        "\n| target ({seconds} s) | execs | execs/s | cov | features | corpus | peak RSS MB | \
         result |\n|---|---|---|---|---|---|---|---|\n"
    );
    let mut crashes = String::new();
    for (t, s) in rows {
        let result = match (&s.crash, &s.why) {
            (None, None) => "ok".to_owned(),
            (Some(path), _) => {
                crashes.push_str(&format!(
                    "{t}: {}\n  input: {path}\n  replay: cargo +nightly fuzz run --fuzz-dir \
                     xtask/fuzz {t} {path}\n",
                    s.why.as_deref().unwrap_or("crash")
                ));
                "**CRASH**".to_owned()
            }
            (None, Some(why)) => format!("**FAILED** ({why})"),
        };
        out.push_str(&format!(
            "| {t} | {} | {} | {} | {} | {} | {} | {result} |\n",
            n(s.execs),
            n(s.per_second),
            n(s.cov),
            n(s.ft),
            n(s.corpus),
            n(s.peak_rss_mb)
        ));
    }
    out + &crashes
}

/// The fuzz crate's folder.
pub fn fuzz_crate() -> PathBuf {
    root().join("xtask").join("fuzz")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn libfuzzer_output_is_read() {
        let mut s = RunStats::default();
        for line in [
            "INFO: Seed: 1234",
            "#2\tINITED cov: 310 ft: 402 corp: 7/2048b exec/s: 0 rss: 40Mb",
            "#512\tNEW    cov: 330 ft: 450 corp: 8/2100b lim: 4096 exec/s: 0 rss: 41Mb",
            "#65536\tpulse  cov: 611 ft: 1204 corp: 60/9Kb lim: 4096 exec/s: 21845 rss: 52Mb",
            "#1310720\tDONE   cov: 640 ft: 1301 corp: 64/10Kb lim: 4096 exec/s: 21845 rss: 53Mb",
            "stat::number_of_executed_units: 1310720",
            "stat::average_exec_per_sec:     21845",
            "stat::peak_rss_mb:              53",
        ] {
            s.read(line);
        }
        assert_eq!(s.execs, Some(1_310_720));
        assert_eq!(s.per_second, Some(21_845));
        assert_eq!((s.cov, s.ft, s.corpus), (Some(640), Some(1301), Some(64)));
        assert_eq!(s.peak_rss_mb, Some(53));
        assert_eq!((s.crash.as_deref(), s.why.as_deref()), (None, None));
        let t = table(&[("png16", s.clone())], 60);
        assert!(
            t.contains("| png16 | 1310720 | 21845 | 640 | 1301 | 64 | 53 | ok |"),
            "{t}"
        );

        let mut c = RunStats::default();
        for line in [
            "thread '<unnamed>' panicked at xtask/test-support/src/decoders/maps.rs:40:5:",
            "==1234== ERROR: libFuzzer: deadly signal",
            "artifact_prefix='target/fuzz/artifacts/tile/'; Test unit written to \
             target/fuzz/artifacts/tile/crash-0a1b",
        ] {
            c.read(line);
        }
        assert_eq!(
            c.crash.as_deref(),
            Some("target/fuzz/artifacts/tile/crash-0a1b")
        );
        assert!(c.why.as_deref().is_some_and(|w| w.contains("panicked at")));
        let t = table(&[("tile", c)], 60);
        assert!(t.contains("**CRASH**"), "{t}");
        assert!(
            t.contains("replay: cargo +nightly fuzz run --fuzz-dir xtask/fuzz tile target/fuzz/artifacts/tile/crash-0a1b"),
            "{t}"
        );
    }

    /// The targets xtask runs are the fuzz crate's binaries, each a file calling the
    /// test-support function of its name, and every decoder of test-support has one.
    #[test]
    fn libfuzzer_targets_match_the_fuzz_crate_and_the_decoders() {
        let manifest = std::fs::read_to_string(fuzz_crate().join("Cargo.toml")).expect("manifest");
        let bins: Vec<&str> = manifest
            .lines()
            .filter_map(|l| l.strip_prefix("name = \""))
            .filter_map(|l| l.strip_suffix('"'))
            .filter(|n| *n != "terrain-fuzz")
            .collect();
        assert_eq!(
            bins, LIBFUZZER_TARGETS,
            "xtask/fuzz/Cargo.toml's [[bin]] names"
        );
        let decoders = std::fs::read_to_string(root().join("xtask/test-support/src/decoders.rs"))
            .expect("decoders.rs");
        let names: Vec<&str> = decoders
            .lines()
            .filter_map(|l| l.trim().strip_prefix("name: \""))
            .filter_map(|l| l.strip_suffix("\","))
            .collect();
        assert_eq!(names, LIBFUZZER_TARGETS, "test-support's DECODERS");
        for t in LIBFUZZER_TARGETS {
            let path = fuzz_crate().join("fuzz_targets").join(format!("{t}.rs"));
            let body = std::fs::read_to_string(&path).expect("target file");
            assert!(
                body.contains(&format!("terrain_test_support::decoders::{t}(data)")),
                "{} does not call decoders::{t}",
                path.display()
            );
        }
    }
}
