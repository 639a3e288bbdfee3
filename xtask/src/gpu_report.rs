//! `cargo xtask gpu-report [--minutes N]`: one prepared command for a machine with a GPU. It
//! builds the GPU tests, benches and the demo in release, then, on whatever adapter is present
//! (`TERRAIN_REQUIRE_GPU=1`: no adapter is a failure, not a skip), runs every terrain-gpu test
//! binary under the test watchdog (`TERRAIN_WATCHDOG_SECS`: a binary that stops making
//! progress prints every thread's stack and its last GPU operations, then fails) and under a
//! per-binary deadline, the demo's default scenario in each LOD mode and the flyover, and each
//! GPU bench in criterion's quick mode. Everything is bounded by one budget (8 minutes by
//! default): what does not fit is listed as skipped. It writes one markdown table,
//! `target/gpu-report/gpu-report.md` (logs beside it), and prints it.

use crate::util::{cargo_exe, root, target_dir, write_atomically};
use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The default budget for the whole report.
const DEFAULT_MINUTES: u64 = 8;
/// The watchdog's limit for the test binaries: a GPU test on hardware takes seconds, but a
/// binary's CPU references may run a while between GPU operations.
const WATCHDOG_SECS: &str = "120";
/// The longest one test binary, demo run or bench may take.
const STEP_LIMIT: Duration = Duration::from_secs(150);

/// How a step ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Passed,
    Failed,
    TimedOut,
    Skipped,
}

impl Outcome {
    fn name(self) -> &'static str {
        match self {
            Outcome::Passed => "ok",
            Outcome::Failed => "FAILED",
            Outcome::TimedOut => "TIMED OUT",
            Outcome::Skipped => "skipped (budget)",
        }
    }
}

/// The report under construction and the budget left.
struct Report {
    dir: PathBuf,
    deadline: Instant,
    md: String,
    failures: usize,
}

pub fn gpu_report(args: &[String]) -> Result<()> {
    let minutes = match args {
        [] => DEFAULT_MINUTES,
        [flag, n] if flag == "--minutes" => n
            .parse()
            .ok()
            .filter(|m| (1..=120).contains(m))
            .context("--minutes takes 1 to 120")?,
        _ => bail!("gpu-report: expected no arguments or --minutes N"),
    };
    let dir = target_dir().join("gpu-report");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut report = Report {
        dir,
        deadline: Instant::now() + Duration::from_secs(minutes * 60),
        md: String::new(),
        failures: 0,
    };
    let built = Instant::now();
    for build in [
        &["build", "--release", "--locked", "-p", "terrain-demo"][..],
        &[
            "test",
            "--release",
            "--locked",
            "-p",
            "terrain-gpu",
            "--no-run",
        ],
        &["bench", "--locked", "-p", "terrain-gpu", "--no-run"],
    ] {
        let log = report.dir.join("build.log");
        if report.run("build", cargo_cmd(build), &log)?.0 != Outcome::Passed {
            bail!(
                "gpu-report: `cargo {}` failed (see {})",
                build.join(" "),
                log.display()
            );
        }
    }
    let build_s = built.elapsed().as_secs_f64();
    let _ = writeln!(
        report.md,
        "# GPU report\n\nBuilt in release in {build_s:.0} s; budget {minutes} min.\n"
    );
    report.demo_runs()?;
    report.test_binaries()?;
    report.benches()?;
    let path = report.dir.join("gpu-report.md");
    write_atomically(&path, report.md.as_bytes())?;
    println!("{}", report.md);
    eprintln!("gpu-report: written to {}", path.display());
    if report.failures > 0 {
        bail!(
            "gpu-report: {} step(s) failed or timed out",
            report.failures
        );
    }
    Ok(())
}

/// `cargo` with `args` in the workspace root, with the GPU requirement and the watchdog.
fn cargo_cmd(args: &[&str]) -> Command {
    let mut cmd = Command::new(cargo_exe());
    cmd.args(args);
    cmd
}

impl Report {
    /// Runs `cmd` in the workspace root within the step limit and the budget, its output
    /// appended to `log`; returns how it ended and its seconds.
    fn run(&mut self, what: &str, mut cmd: Command, log: &Path) -> Result<(Outcome, f64)> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        // Building has no step limit of its own: only the budget bounds it.
        let limit = if what == "build" {
            left
        } else {
            left.min(STEP_LIMIT)
        };
        if limit < Duration::from_secs(5) {
            return Ok((Outcome::Skipped, 0.0));
        }
        let out = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .with_context(|| format!("opening {}", log.display()))?;
        cmd.current_dir(root())
            .env("TERRAIN_REQUIRE_GPU", "1")
            .env("TERRAIN_WATCHDOG_SECS", WATCHDOG_SECS)
            .stdin(Stdio::null())
            .stdout(out.try_clone()?)
            .stderr(out);
        #[cfg(unix)]
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        let started = Instant::now();
        let mut child = cmd.spawn().with_context(|| format!("starting {what}"))?;
        let outcome = loop {
            if let Some(status) = child.try_wait()? {
                break if status.success() {
                    Outcome::Passed
                } else {
                    Outcome::Failed
                };
            }
            if started.elapsed() > limit {
                // The whole group: cargo's child (the test binary) included.
                #[cfg(unix)]
                let _ = Command::new("kill")
                    .args(["-KILL", &format!("-{}", child.id())])
                    .status();
                let _ = child.kill();
                let _ = child.wait();
                break Outcome::TimedOut;
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        if matches!(outcome, Outcome::Failed | Outcome::TimedOut) {
            self.failures += 1;
        }
        Ok((outcome, started.elapsed().as_secs_f64()))
    }

    /// Every test binary of terrain-gpu, one at a time, with its result and time.
    fn test_binaries(&mut self) -> Result<()> {
        let names = rs_stems(&root().join("terrain-gpu/tests"))?;
        self.md.push_str(
            "## terrain-gpu test binaries (release, watchdog at 120 s)\n\n| binary | result | s | tests |\n|---|---|---|---|\n",
        );
        for name in names {
            let log = self.dir.join(format!("test-{name}.log"));
            let cmd = cargo_cmd(&[
                "test",
                "--release",
                "--locked",
                "-p",
                "terrain-gpu",
                "--test",
                &name,
            ]);
            let (outcome, secs) = self.run("test", cmd, &log)?;
            let passed = std::fs::read_to_string(&log)
                .ok()
                .and_then(|t| {
                    t.lines()
                        .rev()
                        .find_map(|l| l.strip_prefix("test result: ").map(str::to_owned))
                })
                .unwrap_or_default();
            let _ = writeln!(
                self.md,
                "| `{name}` | {} | {secs:.1} | {passed} |",
                outcome.name()
            );
        }
        self.md.push('\n');
        Ok(())
    }

    /// The demo's default scenario in each LOD mode, and the flyover: per-step p50 / p95.
    fn demo_runs(&mut self) -> Result<()> {
        let exe = target_dir()
            .join("release")
            .join(format!("terrain-demo{}", std::env::consts::EXE_SUFFIX));
        let runs: [(&str, &[&str]); 4] = [
            ("default, clipmap", &[]),
            ("default, cdlod", &["--lod", "cdlod"]),
            ("default, tessellated", &["--lod", "tessellated"]),
            ("flyover", &["--scenario", "flyover", "--size", "4096"]),
        ];
        self.md
            .push_str("## Demo runs (1280x720, 120 frames, 10 warm-up)\n\nTarget on H200-class hardware (issue 36): the default frame's GPU time at most 1 ms in every LOD mode (Flower 2010, table 4.4: 298 fps on a GTX 295).\n\n| run | result | s | adapter | step p50 / p95 (ms) |\n|---|---|---|---|---|\n");
        for (i, (name, extra)) in runs.iter().enumerate() {
            let out = self.dir.join(format!("demo-{i}"));
            let mut cmd = Command::new(&exe);
            cmd.args([
                "--resolution",
                "1280x720",
                "--frames",
                "120",
                "--warmup",
                "10",
            ])
            .args(["--quiet", "--out"])
            .arg(&out)
            .args(*extra);
            if name.starts_with("flyover") {
                cmd.arg("--world").arg(self.dir.join("world"));
            }
            let log = self.dir.join(format!("demo-{i}.log"));
            let (outcome, secs) = self.run("demo", cmd, &log)?;
            let (adapter, steps) = demo_steps(&out.join("report.json"));
            let _ = writeln!(
                self.md,
                "| {name} | {} | {secs:.1} | {adapter} | {steps} |",
                outcome.name()
            );
        }
        self.md.push('\n');
        Ok(())
    }

    /// Each GPU bench in criterion's quick mode; every benchmark's median.
    fn benches(&mut self) -> Result<()> {
        let home = self.dir.join("criterion");
        let names = rs_stems(&root().join("terrain-gpu/benches"))?;
        self.md.push_str(
            "## GPU benches (criterion --quick)\n\n| bench | result | s |\n|---|---|---|\n",
        );
        for name in &names {
            let log = self.dir.join(format!("bench-{name}.log"));
            let mut cmd = cargo_cmd(&[
                "bench",
                "--locked",
                "-p",
                "terrain-gpu",
                "--bench",
                name,
                "--",
                "--quick",
            ]);
            cmd.env("CRITERION_HOME", &home);
            let (outcome, secs) = self.run("bench", cmd, &log)?;
            let _ = writeln!(self.md, "| `{name}` | {} | {secs:.1} |", outcome.name());
        }
        self.md
            .push_str("\n| benchmark | median | thesis figure or issue target |\n|---|---|---|\n");
        for (id, ns) in medians(&home) {
            let beside = thesis_figure(&id).unwrap_or("-");
            let _ = writeln!(self.md, "| `{id}` | {} | {beside} |", human_ns(ns));
        }
        self.md.push('\n');
        Ok(())
    }
}

/// The thesis figure (or the hardware target of issue 36) a GPU bench compares with, where one
/// measures the same thing: Flower 2010, tables 4.3 (deform + normal generation, GTX 295) and
/// 4.4 (clipmap frame rate), sec. 4.2's detail figures; Persson 2019, tables 5.4-5.5.
fn thesis_figure(id: &str) -> Option<&'static str> {
    Some(match id {
        "gpu_stamp_normals/stamp/500" => "0.971 ms deform, 50 m (Flower 2010, table 4.3)",
        "gpu_stamp_normals/stamp/1000" => "1.192 ms deform, 100 m (Flower 2010, table 4.3)",
        "gpu_stamp_normals/stamp/2000" => "1.875 ms deform, 200 m (Flower 2010, table 4.3)",
        "gpu_stamp_normals/stamp_and_normals/500" => "0.971 + 0.828 ms (Flower 2010, table 4.3)",
        "gpu_stamp_normals/stamp_and_normals/1000" => "1.192 + 0.953 ms (Flower 2010, table 4.3)",
        "gpu_stamp_normals/stamp_and_normals/2000" => {
            "1.875 + 1.329 ms (Flower 2010, table 4.3); target on H200 class: 0.05 ms"
        }
        "gpu_clipmap_render/1024x768_levels/11" => "3.36 ms = 298 fps (Flower 2010, table 4.4)",
        "gpu_detail_render/1024x768/parallax" => "2.33 ms (Flower 2010, parallax)",
        "gpu_detail_render/1024x768/refine" => "9.82 ms (Flower 2010, tessellated refinement)",
        "gpu_granular/step/4096_242064" => {
            "16.86 ms, penetration to slopes (Persson 2019, table 5.5's rows summed); target on H200 class: 0.3 ms"
        }
        "gpu_granular/displace_closest_seed/4096_242064" => "1.66 ms (Persson 2019, table 5.5)",
        _ => return None,
    })
}

/// The names of the `.rs` files directly in `dir` (test binaries, benches), sorted.
fn rs_stems(dir: &Path) -> Result<Vec<String>> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("listing {}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.strip_suffix(".rs").map(str::to_owned)
        })
        .collect();
    names.sort();
    Ok(names)
}

/// The adapter and `step p50 / p95` of a demo run's report.json (dashes when it has none).
fn demo_steps(path: &Path) -> (String, String) {
    let Some(report) = std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
    else {
        return ("-".into(), "-".into());
    };
    let adapter = format!(
        "{} ({})",
        report["adapter"].as_str().unwrap_or("?"),
        report["backend"].as_str().unwrap_or("?")
    );
    let steps = report["steps_ms"]
        .as_object()
        .map(|steps| {
            steps
                .iter()
                .map(|(k, v)| {
                    format!(
                        "{k} {:.2} / {:.2}",
                        v["p50"].as_f64().unwrap_or(f64::NAN),
                        v["p95"].as_f64().unwrap_or(f64::NAN)
                    )
                })
                .collect::<Vec<_>>()
                .join("; ")
        })
        .unwrap_or_else(|| "-".into());
    (adapter, steps)
}

/// Every benchmark under a criterion folder with its median in ns, sorted by id.
fn medians(home: &Path) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    let mut stack = vec![home.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let path = e.path();
            if path.is_dir() && e.file_name() != "report" {
                stack.push(path);
            } else if e.file_name() == "estimates.json"
                && dir.file_name().is_some_and(|n| n == "new")
            {
                let id = dir
                    .parent()
                    .and_then(|d| d.strip_prefix(home).ok())
                    .map(|d| d.to_string_lossy().replace('\\', "/"))
                    .unwrap_or_default();
                let median = std::fs::read_to_string(&path)
                    .ok()
                    .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                    .and_then(|v| v["median"]["point_estimate"].as_f64());
                if let Some(ns) = median {
                    out.push((id, ns));
                }
            }
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// `ns` in the unit that reads best.
fn human_ns(ns: f64) -> String {
    if ns >= 1e6 {
        format!("{:.3} ms", ns / 1e6)
    } else {
        format!("{:.1} us", ns / 1e3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demo_steps_and_medians_are_read_from_what_the_tools_write() {
        let dir = target_dir().join("gpu-report-test");
        let _ = std::fs::remove_dir_all(&dir);
        let est = dir.join("criterion/gpu_stamp/stamp/512/new");
        std::fs::create_dir_all(&est).unwrap();
        std::fs::write(
            est.join("estimates.json"),
            r#"{"median":{"point_estimate":1500.0}}"#,
        )
        .unwrap();
        std::fs::create_dir_all(dir.join("criterion/gpu_stamp/stamp/512/base")).unwrap();
        assert_eq!(
            medians(&dir.join("criterion")),
            vec![("gpu_stamp/stamp/512".to_owned(), 1500.0)]
        );
        assert_eq!(human_ns(1500.0), "1.5 us");
        assert!(thesis_figure("gpu_granular/step/4096_242064").is_some_and(|t| t.contains("5.5")));
        assert_eq!(thesis_figure("gpu_stamp/stamp/512"), None);
        assert_eq!(human_ns(2.5e6), "2.500 ms");
        let report = dir.join("report.json");
        std::fs::write(
            &report,
            r#"{"adapter":"NVIDIA H200","backend":"vulkan","steps_ms":{"render":{"p50":1.21,"p95":1.5}}}"#,
        )
        .unwrap();
        assert_eq!(
            demo_steps(&report),
            (
                "NVIDIA H200 (vulkan)".to_owned(),
                "render 1.21 / 1.50".to_owned()
            )
        );
        assert_eq!(demo_steps(&dir.join("missing.json")).0, "-");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
