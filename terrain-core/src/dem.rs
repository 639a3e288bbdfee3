//! DEM import: reads a digital elevation model in any of the formats terrain tools and GIS
//! export (PNG 8/16-bit, RAW16 in either byte order, R32 floats, GeoTIFF), fills its nodata
//! holes, and turns its heights into the u16 samples and [`HeightEncoding`] of a coarse-map.
//!
//! ```no_run
//! use terrain_core::dem::{DemOptions, HeightRange, read_dem};
//! use terrain_core::CoarseMap;
//!
//! let dem = read_dem("dem.tif", &DemOptions::default())?;
//! // A GeoTIFF's pixel scale gives its texel size (None: say it yourself).
//! let texel = dem.georeference.and_then(|g| g.texel_size());
//! let heights = dem.to_coarse_heights(HeightRange::Auto)?;
//! let map = CoarseMap::coarse(heights.grid, heights.encoding, 10.0)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! What the heights mean depends on the format: GeoTIFF and R32 carry metres (a GeoTIFF in
//! feet, by its vertical unit, is converted), which are kept; PNG and RAW16 carry bare integers,
//! which [`HeightRange::Span`] maps linearly (0 to `min_m`, the type's largest value to
//! `max_m`) and [`HeightRange::Auto`] takes as one metre per unit (as GDAL exports a DEM to
//! `UInt16`). Either way the coarse-map's encoding spans the heights' own lowest to highest
//! value under `Auto`, so the 16 bits cover the terrain and nothing else.
//!
//! Nodata: the GDAL nodata value of a GeoTIFF, and NaN, infinite or huge (magnitude at least
//! [`HUGE_FLOAT_NODATA`]) floats of GeoTIFF and R32 files, are filled with the lowest valid
//! height and counted ([`NodataFill`]); a file of nodata only is an error.

use crate::error::CoreError;
use crate::geotiff::{self, GeoReference, SampleType};
use crate::grid::Grid;
use crate::io::{self, ByteOrder, MapIoError, ReadLimits, open_regular};
use crate::map::{HeightEncoding, HeightSample};
use glam::UVec2;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// Floats at least this large in magnitude are nodata: tools without a nodata tag mark holes
/// with `f32::MIN` (-3.4e38) or 1e38, and no height in metres comes near.
pub const HUGE_FLOAT_NODATA: f64 = 1e30;

/// The file formats a DEM is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DemFormat {
    /// A grayscale PNG, 8 or 16 bits per sample (`.png`).
    Png,
    /// Headerless u16 samples (`.r16`, `.raw`); the size must be given.
    Raw16,
    /// Headerless f32 heights in metres (`.r32`); the size must be given.
    R32,
    /// A GeoTIFF (`.tif`, `.tiff`): see [`crate::geotiff`].
    GeoTiff,
}

impl DemFormat {
    /// The format's name: `PNG`, `RAW16`, `R32`, `GeoTIFF`.
    pub fn name(self) -> &'static str {
        match self {
            DemFormat::Png => "PNG",
            DemFormat::Raw16 => "RAW16",
            DemFormat::R32 => "R32",
            DemFormat::GeoTiff => "GeoTIFF",
        }
    }

    /// The format a file name's extension says (case-insensitive), if it says one.
    pub fn from_extension(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "png" => DemFormat::Png,
            "r16" | "raw" => DemFormat::Raw16,
            "r32" => DemFormat::R32,
            "tif" | "tiff" => DemFormat::GeoTiff,
            _ => return None,
        })
    }

    /// Whether the format stores no size (RAW16, R32).
    pub fn is_headerless(self) -> bool {
        matches!(self, DemFormat::Raw16 | DemFormat::R32)
    }
}

/// How to read a DEM file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DemOptions {
    /// The format, or `None` to choose it by the file's extension, else by its first bytes
    /// (a PNG or TIFF signature), else RAW16 when `raw_size` is given.
    pub format: Option<DemFormat>,
    /// Width and height of a headerless file (RAW16, R32): required for them, refused for the
    /// others.
    pub raw_size: Option<UVec2>,
    /// Byte order of a headerless file's samples (PNG and TIFF say their own).
    pub byte_order: ByteOrder,
    /// Size limits checked before any sample buffer is allocated.
    pub limits: ReadLimits,
}

/// What a DEM's decoded heights are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HeightUnits {
    /// Metres (GeoTIFF, R32).
    Metres,
    /// Bare integers whose full scale is `full_scale` (255 for 8-bit PNG, 65535 for 16-bit
    /// PNG and RAW16): their metres come from a [`HeightRange`].
    Stored {
        /// The largest value of the sample type.
        full_scale: u32,
    },
}

/// The nodata samples of a DEM and what filled them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodataFill {
    /// The file's nodata value (a GeoTIFF's GDAL nodata tag), if it has one; NaN, infinite and
    /// huge floats are nodata in any case.
    pub value: Option<f64>,
    /// Samples that were nodata.
    pub count: u64,
    /// The height they were filled with: the lowest valid height, in the file's units.
    pub fill: f32,
}

/// A DEM as read: heights, what they are, and what the file said about itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Dem {
    /// The heights: metres, or stored integers (see `units`); nodata already filled.
    pub heights: Grid<f32>,
    /// The format it was read as.
    pub format: DemFormat,
    /// The sample type in the file.
    pub sample: SampleType,
    /// What the heights are.
    pub units: HeightUnits,
    /// The nodata samples, when there were any.
    pub nodata: Option<NodataFill>,
    /// The nodata samples as a hole mask ([`crate::holes`]), when there were any: where the
    /// ground is missing, for a renderer to leave out and collision to ignore.
    pub holes: Option<Grid<u8>>,
    /// A GeoTIFF's georeferencing (its pixel scale gives the texel size).
    pub georeference: Option<GeoReference>,
}

/// The span of heights a DEM's coarse-map encoding covers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HeightRange {
    /// The heights' own lowest to highest value (bare integers taken as metres).
    Auto,
    /// The heights' own span widened by `fraction` of it below and above (at least 1 m each
    /// way; bare integers taken as metres): room for deformations to dig below the lowest
    /// ground and pile above the highest (granular trails on a world's highest plateau would
    /// otherwise rise past what u16 stores). `fraction` in `0..=1`.
    Padded {
        /// Of the data's span, added below and above.
        fraction: f32,
    },
    /// `min_m ..= max_m`: bare integers map linearly onto it (0 to `min_m`, full scale to
    /// `max_m`); metres outside it are clamped to it.
    Span {
        /// Metres of the lowest stored value.
        min_m: f32,
        /// Metres of the highest stored value.
        max_m: f32,
    },
}

/// A DEM's heights as coarse-map samples.
#[derive(Debug, Clone, PartialEq)]
pub struct CoarseHeights {
    /// The u16 samples.
    pub grid: Grid<u16>,
    /// Their encoding: it spans the chosen range over the whole u16 range.
    pub encoding: HeightEncoding,
    /// The lowest height of the DEM in metres (as mapped, before any clamping).
    pub data_min_m: f32,
    /// The highest height of the DEM in metres (as mapped, before any clamping).
    pub data_max_m: f32,
    /// Samples clamped to the span (metres outside a [`HeightRange::Span`]).
    pub clamped: u64,
}

/// The format `options` choose for the file at `path`. The file is opened first (anything but
/// a regular file is [`MapIoError::NotRegularFile`], before any other check), then the format
/// is the one given, else the extension's, else the first bytes' (PNG or TIFF signature), else
/// RAW16 when a size is given ([`MapIoError::UnknownFormat`] otherwise). A headerless format
/// without a size is [`MapIoError::RawSizeRequired`]; a size for a format that stores its own
/// is [`MapIoError::RawSizeUnused`].
pub fn resolve_format(
    path: impl AsRef<Path>,
    options: &DemOptions,
) -> Result<DemFormat, MapIoError> {
    let path = path.as_ref();
    resolve_format_of(&open_regular(path)?, path, options)
}

/// [`resolve_format`] of a file already open (its first bytes are read through `file`; `path`
/// gives the extension and names the file in errors, and is never opened).
fn resolve_format_of(
    file: &File,
    path: &Path,
    options: &DemOptions,
) -> Result<DemFormat, MapIoError> {
    let format = match options.format.or_else(|| DemFormat::from_extension(path)) {
        Some(f) => f,
        None => {
            let io_err = |source| MapIoError::Io {
                path: path.to_path_buf(),
                source,
            };
            let mut head = [0u8; 8];
            let mut f = file;
            f.seek(SeekFrom::Start(0)).map_err(io_err)?;
            let n = f.take(8).read(&mut head).map_err(io_err)?;
            match &head[..n] {
                [0x89, b'P', b'N', b'G', ..] => DemFormat::Png,
                [b'I', b'I', 42 | 43, 0, ..] | [b'M', b'M', 0, 42 | 43, ..] => DemFormat::GeoTiff,
                _ if options.raw_size.is_some() => DemFormat::Raw16,
                _ => {
                    return Err(MapIoError::UnknownFormat {
                        path: path.to_path_buf(),
                    });
                }
            }
        }
    };
    match (format.is_headerless(), options.raw_size) {
        (true, None) => Err(MapIoError::RawSizeRequired {
            format: format.name(),
        }),
        (false, Some(_)) => Err(MapIoError::RawSizeUnused {
            format: format.name(),
        }),
        _ => Ok(format),
    }
}

/// A DEM file opened once: its format and size are measured through the open handle, and
/// [`DemFile::read`] decodes the samples from that same handle, so the file read is the file
/// measured even if the path is replaced in between (a caller plans memory from
/// [`DemFile::size`], then reads). The read is bounded by the measured size: a file rewritten
/// in place to a larger image is refused from its header ([`MapIoError::TooLarge`] or
/// [`MapIoError::TooManySamples`]) before any larger buffer exists, and one that decodes to
/// another size is [`MapIoError::Corrupt`].
#[derive(Debug)]
pub struct DemFile {
    file: File,
    path: PathBuf,
    options: DemOptions,
    format: DemFormat,
    size: UVec2,
}

impl DemFile {
    /// Opens the DEM file at `path` (a regular file only: see [`resolve_format`] for the
    /// checks and how the format is chosen) and reads its size from its header (or, for a
    /// headerless file, takes the size given, checked against the file's length), without
    /// reading its samples.
    pub fn open(path: impl AsRef<Path>, options: &DemOptions) -> Result<Self, MapIoError> {
        let path = path.as_ref();
        let file = open_regular(path)?;
        let format = resolve_format_of(&file, path, options)?;
        let limits = &options.limits;
        let size = match (format, options.raw_size) {
            (DemFormat::Png, _) => io::read_png_size_from_file(&file, path, limits)?,
            (DemFormat::GeoTiff, _) => geotiff::read_geotiff_size_from_file(&file, path, limits)?,
            (DemFormat::Raw16, Some(size)) => {
                io::check_raw_from_file(&file, path, size, 2, limits)?;
                size
            }
            (DemFormat::R32, Some(size)) => {
                io::check_raw_from_file(&file, path, size, 4, limits)?;
                size
            }
            (f, None) => return Err(MapIoError::RawSizeRequired { format: f.name() }),
        };
        Ok(Self {
            file,
            path: path.to_path_buf(),
            options: *options,
            format,
            size,
        })
    }

    /// The path it was opened from (for messages: it is never opened again).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its format.
    pub fn format(&self) -> DemFormat {
        self.format
    }

    /// Its size in samples, as measured when it was opened.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// Reads the DEM through the handle opened by [`DemFile::open`] (from its start, the path
    /// is not opened again): its heights with nodata filled, and what the file says about
    /// them. Each reader checks the file as [`crate::io`] and [`crate::geotiff`] describe,
    /// within the measured size.
    pub fn read(self) -> Result<Dem, MapIoError> {
        let Self {
            file,
            path,
            options,
            format,
            size,
        } = self;
        let path = path.as_path();
        let limits = ReadLimits {
            max_side: options.limits.max_side.min(size.max_element()),
            max_samples: options
                .limits
                .max_samples
                .min(u64::from(size.x) * u64::from(size.y)),
        };
        let limits = &limits;
        let stored = |grid: Grid<f32>, sample, full_scale| Dem {
            heights: grid,
            format,
            sample,
            units: HeightUnits::Stored { full_scale },
            nodata: None,
            holes: None,
            georeference: None,
        };
        let dem = match (format, options.raw_size) {
            (DemFormat::Png, _) => match io::read_png_from_file(&file, path, limits, None)? {
                io::GrayImage::Gray8(g) => stored(g.map(|&v| f32::from(v)), SampleType::U8, 255),
                io::GrayImage::Gray16(g) => {
                    stored(g.map(|&v| f32::from(v)), SampleType::U16, 65535)
                }
            },
            (DemFormat::Raw16, Some(size)) => {
                let g = io::read_raw16_from_file(&file, path, size, options.byte_order, limits)?;
                stored(g.map(|&v| f32::from(v)), SampleType::U16, 65535)
            }
            (DemFormat::R32, Some(size)) => {
                let mut heights =
                    io::read_r32_from_file(&file, path, size, options.byte_order, limits)?;
                let holes = nodata_holes(&heights);
                let nodata = fill_nodata(heights.as_mut_slice(), None)?;
                Dem {
                    heights,
                    format,
                    sample: SampleType::F32,
                    units: HeightUnits::Metres,
                    nodata,
                    holes,
                    georeference: None,
                }
            }
            (DemFormat::GeoTiff, _) => {
                Dem::from_geotiff(geotiff::read_geotiff_from_file(&file, path, limits)?)?
            }
            (f, None) => return Err(MapIoError::RawSizeRequired { format: f.name() }),
        };
        if dem.size() != size {
            return Err(MapIoError::Corrupt {
                reason: format!(
                    "{} changed while it was open: measured as {}x{}, decoded as {}x{}",
                    path.display(),
                    size.x,
                    size.y,
                    dem.size().x,
                    dem.size().y
                ),
            });
        }
        Ok(dem)
    }
}

/// The format and size of a DEM file from its header (or, for a headerless file, the size
/// given, checked against the file's length), without reading its samples: to plan memory
/// before reading it. See [`resolve_format`] for how the format is chosen. To read the file
/// measured, keep the [`DemFile`] this opens instead.
pub fn dem_size(
    path: impl AsRef<Path>,
    options: &DemOptions,
) -> Result<(DemFormat, UVec2), MapIoError> {
    let file = DemFile::open(path, options)?;
    Ok((file.format(), file.size()))
}

/// Reads a DEM file: its heights with nodata filled, and what the file says about them. See
/// [`resolve_format`] for how the format is chosen; each reader checks the file as
/// [`crate::io`] and [`crate::geotiff`] describe. The file is opened once ([`DemFile`]).
pub fn read_dem(path: impl AsRef<Path>, options: &DemOptions) -> Result<Dem, MapIoError> {
    DemFile::open(path, options)?.read()
}

impl Dem {
    /// A DEM from a decoded GeoTIFF (metres; nodata filled).
    pub fn from_geotiff(tiff: geotiff::GeoTiff) -> Result<Self, MapIoError> {
        let mut heights = tiff.heights;
        let holes = nodata_holes(&heights);
        let nodata = fill_nodata(heights.as_mut_slice(), tiff.nodata)?;
        Ok(Self {
            heights,
            format: DemFormat::GeoTiff,
            sample: tiff.sample,
            units: HeightUnits::Metres,
            nodata,
            holes,
            georeference: Some(tiff.geo),
        })
    }

    /// Size in samples.
    pub fn size(&self) -> UVec2 {
        self.heights.size()
    }

    /// The heights as u16 coarse-map samples spanning `range` (see [`HeightRange`]). A flat
    /// DEM under `Auto` spans its height plus and minus half a metre. A span that is not
    /// finite, or whose `max_m` is not above `min_m`, is [`CoreError::OutOfRange`].
    pub fn to_coarse_heights(&self, range: HeightRange) -> Result<CoarseHeights, CoreError> {
        if let HeightRange::Span { min_m, max_m } = range {
            for (what, v) in [
                ("height range minimum", min_m),
                ("height range maximum", max_m),
            ] {
                if !v.is_finite() {
                    return Err(CoreError::NonFinite { what, value: v });
                }
            }
            if max_m <= min_m {
                return Err(CoreError::OutOfRange {
                    what: "height range maximum (m)",
                    value: f64::from(max_m),
                    expected: "above the range's minimum",
                });
            }
        }
        let (lo, hi) = self
            .heights
            .as_slice()
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            });
        // Metres of a decoded value: integers under a span map onto it, all else is metres.
        let to_m: Box<dyn Fn(f32) -> f64> = match (self.units, range) {
            (HeightUnits::Stored { full_scale }, HeightRange::Span { min_m, max_m }) => {
                let (a, b) = (f64::from(min_m), f64::from(max_m));
                let full = f64::from(full_scale.max(1));
                Box::new(move |v| a + (b - a) * f64::from(v) / full)
            }
            _ => Box::new(f64::from),
        };
        let (data_min, data_max) = (to_m(lo), to_m(hi));
        let encoding = match range {
            HeightRange::Span { min_m, max_m } => HeightEncoding::spanning::<u16>(min_m, max_m)?,
            HeightRange::Auto if data_max > data_min => {
                HeightEncoding::spanning::<u16>(data_min as f32, data_max as f32)?
            }
            HeightRange::Auto => {
                HeightEncoding::spanning::<u16>(data_min as f32 - 0.5, data_min as f32 + 0.5)?
            }
            HeightRange::Padded { fraction } => {
                if !(fraction.is_finite() && (0.0..=1.0).contains(&fraction)) {
                    return Err(CoreError::OutOfRange {
                        what: "height range padding (fraction of the span)",
                        value: f64::from(fraction),
                        expected: "0 to 1",
                    });
                }
                let pad = ((data_max - data_min) * f64::from(fraction)).max(1.0);
                HeightEncoding::spanning::<u16>((data_min - pad) as f32, (data_max + pad) as f32)?
            }
        };
        let (span_lo, span_hi) = encoding.range::<u16>();
        let mut clamped = 0u64;
        let grid = match (self.units, range) {
            // Integers under a span: a linear map of the full scale onto the whole u16 range,
            // exact for 16-bit files (and 8-bit ones, times 257).
            (HeightUnits::Stored { full_scale }, HeightRange::Span { .. }) => {
                let k = u16::MAX_RAW / f64::from(full_scale.max(1));
                self.heights
                    .map(|&v| u16::from_raw_f64_clamped(f64::from(v) * k))
            }
            _ => self.heights.map(|&v| {
                let m = to_m(v);
                if m < f64::from(span_lo) || m > f64::from(span_hi) {
                    clamped += 1;
                }
                u16::from_raw_f64_clamped(encoding.to_raw(m as f32))
            }),
        };
        // Under `Auto` nothing lies outside the span but f32 rounding of its ends.
        if matches!(range, HeightRange::Auto | HeightRange::Padded { .. }) {
            clamped = 0;
        }
        Ok(CoarseHeights {
            grid,
            encoding,
            data_min_m: data_min as f32,
            data_max_m: data_max as f32,
            clamped,
        })
    }
}

/// Whether a height sample read from a file is nodata: NaN, infinite or huge.
pub fn is_nodata(h: f32) -> bool {
    !h.is_finite() || f64::from(h).abs() >= HUGE_FLOAT_NODATA
}

/// The hole mask of `heights`' nodata, or `None` when they have none.
fn nodata_holes(heights: &Grid<f32>) -> Option<Grid<u8>> {
    heights
        .as_slice()
        .iter()
        .any(|&h| is_nodata(h))
        .then(|| crate::holes::holes_from_nodata(heights))
}

/// Replaces NaN, infinite and huge samples (nodata) with the lowest valid height; says how
/// many there were. All nodata is [`MapIoError::NoValidHeights`].
fn fill_nodata(heights: &mut [f32], value: Option<f64>) -> Result<Option<NodataFill>, MapIoError> {
    let mut count = 0u64;
    let mut lowest = f32::INFINITY;
    for &h in heights.iter() {
        if is_nodata(h) {
            count += 1;
        } else {
            lowest = lowest.min(h);
        }
    }
    if count == 0 {
        return Ok(None);
    }
    if count == heights.len() as u64 {
        return Err(MapIoError::NoValidHeights {
            count,
            marker: match value {
                Some(v) => format!("the GDAL nodata value {v}, NaN or infinite"),
                None => "NaN, infinite or huge floats".to_owned(),
            },
        });
    }
    for h in heights.iter_mut() {
        if is_nodata(*h) {
            *h = lowest;
        }
    }
    Ok(Some(NodataFill {
        value,
        count,
        fill: lowest,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dem(heights: Vec<f32>, units: HeightUnits) -> Dem {
        let n = heights.len() as u32;
        Dem {
            heights: Grid::from_vec(n, 1, heights).unwrap(),
            format: DemFormat::GeoTiff,
            sample: SampleType::F32,
            units,
            nodata: None,
            holes: None,
            georeference: None,
        }
    }

    #[test]
    fn extensions_choose_formats() {
        let f = |p: &str| DemFormat::from_extension(Path::new(p));
        assert_eq!(f("a/dem.PNG"), Some(DemFormat::Png));
        assert_eq!(f("dem.r16"), Some(DemFormat::Raw16));
        assert_eq!(f("dem.raw"), Some(DemFormat::Raw16));
        assert_eq!(f("dem.r32"), Some(DemFormat::R32));
        assert_eq!(f("dem.tif"), Some(DemFormat::GeoTiff));
        assert_eq!(f("dem.TIFF"), Some(DemFormat::GeoTiff));
        assert_eq!(f("dem.asc"), None);
        assert_eq!(f("dem"), None);
    }

    #[test]
    fn nodata_is_filled_with_the_lowest_valid_height() {
        let mut h = vec![5.0, f32::NAN, 3.0, f32::INFINITY, -3.4e38, 7.0];
        let fill = fill_nodata(&mut h, Some(-9999.0)).unwrap().unwrap();
        assert_eq!(fill.count, 3);
        assert_eq!(fill.fill, 3.0);
        assert_eq!(h, [5.0, 3.0, 3.0, 3.0, 3.0, 7.0]);
        let mut clean = vec![1.0, 2.0];
        assert_eq!(fill_nodata(&mut clean, None).unwrap(), None);
        let mut none = vec![f32::NAN; 4];
        assert!(matches!(
            fill_nodata(&mut none, None),
            Err(MapIoError::NoValidHeights { count: 4, .. })
        ));
    }

    #[test]
    fn auto_spans_the_data_and_metres_keep_their_values() {
        let d = dem(vec![100.0, 500.0, 900.0], HeightUnits::Metres);
        let q = d.to_coarse_heights(HeightRange::Auto).unwrap();
        assert_eq!(q.grid.as_slice(), [0, 32768, 65535]);
        assert_eq!((q.data_min_m, q.data_max_m), (100.0, 900.0));
        let back = q.encoding.to_metres(32768.0);
        assert!((back - 500.0).abs() < 0.01, "{back}");
        // A flat DEM still gets a valid encoding.
        let flat = dem(vec![42.0; 3], HeightUnits::Metres);
        let q = flat.to_coarse_heights(HeightRange::Auto).unwrap();
        assert!((q.encoding.to_metres(f64::from(q.grid.as_slice()[0])) - 42.0).abs() < 1e-3);
    }

    /// Padded leaves room above the highest and below the lowest height: a sixteenth of the
    /// span, or 1 m where the span is small; a bad fraction is refused.
    #[test]
    fn padded_leaves_room_to_deform_beyond_the_data() {
        let d = dem(vec![100.0, 500.0, 900.0], HeightUnits::Metres);
        let q = d
            .to_coarse_heights(HeightRange::Padded {
                fraction: 1.0 / 16.0,
            })
            .unwrap();
        let (lo, hi) = q.encoding.range::<u16>();
        assert!(
            (lo - 50.0).abs() < 0.01 && (hi - 950.0).abs() < 0.01,
            "{lo}..{hi}"
        );
        let top = q.grid.as_slice()[2];
        assert!(top < 65535 - 3000, "{top}: room above the highest ground");
        let flat = dem(vec![42.0; 3], HeightUnits::Metres);
        let q = flat
            .to_coarse_heights(HeightRange::Padded { fraction: 0.1 })
            .unwrap();
        let (lo, hi) = q.encoding.range::<u16>();
        assert!(
            (lo - 41.0).abs() < 1e-3 && (hi - 43.0).abs() < 1e-3,
            "{lo}..{hi}"
        );
        for fraction in [f32::NAN, -0.1, 1.5] {
            assert!(
                d.to_coarse_heights(HeightRange::Padded { fraction })
                    .is_err()
            );
        }
    }

    #[test]
    fn a_span_maps_integers_linearly_and_clamps_metres() {
        let png = dem(
            vec![0.0, 255.0, 51.0],
            HeightUnits::Stored { full_scale: 255 },
        );
        let q = png
            .to_coarse_heights(HeightRange::Span {
                min_m: 10.0,
                max_m: 20.0,
            })
            .unwrap();
        assert_eq!(q.grid.as_slice(), [0, 65535, 51 * 257]);
        assert_eq!((q.data_min_m, q.data_max_m), (10.0, 20.0));
        // Integers under `Auto`: one unit per metre.
        let q = png.to_coarse_heights(HeightRange::Auto).unwrap();
        assert_eq!((q.data_min_m, q.data_max_m), (0.0, 255.0));

        let m = dem(vec![-5.0, 50.0, 150.0], HeightUnits::Metres);
        let q = m
            .to_coarse_heights(HeightRange::Span {
                min_m: 0.0,
                max_m: 100.0,
            })
            .unwrap();
        assert_eq!(q.clamped, 2);
        assert_eq!(q.grid.as_slice()[0], 0);
        assert_eq!(q.grid.as_slice()[2], 65535);
        for bad in [(1.0, 1.0), (2.0, 1.0), (f32::NAN, 1.0)] {
            assert!(
                m.to_coarse_heights(HeightRange::Span {
                    min_m: bad.0,
                    max_m: bad.1
                })
                .is_err(),
                "{bad:?}"
            );
        }
    }
}
