//! The write-back journal: a write-back of a height tile changes several files (the tile, then
//! each coarser ancestor and the levels' `bounds.bin`), and a process killed between them
//! leaves ancestors that no longer match their children. Before the tile is written, an empty
//! entry `journal/LL-XXXXXXXX-YYYYYYYY` naming it is stored; it is removed once the ancestors
//! are rebuilt. The next writer ([`RamPool::new`](crate::RamPool::new)) rebuilds the ancestors
//! of every entry it finds, so a world whose owner died mid-write-back is consistent again as
//! soon as another process takes it over.

use crate::build::rebuild_ancestors_shared;
use crate::{CacheError, TileId, World};

/// The store folder of the entries.
pub(crate) const PREFIX: &str = "journal";

/// The entry of tile `id`.
fn key(id: TileId) -> String {
    format!("{PREFIX}/{:02}-{:08x}-{:08x}", id.level, id.x, id.y)
}

/// The tile an entry names, if `key` is one.
fn parse(key: &str) -> Option<TileId> {
    let name = key.strip_prefix(PREFIX)?.strip_prefix('/')?;
    let mut parts = name.split('-');
    let level = parts.next()?.parse::<u32>().ok()?;
    let x = u32::from_str_radix(parts.next()?, 16).ok()?;
    let y = u32::from_str_radix(parts.next()?, 16).ok()?;
    parts.next().is_none().then_some(TileId::new(level, x, y))
}

/// Records that `id`'s ancestors are about to go stale.
pub(crate) fn begin(world: &World, id: TileId) -> Result<(), CacheError> {
    world.store().write(&key(id), b"")
}

/// Records that `id`'s ancestors are current again.
pub(crate) fn end(world: &World, id: TileId) -> Result<(), CacheError> {
    world.store().remove(&key(id))
}

/// Rebuilds the ancestors of every tile a write-back in progress left in the journal (a
/// writer that died, or a write-back that failed), then clears those entries; returns how many
/// tiles were recovered. An entry naming no tile of this world is removed as well. An entry
/// whose ancestors cannot be rebuilt (its tile is damaged) stays, logged: the pool still
/// starts, and `repair_world` or a later write-back of the tile settles it.
pub(crate) fn recover(world: &World) -> Result<usize, CacheError> {
    let m = world.manifest();
    let mut recovered = 0;
    for entry in world.store().list(PREFIX)? {
        if let Some(id) = parse(&entry).filter(|&id| m.check_tile(crate::Layer::Height, id).is_ok())
        {
            match rebuild_ancestors_shared(world, &[id]) {
                Ok(_) => recovered += 1,
                // Nothing can be written: not ours to settle.
                Err(e @ CacheError::ReadOnly { .. }) => return Err(e),
                Err(e) => {
                    tracing::warn!(%id, error = %e, "interrupted write-back not recovered");
                    continue;
                }
            }
        }
        world.store().remove(&entry)?;
    }
    Ok(recovered)
}

/// The level-0 tiles whose write-back a journal entry says was in progress: their files and
/// bounds may disagree until [`recover`] has run.
pub(crate) fn pending_level0(world: &World) -> Result<Vec<TileId>, CacheError> {
    Ok(world
        .store()
        .list(PREFIX)?
        .iter()
        .filter_map(|k| parse(k))
        .filter(|id| id.level == 0)
        .collect())
}

/// Removes every entry (after a repair that rebuilt every coarser level).
pub(crate) fn clear(world: &World) -> Result<(), CacheError> {
    for entry in world.store().list(PREFIX)? {
        world.store().remove(&entry)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_name_their_tile_and_nothing_else_parses() {
        for id in [TileId::new(0, 0, 0), TileId::new(3, 0xffff_ffff, 17)] {
            assert_eq!(parse(&key(id)), Some(id));
        }
        for bad in [
            "journal/00-0-0-0",
            "journal/x-0-0",
            "height/00-0-0",
            "journal/00-zz-0",
            "journal",
        ] {
            assert_eq!(parse(bad), None, "{bad}");
        }
    }
}
