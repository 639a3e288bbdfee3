//! Every numeric flag and `--config` key has a documented range, checked before the run: the
//! binary is driven with extreme values (0, negatives, NaN, infinities, values near the f32
//! and integer limits, products that would overflow) and must exit with status 2, naming the
//! flag or key (flags are checked before anything is read or allocated; `print-config
//! --config FILE` is the validation-only path of the keys: they are checked, then printed); the
//! boundary values inside the ranges are accepted (for the flags, `validate`'s unit tests
//! check them: a run with them would run). Writability: a folder the run cannot write into
//! fails with exit 2 naming it, before the run starts.

mod common;

use common::{demo, fresh_dir, run_within};
use std::path::Path;
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(60);

fn run(dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let mut cmd = demo();
    cmd.args(args);
    let done = run_within(cmd, dir, LIMIT);
    (done.status.code(), done.stderr)
}

fn refused(dir: &Path, args: &[&str], name: &str) {
    let (code, stderr) = run(dir, args);
    assert_eq!(code, Some(2), "{args:?}: {stderr}");
    let first = common::usage_error(&stderr);
    assert!(
        first.contains(name),
        "{args:?} should name {name}: {stderr}"
    );
}

fn accepted(dir: &Path, args: &[&str]) {
    let (code, stderr) = run(dir, args);
    assert_eq!(code, Some(0), "{args:?} should be accepted: {stderr}");
}

#[test]
fn extreme_flag_values_exit_2_naming_the_flag() {
    let dir = fresh_dir("ranges_flags");
    let raw = dir.join("x.r16").display().to_string();
    let cases: &[(&[&str], &str)] = &[
        (&["--size", "0"], "--size"),
        (&["--size", "15"], "--size"),
        (&["--size", "65537"], "--size"),
        (&["--size=-1"], "--size"),
        (&["--size", "4294967296"], "--size"),
        (&["--heightmap", &raw, "--raw-size", "0x16"], "--raw-size"),
        (
            &["--heightmap", &raw, "--raw-size", "16x65537"],
            "--raw-size",
        ),
        (
            &["--heightmap", &raw, "--raw-size", "4294967296x2"],
            "--raw-size",
        ),
        (&["--texel-size", "0"], "--texel-size"),
        (&["--texel-size=-1"], "--texel-size"),
        (&["--texel-size", "NaN"], "--texel-size"),
        (&["--texel-size", "inf"], "--texel-size"),
        (&["--texel-size", "1e-30"], "--texel-size"),
        (&["--texel-size", "3.4e38"], "--texel-size"),
        (&["--texel-size", "1e39"], "--texel-size"),
        (&["--height-range", "-3e38:3e38"], "--height-range"),
        (&["--height-range", "0:1e-9"], "--height-range"),
        (&["--height-range", "-200000:0"], "--height-range"),
        (&["--height-range", "NaN:1"], "--height-range"),
        (&["--max-height", "0"], "--max-height"),
        (&["--max-height=-1"], "--max-height"),
        (&["--max-height", "NaN"], "--max-height"),
        (&["--max-height", "inf"], "--max-height"),
        (&["--max-height", "1e9"], "--max-height"),
        (&["--frames", "0"], "--frames"),
        (&["--frames", "100001"], "--frames"),
        (&["--frames", "4294967296"], "--frames"),
        (&["--warmup", "100001"], "--warmup"),
        (&["--warmup=-1"], "--warmup"),
        (&["--seed=-1"], "--seed"),
        (&["--seed", "18446744073709551616"], "--seed"),
        (&["--resolution", "8x8"], "--resolution"),
        (&["--resolution", "0x0"], "--resolution"),
        (&["--resolution", "16x9000"], "--resolution"),
        (&["--resolution", "4294967296x2"], "--resolution"),
        (&["--overview-size", "8"], "--overview-size"),
        (&["--overview-size", "9000"], "--overview-size"),
        (&["--ram-budget", "0"], "--ram-budget"),
        (&["--ram-budget", "1048577"], "--ram-budget"),
        (&["--ram-budget", "18446744073709551615"], "--ram-budget"),
        (&["--vram-budget", "0"], "--vram-budget"),
        (&["--vram-budget", "4096"], "--vram-budget"),
        (&["--vram-budget", "18446744073709551615"], "--vram-budget"),
        (&["--speed", "0"], "--speed"),
        (&["--speed=-1"], "--speed"),
        (&["--speed", "NaN"], "--speed"),
        (&["--speed", "inf"], "--speed"),
        (&["--speed", "1e30"], "--speed"),
        (&["--speed", "1000.1"], "--speed"),
        (&["--lod", "cdlod", "--target-error", "0"], "--target-error"),
        (
            &["--lod", "cdlod", "--target-error", "1e9"],
            "--target-error",
        ),
        (
            &["--lod", "cdlod", "--target-error", "NaN"],
            "--target-error",
        ),
        (
            &["--lod", "tessellated", "--triangle-width", "0"],
            "--triangle-width",
        ),
        (
            &["--lod", "tessellated", "--triangle-width", "1e9"],
            "--triangle-width",
        ),
        (
            &["--lod", "tessellated", "--triangle-width", "inf"],
            "--triangle-width",
        ),
        (&["--max-memory", "0"], "--max-memory"),
        (&["--max-memory", "99999999T"], "--max-memory"),
        (&["--max-memory=-5G"], "--max-memory"),
        (&["--max-memory", "NaN"], "--max-memory"),
    ];
    let out = dir.join("out").display().to_string();
    for (args, name) in cases {
        let mut args = args.to_vec();
        args.extend(["--no-gpu", "--out", &out]);
        refused(&dir, &args, name);
    }
    assert!(!dir.join("out").exists(), "refused before the run");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `(key, [section] line)` for every numeric config key: each is written with each of
/// `values` and refused, naming the key.
const KEYS: &[(&str, &str)] = &[
    ("stamps", "foot_size_m = [{v}, 0.5]"),
    ("stamps", "foot_depth_m = {v}"),
    ("stamps", "steps_per_frame = {v}"),
    ("stamps", "stride_m = {v}"),
    ("stamps", "crater_every = {v}"),
    ("stamps", "crater_size_m = [1, {v}]"),
    ("stamps", "crater_depth_ratio = {v}"),
    ("stamps", "shock_size_fraction = {v}"),
    ("stamps", "shock_amplitude_m = {v}"),
    ("stamps", "shock_steps_per_frame = {v}"),
    ("stamps", "hole_frame = {v}"),
    ("stamps", "hole_size_m = {v}"),
    ("stamps.shockwave", "resolution = {v}"),
    ("stamps.shockwave", "gamma = {v}"),
    ("stamps.shockwave", "initial_sigma = {v}"),
    ("stamps.shockwave", "damping = {v}"),
    ("granular", "compression = {v}"),
    ("granular", "roughness = {v}"),
    ("granular", "slope_threshold = {v}"),
    ("granular", "slope_d = {v}"),
    ("granular", "num_iterations_even_out_slopes = {v}"),
    ("granular", "num_iterations_blur_normals = {v}"),
    ("granular", "obstacle_margin_m = {v}"),
    ("granular", "active_area_margin = {v}"),
    ("granular", "merge_distance = {v}"),
    ("scheduler", "quiet_gap_ms = {v}"),
    ("scheduler", "max_delay_ms = {v}"),
    ("scheduler", "merge_distance = {v}"),
    ("scheduler", "max_requests = {v}"),
    ("scheduler", "request_timeout_ms = {v}"),
    ("scheduler", "max_in_flight = {v}"),
    ("style", "light_dir = [1, {v}, 0]"),
    ("style", "fog_color = [0.5, 0.5, {v}]"),
    ("style", "fog_density = {v}"),
    ("style", "ramp_m = [0, {v}]"),
    ("style", "material_scale_m = {v}"),
    ("camera", "walker_eye_height_m = {v}"),
    ("camera", "walker_behind_m = {v}"),
    ("camera", "walker_ahead_m = {v}"),
    ("camera", "orbit_pitch_deg = {v}"),
    ("camera", "orbit_period_s = {v}"),
    ("camera", "flyover_period_s = {v}"),
    ("camera", "flyover_height = {v}"),
    ("camera", "flyover_pitch_deg = {v}"),
];

#[test]
fn extreme_config_values_exit_2_naming_the_key() {
    let dir = fresh_dir("ranges_keys");
    let file = dir.join("params.toml");
    let file_arg = file.display().to_string();
    // Every key gets each: NaN, infinities, the f32 and integer limits and beyond, negatives.
    let values = [
        "nan",
        "inf",
        "-inf",
        "1e30",
        "-1e30",
        "3.5e38",
        "-1",
        "4294967296",
        "18446744073709551616",
    ];
    for (section, line) in KEYS {
        let key = line.split_once(' ').map_or(*line, |k| k.0);
        for v in values {
            // -1 is a valid light_dir component: skip the one value a key accepts.
            if key == "light_dir" && v == "-1" {
                continue;
            }
            let text = format!("[{section}]\n{}\n", line.replace("{v}", v));
            std::fs::write(&file, &text).expect("write params");
            let (code, stderr) = run(&dir, &["print-config", "--config", &file_arg]);
            assert_eq!(code, Some(2), "{text}: {stderr}");
            assert!(stderr.contains(key), "{text} should name {key}: {stderr}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn boundary_config_values_are_accepted() {
    // granular.slope_d: terrain-core compares the f32 with 1e-6 in f64, so the f32 nearest
    // 1e-6 (just below it) is refused there; the next ones are the boundary in practice.
    let dir = fresh_dir("ranges_key_bounds");
    let file = dir.join("params.toml");
    let file_arg = file.display().to_string();
    let low = "[stamps]\nfoot_size_m = [1e-30, 1e-30]\nfoot_depth_m = 0\nsteps_per_frame = 1\n\
               stride_m = 1e-30\ncrater_every = 0\ncrater_size_m = [1e-30, 1e-30]\n\
               crater_depth_ratio = 0\nshock_size_fraction = 0\nshock_amplitude_m = 0\n\
               shock_steps_per_frame = 0\nhole_frame = 0\nhole_size_m = 1e-30\n\
               [stamps.shockwave]\nresolution = 8\ngamma = 1e-30\n\
               initial_sigma = 1e-30\ndamping = 0\n\
               [granular]\ncompression = 0\nroughness = 0\nslope_threshold = 0\n\
               slope_d = 1.0001e-6\nnum_iterations_even_out_slopes = 0\n\
               num_iterations_blur_normals = 0\nobstacle_margin_m = 0\nactive_area_margin = 0\n\
               merge_distance = 0\n\
               [scheduler]\nquiet_gap_ms = 0\nmax_delay_ms = 0\nmerge_distance = 0\n\
               max_requests = 1\nrequest_timeout_ms = 1e-3\nmax_in_flight = 1\n\
               [style]\nlight_dir = [-1e6, -1e6, -1e6]\nfog_color = [0, 0, 0]\n\
               fog_density = 0\nramp_m = [-100000, -99999]\nmaterial_scale_m = 0.01\n\
               [camera]\nwalker_eye_height_m = 1e-30\nwalker_behind_m = 0\n\
               walker_ahead_m = 1e-30\norbit_pitch_deg = 0.001\norbit_period_s = 1e-30\n\
               flyover_period_s = 1e-30\nflyover_height = 1e-30\nflyover_pitch_deg = 0.001\n";
    let high = "[stamps]\nfoot_size_m = [100, 100]\nfoot_depth_m = 100\nsteps_per_frame = 64\n\
                stride_m = 1000\ncrater_every = 100000\ncrater_size_m = [100000, 100000]\n\
                crater_depth_ratio = 10\nshock_size_fraction = 1\nshock_amplitude_m = 1000\n\
                shock_steps_per_frame = 64\nhole_frame = 4294967295\n\
                hole_size_m = 100000\n[stamps.shockwave]\nresolution = 4096\n\
                gamma = 0.5\ninitial_sigma = 4096\ndamping = 0.999\n\
                [granular]\ncompression = 1\nroughness = 1\nslope_threshold = 1e6\n\
                slope_d = 1e6\nnum_iterations_even_out_slopes = 1024\n\
                num_iterations_blur_normals = 1024\nobstacle_margin_m = 1e4\n\
                active_area_margin = 4096\nmerge_distance = 4096\n\
                [scheduler]\nquiet_gap_ms = 60000\nmax_delay_ms = 60000\n\
                merge_distance = 65536\nmax_requests = 16\nrequest_timeout_ms = 600000\n\
                max_in_flight = 16\n\
                [style]\nlight_dir = [1e6, 1e6, 1e6]\nfog_color = [1, 1, 1]\n\
                fog_density = 10\nramp_m = [99999, 100000]\nshading = \"ramp\"\n\
                material_scale_m = 10000\n\
                [camera]\nwalker_eye_height_m = 1000\nwalker_behind_m = 10000\n\
                walker_ahead_m = 10000\norbit_pitch_deg = 89.999\norbit_period_s = 86400\n\
                flyover_period_s = 86400\nflyover_height = 100\nflyover_pitch_deg = 89.999\n";
    for text in [low, high] {
        std::fs::write(&file, text).expect("write params");
        accepted(&dir, &["print-config", "--config", &file_arg]);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn help_lists_every_range() {
    let out = demo().arg("--help").output().expect("runs");
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    for name in [
        "--size",
        "--texel-size",
        "--vram-budget",
        "--max-memory",
        "--seed",
        "stamps.foot_size_m",
        "scheduler.max_in_flight",
        "camera.flyover_pitch_deg",
    ] {
        let line = help
            .lines()
            .rev()
            .find(|l| l.trim_start().starts_with(name))
            .unwrap_or_else(|| panic!("{name} has no line in --help: {help}"));
        assert!(line.contains(" to "), "{line}");
    }
    for (section, line) in KEYS {
        let key = line.split_once(' ').map_or(*line, |k| k.0);
        assert!(
            help.contains(&format!("{section}.{key}")),
            "{section}.{key}"
        );
    }
}

#[test]
fn an_unwritable_output_or_world_folder_exits_2_before_the_run() {
    let dir = fresh_dir("ranges_writable");
    let file = dir.join("a_file");
    std::fs::write(&file, b"x").expect("file");
    // A file where the output folder should be, and /proc (read-only even for root).
    let under_file = file.join("out").display().to_string();
    let (code, stderr) = run(&dir, &["--no-gpu", "--size", "16", "--out", &under_file]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("--out") && stderr.contains("a_file"),
        "{stderr}"
    );
    let (code, stderr) = run(
        &dir,
        &["--no-gpu", "--size", "16", "--out", "/proc/self/out"],
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--out /proc/self/out"), "{stderr}");
    let out = dir.join("out").display().to_string();
    let (code, stderr) = run(
        &dir,
        &[
            "--scenario",
            "flyover",
            "--no-gpu",
            "--world",
            "/proc/self/world",
            "--out",
            &out,
        ],
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--world /proc/self/world"), "{stderr}");
    // A folder without write permission (root writes anyway: then only the above holds).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = dir.join("read_only");
        std::fs::create_dir(&ro).expect("folder");
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).expect("chmod");
        let root = std::fs::File::create(ro.join("probe")).is_ok();
        if !root {
            let ro_arg = ro.display().to_string();
            let (code, stderr) = run(&dir, &["--no-gpu", "--size", "16", "--out", &ro_arg]);
            assert_eq!(code, Some(2), "{stderr}");
            assert!(stderr.contains(&ro_arg), "{stderr}");
        }
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
