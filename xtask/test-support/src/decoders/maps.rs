//! The map decoders of terrain-core: PNG (16-bit gray; 8-bit gray and RGBA8), the headerless
//! RAW16 and R32, and GeoTIFF DEMs through to the DEM import's coarse heights.

use super::{LIMITS, Outcome, check_error, check_within, le32, params, tighter};
use glam::UVec2;
use std::fmt::Debug;
use terrain_core::Grid;
use terrain_core::dem::{Dem, HUGE_FLOAT_NODATA, HeightRange};
use terrain_core::geotiff::decode_geotiff;
use terrain_core::io::{
    ByteOrder, GrayImage, MapIoError, ReadLimits, decode_png, decode_png_rgba8, decode_png8,
    decode_png16, decode_r32, decode_raw16_ordered, encode_png_rgba8, encode_png8, encode_png16,
};

/// A PNG decoder of one pixel type.
type PngDecode<T> = fn(&[u8], &ReadLimits) -> Result<Grid<T>, MapIoError>;
/// A PNG encoder of one pixel type.
type PngEncode<T> = fn(&Grid<T>) -> Result<Vec<u8>, MapIoError>;

/// The width and height a PNG's IHDR declares, when the file starts with one.
fn png_declared(data: &[u8]) -> Option<UVec2> {
    let be = |at: usize| u32::from_be_bytes([data[at], data[at + 1], data[at + 2], data[at + 3]]);
    (data.len() >= 24 && data[12..16] == *b"IHDR").then(|| UVec2::new(be(16), be(20)))
}

/// The checks of an image a PNG decoder returned for `data`: the IHDR's size, within
/// [`LIMITS`] and refused one texel tighter, and decoded again unchanged from its own
/// re-encoding.
fn check_png<T: Copy + PartialEq + Debug>(
    what: &str,
    data: &[u8],
    image: &Grid<T>,
    decode: PngDecode<T>,
    encode: PngEncode<T>,
) {
    let size = image.size();
    check_within(what, size, &LIMITS);
    assert_eq!(
        png_declared(data),
        Some(size),
        "{what}: the decoded size is not the one the IHDR declares"
    );
    let again = encode(image)
        .unwrap_or_else(|e| panic!("{what}: re-encoding a decoded {size} image failed: {e}"));
    match decode(&again, &LIMITS) {
        Ok(back) => assert!(
            back == *image,
            "{what}: a decoded {size} image re-encoded decodes to other pixels"
        ),
        Err(e) => panic!("{what}: a decoded {size} image re-encoded does not decode: {e}"),
    }
    if let Some(t) = tighter(size) {
        assert!(
            matches!(decode(data, &t), Err(MapIoError::TooLarge { .. })),
            "{what}: a {size} image is not TooLarge under max_side {}",
            t.max_side
        );
    }
}

/// 16-bit grayscale PNG heights (`decode_png16`), checked against the generic `decode_png`
/// and the 8-bit decoder (which must refuse a 16-bit file). The input is the file.
pub fn png16(data: &[u8]) -> Outcome {
    let generic = decode_png(data, &LIMITS);
    match decode_png16(data, &LIMITS) {
        Ok(g) => {
            check_png("png16", data, &g, decode_png16, encode_png16);
            assert!(
                matches!(&generic, Ok(GrayImage::Gray16(h)) if *h == g),
                "png16: decode_png disagrees: {:?}",
                generic.map(|i| (i.bit_depth(), i.size()))
            );
            assert!(
                decode_png8(data, &LIMITS).is_err(),
                "png16: a 16-bit file also decoded as 8-bit"
            );
            Outcome::Decoded
        }
        Err(e) => {
            check_error("png16", &e);
            assert!(
                !matches!(generic, Ok(GrayImage::Gray16(_))),
                "png16: refused ({e}) a file decode_png reads as 16-bit"
            );
            Outcome::Refused
        }
    }
}

/// 8-bit grayscale PNG (`decode_png8`, checked against `decode_png`) and RGBA8 captures
/// (`decode_png_rgba8`): a file is one or the other, never both. The input is the file.
pub fn png8(data: &[u8]) -> Outcome {
    let generic = decode_png(data, &LIMITS);
    let gray = decode_png8(data, &LIMITS);
    let rgba = decode_png_rgba8(data, &LIMITS);
    match &gray {
        Ok(g) => {
            check_png("png8", data, g, decode_png8, encode_png8);
            assert!(
                matches!(&generic, Ok(GrayImage::Gray8(h)) if h == g),
                "png8: decode_png disagrees"
            );
        }
        Err(e) => {
            check_error("png8", e);
            assert!(
                !matches!(generic, Ok(GrayImage::Gray8(_))),
                "png8: refused ({e}) a file decode_png reads as 8-bit"
            );
        }
    }
    match &rgba {
        Ok(p) => {
            check_png("png8 (RGBA8)", data, p, decode_png_rgba8, encode_png_rgba8);
            assert!(
                generic.is_err(),
                "png8: an RGBA8 file also decoded as grayscale"
            );
        }
        Err(e) => check_error("png8 (RGBA8)", e),
    }
    if gray.is_ok() || rgba.is_ok() {
        Outcome::Decoded
    } else {
        Outcome::Refused
    }
}

/// What a headerless decoder (RAW16, R32) must answer for data of some length at a size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawAnswer {
    /// The samples.
    Samples,
    /// `ZeroSize`: a side is 0.
    ZeroSize,
    /// `TooLarge`: a side over the limit, or a byte count past `u64`.
    TooLarge,
    /// The format's size mismatch: any other byte count.
    Mismatch,
    /// Another error (never right).
    Other,
}

impl RawAnswer {
    /// What `decode_raw16` / `decode_r32` must answer for `len` bytes of `sample_bytes`-byte
    /// samples at `size` under `limits`.
    pub fn expected(len: usize, size: UVec2, sample_bytes: u64, limits: &ReadLimits) -> Self {
        if size.min_element() == 0 {
            return Self::ZeroSize;
        }
        if size.max_element() > limits.max_side {
            return Self::TooLarge;
        }
        let need = u128::from(size.x) * u128::from(size.y) * u128::from(sample_bytes);
        if need > u128::from(u64::MAX) {
            Self::TooLarge
        } else if len as u128 != need {
            Self::Mismatch
        } else {
            Self::Samples
        }
    }

    /// What a decoder answered.
    pub fn of<T>(got: &Result<Grid<T>, MapIoError>) -> Self {
        match got {
            Ok(_) => Self::Samples,
            Err(MapIoError::ZeroSize { .. }) => Self::ZeroSize,
            Err(MapIoError::TooLarge { .. }) => Self::TooLarge,
            Err(MapIoError::RawSizeMismatch { .. } | MapIoError::R32SizeMismatch { .. }) => {
                Self::Mismatch
            }
            Err(_) => Self::Other,
        }
    }
}

/// Checks a headerless decoder's answer for `bytes` at `size` under `limits`: the answer the
/// contract calls for, a clean error, or samples whose bytes (`bytes_of`, in the order asked
/// for) are `bytes` (so NaN samples compare too).
pub fn check_raw<const N: usize, T: Copy>(
    bytes: &[u8],
    size: UVec2,
    limits: &ReadLimits,
    got: &Result<Grid<T>, MapIoError>,
    bytes_of: impl Fn(T) -> [u8; N],
) -> Result<(), String> {
    let want = RawAnswer::expected(bytes.len(), size, N as u64, limits);
    let answer = RawAnswer::of(got);
    if answer != want {
        return Err(format!(
            "{size} from {} bytes, max_side {}: expected {want:?}, got {:?}",
            bytes.len(),
            limits.max_side,
            got.as_ref().map(Grid::size)
        ));
    }
    match got {
        Ok(g) => {
            let same = g.size() == size
                && g.as_slice()
                    .iter()
                    .zip(bytes.chunks_exact(N))
                    .all(|(&v, c)| bytes_of(v) == c);
            if !same {
                return Err(format!("{size} from {} bytes: wrong samples", bytes.len()));
            }
        }
        Err(e) => check_error("raw", e),
    }
    Ok(())
}

/// The parameters of the headerless targets: width, height, max_side (u32 little-endian each),
/// then a byte whose bit 0 asks for big-endian samples.
fn raw_params(p: &[u8; 13]) -> (UVec2, ReadLimits, ByteOrder) {
    let order = if p[12] & 1 == 1 {
        ByteOrder::Big
    } else {
        ByteOrder::Little
    };
    let limits = ReadLimits {
        max_side: le32(p, 8),
        ..ReadLimits::default()
    };
    (UVec2::new(le32(p, 0), le32(p, 4)), limits, order)
}

/// RAW16 (`decode_raw16_ordered`): 13 bytes of parameters (width, height, max_side as u32
/// little-endian, then a byte whose bit 0 asks for big-endian samples), then the samples.
pub fn raw16(data: &[u8]) -> Outcome {
    let Some((p, bytes)) = params::<13>(data) else {
        return Outcome::Refused;
    };
    let (size, limits, order) = raw_params(p);
    let got = decode_raw16_ordered(bytes, size, order, &limits);
    let sample = |v: u16| match order {
        ByteOrder::Little => v.to_le_bytes(),
        ByteOrder::Big => v.to_be_bytes(),
    };
    check_raw(bytes, size, &limits, &got, sample).unwrap_or_else(|e| panic!("raw16: {e}"));
    raw_outcome(&got)
}

/// R32 (`decode_r32`): the parameters of [`raw16`], then the `f32` samples.
pub fn r32(data: &[u8]) -> Outcome {
    let Some((p, bytes)) = params::<13>(data) else {
        return Outcome::Refused;
    };
    let (size, limits, order) = raw_params(p);
    let got = decode_r32(bytes, size, order, &limits);
    let sample = |v: f32| match order {
        ByteOrder::Little => v.to_le_bytes(),
        ByteOrder::Big => v.to_be_bytes(),
    };
    check_raw(bytes, size, &limits, &got, sample).unwrap_or_else(|e| panic!("r32: {e}"));
    raw_outcome(&got)
}

fn raw_outcome<T>(got: &Result<Grid<T>, MapIoError>) -> Outcome {
    if got.is_ok() {
        Outcome::Decoded
    } else {
        Outcome::Refused
    }
}

/// GeoTIFF DEMs (`decode_geotiff`) through the DEM import: `Dem::from_geotiff` (nodata filled:
/// every height finite and below the huge-float nodata marker) and `to_coarse_heights` (the
/// DEM's size) under the heights' own range and a fixed span. The input is the file.
pub fn geotiff(data: &[u8]) -> Outcome {
    let tiff = match decode_geotiff(data, &LIMITS) {
        Ok(t) => t,
        Err(e) => {
            check_error("geotiff", &e);
            return Outcome::Refused;
        }
    };
    let size = tiff.heights.size();
    check_within("geotiff", size, &LIMITS);
    if let Some(t) = tighter(size) {
        assert!(
            matches!(decode_geotiff(data, &t), Err(MapIoError::TooLarge { .. })),
            "geotiff: a {size} DEM is not TooLarge under max_side {}",
            t.max_side
        );
    }
    let _ = tiff.geo.texel_size();
    let dem = match Dem::from_geotiff(tiff) {
        Ok(d) => d,
        Err(e) => {
            // Every sample nodata.
            check_error("geotiff (DEM)", &e);
            return Outcome::Decoded;
        }
    };
    assert!(
        dem.heights
            .as_slice()
            .iter()
            .all(|h| h.is_finite() && f64::from(*h).abs() < HUGE_FLOAT_NODATA),
        "geotiff: a nodata height is left after the fill"
    );
    let span = HeightRange::Span {
        min_m: -500.0,
        max_m: 9000.0,
    };
    for range in [HeightRange::Auto, span] {
        match dem.to_coarse_heights(range) {
            Ok(c) => assert_eq!(c.grid.size(), size, "geotiff: coarse heights of {range:?}"),
            Err(e) => check_error("geotiff (coarse heights)", &e),
        }
    }
    Outcome::Decoded
}
