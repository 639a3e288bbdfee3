//! The density map of Cervin 2012, ch. 3 for the workspace's procedural terrain, with each curvature
//! filter: the time it takes, how its values spread, and (with `--out DIR`) level 0 as an 8-bit
//! PNG per filter.
//!
//! `cargo run --release -p terrain-lod --example density_map -- [--size N] [--texel M]
//! [--max-height M] [--out DIR]` (default 1024 texels of 0.1 m, 0 to 12 m high, as the demo's
//! default scenario).

use glam::UVec2;
use std::time::Instant;
use terrain_core::{HeightEncoding, TerrainParams, generate_coarse_map, io::write_png8};
use terrain_lod::{CurvatureFilter, DensityMap, DensityParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (mut size, mut texel, mut max_height, mut out) = (1024u32, 0.1f32, 12.0f32, None);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--size" => size = value()?.parse()?,
            "--texel" => texel = value()?.parse()?,
            "--max-height" => max_height = value()?.parse()?,
            "--out" => out = Some(std::path::PathBuf::from(value()?)),
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    let params = TerrainParams {
        size: UVec2::splat(size),
        ..TerrainParams::default()
    };
    let map = generate_coarse_map(
        &params,
        HeightEncoding::spanning::<u16>(0.0, max_height)?,
        texel,
    )?;
    println!("{size} x {size} texels of {texel} m, heights 0 to {max_height} m");
    for filter in CurvatureFilter::ALL {
        let p = DensityParams {
            filter,
            ..DensityParams::default()
        };
        let t = Instant::now();
        let dm = DensityMap::from_map(&map, p)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let l0 = dm.level(0).ok_or("no level 0")?;
        let mut v: Vec<u8> = l0.as_slice().to_vec();
        v.sort_unstable();
        let pct = |q: f64| v[((v.len() - 1) as f64 * q) as usize];
        let mut raw: Vec<f32> = dm.raw().as_slice().to_vec();
        raw.sort_unstable_by(f32::total_cmp);
        let rpct = |q: f64| raw[((raw.len() - 1) as f64 * q) as usize];
        let full = v.iter().filter(|&&x| x == 255).count() as f64 / v.len() as f64;
        println!(
            "{:>26}: {ms:8.1} ms, {} levels, level 0 {}x{}: p10 {} p50 {} p90 {} max {}, {:.1} % at full density; normalised curvature p10 {:.4} p50 {:.4} p90 {:.4} max {:.4}",
            filter.name(),
            dm.level_count(),
            l0.width(),
            l0.height(),
            pct(0.1),
            pct(0.5),
            pct(0.9),
            pct(1.0),
            full * 100.0,
            rpct(0.1),
            rpct(0.5),
            rpct(0.9),
            rpct(1.0),
        );
        if let Some(dir) = &out {
            std::fs::create_dir_all(dir)?;
            write_png8(dir.join(format!("density_{}.png", filter.name())), l0)?;
        }
    }
    Ok(())
}
