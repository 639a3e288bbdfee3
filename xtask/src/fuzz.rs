//! `cargo xtask fuzz [--engine harness|libfuzzer] [--seconds N] [--target NAME] [--seed S]`.
//!
//! The default engine, `harness`, runs the time-bounded fuzz targets (the `tests/fuzz.rs`
//! files of the crates in [`FUZZ_TARGETS`]) for N seconds each, in release mode, and prints a
//! table of every input class: cases run and result. CI has no fuzz step of its own: its
//! `test` step runs every target already, for the default 2 seconds each
//! (`TERRAIN_FUZZ_SECONDS` unset), which is the short run of each that CI makes.
//!
//! `--engine libfuzzer` runs the decoders' coverage-guided targets instead ([`crate::libfuzzer`]:
//! nightly, cargo-fuzz), 60 s each unless `--seconds` says otherwise; never part of CI.

use crate::libfuzzer::{self, LIBFUZZER_TARGETS};
use crate::util::{cargo_exe, root};
use anyhow::{Context, Result, bail};
use std::process::Command;
use std::time::Instant;

/// The fuzz targets: crate, target name (as the target prints it), test function in the crate's
/// `tests/fuzz.rs`.
pub const FUZZ_TARGETS: [(&str, &str, &str); 10] = [
    ("terrain-core", "png16", "fuzz_png16"),
    ("terrain-core", "png8", "fuzz_png8"),
    ("terrain-core", "raw16", "fuzz_raw16"),
    ("terrain-core", "geotiff", "fuzz_geotiff"),
    ("terrain-cache", "tile", "fuzz_tile"),
    ("terrain-cache", "manifest", "fuzz_manifest"),
    ("terrain-cache", "bounds", "fuzz_bounds"),
    ("terrain-physics", "physics", "fuzz_physics"),
    ("terrain-lod", "lod", "fuzz_lod"),
    // The decoders' libFuzzer target bodies, briefly (terrain_test_support::decoders).
    ("terrain-test-support", "decoders", "fuzz_decoders"),
];

/// What `fuzz` learned of one input class from the target's output.
#[derive(Debug, Clone, PartialEq)]
struct FuzzRow {
    target: String,
    class: String,
    /// Cases run (`None` for a disabled class).
    cases: Option<u64>,
    /// `ok`, `FAILED (...)`, or `disabled (...)`.
    result: String,
    notes: u64,
}

/// One line of a target's output, as the shared fuzz harness prints it.
#[derive(Debug, Clone, PartialEq)]
enum FuzzLine {
    Class(FuzzRow),
    Notes {
        target: String,
        class: String,
        notes: u64,
    },
    Total {
        target: String,
        cases: u64,
        seed: String,
    },
}

/// Parses a line of a fuzz target's output; `None` for any other line. With `--nocapture` the
/// test harness prints `test <name> ... ` without a newline before the test's first line.
fn parse_fuzz_line(line: &str) -> Option<FuzzLine> {
    let line = match line.strip_prefix("test ") {
        Some(rest) => rest.split_once(" ... ").map_or(line, |(_, r)| r),
        None => line,
    };
    let rest = line.strip_prefix("fuzz ")?;
    let (target, rest) = rest.split_once(": ")?;
    let target = target.to_owned();
    if let Some(rest) = rest.strip_prefix("class ") {
        let (class, tail) = rest.split_once(": ")?;
        let class = class.to_owned();
        if let Some(why) = tail.strip_prefix("disabled") {
            return Some(FuzzLine::Class(FuzzRow {
                target,
                class,
                cases: None,
                result: format!("disabled{why}"),
                notes: 0,
            }));
        }
        if let Some((n, _)) = tail.split_once(" notes, first: ") {
            return Some(FuzzLine::Notes {
                target,
                class,
                notes: n.parse().ok()?,
            });
        }
        let (n, after) = tail.split_once(" cases in ")?;
        let (_, result) = after.split_once(": ")?;
        return Some(FuzzLine::Class(FuzzRow {
            target,
            class,
            cases: Some(n.parse().ok()?),
            result: result.to_owned(),
            notes: 0,
        }));
    }
    let (n, after) = rest.split_once(" cases in ")?;
    let seed = after
        .split_once("(seed ")
        .map(|(_, s)| s.trim_end_matches(')').to_owned())
        .unwrap_or_default();
    Some(FuzzLine::Total {
        target,
        cases: n.parse().ok()?,
        seed,
    })
}

/// `cargo xtask fuzz [--engine E] [--seconds N] [--target NAME] [--seed S]`: see the module
/// docs.
pub fn fuzz(args: &[String]) -> Result<()> {
    let mut seconds: Option<f64> = None;
    let mut only: Option<String> = None;
    let mut seed: Option<String> = None;
    let mut libfuzzer = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |flag: &str| {
            it.next()
                .cloned()
                .with_context(|| format!("{flag} needs a value"))
        };
        match a.as_str() {
            "--seconds" => {
                let v = value("--seconds")?;
                let s: f64 = v
                    .parse()
                    .with_context(|| format!("--seconds {v:?} is not a number"))?;
                if !(s.is_finite() && s > 0.0) {
                    bail!("--seconds must be a positive number of seconds, got {v}");
                }
                seconds = Some(s);
            }
            "--target" => only = Some(value("--target")?),
            "--seed" => seed = Some(value("--seed")?),
            "--engine" => match value("--engine")?.as_str() {
                "harness" => libfuzzer = false,
                "libfuzzer" => libfuzzer = true,
                other => bail!("--engine {other:?}: harness (the default) or libfuzzer"),
            },
            other => bail!(
                "unknown argument {other:?}: cargo xtask fuzz [--engine harness|libfuzzer] \
                 --seconds N [--target NAME] [--seed S]"
            ),
        }
    }
    if libfuzzer {
        let opts = libfuzzer::Options {
            // Whole seconds: libFuzzer's -max_total_time takes no fraction.
            seconds: seconds.map_or(60, |s| s.ceil() as u64),
            target: only,
            seed,
        };
        return libfuzzer::run(&opts);
    }
    let seconds = seconds.context(
        "cargo xtask fuzz needs --seconds N (seconds per target; the libFuzzer engine's \
         targets are --engine libfuzzer)",
    )?;
    let targets: Vec<(&str, &str, &str)> = FUZZ_TARGETS
        .into_iter()
        .filter(|t| only.as_deref().is_none_or(|o| o == t.1 || o == t.2))
        .collect();
    if targets.is_empty() {
        bail!(
            "no fuzz target named {:?}; targets: {} (libFuzzer's, with --engine libfuzzer: {})",
            only.unwrap_or_default(),
            FUZZ_TARGETS.map(|t| t.1).join(", "),
            LIBFUZZER_TARGETS.join(", ")
        );
    }
    let started = Instant::now();
    let mut rows: Vec<FuzzRow> = Vec::new();
    let mut totals: Vec<(String, u64, String)> = Vec::new();
    let mut failed_runs = Vec::new();
    let mut crates: Vec<&str> = targets.iter().map(|t| t.0).collect();
    crates.dedup();
    let seconds_s = seconds.to_string();
    for krate in crates {
        let tests: Vec<&str> = targets
            .iter()
            .filter(|t| t.0 == krate)
            .map(|t| t.2)
            .collect();
        // One test at a time, so each target has the machine to itself for its N seconds.
        let mut args = vec![
            "test",
            "--release",
            "--locked",
            "-p",
            krate,
            "--test",
            "fuzz",
            "--",
            "--nocapture",
            "--test-threads=1",
            "--exact",
        ];
        args.extend(&tests);
        let mut cmd = Command::new(cargo_exe());
        cmd.args(&args)
            .current_dir(root())
            .env("TERRAIN_FUZZ_SECONDS", &seconds_s)
            .stdout(std::process::Stdio::piped());
        if let Some(s) = &seed {
            cmd.env("TERRAIN_FUZZ_SEED", s);
        }
        eprintln!("fuzz: cargo {}", args.join(" "));
        let mut child = cmd
            .spawn()
            .with_context(|| format!("could not start cargo {}", args.join(" ")))?;
        let stdout = child.stdout.take().context("no stdout from cargo test")?;
        // Echo the targets' output as it comes, and keep the lines the table is made of.
        for line in std::io::BufRead::lines(std::io::BufReader::new(stdout)) {
            let line = line.context("reading the fuzz targets' output")?;
            println!("{line}");
            match parse_fuzz_line(&line) {
                Some(FuzzLine::Class(row)) => rows.push(row),
                Some(FuzzLine::Notes {
                    target,
                    class,
                    notes,
                }) => {
                    if let Some(r) = rows
                        .iter_mut()
                        .rev()
                        .find(|r| r.target == target && r.class == class)
                    {
                        r.notes = notes;
                    }
                }
                Some(FuzzLine::Total {
                    target,
                    cases,
                    seed,
                }) => totals.push((target, cases, seed)),
                None => {}
            }
        }
        let status = child.wait().context("waiting for cargo test")?;
        if !status.success() {
            failed_runs.push(format!("{krate} ({status})"));
        }
    }

    let mut table = format!(
        "\n| target | input class | cases ({seconds} s per target) | result |\n|---|---|---|---|\n"
    );
    let mut failed = false;
    for (_, target, _) in &targets {
        let total = totals.iter().find(|t| t.0 == *target);
        for r in rows.iter().filter(|r| r.target == *target) {
            let notes = if r.notes > 0 {
                format!(" ({} notes)", r.notes)
            } else {
                String::new()
            };
            failed |= r.result.starts_with("FAILED");
            table.push_str(&format!(
                "| {target} | {} | {} | {}{notes} |\n",
                r.class,
                r.cases.map_or("-".into(), |n| n.to_string()),
                r.result
            ));
        }
        match total {
            Some((_, cases, seed)) => table.push_str(&format!(
                "| **{target}** | all | **{cases}** | seed {seed} |\n"
            )),
            None => {
                failed = true;
                table.push_str(&format!(
                    "| **{target}** | all | - | no report: the test process crashed or was not run |\n"
                ));
            }
        }
    }
    println!("{table}");
    eprintln!(
        "fuzz: {} target(s) in {:.0} s",
        targets.len(),
        started.elapsed().as_secs_f64()
    );
    if failed || !failed_runs.is_empty() {
        bail!(
            "fuzz: a target failed (see the table; replay a case with the TERRAIN_FUZZ_REPLAY its \
             line prints){}",
            if failed_runs.is_empty() {
                String::new()
            } else {
                format!("; cargo test failed for {}", failed_runs.join(", "))
            }
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A crate's folder: the crates are top-level folders, but for test-support, beside xtask.
    fn crate_dir(krate: &str) -> std::path::PathBuf {
        match krate {
            "terrain-test-support" => root().join("xtask").join("test-support"),
            _ => root().join(krate),
        }
    }

    #[test]
    fn fuzz_lines_parse() {
        let ok = "fuzz png16: class truncated: 396397 cases in 5.5 s: ok";
        assert_eq!(
            parse_fuzz_line(ok),
            Some(FuzzLine::Class(FuzzRow {
                target: "png16".into(),
                class: "truncated".into(),
                cases: Some(396_397),
                result: "ok".into(),
                notes: 0,
            }))
        );
        let skipped = "fuzz physics: class ray_near_map: 1015270 cases in 2.1 s (6840 drawn \
                       outside the class skipped): FAILED (panic: x: y) at case 3; replay with \
                       TERRAIN_FUZZ_REPLAY=ray_near_map:0x1";
        match parse_fuzz_line(skipped) {
            Some(FuzzLine::Class(r)) => {
                assert_eq!(r.cases, Some(1_015_270));
                assert!(r.result.starts_with("FAILED (panic: x: y)"), "{}", r.result);
            }
            other => panic!("{other:?}"),
        }
        let disabled = "fuzz physics: class ray_long_walk: disabled (defect 1: hangs)";
        match parse_fuzz_line(disabled) {
            Some(FuzzLine::Class(r)) => {
                assert_eq!(r.cases, None);
                assert_eq!(r.result, "disabled (defect 1: hangs)");
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            parse_fuzz_line("fuzz physics: class a_b: 12 notes, first: x: y"),
            Some(FuzzLine::Notes {
                target: "physics".into(),
                class: "a_b".into(),
                notes: 12
            })
        );
        assert_eq!(
            parse_fuzz_line("fuzz lod: 18549739 cases in 12.0 s (seed 0x26412cac14b888c7)"),
            Some(FuzzLine::Total {
                target: "lod".into(),
                cases: 18_549_739,
                seed: "0x26412cac14b888c7".into()
            })
        );
        assert_eq!(parse_fuzz_line("test fuzz_lod ... ok"), None);
        assert!(matches!(
            parse_fuzz_line(
                "test fuzz_lod ... fuzz lod: class layout_new_any: 3 cases in 0.2 s: ok"
            ),
            Some(FuzzLine::Class(FuzzRow { cases: Some(3), .. }))
        ));
        assert_eq!(parse_fuzz_line("fuzz: cargo test"), None);
    }

    /// Every target xtask runs is a test of its crate's `tests/fuzz.rs`, every such test is
    /// listed, and no other crate has fuzz targets xtask does not know of.
    #[test]
    fn fuzz_targets_match_the_crates_fuzz_tests() {
        let mut crates: Vec<&str> = FUZZ_TARGETS.iter().map(|t| t.0).collect();
        crates.dedup();
        for krate in &crates {
            let path = crate_dir(krate).join("tests/fuzz.rs");
            let targets = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let listed: Vec<&str> = FUZZ_TARGETS
                .iter()
                .filter(|t| t.0 == *krate)
                .map(|t| t.2)
                .collect();
            for test in &listed {
                assert!(
                    targets.contains(&format!("fn {test}()")),
                    "{krate}/tests/fuzz.rs has no fn {test}()"
                );
            }
            for line in targets.lines() {
                if let Some(name) = line.trim().strip_prefix("fn fuzz_")
                    && let Some((name, _)) = name.split_once("()")
                {
                    let test = format!("fuzz_{name}");
                    assert!(
                        listed.contains(&test.as_str()),
                        "{krate}/tests/fuzz.rs: {test} is not in xtask's FUZZ_TARGETS"
                    );
                }
            }
        }
        for entry in std::fs::read_dir(root()).expect("workspace root") {
            let dir = entry.expect("entry").path();
            let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if dir.join("tests/fuzz.rs").is_file() {
                assert!(
                    crates.contains(&name),
                    "{name}/tests/fuzz.rs exists but no target of it is in FUZZ_TARGETS"
                );
            }
        }
    }
}
