//! The seeds of the decoder targets: small valid inputs, made by the crates' own encoders and
//! by the tests' independent ones (PNG: [`crate::png_encoder`], GeoTIFF: [`crate::tiff`]), the
//! same every time. `cargo xtask fuzz --engine libfuzzer` writes them out as the start of each
//! libFuzzer corpus, and the harness's classes mutate them.

use super::world::{seed_tile, world_of};
use crate::fuzz::Rng;
use crate::png_encoder::Image;
use crate::tiff::{Layout, Sample, TiffSpec};
use glam::UVec2;
use terrain_cache::manifest::DetailLayout;
use terrain_cache::tile_file::{self, TileCodec};
use terrain_cache::{LevelBounds, Manifest, TileFormat};
use terrain_core::io::{DEFAULT_MAX_SIDE, encode_png_rgba8, encode_png8, encode_png16};
use terrain_core::{Grid, HeightEncoding, WrapMode};

/// A `w` x `h` grid of values from `f(x, y)`.
fn grid<T: Copy>(w: u32, h: u32, f: impl Fn(u32, u32) -> T) -> Grid<T> {
    let v = (0..w * h).map(|i| f(i % w, i / w)).collect();
    Grid::from_vec(w, h, v).expect("a small grid")
}

/// Files of the independent PNG encoder in one format, at a few sizes (interlacing, filters
/// and stored block sizes drawn from a fixed seed).
fn independent_pngs(color_type: u8, bit_depth: u8) -> Vec<Vec<u8>> {
    let mut rng = Rng::new(0x5eed_0000 + u64::from(color_type) * 17 + u64::from(bit_depth));
    [(7, 5), (1, 9), (33, 2), (8, 8)]
        .into_iter()
        .map(|(w, h)| Image::random(&mut rng, w, h, color_type, bit_depth).encode(&mut rng))
        .collect()
}

/// 16-bit gray PNGs: terrain-core's encoder (compressed) and the independent one.
pub(super) fn png16() -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<u8>> = [
        grid(1, 1, |_, _| 0u16),
        grid(5, 3, |x, y| (x * 4000 + y * 300) as u16),
        grid(16, 16, |x, y| ((x * 7919) ^ (y * 104_729)) as u16),
    ]
    .iter()
    .map(|g| encode_png16(g).expect("encoding a seed"))
    .collect();
    out.extend(independent_pngs(0, 16));
    out
}

/// 8-bit gray and RGBA8 PNGs from both encoders.
pub(super) fn png8() -> Vec<Vec<u8>> {
    let mut out = vec![
        encode_png8(&grid(4, 4, |x, y| (x * 60 + y) as u8)).expect("encoding a seed"),
        encode_png8(&grid(13, 7, |x, y| ((x * 31) ^ (y * 97)) as u8)).expect("encoding a seed"),
        encode_png_rgba8(&grid(3, 5, |x, y| [x as u8, y as u8, 200, 255])).expect("encoding"),
    ];
    out.extend(independent_pngs(0, 8));
    out.extend(independent_pngs(6, 8));
    out
}

/// The headerless targets' parameters (see `raw16`) in front of `samples`.
fn raw_input(size: UVec2, max_side: u32, big: bool, samples: Vec<u8>) -> Vec<u8> {
    let mut out = Vec::with_capacity(13 + samples.len());
    for v in [size.x, size.y, max_side] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.push(u8::from(big));
    out.extend(samples);
    out
}

/// RAW16 samples at three sizes, both byte orders.
pub(super) fn raw16() -> Vec<Vec<u8>> {
    let mut rng = Rng::new(0x5eed_0016);
    [(1, 1, false), (4, 3, false), (5, 2, true)]
        .into_iter()
        .map(|(w, h, big)| {
            let samples = rng.bytes(2 * (w * h) as usize);
            raw_input(UVec2::new(w, h), DEFAULT_MAX_SIDE, big, samples)
        })
        .collect()
}

/// R32 heights at three sizes, both byte orders, with NaN, infinite and huge samples (kept as
/// they are: the DEM import treats them as nodata).
pub(super) fn r32() -> Vec<Vec<u8>> {
    let values = [
        0.0f32,
        -0.0,
        1.5,
        -412.25,
        8848.86,
        f32::NAN,
        f32::INFINITY,
        1e30,
    ];
    [(1, 1, false), (4, 2, false), (2, 4, true)]
        .into_iter()
        .map(|(w, h, big)| {
            let samples = (0..w * h)
                .flat_map(|i| {
                    let v = values[i as usize % values.len()];
                    if big {
                        v.to_be_bytes()
                    } else {
                        v.to_le_bytes()
                    }
                })
                .collect();
            raw_input(UVec2::new(w, h), 64, big, samples)
        })
        .collect()
}

/// GeoTIFF DEMs of the tests' TIFF writer: several sample types, strips and tiles, both byte
/// orders, classic and BigTIFF, georeferenced or not, one with a nodata value.
pub(super) fn geotiff() -> Vec<Vec<u8>> {
    let mut rng = Rng::new(0x5eed_0717);
    let mut spec = |w: u32, h: u32, sample: Sample| {
        let values = (0..w * h)
            .map(|_| rng.uniform(0.0, 120.0).round())
            .collect();
        TiffSpec::new(w, h, sample, values)
    };
    let georeferenced = |s: TiffSpec| TiffSpec {
        pixel_scale: Some([30.0, 30.0, 0.0]),
        tiepoint: Some([0.0, 0.0, 0.0, 440_720.0, 3_751_320.0, 0.0]),
        geokeys: vec![(1024, 1), (3076, 9001)],
        ..s
    };
    let mut with_nodata = spec(6, 5, Sample::F32);
    with_nodata.values[7] = -9999.0;
    let specs = [
        georeferenced(spec(5, 4, Sample::U16)),
        TiffSpec {
            layout: Layout::Strips(2),
            big_endian: true,
            ..spec(7, 3, Sample::I16)
        },
        TiffSpec {
            layout: Layout::Tiles(16, 16),
            ..georeferenced(spec(18, 17, Sample::F32))
        },
        TiffSpec {
            bigtiff: true,
            ..spec(3, 3, Sample::F64)
        },
        TiffSpec {
            bigtiff: true,
            big_endian: true,
            layout: Layout::Tiles(16, 16),
            ..spec(4, 2, Sample::U8)
        },
        TiffSpec {
            nodata: Some("-9999".into()),
            ..with_nodata
        },
        spec(2, 2, Sample::I32),
    ];
    specs.iter().map(TiffSpec::write).collect()
}

/// Manifests: a plain world, a small wrapped one with a detail layer and fewer levels, and a
/// version-1 world of PNG tiles.
pub(super) fn manifest() -> Vec<Vec<u8>> {
    let enc = HeightEncoding::spanning::<u16>(-100.0, 2000.0).expect("encoding");
    let plain =
        Manifest::new(UVec2::new(1000, 700), 256, 1.0, enc, WrapMode::Clamp).expect("a manifest");
    let mut small = Manifest::new(UVec2::new(100, 70), 32, 0.5, enc, WrapMode::Repeat)
        .expect("a small manifest");
    small.levels = 2;
    small.height_fill = 1234;
    small.generation = 7;
    small.detail =
        Some(DetailLayout::covering(small.extent_m().as_vec2(), 64, 0.1).expect("detail"));
    let mut png = plain;
    png.tile_format = TileFormat::Png;
    png.format_version = TileFormat::Png.format_version();
    [plain, small, png]
        .iter()
        .map(|m| m.to_json().into_bytes())
        .collect()
}

/// Bounds files of 1x1, 3x2 and 5x5 tiles after their tile counts.
pub(super) fn bounds() -> Vec<Vec<u8>> {
    let mut rng = Rng::new(0x5eed_b0d5);
    [(1, 1), (3, 2), (5, 5)]
        .into_iter()
        .map(|(x, y)| {
            let mut b = LevelBounds::empty(UVec2::new(x, y));
            for mm in &mut b.min_max {
                let (lo, hi) = (rng.next_u32() as u16, rng.next_u32() as u16);
                *mm = [lo.min(hi), lo.max(hi)];
            }
            let mut out = [x.to_le_bytes(), y.to_le_bytes()].concat();
            out.extend(b.to_bytes());
            out
        })
        .collect()
}

/// Tile files of both layers: `.tile` files with either codec and PNG tiles, of sides 16 and
/// 32, each after its parameter byte.
pub(super) fn tile() -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    // Bits 2-3 pick the side: 0 for 16, 1 for 32.
    for (p, seed) in [
        (0u8, 1u64),
        (1, 2),
        (2, 3),
        (3, 4),
        (4, 6),
        (5, 5),
        (6, 8),
        (7, 9),
    ] {
        let (world, layer) = world_of(p);
        let data = seed_tile(world, layer, seed);
        if world.manifest().tile_format == TileFormat::Tile {
            let codec = if seed % 2 == 1 {
                TileCodec::Raw
            } else {
                TileCodec::Lz4
            };
            out.push([vec![p], tile_file::encode(&data, codec)].concat());
        } else {
            let bytes = world.encode_tile(layer, &data).expect("encoding a seed");
            out.push([vec![p], bytes].concat());
        }
    }
    out
}
