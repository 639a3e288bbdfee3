//! `DeformableMap` against terrain-core: stamps across the wrap of a repeating map leave the
//! heights the CPU's `apply_stamp` leaves, bit for bit (both run the exact integer stamp
//! program), and the normals that follow them in the same submit are the CPU's slope codes of
//! the stamped map, bit for bit (as `passes.rs` argues for the normal pass). Without an
//! adapter the test skips, or fails under `TERRAIN_REQUIRE_GPU=1`.

use glam::{UVec2, Vec2};
use terrain_core::{
    Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, SlopeCodec, StampPlacement,
    TerrainParams, TextureStamp, WrapMode, apply_stamp, generate_coarse_map,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{DeformableMap, GpuError, GpuStamp, GpuTextureStamp, StampOp, Submit};

/// Counts the submits made through it, by name.
struct Counting<'a> {
    device: &'a wgpu::Device,
    queue: &'a wgpu::Queue,
    names: Vec<&'static str>,
}

impl Submit for Counting<'_> {
    fn submit(
        &mut self,
        name: &'static str,
        work: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> Result<(), GpuError>,
    ) -> Result<(), GpuError> {
        self.names.push(name);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        work(&mut encoder)?;
        self.queue.submit([encoder.finish()]);
        Ok(())
    }
}

/// A procedural map of `size` at 0.5 m, 0-30 m in u16, repeating or clamped at its edges.
fn terrain(size: UVec2, seed: u64, wrap: WrapMode) -> CoarseMap {
    let params = TerrainParams {
        size,
        seed,
        ..TerrainParams::default()
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 30.0).unwrap();
    let map = generate_coarse_map(&params, enc, 0.5).unwrap();
    CoarseMap::new(map.grid().clone(), enc, 0.5, wrap).unwrap()
}

#[test]
fn a_deformed_map_and_its_normals_equal_the_cpu_reference() {
    let Some(ctx) = context_or_skip("a_deformed_map_and_its_normals_equal_the_cpu") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut cpu = terrain(UVec2::new(120, 90), 5, WrapMode::Repeat);
    let mut gpu = DeformableMap::new(device, queue, &cpu).unwrap();
    let codec = SlopeCodec::for_map(&cpu);
    assert_eq!(
        gpu.normals().read_codes(device, queue).unwrap(),
        codec.codes(&cpu),
        "the normals of the map as uploaded"
    );

    let gauss = GaussianStamp::default();
    let image = Grid::from_fn(9, 5, |x, y| (x * 23 + y * 41) as u8).unwrap();
    let tex = TextureStamp::from_gray8(&image);
    let gpu_tex = GpuTextureStamp::new(device, &tex).unwrap();
    // A crater across the map's corner (4 rects on a repeating map), a texture inside it.
    let crater = StampPlacement::new(Vec2::new(1.0, 0.5), Vec2::splat(8.0), -2.5).unwrap();
    let print = StampPlacement::new(Vec2::new(30.0, 20.0), Vec2::new(3.0, 5.0), 0.8)
        .unwrap()
        .with_rotation(0.4)
        .unwrap();
    let ops = [
        StampOp {
            stamp: GpuStamp::Gaussian(&gauss),
            placement: crater,
            blend: Blend::Add,
        },
        StampOp {
            stamp: GpuStamp::Texture(&gpu_tex),
            placement: print,
            blend: Blend::Add,
        },
    ];
    let mut rects = apply_stamp(&mut cpu, &mut gauss.clone(), &crater, Blend::Add).unwrap();
    rects.extend(apply_stamp(&mut cpu, &mut tex.clone(), &print, Blend::Add).unwrap());
    assert_eq!(rects.len(), 5, "the crater wraps into four rects");

    let mut submit = Counting {
        device,
        queue,
        names: Vec::new(),
    };
    let dirty = gpu.deform_with(device, queue, &mut submit, &ops).unwrap();
    assert_eq!(submit.names, [DeformableMap::DEFORM], "one submit");
    assert_eq!(dirty, rects);
    let back = gpu.read(device, queue).unwrap();
    assert_eq!(back.grid(), cpu.grid(), "heights equal the CPU's");
    assert_eq!(
        gpu.normals().read_codes(device, queue).unwrap(),
        codec.codes(&cpu),
        "the normals followed every stamped rect"
    );

    // Nothing to stamp: no rect, no change.
    assert!(gpu.deform(device, queue, &[]).unwrap().is_empty());
    assert_eq!(gpu.read(device, queue).unwrap().grid(), cpu.grid());
    ctx.check().expect("no GPU validation errors");
}

#[test]
fn stamps_recorded_into_the_callers_encoder_on_a_clamped_map_equal_the_cpu() {
    let Some(ctx) = context_or_skip("stamps_recorded_into_the_callers_encoder") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut cpu = terrain(UVec2::new(96, 64), 9, WrapMode::Clamp);
    let mut gpu = DeformableMap::new(device, queue, &cpu).unwrap();
    let gauss = GaussianStamp::default();
    // Across the corner: clipped to one rect on a clamped map; and one off the map: none.
    let corner = StampPlacement::new(Vec2::new(1.0, 0.5), Vec2::splat(8.0), -2.5).unwrap();
    let off = StampPlacement::new(Vec2::new(-40.0, 10.0), Vec2::splat(4.0), 1.0).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    let mut dirty = Vec::new();
    let mut want = Vec::new();
    for placement in [corner, off] {
        let op = StampOp {
            stamp: GpuStamp::Gaussian(&gauss),
            placement,
            blend: Blend::Add,
        };
        dirty.extend(gpu.encode_stamp(device, queue, &mut encoder, &op).unwrap());
        want.extend(apply_stamp(&mut cpu, &mut gauss.clone(), &placement, Blend::Add).unwrap());
    }
    gpu.encode_normals(device, queue, &mut encoder, &dirty)
        .unwrap();
    queue.submit([encoder.finish()]);
    gpu.recall();
    assert_eq!(dirty, want);
    assert_eq!(
        dirty.len(),
        1,
        "the corner crater clipped, the other off the map"
    );
    assert_eq!(gpu.read(device, queue).unwrap().grid(), cpu.grid());
    let codes = gpu.normals().read_codes(device, queue).unwrap();
    assert_eq!(codes, SlopeCodec::for_map(&cpu).codes(&cpu));
    ctx.check().expect("no GPU validation errors");
}
