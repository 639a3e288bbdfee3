//! The artefacts a user reads, checked as a user gets them: report.json validates against
//! `docs/report.schema.json` for every scenario (frames.jsonl's lines too), summary.png has its
//! chart, stderr carries no driver noise, `-q` is quiet, an earlier run's frames do not linger,
//! and `--config` / `print-config` work.

mod common;

use common::{demo, fresh_dir, report, run_within};
use std::path::Path;
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(240);

/// The schema, compiled.
fn schema() -> jsonschema::Validator {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/report.schema.json");
    let text = std::fs::read_to_string(&path).expect("docs/report.schema.json");
    let schema: serde_json::Value = serde_json::from_str(&text).expect("the schema is JSON");
    jsonschema::draft202012::new(&schema).expect("the schema compiles")
}

/// Every violation of `value` against `validator`, one per line.
fn violations(validator: &jsonschema::Validator, value: &serde_json::Value) -> String {
    validator
        .iter_errors(value)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Runs the demo with `args` into a fresh folder (no XDG_RUNTIME_DIR, as on a server) and
/// returns the folder and stderr, asserting success.
fn run(name: &str, args: &[&str]) -> (std::path::PathBuf, String) {
    let out = fresh_dir(name);
    let mut cmd = demo();
    cmd.args(args)
        .arg("--out")
        .arg(&out)
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .env_remove("RUST_LOG");
    let done = run_within(cmd, &out, LIMIT);
    assert!(done.status.success(), "{args:?}: {}", done.stderr);
    (out, done.stderr)
}

#[test]
fn reports_of_every_scenario_validate_against_the_schema() {
    let validator = schema();
    // The last run reads the terrain.png an earlier one wrote, as a DEM.
    let dem = std::env::temp_dir().join(format!(
        "terrain_demo_schema_dem_{}.png",
        std::process::id()
    ));
    let dem_s = dem.to_string_lossy().into_owned();
    // Footprints 0.9 m deep: more than a detail tile's range, so they spill into the coarse-map.
    let deep = std::env::temp_dir().join(format!(
        "terrain_demo_schema_deep_{}.toml",
        std::process::id()
    ));
    std::fs::write(&deep, "[stamps]\nfoot_depth_m = 0.9\n").unwrap();
    let deep_s = deep.to_string_lossy().into_owned();
    let runs: [(&str, &[&str]); 11] = [
        (
            "schema_default",
            &["--size", "96", "--frames", "5", "--resolution", "160x96"],
        ),
        (
            "schema_detail",
            &[
                "--size",
                "96",
                "--frames",
                "4",
                "--resolution",
                "160x96",
                "--detail",
                "refine",
            ],
        ),
        (
            "schema_detail_deep",
            &[
                "--size",
                "96",
                "--frames",
                "2",
                "--resolution",
                "160x96",
                "--detail",
                "refine",
                "--config",
                &deep_s,
            ],
        ),
        (
            "schema_detail_cpu",
            &[
                "--size", "96", "--frames", "3", "--no-gpu", "--detail", "parallax",
            ],
        ),
        (
            "schema_cdlod",
            &[
                "--size",
                "128",
                "--frames",
                "4",
                "--resolution",
                "160x96",
                "--lod",
                "cdlod",
            ],
        ),
        (
            "schema_cdlod_detail",
            &[
                "--size",
                "128",
                "--frames",
                "3",
                "--resolution",
                "160x96",
                "--lod",
                "cdlod",
                "--detail",
                "parallax",
            ],
        ),
        (
            "schema_tessellated_detail",
            &[
                "--size",
                "128",
                "--frames",
                "3",
                "--resolution",
                "160x96",
                "--lod",
                "tessellated",
                "--detail",
                "parallax",
            ],
        ),
        (
            "schema_tessellated",
            &[
                "--size",
                "128",
                "--frames",
                "3",
                "--resolution",
                "160x96",
                "--lod",
                "tessellated",
            ],
        ),
        (
            "schema_cpu",
            &["--size", "96", "--frames", "4", "--no-gpu", "--warmup", "1"],
        ),
        (
            "schema_snow",
            &[
                "--scenario",
                "snow",
                "--size",
                "64",
                "--frames",
                "3",
                "--no-gpu",
            ],
        ),
        (
            "schema_heightmap",
            &[
                "--heightmap",
                &dem_s,
                "--frames",
                "2",
                "--no-gpu",
                "--height-range",
                "0:50",
            ],
        ),
    ];
    for (name, args) in runs {
        let (out, _) = run(name, args);
        if name == "schema_cpu" {
            std::fs::copy(out.join("terrain.png"), &dem).unwrap();
        }
        let r = report(&out);
        if name.starts_with("schema_cdlod") || name.starts_with("schema_tessellated") {
            // Every frame says how it was drawn; the popping metric needs a frame before it.
            let mode = name
                .trim_start_matches("schema_")
                .trim_end_matches("_detail");
            for (i, f) in r["frames"].as_array().unwrap().iter().enumerate() {
                assert_eq!(f["lod"], mode, "frame {i}");
                if name.ends_with("_detail") {
                    // The footprints go into the detail tiles, drawn by this LOD mode.
                    assert!(f["detail_tiles_resident"].as_u64() >= Some(1), "frame {i}");
                    assert!(f["detail_dirty_texels"].as_u64() > Some(0), "frame {i}");
                }
                assert!(f["triangles"].as_u64().unwrap() > 0);
                assert!(f["vertices"].as_u64().unwrap() > 0);
                assert!(f["max_screen_error_px"].as_f64().is_some());
                assert_eq!(f["max_vertex_jump_px"].is_null(), i == 0, "frame {i}");
            }
        } else if name == "schema_default" {
            assert_eq!(r["frames"][0]["lod"], "clipmap");
            assert!(r["frames"][0]["detail_tiles_resident"].is_null());
        } else if name == "schema_detail_deep" {
            // The first frame has footprints only: its coarse dirty texels are their spill.
            assert!(r["frames"][0]["dirty_texels"].as_u64().unwrap() > 0);
        } else if name.starts_with("schema_detail") {
            // Footprints every frame, into the detail tiles: never in the coarse-map's dirty
            // texels on a frame without craters or shockwave (frame 0).
            for (i, f) in r["frames"].as_array().unwrap().iter().enumerate() {
                assert!(
                    f["detail_tiles_resident"].as_u64().unwrap() >= 1,
                    "frame {i}"
                );
                assert!(f["detail_dirty_texels"].as_u64().unwrap() > 0, "frame {i}");
                if r["backend"] != "none" && !args.contains(&"--no-gpu") {
                    assert!(f["timings_ms"]["detail"].as_f64().is_some(), "frame {i}");
                }
            }
            // On the CPU the spill knows it moved nothing; the GPU reports the rects its spill
            // may have changed (it does not count texels), so only the CPU run is exact here.
            if args.contains(&"--no-gpu") {
                assert_eq!(r["frames"][0]["dirty_texels"], 0);
            }
        }
        let bad = violations(&validator, &r);
        assert!(
            bad.is_empty(),
            "{name}: report.json breaks the schema:\n{bad}"
        );
        // frames.jsonl: each line is one frame of the report.
        let lines = std::fs::read_to_string(out.join("frames.jsonl")).unwrap();
        let frames: Vec<serde_json::Value> = lines
            .lines()
            .map(|l| serde_json::from_str(l).expect("a frames.jsonl line is JSON"))
            .collect();
        assert_eq!(&serde_json::Value::Array(frames), &r["frames"], "{name}");
        // The statistics leave the warm-up out and cover every step timed after it.
        let warmup = r["warmup_frames"].as_u64().unwrap() as usize;
        let frames = r["frames"].as_array().unwrap();
        assert!(
            warmup < frames.len(),
            "{name}: at least one frame is measured"
        );
        for (step, stats) in r["steps_ms"].as_object().unwrap() {
            let timed: Vec<f64> = frames[warmup..]
                .iter()
                .filter_map(|f| f["timings_ms"][step].as_f64())
                .collect();
            assert_eq!(
                stats["frames"].as_u64(),
                Some(timed.len() as u64),
                "{name} {step}"
            );
            let max = timed.iter().copied().fold(0.0, f64::max);
            assert_eq!(stats["max"].as_f64(), Some(max), "{name} {step}");
        }
        // Linux has a thread CPU clock: every frame has the frame thread's own CPU time, and
        // the statistics cover the frames after warm-up.
        if cfg!(target_os = "linux") {
            let cpu: Vec<f64> = frames
                .iter()
                .map(|f| {
                    f["frame_thread_cpu_ms"]
                        .as_f64()
                        .expect("frame_thread_cpu_ms")
                })
                .collect();
            assert!(
                cpu.iter().all(|c| c.is_finite() && *c >= 0.0),
                "{name}: {cpu:?}"
            );
            let stats = &r["frame_thread_cpu_ms"];
            assert_eq!(
                stats["frames"].as_u64(),
                Some((frames.len() - warmup) as u64)
            );
            let max = cpu[warmup..].iter().copied().fold(0.0, f64::max);
            assert_eq!(stats["max"].as_f64(), Some(max), "{name}");
        }
        // Where each step ran is in its key.
        let keys: Vec<&str> = frames[0]["timings_ms"]
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        if args.contains(&"--no-gpu") {
            assert!(
                !keys.iter().any(|k| k.ends_with("_gpu")),
                "{name}: {keys:?}"
            );
            if args.contains(&"snow") {
                assert!(keys.contains(&"granular_cpu"), "{name}: {keys:?}");
            } else {
                assert!(keys.contains(&"stamp_cpu"), "{name}: {keys:?}");
                assert!(keys.contains(&"normals_cpu"), "{name}: {keys:?}");
            }
        } else if r["backend"] != "none" {
            assert!(keys.contains(&"stamp_gpu"), "{name}: {keys:?}");
        }
        // Every flag is recorded.
        assert_eq!(r["config"]["flags"]["out"], out.to_string_lossy().as_ref());
        assert_eq!(r["schema_version"], 4);
        if name == "schema_heightmap" {
            assert_eq!(r["heightmap"]["format"], "PNG");
        }
    }
}

/// A change to a valid report that must make it invalid.
type Mutation = fn(&mut serde_json::Value);

#[test]
fn the_schema_rejects_what_it_should() {
    // A schema that accepted anything would pass the test above.
    let validator = schema();
    let (out, _) = run(
        "schema_reject",
        &["--size", "64", "--frames", "2", "--no-gpu"],
    );
    let good = report(&out);
    assert!(violations(&validator, &good).is_empty());
    let mutations: [(&str, Mutation); 5] = [
        ("an unknown top-level field", |r| {
            r["surprise"] = 1.into();
        }),
        ("a missing schema_version", |r| {
            r.as_object_mut().unwrap().remove("schema_version");
        }),
        ("an unknown step key", |r| {
            r["frames"][0]["timings_ms"]["stamp"] = 1.0.into();
        }),
        ("a negative timing", |r| {
            r["steps_ms"]["write"]["p95"] = (-1.0).into();
        }),
        ("an unknown flag", |r| {
            r["config"]["flags"]["turbo"] = true.into();
        }),
    ];
    for (what, mutate) in mutations {
        let mut r = good.clone();
        mutate(&mut r);
        assert!(
            !violations(&validator, &r).is_empty(),
            "the schema accepts {what}"
        );
    }
}

#[test]
fn summary_png_has_thumbnails_and_a_chart() {
    let (out, _) = run("summary", &["--size", "64", "--frames", "6", "--no-gpu"]);
    let file = std::fs::File::open(out.join("summary.png")).unwrap();
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    // Four columns of thumbnails above a 420-pixel chart on white.
    assert_eq!(info.width, 1300);
    assert!(info.height > 420, "{}", info.height);
    let px = |x: u32, y: u32| {
        let i = ((y * info.width + x) * 4) as usize;
        [buf[i], buf[i + 1], buf[i + 2]]
    };
    let chart_top = info.height - 420;
    let chart: Vec<[u8; 3]> = (chart_top..info.height)
        .flat_map(|y| (0..info.width).map(move |x| (x, y)))
        .map(|(x, y)| px(x, y))
        .collect();
    let white = chart.iter().filter(|p| **p == [255, 255, 255]).count();
    assert!(white > chart.len() / 3, "the chart is on white");
    // The stamp_cpu colour (the bars) and dark text (axes, labels, legend).
    assert!(chart.contains(&[255, 127, 14]), "no stamp_cpu bars");
    assert!(
        chart
            .iter()
            .filter(|p| p[0] < 60 && p[1] < 60 && p[2] < 60)
            .count()
            > 500
    );
}

#[test]
fn a_run_says_nothing_but_its_result_and_quiet_says_nothing() {
    // No Vulkan loader or driver lines, even without XDG_RUNTIME_DIR (a server, CI).
    let (_, stderr) = run(
        "noise",
        &["--size", "64", "--frames", "2", "--resolution", "64x64"],
    );
    let lines: Vec<&str> = stderr.lines().collect();
    assert!(
        lines.len() == 1 && lines[0].starts_with("wrote 2 frames"),
        "{stderr}"
    );
    let (_, stderr) = run("quiet", &["--size", "64", "--frames", "2", "-q"]);
    assert_eq!(stderr, "", "-q prints nothing on success");
    // -v shows the libraries' logs (the adapter choice, with a GPU; the removal below).
    let (out, _) = run("verbose", &["--size", "64", "--frames", "3", "--no-gpu"]);
    let mut cmd = demo();
    cmd.args(["--size", "64", "--frames", "1", "--no-gpu", "-v", "--out"])
        .arg(&out);
    let done = run_within(cmd, &out, LIMIT);
    assert!(done.status.success());
    assert!(
        done.stderr.contains("INFO") && done.stderr.contains("removed the outputs"),
        "{}",
        done.stderr
    );
    // With a GPU, -v shows terrain-gpu's adapter choice; RUST_LOG chooses per crate alone.
    let gpu_args = ["--size", "64", "--frames", "1", "--resolution", "64x64"];
    let mut cmd = demo();
    cmd.args(gpu_args).arg("-v").arg("--out").arg(&out);
    let done = run_within(cmd, &out, LIMIT);
    assert!(done.status.success(), "{}", done.stderr);
    assert!(
        done.stderr.contains("GPU adapter chosen"),
        "{}",
        done.stderr
    );
    let mut cmd = demo();
    cmd.args(gpu_args)
        .arg("--out")
        .arg(&out)
        .env("RUST_LOG", "terrain_gpu=info");
    let done = run_within(cmd, &out, LIMIT);
    assert!(done.status.success(), "{}", done.stderr);
    assert!(
        done.stderr.contains("GPU adapter chosen"),
        "{}",
        done.stderr
    );
    assert!(
        !done.stderr.contains("removed the outputs"),
        "only terrain-gpu: {}",
        done.stderr
    );
}

#[test]
fn an_earlier_longer_run_leaves_no_frames_behind() {
    let (out, _) = run(
        "old_outputs",
        &["--size", "64", "--frames", "5", "--no-gpu"],
    );
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    std::fs::create_dir(out.join("frame_9999.png")).unwrap();
    // A user's files under the run's names but not what the run writes there stay too.
    std::fs::write(out.join("frame_0100.png"), "a note, not a PNG").unwrap();
    std::fs::write(out.join("frame_00001.png"), "mine").unwrap();
    let mut cmd = demo();
    cmd.args(["--size", "64", "--frames", "2", "--no-gpu", "-q", "--out"])
        .arg(&out);
    assert!(run_within(cmd, &out, LIMIT).status.success());
    let mut frames: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("frame_"))
        .collect();
    frames.sort();
    assert_eq!(
        frames,
        [
            "frame_0000.png",
            "frame_00001.png",
            "frame_0001.png",
            "frame_0100.png"
        ]
    );
    assert_eq!(
        std::fs::read_to_string(out.join("frame_0100.png")).unwrap(),
        "a note, not a PNG"
    );
    // Files and folders the demo did not write stay.
    assert!(out.join("notes.txt").is_file());
    assert!(out.join("frame_9999.png").is_dir());
}

#[test]
fn a_config_file_sets_the_scenario_and_print_config_round_trips() {
    let dir = fresh_dir("config");
    let file = dir.join("craters.toml");
    std::fs::write(
        &file,
        "# a crater every frame, one footprint per frame\n\
         [stamps]\ncrater_every = 1\nsteps_per_frame = 1\n\
         [scheduler]\nquiet_gap_ms = 5\n",
    )
    .unwrap();
    let file_s = file.to_string_lossy().into_owned();
    let (out, _) = run(
        "config_run",
        &[
            "--size", "128", "--frames", "3", "--no-gpu", "--config", &file_s,
        ],
    );
    let r = report(&out);
    assert_eq!(r["config"]["params"]["stamps"]["crater_every"], 1);
    assert_eq!(r["config"]["params"]["scheduler"]["quiet_gap_ms"], 5.0);
    assert_eq!(r["config"]["flags"]["config"], file_s.as_str());
    for f in r["frames"].as_array().unwrap() {
        assert_eq!(f["footprints"], 1, "{f}");
        assert_eq!(f["craters"], 1, "{f}");
    }

    // print-config prints the parameters; read back, they print the same.
    let printed = demo().arg("print-config").output().unwrap();
    assert!(printed.status.success());
    let text = String::from_utf8(printed.stdout).unwrap();
    assert!(text.contains("[granular]") && text.contains("quiet_gap_ms"));
    let copy = dir.join("defaults.toml");
    std::fs::write(&copy, &text).unwrap();
    let again = demo()
        .args(["print-config", "--config"])
        .arg(&copy)
        .output()
        .unwrap();
    assert_eq!(String::from_utf8(again.stdout).unwrap(), text);

    // A typo, a bad value, a folder: exit 2, the key named, nothing written.
    for (body, expect) in [
        ("[stamps]\nfoot_dept_m = 1\n", "foot_dept_m"),
        ("[camera]\norbit_pitch_deg = 120\n", "orbit_pitch_deg"),
        ("[granular]\nmetric = \"taxicab\"\n", "taxicab"),
    ] {
        std::fs::write(&file, body).unwrap();
        let bad_out = dir.join("bad_out");
        let done = demo()
            .args(["--frames", "1", "--no-gpu", "--config"])
            .arg(&file)
            .arg("--out")
            .arg(&bad_out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&done.stderr);
        assert_eq!(done.status.code(), Some(2), "{body}: {stderr}");
        assert!(stderr.contains(expect), "{body}: {stderr}");
        assert!(!bad_out.exists());
    }
    let done = demo()
        .args(["print-config", "--config"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(done.status.code(), Some(2));
}

/// A contact sheet that cannot be written (here a folder stands where it goes) fails the run,
/// and report.json is still written, with every frame and the reason.
#[test]
fn a_summary_that_cannot_be_written_still_leaves_the_report() {
    let out = common::fresh_dir("summary_blocked");
    std::fs::create_dir(out.join("summary.png")).unwrap();
    let mut cmd = demo();
    cmd.args(["--size", "64", "--frames", "2", "--no-gpu", "-q", "--out"])
        .arg(&out);
    let done = run_within(cmd, &out, LIMIT);
    assert_eq!(done.status.code(), Some(1), "{}", done.stderr);
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(r["frames"].as_array().unwrap().len(), 2);
    assert!(r["error"].as_str().unwrap().contains("summary.png"), "{r}");
    assert!(out.join("summary.png").is_dir(), "left as it was");
    let _ = std::fs::remove_dir_all(&out);
}
