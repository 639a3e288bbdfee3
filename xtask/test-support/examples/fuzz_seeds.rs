//! Writes the decoder targets' seeds (`terrain_test_support::decoders`) as files, one folder
//! per target: `fuzz_seeds DIR` makes `DIR/<target>/seed-NN`, the first corpus of each libFuzzer
//! target. `cargo xtask fuzz --engine libfuzzer` runs it before the targets (into
//! `target/fuzz/seeds/`); the seeds are made by code rather than checked in, so they follow the
//! formats as they change.

use std::path::PathBuf;
use terrain_test_support::decoders::DECODERS;

fn main() -> std::io::Result<()> {
    let Some(dir) = std::env::args_os().nth(1).map(PathBuf::from) else {
        eprintln!("usage: fuzz_seeds DIR");
        std::process::exit(2);
    };
    for d in &DECODERS {
        let folder = dir.join(d.name);
        if folder.exists() {
            std::fs::remove_dir_all(&folder)?;
        }
        std::fs::create_dir_all(&folder)?;
        let seeds = (d.seeds)();
        for (i, seed) in seeds.iter().enumerate() {
            std::fs::write(folder.join(format!("seed-{i:02}")), seed)?;
        }
        println!("{}: {} seeds in {}", d.name, seeds.len(), folder.display());
    }
    Ok(())
}
