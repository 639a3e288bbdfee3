//! RAW16: headerless `u16` samples, row-major, little-endian unless asked otherwise (the
//! `.r16` / `.raw` heightmaps of terrain tools).

use super::raw::RawFormat;
use super::{ByteOrder, MapIoError, ReadLimits, write_atomic};
use crate::grid::Grid;
use glam::UVec2;
use std::fs::File;
use std::path::Path;

/// RAW16 as a headerless format: 2-byte `u16` samples, a wrong length is
/// [`MapIoError::RawSizeMismatch`].
pub(super) const RAW16: RawFormat<2, u16> = RawFormat {
    sample: |b, order| match order {
        ByteOrder::Little => u16::from_le_bytes(b),
        ByteOrder::Big => u16::from_be_bytes(b),
    },
    mismatch: |size, expected_bytes, actual_bytes| MapIoError::RawSizeMismatch {
        width: size.x,
        height: size.y,
        expected_bytes,
        actual_bytes,
    },
};

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
    RAW16.decode(bytes, size, order, limits)
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
    RAW16.read(path.as_ref(), size, order, limits)
}

/// Reads an open RAW16 file of the given size from its start, its samples in `order` (see
/// [`read_raw16`]); `path` names the file in errors only.
pub(crate) fn read_raw16_from_file(
    file: &File,
    path: &Path,
    size: UVec2,
    order: ByteOrder,
    limits: &ReadLimits,
) -> Result<Grid<u16>, MapIoError> {
    RAW16.read_from_file(file, path, size, order, limits)
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
