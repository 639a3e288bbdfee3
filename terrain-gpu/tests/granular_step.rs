//! The chained GPU granular step: volume conservation over 500 frames with three moving
//! objects (checked every frame by the GPU sum), equality with the CPU `GranularSim` step by
//! step, no GPU objects made per frame once the step has run, and the trail it paints; the
//! whole field (`GranularField`), moved on to another window without a wait (`shift`), and
//! `FieldStepper` over it.

use terrain_core::granular::*;
use terrain_core::{FixedPointMap, Grid, MaterialEffect, apply_trail_effect};
use terrain_gpu::granular::{
    DepthSource, GpuGranularStep, GranularField, StepMeasure, StepMeasures, Trail, VolumePass,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{GpuHeightMap, GpuMaterialLayer};
use terrain_test_support::granular::{bumpy_map, empty_pen, meshes, objects_at, small_params};

const METHODS: [(DisplacementMethod, SlopeMethod); 6] = [
    (DisplacementMethod::ClosestSeed, SlopeMethod::Scatter),
    (DisplacementMethod::ClosestSeed, SlopeMethod::Interleaved),
    (DisplacementMethod::MultipleTargets, SlopeMethod::Scatter),
    (
        DisplacementMethod::MultipleTargets,
        SlopeMethod::Interleaved,
    ),
    (DisplacementMethod::iterative(), SlopeMethod::Scatter),
    (DisplacementMethod::iterative(), SlopeMethod::Interleaved),
];

/// The method pair of `frame` of `frames`: each pair for an equal run of frames.
fn methods_at(frame: u32, frames: u32) -> (DisplacementMethod, SlopeMethod) {
    METHODS[frame as usize * METHODS.len() / frames as usize]
}

#[test]
fn gpu_volume_constant_over_500_frames_three_objects() {
    let Some(ctx) = context_or_skip("gpu_volume_constant_over_500_frames_three_objects") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let map = bumpy_map(96, 0.05);
    let v0 = map.raw_sum();
    let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut step = GpuGranularStep::new(device, small_params()).expect("step");
    let mut volume = VolumePass::new(device).expect("volume");
    assert_eq!(volume.sum(device, queue, &gmap).expect("sum"), v0);
    let t0 = std::time::Instant::now();
    for frame in 0..500u32 {
        let (d, s) = methods_at(frame, 500);
        step.displacement = d;
        step.slope = s;
        let objs = objects_at(&m, frame, 96.0 * 0.05);
        let r = step.step(device, queue, &gmap, &objs).expect("step");
        assert_eq!(r.removed, 0, "frame {frame}");
        assert_eq!(
            volume.sum(device, queue, &gmap).expect("sum"),
            v0,
            "frame {frame}"
        );
    }
    ctx.check().expect("validation");
    let end = gmap.read(device, queue).expect("read");
    assert_eq!(end.raw_sum(), v0);
    assert_ne!(end, map, "nothing was deformed");
    eprintln!("500 GPU frames in {:.1} s", t0.elapsed().as_secs_f64());
}

#[test]
fn gpu_step_matches_cpu_sim_bit_for_bit() {
    let Some(ctx) = context_or_skip("gpu_step_matches_cpu_sim_bit_for_bit") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let map = bumpy_map(96, 0.05);
    let p = GranularParams {
        compression: 0.3,
        ..small_params()
    };
    let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut step = GpuGranularStep::new(device, p).expect("step");
    // The CPU rasterizer's depth, so the whole step can be compared bit for bit (the GPU
    // depth pass is compared with it on its own in granular_depth.rs).
    step.depth_source = DepthSource::Cpu;
    let mut sim = GranularSim::new(map, p).expect("sim");
    let mut removed = [0u64; METHODS.len()];
    let mut several_areas = 0;
    for frame in 0..80u32 {
        let (d, s) = methods_at(frame, 80);
        step.displacement = d;
        step.slope = s;
        sim.displacement = d;
        sim.slope = s;
        let objs = objects_at(&m, frame * 5, 96.0 * 0.05);
        let g = step.step(device, queue, &gmap, &objs).expect("gpu step");
        let c = sim.step(&objs).expect("cpu step");
        assert_eq!(g.active_areas, c.active_areas, "frame {frame}");
        assert_eq!(g.removed, c.removed, "frame {frame}");
        several_areas += u32::from(g.active_areas.len() > 1);
        removed[frame as usize * METHODS.len() / 80] += g.removed;
        let gpu = gmap.read(device, queue).expect("read");
        assert!(
            gpu == *sim.map(),
            "frame {frame}: GPU map differs from the CPU map"
        );
    }
    ctx.check().expect("validation");
    // Some frames recorded several areas into one encoder (their depth uploads and uniforms
    // must not overwrite each other).
    assert!(several_areas > 0, "every frame had a single active area");
    // Every method pair ran with penetrating objects.
    assert!(
        removed.iter().all(|&r| r > 0),
        "compression removed nothing under some methods: {removed:?}"
    );
}

/// The GPU objects alive on the device (wgpu's `counters` feature).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct LiveObjects {
    buffers: isize,
    textures: isize,
    texture_views: isize,
    bind_groups: isize,
    bind_group_layouts: isize,
    shader_modules: isize,
    pipelines: isize,
}

fn live_objects(device: &wgpu::Device) -> LiveObjects {
    let hal = device.get_internal_counters().hal;
    LiveObjects {
        buffers: hal.buffers.read(),
        textures: hal.textures.read(),
        texture_views: hal.texture_views.read(),
        bind_groups: hal.bind_groups.read(),
        bind_group_layouts: hal.bind_group_layouts.read(),
        shader_modules: hal.shader_modules.read(),
        pipelines: hal.render_pipelines.read() + hal.compute_pipelines.read(),
    }
}

/// Once a step has run with a set of areas, recording further steps (both depth sources, every
/// method pair, several areas per encoder) and volume sums makes no buffer, texture, view, bind
/// group, layout, shader module or pipeline: they only write uniforms and record commands.
#[test]
fn steady_state_steps_make_no_gpu_objects() {
    let Some(ctx) = context_or_skip("steady_state_steps_make_no_gpu_objects") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let map = bumpy_map(96, 0.05);
    let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut step = GpuGranularStep::new(device, small_params()).expect("step");
    let mut volume = VolumePass::new(device).expect("volume");
    // Objects apart, so each frame has several areas; the same placements every frame.
    let objs = objects_at(&m, 140, 96.0 * 0.05);
    let frame =
        |step: &mut GpuGranularStep, volume: &mut VolumePass, check: Option<LiveObjects>| {
            let mut encoder = device.create_command_encoder(&Default::default());
            let areas = step
                .encode(device, queue, &mut encoder, &gmap, &objs)
                .expect("encode");
            volume
                .encode(device, queue, &mut encoder, &gmap)
                .expect("volume");
            if let Some(before) = check {
                // Anything made while recording is still held by the unsubmitted encoder here.
                // Every `queue.write_buffer` stages through a buffer of wgpu's own until the submit
                // that carries it is done: an empty submit carries them (before the encoder's
                // commands, as a submit of the encoder would) and the poll frees them.
                queue.submit([]);
                device
                    .poll(wgpu::PollType::wait_indefinitely())
                    .expect("poll");
                assert_eq!(live_objects(device), before, "while recording");
            }
            queue.submit([encoder.finish()]);
            step.recall();
            volume.recall();
            volume.read(device).expect("read");
            areas.len()
        };
    let settings: Vec<_> = [DepthSource::Gpu, DepthSource::Cpu]
        .into_iter()
        .flat_map(|d| METHODS.map(|m| (d, m)))
        .collect();
    let mut areas = 0;
    for &(source, (d, s)) in &settings {
        (step.depth_source, step.displacement, step.slope) = (source, d, s);
        areas = areas.max(frame(&mut step, &mut volume, None));
    }
    assert!(areas > 1, "the objects should be in separate areas");
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    let before = live_objects(device);
    assert!(
        before.buffers > 0 && before.pipelines > 0,
        "wgpu's counters are off: {before:?}"
    );
    for &(source, (d, s)) in &settings {
        (step.depth_source, step.displacement, step.slope) = (source, d, s);
        frame(&mut step, &mut volume, Some(before));
    }
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    assert_eq!(live_objects(device), before, "after the frames");
    ctx.check().expect("validation");
}

/// A trail painted during GPU steps (`TrailEffectPass`, in the step's encoder) equals
/// `apply_trail_effect` over the CPU penetration texture of each step, bit for bit, on a layer
/// with paint on it already; a trail that does not fit the map is refused with nothing
/// recorded.
#[test]
fn a_trail_painted_on_the_gpu_equals_the_cpu_reference() {
    let Some(ctx) = context_or_skip("a_trail_painted_on_the_gpu_equals_the_cpu_reference") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let map = bumpy_map(96, 0.05);
    let p = small_params();
    let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut step = GpuGranularStep::new(device, p).expect("step");
    step.depth_source = DepthSource::Cpu;
    let mut sim = GranularSim::new(map, p).expect("sim");
    // Snow painted everywhere, so the trail's paint blends with paint already there.
    let mut expected = Grid::new(96, 96, [0u8, 0, 0, 255]).expect("layer");
    let layer = GpuMaterialLayer::new(device, queue, &expected).expect("layer");
    let effect = MaterialEffect::new(1, 0.35).expect("effect");
    let trail = Trail {
        layer: &layer,
        effect,
    };
    let mut painted = 0;
    for frame in 0..40u32 {
        // One object, one area: the CPU penetration of the map before the step is the GPU's.
        let all = objects_at(&m, frame * 5, 96.0 * 0.05);
        let objs = &all[..1];
        for area in sim.active_areas(objs).expect("areas") {
            let rect = area.rect;
            let depth = depth_from_below(objs, sim.map(), rect).expect("depth");
            let mut pen = empty_pen(rect.size);
            penetration_texture(sim.map(), &depth, rect, 0, &mut pen).expect("penetration");
            let dirty = apply_trail_effect(&mut expected, &pen, rect, &effect).expect("trail");
            painted += u32::from(dirty.is_some());
        }
        sim.step(objs).expect("cpu step");
        let mut encoder = device.create_command_encoder(&Default::default());
        step.encode_with_trail(device, queue, &mut encoder, &gmap, objs, Some(trail))
            .expect("encode");
        queue.submit([encoder.finish()]);
        step.recall();
        let gpu = layer.read(device, queue).expect("read layer");
        assert!(gpu == expected, "frame {frame}: the GPU trail differs");
    }
    assert!(painted > 10, "the object pressed on {painted} frames only");
    let darkened = expected.as_slice().iter().filter(|t| t[1] > 0).count();
    assert!(darkened > 50, "{darkened} texels on the trail");
    // Refused: a layer of another size, an invalid effect.
    let small = GpuMaterialLayer::new(device, queue, &Grid::new(32, 32, [0; 4]).unwrap())
        .expect("small layer");
    let bad = [
        Trail {
            layer: &small,
            effect,
        },
        Trail {
            layer: &layer,
            effect: MaterialEffect {
                material: 4,
                strength: 1.0,
            },
        },
    ];
    let objs = objects_at(&m, 300, 96.0 * 0.05);
    for trail in bad {
        let mut encoder = device.create_command_encoder(&Default::default());
        assert!(
            step.encode_with_trail(device, queue, &mut encoder, &gmap, &objs[..1], Some(trail))
                .is_err()
        );
        queue.submit([encoder.finish()]);
        step.recall();
    }
    assert!(
        gmap.read(device, queue).expect("read") == *sim.map(),
        "a refused step ran"
    );
    assert!(layer.read(device, queue).expect("read") == expected);
    ctx.check().expect("validation");
}

/// A step's volume sum and removed material, copied into small readback rings in the step's
/// own submit (`StepMeasures`), come back without a wait equal to the blocking reads, in step
/// order with their tags; a flush hands over the last ones (what the demo reports a frame
/// later instead of stalling each frame on the GPU).
#[test]
fn volume_and_removed_ride_the_small_readback_rings() {
    let Some(ctx) = context_or_skip("volume_and_removed_ride_the_small_readback_rings") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let map = bumpy_map(96, 0.05);
    let p = GranularParams {
        compression: 0.3,
        ..small_params()
    };
    let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut step = GpuGranularStep::new(device, p).expect("step");
    let mut volume = VolumePass::new(device).expect("volume");
    let mut measures = StepMeasures::new(device).expect("rings");
    let mut expected = Vec::new();
    let mut arrived = Vec::new();
    for frame in 0..24u64 {
        let objs = objects_at(&m, frame as u32 * 5, 96.0 * 0.05);
        let mut encoder = device.create_command_encoder(&Default::default());
        step.encode(device, queue, &mut encoder, &gmap, &objs)
            .expect("step");
        volume
            .encode(device, queue, &mut encoder, &gmap)
            .expect("volume");
        measures
            .request(device, &mut encoder, 100 + frame, &volume, step.scratch())
            .expect("request");
        queue.submit([encoder.finish()]);
        step.recall();
        volume.recall();
        // The blocking reads of the same counters, for reference.
        let scratch = step.scratch().expect("scratch after a step");
        expected.push(StepMeasure {
            tag: 100 + frame,
            volume: volume.read(device).expect("read"),
            removed: scratch.read_removed(device, queue).expect("read"),
        });
        // Every other frame polls: nothing waits, and what arrived comes in order.
        if frame % 2 == 1 {
            arrived.extend(measures.poll(device).expect("poll"));
        }
    }
    arrived.extend(measures.flush(device).expect("flush"));
    assert!(!measures.in_flight());
    assert_eq!(arrived, expected);
    // More steps than the rings hold, never polled: a full ring waits for the GPU instead of
    // losing a step, and the flush hands every one over in order.
    for tag in 0..40u64 {
        let mut encoder = device.create_command_encoder(&Default::default());
        volume
            .encode(device, queue, &mut encoder, &gmap)
            .expect("volume");
        measures
            .request(device, &mut encoder, tag, &volume, None)
            .expect("request");
        queue.submit([encoder.finish()]);
        volume.recall();
    }
    let tags: Vec<u64> = measures
        .flush(device)
        .expect("flush")
        .iter()
        .map(|m| m.tag)
        .collect();
    assert_eq!(tags, (0..40).collect::<Vec<_>>());
    assert!(
        expected.iter().any(|m| m.removed > 0),
        "compression removed nothing: the removed counter went untested"
    );
    ctx.check().expect("validation");
}

/// `GranularField`, the whole of a granular map on the GPU: its steps equal the CPU
/// simulation's; the areas it reads back, applied to a CPU copy as they arrive, leave the copy
/// equal to the simulation's map after a drain; every step's measures come back in order, equal
/// to the simulation's; and a field built from the last one's passes hands over nothing of it.
#[test]
fn a_granular_field_reads_back_what_the_cpu_simulation_computes() {
    let Some(ctx) = context_or_skip("a_granular_field_reads_back_what_the_cpu_simulation_computes")
    else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let map = bumpy_map(96, 0.05);
    let p = GranularParams {
        compression: 0.3,
        ..small_params()
    };
    let mut field = GranularField::new(device, queue, &map, p, None).expect("field");
    // The CPU rasterizer's depth, so that the steps compare bit for bit.
    field.step_pass_mut().depth_source = DepthSource::Cpu;
    let mut sim = GranularSim::new(map.clone(), p).expect("sim");
    let mut copy = map.grid().clone();
    let mut expected = Vec::new();
    let mut measured = Vec::new();
    let apply = |copy: &mut Grid<u32>, arrivals: GranularArrivals| {
        for (rect, heights) in arrivals.areas {
            copy.paste(&heights, rect.min).expect("area inside the map");
        }
        arrivals.measured
    };
    for frame in 0..30u64 {
        let objs = objects_at(&m, frame as u32 * 5, 96.0 * 0.05);
        let areas = field.step(device, queue, &objs, frame).expect("gpu step");
        let c = sim.step(&objs).expect("cpu step");
        let cpu_areas: Vec<_> = c.active_areas.iter().map(|a| a.rect).collect();
        assert_eq!(areas, cpu_areas, "frame {frame}");
        expected.push(StepMeasure {
            tag: frame,
            volume: c.volume,
            removed: c.removed,
        });
        if frame % 3 == 2 {
            let arrivals = field.poll(device).expect("poll");
            measured.extend(apply(&mut copy, arrivals));
        }
    }
    measured.extend(apply(&mut copy, field.drain(device, queue).expect("drain")));
    assert_eq!(measured, expected);
    assert!(
        copy == *sim.map().grid(),
        "the areas read back miss a change"
    );
    assert!(
        expected.iter().any(|m| m.removed > 0),
        "compression untested"
    );
    // The passes serve another map; nothing of the first comes with it.
    let objs = objects_at(&m, 7, 96.0 * 0.05);
    field
        .step(device, queue, &objs, 99)
        .expect("a step left in flight");
    let (last, passes) = field.finish(device, queue).expect("finish");
    assert_eq!(last.measured.len(), 1);
    let mut next = GranularField::new(device, queue, &map, p, Some(passes)).expect("field");
    let nothing = next.drain(device, queue).expect("drain");
    assert!(nothing.areas.is_empty() && nothing.measured.is_empty());
    ctx.check().expect("validation");
}

/// A window moved on by `GranularField::shift`, whose steps were still on their way: the
/// shared columns come from the GPU's map (the CPU map it was given there is stale), so the
/// moved field steps exactly as a CPU simulation taken from the world after the old window's
/// last step; the old map's areas and measures all arrive through the retired field, the new
/// map's sum comes back tagged, and the shared texels are read back.
#[test]
fn a_shifted_field_steps_as_a_window_taken_after_the_last_step() {
    let Some(ctx) = context_or_skip("a_shifted_field_steps_as_a_window_taken_after_the_last_step")
    else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let (side, texel) = (64u32, 0.05);
    let world = bumpy_map(112, texel);
    let window = |grid: &Grid<u32>, min: glam::IVec2| {
        let r = terrain_core::Rect::new(min, glam::UVec2::splat(side));
        let part = grid.copy_rect(r).expect("inside the world");
        FixedPointMap::new(part, world.encoding(), texel, world.wrap()).expect("map")
    };
    let p = small_params();
    // Left and down: a negative offset in x, a positive one in z.
    let a_min = glam::IVec2::new(40, 4);
    let b_min = glam::IVec2::new(22, 30);
    let map_a = window(world.grid(), a_min);
    let mut field = GranularField::new(device, queue, &map_a, p, None).expect("field");
    field.step_pass_mut().depth_source = DepthSource::Cpu;
    let mut sim_a = GranularSim::new(map_a.clone(), p).expect("sim");
    let extent = side as f32 * texel;
    let mut expected_a = Vec::new();
    let mut areas_a = 0;
    for frame in 0..12u64 {
        let objs = objects_at(&m, frame as u32 * 9, extent);
        areas_a += field
            .step(device, queue, &objs, frame)
            .expect("gpu step")
            .len();
        expected_a.push(sim_a.step(&objs).expect("cpu step").volume);
    }
    // More areas than the readback ring holds: some still wait for a buffer at the shift.
    assert!(areas_a > 8, "{areas_a} areas");
    // The CPU world after the old window's last step, and the stale window the GPU is given.
    let mut settled = world.grid().clone();
    settled.paste(sim_a.map().grid(), a_min).expect("paste");
    let stale_b = window(world.grid(), b_min);
    let (mut retired, shared) = field
        .shift(device, queue, &stale_b, b_min - a_min, 1000)
        .expect("shift");
    let shared = shared.expect("the windows overlap");
    let want = terrain_core::Rect::new(glam::IVec2::new(18, 0), glam::UVec2::new(46, 38));
    assert_eq!(shared, want);
    let mut sim_b = GranularSim::new(window(&settled, b_min), p).expect("sim");
    let start_b: u64 = sim_b
        .map()
        .grid()
        .as_slice()
        .iter()
        .map(|&u| u64::from(u))
        .sum();
    let mut copy_b = stale_b.grid().clone();
    let mut measured_b = Vec::new();
    let mut expected_b = vec![(1000, start_b)];
    for frame in 12..18u64 {
        let objs = objects_at(&m, frame as u32 * 9, extent);
        field.step(device, queue, &objs, frame).expect("gpu step");
        expected_b.push((frame, sim_b.step(&objs).expect("cpu step").volume));
    }
    // The retired field polled, never drained, until everything has arrived.
    let mut copy_a = map_a.grid().clone();
    let mut old_volumes = Vec::new();
    for _ in 0..100 {
        let old = retired.poll(device, queue).expect("poll retired");
        for (rect, heights) in old.areas {
            copy_a
                .paste(&heights, rect.min)
                .expect("area inside the old map");
        }
        old_volumes.extend(old.measured.iter().map(|m| m.volume));
        if !old.in_flight {
            break;
        }
        device.poll(terrain_gpu::wait_bounded()).expect("wait");
    }
    assert!(copy_a == *sim_a.map().grid(), "an old area never arrived");
    assert_eq!(old_volumes, expected_a);
    let new = field.drain(device, queue).expect("drain");
    assert_eq!(new.areas.first().map(|a| a.0), Some(shared));
    for (rect, heights) in new.areas {
        copy_b
            .paste(&heights, rect.min)
            .expect("area inside the new map");
    }
    measured_b.extend(new.measured.iter().map(|m| (m.tag, m.volume)));
    assert_eq!(measured_b, expected_b);
    assert!(
        copy_b == *sim_b.map().grid(),
        "the moved window differs from one taken after the last step"
    );
    // The retired field, everything arrived, is taken back (one with readbacks on their way
    // would not be), and a second move runs on its buffers and the replaced normals: still
    // the window taken after the last step.
    let kept = field.recycle(retired);
    assert!(kept.is_none(), "a field with nothing in flight is kept");
    // One more step of the window, its areas on their way at the move.
    let objs = objects_at(&m, 18 * 9, extent);
    field.step(device, queue, &objs, 18).expect("gpu step");
    sim_b.step(&objs).expect("cpu step");
    let c_min = glam::IVec2::new(34, 40);
    let stale_c = window(&settled, c_min);
    settled.paste(sim_b.map().grid(), b_min).expect("paste");
    let (retired_c, _) = field
        .shift(device, queue, &stale_c, c_min - b_min, 2000)
        .expect("shift onto recycled buffers");
    // That step's readbacks are on their way: not taken, given back to poll on.
    let mut retired_c = field.recycle(retired_c).expect("in flight: given back");
    let mut sim_c = GranularSim::new(window(&settled, c_min), p).expect("sim");
    for frame in 19..23u64 {
        let objs = objects_at(&m, frame as u32 * 9, extent);
        field.step(device, queue, &objs, frame).expect("gpu step");
        sim_c.step(&objs).expect("cpu step");
    }
    retired_c.drain(device, queue).expect("drain retired");
    let mut copy_c = stale_c.grid().clone();
    for (rect, heights) in field.drain(device, queue).expect("drain").areas {
        copy_c
            .paste(&heights, rect.min)
            .expect("area inside the map");
    }
    assert!(
        copy_c == *sim_c.map().grid(),
        "a move onto recycled buffers differs from a window taken after the last step"
    );
    // A map of another size or texel size is refused, the field unchanged.
    let coarser = FixedPointMap::new(stale_b.grid().clone(), world.encoding(), 0.1, world.wrap());
    let coarser = coarser.expect("map");
    assert!(
        field
            .shift(device, queue, &coarser, glam::IVec2::ONE, 0)
            .is_err()
    );
    let small = bumpy_map(32, texel);
    assert!(
        field
            .shift(device, queue, &small, glam::IVec2::ONE, 0)
            .is_err()
    );
    ctx.check().expect("validation");
}

/// A `Submit` that counts the submits by name, around plain ones.
struct Counting<'a> {
    plain: terrain_gpu::PlainSubmit<'a>,
    names: Vec<&'static str>,
}

impl terrain_gpu::Submit for Counting<'_> {
    fn submit(
        &mut self,
        name: &'static str,
        work: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> Result<(), terrain_gpu::GpuError>,
    ) -> Result<(), terrain_gpu::GpuError> {
        self.names.push(name);
        self.plain.submit(name, work)
    }
}

/// `FieldStepper`, terrain-core's `GranularStepper` over `GranularField`, driven as a granular
/// window's owner drives it: steps (through the application's `Submit`), a shift with steps on
/// their way, the retired map polled to the end, a stop. Everything that comes back equals the
/// CPU simulation's, and what the contract forbids is refused.
#[test]
fn a_field_stepper_steps_shifts_and_stops_as_the_cpu_simulation() {
    let Some(ctx) = context_or_skip("a_field_stepper_steps_shifts_and_stops_as_the_cpu_simulation")
    else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let m = meshes();
    let texel = 0.05;
    let map = bumpy_map(64, texel);
    let p = small_params();
    let mut stepper = terrain_gpu::granular::FieldStepper::new(device, queue);
    stepper.set_depth_source(DepthSource::Cpu);
    assert!(stepper.step(&[], 0).is_err(), "a step before start");
    stepper.start(&map, p).expect("start");
    assert!(
        stepper.start(&map, p).is_err(),
        "a second start drops the first"
    );
    let mut sim = GranularSim::new(map.clone(), p).expect("sim");
    let mut copy = map.grid().clone();
    let extent = 64.0 * texel;
    let mut counting = Counting {
        plain: terrain_gpu::PlainSubmit { device, queue },
        names: Vec::new(),
    };
    for frame in 0..5u64 {
        let objs = objects_at(&m, frame as u32 * 9, extent);
        let arrived = stepper
            .submitting(&mut counting)
            .step(&objs, frame)
            .expect("step");
        for (rect, heights) in arrived.areas {
            copy.paste(&heights, rect.min).expect("inside");
        }
        sim.step(&objs).expect("cpu step");
    }
    assert_eq!(counting.names.len(), 10);
    assert_eq!(
        &counting.names[..2],
        [GranularField::STEP, GranularField::FOLLOW_UP]
    );
    assert!(stepper.shifts());
    // The same window again (a shift of nothing): the map carries over whole.
    assert!(
        stepper
            .shift(&map, glam::IVec2::ZERO, SHIFT_TAG)
            .expect("shift")
    );
    assert!(
        stepper.shift(&map, glam::IVec2::ZERO, SHIFT_TAG).is_err(),
        "a shift while the last one's readbacks are on their way"
    );
    for _ in 0..100 {
        let old = stepper.poll_retired().expect("poll retired");
        for (rect, heights) in old.areas {
            copy.paste(&heights, rect.min).expect("inside");
        }
        if !old.in_flight {
            break;
        }
        device.poll(terrain_gpu::wait_bounded()).expect("wait");
    }
    assert!(
        copy == *sim.map().grid(),
        "an area of the old map never arrived"
    );
    // The moved map's sum comes first, whether it arrives with the next step or at the stop.
    let sum: u64 = sim
        .map()
        .grid()
        .as_slice()
        .iter()
        .map(|&u| u64::from(u))
        .sum();
    let objs = objects_at(&m, 77, extent);
    let mut arrived = vec![stepper.step(&objs, 5).expect("step after the shift")];
    sim.step(&objs).expect("cpu step");
    arrived.push(stepper.stop().expect("stop"));
    let measured: Vec<(u64, u64)> = arrived
        .iter()
        .flat_map(|a| a.measured.iter().map(|m| (m.tag, m.volume)))
        .collect();
    assert_eq!(measured.first(), Some(&(SHIFT_TAG, sum)));
    assert_eq!(measured.len(), 2);
    for (rect, heights) in arrived.into_iter().flat_map(|a| a.areas) {
        copy.paste(&heights, rect.min).expect("inside");
    }
    assert!(copy == *sim.map().grid(), "the moved map's areas differ");
    assert!(stepper.field().is_none());
    ctx.check().expect("validation");
}
