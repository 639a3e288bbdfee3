//! RAW16: headerless `u16` samples, row-major, little-endian unless asked otherwise (the
//! `.r16` / `.raw` heightmaps of terrain tools).

use super::raw::{raw_len, raw_samples, read_raw_file};
use super::{ByteOrder, MapIoError, ReadLimits, write_atomic};
use crate::grid::Grid;
use glam::UVec2;
use std::path::Path;

fn u16_from(b: [u8; 2], order: ByteOrder) -> u16 {
    match order {
        ByteOrder::Little => u16::from_le_bytes(b),
        ByteOrder::Big => u16::from_be_bytes(b),
    }
}

/// Decodes RAW16 data: `size.x * size.y` little-endian `u16` samples, row-major.
///
/// A zero side is [`MapIoError::ZeroSize`], a side over `limits.max_side` is
/// [`MapIoError::TooLarge`], and any byte count other than `2 * size.x * size.y` (an odd count
/// included) is [`MapIoError::RawSizeMismatch`].
pub fn decode_raw16(
    bytes: &[u8],
    size: UVec2,
    limits: &ReadLimits,
) -> Result<Grid<u16>, MapIoError> {
    decode_raw16_ordered(bytes, size, ByteOrder::Little, limits)
}

/// Decodes RAW16 data whose samples are in `order` (see [`decode_raw16`]).
pub fn decode_raw16_ordered(
    bytes: &[u8],
    size: UVec2,
    order: ByteOrder,
    limits: &ReadLimits,
) -> Result<Grid<u16>, MapIoError> {
    let expected_bytes = raw_len(size, 2, limits)?;
    let actual_bytes = bytes.len() as u64;
    if actual_bytes != expected_bytes {
        return Err(MapIoError::RawSizeMismatch {
            width: size.x,
            height: size.y,
            expected_bytes,
            actual_bytes,
        });
    }
    let samples = raw_samples(bytes, order, u16_from);
    Ok(Grid::from_vec(size.x, size.y, samples)?)
}

pub(super) fn raw16_mismatch(size: UVec2, expected_bytes: u64, actual_bytes: u64) -> MapIoError {
    MapIoError::RawSizeMismatch {
        width: size.x,
        height: size.y,
        expected_bytes,
        actual_bytes,
    }
}

/// Reads a RAW16 file of the given size (see [`decode_raw16`]).
///
/// The file length is checked from its metadata before anything is read, so a wrong size
/// never causes a large read.
pub fn read_raw16(
    path: impl AsRef<Path>,
    size: UVec2,
    limits: &ReadLimits,
) -> Result<Grid<u16>, MapIoError> {
    read_raw16_ordered(path, size, ByteOrder::Little, limits)
}

/// Reads a RAW16 file of the given size whose samples are in `order` (see [`read_raw16`]).
pub fn read_raw16_ordered(
    path: impl AsRef<Path>,
    size: UVec2,
    order: ByteOrder,
    limits: &ReadLimits,
) -> Result<Grid<u16>, MapIoError> {
    let expected = raw_len(size, 2, limits)?;
    let bytes = read_raw_file(path.as_ref(), size, expected, limits, raw16_mismatch)?;
    decode_raw16_ordered(&bytes, size, order, limits)
}

/// Encodes a grid as RAW16: little-endian `u16` samples, row-major, no header.
pub fn encode_raw16(grid: &Grid<u16>) -> Vec<u8> {
    grid.as_slice()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// Writes a RAW16 file atomically (see [`encode_raw16`] and [`write_atomic`]).
pub fn write_raw16(path: impl AsRef<Path>, grid: &Grid<u16>) -> Result<(), MapIoError> {
    write_atomic(path, &encode_raw16(grid))
}
