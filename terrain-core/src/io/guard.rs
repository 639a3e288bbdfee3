//! The checks every reader passes before it reads or allocates: the path must be a regular
//! file, the size must be within [`ReadLimits`], and a pixel buffer is allocated fallibly, so
//! no file can block, over-allocate or abort the process.

use super::{MapIoError, ReadLimits};
use std::fs::{self, File};
use std::path::Path;

/// What a file type is, in words.
pub(super) fn file_kind(ft: &fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return "named pipe (FIFO)";
        }
        if ft.is_char_device() {
            return "character device";
        }
        if ft.is_block_device() {
            return "block device";
        }
        if ft.is_socket() {
            return "socket";
        }
    }
    if ft.is_dir() {
        "directory"
    } else if ft.is_symlink() {
        "symbolic link"
    } else if ft.is_file() {
        "regular file"
    } else {
        "special file"
    }
}

/// Opens `path` for reading if it is a regular file (after following links).
///
/// The type is checked before opening, because opening a named pipe without a writer blocks
/// until one comes; and again on the open file, in case the path was replaced in between.
/// (A pipe swapped in exactly between the two could still block the open: the standard library
/// has no portable non-blocking open.)
pub(crate) fn open_regular(path: &Path) -> Result<File, MapIoError> {
    let io_err = |source| MapIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let check = |ft: fs::FileType| {
        if ft.is_file() {
            Ok(())
        } else {
            Err(MapIoError::NotRegularFile {
                path: path.to_path_buf(),
                kind: file_kind(&ft),
            })
        }
    };
    check(fs::metadata(path).map_err(io_err)?.file_type())?;
    let file = File::open(path).map_err(io_err)?;
    check(file.metadata().map_err(io_err)?.file_type())?;
    Ok(file)
}

/// Checks a size against the limits: zero sides first, then the largest side, then the
/// number of samples.
pub(crate) fn check_size(width: u32, height: u32, limits: &ReadLimits) -> Result<(), MapIoError> {
    if width == 0 || height == 0 {
        return Err(MapIoError::ZeroSize { width, height });
    }
    if width > limits.max_side || height > limits.max_side {
        return Err(MapIoError::TooLarge {
            width,
            height,
            max_side: limits.max_side,
        });
    }
    if u64::from(width) * u64::from(height) > limits.max_samples {
        return Err(MapIoError::TooManySamples {
            width,
            height,
            max_samples: limits.max_samples,
        });
    }
    Ok(())
}

/// A zeroed buffer of `len` elements, or [`MapIoError::OutOfMemory`] when it cannot be
/// allocated (a header or a size announcing a huge image under raised limits must be an error,
/// not an abort). Probed fallibly first, then made zeroed: the zeroed allocation keeps
/// untouched pages lazy, which filling a reserved vector would not.
pub(crate) fn try_zeroed<T: Clone + Default>(
    len: usize,
    width: u32,
    height: u32,
) -> Result<Vec<T>, MapIoError> {
    let bytes = len.saturating_mul(std::mem::size_of::<T>());
    let mut probe: Vec<T> = Vec::new();
    probe
        .try_reserve_exact(len)
        .map_err(|_| MapIoError::OutOfMemory {
            width,
            height,
            bytes,
        })?;
    drop(probe);
    Ok(vec![T::default(); len])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_size_orders_zero_then_large() {
        let l = ReadLimits {
            max_side: 10,
            ..ReadLimits::default()
        };
        assert!(check_size(1, 1, &l).is_ok());
        assert!(check_size(10, 10, &l).is_ok());
        assert!(matches!(
            check_size(0, 20, &l),
            Err(MapIoError::ZeroSize {
                width: 0,
                height: 20
            })
        ));
        assert!(matches!(
            check_size(11, 3, &l),
            Err(MapIoError::TooLarge {
                width: 11,
                height: 3,
                max_side: 10
            })
        ));
        assert!(matches!(
            check_size(3, 11, &l),
            Err(MapIoError::TooLarge { .. })
        ));
    }
}
