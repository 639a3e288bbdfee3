//! `DetailReadback`: footprints stamped on the GPU's detail tiles reach a CPU copy of the tiles
//! only through their read-back rects, and that copy equals terrain-core's `DetailLayer`
//! stamped the same way, bit for bit (the stamps are the same integer program): with a ring
//! far smaller than the rects (they wait in order), overlapping footprints (the later copy
//! wins), rects read while others are still on their way, and a refused rect that loses none
//! of the others; and `GpuDetailStream`, which composes them with the tile slots. On whatever
//! adapter the machine has (lavapipe in CI); without one it skips, or fails under
//! `TERRAIN_REQUIRE_GPU=1`.

use glam::{UVec2, Vec2};
use std::collections::HashMap;
use std::time::Duration;
use terrain_core::detail::{DETAIL_ZERO_RAW, DetailLayer, DetailLayout};
use terrain_core::{Blend, GaussianStamp, Grid, Rect, StampPlacement};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{DetailReadback, GpuDetailTiles, GpuStamp, StampOp, StampPass};

/// The CPU's copy of the tiles, as the rects came back.
#[derive(Default)]
struct CpuTiles(HashMap<UVec2, Grid<u8>>);

impl CpuTiles {
    fn write(&mut self, side: u32, tile: UVec2, rect: Rect, texels: &Grid<u8>) {
        let grid = self
            .0
            .entry(tile)
            .or_insert_with(|| Grid::new(side, side, DETAIL_ZERO_RAW).unwrap());
        grid.paste(texels, rect.min).unwrap();
    }
}

#[test]
fn stamped_rects_come_back_in_order_and_equal_the_cpu_layer() {
    let Some(ctx) = context_or_skip("detail_readback") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    // A 64 x 64 coarse-map at 0.5 m refined x4: 256^2 detail texels in 4 x 4 tiles of 64.
    let layout = DetailLayout::new(UVec2::splat(64), 0.5, 4, 64).unwrap();
    let side = layout.tile_size();
    let mut layer = DetailLayer::new(layout).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout, 16).unwrap();
    let mut pass = StampPass::new(device).unwrap();
    // Two buffers for a dozen rects: most wait for room.
    let mut readback = DetailReadback::new(device, 2).unwrap();
    let mut cpu = CpuTiles::default();
    let mut foot = GaussianStamp::default();
    // A walk across the tile edge at 16 m, then the same spot twice (the second copy of its
    // texels is the newer one).
    let mut centres: Vec<Vec2> = (0..8)
        .map(|i| Vec2::new(12.0 + 1.1 * i as f32, 15.6 + 0.4 * (i % 2) as f32))
        .collect();
    centres.extend([Vec2::new(20.0, 20.0), Vec2::new(20.0, 20.0)]);
    let mut requested = 0;
    for (i, c) in centres.iter().enumerate() {
        let placement = StampPlacement::new(*c, Vec2::new(0.7, 1.1), -0.08).unwrap();
        layer
            .apply_stamp(&mut foot, &placement, Blend::Add)
            .unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        let op = StampOp {
            stamp: GpuStamp::Gaussian(&foot),
            placement,
            blend: Blend::Add,
        };
        let rects = pass
            .encode_detail(device, queue, &mut encoder, &mut tiles, &op)
            .unwrap();
        requested += rects.len();
        readback
            .request(device, &mut encoder, &tiles, rects)
            .unwrap();
        queue.submit([encoder.finish()]);
        pass.recall();
        if i < 3 {
            // Nothing taken yet: the two buffers are busy and the rects wait, their tiles
            // reported in flight.
            continue;
        }
        if i == 3 {
            assert!(readback.outstanding() > 2, "{}", readback.outstanding());
            assert!(!readback.tiles_in_flight().is_empty());
        }
        // Take what has arrived, never waiting.
        let _ = device.poll(wgpu::PollType::Poll);
        for (tile, rect, texels) in readback.poll(device).unwrap() {
            cpu.write(side, tile, rect, &texels);
        }
    }
    assert!(requested > 10, "{requested} rects");
    // A tile without a slot is refused, queueing nothing; the rects waiting from earlier
    // stamps still come back.
    let mut encoder = device.create_command_encoder(&Default::default());
    let bad = [(UVec2::new(3, 3), Rect::from_size(UVec2::splat(4)))];
    assert!(readback.request(device, &mut encoder, &tiles, bad).is_err());
    queue.submit([encoder.finish()]);
    for (tile, rect, texels) in readback
        .flush(device, queue, &tiles, Duration::from_secs(60))
        .unwrap()
    {
        cpu.write(side, tile, rect, &texels);
    }
    assert_eq!(readback.outstanding(), 0);
    assert!(readback.tiles_in_flight().is_empty());
    // Every tile the layer stamped is the CPU copy's, texel for texel.
    let n = layout.tiles();
    let mut compared = 0;
    for ty in 0..n.y {
        for tx in 0..n.x {
            let t = UVec2::new(tx, ty);
            match (layer.tile(t), cpu.0.get(&t)) {
                (Some(want), Some(got)) => {
                    assert_eq!(want, got, "tile {t}");
                    compared += 1;
                }
                (None, None) => {}
                (want, got) => panic!(
                    "tile {t}: stamped on the CPU {}, came back {}",
                    want.is_some(),
                    got.is_some()
                ),
            }
        }
    }
    assert!(
        compared >= 2,
        "the walk crosses a tile edge: {compared} tiles"
    );
    ctx.check().expect("no GPU validation errors");
}

/// `GpuDetailStream`, the detail layer's GPU side whole: a walker's footprints across tiles,
/// two a frame, into a working set of eight slots that follows them (tiles with rects still on
/// their way kept in it, tiles leaving it reloaded from the CPU's copy when they come back);
/// the CPU's copy, fed only by the rects read back, equals `DetailLayer` after the flush.
#[test]
fn a_detail_stream_follows_its_working_set_and_reads_back_the_cpu_layer() {
    use terrain_core::detail::tiles_of_pieces;
    use terrain_gpu::GpuDetailStream;
    let Some(ctx) = context_or_skip("detail_stream") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let layout = DetailLayout::new(UVec2::splat(64), 0.5, 4, 64).unwrap();
    let side = layout.tile_size();
    let mut layer = DetailLayer::new(layout).unwrap();
    let mut stream = GpuDetailStream::new(device, layout, 8, 3).unwrap();
    let mut cpu = CpuTiles::default();
    let mut loaded: Vec<UVec2> = Vec::new();
    let mut foot = GaussianStamp::default();
    let mut unloads = 0;
    for frame in 0..24 {
        // Along a diagonal that crosses three tiles, and back over the first.
        let t = if frame < 16 {
            frame as f32
        } else {
            32.0 - frame as f32
        };
        let steps: Vec<StampPlacement> = (0..2)
            .map(|k| {
                let c = Vec2::splat(6.0 + 1.9 * t + 0.6 * k as f32);
                StampPlacement::new(c, Vec2::new(0.5, 0.9), -0.1).unwrap()
            })
            .collect();
        let mut needed = stream.tiles_in_flight();
        for p in &steps {
            let pieces = layout
                .footprint_pieces(p.footprint(layout.detail_texel_m()).unwrap())
                .unwrap();
            needed.extend(tiles_of_pieces(&pieces).into_iter().map(|(t, _)| t));
        }
        needed.sort_unstable_by_key(|t| (t.y, t.x));
        needed.dedup();
        let unload: Vec<UVec2> = loaded
            .iter()
            .filter(|t| !needed.contains(t))
            .copied()
            .collect();
        unloads += unload.len();
        let load: Vec<UVec2> = needed
            .iter()
            .filter(|t| !loaded.contains(t))
            .copied()
            .collect();
        stream
            .follow(queue, &unload, load.iter().map(|t| (*t, cpu.0.get(t))))
            .unwrap();
        loaded = needed;
        for p in &steps {
            layer.apply_stamp(&mut foot, p, Blend::Add).unwrap();
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        let texels = stream
            .encode_stamps(
                device,
                queue,
                &mut encoder,
                GpuStamp::Gaussian(&foot),
                &steps,
            )
            .unwrap();
        assert!(texels > 0);
        queue.submit([encoder.finish()]);
        stream.recall();
        for (tile, rect, texels) in stream.poll(device).unwrap() {
            cpu.write(side, tile, rect, &texels);
        }
    }
    for (tile, rect, texels) in stream
        .flush(device, queue, Duration::from_secs(30))
        .unwrap()
    {
        cpu.write(side, tile, rect, &texels);
    }
    assert!(unloads > 0, "the working set never moved");
    assert!(cpu.0.len() >= 3);
    for (tile, grid) in &cpu.0 {
        assert!(
            layer.tile(*tile) == Some(grid),
            "tile {tile}: GPU and CPU differ"
        );
    }
    ctx.check().expect("validation");
}
