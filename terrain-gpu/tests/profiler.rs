//! `GpuProfiler`: nested scopes come back a frame or more later with their names, depths and
//! frame numbers; a frame never waits for a staging buffer (it goes untimed instead); misuse
//! is an error, not a panic. Timestamp values are only checked to be finite and bounded:
//! conforming hardware may reorder the timestamps of passes with no barrier between them, so
//! their order proves nothing about this code.

use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{GpuContext, GpuError, GpuProfiler, wgpu};

/// Some GPU work to time: clearing a 4 MiB buffer.
fn work(ctx: &GpuContext) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("profiled work"),
        size: 4 << 20,
        usage: wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn profiler(ctx: &GpuContext, scopes: u32, frames: usize) -> Option<GpuProfiler> {
    let info = ctx.adapter.get_info();
    match GpuProfiler::new(&info, &ctx.device, &ctx.queue, scopes, frames) {
        Ok(p) => Some(p),
        // Without timestamp queries the profiler refuses clearly: that is what is checked.
        Err(GpuError::Unsupported { .. })
            if !ctx
                .device
                .features()
                .contains(wgpu::Features::TIMESTAMP_QUERY) =>
        {
            None
        }
        Err(e) => panic!("GpuProfiler::new: {e}"),
    }
}

/// Records and submits one frame.
fn frame(ctx: &GpuContext, p: &mut GpuProfiler, buffer: &wgpu::Buffer) {
    ctx.queue.submit(record(ctx, p, buffer));
}

/// Records one frame: `outer { a, b }` around clears of `buffer`, ended in a second encoder.
fn record(
    ctx: &GpuContext,
    p: &mut GpuProfiler,
    buffer: &wgpu::Buffer,
) -> [wgpu::CommandBuffer; 2] {
    p.begin_frame();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    p.scope(&mut encoder, "outer", |p, encoder| {
        for name in ["a", "b"] {
            p.scope(encoder, name, |_, encoder| {
                encoder.clear_buffer(buffer, 0, None);
                Ok(())
            })?;
        }
        Ok(())
    })
    .unwrap();
    let mut last = ctx.device.create_command_encoder(&Default::default());
    p.end_frame(&mut last).unwrap();
    [encoder.finish(), last.finish()]
}

#[test]
fn nested_scopes_arrive_later_with_their_names_depths_and_frames() {
    let Some(ctx) = context_or_skip("profiler nesting") else {
        return;
    };
    let Some(mut p) = profiler(&ctx, 8, 4) else {
        return;
    };
    let buffer = work(&ctx);
    let mut arrived = Vec::new();
    for _ in 0..3 {
        frame(&ctx, &mut p, &buffer);
        // Whatever has arrived, without waiting.
        arrived.extend(p.poll(&ctx.device).unwrap());
    }
    arrived.extend(p.flush(&ctx.device).unwrap());
    let frames: Vec<u64> = arrived.iter().map(|f| f.frame).collect();
    assert_eq!(frames, [0, 1, 2]);
    for f in &arrived {
        let shape: Vec<(&str, u32)> = f.scopes.iter().map(|s| (s.name, s.depth)).collect();
        assert_eq!(shape, [("outer", 0), ("a", 1), ("b", 1)]);
        for s in &f.scopes {
            assert!(s.ms.is_finite() && (0.0..10_000.0).contains(&s.ms), "{s:?}");
            assert!(
                s.start_ms.is_finite() && (0.0..10_000.0).contains(&s.start_ms),
                "{s:?}"
            );
        }
    }
    assert_eq!(p.dropped(), (0, 0));
}

#[test]
fn a_frame_goes_untimed_instead_of_waiting_for_a_staging_buffer() {
    let Some(ctx) = context_or_skip("profiler ring") else {
        return;
    };
    let Some(mut p) = profiler(&ctx, 4, 1) else {
        return;
    };
    let buffer = work(&ctx);
    // The first frame is not even submitted when the second begins: the one staging buffer
    // is taken, and the second frame goes untimed.
    let first = record(&ctx, &mut p, &buffer);
    let second = record(&ctx, &mut p, &buffer);
    assert_eq!(p.dropped(), (0, 1));
    ctx.queue.submit(first.into_iter().chain(second));
    let arrived = p.flush(&ctx.device).unwrap();
    assert_eq!(arrived.iter().map(|f| f.frame).collect::<Vec<_>>(), [0]);
    // Freed again: the next frame is timed.
    frame(&ctx, &mut p, &buffer);
    let arrived = p.flush(&ctx.device).unwrap();
    assert_eq!(arrived.iter().map(|f| f.frame).collect::<Vec<_>>(), [2]);
}

#[test]
fn a_frame_dropped_unsubmitted_is_forgotten_and_later_ones_arrive() {
    let Some(ctx) = context_or_skip("profiler dropped frame") else {
        return;
    };
    let Some(mut p) = profiler(&ctx, 4, 2) else {
        return;
    };
    let buffer = work(&ctx);
    p.begin_frame();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let s = p.begin_scope(&mut encoder, "never submitted");
    p.end_scope(&mut encoder, s).unwrap();
    p.end_frame(&mut encoder).unwrap();
    drop(encoder);
    for _ in 0..3 {
        frame(&ctx, &mut p, &buffer);
        p.flush(&ctx.device).unwrap();
    }
    frame(&ctx, &mut p, &buffer);
    let arrived = p.flush(&ctx.device).unwrap();
    assert_eq!(arrived.iter().map(|f| f.frame).collect::<Vec<_>>(), [4]);
}

#[test]
fn bounds_and_misuse_are_errors_not_panics() {
    let Some(ctx) = context_or_skip("profiler misuse") else {
        return;
    };
    let info = ctx.adapter.get_info();
    let new = |scopes, frames| GpuProfiler::new(&info, &ctx.device, &ctx.queue, scopes, frames);
    if !ctx
        .device
        .features()
        .contains(wgpu::Features::TIMESTAMP_QUERY)
    {
        assert!(matches!(new(4, 2), Err(GpuError::Unsupported { .. })));
        return;
    }
    for (scopes, frames) in [
        (0, 2),
        (257, 2),
        (u32::MAX, 2),
        (4, 0),
        (4, 17),
        (4, usize::MAX),
    ] {
        assert!(
            new(scopes, frames).is_err(),
            "{scopes} scopes, {frames} frames"
        );
    }
    let mut p = new(2, 2).unwrap();
    p.begin_frame();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let a = p.begin_scope(&mut encoder, "a");
    let b = p.begin_scope(&mut encoder, "b");
    // Over the bound: not timed, counted.
    let c = p.begin_scope(&mut encoder, "c");
    assert_eq!(p.dropped(), (1, 0));
    p.end_scope(&mut encoder, c).unwrap();
    // Out of order.
    assert!(p.end_scope(&mut encoder, a).is_err());
    // A scope still open at the frame's end: refused, the frame untimed.
    assert!(p.end_frame(&mut encoder).is_err());
    assert_eq!(p.dropped(), (1, 1));
    // Closing after the frame is gone records nothing.
    p.end_scope(&mut encoder, b).unwrap();
    ctx.queue.submit([encoder.finish()]);
    assert!(p.flush(&ctx.device).unwrap().is_empty());
}

/// `StepTimer`: in wall mode each step is timed by its submit and wait and nothing comes later;
/// in timestamp mode (forced, where the device has the queries) each frame's steps come back
/// later, one figure per step and frame, a step timed twice added up; a failing step is an
/// error with nothing submitted.
#[test]
fn the_step_timer_times_steps_in_either_mode() {
    use terrain_gpu::{StepTimer, TimingMode};
    let Some(ctx) = context_or_skip("the_step_timer_times_steps_in_either_mode") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let info = ctx.adapter.get_info();
    let buffer = work(&ctx);
    let clear = |e: &mut wgpu::CommandEncoder| {
        e.clear_buffer(&buffer, 0, None);
        Ok(())
    };
    let mut wall = StepTimer::new(&info, device, queue, Some(TimingMode::Wall));
    assert_eq!(wall.mode(), TimingMode::Wall);
    let span = wall.time(device, queue, "clear", clear).unwrap();
    assert!(span.wall_ms >= 0.0 && !span.includes_recording);
    wall.end_frame(device, queue).unwrap();
    assert!(wall.flush(device, queue).unwrap().is_empty());
    let failed = wall.time(device, queue, "fails", |_| {
        Err(GpuError::Unsupported {
            what: "a step",
            reason: "it fails",
        })
    });
    assert!(failed.is_err());
    let mut stamps = StepTimer::new(&info, device, queue, Some(TimingMode::Timestamps));
    if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
        assert_eq!(stamps.mode(), TimingMode::Wall, "no queries: wall time");
        return;
    }
    assert_eq!(stamps.mode(), TimingMode::Timestamps);
    for _ in 0..3 {
        for name in ["clear", "clear", "other"] {
            let span = stamps.time(device, queue, name, clear).unwrap();
            assert!(span.includes_recording && span.timestamp_ms.is_none());
        }
        stamps.end_frame(device, queue).unwrap();
    }
    let mut figures = stamps.poll(device).unwrap();
    figures.extend(stamps.flush(device, queue).unwrap());
    let frames: Vec<u64> = figures.iter().map(|f| f.frame).collect();
    assert_eq!(frames, [0, 0, 1, 1, 2, 2]);
    assert!(figures.iter().all(|f| f.ms.is_finite() && f.ms >= 0.0));
    assert!(figures.iter().step_by(2).all(|f| f.name == "clear"));
    ctx.check().unwrap();
}
