//! The default scenario's terrain: a procedural coarse-map, or a 16-bit PNG / RAW16 heightmap
//! given with `--heightmap`, with the command line's texel size and height span.

use crate::cli::Cli;
use crate::usage_error::UsageExt;
use anyhow::{Context, Result, bail};
use glam::UVec2;
use terrain_core::io::{self, ReadLimits};
use terrain_core::{CoarseMap, HeightEncoding, TerrainParams, generate_coarse_map};

/// Side of the procedural terrain in texels by default (205 m at 0.1 m).
pub const DEFAULT_SIZE: u32 = 2048;

/// The size of the map `cli` asks for, known before anything is made or read: `--size` (or
/// the default), `--raw-size`, or the PNG's header. Its errors are usage errors.
pub fn planned_size(cli: &Cli) -> Result<UVec2> {
    match (&cli.heightmap, cli.raw_size) {
        (None, _) => Ok(UVec2::splat(cli.size.unwrap_or(DEFAULT_SIZE))),
        (Some(_), Some(size)) => Ok(size),
        (Some(path), None) => io::read_png_size(path, &ReadLimits::default())
            .with_context(|| format!("cannot use heightmap {}", path.display()))
            .usage(),
    }
}

/// The map `cli` asks for, and where it came from (`procedural` or the heightmap's path).
/// Every error is the user's to fix (a flag, or the heightmap file): a usage error.
pub fn load(cli: &Cli) -> Result<(CoarseMap, String)> {
    make(cli).usage()
}

fn make(cli: &Cli) -> Result<(CoarseMap, String)> {
    if !(cli.texel_size.is_finite() && cli.texel_size > 0.0) {
        bail!(
            "--texel-size must be a positive number of metres, got {}",
            cli.texel_size
        );
    }
    if !(cli.max_height.is_finite() && cli.max_height > 0.0) {
        bail!(
            "--max-height must be a positive number of metres, got {}",
            cli.max_height
        );
    }
    let encoding = HeightEncoding::spanning::<u16>(0.0, cli.max_height)?;
    let limits = ReadLimits::default();
    match &cli.heightmap {
        None => {
            let defaults = TerrainParams::default();
            // Octaves whose lattice cells are finer than ~16 texels only add noise that hides
            // the deformations, so stop there.
            let size = cli.size.unwrap_or(DEFAULT_SIZE);
            let cells = (size / 16 / defaults.base_period).max(1);
            let octaves = (u32::BITS - cells.leading_zeros()).clamp(1, defaults.octaves);
            let params = TerrainParams {
                size: UVec2::splat(size),
                seed: cli.seed,
                octaves,
                // Gentler small scales than the library default: a walkable landscape.
                persistence: 0.4,
                ..defaults
            };
            let map = generate_coarse_map(&params, encoding, cli.texel_size)?;
            Ok((map, "procedural".into()))
        }
        Some(path) => {
            let grid = match cli.raw_size {
                Some(size) => io::read_raw16(path, size, &limits),
                None => io::read_png16(path, &limits),
            }
            .with_context(|| format!("cannot use heightmap {}", path.display()))?;
            let min = grid.size().min_element();
            if min < 16 {
                bail!(
                    "heightmap {} is {}: at least 16x16 needed",
                    path.display(),
                    grid.size()
                );
            }
            let map = CoarseMap::coarse(grid, encoding, cli.texel_size)?;
            Ok((map, path.display().to_string()))
        }
    }
}
