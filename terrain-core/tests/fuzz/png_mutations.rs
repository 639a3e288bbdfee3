//! Seeds and mutations of the PNG targets: valid files from either encoder, read limits, and the
//! damage done to them (bit flips, chunk surgery, header fields, a damaged zlib stream with the
//! chunk CRCs fixed).

use crate::png_expect::{Kind, Pixels, expected_pixels};
use terrain_core::io::{DEFAULT_MAX_SIDE, ReadLimits, encode_png_rgba8, encode_png8, encode_png16};
use terrain_test_support::fuzz::Rng;
use terrain_test_support::png::{chunk, chunks_of, fix_crcs};
use terrain_test_support::png_encoder::{Image, VALID_FORMATS};

/// A small random image side, biased to the sizes that stress row and pass handling.
pub(crate) fn side(rng: &mut Rng) -> u32 {
    if rng.chance(1, 2) {
        rng.range_u32(1, 9)
    } else {
        rng.range_u32(1, 70)
    }
}

/// A valid image in the decoder's own format (most of the time) or in any valid format.
pub(crate) fn seed_image(k: Kind, rng: &mut Rng) -> Image {
    let (ct, bits) = if rng.chance(3, 4) {
        k.format()
    } else {
        rng.pick(&VALID_FORMATS)
    };
    let (w, h) = (side(rng), side(rng));
    Image::random(rng, w, h, ct, bits)
}

/// A valid file: the independent encoder's, or terrain-core's own (compressed).
pub(crate) fn seed_file(k: Kind, rng: &mut Rng) -> Vec<u8> {
    let img = seed_image(k, rng);
    if rng.chance(1, 3) && img.color_type == 0 && img.bit_depth >= 8 {
        let e = expected_pixels(
            if img.bit_depth == 8 {
                Kind::Gray8
            } else {
                Kind::Gray16
            },
            &img,
        );
        return match e {
            Pixels::Gray8(g) => encode_png8(&g).unwrap(),
            Pixels::Gray16(g) => encode_png16(&g).unwrap(),
            Pixels::Rgba8(g) => encode_png_rgba8(&g).unwrap(),
        };
    }
    if rng.chance(1, 3) && (img.color_type, img.bit_depth) == (6, 8) {
        let Pixels::Rgba8(g) = expected_pixels(Kind::Rgba8, &img) else {
            unreachable!()
        };
        return encode_png_rgba8(&g).unwrap();
    }
    img.encode(rng)
}

pub(crate) fn limits_for(rng: &mut Rng) -> ReadLimits {
    if rng.chance(1, 4) {
        ReadLimits {
            max_side: rng.range_u32(1, 80),
            ..ReadLimits::default()
        }
    } else {
        ReadLimits::default()
    }
}

/// Chunk types worth inserting: critical ones out of place, ancillary ones the decoder parses,
/// the animation chunks, unknown critical and ancillary ones.
pub(crate) const CHUNK_TYPES: [&[u8; 4]; 22] = [
    b"IHDR", b"PLTE", b"IDAT", b"IEND", b"tRNS", b"gAMA", b"cHRM", b"sRGB", b"iCCP", b"tEXt",
    b"zTXt", b"iTXt", b"bKGD", b"pHYs", b"sBIT", b"tIME", b"acTL", b"fcTL", b"fdAT", b"eXIf",
    b"XXXX", b"prVt",
];

/// Data for an inserted chunk: empty, short, the right length for common chunks, or large.
pub(crate) fn chunk_data(rng: &mut Rng) -> Vec<u8> {
    let n = rng.pick(&[0usize, 1, 4, 8, 9, 13, 26, 38, 300, 5000]);
    rng.bytes(n)
}

/// One structural edit of the chunk list (chunk CRCs stay valid unless a length is changed).
pub(crate) fn chunk_surgery(png: &mut Vec<u8>, rng: &mut Rng) {
    let chunks = chunks_of(png);
    let pick_chunk = |rng: &mut Rng| chunks.get(rng.index(chunks.len())).copied();
    match rng.below(8) {
        0 => {
            // Remove a chunk.
            if let Some((at, len)) = pick_chunk(rng) {
                png.drain(at..at + 12 + len);
            }
        }
        1 => {
            // Duplicate a chunk in place.
            if let Some((at, len)) = pick_chunk(rng) {
                let c = png[at..at + 12 + len].to_vec();
                png.splice(at..at, c);
            }
        }
        2 => {
            // Move a chunk elsewhere.
            if let (Some((at, len)), Some((to, _))) = (pick_chunk(rng), pick_chunk(rng)) {
                let c: Vec<u8> = png.drain(at..at + 12 + len).collect();
                let to = if to > at { to - c.len() } else { to };
                png.splice(to..to, c);
            }
        }
        3 => {
            // Insert a chunk with a valid CRC at a chunk boundary.
            let at = pick_chunk(rng).map_or(png.len(), |(at, _)| at);
            let ty = rng.pick(&CHUNK_TYPES);
            let c = chunk(ty, &chunk_data(rng));
            png.splice(at..at, c);
        }
        4 => {
            // Grow or shrink a length field (the CRC no longer covers what the length says).
            if let Some((at, len)) = pick_chunk(rng) {
                let v = match rng.below(4) {
                    0 => rng.u32_edge(),
                    1 => len as u32 + rng.range_u32(1, 16),
                    2 => (len as u32).saturating_sub(rng.range_u32(1, 16)),
                    _ => 0x7FFF_FFFF,
                };
                png[at..at + 4].copy_from_slice(&v.to_be_bytes());
            }
        }
        5 => {
            // Trailing bytes after IEND.
            let n = rng.range_usize(1, 64);
            png.extend(rng.bytes(n));
        }
        6 => {
            // Drop the end chunk.
            if let Some(&(at, len)) = chunks.last() {
                png.drain(at..at + 12 + len);
            }
        }
        _ => {
            // Split a chunk's data into two chunks of its type.
            if let Some((at, len)) = pick_chunk(rng) {
                let ty: [u8; 4] = png[at + 4..at + 8].try_into().unwrap();
                let data = png[at + 8..at + 8 + len].to_vec();
                let cut = rng.index(len + 1);
                let mut two = chunk(&ty, &data[..cut]);
                two.extend(chunk(&ty, &data[cut..]));
                png.splice(at..at + 12 + len, two);
            }
        }
    }
}

/// Overwrites one IHDR field (the first IHDR chunk's) with an edge value and fixes its CRC.
pub(crate) fn overwrite_header(png: &mut [u8], rng: &mut Rng) {
    let Some((at, len)) = chunks_of(png)
        .into_iter()
        .find(|&(at, _)| &png[at + 4..at + 8] == b"IHDR")
    else {
        return;
    };
    if len < 13 {
        return;
    }
    let d = at + 8;
    let side = |rng: &mut Rng| match rng.below(3) {
        0 => rng.u32_edge(),
        1 => rng.pick(&[DEFAULT_MAX_SIDE - 1, DEFAULT_MAX_SIDE, DEFAULT_MAX_SIDE + 1]),
        _ => rng.range_u32(0, 80),
    };
    match rng.below(7) {
        0 => png[d..d + 4].copy_from_slice(&side(rng).to_be_bytes()),
        1 => png[d + 4..d + 8].copy_from_slice(&side(rng).to_be_bytes()),
        2 => png[d + 8] = rng.pick(&[0, 1, 2, 3, 4, 5, 7, 8, 9, 15, 16, 17, 32, 255]),
        3 => png[d + 9] = rng.pick(&[0, 1, 2, 3, 4, 5, 6, 7, 8, 255]),
        4 => png[d + 10] = rng.pick(&[0, 1, 255]),
        5 => png[d + 11] = rng.pick(&[0, 1, 255]),
        _ => png[d + 12] = rng.pick(&[0, 1, 2, 255]),
    }
    fix_crcs(png);
}

/// Damages the zlib stream inside the IDAT chunks and rewrites them with valid CRCs.
pub(crate) fn damage_zlib(png: &mut Vec<u8>, rng: &mut Rng) {
    let chunks = chunks_of(png);
    let idats: Vec<(usize, usize)> = chunks
        .iter()
        .copied()
        .filter(|&(at, _)| &png[at + 4..at + 8] == b"IDAT")
        .collect();
    let (Some(&(first, _)), Some(&(last, last_len))) = (idats.first(), idats.last()) else {
        return;
    };
    let mut z: Vec<u8> = idats
        .iter()
        .flat_map(|&(at, len)| png[at + 8..at + 8 + len].to_vec())
        .collect();
    match rng.below(7) {
        0 => rng.flip_bits(&mut z),
        1 => {
            // The two header bytes: method, window size, check bits, preset dictionary.
            if z.len() >= 2 {
                let i = rng.index(2);
                z[i] = rng.next_u32() as u8;
            }
        }
        2 => {
            // A stored block's LEN / NLEN, or a block type of 3 (reserved).
            if z.len() > 6 {
                let i = rng.range_usize(2, 6.min(z.len() - 1));
                z[i] = rng.pick(&[0x00, 0x06, 0xFF, 0x7F, 0x80]);
            }
        }
        3 => {
            let n = z.len();
            z.truncate(rng.index(n + 1));
        }
        4 => {
            let n = rng.range_usize(1, 300);
            z.extend(rng.bytes(n));
        }
        5 => {
            // The Adler-32 at the end.
            let n = z.len();
            if n >= 4 {
                let i = n - 1 - rng.index(4);
                z[i] ^= 1 << rng.below(8);
            }
        }
        _ => {
            // Random deflate data after a valid header.
            let n = rng.range_usize(0, 400);
            z.truncate(2.min(z.len()));
            z.extend(rng.bytes(n));
        }
    }
    let parts = rng.range_usize(1, 3);
    let mut data = Vec::new();
    let step = z.len().div_ceil(parts).max(1);
    for part in z.chunks(step) {
        data.extend(chunk(b"IDAT", part));
    }
    if z.is_empty() {
        data.extend(chunk(b"IDAT", &[]));
    }
    png.splice(first..last + 12 + last_len, data);
}
