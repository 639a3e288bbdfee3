//! A streamed world's paint and colour on the GPU (`GpuOverlayAtlas`): the lookup every renderer
//! draws them with equals its CPU reference (`terrain_core::OverlayAtlas::sample`) on clamped
//! and repeating worlds, with tiles resident at several levels; the renderers draw a streamed
//! paint disc in every LOD mode, from whichever level is resident; bad input is refused.

#[path = "common/shading.rs"]
mod shading;

use glam::{IVec2, UVec2, Vec2, Vec3, Vec4};
use shading::*;
use terrain_core::{
    Grid, HeightEncoding, OverlayAtlas, OverlayUploadTarget, StampPlacement, TileLayout, WrapMode,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{GpuContext, GpuMaterials, GpuOverlayAtlas, SurfaceShading};
use wgpu::util::DeviceExt;

/// Runs the lookup at `points` (relative to `camera`'s texel) over `atlas`.
fn probe(
    ctx: &GpuContext,
    atlas: &GpuOverlayAtlas,
    camera: IVec2,
    points: &[Vec2],
    premultiply: bool,
) -> Vec<Vec4> {
    let device = &ctx.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("overlay probe"),
        source: wgpu::ShaderSource::Wgsl(terrain_shaders::OVERLAY_PROBE.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("overlay probe"),
        layout: None,
        module: &module,
        entry_point: Some("probe_main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let layout = atlas.layout();
    let size = layout.world_size.as_ivec2();
    let repeat = layout.wrap == WrapMode::Repeat;
    let frame: [u32; 12] = [
        camera.x as u32,
        camera.y as u32,
        layout.world_size.x,
        layout.world_size.y,
        // A multiple of the size that makes every texel the probe reads positive.
        (size.x * 64) as u32,
        (size.y * 64) as u32,
        if repeat {
            terrain_shaders::codes::WRAP_REPEAT
        } else {
            terrain_shaders::codes::WRAP_CLAMP
        },
        points.len() as u32,
        u32::from(premultiply),
        0,
        0,
        0,
    ];
    let init = |contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents,
            usage,
        })
    };
    let uniform = init(bytemuck::cast_slice(&frame), wgpu::BufferUsages::UNIFORM);
    let input = init(bytemuck::cast_slice(points), wgpu::BufferUsages::STORAGE);
    let out_bytes = (points.len() * 16) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: out_bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: output.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 16,
                resource: wgpu::BindingResource::TextureView(atlas.slots_view()),
            },
            wgpu::BindGroupEntry {
                binding: 17,
                resource: wgpu::BindingResource::TextureView(atlas.table_view()),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups((points.len() as u32).div_ceil(64), 1, 1);
    }
    ctx.queue.submit([encoder.finish()]);
    let bytes = terrain_gpu::download_bytes(device, &ctx.queue, &output, 0, out_bytes)
        .expect("probe output downloads");
    bytemuck::cast_slice::<u8, [f32; 4]>(&bytes)
        .iter()
        .map(|&v| Vec4::from(v))
        .collect()
}

/// A small xorshift for test data.
fn next(state: &mut u64) -> u64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    *state
}

#[test]
fn the_streamed_lookup_equals_its_cpu_reference() {
    let Some(ctx) = context_or_skip("overlay lookup") else {
        return;
    };
    for wrap in [WrapMode::Clamp, WrapMode::Repeat] {
        // 100 x 72 texels in tiles of 16: partial tiles at the far edges, 4 levels.
        let layout = TileLayout {
            world_size: UVec2::new(100, 72),
            tile_size: 16,
            levels: 4,
            texel_size: 1.0,
            encoding: HeightEncoding::spanning::<u16>(0.0, 1.0).expect("encoding"),
            wrap,
            fill: 0,
        };
        // 7 slots: one a layer of the array.
        let mut cpu = OverlayAtlas::new(layout, 7).expect("cpu atlas");
        let mut gpu = GpuOverlayAtlas::new(&ctx.device, &ctx.queue, layout, 7).expect("gpu atlas");
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        // Level 3 whole, two tiles of level 1, three of level 0 (one in the partial corner).
        let tiles = [
            (3, UVec2::new(0, 0)),
            (1, UVec2::new(0, 0)),
            (1, UVec2::new(3, 1)),
            (0, UVec2::new(1, 1)),
            (0, UVec2::new(6, 4)),
            (0, UVec2::new(2, 0)),
        ];
        for (slot, &(level, tile)) in tiles.iter().enumerate() {
            let texels = Grid::from_fn(16, 16, |_, _| {
                let v = next(&mut rng).to_le_bytes();
                [v[0], v[1], v[2], v[3]]
            })
            .expect("tile");
            // Slots out of order, so the slot's place in the array matters.
            let slot = (slot as u32 * 3) % 7;
            for t in [&mut cpu as &mut dyn OverlayUploadTargetDyn, &mut gpu] {
                t.put(slot, level, tile, &texels);
            }
        }
        let camera = IVec2::new(37, -5);
        let points: Vec<Vec2> = (0..2000)
            .map(|_| {
                let u = |r: &mut u64| (next(r) % 100_000) as f32 / 100_000.0;
                // Around the world and a little beyond its edges.
                let p = Vec2::new(u(&mut rng) * 130.0 - 15.0, u(&mut rng) * 100.0 - 14.0);
                p - camera.as_vec2()
            })
            .collect();
        // Then tiles unmapped and a slot given to another tile: the table follows.
        for (round, premultiply) in [(0, false), (0, true), (1, false)] {
            if round == 1 {
                for t in [&mut cpu as &mut dyn OverlayUploadTargetDyn, &mut gpu] {
                    t.unmap(1, UVec2::new(0, 0));
                    t.unmap(0, UVec2::new(6, 4));
                    t.unmap(3, UVec2::new(0, 0));
                    t.unmap(0, UVec2::new(1, 1));
                }
                let texels = Grid::new(16, 16, [9, 200, 30, 255]).expect("tile");
                for t in [&mut cpu as &mut dyn OverlayUploadTargetDyn, &mut gpu] {
                    t.put(3, 2, UVec2::new(1, 0), &texels);
                }
            }
            let got = probe(&ctx, &gpu, camera, &points, premultiply);
            let mut differ = 0;
            for (q, g) in points.iter().zip(&got) {
                let p = (q.as_dvec2() + camera.as_dvec2()).as_vec2();
                let want = cpu.sample(p.as_dvec2(), premultiply);
                // f32 blend weights of positions below 200 texels: off by far less than 1e-4.
                if (want - *g).abs().max_element() > 1e-4 {
                    differ += 1;
                    eprintln!("{wrap:?} {p}: gpu {g}, cpu {want}");
                }
            }
            assert_eq!(
                differ, 0,
                "{wrap:?} round {round} premultiply {premultiply}"
            );
            // Round 1 leaves texels with nothing resident (transparent), others under the
            // new level-2 tile.
            if round == 1 {
                assert!(got.contains(&Vec4::ZERO));
                assert!(got.iter().any(|v| (v.y - 200.0 / 255.0).abs() < 1e-6));
            }
        }
    }
}

/// Uploads and maps, or unmaps, one tile in either atlas.
trait OverlayUploadTargetDyn {
    fn put(&mut self, slot: u32, level: u32, tile: UVec2, texels: &Grid<[u8; 4]>);
    fn unmap(&mut self, level: u32, tile: UVec2);
}

impl<T: OverlayUploadTarget> OverlayUploadTargetDyn for T {
    fn put(&mut self, slot: u32, level: u32, tile: UVec2, texels: &Grid<[u8; 4]>) {
        self.upload(slot, level, tile, texels).expect("upload");
        self.map(level, tile, Some(slot)).expect("map");
    }
    fn unmap(&mut self, level: u32, tile: UVec2) {
        self.map(level, tile, None).expect("unmap");
    }
}

#[test]
fn streamed_paint_shows_from_the_level_that_is_resident_in_every_lod_mode() {
    let Some(ctx) = context_or_skip("streamed paint render") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let solid = GpuMaterials::new(device, queue, &solid_materials()).expect("upload");
    // An 80 m disc of rock at (60, 128), as a streamed world's material tiles hold it: level 0
    // and the coarser levels the cache's pyramid reduces it to (wide enough that level 2's
    // blend over 8 m at its middle is still rock within the colour tolerance).
    let mut paint = Grid::new(MAP, MAP, [0u8; 4]).expect("grid");
    let disc =
        StampPlacement::new(Vec2::new(60.0, 128.0), Vec2::splat(80.0), -1.0).expect("placement");
    let rock_effect = terrain_core::MaterialEffect::new(2, 1.0).expect("effect");
    terrain_core::apply_material_effect(&mut paint, WrapMode::Clamp, 1.0, &disc, &rock_effect)
        .expect("paint");
    let layout = TileLayout {
        world_size: UVec2::splat(MAP),
        tile_size: 64,
        levels: 3,
        texel_size: 1.0,
        encoding: HeightEncoding::spanning::<u16>(0.0, 1.0).expect("encoding"),
        wrap: WrapMode::Clamp,
        fill: 0,
    };
    let level = |l: u32| {
        // The 2x2 mean, l times (the disc's middle stays full rock).
        let mut g = paint.clone();
        for _ in 0..l {
            let s = g.width() / 2;
            g = Grid::from_fn(s, s, |x, y| {
                let t = [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(i, j)| g.get(2 * x + i, 2 * y + j));
                let mut out = [0u8; 4];
                for (c, o) in out.iter_mut().enumerate() {
                    let sum: u32 = t.iter().map(|v| u32::from(v.unwrap_or([0; 4])[c])).sum();
                    *o = ((sum + 2) / 4) as u8;
                }
                out
            })
            .expect("level");
        }
        g
    };
    let l = Vec3::new(-0.8, 0.6, 0.0).normalize();
    let (grass, rock) = (lit(0, l.y), lit(2, l.y));
    let mut atlas = GpuOverlayAtlas::new(device, queue, layout, 8).expect("atlas");
    // The disc's middle (60, 128) lies in level 0's tile (0, 2) (texels 0..64 x 128..192), and
    // in level 2's only tile.
    let (fine, coarse) = ((0u32, UVec2::new(0, 2)), (2u32, UVec2::ZERO));
    for (slot, (lv, tile)) in [fine, coarse].into_iter().enumerate() {
        let g = level(lv)
            .copy_rect(terrain_core::Rect::new(
                (tile * 64).as_ivec2(),
                UVec2::splat(64),
            ))
            .expect("tile");
        atlas.upload(slot as u32, lv, tile, &g).expect("upload");
    }
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_materials(&solid);
        renderer.set_streamed_layers(Some(&atlas), None);
        for (mapped, want) in [
            (vec![fine, coarse], rock),
            (vec![coarse], rock),
            (vec![], grass),
        ] {
            for (lv, tile) in [fine, coarse] {
                let slot = mapped.iter().position(|m| *m == (lv, tile));
                let slot = slot.map(|_| if lv == 0 { 0 } else { 1 });
                atlas.map(lv, tile, slot).expect("map");
            }
            let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
            let centre = around(&image, 60.0, 130.0, 1.0);
            assert!(
                (centre - want).abs().max_element() <= COLOUR_TOLERANCE + 2.0,
                "{mode}: resident {mapped:?}: {centre}, not {want}"
            );
        }
    }
    // A streamed layer of another world size fails the prepare; bad atlases are refused.
    let mut renderer = renderers(&ctx, &map).remove(0);
    let other = TileLayout {
        world_size: UVec2::splat(128),
        ..layout
    };
    let small = GpuOverlayAtlas::new(device, queue, other, 2).expect("atlas");
    renderer.set_streamed_layers(None, Some(&small));
    let err = try_prepare(&ctx, &mut renderer, &gpu).unwrap_err();
    assert!(
        matches!(
            err,
            terrain_gpu::GpuError::Core(terrain_core::CoreError::SizeMismatch { .. })
        ),
        "{err}"
    );
    assert!(GpuOverlayAtlas::new(device, queue, layout, 0).is_err());
    let huge = TileLayout {
        tile_size: 1 << 15,
        ..layout
    };
    assert!(GpuOverlayAtlas::new(device, queue, huge, 1).is_err());
    let tile = Grid::new(64, 64, [0u8; 4]).expect("tile");
    assert!(atlas.upload(8, 0, UVec2::ZERO, &tile).is_err());
    assert!(atlas.upload(0, 3, UVec2::ZERO, &tile).is_err());
    assert!(atlas.map(0, UVec2::new(4, 0), Some(0)).is_err());
    assert!(atlas.map(0, UVec2::ZERO, Some(8)).is_err());
    let wrong = Grid::new(16, 16, [0u8; 4]).expect("tile");
    assert!(atlas.upload(0, 0, UVec2::ZERO, &wrong).is_err());
}
