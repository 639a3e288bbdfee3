//! The tile atlas on the GPU against terrain-core's `TileAtlas`: what the atlas surface reads
//! (stored height exact, metres and central-difference gradients within float rounding) for
//! random residency patterns, clamped and wrapped worlds; a partly resident world drawn
//! without holes; a fully resident one drawn like the coarse-map it was cut from; and refusals
//! instead of panics; stamps on tiles in their slots and the readback of the changed rects
//! against terrain-core's `apply_stamp` on the same tiles.

#[path = "common/cracks.rs"]
mod cracks;
#[path = "common/scene.rs"]
#[allow(dead_code)] // Scene::render draws the coarse surface only; these tests draw their own.
mod scene;
use cracks::holes;

use glam::{IVec2, UVec2, Vec2, Vec3};
use scene::Scene;
use terrain_core::{
    Grid, HeightEncoding, INVALID_SLOT, TileAtlas, TileLayout, TileUploadTarget, WrapMode,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    AtlasConfig, AtlasProbe, Camera, ClipmapSurface, ClipmapView, GpuError, GpuTileAtlas,
    OffscreenTarget, SkyColors, TerrainStyle,
};
use terrain_lod::Frustum;

/// splitmix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn chance(&mut self, p: f64) -> bool {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }
}

/// A level pyramid of `base` (2x2 averages, rounded; odd edges repeat their last sample) cut
/// into tiles: `tile(level, xy)` is the tile's samples, edge tiles padded by clamping.
struct Pyramid {
    levels: Vec<Grid<u16>>,
    tile_size: u32,
}

impl Pyramid {
    fn new(base: Grid<u16>, levels: u32, tile_size: u32) -> Self {
        let mut out = vec![base];
        for _ in 1..levels {
            let prev = out.last().unwrap();
            let size = (prev.size() + 1) / 2;
            let next = Grid::from_fn(size.x, size.y, |x, y| {
                let mut sum = 0u32;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let p = IVec2::new((2 * x + dx) as i32, (2 * y + dy) as i32);
                    sum += u32::from(prev.get_wrapped(p, WrapMode::Clamp));
                }
                ((sum + 2) / 4) as u16
            })
            .unwrap();
            out.push(next);
        }
        Self {
            levels: out,
            tile_size,
        }
    }

    fn tile(&self, level: u32, t: UVec2) -> Grid<u16> {
        let g = &self.levels[level as usize];
        let ts = self.tile_size;
        Grid::from_fn(ts, ts, |x, y| {
            let p = (t * ts + UVec2::new(x, y)).as_ivec2();
            g.get_wrapped(p, WrapMode::Clamp)
        })
        .unwrap()
    }
}

/// Applies one call to both atlases.
fn upload_both(
    gpu: &mut GpuTileAtlas,
    cpu: &mut TileAtlas,
    pyramid: &Pyramid,
    slot: u32,
    level: u32,
    t: UVec2,
) {
    let tile = pyramid.tile(level, t);
    let a = gpu.upload(slot, level, t, &tile).unwrap();
    let b = cpu.upload(slot, level, t, &tile).unwrap();
    assert_eq!(a, b);
}

fn map_both(gpu: &mut GpuTileAtlas, cpu: &mut TileAtlas, level: u32, t: UVec2, slot: Option<u32>) {
    gpu.map(level, t, slot).unwrap();
    cpu.map(level, t, slot).unwrap();
}

/// Random residency: every tile of each level resident with that level's probability (coarser
/// levels likelier; the root missing in some patterns, so the fill shows), then a round of
/// evictions whose slots take other tiles, as a pool would do it.
fn random_residency(gpu: &mut GpuTileAtlas, cpu: &mut TileAtlas, pyramid: &Pyramid, rng: &mut Rng) {
    let layout = *cpu.layout();
    let slots = cpu.slot_count();
    let mut free: Vec<u32> = (0..slots).rev().collect();
    let mut resident = Vec::new();
    let root_missing = rng.chance(0.25);
    for level in (0..layout.levels).rev() {
        let p = match level {
            0 => 0.3,
            1 => 0.5,
            _ => 0.7,
        };
        let t = layout.tiles_at(level);
        for y in 0..t.y {
            for x in 0..t.x {
                let top = level + 1 == layout.levels;
                let want = if top { !root_missing } else { rng.chance(p) };
                if !want {
                    continue;
                }
                let Some(slot) = free.pop() else { continue };
                let xy = UVec2::new(x, y);
                upload_both(gpu, cpu, pyramid, slot, level, xy);
                map_both(gpu, cpu, level, xy, Some(slot));
                resident.push((level, xy, slot));
            }
        }
    }
    // Evict a third of the resident tiles and reuse their slots for tiles not resident.
    for i in (0..resident.len()).rev() {
        if !rng.chance(0.33) {
            continue;
        }
        let (level, xy, slot) = resident.swap_remove(i);
        map_both(gpu, cpu, level, xy, None);
        let l = (rng.next() % u64::from(layout.levels)) as u32;
        let t = layout.tiles_at(l);
        let n = UVec2::new(
            (rng.next() % u64::from(t.x)) as u32,
            (rng.next() % u64::from(t.y)) as u32,
        );
        if cpu.slot_of(l, n).is_none() {
            upload_both(gpu, cpu, pyramid, slot, l, n);
            map_both(gpu, cpu, l, n, Some(slot));
        }
    }
}

fn noise_grid(size: UVec2, seed: u64) -> Grid<u16> {
    let mut rng = Rng(seed);
    Grid::from_fn(size.x, size.y, |_, _| (rng.next() % 65_536) as u16).unwrap()
}

#[test]
fn the_atlas_surface_reads_what_the_cpu_reference_reads_for_random_residency() {
    let Some(ctx) = context_or_skip("atlas_probe_matches_cpu") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut probe = AtlasProbe::new(device, 32_768).unwrap();
    let mut checked = 0usize;
    for (case, wrap) in [WrapMode::Clamp, WrapMode::Repeat, WrapMode::Clamp]
        .into_iter()
        .enumerate()
    {
        // 200 x 136 texels in 16-texel tiles: 13x9, 7x5, 4x3, 2x2, 1x1 tiles; padded edges.
        let layout = TileLayout {
            world_size: UVec2::new(200, 136),
            tile_size: 16,
            levels: 5,
            texel_size: 0.25,
            encoding: HeightEncoding::new(0.01, -3.0).unwrap(),
            wrap,
            fill: 1234,
        };
        let config = AtlasConfig {
            slots: 48,
            world: layout,
        };
        let pyramid = Pyramid::new(noise_grid(layout.world_size, case as u64), 5, 16);
        let mut gpu = GpuTileAtlas::new(device, queue, &config).unwrap();
        let mut cpu = TileAtlas::new(layout, config.slots).unwrap();
        let mut rng = Rng(0xA71A5 + case as u64);
        // Every texel of the world, a margin around it, and far-off texels.
        let mut texels = Vec::new();
        for y in -3..139 {
            for x in -3..203 {
                texels.push(IVec2::new(x, y));
            }
        }
        texels.extend([
            IVec2::new(-(1 << 29), 5),
            IVec2::new(1 << 29, -(1 << 29)),
            IVec2::new(12_345, -987),
        ]);
        for round in 0..3 {
            random_residency(&mut gpu, &mut cpu, &pyramid, &mut rng);
            let table = gpu.read_table(device, queue).unwrap();
            assert_eq!(
                table,
                cpu.table(),
                "case {case} round {round}: tables differ"
            );
            let got = probe.read(device, queue, &gpu, &texels).unwrap();
            assert_eq!(got.len(), texels.len());
            let ts = layout.texel_size;
            let h =
                |t: IVec2| layout.encoding.offset + layout.encoding.scale * cpu.stored_at(t) as f32;
            for (t, g) in texels.iter().zip(&got) {
                let stored = cpu.stored_at(*t);
                assert_eq!(g.stored, stored, "case {case} round {round} texel {t}");
                let want_h = h(*t);
                assert!(
                    (g.height - want_h).abs() <= 1e-4,
                    "texel {t}: height {} vs {want_h}",
                    g.height
                );
                let d = Vec2::new(
                    h(*t + IVec2::X) - h(*t - IVec2::X),
                    h(*t + IVec2::Y) - h(*t - IVec2::Y),
                ) / (2.0 * ts);
                assert!(
                    (g.derivative - d).abs().max_element() <= 1e-3 * d.abs().max_element().max(1.0),
                    "texel {t}: gradient {} vs {d}",
                    g.derivative
                );
                checked += 1;
            }
            // Some texels resolve to the fill, some to each level, in most rounds.
            let fills = got.iter().filter(|g| g.stored == 1234).count();
            eprintln!(
                "case {case} round {round}: {} texels, {fills} fill",
                got.len()
            );
        }
    }
    assert!(checked > 3 * 3 * 29_000);
    ctx.check().expect("no GPU validation errors");
}

/// Renders `surface` from `camera` with the scene's layout, sky and renderer.
fn render(
    scene: &mut Scene,
    surface: Surface<'_>,
    camera: &Camera,
    size: UVec2,
    sky: &SkyColors,
) -> Grid<[u8; 4]> {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let aspect = size.x as f32 / size.y as f32;
    let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
    let frame = scene
        .layout
        .place(
            Vec2::new(camera.position.x, camera.position.z),
            1.0,
            (0.0, scene::HEIGHT),
            Some(&frustum),
        )
        .unwrap();
    let style = TerrainStyle {
        ramp: (0.0, scene::HEIGHT),
        ..TerrainStyle::default()
    };
    scene
        .sky
        .prepare(queue, camera.view_proj_relative(aspect), sky)
        .unwrap();
    let surface = match surface {
        Surface::Coarse => ClipmapSurface::Coarse {
            map: &scene.gpu_map,
            normals: &scene.normals,
        },
        Surface::Atlas(atlas) => ClipmapSurface::Atlas { atlas },
    };
    let view = ClipmapView {
        surface,
        frame: &frame,
        camera,
        style: &style,
        target_size: size,
    };
    scene.renderer.prepare(device, queue, &view).unwrap();
    let target = OffscreenTarget::new(device, size).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
        scene.sky.draw(&mut pass);
        scene.renderer.draw(&mut pass);
    }
    queue.submit([encoder.finish()]);
    let image = target.read_rgba8(device, queue).unwrap();
    scene.ctx.check().expect("no GPU validation errors");
    image
}

/// Which surface [`render`] draws.
enum Surface<'a> {
    /// The scene's coarse-map and derivative normals.
    Coarse,
    /// An atlas.
    Atlas(&'a GpuTileAtlas),
}

/// The scene's map as a tiled world of 32-texel tiles (8x8, 4x4, 2x2, 1x1).
fn scene_world(scene: &Scene, wrap: WrapMode) -> (AtlasConfig, Pyramid) {
    let layout = TileLayout {
        world_size: scene.map.size(),
        tile_size: 32,
        levels: 4,
        texel_size: scene.map.texel_size(),
        encoding: scene.map.encoding(),
        wrap,
        fill: 0,
    };
    let pyramid = Pyramid::new(scene.map.grid().clone(), 4, 32);
    (
        AtlasConfig {
            slots: 85,
            world: layout,
        },
        pyramid,
    )
}

#[test]
fn a_partly_resident_world_draws_without_holes() {
    let Some(ctx) = context_or_skip("atlas_partly_resident_no_holes") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let (config, pyramid) = scene_world(&scene, WrapMode::Clamp);
    let (device, queue) = (scene.ctx.device.clone(), scene.ctx.queue.clone());
    let mut atlas = GpuTileAtlas::new(&device, &queue, &config).unwrap();
    // Level 0 as a checkerboard, level 1 every third tile, level 2 all but one, the root.
    let mut slot = 0;
    let mut put = |atlas: &mut GpuTileAtlas, level: u32, t: UVec2| {
        atlas
            .upload(slot, level, t, &pyramid.tile(level, t))
            .unwrap();
        atlas.map(level, t, Some(slot)).unwrap();
        slot += 1;
    };
    for y in 0..8 {
        for x in 0..8 {
            if (x + y) % 2 == 0 {
                put(&mut atlas, 0, UVec2::new(x, y));
            }
        }
    }
    for i in 0..16 {
        if i % 3 == 0 {
            put(&mut atlas, 1, UVec2::new(i % 4, i / 4));
        }
    }
    for i in 1..4 {
        put(&mut atlas, 2, UVec2::new(i % 2, i / 2));
    }
    put(&mut atlas, 3, UVec2::ZERO);
    let magenta = SkyColors {
        horizon: Vec3::new(1.0, 0.0, 1.0),
        zenith: Vec3::new(1.0, 0.0, 1.0),
    };
    let size = UVec2::new(200, 120);
    for (i, xz) in [Vec2::new(100.3, 120.6), Vec2::new(30.2, 200.7)]
        .iter()
        .enumerate()
    {
        for (j, yaw) in [0.0f32, 1.7, 3.3, 4.9].iter().enumerate() {
            let eye = Vec3::new(xz.x, scene.ground(*xz) + 2.0, xz.y);
            let camera = Camera::looking(eye, Vec3::new(yaw.cos(), 0.0, yaw.sin()));
            let image = render(&mut scene, Surface::Atlas(&atlas), &camera, size, &magenta);
            let (holes, terrain) = holes(&image);
            assert!(terrain > (size.x * size.y / 4) as usize, "view {i}/{j}");
            if holes > 0 {
                let path = std::env::temp_dir().join(format!("atlas_hole_{i}_{j}.png"));
                let _ = terrain_core::io::write_png_rgba8(&path, &image);
                panic!(
                    "view {i}/{j}: {holes} sky pixels inside the terrain ({})",
                    path.display()
                );
            }
        }
    }
    // Nothing resident at all: the fill's flat plane, still without holes.
    let empty = GpuTileAtlas::new(&device, &queue, &config).unwrap();
    let eye = Vec3::new(100.0, 3.0, 100.0);
    let camera = Camera::looking(eye, Vec3::new(1.0, 0.0, 0.2));
    let image = render(&mut scene, Surface::Atlas(&empty), &camera, size, &magenta);
    let (holes, terrain) = holes(&image);
    assert_eq!(holes, 0);
    assert!(terrain > (size.x * size.y / 4) as usize);
}

/// A fully resident atlas of the scene's map against the coarse-map surface: the same heights
/// (so the same silhouette), lit with central differences instead of the 4th-order derivative
/// map, so colours differ a little (measured on lavapipe: 1.74).
const FULL_ATLAS_MEAN_TOLERANCE: f64 = 3.0;

#[test]
fn a_fully_resident_world_draws_like_the_coarse_map() {
    let Some(ctx) = context_or_skip("atlas_full_matches_coarse") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let (config, pyramid) = scene_world(&scene, WrapMode::Repeat);
    let (device, queue) = (scene.ctx.device.clone(), scene.ctx.queue.clone());
    let mut atlas = GpuTileAtlas::new(&device, &queue, &config).unwrap();
    // Only level 0: every texel reads the map itself.
    for y in 0..8 {
        for x in 0..8 {
            let t = UVec2::new(x, y);
            let slot = y * 8 + x;
            atlas.upload(slot, 0, t, &pyramid.tile(0, t)).unwrap();
            atlas.map(0, t, Some(slot)).unwrap();
        }
    }
    let camera = scene::golden_camera(&scene);
    let size = scene::GOLDEN_SIZE;
    let sky = SkyColors::default();
    let coarse = render(&mut scene, Surface::Coarse, &camera, size, &sky);
    let from_atlas = render(&mut scene, Surface::Atlas(&atlas), &camera, size, &sky);
    let mut sum = 0.0;
    for (a, b) in coarse.as_slice().iter().zip(from_atlas.as_slice()) {
        let d = (0..3)
            .map(|c| (i32::from(a[c]) - i32::from(b[c])).unsigned_abs())
            .max()
            .unwrap_or(0);
        sum += f64::from(d);
    }
    let mean = sum / coarse.as_slice().len() as f64;
    eprintln!("atlas vs coarse: mean difference {mean:.2}");
    if mean > FULL_ATLAS_MEAN_TOLERANCE {
        let dir = std::env::temp_dir();
        let _ = terrain_core::io::write_png_rgba8(dir.join("atlas_full.png"), &from_atlas);
        let _ = terrain_core::io::write_png_rgba8(dir.join("atlas_coarse.png"), &coarse);
        panic!("atlas render differs from the coarse render: mean {mean:.2}");
    }
}

#[test]
fn bad_calls_are_errors_not_panics() {
    let Some(ctx) = context_or_skip("atlas_bad_calls") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let layout = TileLayout {
        world_size: UVec2::new(64, 64),
        tile_size: 16,
        levels: 3,
        texel_size: 1.0,
        encoding: HeightEncoding::new(0.01, 0.0).unwrap(),
        wrap: WrapMode::Clamp,
        fill: 0,
    };
    let config = AtlasConfig {
        slots: 4,
        world: layout,
    };
    let mut atlas = GpuTileAtlas::new(device, queue, &config).unwrap();
    let tile = Grid::new(16, 16, 5u16).unwrap();
    assert!(atlas.upload(4, 0, UVec2::ZERO, &tile).is_err());
    assert!(atlas.upload(0, 3, UVec2::ZERO, &tile).is_err());
    assert!(atlas.upload(0, 1, UVec2::new(2, 0), &tile).is_err());
    assert!(matches!(
        atlas.upload(0, 0, UVec2::ZERO, &Grid::new(8, 16, 0).unwrap()),
        Err(GpuError::SizeMismatch { .. })
    ));
    assert!(atlas.map(0, UVec2::ZERO, Some(4)).is_err());
    assert!(atlas.map(0, UVec2::ZERO, Some(INVALID_SLOT)).is_err());
    assert!(atlas.map(2, UVec2::new(1, 0), None).is_err());
    // 2 bytes per texel: 16-bit heights packed two per word.
    assert_eq!(atlas.upload(3, 2, UVec2::ZERO, &tile).unwrap(), 16 * 16 * 2);
    atlas.map(2, UVec2::ZERO, Some(3)).unwrap();
    assert_eq!((atlas.uploads(), atlas.uploaded_bytes()), (1, 512));
    // Sizes past the device's limits or the shaders' u32 indices.
    let huge = AtlasConfig {
        slots: 65_535,
        world: TileLayout {
            tile_size: 256,
            ..layout
        },
    };
    assert!(matches!(
        GpuTileAtlas::new(device, queue, &huge),
        Err(GpuError::MapTooLarge { .. })
    ));
    let too_many = AtlasConfig {
        slots: 65_537,
        ..huge
    };
    assert!(GpuTileAtlas::new(device, queue, &too_many).is_err());
    assert!(GpuTileAtlas::new(device, queue, &AtlasConfig { slots: 0, ..config }).is_err());
    let limits = huge.required_limits(wgpu::Limits::default()).unwrap();
    assert_eq!(limits.max_storage_buffer_binding_size, 65_535 * 65_536 * 2);
    // The probe refuses texels its i32 arithmetic cannot take, and too many.
    let mut probe = AtlasProbe::new(device, 8).unwrap();
    assert!(
        probe
            .read(device, queue, &atlas, &[IVec2::new(i32::MAX, 0)])
            .is_err()
    );
    assert!(
        probe
            .read(device, queue, &atlas, &[IVec2::new(0, i32::MIN)])
            .is_err()
    );
    assert!(
        probe
            .read(device, queue, &atlas, &[IVec2::new((1 << 29) + 1, 0)])
            .is_err()
    );
    assert!(
        probe
            .read(device, queue, &atlas, &[IVec2::ZERO; 9])
            .is_err()
    );
    let got = probe
        .read(device, queue, &atlas, &[IVec2::new(70, -3)])
        .unwrap();
    assert_eq!(got[0].stored, 5);
    ctx.check().expect("no GPU validation errors");
}

/// The tile `grid` of level `level` as the clamped map the CPU stamps it through.
fn tile_map(grid: &Grid<u16>, layout: &TileLayout, level: u32) -> terrain_core::CoarseMap {
    terrain_core::CoarseMap::new(
        grid.clone(),
        layout.encoding,
        layout.texel_size * (1u32 << level) as f32,
        WrapMode::Clamp,
    )
    .unwrap()
}

#[test]
fn stamps_on_atlas_tiles_match_the_cpu_stamp_on_each_tile_and_read_back_by_rect() {
    use terrain_core::{Blend, GaussianStamp, Rect, StampPlacement, TextureStamp, apply_stamp};
    use terrain_gpu::{GpuStamp, GpuTextureStamp, RegionReadback, StampOp, StampPass, TileSlot};
    let Some(ctx) = context_or_skip("atlas_tile_stamps") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let layout = TileLayout {
        world_size: UVec2::new(128, 96),
        tile_size: 32,
        levels: 3,
        texel_size: 0.5,
        encoding: HeightEncoding::new(0.01, -100.0).unwrap(),
        wrap: WrapMode::Clamp,
        fill: 7,
    };
    let config = AtlasConfig {
        slots: 5,
        world: layout,
    };
    let mut atlas = GpuTileAtlas::new(device, queue, &config).unwrap();
    // (slot, level, tile): two neighbours at level 0, one tile each of levels 1 and 2, and one
    // slot never stamped.
    let placed = [
        (3u32, 0u32, UVec2::new(1, 0)),
        (0, 0, UVec2::new(2, 0)),
        (4, 1, UVec2::new(1, 1)),
        (1, 2, UVec2::ZERO),
        (2, 0, UVec2::new(0, 2)),
    ];
    let mut tiles: Vec<Grid<u16>> = Vec::new();
    for (i, &(slot, level, t)) in placed.iter().enumerate() {
        // Mid-range noise so both the add and the clamped min blends change values.
        let g = noise_grid(UVec2::splat(32), 40 + i as u64).map(|&v| 20_000 + v / 4);
        atlas.upload(slot, level, t, &g).unwrap();
        atlas.map(level, t, Some(slot)).unwrap();
        tiles.push(g);
    }
    let mut pass = StampPass::new(device).unwrap();
    let crater = GaussianStamp::default();
    let image = Grid::from_fn(9, 5, |x, y| (x * 29 + y * 41) as u8).unwrap();
    let tex = TextureStamp::from_gray8(&image);
    let gpu_tex = GpuTextureStamp::new(device, &tex).unwrap();
    // A crater across the edge between the two level-0 tiles (world metres), applied to each
    // in its own frame; a rotated texture stamp with a min blend on the level-1 tile; a bump
    // on the level-2 tile that reaches past its corner.
    let crater_at =
        StampPlacement::new(Vec2::new(63.0 * 0.5, 10.0), Vec2::splat(9.0), -3.0).unwrap();
    let ops: Vec<(usize, StampPlacement, bool, Blend)> = vec![
        (0, crater_at, false, Blend::Add),
        (1, crater_at, false, Blend::Add),
        (
            2,
            StampPlacement::new(Vec2::new(40.0, 36.0), Vec2::new(20.0, 11.0), 2.5)
                .unwrap()
                .with_rotation(0.7)
                .unwrap(),
            true,
            Blend::Min { base_m: 30.0 },
        ),
        (
            3,
            StampPlacement::new(Vec2::new(-3.0, 60.0), Vec2::splat(40.0), 1.5).unwrap(),
            false,
            Blend::Add,
        ),
    ];
    let mut readback = RegionReadback::new(device, 10).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    let mut expected = tiles.clone();
    let mut tickets = Vec::new();
    let mut cpu_crater = GaussianStamp::default();
    let mut cpu_tex = tex.clone();
    for &(i, world_placement, texture, blend) in &ops {
        let (slot, level, t) = placed[i];
        let tile_m = 32.0 * layout.texel_size * (1u32 << level) as f32;
        let local = StampPlacement {
            center: world_placement.center - t.as_vec2() * tile_m,
            ..world_placement
        };
        let stamp = if texture {
            GpuStamp::Texture(&gpu_tex)
        } else {
            GpuStamp::Gaussian(&crater)
        };
        let op = StampOp {
            stamp,
            placement: local,
            blend,
        };
        let rects = pass
            .encode_tile(
                device,
                queue,
                &mut encoder,
                &atlas,
                TileSlot { slot, level },
                &op,
            )
            .unwrap();
        let mut map = tile_map(&expected[i], &layout, level);
        let cpu_rects = if texture {
            apply_stamp(&mut map, &mut cpu_tex, &local, blend).unwrap()
        } else {
            apply_stamp(&mut map, &mut cpu_crater, &local, blend).unwrap()
        };
        assert_eq!(rects, cpu_rects, "tile {i}: the rects each side reports");
        assert_eq!(rects.len(), 1, "tile {i}: a stamp that touches the tile");
        expected[i] = map.into_grid();
        for r in rects {
            let ticket = readback
                .request_tile(device, &mut encoder, &atlas, TileSlot { slot, level }, r)
                .unwrap();
            tickets.push((ticket, i, r));
        }
    }
    // Whole tiles afterwards, the untouched slot included.
    let mut whole = Vec::new();
    for (i, &(slot, level, _)) in placed.iter().enumerate() {
        let full = Rect::from_size(UVec2::splat(32));
        whole.push((
            readback
                .request_tile(device, &mut encoder, &atlas, TileSlot { slot, level }, full)
                .unwrap(),
            i,
        ));
    }
    queue.submit([encoder.finish()]);
    pass.recall();
    let arrived = readback.wait(device).unwrap();
    assert_eq!(arrived.len(), tickets.len() + whole.len());
    for (ticket, i, r) in &tickets {
        let got = arrived.iter().find(|a| a.ticket == *ticket).unwrap();
        // The changed rect as it was after that tile's own stamps (each tile is stamped once).
        let want = expected[*i].copy_rect(*r).unwrap();
        assert_eq!(got.rect, *r);
        assert_eq!(got.to_u16(), want, "tile {i}: the rect read back");
    }
    for (ticket, i) in &whole {
        let got = arrived.iter().find(|a| a.ticket == *ticket).unwrap();
        assert_eq!(got.to_u16(), expected[*i], "tile {i}: GPU and CPU stamps");
        if *i == 4 {
            assert_eq!(got.to_u16(), tiles[4], "a slot never stamped is unchanged");
        } else {
            assert_ne!(got.to_u16(), tiles[*i], "tile {i} was stamped");
        }
    }
    // Off the tile, past the slots or the levels: errors, not panics.
    let mut encoder = device.create_command_encoder(&Default::default());
    let op = StampOp {
        stamp: GpuStamp::Gaussian(&crater),
        placement: crater_at,
        blend: Blend::Add,
    };
    assert!(
        pass.encode_tile(
            device,
            queue,
            &mut encoder,
            &atlas,
            TileSlot { slot: 5, level: 0 },
            &op
        )
        .is_err()
    );
    assert!(
        pass.encode_tile(
            device,
            queue,
            &mut encoder,
            &atlas,
            TileSlot { slot: 0, level: 3 },
            &op
        )
        .is_err()
    );
    let off = StampOp {
        placement: StampPlacement::new(Vec2::splat(-500.0), Vec2::splat(4.0), 1.0).unwrap(),
        ..op
    };
    assert!(
        pass.encode_tile(
            device,
            queue,
            &mut encoder,
            &atlas,
            TileSlot { slot: 0, level: 0 },
            &off
        )
        .unwrap()
        .is_empty()
    );
    let outside = Rect::new(IVec2::new(20, 20), UVec2::splat(13));
    assert!(matches!(
        readback.request_tile(
            device,
            &mut encoder,
            &atlas,
            TileSlot { slot: 0, level: 0 },
            outside
        ),
        Err(GpuError::BadRegion { .. })
    ));
    assert!(
        readback
            .request_tile(
                device,
                &mut encoder,
                &atlas,
                TileSlot { slot: 9, level: 0 },
                Rect::from_size(UVec2::ONE)
            )
            .is_err()
    );
    queue.submit([encoder.finish()]);
    pass.recall();
    ctx.check().expect("no GPU validation errors");
}

/// `AtlasStamper`, the GPU half of the tile stamping protocol: Gaussian, texture (rewritten in
/// place between stamps) and uploaded stamps on atlas tiles come back, rect by rect, equal to
/// the CPU stamp of each tile; a full ring refuses a stamp with nothing recorded.
#[test]
fn the_atlas_stamper_reads_back_what_the_cpu_stamps() {
    use terrain_core::{Blend, GaussianStamp, Stamp, StampPlacement, TextureStamp, apply_stamp};
    use terrain_gpu::{AtlasStamp, AtlasStampOp, AtlasStamper, GpuTextureStamp, TileSlot};
    let Some(ctx) = context_or_skip("the_atlas_stamper_reads_back_what_the_cpu_stamps") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let layout = TileLayout {
        world_size: UVec2::new(96, 32),
        tile_size: 32,
        levels: 1,
        texel_size: 0.5,
        encoding: HeightEncoding::new(0.01, -100.0).unwrap(),
        wrap: WrapMode::Clamp,
        fill: 7,
    };
    let config = AtlasConfig {
        slots: 3,
        world: layout,
    };
    let mut atlas = GpuTileAtlas::new(device, queue, &config).unwrap();
    let mut tiles = Vec::new();
    for i in 0..3u32 {
        let g = noise_grid(UVec2::splat(32), 70 + u64::from(i)).map(|&v| 20_000 + v / 4);
        atlas.upload(i, 0, UVec2::new(i, 0), &g).unwrap();
        atlas.map(0, UVec2::new(i, 0), Some(i)).unwrap();
        tiles.push(tile_map(&g, &layout, 0));
    }
    let texture = |seed: u32| {
        let image = Grid::from_fn(7, 5, |x, y| (x * 31 + y * 17 + seed) as u8).unwrap();
        TextureStamp::from_gray8(&image)
    };
    let (mut tex_a, mut tex_b, mut tex_up) = (texture(0), texture(90), texture(200));
    let uploaded = GpuTextureStamp::new(device, &tex_up).unwrap();
    let mut crater = GaussianStamp::default();
    let mut stamper = AtlasStamper::new(device, 2).unwrap();
    let at = |x, y| StampPlacement::new(Vec2::new(x, y), Vec2::splat(6.0), -2.0).unwrap();
    // Each stamp on the GPU and on the tile's CPU copy: its tickets and the rects as the copy
    // has them right after it.
    let mut want = Vec::new();
    let mut stamp = |stamper: &mut AtlasStamper,
                     slot: u32,
                     p: StampPlacement,
                     gpu: AtlasStamp<'_>,
                     cpu: &mut dyn Stamp| {
        let tile = TileSlot { slot, level: 0 };
        let op = AtlasStampOp {
            tile,
            placement: p,
            stamp: gpu,
        };
        let tickets = stamper.stamp(device, queue, &atlas, op).unwrap()?;
        let map = &mut tiles[slot as usize];
        let rects = apply_stamp(map, cpu, &p, Blend::Add).unwrap();
        assert_eq!(tickets.iter().map(|t| t.1).collect::<Vec<_>>(), rects);
        for (ticket, r) in tickets {
            want.push((ticket, r, map.grid().copy_rect(r).unwrap()));
        }
        Some(())
    };
    let gauss = AtlasStamp::Gaussian(&GaussianStamp::default());
    stamp(&mut stamper, 0, at(5.0, 5.0), gauss, &mut crater).unwrap();
    stamp(
        &mut stamper,
        1,
        at(8.0, 3.0),
        AtlasStamp::Texture(&tex_a.clone()),
        &mut tex_a,
    )
    .unwrap();
    assert_eq!(stamper.in_flight(), 2);
    assert!(stamp(&mut stamper, 2, at(4.0, 4.0), gauss, &mut crater).is_none());
    let mut arrived = stamper.wait(device).unwrap();
    assert_eq!(stamper.in_flight(), 0);
    let tex = AtlasStamp::Texture(&tex_b.clone());
    stamp(&mut stamper, 2, at(10.0, 12.0), tex, &mut tex_b).unwrap();
    let up = AtlasStamp::Uploaded(&uploaded);
    stamp(&mut stamper, 0, at(9.0, 9.0), up, &mut tex_up).unwrap();
    arrived.extend(stamper.wait(device).unwrap());
    assert_eq!(arrived.len(), want.len());
    assert_eq!(want.len(), 4);
    // A slot past the atlas's is an error, nothing left in flight.
    let op = AtlasStampOp {
        tile: TileSlot { slot: 99, level: 0 },
        placement: at(5.0, 5.0),
        stamp: gauss,
    };
    assert!(stamper.stamp(device, queue, &atlas, op).is_err());
    assert_eq!(stamper.in_flight(), 0);
    for (a, (ticket, rect, heights)) in arrived.iter().zip(&want) {
        assert_eq!((a.ticket, a.rect), (*ticket, *rect));
        assert_eq!(a.heights, *heights, "ticket {ticket}: GPU and CPU stamps");
    }
    ctx.check().expect("no GPU validation errors");
}
