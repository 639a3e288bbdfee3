//! The pool's threads: loaders decode tiles from the world, the writer stores dirty tiles
//! atomically (and refreshes their coarser ancestors); the frame thread talks to them through
//! channels and one atomic state per load job, which it swaps to cancel or rescue a job. The
//! detail cache runs the same threads (`crate::detail`), so both layers stream alike.

use super::journal;
use crate::CacheError;
use crate::build::rebuild_ancestors_shared;
use crate::tile::{Layer, TileData, TileId};
use crate::world::World;
use crossbeam_channel::{Receiver, Sender};
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

// The states of a load job's cell: the frame thread swaps QUEUED and CANCELLED, a loader
// takes QUEUED to LOADING or CANCELLED to SKIPPED.
pub(crate) const QUEUED: u8 = 0;
pub(crate) const LOADING: u8 = 1;
pub(crate) const CANCELLED: u8 = 2;
pub(crate) const SKIPPED: u8 = 3;

#[derive(Debug)]
pub(crate) struct JobCell {
    pub(crate) state: AtomicU8,
}

pub(crate) struct LoadJob {
    pub(crate) id: TileId,
    pub(crate) ticket: u64,
    pub(crate) cell: Arc<JobCell>,
}

pub(crate) enum LoadDone {
    Loaded {
        id: TileId,
        ticket: u64,
        result: Result<Arc<TileData>, CacheError>,
    },
    Skipped {
        id: TileId,
        ticket: u64,
    },
}

pub(crate) struct WriteJob {
    pub(crate) id: TileId,
    pub(crate) generation: u64,
    pub(crate) data: Arc<TileData>,
}

pub(crate) struct WriteDone {
    pub(crate) id: TileId,
    pub(crate) generation: u64,
    pub(crate) result: Result<Vec<TileId>, CacheError>,
}

pub(crate) fn loader(world: World, layer: Layer, rx: Receiver<LoadJob>, tx: Sender<LoadDone>) {
    while let Ok(job) = rx.recv() {
        // Take the job (QUEUED -> LOADING) or make its cancellation final (CANCELLED ->
        // SKIPPED); retry if the frame thread swapped the state in between.
        let take = loop {
            match job.cell.state.load(Ordering::Acquire) {
                QUEUED => {
                    if job
                        .cell
                        .state
                        .compare_exchange(QUEUED, LOADING, Ordering::AcqRel, Ordering::Acquire)
                        .is_ok()
                    {
                        break true;
                    }
                }
                CANCELLED => {
                    if job
                        .cell
                        .state
                        .compare_exchange(CANCELLED, SKIPPED, Ordering::AcqRel, Ordering::Acquire)
                        .is_ok()
                    {
                        break false;
                    }
                }
                _ => break false,
            }
        };
        let msg = if take {
            LoadDone::Loaded {
                id: job.id,
                ticket: job.ticket,
                result: world.load_tile(layer, job.id),
            }
        } else {
            LoadDone::Skipped {
                id: job.id,
                ticket: job.ticket,
            }
        };
        if tx.send(msg).is_err() {
            return;
        }
    }
}

pub(crate) fn writer(
    world: World,
    layer: Layer,
    propagate: bool,
    rx: Receiver<WriteJob>,
    tx: Sender<WriteDone>,
) {
    while let Ok(job) = rx.recv() {
        let result = if propagate {
            // Journalled: a kill between the tile and its ancestors is recovered by the next
            // writer (journal.rs).
            journal::begin(&world, job.id)
                .and_then(|_| world.write_tile(layer, job.id, &job.data))
                .and_then(|_| rebuild_ancestors_shared(&world, &[job.id]))
                .and_then(|rebuilt| journal::end(&world, job.id).map(|_| rebuilt))
        } else {
            world
                .write_tile(layer, job.id, &job.data)
                .map(|_| Vec::new())
        };
        drop(job.data);
        if tx
            .send(WriteDone {
                id: job.id,
                generation: job.generation,
                result,
            })
            .is_err()
        {
            return;
        }
    }
}
