//! The three-pool streamed tile cache (Fikkan 2013, ch. 4-6, Flower 2010, sec.
//! 2.4.2 and 3.2.3): a world is a pyramid of square tiles behind a [`TileStore`] (local files
//! named by hex level / row / column, or the `object_store` crate for buckets), built from any
//! [`TileSource`] without holding the whole map; a [`RamPool`] fed by worker threads over
//! lock-free queues, selected by square area then spherical distance per level, within a byte
//! budget, with dirty tiles written back atomically off the frame thread; selection policies
//! (spherical, frustum with a motion-dependent margin, band regions) and a deterministic trace
//! simulator that compares them with LRU and Belady's optimum.
//!
//! Conventions: world metres, Y up, right-handed; tile column `x` runs along world X, row `y`
//! along world Z; level 0 is the finest, each level up is a 2x2 average of the one below.
//!
//! ```
//! use std::sync::Arc;
//! use glam::{UVec2, Vec3};
//! use terrain_cache::{
//!     build_world, CameraState, Layer, Manifest, ObjectTileStore, PoolConfig, ProceduralSource,
//!     RamPool, TileId, TileStore,
//! };
//! use terrain_core::{HeightEncoding, TerrainParams, WrapMode};
//!
//! // A 512 x 512 procedural world in 64-texel tiles, in memory (a folder: `FsStore::open`).
//! let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory()?);
//! let base = TerrainParams { size: UVec2::splat(64), ..TerrainParams::default() };
//! let source = ProceduralSource::new(UVec2::splat(512), &base, 2, 0.02)?;
//! let encoding = HeightEncoding::spanning::<u16>(0.0, 100.0)?;
//! let manifest = Manifest::new(UVec2::splat(512), 64, 1.0, encoding, WrapMode::Repeat)?;
//! let (world, report) = build_world(store, manifest, &source, &|_progress| true)?;
//! assert_eq!(report.tiles, 64 + 16 + 4 + 1);
//!
//! // A RAM pool of at most 64 tiles around the camera; `update` never blocks on I/O.
//! let mut pool = RamPool::new(world, PoolConfig::new(Layer::Height, 64 * 64 * 64 * 2))?;
//! let camera = CameraState::at(Vec3::new(100.0, 30.0, 100.0));
//! let here = TileId::new(0, 1, 1);
//! while pool.tile(here).is_none() {
//!     let frame = pool.update(&camera)?;
//!     assert!(frame.ram_bytes <= frame.budget_bytes);
//!     std::thread::sleep(std::time::Duration::from_millis(1));
//! }
//! // Deform it: the tile becomes dirty and is written back atomically by the writer thread.
//! pool.modify(here, |tile| tile.as_u16_mut().unwrap().as_mut_slice()[0] = 0)?;
//! pool.shutdown(std::time::Duration::from_secs(10))?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! The [`VramPool`] decides which loaded tiles to hold in a fixed number of GPU slots (frustum
//! with a turn-dependent margin, or band regions, per level; a per-frame upload budget in
//! bytes, nearest first; least recently wanted evicted first) and uploads them into any
//! [`terrain_core::TileUploadTarget`] (terrain-gpu's `GpuTileAtlas`, or terrain-core's CPU
//! `TileAtlas`), keeping the target's indirection table current so a renderer falls back to
//! the coarser resident level where a tile is missing. It reads the RAM pool through
//! [`RamTiles`]: [`RamPool::tile`], [`RamPool::generation`] (a modified tile is re-uploaded)
//! and [`RamPool::refreshed`] (coarser tiles rewritten on disk). A tile deformed on the GPU in
//! its slot is held there ([`VramPool::hold`]) while its changed rect is read back; the rect
//! goes into RAM with [`RamPool::write_rect`] (or a whole tile with [`RamPool::write`]) and
//! [`VramPool::release`] ends the hold. [`RamPool::read_region`] copies any level-0 rect out
//! of the loaded tiles (coarser data where a tile is missing), e.g. to fill a collision window.
//!
//! What a streamed world's frame drives once each, their GPU sides behind terrain-core's
//! contracts (this crate names no GPU type): [`TileStamps`] (stamps on resident tiles, through
//! a [`TileDeformer`]), [`detail::DetailCache::update_for_stamps`] (footprints in detail
//! tiles), [`GranularTrails`] (granular trails around moving objects, stepped on the CPU or
//! through a [`GranularStepper`]), [`WindowFill`] (a collision window refilled where coarser
//! data stood in; [`WindowFill::over`] is terrain-core's `WindowSource`, which
//! terrain-physics' `CollisionWindow::follow` takes) and [`OverlayWriter`] (holes and paint written on a thread of their own).

// docs.rs: label feature-gated items with the features they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]
#![warn(clippy::unwrap_used)]

mod convert;
pub mod detail;
pub mod error;
mod granular_trails;
mod granular_window;
mod hole_window;
pub mod lock;
pub mod manifest;
#[cfg(feature = "object-store")]
pub mod object;
mod overlay_pyramid;
mod overlay_stream;
mod overlay_writer;
pub mod overlays;
mod overview;
mod region_bounds;
pub mod store;
pub mod streamed_world;
pub mod tile;
pub mod tile_file;
pub mod tile_stamps;
pub mod world;

pub use convert::{ConvertReport, convert_world};
pub use error::CacheError;
pub use granular_trails::{
    CpuOnly, GranularStepper, GranularTrails, HandedBack, MAX_TAKE_TIMEOUT, SHIFT_TAG, TrailConfig,
    TrailFrame, TrailMeasure, TrailsError,
};
pub use granular_window::{GranularWindow, MAX_WINDOW_SIDE};
pub use hole_window::{HoleWindow, HoleWindowError, MAX_HOLE_WINDOW_SIDE};
pub use manifest::{DetailLayout, Manifest, TileFormat, tile_key};
#[cfg(feature = "object-store")]
pub use object::{ObjectStoreConfig, ObjectTileStore};
pub use overlay_stream::OverlayStream;
pub use overlay_writer::{OverlayChange, OverlayJob, OverlayWriter};
pub use overlays::{
    MAX_OVERLAY_REGION_CELLS, read_color, read_holes, read_paint, write_color, write_holes,
    write_paint,
};
pub use region_bounds::RegionBounds;
pub use store::{FsStore, TileStore};
pub use streamed_world::{OverlayUploadError, StreamedWorld, StreamedWorldError, WorldWritten};
pub use tile::{Layer, TileData, TileId};
pub use tile_file::{TileCodec, TileFileError};
pub use tile_stamps::{TileDeformer, TileStampError, TileStampReport, TileStamps};
pub use world::{LevelBounds, TileRead, World};
pub mod build;
pub use build::{
    BuildProgress, BuildReport, MapSource, ProceduralSource, Raw16Source, TileSource, build_world,
    rebuild_ancestors, rebuild_ancestors_shared, reduce_levels,
};
pub mod policy;
pub mod pool;
pub use policy::{
    BandSelection, CameraState, FrustumSelection, SelectionPolicy, SphericalSelection, TileGrid,
    Want,
};
pub use pool::{
    FrameReport, PoolConfig, PoolWindowSource, RamPool, RequestHandle, TileState, TileStatus,
    WindowFill,
};
pub mod vram;
pub use vram::{
    DEFAULT_UPLOAD_BUDGET_BYTES, RamTiles, VramConfig, VramError, VramPool, VramReport,
    VramSelection,
};
pub mod trace_sim;
/// The trace simulator's former module path, kept for existing code: [`trace_sim`].
#[doc(hidden)]
pub use trace_sim as sim;
pub use trace_sim::{CameraPath, SimConfig, SimPolicy, SimResult, comparison_table, simulate};
pub mod verify;
pub use verify::{
    Defect, DefectKind, RepairReport, VerifyError, VerifyOptions, VerifyProgress, VerifyReport,
    check_before_use, repair_world, verify_world,
};

/// The README's code blocks, compiled and run as doc tests so that they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

/// The glam of this crate's public API (its vectors), so callers use the same version.
pub use glam;

// Engines keep the pools in state shared across threads (Bevy's `Resource` is `Send + Sync`):
// a type that loses either fails this build.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<RamPool>();
    send_sync::<VramPool>();
    send_sync::<TileStamps<u8>>();
    send_sync::<World>();
};
