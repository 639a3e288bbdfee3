//! wgpu passes for deformable terrain: the headless context, GPU height and derivative maps,
//! `StampPass`, `NormalPass`, asynchronous `RegionReadback`, and rendering: `SkyPass`,
//! `ClipmapRenderer` and `OffscreenTarget` captures; `GpuTileAtlas`, the tile slots and
//! indirection table of a streamed world that the clipmap can draw from; `GpuDetailTiles`, the
//! detail layer's tiles (stamped by `StampPass::encode_detail`, drawn through
//! `ClipmapSurface::Detail`, or as refined geometry near the camera by `RefinePass` and
//! `RefineRenderer`: one output buffer, so one refine encode per submit).
//!
//! Every pass is a struct that makes everything long-lived in `new(&wgpu::Device, ..)`
//! (pipelines, one shader module per WGSL module, layouts, a uniform ring, scratch buffers) and
//! per frame only writes its uniforms and records commands: compute passes with
//! `encode(&mut self, device, queue, encoder, ..)` and `recall()` after the submit; renderers
//! with `prepare(..)` and `draw(&self, &mut wgpu::RenderPass)` into the caller's own pass, for
//! the caller's [`TargetFormat`]. Passes never create a device: they take the caller's
//! `&wgpu::Device` / `&wgpu::Queue`, so an engine can use its own ([`required_limits`] says
//! what to ask for; see `examples/own_device.rs`). Every pass has a CPU reference in
//! terrain-core and a test comparing the two. Architecture: `docs/ARCHITECTURE.md`; the
//! theses: `docs/REFERENCES.md`.
//!
//! The GPU sides of a streamed world's subsystems compose those passes into what a frame drives
//! once each: [`AtlasStamper`] and [`AtlasDeformer`] (stamps on atlas tiles, the changed rects
//! read back), [`GpuDetailStream`] (detail tiles following a working set, footprints, readback),
//! [`granular::GranularField`] (a granular map stepped, shaded and measured) and [`StepTimer`]
//! (GPU time per step without a stall where timestamps are trusted). Each records into the
//! caller's encoder (`encode_*`, then `recall`) or submits on its own.
//!
//! ```no_run
//! use glam::Vec2;
//! use terrain_core::{Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, StampPlacement};
//! use terrain_gpu::{
//!     GpuContext, GpuDerivativeMap, GpuHeightMap, GpuStamp, NormalPass, StampOp, StampPass,
//! };
//!
//! let ctx = GpuContext::new_headless()?;
//! println!("running on {} ({})", ctx.report().name, ctx.report().backend);
//! let (device, queue) = (&ctx.device, &ctx.queue);
//! let map = CoarseMap::coarse(Grid::new(256, 256, 30_000u16)?, HeightEncoding::new(0.001, 0.0)?, 0.1)?;
//! let gpu_map = GpuHeightMap::from_map(device, queue, &map)?;
//! let normals = GpuDerivativeMap::for_map(device, &gpu_map)?;
//! // Built once: pipelines, layouts, uniform rings.
//! let (mut stamps, mut normal_pass) = (StampPass::new(device)?, NormalPass::new(device)?);
//!
//! let mut encoder = device.create_command_encoder(&Default::default());
//! let crater = StampPlacement::new(Vec2::new(0.5, 0.5), Vec2::splat(4.0), -1.0)?;
//! let gauss = GaussianStamp::default();
//! let op = StampOp { stamp: GpuStamp::Gaussian(&gauss), placement: crater, blend: Blend::Add };
//! // Per frame: write uniforms, record commands.
//! for rect in stamps.encode(device, queue, &mut encoder, &gpu_map, &op)? {
//!     normal_pass.encode(device, queue, &mut encoder, &gpu_map, &normals, rect)?;
//! }
//! queue.submit([encoder.finish()]);
//! // The submit carried the recorded dispatches: their uniform slots are free again.
//! stamps.recall();
//! normal_pass.recall();
//! let deformed: CoarseMap = gpu_map.read(device, queue)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// docs.rs: label feature-gated items with the features they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]
#![warn(clippy::unwrap_used)]

mod device;
mod error;
pub mod granular;
mod passes;
mod render;
mod resources;
#[cfg(feature = "testing")]
pub mod testing;

// The modules sit in folders by role and are private: every public item has one path, at the
// crate root (the granular passes under `granular`, the test helpers under `testing`). These
// imports give the crate's own code the short paths `crate::<module>`.
use device::{
    context, detail_readback, detail_stream, download, limits, profiler, queued_readback, readback,
    region_source, small_readback, step_timer, submit, timer,
};
use passes::{
    atlas_stamper, deformable_map, density, detail_probe, material_effect, normals, spill, stamp,
};
use render::{camera, cdlod, clipmap, offscreen, refine, sky, target, terrain, tessellation};
use resources::{atlas, detail, hole_mask, maps, material_layer, materials, overlay_atlas};

pub use atlas::{AtlasConfig, AtlasProbe, GpuTileAtlas, PROBE_TEXEL_LIMIT, ProbeSample, TileSlot};
pub use atlas_stamper::{ArrivedTileRect, AtlasDeformer, AtlasStamp, AtlasStampOp, AtlasStamper};
pub use camera::{Camera, DepthConvention, RenderView, ViewMatrices};
pub use cdlod::{CdlodDraw, CdlodRenderer};
pub use clipmap::{ClipmapRenderer, ClipmapSurface, ClipmapView, TerrainStyle};
pub use context::{AdapterReport, GpuContext};
pub use deformable_map::DeformableMap;
pub use density::{DensityPass, GpuDensityMap};
pub use detail::{
    DetailShading, DetailTileState, GpuDetailTiles, MAX_PARALLAX_REACH, MAX_PARALLAX_STEPS,
};
pub use detail_probe::{DetailProbe, DetailProbePoint, DetailProbeSample, MAX_PROBE_OFFSET};
pub use detail_readback::{ArrivedDetail, DetailReadback};
pub use detail_stream::GpuDetailStream;
pub use download::{WAIT_TIMEOUT, download_bytes, read_texture_rgba8, wait_bounded};
pub use error::GpuError;
pub use hole_mask::{GpuHoleMask, HoleWindowUpload};
pub use limits::{MapUse, OPTIONAL_FEATURES, check_limits, required_limits};
pub use maps::{ExactInF32, GpuDerivativeMap, GpuHeightMap};
pub use material_effect::{EffectOp, MaterialEffectPass};
pub use material_layer::GpuMaterialLayer;
pub use materials::{
    GpuColorLayer, GpuMaterials, MaterialStyle, PROCEDURAL_MATERIAL_SIZE, SurfaceShading,
};
pub use normals::NormalPass;
pub use offscreen::OffscreenTarget;
pub use overlay_atlas::GpuOverlayAtlas;
pub use profiler::{
    FrameProfile, GpuProfiler, MAX_PROFILER_FRAMES, MAX_PROFILER_SCOPES, Scope, ScopeTiming,
};
pub use queued_readback::QueuedReadback;
pub use readback::{MAX_READBACK_RING, ReadbackTicket, RegionData, RegionReadback, RegionView};
pub use refine::{RefineDraw, RefinePass, RefineRenderer};
pub use region_source::GpuRegionSource;
pub use sky::{SkyColors, SkyPass};
pub use small_readback::{MAX_SMALL_READBACK_BYTES, MAX_SMALL_READBACK_RING, SmallReadback};
pub use spill::{SpillPass, SpillTargets, SpilledStamp};
pub use stamp::{GpuProceduralStamp, GpuStamp, GpuTextureStamp, StampOp, StampPass};
pub use step_timer::{StepFigure, StepTimer, TimedSpan, TimingMode};
pub use submit::{PlainSubmit, Submit};
pub use target::TargetFormat;
pub use terrain::{TESS_CAPACITY, TerrainFrame, TerrainRenderer, TerrainView};
pub use tessellation::{GpuTessellation, TessDraw, TessRenderer, TessWorld, TessellationPass};
pub use timer::{GpuTimer, GpuTiming};

/// The glam of this crate's public API.
pub use glam;
/// The wgpu this crate is built against: use it to make devices and passes of the same version.
pub use wgpu;

/// The README's code blocks, compiled and run as doc tests so that they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

// Engines keep passes and renderers in state shared across threads (Bevy's `Resource` is
// `Send + Sync`): a type that loses either fails this build.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<TerrainRenderer>();
    send_sync::<ClipmapRenderer>();
    send_sync::<SkyPass>();
    send_sync::<StampPass>();
    send_sync::<NormalPass>();
    send_sync::<GpuHeightMap<u16>>();
    send_sync::<GpuDerivativeMap>();
    send_sync::<GpuTileAtlas>();
    send_sync::<GpuOverlayAtlas>();
    send_sync::<RegionReadback>();
    send_sync::<DetailReadback>();
    send_sync::<GpuRegionSource>();
    send_sync::<granular::GpuGranularStep>();
};
