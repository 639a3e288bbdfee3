//! The terrain on the CPU: the procedural coarse-map the viewer starts from (the capture
//! demo's default terrain: terrain-core's generator, 0.1 m texels, heights 0 to 12 m), the
//! crater and footprint stamps. The map is never stamped: it follows the GPU's through the
//! readback (`app.rs`), so picking and the camera meet what the GPU map shows.

use anyhow::{Context, Result};
use glam::{UVec2, Vec2};
use terrain_core::io::{ReadLimits, decode_png8};
use terrain_core::{
    CoarseMap, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams, TextureStamp,
    generate_coarse_map,
};

/// Metres per texel (Flower 2010's 0.1 m, as the demo).
pub const TEXEL_SIZE: f32 = 0.1;
/// Heights the procedural terrain spans (metres).
pub const HEIGHT_RANGE: (f32, f32) = (0.0, 12.0);
/// The demo's footprint image: white where the foot presses hardest.
const FOOTPRINT_PNG: &[u8] = include_bytes!("../../../assets/footprint.png");
/// Footprint length along the view and width, and depth (metres): the demo's.
const FOOT_SIZE: Vec2 = Vec2::new(1.1, 0.45);
const FOOT_DEPTH: f32 = 0.12;
/// Crater diameter (metres); its depth is 0.3 times that, as the demo's craters.
const CRATER_SIZE: f32 = 6.0;

/// Which stamp a click presses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StampKind {
    Crater,
    Footprint,
}

impl StampKind {
    pub fn name(self) -> &'static str {
        match self {
            StampKind::Crater => "crater",
            StampKind::Footprint => "footprint",
        }
    }
}

/// The CPU map and the stamps.
#[derive(Debug)]
pub struct Terrain {
    pub map: CoarseMap,
    pub crater: GaussianStamp,
    pub footprint: TextureStamp,
}

impl Terrain {
    /// The procedural terrain of `size` x `size` texels from `seed`, with the demo's octaves
    /// (none finer than 16 texels) and gentle small scales.
    pub fn procedural(size: u32, seed: u64) -> Result<Self> {
        let encoding = HeightEncoding::spanning::<u16>(HEIGHT_RANGE.0, HEIGHT_RANGE.1)?;
        let defaults = TerrainParams::default();
        let cells = (size / 16 / defaults.base_period).max(1);
        let octaves = (u32::BITS - cells.leading_zeros()).clamp(1, defaults.octaves);
        let params = TerrainParams {
            size: UVec2::splat(size),
            seed,
            octaves,
            persistence: 0.4,
            ..defaults
        };
        let map = generate_coarse_map(&params, encoding, TEXEL_SIZE)
            .with_context(|| format!("generating a {size} x {size} terrain"))?;
        let image = decode_png8(FOOTPRINT_PNG, &ReadLimits::default())
            .context("the embedded footprint image")?;
        Ok(Self {
            map,
            crater: GaussianStamp::default(),
            footprint: TextureStamp::from_gray8(&image),
        })
    }

    /// Where a stamp of `kind` lands at `at` (metres, X Z), a footprint pointing along
    /// `heading` (radians, as the camera's yaw).
    pub fn placement(kind: StampKind, at: Vec2, heading: f32) -> Result<StampPlacement> {
        Ok(match kind {
            StampKind::Crater => {
                StampPlacement::new(at, Vec2::splat(CRATER_SIZE), -0.3 * CRATER_SIZE)?
            }
            StampKind::Footprint => {
                StampPlacement::new(at, FOOT_SIZE, -FOOT_DEPTH)?.with_rotation(heading)?
            }
        })
    }
}
