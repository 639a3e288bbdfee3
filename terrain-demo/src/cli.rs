//! The command line of the demo.

use clap::{ArgAction, Parser, Subcommand};
use schemars::JsonSchema;
use serde::{Serialize, Serializer};
use std::path::PathBuf;

/// Renders offline frame captures of deformable terrain and a timing report.
///
/// Without a command it runs the capture, steered by the flags below. report.json lists every
/// flag of a run (`config.flags`), so a run can be repeated.
#[derive(Debug, Parser, Serialize, JsonSchema)]
#[command(version, about, args_conflicts_with_subcommands = true)]
#[schemars(
    deny_unknown_fields,
    description = "Every flag of the run, named as in --help with `_` for `-`; absent options \
                   are null."
)]
pub struct Cli {
    /// What to do instead of a run; none runs the capture.
    #[command(subcommand)]
    #[serde(skip)]
    #[schemars(skip)]
    pub command: Option<Command>,
    /// Folder the captures and report.json are written to.
    #[arg(long, default_value = "captures", help_heading = OUTPUT)]
    pub out: PathBuf,
    /// What happens: `default` (footprints, craters and a shockwave on the coarse-map) or
    /// `snow` (a vehicle and a walker crossing a snow field with granular deformation).
    #[arg(long, value_enum, default_value_t = ScenarioKind::Default, help_heading = SCENARIO)]
    pub scenario: ScenarioKind,
    /// Side of the procedural terrain in texels (any size, not only powers of two); default
    /// 2048 (205 m at 0.1 m), 512 for the snow field (25.6 m at 0.05 m), 16384 for the
    /// flyover's streamed world (8.2 km at 0.5 m).
    #[arg(long, help_heading = SCENARIO)]
    pub size: Option<u32>,
    /// Flyover: the folder of the streamed world (built there on first use, from the
    /// procedural default or --heightmap; deformations are written back into it).
    #[arg(long, default_value = "worlds/default", help_heading = WORLD)]
    pub world: PathBuf,
    /// Flyover: RAM pool budget in MiB.
    #[arg(long, default_value_t = 256, help_heading = WORLD)]
    pub ram_budget: u64,
    /// Flyover: VRAM pool budget in MiB (tile slots of the GPU atlas, 256 KiB each).
    #[arg(long, default_value_t = 64, help_heading = WORLD)]
    pub vram_budget: u64,
    /// Flyover: camera speed in metres per second (it flies, then drives).
    #[arg(long, default_value_t = 40.0, help_heading = WORLD)]
    pub speed: f32,
    /// Seed of the procedural terrain and of the scripted deformations.
    #[arg(long, default_value_t = 1, help_heading = SCENARIO)]
    pub seed: u64,
    /// Number of frames to capture.
    #[arg(long, default_value_t = 36, help_heading = OUTPUT)]
    pub frames: u32,
    /// Use this DEM / heightmap instead of the procedural terrain: PNG (8 or 16-bit),
    /// RAW16 (.r16, .raw; with --raw-size), R32 floats (.r32; with --raw-size) or GeoTIFF
    /// (.tif, .tiff), chosen by --format.
    #[arg(long, conflicts_with = "size", help_heading = HEIGHTMAP)]
    pub heightmap: Option<PathBuf>,
    /// A colour image drawn over the heightmap (an orthophoto): 8-bit RGB or RGBA, PNG or
    /// (Geo)TIFF, the heightmap's size. GPU frames show it; the overview does not. Flyover and
    /// world: written into the streamed world's colour tiles (the world's size), drawn near the
    /// camera.
    #[arg(long, value_name = "FILE", help_heading = HEIGHTMAP)]
    pub color: Option<PathBuf>,
    /// The heightmap's format: `auto` by its extension (else its first bytes, else RAW16 when
    /// --raw-size is given).
    #[arg(long, value_enum, default_value_t = FormatArg::Auto, help_heading = HEIGHTMAP)]
    pub format: FormatArg,
    /// Size of a RAW16 or R32 heightmap, as WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_size, requires = "heightmap", help_heading = HEIGHTMAP)]
    #[schemars(with = "Option<[u32; 2]>")]
    pub raw_size: Option<glam::UVec2>,
    /// Byte order of a RAW16 or R32 heightmap's samples.
    #[arg(long, value_enum, default_value_t = ByteOrderArg::Little, help_heading = HEIGHTMAP)]
    pub byte_order: ByteOrderArg,
    /// Metres per texel: default the GeoTIFF's pixel scale, else 0.1 m.
    #[arg(long, help_heading = HEIGHTMAP)]
    pub texel_size: Option<f32>,
    /// Heights in metres the coarse-map spans: `auto` (default) is the heightmap's own range
    /// (GeoTIFF and R32 metres kept, PNG / RAW16 integers taken as metres), 0:12 for the
    /// procedural terrain; `MIN:MAX` maps integer heightmaps linearly onto MIN..MAX (0 to MIN,
    /// full scale to MAX) and clamps metres to it.
    #[arg(
        long,
        value_parser = parse_height_range,
        conflicts_with = "max_height",
        allow_hyphen_values = true,
        help_heading = HEIGHTMAP
    )]
    pub height_range: Option<HeightRangeArg>,
    /// Same as --height-range 0:M.
    #[arg(long, value_name = "M", help_heading = HEIGHTMAP)]
    pub max_height: Option<f32>,
    /// The default scenario's camera: `walker` (follows the walker at eye height),
    /// `orbit` (circles the map's centre, framing the whole map) or `flyover` (loops over the
    /// map at a height proportional to its extent). Default: orbit with --heightmap, else
    /// walker.
    #[arg(long, value_enum, help_heading = SCENARIO)]
    pub camera: Option<CameraMode>,
    /// Size of the 3D frames, as WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_size, help_heading = OUTPUT)]
    #[schemars(with = "[u32; 2]")]
    pub resolution: glam::UVec2,
    /// Side of the hillshade overview: inset in the 3D frames, or the whole frame when no GPU
    /// adapter exists (the map is shown nearest-texel).
    #[arg(long, default_value_t = 256, help_heading = OUTPUT)]
    pub overview_size: u32,
    /// Write top-down overview frames only, without the GPU (as when no adapter exists).
    #[arg(long, help_heading = RENDERING)]
    pub no_gpu: bool,
    /// Level of detail of the 3D frames of the default and world scenarios: geometry
    /// clipmaps, CDLOD (quadtree selection with per-vertex morphing), or adaptive tessellation
    /// (edges split by their projected size and, in the default scenario, the density map, as
    /// a compute pass; the streamed world's splits are decided from its quadtree's bounds).
    #[arg(long, value_enum, default_value_t = LodArg::Clipmap, help_heading = RENDERING)]
    pub lod: LodArg,
    /// The default scenario's detail layer: `none` stamps footprints into the coarse-map;
    /// `parallax` stamps them into 8-bit detail tiles refined x3 (streamed around the camera) and
    /// shades the terrain through them under every `--lod` mode: parallax occlusion mapping, the
    /// composite of the coarse and detail normals, faded out with distance; `refine` draws the same
    /// tiles as geometry within 9 m of the camera (each coarse triangle split in up to nine by
    /// refinement patterns; the LOD mode leaves it the texels there) and by their normals beyond.
    /// The world scenario: a walker's footprints in the streamed world's detail tiles (refined x8,
    /// kept in the world's folder), drawn the same two ways.
    #[arg(long, value_enum, default_value_t = DetailArg::None, help_heading = RENDERING)]
    pub detail: DetailArg,
    /// With `--lod cdlod`: choose the LODs by screen-space error, at most PX pixels, instead
    /// of by distance ranges.
    #[arg(long, value_name = "PX", help_heading = RENDERING)]
    pub target_error: Option<f32>,
    /// With `--lod cdlod` or `tessellated`: no per-vertex morph (LOD changes pop; for
    /// comparison).
    #[arg(long, help_heading = RENDERING)]
    pub no_morph: bool,
    /// With `--lod tessellated`: tessellate by projected size alone, without scaling each
    /// edge's split by the curvature density map.
    #[arg(long, help_heading = RENDERING)]
    pub no_density_map: bool,
    /// With `--lod tessellated`: the target projected edge length in pixels (the "triangle
    /// width"; default 8).
    #[arg(long, value_name = "PX", help_heading = RENDERING)]
    pub triangle_width: Option<f32>,
    /// Refuse a run whose estimated memory (maps, GPU copies, frames, pools, the process and
    /// its GPU driver) is above SIZE, as 1536M or 8G; default half the machine's memory.
    #[arg(
        long,
        value_name = "SIZE",
        value_parser = crate::memory_limit::parse_bytes,
        help_heading = LIMITS
    )]
    pub max_memory: Option<u64>,
    /// Leading frames left out of report.json's per-step statistics (`steps_ms`) and shaded
    /// in summary.png's chart: shader compilation and first uploads. At most all frames but
    /// the last.
    #[arg(long, default_value_t = 3, help_heading = OUTPUT)]
    pub warmup: u32,
    /// The scenario's parameters (stamps, granular material, collision readback scheduler,
    /// terrain style, cameras) from a TOML file; every key is optional (see the print-config
    /// command).
    #[arg(long, value_name = "FILE.toml", help_heading = SCENARIO)]
    pub config: Option<PathBuf>,
    /// Nothing on stderr but warnings and errors: no progress, no line of what was read or
    /// built, no closing summary.
    #[arg(short, long, conflicts_with = "verbose", help_heading = LOGGING)]
    pub quiet: bool,
    /// Log what the libraries do on stderr: -v info (adapter, cache, readbacks), -vv debug,
    /// -vvv trace. RUST_LOG (as `terrain_cache=debug`) overrides it.
    #[arg(short, long, action = ArgAction::Count, help_heading = LOGGING)]
    pub verbose: u8,
}

/// `--help` headings of the run flags.
const OUTPUT: &str = "Output";
const SCENARIO: &str = "Scenario";
const WORLD: &str = "Streamed world";
const HEIGHTMAP: &str = "Input heightmap";
const RENDERING: &str = "Rendering / level of detail";
const LIMITS: &str = "Limits";
const LOGGING: &str = "Logging";

/// The commands besides a run.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Check a streamed world against its manifest (and repair it), then exit.
    ///
    /// Checks everything the manifest of the world in DIR promises: every tile present (a missing file is only valid where the tile is all the fill value) and
    /// decoding as itself, every coarser level equal to the 2x2 reduction of the one below,
    /// every level's bounds.bin equal to what the tiles give. Exit 0 when all is valid, 1
    /// with a list of the defects on stdout (key, what, whether repairable), 2 when DIR is not
    /// a world or its manifest promises more tiles (16 M) than a check walks, 130 on Ctrl-C.
    VerifyWorld {
        /// The world's folder (as given to --world).
        #[arg(value_name = "DIR")]
        dir: PathBuf,
        /// Rewrite what level 0 determines (coarser tiles, bounds.bin) where it is wrong, then
        /// check again; exit 0 when the world is valid afterwards, 1 when defects remain
        /// (level-0 tiles lost or damaged cannot be rebuilt).
        #[arg(long)]
        repair: bool,
        /// No progress line on stderr.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Print the scenarios' parameters as TOML and exit.
    ///
    /// The defaults, or those of --config FILE.toml with the defaults for every key it leaves
    /// out: write them to a file, edit it, and run with --config.
    PrintConfig {
        /// Print the parameters of this TOML file (checked, with the defaults for every key
        /// it leaves out).
        #[arg(long, value_name = "FILE.toml")]
        config: Option<PathBuf>,
    },
}

/// Flags that became commands or changed, with the tip that names what replaced them.
const REPLACED: &[(&str, &str)] = &[
    (
        "--verify-world",
        "`terrain-demo verify-world DIR` checks a world (a command now, not a flag)",
    ),
    (
        "--repair",
        "`terrain-demo verify-world DIR --repair` repairs a world",
    ),
    (
        "--print-config",
        "`terrain-demo print-config [--config FILE.toml]` prints the parameters (a command now, \
         not a flag)",
    ),
    (
        "--density-map",
        "`--no-density-map` tessellates without the density map (on by default)",
    ),
];

/// `e` with a tip naming the replacement when it refuses a flag that was replaced (clap's own
/// suggestion of a similar flag, as `--version` for `--verify-world`, would mislead), and the
/// usage of `cmd` in place of the suggested flag's.
pub fn explain_replaced_flags(mut e: clap::Error, cmd: &mut clap::Command) -> clap::Error {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    if e.kind() != ErrorKind::UnknownArgument {
        return e;
    }
    let Some(ContextValue::String(arg)) = e.get(ContextKind::InvalidArg) else {
        return e;
    };
    let name = arg.split('=').next().unwrap_or(arg);
    let Some((_, tip)) = REPLACED.iter().find(|(old, _)| *old == name) else {
        return e;
    };
    e.remove(ContextKind::SuggestedArg);
    e.insert(
        ContextKind::Suggested,
        ContextValue::StyledStrs(vec![(*tip).into()]),
    );
    e.insert(
        ContextKind::Usage,
        ContextValue::StyledStr(cmd.render_usage()),
    );
    e
}

/// The scenarios the demo can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ScenarioKind {
    /// Footprints, Gaussian craters and a shockwave across the wrap corner.
    Default,
    /// A four-wheeled vehicle and a walker crossing a snow field.
    Snow,
    /// A camera flying, then driving, over a streamed world larger than the cache budgets,
    /// stamping craters on its path (they persist in the world's folder).
    Flyover,
    /// The streamed world of the flyover with everything on it: a vehicle driving and leaving
    /// volume-preserving granular trails, craters beside its path (all persisted in
    /// `--world`), collision following the camera.
    World,
}

/// `--format`: how the heightmap file is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum FormatArg {
    /// By the file's extension (.png, .r16 / .raw, .r32, .tif / .tiff).
    Auto,
    /// Grayscale PNG, 8 or 16 bits.
    Png,
    /// Headerless u16 samples.
    Raw16,
    /// Headerless f32 heights in metres.
    R32,
    /// GeoTIFF.
    Geotiff,
}

/// `--byte-order` of RAW16 and R32 heightmaps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ByteOrderArg {
    /// Least significant byte first.
    Little,
    /// Most significant byte first.
    Big,
}

/// `--height-range`: the heightmap's own range, or metres given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HeightRangeArg {
    /// The heightmap's lowest to highest height.
    Auto,
    /// Metres of the lowest and the highest stored height.
    Span(f32, f32),
}

impl Serialize for HeightRangeArg {
    /// As the flag is written: `auto` or `MIN:MAX`.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            HeightRangeArg::Auto => s.serialize_str("auto"),
            HeightRangeArg::Span(lo, hi) => s.serialize_str(&format!("{lo}:{hi}")),
        }
    }
}

/// `--lod`: the level-of-detail scheme.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum LodArg {
    /// Geometry clipmaps.
    Clipmap,
    /// CDLOD quadtree with per-vertex morphing.
    Cdlod,
    /// Adaptive tessellation by longest-edge bisection in a compute pass.
    Tessellated,
}

/// `--detail`: where footprints go and how the finest geometry is shaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum DetailArg {
    /// Coarse-map only.
    None,
    /// Detail tiles, drawn by parallax occlusion mapping on the unrefined mesh (any LOD mode).
    Parallax,
    /// Detail tiles, drawn as refined geometry near the camera (refinement patterns, a compute
    /// pass drawn indirectly) and by their normals beyond, in place of the LOD mode's finest
    /// cells (any LOD mode).
    Refine,
}

/// `--camera` of the default scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CameraMode {
    /// Walks behind the walker at eye height.
    Walker,
    /// Circles the map's centre at a distance and height that frame the whole map.
    Orbit,
    /// Loops over the map at a height above ground proportional to its extent.
    Flyover,
}

impl CameraMode {
    /// The mode's name, as the flag and report.json spell it.
    pub fn name(self) -> &'static str {
        match self {
            CameraMode::Walker => "walker",
            CameraMode::Orbit => "orbit",
            CameraMode::Flyover => "flyover",
        }
    }
}

impl JsonSchema for HeightRangeArg {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "HeightRangeArg".into()
    }

    /// As it is serialised: `auto` or `MIN:MAX`.
    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "`auto` or `MIN:MAX` (metres).",
            "type": "string",
            "pattern": "^(auto|-?[0-9.e+-]+:-?[0-9.e+-]+)$",
        })
    }
}

/// Parses `auto` or `MIN:MAX` (metres, finite, MIN below MAX).
fn parse_height_range(s: &str) -> Result<HeightRangeArg, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(HeightRangeArg::Auto);
    }
    let (lo, hi) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}` is neither `auto` nor MIN:MAX (metres, as -20:850)"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<f32>()
            .ok()
            .filter(|m| m.is_finite())
            .ok_or_else(|| format!("`{v}` in `{s}` is not a finite number of metres"))
    };
    let (lo, hi) = (parse(lo)?, parse(hi)?);
    if hi <= lo {
        return Err(format!("`{s}`: MAX must be above MIN"));
    }
    Ok(HeightRangeArg::Span(lo, hi))
}

/// Parses `WIDTHxHEIGHT`.
fn parse_size(s: &str) -> Result<glam::UVec2, String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|e| format!("`{v}` in `{s}`: {e}"))
    };
    Ok(glam::UVec2::new(parse(w)?, parse(h)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sizes() {
        assert_eq!(parse_size("640x480"), Ok(glam::UVec2::new(640, 480)));
        assert!(parse_size("640").is_err());
        assert!(parse_size("ax3").is_err());
    }

    #[test]
    fn rejects_bad_flags() {
        assert!(Cli::try_parse_from(["demo", "--raw-size", "4x4"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--size", "100", "--heightmap", "a.png"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--size", "100", "--seed", "3"]).is_ok());
        assert!(Cli::try_parse_from(["demo", "--resolution", "640x360"]).is_ok());
        assert!(Cli::try_parse_from(["demo", "--scenario", "snow"]).is_ok());
        assert!(Cli::try_parse_from(["demo", "--scenario", "mud"]).is_err());
        let cli = Cli::try_parse_from(["demo", "--max-memory", "1536M"]).unwrap();
        assert_eq!(cli.max_memory, Some(1536 << 20));
        assert!(Cli::try_parse_from(["demo", "--max-memory", "lots"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--max-memory", "0"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--camera", "orbit"]).is_ok());
        assert!(Cli::try_parse_from(["demo", "--camera", "drone"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--format", "geotiff"]).is_ok());
        assert!(Cli::try_parse_from(["demo", "--format", "jpeg"]).is_err());
        assert!(
            Cli::try_parse_from(["demo", "--height-range", "0:10", "--max-height", "5"]).is_err()
        );
        // A negative minimum is a value, not a flag.
        let cli = Cli::try_parse_from(["demo", "--height-range", "-10:245"]).unwrap();
        assert_eq!(cli.height_range, Some(HeightRangeArg::Span(-10.0, 245.0)));
    }

    #[test]
    fn parses_height_ranges() {
        assert_eq!(parse_height_range("auto"), Ok(HeightRangeArg::Auto));
        assert_eq!(
            parse_height_range("-20.5:850"),
            Ok(HeightRangeArg::Span(-20.5, 850.0))
        );
        for bad in ["", "5", "10:10", "10:5", "a:3", "0:inf", "NaN:4"] {
            assert!(parse_height_range(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn verify_world_and_print_config_are_commands() {
        let cli = Cli::try_parse_from(["demo", "verify-world", "w"]).unwrap();
        let Some(Command::VerifyWorld { dir, repair, quiet }) = cli.command else {
            panic!("{:?}", cli.command)
        };
        assert_eq!((dir, repair, quiet), (PathBuf::from("w"), false, false));
        let cli = Cli::try_parse_from(["demo", "verify-world", "w", "--repair", "-q"]).unwrap();
        assert!(matches!(
            cli.command,
            Some(Command::VerifyWorld {
                repair: true,
                quiet: true,
                ..
            })
        ));
        let cli = Cli::try_parse_from(["demo", "print-config"]).unwrap();
        assert!(matches!(
            cli.command,
            Some(Command::PrintConfig { config: None })
        ));
        let cli = Cli::try_parse_from(["demo", "print-config", "--config", "s.toml"]).unwrap();
        let Some(Command::PrintConfig { config }) = cli.command else {
            panic!("{:?}", cli.command)
        };
        assert_eq!(config, Some(PathBuf::from("s.toml")));
        // No command: a run.
        assert!(Cli::try_parse_from(["demo"]).unwrap().command.is_none());
        // verify-world needs its folder; the old flags are gone.
        assert!(Cli::try_parse_from(["demo", "verify-world"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--verify-world", "w"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--repair"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--print-config"]).is_err());
        assert!(Cli::try_parse_from(["demo", "print-config", "--repair"]).is_err());
    }

    #[test]
    fn run_flags_with_a_command_are_refused() {
        for args in [
            &["demo", "--frames", "3", "verify-world", "w"][..],
            &["demo", "--no-gpu", "print-config"],
            &["demo", "--config", "s.toml", "print-config"],
            &["demo", "-q", "verify-world", "w"],
            &["demo", "verify-world", "w", "--frames", "3"],
            &["demo", "print-config", "--size", "64"],
        ] {
            let e = Cli::try_parse_from(args).expect_err(&format!("{args:?} is refused"));
            assert_eq!(e.exit_code(), 2, "{args:?}: {e}");
            assert!(
                matches!(
                    e.kind(),
                    clap::error::ErrorKind::ArgumentConflict
                        | clap::error::ErrorKind::UnknownArgument
                ),
                "{args:?}: {:?} {e}",
                e.kind()
            );
        }
    }

    #[test]
    fn a_replaced_flag_gets_a_tip_naming_its_replacement() {
        use clap::CommandFactory;
        for (args, says) in [
            (&["demo", "--verify-world", "w"][..], "verify-world DIR`"),
            (&["demo", "--repair"], "verify-world DIR --repair`"),
            (&["demo", "--print-config"], "`terrain-demo print-config"),
            (&["demo", "--density-map=off"], "`--no-density-map`"),
        ] {
            let mut cmd = Cli::command();
            let e = cmd.try_get_matches_from_mut(args).expect_err("refused");
            let text = explain_replaced_flags(e, &mut cmd).to_string();
            assert!(
                text.contains(&format!("tip: {says}")) || text.contains(says),
                "{text}"
            );
            assert!(!text.contains("similar argument"), "{text}");
            assert!(text.contains("Usage: demo [OPTIONS]"), "{text}");
            assert!(text.contains("For more information"), "{text}");
        }
        // Other mistakes keep clap's own suggestion.
        let mut cmd = Cli::command();
        let e = cmd
            .try_get_matches_from_mut(["demo", "--frame", "3"])
            .expect_err("refused");
        let text = explain_replaced_flags(e, &mut cmd).to_string();
        assert!(
            text.contains("tip: a similar argument exists: '--frames'"),
            "{text}"
        );
    }

    #[test]
    fn no_density_map_is_a_switch() {
        let cli = Cli::try_parse_from(["demo", "--lod", "tessellated", "--no-density-map"]);
        assert!(cli.unwrap().no_density_map);
        assert!(!Cli::try_parse_from(["demo"]).unwrap().no_density_map);
        assert!(Cli::try_parse_from(["demo", "--no-density-map", "off"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--density-map", "off"]).is_err());
    }

    #[test]
    fn help_groups_the_run_flags_under_headings_without_citations() {
        use clap::CommandFactory;
        let mut cmd = Cli::command();
        let short = cmd.render_help().to_string();
        let long = cmd.render_long_help().to_string();
        for help in [&short, &long] {
            for heading in [
                OUTPUT, SCENARIO, WORLD, HEIGHTMAP, RENDERING, LIMITS, LOGGING,
            ] {
                assert!(
                    help.contains(&format!("\n{heading}:\n")),
                    "{heading}: {help}"
                );
            }
            for command in ["verify-world", "print-config"] {
                assert!(help.contains(command), "{command}: {help}");
            }
            for citation in ["2010", "2012", "2013", "2019", "sec. ", "eq. "] {
                assert!(!help.contains(citation), "{citation}: {help}");
            }
        }
        // Every run flag has a heading: nothing but --help and --version under "Options".
        for arg in cmd.get_arguments() {
            let id = arg.get_id().as_str();
            assert!(
                arg.get_help_heading().is_some() || matches!(id, "help" | "version"),
                "{id} has no heading"
            );
        }
        for sub in cmd.get_subcommands_mut() {
            let help = sub.render_long_help().to_string();
            for citation in ["2010", "2012", "2013", "2019"] {
                assert!(!help.contains(citation), "{citation}: {help}");
            }
        }
    }
}
