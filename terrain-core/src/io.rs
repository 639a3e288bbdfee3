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

use crate::error::CoreError;
use crate::grid::Grid;
use glam::UVec2;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufRead, BufReader, Cursor, Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

/// Default for [`ReadLimits::max_side`]: the largest width or height a reader accepts.
pub const DEFAULT_MAX_SIDE: u32 = 16384;

/// Limits checked from the header before any pixel buffer is allocated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// The largest width and the largest height accepted, in samples. A file whose header
    /// announces a larger side is rejected with [`MapIoError::TooLarge`].
    pub max_side: u32,
}

impl Default for ReadLimits {
    fn default() -> Self {
        Self {
            max_side: DEFAULT_MAX_SIDE,
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

// ---------------------------------------------------------------------------------------------
// Opening files

/// What a file type is, in words.
fn file_kind(ft: &fs::FileType) -> &'static str {
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

// ---------------------------------------------------------------------------------------------
// Size checks

/// Checks a size against the limits: zero sides first, then the largest side.
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
    Ok(())
}

/// The memory the PNG decoder may allocate for itself (row buffers, metadata chunks). The
/// output image buffer is ours and is sized from the already checked header.
fn png_decoder_limits(limits: &ReadLimits) -> png::Limits {
    // A 16-bit row of the widest accepted image plus its filter byte, a few times over, plus a
    // fixed allowance for ancillary chunks.
    let row = (limits.max_side as usize)
        .saturating_mul(2)
        .saturating_add(1);
    png::Limits {
        bytes: row.saturating_mul(4).saturating_add(8 << 20),
    }
}

// ---------------------------------------------------------------------------------------------
// PNG decoding

/// Which step of decoding an error came from, to say where a truncated file ends when its
/// chunk structure cannot be walked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Header,
    Metadata,
    ImageData,
    Trailer,
}

impl Stage {
    fn truncated_reason(self) -> &'static str {
        match self {
            Stage::Header => "the data ends inside the PNG signature or header (IHDR)",
            Stage::Metadata => "the data ends before the image data (IDAT) starts",
            Stage::ImageData => "the data ends inside the image data (IDAT)",
            Stage::Trailer => "the data ends before the end chunk (IEND)",
        }
    }
}

/// Where the bytes come from: memory, or an open file (whose read errors are I/O errors).
/// Error paths read the file again through the same handle, never by opening the path again:
/// the path may name something else by then.
#[derive(Debug, Clone, Copy)]
enum Source<'a> {
    Memory(&'a [u8]),
    File { path: &'a Path, file: &'a File },
}

/// The PNG file signature.
const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

/// A chunk type as text (`IDAT`), or its bytes when they are not letters.
fn chunk_name(ty: [u8; 4]) -> String {
    if ty.iter().all(u8::is_ascii_alphabetic) {
        ty.iter().map(|&b| char::from(b)).collect()
    } else {
        format!("{ty:02x?}")
    }
}

/// Reads up to `buf.len()` bytes, stopping early only at the end of the data.
fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Says where truncated PNG data ends by walking its chunk headers (reading only the 8-byte
/// headers, seeking over chunk contents). `None` if the structure shows no truncation.
fn describe_truncation(r: &mut (impl Read + Seek)) -> io::Result<Option<String>> {
    let total = r.seek(io::SeekFrom::End(0))?;
    r.seek(io::SeekFrom::Start(0))?;
    if total < PNG_SIGNATURE.len() as u64 {
        return Ok(Some(format!(
            "the data is {total} bytes long and ends inside the 8-byte PNG signature"
        )));
    }
    let mut pos = PNG_SIGNATURE.len() as u64;
    let mut last: Option<String> = None;
    loop {
        r.seek(io::SeekFrom::Start(pos))?;
        let mut head = [0u8; 8];
        let n = read_up_to(r, &mut head)?;
        if n == 0 {
            return Ok(Some(match last {
                Some(name) => format!(
                    "the data ends after the {name} chunk at byte {pos}; more chunks and the \
                     end chunk (IEND) are missing"
                ),
                None => "the data ends right after the PNG signature; the header (IHDR) is \
                         missing"
                    .to_owned(),
            }));
        }
        if n < head.len() {
            return Ok(Some(format!(
                "the data ends inside the header of the chunk that starts at byte {pos} \
                 ({n} of 8 bytes present)"
            )));
        }
        let len = u64::from(u32::from_be_bytes([head[0], head[1], head[2], head[3]]));
        let name = chunk_name([head[4], head[5], head[6], head[7]]);
        let chunk_len = len + 12;
        let available = total - pos;
        if available < chunk_len {
            let what = if name == "IHDR" {
                "the header chunk (IHDR)".to_owned()
            } else {
                format!("the {name} chunk")
            };
            return Ok(Some(format!(
                "the data ends inside {what} that starts at byte {pos} ({available} of its \
                 {chunk_len} bytes present)"
            )));
        }
        if name == "IEND" {
            return Ok(None);
        }
        pos += chunk_len;
        last = Some(name);
    }
}

/// Maps a png decoding error to ours.
fn map_decoding_error(
    e: png::DecodingError,
    stage: Stage,
    source: Source<'_>,
    size: Option<(u32, u32)>,
    limits: &ReadLimits,
) -> MapIoError {
    match e {
        png::DecodingError::IoError(io) if io.kind() == io::ErrorKind::UnexpectedEof => {
            let detail = match source {
                Source::Memory(bytes) => describe_truncation(&mut Cursor::new(bytes)),
                Source::File { file, .. } => {
                    let mut f = file;
                    describe_truncation(&mut f)
                }
            };
            MapIoError::Truncated {
                reason: detail
                    .ok()
                    .flatten()
                    .unwrap_or_else(|| stage.truncated_reason().to_owned()),
            }
        }
        png::DecodingError::IoError(io) => match source {
            Source::File { path, .. } => MapIoError::Io {
                path: path.to_path_buf(),
                source: io,
            },
            Source::Memory(_) => MapIoError::Corrupt {
                reason: format!("reading the PNG data failed: {io}"),
            },
        },
        png::DecodingError::Format(f) => MapIoError::Corrupt {
            reason: format!("invalid PNG: {f}"),
        },
        png::DecodingError::Parameter(p) => MapIoError::Corrupt {
            reason: format!("the PNG decoder rejected the data: {p}"),
        },
        png::DecodingError::LimitsExceeded => match size {
            Some((width, height)) => MapIoError::TooLarge {
                width,
                height,
                max_side: limits.max_side,
            },
            None => MapIoError::Corrupt {
                reason: "the PNG needs more decoder memory than allowed".to_owned(),
            },
        },
    }
}

/// Width and height from the IHDR chunk as stored, without validation, if the data is long
/// enough and starts like a PNG. Used to report a zero size as [`MapIoError::ZeroSize`].
fn peek_ihdr_size(bytes: &[u8]) -> Option<(u32, u32)> {
    let head = bytes.get(..24)?;
    if head[..8] != PNG_SIGNATURE || &head[12..16] != b"IHDR" {
        return None;
    }
    let width = u32::from_be_bytes([head[16], head[17], head[18], head[19]]);
    let height = u32::from_be_bytes([head[20], head[21], head[22], head[23]]);
    Some((width, height))
}

/// The IHDR size of the source, read again after a header error (see [`peek_ihdr_size`]).
fn peek_source_size(source: Source<'_>) -> Option<(u32, u32)> {
    match source {
        Source::Memory(bytes) => peek_ihdr_size(bytes),
        Source::File { file, .. } => {
            let mut head = [0u8; 24];
            let mut f = file;
            let n = f
                .seek(io::SeekFrom::Start(0))
                .and_then(|_| read_up_to(&mut f, &mut head))
                .ok()?;
            peek_ihdr_size(&head[..n])
        }
    }
}

/// A readable name for a PNG colour type.
fn color_type_name(ct: png::ColorType) -> &'static str {
    match ct {
        png::ColorType::Grayscale => "grayscale",
        png::ColorType::Rgb => "RGB colour",
        png::ColorType::Indexed => "palette (indexed colour)",
        png::ColorType::GrayscaleAlpha => "grayscale with alpha",
        png::ColorType::Rgba => "RGBA colour",
    }
}

/// What a caller accepts from a PNG header.
#[derive(Clone, Copy)]
enum Accept {
    /// 8 or 16-bit grayscale, optionally only one of the two depths.
    Gray(Option<u8>),
    /// 8-bit RGBA (frame captures).
    Rgba8,
}

/// A PNG decoder with our memory limits, keeping the samples as stored.
fn png_decoder<R: BufRead + Seek>(reader: R, limits: &ReadLimits) -> png::Decoder<R> {
    let mut decoder = png::Decoder::new_with_limits(reader, png_decoder_limits(limits));
    decoder.set_transformations(png::Transformations::IDENTITY);
    // Text and ICC profiles mean nothing to a heightmap; skipping them keeps their memory out.
    decoder.set_ignore_text_chunk(true);
    decoder.set_ignore_iccp_chunk(true);
    decoder
}

/// Reads the header: `(width, height, colour type, bits per sample)`, unchecked.
fn read_header<R: BufRead + Seek>(
    decoder: &mut png::Decoder<R>,
    limits: &ReadLimits,
    source: Source<'_>,
) -> Result<(u32, u32, png::ColorType, u8), MapIoError> {
    match decoder.read_header_info() {
        Ok(info) => Ok((
            info.width,
            info.height,
            info.color_type,
            info.bit_depth as u8,
        )),
        Err(e) => {
            // The png crate rejects a zero side as a generic format error; say what it is.
            if let Some((w, h)) = peek_source_size(source)
                && (w == 0 || h == 0)
            {
                return Err(MapIoError::ZeroSize {
                    width: w,
                    height: h,
                });
            }
            Err(map_decoding_error(e, Stage::Header, source, None, limits))
        }
    }
}

/// Decodes the pixels of a PNG the caller accepts: `(width, height, bit depth, raw bytes)`.
fn decode_png_pixels<R: BufRead + Seek>(
    reader: R,
    limits: &ReadLimits,
    accept: Accept,
    source: Source<'_>,
) -> Result<(u32, u32, u8, Vec<u8>), MapIoError> {
    let mut decoder = png_decoder(reader, limits);
    let (width, height, color_type, bits) = read_header(&mut decoder, limits, source)?;

    // Everything below is decided from the header alone, before any pixel buffer exists.
    check_size(width, height, limits)?;
    let channels = match accept {
        Accept::Gray(want) => {
            if color_type != png::ColorType::Grayscale {
                return Err(MapIoError::NotGrayscale {
                    color_type: color_type_name(color_type).to_owned(),
                });
            }
            if bits != 8 && bits != 16 {
                return Err(MapIoError::UnsupportedBitDepth { bits });
            }
            if let Some(expected) = want
                && expected != bits
            {
                return Err(MapIoError::WrongBitDepth {
                    expected,
                    found: bits,
                });
            }
            1
        }
        Accept::Rgba8 => {
            if color_type != png::ColorType::Rgba {
                return Err(MapIoError::NotRgba {
                    color_type: color_type_name(color_type).to_owned(),
                });
            }
            if bits != 8 {
                return Err(MapIoError::WrongBitDepth {
                    expected: 8,
                    found: bits,
                });
            }
            4
        }
    };

    let size = Some((width, height));
    let mut reader = decoder
        .read_info()
        .map_err(|e| map_decoding_error(e, Stage::Metadata, source, size, limits))?;
    let buffer_len = reader.output_buffer_size().ok_or(MapIoError::TooLarge {
        width,
        height,
        max_side: limits.max_side,
    })?;
    let expected_len = (width as usize)
        .checked_mul(height as usize)
        .and_then(|n| n.checked_mul(usize::from(bits / 8) * channels));
    if expected_len != Some(buffer_len) {
        return Err(MapIoError::Corrupt {
            reason: format!(
                "the PNG decoder wants a {buffer_len}-byte buffer for a {width}x{height} \
                 {bits}-bit image of {channels} channel(s)"
            ),
        });
    }

    // A tiny file may announce a huge image (under raised limits): see `try_zeroed`.
    let mut buf = try_zeroed::<u8>(buffer_len, width, height)?;
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| map_decoding_error(e, Stage::ImageData, source, size, limits))?;
    if frame.width != width || frame.height != height {
        return Err(MapIoError::Corrupt {
            reason: format!(
                "the first frame is {}x{} but the header says {width}x{height}",
                frame.width, frame.height
            ),
        });
    }
    // Read up to IEND so that a file cut after the image data or with a damaged trailer is
    // reported rather than silently accepted.
    reader
        .finish()
        .map_err(|e| map_decoding_error(e, Stage::Trailer, source, size, limits))?;
    Ok((width, height, bits, buf))
}

/// Decodes a grayscale PNG from `reader` into its grid. `want` is the bit depth the caller
/// requires, if any; it is checked from the header before the pixels are decoded.
fn decode_png_from<R: BufRead + Seek>(
    reader: R,
    limits: &ReadLimits,
    want: Option<u8>,
    source: Source<'_>,
) -> Result<GrayImage, MapIoError> {
    let (width, height, bits, buf) = decode_png_pixels(reader, limits, Accept::Gray(want), source)?;
    if bits == 16 {
        let samples = buf
            .chunks_exact(2)
            .map(|b| u16::from_be_bytes([b[0], b[1]]))
            .collect();
        Ok(GrayImage::Gray16(Grid::from_vec(width, height, samples)?))
    } else {
        Ok(GrayImage::Gray8(Grid::from_vec(width, height, buf)?))
    }
}

/// Decodes an 8-bit or 16-bit grayscale PNG held in memory.
///
/// The size is checked against `limits` from the header before the pixel buffer is allocated.
/// Colour, palette and gray+alpha images are [`MapIoError::NotGrayscale`]; 1, 2 and 4-bit
/// images are [`MapIoError::UnsupportedBitDepth`]. Interlaced images are supported.
pub fn decode_png(bytes: &[u8], limits: &ReadLimits) -> Result<GrayImage, MapIoError> {
    decode_png_from(Cursor::new(bytes), limits, None, Source::Memory(bytes))
}

/// Decodes a 16-bit grayscale PNG held in memory (a coarse-map, for example).
///
/// An 8-bit file is [`MapIoError::WrongBitDepth`] `{ expected: 16, found: 8 }`; see
/// [`decode_png`] for the other errors.
pub fn decode_png16(bytes: &[u8], limits: &ReadLimits) -> Result<Grid<u16>, MapIoError> {
    match decode_png_from(Cursor::new(bytes), limits, Some(16), Source::Memory(bytes))? {
        GrayImage::Gray16(g) => Ok(g),
        GrayImage::Gray8(_) => Err(MapIoError::WrongBitDepth {
            expected: 16,
            found: 8,
        }),
    }
}

/// Decodes an 8-bit grayscale PNG held in memory (a detail-map tile, for example).
///
/// A 16-bit file is [`MapIoError::WrongBitDepth`] `{ expected: 8, found: 16 }`; see
/// [`decode_png`] for the other errors.
pub fn decode_png8(bytes: &[u8], limits: &ReadLimits) -> Result<Grid<u8>, MapIoError> {
    match decode_png_from(Cursor::new(bytes), limits, Some(8), Source::Memory(bytes))? {
        GrayImage::Gray8(g) => Ok(g),
        GrayImage::Gray16(_) => Err(MapIoError::WrongBitDepth {
            expected: 8,
            found: 16,
        }),
    }
}

/// Reads a PNG file through a buffered reader, without loading the whole file first.
fn read_png_file(
    path: &Path,
    limits: &ReadLimits,
    want: Option<u8>,
) -> Result<GrayImage, MapIoError> {
    let file = open_regular(path)?;
    decode_png_from(
        BufReader::new(&file),
        limits,
        want,
        Source::File { path, file: &file },
    )
}

/// Reads an 8-bit or 16-bit grayscale PNG file. See [`decode_png`] for the checks; a file that
/// cannot be opened or read is [`MapIoError::Io`] with its path.
pub fn read_png(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<GrayImage, MapIoError> {
    read_png_file(path.as_ref(), limits, None)
}

/// Reads a 16-bit grayscale PNG file. See [`decode_png16`] and [`read_png`].
pub fn read_png16(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<Grid<u16>, MapIoError> {
    match read_png_file(path.as_ref(), limits, Some(16))? {
        GrayImage::Gray16(g) => Ok(g),
        GrayImage::Gray8(_) => Err(MapIoError::WrongBitDepth {
            expected: 16,
            found: 8,
        }),
    }
}

/// Reads an 8-bit grayscale PNG file. See [`decode_png8`] and [`read_png`].
pub fn read_png8(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<Grid<u8>, MapIoError> {
    match read_png_file(path.as_ref(), limits, Some(8))? {
        GrayImage::Gray8(g) => Ok(g),
        GrayImage::Gray16(_) => Err(MapIoError::WrongBitDepth {
            expected: 8,
            found: 16,
        }),
    }
}

/// The size of a PNG file from its header alone, without decoding (nor allocating) its
/// pixels: to plan memory before reading a map. The side limits are checked as the readers
/// check them; the colour type and bit depth are not (the full read reports them).
pub fn read_png_size(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<UVec2, MapIoError> {
    let path = path.as_ref();
    let file = open_regular(path)?;
    let mut decoder = png_decoder(BufReader::new(&file), limits);
    let (width, height, _, _) =
        read_header(&mut decoder, limits, Source::File { path, file: &file })?;
    check_size(width, height, limits)?;
    Ok(UVec2::new(width, height))
}

/// Decodes an 8-bit RGBA PNG held in memory (a frame capture): each pixel `[r, g, b, a]`.
///
/// Other colour types are [`MapIoError::NotRgba`], 16-bit RGBA is
/// [`MapIoError::WrongBitDepth`]; sizes and corruption are checked as in [`decode_png`].
pub fn decode_png_rgba8(bytes: &[u8], limits: &ReadLimits) -> Result<Grid<[u8; 4]>, MapIoError> {
    let (width, height, _, buf) = decode_png_pixels(
        Cursor::new(bytes),
        limits,
        Accept::Rgba8,
        Source::Memory(bytes),
    )?;
    let pixels = buf
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    Ok(Grid::from_vec(width, height, pixels)?)
}

/// Reads an 8-bit RGBA PNG file. See [`decode_png_rgba8`].
pub fn read_png_rgba8(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
) -> Result<Grid<[u8; 4]>, MapIoError> {
    let path = path.as_ref();
    let file = open_regular(path)?;
    let (width, height, _, buf) = decode_png_pixels(
        BufReader::new(&file),
        limits,
        Accept::Rgba8,
        Source::File { path, file: &file },
    )?;
    let pixels = buf
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    Ok(Grid::from_vec(width, height, pixels)?)
}

// ---------------------------------------------------------------------------------------------
// PNG encoding

/// Encodes row-major sample bytes as a non-interlaced PNG.
fn encode_png(
    width: u32,
    height: u32,
    color: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<Vec<u8>, MapIoError> {
    let encode_err = |e: png::EncodingError| MapIoError::Encode {
        width,
        height,
        reason: e.to_string(),
    };
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(color);
    encoder.set_depth(depth);
    // fdeflate's fast mode: ~10x faster than the default `Balanced` on 16-bit heightmaps for
    // a file a few per cent larger (criterion `io_and_generation/png16_encode/4096`).
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header().map_err(encode_err)?;
    writer.write_image_data(data).map_err(encode_err)?;
    writer.finish().map_err(encode_err)?;
    Ok(out)
}

/// Encodes a 16-bit grayscale PNG (samples stored big-endian, as PNG requires).
pub fn encode_png16(grid: &Grid<u16>) -> Result<Vec<u8>, MapIoError> {
    let data: Vec<u8> = grid
        .as_slice()
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    encode_png(
        grid.width(),
        grid.height(),
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
        &data,
    )
}

/// Encodes an 8-bit grayscale PNG.
pub fn encode_png8(grid: &Grid<u8>) -> Result<Vec<u8>, MapIoError> {
    encode_png(
        grid.width(),
        grid.height(),
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
        grid.as_slice(),
    )
}

/// Encodes an 8-bit RGBA PNG (frame captures): each sample is `[r, g, b, a]`.
pub fn encode_png_rgba8(grid: &Grid<[u8; 4]>) -> Result<Vec<u8>, MapIoError> {
    encode_png(
        grid.width(),
        grid.height(),
        png::ColorType::Rgba,
        png::BitDepth::Eight,
        bytemuck::cast_slice(grid.as_slice()),
    )
}

/// Writes a 16-bit grayscale PNG file atomically (see [`write_atomic`]).
pub fn write_png16(path: impl AsRef<Path>, grid: &Grid<u16>) -> Result<(), MapIoError> {
    write_atomic(path, &encode_png16(grid)?)
}

/// Writes an 8-bit grayscale PNG file atomically (see [`write_atomic`]).
pub fn write_png8(path: impl AsRef<Path>, grid: &Grid<u8>) -> Result<(), MapIoError> {
    write_atomic(path, &encode_png8(grid)?)
}

/// Writes an 8-bit RGBA PNG file atomically (see [`write_atomic`]).
pub fn write_png_rgba8(path: impl AsRef<Path>, grid: &Grid<[u8; 4]>) -> Result<(), MapIoError> {
    write_atomic(path, &encode_png_rgba8(grid)?)
}

// ---------------------------------------------------------------------------------------------
// RAW16 and R32

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

fn u16_from(b: [u8; 2], order: ByteOrder) -> u16 {
    match order {
        ByteOrder::Little => u16::from_le_bytes(b),
        ByteOrder::Big => u16::from_be_bytes(b),
    }
}

fn f32_from(b: [u8; 4], order: ByteOrder) -> f32 {
    match order {
        ByteOrder::Little => f32::from_le_bytes(b),
        ByteOrder::Big => f32::from_be_bytes(b),
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

/// Decodes R32 data: `size.x * size.y` `f32` heights in `order`, row-major. Sizes are checked
/// as in [`decode_raw16`]; a byte count other than `4 * size.x * size.y` is
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

/// Reads the whole of a headerless file that must be `expected_bytes` long; `mismatch` makes
/// the error for another length. The length is checked from the file's metadata before
/// anything is read, so a wrong size never causes a large read.
fn read_raw_file(
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
    let file = open_regular(path)?;
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
    // Read at most one byte more than expected, so a file that changed since the metadata
    // check is still caught without reading it all.
    file.take(expected_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io_err)?;
    Ok(bytes)
}

fn raw16_mismatch(size: UVec2, expected_bytes: u64, actual_bytes: u64) -> MapIoError {
    MapIoError::RawSizeMismatch {
        width: size.x,
        height: size.y,
        expected_bytes,
        actual_bytes,
    }
}

fn r32_mismatch(size: UVec2, expected_bytes: u64, actual_bytes: u64) -> MapIoError {
    MapIoError::R32SizeMismatch {
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

/// Reads an R32 file of the given size (see [`decode_r32`]); the length is checked before
/// anything is read, as in [`read_raw16`].
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

/// Checks that a headerless file of `bytes_per_sample` (2 for RAW16, 4 for R32) holds exactly
/// `size`, from its metadata alone: to plan memory before reading it.
pub fn check_raw_file(
    path: impl AsRef<Path>,
    size: UVec2,
    bytes_per_sample: u8,
    limits: &ReadLimits,
) -> Result<(), MapIoError> {
    let path = path.as_ref();
    let expected = raw_len(size, u64::from(bytes_per_sample), limits)?;
    let file = open_regular(path)?;
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
        Err(r32_mismatch(size, expected, actual))
    } else {
        Err(raw16_mismatch(size, expected, actual))
    }
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

// ---------------------------------------------------------------------------------------------
// Atomic writes

/// Distinguishes temp files of concurrent writes from the same process.
static TEMP_COUNTER: AtomicU32 = AtomicU32::new(0);

/// The most bytes of the target's name a temp file name repeats: with the dot, process id,
/// counter and `.tmp` around it the temp name stays far below the 255 bytes most file systems
/// allow, however long the target's name is.
const TEMP_STEM_MAX: usize = 128;

/// The start of `name`, at most [`TEMP_STEM_MAX`] bytes, cut at a character boundary.
fn temp_stem(name: &str) -> &str {
    let mut end = name.len().min(TEMP_STEM_MAX);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    &name[..end]
}

/// Creates a new, uniquely named temp file next to the target.
fn create_temp_file(dir: &Path, file_name: &str) -> io::Result<(PathBuf, File)> {
    let pid = std::process::id();
    let stem = temp_stem(file_name);
    let mut last_err = None;
    for _ in 0..64 {
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = dir.join(format!(".{stem}.{pid}.{n}.tmp"));
        match OpenOptions::new().write(true).create_new(true).open(&temp) {
            Ok(f) => return Ok((temp, f)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last_err = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last_err.unwrap_or_else(|| io::Error::other("could not create a unique temp file")))
}

/// The file-system steps of an atomic write. Tests replace them to make each one fail.
struct AtomicSteps {
    write: fn(&mut File, &[u8]) -> io::Result<()>,
    sync_file: fn(&File) -> io::Result<()>,
    rename: fn(&Path, &Path) -> io::Result<()>,
    sync_dir: fn(&Path) -> io::Result<()>,
}

fn os_write(file: &mut File, bytes: &[u8]) -> io::Result<()> {
    file.write_all(bytes)
}

fn os_sync_file(file: &File) -> io::Result<()> {
    file.sync_all()
}

fn os_rename(from: &Path, to: &Path) -> io::Result<()> {
    fs::rename(from, to)
}

/// The steps as the operating system does them.
const OS_STEPS: AtomicSteps = AtomicSteps {
    write: os_write,
    sync_file: os_sync_file,
    rename: os_rename,
    sync_dir,
};

/// Writes, syncs and renames the temp file over the target.
fn write_and_replace(
    temp: &Path,
    mut file: File,
    bytes: &[u8],
    target: &Path,
    steps: &AtomicSteps,
) -> io::Result<()> {
    (steps.write)(&mut file, bytes)?;
    (steps.sync_file)(&file)?;
    drop(file);
    (steps.rename)(temp, target)
}

/// Makes the rename durable by syncing the directory (unix only; elsewhere a no-op).
fn sync_dir(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        match File::open(dir).and_then(|d| d.sync_all()) {
            // Some file systems cannot sync directories; the rename has happened regardless.
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::InvalidInput | io::ErrorKind::Unsupported
                ) =>
            {
                Ok(())
            }
            other => other,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

/// What a successful atomic write leaves to say.
#[derive(Debug)]
pub struct AtomicWrite {
    /// Why the directory could not be synced after the rename, if it could not: the new
    /// content is in place and every reader sees it, but after a power loss the old file may
    /// come back. A warning, not a failure: reporting the write as failed would claim the old
    /// file is still there, and it is not.
    pub dir_sync_error: Option<io::Error>,
}

/// Writes bytes atomically: temp file in the same directory, write, fsync, rename over the
/// target, fsync the directory (on unix). On any error before the rename the temp file is
/// removed and the old target is untouched; once the rename succeeded the write is done
/// (see [`write_atomic_report`] for a failed directory sync after it).
///
/// Readers of `path` see either the old content or the new one, never a partial file. The
/// parent directory must exist; it is not created. File names up to the file system's limit
/// (255 bytes on most) work: the temp file's name repeats at most the first 128 bytes.
pub fn write_atomic(path: impl AsRef<Path>, bytes: &[u8]) -> Result<(), MapIoError> {
    write_atomic_with(path.as_ref(), bytes, &OS_STEPS).map(|_| ())
}

/// [`write_atomic`], also saying whether the directory sync after the rename failed (for
/// callers that warn about it).
pub fn write_atomic_report(
    path: impl AsRef<Path>,
    bytes: &[u8],
) -> Result<AtomicWrite, MapIoError> {
    write_atomic_with(path.as_ref(), bytes, &OS_STEPS)
}

fn write_atomic_with(
    path: &Path,
    bytes: &[u8],
    steps: &AtomicSteps,
) -> Result<AtomicWrite, MapIoError> {
    let io_err = |source| MapIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| {
            io_err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "the path does not name a file",
            ))
        })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };

    let (temp, file) = create_temp_file(dir, &file_name).map_err(io_err)?;
    if let Err(e) = write_and_replace(&temp, file, bytes, path, steps) {
        // Best effort: the original error is the one worth reporting.
        let _ = fs::remove_file(&temp);
        return Err(io_err(e));
    }
    // The target is the new file from here on, whatever the directory sync says.
    Ok(AtomicWrite {
        dir_sync_error: (steps.sync_dir)(dir).err(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder for the atomic-write tests, removed at the end.
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(name: &str) -> Self {
            let dir = std::env::temp_dir().join(format!(
                "terrain-core-io-unit-{}-{name}",
                std::process::id()
            ));
            let _ = fs::remove_dir_all(&dir);
            fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }

        fn names(&self) -> Vec<String> {
            let mut n: Vec<String> = fs::read_dir(&self.0)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    fn fails<T>() -> io::Result<T> {
        Err(io::Error::other("injected failure"))
    }

    #[test]
    fn a_failed_directory_sync_after_the_rename_still_reports_the_write_as_done() {
        let dir = Scratch::new("dir-sync");
        let target = dir.0.join("map.png");
        fs::write(&target, b"old").unwrap();
        let steps = AtomicSteps {
            sync_dir: |_| fails(),
            ..OS_STEPS
        };
        let written = write_atomic_with(&target, b"new", &steps)
            .expect("the rename happened: the write is done");
        // The new content is in place; only its durability over a power loss is in doubt.
        assert_eq!(fs::read(&target).unwrap(), b"new");
        let warning = written.dir_sync_error.expect("the failed sync is reported");
        assert!(warning.to_string().contains("injected"), "{warning}");
        assert_eq!(dir.names(), ["map.png"]);
        let clean = write_atomic_with(&target, b"newer", &OS_STEPS).unwrap();
        assert!(clean.dir_sync_error.is_none());
    }

    #[test]
    fn every_failing_step_before_the_rename_removes_the_temp_file_and_keeps_the_old_file() {
        let broken = [
            AtomicSteps {
                write: |_, _| fails(),
                ..OS_STEPS
            },
            AtomicSteps {
                // Half the bytes reach the temp file, then the disk is full.
                write: |f, b| {
                    f.write_all(&b[..b.len() / 2])?;
                    fails()
                },
                ..OS_STEPS
            },
            AtomicSteps {
                sync_file: |_| fails(),
                ..OS_STEPS
            },
            AtomicSteps {
                rename: |_, _| fails(),
                ..OS_STEPS
            },
        ];
        for (i, steps) in broken.iter().enumerate() {
            let dir = Scratch::new(&format!("steps-{i}"));
            let target = dir.0.join("map.png");
            fs::write(&target, b"old").unwrap();
            let e = write_atomic_with(&target, b"new content", steps)
                .expect_err("a failed step fails the write");
            assert!(
                matches!(&e, MapIoError::Io { path, .. } if *path == target),
                "{e}"
            );
            assert_eq!(fs::read(&target).unwrap(), b"old", "step {i}");
            assert_eq!(dir.names(), ["map.png"], "step {i}: temp file left");
        }
    }

    #[test]
    fn check_size_orders_zero_then_large() {
        let l = ReadLimits { max_side: 10 };
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

    #[test]
    fn decoding_errors_map_to_variants() {
        let l = ReadLimits::default();
        let eof = png::DecodingError::IoError(io::ErrorKind::UnexpectedEof.into());
        // The chunk walk finds no truncation in complete data: the stage names the place.
        let full = encode_png8(&Grid::new(3, 3, 7u8).unwrap()).unwrap();
        let e = map_decoding_error(eof, Stage::ImageData, Source::Memory(&full), None, &l);
        assert!(
            matches!(&e, MapIoError::Truncated { reason } if reason.contains("image data")),
            "{e:?}"
        );
        // Otherwise the chunk walk says where the data ends.
        let eof = png::DecodingError::IoError(io::ErrorKind::UnexpectedEof.into());
        let e = map_decoding_error(eof, Stage::Header, Source::Memory(&full[..3]), None, &l);
        assert!(
            matches!(&e, MapIoError::Truncated { reason } if reason.contains("signature")),
            "{e:?}"
        );

        let other = png::DecodingError::IoError(io::ErrorKind::PermissionDenied.into());
        // Any open file serves: a permission error is reported without reading it.
        let exe = File::open(std::env::current_exe().unwrap()).unwrap();
        let e = map_decoding_error(
            other,
            Stage::Header,
            Source::File {
                path: Path::new("/x/y.png"),
                file: &exe,
            },
            None,
            &l,
        );
        assert!(matches!(&e, MapIoError::Io { path, .. } if path == Path::new("/x/y.png")));
        assert!(e.to_string().contains("/x/y.png"));

        let e = map_decoding_error(
            png::DecodingError::LimitsExceeded,
            Stage::ImageData,
            Source::Memory(&[]),
            Some((7, 9)),
            &l,
        );
        assert!(matches!(
            e,
            MapIoError::TooLarge {
                width: 7,
                height: 9,
                ..
            }
        ));
        let e = map_decoding_error(
            png::DecodingError::LimitsExceeded,
            Stage::Header,
            Source::Memory(&[]),
            None,
            &l,
        );
        assert!(matches!(e, MapIoError::Corrupt { .. }));
    }

    #[test]
    fn a_truncated_file_is_described_through_its_open_handle() {
        // The error path reads the file it decoded again, to say where the data ends. It
        // reads through the open handle: here the path is gone by then (removed, or replaced by
        // something that could block), and the chunk walk still finds the cut.
        let full =
            encode_png16(&Grid::from_fn(9, 4, |x, y| (x * 1000 + y) as u16).unwrap()).unwrap();
        let dir = Scratch::new("handle");
        let path = dir.0.join("cut.png");
        fs::write(&path, &full[..50]).unwrap();
        let file = File::open(&path).unwrap();
        fs::remove_file(&path).unwrap();
        let e = decode_png_from(
            BufReader::new(&file),
            &ReadLimits::default(),
            None,
            Source::File {
                path: &path,
                file: &file,
            },
        )
        .unwrap_err();
        assert!(
            matches!(&e, MapIoError::Truncated { reason } if reason.contains("byte 33")),
            "{e}"
        );
    }

    #[test]
    fn peek_ihdr_reads_size_of_encoded_png() {
        let g = Grid::from_fn(5, 3, |x, y| (x + y) as u8).unwrap();
        let bytes = encode_png8(&g).unwrap();
        assert_eq!(peek_ihdr_size(&bytes), Some((5, 3)));
        assert_eq!(peek_ihdr_size(&bytes[..23]), None);
        assert_eq!(
            peek_ihdr_size(b"not a png at all, but 24+ bytes long"),
            None
        );
    }

    #[test]
    fn truncation_is_located_by_chunk() {
        let full =
            encode_png16(&Grid::from_fn(9, 4, |x, y| (x * 1000 + y) as u16).unwrap()).unwrap();
        let describe = |n: usize| describe_truncation(&mut Cursor::new(&full[..n])).unwrap();
        assert_eq!(describe(full.len()), None);
        assert!(describe(5).unwrap().contains("signature"));
        assert!(describe(8).unwrap().contains("IHDR"));
        assert!(describe(12).unwrap().contains("header of the chunk"));
        assert!(describe(20).unwrap().contains("IHDR"));
        let at_idat = describe(50).unwrap();
        assert!(
            at_idat.contains("IDAT") && at_idat.contains("byte 33"),
            "{at_idat}"
        );
        let before_iend = describe(full.len() - 12).unwrap();
        assert!(before_iend.contains("IEND"), "{before_iend}");
        assert_eq!(chunk_name(*b"IDAT"), "IDAT");
        assert_eq!(chunk_name([0, 1, 2, 255]), "[00, 01, 02, ff]");
    }

    #[test]
    fn png_decoder_limit_covers_widest_row() {
        let l = ReadLimits::default();
        assert!(png_decoder_limits(&l).bytes > DEFAULT_MAX_SIDE as usize * 2 + 1);
        let huge = ReadLimits { max_side: u32::MAX };
        assert!(png_decoder_limits(&huge).bytes >= u32::MAX as usize);
    }

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
