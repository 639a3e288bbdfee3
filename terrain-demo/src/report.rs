//! `report.json`: what was rendered and how long each step of each frame took. Its JSON Schema,
//! `docs/report.schema.json`, is generated from these types (`schema`, for the tests).

use crate::cli::{CameraMode, Cli, LodArg, ScenarioKind};
use crate::config::DemoParams;
use crate::timings::{GpuFigure, Step};
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::Serialize;
use std::borrow::Cow;
use std::collections::BTreeMap;

/// The version of report.json's layout (`docs/report.schema.json`): raised when a field is
/// renamed, removed or changes meaning (adding one does not).
pub const SCHEMA_VERSION: u32 = 4;

/// What a terrain-demo run rendered and how long each step of each frame took.
/// `schema_version` is raised when a field is renamed, removed or changes meaning; new optional
/// fields may appear without it. Every line of frames.jsonl is one element of `frames`.
#[derive(Debug, Serialize, JsonSchema)]
#[schemars(title = "terrain-demo report.json", deny_unknown_fields)]
pub struct Report {
    /// The version of the report's layout.
    #[schemars(extend("const" = SCHEMA_VERSION))]
    pub schema_version: u32,
    /// The program that wrote the report.
    pub tool: ToolInfo,
    /// The run's whole configuration: every flag (defaults included) and the parameters of
    /// `--config` (defaults included). `flags.config` names the parameter file, if any.
    #[schemars(schema_with = "config_schema")]
    pub config: serde_json::Value,
    /// Where the heights came from: `procedural`, the heightmap's path, or the streamed
    /// world's folder.
    pub source: String,
    /// Map size in texels.
    pub size: [u32; 2],
    /// Metres per texel.
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub texel_size_m: f32,
    /// How stored heights become metres, and the heights the map holds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub height_encoding: Option<HeightEncodingReport>,
    /// How `--heightmap` was read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heightmap: Option<HeightmapReport>,
    /// The heightmap's nodata samples and what filled them, when it had any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nodata: Option<NodataReport>,
    /// The default scenario's camera.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "CameraMode")]
    pub camera: Option<&'static str>,
    /// The scenario.
    #[schemars(with = "ScenarioKind")]
    pub scenario: String,
    /// Scenario (and terrain) seed.
    pub seed: u64,
    /// The GPU adapter's name, or `none` for overview-only frames.
    pub adapter: String,
    /// The wgpu backend (`vulkan`, `gl`, `metal`, `dx12`), or `none`.
    pub backend: String,
    /// How the GPU steps were timed: `timestamps` (a hardware adapter with timestamp queries:
    /// the frames' `timings_ms` of GPU steps are the CPU time to record and submit them, their
    /// GPU time is in `gpu_timestamps_ms`, read back a frame or more later) or `wall` (a
    /// software adapter, whose timestamps miss deferred compute work, or no timestamp queries:
    /// `timings_ms` holds the wall time of submitting each step and waiting for it). Absent
    /// without a GPU.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_timing: Option<GpuTiming>,
    /// Frame size in pixels.
    pub resolution: [u32; 2],
    /// Milliseconds to generate or load the terrain.
    #[schemars(with = "Ms")]
    pub load_ms: f64,
    /// Milliseconds to compute the first full normal map.
    #[schemars(with = "Ms")]
    pub initial_normals_ms: f64,
    /// Flyover: tiles written back into the world during and at the end of the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub written_back_tiles: Option<u64>,
    /// Frames asked for (`--frames`).
    #[schemars(range(min = 1))]
    pub frames_requested: u32,
    /// Whether Ctrl-C ended the run early: `frames` lists the frames done before it.
    pub interrupted: bool,
    /// The error that ended the run early (a frame that could not be written, a world tile
    /// that could not be read or written back): `frames` lists the frames done before it, and
    /// the run exits with a non-zero status. Absent when no error ended the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The run's memory: its limit, the estimate it was accepted on, the peak measured.
    pub memory: MemoryReport,
    /// Per frame.
    pub frames: Vec<FrameReport>,
    /// Sum of each step over all frames, in milliseconds.
    #[schemars(schema_with = "by_step::<Ms>")]
    pub totals_ms: BTreeMap<&'static str, f64>,
    /// Leading frames left out of `steps_ms` (shader compilation, first uploads): `--warmup`,
    /// at most all frames but the last.
    pub warmup_frames: u32,
    /// Per step, over the frames after warm-up that timed it: mean, median, 95th percentile
    /// and maximum in milliseconds.
    #[schemars(schema_with = "by_step::<StepStats>")]
    pub steps_ms: BTreeMap<&'static str, StepStats>,
    /// The frames' `frame_thread_cpu_ms` over the frames after warm-up: mean, median, 95th
    /// percentile and maximum. Absent where the platform has no thread CPU clock.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame_thread_cpu_ms: Option<StepStats>,
}

/// The JSON Schema (draft 2020-12) of report.json, derived from [`Report`] and the types in
/// it; `docs/report.schema.json` is this, written out by the test that keeps the two the same.
#[cfg(test)]
pub fn schema() -> serde_json::Value {
    use schemars::generate::SchemaSettings;
    let generator = SchemaSettings::draft2020_12()
        .for_serialize()
        .into_generator();
    let mut schema = generator.into_root_schema_for::<Report>().to_value();
    schema["$id"] = format!("urn:terrain-demo:report.schema.json:{SCHEMA_VERSION}").into();
    unwrap_descriptions(&mut schema);
    schema
}

/// Joins the lines of every paragraph of every `description` in `value` (doc comments are
/// wrapped at 100 columns; a schema reader wraps them itself).
#[cfg(test)]
fn unwrap_descriptions(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::Object(map) => {
            for (key, v) in map.iter_mut() {
                match v {
                    serde_json::Value::String(text) if key == "description" => {
                        *text = text
                            .split("\n\n")
                            .map(|paragraph| paragraph.split('\n').collect::<Vec<_>>().join(" "))
                            .collect::<Vec<_>>()
                            .join("\n\n");
                    }
                    _ => unwrap_descriptions(v),
                }
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(unwrap_descriptions),
        _ => {}
    }
}

/// The schema of `Report::config`: `flags` as [`Cli`] writes them, `params` as [`DemoParams`].
fn config_schema(generator: &mut SchemaGenerator) -> Schema {
    json_schema!({
        "type": "object",
        "properties": {
            "flags": generator.subschema_for::<Cli>(),
            "params": generator.subschema_for::<DemoParams>(),
        },
        "required": ["flags", "params"],
        "additionalProperties": false,
    })
}

/// The schema of a map keyed by [`Step::name`] whose values are `V`s.
fn by_step<V: JsonSchema>(generator: &mut SchemaGenerator) -> Schema {
    json_schema!({
        "type": "object",
        "propertyNames": generator.subschema_for::<Step>(),
        "additionalProperties": generator.subschema_for::<V>(),
    })
}

/// The schema of a duration in milliseconds (an `f64` of the report): never negative.
struct Ms;

impl JsonSchema for Ms {
    fn schema_name() -> Cow<'static, str> {
        "ms".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "description": "Milliseconds.",
            "type": "number",
            "minimum": 0,
        })
    }
}

/// The program that wrote a report.
#[derive(Debug, Clone, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ToolInfo {
    /// `terrain-demo`.
    #[schemars(extend("const" = env!("CARGO_PKG_NAME")))]
    pub name: &'static str,
    /// The crate version.
    #[schemars(regex(pattern = r"^[0-9]+\.[0-9]+\.[0-9]+"))]
    pub version: &'static str,
    /// The git commit it was built from (12 hex digits), or `unknown` when built outside a
    /// git checkout.
    #[schemars(regex(pattern = r"^([0-9a-f]{7,40}|unknown)$"))]
    pub git_revision: &'static str,
}

impl ToolInfo {
    /// This build.
    pub fn current() -> Self {
        Self {
            name: env!("CARGO_PKG_NAME"),
            version: env!("CARGO_PKG_VERSION"),
            git_revision: env!("TERRAIN_DEMO_GIT_REVISION"),
        }
    }
}

/// A step's milliseconds over the measured frames.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct StepStats {
    /// Frames that timed the step.
    pub frames: usize,
    /// Mean.
    #[schemars(with = "Ms")]
    pub mean: f64,
    /// Median (nearest rank).
    #[schemars(with = "Ms")]
    pub p50: f64,
    /// 95th percentile (nearest rank).
    #[schemars(with = "Ms")]
    pub p95: f64,
    /// Maximum.
    #[schemars(with = "Ms")]
    pub max: f64,
}

impl StepStats {
    /// The statistics of `sorted` (ascending); all zero when it is empty.
    pub fn of_sorted(sorted: &[f64]) -> Self {
        let n = sorted.len();
        // Nearest rank: the smallest value with at least p % of the values at or below it.
        let rank = |p: usize| sorted[(n * p).div_ceil(100).clamp(1, n) - 1];
        if n == 0 {
            return Self {
                frames: 0,
                mean: 0.0,
                p50: 0.0,
                p95: 0.0,
                max: 0.0,
            };
        }
        Self {
            frames: n,
            mean: sorted.iter().sum::<f64>() / n as f64,
            p50: rank(50),
            p95: rank(95),
            max: sorted[n - 1],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank() {
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        let s = StepStats::of_sorted(&v);
        assert_eq!((s.frames, s.p50, s.p95, s.max), (20, 10.0, 19.0, 20.0));
        assert_eq!(s.mean, 10.5);
        let one = StepStats::of_sorted(&[3.0]);
        assert_eq!((one.p50, one.p95, one.max, one.mean), (3.0, 3.0, 3.0, 3.0));
        assert_eq!(StepStats::of_sorted(&[]).frames, 0);
        let s = StepStats::of_sorted(&[1.0, 2.0, 3.0, 100.0]);
        assert_eq!((s.p50, s.p95), (2.0, 100.0));
    }

    fn frame(index: u32) -> FrameReport {
        FrameReport {
            index,
            file: format!("frame_{index:04}.png"),
            stats: FrameStats::default(),
            triangles: 0,
            lod: None,
            vertices: None,
            max_screen_error_px: None,
            max_vertex_jump_px: None,
            refined: None,
            camera_clearance_m: 1.0,
            timings_ms: BTreeMap::from([("render", 0.5)]),
            gpu_timestamps_ms: BTreeMap::new(),
            frame_thread_cpu_ms: Some(0.25),
            gpu_objects: None,
        }
    }

    #[test]
    fn late_gpu_figures_go_to_their_frames_and_missing_ones_stay_absent() {
        let mut frames: Vec<FrameReport> = (0..4).map(frame).collect();
        let figure = |frame, step, ms| GpuFigure { frame, step, ms };
        // Frame 0's figures arrive in frame 2, frame 2's own ones in frame 3, frame 3's at the
        // flush; frame 1's never arrive; one of a frame never captured is left out.
        credit_gpu(&mut frames, &[figure(0, Step::Render, 2.0)]);
        credit_gpu(
            &mut frames,
            &[
                figure(2, Step::StampGpu, 0.25),
                figure(2, Step::StampGpu, 0.5),
                figure(2, Step::Render, 1.0),
            ],
        );
        credit_gpu(
            &mut frames,
            &[figure(3, Step::Render, 3.0), figure(9, Step::Render, 1.0)],
        );
        let gpu = |i: usize| serde_json::to_value(&frames[i]).unwrap()["gpu_timestamps_ms"].clone();
        assert_eq!(gpu(0), serde_json::json!({"render": 2.0}));
        assert_eq!(gpu(1), serde_json::json!({}), "absent, not zero");
        assert_eq!(
            gpu(2),
            serde_json::json!({"stamp_gpu": 0.75, "render": 1.0})
        );
        assert_eq!(gpu(3), serde_json::json!({"render": 3.0}));
        // The wall figures are untouched.
        assert!(frames.iter().all(|f| f.timings_ms["render"] == 0.5));
    }

    /// `docs/report.schema.json` is [`schema`] written out. `TERRAIN_BLESS=1` rewrites it
    /// (atomically: a temporary file renamed over it) instead of comparing.
    #[test]
    fn docs_report_schema_is_the_generated_schema() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/report.schema.json");
        let generated = schema();
        if std::env::var_os("TERRAIN_BLESS").is_some_and(|v| !v.is_empty() && v != "0") {
            let text = schema_text(&generated);
            let tmp = path.with_extension("json.tmp");
            std::fs::write(&tmp, text).unwrap();
            std::fs::rename(&tmp, &path).unwrap();
            return;
        }
        let text = std::fs::read_to_string(&path).expect("docs/report.schema.json");
        let on_disk: serde_json::Value = serde_json::from_str(&text).expect("the schema is JSON");
        assert!(
            on_disk == generated,
            "docs/report.schema.json is not the schema of report.json's types; regenerate it with \
             `TERRAIN_BLESS=1 cargo test -p terrain-demo --bin terrain-demo report::tests` and \
             review the diff"
        );
    }

    /// `schema` as pretty JSON with `$schema`, `$id`, `title` and `description` first and
    /// `$defs` last (serde_json's maps sort their keys).
    fn schema_text(schema: &serde_json::Value) -> String {
        let map = schema.as_object().expect("a schema is an object");
        let head = ["$schema", "$id", "title", "description"];
        let middle = map
            .keys()
            .map(String::as_str)
            .filter(|k| !head.contains(k) && *k != "$defs");
        let keys = head.into_iter().chain(middle).chain(["$defs"]);
        let fields: Vec<String> = keys
            .filter_map(|key| {
                let value = serde_json::to_string_pretty(map.get(key)?).unwrap();
                let key = serde_json::to_string(key).unwrap();
                // JSON strings hold no raw newline: every one is between tokens.
                Some(format!("  {key}: {}", value.replace('\n', "\n  ")))
            })
            .collect();
        format!("{{\n{}\n}}\n", fields.join(",\n"))
    }
}

/// A map's height encoding: `metres = offset + scale * stored` (u16).
#[derive(Debug, Clone, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct HeightEncodingReport {
    /// Metres of stored value 0.
    pub offset: f32,
    /// Metres per stored unit.
    pub scale: f32,
    /// Metres of the lowest stored value (the span's low end).
    pub min_m: f32,
    /// Metres of the highest stored value (the span's high end).
    pub max_m: f32,
    /// The lowest height of the terrain itself.
    pub data_min_m: f32,
    /// The highest height of the terrain itself.
    pub data_max_m: f32,
    /// What chose the span: `data` (`--height-range auto`: the heightmap's own range),
    /// `height-range`, `max-height`, `procedural` (its default 0..12 m), `world` (a flyover
    /// world's manifest) or `snow field`.
    pub source: &'static str,
}

/// How `--heightmap` was read.
#[derive(Debug, Clone, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct HeightmapReport {
    /// `PNG`, `RAW16`, `R32` or `GeoTIFF`.
    pub format: &'static str,
    /// The file's sample type: `u8`, `u16`, `i16`, `f32`, ...
    pub sample: &'static str,
    /// Where the texel size came from: `--texel-size`, the GeoTIFF's pixel scale, or the
    /// default.
    pub texel_size_source: &'static str,
    /// Samples outside `--height-range`, clamped to it.
    pub clamped_samples: u64,
}

/// A heightmap's nodata samples.
#[derive(Debug, Clone, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct NodataReport {
    /// How many samples were nodata.
    pub count: u64,
    /// The file's nodata value (GeoTIFF's GDAL nodata tag; null when only NaN, infinite or
    /// huge floats were nodata, or the tag is NaN).
    pub value: Option<f64>,
    /// The height they were filled with (metres, or integers under `--height-range`): the
    /// lowest valid height.
    pub fill_m: f32,
}

/// The memory of a run.
#[derive(Debug, Clone, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct MemoryReport {
    /// The limit (`--max-memory`, or the default fraction of the machine's memory).
    pub limit_bytes: u64,
    /// What the run was estimated to need from its flags, before anything was allocated.
    pub estimate_bytes: u64,
    /// The estimate's parts (they add up to `estimate_bytes`).
    pub estimate: BTreeMap<&'static str, u64>,
    /// The peak resident memory of the process (VmHWM: every thread, the GPU driver
    /// included), read just before report.json is written; absent where it cannot be read.
    pub peak_rss_bytes: Option<u64>,
}

impl MemoryReport {
    /// The report of a run accepted under `limit` on the estimate `parts`.
    pub fn new(limit_bytes: u64, parts: &[(&'static str, u64)]) -> Self {
        Self {
            limit_bytes,
            estimate_bytes: parts.iter().map(|p| p.1).sum(),
            estimate: parts.iter().copied().collect(),
            peak_rss_bytes: None,
        }
    }
}

/// One frame.
#[derive(Debug, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct FrameReport {
    /// Frame number from 0.
    pub index: u32,
    /// The image, relative to the output folder.
    #[schemars(regex(pattern = r"^frame_[0-9]{4,}\.png$"))]
    pub file: String,
    /// What the scenario measured.
    #[serde(flatten)]
    pub stats: FrameStats,
    /// Non-degenerate triangles drawn (0 without the GPU).
    pub triangles: u64,
    /// The LOD scheme of the 3D frame (absent without the GPU).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "LodArg")]
    pub lod: Option<&'static str>,
    /// Vertices drawn (shared-mesh vertices per instance).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vertices: Option<u64>,
    /// CDLOD: the largest projected geometric error of the drawn nodes against the full map,
    /// pixels (Cervin 2012, eq. 1.1, on the CPU).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_screen_error_px: Option<f32>,
    /// CDLOD: the largest screen-space jump of the drawn surface since the last frame that the
    /// camera's motion does not explain (both frames' meshes on today's heights, projected by
    /// today's camera), pixels: the popping metric.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_vertex_jump_px: Option<f32>,
    /// `--detail refine`: whether the refined cells near the camera were drawn. Not on a frame
    /// whose LOD could not leave their region out (it reached where the LOD morphs: near a
    /// cliff, or where a streamed quadtree's bounds were still a whole tile's); the LOD drew
    /// the region itself, and `triangles` leaves the refined ones out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refined: Option<bool>,
    /// Height of the camera's eye above the true surface under it (never negative: the camera
    /// is a body on the collision mirror, kept above pending deformations by their bounds).
    pub camera_clearance_m: f32,
    /// Milliseconds per step, keyed by the step's name:
    /// `stamp_gpu` (the footprints' in detail tiles too), `normals_gpu`, `granular_gpu` and
    /// `render` (sky + terrain) are, with `gpu_timing` `wall`, the wall time of submitting the
    /// GPU work and waiting for it, and with `timestamps` the CPU time of recording and
    /// submitting it (no wait: its GPU time is in `gpu_timestamps_ms`); `stamp_cpu`,
    /// `normals_cpu`, `granular_cpu` the same work on the CPU (without a GPU); `lod` (clipmap
    /// placement and culling), `capture` (image readback), `physics` (collision, the camera,
    /// and with a GPU the regions read back copied into the CPU's map), `overview` (hillshade),
    /// `write` (PNG), `cache` (flyover), `detail` (the detail cache, its tiles streamed to the
    /// GPU and its stamped rects read back).
    #[schemars(schema_with = "by_step::<Ms>")]
    pub timings_ms: BTreeMap<&'static str, f64>,
    /// GPU timestamp spans of the GPU steps, where the adapter has timestamp queries. With
    /// `gpu_timing` `timestamps` they are read back a frame or more later and credited to this
    /// frame; a step whose timestamps never arrived (a frame left untimed) is absent. With
    /// `wall` they are taken per step beside the wait (on lavapipe they miss deferred compute
    /// work: see terrain-gpu's `timer`).
    #[schemars(schema_with = "by_step::<Ms>")]
    pub gpu_timestamps_ms: BTreeMap<&'static str, f64>,
    /// The frame thread's own CPU work in the frame, in milliseconds of its CPU clock: the
    /// thread's CPU time from the start of the frame to its capture, less its CPU time in GPU
    /// submits and waits (`stamp_gpu`, `normals_gpu`, `granular_gpu`, `render`) and in the
    /// capture's readback; the frame's PNG write comes after. Unlike the wall figures of
    /// `timings_ms` it leaves out the time the thread waited or was preempted (on a software
    /// adapter, whose threads share the cores). Absent where the platform has no thread CPU
    /// clock (Linux and Android have one).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<Ms>")]
    pub frame_thread_cpu_ms: Option<f64>,
    /// GPU objects alive after the frame (wgpu's internal counters), with a GPU: they stop
    /// changing after the first frames, since passes allocate only when built.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_objects: Option<GpuObjects>,
}

/// How a run timed its GPU steps (`gpu_scene::frame_timer`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum GpuTiming {
    /// A hardware adapter with timestamp queries: each step's work inside GPU timestamp
    /// queries, read back a frame or more later without waiting.
    Timestamps,
    /// A software adapter (lavapipe, whose timestamps miss deferred compute work) or no
    /// timestamp queries: each step submitted and waited for.
    Wall,
}

/// Credits GPU timestamp figures that arrived after their frames were captured to those
/// frames (`frames[i]` is frame `i`): a step's figures add up; figures of frames not captured
/// are left out. A frame no figure arrived for keeps its GPU timings absent, not zero.
pub fn credit_gpu(frames: &mut [FrameReport], figures: &[GpuFigure]) {
    for figure in figures {
        let Some(frame) = usize::try_from(figure.frame)
            .ok()
            .and_then(|i| frames.get_mut(i))
        else {
            continue;
        };
        *frame
            .gpu_timestamps_ms
            .entry(figure.step.name())
            .or_default() += figure.ms;
    }
}

/// Credits granular measures that arrived after their frames were captured to those frames
/// (`frames[i]` is frame `i`); measures of frames not captured are left out.
pub fn credit_granular(frames: &mut [FrameReport], figures: &[crate::timings::GranularFigure]) {
    for figure in figures {
        let Some(frame) = usize::try_from(figure.frame)
            .ok()
            .and_then(|i| frames.get_mut(i))
        else {
            continue;
        };
        frame.stats.granular_volume = Some(figure.volume);
        frame.stats.granular_volume_taken = figure.volume_taken;
        frame.stats.granular_removed = figure.removed;
    }
}

/// Live GPU objects of the device, from wgpu's internal counters (`counters` feature).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct GpuObjects {
    /// Buffers.
    pub buffers: isize,
    /// Textures.
    pub textures: isize,
    /// Bind groups.
    pub bind_groups: isize,
    /// Shader modules.
    pub shader_modules: isize,
    /// Render and compute pipelines.
    pub pipelines: isize,
}

/// The fields of a frame's report that depend on the scenario (zero or absent where it has
/// no such thing).
#[derive(Debug, Default, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct FrameStats {
    /// Footprints stamped this frame.
    pub footprints: u32,
    /// Craters stamped this frame.
    pub craters: u32,
    /// Shockwave stamps this frame.
    pub shockwaves: u32,
    /// Texels inside the rects the frame deformed (stamps, or granular active areas). With a
    /// GPU, a spilling footprint's rects count whether or not its spill moved a texel (the GPU
    /// does not say; they are read back and their normals rebuilt either way).
    pub dirty_texels: u64,
    /// On frames where a collision readback landed: milliseconds from its request to its
    /// application (the longest, if several landed).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Ms")]
    pub readback_ms: Option<f64>,
    /// Snow scenario: the u64 sum of the granular heights after the frame (constant with
    /// compression 0: the volume is preserved). The granular fields of a GPU step are read back
    /// without a wait and credited to their frame in report.json a frame or more later: its
    /// `frames.jsonl` line (written as the frame completes) lacks them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub granular_volume: Option<u64>,
    /// World scenario: the units the granular window held when it was taken, less those
    /// compression removed: equal to `granular_volume` at every frame (the hand-over is exact).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub granular_volume_taken: Option<u64>,
    /// Flyover: the tile cache this frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cache: Option<CacheStats>,
    /// Snow scenario: where the granular steps run, `gpu` or `cpu` (without an adapter, or
    /// `--no-gpu`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub granular_backend: Option<&'static str>,
    /// World scenario, on a frame where the granular window moved on: whether the move waited
    /// for writes on their way (areas stepped on the GPU, craters read back). It waits for
    /// nothing unless the vehicle reaches the window's edge before they land.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub granular_move_waited: Option<bool>,
    /// Snow scenario: material removed by compression so far, in height units.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub granular_removed: Option<u64>,
    /// `--detail parallax` or `refine`: detail tiles in a GPU slot after the frame (without a GPU: tiles
    /// the CPU layer holds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail_tiles_resident: Option<u32>,
    /// `--detail parallax` or `refine`: detail texels inside the rects the frame's footprints stamped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail_dirty_texels: Option<u64>,
}

/// The flyover's tile cache in one frame.
#[derive(Debug, Clone, Copy, Default, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct CacheStats {
    /// Tiles the selection wants near the camera that are not in RAM yet (the frame falls back
    /// to coarser data there).
    pub tiles_missing: usize,
    /// With a GPU: bytes of the tiles resident in the atlases (heights, paint and colour; at
    /// most the VRAM budget).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vram_bytes: Option<u64>,
    /// With a GPU: bytes uploaded this frame (never above the per-frame budget).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub upload_bytes: Option<u64>,
    /// With a GPU: tiles uploaded this frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uploads: Option<usize>,
    /// With a GPU: wanted paint (material) tiles not in the GPU's paint atlas (drawn from a
    /// coarser level's paint there).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material_tiles_missing: Option<usize>,
    /// With a GPU and a colour layer: the same for colour tiles.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub color_tiles_missing: Option<usize>,
    /// With a GPU: bytes of paint and colour tiles uploaded this frame (within their streams'
    /// per-frame budgets).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub overlay_upload_bytes: Option<u64>,
    /// Tiles the selection wants further out (ahead of the camera) still loading.
    pub prefetching: usize,
    /// Bytes the RAM pool holds, and its budget (never exceeded).
    pub ram_bytes: u64,
    /// The RAM pool's budget.
    pub ram_budget_bytes: u64,
    /// Loads issued this frame.
    pub loads: usize,
    /// Tiles dropped to make room this frame.
    pub evictions: usize,
    /// Tiles changed and not yet written back.
    pub dirty_tiles: usize,
    /// Craters waiting for a tile they touch to be resident.
    pub pending_craters: usize,
    /// Level-0 tiles stamped so far on the GPU in their atlas slot (read back into RAM).
    pub gpu_tile_stamps: u64,
    /// Level-0 tiles stamped so far on the CPU in RAM (not in the atlas, or no GPU).
    pub cpu_tile_stamps: u64,
    /// Rects of GPU-stamped tiles on their way back to RAM.
    pub tile_readbacks_in_flight: usize,
    /// The collision window around the camera: level-0 texels `[x, y, width, height]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub collision_window: Option<[i32; 4]>,
    /// Level-0 tiles of the collision window filled from coarser data (not loaded yet).
    pub collision_coarse_tiles: usize,
    /// Milliseconds the frame thread spent in cache calls, CPU crater stamps on tiles and the
    /// collision window (GPU stamps are timed as `stamp_gpu`).
    #[schemars(with = "Ms")]
    pub frame_thread_ms: f64,
}
