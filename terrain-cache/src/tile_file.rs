//! The `.tile` file: how worlds of format version 2 store a tile (PNG files stay for version-1
//! worlds and for import / export).
//!
//! Layout (all integers little-endian):
//!
//! | bytes  | field                                                                  |
//! |--------|------------------------------------------------------------------------|
//! | 0..4   | magic `b"TCTL"`                                                        |
//! | 4      | version: 1, or 2 for a file that names its tile (below)                |
//! | 5      | bits per sample: 16 (heights) or 8 (detail)                            |
//! | 6      | codec: 0 raw samples, 1 LZ4 block (of filtered samples for 16 bits)    |
//! | 7      | flags, 0 (none defined; a set bit is refused)                          |
//! | 8..12  | width in samples (u32)                                                 |
//! | 12..16 | height in samples (u32)                                                |
//! | 16..20 | payload length in bytes (u32): the file is exactly 24 + this long       |
//! | 20..24 | CRC-32 (IEEE) of bytes 0..20 followed by everything after byte 24      |
//! | 24..   | payload (version 1)                                                    |
//!
//! Version 2 (what a [`World`](crate::World) writes) inserts the tile's identity before the
//! payload, covered by the checksum, so a valid file copied or moved to another tile's path is
//! refused ([`TileFileError::Identity`]) instead of read as that tile:
//!
//! | bytes  | field                                                                  |
//! |--------|------------------------------------------------------------------------|
//! | 24     | layer: 0 heights, 1 detail                                             |
//! | 25..28 | reserved, 0                                                            |
//! | 28..32 | level (u32)                                                            |
//! | 32..36 | column x (u32)                                                         |
//! | 36..40 | row y (u32)                                                            |
//! | 40..   | payload                                                                |
//!
//! Version-1 files (written before, or by [`encode`] without an identity) still decode; they
//! carry no identity to check.
//!
//! Raw payload: the samples row-major, little-endian. LZ4 payload: an LZ4 block that
//! decompresses to exactly `width * height * bits / 8` bytes. 8-bit samples go in as they
//! are. 16-bit samples are filtered first: per row, each sample minus the one to its left (the
//! first minus 0), wrapping, zigzag-coded, as two planes, every low byte then every high byte
//! (smooth terrain's deltas are small, so the high plane is nearly all zero).
//!
//! Measured choices (docs/MEASUREMENTS.md): heights are written raw, since a 256^2 tile then
//! loads in about 1.3x the time of reading and copying its bytes, while LZ4 saved nothing on
//! the procedural world's noisy 256^2 tiles (25 % at 2048^2) and took 4x as long to load.
//! Detail tiles are written with LZ4: they are mostly the zero deformation, so a 2048^2 tile
//! with 40 footprints shrinks from 4 MiB to 3 % and decodes in about 1 ms; a delta filter
//! saved another 15 % of the size but made decoding 4x slower.

use crate::manifest::{MAX_TILE_SIZE, MIN_TILE_SIZE};
use crate::tile::{Layer, TileData, TileId};
use terrain_core::Grid;
use terrain_core::io::MapIoError;

/// The first four bytes of a tile file.
pub const MAGIC: [u8; 4] = *b"TCTL";
/// The tile file version without an identity, which [`encode`] writes (and every build reads).
pub const VERSION: u8 = 1;
/// The tile file version that names its tile ([`encode_as`]; what worlds write).
pub const VERSION_WITH_IDENTITY: u8 = 2;
/// Bytes before the payload in a version-1 file (and the common header of both versions).
pub const HEADER_LEN: usize = 24;
/// Bytes before the payload in a version-2 file: the header and the identity.
pub const HEADER_LEN_WITH_IDENTITY: usize = 40;

/// Which tile a file was written for: what a version-2 file carries after its header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TileIdentity {
    /// The layer.
    pub layer: Layer,
    /// The tile.
    pub id: TileId,
}

impl TileIdentity {
    /// Tile `id` of `layer`.
    pub const fn new(layer: Layer, id: TileId) -> Self {
        Self { layer, id }
    }

    fn to_bytes(self) -> [u8; 16] {
        let mut b = [0u8; 16];
        b[0] = layer_byte(self.layer);
        b[4..8].copy_from_slice(&self.id.level.to_le_bytes());
        b[8..12].copy_from_slice(&self.id.x.to_le_bytes());
        b[12..16].copy_from_slice(&self.id.y.to_le_bytes());
        b
    }
}

const fn layer_byte(layer: Layer) -> u8 {
    match layer {
        Layer::Height => 0,
        Layer::Detail => 1,
        Layer::Hole => 2,
        Layer::Material => 3,
        Layer::Color => 4,
    }
}

/// How a tile file's payload holds the samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TileCodec {
    /// The samples as they are, little-endian.
    Raw,
    /// Row-delta filtered samples, LZ4 block compressed.
    Lz4,
}

impl TileCodec {
    /// The codec byte in the header.
    pub const fn byte(self) -> u8 {
        match self {
            TileCodec::Raw => 0,
            TileCodec::Lz4 => 1,
        }
    }

    /// The codec of a header byte.
    pub const fn from_byte(b: u8) -> Option<Self> {
        match b {
            0 => Some(TileCodec::Raw),
            1 => Some(TileCodec::Lz4),
            _ => None,
        }
    }

    /// The codec a world of format version 2 writes `layer`'s tiles with.
    pub const fn for_layer(layer: Layer) -> Self {
        match layer {
            Layer::Height => TileCodec::Raw,
            // Holes are rare: LZ4 keeps a tile with a few of them small.
            Layer::Detail | Layer::Hole | Layer::Material | Layer::Color => TileCodec::Lz4,
        }
    }
}

/// Why a tile file does not decode.
#[derive(Debug, thiserror::Error)]
pub enum TileFileError {
    /// A PNG tile (a version-1 world's) did not decode.
    #[error("PNG: {0}")]
    Png(#[from] MapIoError),
    /// Shorter than the header.
    #[error("{len} bytes, shorter than the {HEADER_LEN}-byte tile header")]
    Truncated {
        /// The file's length.
        len: usize,
    },
    /// Not a tile file.
    #[error("not a tile file: magic {found:02x?}, expected \"TCTL\"")]
    Magic {
        /// The first four bytes.
        found: [u8; 4],
    },
    /// A version this build does not read.
    #[error(
        "tile file version {found}; this build reads versions {VERSION} and {VERSION_WITH_IDENTITY}"
    )]
    Version {
        /// The version byte.
        found: u8,
    },
    /// An unknown codec or a flag this build does not know.
    #[error("unknown codec {codec} or flags {flags:#04x}")]
    Codec {
        /// The codec byte.
        codec: u8,
        /// The flags byte.
        flags: u8,
    },
    /// The samples have another bit depth than the layer.
    #[error("{found} bits per sample, the layer has {expected}")]
    Bits {
        /// The header's.
        found: u8,
        /// The layer's.
        expected: u8,
    },
    /// The tile side asked for is no world's: tiles are a power of two in 16..=4096 (checked
    /// before anything is read, since allocation is bounded by the side).
    #[error("tiles of side {side} do not exist: a side is a power of two in 16..=4096")]
    Side {
        /// The side asked for.
        side: u32,
    },
    /// The header's size differs from the world's tile size (checked before any allocation).
    #[error("{found_w}x{found_h} samples, the world's tiles are {expected}x{expected}")]
    Shape {
        /// The header's width.
        found_w: u32,
        /// The header's height.
        found_h: u32,
        /// The world's tile side.
        expected: u32,
    },
    /// The file is longer or shorter than its header says (truncated, or appended to).
    #[error("the header says {expected} payload bytes, the file holds {found}")]
    Length {
        /// The header's payload length.
        expected: u64,
        /// The bytes after the header.
        found: u64,
    },
    /// The checksum does not match: the file was damaged.
    #[error("checksum mismatch: stored {stored:#010x}, computed {computed:#010x}")]
    Checksum {
        /// The header's.
        stored: u32,
        /// Of the bytes read.
        computed: u32,
    },
    /// A valid file written for another tile (copied or moved to this tile's path).
    #[error(
        "the file was written for {} tile L{level}({x:#x}, {y:#x}), not this one (a tile file \
         copied or moved from another path)",
        match layer {
            0 => "height",
            1 => "detail",
            2 => "hole",
            3 => "material",
            4 => "colour",
            _ => "an unknown layer's",
        }
    )]
    Identity {
        /// The layer byte found (0 heights, 1 detail, 2 holes, 3 materials, 4 colours).
        layer: u8,
        /// The level found.
        level: u32,
        /// The column found.
        x: u32,
        /// The row found.
        y: u32,
    },
    /// A payload whose checksum matches but does not hold the tile's samples (a writer bug, or
    /// a file crafted with a valid checksum).
    #[error("the {codec:?} payload does not hold {expected} bytes of samples: {reason}")]
    Payload {
        /// The codec.
        codec: TileCodec,
        /// Bytes of samples the tile has.
        expected: usize,
        /// What was wrong.
        reason: String,
    },
}

/// The file bytes of `data` with `codec`, version 1 (no identity).
pub fn encode(data: &TileData, codec: TileCodec) -> Vec<u8> {
    match data {
        TileData::U16(g) => encode_u16(g, codec),
        TileData::U8(g) => encode_u8(g, codec),
        TileData::Rgba8(g) => encode_rgba8_with(g, codec, None),
    }
}

/// The file bytes of `data` with `codec`, version 2: naming the tile it is written for.
pub fn encode_as(data: &TileData, codec: TileCodec, identity: TileIdentity) -> Vec<u8> {
    match data {
        TileData::U16(g) => encode_u16_with(g, codec, Some(identity)),
        TileData::U8(g) => encode_u8_with(g, codec, Some(identity)),
        TileData::Rgba8(g) => encode_rgba8_with(g, codec, Some(identity)),
    }
}

/// The file bytes of a height grid, version 1 (no identity).
pub fn encode_u16(grid: &Grid<u16>, codec: TileCodec) -> Vec<u8> {
    encode_u16_with(grid, codec, None)
}

/// The file bytes of a height grid, version 2 when `identity` is given.
pub fn encode_u16_with(
    grid: &Grid<u16>,
    codec: TileCodec,
    identity: Option<TileIdentity>,
) -> Vec<u8> {
    let samples = grid.as_slice();
    match codec {
        TileCodec::Raw => finish(16, codec, grid.width(), grid.height(), identity, |out| {
            if cfg!(target_endian = "little") {
                out.extend_from_slice(bytemuck::cast_slice(samples));
            } else {
                out.extend(samples.iter().flat_map(|v| v.to_le_bytes()));
            }
        }),
        TileCodec::Lz4 => {
            let filtered = filter_u16(samples, grid.width() as usize);
            finish(16, codec, grid.width(), grid.height(), identity, |out| {
                compress_into(&filtered, out)
            })
        }
    }
}

/// The file bytes of a detail grid, version 1 (no identity).
pub fn encode_u8(grid: &Grid<u8>, codec: TileCodec) -> Vec<u8> {
    encode_u8_with(grid, codec, None)
}

/// The file bytes of a detail grid, version 2 when `identity` is given.
pub fn encode_u8_with(
    grid: &Grid<u8>,
    codec: TileCodec,
    identity: Option<TileIdentity>,
) -> Vec<u8> {
    let samples = grid.as_slice();
    match codec {
        TileCodec::Raw => finish(8, codec, grid.width(), grid.height(), identity, |out| {
            out.extend_from_slice(samples)
        }),
        TileCodec::Lz4 => finish(8, codec, grid.width(), grid.height(), identity, |out| {
            compress_into(samples, out)
        }),
    }
}

/// The file bytes of a material grid, version 2 when `identity` is given. LZ4 takes the
/// four channels as planes (all grass, then all dirt, ...): a channel varies smoothly, so a
/// plane compresses better than interleaved texels.
pub fn encode_rgba8_with(
    grid: &Grid<[u8; 4]>,
    codec: TileCodec,
    identity: Option<TileIdentity>,
) -> Vec<u8> {
    let (w, h) = (grid.width(), grid.height());
    match codec {
        TileCodec::Raw => finish(32, codec, w, h, identity, |out| {
            out.extend_from_slice(bytemuck::cast_slice(grid.as_slice()))
        }),
        TileCodec::Lz4 => {
            let texels = grid.as_slice();
            let planes: Vec<u8> = (0..4)
                .flat_map(|c| texels.iter().map(move |t| t[c]))
                .collect();
            finish(32, codec, w, h, identity, |out| compress_into(&planes, out))
        }
    }
}

/// Header (and identity), then the payload `body` appends, then the length and checksum
/// filled in.
fn finish(
    bits: u8,
    codec: TileCodec,
    w: u32,
    h: u32,
    identity: Option<TileIdentity>,
    body: impl FnOnce(&mut Vec<u8>),
) -> Vec<u8> {
    let raw_len = w as usize * h as usize * usize::from(bits / 8);
    let mut out = Vec::with_capacity(HEADER_LEN_WITH_IDENTITY + raw_len);
    out.extend_from_slice(&MAGIC);
    let version = if identity.is_some() {
        VERSION_WITH_IDENTITY
    } else {
        VERSION
    };
    out.extend_from_slice(&[version, bits, codec.byte(), 0]);
    out.extend_from_slice(&w.to_le_bytes());
    out.extend_from_slice(&h.to_le_bytes());
    out.extend_from_slice(&[0; 8]);
    if let Some(identity) = identity {
        out.extend_from_slice(&identity.to_bytes());
    }
    let header = out.len();
    body(&mut out);
    // Tiles are at most 4096^2 x 2 bytes (the manifest's bound), far below 4 GiB.
    let payload_len = (out.len() - header) as u32;
    out[16..20].copy_from_slice(&payload_len.to_le_bytes());
    let sum = checksum(&out[..20], &out[HEADER_LEN..]);
    out[20..24].copy_from_slice(&sum.to_le_bytes());
    out
}

fn checksum(head: &[u8], payload: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(head);
    h.update(payload);
    h.finalize()
}

fn compress_into(filtered: &[u8], out: &mut Vec<u8>) {
    let start = out.len();
    out.resize(
        start + lz4_flex::block::get_maximum_output_size(filtered.len()),
        0,
    );
    // The buffer has the block format's worst-case size, so compression cannot run out of
    // room; were it to fail anyway, the raw bytes would not decode as LZ4 and be refused.
    let n = lz4_flex::block::compress_into(filtered, &mut out[start..]).unwrap_or(0);
    out.truncate(start + n);
}

/// The largest file a tile of `side` x `side` samples of `bits` can take in this format.
/// A side no world has (over 2^20) answers `u64::MAX`.
pub fn max_file_len(side: u32, bits: u8) -> u64 {
    if side > 1 << 20 {
        return u64::MAX;
    }
    let raw = u64::from(side) * u64::from(side) * u64::from(bits / 8);
    let lz4_worst = lz4_flex::block::get_maximum_output_size(raw as usize) as u64;
    HEADER_LEN_WITH_IDENTITY as u64 + raw.max(lz4_worst)
}

/// Decodes a tile file of `layer` whose tiles are `side` x `side`: header and length checked,
/// then the checksum, then the payload; allocation is bounded by `side`, never by the header.
/// A version-2 file's identity is checked for integrity only; [`decode_as`] also checks that
/// it names the tile asked for.
pub fn decode(bytes: &[u8], layer: Layer, side: u32) -> Result<TileData, TileFileError> {
    decode_checked(bytes, layer, side, None)
}

/// Decodes the file of tile `identity` as [`decode`] does, and refuses a version-2 file
/// written for another tile ([`TileFileError::Identity`]). A version-1 file names no tile and
/// is accepted as it decodes.
pub fn decode_as(
    bytes: &[u8],
    identity: TileIdentity,
    side: u32,
) -> Result<TileData, TileFileError> {
    decode_checked(bytes, identity.layer, side, Some(identity))
}

fn decode_checked(
    bytes: &[u8],
    layer: Layer,
    side: u32,
    expected: Option<TileIdentity>,
) -> Result<TileData, TileFileError> {
    if !side.is_power_of_two() || !(MIN_TILE_SIZE..=MAX_TILE_SIZE).contains(&side) {
        return Err(TileFileError::Side { side });
    }
    if bytes.len() < HEADER_LEN {
        return Err(TileFileError::Truncated { len: bytes.len() });
    }
    let u32_at =
        |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    let magic = [bytes[0], bytes[1], bytes[2], bytes[3]];
    if magic != MAGIC {
        return Err(TileFileError::Magic { found: magic });
    }
    let header = match bytes[4] {
        VERSION => HEADER_LEN,
        VERSION_WITH_IDENTITY if bytes.len() >= HEADER_LEN_WITH_IDENTITY => {
            HEADER_LEN_WITH_IDENTITY
        }
        VERSION_WITH_IDENTITY => return Err(TileFileError::Truncated { len: bytes.len() }),
        found => return Err(TileFileError::Version { found }),
    };
    let (bits, codec_byte, flags) = (bytes[5], bytes[6], bytes[7]);
    let codec = match TileCodec::from_byte(codec_byte) {
        Some(c) if flags == 0 => c,
        _ => {
            return Err(TileFileError::Codec {
                codec: codec_byte,
                flags,
            });
        }
    };
    if bits != layer.bits() {
        return Err(TileFileError::Bits {
            found: bits,
            expected: layer.bits(),
        });
    }
    let (w, h) = (u32_at(8), u32_at(12));
    if w != side || h != side {
        return Err(TileFileError::Shape {
            found_w: w,
            found_h: h,
            expected: side,
        });
    }
    let payload = &bytes[header..];
    let declared = u64::from(u32_at(16));
    if declared != payload.len() as u64 {
        return Err(TileFileError::Length {
            expected: declared,
            found: payload.len() as u64,
        });
    }
    let stored = u32_at(20);
    let computed = checksum(&bytes[..20], &bytes[HEADER_LEN..]);
    if stored != computed {
        return Err(TileFileError::Checksum { stored, computed });
    }
    if header == HEADER_LEN_WITH_IDENTITY {
        let found: [u8; 16] = std::array::from_fn(|i| bytes[HEADER_LEN + i]);
        let known = matches!(found[0], 0..=4) && found[1..4] == [0, 0, 0];
        if !known || expected.is_some_and(|e| e.to_bytes() != found) {
            return Err(TileFileError::Identity {
                layer: found[0],
                level: u32_at(28),
                x: u32_at(32),
                y: u32_at(36),
            });
        }
    }
    let n = side as usize * side as usize;
    let bad = |expected: usize, reason: String| TileFileError::Payload {
        codec,
        expected,
        reason,
    };
    Ok(match (layer, codec) {
        (Layer::Height, TileCodec::Raw) => {
            if payload.len() != 2 * n {
                return Err(bad(2 * n, format!("{} bytes", payload.len())));
            }
            let mut out = vec![0u16; n];
            bytemuck::cast_slice_mut::<u16, u8>(&mut out).copy_from_slice(payload);
            if cfg!(target_endian = "big") {
                out.iter_mut().for_each(|v| *v = u16::from_le(*v));
            }
            TileData::U16(grid(side, out))
        }
        (Layer::Detail | Layer::Hole, TileCodec::Raw) => {
            if payload.len() != n {
                return Err(bad(n, format!("{} bytes", payload.len())));
            }
            TileData::U8(grid(side, payload.to_vec()))
        }
        (Layer::Height, TileCodec::Lz4) => {
            let planes = decompress(payload, 2 * n).map_err(|r| bad(2 * n, r))?;
            TileData::U16(grid(side, unfilter_u16(&planes, side as usize)))
        }
        (Layer::Detail | Layer::Hole, TileCodec::Lz4) => {
            TileData::U8(grid(side, decompress(payload, n).map_err(|r| bad(n, r))?))
        }
        (Layer::Material | Layer::Color, TileCodec::Raw) => {
            if payload.len() != 4 * n {
                return Err(bad(4 * n, format!("{} bytes", payload.len())));
            }
            TileData::Rgba8(grid(side, bytemuck::cast_slice(payload).to_vec()))
        }
        (Layer::Material | Layer::Color, TileCodec::Lz4) => {
            let planes = decompress(payload, 4 * n).map_err(|r| bad(4 * n, r))?;
            let texels = (0..n)
                .map(|i| {
                    [
                        planes[i],
                        planes[n + i],
                        planes[2 * n + i],
                        planes[3 * n + i],
                    ]
                })
                .collect();
            TileData::Rgba8(grid(side, texels))
        }
    })
}

/// A `side` x `side` grid of `data`, which has `side^2` samples by construction.
fn grid<T: Copy + Default>(side: u32, data: Vec<T>) -> Grid<T> {
    Grid::from_vec(side, side, data).unwrap_or_else(|_| {
        // Unreachable: every caller sized `data` from `side`, which the manifest bounds.
        Grid::new(1, 1, T::default()).unwrap_or_else(|_| unreachable!("1x1 grid"))
    })
}

/// Exactly `len` bytes out of an LZ4 block, or why not.
fn decompress(payload: &[u8], len: usize) -> Result<Vec<u8>, String> {
    let mut out = vec![0u8; len];
    match lz4_flex::block::decompress_into(payload, &mut out) {
        Ok(n) if n == len => Ok(out),
        Ok(n) => Err(format!("it decompresses to {n} bytes")),
        Err(e) => Err(e.to_string()),
    }
}

fn zigzag16(d: u16) -> u16 {
    let s = d as i16;
    ((s << 1) ^ (s >> 15)) as u16
}

fn unzigzag16(z: u16) -> u16 {
    (z >> 1) ^ (z & 1).wrapping_neg()
}

/// Row deltas, zigzag, split into a low-byte plane then a high-byte plane.
fn filter_u16(samples: &[u16], width: usize) -> Vec<u8> {
    let n = samples.len();
    let mut out = vec![0u8; 2 * n];
    let (lo, hi) = out.split_at_mut(n);
    for (r, row) in samples.chunks_exact(width.max(1)).enumerate() {
        let mut prev = 0u16;
        for (i, &v) in row.iter().enumerate() {
            let z = zigzag16(v.wrapping_sub(prev));
            prev = v;
            lo[r * width + i] = z as u8;
            hi[r * width + i] = (z >> 8) as u8;
        }
    }
    out
}

fn unfilter_u16(planes: &[u8], width: usize) -> Vec<u16> {
    let n = planes.len() / 2;
    let (lo, hi) = planes.split_at(n);
    let mut out = vec![0u16; n];
    for ((row, lo), hi) in out
        .chunks_exact_mut(width.max(1))
        .zip(lo.chunks_exact(width.max(1)))
        .zip(hi.chunks_exact(width.max(1)))
    {
        let mut prev = 0u16;
        for ((o, &l), &h) in row.iter_mut().zip(lo).zip(hi) {
            prev = prev.wrapping_add(unzigzag16(u16::from(l) | (u16::from(h) << 8)));
            *o = prev;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn heights(side: u32) -> Grid<u16> {
        Grid::from_fn(side, side, |x, y| {
            (30_000.0 + 8_000.0 * ((x as f32) * 0.05).sin() * ((y as f32) * 0.03).cos()) as u16
                ^ ((x * 7 + y * 13) % 5) as u16
        })
        .unwrap()
    }

    #[test]
    fn zigzag_is_invertible() {
        for v in 0..=u16::MAX {
            assert_eq!(unzigzag16(zigzag16(v)), v);
        }
        assert_eq!(zigzag16(1u16.wrapping_neg()), 1);
        assert_eq!(zigzag16(1), 2);
    }

    #[test]
    fn every_codec_round_trips_every_layer() {
        let h = heights(64);
        let d = Grid::from_fn(64, 64, |x, y| if x > 20 && y < 9 { 90 } else { 128u8 }).unwrap();
        let paint = Grid::from_fn(64, 64, |x, y| {
            let a = (200u32.saturating_sub(3 * (x + y))) as u8;
            [0, a, a / 4, 0]
        })
        .unwrap();
        for codec in [TileCodec::Raw, TileCodec::Lz4] {
            let bytes = encode_u16(&h, codec);
            assert!(bytes.len() as u64 <= max_file_len(64, 16));
            assert_eq!(
                decode(&bytes, Layer::Height, 64).unwrap(),
                TileData::U16(h.clone())
            );
            let bytes = encode_u8(&d, codec);
            assert_eq!(
                decode(&bytes, Layer::Detail, 64).unwrap(),
                TileData::U8(d.clone())
            );
            let bytes = encode_rgba8_with(&paint, codec, None);
            assert!(bytes.len() as u64 <= max_file_len(64, 32));
            assert_eq!(
                decode(&bytes, Layer::Material, 64).unwrap(),
                TileData::Rgba8(paint.clone())
            );
            // A material file is refused as another layer's, and the other way round.
            assert!(decode(&bytes, Layer::Detail, 64).is_err());
            assert!(decode(&encode_u8(&d, codec), Layer::Material, 64).is_err());
        }
        // Paint that covers a crater's corner of the tile compresses to a small fraction.
        assert!(encode_rgba8_with(&paint, TileCodec::Lz4, None).len() < 64 * 64 * 4 / 10);
        // Mostly-constant detail compresses to a small fraction.
        assert!(encode_u8(&d, TileCodec::Lz4).len() < 64 * 64 / 10);
        assert_eq!(
            encode_u16(&h, TileCodec::Raw).len(),
            HEADER_LEN + 64 * 64 * 2
        );
    }

    #[test]
    fn damaged_files_are_refused_by_kind() {
        let good = encode_u16(&heights(32), TileCodec::Lz4);
        let err = |b: &[u8]| decode(b, Layer::Height, 32).unwrap_err();
        assert!(matches!(
            err(&good[..10]),
            TileFileError::Truncated { len: 10 }
        ));
        assert!(matches!(
            err(&good[..good.len() - 1]),
            TileFileError::Length { .. }
        ));
        let mut long = good.clone();
        long.push(0);
        assert!(matches!(err(&long), TileFileError::Length { .. }));
        let mut b = good.clone();
        b[0] = b'X';
        assert!(matches!(err(&b), TileFileError::Magic { .. }));
        let mut b = good.clone();
        b[4] = 3;
        assert!(matches!(err(&b), TileFileError::Version { found: 3 }));
        let mut b = good.clone();
        b[6] = 9;
        assert!(matches!(err(&b), TileFileError::Codec { codec: 9, .. }));
        let mut b = good.clone();
        b[7] = 1;
        assert!(matches!(err(&b), TileFileError::Codec { flags: 1, .. }));
        assert!(matches!(
            decode(&good, Layer::Detail, 32).unwrap_err(),
            TileFileError::Bits {
                found: 16,
                expected: 8
            }
        ));
        assert!(matches!(
            decode(&good, Layer::Height, 64).unwrap_err(),
            TileFileError::Shape { found_w: 32, .. }
        ));
        // A side no world has is refused before the header is read: a crafted file of
        // 65536^2 samples with a valid checksum cannot make a caller allocate 8 GiB.
        for side in [0, 17, 8, 8192, 65536, u32::MAX] {
            assert!(
                matches!(
                    decode(&good, Layer::Height, side).unwrap_err(),
                    TileFileError::Side { side: s } if s == side
                ),
                "{side}"
            );
        }
        assert_eq!(max_file_len(u32::MAX, 32), u64::MAX);
        assert_eq!(max_file_len(1 << 31, 32), u64::MAX);
        // An absurd size is refused from the header, before anything is allocated.
        let mut b = good.clone();
        b[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(err(&b), TileFileError::Shape { .. }));
        for i in [21, HEADER_LEN, good.len() - 1] {
            let mut b = good.clone();
            b[i] ^= 0x40;
            assert!(
                matches!(err(&b), TileFileError::Checksum { .. }),
                "byte {i}"
            );
        }
    }

    #[test]
    fn a_file_naming_its_tile_is_refused_at_another_tiles_path() {
        let h = heights(32);
        let here = TileIdentity::new(Layer::Height, TileId::new(2, 5, 7));
        for codec in [TileCodec::Raw, TileCodec::Lz4] {
            let bytes = encode_u16_with(&h, codec, Some(here));
            assert_eq!(bytes[4], VERSION_WITH_IDENTITY);
            assert!(bytes.len() as u64 <= max_file_len(32, 16));
            let want = TileData::U16(h.clone());
            assert_eq!(decode_as(&bytes, here, 32).unwrap(), want);
            assert_eq!(decode(&bytes, Layer::Height, 32).unwrap(), want);
            for other in [
                TileIdentity::new(Layer::Height, TileId::new(2, 5, 8)),
                TileIdentity::new(Layer::Height, TileId::new(2, 6, 7)),
                TileIdentity::new(Layer::Height, TileId::new(1, 5, 7)),
            ] {
                assert!(matches!(
                    decode_as(&bytes, other, 32).unwrap_err(),
                    TileFileError::Identity {
                        layer: 0,
                        level: 2,
                        x: 5,
                        y: 7
                    }
                ));
            }
            // The identity is under the checksum: editing it is damage, not a new name.
            for i in HEADER_LEN..HEADER_LEN_WITH_IDENTITY {
                let mut b = bytes.clone();
                b[i] ^= 1;
                assert!(
                    matches!(
                        decode(&b, Layer::Height, 32).unwrap_err(),
                        TileFileError::Checksum { .. }
                    ),
                    "byte {i}"
                );
            }
            // Cut inside the identity.
            assert!(matches!(
                decode(&bytes[..30], Layer::Height, 32).unwrap_err(),
                TileFileError::Truncated { len: 30 }
            ));
        }
        // Detail tiles name their layer.
        let d = Grid::new(16, 16, 3u8).unwrap();
        let id = TileId::new(0, 1, 1);
        let bytes = encode_u8_with(
            &d,
            TileCodec::Lz4,
            Some(TileIdentity::new(Layer::Detail, id)),
        );
        assert!(decode_as(&bytes, TileIdentity::new(Layer::Detail, id), 16).is_ok());
        // A version-1 file names no tile: accepted at any path, as before.
        let old = encode_u16(&h, TileCodec::Raw);
        assert_eq!(old[4], VERSION);
        assert!(decode_as(&old, here, 32).is_ok());
    }

    #[test]
    fn a_payload_with_a_valid_checksum_but_wrong_content_is_refused() {
        // Raw codec with a short payload, checksum recomputed: a crafted file.
        let mut b = encode_u16(&heights(32), TileCodec::Raw);
        b.truncate(b.len() - 2);
        let len = (b.len() - HEADER_LEN) as u32;
        b[16..20].copy_from_slice(&len.to_le_bytes());
        let sum = checksum(&b[..20], &b[HEADER_LEN..]);
        b[20..24].copy_from_slice(&sum.to_le_bytes());
        assert!(matches!(
            decode(&b, Layer::Height, 32).unwrap_err(),
            TileFileError::Payload {
                codec: TileCodec::Raw,
                ..
            }
        ));
        // An LZ4 block of another tile's size.
        let small = encode_u16(&heights(16), TileCodec::Lz4);
        let mut b = small.clone();
        b[8..16].copy_from_slice(&[32, 0, 0, 0, 32, 0, 0, 0]);
        let sum = checksum(&b[..20], &b[HEADER_LEN..]);
        b[20..24].copy_from_slice(&sum.to_le_bytes());
        assert!(matches!(
            decode(&b, Layer::Height, 32).unwrap_err(),
            TileFileError::Payload {
                codec: TileCodec::Lz4,
                ..
            }
        ));
    }
}
