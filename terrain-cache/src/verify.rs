//! Checking a world against what its manifest promises ([`verify_world`]) and rebuilding what
//! level 0 determines ([`repair_world`]): coarser levels and the `bounds.bin` side files.
//!
//! What a valid world is, as the builder ([`build_world`](crate::build_world)) and write-back
//! ([`rebuild_ancestors`](crate::rebuild_ancestors)) leave it:
//!
//! - **Every tile decodes** as a tile of its layer, its size, and (`.tile` files written with an
//!   identity, [`tile_file::TileIdentity`](crate::tile_file::TileIdentity)) its own key: a file
//!   copied over another tile's path is refused, at any level, including the top and a world of
//!   one level, where no parent could tell.
//! - **Missing tiles.** A tile equal to the layer's zero tile (every sample the fill value) is
//!   never stored: no file *means* the zero tile. So a missing file is valid exactly where the
//!   zero tile is the right content:
//!   - at a coarser level, where the reduction of its children is all fill;
//!   - at level 0, where level 0's `bounds.bin` records the tile as `[fill, fill]`; a missing
//!     file whose recorded bounds are anything else is a lost tile, except an entry never
//!     written (`[u16::MAX, 0]`): the tile is then taken as the zero tile and the entry is
//!     reported as a `bounds.bin` defect (repairable), not as a lost tile;
//!   - in the detail layer, always: detail tiles are the zero deformation until first written;
//!   - in the hole and material layers, always: a tile without a hole, or unpainted, is not
//!     stored.
//! - **Coarser levels** equal the reduction of their children bit for bit (the 2x2 mean
//!   rounded to nearest, clamped padding beyond the level's size, exactly as the builder
//!   computes them).
//! - **`bounds.bin`** exists for every height level and holds, per tile, the min / max of the
//!   level-0 samples under it (level 0: of the whole stored tile).
//!
//! Level 0 is the truth: what it holds cannot be checked against anything but its own
//! checksums, identities and bounds, and a defect there is not repairable. Everything else is
//! derived from it and [`repair_world`] rewrites it (atomically, through
//! [`World::write_tile`] and [`World::write_bounds`]); ancestors of a damaged level-0 tile are
//! left as they are, since their stored copy may be the best record of it left.
//!
//! Work is bounded before anything is read: a manifest promising more tiles than
//! [`VerifyOptions::max_tiles`] is refused ([`VerifyError::TooManyTiles`]), and the walk checks
//! a cancel flag before every tile. Memory: the level files' bounds, and at most four tiles per
//! level in flight (the walk is depth first, as the build). The report counts every defect
//! and keeps the first [`VerifyOptions::max_listed`].

use crate::CacheError;
use crate::build::{Node, reduce_children};
use crate::manifest::{Manifest, bounds_key};
use crate::tile::{Layer, TileData, TileId};
use crate::world::{LevelBounds, TileRead, World};
use std::fmt;
use std::sync::atomic::{AtomicBool, Ordering};
use terrain_core::Grid;

/// Most tiles (both layers, every level) a verification walks by default: 2^24, a world of
/// 16 million tiles (a 1 M texel square world in 256^2 tiles). A crafted manifest may promise
/// 4 billion level-0 tiles; walking their paths would take hours.
pub const DEFAULT_MAX_TILES: u64 = 1 << 24;
/// Defects listed in a report by default (all are counted).
pub const DEFAULT_MAX_LISTED: usize = 100;
/// Longest reason kept per listed defect, in bytes.
const MAX_REASON: usize = 400;

/// Limits of a verification.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VerifyOptions {
    /// The most tiles (height levels and the other layers together) the manifest may promise; a
    /// larger world is refused before anything is read ([`VerifyError::TooManyTiles`]).
    pub max_tiles: u64,
    /// Defects kept in [`VerifyReport::listed`]; every defect is counted regardless.
    pub max_listed: usize,
}

impl Default for VerifyOptions {
    fn default() -> Self {
        Self {
            max_tiles: DEFAULT_MAX_TILES,
            max_listed: DEFAULT_MAX_LISTED,
        }
    }
}

/// What is wrong with one file of a world.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum DefectKind {
    /// The tile file cannot be read or does not decode as this tile: corrupt, truncated,
    /// foreign, of the wrong shape, or written for another tile (a swapped file).
    Unreadable,
    /// The tile has no file but should not be the zero tile (level 0: its recorded bounds say
    /// so; a coarser level: its children reduce to something else).
    Missing,
    /// A coarser tile that differs from the reduction of its children.
    Mismatch,
    /// A level has no `bounds.bin`.
    BoundsMissing,
    /// A level's `bounds.bin` does not decode (damaged, truncated, of another layout).
    BoundsUnreadable,
    /// A level's `bounds.bin` decodes but disagrees with the tiles.
    BoundsMismatch,
}

impl DefectKind {
    /// A short name, as reports print it.
    pub const fn name(self) -> &'static str {
        match self {
            DefectKind::Unreadable => "unreadable",
            DefectKind::Missing => "missing",
            DefectKind::Mismatch => "mismatch",
            DefectKind::BoundsMissing => "bounds missing",
            DefectKind::BoundsUnreadable => "bounds unreadable",
            DefectKind::BoundsMismatch => "bounds mismatch",
        }
    }
}

/// One defect: the store key of the file, what is wrong, and whether [`repair_world`] can
/// rebuild it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Defect {
    /// The store key (`height/00/0001/0002.tile`, `height/01/bounds.bin`).
    pub key: String,
    /// What is wrong.
    pub kind: DefectKind,
    /// Whether it is rebuilt from level 0 by [`repair_world`].
    pub repairable: bool,
    /// Why, in words (at most a few hundred bytes).
    pub reason: String,
}

impl fmt::Display for Defect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {}: {}{}",
            self.key,
            self.kind.name(),
            self.reason,
            if self.repairable {
                " (repairable)"
            } else {
                " (not repairable)"
            }
        )
    }
}

/// What a verification found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct VerifyReport {
    /// Tiles the manifest promises (every height level and the detail layer).
    pub tiles: u64,
    /// Tiles with a file that decodes as theirs.
    pub stored: u64,
    /// Tiles without a file that are rightly the zero tile.
    pub zero: u64,
    /// Defects found, all counted.
    pub defects: u64,
    /// Of them, those [`repair_world`] cannot rebuild (level-0 and detail tiles).
    pub unrepairable: u64,
    /// The first [`VerifyOptions::max_listed`] defects, in the order found.
    pub listed: Vec<Defect>,
}

impl VerifyReport {
    /// Whether the world is as its manifest promises.
    pub fn is_valid(&self) -> bool {
        self.defects == 0
    }

    /// Defects counted but not listed.
    pub fn unlisted(&self) -> u64 {
        self.defects.saturating_sub(self.listed.len() as u64)
    }
}

/// What a repair did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RepairReport {
    /// The world as found (before any write).
    pub found: VerifyReport,
    /// Coarser tiles rewritten (or removed, where they are the zero tile).
    pub tiles_rewritten: u64,
    /// `bounds.bin` files rewritten.
    pub bounds_rewritten: u32,
}

/// How far a walk is, handed to the progress callback after every tile.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VerifyProgress {
    /// Tiles checked.
    pub done: u64,
    /// Tiles in all.
    pub total: u64,
}

/// Why a verification or repair did not finish.
#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    /// The manifest promises more tiles than the options allow.
    #[error(
        "the manifest promises {tiles} tiles, more than the {max} a verification walks \
         (a crafted or damaged manifest, or a world too large to verify with these limits)"
    )]
    TooManyTiles {
        /// Tiles promised (saturating).
        tiles: u64,
        /// The limit.
        max: u64,
    },
    /// The cancel flag was set.
    #[error("verification cancelled after {done} of {total} tiles")]
    Cancelled {
        /// Tiles checked.
        done: u64,
        /// Tiles in all.
        total: u64,
    },
    /// A repair's write failed.
    #[error(transparent)]
    Cache(#[from] CacheError),
}

/// Checks every file `world`'s manifest promises (see the [module docs](self) for the rules)
/// and returns what is wrong. Never writes.
///
/// `cancel` is read before every tile; once set, the walk ends with
/// [`VerifyError::Cancelled`]. `progress` is called after every tile. Problems with the
/// world's files are defects in the report, never errors.
pub fn verify_world(
    world: &World,
    options: &VerifyOptions,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(VerifyProgress),
) -> Result<VerifyReport, VerifyError> {
    Walk::new(world, options, cancel, progress, false)?.run()
}

/// Verifies `world` as [`verify_world`] does and rewrites, atomically, every defect that
/// level 0 determines: coarser tiles that are missing, unreadable or stale, and `bounds.bin`
/// files that are missing, damaged or stale. Level-0 and detail tiles are never written:
/// their defects stay in the report as not repairable, and the ancestors of a damaged
/// level-0 tile are left as they are.
///
/// Cancelling stops before the next tile or `bounds.bin`: what was rewritten stays rewritten
/// (each file is correct on its own), the rest is as it was; `bounds.bin` files are written
/// after every tile, so a cancelled walk over the tiles writes none.
pub fn repair_world(
    world: &World,
    options: &VerifyOptions,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(VerifyProgress),
) -> Result<RepairReport, VerifyError> {
    let mut walk = Walk::new(world, options, cancel, progress, true)?;
    walk.walk()?;
    let bounds_rewritten = walk.finish_bounds()?;
    // Every coarser level now matches level 0: interrupted write-backs have nothing left to
    // recover.
    if !cancel.load(std::sync::atomic::Ordering::Relaxed) {
        crate::pool::journal::clear(world).map_err(VerifyError::from)?;
    }
    Ok(RepairReport {
        tiles_rewritten: walk.rewritten,
        bounds_rewritten,
        found: walk.report,
    })
}

/// Most level-0 tiles [`check_before_use`] looks for lost files among (2^16: a world of
/// 65536^2 texels in 256^2 tiles); a larger world has its `bounds.bin` files checked only
/// (`verify_world` walks every tile).
pub const CHECK_BEFORE_USE_MAX_TILES: u64 = 1 << 16;

/// The defects a run must not start over, found without decoding a tile (milliseconds, where
/// [`verify_world`] reads everything): a height level whose `bounds.bin` is missing or does
/// not read (a run's write-backs would merge into an empty one and record every other tile
/// as empty), and a level-0 tile without a file whose recorded bounds are not the zero tile's
/// (a lost tile a run would read as flat, then write its flat ancestors and bounds over the
/// last record of it). A tile whose write-back the journal says was in progress is left to
/// the journal's recovery (its file and bounds may rightly disagree). Lost tiles are looked
/// for in worlds of at most [`CHECK_BEFORE_USE_MAX_TILES`] level-0 tiles, a row of files
/// listed at a time. Listed as [`verify_world`] lists them, at most `max_listed`; never
/// writes. A store that cannot be listed is an error.
pub fn check_before_use(world: &World, max_listed: usize) -> Result<Vec<Defect>, CacheError> {
    let m = *world.manifest();
    let mut found = Vec::new();
    let mut push = |key: String, kind: DefectKind, repairable: bool, reason: String| {
        if found.len() < max_listed {
            found.push(Defect {
                key,
                kind,
                repairable,
                reason: cut(reason),
            });
        }
    };
    let mut level0 = None;
    for level in 0..m.levels {
        let key = bounds_key(Layer::Height, level);
        match world.bounds(level) {
            Ok(Some(b)) if level == 0 => level0 = Some(b),
            Ok(Some(_)) => {}
            Ok(None) => push(key, DefectKind::BoundsMissing, true, "no file".into()),
            // Damaged, too large, a folder in its place: unreadable, rebuilt from level 0.
            Err(e) => push(key, DefectKind::BoundsUnreadable, true, e.to_string()),
        }
    }
    let tiles = m.tiles_at(0);
    let Some(bounds) =
        level0.filter(|_| u64::from(tiles.x) * u64::from(tiles.y) <= CHECK_BEFORE_USE_MAX_TILES)
    else {
        return Ok(found);
    };
    let pending: std::collections::HashSet<TileId> = crate::pool::journal::pending_level0(world)?
        .into_iter()
        .collect();
    let fill = m.height_fill;
    let held = |r: [u16; 2]| r != [fill, fill] && r != [u16::MAX, 0];
    for y in 0..tiles.y {
        let lost: Vec<(TileId, [u16; 2])> = (0..tiles.x)
            .map(|x| TileId::new(0, x, y))
            .filter_map(|id| bounds.get(id.x, id.y).map(|r| (id, r)))
            .filter(|&(id, r)| held(r) && !pending.contains(&id))
            .collect();
        if lost.is_empty() {
            continue;
        }
        // The row's folder: the key of its first tile without the file name.
        let first = m.tile_key(Layer::Height, lost[0].0);
        let row = first
            .rsplit_once('/')
            .map_or(first.as_str(), |(dir, _)| dir);
        let stored: std::collections::HashSet<String> =
            world.store().list(row)?.into_iter().collect();
        for (id, r) in lost {
            let key = m.tile_key(Layer::Height, id);
            if !stored.contains(&key) {
                push(
                    key,
                    DefectKind::Missing,
                    false,
                    format!(
                        "no file, but level 0's bounds.bin records heights {}..={} (a missing \
                         tile is the zero tile, all {fill})",
                        r[0], r[1]
                    ),
                );
            }
        }
    }
    Ok(found)
}

/// Tiles `m` promises, every layer, saturating.
fn promised_tiles(m: &Manifest) -> u64 {
    let count = |t: glam::UVec2| u64::from(t.x).saturating_mul(u64::from(t.y));
    (0..m.levels)
        .map(|l| count(m.tiles_at(l)))
        .chain(std::iter::once(count(m.layer_tiles(Layer::Detail, 0))))
        .chain(std::iter::once(count(m.layer_tiles(Layer::Hole, 0))))
        .chain(
            (0..m.layer_levels(Layer::Material)).map(|l| count(m.layer_tiles(Layer::Material, l))),
        )
        .chain((0..m.layer_levels(Layer::Color)).map(|l| count(m.layer_tiles(Layer::Color, l))))
        .fold(0u64, u64::saturating_add)
}

/// A level's `bounds.bin` as read.
enum StoredBounds {
    Ok(LevelBounds),
    Missing,
    Unreadable(String),
}

/// One tile's content as far as the walk knows it: `None` where it depends on a damaged
/// level-0 tile.
type Known = Option<Node>;

struct Walk<'a> {
    world: &'a World,
    m: Manifest,
    max_listed: usize,
    cancel: &'a AtomicBool,
    progress: &'a mut dyn FnMut(VerifyProgress),
    repair: bool,
    done: u64,
    total: u64,
    report: VerifyReport,
    stored_bounds: Vec<StoredBounds>,
    /// Per level, the bounds the tiles give (`[u16::MAX, 0]` where unknown) and whether known.
    expected: Vec<(LevelBounds, Vec<bool>)>,
    rewritten: u64,
}

impl<'a> Walk<'a> {
    fn new(
        world: &'a World,
        options: &VerifyOptions,
        cancel: &'a AtomicBool,
        progress: &'a mut dyn FnMut(VerifyProgress),
        repair: bool,
    ) -> Result<Self, VerifyError> {
        let m = *world.manifest();
        let total = promised_tiles(&m);
        if total > options.max_tiles {
            return Err(VerifyError::TooManyTiles {
                tiles: total,
                max: options.max_tiles,
            });
        }
        Ok(Self {
            world,
            m,
            max_listed: options.max_listed,
            cancel,
            progress,
            repair,
            done: 0,
            total,
            report: VerifyReport {
                tiles: total,
                ..VerifyReport::default()
            },
            stored_bounds: Vec::new(),
            expected: Vec::new(),
            rewritten: 0,
        })
    }

    fn run(mut self) -> Result<VerifyReport, VerifyError> {
        self.walk()?;
        self.finish_bounds()?;
        Ok(self.report)
    }

    fn defect(&mut self, key: String, kind: DefectKind, repairable: bool, reason: String) {
        self.report.defects += 1;
        if !repairable {
            self.report.unrepairable += 1;
        }
        if self.report.listed.len() < self.max_listed {
            self.report.listed.push(Defect {
                key,
                kind,
                repairable,
                reason: cut(reason),
            });
        }
    }

    /// Counts a tile as checked; errs once the cancel flag is set.
    fn tick(&mut self) -> Result<(), VerifyError> {
        if self.cancel.load(Ordering::Relaxed) {
            return Err(VerifyError::Cancelled {
                done: self.done,
                total: self.total,
            });
        }
        Ok(())
    }

    fn ticked(&mut self) {
        self.done += 1;
        (self.progress)(VerifyProgress {
            done: self.done,
            total: self.total,
        });
    }

    fn walk(&mut self) -> Result<(), VerifyError> {
        // Bounds first, each level's file alone (their size is bounded by the tile count).
        for level in 0..self.m.levels {
            self.tick()?;
            let b = match self.world.bounds(level) {
                Ok(Some(b)) => StoredBounds::Ok(b),
                Ok(None) => StoredBounds::Missing,
                Err(e) => StoredBounds::Unreadable(e.to_string()),
            };
            self.stored_bounds.push(b);
            let t = self.m.tiles_at(level);
            self.expected.push((
                LevelBounds::empty(t),
                vec![false; t.x as usize * t.y as usize],
            ));
        }
        let top = self.m.levels - 1;
        let tops: Vec<TileId> = self.m.tiles_of(Layer::Height, top).collect();
        for id in tops {
            self.height(id)?;
        }
        if self.m.detail.is_some() {
            let ids: Vec<TileId> = self.m.tiles_of(Layer::Detail, 0).collect();
            for id in ids {
                self.flat_tile(Layer::Detail, id)?;
            }
        }
        for layer in [Layer::Hole, Layer::Material, Layer::Color] {
            for level in 0..self.m.layer_levels(layer) {
                let ids: Vec<TileId> = self.m.tiles_of(layer, level).collect();
                for id in ids {
                    self.flat_tile(layer, id)?;
                }
            }
        }
        Ok(())
    }

    /// Checks tile `id` of the height layer and everything below it; returns its content.
    fn height(&mut self, id: TileId) -> Result<Known, VerifyError> {
        let tiles = self.m.tiles_at(id.level);
        if id.x >= tiles.x || id.y >= tiles.y {
            return Ok(None);
        }
        let node = if id.level == 0 {
            self.tick()?;
            let node = self.level0(id);
            self.ticked();
            node
        } else {
            let Some(kids) = id.children() else {
                return Ok(None);
            };
            let mut children: [Option<Node>; 4] = [None, None, None, None];
            let mut all_known = true;
            for (slot, k) in children.iter_mut().zip(kids) {
                let inside = {
                    let t = self.m.tiles_at(k.level);
                    k.x < t.x && k.y < t.y
                };
                let got = self.height(k)?;
                all_known &= got.is_some() || !inside;
                *slot = got;
            }
            self.tick()?;
            let node = if all_known {
                Some(self.coarser(id, &children)?)
            } else {
                self.above_damage(id);
                None
            };
            self.ticked();
            node
        };
        if let Some(n) = &node {
            let (b, known) = &mut self.expected[id.level as usize];
            let i = id.y as usize * b.tiles.x as usize + id.x as usize;
            if let (Some(slot), Some(k)) = (b.min_max.get_mut(i), known.get_mut(i)) {
                *slot = [n.min, n.max];
                *k = true;
            }
        }
        Ok(node)
    }

    /// A level-0 tile: its stored content, or `None` when it is damaged.
    fn level0(&mut self, id: TileId) -> Known {
        let key = self.m.tile_key(Layer::Height, id);
        match self.world.read_tile(Layer::Height, id) {
            Ok(TileRead::Stored(TileData::U16(grid))) => {
                self.report.stored += 1;
                let (min, max) = min_max(&grid);
                Some(Node { grid, min, max })
            }
            Ok(TileRead::Stored(TileData::U8(_) | TileData::Rgba8(_))) => {
                self.defect(
                    key,
                    DefectKind::Unreadable,
                    false,
                    "a tile of another sample type in the height layer".into(),
                );
                None
            }
            Ok(TileRead::Zero) => {
                let fill = self.m.height_fill;
                let recorded = match &self.stored_bounds[0] {
                    StoredBounds::Ok(b) => b.get(id.x, id.y),
                    _ => None,
                };
                match recorded {
                    Some(r) if r != [fill, fill] && r != [u16::MAX, 0] => {
                        self.defect(
                            key,
                            DefectKind::Missing,
                            false,
                            format!(
                                "no file, but level 0's bounds.bin records heights {}..={} \
                                 (a missing tile is the zero tile, all {fill})",
                                r[0], r[1]
                            ),
                        );
                        None
                    }
                    _ => {
                        self.report.zero += 1;
                        let grid = Grid::new(self.m.tile_size, self.m.tile_size, fill).ok()?;
                        Some(Node {
                            grid,
                            min: fill,
                            max: fill,
                        })
                    }
                }
            }
            Err(e) => {
                self.defect(key, DefectKind::Unreadable, false, e.to_string());
                None
            }
        }
    }

    /// A coarser tile whose children are all known: compared with their reduction (and, when
    /// repairing, rewritten where it differs). Returns the reduction.
    fn coarser(&mut self, id: TileId, children: &[Option<Node>; 4]) -> Result<Node, VerifyError> {
        let expected = reduce_children(&self.m, id, children);
        let key = self.m.tile_key(Layer::Height, id);
        let fill = self.m.height_fill;
        let is_zero = expected.grid.as_slice().iter().all(|&v| v == fill);
        let wrong = match self.world.read_tile(Layer::Height, id) {
            Ok(TileRead::Stored(TileData::U16(g))) => {
                if g.as_slice() == expected.grid.as_slice() {
                    None
                } else {
                    let differ = g
                        .as_slice()
                        .iter()
                        .zip(expected.grid.as_slice())
                        .filter(|(a, b)| a != b)
                        .count();
                    Some((
                        DefectKind::Mismatch,
                        format!(
                            "{differ} of {} samples differ from the reduction of its children",
                            expected.grid.as_slice().len()
                        ),
                    ))
                }
            }
            Ok(TileRead::Stored(TileData::U8(_) | TileData::Rgba8(_))) => Some((
                DefectKind::Unreadable,
                "a tile of another sample type in the height layer".into(),
            )),
            Ok(TileRead::Zero) if is_zero => None,
            Ok(TileRead::Zero) => Some((
                DefectKind::Missing,
                "no file, but its children do not reduce to the zero tile".into(),
            )),
            Err(e) => Some((DefectKind::Unreadable, e.to_string())),
        };
        match wrong {
            None if is_zero => self.report.zero += 1,
            None => self.report.stored += 1,
            Some((kind, reason)) => {
                self.defect(key, kind, true, reason);
                if self.repair {
                    self.world.write_tile(
                        Layer::Height,
                        id,
                        &TileData::U16(expected.grid.clone()),
                    )?;
                    self.rewritten += 1;
                }
            }
        }
        Ok(expected)
    }

    /// A coarser tile above a damaged level-0 tile: only checked to decode as itself.
    fn above_damage(&mut self, id: TileId) {
        match self.world.read_tile(Layer::Height, id) {
            Ok(TileRead::Stored(TileData::U16(_))) => self.report.stored += 1,
            Ok(TileRead::Zero) => self.report.zero += 1,
            Ok(TileRead::Stored(TileData::U8(_) | TileData::Rgba8(_))) => {
                let key = self.m.tile_key(Layer::Height, id);
                self.defect(
                    key,
                    DefectKind::Unreadable,
                    false,
                    "a tile of another sample type in the height layer".into(),
                );
            }
            Err(e) => {
                let key = self.m.tile_key(Layer::Height, id);
                self.defect(
                    key,
                    DefectKind::Unreadable,
                    false,
                    format!("{e} (above a damaged level-0 tile: repair that first)"),
                );
            }
        }
    }

    /// A detail, hole or material tile: it decodes as itself, or has no file (the zero
    /// deformation, no hole, no paint).
    fn flat_tile(&mut self, layer: Layer, id: TileId) -> Result<(), VerifyError> {
        self.tick()?;
        match self.world.read_tile(layer, id) {
            Ok(TileRead::Stored(_)) => self.report.stored += 1,
            Ok(TileRead::Zero) => self.report.zero += 1,
            Err(e) => {
                let key = self.m.tile_key(layer, id);
                self.defect(key, DefectKind::Unreadable, false, e.to_string());
            }
        }
        self.ticked();
        Ok(())
    }

    /// Compares each level's `bounds.bin` with what the tiles give; when repairing, rewrites
    /// those that differ (tiles whose bounds are unknown keep their stored entry). Returns the
    /// files rewritten.
    fn finish_bounds(&mut self) -> Result<u32, VerifyError> {
        let mut rewritten = 0;
        for level in 0..self.m.levels {
            let key = bounds_key(Layer::Height, level);
            let stored = std::mem::replace(
                &mut self.stored_bounds[level as usize],
                StoredBounds::Missing,
            );
            let (expected, known) = &self.expected[level as usize];
            let mut fixed = expected.clone();
            let wrong = match &stored {
                StoredBounds::Missing => Some((DefectKind::BoundsMissing, "no file".to_string())),
                StoredBounds::Unreadable(reason) => {
                    Some((DefectKind::BoundsUnreadable, reason.clone()))
                }
                StoredBounds::Ok(b) => {
                    let mut differ = 0u64;
                    let mut first = None;
                    for (i, ((e, s), &k)) in expected
                        .min_max
                        .iter()
                        .zip(&b.min_max)
                        .zip(known)
                        .enumerate()
                    {
                        if !k {
                            fixed.min_max[i] = *s;
                        } else if e != s {
                            differ += 1;
                            first.get_or_insert((i, *s, *e));
                        }
                    }
                    first.map(|(i, s, e)| {
                        let w = b.tiles.x.max(1) as usize;
                        (
                            DefectKind::BoundsMismatch,
                            format!(
                                "{differ} tile(s) differ from the tiles' heights, the first \
                                 ({}, {}): recorded {}..={}, the tiles give {}..={}",
                                i % w,
                                i / w,
                                s[0],
                                s[1],
                                e[0],
                                e[1]
                            ),
                        )
                    })
                }
            };
            if let Some((kind, reason)) = wrong {
                self.defect(key, kind, true, reason);
                if self.repair {
                    self.tick()?;
                    self.world.write_bounds(level, &fixed)?;
                    rewritten += 1;
                }
            }
        }
        Ok(rewritten)
    }
}

fn min_max(grid: &Grid<u16>) -> (u16, u16) {
    grid.as_slice()
        .iter()
        .fold((u16::MAX, 0), |(lo, hi), &v| (lo.min(v), hi.max(v)))
}

/// `reason` cut to [`MAX_REASON`] bytes at a character boundary.
fn cut(mut reason: String) -> String {
    if reason.len() > MAX_REASON {
        let end = (0..=MAX_REASON)
            .rev()
            .find(|&i| reason.is_char_boundary(i))
            .unwrap_or(0);
        reason.truncate(end);
        reason.push_str("...");
    }
    reason
}
