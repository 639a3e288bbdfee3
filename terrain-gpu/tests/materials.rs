//! Material shading: the autoshader's weights and curvature on the GPU equal
//! terrain_core::material's, and every LOD mode draws a frame's flat lowland as grass, its
//! cliff as rock and its flat highland as snow, in the colours of the material images it was
//! given; the procedural images show texture where the ramp is flat; material effects painted on
//! the GPU equal terrain_core's and show in every LOD mode.

use glam::{UVec2, Vec2, Vec3, Vec4};
use terrain_core::{
    AutoshadeParams, CoarseMap, Grid, HeightEncoding, MaterialEffect, MaterialTextures,
    StampPlacement, WrapMode, autoshade_weights, curvature_from_gradients, curvature_from_heights,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    ClipmapSurface, EffectOp, GpuContext, GpuError, GpuHeightMap, GpuMaterialLayer, GpuMaterials,
    MaterialEffectPass, NormalPass, SurfaceShading, TerrainStyle, TerrainView,
};
use wgpu::util::DeviceExt;

/// Probe input as materials_probe.wgsl reads it.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ProbePoint {
    a: [f32; 4],
    b: [f32; 4],
    c: [f32; 4],
    d: [f32; 4],
    e: [f32; 4],
}

/// Runs the probe over `points` with `params`; per point the weights and the curvature.
fn probe(ctx: &GpuContext, params: &AutoshadeParams, points: &[ProbePoint]) -> Vec<[Vec4; 2]> {
    let device = &ctx.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("material probe"),
        source: wgpu::ShaderSource::Wgsl(terrain_shaders::MATERIAL_PROBE.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("material probe"),
        layout: None,
        module: &module,
        entry_point: Some("probe_main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let uniform = [
        params.rock_slope.0,
        params.rock_slope.1,
        params.snow_height.0,
        params.snow_height.1,
        params.dirt_curvature.0,
        params.dirt_curvature.1,
        f32::from_bits(points.len() as u32),
        0.0,
    ];
    let init = |contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents,
            usage,
        })
    };
    let uniform = init(bytemuck::cast_slice(&uniform), wgpu::BufferUsages::UNIFORM);
    let input = init(bytemuck::cast_slice(points), wgpu::BufferUsages::STORAGE);
    let out_bytes = (points.len() * 32) as u64;
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
    let values: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    values
        .chunks_exact(2)
        .map(|c| [Vec4::from(c[0]), Vec4::from(c[1])])
        .collect()
}

/// Each weight is a product of at most three smoothsteps of a few f32 operations: conforming
/// devices may fuse multiply-adds and divide within 2.5 ULP, a few ULP of 1.0 in all; the
/// curvature is a sum of five heights divided by the spacing squared, within a few ULP of its
/// terms' size.
const WEIGHT_TOLERANCE: f32 = 1e-5;

#[test]
fn autoshade_weights_and_curvature_on_the_gpu_equal_the_cpu_reference() {
    let Some(ctx) = context_or_skip("material probe") else {
        return;
    };
    let params = AutoshadeParams::default();
    // Every region of every smoothstep: below, across and above each pair of edges.
    let mut points = Vec::new();
    let mut seed = 0x1234_5678_u32;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        (seed >> 8) as f32 / (1u32 << 24) as f32
    };
    for i in 0..2000 {
        let t = next() * 1.2 - 0.1;
        let slope = next() * 1.6;
        let curvature = (next() - 0.5) * 2.4;
        let spacing = [0.1, 0.5, 1.0, 30.0][i % 4];
        // Heights of a 0..50 m terrain.
        let h = |r: f32| r * 50.0;
        let g = |r: f32| (r - 0.5) * 3.0;
        points.push(ProbePoint {
            a: [t, slope, curvature, spacing],
            b: [h(next()), h(next()), h(next()), h(next())],
            c: [h(next()), spacing, 0.0, 0.0],
            d: [g(next()), g(next()), g(next()), g(next())],
            e: [g(next()), g(next()), g(next()), g(next())],
        });
    }
    let gpu = probe(&ctx, &params, &points);
    let mut worst = (0.0f32, 0.0f32);
    for (p, [w, c]) in points.iter().zip(&gpu) {
        let expected = autoshade_weights(&params, p.a[0], p.a[1], p.a[2]);
        let curvature = curvature_from_heights(p.c[0], p.b, p.a[3]);
        let from_gradients = curvature_from_gradients(
            Vec2::new(p.d[0], p.d[1]),
            Vec2::new(p.d[2], p.d[3]),
            Vec2::new(p.e[0], p.e[1]),
            Vec2::new(p.e[2], p.e[3]),
            p.c[1],
        );
        worst.0 = worst.0.max((*w - expected).abs().max_element());
        // Relative to the terms' size: heights of up to 50 m over the spacing squared, and
        // gradients of up to 1.5 over twice the texel size.
        let heights = 200.0 / (p.a[3] * p.a[3]);
        let gradients = 6.0 / (2.0 * p.c[1]);
        worst.1 = worst.1.max((c.x - curvature).abs() / heights);
        worst.1 = worst.1.max((c.y - from_gradients).abs() / gradients);
    }
    eprintln!(
        "largest differences: weights {:e}, curvature {:e}",
        worst.0, worst.1
    );
    assert!(
        worst.0 <= WEIGHT_TOLERANCE,
        "weights differ by {:e}",
        worst.0
    );
    assert!(
        worst.1 <= WEIGHT_TOLERANCE,
        "curvature differs by {:e}",
        worst.1
    );
    ctx.check().expect("no GPU validation errors");
}

#[path = "common/shading.rs"]
mod shading;
use shading::*;

#[test]
fn every_lod_mode_shades_lowland_grass_cliff_rock_and_highland_snow() {
    let Some(ctx) = context_or_skip("material shading") else {
        return;
    };
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let solid = GpuMaterials::new(&ctx.device, &ctx.queue, &solid_materials()).expect("upload");
    let l = Vec3::new(-0.8, 0.6, 0.0).normalize();
    // The cliff's normal: rising eastwards.
    let cliff_n = Vec3::new(-(HIGH - LOW) / 16.0, 1.0, 0.0).normalize();
    let expected = [
        ((20, 100), lit(0, l.y)),
        ((124, 132), lit(2, cliff_n.dot(l))),
        ((156, 236), lit(3, l.y)),
    ];
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_materials(&solid);
        let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
        let ramp = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Ramp);
        for (columns, want) in expected {
            let (mean, _) = region(&image, columns);
            let (ramp_mean, _) = region(&ramp, columns);
            eprintln!("{mode} {columns:?}: {mean} (want {want}; ramp {ramp_mean})");
            assert!(
                (mean - want).abs().max_element() <= COLOUR_TOLERANCE,
                "{mode}: columns {columns:?} are {mean}, not the material's {want}"
            );
            // The ramp draws something else: the test sees the materials, not the ramp.
            assert!(
                (ramp_mean - want).abs().max_element() > 20.0,
                "{mode}: {columns:?}"
            );
        }
    }
}

#[test]
fn the_procedural_materials_show_texture_where_the_ramp_is_flat() {
    let Some(ctx) = context_or_skip("procedural materials") else {
        return;
    };
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let mut renderer = renderers(&ctx, &map).swap_remove(0);
    let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
    let ramp = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Ramp);
    let procedural = MaterialTextures::procedural(terrain_gpu::PROCEDURAL_MATERIAL_SIZE)
        .expect("procedural images");
    for (columns, material) in [((20, 100), 0), ((156, 236), 3)] {
        let (mean, spread) = region(&image, columns);
        let (_, ramp_spread) = region(&ramp, columns);
        eprintln!("{columns:?}: mean {mean}, spread {spread} (ramp {ramp_spread})");
        assert!(ramp_spread < 0.5, "the ramp is flat on flat ground");
        // At 0.8 m a pixel the 8 m images are seen through their small mips: little but
        // clear texture.
        assert!(
            spread > 0.5 && spread > 4.0 * ramp_spread,
            "{columns:?}: no texture (spread {spread}, ramp {ramp_spread})"
        );
        // From afar the material's mean colour shows, lit (its normals tilt the light a
        // little, hence the wide margin).
        let albedo = procedural.mean_albedo(material).expect("layer");
        let want = albedo * 255.0 * (0.28 + 0.8 * 0.6);
        assert!(
            (mean - want).abs().max_element() <= 16.0,
            "{columns:?}: {mean} against the material's {want}"
        );
    }
}

#[test]
fn a_crater_changes_what_the_ground_shows() {
    let Some(ctx) = context_or_skip("material after a crater") else {
        return;
    };
    let mut map = cliff_map();
    let solid = GpuMaterials::new(&ctx.device, &ctx.queue, &solid_materials()).expect("upload");
    let mut renderer = renderers(&ctx, &map).swap_remove(0);
    renderer.set_materials(&solid);
    // Pixels within 4 m of the crater's centre (map (60, 128); 0.8 m a pixel, rows from
    // z = 56 down) that are not grass (red).
    let not_grass = |image: &Grid<[u8; 4]>| {
        let (cx, cy) = (60.0 / 0.8, (128.0 - 56.0) / 0.8);
        let (mut n, mut other) = (0, 0);
        for y in 0..SIZE.y {
            for x in 0..SIZE.x {
                if (x as f32 - cx).hypot(y as f32 - cy) <= 4.0 / 0.8 {
                    let p = image.get(x, y).expect("inside");
                    n += 1;
                    other += usize::from(p[1] > p[0] || p[2] > p[0]);
                }
            }
        }
        other as f64 / n as f64
    };
    let before = draw(
        &ctx,
        &mut renderer,
        &upload(&ctx, &map),
        SurfaceShading::Materials,
    );
    let placement =
        terrain_core::StampPlacement::new(Vec2::new(60.0, 128.0), Vec2::splat(16.0), -5.0)
            .expect("placement");
    terrain_core::apply_stamp(
        &mut map,
        &mut terrain_core::GaussianStamp::default(),
        &placement,
        terrain_core::Blend::Add,
    )
    .expect("crater");
    let after = draw(
        &ctx,
        &mut renderer,
        &upload(&ctx, &map),
        SurfaceShading::Materials,
    );
    let (b, a) = (not_grass(&before), not_grass(&after));
    eprintln!("not grass in the crater: before {b:.2}, after {a:.2}");
    assert_eq!(b, 0.0, "flat lowland is grass");
    // The crater's walls bend and slope enough for dirt and rock.
    assert!(a > 0.3, "the crater shows {a:.2} dirt or rock");
}

#[test]
fn an_engine_shades_every_lod_mode_with_its_own_surface_function() {
    let Some(ctx) = context_or_skip("user surface function") else {
        return;
    };
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let solid = GpuMaterials::new(&ctx.device, &ctx.queue, &solid_materials()).expect("upload");
    // Dirt west of x = 64 m, snow east of it, whatever the ground: a painted road's shape.
    let painted = "fn surface_weights(p: SurfacePoint) -> vec4<f32> {\n\
                   return select(vec4<f32>(0.0, 0.0, 0.0, 1.0), vec4<f32>(0.0, 1.0, 0.0, 0.0), \
                   p.position.x < 64.0);\n}";
    let l = Vec3::new(-0.8, 0.6, 0.0).normalize();
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_materials(&solid);
        // A function that does not compile is refused and changes nothing.
        let err = renderer.set_surface_shader(&ctx.device, Some("fn surface_weights("));
        assert!(
            matches!(err, Err(GpuError::UserShader { .. })),
            "{mode}: {err:?}"
        );
        renderer
            .set_surface_shader(&ctx.device, Some(painted))
            .expect("the painted function compiles");
        let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
        for (columns, material) in [((10, 56), 1), ((72, 110), 3), ((156, 236), 3)] {
            let (mean, _) = region(&image, columns);
            let want = lit(material, l.y);
            assert!(
                (mean - want).abs().max_element() <= COLOUR_TOLERANCE,
                "{mode}: {columns:?} are {mean}, not {want}"
            );
        }
        // Back to the autoshader: the lowland is grass again.
        renderer
            .set_surface_shader(&ctx.device, None)
            .expect("built-in");
        let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
        let (mean, _) = region(&image, (10, 56));
        assert!(
            (mean - lit(0, l.y)).abs().max_element() <= COLOUR_TOLERANCE,
            "{mode}: {mean}"
        );
    }
}

#[test]
fn a_colour_layer_gives_the_albedo_in_every_lod_mode() {
    let Some(ctx) = context_or_skip("colour layer") else {
        return;
    };
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    // An "orthophoto": orange west of x = 64, teal east of it.
    let (west, east) = ([230u8, 120, 30, 255], [30u8, 160, 170, 255]);
    let colors = Grid::from_fn(MAP, MAP, |x, _| if x < 64 { west } else { east }).expect("grid");
    let layer = terrain_gpu::GpuColorLayer::new(&ctx.device, &ctx.queue, &colors).expect("upload");
    let wrong = Grid::new(MAP / 2, MAP, west).expect("grid");
    let wrong = terrain_gpu::GpuColorLayer::new(&ctx.device, &ctx.queue, &wrong).expect("upload");
    let l = Vec3::new(-0.8, 0.6, 0.0).normalize();
    let lit = |c: [u8; 4]| Vec3::new(c[0].into(), c[1].into(), c[2].into()) * (0.28 + 0.8 * l.y);
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_color_layer(Some(&layer));
        let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Ramp);
        for (columns, want) in [((10, 56), lit(west)), ((72, 110), lit(east))] {
            let (mean, _) = region(&image, columns);
            assert!(
                (mean - want).abs().max_element() <= COLOUR_TOLERANCE,
                "{mode}: {columns:?} are {mean}, not the layer's {want}"
            );
        }
        // A layer of another size than the map is refused, not drawn misplaced.
        renderer.set_color_layer(Some(&wrong));
        let (device, queue) = (&ctx.device, &ctx.queue);
        let style = TerrainStyle::default();
        let view = terrain_gpu::Camera::looking(Vec3::new(128.0, 60.0, 128.0), Vec3::X);
        let terrain_view = TerrainView {
            surface: ClipmapSurface::Coarse {
                map: &gpu.0,
                normals: &gpu.1,
            },
            camera: &view,
            style: &style,
            target_size: SIZE,
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        let err = renderer.prepare(device, queue, &mut encoder, &terrain_view);
        assert!(
            matches!(
                err,
                Err(GpuError::Core(terrain_core::CoreError::SizeMismatch { .. }))
            ),
            "{mode}: {err:?}"
        );
    }
}

/// A material layer with some paint already on it (a splat map that is not all zero).
fn painted_layer(size: UVec2) -> Grid<[u8; 4]> {
    Grid::from_fn(size.x, size.y, |x, y| {
        // Two weights from the texel's place, the rest of the cover in snow.
        let (a, b) = ((x * 37 + y * 11) % 128, (x * 5 + y * 53) % 128);
        [a as u8, b as u8, 0, (255 - a - b) as u8]
    })
    .expect("grid")
}

#[test]
fn material_effects_on_the_gpu_equal_the_cpu_reference() {
    let Some(ctx) = context_or_skip("material effects") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let size = UVec2::new(100, 72);
    let texel = 0.5;
    let mut cpu = painted_layer(size);
    let gpu = GpuMaterialLayer::new(device, queue, &cpu).expect("upload");
    let mut pass = MaterialEffectPass::new(device).expect("pass");
    let place = |c: Vec2, s: Vec2, r: f32| {
        StampPlacement::new(c, s, -1.0)
            .and_then(|p| p.with_rotation(r))
            .expect("placement")
    };
    // Across the repeating layer's corner, a long rotated one, and two that overlap (so a
    // texel is painted at most twice).
    let effects = [
        (
            place(Vec2::new(1.0, 0.5), Vec2::splat(9.0), 0.0),
            MaterialEffect::new(1, 1.0),
        ),
        (
            place(Vec2::new(25.0, 18.0), Vec2::new(30.0, 6.0), 0.7),
            MaterialEffect::new(2, 0.8),
        ),
        (
            place(Vec2::new(12.0, 20.0), Vec2::splat(12.0), 0.0),
            MaterialEffect::new(3, 0.35),
        ),
        (
            place(Vec2::new(14.0, 22.0), Vec2::splat(12.0), 0.3),
            MaterialEffect::new(0, 0.6),
        ),
    ];
    // The map the effects go with: the layer's size, repeating, `texel` metres a texel.
    let enc = HeightEncoding::spanning::<u16>(0.0, 10.0).expect("range");
    let heights = Grid::new(size.x, size.y, 0u16).expect("grid");
    let map = CoarseMap::new(heights, enc, texel, WrapMode::Repeat).expect("map");
    let map = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut encoder = device.create_command_encoder(&Default::default());
    for (placement, effect) in &effects {
        let effect = effect.as_ref().expect("effect");
        let op = EffectOp {
            placement: *placement,
            effect: *effect,
        };
        let want = terrain_core::apply_material_effect(
            &mut cpu,
            WrapMode::Repeat,
            texel,
            placement,
            effect,
        )
        .expect("cpu");
        let got = pass
            .encode(device, queue, &mut encoder, &gpu, &map, &op)
            .expect("gpu");
        assert_eq!(got, want, "the same rects");
    }
    // Refused with nothing recorded, as on the CPU.
    let bad = MaterialEffect {
        material: 4,
        strength: 1.0,
    };
    let bad = EffectOp {
        placement: effects[0].0,
        effect: bad,
    };
    assert!(
        pass.encode(device, queue, &mut encoder, &gpu, &map, &bad)
            .is_err()
    );
    // A layer of another size than the map is refused.
    let small = GpuMaterialLayer::new(device, queue, &Grid::new(8, 8, [0u8; 4]).expect("grid"))
        .expect("upload");
    let fine = EffectOp {
        placement: effects[0].0,
        effect: MaterialEffect::new(1, 1.0).expect("effect"),
    };
    let err = pass.encode(device, queue, &mut encoder, &small, &map, &fine);
    assert!(
        matches!(
            err,
            Err(GpuError::Core(terrain_core::CoreError::SizeMismatch { .. }))
        ),
        "{err:?}"
    );
    queue.submit([encoder.finish()]);
    pass.recall();
    let read = gpu.read(device, queue).expect("read back");
    ctx.check().expect("no GPU validation errors");
    // An amount may differ by one step where the GPU fuses a multiply and an add (see
    // terrain_core::material_effect); each painting then moves a channel by at most one.
    let (mut differ, mut painted) = (0, 0);
    let start = painted_layer(size);
    for ((g, c), s) in read
        .as_slice()
        .iter()
        .zip(cpu.as_slice())
        .zip(start.as_slice())
    {
        painted += usize::from(c != s);
        if g != c {
            differ += 1;
            let d = g
                .iter()
                .zip(c)
                .map(|(a, b)| a.abs_diff(*b))
                .max()
                .unwrap_or(0);
            assert!(d <= 2, "GPU {g:?} against CPU {c:?}");
        }
    }
    eprintln!("{painted} texels painted, {differ} differ by a step");
    assert!(painted > 500, "the effects painted {painted} texels");
    assert!(differ * 100 <= painted, "{differ} of {painted} differ");
}

/// Renders a frame of every LOD mode after a shallow stamp that paints rock (a blast's
/// scorch): without the effect the flat lowland stays grass (the autoshader sees no slope or
/// curvature in a 0.2 m dip), with it the stamp's centre shows the rock material.
#[test]
fn a_stamps_material_effect_shows_in_every_lod_mode() {
    let Some(ctx) = context_or_skip("material effect render") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let solid = GpuMaterials::new(device, queue, &solid_materials()).expect("upload");
    let layer = GpuMaterialLayer::new(device, queue, &Grid::new(MAP, MAP, [0u8; 4]).expect("grid"))
        .expect("layer");
    let placement =
        StampPlacement::new(Vec2::new(60.0, 128.0), Vec2::splat(24.0), -0.2).expect("placement");
    let mut stamps = terrain_gpu::StampPass::new(device).expect("stamp pass");
    let mut effects = MaterialEffectPass::new(device).expect("effect pass");
    let mut encoder = device.create_command_encoder(&Default::default());
    let gaussian = terrain_core::GaussianStamp::default();
    let op = terrain_gpu::StampOp {
        stamp: terrain_gpu::GpuStamp::Gaussian(&gaussian),
        placement,
        blend: terrain_core::Blend::Add,
    };
    stamps
        .encode(device, queue, &mut encoder, &gpu.0, &op)
        .expect("stamp");
    let rock = EffectOp {
        placement,
        effect: MaterialEffect::new(2, 1.0).expect("effect"),
    };
    effects
        .encode(device, queue, &mut encoder, &layer, &gpu.0, &rock)
        .expect("effect");
    let mut normals = NormalPass::new(device).expect("normal pass");
    normals
        .encode_full(device, queue, &mut encoder, &gpu.0, &gpu.1)
        .expect("normals");
    queue.submit([encoder.finish()]);
    // Pixels within 0.8 m of the centre (map (60, 128); 0.8 m a pixel, rows from z = 56 down):
    // 99% rock there.
    let centre = |image: &Grid<[u8; 4]>| {
        let (cx, cy) = (60.0 / 0.8, (128.0 - 56.0) / 0.8);
        let mut sum = Vec3::ZERO;
        let mut n = 0.0;
        for y in 0..SIZE.y {
            for x in 0..SIZE.x {
                if (x as f32 - cx).hypot(y as f32 - cy) <= 1.0 {
                    let p = image.get(x, y).expect("inside");
                    sum += Vec3::new(p[0].into(), p[1].into(), p[2].into());
                    n += 1.0;
                }
            }
        }
        sum / n
    };
    let l = Vec3::new(-0.8, 0.6, 0.0).normalize();
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_materials(&solid);
        let unpainted = centre(&draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials));
        assert!(
            (unpainted - lit(0, l.y)).abs().max_element() <= COLOUR_TOLERANCE,
            "{mode}: without the layer the dip is grass, not {unpainted}"
        );
        renderer.set_material_layer(Some(&layer));
        let painted = centre(&draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials));
        assert!(
            (painted - lit(2, l.y)).abs().max_element() <= COLOUR_TOLERANCE + 2.0,
            "{mode}: the effect paints rock, the frame shows {painted}"
        );
    }
}
