//! `StampPass::encode_detail` on `GpuDetailTiles` against its CPU reference
//! (`terrain_core::detail::DetailLayer`) and against the GPU stamp on one large map, on whatever
//! adapter the machine has (lavapipe in CI). Without an adapter they skip, or fail under
//! `TERRAIN_REQUIRE_GPU=1`.

use glam::{UVec2, Vec2};
use terrain_core::detail::{DETAIL_ZERO_RAW, DetailLayer, DetailLayout, detail_encoding};
use terrain_core::{
    Blend, GaussianStamp, Grid, HeightMap, Rect, Stamp, StampPlacement, TextureStamp, WrapMode,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    DetailTileState, GpuContext, GpuDetailTiles, GpuError, GpuHeightMap, GpuProceduralStamp,
    GpuStamp, GpuTextureStamp, StampOp, StampPass,
};

/// GPU and CPU stamps may not differ at all: both run terrain-core's exact integer stamp
/// program, as on the coarse-map (tests/passes.rs).
const STAMP_BOUND_LSB: i32 = 0;

/// A 48 x 40 coarse-map at 0.1 m refined x3: 144 x 120 detail texels in 5 x 4 tiles of 32
/// (the last column and row of tiles reach past the map).
fn layout() -> DetailLayout {
    DetailLayout::new(UVec2::new(48, 40), 0.1, 3, 32).unwrap()
}

fn hashed(side: u32, seed: u32) -> Grid<u8> {
    Grid::from_fn(side, side, |x, y| {
        let z = (x.wrapping_mul(0x9E37_79B9) ^ y.wrapping_mul(0x85EB_CA6B) ^ seed) >> 7;
        (100 + z % 60) as u8
    })
    .unwrap()
}

fn place(c: Vec2, s: Vec2, i: f32, r: f32) -> StampPlacement {
    StampPlacement::new(c, s, i)
        .unwrap()
        .with_rotation(r)
        .unwrap()
}

/// A ring: 1 inside radius 0.5 (the user procedural stamp, CPU and WGSL).
struct Ring;
impl Stamp for Ring {
    fn value(&self, local: Vec2) -> f32 {
        let r = local.length();
        if r < 0.5 { 1.0 - r } else { 0.0 }
    }
}
const RING_WGSL: &str = "fn user_stamp_value(local: vec2<f32>) -> f32 {
    let r = length(local);
    return select(0.0, 1.0 - r, r < 0.5);
}";

/// Every tile of the layout as the GPU holds it (the zero tile reads as raw 128).
fn gpu_tiles(ctx: &GpuContext, tiles: &GpuDetailTiles) -> Vec<Grid<u8>> {
    let n = tiles.layout().tiles();
    let side = tiles.layout().tile_size();
    let all = Rect::from_size(UVec2::splat(side));
    (0..n.y)
        .flat_map(|y| (0..n.x).map(move |x| UVec2::new(x, y)))
        .map(|t| tiles.read(&ctx.device, &ctx.queue, t, all).unwrap())
        .collect()
}

/// The largest |GPU - CPU| over every tile and the number of texels that differ.
fn compare(ctx: &GpuContext, tiles: &GpuDetailTiles, layer: &DetailLayer) -> (i32, usize) {
    let n = layer.layout().tiles();
    let mut max = 0;
    let mut differ = 0;
    for (i, gpu) in gpu_tiles(ctx, tiles).iter().enumerate() {
        let t = UVec2::new(i as u32 % n.x, i as u32 / n.x);
        let cpu = layer.tile_map(t).unwrap();
        for (a, b) in cpu.grid().as_slice().iter().zip(gpu.as_slice()) {
            let d = (i32::from(*a) - i32::from(*b)).abs();
            max = max.max(d);
            differ += usize::from(d != 0);
        }
    }
    (max, differ)
}

#[test]
fn detail_stamps_match_the_cpu_layer_across_tile_corners_and_the_wrap() {
    let Some(ctx) = context_or_skip("detail_stamps_match_the_cpu_layer") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = StampPass::new(device).unwrap();
    let mut layer = DetailLayer::new(layout()).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout(), 20).unwrap();
    // One tile holds data from the cache before the stamps.
    let loaded = hashed(32, 7);
    layer.set_tile(UVec2::new(2, 1), loaded.clone()).unwrap();
    tiles.load(queue, UVec2::new(2, 1), Some(&loaded)).unwrap();

    let ts = layout().detail_texel_m();
    let corner = |tx: f32, ty: f32| Vec2::new(tx, ty) * 32.0 * ts;
    let image = Grid::from_fn(13, 7, |x, y| (x * 19 + y * 31) as u8).unwrap();
    let tex = TextureStamp::from_gray8(&image);
    let gpu_tex = GpuTextureStamp::new(device, &tex).unwrap();
    let gauss = GaussianStamp::default();
    let ring = GpuProceduralStamp::new(device, &pass, RING_WGSL).unwrap();
    let extent = Vec2::new(144.0, 120.0) * ts;
    let mut stamps: Vec<(Box<dyn Stamp>, GpuStamp<'_>, StampPlacement, Blend)> = vec![
        // A rotated footprint over the corner of four tiles, one of them loaded.
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&gauss),
            place(corner(2.0, 1.0), Vec2::new(0.9, 0.5), -0.3, 0.6),
            Blend::Add,
        ),
        // Across the map's wrap corner: four tiles at the four corners of the layer.
        (
            Box::new(tex.clone()),
            GpuStamp::Texture(&gpu_tex),
            place(Vec2::splat(0.05), Vec2::new(0.6, 0.4), 0.2, 0.7),
            Blend::Add,
        ),
        // Over the partial last tile column and row.
        (
            Box::new(tex),
            GpuStamp::Texture(&gpu_tex),
            place(extent - 0.1, Vec2::splat(0.5), -0.25, -0.3),
            Blend::Min { base_m: 0.1 },
        ),
        (
            Box::new(Ring),
            GpuStamp::Procedural(&ring),
            place(corner(1.0, 3.0), Vec2::splat(0.7), 0.3, 0.0),
            Blend::Max { base_m: -0.05 },
        ),
        // Saturates at the bottom of the tiles' 1 m range.
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&gauss),
            place(corner(3.0, 2.0), Vec2::splat(0.4), -5.0, 0.0),
            Blend::Add,
        ),
    ];
    let mut encoder = device.create_command_encoder(&Default::default());
    let mut touched = std::collections::BTreeSet::new();
    for (cpu, gpu, placement, blend) in stamps.iter_mut() {
        let change = layer.apply_stamp(cpu.as_mut(), placement, *blend).unwrap();
        let op = StampOp {
            stamp: *gpu,
            placement: *placement,
            blend: *blend,
        };
        let covered = pass
            .encode_detail(device, queue, &mut encoder, &mut tiles, &op)
            .unwrap();
        assert_eq!(covered, change.tiles, "dirty tiles of {placement:?}");
        assert!(change.changed_texels > 0, "{placement:?} changed nothing");
        touched.extend(covered.iter().map(|(t, _)| (t.y, t.x)));
    }
    queue.submit([encoder.finish()]);
    pass.recall();
    let (max, differ) = compare(&ctx, &tiles, &layer);
    ctx.check().expect("no GPU validation errors");
    eprintln!(
        "detail stamps on {}: max |GPU - CPU| = {max} LSB, {differ} texels differ",
        ctx.report().name
    );
    assert!(max <= STAMP_BOUND_LSB, "max difference {max} LSB");
    assert_eq!(differ, 0, "{differ} texels differ");
    // The wrap-corner stamp reached the four corner tiles; every covered tile has a slot,
    // every other tile is still the shared zero tile.
    for t in [(0, 0), (4, 0), (0, 3), (4, 3)] {
        assert!(touched.contains(&(t.1, t.0)), "tile {t:?} covered");
    }
    let grid = layout().tiles();
    let mut untouched = 0;
    for y in 0..grid.y {
        for x in 0..grid.x {
            let t = UVec2::new(x, y);
            if touched.contains(&(y, x)) || t == UVec2::new(2, 1) {
                assert!(tiles.slot_of(t).is_some(), "tile {t} resident");
            } else {
                assert_eq!(tiles.state(t), Some(DetailTileState::Zero), "tile {t}");
                untouched += 1;
            }
        }
    }
    assert!(untouched > 0, "the test leaves some tile untouched");
}

#[test]
fn a_detail_stamp_across_tiles_equals_the_gpu_stamp_on_one_large_map() {
    let Some(ctx) = context_or_skip("a_detail_stamp_across_tiles_equals_one_large_map") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = StampPass::new(device).unwrap();
    // A layer whose size is a whole number of tiles, so it repeats as the large map does.
    let layout = DetailLayout::new(UVec2::new(32, 32), 0.1, 3, 24).unwrap();
    let ts = layout.detail_texel_m();
    let mut tiles = GpuDetailTiles::new(device, layout, 16).unwrap();
    let whole = HeightMap::new(
        Grid::new(96, 96, 128u8).unwrap(),
        detail_encoding(),
        ts,
        WrapMode::Repeat,
    )
    .unwrap();
    let big = GpuHeightMap::from_map(device, queue, &whole).unwrap();
    let image = Grid::from_fn(9, 11, |x, y| (x * 37 + y * 11) as u8).unwrap();
    let gpu_tex = GpuTextureStamp::new(device, &TextureStamp::from_gray8(&image)).unwrap();
    let gauss = GaussianStamp::default();
    let ops = [
        // Over the corner of four tiles (24 texels = 0.8 m), rotated.
        StampOp {
            stamp: GpuStamp::Gaussian(&gauss),
            placement: place(Vec2::splat(0.8), Vec2::new(0.7, 0.3), -0.2, 1.1),
            blend: Blend::Add,
        },
        // Over the wrap corner.
        StampOp {
            stamp: GpuStamp::Texture(&gpu_tex),
            placement: place(Vec2::new(3.15, 0.02), Vec2::new(0.5, 0.6), 0.3, -0.4),
            blend: Blend::Add,
        },
        StampOp {
            stamp: GpuStamp::Texture(&gpu_tex),
            placement: place(Vec2::new(1.6, 2.4), Vec2::new(0.9, 0.6), -0.4, 0.2),
            blend: Blend::Min { base_m: 0.05 },
        },
    ];
    let mut encoder = device.create_command_encoder(&Default::default());
    for op in &ops {
        pass.encode_detail(device, queue, &mut encoder, &mut tiles, op)
            .unwrap();
        pass.encode(device, queue, &mut encoder, &big, op).unwrap();
    }
    queue.submit([encoder.finish()]);
    pass.recall();
    let big: HeightMap<u8> = big.read(device, queue).unwrap();
    let got = gpu_tiles(&ctx, &tiles);
    ctx.check().expect("no GPU validation errors");
    let mut changed = 0;
    for y in 0..96 {
        for x in 0..96 {
            let (tx, ty) = (x / 24, y / 24);
            let tile = &got[(ty * 4 + tx) as usize];
            let a = big.grid().get(x, y).unwrap();
            assert_eq!(tile.get(x % 24, y % 24).unwrap(), a, "texel ({x}, {y})");
            changed += usize::from(a != 128);
        }
    }
    assert!(changed > 500, "the stamps changed {changed} texels");
}

#[test]
fn detail_stamps_over_unloaded_tiles_or_without_slots_change_nothing() {
    let Some(ctx) = context_or_skip("detail_stamps_over_unloaded_tiles") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = StampPass::new(device).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout(), 4).unwrap();
    let data = hashed(32, 3);
    tiles.load(queue, UVec2::new(1, 1), Some(&data)).unwrap();
    tiles.load(queue, UVec2::new(2, 1), Some(&data)).unwrap();
    assert!(tiles.unload(queue, UVec2::new(2, 1)));
    assert_eq!(
        tiles.state(UVec2::new(2, 1)),
        Some(DetailTileState::NotLoaded)
    );
    assert!(
        !tiles.unload(queue, UVec2::new(9, 9)),
        "off the grid: left alone"
    );
    let ts = layout().detail_texel_m();
    let gauss = GaussianStamp::default();
    let at = |c: Vec2, blend| StampOp {
        stamp: GpuStamp::Gaussian(&gauss),
        placement: place(c, Vec2::splat(0.5), -0.2, 0.0),
        blend,
    };
    let corner = |tx: f32, ty: f32| Vec2::new(tx, ty) * 32.0 * ts;
    let mut encoder = device.create_command_encoder(&Default::default());
    let mut stamp = |op: &StampOp<'_>, tiles: &mut GpuDetailTiles| {
        pass.encode_detail(device, queue, &mut encoder, tiles, op)
    };
    // Over the unloaded tile: refused, whatever else it covers.
    let e = stamp(&at(corner(2.0, 1.0), Blend::Add), &mut tiles).unwrap_err();
    assert!(matches!(e, GpuError::DetailTileNotLoaded { tile } if tile == UVec2::new(2, 1)));
    // Four zero tiles need four slots; three are free.
    let e = stamp(&at(corner(4.0, 3.0), Blend::Add), &mut tiles).unwrap_err();
    assert!(
        matches!(e, GpuError::DetailSlotsFull { needed: 4, free: 3 }),
        "{e}"
    );
    let nan = at(corner(1.5, 1.5), Blend::Min { base_m: f32::NAN });
    assert!(stamp(&nan, &mut tiles).is_err());
    let huge = StampOp {
        placement: place(Vec2::splat(2.0), Vec2::splat(50.0), 0.1, 0.0),
        ..at(Vec2::ZERO, Blend::Add)
    };
    assert!(
        stamp(&huge, &mut tiles).is_err(),
        "a footprint larger than the layer"
    );
    // Narrower than a texel between texel centres, or an absurd centre: nothing to do.
    for c in [
        Vec2::splat(15.5 * ts),
        Vec2::splat(1e30),
        Vec2::new(-1e30, 3.0),
    ] {
        let tiny = StampOp {
            placement: place(c, Vec2::splat(ts * 0.2), 0.1, 0.0),
            ..at(Vec2::ZERO, Blend::Add)
        };
        assert_eq!(stamp(&tiny, &mut tiles).unwrap(), Vec::new(), "at {c}");
    }
    queue.submit([encoder.finish()]);
    // Nothing was materialised or written.
    assert_eq!(tiles.resident(), 1);
    let all = Rect::from_size(UVec2::splat(32));
    assert_eq!(
        tiles.read(device, queue, UVec2::new(1, 1), all).unwrap(),
        data
    );
    assert!(matches!(
        tiles.read(device, queue, UVec2::new(2, 1), all),
        Err(GpuError::DetailTileNotLoaded { .. })
    ));
    // Reads and loads outside the tile or of the wrong size are refused.
    assert!(
        tiles
            .read(
                device,
                queue,
                UVec2::new(1, 1),
                Rect::new(glam::IVec2::new(20, 0), UVec2::splat(16))
            )
            .is_err()
    );
    assert!(tiles.read(device, queue, UVec2::new(5, 0), all).is_err());
    assert!(
        tiles
            .load(queue, UVec2::new(0, 0), Some(&hashed(16, 1)))
            .is_err()
    );
    assert!(tiles.load(queue, UVec2::new(5, 0), Some(&data)).is_err());
    // A sub-rect reads what was loaded; a zero tile reads as zero.
    let part = tiles
        .read(
            device,
            queue,
            UVec2::new(1, 1),
            Rect::new(glam::IVec2::new(3, 5), UVec2::new(7, 2)),
        )
        .unwrap();
    assert_eq!(part.get(0, 0), data.get(3, 5));
    assert_eq!(part.get(6, 1), data.get(9, 6));
    assert_eq!(
        tiles.read(device, queue, UVec2::ZERO, all).unwrap(),
        Grid::new(32, 32, 128u8).unwrap()
    );
    // Loading the unloaded tile back makes the first stamp possible.
    tiles.load(queue, UVec2::new(2, 1), None).unwrap();
    assert_eq!(tiles.state(UVec2::new(2, 1)), Some(DetailTileState::Zero));
    let mut encoder = device.create_command_encoder(&Default::default());
    let covered = pass
        .encode_detail(
            device,
            queue,
            &mut encoder,
            &mut tiles,
            &at(corner(2.0, 1.0), Blend::Add),
        )
        .unwrap();
    queue.submit([encoder.finish()]);
    assert_eq!(covered.len(), 4);
    assert_eq!(
        tiles.resident(),
        4,
        "the slot freed by the unload was reused"
    );
    ctx.check().expect("no GPU validation errors");
    assert!(GpuDetailTiles::new(device, layout(), 0).is_err());
    assert!(GpuDetailTiles::new(device, layout(), u32::MAX).is_err());
}

/// Streaming from a CPU layer: the wanted tiles are on the GPU as the layer holds them, the
/// others lose their slots, and too many wanted tiles are refused without a change.
#[test]
fn streaming_from_the_cpu_layer_keeps_the_wanted_tiles_resident() {
    let Some(ctx) = context_or_skip("detail_stream_from") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut layer = DetailLayer::new(layout()).unwrap();
    for (x, y, seed) in [(0, 0, 1), (1, 0, 2), (4, 3, 3), (2, 2, 4)] {
        layer.set_tile(UVec2::new(x, y), hashed(32, seed)).unwrap();
    }
    let mut tiles = GpuDetailTiles::new(device, layout(), 3).unwrap();
    let t = |x, y| UVec2::new(x, y);
    // Wanted: two marked tiles and a zero one (which needs no slot).
    let (up, down) = tiles
        .stream_from(queue, &layer, &[t(0, 0), t(1, 0), t(3, 3)])
        .unwrap();
    assert_eq!((up, down), (2, 0));
    assert_eq!(tiles.resident(), 2);
    assert_eq!(tiles.state(t(3, 3)), Some(DetailTileState::Zero));
    let all = Rect::from_size(UVec2::splat(32));
    for w in [t(0, 0), t(1, 0)] {
        assert_eq!(
            &tiles.read(device, queue, w, all).unwrap(),
            layer.tile(w).unwrap()
        );
    }
    // Moving on: (0, 0) is dropped, (4, 3) and (2, 2) come in.
    let (up, down) = tiles
        .stream_from(queue, &layer, &[t(1, 0), t(4, 3), t(2, 2)])
        .unwrap();
    assert_eq!((up, down), (2, 1));
    assert_eq!(tiles.state(t(0, 0)), Some(DetailTileState::NotLoaded));
    for w in [t(1, 0), t(4, 3), t(2, 2)] {
        assert_eq!(
            &tiles.read(device, queue, w, all).unwrap(),
            layer.tile(w).unwrap()
        );
    }
    // Four tiles with texels for three slots: refused, nothing changed.
    let err = tiles
        .stream_from(queue, &layer, &[t(0, 0), t(1, 0), t(4, 3), t(2, 2)])
        .unwrap_err();
    assert!(
        matches!(err, GpuError::DetailSlotsFull { needed: 4, .. }),
        "{err}"
    );
    assert_eq!(tiles.state(t(0, 0)), Some(DetailTileState::NotLoaded));
    assert_eq!(tiles.resident(), 3);
    // Off the grid, or another layout's layer: refused.
    assert!(tiles.stream_from(queue, &layer, &[t(9, 0)]).is_err());
    let other =
        DetailLayer::new(DetailLayout::new(UVec2::new(48, 40), 0.1, 3, 16).unwrap()).unwrap();
    assert!(tiles.stream_from(queue, &other, &[]).is_err());
    ctx.check().expect("no GPU validation errors");
}

/// A coarse-map under `layout()`: 1 mm units around 30 m, uneven (so the spill lands on
/// different values), repeating.
fn spill_coarse() -> HeightMap<u16> {
    let enc = terrain_core::HeightEncoding::new(0.001, -30.0).unwrap();
    let g = Grid::from_fn(48, 40, |x, y| (30_000 + (x * 37 + y * 53) % 400) as u16).unwrap();
    HeightMap::new(g, enc, 0.1, WrapMode::Repeat).unwrap()
}

#[test]
fn spilled_detail_stamps_match_the_cpu_spill_rule() {
    let Some(ctx) = context_or_skip("spilled_detail_stamps_match_the_cpu_spill_rule") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = StampPass::new(device).unwrap();
    let mut spill = terrain_gpu::SpillPass::new(device, 64 * 64).unwrap();
    let mut layer = DetailLayer::new(layout()).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout(), 20).unwrap();
    let mut cpu_coarse = spill_coarse();
    let gpu_coarse = GpuHeightMap::from_map(device, queue, &cpu_coarse).unwrap();
    let ts = layout().detail_texel_m();
    let corner = |tx: f32, ty: f32| Vec2::new(tx, ty) * 32.0 * ts;
    let image = Grid::from_fn(13, 7, |x, y| (x * 19 + y * 31) as u8).unwrap();
    let tex = TextureStamp::from_gray8(&image);
    let gpu_tex = GpuTextureStamp::new(device, &tex).unwrap();
    let gauss = GaussianStamp::default();
    let mut stamps: Vec<(Box<dyn Stamp>, GpuStamp<'_>, StampPlacement, Blend)> = vec![
        // 1.5 m deep over the corner of four tiles: a metre spills down.
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&gauss),
            place(corner(2.0, 1.0), Vec2::new(0.9, 0.5), -1.5, 0.6),
            Blend::Add,
        ),
        // Raised 1.2 m across the map's wrap corner: spills up, onto the coarse-map's corners.
        (
            Box::new(tex.clone()),
            GpuStamp::Texture(&gpu_tex),
            place(Vec2::splat(0.05), Vec2::new(0.6, 0.4), 1.2, 0.7),
            Blend::Add,
        ),
        // A mould pressed 2 to 3 m down.
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&gauss),
            place(corner(1.0, 3.0), Vec2::splat(0.5), 1.0, 0.0),
            Blend::Min { base_m: -3.0 },
        ),
        // Within the range: spills nothing.
        (
            Box::new(tex),
            GpuStamp::Texture(&gpu_tex),
            place(corner(3.0, 2.0), Vec2::splat(0.5), -0.2, -0.3),
            Blend::Add,
        ),
    ];
    let mut encoder = device.create_command_encoder(&Default::default());
    let mut spilled_rects = 0;
    for (i, (cpu, gpu, placement, blend)) in stamps.iter_mut().enumerate() {
        let (change, rects) = layer
            .apply_stamp_spilling(&mut cpu_coarse, cpu.as_mut(), placement, *blend)
            .unwrap();
        let op = StampOp {
            stamp: *gpu,
            placement: *placement,
            blend: *blend,
        };
        let out = spill
            .encode(
                device,
                queue,
                &mut encoder,
                &mut pass,
                terrain_gpu::SpillTargets {
                    tiles: &mut tiles,
                    coarse: &gpu_coarse,
                },
                &op,
            )
            .unwrap();
        assert_eq!(out.detail, change.tiles, "stamp {i}");
        for r in &rects {
            assert!(
                out.coarse.contains(r),
                "stamp {i}: CPU rect {r:?} in {:?}",
                out.coarse
            );
        }
        assert_eq!(rects.is_empty(), i == 3, "stamp {i} spills: {rects:?}");
        spilled_rects += rects.len();
    }
    queue.submit([encoder.finish()]);
    pass.recall();
    spill.recall();
    assert!(
        spilled_rects >= 3,
        "{spilled_rects} coarse rects spilled onto"
    );
    let (max, differ) = compare(&ctx, &tiles, &layer);
    assert!(max <= STAMP_BOUND_LSB, "detail: max difference {max} LSB");
    assert_eq!(differ, 0, "detail: {differ} texels differ");
    // One unit of one texel's excess moves a coarse texel by at most r^2 k = 1/255 m / 1 mm
    // (3.9 units), and a stamp differs from the CPU's by one unit where a value rounds.
    let gpu = gpu_coarse.read(device, queue).unwrap();
    let start = spill_coarse();
    let (mut max_c, mut differ_c, mut moved) = (0, 0, 0);
    for ((a, b), s) in cpu_coarse
        .grid()
        .as_slice()
        .iter()
        .zip(gpu.grid().as_slice())
        .zip(start.grid().as_slice())
    {
        let d = (i32::from(*a) - i32::from(*b)).abs();
        max_c = max_c.max(d);
        differ_c += usize::from(d != 0);
        moved = moved.max((i32::from(*a) - i32::from(*s)).abs());
    }
    ctx.check().expect("no GPU validation errors");
    eprintln!(
        "spill on {}: detail max {max} LSB ({differ} texels), coarse max {max_c} units ({differ_c} texels), largest coarse change {moved} units",
        ctx.report().name
    );
    assert!(
        moved > 500,
        "the spill moved the coarse-map by {moved} units"
    );
    assert!(max_c <= 5, "coarse: max difference {max_c} units");
    assert!(differ_c < 20, "coarse: {differ_c} texels differ");
}

#[test]
fn a_spill_the_pass_cannot_hold_is_refused_before_anything_is_stamped() {
    let Some(ctx) = context_or_skip("a_spill_the_pass_cannot_hold_is_refused") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = StampPass::new(device).unwrap();
    let mut spill = terrain_gpu::SpillPass::new(device, 100).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout(), 20).unwrap();
    let coarse = GpuHeightMap::from_map(device, queue, &spill_coarse()).unwrap();
    let enc = terrain_core::HeightEncoding::new(0.001, -30.0).unwrap();
    let other =
        HeightMap::new(Grid::new(40, 40, 0u16).unwrap(), enc, 0.1, WrapMode::Repeat).unwrap();
    let other = GpuHeightMap::from_map(device, queue, &other).unwrap();
    let gauss = GaussianStamp::default();
    let op = |s: f32| StampOp {
        stamp: GpuStamp::Gaussian(&gauss),
        placement: place(Vec2::splat(1.0), Vec2::splat(s), -2.0, 0.0),
        blend: Blend::Add,
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    // 0.5 m is 15 x 15 detail texels: more than the window's 100.
    let big = spill.encode(
        device,
        queue,
        &mut encoder,
        &mut pass,
        terrain_gpu::SpillTargets {
            tiles: &mut tiles,
            coarse: &coarse,
        },
        &op(0.5),
    );
    assert!(matches!(big, Err(GpuError::Core(_))), "{big:?}");
    let wrong = spill.encode(
        device,
        queue,
        &mut encoder,
        &mut pass,
        terrain_gpu::SpillTargets {
            tiles: &mut tiles,
            coarse: &other,
        },
        &op(0.2),
    );
    assert!(
        matches!(wrong, Err(GpuError::SizeMismatch { .. })),
        "{wrong:?}"
    );
    assert!(terrain_gpu::SpillPass::new(device, 0).is_err());
    assert!(terrain_gpu::SpillPass::new(device, (1 << 24) + 1).is_err());
    queue.submit([encoder.finish()]);
    let grid = layout().tiles();
    for y in 0..grid.y {
        for x in 0..grid.x {
            assert_eq!(tiles.state(UVec2::new(x, y)), Some(DetailTileState::Zero));
        }
    }
    assert_eq!(coarse.read(device, queue).unwrap(), spill_coarse());
    // A small mark fits and spills.
    let mut encoder = device.create_command_encoder(&Default::default());
    let out = spill
        .encode(
            device,
            queue,
            &mut encoder,
            &mut pass,
            terrain_gpu::SpillTargets {
                tiles: &mut tiles,
                coarse: &coarse,
            },
            &op(0.2),
        )
        .unwrap();
    queue.submit([encoder.finish()]);
    assert!(!out.coarse.is_empty());
    assert_ne!(coarse.read(device, queue).unwrap(), spill_coarse());
    // The ends of the f32 range: an answer or an error, never a panic or a validation error.
    let mut encoder = device.create_command_encoder(&Default::default());
    for c in [1e30f32, -3e38] {
        let far = StampOp {
            stamp: GpuStamp::Gaussian(&gauss),
            placement: place(Vec2::splat(c), Vec2::splat(0.2), -1e30, 0.0),
            blend: Blend::Add,
        };
        let _ = spill.encode(
            device,
            queue,
            &mut encoder,
            &mut pass,
            terrain_gpu::SpillTargets {
                tiles: &mut tiles,
                coarse: &coarse,
            },
            &far,
        );
    }
    queue.submit([encoder.finish()]);
    ctx.check().expect("no GPU validation errors");
}

/// The rects a detail stamp changed come back through the readback ring, never waiting, equal
/// to a blocking download of the same texels; a tile without a slot is refused.
#[test]
fn stamped_detail_rects_come_back_through_the_readback_ring() {
    let Some(ctx) = context_or_skip("stamped_detail_rects_come_back_through_the_ring") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = StampPass::new(device).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout(), 8).unwrap();
    let mut readback = terrain_gpu::RegionReadback::new(device, 8).unwrap();
    let gauss = GaussianStamp::default();
    let ts = layout().detail_texel_m();
    // Over the corner of four tiles: four rects.
    let op = StampOp {
        stamp: GpuStamp::Gaussian(&gauss),
        placement: place(Vec2::new(64.0, 32.0) * ts, Vec2::new(0.9, 0.5), -0.3, 0.6),
        blend: Blend::Add,
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    let covered = pass
        .encode_detail(device, queue, &mut encoder, &mut tiles, &op)
        .unwrap();
    assert_eq!(covered.len(), 4);
    let mut asked = std::collections::HashMap::new();
    for &(tile, rect) in &covered {
        let ticket = readback
            .request_detail(device, &mut encoder, &tiles, tile, rect)
            .unwrap();
        asked.insert(ticket, (tile, rect));
    }
    queue.submit([encoder.finish()]);
    pass.recall();
    let mut arrived = Vec::new();
    let start = std::time::Instant::now();
    while arrived.len() < covered.len() {
        assert!(start.elapsed().as_secs() < 30, "the rects never arrived");
        arrived.extend(
            readback
                .poll_with(device, |r| (r.ticket, r.rect, r.to_u8()))
                .unwrap(),
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    for (ticket, rect, texels) in arrived {
        let (tile, asked_rect) = asked[&ticket];
        assert_eq!(rect, asked_rect);
        let want = tiles.read(device, queue, tile, rect).unwrap();
        assert_eq!(texels.unwrap(), want, "tile {tile}");
        assert!(
            want.as_slice().iter().any(|&v| v != DETAIL_ZERO_RAW),
            "the stamp reached tile {tile}"
        );
    }
    // The zero tile and a tile off the grid have nothing to read back.
    let mut encoder = device.create_command_encoder(&Default::default());
    let all = Rect::from_size(UVec2::splat(32));
    assert!(
        readback
            .request_detail(device, &mut encoder, &tiles, UVec2::new(4, 3), all)
            .is_err()
    );
    assert!(
        readback
            .request_detail(device, &mut encoder, &tiles, UVec2::new(9, 9), all)
            .is_err()
    );
    ctx.check().expect("no GPU validation errors");
}
