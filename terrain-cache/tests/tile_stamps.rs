//! The tile stamping protocol of `TileStamps` on a real RAM pool and VRAM pool, with a GPU
//! stood in for by tile copies per slot (what the atlas holds): every tile a stamp touches gets
//! it exactly once, on the "GPU" where the tile has a slot (held and pinned until its rects come
//! back) and in RAM elsewhere, the world written back equals the stamps applied tile by tile,
//! and stamps whose tiles never became resident still reach the world's files.

mod common;

use common::build;
use glam::{UVec2, Vec2, Vec3};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, Layer, ObjectTileStore, PoolConfig, RamPool, SphericalSelection, TileDeformer,
    TileId, TileStampError, TileStamps, TileStore, VramConfig, VramPool, World,
};
use terrain_core::{
    Blend, CoarseMap, CoreError, GaussianStamp, Grid, Rect, StampPlacement, TileAtlas, WrapMode,
    apply_stamp,
};

/// The stand-in GPU: each slot's tile as a map (copied from RAM when the test takes a
/// snapshot), stamped in place; its changed rects wait in `arrived` as a readback would.
#[derive(Default)]
struct FakeGpu {
    slots: HashMap<u32, CoarseMap>,
    next_ticket: u64,
    arrived: Vec<(u64, Rect, Grid<u16>)>,
    /// No readback to be had: `stamp_slot` refuses (nothing stamped).
    ring_full: bool,
    gauss: GaussianStamp,
}

impl TileDeformer<f32> for FakeGpu {
    type Error = CoreError;

    fn stamp_slot(
        &mut self,
        slot: u32,
        depth: &f32,
        placement: &StampPlacement,
    ) -> Result<Option<Vec<(u64, Rect)>>, CoreError> {
        if self.ring_full {
            return Ok(None);
        }
        let map = self.slots.get_mut(&slot).expect("a snapshot of every slot");
        let p = StampPlacement {
            intensity: *depth,
            ..*placement
        };
        let rects = apply_stamp(map, &mut self.gauss, &p, Blend::Add)?;
        let mut tickets = Vec::new();
        for r in rects {
            self.next_ticket += 1;
            self.arrived
                .push((self.next_ticket, r, map.grid().copy_rect(r)?));
            tickets.push((self.next_ticket, r));
        }
        Ok(Some(tickets))
    }

    fn stamp_ram(
        &mut self,
        depth: &f32,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>, CoreError> {
        let p = StampPlacement {
            intensity: *depth,
            ..*placement
        };
        apply_stamp(tile, &mut self.gauss, &p, Blend::Add)
    }
}

/// The world's level-0 tile `id` with `stamps` (world metres) applied in its own frame, one by
/// one: what the protocol must leave in the world.
fn expected_tile(world: &World, id: TileId, stamps: &[(f32, StampPlacement)]) -> Grid<u16> {
    let m = world.manifest();
    let data = world.load_tile(Layer::Height, id).expect("tile");
    let grid = data.as_u16().expect("u16").clone();
    let mut map = CoarseMap::new(grid, m.encoding, m.texel_size, WrapMode::Clamp).expect("map");
    let origin = UVec2::new(id.x, id.y).as_vec2() * m.tile_size as f32 * m.texel_size;
    for (depth, p) in stamps {
        let local = StampPlacement {
            center: p.center - origin,
            intensity: *depth,
            ..*p
        };
        apply_stamp(&mut map, &mut GaussianStamp::default(), &local, Blend::Add).expect("stamp");
    }
    map.into_grid()
}

#[test]
fn every_touched_tile_gets_each_stamp_once_on_the_gpu_or_in_ram() {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let world = build(store, UVec2::splat(512), 32);
    let original = {
        // A second, untouched copy of the world to compute what the tiles must become.
        let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        build(store, UVec2::splat(512), 32)
    };
    let m = *world.manifest();
    let spherical = SphericalSelection {
        view_distance: 1e4,
        lod0_range: 3.0 * 32.0,
        lod_ratio: 2.0,
    };
    let mut ram = RamPool::with_policy(
        world.clone(),
        PoolConfig::new(Layer::Height, 200 * 32 * 32 * 2),
        Box::new(spherical),
    )
    .unwrap();
    let slots = 24;
    let mut vram = VramPool::new(VramConfig::new(&m, slots)).unwrap();
    let mut atlas = TileAtlas::new(m.tile_layout(), slots).unwrap();
    let camera = CameraState::at(Vec3::new(64.0, 40.0, 64.0));
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut quiet = 0;
    loop {
        ram.update(&camera).unwrap();
        let r = vram.update(&camera, &ram, &mut atlas).unwrap();
        // Settled: the slots are full (more tiles are wanted than 24 slots hold, so some
        // tiles near the camera are in RAM only and are stamped there).
        quiet = if r.uploads == 0 { quiet + 1 } else { 0 };
        if quiet >= 20 {
            break;
        }
        assert!(Instant::now() < deadline, "did not settle: {r:?}");
        std::thread::sleep(Duration::from_millis(2));
    }

    // Craters near the camera (across tile corners: 4 tiles each) and one far away, whose
    // tiles are not resident.
    let stamps = [
        (
            -3.0,
            StampPlacement::new(Vec2::new(64.0, 64.0), Vec2::splat(10.0), 1.0).unwrap(),
        ),
        (
            2.0,
            StampPlacement::new(Vec2::new(66.0, 60.0), Vec2::splat(7.0), 1.0).unwrap(),
        ),
        (
            -1.0,
            StampPlacement::new(Vec2::new(96.0, 40.0), Vec2::splat(6.0), 1.0).unwrap(),
        ),
        (
            -2.0,
            StampPlacement::new(Vec2::new(480.0, 480.0), Vec2::splat(9.0), 1.0).unwrap(),
        ),
    ];
    let mut tile_stamps = TileStamps::new(&m).unwrap();
    let mut touched = 0;
    for (depth, p) in stamps {
        touched += tile_stamps.push(depth, p).unwrap();
    }
    assert_eq!(tile_stamps.pending(), 4);
    // Off the world: nothing queued.
    let off = StampPlacement::new(Vec2::new(-500.0, 9.0), Vec2::splat(4.0), 1.0).unwrap();
    assert_eq!(tile_stamps.push(-1.0, off).unwrap(), 0);

    let snapshot = |vram: &VramPool, ram: &RamPool, gpu: &mut FakeGpu| {
        gpu.slots.clear();
        for id in vram.resident_ids().into_iter().filter(|id| id.level == 0) {
            let slot = vram.slot_of(id).unwrap();
            let grid = ram.tile(id).unwrap().as_u16().unwrap().clone();
            let map = CoarseMap::new(grid, m.encoding, m.texel_size, WrapMode::Clamp).unwrap();
            gpu.slots.insert(slot, map);
        }
    };
    let mut gpu = FakeGpu::default();
    snapshot(&vram, &ram, &mut gpu);

    // A full readback ring: the slots are left alone, holds released, nothing done on the GPU.
    gpu.ring_full = true;
    let r = tile_stamps
        .apply(&mut ram, Some(&mut vram), &mut gpu)
        .unwrap();
    assert_eq!(r.gpu_tiles, 0);
    assert_eq!(vram.held(), 0);
    gpu.ring_full = false;
    let before_cpu = r.cpu_tiles;

    let r = tile_stamps
        .apply(&mut ram, Some(&mut vram), &mut gpu)
        .unwrap();
    assert!(r.gpu_tiles > 0, "{r:?}");
    assert!(vram.held() > 0, "held while the rects are on their way");
    assert_eq!(tile_stamps.in_flight(), gpu.arrived.len());
    // Applying again stamps nothing twice.
    let again = tile_stamps
        .apply(&mut ram, Some(&mut vram), &mut gpu)
        .unwrap();
    assert_eq!((again.gpu_tiles, again.cpu_tiles), (0, 0));
    // The far crater waits for its tiles; the near ones are done.
    assert_eq!(tile_stamps.pending(), 1);
    assert!((before_cpu + r.cpu_tiles + r.gpu_tiles) as usize <= touched);
    assert!(before_cpu + r.cpu_tiles > 0, "some tiles in RAM only");

    // A readback nobody asked for, or of the wrong rect, is refused.
    let bogus = Grid::new(2, 2, 0u16).unwrap();
    let e = tile_stamps
        .receive::<CoreError>(
            &mut ram,
            Some(&mut vram),
            9999,
            Rect::from_size(UVec2::splat(2)),
            &bogus,
        )
        .unwrap_err();
    assert!(
        matches!(e, TileStampError::UnknownTicket { ticket: 9999 }),
        "{e}"
    );
    let (ticket, rect, _) = &gpu.arrived[0];
    let wrong = Rect::new(rect.min, rect.size + UVec2::ONE);
    let e = tile_stamps
        .receive::<CoreError>(&mut ram, Some(&mut vram), *ticket, wrong, &bogus)
        .unwrap_err();
    assert!(matches!(e, TileStampError::WrongRect { .. }), "{e}");

    for (ticket, rect, heights) in std::mem::take(&mut gpu.arrived) {
        tile_stamps
            .receive::<CoreError>(&mut ram, Some(&mut vram), ticket, rect, &heights)
            .unwrap();
    }
    assert_eq!(tile_stamps.in_flight(), 0);
    assert_eq!(vram.held(), 0, "every hold released");

    // Written back, then the far crater straight into the files.
    ram.flush();
    ram.shutdown(Duration::from_secs(10)).unwrap();
    let written = tile_stamps.finish_into_world(&world, &mut gpu).unwrap();
    assert!(!written.is_empty());
    assert_eq!(tile_stamps.pending(), 0);

    // Every level-0 tile holds exactly the stamps that touch it, applied once.
    for ty in 0..16 {
        for tx in 0..16 {
            let id = TileId::new(0, tx, ty);
            let want = expected_tile(&original, id, &stamps);
            let got = world.load_tile(Layer::Height, id).unwrap();
            assert_eq!(got.as_u16().unwrap(), &want, "{id}");
        }
    }
}

#[test]
fn a_stamp_wider_than_the_limit_is_refused_and_nothing_is_queued() {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let world = build(store, UVec2::splat(512), 32);
    let mut tile_stamps: TileStamps<f32> = TileStamps::new(world.manifest()).unwrap();
    // 300 m covers 10 x 10 tiles of 32 m: more than 64.
    let huge = StampPlacement::new(Vec2::splat(256.0), Vec2::splat(300.0), 1.0).unwrap();
    assert!(tile_stamps.push(-1.0, huge).is_err());
    // The largest finite size: refused, in bounded time.
    let absurd = StampPlacement::new(Vec2::splat(256.0), Vec2::splat(f32::MAX), 1.0);
    if let Ok(p) = absurd {
        assert!(tile_stamps.push(-1.0, p).is_err());
    }
    assert_eq!(tile_stamps.pending(), 0);
}
