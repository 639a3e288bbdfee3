//! What a run will need in memory, from its flags and the headers of its input (a heightmap's
//! size and format, a world's manifest) before anything large is allocated: the maps, the
//! import of a heightmap, their derivatives, the
//! collision mirror, the GPU copies and their upload staging, the frames, the contact sheet,
//! the flyover's pools and tile atlas, and the process and GPU driver themselves.
//!
//! Each part is an upper bound of what the code allocates for it (the constants below say
//! what they count), and the parts are added as if all were alive at once, so the total bounds
//! the peak resident memory of the process. `tests/memory_limit.rs` runs the demo and checks
//! the peak it measures (VmHWM) against this total; the README lists measured pairs.

use crate::capture;
use crate::cli::{Cli, ScenarioKind};
use crate::scenarios::{
    fit_overview, flyover,
    heightmap::{self, PlannedMap},
    snow,
    world_files::{self, WorldBuild},
};
use anyhow::Result;
use glam::UVec2;
use terrain_core::dem::DemFormat;

/// The process without its maps: code, the standard library, rayon's and the cache's threads
/// (a 64 x 64 run without a GPU peaks at 14 MiB).
const PROCESS: u64 = 32 << 20;
/// The GPU driver, device, pipelines and compiled shaders, beyond the buffers counted below:
/// 156 MiB (default scenario) and 196 MiB (snow: more pipelines) on lavapipe, whose "device
/// memory" is the process's own; with room for drivers that keep more.
const GPU_DRIVER: u64 = 320 << 20;

/// Bytes per texel of a CPU map: the u16 heights kept, and 4 more while they are made (the f32
/// heights of the procedural terrain, or a file's bytes beside the decoded samples).
const MAP_PER_TEXEL: u64 = 2 + 4;
/// Bytes per texel of importing a heightmap beyond [`MAP_PER_TEXEL`] (which counts the kept u16
/// samples and the f32 heights they are made from): the file's samples as decoded beside
/// those f32 heights, at most 8 bytes (f64 GeoTIFFs; PNG and RAW16 decode to 2 bytes kept as
/// u16 and as bytes, 4 in all).
const DEM_IMPORT_PER_TEXEL: u64 = 8;
/// Bytes per texel of the derivative (normal) map: a `Vec2<f32>`.
const NORMALS_PER_TEXEL: u64 = 8;
/// Bytes per texel of the collision mirror: front and back u16 buffers, a third copy while a
/// reader still holds the back one, and regions (u16) on their way in.
const COLLISION_PER_TEXEL: u64 = 3 * 2 + 2;
/// Bytes per texel of writing `terrain.png` / `terrain_final.png`: the samples as bytes, the
/// compressed file (at worst a little more than the samples) and the encoder's state.
const TERRAIN_PNG_PER_TEXEL: u64 = 5;
/// Bytes per texel of `--lod tessellated`: the hierarchy's height, radius, density and error
/// per grid vertex on the CPU (16) and on the GPU (16, and 16 more of wgpu's staging while it
/// is uploaded), and the density map (a f32 and about 1.33 u8 per 16 texels, rounded up).
const TESS_PER_TEXEL: u64 = 16 + 16 + 16 + 1;
/// Bytes of `--lod tessellated` beyond its per-texel part, for 2^21 triangles (the output's
/// capacity): the GPU's output (36 bytes each) and its breadth-first level queues (48), the
/// CPU reference's per-row triangles and the frame they are joined into (36 + 36), and the
/// vertex count's keys (24).
const TESS_FIXED: u64 = (36 + 48 + 36 + 36 + 24) << 21;
/// Bytes per texel of a coarse-map on the GPU: 16-bit heights and 16-bit slope codes (each
/// packed two per u32 word), and the upload (a packed copy and wgpu's staging buffer).
const GPU_MAP_PER_TEXEL: u64 = 2 + 2 + 2 + 2;
/// Bytes per texel of the default scenario's collision readback on the GPU: a ring of 4
/// staging buffers that grow to the largest merged dirty region (at most the map, 2 bytes per
/// texel), the arrived region unpacked to u32 and converted to u16.
const GPU_READBACK_PER_TEXEL: u64 = 4 * 2 + 4 + 2;
/// Bytes per texel of the snow field on the CPU: f32 ground while it is made, the u32 heights
/// of the simulation and their initial copy.
const SNOW_FIELD_PER_TEXEL: u64 = 4 + 4 + 4;
/// Bytes per texel of the snow field on the GPU: u32 heights, its upload staging, and the
/// normals-and-heights buffer with its blur scratch (16 bytes each).
const SNOW_GPU_PER_TEXEL: u64 = 4 + 4 + 16 + 16;
/// The most columns the granular working set covers: active areas follow the objects (a
/// vehicle and a walker, a few metres at 5 cm per texel), not the map.
const GRANULAR_AREA_COLUMNS: u64 = 512 * 512;
/// Bytes per column of an active area: the CPU step's buffers and, with a GPU, its scratch
/// (depth, penetration, seeds, accumulators, distances) and the readback ring of 8 regions.
const GRANULAR_PER_COLUMN: u64 = 64 + 96 + 32;
/// Bytes per pixel of a 3D frame: colour and depth targets, the capture's staging buffer and
/// its mapped copy, the image, and its PNG (a little more than the pixels at worst).
const GPU_FRAME_PER_PIXEL: u64 = 4 * 5 + 8;
/// Bytes per pixel of an overview frame (no GPU): the overlay's copy and the PNG.
const OVERVIEW_FRAME_PER_PIXEL: u64 = 4 + 8;
/// Bytes per pixel of the overview: the image, and the flyover's copy with tiles drawn on it.
const OVERVIEW_PER_PIXEL: u64 = 8;
/// Bytes per frame of the report: the frame's record in memory and its JSON (about 1 KiB).
const REPORT_PER_FRAME: u64 = 4 << 10;
/// The RAM pool beyond its budget: loader threads decoding (a file and its samples each) and
/// the writer encoding tiles back.
const RAM_POOL_SLACK: u64 = 16 << 20;
/// The VRAM pool beyond its atlas: uploads staged for a few frames (2 MiB a frame) and the
/// ring of 16 tile readbacks.
const VRAM_POOL_SLACK: u64 = 16 << 20;
/// Bytes per sample of the shockwave (`[stamps.shockwave] resolution` squared): its three
/// f32 grids (previous, current, applied), a step's next grid and the change taken each
/// frame, and with a GPU its f32 texture and upload staging.
const SHOCKWAVE_PER_SAMPLE: u64 = 5 * 4 + 2 * 4;
/// Building a world: tiles in flight on each building thread and their pyramid levels.
const WORLD_BUILD: u64 = 64 << 20;

/// What a run is made of, as far as memory goes.
#[derive(Debug, PartialEq, Eq)]
pub struct RunShape {
    /// The scenario.
    pub scenario: ScenarioKind,
    /// The LOD scheme of its 3D frames.
    pub lod: crate::cli::LodArg,
    /// Whether the default scenario has a detail layer (`--detail parallax` or `refine`).
    pub detail: bool,
    /// Whether it renders on the GPU (the estimate assumes it does unless `--no-gpu`: without
    /// an adapter the run falls back to less).
    pub gpu: bool,
    /// Texels of the scenario's CPU map (the flyover's: its overview level).
    pub map: UVec2,
    /// The heightmap the default scenario imports (`None` for the procedural terrain; a
    /// flyover's is in its `build`).
    pub heightmap: Option<PlannedMap>,
    /// `--color`: a colour layer of the map's size.
    pub color: bool,
    /// Frame size with a GPU.
    pub resolution: UVec2,
    /// Size of the overview (the frame without a GPU).
    pub overview: UVec2,
    /// Frames asked for.
    pub frames: u32,
    /// The flyover's world, budgets and atlas.
    pub flyover: Option<FlyoverShape>,
    /// Samples per side of the shockwave's texture, where the scenario has one
    /// ([`RunShape::with_params`]; 0 until then).
    pub shockwave: u32,
}

/// The memory side of a flyover.
#[derive(Debug, PartialEq, Eq)]
pub struct FlyoverShape {
    /// RAM pool budgets in bytes: the heights' and the paint and colour streams'.
    pub ram_budget: u64,
    /// Bytes of the atlases' tile slots (heights, paint and colour: as many whole tiles as the
    /// VRAM budget holds).
    pub atlas: u64,
    /// Bytes of the atlases' indirection tables.
    pub atlas_table: u64,
    /// Whether the world is built first, and from what.
    pub build: Option<WorldBuild>,
    /// Level-0 size of the world in texels.
    pub world: UVec2,
}

impl RunShape {
    /// The shape of the run `cli` asks for. Reads only headers (a PNG's, a manifest); its
    /// errors (an unreadable heightmap or world) are usage errors.
    pub fn of(cli: &Cli) -> Result<Self> {
        let gpu = !cli.no_gpu;
        let mut heightmap = None;
        let (map, flyover) = match cli.scenario {
            ScenarioKind::Default => {
                let planned = heightmap::planned(cli)?;
                let size = planned.size;
                heightmap = planned.format.is_some().then_some(planned);
                (size, None)
            }
            ScenarioKind::Snow => (UVec2::splat(cli.size.unwrap_or(snow::SNOW_SIZE)), None),
            ScenarioKind::Flyover | ScenarioKind::World => {
                let planned = world_files::planned_world(cli)?;
                let m = planned.manifest;
                let layout = m.tile_layout();
                // Colour tiles are streamed where the world has them or `--color` makes them.
                let colored = cli.color.is_some()
                    || cli
                        .world
                        .join(terrain_cache::Layer::Color.folder())
                        .is_dir();
                let slot = flyover::vram_slot_bytes(&m, colored);
                let slots = cli.vram_budget.saturating_mul(1 << 20) / slot.max(1);
                let ram = cli.ram_budget.saturating_mul(1 << 20);
                // The paint stream's RAM pool (as the heights'), the colour's (twice).
                let overlay_ram = ram + if colored { ram.saturating_mul(2) } else { 0 };
                let shape = FlyoverShape {
                    ram_budget: ram.saturating_add(overlay_ram),
                    atlas: slots.saturating_mul(slot),
                    // The heights' table, and a table of the same entries per overlay atlas.
                    atlas_table: layout
                        .table_len()
                        .saturating_add(128)
                        .saturating_mul(4 * (2 + u64::from(colored))),
                    build: planned.build,
                    world: m.world_size,
                };
                (m.level_size(flyover::overview_level(&m)), Some(shape))
            }
        };
        let overview = match cli.scenario {
            // As `SnowScenario::overview_size`: no larger than the field.
            ScenarioKind::Snow => map.min(UVec2::splat(cli.overview_size)),
            _ => fit_overview(map, cli.overview_size),
        };
        Ok(Self {
            scenario: cli.scenario,
            lod: cli.lod,
            detail: cli.detail != crate::cli::DetailArg::None,
            gpu,
            map,
            heightmap,
            color: cli.color.is_some(),
            resolution: cli.resolution,
            overview,
            frames: cli.frames,
            flyover,
            shockwave: 0,
        })
    }

    /// The shape with what the scenario's parameters add: the default and world scenarios'
    /// shockwave (unless its amplitude or size makes it none).
    pub fn with_params(self, params: &crate::config::DemoParams) -> Self {
        let s = &params.stamps;
        let waves = match self.scenario {
            ScenarioKind::Default => s.shock_size_fraction > 0.0,
            ScenarioKind::World => s.shock_amplitude_m != 0.0,
            ScenarioKind::Snow | ScenarioKind::Flyover => false,
        };
        Self {
            shockwave: if waves { s.shockwave.resolution } else { 0 },
            ..self
        }
    }

    /// The parts of the run's memory, in bytes, named as report.json names them.
    pub fn estimate(&self) -> Vec<(&'static str, u64)> {
        let texels = area(self.map);
        let per_texel = |bytes: u64| texels.saturating_mul(bytes);
        let mut parts = vec![("process", PROCESS)];
        if self.gpu {
            parts.push(("gpu_driver", GPU_DRIVER));
        }
        if let Some(planned) = &self.heightmap {
            parts.push(("dem_import", import_bytes(planned)));
        }
        if self.color {
            let color = match &self.flyover {
                // A streamed world's: the file's bytes while read and its RGBA pixels, written
                // into colour tiles (the GPU draws a window of them: `overlays`).
                Some(f) => area(f.world).saturating_mul(8),
                // `--color` over a heightmap: the same, and the GPU's copy.
                None => per_texel(if self.gpu { 12 } else { 8 }),
            };
            parts.push(("color_layer", color));
        }
        if self.shockwave > 0 {
            let samples = area(UVec2::splat(self.shockwave));
            parts.push(("shockwave", samples.saturating_mul(SHOCKWAVE_PER_SAMPLE)));
        }
        match self.scenario {
            ScenarioKind::Default => {
                parts.push(("map", per_texel(MAP_PER_TEXEL)));
                parts.push(("normals", per_texel(NORMALS_PER_TEXEL)));
                parts.push(("collision", per_texel(COLLISION_PER_TEXEL)));
                // The hole mask once a hole is cut (`[stamps] hole_frame`, or a heightmap's
                // nodata): the CPU's, the collision snapshot's and the GPU's, a byte a texel
                // each, counted whether or not one is cut (the flags do not say it).
                parts.push(("holes", per_texel(if self.gpu { 3 } else { 2 })));
                if self.detail {
                    // The CPU layer if every tile were stamped (one byte per detail texel),
                    // and the GPU's tile slots and spill window.
                    let refine = u64::from(crate::scenarios::DETAIL_REFINE);
                    let mut bytes = per_texel(refine * refine);
                    if self.gpu {
                        let tile = u64::from(crate::scenarios::DETAIL_TILE);
                        let slots = u64::from(crate::gpu_scene::DETAIL_SLOTS);
                        let spill = u64::from(crate::gpu_scene::SPILL_WINDOW_TEXELS) * 4;
                        // A byte a detail texel (packed four to a u32 word).
                        bytes = bytes.saturating_add(slots * tile * tile + spill);
                    }
                    parts.push(("detail", bytes));
                }
                if self.gpu {
                    let gpu = GPU_MAP_PER_TEXEL + GPU_READBACK_PER_TEXEL;
                    parts.push(("gpu_map", per_texel(gpu)));
                    // The material layer the stamps paint (its buffer and texture, 4 bytes a
                    // texel each), counted whatever the shading: the flags do not say it.
                    parts.push(("material_layer", per_texel(8)));
                    if self.lod == crate::cli::LodArg::Tessellated {
                        let tess = per_texel(TESS_PER_TEXEL).saturating_add(TESS_FIXED);
                        parts.push(("tessellation", tess));
                    }
                }
            }
            ScenarioKind::Snow => {
                // The coarse-map copy of the field is made from it directly (2 bytes).
                parts.push(("map", per_texel(2)));
                parts.push(("normals", per_texel(NORMALS_PER_TEXEL)));
                parts.push(("collision", per_texel(COLLISION_PER_TEXEL)));
                let columns = texels.min(GRANULAR_AREA_COLUMNS);
                let field = per_texel(SNOW_FIELD_PER_TEXEL);
                parts.push((
                    "granular",
                    field.saturating_add(columns * GRANULAR_PER_COLUMN),
                ));
                if self.gpu {
                    let gpu = GPU_MAP_PER_TEXEL + SNOW_GPU_PER_TEXEL;
                    parts.push(("gpu_map", per_texel(gpu)));
                    // The material layer the trails paint, whatever the shading (as above).
                    parts.push(("material_layer", per_texel(8)));
                }
            }
            ScenarioKind::Flyover | ScenarioKind::World => {
                if self.scenario == ScenarioKind::World {
                    // The granular window: scratch map, its initial copy and the step's
                    // per-column buffers (or the GPU's).
                    let side = u64::from(crate::scenarios::trails::WINDOW_SIDE);
                    parts.push(("granular", side * side * GRANULAR_PER_COLUMN));
                    if self.detail {
                        parts.push(("detail", crate::scenarios::world_detail_bytes(self.gpu)));
                    }
                }
                // The overview level: made from tiles, kept with its normals, uploaded once.
                parts.push(("map", per_texel(MAP_PER_TEXEL)));
                parts.push(("normals", per_texel(NORMALS_PER_TEXEL)));
                let window = u64::from(flyover::COLLISION_WINDOW).pow(2);
                parts.push(("collision", window.saturating_mul(COLLISION_PER_TEXEL)));
                // Holes in the collision window (its mask and the one read for it); with a
                // GPU, its hole window (1 byte a cell) and the mask read for it when it moves.
                // (Paint and colour stream in tiles: `ram_pool`, `vram_pool`.)
                let mut overlays = window.saturating_mul(2);
                if self.gpu {
                    parts.push(("gpu_map", per_texel(GPU_MAP_PER_TEXEL)));
                    let gpu_window = u64::from(crate::scenarios::GPU_OVERLAY_WINDOW).pow(2);
                    overlays = overlays.saturating_add(gpu_window.saturating_mul(2));
                }
                parts.push(("overlays", overlays));
                if let Some(f) = &self.flyover {
                    // The world's quadtree with a streamed LOD (node bounds on the CPU, and the
                    // tessellation's on the GPU with its output and queues).
                    let tree = |leaf: u64, per_node: u64| {
                        let leaves = f.world.as_u64vec2().map(|s| s.div_ceil(leaf));
                        (leaves.x.saturating_mul(leaves.y) * 4 / 3).saturating_mul(per_node)
                    };
                    if self.gpu {
                        match self.lod {
                            crate::cli::LodArg::Cdlod => parts.push(("lod", tree(32, 12))),
                            crate::cli::LodArg::Tessellated => {
                                parts.push(("lod", tree(16, 12 + 8).saturating_add(TESS_FIXED)));
                            }
                            crate::cli::LodArg::Clipmap => {}
                        }
                    }
                    parts.push(("ram_pool", f.ram_budget.saturating_add(RAM_POOL_SLACK)));
                    if self.gpu {
                        let vram = f.atlas.saturating_add(f.atlas_table);
                        parts.push(("vram_pool", vram.saturating_add(VRAM_POOL_SLACK)));
                    }
                    match &f.build {
                        None => {}
                        Some(WorldBuild::Procedural) => parts.push(("world_build", WORLD_BUILD)),
                        Some(WorldBuild::Heightmap(planned)) => {
                            let map = area(planned.size).saturating_mul(MAP_PER_TEXEL);
                            parts.push(("world_build", map.saturating_add(WORLD_BUILD)));
                            parts.push(("dem_import", import_bytes(planned)));
                        }
                    }
                }
            }
        }
        parts.push(("terrain_png", per_texel(TERRAIN_PNG_PER_TEXEL)));
        let frames = if self.gpu {
            area(self.resolution).saturating_mul(GPU_FRAME_PER_PIXEL)
        } else {
            area(self.overview).saturating_mul(OVERVIEW_FRAME_PER_PIXEL)
        };
        parts.push(("frames", frames));
        parts.push((
            "overview",
            area(self.overview).saturating_mul(OVERVIEW_PER_PIXEL),
        ));
        parts.push(("summary", capture::SUMMARY_BYTES));
        parts.push((
            "report",
            u64::from(self.frames).saturating_mul(REPORT_PER_FRAME),
        ));
        parts
    }
}

/// The import of a heightmap beyond its map: decoded samples, and a GeoTIFF's directory as the
/// decoder reads it (bounded by terrain-core's walk of it).
fn import_bytes(planned: &PlannedMap) -> u64 {
    let directory = match planned.format {
        Some(DemFormat::GeoTiff) => terrain_core::geotiff::DIRECTORY_BYTES_BOUND,
        _ => 0,
    };
    area(planned.size)
        .saturating_mul(DEM_IMPORT_PER_TEXEL)
        .saturating_add(directory)
}

/// `size.x * size.y` without overflow.
fn area(size: UVec2) -> u64 {
    u64::from(size.x) * u64::from(size.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn shape(args: &[&str]) -> RunShape {
        let cli = Cli::try_parse_from(std::iter::once("demo").chain(args.iter().copied()))
            .expect("flags parse");
        RunShape::of(&cli).expect("shape")
    }

    fn part(parts: &[(&str, u64)], name: &str) -> u64 {
        parts.iter().find(|(n, _)| *n == name).map_or(0, |p| p.1)
    }

    #[test]
    fn the_estimate_grows_with_what_the_flags_ask_for() {
        let small = shape(&["--size", "256", "--no-gpu"]).estimate();
        let large = shape(&["--size", "4096", "--no-gpu"]).estimate();
        // 256 times the texels: the map parts grow 256 times, the fixed parts not at all.
        assert_eq!(part(&large, "map"), 256 * part(&small, "map"));
        assert_eq!(part(&large, "normals"), 4096 * 4096 * 8);
        assert_eq!(part(&large, "process"), part(&small, "process"));
        assert_eq!(part(&small, "gpu_driver"), 0);
        let gpu = shape(&["--size", "256", "--resolution", "1920x1080"]).estimate();
        assert!(part(&gpu, "gpu_driver") > 0 && part(&gpu, "gpu_map") > 0);
        assert_eq!(part(&gpu, "frames"), 1920 * 1080 * GPU_FRAME_PER_PIXEL);
        let frames = shape(&["--no-gpu", "--frames", "100000"]).estimate();
        assert_eq!(part(&frames, "report"), 100_000 * REPORT_PER_FRAME);
    }

    /// The shockwave's texture is counted where the scenario has one, by its resolution (a
    /// 4096-sample wave peaked 270 MiB above an estimate that left it out).
    #[test]
    fn the_shockwave_is_counted_by_its_resolution() {
        let mut params = crate::config::DemoParams::default();
        params.stamps.shockwave.resolution = 4096;
        let default = shape(&["--no-gpu"]).with_params(&params).estimate();
        assert_eq!(
            part(&default, "shockwave"),
            4096 * 4096 * SHOCKWAVE_PER_SAMPLE
        );
        let snow = shape(&["--no-gpu", "--scenario", "snow"])
            .with_params(&params)
            .estimate();
        assert_eq!(part(&snow, "shockwave"), 0);
        params.stamps.shock_size_fraction = 0.0;
        let none = shape(&["--no-gpu"]).with_params(&params).estimate();
        assert_eq!(part(&none, "shockwave"), 0);
    }

    #[test]
    fn the_overview_and_frames_follow_the_scenarios_sizes() {
        // A long, thin heightmap: the overview keeps its aspect, the frame is the overview.
        // (Its length is checked against the size: the file must exist.)
        let thin =
            std::env::temp_dir().join(format!("terrain_estimate_thin_{}.r16", std::process::id()));
        std::fs::write(&thin, vec![0u8; 16 * 4096 * 2]).expect("write");
        let thin_arg = thin.display().to_string();
        let cli = Cli::try_parse_from([
            "demo",
            "--no-gpu",
            "--heightmap",
            &thin_arg,
            "--raw-size",
            "16x4096",
            "--overview-size",
            "4096",
        ])
        .expect("flags");
        let s = RunShape::of(&cli).expect("shape");
        let _ = std::fs::remove_file(&thin);
        assert_eq!(s.overview, UVec2::new(16, 4096));
        assert_eq!(part(&s.estimate(), "frames"), 16 * 4096 * 12);
        // The import is counted beside the map: its decoded samples, no TIFF directory.
        assert_eq!(
            part(&s.estimate(), "dem_import"),
            16 * 4096 * DEM_IMPORT_PER_TEXEL
        );
        let snow = shape(&[
            "--scenario",
            "snow",
            "--size",
            "128",
            "--overview-size",
            "256",
        ]);
        assert_eq!(snow.overview, UVec2::splat(128));
        assert!(part(&snow.estimate(), "granular") > 0);
    }

    #[test]
    fn the_flyover_counts_its_budgets_and_atlas() {
        let world =
            std::env::temp_dir().join(format!("terrain_estimate_no_world_{}", std::process::id()));
        let world = world.display().to_string();
        let s = shape(&[
            "--scenario",
            "flyover",
            "--world",
            &world,
            "--ram-budget",
            "100",
            "--vram-budget",
            "10",
        ]);
        let f = s.flyover.as_ref().expect("flyover");
        assert_eq!(f.build, Some(WorldBuild::Procedural));
        // 26 whole 256^2 tiles of heights (2 bytes a texel) and paint (4) fit 10 MiB.
        assert_eq!(f.atlas, 26 * 256 * 256 * 6);
        assert!(f.atlas_table > 0);
        let parts = s.estimate();
        // The heights' pool and the paint stream's, as large.
        assert_eq!(part(&parts, "ram_pool"), (200 << 20) + RAM_POOL_SLACK);
        assert_eq!(
            part(&parts, "vram_pool"),
            f.atlas + f.atlas_table + VRAM_POOL_SLACK
        );
        // The default 16384^2 world is shown at its 1024^2 level.
        assert_eq!(s.map, UVec2::splat(1024));
        assert_eq!(part(&parts, "world_build"), WORLD_BUILD);
        assert_eq!(part(&parts, "lod"), 0, "the clipmap keeps no tree");
        // A streamed LOD counts the world's quadtree: 4 / 3 of its leaves' nodes (and the
        // tessellation's GPU copy, output and queues).
        let lod = |mode: &str| {
            let args = ["--scenario", "world", "--world", &world, "--lod", mode];
            part(&shape(&args).estimate(), "lod")
        };
        assert_eq!(lod("cdlod"), 512 * 512 * 4 / 3 * 12);
        assert_eq!(lod("tessellated"), 1024 * 1024 * 4 / 3 * 20 + TESS_FIXED);
    }
}
