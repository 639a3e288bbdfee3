//! The default scenario's terrain (and the source a flyover world is built from): the
//! procedural coarse-map, or a DEM given with `--heightmap`, read by terrain-core's DEM import
//! (`--format`, `--raw-size`, `--byte-order`) and spanned by `--height-range` (or
//! `--max-height`), at `--texel-size` or the GeoTIFF's own pixel scale. What was chosen is
//! printed as one line and returned for report.json.

use crate::cli::{ByteOrderArg, Cli, FormatArg, HeightRangeArg, ScenarioKind};
use crate::report::{HeightEncodingReport, HeightmapReport, NodataReport};
use crate::usage_error::{UsageExt, usage};
use anyhow::{Context, Result, bail};
use glam::UVec2;
use std::path::Path;
use terrain_core::dem::{
    CoarseHeights, Dem, DemFile, DemFormat, DemOptions, HeightRange, HeightUnits, read_dem,
};
use terrain_core::geotiff::TexelSize;
use terrain_core::io::{ByteOrder, ReadLimits};
use terrain_core::{CoarseMap, HeightEncoding, TerrainParams, generate_coarse_map};

/// Side of the procedural terrain in texels by default (205 m at 0.1 m).
pub const DEFAULT_SIZE: u32 = 2048;
/// Metres per texel without `--texel-size` or a GeoTIFF pixel scale (Flower 2010's 0.1 m).
pub const DEFAULT_TEXEL_SIZE: f32 = 0.1;
/// Heights of the procedural terrain without `--height-range` (metres).
pub const PROCEDURAL_RANGE: (f32, f32) = (0.0, 12.0);
/// The largest side read (as `--size` allows): below it, `--max-memory` decides.
pub const MAX_SIDE: u32 = 65_536;
/// The smallest side a map may have (the clipmap and stamps need a few texels).
const MIN_SIDE: u32 = 16;

/// How `cli` asks for its heightmap to be read.
pub fn dem_options(cli: &Cli) -> DemOptions {
    DemOptions {
        format: match cli.format {
            FormatArg::Auto => None,
            FormatArg::Png => Some(DemFormat::Png),
            FormatArg::Raw16 => Some(DemFormat::Raw16),
            FormatArg::R32 => Some(DemFormat::R32),
            FormatArg::Geotiff => Some(DemFormat::GeoTiff),
        },
        raw_size: cli.raw_size,
        byte_order: match cli.byte_order {
            ByteOrderArg::Little => ByteOrder::Little,
            ByteOrderArg::Big => ByteOrder::Big,
        },
        limits: ReadLimits {
            max_side: MAX_SIDE,
            ..ReadLimits::default()
        },
    }
}

/// The map `cli` asks for, known before anything is made or read. A heightmap's is measured
/// through its open file, which is kept here and read as it was measured: the path is not
/// opened again, so a file swapped in since is not the one read.
#[derive(Debug)]
pub struct PlannedMap {
    /// Its size in texels.
    pub size: UVec2,
    /// The heightmap's format, when one is read.
    pub format: Option<DemFormat>,
    /// The heightmap, open, when one is read.
    dem: Option<DemFile>,
}

/// Plans are compared by what they measured (size and format), not by their open file.
impl PartialEq for PlannedMap {
    fn eq(&self, other: &Self) -> bool {
        (self.size, self.format) == (other.size, other.format)
    }
}

impl Eq for PlannedMap {}

/// The map `cli` asks for: `--size` (or the default), or the heightmap's size from its header
/// (or `--raw-size`, checked against the file's length), the heightmap kept open to be read.
/// Its errors are usage errors.
pub fn planned(cli: &Cli) -> Result<PlannedMap> {
    match &cli.heightmap {
        None => Ok(PlannedMap {
            size: UVec2::splat(cli.size.unwrap_or(DEFAULT_SIZE)),
            format: None,
            dem: None,
        }),
        Some(path) => {
            let dem = DemFile::open(path, &dem_options(cli))
                .with_context(|| format!("cannot use heightmap {}", path.display()))
                .usage()?;
            Ok(PlannedMap {
                size: dem.size(),
                format: Some(dem.format()),
                dem: Some(dem),
            })
        }
    }
}

/// The terrain a run starts from, and what report.json says of it.
#[derive(Debug)]
pub struct Terrain {
    /// The coarse-map.
    pub map: CoarseMap,
    /// Where it came from: `procedural` or the heightmap's path.
    pub source: String,
    /// Its heights, for report.json.
    pub heights: HeightsInfo,
    /// The heightmap's nodata as holes (`terrain_core::holes`), when it had any.
    pub holes: Option<terrain_core::Grid<u8>>,
}

/// What report.json says of a terrain's heights.
#[derive(Debug, Clone)]
pub struct HeightsInfo {
    /// The height encoding and the heights held.
    pub encoding: HeightEncodingReport,
    /// How the heightmap was read, when there was one.
    pub heightmap: Option<HeightmapReport>,
    /// Its nodata samples, when there were any.
    pub nodata: Option<NodataReport>,
}

impl HeightsInfo {
    /// The heights of a map of `encoding` whose stored values span `stored` (lowest,
    /// highest), the span chosen by `source`, no heightmap read.
    pub fn of_encoding(encoding: HeightEncoding, stored: (f64, f64), source: &'static str) -> Self {
        Self {
            encoding: encoding_report(
                encoding,
                encoding.to_metres(stored.0),
                encoding.to_metres(stored.1),
                source,
            ),
            heightmap: None,
            nodata: None,
        }
    }
}

/// The map `cli` asks for (every error is the user's to fix: a usage error), its heightmap read through the file `planned` opened and measured
/// (for the memory estimate that `--max-memory` accepted): a file swapped in at the path since
/// is not read, and one rewritten in place is refused beyond the measured size before any
/// larger buffer exists. Errors are usage errors.
pub fn load_planned(cli: &Cli, planned: Option<PlannedMap>) -> Result<Terrain> {
    make(cli, planned).usage()
}

/// The room a streamed world's encoding leaves above and below a heightmap's heights with
/// `--height-range auto`: a sixteenth of their span (at least 1 m) each way.
const WORLD_HEADROOM: f32 = 1.0 / 16.0;

/// The farthest from 0 a heightmap's heights may lie, in metres (the Earth's radius is
/// 6.4e6 m): beyond, the values are not metres (raw integers of a u32 file, say), and no
/// camera frames them.
const MAX_TERRAIN_M: f64 = 1e7;

/// The range `cli` asks for and the name report.json gives its source.
fn height_range(cli: &Cli) -> Result<(HeightRange, &'static str)> {
    Ok(match (cli.height_range, cli.max_height) {
        (Some(HeightRangeArg::Span(min_m, max_m)), _) => {
            (HeightRange::Span { min_m, max_m }, "height-range")
        }
        // `validate::flags` checked it is a positive number of metres.
        (_, Some(max)) => (
            HeightRange::Span {
                min_m: 0.0,
                max_m: max,
            },
            "max-height",
        ),
        // A streamed world is deformed where its ground is highest too (granular trails pile
        // material): its encoding leaves room above and below the data.
        (Some(HeightRangeArg::Auto) | None, None) => match cli.scenario {
            ScenarioKind::World | ScenarioKind::Flyover => (
                HeightRange::Padded {
                    fraction: WORLD_HEADROOM,
                },
                "data",
            ),
            ScenarioKind::Default | ScenarioKind::Snow => (HeightRange::Auto, "data"),
        },
    })
}

fn make(cli: &Cli, planned: Option<PlannedMap>) -> Result<Terrain> {
    let (range, range_source) = height_range(cli)?;
    match &cli.heightmap {
        None => procedural(cli, range),
        Some(path) => {
            // The heightmap the memory estimate measured is read through the file it opened
            // (bounded by the size it measured); without a plan, it is opened here.
            let dem = match planned.and_then(|p| p.dem) {
                Some(file) => file.read(),
                None => read_dem(path, &dem_options(cli)),
            }
            .with_context(|| format!("cannot use heightmap {}", path.display()))?;
            from_dem(cli, path, dem, range, range_source)
        }
    }
}

/// The procedural terrain of `--size`, spanning `--height-range` (0..12 m by default).
fn procedural(cli: &Cli, range: HeightRange) -> Result<Terrain> {
    let (lo, hi) = match range {
        HeightRange::Auto | HeightRange::Padded { .. } => PROCEDURAL_RANGE,
        HeightRange::Span { min_m, max_m } => (min_m, max_m),
    };
    let encoding = HeightEncoding::spanning::<u16>(lo, hi)?;
    let defaults = TerrainParams::default();
    // Octaves whose lattice cells are finer than ~16 texels only add noise that hides the
    // deformations, so stop there.
    let size = cli.size.unwrap_or(DEFAULT_SIZE);
    let cells = (size / 16 / defaults.base_period).max(1);
    let octaves = (u32::BITS - cells.leading_zeros()).clamp(1, defaults.octaves);
    let params = TerrainParams {
        size: UVec2::splat(size),
        seed: cli.seed,
        octaves,
        // Gentler small scales than the library default: a walkable landscape.
        persistence: 0.4,
        ..defaults
    };
    let texel = cli.texel_size.unwrap_or(DEFAULT_TEXEL_SIZE);
    let map = generate_coarse_map(&params, encoding, texel)?;
    let source = if matches!(range, HeightRange::Auto | HeightRange::Padded { .. }) {
        "procedural"
    } else {
        "height-range"
    };
    Ok(Terrain {
        heights: HeightsInfo::of_encoding(encoding, terrain_core::hillshade_range(&map), source),
        map,
        source: "procedural".into(),
        holes: None,
    })
}

fn encoding_report(
    e: HeightEncoding,
    data_min_m: f32,
    data_max_m: f32,
    source: &'static str,
) -> HeightEncodingReport {
    let (min_m, max_m) = e.range::<u16>();
    HeightEncodingReport {
        offset: e.offset,
        scale: e.scale,
        min_m,
        max_m,
        data_min_m,
        data_max_m,
        source,
    }
}

/// The map of a DEM read: quantised over `range`, at the texel size the flag or the file
/// gives; says what it chose on one line (and warns where the file's georeferencing is only
/// approximate).
fn from_dem(
    cli: &Cli,
    path: &Path,
    dem: Dem,
    range: HeightRange,
    range_source: &'static str,
) -> Result<Terrain> {
    let size = dem.size();
    if size.min_element() < MIN_SIDE {
        bail!(
            "heightmap {} is {}x{}: at least {MIN_SIDE}x{MIN_SIDE} needed",
            path.display(),
            size.x,
            size.y
        );
    }
    let (texel, texel_source) = texel_size(cli, path, &dem);
    // Heights no u16 encoding can span (beyond +-1e15 m, or a constant too large for f32 to
    // step) are the file's fault: a usage error that names it.
    let q: CoarseHeights = dem
        .to_coarse_heights(range)
        .with_context(|| format!("the heights of {}", path.display()))
        .usage()?;
    let far = f64::from(q.data_min_m.abs().max(q.data_max_m.abs()));
    if far > MAX_TERRAIN_M {
        return Err(usage(anyhow::anyhow!(
            "the heights of {} reach {far:.3e} m, beyond the +-{MAX_TERRAIN_M:.0e} m of any \
             terrain: give --height-range MIN:MAX to map the file's values onto metres",
            path.display()
        )));
    }
    let format = dem.format.name();
    let sample = dem.sample.name();
    let units = match (dem.units, range) {
        (HeightUnits::Metres, _) => "metres",
        (HeightUnits::Stored { .. }, HeightRange::Auto | HeightRange::Padded { .. }) => {
            "integers taken as metres"
        }
        (HeightUnits::Stored { .. }, HeightRange::Span { .. }) => "integers mapped onto the range",
    };
    let encoding = encoding_report(q.encoding, q.data_min_m, q.data_max_m, range_source);
    let mut line = format!(
        "heightmap {}: {format} {sample} {}x{} ({units}), heights {:.2}..{:.2} m; coarse-map \
         {:.2}..{:.2} m in steps of {:.4} m ({}); texel {texel} m ({texel_source})",
        path.display(),
        size.x,
        size.y,
        q.data_min_m,
        q.data_max_m,
        encoding.min_m,
        encoding.max_m,
        encoding.scale,
        match range_source {
            "data" if matches!(range, HeightRange::Padded { .. }) => {
                "--height-range auto: the data's range and a sixteenth of it above and below, \
                 room for the world's deformations"
            }
            "data" => "--height-range auto: the data's range",
            "max-height" => "--max-height",
            _ => "--height-range",
        },
    );
    let nodata = dem.nodata.map(|n| NodataReport {
        count: n.count,
        value: n.value,
        fill_m: n.fill,
    });
    if let Some(n) = &nodata {
        let value = n
            .value
            .map_or("NaN / infinite".to_owned(), |v| v.to_string());
        line.push_str(&format!(
            "; {} nodata samples ({value}) filled with {:.2} m, the lowest valid height, and \
             left out as holes",
            n.count, n.fill_m
        ));
    }
    if q.clamped > 0 {
        line.push_str(&format!("; {} samples clamped to the range", q.clamped));
    }
    if !cli.quiet {
        crate::console::note!("{line}");
    }
    let map = CoarseMap::coarse(q.grid, q.encoding, texel)?;
    Ok(Terrain {
        map,
        holes: dem.holes,
        source: path.display().to_string(),
        heights: HeightsInfo {
            encoding,
            heightmap: Some(HeightmapReport {
                format,
                sample,
                texel_size_source: texel_source,
                clamped_samples: q.clamped,
            }),
            nodata,
        },
    })
}

/// The texel size: `--texel-size`, else the GeoTIFF's pixel scale (degrees turned into metres
/// at the raster's latitude, with a warning), else the default. Returns it and where it came
/// from, as report.json names it.
fn texel_size(cli: &Cli, path: &Path, dem: &Dem) -> (f32, &'static str) {
    if let Some(t) = cli.texel_size {
        return (t, "--texel-size");
    }
    let name = path.display();
    match dem.georeference.and_then(|g| g.texel_size()) {
        Some(TexelSize::Metres { x_m, y_m }) => {
            if (x_m - y_m).abs() > 0.01 * x_m {
                crate::console::note!(
                    "warning: {name} has {x_m} x {y_m} m pixels; texels are square here, so \
                     it is drawn at {x_m} m (rows stretched {:.2} times)",
                    x_m / y_m
                );
            }
            (x_m as f32, "the GeoTIFF's pixel scale")
        }
        Some(TexelSize::Degrees {
            degrees,
            north_south_m,
            east_west_m,
            latitude,
            guessed,
        }) => {
            let why = if guessed {
                "its pixel scale is below 0.01 and it says no model type, so it is taken as"
            } else {
                "it is"
            };
            let at = latitude.map_or("at the equator (the file gives no latitude)".into(), |l| {
                format!("at latitude {l:.2}°")
            });
            crate::console::note!(
                "warning: {name}: {why} a geographic raster ({:.7}° per pixel), {north_south_m:.2} \
                 m north-south and {east_west_m:.2} m east-west {at}; drawn with square \
                 {north_south_m:.2} m texels (east-west stretched {:.2} times). Reproject it \
                 (gdalwarp -t_srs to a metric CRS) or give --texel-size",
                degrees[1],
                north_south_m / east_west_m.max(1e-9)
            );
            (
                north_south_m as f32,
                "the GeoTIFF's pixel scale in degrees (approximate)",
            )
        }
        Some(TexelSize::UnknownUnit { unit, per_pixel }) => {
            crate::console::note!(
                "warning: {name}: pixel scale {per_pixel} in linear unit {unit}, which this \
                 reader does not know: taken as metres (give --texel-size if it is not)"
            );
            (per_pixel as f32, "the GeoTIFF's pixel scale (unknown unit)")
        }
        None => (DEFAULT_TEXEL_SIZE, "the default: give --texel-size"),
    }
}

/// `--color`'s image, which must be `size` (the heightmap's, or the streamed world's).
pub fn color_layer(cli: &Cli, size: glam::UVec2) -> Result<Option<terrain_core::Grid<[u8; 4]>>> {
    let Some(path) = &cli.color else {
        return Ok(None);
    };
    let limits = terrain_core::io::ReadLimits {
        max_samples: u64::from(size.x) * u64::from(size.y),
        ..terrain_core::io::ReadLimits::default()
    };
    let colors = terrain_core::io::read_color_image(path, &limits)
        .with_context(|| format!("--color {}", path.display()))?;
    let found = glam::UVec2::new(colors.width(), colors.height());
    if found != size {
        anyhow::bail!(
            "--color {} is {}x{}; it must be the heightmap's size, {}x{}",
            path.display(),
            found.x,
            found.y,
            size.x,
            size.y
        );
    }
    Ok(Some(colors))
}
