//! Exact determinism, replayed (issue 38): a seeded stream of deformation events covering every
//! stamp kind (Gaussian, texture, shockwave, user procedural) and every blend (add, min, max),
//! with half-unit bases, rotations, footprints across the wrap edges and corners of a repeating
//! map and across the edges of a clamped one, applied with terrain-core on the CPU and with
//! `StampPass` on the GPU: the heights must be equal byte for byte. Without an adapter the tests
//! skip, or fail under `TERRAIN_REQUIRE_GPU=1`.

use glam::Vec2;
use terrain_core::{
    Blend, GaussianStamp, Grid, HeightEncoding, HeightMap, Shockwave, ShockwaveParams, Stamp,
    StampPlacement, TextureStamp, WrapMode, apply_stamp,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    ExactInF32, GpuContext, GpuHeightMap, GpuProceduralStamp, GpuStamp, GpuTextureStamp, StampOp,
    StampPass,
};

/// splitmix64: the stream's generator, so a seed replays the same events everywhere.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next() >> 40) as f32 / (1u64 << 24) as f32)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// The user procedural stamp on both sides, written with exact f32 operations (see
/// `GpuProceduralStamp`): a diamond `1 - (|x| + |y|)` inside `|x| + |y| < 0.5`, and a step.
struct Diamond;
impl Stamp for Diamond {
    fn value(&self, local: Vec2) -> f32 {
        let r = local.x.abs() + local.y.abs();
        if r < 0.5 {
            1.0 - r
        } else if local.x < 0.0 {
            0.25
        } else {
            0.0
        }
    }
}
const DIAMOND_WGSL: &str = "fn user_stamp_value(local: vec2<f32>) -> f32 {
    let r = abs(local.x) + abs(local.y);
    if r < 0.5 {
        return 1.0 - r;
    }
    return select(0.0, 0.25, local.x < 0.0);
}";

/// One recorded event.
#[derive(Debug, Clone)]
enum Kind {
    Gaussian(GaussianStamp),
    Texture,
    /// The shockwave's change since its last application, after `steps` more steps.
    Shockwave {
        steps: u32,
    },
    User,
}

#[derive(Debug, Clone)]
struct Event {
    kind: Kind,
    placement: StampPlacement,
    blend: Blend,
}

/// A base whose stored value is a half unit (`k + 0.5`) of `enc`, the case f32 sums rounded
/// differently on the GPU; or any base in the map's range.
fn base(rng: &mut Rng, enc: HeightEncoding, max_raw: f64) -> f32 {
    let k = rng.below(max_raw as u64) as f64;
    if rng.below(2) == 0 {
        enc.to_metres(k + 0.5)
    } else {
        enc.to_metres(k + f64::from(rng.range(0.0, 1.0)))
    }
}

/// `n` events over a map of `extent` metres: centres from a tenth outside to a tenth past the
/// far edge (so across edges and corners), plus one on each corner.
fn stream(
    seed: u64,
    n: usize,
    extent: Vec2,
    max_size: f32,
    intensity: f32,
    enc: HeightEncoding,
    max_raw: f64,
) -> Vec<Event> {
    let mut rng = Rng(seed);
    let corners = [
        Vec2::ZERO,
        Vec2::new(extent.x, 0.0),
        Vec2::new(0.0, extent.y),
        extent,
    ];
    (0..n)
        .map(|e| {
            let center = if e < 4 {
                corners[e]
            } else {
                Vec2::new(
                    rng.range(-0.1, 1.1) * extent.x,
                    rng.range(-0.1, 1.1) * extent.y,
                )
            };
            let scale = Vec2::new(
                rng.range(0.02, 1.0) * max_size,
                rng.range(0.02, 1.0) * max_size,
            );
            let rotation = match rng.below(3) {
                0 => 0.0,
                1 => std::f32::consts::FRAC_PI_2 * rng.below(4) as f32,
                _ => rng.range(-7.0, 7.0),
            };
            let placement = StampPlacement::new(
                center,
                scale,
                rng.range(-1.0, 1.0) * intensity * if rng.below(8) == 0 { 40.0 } else { 1.0 },
            )
            .unwrap()
            .with_rotation(rotation)
            .unwrap();
            let kind = match e % 4 {
                0 => Kind::Gaussian(GaussianStamp::new(10f32.powf(rng.range(-4.0, -1.0))).unwrap()),
                1 => Kind::Texture,
                2 => Kind::Shockwave {
                    steps: 1 + rng.below(4) as u32,
                },
                _ => Kind::User,
            };
            let blend = match (e / 4) % 3 {
                0 => Blend::Add,
                1 => Blend::Min {
                    base_m: base(&mut rng, enc, max_raw),
                },
                _ => Blend::Max {
                    base_m: base(&mut rng, enc, max_raw),
                },
            };
            Event {
                kind,
                placement,
                blend,
            }
        })
        .collect()
}

/// A grey image with fine structure (odd size, values not binary fractions: /255).
fn image() -> TextureStamp {
    TextureStamp::from_gray8(
        &Grid::from_fn(13, 9, |x, y| ((x * 37 + y * 91 + x * y * 7) % 256) as u8).unwrap(),
    )
}

/// Replays `events` on `map` with terrain-core and with `StampPass` (in submits of 8 events)
/// and returns both results.
fn replay<T: ExactInF32>(
    ctx: &GpuContext,
    mut map: HeightMap<T>,
    events: &[Event],
) -> (HeightMap<T>, HeightMap<T>) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = StampPass::new(device).unwrap();
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let tex = image();
    let gpu_tex = GpuTextureStamp::new(device, &tex).unwrap();
    let user = GpuProceduralStamp::new(device, &pass, DIAMOND_WGSL).unwrap();
    let mut wave = Shockwave::new(ShockwaveParams {
        resolution: 24,
        damping: 0.01,
        ..Default::default()
    })
    .unwrap();
    for batch in events.chunks(8) {
        let mut encoder = device.create_command_encoder(&Default::default());
        // Shockwave deltas of this batch, uploaded before recording (kept alive to the submit).
        let mut waves = Vec::new();
        for ev in batch {
            if let Kind::Shockwave { steps } = ev.kind {
                for _ in 0..steps {
                    wave.step();
                }
                let delta = wave.take_delta().unwrap();
                waves.push((GpuTextureStamp::new(device, &delta).unwrap(), delta));
            }
        }
        let mut w = 0;
        for ev in batch {
            let (mut cpu_stamp, gpu_stamp): (Box<dyn Stamp>, GpuStamp<'_>) = match &ev.kind {
                Kind::Gaussian(g) => (Box::new(*g), GpuStamp::Gaussian(g)),
                Kind::Texture => (Box::new(tex.clone()), GpuStamp::Texture(&gpu_tex)),
                Kind::Shockwave { .. } => {
                    w += 1;
                    let (g, c) = &waves[w - 1];
                    (Box::new(c.clone()), GpuStamp::Texture(g))
                }
                Kind::User => (Box::new(Diamond), GpuStamp::Procedural(&user)),
            };
            let cpu_dirty =
                apply_stamp(&mut map, cpu_stamp.as_mut(), &ev.placement, ev.blend).unwrap();
            let op = StampOp {
                stamp: gpu_stamp,
                placement: ev.placement,
                blend: ev.blend,
            };
            let gpu_dirty = pass.encode(device, queue, &mut encoder, &gpu, &op).unwrap();
            assert_eq!(cpu_dirty, gpu_dirty, "dirty rects of {ev:?}");
        }
        queue.submit([encoder.finish()]);
        pass.recall();
    }
    let back: HeightMap<T> = gpu.read(device, queue).unwrap();
    ctx.check().expect("no GPU validation errors");
    (map, back)
}

/// Equal byte for byte; on failure, how many texels differ and the first.
fn assert_bytes_equal<T: ExactInF32 + std::fmt::Debug + PartialEq>(
    what: &str,
    cpu: &HeightMap<T>,
    gpu: &HeightMap<T>,
    before: &HeightMap<T>,
) {
    let (c, g) = (cpu.grid().as_slice(), gpu.grid().as_slice());
    let differ: Vec<usize> = (0..c.len()).filter(|&i| c[i] != g[i]).collect();
    let changed = c
        .iter()
        .zip(before.grid().as_slice())
        .filter(|(a, b)| a != b)
        .count();
    eprintln!(
        "{what}: {changed} of {} texels changed, {} differ, FNV-1a {:016x}",
        c.len(),
        differ.len(),
        fnv(bytemuck::cast_slice(c))
    );
    assert!(
        changed > c.len() / 10,
        "{what}: the stream changed only {changed} texels"
    );
    if let Some(&i) = differ.first() {
        let w = cpu.size().x as usize;
        panic!(
            "{what}: {} texels differ, first ({}, {}): CPU {:?} GPU {:?}",
            differ.len(),
            i % w,
            i / w,
            c[i],
            g[i]
        );
    }
    assert!(
        bytemuck::cast_slice::<T, u8>(c) == bytemuck::cast_slice::<T, u8>(g),
        "{what}: bytes differ"
    );
}

fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn hashed<T: terrain_core::HeightSample>(w: u32, h: u32, lo: u32, span: u32) -> Grid<T> {
    Grid::from_fn(w, h, |x, y| {
        let mut z = u64::from(x).wrapping_mul(0x9E37_79B9) ^ u64::from(y).wrapping_mul(0x85EB_CA6B);
        z ^= z >> 15;
        T::from_raw_f64_clamped(f64::from(lo + (z % u64::from(span)) as u32))
    })
    .unwrap()
}

/// A repeating u16 coarse-map (odd size, 0.5 m texels, millimetre units) and a clamped u8
/// detail-like map, each with its own seeded stream of every kind and blend.
#[test]
fn a_recorded_event_stream_replays_bit_identically_on_cpu_and_gpu() {
    let Some(ctx) = context_or_skip("a_recorded_event_stream_replays_bit_identically") else {
        return;
    };
    let enc = HeightEncoding::new(0.001, -5.0).unwrap();
    let before = HeightMap::new(
        hashed::<u16>(301, 263, 10_000, 40_000),
        enc,
        0.5,
        WrapMode::Repeat,
    )
    .unwrap();
    let extent = Vec2::new(150.5, 131.5);
    let events = stream(0x5EED_0038, 96, extent, 60.0, 4.0, enc, 65_535.0);
    let (cpu, gpu) = replay(&ctx, before.clone(), &events);
    assert_bytes_equal("u16 repeating", &cpu, &gpu, &before);

    let enc8 = HeightEncoding::spanning::<u8>(-0.5, 0.5).unwrap();
    let before8 =
        HeightMap::new(hashed::<u8>(97, 75, 60, 100), enc8, 0.03, WrapMode::Clamp).unwrap();
    let extent8 = Vec2::new(97.0, 75.0) * 0.03;
    let events8 = stream(0x5EED_0039, 64, extent8, 1.5, 0.2, enc8, 255.0);
    let (cpu8, gpu8) = replay(&ctx, before8.clone(), &events8);
    assert_bytes_equal("u8 clamped", &cpu8, &gpu8, &before8);
}

/// The case: a texture stamp with a min and a max blend whose base is half a unit
/// (30 m on a 0-60 m u16 map, raw 32 767.5) over a 1024^2 map, which differed by one unit at 77
/// texels while the GPU summed in f32.
#[test]
fn half_unit_bases_on_a_1024_map_are_exact() {
    let Some(ctx) = context_or_skip("half_unit_bases_on_a_1024_map_are_exact") else {
        return;
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 60.0).unwrap();
    let before = HeightMap::new(
        hashed::<u16>(1024, 1024, 20_000, 25_000),
        enc,
        1.0,
        WrapMode::Repeat,
    )
    .unwrap();
    let mk = |c: f32, i: f32, blend| Event {
        kind: Kind::Texture,
        placement: StampPlacement::new(Vec2::splat(c), Vec2::splat(700.0), i)
            .unwrap()
            .with_rotation(0.3)
            .unwrap(),
        blend,
    };
    let events = [
        mk(512.0, -6.0, Blend::Min { base_m: 30.0 }),
        mk(300.0, 7.5, Blend::Max { base_m: 30.0 }),
        mk(700.0, 3.0, Blend::Min { base_m: 30.0 }),
    ];
    let (cpu, gpu) = replay(&ctx, before.clone(), &events);
    assert_bytes_equal("1024^2 half-unit base", &cpu, &gpu, &before);
}
