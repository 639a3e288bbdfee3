//! `cargo xtask golden`: regenerates the render test's golden image on this machine's adapter
//! (never done by the tests themselves, so a test cannot bless its own output).

use crate::util::{cargo, root};
use anyhow::Result;

/// Regenerates `terrain-gpu/tests/data/golden_clipmap.png` on this machine's adapter.
pub fn golden() -> Result<()> {
    let path = root().join("terrain-gpu/tests/data/golden_clipmap.png");
    cargo(
        &[
            "run",
            "--locked",
            "-p",
            "terrain-gpu",
            "--example",
            "golden",
            "--",
            &path.to_string_lossy(),
        ],
        &[],
    )
}
