//! wgpu passes for deformable terrain: the headless context, GPU height and derivative maps,
//! `StampPass`, `NormalPass`, asynchronous `RegionReadback`, and rendering: `SkyPass`,
//! `ClipmapRenderer` and `OffscreenTarget` captures.
//!
//! Every pass is a struct built once with `new(&wgpu::Device)` and recorded with
//! `encode(&self, .., &mut wgpu::CommandEncoder, ..)`. Passes never create a device: they take
//! the caller's `&wgpu::Device` / `&wgpu::Queue`, so an engine can use its own. Every pass has
//! a CPU reference in terrain-core and a test comparing the two.
//!
//! ```no_run
//! use glam::Vec2;
//! use terrain_core::{Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, StampPlacement};
//! use terrain_gpu::{GpuContext, GpuDerivativeMap, GpuHeightMap, GpuStamp, NormalPass, StampPass};
//!
//! let ctx = GpuContext::new_headless()?;
//! println!("running on {} ({})", ctx.report().name, ctx.report().backend);
//! let (device, queue) = (&ctx.device, &ctx.queue);
//! let map = CoarseMap::coarse(Grid::new(256, 256, 30_000u16)?, HeightEncoding::new(0.001, 0.0)?, 0.1)?;
//! let gpu_map = GpuHeightMap::from_map(device, queue, &map)?;
//! let normals = GpuDerivativeMap::for_map(device, &gpu_map)?;
//! let (stamps, normal_pass) = (StampPass::new(device)?, NormalPass::new(device)?);
//!
//! let mut encoder = device.create_command_encoder(&Default::default());
//! let crater = StampPlacement::new(Vec2::new(0.5, 0.5), Vec2::splat(4.0), -1.0)?;
//! let gauss = GaussianStamp::default();
//! for rect in stamps.encode(device, &mut encoder, &gpu_map, GpuStamp::Gaussian(&gauss), &crater, Blend::Add)? {
//!     normal_pass.encode(device, &mut encoder, &gpu_map, &normals, rect)?;
//! }
//! queue.submit([encoder.finish()]);
//! let deformed: CoarseMap = gpu_map.read(device, queue)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]
#![warn(clippy::unwrap_used)]

pub mod camera;
pub mod clipmap;
pub mod compute;
pub mod context;
pub mod download;
pub mod error;
pub mod granular;
pub mod limits;
pub mod maps;
pub mod normals;
pub mod offscreen;
pub mod readback;
pub mod region_source;
pub mod scope;
pub mod sky;
pub mod stamp;
pub mod target;
pub mod testing;
pub mod timer;

pub use camera::Camera;
pub use clipmap::{ClipmapRenderer, ClipmapView, TerrainStyle};
pub use context::{AdapterReport, GpuContext};
pub use error::GpuError;
pub use limits::{MapUse, OPTIONAL_FEATURES, check_limits, required_limits};
pub use maps::{ExactInF32, GpuDerivativeMap, GpuHeightMap};
pub use normals::NormalPass;
pub use offscreen::OffscreenTarget;
pub use readback::{ReadbackTicket, RegionData, RegionReadback};
pub use region_source::GpuRegionSource;
pub use sky::{SkyColors, SkyPass};
pub use stamp::{GpuProceduralStamp, GpuStamp, GpuTextureStamp, StampPass};
pub use target::TargetFormat;
pub use timer::{GpuTimer, GpuTiming};

/// The glam of this crate's public API.
pub use glam;
/// The wgpu this crate is built against: use it to make devices and passes of the same version.
pub use wgpu;
