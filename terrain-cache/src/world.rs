//! A world on a store: [`World`] (manifest + [`TileStore`]), tile encode / decode (`.tile` files,
//! [`tile_file`]; PNG16 heights and PNG8 detail through `terrain_core::io` in
//! worlds of format version 1), the shared zero tile, and the per-level min/max side files
//! ([`LevelBounds`]).

use crate::CacheError;
use crate::manifest::{MANIFEST_KEY, MAX_MANIFEST_BYTES, Manifest, TileFormat, bounds_key};
use crate::store::TileStore;
use crate::tile::{Layer, TileData, TileId};
use crate::tile_file::{self, TileCodec, TileFileError, TileIdentity};
use glam::UVec2;
use std::sync::{Arc, OnceLock};
use terrain_core::Grid;
use terrain_core::io::{ReadLimits, decode_png8, decode_png16, encode_png8, encode_png16};

/// What reading a tile found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TileRead {
    /// A stored tile, decoded.
    Stored(TileData),
    /// No file: the tile is the layer's shared zero tile ([`World::zero_tile`]).
    Zero,
}

/// A world: its [`Manifest`] and the store its tiles live in. Cheap to clone and share between
/// threads.
#[derive(Debug, Clone)]
pub struct World {
    store: Arc<dyn TileStore>,
    manifest: Manifest,
    zero: Arc<[OnceLock<Arc<TileData>>; Layer::ALL.len()]>,
}

impl World {
    /// Writes `manifest` (validated) to an empty or existing store and returns the world.
    pub fn create(store: Arc<dyn TileStore>, manifest: Manifest) -> Result<Self, CacheError> {
        manifest.validate()?;
        store.write(MANIFEST_KEY, manifest.to_json().as_bytes())?;
        Ok(Self::with_manifest(store, manifest))
    }

    /// Opens the world in `store`, reading and validating its manifest.
    pub fn open(store: Arc<dyn TileStore>) -> Result<Self, CacheError> {
        let manifest = read_manifest(store.as_ref())?;
        Ok(Self::with_manifest(store, manifest))
    }

    /// The world without writing its manifest (the builder writes it last).
    pub(crate) fn unwritten(store: Arc<dyn TileStore>, manifest: Manifest) -> Self {
        Self::with_manifest(store, manifest)
    }

    fn with_manifest(store: Arc<dyn TileStore>, manifest: Manifest) -> Self {
        Self {
            store,
            manifest,
            zero: Arc::new(std::array::from_fn(|_| OnceLock::new())),
        }
    }

    /// The layout.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The store.
    pub fn store(&self) -> &Arc<dyn TileStore> {
        &self.store
    }

    /// Rewrites the manifest atomically with `generation` bumped (the layout itself is fixed at
    /// creation: only the detail layer may be added or the zero tile changed before tiles
    /// exist).
    pub fn update_manifest(&mut self, edit: impl FnOnce(&mut Manifest)) -> Result<(), CacheError> {
        let mut m = self.manifest;
        edit(&mut m);
        m.generation = self.manifest.generation.wrapping_add(1);
        m.validate()?;
        self.store.write(MANIFEST_KEY, m.to_json().as_bytes())?;
        self.manifest = m;
        self.zero = Arc::new(std::array::from_fn(|_| OnceLock::new()));
        Ok(())
    }

    /// The shared zero tile of `layer`: every sample the layer's fill value. One allocation per
    /// world and layer, shared by every tile that has no file (copy it before writing: see
    /// [`RamPool::modify`](crate::RamPool::modify)).
    pub fn zero_tile(&self, layer: Layer) -> Result<Arc<TileData>, CacheError> {
        let slot = &self.zero[layer as usize];
        if let Some(z) = slot.get() {
            return Ok(z.clone());
        }
        let size = self.manifest.layer_tile_size(layer)?;
        let fill = self.manifest.layer_fill(layer)?;
        let z = Arc::new(TileData::filled(layer, size, fill)?);
        Ok(slot.get_or_init(|| z).clone())
    }

    /// Largest file a valid tile of `layer` can take (a `.tile` file's worst case, or an
    /// uncompressed PNG with generous overhead); longer files are refused unread.
    pub fn max_tile_file_bytes(&self, layer: Layer) -> u64 {
        let side = self.manifest.layer_tile_size(layer).unwrap_or(0);
        match self.manifest.tile_format {
            TileFormat::Tile => tile_file::max_file_len(side, layer.bits()),
            TileFormat::Png => {
                let size = u64::from(side);
                let raw = size * (size * u64::from(layer.bits() / 8) + 1);
                2 * raw + 65536
            }
        }
    }

    /// Reads tile `id` of `layer`: the decoded samples, or [`TileRead::Zero`] if it has no file.
    ///
    /// A corrupt, truncated or foreign file is an error naming the tile
    /// ([`CacheError::CorruptTile`], [`CacheError::WrongTileShape`],
    /// [`CacheError::TileTooLarge`]), never a panic.
    pub fn read_tile(&self, layer: Layer, id: TileId) -> Result<TileRead, CacheError> {
        self.manifest.check_tile(layer, id)?;
        let max = self.max_tile_file_bytes(layer);
        let bytes = match self.store.read(&self.manifest.tile_key(layer, id), max) {
            Ok(Some(b)) => b,
            Ok(None) => return Ok(TileRead::Zero),
            Err(CacheError::TooLarge { len, max, .. }) => {
                return Err(CacheError::TileTooLarge {
                    layer,
                    id,
                    len,
                    max,
                });
            }
            Err(e) => return Err(e),
        };
        self.decode_tile(layer, id, &bytes).map(TileRead::Stored)
    }

    /// Reads tile `id`, with the zero tile as a shared allocation.
    pub fn load_tile(&self, layer: Layer, id: TileId) -> Result<Arc<TileData>, CacheError> {
        match self.read_tile(layer, id)? {
            TileRead::Stored(d) => Ok(Arc::new(d)),
            TileRead::Zero => self.zero_tile(layer),
        }
    }

    /// Decodes the bytes of the file of tile `id` of `layer` and checks its shape and, for a
    /// `.tile` file that names its tile (version 2), that it names this one.
    pub fn decode_tile(
        &self,
        layer: Layer,
        id: TileId,
        bytes: &[u8],
    ) -> Result<TileData, CacheError> {
        let size = self.manifest.layer_tile_size(layer)?;
        let corrupt = |source| CacheError::CorruptTile { layer, id, source };
        let data = match self.manifest.tile_format {
            TileFormat::Tile => {
                match tile_file::decode_as(bytes, TileIdentity::new(layer, id), size) {
                    Ok(d) => d,
                    Err(TileFileError::Shape {
                        found_w, found_h, ..
                    }) => {
                        return Err(CacheError::WrongTileShape {
                            layer,
                            id,
                            expected: size,
                            found_w,
                            found_h,
                        });
                    }
                    Err(e) => return Err(corrupt(e)),
                }
            }
            TileFormat::Png => {
                let limits = ReadLimits {
                    max_side: size,
                    ..ReadLimits::default()
                };
                let png = |e| corrupt(TileFileError::Png(e));
                match layer {
                    Layer::Height => TileData::U16(decode_png16(bytes, &limits).map_err(png)?),
                    Layer::Detail | Layer::Hole => {
                        TileData::U8(decode_png8(bytes, &limits).map_err(png)?)
                    }
                    Layer::Material | Layer::Color => {
                        return Err(CacheError::NoSuchLayer { layer });
                    }
                }
            }
        };
        let s = data.size();
        if s != UVec2::splat(size) {
            return Err(CacheError::WrongTileShape {
                layer,
                id,
                expected: size,
                found_w: s.x,
                found_h: s.y,
            });
        }
        Ok(data)
    }

    /// Checks that `data` has `layer`'s sample type and tile size.
    pub fn check_data(&self, layer: Layer, data: &TileData) -> Result<(), CacheError> {
        let size = self.manifest.layer_tile_size(layer)?;
        let s = data.size();
        if data.bits() != layer.bits() || s != UVec2::splat(size) {
            return Err(CacheError::TileDataMismatch {
                layer,
                expected_bits: layer.bits(),
                size,
                found_bits: data.bits(),
                found_w: s.x,
                found_h: s.y,
            });
        }
        Ok(())
    }

    /// Encodes a tile as its file bytes: a `.tile` file with the layer's codec
    /// ([`TileCodec::for_layer`]) and no identity (version 1, valid at any tile's path), or
    /// PNG16 / PNG8 in a world of PNG tiles. [`write_tile`](Self::write_tile) writes the
    /// file naming its tile ([`encode_tile_as`](Self::encode_tile_as)).
    pub fn encode_tile(&self, layer: Layer, data: &TileData) -> Result<Vec<u8>, CacheError> {
        self.encode_with(layer, None, data)
    }

    /// Encodes tile `id` of `layer` as its file bytes: a `.tile` file naming the tile (version
    /// 2, refused at any other tile's path), or PNG16 / PNG8 in a world of PNG tiles.
    pub fn encode_tile_as(
        &self,
        layer: Layer,
        id: TileId,
        data: &TileData,
    ) -> Result<Vec<u8>, CacheError> {
        self.encode_with(layer, Some(TileIdentity::new(layer, id)), data)
    }

    fn encode_with(
        &self,
        layer: Layer,
        identity: Option<TileIdentity>,
        data: &TileData,
    ) -> Result<Vec<u8>, CacheError> {
        self.check_data(layer, data)?;
        if self.manifest.tile_format == TileFormat::Tile {
            let codec = TileCodec::for_layer(layer);
            return Ok(match identity {
                Some(identity) => tile_file::encode_as(data, codec, identity),
                None => tile_file::encode(data, codec),
            });
        }
        let encoded = match data {
            TileData::U16(g) => encode_png16(g),
            TileData::U8(g) => encode_png8(g),
            TileData::Rgba8(_) => return Err(CacheError::NoSuchLayer { layer }),
        };
        encoded.map_err(|source| CacheError::Write {
            key: String::new(),
            source,
        })
    }

    /// Writes tile `id` atomically. A tile equal to the zero tile is not stored: its file is
    /// removed (also atomic), so it reads as the shared zero tile again.
    ///
    /// Returns the bytes of the file written, 0 when the tile is the zero tile (no file).
    pub fn write_tile(&self, layer: Layer, id: TileId, data: &TileData) -> Result<u64, CacheError> {
        self.manifest.check_tile(layer, id)?;
        self.check_data(layer, data)?;
        let key = self.manifest.tile_key(layer, id);
        if data.uniform_value() == Some(self.manifest.layer_fill(layer)?) {
            self.store.remove(&key)?;
            return Ok(0);
        }
        let bytes = self.encode_tile_as(layer, id, data).map_err(|e| match e {
            CacheError::Write { source, .. } => CacheError::Write {
                key: key.clone(),
                source,
            },
            other => other,
        })?;
        self.store.write(&key, &bytes)?;
        Ok(bytes.len() as u64)
    }

    /// What [`write_tile`](Self::write_tile) of a height tile held as a bare grid stores: its
    /// key and file bytes, `None` for a tile equal to the zero tile (its file is removed). The
    /// builder encodes on its compute threads and writes on its I/O threads.
    pub(crate) fn encode_grid16(
        &self,
        id: TileId,
        grid: &Grid<u16>,
    ) -> Result<(String, Option<Vec<u8>>), CacheError> {
        let key = self.manifest.tile_key(Layer::Height, id);
        if grid
            .as_slice()
            .iter()
            .all(|&v| v == self.manifest.height_fill)
        {
            return Ok((key, None));
        }
        let bytes = match self.manifest.tile_format {
            TileFormat::Tile => tile_file::encode_u16_with(
                grid,
                TileCodec::for_layer(Layer::Height),
                Some(TileIdentity::new(Layer::Height, id)),
            ),
            TileFormat::Png => encode_png16(grid).map_err(|source| CacheError::Write {
                key: key.clone(),
                source,
            })?,
        };
        Ok((key, Some(bytes)))
    }

    /// The min/max side file of height level `level`, if it was written.
    pub fn bounds(&self, level: u32) -> Result<Option<LevelBounds>, CacheError> {
        let tiles = self.manifest.layer_tiles(Layer::Height, level);
        if tiles == UVec2::ZERO {
            return Err(CacheError::TileOutOfRange {
                id: TileId::new(level, 0, 0),
                levels: self.manifest.levels,
                tiles_x: 0,
                tiles_y: 0,
            });
        }
        let key = bounds_key(Layer::Height, level);
        let max = LevelBounds::file_len(tiles);
        match self.store.read(&key, max)? {
            None => Ok(None),
            Some(bytes) => LevelBounds::from_bytes(&bytes, tiles)
                .map(Some)
                .map_err(|reason| CacheError::Manifest { key, reason }),
        }
    }

    /// Writes the min/max side file of height level `level` atomically.
    pub fn write_bounds(&self, level: u32, bounds: &LevelBounds) -> Result<(), CacheError> {
        let tiles = self.manifest.layer_tiles(Layer::Height, level);
        if bounds.tiles != tiles
            || bounds.min_max.len() as u64 != u64::from(tiles.x) * u64::from(tiles.y)
        {
            return Err(CacheError::OutOfRange {
                what: "bounds tiles",
                value: f64::from(bounds.tiles.x) * f64::from(bounds.tiles.y),
                expected: "the level's tiles across times down",
            });
        }
        self.store
            .write(&bounds_key(Layer::Height, level), &bounds.to_bytes())
    }
}

/// Reads and validates the manifest of `store`.
pub fn read_manifest(store: &dyn TileStore) -> Result<Manifest, CacheError> {
    let bytes = store
        .read(MANIFEST_KEY, MAX_MANIFEST_BYTES)?
        .ok_or_else(|| CacheError::Manifest {
            key: MANIFEST_KEY.into(),
            reason: "missing: not a world (or not yet built)".into(),
        })?;
    let text = std::str::from_utf8(&bytes).map_err(|e| CacheError::Manifest {
        key: MANIFEST_KEY.into(),
        reason: format!("not UTF-8: {e}"),
    })?;
    Manifest::from_json(text)
}

/// Per-tile bounds of one height level: the smallest and largest level-0 sample under each
/// tile (so coarser levels bound the finest data, as CDLOD needs), row-major.
///
/// File format (`height/{level:02x}/bounds.bin`): `b"TCBN"`, version 1, tiles across, tiles
/// down (u32 little-endian each), then `[min, max]` as u16 little-endian per tile, then an
/// FNV-1a 64 checksum of everything before it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LevelBounds {
    /// Tiles across and down.
    pub tiles: UVec2,
    /// `[min, max]` per tile, row-major.
    pub min_max: Vec<[u16; 2]>,
}

impl LevelBounds {
    const MAGIC: &'static [u8; 4] = b"TCBN";

    /// Bounds of `tiles` tiles, all `[u16::MAX, 0]` (empty).
    pub fn empty(tiles: UVec2) -> Self {
        Self {
            tiles,
            min_max: vec![[u16::MAX, 0]; tiles.x as usize * tiles.y as usize],
        }
    }

    /// The `[min, max]` of tile `(x, y)`.
    pub fn get(&self, x: u32, y: u32) -> Option<[u16; 2]> {
        if x >= self.tiles.x || y >= self.tiles.y {
            return None;
        }
        self.min_max
            .get(y as usize * self.tiles.x as usize + x as usize)
            .copied()
    }

    /// Bytes of the file of `tiles` tiles. Saturating: a tile count given to
    /// [`from_bytes`](Self::from_bytes) may be anything up to `u32::MAX` per side, whose file
    /// would not fit in a `u64` (the fuzz target `bounds` found the overflow); no slice is that
    /// long, so a saturated length is simply never matched.
    fn file_len(tiles: UVec2) -> u64 {
        4u64.saturating_mul(u64::from(tiles.x))
            .saturating_mul(u64::from(tiles.y))
            .saturating_add(16 + 8)
    }

    /// The file bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        // Sized from the entries actually written, not from `tiles`: the fields are public and
        // may disagree, and a capacity from a large `tiles` aborted on allocation (found by the
        // fuzz target `bounds`).
        let mut out = Vec::with_capacity(24 + 4 * self.min_max.len());
        out.extend_from_slice(Self::MAGIC);
        out.extend_from_slice(&1u32.to_le_bytes());
        out.extend_from_slice(&self.tiles.x.to_le_bytes());
        out.extend_from_slice(&self.tiles.y.to_le_bytes());
        for [lo, hi] in &self.min_max {
            out.extend_from_slice(&lo.to_le_bytes());
            out.extend_from_slice(&hi.to_le_bytes());
        }
        let sum = fnv1a(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }

    /// Parses file bytes, expecting `tiles`.
    pub fn from_bytes(bytes: &[u8], tiles: UVec2) -> Result<Self, String> {
        if bytes.len() as u64 != Self::file_len(tiles) {
            return Err(format!(
                "{} bytes, expected {} for {}x{} tiles",
                bytes.len(),
                Self::file_len(tiles),
                tiles.x,
                tiles.y
            ));
        }
        let (body, sum) = bytes.split_at(bytes.len() - 8);
        let u32_at =
            |i: usize| u32::from_le_bytes([body[i], body[i + 1], body[i + 2], body[i + 3]]);
        if &body[..4] != Self::MAGIC || u32_at(4) != 1 {
            return Err("not a version-1 bounds file".into());
        }
        if UVec2::new(u32_at(8), u32_at(12)) != tiles {
            return Err("tile counts differ from the manifest".into());
        }
        if fnv1a(body).to_le_bytes() != sum {
            return Err("checksum mismatch".into());
        }
        let min_max = body[16..]
            .chunks_exact(4)
            .map(|c| {
                [
                    u16::from_le_bytes([c[0], c[1]]),
                    u16::from_le_bytes([c[2], c[3]]),
                ]
            })
            .collect();
        Ok(Self { tiles, min_max })
    }
}

fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifest::DetailLayout;
    use crate::object::ObjectTileStore;
    use terrain_core::{HeightEncoding, WrapMode};

    fn world() -> World {
        let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let mut m = Manifest::new(
            UVec2::new(100, 70),
            32,
            1.0,
            HeightEncoding::spanning::<u16>(0.0, 10.0).unwrap(),
            WrapMode::Clamp,
        )
        .unwrap();
        m.detail = Some(DetailLayout::covering(glam::Vec2::new(100.0, 70.0), 16, 0.5).unwrap());
        World::create(store, m).unwrap()
    }

    #[test]
    fn tiles_round_trip_and_zero_tile_is_shared() {
        let w = world();
        let id = TileId::new(0, 3, 2);
        assert_eq!(w.read_tile(Layer::Height, id).unwrap(), TileRead::Zero);
        let a = w.load_tile(Layer::Height, id).unwrap();
        let b = w.load_tile(Layer::Height, TileId::new(0, 0, 0)).unwrap();
        assert!(Arc::ptr_eq(&a, &b), "one shared zero tile");
        let data = TileData::U16(Grid::from_fn(32, 32, |x, y| (x * 100 + y) as u16).unwrap());
        assert!(w.write_tile(Layer::Height, id, &data).unwrap() > 0);
        assert_eq!(
            w.read_tile(Layer::Height, id).unwrap(),
            TileRead::Stored(data)
        );
        // Writing the zero tile removes the file.
        assert_eq!(w.write_tile(Layer::Height, id, &a).unwrap(), 0);
        assert_eq!(w.read_tile(Layer::Height, id).unwrap(), TileRead::Zero);
        // Detail tiles: u8 (LZ4 .tile files), fill = zero deformation.
        let d = w.zero_tile(Layer::Detail).unwrap();
        assert_eq!(
            d.uniform_value(),
            Some(u16::from(w.manifest().detail.unwrap().fill))
        );
        let mut dd = (*d).clone();
        dd.as_u8_mut().unwrap().as_mut_slice()[5] = 3;
        w.write_tile(Layer::Detail, TileId::new(0, 1, 1), &dd)
            .unwrap();
        assert_eq!(
            w.read_tile(Layer::Detail, TileId::new(0, 1, 1)).unwrap(),
            TileRead::Stored(dd)
        );
        // Wrong data for the layer.
        assert!(matches!(
            w.write_tile(Layer::Detail, id, &a),
            Err(CacheError::TileDataMismatch { .. })
        ));
        let reopened = World::open(w.store().clone()).unwrap();
        assert_eq!(reopened.manifest(), w.manifest());
    }

    #[test]
    fn bounds_round_trip_and_reject_garbage() {
        let w = world();
        let t = w.manifest().tiles_at(1);
        let mut b = LevelBounds::empty(t);
        b.min_max[1] = [3, 9];
        w.write_bounds(1, &b).unwrap();
        assert_eq!(w.bounds(1).unwrap().unwrap(), b);
        assert_eq!(w.bounds(1).unwrap().unwrap().get(1, 0), Some([3, 9]));
        assert_eq!(w.bounds(0).unwrap(), None);
        let mut bytes = b.to_bytes();
        bytes[17] ^= 1;
        w.store()
            .write(&bounds_key(Layer::Height, 1), &bytes)
            .unwrap();
        assert!(matches!(w.bounds(1), Err(CacheError::Manifest { .. })));
        assert!(w.bounds(40).is_err());
    }
}
