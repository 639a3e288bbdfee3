//! PNG: grayscale maps (8 and 16 bit) and RGBA8 frame captures, decoded from memory or a file
//! and encoded with the `png` crate. Decoding checks the header before any pixel buffer
//! exists and turns every decoder error into a [`MapIoError`] that says where a truncated
//! file ends.

use super::{
    GrayImage, MapIoError, ReadLimits, check_size, open_regular, try_zeroed, write_atomic,
};
use crate::grid::Grid;
use glam::UVec2;
use std::fs::File;
use std::io::{self, BufRead, BufReader, Cursor, Read, Seek};
use std::path::Path;

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
    /// 8-bit RGB or RGBA (colour layers).
    Color8,
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
        Accept::Color8 => {
            let channels = match color_type {
                png::ColorType::Rgb => 3,
                png::ColorType::Rgba => 4,
                other => {
                    return Err(MapIoError::NotRgba {
                        color_type: color_type_name(other).to_owned(),
                    });
                }
            };
            if bits != 8 {
                return Err(MapIoError::WrongBitDepth {
                    expected: 8,
                    found: bits,
                });
            }
            channels
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
    read_png_from_file(&open_regular(path)?, path, limits, want)
}

/// Seeks an open file back to its start (a caller may have read from it already).
fn rewind(file: &File, path: &Path) -> Result<(), MapIoError> {
    let mut f = file;
    f.seek(io::SeekFrom::Start(0))
        .map(|_| ())
        .map_err(|source| MapIoError::Io {
            path: path.to_path_buf(),
            source,
        })
}

/// Reads a grayscale PNG from an open file, from its start (see [`read_png`]); `path` names
/// the file in errors only, and is never opened. `want` is the bit depth required, if any.
pub(crate) fn read_png_from_file(
    file: &File,
    path: &Path,
    limits: &ReadLimits,
    want: Option<u8>,
) -> Result<GrayImage, MapIoError> {
    rewind(file, path)?;
    decode_png_from(
        BufReader::new(file),
        limits,
        want,
        Source::File { path, file },
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
    read_png_size_from_file(&open_regular(path)?, path, limits)
}

/// The size of a PNG from the header of an open file, read from its start (see
/// [`read_png_size`]); `path` names the file in errors only.
pub(crate) fn read_png_size_from_file(
    file: &File,
    path: &Path,
    limits: &ReadLimits,
) -> Result<UVec2, MapIoError> {
    rewind(file, path)?;
    let mut decoder = png_decoder(BufReader::new(file), limits);
    let (width, height, _, _) = read_header(&mut decoder, limits, Source::File { path, file })?;
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

/// Decodes an 8-bit RGB or RGBA PNG held in memory into RGBA pixels (alpha 255 for RGB);
/// other colour types are [`MapIoError::NotRgba`].
pub(crate) fn decode_png_color(
    bytes: &[u8],
    limits: &ReadLimits,
) -> Result<Grid<[u8; 4]>, MapIoError> {
    let (width, height, _, buf) = decode_png_pixels(
        Cursor::new(bytes),
        limits,
        Accept::Color8,
        Source::Memory(bytes),
    )?;
    let channels = buf.len() / (width as usize * height as usize).max(1);
    let pixels = buf
        .chunks_exact(channels.max(1))
        .map(|p| [p[0], p[1], p[2], if channels == 4 { p[3] } else { 255 }])
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::DEFAULT_MAX_SIDE;
    use std::fs;

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
        let path = std::env::temp_dir().join(format!(
            "terrain-core-io-unit-{}-handle-cut.png",
            std::process::id()
        ));
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
        let huge = ReadLimits {
            max_side: u32::MAX,
            ..ReadLimits::default()
        };
        assert!(png_decoder_limits(&huge).bytes >= u32::MAX as usize);
    }
}
