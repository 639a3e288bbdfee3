//! The demo: deforms a terrain with a scripted scenario and writes offline frame captures plus
//! `report.json` with per-frame timings. Everything it does is glue over the library crates:
//! `scenarios` says what happens, `driver` runs the frames, `gpu_scene` is the GPU side.

mod camera_rig;
mod capture;
mod cli;
mod driver;
mod gpu_scene;
mod images;
mod overview;
mod report;
mod scenarios;
mod timings;

use anyhow::Result;
use clap::Parser;
use cli::Cli;

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
        // One line: the error and its causes, skipping a cause whose text is already shown
        // (library errors often include their source in their own message).
        let mut line = e.to_string();
        for cause in e.chain().skip(1) {
            let text = cause.to_string();
            if !line.contains(&text) {
                line.push_str(": ");
                line.push_str(&text);
            }
        }
        eprintln!("error: {line}");
        std::process::exit(2);
    }
}

fn run(cli: &Cli) -> Result<()> {
    if let Some(dir) = &cli.verify_world {
        let bad = scenarios::world_files::verify(dir)?;
        if bad.is_empty() {
            println!(
                "world {}: every tile and the manifest are valid",
                dir.display()
            );
            return Ok(());
        }
        for line in &bad {
            println!("{line}");
        }
        eprintln!("world {}: {} bad tile(s)", dir.display(), bad.len());
        std::process::exit(1);
    }
    let mut scenario = scenarios::open(cli)?;
    driver::run(cli, scenario.as_mut())?;
    Ok(())
}
