//! The demo: deforms a terrain with a scripted scenario and writes offline frame captures plus
//! `report.json` with per-frame timings. Everything it does is glue over the library crates.

mod cli;
mod report;
mod scenario;

use anyhow::{Context, Result, bail};
use clap::Parser;
use cli::Cli;
use glam::UVec2;
use report::{FrameReport, Report};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;
use terrain_core::io::{self, ReadLimits};
use terrain_core::{
    CoarseMap, DerivativeMap, HeightEncoding, HillshadeParams, TerrainParams, generate_coarse_map,
    hillshade,
};

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help and --version.
            let _ = e.print();
            return;
        }
        Err(e) => {
            let msg = e.to_string();
            let first = msg.lines().next().unwrap_or("invalid arguments");
            eprintln!("{first} (see --help)");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(&cli) {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}

/// Milliseconds since `t`.
fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn load_map(cli: &Cli) -> Result<(CoarseMap, String)> {
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
            let cells = (cli.size / 16 / defaults.base_period).max(1);
            let octaves = (u32::BITS - cells.leading_zeros()).clamp(1, defaults.octaves);
            let params = TerrainParams {
                size: UVec2::splat(cli.size),
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

fn run(cli: &Cli) -> Result<()> {
    std::fs::create_dir_all(&cli.out)
        .with_context(|| format!("cannot create output folder {}", cli.out.display()))?;
    let t = Instant::now();
    let (mut map, source) = load_map(cli)?;
    let load_ms = ms(t);
    io::write_png16(cli.out.join("terrain.png"), map.grid())?;

    let t = Instant::now();
    let mut normals = DerivativeMap::from_map(&map);
    let initial_normals_ms = ms(t);

    let size = map.size();
    let scale = cli.frame_size as f32 / size.max_element() as f32;
    let frame_px = (size.as_vec2() * scale.min(1.0))
        .round()
        .as_uvec2()
        .max(UVec2::ONE);
    let shade = HillshadeParams::with_size(frame_px);

    let mut scenario = scenario::Scenario::new(map.extent_m(), cli.seed)?;
    let mut frames = Vec::with_capacity(cli.frames as usize);
    let mut totals: BTreeMap<String, f64> = BTreeMap::new();
    for index in 0..cli.frames {
        let mut timings = BTreeMap::new();
        let t = Instant::now();
        let done = scenario.apply_next_frame(&mut map)?;
        timings.insert("stamp".to_string(), ms(t));

        let t = Instant::now();
        for rect in &done.dirty {
            normals.update_rect(&map, *rect)?;
        }
        timings.insert("normals".to_string(), ms(t));

        let t = Instant::now();
        let image = hillshade(&map, &normals, &shade)?;
        timings.insert("hillshade".to_string(), ms(t));

        let t = Instant::now();
        let file = format!("frame_{index:04}.png");
        write_frame(&cli.out.join(&file), &image)?;
        timings.insert("write".to_string(), ms(t));

        for (k, v) in &timings {
            *totals.entry(k.clone()).or_default() += v;
        }
        frames.push(FrameReport {
            index,
            file,
            footprints: done.footprints,
            craters: done.craters,
            shockwaves: done.shockwaves,
            dirty_texels: done.dirty.iter().map(|r| r.area()).sum(),
            timings_ms: timings,
        });
    }
    io::write_png16(cli.out.join("terrain_final.png"), map.grid())?;

    let report = Report {
        source,
        size: [size.x, size.y],
        texel_size_m: map.texel_size(),
        seed: cli.seed,
        load_ms,
        initial_normals_ms,
        frames,
        totals_ms: totals,
    };
    let json = serde_json::to_vec_pretty(&report)?;
    io::write_atomic(cli.out.join("report.json"), &json)?;
    eprintln!(
        "wrote {} frames of {}x{} to {} ({:.0} ms stamping, {:.0} ms normals in all)",
        cli.frames,
        frame_px.x,
        frame_px.y,
        cli.out.display(),
        report.totals_ms.get("stamp").copied().unwrap_or(0.0),
        report.totals_ms.get("normals").copied().unwrap_or(0.0),
    );
    Ok(())
}

fn write_frame(path: &Path, image: &terrain_core::Grid<[u8; 4]>) -> Result<()> {
    io::write_png_rgba8(path, image).with_context(|| format!("writing {}", path.display()))
}
