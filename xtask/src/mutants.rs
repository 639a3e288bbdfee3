//! `cargo xtask mutants [--shard K/N] [--crate NAME] | --summary`: runs cargo-mutants over the
//! algorithm files of [`MUTANT_CRATES`] (listed in `.cargo/mutants.toml`), then prints caught /
//! missed / timeout / unviable and the mutation score per crate (docs/testing.md). A shard is a
//! round-robin sample; each run keeps its results in `target/mutants/<crate>-<K>of<N>`, and
//! `--summary` adds up every stored run. Not part of `ci`.

use crate::util::{cargo_exe, root};
use anyhow::{Context, Result, bail};
use std::path::Path;
use std::process::Command;
use std::time::Instant;

/// The crates `cargo xtask mutants` mutates (their algorithm files: `.cargo/mutants.toml`).
pub const MUTANT_CRATES: [&str; 4] = [
    "terrain-core",
    "terrain-physics",
    "terrain-lod",
    "terrain-cache",
];

/// Outcome counts of one crate's mutants.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct MutantCounts {
    caught: u64,
    missed: u64,
    timeout: u64,
    unviable: u64,
}

impl MutantCounts {
    /// The mutation score: caught / (caught + missed + timeout); `None` with nothing tested.
    fn score(&self) -> Option<f64> {
        let tested = self.caught + self.missed + self.timeout;
        (tested > 0).then(|| self.caught as f64 / tested as f64)
    }

    fn add(&mut self, summary: &str) -> bool {
        match summary {
            "CaughtMutant" => self.caught += 1,
            "MissedMutant" => self.missed += 1,
            "Timeout" => self.timeout += 1,
            "Unviable" => self.unviable += 1,
            _ => return false,
        }
        true
    }
}

/// The crate of a mutant from its package name or, failing that, the first component of its
/// file path (`terrain-core/src/...`).
fn mutant_crate(package: Option<&str>, file: &str) -> String {
    package
        .map(str::to_owned)
        .unwrap_or_else(|| file.split(['/', '\\']).next().unwrap_or(file).to_owned())
}

/// One mutant's outcome from cargo-mutants' `outcomes.json`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct MutantRecord {
    /// What identifies the mutant across runs: its file, place and replacement.
    key: String,
    krate: String,
    summary: String,
}

/// The mutants' outcomes in cargo-mutants' `outcomes.json` (the baseline is skipped).
fn mutant_records(json: &str) -> Result<Vec<MutantRecord>> {
    let v: serde_json::Value =
        serde_json::from_str(json).context("outcomes.json is not valid JSON")?;
    let outcomes = v
        .get("outcomes")
        .and_then(|o| o.as_array())
        .context("outcomes.json has no `outcomes` array")?;
    let mut out = Vec::new();
    for o in outcomes {
        let Some(m) = o.get("scenario").and_then(|s| s.get("Mutant")) else {
            continue; // the baseline
        };
        let file = m.get("file").and_then(|f| f.as_str()).unwrap_or("");
        out.push(MutantRecord {
            key: m.to_string(),
            krate: mutant_crate(m.get("package").and_then(|p| p.as_str()), file),
            summary: o
                .get("summary")
                .and_then(|s| s.as_str())
                .unwrap_or("")
                .to_owned(),
        });
    }
    Ok(out)
}

/// Counts per crate of `records`, sorted by crate.
fn count_records<'a>(
    records: impl IntoIterator<Item = &'a MutantRecord>,
) -> Vec<(String, MutantCounts)> {
    let mut out: Vec<(String, MutantCounts)> = Vec::new();
    for r in records {
        let i = match out.iter().position(|(k, _)| *k == r.krate) {
            Some(i) => i,
            None => {
                out.push((r.krate.clone(), MutantCounts::default()));
                out.len() - 1
            }
        };
        if !out[i].1.add(&r.summary) {
            eprintln!(
                "mutants: outcomes.json: unknown mutant outcome {:?} (not counted)",
                r.summary
            );
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// Counts per crate from cargo-mutants' `outcomes.json` (the baseline is skipped).
fn parse_mutants_outcomes(json: &str) -> Result<Vec<(String, MutantCounts)>> {
    Ok(count_records(&mutant_records(json)?))
}

/// The runs' records merged, oldest run first: a mutant tested in several runs (a shard run
/// again after new tests) counts once, with its latest outcome.
fn merge_runs(runs: &[Vec<MutantRecord>]) -> Vec<MutantRecord> {
    let mut merged: Vec<MutantRecord> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for r in runs.iter().flatten() {
        match index.get(&r.key) {
            Some(&i) => merged[i] = r.clone(),
            None => {
                index.insert(r.key.clone(), merged.len());
                merged.push(r.clone());
            }
        }
    }
    merged
}

/// Counts per crate from the `caught.txt`, `missed.txt`, `timeout.txt` and `unviable.txt`
/// lists (one mutant a line, `path:line:col: description`), as `(summary, text)` pairs.
fn parse_mutants_lists(lists: &[(&str, &str)]) -> Vec<(String, MutantCounts)> {
    let records: Vec<MutantRecord> = lists
        .iter()
        .flat_map(|&(summary, text)| {
            text.lines()
                .filter(|l| !l.trim().is_empty())
                .map(move |line| MutantRecord {
                    key: line.to_owned(),
                    krate: mutant_crate(None, line.split(':').next().unwrap_or(line)),
                    summary: summary.to_owned(),
                })
        })
        .collect();
    count_records(&records)
}

/// The table `cargo xtask mutants` prints.
fn mutants_table(rows: &[(String, MutantCounts)]) -> String {
    let mut t = String::from(
        "| crate | caught | missed | timeout | unviable | score |\n|---|---|---|---|---|---|\n",
    );
    let mut total = MutantCounts::default();
    let pct = |c: &MutantCounts| {
        c.score()
            .map_or("-".into(), |s| format!("{:.1} %", 100.0 * s))
    };
    for (krate, c) in rows {
        t.push_str(&format!(
            "| {krate} | {} | {} | {} | {} | {} |\n",
            c.caught,
            c.missed,
            c.timeout,
            c.unviable,
            pct(c)
        ));
        total.caught += c.caught;
        total.missed += c.missed;
        total.timeout += c.timeout;
        total.unviable += c.unviable;
    }
    t.push_str(&format!(
        "| **all** | {} | {} | {} | {} | {} |\n",
        total.caught,
        total.missed,
        total.timeout,
        total.unviable,
        pct(&total)
    ));
    t
}

/// The folder under `target/mutants` that keeps one run's results: the crate (or `all`) and
/// the shard (`3of8`, or `all`), so that runs of other shards or crates do not overwrite it.
fn mutants_run_dir(krate: Option<&str>, shard: Option<&str>) -> String {
    format!(
        "{}-{}",
        krate.unwrap_or("all"),
        shard.map_or("all".into(), |s| s.replace('/', "of"))
    )
}

/// Every run kept under `target/mutants`, oldest first, merged (see [`merge_runs`]).
fn stored_mutant_runs(dir: &Path) -> Result<Vec<MutantRecord>> {
    let mut runs = Vec::new();
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("no mutants runs in {}", dir.display()))?;
    for e in entries.flatten() {
        let path = e.path().join("mutants.out").join("outcomes.json");
        let Ok(meta) = std::fs::metadata(&path) else {
            continue;
        };
        let json = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let records =
            mutant_records(&json).with_context(|| format!("parsing {}", path.display()))?;
        runs.push((meta.modified().ok(), path, records));
    }
    runs.sort_by(|a, b| (a.0, &a.1).cmp(&(b.0, &b.1)));
    for (_, path, records) in &runs {
        eprintln!("mutants: {} mutants in {}", records.len(), path.display());
    }
    let runs: Vec<_> = runs.into_iter().map(|r| r.2).collect();
    Ok(merge_runs(&runs))
}

/// `cargo xtask mutants [--shard K/N] [--crate NAME] | --summary`: see the module docs.
pub fn mutants(args: &[String]) -> Result<()> {
    let mut shard: Option<String> = None;
    let mut krate: Option<String> = None;
    let mut summary = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |flag: &str| {
            it.next()
                .cloned()
                .with_context(|| format!("{flag} needs a value"))
        };
        match a.as_str() {
            "--shard" => {
                let v = value("--shard")?;
                let ok = v.split_once('/').is_some_and(|(k, n)| {
                    matches!((k.parse::<u32>(), n.parse::<u32>()), (Ok(k), Ok(n)) if k < n)
                });
                if !ok {
                    bail!("--shard {v:?}: expected K/N with 0 <= K < N, e.g. 0/8");
                }
                shard = Some(v);
            }
            "--crate" => {
                let v = value("--crate")?;
                if !MUTANT_CRATES.contains(&v.as_str()) {
                    bail!(
                        "--crate {v:?}: expected one of {}",
                        MUTANT_CRATES.join(", ")
                    );
                }
                krate = Some(v);
            }
            "--summary" => summary = true,
            other => bail!(
                "unknown argument {other:?}: cargo xtask mutants [--shard K/N] [--crate NAME] | --summary"
            ),
        }
    }
    let runs_dir = root().join("target").join("mutants");
    if summary {
        if shard.is_some() || krate.is_some() {
            bail!("--summary reads the stored runs; it takes no --shard or --crate");
        }
        let merged = stored_mutant_runs(&runs_dir)?;
        println!("\n{}", mutants_table(&count_records(&merged)));
        return Ok(());
    }
    let cargo = cargo_exe();
    let installed = Command::new(&cargo)
        .args(["mutants", "--version"])
        .current_dir(root())
        .output()
        .is_ok_and(|o| o.status.success());
    if !installed {
        eprintln!("mutants: cargo-mutants is not installed; install it with");
        eprintln!("  cargo install --locked cargo-mutants");
        std::process::exit(1);
    }
    // Each run keeps its results in its own folder under target/mutants (ignored by git), so
    // that `--summary` can add up shards run one at a time; the file list and exclusions come
    // from .cargo/mutants.toml.
    let out_dir = runs_dir.join(mutants_run_dir(krate.as_deref(), shard.as_deref()));
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let out_str = out_dir.to_string_lossy().into_owned();
    // Each mutant builds in a fresh copy of the tree: copying target/ does not help (cargo's
    // fingerprints hold the path, so the copy rebuilds everything anyway) and costs gigabytes.
    let mut cmd_args = vec![
        "mutants",
        "--output",
        out_str.as_str(),
        "--copy-target=false",
    ];
    if let Some(s) = &shard {
        // Round-robin: a shard is a sample spread over every examined file, not one slice of
        // them, so that one shard already estimates the whole crate's score.
        cmd_args.extend(["--shard", s.as_str(), "--sharding", "round-robin"]);
    }
    if let Some(k) = &krate {
        cmd_args.extend(["--package", k.as_str()]);
    }
    eprintln!("mutants: cargo {}", cmd_args.join(" "));
    let started = Instant::now();
    // cargo-mutants exits non-zero when a mutant is missed (2) or times out (3): the table
    // still comes from its output; other failures (1: bad usage, 4: the baseline failed) stop.
    // The fuzz tests run for a wall-clock budget (2 s each by default): a quarter second per
    // mutant keeps their smoke value while the deterministic tests do the pinning. The soak
    // test of terrain-core's granular step runs 300 frames instead of 5000 for the same reason.
    let status = Command::new(&cargo)
        .args(&cmd_args)
        .env("TERRAIN_FUZZ_SECONDS", "0.25")
        .env("TERRAIN_SOAK_FRAMES", "300")
        .current_dir(root())
        .status()
        .with_context(|| format!("could not start cargo {}", cmd_args.join(" ")))?;
    let code = status.code();
    if !matches!(code, Some(0 | 2 | 3)) {
        bail!("`cargo {}` exited with {status}", cmd_args.join(" "));
    }
    let dir = out_dir.join("mutants.out");
    let rows = match std::fs::read_to_string(dir.join("outcomes.json")) {
        Ok(json) => parse_mutants_outcomes(&json)?,
        Err(_) => {
            let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap_or_default();
            let lists = [
                ("CaughtMutant", read("caught.txt")),
                ("MissedMutant", read("missed.txt")),
                ("Timeout", read("timeout.txt")),
                ("Unviable", read("unviable.txt")),
            ];
            let refs: Vec<(&str, &str)> = lists.iter().map(|(s, t)| (*s, t.as_str())).collect();
            parse_mutants_lists(&refs)
        }
    };
    println!("\n{}", mutants_table(&rows));
    eprintln!(
        "mutants: {} in {:.0} s; missed mutants are listed in {}; `cargo xtask mutants --summary` adds up every stored run",
        shard.map_or("all shards".into(), |s| format!("shard {s}")),
        started.elapsed().as_secs_f64(),
        dir.join("missed.txt").display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutant_runs_merge_with_the_latest_outcome_of_each_mutant() {
        let rec = |key: &str, krate: &str, summary: &str| MutantRecord {
            key: key.into(),
            krate: krate.into(),
            summary: summary.into(),
        };
        let first = vec![
            rec("a", "terrain-core", "MissedMutant"),
            rec("b", "terrain-core", "CaughtMutant"),
        ];
        let rerun = vec![
            rec("a", "terrain-core", "CaughtMutant"),
            rec("c", "terrain-lod", "Timeout"),
        ];
        let merged = merge_runs(&[first, rerun]);
        assert_eq!(
            merged,
            vec![
                rec("a", "terrain-core", "CaughtMutant"),
                rec("b", "terrain-core", "CaughtMutant"),
                rec("c", "terrain-lod", "Timeout"),
            ]
        );
        let rows = count_records(&merged);
        assert_eq!(rows[0].0, "terrain-core");
        assert_eq!(rows[0].1.caught, 2);
        assert_eq!(rows[1].0, "terrain-lod");
        assert_eq!(rows[1].1.timeout, 1);
        assert_eq!(
            mutants_run_dir(Some("terrain-lod"), Some("3/24")),
            "terrain-lod-3of24"
        );
        assert_eq!(mutants_run_dir(None, None), "all-all");
    }

    #[test]
    fn mutant_outcomes_parse_and_score() {
        let json = r#"{"outcomes": [
            {"scenario": "Baseline", "summary": "Success"},
            {"scenario": {"Mutant": {"package": "terrain-core", "file": "terrain-core/src/granular/jfa.rs"}}, "summary": "CaughtMutant"},
            {"scenario": {"Mutant": {"package": "terrain-core", "file": "terrain-core/src/granular/jfa.rs"}}, "summary": "CaughtMutant"},
            {"scenario": {"Mutant": {"package": "terrain-core", "file": "terrain-core/src/stamp.rs"}}, "summary": "MissedMutant"},
            {"scenario": {"Mutant": {"file": "terrain-physics/src/ray.rs"}}, "summary": "Timeout"},
            {"scenario": {"Mutant": {"package": "terrain-physics", "file": "terrain-physics/src/ray.rs"}}, "summary": "Unviable"},
            {"scenario": {"Mutant": {"package": "terrain-physics", "file": "terrain-physics/src/ray.rs"}}, "summary": "CaughtMutant"}
        ], "total_mutants": 6}"#;
        let rows = parse_mutants_outcomes(json).expect("parse");
        let core = MutantCounts {
            caught: 2,
            missed: 1,
            timeout: 0,
            unviable: 0,
        };
        let physics = MutantCounts {
            caught: 1,
            missed: 0,
            timeout: 1,
            unviable: 1,
        };
        assert_eq!(
            rows,
            vec![
                ("terrain-core".to_owned(), core),
                ("terrain-physics".to_owned(), physics)
            ]
        );
        assert_eq!(core.score(), Some(2.0 / 3.0));
        // Unviable mutants do not count; a timeout counts as not caught.
        assert_eq!(physics.score(), Some(0.5));
        assert_eq!(MutantCounts::default().score(), None);
        let table = mutants_table(&rows);
        assert!(
            table.contains("| terrain-core | 2 | 1 | 0 | 0 | 66.7 % |"),
            "{table}"
        );
        assert!(
            table.contains("| **all** | 3 | 1 | 1 | 1 | 60.0 % |"),
            "{table}"
        );
        assert!(parse_mutants_outcomes("{}").is_err());
        // An outcome this version does not know is not counted (and not fatal).
        let odd =
            r#"{"outcomes": [{"scenario": {"Mutant": {"file": "a/b.rs"}}, "summary": "Odd"}]}"#;
        assert_eq!(
            parse_mutants_outcomes(odd).expect("parse"),
            vec![("a".to_owned(), MutantCounts::default())]
        );
        // The plain lists give the same counts.
        let lists = [
            (
                "CaughtMutant",
                "terrain-core/src/granular/jfa.rs:222:51: replace + with - in jfa_pass_reference\n\
                 terrain-core/src/granular/jfa.rs:12:5: replace pcg_hash -> u32 with 0\n",
            ),
            (
                "MissedMutant",
                "terrain-core/src/stamp.rs:285:9: replace GaussianStamp::beta -> f32 with 1.0\n",
            ),
            ("Timeout", "terrain-physics/src/ray.rs:1:1: x\n"),
            ("Unviable", "terrain-physics/src/ray.rs:1:1: y\n\n"),
        ];
        let mut from_lists = parse_mutants_lists(&lists);
        from_lists[1].1.caught = 1; // the JSON above has one more caught physics mutant
        assert_eq!(from_lists, rows);
    }

    /// Every line-anchored exclusion of .cargo/mutants.toml still names the line it was
    /// written for (its `# at:` text), so a moved line cannot silently hide another mutant.
    #[test]
    fn mutants_exclusions_point_at_their_lines() {
        let config =
            std::fs::read_to_string(root().join(".cargo/mutants.toml")).expect("mutants.toml");
        let mut checked = 0;
        for line in config.lines() {
            let Some((entry, at)) = line.split_once("# at: ") else {
                continue;
            };
            let re = entry.trim().trim_end_matches(',').trim_matches('\'');
            let (path, rest) = re.split_once(':').expect("path:line: in the regex");
            let path = path.replace("\\.", ".");
            let line_no: usize = rest
                .split(':')
                .next()
                .and_then(|n| n.parse().ok())
                .expect("a line number after the path");
            let text = std::fs::read_to_string(root().join(&path)).expect("excluded file");
            let src = text.lines().nth(line_no - 1).unwrap_or("");
            assert!(
                src.contains(at.trim()),
                "{path}:{line_no} is now {src:?}, not {:?}: update .cargo/mutants.toml",
                at.trim()
            );
            checked += 1;
        }
        assert!(checked >= 5, "only {checked} exclusions checked");
        assert!(config.contains("examine_globs"));
        for krate in MUTANT_CRATES {
            assert!(
                config.contains(&format!("\"{krate}/src/")),
                "{krate} has no examined files"
            );
        }
    }
}
