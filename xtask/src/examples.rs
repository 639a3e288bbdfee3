//! `cargo xtask examples`: runs every library example once at a tiny size, so an example that
//! no longer runs is caught; an example file that is not listed here fails the command, so
//! none is left unrun.

use crate::util::{cargo, root, target_dir};
use anyhow::{Context, Result, bail};
use std::process::Command;

/// The library examples `examples` runs, with tiny arguments (`{out}`: a folder under target).
const EXAMPLES: [(&str, &str, &[&str]); 16] = [
    (
        "terrain-core",
        "stamp_heightmap",
        &["--size", "64", "--out", "{out}"],
    ),
    (
        "terrain-core",
        "edt_masks",
        &["--size", "48", "--repeat", "1", "--out", "{out}"],
    ),
    (
        "terrain-physics",
        "drop_spheres",
        &["--size", "64", "--spheres", "2", "--steps", "90"],
    ),
    (
        "terrain-physics",
        "camera_flight",
        &["--size", "64", "--frames", "60"],
    ),
    ("terrain-gpu", "own_device", &["{out}/own_device.png"]),
    ("terrain-gpu", "gpu_memory", &["64"]),
    ("terrain-lod", "clipmap_frame", &["63", "4"]),
    (
        "terrain-lod",
        "density_map",
        &["--size", "64", "--out", "{out}/density"],
    ),
    ("terrain-lod", "tessellation_ratio", &["--size", "256"]),
    ("terrain-cache", "build_world", &["512", "{out}/world"]),
    // Reads the world build_world just wrote.
    ("terrain-cache", "random_blocks", &["{out}/world", "20"]),
    // Paints and stamps into that world and streams both (`StreamedWorld`).
    ("terrain-cache", "streamed_world", &["{out}/world", "12"]),
    ("terrain-cache", "trace_sim", &[]),
    ("terrain-cache", "granular_trails", &["120"]),
    // The whole frame an engine runs: it joins every library crate, so it lives in the demo.
    (
        "terrain-demo",
        "engine_frame",
        &["{out}/engine_frame", "24"],
    ),
    // Footprints in a streamed world's detail tiles: terrain-cache's detail cache and
    // terrain-gpu's stamps, readback and renderer together.
    (
        "terrain-demo",
        "world_footprints",
        &["{out}/world_footprints", "24"],
    ),
];

/// Library examples behind a feature of their crate (`required-features`): the workspace build
/// of `examples` has the feature on ([`crate::ci::ADAPTERS`] must name it).
const FEATURE_EXAMPLES: [(&str, &str, &str, &[&str]); 1] = [(
    "terrain-physics",
    "parry_drop",
    "parry",
    &["--size", "64", "--tile", "16", "--steps", "60"],
)];

/// Example files that are tools rather than examples, with why `examples` does not run them.
const NOT_EXAMPLES: [(&str, &str, &str); 1] = [(
    "terrain-gpu",
    "golden",
    "regenerates the render test's golden image in the repository: `cargo xtask golden`",
)];

/// Runs every example of the library crates once at a tiny size; fails on an example file that
/// `EXAMPLES` does not list, so none is left unrun.
pub fn examples() -> Result<()> {
    for krate in [
        "terrain-core",
        "terrain-physics",
        "terrain-gpu",
        "terrain-lod",
        "terrain-cache",
        "terrain-demo",
    ] {
        let dir = root().join(krate).join("examples");
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries {
            let path = entry?.path();
            let Some(name) = path.file_stem().and_then(|s| s.to_str()) else {
                continue;
            };
            if NOT_EXAMPLES
                .iter()
                .any(|(k, e, _)| *k == krate && *e == name)
            {
                continue;
            }
            if !EXAMPLES.iter().any(|(k, e, _)| *k == krate && *e == name)
                && !FEATURE_EXAMPLES
                    .iter()
                    .any(|(k, e, _, _)| *k == krate && *e == name)
            {
                bail!("{} is not listed in xtask's EXAMPLES", path.display());
            }
        }
    }
    let out = root().join("target").join("ci-examples");
    if out.exists() {
        std::fs::remove_dir_all(&out).with_context(|| format!("clearing {}", out.display()))?;
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let out = out.to_string_lossy();
    // The examples as the test step built them (`cargo test` builds every example, with the
    // adapters' features, which the examples behind a feature need too): cargo makes them
    // current and builds nothing right after that step. Then each binary runs. `cargo run -p`
    // would resolve each crate's features on its own and rebuild the dependencies for it, a
    // build without those features rebuilt every crate above object_store and parry (2.5
    // minutes), and `cargo build --examples` with them still compiled our crates again.
    for (krate, example, feature, _) in FEATURE_EXAMPLES {
        let needed = format!("{krate}/{feature}");
        if !crate::ci::ADAPTERS.split(',').any(|f| f == needed) {
            bail!("{krate}'s example {example} needs {needed}, which ADAPTERS does not turn on");
        }
    }
    cargo(
        &[
            "test",
            "--locked",
            "--workspace",
            "--features",
            crate::ci::ADAPTERS,
            "--no-run",
        ],
        &[],
    )?;
    let target = target_dir();
    let feature_examples = FEATURE_EXAMPLES.map(|(k, e, _, a)| (k, e, a));
    for (krate, example, args) in EXAMPLES.into_iter().chain(feature_examples) {
        let args: Vec<String> = args.iter().map(|a| a.replace("{out}", &out)).collect();
        let exe = target
            .join("debug")
            .join("examples")
            .join(format!("{example}{}", std::env::consts::EXE_SUFFIX));
        let status = Command::new(&exe)
            .args(&args)
            .current_dir(root())
            .status()
            .with_context(|| format!("could not start {krate}'s example {}", exe.display()))?;
        if !status.success() {
            bail!(
                "{krate}'s example `{example} {}` exited with {status}",
                args.join(" ")
            );
        }
    }
    Ok(())
}
