//! An independent PNG encoder for the PNG fuzz targets' seeds (terrain-core's hand-rolled
//! classes and the [`decoders`](crate::decoders) corpora): every bit depth and colour type,
//! Adam7 interlacing, all five row filters, stored deflate blocks of random sizes and image data
//! split over several IDAT chunks, written without the png crate the decoders use.

use crate::fuzz::Rng;
use crate::png::{SIGNATURE, adler32, chunk};

/// A zlib stream of stored (uncompressed) deflate blocks of random sizes.
fn zlib_stored(data: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    let mut rest = data;
    loop {
        let max = rng.pick(&[1usize, 3, 100, 4096, 65535]);
        let n = rest.len().min(rng.range_usize(1, max));
        let (block, tail) = rest.split_at(n);
        let last = tail.is_empty();
        out.push(u8::from(last));
        let len = block.len() as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(block);
        rest = tail;
        if last {
            break;
        }
    }
    out.extend_from_slice(&adler32(data).to_be_bytes());
    out
}

/// Samples per pixel of a PNG colour type.
fn channels(color_type: u8) -> usize {
    match color_type {
        2 => 3,
        4 => 2,
        6 => 4,
        _ => 1,
    }
}

/// An image to encode: every channel sample as a u16 (only the low `bit_depth` bits count).
#[derive(Debug, Clone)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub color_type: u8,
    pub bit_depth: u8,
    pub samples: Vec<u16>,
}

/// The valid (colour type, bit depth) pairs of the PNG specification.
pub const VALID_FORMATS: [(u8, u8); 15] = [
    (0, 1),
    (0, 2),
    (0, 4),
    (0, 8),
    (0, 16),
    (2, 8),
    (2, 16),
    (3, 1),
    (3, 2),
    (3, 4),
    (3, 8),
    (4, 8),
    (4, 16),
    (6, 8),
    (6, 16),
];

impl Image {
    /// A `width` x `height` image of the format: a smooth ramp or noise, half the time each.
    pub fn random(rng: &mut Rng, width: u32, height: u32, color_type: u8, bit_depth: u8) -> Self {
        let n = width as usize * height as usize * channels(color_type);
        let mask = if bit_depth >= 16 {
            u16::MAX
        } else {
            (1u16 << bit_depth) - 1
        };
        // Smooth ramps and noise: both kinds of rows filter differently.
        let noisy = rng.chance(1, 2);
        let base = rng.next_u32() as u16;
        let samples = (0..n)
            .map(|i| {
                if noisy {
                    rng.next_u32() as u16 & mask
                } else {
                    base.wrapping_add((i as u16).wrapping_mul(3)) & mask
                }
            })
            .collect();
        Self {
            width,
            height,
            color_type,
            bit_depth,
            samples,
        }
    }

    /// Bytes per complete pixel for the filters (at least 1).
    fn filter_bpp(&self) -> usize {
        (channels(self.color_type) * usize::from(self.bit_depth) / 8).max(1)
    }

    /// The packed bytes of row `y`, columns `xs`.
    fn pack_row(&self, y: u32, xs: impl Iterator<Item = u32>) -> Vec<u8> {
        let ch = channels(self.color_type);
        let bits = usize::from(self.bit_depth);
        let mut out = Vec::new();
        let mut acc = 0u32;
        let mut filled = 0usize;
        for x in xs {
            for c in 0..ch {
                let v = self.samples[(y as usize * self.width as usize + x as usize) * ch + c];
                match bits {
                    16 => out.extend_from_slice(&v.to_be_bytes()),
                    8 => out.push(v as u8),
                    _ => {
                        acc = (acc << bits) | u32::from(v);
                        filled += bits;
                        if filled == 8 {
                            out.push(acc as u8);
                            acc = 0;
                            filled = 0;
                        }
                    }
                }
            }
        }
        if filled > 0 {
            out.push((acc << (8 - filled)) as u8);
        }
        out
    }

    /// Filtered scanlines, Adam7 passes when `interlaced`, each row with a random filter.
    fn scanlines(&self, interlaced: bool, rng: &mut Rng) -> Vec<u8> {
        const PASSES: [(u32, u32, u32, u32); 7] = [
            (0, 0, 8, 8),
            (4, 0, 8, 8),
            (0, 4, 4, 8),
            (2, 0, 4, 4),
            (0, 2, 2, 4),
            (1, 0, 2, 2),
            (0, 1, 1, 2),
        ];
        let passes: &[(u32, u32, u32, u32)] = if interlaced { &PASSES } else { &[(0, 0, 1, 1)] };
        let bpp = self.filter_bpp();
        let mut out = Vec::new();
        for &(x0, y0, dx, dy) in passes {
            if x0 >= self.width || y0 >= self.height {
                continue; // an empty pass has no scanlines at all
            }
            let mut prev: Vec<u8> = Vec::new();
            for y in (y0..self.height).step_by(dy as usize) {
                let row = self.pack_row(y, (x0..self.width).step_by(dx as usize));
                let kind = rng.below(5) as u8;
                out.push(kind);
                for i in 0..row.len() {
                    let a = if i >= bpp { row[i - bpp] } else { 0 };
                    let b = prev.get(i).copied().unwrap_or(0);
                    let c = if i >= bpp {
                        prev.get(i - bpp).copied().unwrap_or(0)
                    } else {
                        0
                    };
                    let pred = match kind {
                        0 => 0,
                        1 => a,
                        2 => b,
                        3 => ((u16::from(a) + u16::from(b)) / 2) as u8,
                        _ => paeth(a, b, c),
                    };
                    out.push(row[i].wrapping_sub(pred));
                }
                prev = row;
            }
        }
        out
    }

    /// The PNG file: IHDR, PLTE for palette images, well-formed ancillary chunks, the image
    /// data over 1 to 4 IDAT chunks (some possibly empty), IEND.
    pub fn encode(&self, rng: &mut Rng) -> Vec<u8> {
        let interlaced = rng.chance(1, 3);
        let mut ihdr = Vec::new();
        ihdr.extend_from_slice(&self.width.to_be_bytes());
        ihdr.extend_from_slice(&self.height.to_be_bytes());
        ihdr.extend_from_slice(&[self.bit_depth, self.color_type, 0, 0, u8::from(interlaced)]);
        let mut out = SIGNATURE.to_vec();
        out.extend(chunk(b"IHDR", &ihdr));
        if rng.chance(1, 3) {
            out.extend(chunk(b"tEXt", b"Software\0terrain fuzz"));
        }
        if rng.chance(1, 4) {
            out.extend(chunk(b"gAMA", &45455u32.to_be_bytes()));
        }
        if self.color_type == 3 {
            let entries = 1usize << self.bit_depth.min(8);
            out.extend(chunk(b"PLTE", &rng.bytes(3 * entries)));
        }
        if rng.chance(1, 4) {
            let n = rng.index(40);
            out.extend(chunk(b"prVt", &rng.bytes(n)));
        }
        let z = zlib_stored(&self.scanlines(interlaced, rng), rng);
        let parts = rng.range_usize(1, 4);
        let mut cuts: Vec<usize> = (0..parts - 1).map(|_| rng.index(z.len() + 1)).collect();
        cuts.sort_unstable();
        let mut start = 0;
        for cut in cuts.into_iter().chain([z.len()]) {
            out.extend(chunk(b"IDAT", &z[start..cut]));
            start = cut;
        }
        if rng.chance(1, 4) {
            out.extend(chunk(b"tEXt", b"Comment\0after the image data"));
        }
        out.extend(chunk(b"IEND", &[]));
        out
    }
}

fn paeth(a: u8, b: u8, c: u8) -> u8 {
    let p = i16::from(a) + i16::from(b) - i16::from(c);
    let (pa, pb, pc) = (
        (p - i16::from(a)).abs(),
        (p - i16::from(b)).abs(),
        (p - i16::from(c)).abs(),
    );
    if pa <= pb && pa <= pc {
        a
    } else if pb <= pc {
        b
    } else {
        c
    }
}
