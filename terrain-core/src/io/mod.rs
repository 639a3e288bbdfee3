//! Map file I/O: grayscale PNG (8 and 16 bit) and RAW16 reading and writing, RGBA8 PNG
//! encoding for frame captures, and atomic file replacement. This is the only module of
//! terrain-core that touches files.
//!
//! Readers open only regular files ([`MapIoError::NotRegularFile`] for a directory, a named
//! pipe or a device: opening a pipe could block for ever). Readers never trust a file: the
//! image size is checked against [`ReadLimits`] from the PNG header (or, for RAW16, from the
//! requested size and the file length) before any pixel buffer is allocated, and every
//! malformed input is reported as a [`MapIoError`], never a panic.
//!
//! Formats:
//! - PNG: single-channel grayscale, 8 or 16 bits per sample, interlaced or not. 16-bit samples
//!   are big-endian in the file (as the PNG specification requires); decoding keeps their full
//!   precision.
//! - RAW16: headerless `u16` samples, little-endian by default (big-endian on request: see
//!   [`ByteOrder`]), row-major (row `y = 0` first), as written by common terrain tools. The size
//!   is not stored in the file and must be given.
//! - R32: headerless `f32` heights in metres, laid out as RAW16 (the `.r32` of terrain tools).
//!
//! GeoTIFF DEMs are read by [`crate::geotiff`], and [`crate::dem`] picks the reader for a DEM
//! file and turns its heights into a coarse-map; both open files through this module.
//!
//! One private module per format (`png`, `raw16`, `r32`, with `raw` for what the two
//! headerless formats share), one for the checks every reader passes first (`guard`) and one
//! for atomic writes (`atomic`); this module holds the types they share and re-exports their
//! functions, so every path stays `terrain_core::io::*`.

use crate::error::CoreError;
use crate::grid::Grid;
use glam::UVec2;
use std::io;
use std::path::PathBuf;

mod atomic;
mod color;
mod guard;
mod png;
mod r32;
mod raw;
mod raw16;

pub use self::atomic::{AtomicWrite, write_atomic, write_atomic_report};
pub use self::color::{decode_color_image, read_color_image};
pub(crate) use self::guard::{check_size, open_regular, try_zeroed};
pub use self::png::{
    decode_png, decode_png_rgba8, decode_png8, decode_png16, encode_png_rgba8, encode_png8,
    encode_png16, read_png, read_png_rgba8, read_png_size, read_png8, read_png16, write_png_rgba8,
    write_png8, write_png16,
};
pub(crate) use self::png::{read_png_from_file, read_png_size_from_file};
pub(crate) use self::r32::read_r32_from_file;
pub use self::r32::{decode_r32, read_r32};
pub use self::raw::check_raw_file;
pub(crate) use self::raw::check_raw_from_file;
pub(crate) use self::raw16::read_raw16_from_file;
pub use self::raw16::{
    decode_raw16, decode_raw16_ordered, encode_raw16, read_raw16, read_raw16_ordered, write_raw16,
};

/// Default for [`ReadLimits::max_side`]: the largest width or height a reader accepts.
pub const DEFAULT_MAX_SIDE: u32 = 16384;

/// Limits checked from the header before any pixel buffer is allocated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// The largest width and the largest height accepted, in samples. A file whose header
    /// announces a larger side is rejected with [`MapIoError::TooLarge`].
    pub max_side: u32,
    /// The most samples (width times height) accepted: a caller that measured a file before
    /// reading it sets this to what it measured, so a file swapped in between cannot make the
    /// read larger than planned ([`MapIoError::TooManySamples`]).
    pub max_samples: u64,
}

impl Default for ReadLimits {
    fn default() -> Self {
        Self {
            max_side: DEFAULT_MAX_SIDE,
            max_samples: u64::MAX,
        }
    }
}

/// A decoded grayscale image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GrayImage {
    /// 8 bits per sample (a detail-map tile, for example).
    Gray8(Grid<u8>),
    /// 16 bits per sample (a coarse-map, for example).
    Gray16(Grid<u16>),
}

impl GrayImage {
    /// Bits per sample: 8 or 16.
    pub fn bit_depth(&self) -> u8 {
        match self {
            GrayImage::Gray8(_) => 8,
            GrayImage::Gray16(_) => 16,
        }
    }

    /// Width and height in samples.
    pub fn size(&self) -> UVec2 {
        match self {
            GrayImage::Gray8(g) => g.size(),
            GrayImage::Gray16(g) => g.size(),
        }
    }
}

/// Errors from reading and writing map files.
///
/// Every variant carries the offending values (path, size, bit depth, ...) so the message says
/// what to fix.
#[derive(Debug, thiserror::Error)]
pub enum MapIoError {
    /// A file could not be opened, read, written, synced or renamed.
    #[error("I/O error on {}: {source}", path.display())]
    Io {
        /// The file (or, for an atomic write, the target file) the operation was on.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: io::Error,
    },
    /// The PNG is not single-channel grayscale.
    #[error(
        "the PNG is {color_type}, but a map must be single-channel grayscale (8 or 16 bit) \
         without alpha: convert it to grayscale before loading it"
    )]
    NotGrayscale {
        /// The colour type found in the file, in words.
        color_type: String,
    },
    /// An RGBA image was expected (frame captures) but the file has another colour type.
    #[error("expected an 8-bit RGBA image, found {color_type}")]
    NotRgba {
        /// The colour type found.
        color_type: String,
    },
    /// The PNG has a supported bit depth, but not the one the caller asked for.
    #[error(
        "the PNG has {found}-bit samples but a {expected}-bit map was requested: \
         re-export it with {expected} bits per sample, or read it with the {found}-bit reader"
    )]
    WrongBitDepth {
        /// Bits per sample requested.
        expected: u8,
        /// Bits per sample in the file.
        found: u8,
    },
    /// The PNG uses a bit depth maps are never stored with (1, 2 or 4 bits per sample).
    #[error(
        "the PNG has {bits}-bit samples: only 8-bit and 16-bit grayscale maps are supported, \
         re-export it with 8 or 16 bits per sample"
    )]
    UnsupportedBitDepth {
        /// Bits per sample in the file.
        bits: u8,
    },
    /// The data ends before the file format says it should.
    #[error("the file is truncated: {reason}")]
    Truncated {
        /// Where the data ended, in words.
        reason: String,
    },
    /// The data is not a valid file of the expected format (bad signature, bad checksum, bad
    /// compressed stream, invalid header fields, ...).
    #[error("the file is corrupt: {reason}")]
    Corrupt {
        /// What was wrong, in words.
        reason: String,
    },
    /// A zero width or height was announced or requested.
    #[error("image size {width}x{height} is empty: both sides must be at least 1")]
    ZeroSize {
        /// Width announced or requested.
        width: u32,
        /// Height announced or requested.
        height: u32,
    },
    /// The image is larger than the reader accepts.
    #[error(
        "image size {width}x{height} is too large: each side may be at most {max_side} samples \
         (raise ReadLimits::max_side to accept it)"
    )]
    TooLarge {
        /// Width announced or requested.
        width: u32,
        /// Height announced or requested.
        height: u32,
        /// The limit in force.
        max_side: u32,
    },
    /// The image has more samples than the reader accepts.
    #[error(
        "image size {width}x{height} is too large: at most {max_samples} samples are accepted \
         (ReadLimits::max_samples)"
    )]
    TooManySamples {
        /// Width announced or requested.
        width: u32,
        /// Height announced or requested.
        height: u32,
        /// The limit in force.
        max_samples: u64,
    },
    /// Decoding needs a buffer larger than the machine can allocate (a header announcing a huge
    /// image under raised limits): refused instead of aborting the process.
    #[error("a {width}x{height} image needs {bytes} bytes to decode, more than can be allocated")]
    OutOfMemory {
        /// Width announced.
        width: u32,
        /// Height announced.
        height: u32,
        /// Bytes the decoder asked for.
        bytes: usize,
    },
    /// A RAW16 file or buffer does not hold exactly `width * height` little-endian `u16`s.
    #[error(
        "RAW16 data of {actual_bytes} bytes does not match size {width}x{height}, which needs \
         exactly {expected_bytes} bytes (2 per sample): check the size given for this file"
    )]
    RawSizeMismatch {
        /// Width requested.
        width: u32,
        /// Height requested.
        height: u32,
        /// Byte count the size needs.
        expected_bytes: u64,
        /// Byte count found.
        actual_bytes: u64,
    },
    /// The PNG encoder refused the image.
    #[error("could not encode {width}x{height} image as PNG: {reason}")]
    Encode {
        /// Width of the image.
        width: u32,
        /// Height of the image.
        height: u32,
        /// The encoder's reason, in words.
        reason: String,
    },
    /// The path names a directory, a named pipe, a device or a socket: reading a map from it
    /// means nothing, and opening a pipe or a terminal could block for ever.
    #[error(
        "{} is a {kind}, not a regular file: maps and images are read from regular files",
        path.display()
    )]
    NotRegularFile {
        /// The path given.
        path: PathBuf,
        /// What it is, in words (`directory`, `named pipe (FIFO)`, `character device`, ...).
        kind: &'static str,
    },
    /// An R32 file or buffer does not hold exactly `width * height` `f32`s.
    #[error(
        "R32 data of {actual_bytes} bytes does not match size {width}x{height}, which needs \
         exactly {expected_bytes} bytes (4 per sample): check the size given for this file"
    )]
    R32SizeMismatch {
        /// Width requested.
        width: u32,
        /// Height requested.
        height: u32,
        /// Byte count the size needs.
        expected_bytes: u64,
        /// Byte count found.
        actual_bytes: u64,
    },
    /// The format of a DEM file could not be told from its name or its first bytes.
    #[error(
        "cannot tell the format of {}: name it .png, .r16 / .raw (RAW16), .r32 or \
         .tif / .tiff (GeoTIFF), or choose the format explicitly",
        path.display()
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// A headerless format was chosen without its size.
    #[error("{format} files do not store their size: give the width and height of this one")]
    RawSizeRequired {
        /// The format (`RAW16`, `R32`).
        format: &'static str,
    },
    /// A size was given for a format that stores its own.
    #[error("{format} files store their size: a raw size is only used for RAW16 and R32 files")]
    RawSizeUnused {
        /// The format (`PNG`, `GeoTIFF`).
        format: &'static str,
    },
    /// The TIFF is valid but not a DEM this reader takes (several bands, a palette, 1-bit or
    /// 16-bit float samples, a compression it lacks, ...).
    #[error(
        "the TIFF is not a supported DEM: {reason} (a DEM is one band of u8, i8, u16, i16, \
         u32, i32, f32 or f64 samples, uncompressed, LZW, Deflate or PackBits)"
    )]
    UnsupportedTiff {
        /// What the file has, in words.
        reason: String,
    },
    /// Every sample of the DEM is nodata: there is no height to fill the holes with.
    #[error("all {count} samples are nodata ({marker}): the DEM holds no height at all")]
    NoValidHeights {
        /// How many samples.
        count: u64,
        /// What marks nodata, in words (`the GDAL nodata value -9999`, `NaN or infinite`).
        marker: String,
    },
    /// The decoded samples could not form a grid.
    #[error(transparent)]
    Grid(#[from] CoreError),
}

/// The byte order of the samples of a headerless file (RAW16, R32).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ByteOrder {
    /// Least significant byte first (PC tools, the default).
    #[default]
    Little,
    /// Most significant byte first.
    Big,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_round_trips() {
        let l = ReadLimits::default();
        let g16 = Grid::from_fn(3, 2, |x, y| (x * 30000 + y * 7) as u16).unwrap();
        assert_eq!(decode_png16(&encode_png16(&g16).unwrap(), &l).unwrap(), g16);
        let g8 = Grid::from_fn(2, 3, |x, y| (x * 100 + y) as u8).unwrap();
        assert_eq!(decode_png8(&encode_png8(&g8).unwrap(), &l).unwrap(), g8);
        let raw = encode_raw16(&g16);
        assert_eq!(raw[..2], (g16.as_slice()[0]).to_le_bytes());
        assert_eq!(decode_raw16(&raw, g16.size(), &l).unwrap(), g16);
        let rgba = Grid::from_fn(5, 3, |x, y| [x as u8, y as u8, 200, 255 - x as u8]).unwrap();
        assert_eq!(
            decode_png_rgba8(&encode_png_rgba8(&rgba).unwrap(), &l).unwrap(),
            rgba
        );
        // A grayscale file is not an RGBA capture, and a capture is not a heightmap.
        assert!(matches!(
            decode_png_rgba8(&encode_png8(&g8).unwrap(), &l),
            Err(MapIoError::NotRgba { .. })
        ));
        assert!(matches!(
            decode_png8(&encode_png_rgba8(&rgba).unwrap(), &l),
            Err(MapIoError::NotGrayscale { .. })
        ));
    }

    #[test]
    fn messages_carry_values() {
        let e = MapIoError::RawSizeMismatch {
            width: 3,
            height: 4,
            expected_bytes: 24,
            actual_bytes: 23,
        };
        let s = e.to_string();
        assert!(
            s.contains("3x4") && s.contains("24") && s.contains("23"),
            "{s}"
        );
        let s = MapIoError::WrongBitDepth {
            expected: 16,
            found: 8,
        }
        .to_string();
        assert!(s.contains("16") && s.contains('8'), "{s}");
        let s = MapIoError::TooLarge {
            width: 20000,
            height: 5,
            max_side: 16384,
        }
        .to_string();
        assert!(s.contains("20000x5") && s.contains("16384"), "{s}");
    }
}
