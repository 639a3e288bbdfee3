//! The crate's error type: [`CacheError`], one enum whose variants carry the offending values.

use crate::tile::{Layer, TileId};
use std::path::PathBuf;
use terrain_core::{CoreError, MapIoError};

/// Everything that can go wrong in terrain-cache.
///
/// Tile-level failures ([`CacheError::CorruptTile`], [`CacheError::TileTooLarge`],
/// [`CacheError::WrongTileShape`]) name the tile, so a pool can report them and treat the tile
/// as missing.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// A key given to a [`TileStore`](crate::TileStore) is not a clean relative path.
    #[error("invalid store key {key:?}: {reason}")]
    InvalidKey {
        /// The key as given.
        key: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A file of the local store could not be read, written, synced, renamed or listed.
    #[error("I/O error on {}: {source}", path.display())]
    Io {
        /// The file or folder the operation was on.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// Another process writes to this world folder (it holds the folder's lock, see
    /// [`FsStore::open`](crate::FsStore::open)); open it read-only or wait for that process.
    #[error("the world in {} is in use by {owner}", dir.display())]
    WorldLocked {
        /// The world folder.
        dir: PathBuf,
        /// Who holds it, as its lock file says (pid, host, start time).
        owner: String,
    },
    /// A write or remove on a store opened read-only.
    #[error("store opened read-only: cannot {op} {key:?}")]
    ReadOnly {
        /// The operation (`write`, `remove`).
        op: &'static str,
        /// The store key.
        key: String,
    },
    /// A file or folder inside a world folder is a symbolic link: it could lead reads and
    /// writes anywhere, so the store refuses it.
    #[error("{} is a symbolic link inside the world folder; links are refused", path.display())]
    LinkInWorld {
        /// The link.
        path: PathBuf,
    },
    /// An atomic file write failed (terrain-core's writer: temp file, fsync, rename, dir fsync).
    #[error("writing {key:?} failed: {source}")]
    Write {
        /// The store key.
        key: String,
        /// The cause.
        #[source]
        source: MapIoError,
    },
    /// An `object_store` operation failed.
    #[cfg(feature = "object-store")]
    #[error("object store operation {op} on {key:?} failed: {source}")]
    ObjectStore {
        /// The operation (`get`, `put`, `head`, `list`, `delete`).
        op: &'static str,
        /// The store key.
        key: String,
        /// The cause.
        #[source]
        source: object_store::Error,
    },
    /// A conditional write was refused: the object changed (or was created or deleted) since
    /// this store last read it, so writing would silently replace another writer's version.
    /// Read the key again and reapply the change (see `ObjectTileStore`, module `object`).
    #[error("{key:?} was changed by another writer since it was read; not overwritten")]
    Conflict {
        /// The store key.
        key: String,
    },
    /// A store URL could not be parsed or names a scheme this build does not support.
    #[error("store URL {url:?}: {reason}")]
    InvalidUrl {
        /// The URL as given.
        url: String,
        /// What is wrong (the parser's or object_store's message).
        reason: String,
    },
    /// A blocking store call was made from inside an async runtime, where blocking on the
    /// object store's own runtime would deadlock; call it from a plain thread.
    #[error("blocking object-store call {op} made from inside an async runtime")]
    InsideAsyncRuntime {
        /// The operation.
        op: &'static str,
    },
    /// A stored object is larger than the reader accepts (a foreign file where a tile or the
    /// manifest should be).
    #[error("{key:?} is {len} bytes, more than the {max} accepted")]
    TooLarge {
        /// The store key.
        key: String,
        /// Its length in bytes.
        len: u64,
        /// The limit.
        max: u64,
    },
    /// A tile file could not be decoded (corrupt, truncated, a checksum mismatch, not a tile or
    /// PNG, wrong bit depth).
    #[error("tile {layer:?} {id} is corrupt: {source}")]
    CorruptTile {
        /// The layer.
        layer: Layer,
        /// The tile.
        id: TileId,
        /// The decoder's report.
        #[source]
        source: crate::tile_file::TileFileError,
    },
    /// A tile file decodes but has the wrong size (a foreign image).
    #[error("tile {layer:?} {id} is {found_w}x{found_h} texels, the world says {expected}")]
    WrongTileShape {
        /// The layer.
        layer: Layer,
        /// The tile.
        id: TileId,
        /// The tile size of the manifest.
        expected: u32,
        /// The width found.
        found_w: u32,
        /// The height found.
        found_h: u32,
    },
    /// A tile file is larger than any valid tile of this world can be.
    #[error("tile {layer:?} {id} file is {len} bytes, more than the {max} a valid tile can take")]
    TileTooLarge {
        /// The layer.
        layer: Layer,
        /// The tile.
        id: TileId,
        /// Its length.
        len: u64,
        /// The limit.
        max: u64,
    },
    /// A tile id lies outside the world's pyramid.
    #[error("tile {id} is outside the pyramid ({levels} levels, level {} has {tiles_x}x{tiles_y} tiles)", id.level)]
    TileOutOfRange {
        /// The tile.
        id: TileId,
        /// Levels of the pyramid.
        levels: u32,
        /// Tiles across the tile's level (0 if the level does not exist).
        tiles_x: u32,
        /// Tiles down the tile's level (0 if the level does not exist).
        tiles_y: u32,
    },
    /// The world has no such layer (a detail tile asked of a world without a detail layer).
    #[error("the world has no {layer:?} layer")]
    NoSuchLayer {
        /// The layer asked for.
        layer: Layer,
    },
    /// Tile data of the wrong sample type or size was handed to a layer.
    #[error(
        "{layer:?} tiles are {expected_bits}-bit {size}x{size}; got {found_bits}-bit {found_w}x{found_h}"
    )]
    TileDataMismatch {
        /// The layer.
        layer: Layer,
        /// Bits per sample the layer stores.
        expected_bits: u8,
        /// Tile side of the layer.
        size: u32,
        /// Bits per sample given.
        found_bits: u8,
        /// Width given.
        found_w: u32,
        /// Height given.
        found_h: u32,
    },
    /// The manifest is missing, not valid JSON or of another format.
    #[error("manifest {key:?}: {reason}")]
    Manifest {
        /// The store key of the manifest.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// The manifest's format version is not one this build reads.
    #[error(
        "manifest format version {found} is not supported (this build reads versions 1 to {supported})"
    )]
    ManifestVersion {
        /// The version found.
        found: u32,
        /// The version this build reads.
        supported: u32,
    },
    /// A parameter (of the manifest, a config, a camera) is out of its valid range.
    #[error("{what} = {value} is out of range: expected {expected}")]
    OutOfRange {
        /// The parameter.
        what: &'static str,
        /// The value given.
        value: f64,
        /// The valid range.
        expected: &'static str,
    },
    /// A tile source failed to produce a region.
    #[error("tile source failed on level-0 tile {id}: {source}")]
    Source {
        /// The tile being built.
        id: TileId,
        /// The source's own error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The build was cancelled by its progress callback.
    #[error("build cancelled after {done} of {total} tiles")]
    Cancelled {
        /// Tiles finished.
        done: u64,
        /// Tiles in all.
        total: u64,
    },
    /// The memory budget does not allow the operation (a copy-on-write of a tile whose
    /// previous version is still being written back, with no evictable tile left).
    #[error("RAM budget of {budget} bytes exceeded: {needed} more bytes needed, {used} in use")]
    OverBudget {
        /// The budget.
        budget: u64,
        /// Bytes in use.
        used: u64,
        /// Bytes the operation needs.
        needed: u64,
    },
    /// The tile is not resident in the pool (it must be loaded before it can be modified).
    #[error("tile {id} is not loaded in the RAM pool")]
    NotResident {
        /// The tile.
        id: TileId,
    },
    /// A wait (pool flush, shutdown) ran out of time.
    #[error("{what} did not finish within {timeout_ms} ms")]
    Timeout {
        /// What was waited for.
        what: &'static str,
        /// The timeout.
        timeout_ms: u64,
    },
    /// A worker thread is gone (it panicked or could not be spawned).
    #[error("worker thread {what}: {reason}")]
    Worker {
        /// Which worker.
        what: &'static str,
        /// What happened.
        reason: String,
    },
    /// A tile upload target does not index the world or hold the slots a VRAM pool needs.
    #[error("the upload target's {what} is {target}, the VRAM pool needs {pool}")]
    TargetMismatch {
        /// What differs (tile size, levels, tiles of a level, slots).
        what: &'static str,
        /// What the pool needs.
        pool: u64,
        /// What the target has.
        target: u64,
    },
    /// A grid operation of terrain-core failed.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A granular hand-over of terrain-core refused its input.
    #[error(transparent)]
    Granular(#[from] terrain_core::granular::GranularError),
}
