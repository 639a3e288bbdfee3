//! GeoTIFF DEMs: one band of `u8`, `i8`, `u16`, `i16`, `u32`, `i32`, `f32` or `f64` samples,
//! in strips or tiles, uncompressed, LZW, Deflate or PackBits (with or without a predictor),
//! classic TIFF or BigTIFF, decoded by the `tiff` crate; and the GeoTIFF tags a DEM carries:
//! the GDAL nodata value (tag 42113), the pixel scale (33550) or model transformation (34264),
//! the tie point (33922) and the GeoKey directory (34735: model type, linear and vertical
//! units).
//!
//! Nothing of the file is trusted. Before the `tiff` crate sees the file, the first image
//! directory is walked here (its entry count, and each tag's value count against the file's
//! length), so no tag can make the decoder allocate more than the file could hold; the image
//! size is checked against [`ReadLimits`] and the sample buffer is allocated fallibly before
//! any pixel is decoded, with the decoder limited to exactly that buffer.

use crate::grid::Grid;
use crate::io::{MapIoError, ReadLimits, check_size, open_regular, try_zeroed};
use glam::UVec2;
use std::fs::File;
use std::io::{self, BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::{SampleFormat, Tag};
use tiff::{ColorType, TiffError, TiffFormatError};

/// The most entries a first image directory may have (real ones have a few dozen).
const MAX_IFD_ENTRIES: u64 = 4096;
/// The most values the tags of the first directory may hold together: 2^20 covers the offsets
/// and byte counts of a 65536^2 image in 128^2 tiles, or in strips of one row, many times over.
pub const MAX_DIRECTORY_VALUES: u64 = 1 << 20;
/// The most memory the decoder's reading of the first directory can take: each value as a
/// 32-byte enum (`tiff::decoder::ifd::Value`, checked by a test) and again as the u64 chunk
/// offsets and byte counts it keeps.
pub const DIRECTORY_BYTES_BOUND: u64 = MAX_DIRECTORY_VALUES * (32 + 16);

/// GeoKey ids (GeoTIFF 1.1, sec. 7.1) and codes (EPSG units).
const GT_MODEL_TYPE: u16 = 1024;
const PROJ_LINEAR_UNITS: u16 = 3076;
const VERTICAL_UNITS: u16 = 4099;
const MODEL_PROJECTED: u16 = 1;
const MODEL_GEOGRAPHIC: u16 = 2;
const MODEL_GEOCENTRIC: u16 = 3;
const UNIT_METRE: u16 = 9001;
const UNIT_FOOT: u16 = 9002;
const UNIT_US_SURVEY_FOOT: u16 = 9003;

/// Below this many units per pixel, a raster without a GeoKey directory is taken to be in
/// degrees (0.01° is about 1 km; a metric DEM this fine, 1 cm per pixel, is rare, and says
/// what it is in its GeoKeys).
pub const DEGREES_GUESS_BELOW: f64 = 0.01;

/// The sample type of a DEM file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleType {
    /// Unsigned 8-bit integers.
    U8,
    /// Signed 8-bit integers.
    I8,
    /// Unsigned 16-bit integers.
    U16,
    /// Signed 16-bit integers.
    I16,
    /// Unsigned 32-bit integers.
    U32,
    /// Signed 32-bit integers.
    I32,
    /// 32-bit floats.
    F32,
    /// 64-bit floats.
    F64,
}

impl SampleType {
    /// The type's name: `u8`, `i16`, `f32`, ...
    pub fn name(self) -> &'static str {
        match self {
            SampleType::U8 => "u8",
            SampleType::I8 => "i8",
            SampleType::U16 => "u16",
            SampleType::I16 => "i16",
            SampleType::U32 => "u32",
            SampleType::I32 => "i32",
            SampleType::F32 => "f32",
            SampleType::F64 => "f64",
        }
    }

    /// Bytes per sample.
    pub fn bytes(self) -> u8 {
        match self {
            SampleType::U8 | SampleType::I8 => 1,
            SampleType::U16 | SampleType::I16 => 2,
            SampleType::U32 | SampleType::I32 | SampleType::F32 => 4,
            SampleType::F64 => 8,
        }
    }
}

/// What the raster's coordinates are (GTModelTypeGeoKey).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RasterModel {
    /// No GeoKey directory, or no model type in it.
    Unspecified,
    /// Projected: the pixel scale is in the linear unit (metres unless it says otherwise).
    Projected,
    /// Geographic: the pixel scale is in degrees.
    Geographic,
    /// Geocentric (X, Y, Z): the pixel scale says nothing about the ground.
    Geocentric,
    /// A model type code GeoTIFF does not define.
    Other(u16),
}

/// The georeferencing of a GeoTIFF, as far as a DEM import needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoReference {
    /// Raster units per pixel along x (columns) and y (rows), positive; from the pixel scale
    /// tag, else from the model transformation's columns.
    pub pixel_scale: Option<[f64; 2]>,
    /// The model type.
    pub model: RasterModel,
    /// The linear unit's code (ProjLinearUnitsGeoKey), when given.
    pub linear_unit: Option<u16>,
    /// The vertical unit's code (VerticalUnitsGeoKey), when given.
    pub vertical_unit: Option<u16>,
    /// Latitude of the raster's centre in degrees, for a geographic raster with a tie point.
    pub centre_latitude: Option<f64>,
}

/// The texel size a GeoTIFF's georeferencing gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TexelSize {
    /// Metres per pixel of a projected raster (x; see `y_m` for rows).
    Metres {
        /// Metres per pixel along x.
        x_m: f64,
        /// Metres per pixel along y.
        y_m: f64,
    },
    /// A geographic raster: degrees per pixel, turned into metres at its latitude (north-south,
    /// the `metres` a square texel takes; east-west shorter by the cosine of the latitude).
    Degrees {
        /// Degrees per pixel along x and y.
        degrees: [f64; 2],
        /// Metres per pixel north-south at the raster's latitude (the equator's when unknown).
        north_south_m: f64,
        /// Metres per pixel east-west at that latitude.
        east_west_m: f64,
        /// The latitude used, when the file gives it.
        latitude: Option<f64>,
        /// Whether the file says nothing of its model and degrees were guessed from a pixel
        /// scale below [`DEGREES_GUESS_BELOW`].
        guessed: bool,
    },
    /// A projected raster in a linear unit this reader does not know: units per pixel.
    UnknownUnit {
        /// The unit's code.
        unit: u16,
        /// Units per pixel along x.
        per_pixel: f64,
    },
}

impl GeoReference {
    /// The texel size the pixel scale gives, or `None` without a pixel scale (or for a
    /// geocentric raster, whose scale is not along the ground).
    pub fn texel_size(&self) -> Option<TexelSize> {
        let [sx, sy] = self.pixel_scale?;
        let degrees = match self.model {
            RasterModel::Geographic => Some(false),
            RasterModel::Unspecified if sx < DEGREES_GUESS_BELOW && sy < DEGREES_GUESS_BELOW => {
                Some(true)
            }
            RasterModel::Geocentric => return None,
            _ => None,
        };
        if let Some(guessed) = degrees {
            let (lat_m, lon_m) = metres_per_degree(self.centre_latitude.unwrap_or(0.0));
            return Some(TexelSize::Degrees {
                degrees: [sx, sy],
                north_south_m: sy * lat_m,
                east_west_m: sx * lon_m,
                latitude: self.centre_latitude,
                guessed,
            });
        }
        match self.linear_unit.map(unit_metres) {
            None => Some(TexelSize::Metres { x_m: sx, y_m: sy }),
            Some(Some(m)) => Some(TexelSize::Metres {
                x_m: sx * m,
                y_m: sy * m,
            }),
            Some(None) => Some(TexelSize::UnknownUnit {
                unit: self.linear_unit.unwrap_or(0),
                per_pixel: sx,
            }),
        }
    }
}

/// Metres per degree of latitude and of longitude at latitude `lat` (degrees), on the WGS 84
/// ellipsoid (the usual series, within a few centimetres).
pub fn metres_per_degree(lat: f64) -> (f64, f64) {
    let p = lat.to_radians();
    let lat_m = 111_132.92 - 559.82 * (2.0 * p).cos() + 1.175 * (4.0 * p).cos();
    let lon_m = 111_412.84 * p.cos() - 93.5 * (3.0 * p).cos();
    (lat_m, lon_m.max(0.0))
}

/// Metres per unit of an EPSG unit code, for the units DEMs use.
fn unit_metres(code: u16) -> Option<f64> {
    match code {
        UNIT_METRE => Some(1.0),
        UNIT_FOOT => Some(0.3048),
        UNIT_US_SURVEY_FOOT => Some(1200.0 / 3937.0),
        _ => None,
    }
}

/// A decoded GeoTIFF DEM.
#[derive(Debug, Clone, PartialEq)]
pub struct GeoTiff {
    /// The heights, in the file's vertical unit converted to metres (feet are converted; an
    /// unknown or absent vertical unit is taken as metres). Nodata samples (the GDAL nodata
    /// value, and NaN or infinite floats) are NaN.
    pub heights: Grid<f32>,
    /// The sample type in the file.
    pub sample: SampleType,
    /// The GDAL nodata value, when the file has one.
    pub nodata: Option<f64>,
    /// The georeferencing.
    pub geo: GeoReference,
}

/// Where the bytes come from, for errors: an I/O error on a file names it.
#[derive(Clone, Copy)]
pub(crate) enum Origin<'a> {
    Memory,
    File(&'a Path),
}

/// Reads a GeoTIFF DEM file. See the module docs for what is accepted and checked.
pub fn read_geotiff(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<GeoTiff, MapIoError> {
    let path = path.as_ref();
    read_geotiff_from_file(&open_regular(path)?, path, limits)
}

/// Reads a GeoTIFF DEM from an open file, from its start (see [`read_geotiff`]); `path` names
/// the file in errors only, and is never opened.
pub(crate) fn read_geotiff_from_file(
    file: &File,
    path: &Path,
    limits: &ReadLimits,
) -> Result<GeoTiff, MapIoError> {
    let len = file_len(file, path)?;
    let origin = Origin::File(path);
    check_first_ifd(&mut rewound(file, path)?, len, limits, origin)?;
    decode_from(rewound(file, path)?, len, limits, origin)
}

/// Decodes a GeoTIFF DEM held in memory (see [`read_geotiff`]).
pub fn decode_geotiff(bytes: &[u8], limits: &ReadLimits) -> Result<GeoTiff, MapIoError> {
    let len = bytes.len() as u64;
    check_first_ifd(&mut Cursor::new(bytes), len, limits, Origin::Memory)?;
    decode_from(Cursor::new(bytes), len, limits, Origin::Memory)
}

/// The size of a GeoTIFF file from its first image directory alone (no pixel is decoded), its
/// side limits checked: to plan memory before reading it.
pub fn read_geotiff_size(path: impl AsRef<Path>, limits: &ReadLimits) -> Result<UVec2, MapIoError> {
    let path = path.as_ref();
    read_geotiff_size_from_file(&open_regular(path)?, path, limits)
}

/// The size of a GeoTIFF from the first image directory of an open file (see
/// [`read_geotiff_size`]); `path` names the file in errors only.
pub(crate) fn read_geotiff_size_from_file(
    file: &File,
    path: &Path,
    limits: &ReadLimits,
) -> Result<UVec2, MapIoError> {
    let len = file_len(file, path)?;
    let origin = Origin::File(path);
    check_first_ifd(&mut rewound(file, path)?, len, limits, origin)?;
    let mut decoder = Decoder::new(rewound(file, path)?).map_err(|e| map_tiff_error(e, origin))?;
    let (w, h) = decoder
        .dimensions()
        .map_err(|e| map_tiff_error(e, origin))?;
    check_size(w, h, limits)?;
    Ok(UVec2::new(w, h))
}

/// A buffered reader of `file` from its start (the directory walk moved its position).
fn rewound<'f>(file: &'f File, path: &Path) -> Result<BufReader<&'f File>, MapIoError> {
    let mut f = file;
    f.seek(SeekFrom::Start(0))
        .map_err(|source| MapIoError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    Ok(BufReader::new(file))
}

fn file_len(file: &File, path: &Path) -> Result<u64, MapIoError> {
    Ok(file
        .metadata()
        .map_err(|source| MapIoError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .len())
}

fn decode_from<R: Read + Seek>(
    reader: R,
    len: u64,
    limits: &ReadLimits,
    origin: Origin<'_>,
) -> Result<GeoTiff, MapIoError> {
    let err = |e| map_tiff_error(e, origin);
    let mut decoder = Decoder::new(reader).map_err(err)?;
    let (width, height) = decoder.dimensions().map_err(err)?;
    // Everything below up to the pixel buffer is decided from the directory alone.
    check_size(width, height, limits)?;
    let sample = sample_type(&mut decoder, origin)?;
    // The tags are read with the decoder's default limits; `check_first_ifd` already bounded
    // each of them by the file's length.
    let nodata = read_nodata(&mut decoder, origin)?;
    let geo = read_georeference(&mut decoder, height, origin)?;

    let texels = (width as usize)
        .checked_mul(height as usize)
        .ok_or(MapIoError::TooLarge {
            width,
            height,
            max_side: limits.max_side,
        })?;
    let bytes = texels.saturating_mul(usize::from(sample.bytes()));
    // The decoder allocates the sample buffer itself, infallibly: make sure it can exist, then
    // limit the decoder to exactly it. A chunk cannot be larger than the file.
    drop(try_zeroed::<u8>(bytes, width, height)?);
    let mut tiff_limits = Limits::default();
    tiff_limits.decoding_buffer_size = bytes;
    tiff_limits.intermediate_buffer_size = usize::try_from(len).unwrap_or(usize::MAX);
    let mut decoder = decoder.with_limits(tiff_limits);
    let decoded = decoder.read_image().map_err(err)?;

    let vertical = geo.vertical_unit.and_then(unit_metres).unwrap_or(1.0);
    let heights = to_metres(decoded, nodata, vertical, sample)?;
    if heights.len() != texels {
        return Err(MapIoError::Corrupt {
            reason: format!(
                "the TIFF decoder returned {} samples for a {width}x{height} image",
                heights.len()
            ),
        });
    }
    Ok(GeoTiff {
        heights: Grid::from_vec(width, height, heights)?,
        sample,
        nodata,
        geo,
    })
}

/// The sample type from the colour type and SampleFormat, or why the image is no DEM.
fn sample_type<R: Read + Seek>(
    decoder: &mut Decoder<R>,
    origin: Origin<'_>,
) -> Result<SampleType, MapIoError> {
    let unsupported = |reason: String| MapIoError::UnsupportedTiff { reason };
    let bits = match decoder.colortype().map_err(|e| map_tiff_error(e, origin))? {
        ColorType::Gray(bits) => bits,
        ColorType::Multiband {
            bit_depth,
            num_samples,
        } => {
            return Err(unsupported(format!(
                "{num_samples} bands of {bit_depth}-bit samples"
            )));
        }
        other => return Err(unsupported(format!("colour image ({other:?})"))),
    };
    let format = decoder
        .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
        .map_err(|e| map_tiff_error(e, origin))?
        .and_then(|v| v.first().copied())
        .map_or(SampleFormat::Uint, SampleFormat::from_u16_exhaustive);
    Ok(match (format, bits) {
        (SampleFormat::Uint, 8) => SampleType::U8,
        (SampleFormat::Int, 8) => SampleType::I8,
        (SampleFormat::Uint, 16) => SampleType::U16,
        (SampleFormat::Int, 16) => SampleType::I16,
        (SampleFormat::Uint, 32) => SampleType::U32,
        (SampleFormat::Int, 32) => SampleType::I32,
        (SampleFormat::IEEEFP, 32) => SampleType::F32,
        (SampleFormat::IEEEFP, 64) => SampleType::F64,
        (format, bits) => {
            return Err(unsupported(format!(
                "{bits}-bit samples of format {format:?}"
            )));
        }
    })
}

/// The GDAL nodata value (ASCII, as GDAL writes it: `-9999`, `nan`, `-3.4028235e+38`).
fn read_nodata<R: Read + Seek>(
    decoder: &mut Decoder<R>,
    origin: Origin<'_>,
) -> Result<Option<f64>, MapIoError> {
    let Some(value) = decoder
        .find_tag(Tag::GdalNodata)
        .map_err(|e| map_tiff_error(e, origin))?
    else {
        return Ok(None);
    };
    let text = match value {
        tiff::decoder::ifd::Value::Ascii(s) => s,
        other => {
            return Err(MapIoError::Corrupt {
                reason: bounded(format!(
                    "the GDAL nodata tag (42113) is not text: {other:?}"
                )),
            });
        }
    };
    let trimmed = text.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    if trimmed.is_empty() {
        return Ok(None);
    }
    trimmed
        .to_ascii_lowercase()
        .parse::<f64>()
        .map(Some)
        .map_err(|_| MapIoError::Corrupt {
            reason: bounded(format!(
                "the GDAL nodata tag (42113) holds `{trimmed}`, which is no number"
            )),
        })
}

/// The georeferencing tags: pixel scale (or transformation), tie point, GeoKeys.
fn read_georeference<R: Read + Seek>(
    decoder: &mut Decoder<R>,
    height: u32,
    origin: Origin<'_>,
) -> Result<GeoReference, MapIoError> {
    let err = |e| map_tiff_error(e, origin);
    let doubles = |decoder: &mut Decoder<R>, tag: Tag| -> Result<Option<Vec<f64>>, MapIoError> {
        decoder
            .find_tag(tag)
            .map_err(err)?
            .map(|v| v.into_f64_vec().map_err(err))
            .transpose()
    };
    let scale = doubles(decoder, Tag::ModelPixelScaleTag)?;
    let transform = doubles(decoder, Tag::ModelTransformationTag)?;
    let pixel_scale = match (scale, transform) {
        (Some(s), _) if s.len() >= 2 => Some([s[0].abs(), s[1].abs()]),
        // A 4 x 4 row-major matrix: its first two columns are a pixel step along x and y.
        (_, Some(m)) if m.len() >= 16 => Some([m[0].hypot(m[4]), m[1].hypot(m[5])]),
        _ => None,
    }
    .filter(|s| s.iter().all(|v| v.is_finite() && *v > 0.0));
    let tiepoint = doubles(decoder, Tag::ModelTiepointTag)?;

    let keys = decoder
        .find_tag(Tag::GeoKeyDirectoryTag)
        .map_err(err)?
        .map(|v| v.into_u16_vec().map_err(err))
        .transpose()?
        .unwrap_or_default();
    let key = |id: u16| -> Option<u16> {
        // Header: version, revision, minor revision, key count; then 4 shorts per key: id,
        // location (0: the value is the 4th short), count, value. Only inline keys are read.
        let count = usize::from(*keys.get(3)?);
        keys.get(4..)?
            .chunks_exact(4)
            .take(count)
            .find(|k| k[0] == id && k[1] == 0)
            .map(|k| k[3])
    };
    let model = match key(GT_MODEL_TYPE) {
        None => RasterModel::Unspecified,
        Some(MODEL_PROJECTED) => RasterModel::Projected,
        Some(MODEL_GEOGRAPHIC) => RasterModel::Geographic,
        Some(MODEL_GEOCENTRIC) => RasterModel::Geocentric,
        Some(other) => RasterModel::Other(other),
    };
    // A tie point (i, j, k, x, y, z) puts raster row j at latitude y: the centre row is
    // height / 2 - j rows further south.
    let centre_latitude = match (tiepoint, pixel_scale) {
        (Some(t), Some([_, sy])) if t.len() >= 6 => {
            let lat = t[4] - sy * (f64::from(height) / 2.0 - t[1]);
            (lat.is_finite() && lat.abs() <= 90.0).then_some(lat)
        }
        _ => None,
    };
    Ok(GeoReference {
        pixel_scale,
        model,
        linear_unit: key(PROJ_LINEAR_UNITS),
        vertical_unit: key(VERTICAL_UNITS),
        centre_latitude,
    })
}

/// The decoded samples as f32 metres (times `vertical`), nodata as NaN. Compared with the
/// nodata value in the sample's own type, so a large integer that rounds to it as f32 is not
/// taken for it.
fn to_metres(
    decoded: DecodingResult,
    nodata: Option<f64>,
    vertical: f64,
    sample: SampleType,
) -> Result<Vec<f32>, MapIoError> {
    fn ints<T: Copy + Into<f64>>(v: &[T], nodata: Option<f64>, vertical: f64) -> Vec<f32> {
        v.iter()
            .map(|&s| {
                let s: f64 = s.into();
                if nodata == Some(s) {
                    f32::NAN
                } else {
                    (s * vertical) as f32
                }
            })
            .collect()
    }
    // A float nodata is compared at the file's precision: GDAL writes the f32 value's
    // shortest text, which parses back to a slightly different f64.
    let float_nodata = |s: f64, as_file: fn(f64) -> f64| -> bool {
        !s.is_finite() || nodata.is_some_and(|n| as_file(n) == s)
    };
    Ok(match decoded {
        DecodingResult::U8(v) => ints(&v, nodata, vertical),
        DecodingResult::I8(v) => ints(&v, nodata, vertical),
        DecodingResult::U16(v) => ints(&v, nodata, vertical),
        DecodingResult::I16(v) => ints(&v, nodata, vertical),
        DecodingResult::U32(v) => ints(&v, nodata, vertical),
        DecodingResult::I32(v) => ints(&v, nodata, vertical),
        DecodingResult::F32(mut v) => {
            // In place: no second buffer for the commonest DEM type.
            for s in &mut v {
                if float_nodata(f64::from(*s), |n| f64::from(n as f32)) {
                    *s = f32::NAN;
                } else if vertical != 1.0 {
                    *s = (f64::from(*s) * vertical) as f32;
                }
            }
            v
        }
        DecodingResult::F64(v) => v
            .iter()
            .map(|&s| {
                if float_nodata(s, |n| n) {
                    f32::NAN
                } else {
                    (s * vertical) as f32
                }
            })
            .collect(),
        other => {
            return Err(MapIoError::UnsupportedTiff {
                reason: format!(
                    "the decoder returned {} samples for a {} image",
                    decoded_name(&other),
                    sample.name()
                ),
            });
        }
    })
}

fn decoded_name(d: &DecodingResult) -> &'static str {
    match d {
        DecodingResult::U8(_) => "u8",
        DecodingResult::U16(_) => "u16",
        DecodingResult::U32(_) => "u32",
        DecodingResult::U64(_) => "u64",
        DecodingResult::F16(_) => "f16",
        DecodingResult::F32(_) => "f32",
        DecodingResult::F64(_) => "f64",
        DecodingResult::I8(_) => "i8",
        DecodingResult::I16(_) => "i16",
        DecodingResult::I32(_) => "i32",
        DecodingResult::I64(_) => "i64",
    }
}

/// The most bytes of a reason that quotes the file (a tag's values, the TIFF decoder's
/// message, which lists every value of a bad tag): the file decides how long those are, up to
/// megabytes, and an error is read by a person (the decoders' fuzz targets found a 14 kB one).
const MAX_REASON: usize = 240;

/// `reason` cut to [`MAX_REASON`] bytes at a character boundary, saying how much was left out.
fn bounded(reason: String) -> String {
    if reason.len() <= MAX_REASON {
        return reason;
    }
    let mut end = MAX_REASON;
    while !reason.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}... ({} more bytes)", &reason[..end], reason.len() - end)
}

/// Maps a `tiff` error to ours.
pub(crate) fn map_tiff_error(e: TiffError, origin: Origin<'_>) -> MapIoError {
    match e {
        TiffError::IoError(io) if io.kind() == io::ErrorKind::UnexpectedEof => {
            MapIoError::Truncated {
                reason: "the data ends inside the TIFF's image data or a tag's values".to_owned(),
            }
        }
        TiffError::IoError(source) => match origin {
            Origin::File(path) => MapIoError::Io {
                path: path.to_path_buf(),
                source,
            },
            Origin::Memory => MapIoError::Corrupt {
                reason: bounded(format!("reading the TIFF data failed: {source}")),
            },
        },
        TiffError::FormatError(TiffFormatError::TiffSignatureNotFound) => MapIoError::Corrupt {
            reason: "not a TIFF file (it does not start with II or MM)".to_owned(),
        },
        TiffError::FormatError(f) => MapIoError::Corrupt {
            reason: bounded(format!("invalid TIFF: {f}")),
        },
        TiffError::UnsupportedError(u) => MapIoError::UnsupportedTiff {
            reason: bounded(u.to_string()),
        },
        TiffError::LimitsExceeded => MapIoError::Corrupt {
            reason: "the TIFF's chunks need more memory than its image size allows".to_owned(),
        },
        TiffError::IntSizeError => MapIoError::Corrupt {
            reason: "a TIFF size or offset does not fit this platform".to_owned(),
        },
        TiffError::UsageError(u) => MapIoError::Corrupt {
            reason: bounded(format!("the TIFF decoder refused the file: {u}")),
        },
    }
}

// ---------------------------------------------------------------------------------------------
// The first image directory, walked before the decoder sees it

/// Little- or big-endian integers of the file.
#[derive(Clone, Copy)]
struct Endian {
    big: bool,
}

impl Endian {
    fn u16(self, b: [u8; 2]) -> u16 {
        if self.big {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    }

    fn u32(self, b: [u8; 4]) -> u32 {
        if self.big {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    }

    fn u64(self, b: [u8; 8]) -> u64 {
        if self.big {
            u64::from_be_bytes(b)
        } else {
            u64::from_le_bytes(b)
        }
    }
}

/// Bytes per value of a TIFF field type (0 for types the specification does not define: the
/// decoder skips them).
fn type_size(ty: u16) -> u64 {
    match ty {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 | 16 | 17 | 18 => 8,
        _ => 0,
    }
}

/// Reads exactly `N` bytes at `pos`, or says the file ends there.
fn read_at<const N: usize>(
    r: &mut (impl Read + Seek),
    pos: u64,
    what: &str,
    origin: Origin<'_>,
) -> Result<[u8; N], MapIoError> {
    let mut b = [0u8; N];
    r.seek(SeekFrom::Start(pos))
        .and_then(|_| r.read_exact(&mut b))
        .map_err(|e| match e.kind() {
            io::ErrorKind::UnexpectedEof => MapIoError::Truncated {
                reason: format!("the data ends inside {what} at byte {pos}"),
            },
            _ => match origin {
                Origin::File(path) => MapIoError::Io {
                    path: path.to_path_buf(),
                    source: e,
                },
                Origin::Memory => MapIoError::Corrupt {
                    reason: format!("reading the TIFF data failed: {e}"),
                },
            },
        })?;
    Ok(b)
}

/// Walks the header and the first image directory: the entry count is bounded, and every
/// tag's values must lie inside the file and number at most [`MAX_DIRECTORY_VALUES`] in all,
/// so the decoder
/// (which reads the directory with its default limits, up to 256 MiB per tag) allocates no
/// more than the file could justify. The image size is checked against `limits` here too,
/// before the decoder works out strips and tiles for it.
pub(crate) fn check_first_ifd(
    r: &mut (impl Read + Seek),
    len: u64,
    limits: &ReadLimits,
    origin: Origin<'_>,
) -> Result<(), MapIoError> {
    let head: [u8; 4] = read_at(r, 0, "the TIFF header", origin)?;
    let e = match &head[..2] {
        b"II" => Endian { big: false },
        b"MM" => Endian { big: true },
        _ => {
            return Err(MapIoError::Corrupt {
                reason: "not a TIFF file (it does not start with II or MM)".to_owned(),
            });
        }
    };
    let (big, first) = match e.u16([head[2], head[3]]) {
        42 => (
            false,
            u64::from(e.u32(read_at(r, 4, "the TIFF header", origin)?)),
        ),
        43 => (true, e.u64(read_at(r, 8, "the BigTIFF header", origin)?)),
        magic => {
            return Err(MapIoError::Corrupt {
                reason: format!("not a TIFF file (version {magic}, not 42 or 43)"),
            });
        }
    };
    let (count_len, entry_len, inline) = if big { (8, 20, 8) } else { (2, 12, 4) };
    let dir = "the first image directory";
    let count = if big {
        e.u64(read_at(r, first, dir, origin)?)
    } else {
        u64::from(e.u16(read_at(r, first, dir, origin)?))
    };
    if count == 0 || count > MAX_IFD_ENTRIES {
        return Err(MapIoError::Corrupt {
            reason: format!("the first image directory has {count} entries"),
        });
    }
    let end = first
        .checked_add(count_len + count * entry_len)
        .filter(|&end| end <= len)
        .ok_or_else(|| MapIoError::Truncated {
            reason: format!(
                "the data ends inside the first image directory ({count} entries at byte \
                 {first}, {len} bytes in all)"
            ),
        })?;
    let mut pos = first + count_len;
    let (mut width, mut height) = (None, None);
    let mut total = 0u64;
    while pos < end {
        let (tag, ty, values, offset) = if big {
            let b: [u8; 20] = read_at(r, pos, dir, origin)?;
            let (tag, ty) = (e.u16([b[0], b[1]]), e.u16([b[2], b[3]]));
            let mut n = [0u8; 8];
            n.copy_from_slice(&b[4..12]);
            let mut o = [0u8; 8];
            o.copy_from_slice(&b[12..20]);
            (tag, ty, e.u64(n), e.u64(o))
        } else {
            let b: [u8; 12] = read_at(r, pos, dir, origin)?;
            let (tag, ty) = (e.u16([b[0], b[1]]), e.u16([b[2], b[3]]));
            let n = e.u32([b[4], b[5], b[6], b[7]]);
            let o = e.u32([b[8], b[9], b[10], b[11]]);
            (tag, ty, u64::from(n), u64::from(o))
        };
        pos += entry_len;
        // ImageWidth and ImageLength: one SHORT or LONG, inline at the start of the field
        // (whose bytes were read in the file's order, so a SHORT sits in the high half of a
        // big-endian LONG).
        if (tag == 256 || tag == 257) && values == 1 {
            let v = match (ty, e.big, big) {
                (3, true, false) => offset >> 16,
                (3, true, true) => offset >> 48,
                (3, false, _) => offset & 0xFFFF,
                (4, true, true) => offset >> 32,
                (4, _, _) => offset & 0xFFFF_FFFF,
                _ => continue,
            };
            let v = u32::try_from(v).unwrap_or(u32::MAX);
            if tag == 256 {
                width = Some(v);
            } else {
                height = Some(v);
            }
        }
        total = total.saturating_add(values);
        if total > MAX_DIRECTORY_VALUES {
            return Err(MapIoError::Corrupt {
                reason: format!(
                    "tag {tag} holds {values} values, which brings the directory past the \
                     {MAX_DIRECTORY_VALUES} values a DEM's directory needs"
                ),
            });
        }
        let bytes = values.saturating_mul(type_size(ty));
        if bytes > inline && offset.checked_add(bytes).is_none_or(|end| end > len) {
            return Err(MapIoError::Truncated {
                reason: format!(
                    "the values of tag {tag} (bytes {offset}..{}) lie past the end of the \
                     {len}-byte file",
                    offset.saturating_add(bytes)
                ),
            });
        }
    }
    if let (Some(w), Some(h)) = (width, height) {
        check_size(w, h, limits)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_directory_bound_counts_the_decoders_value_size() {
        assert!(std::mem::size_of::<tiff::decoder::ifd::Value>() <= 32);
    }

    #[test]
    fn metres_per_degree_matches_known_values() {
        let (lat, lon) = metres_per_degree(0.0);
        assert!((lat - 110_574.0).abs() < 2.0, "{lat}");
        assert!((lon - 111_320.0).abs() < 2.0, "{lon}");
        let (lat, lon) = metres_per_degree(60.0);
        assert!((lat - 111_412.0).abs() < 2.0, "{lat}");
        assert!((lon - 55_800.0).abs() < 20.0, "{lon}");
        assert!(metres_per_degree(90.0).1 < 1e-6);
    }

    #[test]
    fn texel_size_follows_the_model_and_units() {
        let geo = |model, scale: f64, unit| GeoReference {
            pixel_scale: Some([scale, scale]),
            model,
            linear_unit: unit,
            vertical_unit: None,
            centre_latitude: None,
        };
        assert_eq!(
            geo(RasterModel::Projected, 10.0, None).texel_size(),
            Some(TexelSize::Metres {
                x_m: 10.0,
                y_m: 10.0
            })
        );
        match geo(RasterModel::Projected, 10.0, Some(UNIT_FOOT)).texel_size() {
            Some(TexelSize::Metres { x_m, .. }) => assert!((x_m - 3.048).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            geo(RasterModel::Projected, 10.0, Some(9036)).texel_size(),
            Some(TexelSize::UnknownUnit { unit: 9036, .. })
        ));
        // One arc-second: 30.7 m north-south at the equator.
        match geo(RasterModel::Geographic, 1.0 / 3600.0, None).texel_size() {
            Some(TexelSize::Degrees {
                north_south_m,
                guessed: false,
                ..
            }) => assert!((north_south_m - 30.715).abs() < 0.01, "{north_south_m}"),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            geo(RasterModel::Unspecified, 0.001, None).texel_size(),
            Some(TexelSize::Degrees { guessed: true, .. })
        ));
        assert!(matches!(
            geo(RasterModel::Unspecified, 5.0, None).texel_size(),
            Some(TexelSize::Metres { .. })
        ));
        assert_eq!(geo(RasterModel::Geocentric, 5.0, None).texel_size(), None);
    }
}
