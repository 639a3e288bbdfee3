//! Three-pool streamed tile cache (stub docs, filled in below).
#![warn(missing_docs)]
#![warn(clippy::unwrap_used)]

pub mod error;
pub mod manifest;
#[cfg(feature = "object-store")]
pub mod object;
pub mod store;
pub mod tile;
pub mod world;

pub use error::CacheError;
pub use manifest::{DetailLayout, Manifest, tile_key};
#[cfg(feature = "object-store")]
pub use object::ObjectTileStore;
pub use store::{FsStore, TileStore};
pub use tile::{Layer, TileData, TileId};
pub use world::{LevelBounds, TileRead, World};
pub mod build;
pub use build::{BuildProgress, BuildReport, MapSource, ProceduralSource, Raw16Source, TileSource, build_world, rebuild_ancestors};
pub mod policy;
pub mod pool;
pub use policy::{BandSelection, CameraState, FrustumSelection, SelectionPolicy, SphericalSelection, TileGrid, Want};
pub use pool::{FrameReport, PoolConfig, RamPool, RequestHandle, TileState, TileStatus};
pub mod sim;
pub use sim::{CameraPath, SimConfig, SimPolicy, SimResult, comparison_table, simulate};
