//! Unit tests of the VRAM pool against a mock RAM pool and a logging CPU atlas: budget, slots,
//! ranking, fallback, re-uploads, holds, eviction order and bad input. Here rather than in
//! `tests/` because the ranking test checks the pool's private distance order.

use super::*;
use glam::Vec3;
use terrain_core::{HeightEncoding, TileAtlas};

const TS: u32 = 16;

/// The stored value of texel `c` of `level`: different on every level.
fn truth(level: u32, c: UVec2) -> u16 {
    ((level * 7919 + c.x * 31 + c.y * 17) % 65_000) as u16
}

fn tile(id: TileId) -> TileData {
    TileData::U16(
        Grid::from_fn(TS, TS, |x, y| {
            truth(id.level, UVec2::new(id.x * TS + x, id.y * TS + y))
        })
        .unwrap(),
    )
}

/// A 256^2 world of 16-texel tiles at 1 m: 16, 8, 4, 2, 1 tiles per side.
fn manifest(wrap: WrapMode) -> Manifest {
    let enc = HeightEncoding::spanning::<u16>(0.0, 50.0).unwrap();
    Manifest::new(UVec2::splat(256), TS, 1.0, enc, wrap).unwrap()
}

#[derive(Debug, Default)]
struct MockRam {
    tiles: HashMap<TileId, TileData>,
    versions: HashMap<TileId, u64>,
    refreshed: Vec<TileId>,
}

impl MockRam {
    fn all(m: &Manifest) -> Self {
        let mut ram = MockRam::default();
        for l in 0..m.levels {
            for id in m.tiles_of(Layer::Height, l) {
                ram.tiles.insert(id, tile(id));
            }
        }
        ram
    }
}

impl RamTiles for MockRam {
    fn tile(&self, id: TileId) -> Option<&TileData> {
        self.tiles.get(&id)
    }
    fn version(&self, id: TileId) -> Option<u64> {
        self.tiles
            .contains_key(&id)
            .then(|| self.versions.get(&id).copied().unwrap_or(0))
    }
    fn refreshed(&self) -> &[TileId] {
        &self.refreshed
    }
}

/// A CPU atlas that logs its calls and checks the contract's ordering: a slot is only
/// uploaded into while no tile is mapped to it (or for the tile mapped to it), and a tile
/// is only mapped to a slot that holds its upload.
#[derive(Debug)]
struct Logged {
    atlas: TileAtlas,
    holds: HashMap<u32, TileId>,
    mapped: HashMap<TileId, u32>,
    uploads: Vec<TileId>,
}

impl Logged {
    fn new(m: &Manifest, slots: u32) -> Self {
        Self {
            atlas: TileAtlas::new(m.tile_layout(), slots).unwrap(),
            holds: HashMap::new(),
            mapped: HashMap::new(),
            uploads: Vec::new(),
        }
    }
}

impl TileUploadTarget for Logged {
    type Error = terrain_core::CoreError;
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
        heights: &Grid<u16>,
    ) -> Result<u64, Self::Error> {
        let id = TileId::new(level, tile.x, tile.y);
        for (&other, &s) in &self.mapped {
            assert!(
                s != slot || other == id,
                "slot {slot} overwritten under {other}"
            );
        }
        self.holds.insert(slot, id);
        self.uploads.push(id);
        self.atlas.upload(slot, level, tile, heights)
    }
    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), Self::Error> {
        let id = TileId::new(level, tile.x, tile.y);
        match slot {
            Some(s) => {
                assert_eq!(self.holds.get(&s), Some(&id), "mapped before its upload");
                self.mapped.insert(id, s);
            }
            None => {
                self.mapped.remove(&id);
            }
        }
        self.atlas.map(level, tile, slot)
    }
}

fn camera(x: f32, z: f32, heading: f32) -> CameraState {
    CameraState {
        forward: Vec3::new(heading.cos(), -0.2, heading.sin()),
        ..CameraState::at(Vec3::new(x, 20.0, z))
    }
}

/// Every texel of the world resolves to the finest level the pool holds, and reads that
/// level's true value: the fallback chain.
fn assert_fallback(pool: &VramPool, atlas: &TileAtlas, m: &Manifest) {
    for y in 0..m.world_size.y {
        for x in 0..m.world_size.x {
            let t = UVec2::new(x, y);
            let finest = (0..m.levels).find(|&l| {
                let c = (t >> l) / TS;
                pool.slot_of(TileId::new(l, c.x, c.y)).is_some()
            });
            let got = atlas.stored_at(t.as_ivec2());
            match finest {
                Some(l) => assert_eq!(got, u32::from(truth(l, t >> l)), "texel {t} level {l}"),
                None => assert_eq!(got, u32::from(m.height_fill)),
            }
        }
    }
}

#[test]
fn uploads_stay_within_budget_nearest_first_and_within_the_slots() {
    let m = manifest(WrapMode::Clamp);
    let ram = MockRam::all(&m);
    let mut cfg = VramConfig::new(&m, 24);
    let tile_bytes = u64::from(TS * TS) * 2;
    cfg.upload_budget_bytes = 3 * tile_bytes + 5;
    let mut pool = VramPool::new(cfg).unwrap();
    let mut target = Logged::new(&m, 24);
    let mut cam = camera(100.0, 120.0, 0.3);
    let mut uploaded = 0;
    for frame in 0..60 {
        if frame == 30 {
            cam = camera(30.0, 200.0, 2.0);
        }
        let before = target.atlas.uploaded_bytes();
        target.uploads.clear();
        let r = pool.update(&cam, &ram, &mut target).unwrap();
        let spent = target.atlas.uploaded_bytes() - before;
        assert_eq!(spent, r.upload_bytes);
        assert!(r.upload_bytes <= r.budget_bytes, "{r:?}");
        assert!(r.uploads <= 3);
        assert!(
            r.resident <= 24 && target.atlas.mapped() == r.resident,
            "{r:?}"
        );
        // Mapped slots are distinct.
        let mut slots: Vec<u32> = target.mapped.values().copied().collect();
        slots.sort_unstable();
        slots.dedup();
        assert_eq!(slots.len(), target.mapped.len());
        // This frame's uploads are the most urgent missing tiles, in rank order.
        let wanted: Vec<TileId> = pool.wanted().collect();
        let mut expect = Vec::new();
        for id in &wanted {
            if target.uploads.contains(id) {
                expect.push(*id);
            }
        }
        assert_eq!(
            target.uploads, expect,
            "frame {frame}: uploads out of rank order"
        );
        if r.uploads == 3 {
            // Nothing more urgent than the last upload was left missing.
            let last = *target.uploads.last().unwrap();
            let pos = wanted.iter().position(|w| *w == last).unwrap();
            for w in &wanted[..pos] {
                assert!(pool.slot_of(*w).is_some(), "frame {frame}: {w} skipped");
            }
        }
        uploaded += r.uploads;
        assert_fallback(&pool, &target.atlas, &m);
    }
    assert!(
        uploaded > 24,
        "the move must have evicted and re-filled slots"
    );
    // Settled: the most urgent tiles fill the slots.
    let r = pool.update(&cam, &ram, &mut target).unwrap();
    assert_eq!(r.tiles_missing, r.tiles_wanted.saturating_sub(24), "{r:?}");
    assert_eq!(r.vram_bytes, r.resident as u64 * tile_bytes);
}

#[test]
fn ranking_puts_the_root_first_then_nearest_coarser_before_finer() {
    let m = manifest(WrapMode::Clamp);
    let mut pool = VramPool::new(VramConfig::new(&m, 64)).unwrap();
    let mut target = TileAtlas::new(m.tile_layout(), 64).unwrap();
    let cam = camera(100.0, 120.0, 0.3);
    pool.update(&cam, &MockRam::default(), &mut target).unwrap();
    let wanted: Vec<TileId> = pool.wanted().collect();
    assert_eq!(wanted[0], TileId::new(4, 0, 0));
    let grid = &pool.config().grid;
    let xz = grid.camera_xz(cam.position);
    let eye = DVec3::new(xz.x, f64::from(cam.position.y), xz.y);
    let d: Vec<f64> = wanted[1..]
        .iter()
        .map(|id| tile_distance(grid, eye, *id))
        .collect();
    assert!(d.windows(2).all(|w| w[0] <= w[1]), "{d:?}");
    // The tiles under the camera, coarse to fine, come right after the root.
    let under: Vec<u32> = wanted[1..5].iter().map(|w| w.level).collect();
    assert_eq!(under, [3, 2, 1, 0]);
}

#[test]
fn missing_fine_tiles_fall_back_to_coarser_ones_and_come_in_when_loaded() {
    let m = manifest(WrapMode::Clamp);
    let mut ram = MockRam::all(&m);
    // Level 0 and level 1 partly missing in RAM around the camera.
    let removed: Vec<TileId> = [(0, 6, 7), (0, 7, 7), (0, 6, 8), (1, 3, 3), (0, 5, 6)]
        .iter()
        .map(|&(l, x, y)| TileId::new(l, x, y))
        .collect();
    let mut held = HashMap::new();
    for id in &removed {
        held.insert(*id, ram.tiles.remove(id).unwrap());
    }
    let mut pool = VramPool::new(VramConfig::new(&m, 128)).unwrap();
    let mut atlas = TileAtlas::new(m.tile_layout(), 128).unwrap();
    let cam = camera(110.0, 115.0, 0.0);
    let mut r = VramReport::default();
    for _ in 0..20 {
        r = pool.update(&cam, &ram, &mut atlas).unwrap();
    }
    assert!(
        r.waiting_for_ram > 0 && r.tiles_missing == r.waiting_for_ram,
        "{r:?}"
    );
    assert_eq!(r.deferred, 0);
    for id in &removed {
        assert!(pool.slot_of(*id).is_none());
    }
    assert_fallback(&pool, &atlas, &m);
    // Texel (100, 115) lies in level-0 tile (6, 7), missing: level 1 tile (3, 3) is
    // missing too, so level 2 answers.
    assert_eq!(
        atlas.stored_at(glam::IVec2::new(100, 115)),
        u32::from(truth(2, UVec2::new(25, 28)))
    );
    // They arrive: uploaded, and the fine values show.
    ram.tiles.extend(held);
    for _ in 0..5 {
        r = pool.update(&cam, &ram, &mut atlas).unwrap();
    }
    assert_eq!(r.tiles_missing, 0, "{r:?}");
    assert_eq!(
        atlas.stored_at(glam::IVec2::new(100, 115)),
        u32::from(truth(0, UVec2::new(100, 115)))
    );
    assert_fallback(&pool, &atlas, &m);
}

#[test]
fn modified_and_refreshed_tiles_are_uploaded_again() {
    let m = manifest(WrapMode::Clamp);
    let mut ram = MockRam::all(&m);
    let mut pool = VramPool::new(VramConfig::new(&m, 64)).unwrap();
    let mut atlas = TileAtlas::new(m.tile_layout(), 64).unwrap();
    let cam = camera(110.0, 115.0, 0.0);
    for _ in 0..20 {
        pool.update(&cam, &ram, &mut atlas).unwrap();
    }
    let here = TileId::new(0, 6, 7);
    let parent = TileId::new(1, 3, 3);
    assert!(pool.slot_of(here).is_some() && pool.slot_of(parent).is_some());
    // A deformation modifies the level-0 tile in RAM; its write-back refreshes the parent.
    if let Some(TileData::U16(g)) = ram.tiles.get_mut(&here) {
        *g.get_mut(4, 3).unwrap() = 12_345;
    }
    ram.versions.insert(here, 1);
    ram.refreshed.push(parent);
    let r = pool.update(&cam, &ram, &mut atlas).unwrap();
    assert_eq!((r.uploads, r.refreshes, r.stale), (2, 2, 0), "{r:?}");
    assert_eq!(atlas.stored_at(glam::IVec2::new(100, 115)), 12_345);
    ram.refreshed.clear();
    let r = pool.update(&cam, &ram, &mut atlas).unwrap();
    assert_eq!(r.uploads, 0);
    // A stale tile whose RAM copy is gone stays drawn (its old data) until it is back.
    ram.refreshed.push(parent);
    let data = ram.tiles.remove(&parent).unwrap();
    let r = pool.update(&cam, &ram, &mut atlas).unwrap();
    assert_eq!((r.uploads, r.stale), (0, 1), "{r:?}");
    assert!(pool.slot_of(parent).is_some());
    ram.refreshed.clear();
    ram.tiles.insert(parent, data);
    let r = pool.update(&cam, &ram, &mut atlas).unwrap();
    assert_eq!((r.refreshes, r.stale), (1, 0), "{r:?}");
}

#[test]
fn a_held_tile_keeps_its_slot_and_is_not_overwritten_from_ram_until_released() {
    let m = manifest(WrapMode::Clamp);
    let mut ram = MockRam::all(&m);
    let slots = 24;
    let mut cfg = VramConfig::new(&m, slots);
    cfg.upload_budget_bytes = 64 * u64::from(TS * TS) * 4;
    let mut pool = VramPool::new(cfg).unwrap();
    let mut atlas = TileAtlas::new(m.tile_layout(), slots).unwrap();
    let here = camera(40.0, 40.0, 0.0);
    pool.update(&here, &ram, &mut atlas).unwrap();
    let id = TileId::new(0, 2, 2);
    assert!(pool.hold(TileId::new(0, 15, 15)).is_none(), "not resident");
    let slot = pool.hold(id).expect("resident");
    assert_eq!(pool.hold(id), Some(slot), "holds nest");
    assert_eq!(pool.held(), 1);
    // The GPU changed the slot (here: the CPU atlas standing in for it); RAM then changes
    // too (the first readback) and the camera goes where the tile is not wanted and every
    // slot is needed: the slot is neither refreshed from RAM nor taken.
    let mut changed = tile(id);
    if let TileData::U16(g) = &mut changed {
        *g.get_mut(1, 1).unwrap() = 777;
    }
    // The slot also has a later change that RAM does not have yet.
    let mut newer = changed.clone();
    if let TileData::U16(g) = &mut newer {
        *g.get_mut(2, 2).unwrap() = 888;
    }
    atlas
        .upload(slot, 0, UVec2::new(2, 2), newer.as_u16().unwrap())
        .unwrap();
    ram.tiles.insert(id, changed.clone());
    ram.versions.insert(id, 1);
    let far = camera(230.0, 230.0, 3.0);
    for _ in 0..5 {
        let r = pool.update(&far, &ram, &mut atlas).unwrap();
        assert!(r.evictions > 0 || r.uploads == 0, "{r:?}");
        assert_eq!(pool.slot_of(id), Some(slot));
    }
    assert_eq!(atlas.stored_at(glam::IVec2::new(33, 33)), 777);
    assert_eq!(
        atlas.stored_at(glam::IVec2::new(34, 34)),
        888,
        "not overwritten"
    );
    // One release: still held.
    pool.release(id, Some(1));
    pool.update(&far, &ram, &mut atlas).unwrap();
    assert_eq!(pool.slot_of(id), Some(slot));
    // The last release: current for RAM version 1 (no upload of it), and free to go.
    pool.release(id, Some(1));
    assert_eq!(pool.held(), 0);
    pool.release(id, Some(1));
    let before = atlas.uploads();
    let r = pool.update(&here, &ram, &mut atlas).unwrap();
    if pool.slot_of(id) == Some(slot) {
        assert_eq!(atlas.uploads() - before, r.uploads as u64);
        assert_eq!(atlas.stored_at(glam::IVec2::new(33, 33)), 777);
    }
    for _ in 0..5 {
        pool.update(&far, &ram, &mut atlas).unwrap();
    }
    assert!(
        pool.slot_of(id).is_none(),
        "released tiles are evicted again"
    );
}

#[test]
fn a_stale_slot_is_not_held() {
    let m = manifest(WrapMode::Clamp);
    let mut ram = MockRam::all(&m);
    let mut pool = VramPool::new(VramConfig::new(&m, 200)).unwrap();
    let mut atlas = TileAtlas::new(m.tile_layout(), 200).unwrap();
    pool.update(&camera(40.0, 40.0, 0.0), &ram, &mut atlas)
        .unwrap();
    let id = TileId::new(0, 2, 2);
    assert!(pool.slot_of(id).is_some());
    // RAM changes while the camera looks elsewhere: the slot stays resident but stale.
    ram.versions.insert(id, 7);
    let r = pool
        .update(&camera(230.0, 230.0, 3.0), &ram, &mut atlas)
        .unwrap();
    assert!(pool.slot_of(id).is_some() && r.stale >= 1, "{r:?}");
    assert_eq!(
        pool.hold(id),
        None,
        "a stale slot would overwrite newer RAM texels"
    );
    assert_eq!(pool.held(), 0);
    // Refreshed, it can be held again.
    pool.update(&camera(40.0, 40.0, 0.0), &ram, &mut atlas)
        .unwrap();
    assert!(pool.hold(id).is_some());
}

#[test]
fn the_least_recently_wanted_tiles_are_evicted_first() {
    let m = manifest(WrapMode::Clamp);
    let ram = MockRam::all(&m);
    let mut cfg = VramConfig::new(&m, 34);
    cfg.selection = VramSelection::Band {
        band_width: 1.0 / 3.0,
    };
    cfg.upload_budget_bytes = 64 * u64::from(TS * TS) * 4;
    let mut pool = VramPool::new(cfg).unwrap();
    let mut atlas = TileAtlas::new(m.tile_layout(), 34).unwrap();
    // A tour of the world; each place wants at most 9 tiles per level.
    let places = [
        (40.0, 40.0),
        (200.0, 40.0),
        (200.0, 200.0),
        (40.0, 200.0),
        (120.0, 130.0),
        (40.0, 40.0),
        (250.0, 10.0),
    ];
    let mut last_wanted: HashMap<TileId, usize> = HashMap::new();
    let mut evictions = 0;
    for (frame, &(x, z)) in places.iter().enumerate() {
        let before = pool.resident_ids();
        let r = pool.update(&camera(x, z, 0.0), &ram, &mut atlas).unwrap();
        assert_eq!(r.tiles_missing, 0, "{r:?}");
        assert!(r.tiles_wanted <= 9 * 4 + 1);
        let after = pool.resident_ids();
        let evicted: Vec<TileId> = before
            .iter()
            .filter(|id| !after.contains(id))
            .copied()
            .collect();
        evictions += evicted.len();
        // Each evicted tile was wanted no later than any unwanted tile that stayed.
        for e in &evicted {
            for s in after.iter().filter(|s| !pool.wanted().any(|w| w == **s)) {
                assert!(
                    last_wanted[e] <= last_wanted[s],
                    "frame {frame}: evicted {e} (wanted {}) before {s} (wanted {})",
                    last_wanted[e],
                    last_wanted[s]
                );
            }
        }
        for w in pool.wanted() {
            last_wanted.insert(w, frame);
        }
        assert_fallback(&pool, &atlas, &m);
    }
    assert!(evictions > 0);
}

#[test]
fn tiles_beyond_the_slot_count_never_evict_nearer_ones() {
    let m = manifest(WrapMode::Repeat);
    let ram = MockRam::all(&m);
    let mut cfg = VramConfig::new(&m, 6);
    cfg.upload_budget_bytes = 100 * u64::from(TS * TS) * 4;
    let mut pool = VramPool::new(cfg).unwrap();
    let mut atlas = TileAtlas::new(m.tile_layout(), 6).unwrap();
    let cam = camera(128.0, 128.0, 1.0);
    let r = pool.update(&cam, &ram, &mut atlas).unwrap();
    assert_eq!(r.resident, 6);
    assert_eq!(r.tiles_missing, r.tiles_wanted - 6);
    let top: Vec<TileId> = pool.wanted().take(6).collect();
    for _ in 0..5 {
        let r = pool.update(&cam, &ram, &mut atlas).unwrap();
        assert_eq!((r.uploads, r.evictions), (0, 0), "{r:?}");
    }
    for id in &top {
        assert!(pool.slot_of(*id).is_some());
    }
    assert_fallback(&pool, &atlas, &m);
}

#[test]
fn extreme_cameras_are_bounded_and_nan_is_refused_without_change() {
    let m = manifest(WrapMode::Repeat);
    let ram = MockRam::all(&m);
    for selection in [
        VramSelection::default(),
        VramSelection::Band { band_width: 0.5 },
    ] {
        let mut cfg = VramConfig::new(&m, 16);
        cfg.selection = selection;
        let mut pool = VramPool::new(cfg).unwrap();
        let mut atlas = TileAtlas::new(m.tile_layout(), 16).unwrap();
        let total: usize = (0..m.levels)
            .map(|l| m.tiles_of(Layer::Height, l).count())
            .sum();
        for p in [
            Vec3::splat(f32::MAX),
            Vec3::splat(f32::MIN),
            Vec3::new(1e30, -1e30, -1e-30),
            Vec3::new(-3e38, 0.0, 3e38),
        ] {
            for fwd in [Vec3::X, Vec3::ZERO, Vec3::splat(f32::MAX), Vec3::NEG_Y] {
                let cam = CameraState {
                    position: p,
                    forward: fwd,
                    fov_y: 3.1,
                    aspect: 1e30,
                };
                let r = pool.update(&cam, &ram, &mut atlas).unwrap();
                assert!(r.tiles_wanted <= total && r.resident <= 16, "{r:?}");
                assert!(r.upload_bytes <= r.budget_bytes);
            }
        }
        let frame = pool
            .update(&camera(1.0, 1.0, 0.0), &ram, &mut atlas)
            .unwrap()
            .frame;
        let table = atlas.table().to_vec();
        for bad in [
            CameraState::at(Vec3::new(f32::NAN, 0.0, 0.0)),
            CameraState::at(Vec3::new(0.0, f32::INFINITY, 0.0)),
            CameraState {
                forward: Vec3::new(0.0, f32::NAN, 1.0),
                ..CameraState::at(Vec3::ZERO)
            },
            CameraState {
                fov_y: f32::NAN,
                ..CameraState::at(Vec3::ZERO)
            },
        ] {
            assert!(matches!(
                pool.update(&bad, &ram, &mut atlas),
                Err(VramError::Cache(_))
            ));
        }
        assert_eq!(atlas.table(), table.as_slice());
        let next = pool
            .update(&camera(1.0, 1.0, 0.0), &ram, &mut atlas)
            .unwrap();
        assert_eq!(next.frame, frame + 1);
    }
}

#[test]
fn bad_configs_and_mismatched_targets_are_errors() {
    let m = manifest(WrapMode::Clamp);
    let mut cfg = VramConfig::new(&m, 0);
    assert!(VramPool::new(cfg.clone()).is_err());
    cfg.slots = 8;
    cfg.upload_budget_bytes = 10;
    assert!(VramPool::new(cfg.clone()).is_err());
    cfg.upload_budget_bytes = DEFAULT_UPLOAD_BUDGET_BYTES;
    cfg.selection = VramSelection::Band {
        band_width: f64::NAN,
    };
    assert!(VramPool::new(cfg.clone()).is_err());
    cfg.selection = VramSelection::Frustum {
        far_tiles: f64::INFINITY,
        near_tiles: 1.0,
        fov_margin: 0.1,
        turn_gain: 1.0,
    };
    assert!(VramPool::new(cfg.clone()).is_err());
    cfg.selection = VramSelection::default();
    let mut pool = VramPool::new(cfg).unwrap();
    let ram = MockRam::all(&m);
    let cam = camera(10.0, 10.0, 0.0);
    let mut few = TileAtlas::new(m.tile_layout(), 4).unwrap();
    assert!(matches!(
        pool.update(&cam, &ram, &mut few),
        Err(VramError::Cache(CacheError::TargetMismatch {
            what: "slot count",
            ..
        }))
    ));
    let other = Manifest::new(UVec2::splat(512), TS, 1.0, m.encoding, WrapMode::Clamp).unwrap();
    let mut wrong = TileAtlas::new(other.tile_layout(), 8).unwrap();
    assert!(pool.update(&cam, &ram, &mut wrong).is_err());
    // A tile of the wrong shape in RAM is reported, not uploaded.
    let mut bad = MockRam::all(&m);
    bad.tiles.insert(
        TileId::new(4, 0, 0),
        TileData::filled(Layer::Detail, TS, 3).unwrap(),
    );
    let mut atlas = TileAtlas::new(m.tile_layout(), 8).unwrap();
    assert!(matches!(
        pool.update(&cam, &bad, &mut atlas),
        Err(VramError::Cache(CacheError::TileDataMismatch { .. }))
    ));
    // Cleared: nothing mapped, every slot free again.
    pool.update(&cam, &ram, &mut atlas).unwrap();
    assert!(atlas.mapped() > 0);
    pool.clear(&mut atlas).unwrap();
    assert_eq!(atlas.mapped(), 0);
    assert!(pool.resident_ids().is_empty());
    let r = pool.update(&cam, &ram, &mut atlas).unwrap();
    assert_eq!(r.resident, atlas.mapped());
}

#[test]
fn an_overlay_pool_streams_paint_where_its_height_pool_streams_heights() {
    use glam::DVec2;
    use terrain_core::OverlayAtlas;
    let m = manifest(WrapMode::Clamp);
    let heights = MockRam::all(&m);
    // Paint that names its level and texel; level-0 tiles with x = 3 have no file (the zero
    // tile the RAM pool gives for them).
    let texel = |level: u32, c: UVec2| {
        let v = truth(level, c);
        [v as u8, (v >> 8) as u8, level as u8, 255]
    };
    let mut paint = MockRam::default();
    for l in 0..m.layer_levels(Layer::Material) {
        for id in m.tiles_of(Layer::Material, l) {
            let g = if l == 0 && id.x == 3 {
                Grid::new(TS, TS, [0; 4]).unwrap()
            } else {
                Grid::from_fn(TS, TS, |x, y| {
                    texel(l, UVec2::new(id.x * TS + x, id.y * TS + y))
                })
                .unwrap()
            };
            paint.tiles.insert(id, TileData::Rgba8(g));
        }
    }
    let cfg = VramConfig {
        upload_budget_bytes: 64 * 1024,
        ..VramConfig::new(&m, 128)
    };
    let mut height_pool = VramPool::new(cfg.clone()).unwrap();
    let mut paint_pool = VramPool::new(cfg).unwrap();
    let mut height_atlas = TileAtlas::new(m.tile_layout(), 128).unwrap();
    let mut paint_atlas = OverlayAtlas::new(m.tile_layout(), 128).unwrap();
    for x in [20.0, 60.0, 130.0, 230.0] {
        let cam = camera(x, 40.0, 0.4);
        let mut missing = usize::MAX;
        for _ in 0..3 {
            let h = height_pool
                .update(&cam, &heights, &mut height_atlas)
                .unwrap();
            let p = paint_pool
                .update_overlay(&cam, Layer::Material, &paint, &mut paint_atlas)
                .unwrap();
            assert!(p.upload_bytes <= p.budget_bytes);
            assert_eq!((h.tiles_wanted, h.resident), (p.tiles_wanted, p.resident));
            missing = p.tiles_missing;
        }
        assert_eq!(missing, 0);
        // Every texel's paint comes from the level its height comes from; at level 0 it is
        // the tile's texel itself (transparent in the tiles without a file).
        for y in (0..256).step_by(5) {
            for x in (0..256).step_by(3) {
                let t = UVec2::new(x, y);
                let level = height_atlas.resolve(t).map(|r| r.0);
                assert_eq!(paint_atlas.resolve(t).map(|r| r.0), level, "{t}");
                if level == Some(0) {
                    let want = if x / TS == 3 { [0; 4] } else { texel(0, t) };
                    let got = paint_atlas.sample(DVec2::new(f64::from(x), f64::from(y)), false);
                    let got = (got * 255.0).round().to_array().map(|v| v as u8);
                    assert_eq!(got, want, "{t}");
                }
            }
        }
    }
    // A height layer or height tiles are refused, and nothing changes.
    let cam = camera(20.0, 40.0, 0.4);
    let before = paint_atlas.clone();
    assert!(
        paint_pool
            .update_overlay(&cam, Layer::Height, &paint, &mut paint_atlas)
            .is_err()
    );
    let mut fresh = VramPool::new(VramConfig::new(&m, 128)).unwrap();
    assert!(
        fresh
            .update_overlay(&cam, Layer::Color, &heights, &mut paint_atlas)
            .is_err()
    );
    assert_eq!(paint_atlas, before);
    paint_pool.clear_overlay(&mut paint_atlas).unwrap();
    assert_eq!(paint_atlas.mapped(), 0);
}
