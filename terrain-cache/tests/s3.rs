//! `ObjectTileStore` against a real S3-compatible server (moto, started on loopback by the
//! tests; see `common/s3.rs` for which server and why), through a fault-injecting proxy of our
//! own: a world built into a bucket, streamed through a `RamPool`, deformed and written back
//! while requests are delayed, stalled past the client's timeout, answered 503 / 500 by the
//! proxy, or cut before or after moto applied them; then every object is compared with the
//! same world built and deformed in memory. Also: an unreadable tile falls back to its parent
//! in the pool, a conditional write whose answer was lost is not a conflict, and two writers
//! of one tile are detected instead of one silently overwriting the other.
//!
//! Needs the `aws` feature: `cargo test -p terrain-cache --features aws --test s3`. Without a
//! server the tests skip with a message, or fail when `TERRAIN_REQUIRE_S3=1` (CI).
#![cfg(feature = "aws")]

mod common;
#[path = "common/s3.rs"]
mod s3;

use common::build;
use glam::{UVec2, Vec3};
use object_store::aws::AmazonS3Builder;
use s3::{Fault, FaultProxy, ProxyStats, Rule};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::object::ObjectStoreConfig;
use terrain_cache::{
    CacheError, CameraState, Layer, ObjectTileStore, PoolConfig, RamPool, TileData, TileId,
    TileState, TileStore, World, rebuild_ancestors,
};

/// Short timeouts and backoffs so that faults cost little test time; the store's defaults are
/// documented on `ObjectStoreConfig`.
fn config() -> ObjectStoreConfig {
    ObjectStoreConfig {
        request_timeout: Duration::from_millis(1000),
        connect_timeout: Duration::from_millis(1000),
        max_retries: 3,
        retry_timeout: Duration::from_secs(10),
        init_backoff: Duration::from_millis(10),
        max_backoff: Duration::from_millis(100),
        attempts: 4,
        conflict_detection: true,
        version_capacity: 4096,
    }
}

fn s3_store(endpoint: &str, bucket: &str, config: ObjectStoreConfig) -> ObjectTileStore {
    let builder = AmazonS3Builder::new()
        .with_endpoint(endpoint)
        .with_allow_http(true)
        .with_bucket_name(bucket)
        .with_region("us-east-1")
        .with_access_key_id("terrain-test")
        .with_secret_access_key("terrain-test");
    ObjectTileStore::s3(builder, "world", config).unwrap()
}

/// The moto server and a fresh bucket, or `None` (skip) without a server.
fn bucket(name: &str) -> Option<&'static s3::Moto> {
    let moto = s3::moto()?;
    moto.create_bucket(name);
    Some(moto)
}

fn set_first_sample(d: &mut TileData, v: u16) {
    d.as_u16_mut().unwrap().as_mut_slice()[0] = v;
}

fn first_sample(d: &TileData) -> u16 {
    d.as_u16().unwrap().as_slice()[0]
}

/// Pumps `pool` at `cam` until `done` or 15 s.
fn pump(pool: &mut RamPool, cam: &CameraState, mut done: impl FnMut(&RamPool) -> bool) {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(15) {
        pool.update(cam).unwrap();
        if done(pool) {
            return;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("pool did not settle in 15 s: {:?}", pool.errors());
}

/// What the deformation writes into level-0 tile `id`.
fn deformed(id: TileId) -> u16 {
    (1000 + id.x * 37 + id.y * 101) as u16
}

/// Every object of `a` equals the one of `b` (same keys, same bytes).
fn assert_same_objects(a: &dyn TileStore, b: &dyn TileStore) -> usize {
    let keys = a.list("").unwrap();
    assert_eq!(keys, b.list("").unwrap());
    for k in &keys {
        let x = a.read(k, 1 << 24).unwrap();
        let y = b.read(k, 1 << 24).unwrap();
        assert!(x.is_some() && x == y, "{k} differs");
    }
    keys.len()
}

/// The faults of the round trip; `lost_answers` adds answers cut off after moto applied
/// conditional writes of level-0 tiles (the pool's write-back), as rule 5.
fn fault_rules(lost_answers: bool) -> Vec<Rule> {
    let ms = Duration::from_millis;
    let mut rules = vec![
        // Answers of the proxy's own, moto never sees these requests.
        Rule::new(Fault::Status(503)).method("PUT").skip(2).every(5),
        Rule::new(Fault::Status(500)).method("GET").skip(1).every(7),
        // Longer than the 1 s request timeout: the client gives up and retries.
        Rule::new(Fault::Stall(ms(2500)))
            .method("PUT")
            .skip(20)
            .times(1),
        Rule::new(Fault::Stall(ms(2500)))
            .method("GET")
            .skip(10)
            .times(1),
        // Connections cut before moto sees the request.
        Rule::new(Fault::DropBefore)
            .method("PUT")
            .skip(3)
            .every(13)
            .times(4),
    ];
    if lost_answers {
        rules.push(
            Rule::new(Fault::DropAfter)
                .method("PUT")
                .path("/height/00/")
                .every(2)
                .times(3),
        );
    }
    rules.push(Rule::new(Fault::Delay(ms(30))).every(9));
    rules
}

#[test]
fn world_round_trip_through_the_pool_loses_no_tile_under_faults() {
    let Some(moto) = bucket("faults") else { return };
    let proxy = FaultProxy::start(moto.addr);
    proxy.set_rules(fault_rules(false));
    let t0 = Instant::now();
    let store: Arc<dyn TileStore> = Arc::new(s3_store(&proxy.endpoint(), "faults", config()));
    let world = build(store, UVec2::splat(256), 32);
    // The same world in memory, faults and network aside.
    let reference = build(
        Arc::new(ObjectTileStore::in_memory().unwrap()),
        UVec2::splat(256),
        32,
    );
    let direct = s3_store(&moto.endpoint(), "faults", config());
    let built = assert_same_objects(&direct, reference.store().as_ref());
    eprintln!(
        "built {built} objects in {:.1} s",
        t0.elapsed().as_secs_f64()
    );

    // Stream the world through a RAM pool over the faulty link, deform every resident
    // level-0 tile, write back (ancestors and bounds refreshed on the writer thread).
    let world = World::open(world.store().clone()).unwrap();
    let tb = 32 * 32 * 2;
    let mut cfg = PoolConfig::new(Layer::Height, 200 * tb);
    cfg.write_back_idle_frames = None;
    let mut pool = RamPool::new(world, cfg).unwrap();
    let cam = CameraState::at(Vec3::new(128.0, 40.0, 128.0));
    pump(&mut pool, &cam, |p| {
        p.statuses()
            .iter()
            .any(|(id, s)| id.level == 0 && s.state == TileState::Loaded)
            && p.statuses()
                .iter()
                .all(|(_, s)| s.state == TileState::Loaded)
    });
    let mut ids: Vec<TileId> = pool
        .resident_ids()
        .into_iter()
        .filter(|id| id.level == 0)
        .collect();
    ids.sort();
    assert!(ids.len() >= 4, "{ids:?}");
    for &id in &ids {
        pool.modify(id, |d| set_first_sample(d, deformed(id)))
            .unwrap();
    }
    let before = proxy.stats.faults();
    proxy.set_rules(fault_rules(true));
    pool.flush_and_wait(Duration::from_secs(30)).unwrap();
    assert!(pool.errors().is_empty(), "{:?}", pool.errors());
    pool.shutdown(Duration::from_secs(30)).unwrap();
    for &id in &ids {
        let mut d = (*reference.load_tile(Layer::Height, id).unwrap()).clone();
        set_first_sample(&mut d, deformed(id));
        reference.write_tile(Layer::Height, id, &d).unwrap();
    }
    rebuild_ancestors(&reference, &ids).unwrap();

    // Reopened from the bucket without the proxy: every object as the reference has it.
    let n = assert_same_objects(&direct, reference.store().as_ref());
    let reopened = World::open(Arc::new(direct)).unwrap();
    for &id in &ids {
        assert_eq!(
            first_sample(&reopened.load_tile(Layer::Height, id).unwrap()),
            deformed(id)
        );
    }
    assert!(
        proxy.stats.faults() > before,
        "no faults during the write-back"
    );
    let st = &proxy.stats;
    eprintln!(
        "{} requests, {} faults ({:?} per rule in the write-back), {} level-0 tiles deformed, {n} objects equal, {:.1} s in all",
        ProxyStats::get(&st.requests),
        st.faults(),
        proxy.fired(),
        ids.len(),
        t0.elapsed().as_secs_f64()
    );
    // Every kind of fault happened.
    for (what, c) in [
        ("5xx", &st.status),
        ("stall", &st.stalled),
        ("drop before", &st.dropped_before),
        ("drop after", &st.dropped_after),
        ("delay", &st.delayed),
    ] {
        assert!(
            ProxyStats::get(c) > 0,
            "no {what} fault was injected: {:?}",
            proxy.fired()
        );
    }
    assert_eq!(
        proxy.fired()[5],
        3,
        "lost answers of conditional tile writes"
    );
}

#[test]
fn unreadable_tile_falls_back_to_its_parent_in_the_pool() {
    let Some(moto) = bucket("fallback") else {
        return;
    };
    let direct: Arc<dyn TileStore> = Arc::new(s3_store(&moto.endpoint(), "fallback", config()));
    let built = build(direct, UVec2::splat(128), 32);
    let bad = TileId::new(0, 1, 1);
    let key = built.manifest().tile_key(Layer::Height, bad);
    let proxy = FaultProxy::start(moto.addr);
    // Every read of that one tile fails (500), retries included.
    proxy.set_rules(vec![
        Rule::new(Fault::Status(500))
            .method("GET")
            .path(key.clone()),
    ]);
    let few = ObjectStoreConfig {
        max_retries: 2,
        attempts: 2,
        ..config()
    };
    let world = World::open(Arc::new(s3_store(&proxy.endpoint(), "fallback", few))).unwrap();
    let mut cfg = PoolConfig::new(Layer::Height, 64 * 32 * 32 * 2);
    cfg.retry_failed_frames = 20;
    let mut pool = RamPool::new(world, cfg).unwrap();
    let cam = CameraState::at(Vec3::new(48.0, 10.0, 48.0));
    let mut reported = false;
    pump(&mut pool, &cam, |p| {
        reported |= p
            .errors()
            .iter()
            .any(|(id, e)| *id == bad && matches!(e, CacheError::ObjectStore { op: "get", .. }));
        reported && p.status(bad).is_some_and(|s| s.state == TileState::Failed)
    });
    // 1 + max_retries requests per attempt, attempts per load, nothing more.
    let tries = proxy.fired()[0];
    assert!(tries >= 6 && tries.is_multiple_of(6), "{tries}");
    let (stand_in, data) = pool.best_available(bad).unwrap();
    assert!(stand_in.level > 0, "{stand_in}");
    assert_eq!(*data, *built.load_tile(Layer::Height, stand_in).unwrap());
    // The link heals: the tile is retried and loads.
    proxy.set_rules(Vec::new());
    pump(&mut pool, &cam, |p| p.tile(bad).is_some());
    assert_eq!(
        *pool.tile(bad).unwrap(),
        *built.load_tile(Layer::Height, bad).unwrap()
    );
    pool.shutdown(Duration::from_secs(10)).unwrap();
}

#[test]
fn a_conditional_write_whose_answer_was_lost_is_not_a_conflict() {
    let Some(moto) = bucket("lost") else { return };
    let proxy = FaultProxy::start(moto.addr);
    let store = s3_store(&proxy.endpoint(), "lost", config());
    let direct = s3_store(&moto.endpoint(), "lost", config());
    // Creation (If-None-Match: *) and update (If-Match), each applied by moto with the
    // answer cut off: the retry is refused, the bytes are ours, so the write is done.
    assert_eq!(store.read("t/a.tile", 64).unwrap(), None);
    proxy.set_rules(vec![Rule::new(Fault::DropAfter).method("PUT").times(1)]);
    store.write("t/a.tile", b"first").unwrap();
    proxy.set_rules(vec![Rule::new(Fault::DropAfter).method("PUT").times(1)]);
    store.write("t/a.tile", b"second").unwrap();
    assert_eq!(ProxyStats::get(&proxy.stats.dropped_after), 2);
    assert_eq!(direct.read("t/a.tile", 64).unwrap().unwrap(), b"second");
    // The version remembered is the landed one: the next write is not a conflict either.
    store.write("t/a.tile", b"third").unwrap();
    assert_eq!(direct.read("t/a.tile", 64).unwrap().unwrap(), b"third");
}

#[test]
fn two_writers_of_one_tile_are_detected() {
    let Some(moto) = bucket("conflict") else {
        return;
    };
    let a: Arc<dyn TileStore> = Arc::new(s3_store(&moto.endpoint(), "conflict", config()));
    let b: Arc<dyn TileStore> = Arc::new(s3_store(&moto.endpoint(), "conflict", config()));
    build(a.clone(), UVec2::splat(128), 32);
    let (wa, wb) = (World::open(a).unwrap(), World::open(b).unwrap());
    let id = TileId::new(0, 2, 1);
    let key = wa.manifest().tile_key(Layer::Height, id);
    let mut da = (*wa.load_tile(Layer::Height, id).unwrap()).clone();
    let mut db = (*wb.load_tile(Layer::Height, id).unwrap()).clone();
    set_first_sample(&mut da, 111);
    set_first_sample(&mut db, 222);
    wa.write_tile(Layer::Height, id, &da).unwrap();
    // b read the tile before a wrote it: refused, a's tile stays.
    let err = wb.write_tile(Layer::Height, id, &db).unwrap_err();
    assert!(
        matches!(&err, CacheError::Conflict { key: k } if *k == key),
        "{err}"
    );
    assert!(
        wb.write_tile(Layer::Height, id, &db).is_err(),
        "a stale retry conflicts again"
    );
    assert_eq!(first_sample(&wa.load_tile(Layer::Height, id).unwrap()), 111);
    // b reads again (a's version), reapplies its change: accepted.
    let mut db = (*wb.load_tile(Layer::Height, id).unwrap()).clone();
    assert_eq!(first_sample(&db), 111);
    set_first_sample(&mut db, 222);
    wb.write_tile(Layer::Height, id, &db).unwrap();

    // Through a pool: it loaded the tile, b changed it meanwhile, the write-back conflicts,
    // the tile stays dirty in the pool and b's version in the bucket.
    let mut cfg = PoolConfig::new(Layer::Height, 64 * 32 * 32 * 2);
    cfg.write_back_idle_frames = None;
    let mut pool = RamPool::new(wa.clone(), cfg).unwrap();
    let cam = CameraState::at(Vec3::new(80.0, 10.0, 48.0));
    pump(&mut pool, &cam, |p| p.tile(id).is_some());
    assert_eq!(first_sample(pool.tile(id).unwrap()), 222);
    let mut db = (*wb.load_tile(Layer::Height, id).unwrap()).clone();
    set_first_sample(&mut db, 333);
    wb.write_tile(Layer::Height, id, &db).unwrap();
    pool.modify(id, |d| set_first_sample(d, 444)).unwrap();
    let err = pool.flush_and_wait(Duration::from_secs(10)).unwrap_err();
    assert!(
        matches!(&err, CacheError::Conflict { key: k } if *k == key),
        "{err}"
    );
    assert!(pool.status(id).unwrap().dirty);
    assert_eq!(first_sample(&wb.load_tile(Layer::Height, id).unwrap()), 333);
    drop(pool);
}
