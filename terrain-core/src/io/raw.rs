//! What the two headerless formats (RAW16 and R32) share: a file's length follows from the
//! requested size, so it is checked from the metadata before anything is read.

use super::r32::R32;
use super::raw16::RAW16;
use super::{ByteOrder, MapIoError, ReadLimits, check_size, open_regular};
use crate::grid::Grid;
use glam::UVec2;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// A headerless format: row-major `T` samples of `N` bytes each, in a byte order the caller
/// gives. Only how a sample is read and the error for a wrong length differ between RAW16 and
/// R32; decoding and reading are the same.
pub(super) struct RawFormat<const N: usize, T> {
    /// A sample from its bytes in an order.
    pub(super) sample: fn([u8; N], ByteOrder) -> T,
    /// The error for data of `actual_bytes` where `size` needs `expected_bytes`.
    pub(super) mismatch: fn(size: UVec2, expected_bytes: u64, actual_bytes: u64) -> MapIoError,
}

impl<const N: usize, T: Copy> RawFormat<N, T> {
    /// Decodes `size.x * size.y` samples in `order`: the size is checked against `limits`
    /// first, and any other byte count is the format's mismatch.
    pub(super) fn decode(
        &self,
        bytes: &[u8],
        size: UVec2,
        order: ByteOrder,
        limits: &ReadLimits,
    ) -> Result<Grid<T>, MapIoError> {
        let expected_bytes = raw_len(size, N as u64, limits)?;
        let actual_bytes = bytes.len() as u64;
        if actual_bytes != expected_bytes {
            return Err((self.mismatch)(size, expected_bytes, actual_bytes));
        }
        let samples = raw_samples(bytes, order, self.sample);
        Ok(Grid::from_vec(size.x, size.y, samples)?)
    }

    /// Reads a file of `size` and decodes it (see [`read_raw_file`]: the length is checked
    /// before anything is read).
    pub(super) fn read(
        &self,
        path: &Path,
        size: UVec2,
        order: ByteOrder,
        limits: &ReadLimits,
    ) -> Result<Grid<T>, MapIoError> {
        self.read_from_file(&open_regular(path)?, path, size, order, limits)
    }

    /// Reads an open file of `size` from its start and decodes it (see [`Self::read`]);
    /// `path` names the file in errors only, and is never opened.
    pub(super) fn read_from_file(
        &self,
        file: &File,
        path: &Path,
        size: UVec2,
        order: ByteOrder,
        limits: &ReadLimits,
    ) -> Result<Grid<T>, MapIoError> {
        let expected = raw_len(size, N as u64, limits)?;
        let bytes = read_raw_file(file, path, size, expected, limits, self.mismatch)?;
        self.decode(&bytes, size, order, limits)
    }
}

/// Checks a headerless file's size and returns the byte count it needs at `sample_bytes` per
/// sample.
fn raw_len(size: UVec2, sample_bytes: u64, limits: &ReadLimits) -> Result<u64, MapIoError> {
    check_size(size.x, size.y, limits)?;
    // (2^32 - 1)^2 * 4 can overflow u64 when the limit is raised that far.
    u64::from(size.x)
        .checked_mul(u64::from(size.y))
        .and_then(|n| n.checked_mul(sample_bytes))
        .ok_or(MapIoError::TooLarge {
            width: size.x,
            height: size.y,
            max_side: limits.max_side,
        })
}

/// The samples of headerless data: `bytes` cut into `N`-byte samples in `order`.
fn raw_samples<const N: usize, T>(
    bytes: &[u8],
    order: ByteOrder,
    from: fn([u8; N], ByteOrder) -> T,
) -> Vec<T> {
    bytes
        .chunks_exact(N)
        .map(|c| {
            let mut b = [0u8; N];
            b.copy_from_slice(c);
            from(b, order)
        })
        .collect()
}

/// Reads the whole of a headerless file that must be `expected_bytes` long; `mismatch` makes
/// the error for another length. The length is checked from the file's metadata before
/// anything is read, so a wrong size never causes a large read.
fn read_raw_file(
    file: &File,
    path: &Path,
    size: UVec2,
    expected_bytes: u64,
    limits: &ReadLimits,
    mismatch: fn(UVec2, u64, u64) -> MapIoError,
) -> Result<Vec<u8>, MapIoError> {
    let io_err = |source| MapIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let actual_bytes = file.metadata().map_err(io_err)?.len();
    if actual_bytes != expected_bytes {
        return Err(mismatch(size, expected_bytes, actual_bytes));
    }
    let capacity = usize::try_from(expected_bytes).map_err(|_| MapIoError::TooLarge {
        width: size.x,
        height: size.y,
        max_side: limits.max_side,
    })?;
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(capacity.saturating_add(1))
        .map_err(|_| MapIoError::OutOfMemory {
            width: size.x,
            height: size.y,
            bytes: capacity,
        })?;
    let mut file = file;
    file.seek(SeekFrom::Start(0)).map_err(io_err)?;
    // Read at most one byte more than expected, so a file that changed since the metadata
    // check is still caught without reading it all.
    file.take(expected_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io_err)?;
    Ok(bytes)
}

/// Checks that a headerless file of `bytes_per_sample` (2 for RAW16, 4 for R32) holds exactly
/// `size`, from its metadata alone: to plan memory before reading it.
pub fn check_raw_file(
    path: impl AsRef<Path>,
    size: UVec2,
    bytes_per_sample: u8,
    limits: &ReadLimits,
) -> Result<(), MapIoError> {
    let path = path.as_ref();
    check_raw_from_file(&open_regular(path)?, path, size, bytes_per_sample, limits)
}

/// Checks that an open headerless file holds exactly `size` (see [`check_raw_file`]); `path`
/// names the file in errors only.
pub(crate) fn check_raw_from_file(
    file: &File,
    path: &Path,
    size: UVec2,
    bytes_per_sample: u8,
    limits: &ReadLimits,
) -> Result<(), MapIoError> {
    let expected = raw_len(size, u64::from(bytes_per_sample), limits)?;
    let actual = file
        .metadata()
        .map_err(|source| MapIoError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .len();
    if actual == expected {
        Ok(())
    } else if bytes_per_sample == 4 {
        Err((R32.mismatch)(size, expected, actual))
    } else {
        Err((RAW16.mismatch)(size, expected, actual))
    }
}
