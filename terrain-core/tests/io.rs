//! Integration tests of terrain-core's map I/O: PNG 8/16-bit, RGBA8 and RAW16 round trips,
//! interlaced PNGs built by an independent encoder, every bad-input error variant, fuzzing with
//! proptest, and atomic writes.

use glam::UVec2;
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use terrain_core::Grid;
use terrain_core::io::{
    DEFAULT_MAX_SIDE, GrayImage, MapIoError, ReadLimits, decode_png, decode_png8, decode_png16,
    decode_raw16, encode_png_rgba8, encode_png8, encode_png16, encode_raw16, read_png,
    read_png_size, read_png8, read_png16, read_raw16, write_atomic, write_png_rgba8, write_png8,
    write_png16, write_raw16,
};

// ---------------------------------------------------------------------------------------------
// Helpers: test images, a tiny independent PNG writer, temp dirs

const SIZES: [(u32, u32); 7] = [
    (1, 1),
    (3, 7),
    (7, 3),
    (1, 300),
    (64, 64),
    (257, 129),
    (100, 1),
];

fn pattern16(x: u32, y: u32) -> u16 {
    (x.wrapping_mul(7919).wrapping_add(y.wrapping_mul(104729))) as u16
}

fn pattern8(x: u32, y: u32) -> u8 {
    (x.wrapping_mul(31).wrapping_add(y.wrapping_mul(17)) ^ (x * y)) as u8
}

fn grid16(w: u32, h: u32) -> Grid<u16> {
    Grid::from_fn(w, h, pattern16).unwrap()
}

fn grid8(w: u32, h: u32) -> Grid<u8> {
    Grid::from_fn(w, h, pattern8).unwrap()
}

#[path = "io/png_writer.rs"]
mod png_writer;
use png_writer::{adam7_scanlines, build_png, find_chunk, patch_ihdr_size, scanlines};
use terrain_test_support::png::{crc32, fix_crcs};

/// A fresh directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos();
        let dir = std::env::temp_dir().join(format!(
            "terrain-core-io-test-{}-{name}-{nanos}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }

    fn path(&self) -> &Path {
        &self.0
    }

    fn entries(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(&self.0)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn limits() -> ReadLimits {
    ReadLimits::default()
}

// ---------------------------------------------------------------------------------------------
// Round trips

#[test]
fn png16_round_trips_all_sizes() {
    for (w, h) in SIZES {
        let g = grid16(w, h);
        let bytes = encode_png16(&g).unwrap();
        assert_eq!(decode_png16(&bytes, &limits()).unwrap(), g, "{w}x{h}");
        assert_eq!(
            decode_png(&bytes, &limits()).unwrap(),
            GrayImage::Gray16(g),
            "{w}x{h}"
        );
    }
    // The extremes of the range survive (no scaling, no sign or byte order slip).
    let g = Grid::from_vec(4, 1, vec![0u16, 1, 0x8000, u16::MAX]).unwrap();
    assert_eq!(
        decode_png16(&encode_png16(&g).unwrap(), &limits()).unwrap(),
        g
    );
}

#[test]
fn png8_round_trips_all_sizes() {
    for (w, h) in SIZES {
        let g = grid8(w, h);
        let bytes = encode_png8(&g).unwrap();
        assert_eq!(decode_png8(&bytes, &limits()).unwrap(), g, "{w}x{h}");
        let img = decode_png(&bytes, &limits()).unwrap();
        assert_eq!(img.bit_depth(), 8);
        assert_eq!(img.size(), UVec2::new(w, h));
        assert_eq!(img, GrayImage::Gray8(g), "{w}x{h}");
    }
}

#[test]
fn rgba8_round_trips_through_an_independent_decoder() {
    for (w, h) in SIZES {
        let g = Grid::from_fn(w, h, |x, y| {
            [
                pattern8(x, y),
                pattern8(y, x),
                (x ^ y) as u8,
                (x + 3 * y) as u8,
            ]
        })
        .unwrap();
        let bytes = encode_png_rgba8(&g).unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(&bytes))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (w, h));
        assert_eq!(info.color_type, png::ColorType::Rgba);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        assert_eq!(buf, bytemuck::cast_slice::<[u8; 4], u8>(g.as_slice()));
        // A map reader refuses it: it is colour.
        assert!(matches!(
            decode_png(&bytes, &limits()),
            Err(MapIoError::NotGrayscale { .. })
        ));
    }
}

#[test]
fn raw16_round_trips_all_sizes_little_endian() {
    for (w, h) in SIZES {
        let g = grid16(w, h);
        let bytes = encode_raw16(&g);
        assert_eq!(bytes.len(), (w * h * 2) as usize);
        assert_eq!(
            decode_raw16(&bytes, UVec2::new(w, h), &limits()).unwrap(),
            g,
            "{w}x{h}"
        );
    }
    // Layout: little-endian, row-major.
    let g = Grid::from_vec(2, 2, vec![0x0102u16, 0x0304, 0x0506, 0xA0B0]).unwrap();
    assert_eq!(encode_raw16(&g), vec![2, 1, 4, 3, 6, 5, 0xB0, 0xA0]);
    let bytes = [1u8, 0, 0, 1, 0xFF, 0xFF];
    let d = decode_raw16(&bytes, UVec2::new(3, 1), &limits()).unwrap();
    assert_eq!(d.as_slice(), &[1, 256, u16::MAX]);
    let d = decode_raw16(&bytes, UVec2::new(1, 3), &limits()).unwrap();
    assert_eq!(d.as_slice(), &[1, 256, u16::MAX]);
}

#[test]
fn encoded_png16_stores_big_endian_gray16() {
    let g = Grid::from_vec(2, 1, vec![0x1234u16, 0xABCD]).unwrap();
    let bytes = encode_png16(&g).unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(&bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Grayscale);
    assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
    assert!(!reader.info().interlaced);
    assert_eq!(buf, vec![0x12, 0x34, 0xAB, 0xCD]);
}

#[test]
fn hand_built_pngs_decode_to_their_samples() {
    for (w, h) in [(1, 1), (3, 7), (257, 129)] {
        let png16 = build_png(w, h, 16, 0, false, &[], &scanlines(w, h, 16, pattern16));
        assert_eq!(decode_png16(&png16, &limits()).unwrap(), grid16(w, h));
        let png8 = build_png(
            w,
            h,
            8,
            0,
            false,
            &[],
            &scanlines(w, h, 8, |x, y| u16::from(pattern8(x, y))),
        );
        assert_eq!(decode_png8(&png8, &limits()).unwrap(), grid8(w, h));
    }
}

#[test]
fn interlaced_pngs_decode_correctly() {
    // Sizes that leave some Adam7 passes empty (1x1, 2x1, 1x5) and some partial.
    for (w, h) in [
        (1, 1),
        (2, 1),
        (1, 5),
        (3, 7),
        (8, 8),
        (9, 10),
        (33, 17),
        (257, 129),
    ] {
        let png16 = build_png(
            w,
            h,
            16,
            0,
            true,
            &[],
            &adam7_scanlines(w, h, 16, pattern16),
        );
        assert_eq!(
            decode_png16(&png16, &limits()).unwrap(),
            grid16(w, h),
            "16-bit {w}x{h}"
        );
        let f8 = |x, y| u16::from(pattern8(x, y));
        let png8 = build_png(w, h, 8, 0, true, &[], &adam7_scanlines(w, h, 8, f8));
        assert_eq!(
            decode_png8(&png8, &limits()).unwrap(),
            grid8(w, h),
            "8-bit {w}x{h}"
        );
    }
}

#[test]
fn file_round_trips_through_a_temp_dir() {
    let dir = TempDir::new("roundtrip");
    for (w, h) in [(1, 1), (3, 7), (257, 129)] {
        let g16 = grid16(w, h);
        let g8 = grid8(w, h);
        let p16 = dir.path().join(format!("coarse_{w}x{h}.png"));
        let p8 = dir.path().join(format!("detail_{w}x{h}.png"));
        let praw = dir.path().join(format!("coarse_{w}x{h}.r16"));
        let prgba = dir.path().join(format!("frame_{w}x{h}.png"));

        write_png16(&p16, &g16).unwrap();
        assert_eq!(read_png16(&p16, &limits()).unwrap(), g16);
        assert_eq!(
            read_png(&p16, &limits()).unwrap(),
            GrayImage::Gray16(g16.clone())
        );

        write_png8(&p8, &g8).unwrap();
        assert_eq!(read_png8(&p8, &limits()).unwrap(), g8);
        assert_eq!(
            read_png(&p8, &limits()).unwrap(),
            GrayImage::Gray8(g8.clone())
        );

        write_raw16(&praw, &g16).unwrap();
        assert_eq!(std::fs::read(&praw).unwrap(), encode_raw16(&g16));
        assert_eq!(read_raw16(&praw, UVec2::new(w, h), &limits()).unwrap(), g16);

        let rgba = g8.map(|&v| [v, v / 2, 255 - v, 255]);
        write_png_rgba8(&prgba, &rgba).unwrap();
        assert_eq!(
            std::fs::read(&prgba).unwrap(),
            encode_png_rgba8(&rgba).unwrap()
        );
    }
    // Only the targets exist: no temp files were left behind.
    assert_eq!(dir.entries().len(), 12, "{:?}", dir.entries());
    assert!(
        dir.entries().iter().all(|n| !n.starts_with('.')),
        "{:?}",
        dir.entries()
    );
}

// ---------------------------------------------------------------------------------------------
// Bad input: each case has its own error variant

#[test]
fn colour_palette_and_alpha_pngs_are_not_grayscale() {
    let (w, h) = (3u32, 2u32);
    let rgb = build_png(w, h, 8, 2, false, &[], &[0u8; 20]);
    let palette_plte = [0u8, 0, 0, 255, 255, 255];
    let palette = build_png(w, h, 8, 3, false, &[(b"PLTE", &palette_plte)], &[0u8; 8]);
    let gray_alpha = build_png(w, h, 8, 4, false, &[], &[0u8; 14]);
    let gray_alpha16 = build_png(w, h, 16, 4, false, &[], &[0u8; 26]);
    let rgba = build_png(w, h, 8, 6, false, &[], &[0u8; 26]);
    for (name, bytes, word) in [
        ("rgb", rgb, "RGB"),
        ("palette", palette, "palette"),
        ("gray+alpha", gray_alpha, "alpha"),
        ("gray+alpha 16", gray_alpha16, "alpha"),
        ("rgba", rgba, "RGBA"),
    ] {
        for r in [
            decode_png(&bytes, &limits()).map(|_| ()),
            decode_png16(&bytes, &limits()).map(|_| ()),
            decode_png8(&bytes, &limits()).map(|_| ()),
        ] {
            match r {
                Err(MapIoError::NotGrayscale { color_type }) => {
                    assert!(color_type.contains(word), "{name}: {color_type}")
                }
                other => panic!("{name}: expected NotGrayscale, got {other:?}"),
            }
        }
    }
    // The same files are valid PNGs: a real encoder's RGB output is refused the same way.
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, 2, 2);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut wr = enc.write_header().unwrap();
    wr.write_image_data(&[7u8; 12]).unwrap();
    wr.finish().unwrap();
    assert!(matches!(
        decode_png(&out, &limits()),
        Err(MapIoError::NotGrayscale { .. })
    ));
}

#[test]
fn wrong_bit_depth_is_reported_both_ways() {
    let p8 = encode_png8(&grid8(5, 4)).unwrap();
    let p16 = encode_png16(&grid16(5, 4)).unwrap();
    assert!(matches!(
        decode_png16(&p8, &limits()),
        Err(MapIoError::WrongBitDepth {
            expected: 16,
            found: 8
        })
    ));
    assert!(matches!(
        decode_png8(&p16, &limits()),
        Err(MapIoError::WrongBitDepth {
            expected: 8,
            found: 16
        })
    ));
    let dir = TempDir::new("bitdepth");
    let f8 = dir.path().join("eight.png");
    std::fs::write(&f8, &p8).unwrap();
    assert!(matches!(
        read_png16(&f8, &limits()),
        Err(MapIoError::WrongBitDepth {
            expected: 16,
            found: 8
        })
    ));
    let f16 = dir.path().join("sixteen.png");
    std::fs::write(&f16, &p16).unwrap();
    assert!(matches!(
        read_png8(&f16, &limits()),
        Err(MapIoError::WrongBitDepth {
            expected: 8,
            found: 16
        })
    ));
}

#[test]
fn low_bit_depth_grayscale_is_unsupported() {
    let (w, h) = (9u32, 3u32);
    for bits in [1u8, 2, 4] {
        let row_bytes = (w * u32::from(bits)).div_ceil(8) as usize;
        let mut lines = Vec::new();
        for _ in 0..h {
            lines.push(0);
            lines.extend(std::iter::repeat_n(0xA5u8, row_bytes));
        }
        let bytes = build_png(w, h, bits, 0, false, &[], &lines);
        for r in [
            decode_png(&bytes, &limits()).map(|_| ()),
            decode_png16(&bytes, &limits()).map(|_| ()),
            decode_png8(&bytes, &limits()).map(|_| ()),
        ] {
            match r {
                Err(MapIoError::UnsupportedBitDepth { bits: b }) => assert_eq!(b, bits),
                other => panic!("{bits}-bit: expected UnsupportedBitDepth, got {other:?}"),
            }
        }
    }
}

#[test]
fn truncated_pngs_are_errors_at_every_cut() {
    let g = grid16(13, 11);
    let full = encode_png16(&g).unwrap();
    let iend = find_chunk(&full, b"IEND");
    let idat = find_chunk(&full, b"IDAT");
    for cut in 0..full.len() {
        match decode_png16(&full[..cut], &limits()) {
            Err(MapIoError::Truncated { .. }) | Err(MapIoError::Corrupt { .. }) => {}
            Ok(decoded) => {
                // Only a missing trailer may be tolerated, and only with the exact pixels.
                assert!(cut >= iend, "cut at {cut} (IEND at {iend}) decoded");
                assert_eq!(decoded, g);
            }
            Err(other) => panic!("cut at {cut}: unexpected {other:?}"),
        }
    }
    // Specific places: inside the signature, inside IHDR, inside IDAT, just before IEND.
    for (cut, word) in [
        (4, "signature"),
        (20, "IHDR"),
        (idat + 20, "IDAT"),
        (iend, "IEND"),
    ] {
        match decode_png16(&full[..cut], &limits()) {
            Err(MapIoError::Truncated { reason }) => {
                assert!(reason.contains(word), "cut at {cut}: {reason}")
            }
            other => panic!("cut at {cut}: expected Truncated, got {other:?}"),
        }
    }
    assert!(matches!(
        decode_png(&[], &limits()),
        Err(MapIoError::Truncated { .. })
    ));
}

#[test]
fn flipped_bytes_fail_the_crc() {
    let full = encode_png16(&grid16(13, 11)).unwrap();
    let idat = find_chunk(&full, b"IDAT");
    let iend = find_chunk(&full, b"IEND");
    // A byte of IHDR data, of the IHDR CRC, of the IDAT CRC, and of the IEND CRC: the CRC
    // check names the chunk.
    for at in [18, 25, 30, iend - 1, iend + 9] {
        let mut bad = full.clone();
        bad[at] ^= 0x40;
        match decode_png16(&bad, &limits()) {
            Err(MapIoError::Corrupt { reason }) => {
                assert!(reason.to_lowercase().contains("crc"), "byte {at}: {reason}")
            }
            other => panic!("byte {at}: expected Corrupt, got {other:?}"),
        }
    }
    // Bytes of IDAT data are decompressed as they stream in, so the deflate decoder may be
    // the first to notice; either way the file is corrupt, never Ok.
    for at in [idat + 10, idat + 8 + 3, idat + 30] {
        let mut bad = full.clone();
        bad[at] ^= 0x40;
        assert!(
            matches!(
                decode_png16(&bad, &limits()),
                Err(MapIoError::Corrupt { .. })
            ),
            "byte {at}"
        );
    }
    // A bad signature is corrupt too.
    let mut bad = full.clone();
    bad[1] = b'X';
    assert!(matches!(
        decode_png(&bad, &limits()),
        Err(MapIoError::Corrupt { .. })
    ));
    // Bad zlib data behind a valid CRC.
    let mut bad = full.clone();
    bad[idat + 8] ^= 0xFF; // the zlib header
    fix_crcs(&mut bad);
    assert!(matches!(
        decode_png(&bad, &limits()),
        Err(MapIoError::Corrupt { .. })
    ));
}

#[test]
fn oversized_header_is_rejected_before_decoding() {
    let small = encode_png16(&grid16(4, 4)).unwrap();
    let header_end = 33; // signature + IHDR chunk
    for (w, h) in [
        (20000, 20000),
        (20000, 1),
        (1, 20000),
        (u32::MAX >> 1, u32::MAX >> 1),
    ] {
        let mut big = small.clone();
        patch_ihdr_size(&mut big, w, h);
        // The pixel data is only 4x4: had the decoder gone on past the header, it would
        // report missing data, not the size.
        for bytes in [&big[..], &big[..header_end]] {
            match decode_png(bytes, &limits()) {
                Err(MapIoError::TooLarge {
                    width,
                    height,
                    max_side,
                }) => assert_eq!((width, height, max_side), (w, h, DEFAULT_MAX_SIDE)),
                other => panic!("{w}x{h}: expected TooLarge, got {other:?}"),
            }
        }
        assert!(matches!(
            decode_png16(&big, &limits()),
            Err(MapIoError::TooLarge { .. })
        ));
    }
    // A custom limit applies to each side, inclusive.
    let tight = ReadLimits {
        max_side: 8,
        ..ReadLimits::default()
    };
    let ok = encode_png8(&grid8(8, 8)).unwrap();
    assert_eq!(decode_png8(&ok, &tight).unwrap(), grid8(8, 8));
    let wide = encode_png8(&grid8(9, 3)).unwrap();
    assert!(matches!(
        decode_png8(&wide, &tight),
        Err(MapIoError::TooLarge {
            width: 9,
            height: 3,
            max_side: 8
        })
    ));
    // A sample limit applies to the product, inclusive (a long thin image within the sides).
    let counted = ReadLimits {
        max_samples: 64,
        ..ReadLimits::default()
    };
    assert_eq!(decode_png8(&ok, &counted).unwrap(), grid8(8, 8));
    for (w, h) in [(65, 1), (9, 8), (1, 65)] {
        assert!(matches!(
            decode_png8(&encode_png8(&grid8(w, h)).unwrap(), &counted),
            Err(MapIoError::TooManySamples {
                max_samples: 64,
                ..
            })
        ));
    }
    // A file on disk too.
    let dir = TempDir::new("toolarge");
    let p = dir.path().join("big.png");
    let mut big = small.clone();
    patch_ihdr_size(&mut big, 20000, 20000);
    std::fs::write(&p, &big).unwrap();
    assert!(matches!(
        read_png16(&p, &limits()),
        Err(MapIoError::TooLarge { .. })
    ));
}

#[test]
fn zero_size_is_reported() {
    let mut png = encode_png8(&grid8(4, 4)).unwrap();
    patch_ihdr_size(&mut png, 0, 5);
    assert!(matches!(
        decode_png(&png, &limits()),
        Err(MapIoError::ZeroSize {
            width: 0,
            height: 5
        })
    ));
    for size in [UVec2::new(0, 0), UVec2::new(0, 5), UVec2::new(5, 0)] {
        match decode_raw16(&[], size, &limits()) {
            Err(MapIoError::ZeroSize { width, height }) => {
                assert_eq!(UVec2::new(width, height), size)
            }
            other => panic!("{size}: expected ZeroSize, got {other:?}"),
        }
    }
}

#[test]
fn raw16_of_wrong_length_is_a_size_mismatch() {
    let size = UVec2::new(3, 7);
    for len in [0usize, 2, 41, 43, 44, 84] {
        match decode_raw16(&vec![0u8; len], size, &limits()) {
            Err(MapIoError::RawSizeMismatch {
                width: 3,
                height: 7,
                expected_bytes: 42,
                actual_bytes,
            }) => assert_eq!(actual_bytes, len as u64),
            other => panic!("{len} bytes: expected RawSizeMismatch, got {other:?}"),
        }
    }
    // An odd byte count can never be u16 samples, even for a size it almost matches.
    assert!(matches!(
        decode_raw16(&[1, 2, 3], UVec2::new(1, 1), &limits()),
        Err(MapIoError::RawSizeMismatch {
            expected_bytes: 2,
            actual_bytes: 3,
            ..
        })
    ));
    // Sizes over the limit are refused before the length is even looked at.
    assert!(matches!(
        decode_raw16(&[], UVec2::new(DEFAULT_MAX_SIDE + 1, 1), &limits()),
        Err(MapIoError::TooLarge { .. })
    ));
    assert!(matches!(
        decode_raw16(
            &[],
            UVec2::new(u32::MAX, u32::MAX),
            &ReadLimits {
                max_side: u32::MAX,
                ..ReadLimits::default()
            }
        ),
        Err(MapIoError::TooLarge { .. }) | Err(MapIoError::RawSizeMismatch { .. })
    ));

    // From a file: the length comes from the metadata.
    let dir = TempDir::new("rawsize");
    let p = dir.path().join("short.r16");
    std::fs::write(&p, [0u8; 41]).unwrap();
    assert!(matches!(
        read_raw16(&p, size, &limits()),
        Err(MapIoError::RawSizeMismatch {
            expected_bytes: 42,
            actual_bytes: 41,
            ..
        })
    ));
    assert!(matches!(
        read_raw16(&p, UVec2::new(0, 7), &limits()),
        Err(MapIoError::ZeroSize { .. })
    ));
}

#[test]
fn missing_files_are_io_errors_with_the_path() {
    let dir = TempDir::new("missing");
    let p = dir.path().join("does_not_exist.png");
    let shown = p.display().to_string();
    let results = [
        read_png(&p, &limits()).map(|_| ()),
        read_png16(&p, &limits()).map(|_| ()),
        read_png8(&p, &limits()).map(|_| ()),
        read_raw16(&p, UVec2::new(2, 2), &limits()).map(|_| ()),
    ];
    for r in results {
        match r {
            Err(e @ MapIoError::Io { .. }) => {
                assert!(e.to_string().contains(&shown), "{e}");
                let MapIoError::Io { path, source } = e else {
                    unreachable!()
                };
                assert_eq!(path, p);
                assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
            }
            other => panic!("expected Io, got {other:?}"),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Atomic writes

#[test]
fn write_atomic_replaces_an_existing_file() {
    let dir = TempDir::new("atomic-replace");
    let p = dir.path().join("map.r16");
    write_atomic(&p, b"old content that is longer").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"old content that is longer");
    write_atomic(&p, b"new").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"new");
    write_atomic(&p, b"").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"");
    assert_eq!(dir.entries(), vec!["map.r16".to_owned()]);
}

#[test]
fn write_atomic_into_a_missing_directory_fails_and_leaves_nothing() {
    let dir = TempDir::new("atomic-missing");
    let missing = dir.path().join("no_such_dir");
    let p = missing.join("map.png");
    match write_atomic(&p, b"data") {
        Err(e @ MapIoError::Io { .. }) => {
            assert!(e.to_string().contains(&p.display().to_string()), "{e}")
        }
        other => panic!("expected Io, got {other:?}"),
    }
    assert!(!missing.exists());
    assert!(dir.entries().is_empty(), "{:?}", dir.entries());
    assert!(matches!(
        write_png16(&p, &grid16(2, 2)),
        Err(MapIoError::Io { .. })
    ));
    assert!(dir.entries().is_empty(), "{:?}", dir.entries());
}

#[test]
fn write_atomic_leaves_no_temp_files() {
    let dir = TempDir::new("atomic-clean");
    for i in 0..5 {
        write_atomic(dir.path().join("a.bin"), &[i; 100]).unwrap();
        write_atomic(dir.path().join("b.bin"), &[i; 10]).unwrap();
    }
    assert_eq!(dir.entries(), vec!["a.bin".to_owned(), "b.bin".to_owned()]);
    assert_eq!(
        std::fs::read(dir.path().join("a.bin")).unwrap(),
        vec![4u8; 100]
    );
}

#[test]
fn failed_rename_removes_the_temp_file_and_keeps_the_target() {
    // The target is a non-empty directory: the temp file is written, the rename fails.
    let dir = TempDir::new("atomic-rename");
    let target = dir.path().join("occupied");
    std::fs::create_dir(&target).unwrap();
    std::fs::write(target.join("keep.txt"), b"keep").unwrap();
    assert!(matches!(
        write_atomic(&target, b"data"),
        Err(MapIoError::Io { .. })
    ));
    assert_eq!(dir.entries(), vec!["occupied".to_owned()]);
    assert_eq!(std::fs::read(target.join("keep.txt")).unwrap(), b"keep");
}

#[test]
fn png_size_comes_from_the_header_alone() {
    let dir = TempDir::new("png-size");
    let p = dir.path().join("wide.png");
    write_png16(&p, &grid16(300, 7)).unwrap();
    assert_eq!(read_png_size(&p, &limits()).unwrap(), UVec2::new(300, 7));
    // Only the header is read: a file cut right after it still has a size.
    let bytes = std::fs::read(&p).unwrap();
    let head = dir.path().join("head.png");
    std::fs::write(&head, &bytes[..33]).unwrap();
    assert_eq!(read_png_size(&head, &limits()).unwrap(), UVec2::new(300, 7));
    let small = ReadLimits {
        max_side: 100,
        ..ReadLimits::default()
    };
    assert!(matches!(
        read_png_size(&p, &small),
        Err(MapIoError::TooLarge {
            width: 300,
            height: 7,
            max_side: 100
        })
    ));
    std::fs::write(&head, b"not a png").unwrap();
    assert!(matches!(
        read_png_size(&head, &limits()),
        Err(MapIoError::Corrupt { .. } | MapIoError::Truncated { .. })
    ));
    assert!(matches!(
        read_png_size(dir.path().join("missing.png"), &limits()),
        Err(MapIoError::Io { .. })
    ));
}

#[test]
fn write_atomic_takes_the_longest_file_names() {
    // 255 bytes is the longest name most file systems take; the temp file beside it must not
    // need a longer one.
    let dir = TempDir::new("atomic-long");
    for len in [200usize, 250, 255] {
        let name = "n".repeat(len - 4) + ".png";
        let p = dir.path().join(&name);
        write_atomic(&p, b"first").unwrap_or_else(|e| panic!("{len}-byte name: {e}"));
        write_atomic(&p, b"second").unwrap_or_else(|e| panic!("{len}-byte name: {e}"));
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
    }
    // Multi-byte characters are cut at a character boundary, never inside one.
    let name = "\u{e9}".repeat(126) + ".r";
    assert_eq!(name.len(), 254);
    let p = dir.path().join(&name);
    write_atomic(&p, b"accented").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"accented");
    assert_eq!(
        dir.entries().len(),
        4,
        "no temp file left: {:?}",
        dir.entries()
    );
}

/// Runs `read` on another thread and fails (instead of blocking the test) if it has not
/// returned within a few seconds.
fn returns_promptly<T: Send + 'static>(what: &str, read: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(read());
    });
    rx.recv_timeout(std::time::Duration::from_secs(10))
        .unwrap_or_else(|_| panic!("{what} blocked"))
}

#[test]
fn special_files_are_refused_as_not_regular_files() {
    let dir = TempDir::new("special");
    let fifo = dir.path().join("pipe.png");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(made.success());
    let l = limits();
    let cases: [(&Path, &str); 3] = [
        (&fifo, "named pipe"),
        (dir.path(), "directory"),
        (Path::new("/dev/null"), "device"),
    ];
    for (path, kind) in cases {
        let p = path.to_path_buf();
        let png = returns_promptly("read_png16", move || read_png16(&p, &l).map(|_| ()));
        let p = path.to_path_buf();
        let raw = returns_promptly("read_raw16", move || {
            read_raw16(&p, UVec2::new(4, 4), &l).map(|_| ())
        });
        let p = path.to_path_buf();
        let any = returns_promptly("read_png", move || read_png(&p, &l).map(|_| ()));
        let p = path.to_path_buf();
        let size = returns_promptly("read_png_size", move || read_png_size(&p, &l).map(|_| ()));
        for r in [png, raw, any, size] {
            let e = r.expect_err("a special file is not a map");
            assert!(
                matches!(&e, MapIoError::NotRegularFile { path: p, .. } if p == path),
                "{e:?}"
            );
            let s = e.to_string();
            assert!(
                s.contains(kind) && s.contains("not a regular file"),
                "{}: {s}",
                path.display()
            );
            assert!(s.contains(&path.display().to_string()), "{s}");
        }
    }
}

#[test]
fn write_atomic_rejects_a_path_without_a_file_name() {
    assert!(matches!(
        write_atomic(Path::new("/"), b"data"),
        Err(MapIoError::Io { .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Fuzzing: no input panics

fn valid_png_sample() -> Vec<u8> {
    encode_png16(&grid16(13, 11)).unwrap()
}

fn valid_interlaced_sample() -> Vec<u8> {
    build_png(
        9,
        10,
        8,
        0,
        true,
        &[],
        &adam7_scanlines(9, 10, 8, pattern16),
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        let _ = decode_png(&bytes, &limits());
        let _ = decode_png16(&bytes, &limits());
        let _ = decode_png8(&bytes, &limits());
        let mut with_signature = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
        with_signature.extend_from_slice(&bytes);
        let _ = decode_png(&with_signature, &limits());
    }

    #[test]
    fn random_raw16_never_panics(
        bytes in proptest::collection::vec(any::<u8>(), 0..4096),
        w in 0u32..80,
        h in 0u32..80,
    ) {
        let r = decode_raw16(&bytes, UVec2::new(w, h), &limits());
        let fits = w > 0 && h > 0 && bytes.len() as u64 == u64::from(w) * u64::from(h) * 2;
        prop_assert_eq!(r.is_ok(), fits);
    }

    #[test]
    fn mutated_pngs_never_panic(
        which in 0usize..2,
        edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..8),
        fix in any::<bool>(),
        cut in proptest::option::of(any::<usize>()),
    ) {
        let original = if which == 0 { valid_png_sample() } else { valid_interlaced_sample() };
        let mut bytes = original.clone();
        for (at, x) in &edits {
            let i = at % bytes.len();
            bytes[i] ^= x | 1;
        }
        if fix {
            fix_crcs(&mut bytes);
        }
        if let Some(c) = cut {
            bytes.truncate(c % (bytes.len() + 1));
        }
        let small = ReadLimits { max_side: 64, ..ReadLimits::default() };
        if let Ok(img) = decode_png(&bytes, &small) {
            let s = img.size();
            prop_assert!(s.x >= 1 && s.y >= 1 && s.x <= 64 && s.y <= 64);
            match &img {
                GrayImage::Gray8(g) => prop_assert_eq!(g.as_slice().len(), (s.x * s.y) as usize),
                GrayImage::Gray16(g) => prop_assert_eq!(g.as_slice().len(), (s.x * s.y) as usize),
            }
        }
        let _ = decode_png16(&bytes, &limits());
        let _ = decode_png8(&bytes, &limits());
    }

    #[test]
    fn truncated_pngs_never_return_garbage(cut in 0usize..10_000) {
        let g = grid16(13, 11);
        let full = encode_png16(&g).unwrap();
        let cut = cut % full.len();
        if let Ok(decoded) = decode_png16(&full[..cut], &limits()) {
            prop_assert_eq!(decoded, g);
        }
    }
}

/// Found by the fuzzing (`cargo xtask fuzz`): with raised limits, a 78-byte PNG whose header
/// announces 2^30 x 2^30 samples made the decoder reserve the whole output up front, and the
/// failed allocation aborted the process.
#[test]
fn raised_limits_never_abort_on_a_huge_header() {
    let mut png = encode_png16(&Grid::new(2, 2, 7u16).unwrap()).unwrap();
    png[16..20].copy_from_slice(&(1u32 << 30).to_be_bytes());
    png[20..24].copy_from_slice(&(1u32 << 30).to_be_bytes());
    let crc = crc32(&[&png[12..29]]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    let limits = ReadLimits {
        max_side: u32::MAX,
        ..ReadLimits::default()
    };
    assert!(decode_png16(&png, &limits).is_err());
    assert!(decode_png(&png, &limits).is_err());
}
