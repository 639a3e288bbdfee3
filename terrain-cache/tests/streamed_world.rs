//! `StreamedWorld` driven as an engine drives it, once per frame, with a GPU stood in for by
//! an atlas that keeps each slot's heights and stamps them in place, its rects arriving a
//! frame late: the world it leaves equals the one a RAM-only run leaves byte for byte, stamps
//! land on the GPU, in RAM and (never resident) in the files at the end, and what it cannot
//! do is refused without losing anything.

mod common;

use common::build;
use glam::{UVec2, Vec2, Vec3};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::{
    CameraState, Layer, ObjectTileStore, PoolConfig, StreamedWorld, StreamedWorldError, TileId,
    TileState, TileStore, VramConfig, World,
};
use terrain_core::{
    CoarseMap, CoreError, GaussianStamp, Grid, MaterialEffect, OverlayAtlas, Rect, StampPlacement,
    TileAtlas, TileDeformer, TileLayout, TileStamp, TileUploadTarget, WrapMode,
    apply_material_effect,
};

const SLOTS: u32 = 24;
/// RAM for 48 level-0 tiles of the 256: the far corner is never resident.
const BUDGET: u64 = 48 * 32 * 32 * 2;
const TIMEOUT: Duration = Duration::from_secs(20);

/// The stand-in GPU: an atlas whose slots keep their heights (what an upload put there, and
/// every stamp since), and a readback queue of the rects each stamp changed.
struct FakeGpu {
    atlas: TileAtlas,
    slots: HashMap<u32, CoarseMap>,
    next_ticket: u64,
    arrived: Vec<(u64, Rect, Grid<u16>)>,
}

impl FakeGpu {
    fn new(layout: TileLayout) -> Self {
        Self {
            atlas: TileAtlas::new(layout, SLOTS).unwrap(),
            slots: HashMap::new(),
            next_ticket: 0,
            arrived: Vec::new(),
        }
    }
}

impl TileUploadTarget for FakeGpu {
    type Error = CoreError;
    fn layout(&self) -> &TileLayout {
        self.atlas.layout()
    }
    fn slot_count(&self) -> u32 {
        self.atlas.slot_count()
    }
    fn upload_bytes(&self) -> u64 {
        self.atlas.upload_bytes()
    }
    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        h: &Grid<u16>,
    ) -> Result<u64, CoreError> {
        let l = *self.atlas.layout();
        let texel = l.texel_size * (1u32 << level) as f32;
        let map = CoarseMap::new(h.clone(), l.encoding, texel, WrapMode::Clamp)?;
        self.slots.insert(slot, map);
        self.atlas.upload(slot, level, tile, h)
    }
    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), CoreError> {
        self.atlas.map(level, tile, slot)
    }
}

impl TileDeformer<TileStamp> for FakeGpu {
    type Error = CoreError;
    fn stamp_slot(
        &mut self,
        slot: u32,
        kind: &TileStamp,
        placement: &StampPlacement,
    ) -> Result<Option<Vec<(u64, Rect)>>, CoreError> {
        let map = self
            .slots
            .get_mut(&slot)
            .expect("a stamped slot was uploaded");
        let mut tickets = Vec::new();
        for r in kind.apply(map, placement)? {
            self.next_ticket += 1;
            let heights = map.grid().copy_rect(r)?;
            self.arrived.push((self.next_ticket, r, heights));
            tickets.push((self.next_ticket, r));
        }
        Ok(Some(tickets))
    }
    fn stamp_ram(
        &mut self,
        kind: &TileStamp,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>, CoreError> {
        kind.apply(tile, placement)
    }
}

fn world() -> World {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    build(store, UVec2::splat(512), 32)
}

fn crater(at: Vec2, size: f32) -> (TileStamp, StampPlacement) {
    let stamp = TileStamp::Gaussian(GaussianStamp::default());
    (
        stamp,
        StampPlacement::new(at, Vec2::splat(size), -2.0).unwrap(),
    )
}

/// 40 frames along a line: a crater ahead every 3rd frame and one far away on the first, on
/// the GPU stand-in (`gpu`) or in RAM. Returns the tiles stamped (GPU, RAM), what finish
/// wrote, and the world.
fn run(gpu: bool) -> ((u64, u64), terrain_cache::WorldWritten, World) {
    let world = world();
    let mut streamed = StreamedWorld::open(world, BUDGET).unwrap();
    let mut fake = FakeGpu::new(streamed.world().manifest().tile_layout());
    if gpu {
        streamed.enable_gpu(SLOTS, false, false).unwrap();
    }
    let far = crater(Vec2::new(500.0, 20.0), 9.0);
    assert!(streamed.push(far.0, far.1).unwrap() > 0);
    let mut late: Vec<(u64, Rect, Grid<u16>)> = Vec::new();
    for frame in 0..40u32 {
        let xz = Vec2::new(60.0 + frame as f32 * 3.0, 80.0 + frame as f32 * 1.5);
        let camera = CameraState::at(Vec3::new(xz.x, 30.0, xz.y));
        streamed.update(&camera).unwrap();
        if frame % 3 == 0 {
            let (stamp, p) = crater(xz + Vec2::new(12.0, 4.0), 10.0);
            streamed.push(stamp, p).unwrap();
        }
        // Last frame's rects arrive now; this frame's wait for the next.
        for (ticket, rect, heights) in late.drain(..) {
            streamed.receive(ticket, rect, &heights).unwrap();
        }
        if gpu {
            streamed.upload(&camera, &mut fake).unwrap().unwrap();
            streamed.deform(&mut fake).unwrap();
            late = std::mem::take(&mut fake.arrived);
        } else {
            assert!(streamed.upload(&camera, &mut fake).unwrap().is_none());
            streamed.deform_in_ram().unwrap();
        }
        std::thread::sleep(Duration::from_millis(3));
    }
    for (ticket, rect, heights) in late {
        streamed.receive(ticket, rect, &heights).unwrap();
    }
    assert_eq!(streamed.readbacks_in_flight(), 0);
    let stamped = streamed.tiles_stamped();
    let (written, world) = streamed.finish(TIMEOUT).unwrap();
    (stamped, written, world)
}

fn tiles(world: &World) -> Vec<(TileId, Vec<u16>)> {
    let m = *world.manifest();
    let mut out = Vec::new();
    for level in 0..m.levels {
        let n = m.tiles_at(level);
        for i in 0..n.x * n.y {
            let id = TileId::new(level, i % n.x, i / n.x);
            let data = world.load_tile(Layer::Height, id).unwrap();
            out.push((id, data.as_u16().unwrap().as_slice().to_vec()));
        }
    }
    out
}

#[test]
fn a_gpu_run_leaves_the_world_a_ram_run_leaves() {
    let ((gpu_tiles, gpu_ram_tiles), gpu_written, gpu_world) = run(true);
    let ((no_gpu, ram_tiles), ram_written, ram_world) = run(false);
    assert!(gpu_tiles > 0, "some tiles stamped in their slots");
    assert_eq!(no_gpu, 0);
    assert_eq!(
        gpu_tiles + gpu_ram_tiles,
        ram_tiles,
        "each tile stamped once either way"
    );
    assert_eq!(gpu_written.stamped_at_finish, ram_written.stamped_at_finish);
    assert!(
        ram_written.stamped_at_finish > 0,
        "the far crater went into the files"
    );
    assert!(gpu_written.written_back > 0 && ram_written.written_back > 0);
    let (a, b) = (tiles(&gpu_world), tiles(&ram_world));
    assert_eq!(a.len(), b.len());
    for ((id, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "tile {id} differs between the GPU and the RAM run");
    }
    // And the stamps are there: the world differs from one never stamped, and every coarser
    // tile is its children's reduction (the far crater's ancestors were rebuilt).
    assert_ne!(tiles(&world()), b);
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let options = terrain_cache::VerifyOptions::default();
    let report = terrain_cache::verify_world(&gpu_world, &options, &cancel, &mut |_| {}).unwrap();
    assert_eq!(report.defects, 0, "{:?}", report.listed);
}

#[test]
fn what_a_streamed_world_cannot_do_is_refused_and_loses_nothing() {
    let mut streamed = StreamedWorld::open(world(), BUDGET).unwrap();
    // No slots: the GPU side is refused and not half made.
    let e = streamed.enable_gpu(0, true, false).unwrap_err();
    assert!(matches!(e, StreamedWorldError::Cache(_)), "{e}");
    assert!(streamed.vram().is_none());
    // A VRAM configuration of another world's tiles is refused.
    let other = build(
        Arc::new(ObjectTileStore::in_memory().unwrap()),
        UVec2::splat(256),
        16,
    );
    let foreign = VramConfig::new(other.manifest(), SLOTS);
    let e = streamed.enable_gpu_with(foreign, false, false).unwrap_err();
    assert!(matches!(e, StreamedWorldError::Cache(_)), "{e}");
    assert!(streamed.vram().is_none());
    streamed.enable_gpu(SLOTS, false, false).unwrap();
    let e = streamed.enable_gpu(SLOTS, false, false).unwrap_err();
    assert!(matches!(e, StreamedWorldError::GpuEnabled), "{e}");

    // A camera that is not finite, a stamp off the world, a readback nobody asked for.
    let nan = CameraState::at(Vec3::new(f32::NAN, 1.0, 2.0));
    assert!(streamed.update(&nan).is_err());
    let (stamp, off) = crater(Vec2::new(-900.0, 5.0), 4.0);
    assert_eq!(streamed.push(stamp, off).unwrap(), 0);
    let bogus = Grid::new(2, 2, 0u16).unwrap();
    let rect = Rect::from_size(UVec2::splat(2));
    assert!(streamed.receive(7, rect, &bogus).is_err());

    // With a crater's rects on their way back, a RAM stamp (which they would overwrite) is
    // refused; a run that ends so names them, and still writes the rest: a crater whose tiles
    // never became resident reaches the files.
    let (mut streamed, _, count) = stamped_on_the_gpu(streamed);
    let e = streamed.deform_in_ram().unwrap_err();
    assert!(
        matches!(e, StreamedWorldError::ReadbacksOutstanding { .. }),
        "{e}"
    );
    let far = crater(Vec2::new(500.0, 20.0), 9.0);
    assert!(streamed.push(far.0, far.1).unwrap() > 0);
    let e = streamed.finish(TIMEOUT).unwrap_err();
    assert!(
        matches!(e, StreamedWorldError::ReadbacksOutstanding { count: c } if c == count),
        "{e}"
    );
}

/// Streams `streamed` around a crater stamped on a GPU stand-in until its rects are on their
/// way back (never received); returns it, the stand-in and how many rects are.
fn stamped_on_the_gpu(mut streamed: StreamedWorld) -> (StreamedWorld, FakeGpu, usize) {
    let mut fake = FakeGpu::new(streamed.world().manifest().tile_layout());
    let camera = CameraState::at(Vec3::new(100.0, 30.0, 100.0));
    let (stamp, p) = crater(Vec2::new(100.0, 100.0), 10.0);
    streamed.push(stamp, p).unwrap();
    for _ in 0..400 {
        streamed.update(&camera).unwrap();
        streamed.upload(&camera, &mut fake).unwrap();
        streamed.deform(&mut fake).unwrap();
        if streamed.readbacks_in_flight() > 0 {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let count = streamed.readbacks_in_flight();
    assert!(count > 0, "the crater was stamped on the GPU stand-in");
    assert!(streamed.vram().unwrap().held() > 0, "its slots held");
    (streamed, fake, count)
}

#[test]
fn configurations_of_its_own_are_kept_and_others_refused() {
    let world = world();
    // A pool of another layer than the heights: refused.
    let paint = PoolConfig::new(Layer::Material, BUDGET);
    let policy = Box::new(StreamedWorld::default_selection(&world));
    assert!(StreamedWorld::open_with(world.clone(), paint, policy).is_err());
    // The heights' pool with a selection of the caller's (a narrower reach).
    let mut selection = StreamedWorld::default_selection(&world);
    selection.lod0_range /= 3.0;
    let config = PoolConfig::new(Layer::Height, BUDGET);
    let mut streamed = StreamedWorld::open_with(world, config, Box::new(selection)).unwrap();
    // An upload budget of one 32^2 tile a frame.
    let mut vram = VramConfig::new(streamed.world().manifest(), SLOTS);
    vram.upload_budget_bytes = 32 * 32 * 2;
    streamed.enable_gpu_with(vram, false, false).unwrap();
    let mut fake = FakeGpu::new(streamed.world().manifest().tile_layout());
    let camera = CameraState::at(Vec3::new(100.0, 30.0, 100.0));
    let mut uploads = 0;
    for _ in 0..20 {
        streamed.update(&camera).unwrap();
        let r = streamed.upload(&camera, &mut fake).unwrap().unwrap();
        assert_eq!(r.budget_bytes, 32 * 32 * 2);
        assert!(r.uploads <= 1, "{r:?}");
        uploads += r.uploads;
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(uploads > 0);
    streamed.finish(TIMEOUT).unwrap();
}

#[test]
fn readbacks_given_up_free_their_tiles_and_the_rest_is_written() {
    let world = world();
    let untouched = tiles(&world);
    let mut streamed = StreamedWorld::open(world, BUDGET).unwrap();
    streamed.enable_gpu(SLOTS, false, false).unwrap();
    let (mut streamed, mut fake, count) = stamped_on_the_gpu(streamed);
    let far = crater(Vec2::new(500.0, 20.0), 9.0);
    assert!(streamed.push(far.0, far.1).unwrap() > 0);
    assert_eq!(streamed.abandon_readbacks(), count);
    assert_eq!(streamed.readbacks_in_flight(), 0);
    assert_eq!(streamed.vram().unwrap().held(), 0, "every hold ended");
    let pinned = streamed.ram().statuses().into_iter();
    let pinned = pinned.filter(|(_, s)| s.state == TileState::InUse).count();
    assert_eq!(pinned, 0, "every pin ended");
    // The slots given up hold a change RAM does not: uploaded again from RAM.
    let camera = CameraState::at(Vec3::new(100.0, 30.0, 100.0));
    streamed.update(&camera).unwrap();
    let again = streamed.upload(&camera, &mut fake).unwrap().unwrap();
    assert!(again.uploads > 0, "{again:?}");
    let (written, world) = streamed.finish(TIMEOUT).unwrap();
    // The near crater's rects were given up; the far one went into its tiles' files.
    assert!(written.stamped_at_finish > 0);
    let changed: Vec<TileId> = (tiles(&world).into_iter().zip(&untouched))
        .filter(|((_, a), (_, b))| a != b)
        .map(|((id, _), _)| id)
        .collect();
    assert!(!changed.is_empty());
    assert!(
        changed.iter().all(|id| id.x >= 14 >> id.level),
        "only the far crater's tiles (x >= 14 at level 0) changed: {changed:?}"
    );
}

#[test]
fn paint_streams_into_its_atlas_and_follows_a_rewrite() {
    let world = world();
    let m = *world.manifest();
    let mut streamed = StreamedWorld::open(world.clone(), BUDGET).unwrap();
    streamed.enable_gpu(SLOTS, true, false).unwrap();
    let mut atlas = OverlayAtlas::new(m.tile_layout(), SLOTS).unwrap();
    let camera = CameraState::at(Vec3::new(100.0, 30.0, 100.0));
    let at = glam::DVec2::splat(100.0);
    let mut color = OverlayAtlas::new(m.tile_layout(), SLOTS).unwrap();
    // No colour streamed: nothing uploaded, and no error.
    assert!(
        streamed
            .upload_color(&camera, &mut color)
            .unwrap()
            .is_none()
    );
    let mut paint_shown = |streamed: &mut StreamedWorld, want: f32| {
        for _ in 0..400 {
            streamed.update(&camera).unwrap();
            let r = streamed.upload_paint(&camera, &mut atlas).unwrap().unwrap();
            // Settled, with the level-0 tile under `at` (32 m tiles) in the atlas.
            let finest = atlas.slot_of(0, UVec2::splat(3)).is_some();
            if r.uploads == 0 && finest && (atlas.sample(at, false).y - want).abs() < 0.01 {
                return;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        panic!("the atlas never showed paint {want}");
    };
    paint_shown(&mut streamed, 0.0);
    // Dirt painted into the world's files while it streams: shown once reloaded.
    let rect = Rect::new(glam::IVec2::splat(90), UVec2::splat(20));
    let mut paint = terrain_cache::read_paint(&world, rect).unwrap();
    let local = StampPlacement::new(Vec2::splat(10.0), Vec2::splat(12.0), -1.0).unwrap();
    let dirt = MaterialEffect::new(1, 0.9).unwrap();
    apply_material_effect(&mut paint, WrapMode::Clamp, m.texel_size, &local, &dirt).unwrap();
    let rewritten = terrain_cache::write_paint(&world, rect, &paint).unwrap();
    streamed.reload_paint(&rewritten);
    paint_shown(&mut streamed, 0.9);
    streamed.finish(TIMEOUT).unwrap();
}

#[test]
fn a_tile_that_cannot_be_read_fails_the_frame_with_its_name() {
    let world = world();
    let id = TileId::new(0, 3, 3);
    let key = world.manifest().tile_key(Layer::Height, id);
    world.store().write(&key, b"not a tile").unwrap();
    let mut streamed = StreamedWorld::open(world, BUDGET).unwrap();
    let camera = CameraState::at(Vec3::new(112.0, 20.0, 112.0));
    for _ in 0..400 {
        match streamed.update(&camera) {
            Ok(_) => std::thread::sleep(Duration::from_millis(5)),
            Err(StreamedWorldError::Tile { layer, id: bad, .. }) => {
                assert_eq!((layer, bad), (Layer::Height, id));
                return;
            }
            Err(e) => panic!("{e}"),
        }
    }
    panic!("the corrupt tile was never reported");
}
