//! Fuzz targets for terrain-core's map decoders: PNG 16-bit (`png16`), PNG 8-bit and RGBA8
//! captures (`png8`), RAW16 (`raw16`) and GeoTIFF DEMs (`geotiff`, seeded by the tests' own
//! TIFF writer in `dem/tiff_writer.rs`: every sample type, strips and tiles, both byte orders,
//! classic and BigTIFF, with GeoTIFF tags). Each target is time-bounded (`TERRAIN_FUZZ_SECONDS`,
//! default 2 s; `cargo xtask fuzz --seconds N` runs them longer, in release mode) and prints how
//! many cases each input class ran; see `fuzz/harness.rs` for the seed, replay and class
//! selection variables.
//!
//! Seeds are valid files made here by an encoder independent of the png crate (every bit
//! depth and colour type, Adam7 interlacing, all five row filters, stored deflate blocks of
//! random sizes, image data split over several IDAT chunks, ancillary chunks) and by
//! terrain-core's own encoder (compressed deflate). They are then truncated, bit-flipped,
//! their header fields overwritten, their chunks removed / duplicated / grown, their zlib
//! stream damaged (with chunk CRCs fixed, so the damage reaches the parsers behind the CRC
//! check), or replaced by random bytes. Valid inputs must decode to exactly the samples
//! encoded (or to the error the header calls for); every other input must give `Ok` or `Err`,
//! never a panic or a hang, and an `Ok` must respect the read limits.

#[path = "fuzz/harness.rs"]
mod harness;
#[path = "dem/tiff_writer.rs"]
mod tiff_writer;

use glam::UVec2;
use harness::{Case, Class, Rng, Target};
use std::path::PathBuf;
use std::time::Duration;
use terrain_core::Grid;
use terrain_core::geotiff::{decode_geotiff, read_geotiff};
use terrain_core::io::{
    DEFAULT_MAX_SIDE, GrayImage, MapIoError, ReadLimits, decode_png, decode_png_rgba8, decode_png8,
    decode_png16, decode_raw16, encode_png_rgba8, encode_png8, encode_png16, encode_raw16,
    read_png, read_png8, read_png16, read_raw16,
};

/// A decode of small images takes well under a millisecond; 250 ms leaves room for debug
/// builds on a loaded machine while still catching a decoder that loops.
const PER_CASE_LIMIT: Duration = Duration::from_millis(250);

// ---------------------------------------------------------------------------------------------
// An independent PNG encoder

#[path = "common/png_bytes.rs"]
mod png_bytes;
use png_bytes::{SIGNATURE, adler32, chunk, crc32};

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
struct Image {
    width: u32,
    height: u32,
    color_type: u8,
    bit_depth: u8,
    samples: Vec<u16>,
}

/// The valid (colour type, bit depth) pairs of the PNG specification.
const VALID_FORMATS: [(u8, u8); 15] = [
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
    fn random(rng: &mut Rng, width: u32, height: u32, color_type: u8, bit_depth: u8) -> Self {
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
    fn encode(&self, rng: &mut Rng) -> Vec<u8> {
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

/// The chunks of a PNG: (offset of the length field, data length), as far as they are whole.
fn chunks_of(png: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 12 <= png.len() {
        let len = u32::from_be_bytes([png[at], png[at + 1], png[at + 2], png[at + 3]]) as usize;
        if len > png.len() || at + 12 + len > png.len() {
            break;
        }
        out.push((at, len));
        at += 12 + len;
    }
    out
}

/// Recomputes every whole chunk's CRC, so that a mutation reaches the parser behind it.
fn fix_crcs(png: &mut [u8]) {
    for (at, len) in chunks_of(png) {
        let crc = crc32(&[&png[at + 4..at + 8 + len]]);
        png[at + 8 + len..at + 12 + len].copy_from_slice(&crc.to_be_bytes());
    }
}

// ---------------------------------------------------------------------------------------------
// What each decoder must return

/// Which decoder a target drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Gray8,
    Gray16,
    Rgba8,
}

const GRAY8: u8 = 0;
const GRAY16: u8 = 1;
const RGBA8: u8 = 2;

fn kind(k: u8) -> Kind {
    match k {
        GRAY8 => Kind::Gray8,
        GRAY16 => Kind::Gray16,
        _ => Kind::Rgba8,
    }
}

impl Kind {
    /// The (colour type, bit depth) this decoder accepts.
    fn format(self) -> (u8, u8) {
        match self {
            Kind::Gray8 => (0, 8),
            Kind::Gray16 => (0, 16),
            Kind::Rgba8 => (6, 8),
        }
    }
}

/// A decoder's output as one comparable value.
#[derive(Debug, PartialEq)]
enum Pixels {
    Gray8(Grid<u8>),
    Gray16(Grid<u16>),
    Rgba8(Grid<[u8; 4]>),
}

impl Pixels {
    fn size(&self) -> UVec2 {
        match self {
            Pixels::Gray8(g) => g.size(),
            Pixels::Gray16(g) => g.size(),
            Pixels::Rgba8(g) => g.size(),
        }
    }
}

fn decode(k: Kind, bytes: &[u8], limits: &ReadLimits) -> Result<Pixels, MapIoError> {
    match k {
        Kind::Gray8 => decode_png8(bytes, limits).map(Pixels::Gray8),
        Kind::Gray16 => decode_png16(bytes, limits).map(Pixels::Gray16),
        Kind::Rgba8 => decode_png_rgba8(bytes, limits).map(Pixels::Rgba8),
    }
}

fn read_file(k: Kind, path: &std::path::Path, limits: &ReadLimits) -> Result<Pixels, MapIoError> {
    match k {
        Kind::Gray8 => read_png8(path, limits).map(Pixels::Gray8),
        Kind::Gray16 => read_png16(path, limits).map(Pixels::Gray16),
        Kind::Rgba8 => terrain_core::io::read_png_rgba8(path, limits).map(Pixels::Rgba8),
    }
}

/// The pixels a decoder of kind `k` must return for `img`.
fn expected_pixels(k: Kind, img: &Image) -> Pixels {
    let (w, h) = (img.width, img.height);
    match k {
        Kind::Gray8 => Pixels::Gray8(
            Grid::from_vec(w, h, img.samples.iter().map(|&v| v as u8).collect()).unwrap(),
        ),
        Kind::Gray16 => Pixels::Gray16(Grid::from_vec(w, h, img.samples.clone()).unwrap()),
        Kind::Rgba8 => Pixels::Rgba8(
            Grid::from_vec(
                w,
                h,
                img.samples
                    .chunks_exact(4)
                    .map(|p| [p[0] as u8, p[1] as u8, p[2] as u8, p[3] as u8])
                    .collect(),
            )
            .unwrap(),
        ),
    }
}

/// Checks a decode of a valid file of `img`: the exact pixels when the decoder takes the
/// image's format and size, else the error the header calls for.
fn check_valid(
    k: Kind,
    img: &Image,
    limits: &ReadLimits,
    got: Result<Pixels, MapIoError>,
) -> Result<(), String> {
    let (w, h) = (img.width, img.height);
    let fmt = (img.color_type, img.bit_depth);
    let describe = || format!("{w}x{h} colour type {} depth {}", fmt.0, fmt.1);
    if w > limits.max_side || h > limits.max_side {
        return match got {
            Err(MapIoError::TooLarge { width, height, .. }) if width == w && height == h => Ok(()),
            other => Err(format!(
                "{}: over max_side {}, expected TooLarge, got {other:?}",
                describe(),
                limits.max_side
            )),
        };
    }
    let ok = match (k, got) {
        (_, Ok(p)) if fmt == k.format() => {
            let want = expected_pixels(k, img);
            if p == want {
                return Ok(());
            }
            return Err(format!(
                "{}: decoded pixels differ from the encoded ones",
                describe()
            ));
        }
        (Kind::Gray8 | Kind::Gray16, Err(MapIoError::NotGrayscale { .. })) => fmt.0 != 0,
        (Kind::Gray8 | Kind::Gray16, Err(MapIoError::UnsupportedBitDepth { bits })) => {
            fmt.0 == 0 && bits == fmt.1 && bits < 8
        }
        (Kind::Gray8, Err(MapIoError::WrongBitDepth { expected: 8, found })) => {
            fmt == (0, 16) && found == 16
        }
        (
            Kind::Gray16,
            Err(MapIoError::WrongBitDepth {
                expected: 16,
                found,
            }),
        ) => fmt == (0, 8) && found == 8,
        (Kind::Rgba8, Err(MapIoError::NotRgba { .. })) => fmt.0 != 6,
        (Kind::Rgba8, Err(MapIoError::WrongBitDepth { expected: 8, found })) => {
            fmt == (6, 16) && found == 16
        }
        (_, other) => {
            return Err(format!("{}: unexpected result {other:?}", describe()));
        }
    };
    if ok {
        Ok(())
    } else {
        Err(format!("{}: wrong error for this header", describe()))
    }
}

/// Checks what any input may decode to: an error, or pixels within the limits. For the gray
/// decoders, also that the generic `decode_png` agrees with the depth-specific one.
fn check_any(k: Kind, bytes: &[u8], limits: &ReadLimits) -> Result<Option<Pixels>, String> {
    let got = decode(k, bytes, limits);
    if let Ok(p) = &got {
        let s = p.size();
        if s.x == 0 || s.y == 0 || s.x > limits.max_side || s.y > limits.max_side {
            return Err(format!(
                "decoded a {}x{} image, limits {limits:?}",
                s.x, s.y
            ));
        }
    }
    if k != Kind::Rgba8 {
        let generic = decode_png(bytes, limits);
        let agree = match (&got, &generic) {
            (Ok(Pixels::Gray8(a)), Ok(GrayImage::Gray8(b))) => a == b,
            (Ok(Pixels::Gray16(a)), Ok(GrayImage::Gray16(b))) => a == b,
            (Ok(_), _) => false,
            (Err(_), Ok(GrayImage::Gray8(_))) => k == Kind::Gray16,
            (Err(_), Ok(GrayImage::Gray16(_))) => k == Kind::Gray8,
            (Err(_), Err(_)) => true,
        };
        if !agree {
            return Err(format!(
                "decode_png and the {k:?} decoder disagree: {:?} vs {:?}",
                got.as_ref().map(Pixels::size),
                generic.as_ref().map(GrayImage::size)
            ));
        }
    }
    Ok(got.ok())
}

// ---------------------------------------------------------------------------------------------
// Seeds and mutations

/// A small random image side, biased to the sizes that stress row and pass handling.
fn side(rng: &mut Rng) -> u32 {
    if rng.chance(1, 2) {
        rng.range_u32(1, 9)
    } else {
        rng.range_u32(1, 70)
    }
}

/// A valid image in the decoder's own format (most of the time) or in any valid format.
fn seed_image(k: Kind, rng: &mut Rng) -> Image {
    let (ct, bits) = if rng.chance(3, 4) {
        k.format()
    } else {
        rng.pick(&VALID_FORMATS)
    };
    let (w, h) = (side(rng), side(rng));
    Image::random(rng, w, h, ct, bits)
}

/// A valid file: the independent encoder's, or terrain-core's own (compressed).
fn seed_file(k: Kind, rng: &mut Rng) -> Vec<u8> {
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

fn limits_for(rng: &mut Rng) -> ReadLimits {
    if rng.chance(1, 4) {
        ReadLimits {
            max_side: rng.range_u32(1, 80),
        }
    } else {
        ReadLimits::default()
    }
}

/// Flips 1 to 16 random bits.
fn flip_bits(bytes: &mut [u8], rng: &mut Rng) {
    if bytes.is_empty() {
        return;
    }
    for _ in 0..rng.range_u32(1, 16) {
        let i = rng.index(bytes.len());
        bytes[i] ^= 1 << rng.below(8);
    }
}

/// Chunk types worth inserting: critical ones out of place, ancillary ones the decoder parses,
/// the animation chunks, unknown critical and ancillary ones.
const CHUNK_TYPES: [&[u8; 4]; 22] = [
    b"IHDR", b"PLTE", b"IDAT", b"IEND", b"tRNS", b"gAMA", b"cHRM", b"sRGB", b"iCCP", b"tEXt",
    b"zTXt", b"iTXt", b"bKGD", b"pHYs", b"sBIT", b"tIME", b"acTL", b"fcTL", b"fdAT", b"eXIf",
    b"XXXX", b"prVt",
];

/// Data for an inserted chunk: empty, short, the right length for common chunks, or large.
fn chunk_data(rng: &mut Rng) -> Vec<u8> {
    let n = rng.pick(&[0usize, 1, 4, 8, 9, 13, 26, 38, 300, 5000]);
    rng.bytes(n)
}

/// One structural edit of the chunk list (chunk CRCs stay valid unless a length is changed).
fn chunk_surgery(png: &mut Vec<u8>, rng: &mut Rng) {
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
fn overwrite_header(png: &mut [u8], rng: &mut Rng) {
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
fn damage_zlib(png: &mut Vec<u8>, rng: &mut Rng) {
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
        0 => flip_bits(&mut z, rng),
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

// ---------------------------------------------------------------------------------------------
// Classes shared by the PNG targets (K: GRAY8, GRAY16 or RGBA8)

/// Shared state: a folder for the file-reader classes.
struct Ctx {
    dir: PathBuf,
}

impl Ctx {
    fn new(target: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("terrain-core-fuzz-{target}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self { dir }
    }
}

impl Drop for Ctx {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Valid files of every format from the independent encoder: exact pixels or the right error.
fn png_valid<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let img = seed_image(k, rng);
    let bytes = img.encode(rng);
    let limits = limits_for(rng);
    check_valid(k, &img, &limits, decode(k, &bytes, &limits))?;
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Round trips through terrain-core's own encoder (compressed deflate).
fn png_roundtrip<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let (w, h) = (side(rng), side(rng));
    let (ct, bits) = k.format();
    let img = Image::random(rng, w, h, ct, bits);
    let bytes = match expected_pixels(k, &img) {
        Pixels::Gray8(g) => encode_png8(&g),
        Pixels::Gray16(g) => encode_png16(&g),
        Pixels::Rgba8(g) => encode_png_rgba8(&g),
    }
    .map_err(|e| format!("encoding {w}x{h} failed: {e}"))?;
    check_valid(
        k,
        &img,
        &ReadLimits::default(),
        decode(k, &bytes, &ReadLimits::default()),
    )
}

/// A valid file cut anywhere before its end must be an error.
fn png_truncated<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let full = seed_file(k, rng);
    let cut = if rng.chance(1, 4) {
        full.len() - rng.range_usize(1, 12.min(full.len()))
    } else {
        rng.index(full.len())
    };
    let limits = limits_for(rng);
    match check_any(k, &full[..cut], &limits)? {
        None => Ok(()),
        Some(p) => Err(format!(
            "a file cut to {cut} of {} bytes decoded as a {} image",
            full.len(),
            p.size()
        )),
    }
}

/// Random bit flips, CRCs left as they are (most stop at the CRC check).
fn png_bit_flips<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    flip_bits(&mut bytes, rng);
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Random bit flips with every chunk CRC fixed, so they reach the parsers.
fn png_bit_flips_crc_fixed<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    flip_bits(&mut bytes, rng);
    fix_crcs(&mut bytes);
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// IHDR fields overwritten with edge values (sizes near the limits, bad depths and types).
fn png_header_fields<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    for _ in 0..rng.range_u32(1, 3) {
        overwrite_header(&mut bytes, rng);
    }
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Chunks removed, duplicated, moved, inserted, split, grown; trailing bytes; no IEND.
fn png_chunk_surgery<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    for _ in 0..rng.range_u32(1, 4) {
        chunk_surgery(&mut bytes, rng);
    }
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// The zlib stream damaged (header, block lengths, block type, data, checksum, length), the
/// IDAT chunks rewritten with valid CRCs.
fn png_zlib_damage<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    damage_zlib(&mut bytes, rng);
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Sizes at the limits: sides of `max_side - 1`, `max_side`, `max_side + 1` for a small
/// `max_side` (valid files: decoded exactly or TooLarge), and headers announcing sides around
/// the default limit (16384) or far beyond it over a few bytes of data (an error, quickly).
fn png_size_limits<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    if rng.chance(1, 2) {
        let max_side = rng.range_u32(1, 48);
        let near = |rng: &mut Rng| (max_side + rng.range_u32(0, 2)).saturating_sub(1).max(1);
        let (w, h) = (near(rng), near(rng));
        let (ct, bits) = k.format();
        let img = Image::random(rng, w, h, ct, bits);
        let bytes = img.encode(rng);
        let limits = ReadLimits { max_side };
        return check_valid(k, &img, &limits, decode(k, &bytes, &limits));
    }
    let mut bytes = seed_file(k, rng);
    let big = [
        DEFAULT_MAX_SIDE - 1,
        DEFAULT_MAX_SIDE,
        DEFAULT_MAX_SIDE + 1,
        u32::MAX,
        1 << 31,
        (1 << 31) - 1,
    ];
    let (w, h) = (rng.pick(&big), rng.pick(&big));
    if let Some((at, len)) = chunks_of(&bytes).first().copied()
        && len >= 13
    {
        bytes[at + 8..at + 12].copy_from_slice(&w.to_be_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&h.to_be_bytes());
        fix_crcs(&mut bytes);
    }
    match check_any(k, &bytes, &ReadLimits::default())? {
        None => Ok(()),
        Some(p) => Err(format!(
            "a small file announcing {w}x{h} decoded as a {} image",
            p.size()
        )),
    }
}

/// Random bytes: bare, after the PNG signature, as random chunks with valid CRCs, or as a
/// valid IHDR of random fields followed by random chunks.
fn png_random_bytes<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let n = rng.range_usize(0, 2048);
    let bytes = match rng.below(4) {
        0 => rng.bytes(n),
        1 => {
            let mut b = SIGNATURE.to_vec();
            b.extend(rng.bytes(n));
            b
        }
        mode => {
            let mut b = SIGNATURE.to_vec();
            if mode == 3 {
                let mut ihdr = Vec::new();
                ihdr.extend_from_slice(&rng.range_u32(0, 70).to_be_bytes());
                ihdr.extend_from_slice(&rng.range_u32(0, 70).to_be_bytes());
                ihdr.push(rng.pick(&[1, 2, 4, 8, 16, 3]));
                ihdr.push(rng.pick(&[0, 2, 3, 4, 6, 1]));
                ihdr.extend_from_slice(&[0, 0, rng.range_u32(0, 1) as u8]);
                b.extend(chunk(b"IHDR", &ihdr));
            }
            for _ in 0..rng.range_u32(0, 6) {
                let ty = rng.pick(&CHUNK_TYPES);
                b.extend(chunk(ty, &chunk_data(rng)));
            }
            b
        }
    };
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// The file readers (buffered, with their own truncation report) against the in-memory
/// decoders on the same mutated bytes: the same pixels, or both an error.
fn png_file_reader<const K: u8>(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    match rng.below(5) {
        0 => {}
        1 => {
            let n = bytes.len();
            bytes.truncate(rng.index(n));
        }
        2 => {
            flip_bits(&mut bytes, rng);
            fix_crcs(&mut bytes);
        }
        3 => overwrite_header(&mut bytes, rng),
        _ => chunk_surgery(&mut bytes, rng),
    }
    let limits = limits_for(rng);
    let path = ctx.dir.join(format!("{:016x}.png", rng.next_u64()));
    std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
    let from_file = read_file(k, &path, &limits);
    let _ = std::fs::remove_file(&path);
    let in_memory = decode(k, &bytes, &limits);
    if k != Kind::Rgba8 {
        // The generic file reader must agree with the generic in-memory decoder.
        let path = ctx.dir.join(format!("{:016x}.png", rng.next_u64()));
        std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
        let a = read_png(&path, &limits).ok();
        let _ = std::fs::remove_file(&path);
        if a != decode_png(&bytes, &limits).ok() {
            return Err("read_png and decode_png disagree".into());
        }
    }
    match (from_file, in_memory) {
        (Ok(a), Ok(b)) if a == b => Ok(()),
        (Err(_), Err(_)) => Ok(()),
        (a, b) => Err(format!(
            "file reader and in-memory decoder disagree: {:?} vs {:?}",
            a.map(|p| p.size()),
            b.map(|p| p.size())
        )),
    }
}

fn png_classes<const K: u8>(rgba_too: bool) -> Vec<Class<Ctx>> {
    let mut classes = vec![
        Class {
            name: "valid_any_format",
            run: png_valid::<K>,
        },
        Class {
            name: "roundtrip_own_encoder",
            run: png_roundtrip::<K>,
        },
        Class {
            name: "truncated",
            run: png_truncated::<K>,
        },
        Class {
            name: "bit_flips",
            run: png_bit_flips::<K>,
        },
        Class {
            name: "bit_flips_crc_fixed",
            run: png_bit_flips_crc_fixed::<K>,
        },
        Class {
            name: "header_fields",
            run: png_header_fields::<K>,
        },
        Class {
            name: "chunk_surgery",
            run: png_chunk_surgery::<K>,
        },
        Class {
            name: "zlib_damage",
            run: png_zlib_damage::<K>,
        },
        Class {
            name: "size_limits",
            run: png_size_limits::<K>,
        },
        Class {
            name: "random_bytes",
            run: png_random_bytes::<K>,
        },
        Class {
            name: "file_reader",
            run: png_file_reader::<K>,
        },
    ];
    if rgba_too {
        // The RGBA8 capture decoder shares the PNG path; a few classes of its own.
        classes.extend([
            Class {
                name: "rgba8_valid_any_format",
                run: png_valid::<RGBA8>,
            },
            Class {
                name: "rgba8_header_fields",
                run: png_header_fields::<RGBA8>,
            },
            Class {
                name: "rgba8_zlib_damage",
                run: png_zlib_damage::<RGBA8>,
            },
            Class {
                name: "rgba8_truncated",
                run: png_truncated::<RGBA8>,
            },
        ]);
    }
    classes
}

#[test]
fn fuzz_png16() {
    harness::run(
        Target {
            name: "png16",
            per_case_limit: PER_CASE_LIMIT,
            classes: png_classes::<GRAY16>(false),
            disabled: &[],
        },
        Ctx::new("png16"),
    );
}

#[test]
fn fuzz_png8() {
    harness::run(
        Target {
            name: "png8",
            per_case_limit: PER_CASE_LIMIT,
            classes: png_classes::<GRAY8>(true),
            disabled: &[],
        },
        Ctx::new("png8"),
    );
}

// ---------------------------------------------------------------------------------------------
// RAW16

/// The error `decode_raw16` must give for `len` bytes at `size` under `limits`, if any.
fn raw16_expected(len: usize, size: UVec2, limits: &ReadLimits) -> Option<&'static str> {
    if size.x == 0 || size.y == 0 {
        return Some("ZeroSize");
    }
    if size.x > limits.max_side || size.y > limits.max_side {
        return Some("TooLarge");
    }
    let need = u128::from(size.x) * u128::from(size.y) * 2;
    if need > u128::from(u64::MAX) {
        return Some("TooLarge");
    }
    (len as u128 != need).then_some("RawSizeMismatch")
}

fn raw16_variant(e: &MapIoError) -> &'static str {
    match e {
        MapIoError::ZeroSize { .. } => "ZeroSize",
        MapIoError::TooLarge { .. } => "TooLarge",
        MapIoError::RawSizeMismatch { .. } => "RawSizeMismatch",
        _ => "other",
    }
}

fn check_raw16(
    bytes: &[u8],
    size: UVec2,
    limits: &ReadLimits,
    got: Result<Grid<u16>, MapIoError>,
) -> Result<(), String> {
    let want = raw16_expected(bytes.len(), size, limits);
    match (want, got) {
        (None, Ok(g)) => {
            let same = g.size() == size
                && g.as_slice()
                    .iter()
                    .zip(bytes.chunks_exact(2))
                    .all(|(v, b)| *v == u16::from_le_bytes([b[0], b[1]]));
            if same {
                Ok(())
            } else {
                Err(format!("{size} from {} bytes: wrong samples", bytes.len()))
            }
        }
        (Some(v), Err(e)) if raw16_variant(&e) == v => Ok(()),
        (want, got) => Err(format!(
            "{size} from {} bytes, limits {limits:?}: expected {}, got {:?}",
            bytes.len(),
            want.unwrap_or("Ok"),
            got.map(|g| g.size())
        )),
    }
}

/// Round trips through `encode_raw16`.
fn raw16_roundtrip(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let (w, h) = (side(rng), side(rng));
    let samples = (0..w * h).map(|_| rng.next_u32() as u16).collect();
    let g = Grid::from_vec(w, h, samples).unwrap();
    let bytes = encode_raw16(&g);
    match decode_raw16(&bytes, g.size(), &ReadLimits::default()) {
        Ok(d) if d == g => Ok(()),
        other => Err(format!("{w}x{h}: round trip gave {other:?}")),
    }
}

/// Byte counts beside the right one (short, long, odd) for the size given.
fn raw16_length_mismatch(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let size = UVec2::new(side(rng), side(rng));
    let right = (size.x * size.y * 2) as usize;
    let len = match rng.below(4) {
        0 => right + rng.range_usize(1, 3),
        1 => right.saturating_sub(rng.range_usize(1, 3)),
        2 => rng.index(2 * right + 2),
        _ => right,
    };
    let bytes = rng.bytes(len);
    let limits = limits_for(rng);
    check_raw16(&bytes, size, &limits, decode_raw16(&bytes, size, &limits))
}

/// Sizes at and past the limits: zero sides, `max_side` and its neighbours, sizes whose byte
/// count overflows, limits raised to `u32::MAX`.
fn raw16_size_limits(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let max_side = match rng.below(3) {
        0 => rng.range_u32(1, 64),
        1 => DEFAULT_MAX_SIDE,
        _ => u32::MAX,
    };
    let limits = ReadLimits { max_side };
    let pick_side = |rng: &mut Rng| match rng.below(4) {
        0 => rng.u32_edge(),
        1 => max_side
            .saturating_add(rng.range_u32(0, 2))
            .saturating_sub(1),
        2 => 0,
        _ => rng.range_u32(1, 40),
    };
    let size = UVec2::new(pick_side(rng), pick_side(rng));
    // Only the right byte count for sizes small enough to hold; otherwise a few bytes.
    let need = u128::from(size.x) * u128::from(size.y) * 2;
    let len = if need <= 8192 && rng.chance(1, 2) {
        need as usize
    } else {
        rng.index(64)
    };
    let bytes = rng.bytes(len);
    check_raw16(&bytes, size, &limits, decode_raw16(&bytes, size, &limits))
}

/// Random bytes at random small sizes.
fn raw16_random(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let size = UVec2::new(rng.range_u32(0, 40), rng.range_u32(0, 40));
    let n = rng.range_usize(0, 4000);
    let bytes = rng.bytes(n);
    let limits = limits_for(rng);
    check_raw16(&bytes, size, &limits, decode_raw16(&bytes, size, &limits))
}

/// `read_raw16` (length checked from the file's metadata) against `decode_raw16`; a missing
/// file is an I/O error.
fn raw16_file_reader(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let size = UVec2::new(rng.range_u32(0, 40), rng.range_u32(0, 40));
    let right = (size.x * size.y * 2) as usize;
    let len = if rng.chance(1, 2) {
        right
    } else {
        rng.index(right + 8)
    };
    let bytes = rng.bytes(len);
    let limits = limits_for(rng);
    let path = ctx.dir.join(format!("{:016x}.r16", rng.next_u64()));
    if rng.chance(1, 10) {
        return match read_raw16(&path, size, &limits) {
            Err(MapIoError::Io { .. }) | Err(MapIoError::ZeroSize { .. }) => Ok(()),
            Err(MapIoError::TooLarge { .. }) => Ok(()),
            other => Err(format!("a missing file gave {:?}", other.map(|g| g.size()))),
        };
    }
    std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
    let got = read_raw16(&path, size, &limits);
    let _ = std::fs::remove_file(&path);
    check_raw16(&bytes, size, &limits, got)
}

#[test]
fn fuzz_raw16() {
    harness::run(
        Target {
            name: "raw16",
            per_case_limit: PER_CASE_LIMIT,
            classes: vec![
                Class {
                    name: "roundtrip",
                    run: raw16_roundtrip,
                },
                Class {
                    name: "length_mismatch",
                    run: raw16_length_mismatch,
                },
                Class {
                    name: "size_limits",
                    run: raw16_size_limits,
                },
                Class {
                    name: "random_bytes",
                    run: raw16_random,
                },
                Class {
                    name: "file_reader",
                    run: raw16_file_reader,
                },
            ],
            disabled: &[],
        },
        Ctx::new("raw16"),
    );
}

// ---------------------------------------------------------------------------------------------
// GeoTIFF

/// A valid GeoTIFF from the tests' writer, and the heights it must decode to.
fn geotiff_seed(rng: &mut Rng) -> (Vec<u8>, Vec<f32>) {
    use tiff_writer::{Layout, Sample, TiffSpec};
    let sample = rng.pick(&Sample::ALL);
    let (w, h) = (side(rng), side(rng));
    let values: Vec<f64> = (0..w * h)
        .map(|_| match sample {
            Sample::U8 => f64::from(rng.below(256) as u8),
            Sample::I8 => f64::from(rng.below(256) as u8 as i8),
            Sample::U16 => f64::from(rng.next_u32() as u16),
            Sample::I16 => f64::from(rng.next_u32() as u16 as i16),
            Sample::U32 => f64::from(rng.next_u32() >> 8),
            Sample::I32 => f64::from((rng.next_u32() >> 8) as i32 - (1 << 23)),
            Sample::F32 | Sample::F64 => f64::from(rng.uniform(-500.0, 9000.0) as f32),
        })
        .collect();
    let want = values.iter().map(|&v| v as f32).collect();
    let layout = if rng.chance(1, 3) {
        Layout::Tiles(16 * rng.range_u32(1, 2), 16 * rng.range_u32(1, 2))
    } else {
        Layout::Strips(rng.range_u32(1, h + 1))
    };
    let spec = TiffSpec {
        big_endian: rng.chance(1, 2),
        bigtiff: rng.chance(1, 4),
        layout,
        pixel_scale: rng
            .chance(1, 2)
            .then(|| [rng.uniform(0.0001, 50.0), 5.0, 0.0]),
        tiepoint: rng
            .chance(1, 3)
            .then(|| [0.0, 0.0, 0.0, 7.0, rng.uniform(-80.0, 80.0), 0.0]),
        geokeys: if rng.chance(1, 2) {
            vec![(1024, rng.range_u32(1, 3) as u16), (3076, 9001)]
        } else {
            Vec::new()
        },
        ..TiffSpec::new(w, h, sample, values)
    };
    (spec.write(), want)
}

/// Any input: `Ok` within the limits (with a texel size, when any, that is finite), or `Err`.
fn geotiff_any(bytes: &[u8], limits: &ReadLimits) -> Result<(), String> {
    match decode_geotiff(bytes, limits) {
        Ok(t) => {
            let s = t.heights.size();
            if s.x == 0 || s.y == 0 || s.x > limits.max_side || s.y > limits.max_side {
                return Err(format!("decoded {s} under {limits:?}"));
            }
            Ok(())
        }
        Err(_) => Ok(()),
    }
}

/// Valid files decode to exactly the heights written.
fn geotiff_valid(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (bytes, want) = geotiff_seed(&mut case.rng);
    match decode_geotiff(&bytes, &ReadLimits::default()) {
        Ok(t) if t.heights.as_slice() == want => Ok(()),
        Ok(_) => Err("wrong heights".into()),
        Err(e) => Err(format!("a valid file was refused: {e}")),
    }
}

/// Valid files cut anywhere.
fn geotiff_truncated(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (bytes, _) = geotiff_seed(&mut case.rng);
    let n = case.rng.index(bytes.len());
    match decode_geotiff(&bytes[..n], &ReadLimits::default()) {
        Err(_) => Ok(()),
        // The directory is written last: a cut file has lost part of it.
        Ok(_) => Err(format!("{n} of {} bytes decoded", bytes.len())),
    }
}

/// Valid files with bits flipped.
fn geotiff_bit_flips(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (mut bytes, _) = geotiff_seed(&mut case.rng);
    flip_bits(&mut bytes, &mut case.rng);
    let limits = limits_for(&mut case.rng);
    geotiff_any(&bytes, &limits)
}

/// Valid files with directory entries' types, counts and offsets overwritten (sizes, strip
/// offsets and counts, tag value counts: where a decoder trusts the file most).
fn geotiff_directory_fields(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (mut bytes, _) = geotiff_seed(&mut case.rng);
    let rng = &mut case.rng;
    let big = bytes[0] == b'M';
    let bigtiff = bytes[2..4] == [0, 43] || bytes[2..4] == [43, 0];
    let rd = |b: &[u8]| -> u64 {
        let mut v = 0u64;
        if big {
            for &x in b {
                v = v << 8 | u64::from(x);
            }
        } else {
            for &x in b.iter().rev() {
                v = v << 8 | u64::from(x);
            }
        }
        v
    };
    let (ifd, count_len, entry_len) = if bigtiff {
        (rd(&bytes[8..16]) as usize, 8, 20)
    } else {
        (rd(&bytes[4..8]) as usize, 2, 12)
    };
    let n = rd(&bytes[ifd..ifd + count_len]) as usize;
    for _ in 0..rng.range_u32(1, 4) {
        let e = ifd + count_len + entry_len * rng.index(n);
        // A field of the entry (type, count or value) gets an edge value.
        let (at, len) = match rng.below(3) {
            0 => (e + 2, 2),
            1 => (e + 4, if bigtiff { 8 } else { 4 }),
            _ => (
                e + if bigtiff { 12 } else { 8 },
                if bigtiff { 8 } else { 4 },
            ),
        };
        let v = match rng.below(4) {
            0 => u64::from(rng.u32_edge()),
            1 => rng.below(20),
            2 => rng.next_u64(),
            _ => bytes.len() as u64 + rng.below(16),
        };
        for i in 0..len {
            let shift = if big { 8 * (len - 1 - i) } else { 8 * i };
            bytes[at + i] = (v >> shift) as u8;
        }
    }
    let limits = limits_for(rng);
    geotiff_any(&bytes, &limits)
}

/// Random bytes, half of them behind a TIFF header.
fn geotiff_random(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let n = rng.range_usize(0, 600);
    let mut bytes = rng.bytes(n);
    if rng.chance(1, 2) && bytes.len() >= 8 {
        bytes[..4].copy_from_slice(if rng.chance(1, 2) { b"II*\0" } else { b"MM\0*" });
        bytes[4..8].copy_from_slice(&[8, 0, 0, 0]);
    }
    let limits = limits_for(rng);
    geotiff_any(&bytes, &limits)
}

/// `read_geotiff` on a file equals `decode_geotiff` on its bytes.
fn geotiff_file_reader(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let (mut bytes, _) = geotiff_seed(&mut case.rng);
    if case.rng.chance(1, 2) {
        flip_bits(&mut bytes, &mut case.rng);
    }
    let limits = ReadLimits::default();
    let path = ctx.dir.join(format!("{:016x}.tif", case.rng.next_u64()));
    std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
    let from_file = read_geotiff(&path, &limits);
    let _ = std::fs::remove_file(&path);
    match (from_file, decode_geotiff(&bytes, &limits)) {
        (Ok(a), Ok(b))
            if a.heights.as_slice().iter().map(|v| v.to_bits()).eq(b
                .heights
                .as_slice()
                .iter()
                .map(|v| v.to_bits())) =>
        {
            Ok(())
        }
        (Err(_), Err(_)) => Ok(()),
        (a, b) => Err(format!(
            "file and memory disagree: {:?} / {:?}",
            a.map(|t| t.heights.size()),
            b.map(|t| t.heights.size())
        )),
    }
}

#[test]
fn fuzz_geotiff() {
    harness::run(
        Target {
            name: "geotiff",
            per_case_limit: PER_CASE_LIMIT,
            classes: vec![
                Class {
                    name: "valid",
                    run: geotiff_valid,
                },
                Class {
                    name: "truncated",
                    run: geotiff_truncated,
                },
                Class {
                    name: "bit_flips",
                    run: geotiff_bit_flips,
                },
                Class {
                    name: "directory_fields",
                    run: geotiff_directory_fields,
                },
                Class {
                    name: "random_bytes",
                    run: geotiff_random,
                },
                Class {
                    name: "file_reader",
                    run: geotiff_file_reader,
                },
            ],
            disabled: &[],
        },
        Ctx::new("geotiff"),
    );
}
