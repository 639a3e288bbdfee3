//! Writes seed masks and the exact nearest-seed transform of each (distances and seeds), and
//! times the transform: the Rust half of `scripts/compare_edt.py`, which runs scipy's
//! `distance_transform_edt(return_indices=True)` on the same masks and checks the distances.
//!
//! ```text
//! cargo run --release -p terrain-core --example edt_masks -- [--size N] [--repeat R] [--out DIR]
//! ```
//!
//! - `--size N`: masks are N x N (default 492, the 242 064-column active area of the 4096 map
//!   in Persson 2019, table 5.4).
//! - `--repeat R`: the transform is timed R times per mask and the best is kept (default 20).
//! - `--no-jfa`: skip timing jump flooding on the same masks.
//! - `--mask NAME`: only the mask called NAME (footprint, sparse, footprint_obstacles).
//! - `--out DIR`: where the files go (default the system's temporary folder). Per mask NAME:
//!   `NAME.mask.u8` (1 = seed, row-major), `NAME.dist2.u32` (squared Euclidean distance to the
//!   returned seed, little-endian), and one `edt_timings.json` for all masks.

use glam::{IVec2, UVec2};
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;
use terrain_core::granular::{
    ColumnKind, DistanceMetric, NO_SEED, Penetration, distance_grid, exact_nearest_seed,
    jump_flood, pcg_hash,
};
use terrain_core::{Grid, Rect};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;
/// Whether column `(x, y)` of a mask is a seed.
type SeedTest = dyn Fn(u32, u32) -> bool;

fn main() -> Result<()> {
    let (mut size, mut repeat, mut out) = (492u32, 20u32, std::env::temp_dir());
    let (mut with_jfa, mut only) = (true, None);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--size" => size = value()?.parse()?,
            "--repeat" => repeat = value()?.parse::<u32>()?.max(1),
            "--out" => out = PathBuf::from(value()?),
            "--no-jfa" => with_jfa = false,
            "--mask" => only = Some(value()?),
            _ => return Err(format!("unknown argument {a}").into()),
        }
    }
    if !(1..=8192).contains(&size) {
        return Err("--size must be 1..=8192".into());
    }
    std::fs::create_dir_all(&out)?;
    let n = size as f32;
    // A wheel-like footprint (no seeds inside an ellipse, as under an object), sparse random
    // seeds, and a footprint with scattered obstacles.
    let masks: [(&str, Box<SeedTest>); 3] = [
        (
            "footprint",
            Box::new(move |x, y| {
                let (dx, dy) = (
                    (x as f32 - n * 0.5) / (n * 0.45),
                    (y as f32 - n * 0.5) / (n * 0.25),
                );
                dx * dx + dy * dy > 1.0
            }),
        ),
        (
            "sparse",
            Box::new(|x, y| pcg_hash(x ^ pcg_hash(y)).is_multiple_of(1000)),
        ),
        (
            "footprint_obstacles",
            Box::new(move |x, y| {
                let (dx, dy) = (
                    (x as f32 - n * 0.5) / (n * 0.3),
                    (y as f32 - n * 0.5) / (n * 0.3),
                );
                dx * dx + dy * dy > 1.0 && !pcg_hash((x * 7) ^ pcg_hash(y * 13)).is_multiple_of(8)
            }),
        ),
    ];
    let area = Rect::new(IVec2::ZERO, UVec2::splat(size));
    let mut timings = Vec::new();
    println!("mask                 exact (ms)   jump flooding (ms)");
    for (name, is_seed) in &masks {
        if only.as_deref().is_some_and(|o| o != *name) {
            continue;
        }
        let pen = Grid::from_fn(size, size, |x, y| {
            if is_seed(x, y) {
                Penetration {
                    seed_x: x,
                    seed_y: y,
                    kind: ColumnKind::Seed as i32,
                    penetration: 0,
                }
            } else {
                Penetration {
                    seed_x: NO_SEED,
                    seed_y: NO_SEED,
                    kind: ColumnKind::Penetrating as i32,
                    penetration: 1,
                }
            }
        })?;
        let time = |f: &dyn Fn()| {
            (0..repeat)
                .map(|_| {
                    let t = Instant::now();
                    f();
                    t.elapsed().as_secs_f64() * 1e3
                })
                .fold(f64::INFINITY, f64::min)
        };
        let metric = DistanceMetric::Euclidean;
        let exact_ms = time(&|| {
            std::hint::black_box(exact_nearest_seed(&pen, area, metric).expect("valid"));
        });
        let jfa_ms = if with_jfa {
            time(&|| {
                std::hint::black_box(jump_flood(&pen, area, metric, true).expect("valid"));
            })
        } else {
            f64::NAN
        };
        println!("{name:<20} {exact_ms:>10.3}   {jfa_ms:>18.3}");
        let seeds = exact_nearest_seed(&pen, area, metric)?;
        let dist = distance_grid(&seeds, area, metric);
        let mask: Vec<u8> = pen
            .as_slice()
            .iter()
            .map(|p| u8::from(p.seed_x != NO_SEED))
            .collect();
        std::fs::write(out.join(format!("{name}.mask.u8")), &mask)?;
        let mut f = std::fs::File::create(out.join(format!("{name}.dist2.u32")))?;
        for d in dist.as_slice() {
            f.write_all(&d.to_le_bytes())?;
        }
        timings.push(format!(
            "\"{name}\": {{\"size\": {size}, \"exact_ms\": {exact_ms:.4}, \"jump_flood_ms\": {jfa_ms:.4}}}"
        ));
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    std::fs::write(
        out.join("edt_timings.json"),
        format!(
            "{{\"threads\": {threads}, \"masks\": {{{}}}}}\n",
            timings.join(", ")
        ),
    )?;
    println!(
        "wrote masks, distances and edt_timings.json to {}",
        out.display()
    );
    Ok(())
}
