//! A tiny PNG writer independent of the png crate, for the I/O tests: stored deflate blocks,
//! filtered scanlines (plain and Adam7), extra chunks, and edits of a written file's header.

use terrain_test_support::png::{SIGNATURE, adler32, chunk, chunks_of, crc32};

/// A zlib stream made of stored (uncompressed) deflate blocks.
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = if data.is_empty() {
        vec![&[]]
    } else {
        data.chunks(65535).collect()
    };
    for (i, block) in blocks.iter().enumerate() {
        out.push(u8::from(i + 1 == blocks.len()));
        let len = block.len() as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(block);
    }
    out.extend_from_slice(&adler32(data).to_be_bytes());
    out
}

/// A PNG from already filtered scanlines (each starting with its filter byte), written without
/// the png crate so that decoding is checked against an independent encoder.
pub(crate) fn build_png(
    width: u32,
    height: u32,
    bit_depth: u8,
    color_type: u8,
    interlaced: bool,
    extra_chunks: &[(&[u8; 4], &[u8])],
    scanlines: &[u8],
) -> Vec<u8> {
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[bit_depth, color_type, 0, 0, u8::from(interlaced)]);
    let mut out = SIGNATURE.to_vec();
    out.extend(chunk(b"IHDR", &ihdr));
    for (ty, data) in extra_chunks {
        out.extend(chunk(ty, data));
    }
    let z = zlib_stored(scanlines);
    // Two IDAT chunks, to exercise chunk boundaries inside the image data.
    let mid = z.len() / 2;
    out.extend(chunk(b"IDAT", &z[..mid]));
    out.extend(chunk(b"IDAT", &z[mid..]));
    out.extend(chunk(b"IEND", &[]));
    out
}

/// Big-endian bytes of one grayscale sample of `bits` (8 or 16).
fn sample_bytes(v: u16, bits: u8) -> Vec<u8> {
    if bits == 16 {
        v.to_be_bytes().to_vec()
    } else {
        vec![v as u8]
    }
}

/// Unfiltered scanlines (filter type 0) of a non-interlaced grayscale image.
pub(crate) fn scanlines(w: u32, h: u32, bits: u8, f: impl Fn(u32, u32) -> u16) -> Vec<u8> {
    let mut out = Vec::new();
    for y in 0..h {
        out.push(0);
        for x in 0..w {
            out.extend(sample_bytes(f(x, y), bits));
        }
    }
    out
}

/// Unfiltered scanlines of the seven Adam7 passes of a grayscale image.
pub(crate) fn adam7_scanlines(w: u32, h: u32, bits: u8, f: impl Fn(u32, u32) -> u16) -> Vec<u8> {
    const PASSES: [(u32, u32, u32, u32); 7] = [
        (0, 0, 8, 8),
        (4, 0, 8, 8),
        (0, 4, 4, 8),
        (2, 0, 4, 4),
        (0, 2, 2, 4),
        (1, 0, 2, 2),
        (0, 1, 1, 2),
    ];
    let mut out = Vec::new();
    for (x0, y0, dx, dy) in PASSES {
        if x0 >= w || y0 >= h {
            continue; // an empty pass has no scanlines at all
        }
        for y in (y0..h).step_by(dy as usize) {
            out.push(0);
            for x in (x0..w).step_by(dx as usize) {
                out.extend(sample_bytes(f(x, y), bits));
            }
        }
    }
    out
}

/// Rewrites the IHDR size of a PNG and its CRC.
pub(crate) fn patch_ihdr_size(png: &mut [u8], width: u32, height: u32) {
    assert_eq!(&png[12..16], b"IHDR");
    png[16..20].copy_from_slice(&width.to_be_bytes());
    png[20..24].copy_from_slice(&height.to_be_bytes());
    let crc = crc32(&[&png[12..29]]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
}

/// Offset of the first chunk of a type.
pub(crate) fn find_chunk(png: &[u8], ty: &[u8; 4]) -> usize {
    chunks_of(png)
        .into_iter()
        .find(|(at, _)| &png[at + 4..at + 8] == ty)
        .map(|(at, _)| at)
        .unwrap()
}
