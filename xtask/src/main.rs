//! Workspace commands, one module each (rust-analyzer's xtask style): `cargo xtask ci` runs
//! every check CI runs, in order, and names the step that failed; the others run one part of
//! it, or a tool CI does not run (fuzz for longer, mutants, bench-report, golden). This file
//! only dispatches and prints the usage.

mod bench_report;
mod ci;
mod examples;
mod fuzz;
mod golden;
mod gpu_report;
mod import_cycles;
mod libfuzzer;
mod msrv;
mod mutants;
mod package;
mod smoke;
mod tidy;
mod util;

use anyhow::Result;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("ci") => ci::ci(),
        Some("tidy") => tidy::tidy(),
        Some("smoke") => smoke::smoke(),
        Some("package") => package::package(),
        Some("examples") => examples::examples(),
        Some("golden") => golden::golden(),
        Some("bench-report") => bench_report::bench_report(&args[1..]),
        Some("gpu-report") => gpu_report::gpu_report(&args[1..]),
        Some("fuzz") => fuzz::fuzz(&args[1..]),
        Some("mutants") => mutants::mutants(&args[1..]),
        Some("msrv") => msrv::msrv(),
        _ => {
            usage();
            std::process::exit(2);
        }
    }
}

fn usage() {
    eprintln!(
        "usage: cargo xtask <ci|tidy|smoke|package|examples|golden|bench-report [--quick] [--write-docs]|gpu-report [--minutes N]|fuzz [--engine harness|libfuzzer] --seconds N [--target NAME] [--seed S]|mutants [--shard K/N] [--crate NAME] | --summary|msrv>"
    );
    eprintln!(
        "  ci      tidy, fmt, clippy, tests, docs, package, examples, demo smoke (what CI runs)"
    );
    eprintln!(
        "  tidy    repository rules: no silenced clippy::too_many_arguments, no copied fuzz harness,"
    );
    eprintln!(
        "          no path outside the repository or into a crates folder, no .rs file over 1000 lines"
    );
    eprintln!("  examples  run every library example once at a tiny size");
    eprintln!("  smoke   only the demo smoke runs (default backend, then GL)");
    eprintln!("  package package and verify the publishable crates (`cargo package`)");
    eprintln!(
        "  msrv    check the workspace with the declared rust-version (rustup installs it; not part of ci)"
    );
    eprintln!("  golden  regenerate the render test's golden image (never done by tests)");
    eprintln!(
        "  bench-report  run the headline CPU benches (all cores, then one); write target/bench-report.{{json,md}}; --write-docs also writes docs/BENCHMARKS.md"
    );
    eprintln!(
        "  gpu-report  on a machine with a GPU: release GPU tests (watchdog), demo runs and GPU benches"
    );
    eprintln!(
        "          within one budget (8 min default); writes target/gpu-report/gpu-report.md"
    );
    eprintln!(
        "  fuzz    run the fuzz targets N seconds each (release), print cases and results per input class"
    );
    eprintln!(
        "          (ci's `test` step already runs each target for 2 s; targets: {})",
        fuzz::FUZZ_TARGETS.map(|t| t.1).join(", ")
    );
    eprintln!(
        "          --engine libfuzzer: the decoders' coverage-guided targets instead (nightly, cargo-fuzz;"
    );
    eprintln!(
        "          default 60 s each; crash inputs under target/fuzz/artifacts; not part of ci): {}",
        libfuzzer::LIBFUZZER_TARGETS.join(", ")
    );
    eprintln!(
        "  mutants run cargo-mutants on the algorithm files; print caught / missed / score per crate"
    );
    eprintln!(
        "          (crates: {}; not part of ci)",
        mutants::MUTANT_CRATES.join(", ")
    );
}
