//! A streamed world driven once per frame: the pools and the stamps an engine otherwise wires
//! together itself.
//!
//! [`StreamedWorld`] owns the world's height tiles in a RAM pool (worker threads; a spherical
//! selection three times the default's reach, beyond the VRAM pool's frustum, so what the GPU
//! wants next is already in RAM: Fikkan 2013, sec. 4.3), with a GPU the VRAM pool that fills
//! the caller's tile atlas and the streams of the world's paint and colour, and the stamps
//! queued on its level-0 tiles with their hold / pin / read back / release protocol
//! ([`TileStamps`]). A frame is:
//!
//! 1. [`update`](StreamedWorld::update): the heights' RAM pool follows the camera (loads and
//!    write-backs on worker threads); a tile that failed fails the frame;
//! 2. with a GPU, [`upload`](StreamedWorld::upload) the nearest wanted tiles into the atlas,
//!    within the per-frame budget, and [`upload_paint`](StreamedWorld::upload_paint) /
//!    [`upload_color`](StreamedWorld::upload_color) the overlays' (their RAM pools follow the
//!    camera there);
//! 3. [`push`](StreamedWorld::push) stamps, then [`deform`](StreamedWorld::deform) (the GPU's
//!    deformer stamps the slots, RAM the rest) or, without a GPU,
//!    [`deform_in_ram`](StreamedWorld::deform_in_ram), after the uploads so a GPU stamp lands on
//!    what the slot holds this frame;
//! 4. [`receive`](StreamedWorld::receive) each rect the GPU read back (never waited for).
//!
//! [`finish`](StreamedWorld::finish) ends it: every dirty tile goes back into the world, stamps
//! whose tiles never became resident are written straight into its files, and the coarser
//! levels follow. Granular trails and collision use the RAM pool
//! ([`ram_mut`](StreamedWorld::ram_mut)) beside it. terrain-cache names no GPU type: the
//! atlases and the deformer are the caller's, through terrain-core's contracts.

use crate::build::rebuild_ancestors_shared;
use crate::error::CacheError;
use crate::overlay_stream::OverlayStream;
use crate::policy::{CameraState, SelectionPolicy, SphericalSelection, TileGrid};
use crate::pool::journal;
use crate::pool::{FrameReport, PoolConfig, RamPool};
use crate::tile::{Layer, TileId};
use crate::tile_stamps::{TileStampError, TileStampReport, TileStamps};
use crate::vram::{VramConfig, VramError, VramPool, VramReport};
use crate::world::World;
use std::convert::Infallible;
use std::time::Duration;
use terrain_core::{
    CoreError, Grid, OverlayUploadTarget, RamDeformer, Rect, StampPlacement, TileDeformer,
    TileStamp, TileUploadTarget,
};

/// Why a [`StreamedWorld`] call failed.
#[derive(Debug, thiserror::Error)]
pub enum StreamedWorldError {
    /// The pools or the world refused (a bad camera, a write, a file).
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// A tile of the world could not be read (corrupt, unreadable: the frame would draw and
    /// deform a stand-in in its place) or written back; the pool's error, as text.
    #[error("{layer:?} tile {id} of the world: {message}")]
    Tile {
        /// The tile's layer.
        layer: Layer,
        /// The tile.
        id: TileId,
        /// The pool's error.
        message: String,
    },
    /// A stamp applied in RAM (or in the world's files at the end) failed, or
    /// [`StreamedWorld::deform_in_ram`] was called while GPU stamps are on their way back.
    #[error(transparent)]
    Stamp(#[from] TileStampError<CoreError>),
    /// [`StreamedWorld::enable_gpu`] was called a second time.
    #[error("the streamed world's GPU side is already enabled")]
    GpuEnabled,
    /// [`StreamedWorld::finish`] found GPU-stamped rects still on their way back (everything
    /// else was written), or [`StreamedWorld::deform_in_ram`] would stamp under them.
    #[error("{count} tile readbacks have not arrived: their stamps are not in RAM")]
    ReadbacksOutstanding {
        /// Rects in flight.
        count: usize,
    },
}

/// The GPU side of a [`StreamedWorld`]: its VRAM pool and the overlays' streams.
#[derive(Debug)]
struct GpuSide {
    vram: VramPool,
    paint: Option<OverlayStream>,
    color: Option<OverlayStream>,
}

/// What [`StreamedWorld::finish`] wrote.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WorldWritten {
    /// Write-backs of level-0 tiles the RAM pool finished over the run (a tile written back
    /// twice counts twice), and those it issued at the end.
    pub written_back: u64,
    /// Level-0 tiles stamped straight in the world's files at the end (never resident).
    pub stamped_at_finish: u64,
}

/// A streamed world's pools and stamps, driven once per frame (see the module docs).
#[derive(Debug)]
pub struct StreamedWorld {
    ram: RamPool,
    gpu: Option<GpuSide>,
    stamps: TileStamps<TileStamp>,
    written_back: u64,
    gpu_tiles: u64,
    cpu_tiles: u64,
}

/// The RAM pools' selection: the spherical default's reach three times over.
fn ram_selection(world: &World) -> Box<SphericalSelection> {
    Box::new(StreamedWorld::default_selection(world))
}

impl StreamedWorld {
    /// Streams `world`'s heights through a RAM pool of `ram_budget_bytes`, with no GPU side.
    /// Fails on a budget below the pool's minimum.
    pub fn open(world: World, ram_budget_bytes: u64) -> Result<Self, CacheError> {
        let config = PoolConfig::new(Layer::Height, ram_budget_bytes);
        let policy = ram_selection(&world);
        Self::open_with(world, config, policy)
    }

    /// [`open`](Self::open) with the heights' pool configured by `config` (its budget, workers,
    /// idle write-back) and selecting with `policy` (the overlays' pools keep the
    /// [`default_selection`](Self::default_selection)). Fails on a configuration the pool
    /// refuses, or one of another layer than the heights.
    pub fn open_with(
        world: World,
        config: PoolConfig,
        policy: Box<dyn SelectionPolicy>,
    ) -> Result<Self, CacheError> {
        if config.layer != Layer::Height {
            return Err(CacheError::NoSuchLayer {
                layer: config.layer,
            });
        }
        let manifest = *world.manifest();
        let ram = RamPool::with_policy(world, config, policy)?;
        Ok(Self {
            ram,
            gpu: None,
            stamps: TileStamps::new(&manifest)?,
            written_back: 0,
            gpu_tiles: 0,
            cpu_tiles: 0,
        })
    }

    /// The RAM selection [`open`](Self::open) gives the heights' and the overlays' pools: the
    /// spherical selection of the world's height tiles with three times its default reach,
    /// beyond the VRAM pool's frustum, so what the GPU wants next is already in RAM (Fikkan
    /// 2013, sec. 4.3).
    pub fn default_selection(world: &World) -> SphericalSelection {
        let grid = TileGrid::from_manifest(world.manifest(), Layer::Height);
        let mut spherical = SphericalSelection::for_grid(&grid);
        spherical.lod0_range *= 3.0;
        spherical.view_distance *= 3.0;
        spherical
    }

    /// Adds the GPU side: a VRAM pool of `slots` tile slots (the caller's atlases have as many)
    /// with the default upload budget and selection, and, with `paint` / `color`, the streams
    /// of the world's paint and colour with the heights' selection. Paint tiles are mostly
    /// empty (the pool's shared zero tile costs nothing), so its RAM budget is the heights'
    /// (half as many tiles, at 4 bytes a texel); colour is dense, so twice it (as many tiles).
    /// Fails on 0 slots, on a layer the world does not have, or when called twice; on failure
    /// the world is as before.
    pub fn enable_gpu(
        &mut self,
        slots: u32,
        paint: bool,
        color: bool,
    ) -> Result<(), StreamedWorldError> {
        let vram = VramConfig::new(self.ram.world().manifest(), slots);
        self.enable_gpu_with(vram, paint, color)
    }

    /// [`enable_gpu`](Self::enable_gpu) with the VRAM pool configured by `vram` (its slots,
    /// per-frame upload budget and selection), which the overlays' pools share. Fails as
    /// `enable_gpu` does, or on a configuration of another world.
    pub fn enable_gpu_with(
        &mut self,
        vram: VramConfig,
        paint: bool,
        color: bool,
    ) -> Result<(), StreamedWorldError> {
        if self.gpu.is_some() {
            return Err(StreamedWorldError::GpuEnabled);
        }
        let manifest = *self.ram.world().manifest();
        let own = VramConfig::new(&manifest, vram.slots);
        if vram.grid != own.grid || vram.tile_size != own.tile_size {
            return Err(CacheError::TargetMismatch {
                what: "VRAM configuration's tile grid or size",
                pool: u64::from(own.tile_size),
                target: u64::from(vram.tile_size),
            }
            .into());
        }
        let heights_budget = self.ram.config().budget_bytes;
        let stream = |on: bool, layer: Layer, budget: u64| {
            on.then(|| {
                let budget = budget.max(2 * layer.tile_bytes(manifest.tile_size));
                let world = self.ram.world().clone();
                let policy = ram_selection(&world);
                OverlayStream::new(world, layer, budget, policy, vram.clone())
            })
            .transpose()
        };
        let paint = stream(paint, Layer::Material, heights_budget)?;
        let color = stream(color, Layer::Color, heights_budget.saturating_mul(2))?;
        self.gpu = Some(GpuSide {
            vram: VramPool::new(vram)?,
            paint,
            color,
        });
        Ok(())
    }

    /// The world streamed.
    pub fn world(&self) -> &World {
        self.ram.world()
    }

    /// The heights' RAM pool (ground queries, collision fills, overviews).
    pub fn ram(&self) -> &RamPool {
        &self.ram
    }

    /// The heights' RAM pool, for what writes into it beside the stamps (granular trails).
    pub fn ram_mut(&mut self) -> &mut RamPool {
        &mut self.ram
    }

    /// The VRAM pool, once [`enable_gpu`](Self::enable_gpu) added it.
    pub fn vram(&self) -> Option<&VramPool> {
        self.gpu.as_ref().map(|g| &g.vram)
    }

    /// The paint's and the colour's streams, where enabled.
    pub fn overlay_streams(&self) -> [Option<&OverlayStream>; 2] {
        match &self.gpu {
            Some(g) => [g.paint.as_ref(), g.color.as_ref()],
            None => [None, None],
        }
    }

    /// One frame of the heights' RAM pool for `camera`: loads and write-backs on its workers.
    /// Fails on a bad camera, or on a height tile that could not be read or written back.
    pub fn update(&mut self, camera: &CameraState) -> Result<FrameReport, StreamedWorldError> {
        let report = self.ram.update(camera)?;
        self.written_back += report.written as u64;
        if let Some((id, e)) = self.ram.errors().first() {
            return Err(StreamedWorldError::Tile {
                layer: Layer::Height,
                id: *id,
                message: e.to_string(),
            });
        }
        Ok(report)
    }

    /// Uploads the nearest wanted height tiles in RAM into `atlas`, within the per-frame
    /// budget. Without a GPU side, `None`.
    pub fn upload<T: TileUploadTarget>(
        &mut self,
        camera: &CameraState,
        atlas: &mut T,
    ) -> Result<Option<VramReport>, VramError<T::Error>> {
        match self.gpu.as_mut() {
            Some(g) => g.vram.update(camera, &self.ram, atlas).map(Some),
            None => Ok(None),
        }
    }

    /// One frame of the paint's stream for `camera` (its RAM pool's loads, then uploads into
    /// `atlas` within its budget); `None` when the paint is not streamed. Fails as
    /// [`update`](Self::update) does, on a paint tile.
    pub fn upload_paint<T: OverlayUploadTarget>(
        &mut self,
        camera: &CameraState,
        atlas: &mut T,
    ) -> Result<Option<VramReport>, OverlayUploadError<T::Error>> {
        let stream = self.gpu.as_mut().and_then(|g| g.paint.as_mut());
        stream.map(|s| upload_overlay(s, camera, atlas)).transpose()
    }

    /// [`upload_paint`](Self::upload_paint) for the world's colour.
    pub fn upload_color<T: OverlayUploadTarget>(
        &mut self,
        camera: &CameraState,
        atlas: &mut T,
    ) -> Result<Option<VramReport>, OverlayUploadError<T::Error>> {
        let stream = self.gpu.as_mut().and_then(|g| g.color.as_mut());
        stream.map(|s| upload_overlay(s, camera, atlas)).transpose()
    }

    /// Paint tiles whose files were rewritten (what `write_paint` returned): read again and
    /// uploaded again.
    pub fn reload_paint(&mut self, ids: &[TileId]) {
        if let Some(paint) = self.gpu.as_mut().and_then(|g| g.paint.as_mut()) {
            paint.reload(ids);
        }
    }

    /// [`reload_paint`](Self::reload_paint) for colour tiles (what `write_color` returned).
    pub fn reload_color(&mut self, ids: &[TileId]) {
        if let Some(color) = self.gpu.as_mut().and_then(|g| g.color.as_mut()) {
            color.reload(ids);
        }
    }

    /// Queues `stamp` at `placement` (world metres) on every level-0 tile it touches; returns
    /// how many (0 off the world). See [`TileStamps::push`].
    pub fn push(
        &mut self,
        stamp: TileStamp,
        placement: StampPlacement,
    ) -> Result<usize, CacheError> {
        self.stamps.push(stamp, placement)
    }

    /// Applies the queued stamps to their resident tiles: on the GPU through `deformer` where
    /// the VRAM pool holds the tile (its rects come back through [`receive`](Self::receive)),
    /// else in RAM. Call after [`upload`](Self::upload).
    pub fn deform<D: TileDeformer<TileStamp>>(
        &mut self,
        deformer: &mut D,
    ) -> Result<TileStampReport, TileStampError<D::Error>> {
        let vram = self.gpu.as_mut().map(|g| &mut g.vram);
        let report = self.stamps.apply(&mut self.ram, vram, deformer)?;
        self.count(&report);
        Ok(report)
    }

    /// Applies the queued stamps to their resident tiles in RAM, without a GPU; with one the
    /// VRAM pool uploads the changed tiles again. Refused while GPU-stamped rects are on their
    /// way back: an arriving rect would overwrite the RAM stamp under it.
    pub fn deform_in_ram(&mut self) -> Result<TileStampReport, StreamedWorldError> {
        let count = self.stamps.in_flight();
        if count > 0 {
            return Err(StreamedWorldError::ReadbacksOutstanding { count });
        }
        let report = self.stamps.apply(&mut self.ram, None, &mut RamDeformer)?;
        self.count(&report);
        Ok(report)
    }

    fn count(&mut self, report: &TileStampReport) {
        self.gpu_tiles += u64::from(report.gpu_tiles);
        self.cpu_tiles += u64::from(report.cpu_tiles);
    }

    /// A rect the deformer read back arrived (`ticket` and `rect` as it gave them): into the
    /// RAM tile, its pin and hold released. Returns the rect in world texels (level 0). A rect
    /// nobody asked for, or of another size, is refused and changes nothing.
    pub fn receive(
        &mut self,
        ticket: u64,
        rect: Rect,
        heights: &Grid<u16>,
    ) -> Result<Rect, TileStampError<Infallible>> {
        let vram = self.gpu.as_mut().map(|g| &mut g.vram);
        let (_, world) = self
            .stamps
            .receive(&mut self.ram, vram, ticket, rect, heights)?;
        Ok(world)
    }

    /// Gives up on every GPU-stamped rect still on its way back (the device was lost): pins and
    /// holds end, the slots are uploaded again from RAM, and those rects' stamps are not in
    /// the world. Returns how many were given up; [`finish`](Self::finish) can follow.
    pub fn abandon_readbacks(&mut self) -> usize {
        let vram = self.gpu.as_mut().map(|g| &mut g.vram);
        self.stamps.abandon(&mut self.ram, vram)
    }

    /// Stamps queued and not yet on every tile they touch.
    pub fn stamps_pending(&self) -> usize {
        self.stamps.pending()
    }

    /// GPU-stamped rects on their way back.
    pub fn readbacks_in_flight(&self) -> usize {
        self.stamps.in_flight()
    }

    /// Level-0 tiles stamped on the GPU and in RAM so far.
    pub fn tiles_stamped(&self) -> (u64, u64) {
        (self.gpu_tiles, self.cpu_tiles)
    }

    /// Level-0 tiles written back so far.
    pub fn written_back(&self) -> u64 {
        self.written_back
    }

    /// Ends the run: release the granular trails first, and receive every readback (or
    /// [`abandon_readbacks`](Self::abandon_readbacks)). Every dirty tile is written back
    /// (waiting at most `timeout` for the heights' pool, and as long again for each overlay's),
    /// stamps whose tiles never became resident go straight into the world's files, and their
    /// coarser levels are rebuilt (journalled, as the pool's write-backs are). Each step runs
    /// whatever an earlier one reported; the first failure is returned, after everything else
    /// was written. Returns what was written and the world.
    pub fn finish(self, timeout: Duration) -> Result<(WorldWritten, World), StreamedWorldError> {
        let Self {
            mut ram,
            gpu,
            mut stamps,
            written_back,
            ..
        } = self;
        let mut first: Option<StreamedWorldError> = None;
        let mut keep = |r: Result<(), StreamedWorldError>| {
            if let Err(e) = r {
                first.get_or_insert(e);
            }
        };
        if stamps.in_flight() > 0 {
            let count = stamps.in_flight();
            keep(Err(StreamedWorldError::ReadbacksOutstanding { count }));
        }
        let world = ram.world().clone();
        let issued = ram.flush() as u64;
        // Stopped even when a write-back (or a read of the last frames) failed: its threads
        // are joined, so nothing races the writes below.
        keep(ram.shutdown(timeout).map_err(Into::into));
        let late = write_late_stamps(&world, &mut stamps);
        let stamped_at_finish = late.as_ref().map_or(0, |l| l.len() as u64);
        keep(late.map(drop));
        if let Some(g) = gpu {
            for stream in [g.paint, g.color].into_iter().flatten() {
                keep(stream.shutdown(timeout).map_err(Into::into));
            }
        }
        match first {
            Some(e) => Err(e),
            None => Ok((
                WorldWritten {
                    written_back: written_back + issued,
                    stamped_at_finish,
                },
                world,
            )),
        }
    }
}

/// One frame of an overlay's stream into `atlas`, failing on a tile its pool could not read.
fn upload_overlay<T: OverlayUploadTarget>(
    stream: &mut OverlayStream,
    camera: &CameraState,
    atlas: &mut T,
) -> Result<VramReport, OverlayUploadError<T::Error>> {
    let (_, uploaded) = stream.update(camera, atlas)?;
    if let Some((id, e)) = stream.ram().errors().first() {
        return Err(OverlayUploadError::Tile(StreamedWorldError::Tile {
            layer: stream.layer(),
            id: *id,
            message: e.to_string(),
        }));
    }
    Ok(uploaded)
}

/// The queued stamps into the files of the tiles they have not reached, each tile journalled
/// until its coarser levels are rebuilt (a process killed in between leaves the journal entry
/// the next writer recovers from); returns the tiles written.
fn write_late_stamps(
    world: &World,
    stamps: &mut TileStamps<TileStamp>,
) -> Result<Vec<TileId>, StreamedWorldError> {
    let tiles = stamps.pending_tiles();
    for id in &tiles {
        journal::begin(world, *id)?;
    }
    let late = stamps.finish_into_world(world, &mut RamDeformer)?;
    rebuild_ancestors_shared(world, &late)?;
    for id in &tiles {
        journal::end(world, *id)?;
    }
    Ok(late)
}

/// Why [`StreamedWorld::upload_paint`] or [`StreamedWorld::upload_color`] failed.
#[derive(Debug, thiserror::Error)]
pub enum OverlayUploadError<E> {
    /// A tile of the overlay could not be read ([`StreamedWorldError::Tile`]).
    #[error(transparent)]
    Tile(StreamedWorldError),
    /// A bad camera, or the VRAM pool or the atlas refused.
    #[error(transparent)]
    Upload(#[from] VramError<E>),
}
