//! R32: headerless `f32` heights in metres, laid out as RAW16 (the `.r32` of terrain tools).

use super::raw::{raw_len, raw_samples, read_raw_file};
use super::{ByteOrder, MapIoError, ReadLimits};
use crate::grid::Grid;
use glam::UVec2;
use std::path::Path;

fn f32_from(b: [u8; 4], order: ByteOrder) -> f32 {
    match order {
        ByteOrder::Little => f32::from_le_bytes(b),
        ByteOrder::Big => f32::from_be_bytes(b),
    }
}

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
    let expected_bytes = raw_len(size, 4, limits)?;
    let actual_bytes = bytes.len() as u64;
    if actual_bytes != expected_bytes {
        return Err(MapIoError::R32SizeMismatch {
            width: size.x,
            height: size.y,
            expected_bytes,
            actual_bytes,
        });
    }
    let samples = raw_samples(bytes, order, f32_from);
    Ok(Grid::from_vec(size.x, size.y, samples)?)
}

pub(super) fn r32_mismatch(size: UVec2, expected_bytes: u64, actual_bytes: u64) -> MapIoError {
    MapIoError::R32SizeMismatch {
        width: size.x,
        height: size.y,
        expected_bytes,
        actual_bytes,
    }
}

/// Reads an R32 file of the given size (see [`decode_r32`]); the length is checked before
/// anything is read, as in [`read_raw16`](super::read_raw16).
pub fn read_r32(
    path: impl AsRef<Path>,
    size: UVec2,
    order: ByteOrder,
    limits: &ReadLimits,
) -> Result<Grid<f32>, MapIoError> {
    let expected = raw_len(size, 4, limits)?;
    let bytes = read_raw_file(path.as_ref(), size, expected, limits, r32_mismatch)?;
    decode_r32(&bytes, size, order, limits)
}
