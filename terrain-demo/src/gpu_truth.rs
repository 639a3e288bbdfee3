//! GPU truth (Flower 2010, sec. 3.2.3): with a GPU every deformation is applied once, on the
//! GPU, and the CPU receives the changed regions only by readback. These runs count, through
//! terrain-core's `cpu-work` feature, every stamp and granular step the frame thread applies
//! on the CPU: none with a GPU, and some without one (so the count is seen to work).

use super::run;
use crate::cli::Cli;
use clap::Parser;
use terrain_core::cpu_work::{self, CpuWork};

/// Runs the demo in this thread with `args` and returns the CPU deformations it applied.
fn deformations(name: &str, args: &[&str]) -> CpuWork {
    let out = std::env::temp_dir().join(format!("terrain-gpu-truth-{}-{name}", std::process::id()));
    let cli = Cli::try_parse_from(
        ["terrain-demo", "-q", "--out"]
            .into_iter()
            .map(String::from)
            .chain([out.to_string_lossy().into_owned()])
            .chain(args.iter().map(|a| (*a).to_owned())),
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"));
    cpu_work::reset();
    run(&cli).unwrap_or_else(|e| panic!("{name}: {e:#}"));
    let work = cpu_work::cpu_work();
    let _ = std::fs::remove_dir_all(&out);
    work
}

#[test]
fn with_a_gpu_no_deformation_is_applied_to_a_cpu_copy() {
    if terrain_gpu::testing::context_or_skip("GPU truth").is_none() {
        return;
    }
    let default = ["--size", "128", "--frames", "24", "--resolution", "64x48"];
    let runs: [(&str, Vec<&str>); 3] = [
        ("default", default.to_vec()),
        ("detail", [&default[..], &["--detail", "parallax"]].concat()),
        ("snow", [&default[..], &["--scenario", "snow"]].concat()),
    ];
    for (name, args) in runs {
        let cpu = deformations(&format!("{name}-cpu"), &[&args[..], &["--no-gpu"]].concat());
        assert!(
            !cpu.is_none(),
            "{name} without a GPU deformed nothing: {cpu:?}"
        );
        let gpu = deformations(&format!("{name}-gpu"), &args);
        assert!(
            gpu.is_none(),
            "{name} with a GPU deformed a CPU copy: {gpu:?}"
        );
    }
}
