//! Exit statuses: 2 for usage errors (bad flags, unreadable input), found before any frame;
//! 1 for failures while the run goes on (here a frame that cannot be written), after which
//! the frames already done are still listed in `frames.jsonl`, `report.json` and
//! `summary.png`.

mod common;

use common::{demo, fresh_dir, run_within};
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(120);

fn status_of(name: &str, args: &[&str]) -> (Option<i32>, String) {
    let dir = fresh_dir(name);
    let mut cmd = demo();
    cmd.args(args).arg("--out").arg(dir.join("out"));
    let done = run_within(cmd, &dir, LIMIT);
    let _ = std::fs::remove_dir_all(&dir);
    (done.status.code(), done.stderr)
}

#[test]
fn usage_errors_exit_with_2() {
    let dir = fresh_dir("usage_inputs");
    let missing = dir.join("missing.png").display().to_string();
    let garbage = dir.join("garbage.png");
    std::fs::write(&garbage, b"this is not a PNG file at all").expect("write");
    let garbage = garbage.display().to_string();
    let cases: [&[&str]; 17] = [
        &["--scenario", "snow", "--lod", "cdlod", "--no-gpu"],
        &["--scenario", "snow", "--detail", "parallax", "--no-gpu"],
        &["--scenario", "flyover", "--detail", "refine", "--no-gpu"],
        &[
            "--scenario",
            "world",
            "--lod",
            "tessellated",
            "--target-error",
            "1",
            "--no-gpu",
        ],
        &["--lod", "cdlod", "--target-error", "0", "--no-gpu"],
        &["--target-error", "2", "--no-gpu"],
        &["--no-morph", "--no-gpu"],
        &["--no-density-map", "--no-gpu"],
        &["--lod", "cdlod", "--triangle-width", "4", "--no-gpu"],
        &["--lod", "tessellated", "--triangle-width", "0", "--no-gpu"],
        &["--no-such-flag"],
        &["--frames", "0"],
        &["--texel-size", "-1", "--no-gpu"],
        &["--max-height", "NaN", "--no-gpu"],
        &["--heightmap", &missing, "--no-gpu"],
        &["--heightmap", &garbage, "--no-gpu"],
        &["--scenario", "snow", "--heightmap", &garbage, "--no-gpu"],
    ];
    for args in cases {
        let (code, stderr) = status_of("usage", args);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        let first = common::usage_error(&stderr);
        // clap's errors keep their usage line; the demo's own are one line.
        if first.starts_with("error: unexpected argument") {
            assert!(
                stderr.contains("\nUsage: terrain-demo [OPTIONS]"),
                "{args:?}: {stderr}"
            );
        } else {
            assert_eq!(stderr.lines().count(), 1, "{args:?}: one line: {stderr}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A command line clap cannot parse: its whole message (the error, a tip and the usage line
/// where clap has them, the pointer to --help), exit status 2, nothing run.
#[test]
fn a_command_line_mistake_shows_clap_s_tips_and_usage() {
    let dir = fresh_dir("clap_usage");
    let run = |args: &[&str]| {
        let mut cmd = demo();
        cmd.args(args);
        let done = run_within(cmd, &dir, LIMIT);
        (done.status.code(), done.stderr)
    };
    // (arguments, in the error line, elsewhere in the message)
    let cases: [(&[&str], &str, &str); 7] = [
        // A value clap cannot parse: the error and the pointer to --help.
        (
            &["--frames", "abc"],
            "invalid value 'abc' for '--frames <FRAMES>'",
            "\n\nFor more information, try '--help'.",
        ),
        // A mistyped flag gets clap's suggestion.
        (
            &["--frame", "3"],
            "'--frame'",
            "tip: a similar argument exists: '--frames'\n\nUsage: terrain-demo --frames",
        ),
        // The flags that became commands or changed name their replacement.
        (
            &["--print-config"],
            "'--print-config'",
            "tip: `terrain-demo print-config [--config FILE.toml]`",
        ),
        (
            &["--verify-world", "w"],
            "'--verify-world'",
            "tip: `terrain-demo verify-world DIR`",
        ),
        (
            &["--density-map", "off"],
            "'--density-map'",
            "tip: `--no-density-map`",
        ),
        // Run flags and a command do not mix.
        (
            &["--frames", "3", "verify-world", "w"],
            "'verify-world' cannot be used with '--frames <FRAMES>'",
            "Usage: terrain-demo [OPTIONS]",
        ),
        (
            &["print-config", "--no-gpu"],
            "'--no-gpu'",
            "Usage: terrain-demo print-config",
        ),
    ];
    for (args, says, tip) in cases {
        let (code, stderr) = run(args);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        let first = common::usage_error(&stderr);
        assert!(first.contains(says), "{args:?}: `{says}` in: {stderr}");
        assert!(stderr.contains(tip), "{args:?}: `{tip}` in: {stderr}");
        if args[0] != "--frames" || args.len() > 2 {
            assert!(
                stderr.contains("\nUsage: terrain-demo "),
                "{args:?}: {stderr}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
