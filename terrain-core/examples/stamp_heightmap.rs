//! Load a heightmap (or generate one), stamp it with a Gaussian crater and a texture stamp,
//! and write the result as a 16-bit PNG plus a hillshade PNG.
//!
//! ```text
//! cargo run -p terrain-core --example stamp_heightmap -- [HEIGHTMAP] [--size N] [--out DIR]
//! ```
//!
//! - `HEIGHTMAP`: a 16-bit grayscale PNG, or a square RAW16 file (`.raw` / `.r16`,
//!   little-endian; its side is taken from the file length). Without it the procedural default
//!   terrain is generated, `--size` texels square (default 256).
//! - `--out DIR`: where `stamped.png` (16-bit heights) and `hillshade.png` go; default the
//!   system's temporary folder.
//!
//! The heights are read as 0 to 100 m over the 16-bit range at 1 m per texel: set your data's
//! own span and spacing in `ENCODING_SPAN_M` and `TEXEL_SIZE_M`.

use glam::{UVec2, Vec2};
use std::path::{Path, PathBuf};
use terrain_core::io::{self, ReadLimits};
use terrain_core::{
    Blend, CoarseMap, DerivativeMap, GaussianStamp, Grid, HeightEncoding, HillshadeParams,
    StampPlacement, TerrainParams, TextureStamp, apply_stamp, generate_heights, hillshade,
};

/// Metres of the lowest and highest 16-bit value.
const ENCODING_SPAN_M: (f32, f32) = (0.0, 100.0);
/// Metres per texel.
const TEXEL_SIZE_M: f32 = 1.0;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    let args = Args::parse()?;
    let encoding = HeightEncoding::spanning::<u16>(ENCODING_SPAN_M.0, ENCODING_SPAN_M.1)?;

    // 1. The map: loaded (PNG16 or RAW16), or the procedural default terrain.
    let mut map = match &args.heightmap {
        Some(path) => CoarseMap::coarse(read_heightmap(path)?, encoding, TEXEL_SIZE_M)?,
        None => {
            // Fewer, gentler octaves than the default, so the stamps stand out.
            let params = TerrainParams {
                size: UVec2::splat(args.size),
                octaves: 5,
                persistence: 0.4,
                ..TerrainParams::default()
            };
            // Heights in [0, 1], placed at 20..80 m: stamps have room before the 16-bit range
            // clamps them (`generate_coarse_map` would span the whole range).
            let heights = generate_heights(&params)?;
            let grid = heights.map(|h| encoding.to_raw(20.0 + 60.0 * h).round() as u16);
            CoarseMap::coarse(grid, encoding, TEXEL_SIZE_M)?
        }
    };
    let mut normals = DerivativeMap::from_map(&map);
    let extent = map.extent_m();
    println!("map: {} texels, {} m", map.size(), extent);

    // 2. A Gaussian crater, a third of the map wide and 25 m deep, in the middle.
    let mut crater = GaussianStamp::default();
    let placement = StampPlacement::new(extent * 0.5, extent / 3.0, -25.0)?;
    let mut dirty = apply_stamp(&mut map, &mut crater, &placement, Blend::Add)?;

    // 3. A texture stamp: a ring (an 8-bit image, white = full effect; a real one would come
    //    from `io::read_png8`), 10 m high, rotated 30°, across the map's corner: the map wraps,
    //    so it lands in four pieces.
    let ring = Grid::from_fn(64, 64, |x, y| {
        let r = (Vec2::new(x as f32, y as f32) - 31.5).length() / 32.0;
        (255.0 * (1.0 - ((r - 0.7) / 0.2).powi(2)).max(0.0)) as u8
    })?;
    let mut ring = TextureStamp::from_gray8(&ring);
    let placement = StampPlacement::new(Vec2::ZERO, extent * 0.3, 10.0)?.with_rotation(0.52)?;
    dirty.extend(apply_stamp(&mut map, &mut ring, &placement, Blend::Add)?);

    // 4. Normals follow the dirty rects only.
    for rect in &dirty {
        normals.update_rect(&map, *rect)?;
    }
    let texels: u64 = dirty.iter().map(|r| r.area()).sum();
    println!("stamped {} rects, {texels} texels", dirty.len());

    // 5. The heights as a 16-bit PNG and a hillshade of them.
    std::fs::create_dir_all(&args.out)?;
    let heights = args.out.join("stamped.png");
    io::write_png16(&heights, map.grid())?;
    let shade = hillshade(&map, &normals, &HillshadeParams::with_size(map.size()))?;
    let image = args.out.join("hillshade.png");
    io::write_png_rgba8(&image, &shade)?;
    println!("wrote {} and {}", heights.display(), image.display());
    Ok(())
}

/// A 16-bit PNG, or a square RAW16 file whose side follows from its length.
fn read_heightmap(path: &Path) -> Result<Grid<u16>> {
    let limits = ReadLimits::default();
    let raw = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("raw") || e.eq_ignore_ascii_case("r16"));
    if !raw {
        return Ok(io::read_png16(path, &limits)?);
    }
    let samples = std::fs::metadata(path)?.len() / 2;
    let side = samples.isqrt();
    if side * side != samples || side == 0 || side > u64::from(limits.max_side) {
        return Err(format!("{}: not a square RAW16 file", path.display()).into());
    }
    Ok(io::read_raw16(path, UVec2::splat(side as u32), &limits)?)
}

/// The command line.
struct Args {
    heightmap: Option<PathBuf>,
    size: u32,
    out: PathBuf,
}

impl Args {
    fn parse() -> Result<Self> {
        let mut args = Args {
            heightmap: None,
            size: 256,
            out: std::env::temp_dir(),
        };
        let mut it = std::env::args().skip(1);
        while let Some(arg) = it.next() {
            match arg.as_str() {
                "--size" => args.size = it.next().ok_or("--size needs a value")?.parse()?,
                "--out" => args.out = it.next().ok_or("--out needs a folder")?.into(),
                _ if arg.starts_with("--") => return Err(format!("unknown option {arg}").into()),
                _ => args.heightmap = Some(arg.into()),
            }
        }
        Ok(args)
    }
}
