//! Every check of the flags against each other and against their ranges, in one place, run
//! before anything is read or allocated. What clap cannot say (a flag that only one scenario
//! or LOD mode reads, a number out of range) is a usage error here (exit status 2), so a
//! run never starts and fails later on a flag. Checks that need an input's contents (a
//! heightmap's size, a world's manifest) stay where that input is read.

use crate::cli::{Cli, DetailArg, HeightRangeArg, LodArg, ScenarioKind};
use crate::ranges;
use crate::usage_error::usage;
use anyhow::{Result, anyhow};
use terrain_lod::TessConfig;

/// Checks `cli`'s flags; the first problem found, as a usage error that names the flag.
pub fn flags(cli: &Cli) -> Result<()> {
    scenario_flags(cli).map_err(usage)?;
    numbers(cli).map_err(usage)?;
    lod_flags(cli).map_err(usage)?;
    tess_config(cli).map_err(usage)?;
    Ok(())
}

/// The tessellation of `--lod tessellated`: patches of 32 texels, split by edge size
/// (`--triangle-width`, scaled by the density map unless `--no-density-map`) or by
/// screen-space error (`--target-error`).
pub fn tess_config(cli: &Cli) -> Result<TessConfig> {
    let config = TessConfig {
        triangle_width_px: cli.triangle_width.unwrap_or(8.0),
        use_density: !cli.no_density_map,
        morph: !cli.no_morph,
        max_error_px: cli.target_error,
        ..TessConfig::default()
    };
    config
        .validate()
        .map_err(|e| anyhow!("--triangle-width or --target-error: {e}"))?;
    Ok(config)
}

fn scenario_name(kind: ScenarioKind) -> &'static str {
    match kind {
        ScenarioKind::Default => "default",
        ScenarioKind::Snow => "snow",
        ScenarioKind::Flyover => "flyover",
        ScenarioKind::World => "world",
    }
}

/// Flags that only some scenarios read.
fn scenario_flags(cli: &Cli) -> Result<()> {
    let name = scenario_name(cli.scenario);
    if cli.camera.is_some() && cli.scenario != ScenarioKind::Default {
        return Err(anyhow!(
            "--camera chooses the default scenario's camera; the {name} scenario moves its own"
        ));
    }
    let with_detail = matches!(cli.scenario, ScenarioKind::Default | ScenarioKind::World);
    if cli.detail != DetailArg::None && !with_detail {
        return Err(anyhow!(
            "--detail puts the default scenario's footprints, or the world scenario's walker's, \
             into detail tiles; the snow and flyover scenarios have no detail layer"
        ));
    }
    if cli.color.is_some() && cli.scenario == ScenarioKind::Default && cli.heightmap.is_none() {
        return Err(anyhow!(
            "--color draws an image over the default scenario's --heightmap: give one"
        ));
    }
    if cli.color.is_some() && cli.scenario == ScenarioKind::Snow {
        return Err(anyhow!(
            "--color draws an image over a heightmap or a streamed world; the snow scenario \
             generates its snow field"
        ));
    }
    if cli.heightmap.is_some() && cli.scenario == ScenarioKind::Snow {
        return Err(anyhow!(
            "--heightmap is not used by the snow scenario (it generates its snow field)"
        ));
    }
    Ok(())
}

/// Every numeric flag against its range in [`ranges::FLAGS`].
fn numbers(cli: &Cli) -> Result<()> {
    if let Some(size) = cli.size {
        ranges::check("--size", size)?;
    }
    if let Some(raw) = cli.raw_size {
        ranges::check_as(
            "--raw-size",
            &format!("--raw-size {}x{}", raw.x, raw.y),
            f64::from(raw.min_element()),
        )?;
        ranges::check_as(
            "--raw-size",
            &format!("--raw-size {}x{}", raw.x, raw.y),
            f64::from(raw.max_element()),
        )?;
    }
    let res = cli.resolution;
    for side in [res.x, res.y] {
        ranges::check_as(
            "--resolution",
            &format!("--resolution {}x{}", res.x, res.y),
            side,
        )?;
    }
    ranges::check("--frames", cli.frames)?;
    ranges::check("--warmup", cli.warmup)?;
    ranges::check("--overview-size", cli.overview_size)?;
    // Exact: both bounds are far below 2^53.
    ranges::check("--ram-budget", cli.ram_budget)?;
    ranges::check("--vram-budget", cli.vram_budget)?;
    ranges::check("--speed", cli.speed)?;
    if let Some(t) = cli.texel_size {
        ranges::check("--texel-size", t)?;
    }
    if let Some(max) = cli.max_height {
        ranges::check("--max-height", max)?;
    }
    if let Some(HeightRangeArg::Span(lo, hi)) = cli.height_range {
        let shown = format!("--height-range {lo}:{hi}");
        ranges::check_as("--height-range", &shown, lo)?;
        ranges::check_as("--height-range", &shown, hi)?;
        if f64::from(hi) - f64::from(lo) < ranges::MIN_HEIGHT_SPAN_M {
            return Err(anyhow!(
                "{shown}: MAX - MIN must be at least {} m (the u16 steps of a narrower span \
                 are below f32's resolution of its heights)",
                ranges::MIN_HEIGHT_SPAN_M
            ));
        }
    }
    if let Some(tau) = cli.target_error {
        ranges::check("--target-error", tau)?;
    }
    if let Some(w) = cli.triangle_width {
        ranges::check("--triangle-width", w)?;
    }
    if let Some(bytes) = cli.max_memory {
        ranges::check("--max-memory", bytes)?;
    }
    Ok(())
}

/// The LOD mode and the flags that steer one mode only.
fn lod_flags(cli: &Cli) -> Result<()> {
    let lod_scenario = matches!(cli.scenario, ScenarioKind::Default | ScenarioKind::World);
    if cli.lod != LodArg::Clipmap && !lod_scenario {
        return Err(anyhow!(
            "--lod cdlod and --lod tessellated draw the coarse-map of the default scenario (and \
             of --heightmap) and the world scenario's streamed world; the snow and flyover \
             scenarios draw with the clipmap"
        ));
    }
    if cli.target_error.is_some() && cli.lod == LodArg::Clipmap {
        return Err(anyhow!(
            "--target-error chooses CDLOD's LODs or the tessellation's splits by screen-space \
             error: it needs --lod cdlod or --lod tessellated"
        ));
    }
    let world_tess = cli.lod == LodArg::Tessellated && cli.scenario == ScenarioKind::World;
    if world_tess && (cli.target_error.is_some() || cli.no_density_map) {
        return Err(anyhow!(
            "the streamed world is tessellated by edge size (--triangle-width) alone: its splits \
             are decided from node bounds, which carry no density map and bound no small \
             triangle's error (--target-error and --no-density-map are for the default scenario)"
        ));
    }
    if cli.no_morph && cli.lod == LodArg::Clipmap {
        return Err(anyhow!(
            "--no-morph turns off CDLOD's or the tessellation's morph: it needs --lod cdlod or \
             --lod tessellated"
        ));
    }
    if (cli.no_density_map || cli.triangle_width.is_some()) && cli.lod != LodArg::Tessellated {
        return Err(anyhow!(
            "--no-density-map and --triangle-width steer the adaptive tessellation: they need \
             --lod tessellated"
        ));
    }
    if cli.target_error.is_some() && (cli.no_density_map || cli.triangle_width.is_some()) {
        return Err(anyhow!(
            "--target-error splits the tessellation by screen-space error, without the density \
             map or a triangle width: give one or the other"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn check(args: &[&str]) -> Result<()> {
        let cli = Cli::try_parse_from(std::iter::once("demo").chain(args.iter().copied()))
            .expect("clap parses");
        flags(&cli)
    }

    #[test]
    fn the_defaults_and_each_modes_own_flags_pass() {
        for args in [
            &[][..],
            &["--lod", "cdlod", "--target-error", "1"],
            &[
                "--lod",
                "tessellated",
                "--triangle-width",
                "4",
                "--no-density-map",
            ],
            &[
                "--lod",
                "tessellated",
                "--target-error",
                "0.5",
                "--no-morph",
            ],
            &["--scenario", "world", "--lod", "cdlod"],
            &["--scenario", "world", "--detail", "parallax"],
            &["--scenario", "world", "--detail", "refine"],
            &[
                "--scenario",
                "world",
                "--lod",
                "cdlod",
                "--detail",
                "parallax",
            ],
            &["--detail", "refine"],
            &["--lod", "cdlod", "--detail", "parallax"],
            &["--lod", "tessellated", "--detail", "parallax"],
            &["--lod", "cdlod", "--detail", "refine"],
            &["--lod", "tessellated", "--detail", "refine"],
            &[
                "--scenario",
                "world",
                "--lod",
                "tessellated",
                "--detail",
                "refine",
                "--triangle-width",
                "12",
            ],
            &[
                "--camera",
                "orbit",
                "--max-height",
                "40",
                "--texel-size",
                "0.5",
            ],
        ] {
            check(args).unwrap_or_else(|e| panic!("{args:?}: {e:#}"));
        }
    }

    /// The boundary values of every flag's range pass (tests/ranges.rs runs the binary
    /// with the values just outside; a run with these would run).
    #[test]
    fn the_boundary_values_of_every_range_pass() {
        for args in [
            &["--size", "16"][..],
            &["--size", "65536"],
            &["--heightmap", "x.r16", "--raw-size", "16x65536"],
            &["--texel-size", "0.001"],
            &["--texel-size", "10000"],
            &["--height-range", "-100000:100000"],
            &["--height-range", "0:0.001"],
            &["--max-height", "0.001"],
            &["--max-height", "100000"],
            &["--frames", "1", "--warmup", "0"],
            &["--frames", "100000", "--warmup", "100000"],
            &["--seed", "0"],
            &["--seed", "18446744073709551615"],
            &["--resolution", "16x16", "--overview-size", "16"],
            &["--resolution", "8192x8192", "--overview-size", "8192"],
            &["--ram-budget", "1", "--vram-budget", "1"],
            &["--ram-budget", "1048576", "--vram-budget", "4095"],
            &["--speed", "1e-30"],
            &["--speed", "1000"],
            &["--lod", "cdlod", "--target-error", "0.01"],
            &["--lod", "cdlod", "--target-error", "1000"],
            &["--lod", "tessellated", "--triangle-width", "0.01"],
            &["--lod", "tessellated", "--triangle-width", "10000"],
            &["--max-memory", "1"],
            &["--max-memory", "8388607T"],
        ] {
            check(args).unwrap_or_else(|e| panic!("{args:?}: {e:#}"));
        }
    }

    #[test]
    fn each_flag_out_of_place_or_range_is_a_usage_error_naming_it() {
        for (args, flag) in [
            (&["--scenario", "snow", "--camera", "orbit"][..], "--camera"),
            (
                &["--scenario", "snow", "--heightmap", "x.png"],
                "--heightmap",
            ),
            (&["--speed", "0"], "--speed"),
            (&["--size", "8"], "--size"),
            (&["--frames", "0"], "--frames"),
            (&["--resolution", "8x8"], "--resolution"),
            (&["--vram-budget", "65536"], "--vram-budget"),
            (&["--height-range", "0:0.0001"], "--height-range"),
            (&["--speed", "1e30"], "--speed"),
            (&["--max-height=-1"], "--max-height"),
            (&["--texel-size", "0"], "--texel-size"),
            (
                &["--lod", "cdlod", "--target-error", "1e9"],
                "--target-error",
            ),
            (&["--scenario", "flyover", "--lod", "cdlod"], "--lod"),
            (&["--scenario", "snow", "--lod", "tessellated"], "--lod"),
            (
                &[
                    "--scenario",
                    "world",
                    "--lod",
                    "tessellated",
                    "--target-error",
                    "1",
                ],
                "--triangle-width",
            ),
            (
                &["--scenario", "flyover", "--detail", "parallax"],
                "--detail",
            ),
            (&["--target-error", "1"], "--target-error"),
            (&["--no-morph"], "--no-morph"),
            (&["--no-density-map"], "--no-density-map"),
            (
                &["--lod", "cdlod", "--triangle-width", "4"],
                "--triangle-width",
            ),
            (
                &[
                    "--lod",
                    "tessellated",
                    "--target-error",
                    "1",
                    "--no-density-map",
                ],
                "--target-error",
            ),
            (
                &["--lod", "tessellated", "--triangle-width", "0"],
                "--triangle-width",
            ),
        ] {
            let e = check(args).expect_err(&format!("{args:?} is refused"));
            assert_eq!(
                crate::usage_error::exit_status(&e),
                crate::usage_error::USAGE_EXIT,
                "{args:?}"
            );
            assert!(format!("{e:#}").contains(flag), "{args:?}: {e:#}");
        }
    }
}
