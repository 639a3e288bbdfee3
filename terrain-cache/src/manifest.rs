//! The world layout: [`Manifest`] (format version, tile file format, tile size, levels, texel
//! size, height encoding, wrap mode, world size, the zero tile's value, the optional detail
//! layer), stored as a small JSON file, and the store keys of tiles (folders per level and row,
//! hex names, Fikkan 2013, fig. 5.1).

use crate::CacheError;
use crate::tile::{Layer, TileId};
use glam::{DVec2, UVec2};
use serde::{Deserialize, Serialize};
use terrain_core::{HeightEncoding, WrapMode};

/// The manifest format version this build writes: 2, whose tiles are `.tile` files
/// ([`TileFormat::Tile`]). It also reads and keeps writing version 1, whose tiles are PNG.
pub const FORMAT_VERSION: u32 = 2;
/// The oldest manifest format version this build reads (PNG tiles).
pub const OLDEST_FORMAT_VERSION: u32 = 1;

/// How a world's tile files are encoded (both layers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TileFormat {
    /// PNG16 heights and PNG8 detail, `.png`: worlds of format version 1, which open and are
    /// written back as they are ([`convert_world`](crate::convert_world) rewrites one as
    /// [`TileFormat::Tile`]).
    Png,
    /// The `.tile` file of [`tile_file`](crate::tile_file): a 24-byte header with a CRC-32,
    /// raw heights, LZ4-compressed detail. Format version 2.
    Tile,
}

impl TileFormat {
    /// The file name extension of its tiles (without the dot).
    pub const fn extension(self) -> &'static str {
        match self {
            TileFormat::Png => "png",
            TileFormat::Tile => "tile",
        }
    }

    /// The manifest format version that records it.
    pub const fn format_version(self) -> u32 {
        match self {
            TileFormat::Png => 1,
            TileFormat::Tile => 2,
        }
    }
}
/// The store key of the manifest.
pub const MANIFEST_KEY: &str = "manifest.json";
/// Largest manifest file accepted, in bytes (it is a few hundred bytes when valid).
pub const MAX_MANIFEST_BYTES: u64 = 64 * 1024;
/// Default tile side in texels (Fikkan 2013, sec. 5.1: 256 x 256 blocks).
pub const DEFAULT_TILE_SIZE: u32 = 256;
/// Most tiles along one side of a level: four hex digits in a file name (Fikkan 2013, sec. 5.1:
/// "the current limit of blocks are 65536").
pub const MAX_TILES_PER_SIDE: u32 = 65536;
/// Most tiles in one level (level 0 has the most): the tables kept per tile (bounds, a
/// build's progress, a verification's marks) stay within a few hundred MiB, whatever a
/// manifest says. 2^24 tiles of 256^2 texels are a world of 1 048 576^2 texels.
pub const MAX_LEVEL_TILES: u64 = 1 << 24;
/// The most metres the u16 heights of a world may span.
const MAX_HEIGHT_SPAN_M: f64 = 1e9;
/// Smallest accepted tile side.
pub const MIN_TILE_SIZE: u32 = 16;
/// Largest accepted tile side (Flower 2010's 2048 detail tiles fit).
pub const MAX_TILE_SIZE: u32 = 4096;

/// The optional detail layer (Flower 2010, sec. 2.4.2): one level of u8 tiles over the world, all
/// sharing the zero tile until first written.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetailLayout {
    /// Tile side in texels (power of two).
    pub tile_size: u32,
    /// Tiles across and down.
    pub tiles: UVec2,
    /// Metres per detail texel.
    pub texel_size: f32,
    /// Detail height encoding (at most 1 m of range, as terrain-core's `DetailTile`).
    pub encoding: HeightEncoding,
    /// The value of the zero tile (no deformation); tiles equal to it are not stored.
    pub fill: u8,
}

impl DetailLayout {
    /// Detail tiles of `tile_size` covering a world of `extent_m` metres at `texel_size` metres
    /// per texel, encoded over `[-0.5, 0.5]` m, zero deformation as the fill.
    pub fn covering(
        extent_m: glam::Vec2,
        tile_size: u32,
        texel_size: f32,
    ) -> Result<Self, CacheError> {
        check_tile_size(tile_size)?;
        check_positive("detail texel_size", texel_size)?;
        let tile_m = f64::from(tile_size) * f64::from(texel_size);
        let tiles = (extent_m.as_dvec2() / tile_m).ceil().max(DVec2::ONE);
        if tiles.max_element() > f64::from(MAX_TILES_PER_SIDE) {
            return Err(CacheError::OutOfRange {
                what: "detail tiles per side",
                value: tiles.max_element(),
                expected: "at most 65536",
            });
        }
        let encoding = HeightEncoding::spanning::<u8>(-0.5, 0.5)?;
        let fill = encoding.to_raw(0.0).round().clamp(0.0, 255.0) as u8;
        Ok(Self {
            tile_size,
            tiles: tiles.as_uvec2(),
            texel_size,
            encoding,
            fill,
        })
    }
}

/// The layout of a world: everything needed to name, decode and place its tiles.
///
/// Level 0 is the finest; level `l` has `ceil(world_size / 2^l)` texels, made from level
/// `l - 1` by 2x2 averaging (rounded to nearest), cut into square tiles of `tile_size`. The
/// samples of an edge tile beyond its level's size repeat the last valid sample of their row or
/// column (clamped padding), so every tile is built from itself and its four children only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Manifest {
    /// Format version: [`FORMAT_VERSION`], or 1 for a world of PNG tiles; always
    /// `tile_format.format_version()`.
    pub format_version: u32,
    /// How the tile files are encoded.
    pub tile_format: TileFormat,
    /// Tile side in texels, a power of two in `16..=4096` (default 256).
    pub tile_size: u32,
    /// Level-0 size in texels.
    pub world_size: UVec2,
    /// Levels in the pyramid, `1..=max_levels()`.
    pub levels: u32,
    /// Metres per texel at level 0.
    pub texel_size: f32,
    /// Stored u16 to metres.
    pub encoding: HeightEncoding,
    /// How the world is addressed beyond its edges (a coarse-map wraps).
    pub wrap: WrapMode,
    /// The value of the shared zero tile of the height layer: a tile all of whose samples equal
    /// it is not stored, and a missing tile file reads as it.
    pub height_fill: u16,
    /// Bumped on every rewrite of the manifest.
    pub generation: u64,
    /// The detail layer, if the world has one.
    pub detail: Option<DetailLayout>,
}

impl Manifest {
    /// A manifest for a world of `world_size` texels with every level down to one tile.
    pub fn new(
        world_size: UVec2,
        tile_size: u32,
        texel_size: f32,
        encoding: HeightEncoding,
        wrap: WrapMode,
    ) -> Result<Self, CacheError> {
        let mut m = Self {
            format_version: FORMAT_VERSION,
            tile_format: TileFormat::Tile,
            tile_size,
            world_size,
            levels: 1,
            texel_size,
            encoding,
            wrap,
            height_fill: 0,
            generation: 0,
            detail: None,
        };
        check_tile_size(tile_size)?;
        m.levels = m.max_levels();
        m.validate()?;
        Ok(m)
    }

    /// Checks every field; a manifest read from a store is validated before use.
    pub fn validate(&self) -> Result<(), CacheError> {
        if !(OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&self.format_version) {
            return Err(CacheError::ManifestVersion {
                found: self.format_version,
                supported: FORMAT_VERSION,
            });
        }
        if self.format_version != self.tile_format.format_version() {
            return Err(CacheError::Manifest {
                key: MANIFEST_KEY.into(),
                reason: format!(
                    "format version {} does not have {:?} tiles",
                    self.format_version, self.tile_format
                ),
            });
        }
        check_tile_size(self.tile_size)?;
        if self.world_size.min_element() == 0 {
            return Err(CacheError::OutOfRange {
                what: "world size (texels)",
                value: f64::from(self.world_size.min_element()),
                expected: "at least 1 on each side",
            });
        }
        let tiles0 = self.tiles_at(0);
        if tiles0.max_element() > MAX_TILES_PER_SIDE {
            return Err(CacheError::OutOfRange {
                what: "level-0 tiles per side",
                value: f64::from(tiles0.max_element()),
                expected: "at most 65536 (four hex digits)",
            });
        }
        let level_tiles = u64::from(tiles0.x) * u64::from(tiles0.y);
        if level_tiles > MAX_LEVEL_TILES {
            return Err(CacheError::OutOfRange {
                what: "level-0 tiles",
                value: level_tiles as f64,
                expected: "at most 2^24 (16 777 216)",
            });
        }
        if self.levels == 0 || self.levels > self.max_levels() {
            return Err(CacheError::OutOfRange {
                what: "levels",
                value: f64::from(self.levels),
                expected: "1 ..= levels down to a single tile",
            });
        }
        check_positive("texel_size", self.texel_size)?;
        HeightEncoding::new(self.encoding.scale, self.encoding.offset)?;
        // Heights a world can hold and deform: a stored unit of 1 nm at least (finer steps
        // have no fixed-point scale for granular trails) and a u16 span of at most 1e9 m.
        let scale = f64::from(self.encoding.scale);
        if !(1e-9..=MAX_HEIGHT_SPAN_M / 65535.0).contains(&scale) {
            return Err(CacheError::OutOfRange {
                what: "height encoding scale (metres per stored unit)",
                value: scale,
                expected: "1e-9 to 1e9 / 65535 (a u16 span of at most 1e9 m)",
            });
        }
        if let Some(d) = &self.detail {
            check_tile_size(d.tile_size)?;
            check_positive("detail texel_size", d.texel_size)?;
            HeightEncoding::new(d.encoding.scale, d.encoding.offset)?;
            let (lo, hi) = d.encoding.range::<u8>();
            if hi - lo > terrain_core::DETAIL_MAX_RANGE_M * (1.0 + f32::EPSILON) {
                return Err(CacheError::OutOfRange {
                    what: "detail height range (m)",
                    value: f64::from(hi - lo),
                    expected: "at most 1 m",
                });
            }
            if d.tiles.min_element() == 0 || d.tiles.max_element() > MAX_TILES_PER_SIDE {
                return Err(CacheError::OutOfRange {
                    what: "detail tiles per side",
                    value: f64::from(d.tiles.max_element().max(d.tiles.min_element())),
                    expected: "1 ..= 65536",
                });
            }
            let detail_tiles = u64::from(d.tiles.x) * u64::from(d.tiles.y);
            if detail_tiles > MAX_LEVEL_TILES {
                return Err(CacheError::OutOfRange {
                    what: "detail tiles",
                    value: detail_tiles as f64,
                    expected: "at most 2^24 (16 777 216)",
                });
            }
        }
        Ok(())
    }

    /// The most levels this world can have: down to a level of one tile.
    pub fn max_levels(&self) -> u32 {
        let mut l = 0;
        while l < 31 && self.tiles_at(l).max_element() > 1 {
            l += 1;
        }
        l + 1
    }

    /// Texels of level `level` (`ceil(world_size / 2^level)`, at least 1).
    pub fn level_size(&self, level: u32) -> UVec2 {
        let s = level.min(31);
        let ceil_shift = |v: u32| (((u64::from(v)) + (1u64 << s) - 1) >> s).max(1) as u32;
        UVec2::new(ceil_shift(self.world_size.x), ceil_shift(self.world_size.y))
    }

    /// Tiles across and down level `level`.
    pub fn tiles_at(&self, level: u32) -> UVec2 {
        let s = self.level_size(level);
        let t = self.tile_size.max(1);
        UVec2::new(s.x.div_ceil(t), s.y.div_ceil(t))
    }

    /// Tiles of `layer` across and down `level` (zero where the layer has no such level).
    pub fn layer_tiles(&self, layer: Layer, level: u32) -> UVec2 {
        match layer {
            Layer::Height if level < self.levels => self.tiles_at(level),
            Layer::Hole if level == 0 => self.tiles_at(0),
            // RGBA tiles have no PNG form here: a version-1 world has no material layer. Paint
            // and colour have a pyramid like the heights (overlay_pyramid), so far ground is
            // streamed at the level its heights are.
            Layer::Material | Layer::Color
                if level < self.levels && self.tile_format == TileFormat::Tile =>
            {
                self.tiles_at(level)
            }
            Layer::Detail => match &self.detail {
                Some(d) if level == 0 => d.tiles,
                _ => UVec2::ZERO,
            },
            _ => UVec2::ZERO,
        }
    }

    /// Levels of `layer` (the detail and hole layers have one; paint and colour as many as the
    /// heights, none in a version-1 world).
    pub fn layer_levels(&self, layer: Layer) -> u32 {
        match layer {
            Layer::Height => self.levels,
            Layer::Detail => u32::from(self.detail.is_some()),
            Layer::Hole => 1,
            Layer::Material | Layer::Color if self.tile_format == TileFormat::Tile => self.levels,
            Layer::Material | Layer::Color => 0,
        }
    }

    /// Tile side of `layer`.
    pub fn layer_tile_size(&self, layer: Layer) -> Result<u32, CacheError> {
        match layer {
            Layer::Height | Layer::Hole | Layer::Material | Layer::Color => Ok(self.tile_size),
            Layer::Detail => self
                .detail
                .map(|d| d.tile_size)
                .ok_or(CacheError::NoSuchLayer { layer }),
        }
    }

    /// The zero tile's value of `layer`.
    pub fn layer_fill(&self, layer: Layer) -> Result<u16, CacheError> {
        match layer {
            Layer::Height => Ok(self.height_fill),
            Layer::Hole | Layer::Material | Layer::Color => Ok(0),
            Layer::Detail => self
                .detail
                .map(|d| u16::from(d.fill))
                .ok_or(CacheError::NoSuchLayer { layer }),
        }
    }

    /// Side of one tile of `layer` at `level`, in metres.
    pub fn tile_extent_m(&self, layer: Layer, level: u32) -> f64 {
        match (layer, &self.detail) {
            (Layer::Detail, Some(d)) => f64::from(d.tile_size) * f64::from(d.texel_size),
            _ => {
                f64::from(self.tile_size)
                    * f64::from(self.texel_size)
                    * f64::from(2u32.pow(level.min(31)))
            }
        }
    }

    /// Size of the world in metres.
    pub fn extent_m(&self) -> DVec2 {
        self.world_size.as_dvec2() * f64::from(self.texel_size)
    }

    /// Checks that `id` lies in `layer`'s pyramid.
    pub fn check_tile(&self, layer: Layer, id: TileId) -> Result<(), CacheError> {
        let material_in_png =
            matches!(layer, Layer::Material | Layer::Color) && self.tile_format == TileFormat::Png;
        if (layer == Layer::Detail && self.detail.is_none()) || material_in_png {
            return Err(CacheError::NoSuchLayer { layer });
        }
        let t = self.layer_tiles(layer, id.level);
        if id.x >= t.x || id.y >= t.y {
            return Err(CacheError::TileOutOfRange {
                id,
                levels: self.layer_levels(layer),
                tiles_x: t.x,
                tiles_y: t.y,
            });
        }
        Ok(())
    }

    /// Every tile of `layer` at `level`, row-major.
    pub fn tiles_of(&self, layer: Layer, level: u32) -> impl Iterator<Item = TileId> {
        let t = self.layer_tiles(layer, level);
        (0..t.y).flat_map(move |y| (0..t.x).map(move |x| TileId::new(level, x, y)))
    }

    /// The store key of tile `id` of `layer` in this world's format.
    pub fn tile_key(&self, layer: Layer, id: TileId) -> String {
        tile_key(layer, id, self.tile_format)
    }

    /// Serialises to the JSON text stored under [`MANIFEST_KEY`].
    pub fn to_json(&self) -> String {
        let file = ManifestFile::from(self);
        // Serialising plain numbers, strings and options cannot fail.
        serde_json::to_string_pretty(&file).unwrap_or_default() + "\n"
    }

    /// Parses and validates the JSON text of a manifest.
    pub fn from_json(text: &str) -> Result<Self, CacheError> {
        let file: ManifestFile = serde_json::from_str(text).map_err(|e| CacheError::Manifest {
            key: MANIFEST_KEY.into(),
            reason: bounded(e.to_string()),
        })?;
        if !(OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&file.format_version) {
            return Err(CacheError::ManifestVersion {
                found: file.format_version,
                supported: FORMAT_VERSION,
            });
        }
        let m = file.into_manifest()?;
        m.validate()?;
        Ok(m)
    }
}

/// The most bytes of a JSON error kept in [`CacheError::Manifest`]: serde_json quotes an
/// unknown field's name, which the file makes as long as it likes (the decoder target
/// `manifest` found a 2 kB message; a 64 KiB manifest would make one of 64 KiB).
const MAX_REASON: usize = 240;

/// `reason` cut to [`MAX_REASON`] bytes at a character boundary, saying how much was left out.
fn bounded(reason: String) -> String {
    if reason.len() <= MAX_REASON {
        return reason;
    }
    let end = (0..=MAX_REASON)
        .rev()
        .find(|&i| reason.is_char_boundary(i))
        .unwrap_or(0);
    format!("{}... ({} more bytes)", &reason[..end], reason.len() - end)
}

/// The store key of a tile: `{layer}/{level:02x}/{y:04x}/{x:04x}.{tile}` (one folder per level,
/// one per row, hex names: Fikkan 2013, fig. 5.1), `.png` in a world of PNG tiles. A world's
/// own keys: [`Manifest::tile_key`].
pub fn tile_key(layer: Layer, id: TileId, format: TileFormat) -> String {
    format!(
        "{}/{:02x}/{:04x}/{:04x}.{}",
        layer.folder(),
        id.level,
        id.y,
        id.x,
        format.extension()
    )
}

/// The store key of the min/max side file of a level of a layer (see
/// [`World::bounds`](crate::World::bounds)).
pub fn bounds_key(layer: Layer, level: u32) -> String {
    format!("{}/{:02x}/bounds.bin", layer.folder(), level)
}

/// Parses a tile key of either format back into its layer and id (`None` for any other key).
pub fn parse_tile_key(key: &str) -> Option<(Layer, TileId)> {
    let mut parts = key.split('/');
    let layer = match parts.next()? {
        "height" => Layer::Height,
        "detail" => Layer::Detail,
        "hole" => Layer::Hole,
        "material" => Layer::Material,
        "color" => Layer::Color,
        _ => return None,
    };
    let level = parts.next()?;
    let y = parts.next()?;
    let name = parts.next()?;
    let x = name
        .strip_suffix(".tile")
        .or_else(|| name.strip_suffix(".png"))?;
    if parts.next().is_some() || level.len() != 2 || y.len() != 4 || x.len() != 4 {
        return None;
    }
    let hex = |s: &str| {
        s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
            .then(|| u32::from_str_radix(s, 16).ok())
            .flatten()
    };
    Some((layer, TileId::new(hex(level)?, hex(x)?, hex(y)?)))
}

fn check_tile_size(t: u32) -> Result<(), CacheError> {
    if !t.is_power_of_two() || !(MIN_TILE_SIZE..=MAX_TILE_SIZE).contains(&t) {
        return Err(CacheError::OutOfRange {
            what: "tile_size",
            value: f64::from(t),
            expected: "a power of two in 16..=4096",
        });
    }
    Ok(())
}

fn check_positive(what: &'static str, v: f32) -> Result<(), CacheError> {
    if !(v.is_finite() && v > 0.0) {
        return Err(CacheError::OutOfRange {
            what,
            value: f64::from(v),
            expected: "finite and > 0",
        });
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The file format (private mirror with plain arrays, so the public types stay glam's).

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ManifestFile {
    format_version: u32,
    /// Absent in version 1 (PNG tiles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tile_format: Option<String>,
    tile_size: u32,
    world_size: [u32; 2],
    levels: u32,
    texel_size: f32,
    height_scale: f32,
    height_offset: f32,
    wrap: String,
    height_fill: u16,
    /// Stated, not configurable: how coarser levels are made.
    reduction: String,
    generation: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    detail: Option<DetailFile>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct DetailFile {
    tile_size: u32,
    tiles: [u32; 2],
    texel_size: f32,
    scale: f32,
    offset: f32,
    fill: u8,
}

const REDUCTION: &str =
    "2x2 average, rounded to nearest; bounds.bin holds level-0 min/max per tile";

impl From<&Manifest> for ManifestFile {
    fn from(m: &Manifest) -> Self {
        Self {
            format_version: m.format_version,
            // Version 1 had no such field: a version-1 world stays readable by older builds.
            tile_format: (m.format_version > 1).then(|| m.tile_format.extension().to_owned()),
            tile_size: m.tile_size,
            world_size: m.world_size.to_array(),
            levels: m.levels,
            texel_size: m.texel_size,
            height_scale: m.encoding.scale,
            height_offset: m.encoding.offset,
            wrap: match m.wrap {
                WrapMode::Repeat => "repeat".into(),
                WrapMode::Clamp => "clamp".into(),
            },
            height_fill: m.height_fill,
            reduction: REDUCTION.into(),
            generation: m.generation,
            detail: m.detail.map(|d| DetailFile {
                tile_size: d.tile_size,
                tiles: d.tiles.to_array(),
                texel_size: d.texel_size,
                scale: d.encoding.scale,
                offset: d.encoding.offset,
                fill: d.fill,
            }),
        }
    }
}

impl ManifestFile {
    fn into_manifest(self) -> Result<Manifest, CacheError> {
        let wrap = match self.wrap.as_str() {
            "repeat" => WrapMode::Repeat,
            "clamp" => WrapMode::Clamp,
            other => {
                return Err(CacheError::Manifest {
                    key: MANIFEST_KEY.into(),
                    reason: format!("wrap {other:?} is neither \"repeat\" nor \"clamp\""),
                });
            }
        };
        let tile_format = match (self.format_version, self.tile_format.as_deref()) {
            (1, None) => TileFormat::Png,
            (_, Some("tile")) => TileFormat::Tile,
            (_, Some("png")) => TileFormat::Png,
            (v, other) => {
                return Err(CacheError::Manifest {
                    key: MANIFEST_KEY.into(),
                    reason: format!(
                        "format version {v} with tile_format {other:?}: expected \"tile\" \
                         (version 2) or none (version 1, PNG tiles)"
                    ),
                });
            }
        };
        let detail = match self.detail {
            None => None,
            Some(d) => Some(DetailLayout {
                tile_size: d.tile_size,
                tiles: UVec2::from(d.tiles),
                texel_size: d.texel_size,
                encoding: HeightEncoding::new(d.scale, d.offset)?,
                fill: d.fill,
            }),
        };
        Ok(Manifest {
            format_version: self.format_version,
            tile_format,
            tile_size: self.tile_size,
            world_size: UVec2::from(self.world_size),
            levels: self.levels,
            texel_size: self.texel_size,
            encoding: HeightEncoding::new(self.height_scale, self.height_offset)?,
            wrap,
            height_fill: self.height_fill,
            generation: self.generation,
            detail,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn enc() -> HeightEncoding {
        HeightEncoding::spanning::<u16>(0.0, 100.0).unwrap()
    }

    #[test]
    fn levels_and_tiles() {
        let m = Manifest::new(UVec2::new(1000, 600), 256, 0.5, enc(), WrapMode::Repeat).unwrap();
        assert_eq!(m.tiles_at(0), UVec2::new(4, 3));
        assert_eq!(m.level_size(1), UVec2::new(500, 300));
        assert_eq!(m.tiles_at(1), UVec2::new(2, 2));
        assert_eq!(m.tiles_at(2), UVec2::new(1, 1));
        assert_eq!(m.levels, 3);
        assert_eq!(m.tiles_of(Layer::Height, 0).count(), 12);
        assert!(m.check_tile(Layer::Height, TileId::new(0, 3, 2)).is_ok());
        assert!(matches!(
            m.check_tile(Layer::Height, TileId::new(0, 4, 0)),
            Err(CacheError::TileOutOfRange { .. })
        ));
        assert!(matches!(
            m.check_tile(Layer::Height, TileId::new(9, 0, 0)),
            Err(CacheError::TileOutOfRange { .. })
        ));
        assert!(matches!(
            m.check_tile(Layer::Detail, TileId::new(0, 0, 0)),
            Err(CacheError::NoSuchLayer { .. })
        ));
        let one = Manifest::new(UVec2::splat(16), 16, 1.0, enc(), WrapMode::Clamp).unwrap();
        assert_eq!(one.levels, 1);
        let huge = Manifest::new(UVec2::splat(u32::MAX), 4096, 1.0, enc(), WrapMode::Clamp);
        assert!(matches!(huge, Err(CacheError::OutOfRange { .. })));
        // The largest level 0 accepted: 4096^2 tiles (MAX_LEVEL_TILES).
        let big = Manifest::new(UVec2::splat(1 << 20), 256, 1.0, enc(), WrapMode::Clamp).unwrap();
        assert_eq!(big.levels, 13);
    }

    #[test]
    fn json_round_trip_and_rejections() {
        let mut m = Manifest::new(UVec2::new(300, 200), 64, 0.25, enc(), WrapMode::Clamp).unwrap();
        m.detail = Some(DetailLayout::covering(glam::Vec2::new(75.0, 50.0), 128, 0.05).unwrap());
        m.generation = 7;
        let text = m.to_json();
        assert_eq!(Manifest::from_json(&text).unwrap(), m);
        assert!(matches!(
            Manifest::from_json("{nope"),
            Err(CacheError::Manifest { .. })
        ));
        let v3 = text.replace("\"format_version\": 2", "\"format_version\": 3");
        assert!(matches!(
            Manifest::from_json(&v3),
            Err(CacheError::ManifestVersion { found: 3, .. })
        ));
        // Version 1 (PNG tiles) has no tile_format field; a version 2 without one is refused.
        let v1 = text
            .replace("\"format_version\": 2", "\"format_version\": 1")
            .replace("  \"tile_format\": \"tile\",\n", "");
        let old = Manifest::from_json(&v1).unwrap();
        assert_eq!((old.format_version, old.tile_format), (1, TileFormat::Png));
        assert_eq!(
            old.to_json(),
            v1,
            "a version-1 manifest is written back as it was"
        );
        assert_eq!(
            old.tile_key(Layer::Height, TileId::new(0, 1, 2)),
            "height/00/0002/0001.png"
        );
        let no_format = text.replace("  \"tile_format\": \"tile\",\n", "");
        assert!(matches!(
            Manifest::from_json(&no_format),
            Err(CacheError::Manifest { .. })
        ));
        let v1_tile = text.replace("\"format_version\": 2", "\"format_version\": 1");
        assert!(Manifest::from_json(&v1_tile).is_err());
        let bad = text.replace("\"tile_size\": 64", "\"tile_size\": 65");
        assert!(matches!(
            Manifest::from_json(&bad),
            Err(CacheError::OutOfRange {
                what: "tile_size",
                ..
            })
        ));
        let nan = text.replace("\"texel_size\": 0.25", "\"texel_size\": -1.0");
        assert!(Manifest::from_json(&nan).is_err());
        // Encodings no world can hold or deform (a denormal step, a span past 1e9 m).
        for scale in ["1e-45", "1e38"] {
            let bad = text.replace(
                &format!("\"height_scale\": {}", m.encoding.scale),
                &format!("\"height_scale\": {scale}"),
            );
            assert_ne!(bad, text);
            assert!(
                matches!(
                    Manifest::from_json(&bad),
                    Err(CacheError::OutOfRange { what, .. }) if what.starts_with("height encoding")
                ),
                "{scale}"
            );
        }
    }

    /// A manifest of a few hundred bytes cannot ask for tables of billions of tiles: 65536^2
    /// tiles of 16 texels pass the per-side limit but not the per-level one, nor do detail
    /// tiles as many; 2^24 tiles still open.
    #[test]
    fn a_level_holds_at_most_2_pow_24_tiles() {
        let huge = Manifest::new(UVec2::splat(1 << 20), 16, 0.5, enc(), WrapMode::Clamp);
        assert!(
            matches!(
                huge,
                Err(CacheError::OutOfRange {
                    what: "level-0 tiles",
                    ..
                })
            ),
            "{huge:?}"
        );
        let most = Manifest::new(UVec2::splat(1 << 16), 16, 0.5, enc(), WrapMode::Clamp).unwrap();
        assert_eq!(most.tiles_at(0), UVec2::splat(4096));
        let mut m = Manifest::new(UVec2::new(300, 200), 64, 0.25, enc(), WrapMode::Clamp).unwrap();
        let mut detail = DetailLayout::covering(glam::Vec2::new(75.0, 50.0), 128, 0.05).unwrap();
        detail.tiles = UVec2::splat(65536);
        m.detail = Some(detail);
        assert!(matches!(
            Manifest::from_json(&m.to_json()),
            Err(CacheError::OutOfRange {
                what: "detail tiles",
                ..
            })
        ));
    }

    #[test]
    fn keys_are_hex_per_level_and_row() {
        let id = TileId::new(3, 0x1a, 0xff);
        let k = tile_key(Layer::Height, id, TileFormat::Png);
        assert_eq!(k, "height/03/00ff/001a.png");
        assert_eq!(parse_tile_key(&k), Some((Layer::Height, id)));
        let k = tile_key(Layer::Height, id, TileFormat::Tile);
        assert_eq!(k, "height/03/00ff/001a.tile");
        assert_eq!(parse_tile_key(&k), Some((Layer::Height, id)));
        assert_eq!(parse_tile_key("detail/00/0000/0001.png").unwrap().1.x, 1);
        for bad in [
            "height/03/00ff/001a.png.tmp",
            "x/00/0000/0000.png",
            "height/3/00ff/001a.png",
            "height/03/00FF/001a.png",
            "height/03/00ff/001a",
            "height/03/00ff/001a.tiles",
            "height/03/bounds.bin",
        ] {
            assert_eq!(parse_tile_key(bad), None, "{bad}");
        }
        assert_eq!(bounds_key(Layer::Height, 2), "height/02/bounds.bin");
    }
}
