//! R32: headerless `f32` heights in metres, laid out as RAW16 (the `.r32` of terrain tools).

use super::raw::RawFormat;
use super::{ByteOrder, MapIoError, ReadLimits};
use crate::grid::Grid;
use glam::UVec2;
use std::fs::File;
use std::path::Path;

/// R32 as a headerless format: 4-byte `f32` samples, a wrong length is
/// [`MapIoError::R32SizeMismatch`].
pub(super) const R32: RawFormat<4, f32> = RawFormat {
    sample: |b, order| match order {
        ByteOrder::Little => f32::from_le_bytes(b),
        ByteOrder::Big => f32::from_be_bytes(b),
    },
    mismatch: |size, expected_bytes, actual_bytes| MapIoError::R32SizeMismatch {
        width: size.x,
        height: size.y,
        expected_bytes,
        actual_bytes,
    },
};

/// Decodes R32 data: `size.x * size.y` `f32` heights in `order`, row-major. Sizes are checked
/// as in [`decode_raw16`](super::decode_raw16); a byte count other than `4 * size.x * size.y` is
/// [`MapIoError::R32SizeMismatch`]. NaN and infinite samples are kept as they are (the DEM
/// import treats them as nodata).
pub fn decode_r32(
    bytes: &[u8],
    size: UVec2,
    order: ByteOrder,
    limits: &ReadLimits,
) -> Result<Grid<f32>, MapIoError> {
    R32.decode(bytes, size, order, limits)
}

/// Reads an R32 file of the given size (see [`decode_r32`]); the length is checked before
/// anything is read, as in [`read_raw16`](super::read_raw16).
pub fn read_r32(
    path: impl AsRef<Path>,
    size: UVec2,
    order: ByteOrder,
    limits: &ReadLimits,
) -> Result<Grid<f32>, MapIoError> {
    R32.read(path.as_ref(), size, order, limits)
}

/// Reads an open R32 file of the given size from its start (see [`read_r32`]); `path` names
/// the file in errors only.
pub(crate) fn read_r32_from_file(
    file: &File,
    path: &Path,
    size: UVec2,
    order: ByteOrder,
    limits: &ReadLimits,
) -> Result<Grid<f32>, MapIoError> {
    R32.read_from_file(file, path, size, order, limits)
}
