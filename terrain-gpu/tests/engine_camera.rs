//! Engine cameras: every LOD mode draws an engine's own view and projection matrices into the
//! caller's pass as it draws a `Camera`, with reverse-Z and an infinite far plane, with a TAA
//! jitter, and orthographic; a view whose depth convention is not the target's is refused.

#[path = "common/scene.rs"]
#[allow(dead_code)] // the parts of the shared scene other tests use
mod scene;

use glam::camera::rh::proj::directx;
use glam::{UVec2, Vec3};
use scene::{HEIGHT, Scene};
use terrain_core::Grid;
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    Camera, ClipmapSurface, DepthConvention, GpuError, OffscreenTarget, RenderView, SkyColors,
    SkyPass, TargetFormat, TerrainFrame, TerrainRenderer, TerrainStyle, TerrainView, ViewMatrices,
};
use terrain_lod::{CdlodConfig, LodMetric, TessConfig};

const SIZE: UVec2 = UVec2::new(320, 180);

fn camera() -> Camera {
    Camera::looking(Vec3::new(60.0, 55.0, 70.0), Vec3::new(1.0, -0.45, 0.6))
}

/// The camera's own projection with reverse-Z and an infinite far plane (as Bevy makes it).
fn reverse_infinite(camera: &Camera) -> ViewMatrices {
    let aspect = SIZE.x as f32 / SIZE.y as f32;
    ViewMatrices {
        view: camera.view_matrix(),
        projection: directx::perspective_infinite_reverse(camera.fov_y, aspect, camera.near),
    }
}

/// The three modes over `scene`'s map, for `format`.
fn renderers(scene: &Scene, format: &TargetFormat) -> Vec<TerrainRenderer> {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let cdlod = CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 4,
        metric: LodMetric::Distance,
        ..CdlodConfig::default()
    };
    let tess = TessConfig {
        triangle_width_px: 6.0,
        ..TessConfig::default()
    };
    vec![
        TerrainRenderer::clipmap(device, format, scene.layout.clone(), (0.0, HEIGHT)).unwrap(),
        TerrainRenderer::cdlod(device, format, &scene.map, cdlod).unwrap(),
        TerrainRenderer::tessellated(device, queue, format, &scene.map, tess, true).unwrap(),
    ]
}

/// One frame of `renderer` seen by `view`: the sky and the terrain drawn into a pass the
/// caller begins over `target`, its depth cleared as `depth` wants.
fn draw(
    scene: &Scene,
    renderer: &mut TerrainRenderer,
    view: &dyn RenderView,
    depth: DepthConvention,
) -> Result<(TerrainFrame, Grid<[u8; 4]>), GpuError> {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let format = TargetFormat::CAPTURE.with_depth_convention(depth);
    let target = OffscreenTarget::new(device, SIZE)?;
    let sky = SkyPass::new(device, &format)?;
    sky.prepare(
        queue,
        view.projection_matrix(SIZE) * view.view_matrix(),
        &SkyColors::default(),
    )?;
    let style = TerrainStyle {
        ramp: (0.0, HEIGHT),
        ..TerrainStyle::default()
    };
    let terrain_view = TerrainView {
        surface: ClipmapSurface::Coarse {
            map: &scene.gpu_map,
            normals: &scene.normals,
        },
        camera: view,
        style: &style,
        target_size: SIZE,
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    renderer.prepare(device, queue, &mut encoder, &terrain_view)?;
    let frame = renderer.figures(&terrain_view)?;
    {
        // The caller's pass: its own clear values for its own convention.
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("caller's pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target.color_view(),
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: target.depth_view(),
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(depth.clear_depth()),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            ..Default::default()
        });
        sky.draw(&mut pass);
        renderer.draw(&mut pass);
    }
    queue.submit([encoder.finish()]);
    renderer.recall();
    let image = target.read_rgba8(device, queue)?;
    scene.ctx.check().expect("no GPU validation errors");
    Ok((frame, image))
}

/// Terrain pixels: sky pixels are blue over red by 43 (horizon) to 133 (zenith), lit terrain
/// is not (as in the render tests).
fn terrain_pixels(image: &Grid<[u8; 4]>) -> usize {
    image
        .as_slice()
        .iter()
        .filter(|p| i32::from(p[2]) - i32::from(p[0]) < 30)
        .count()
}

/// The mean largest-channel difference of `a` against `b` moved `shift` pixels right, and the
/// share of pixels differing by more than 24, over columns `margin ..` width − `margin`.
fn difference(a: &Grid<[u8; 4]>, b: &Grid<[u8; 4]>, shift: u32, margin: u32) -> (f64, f64) {
    let (mut sum, mut far, mut n) = (0.0, 0usize, 0usize);
    for y in 0..SIZE.y {
        for x in margin..SIZE.x - margin - shift {
            let (p, q) = (a.get(x + shift, y).unwrap(), b.get(x, y).unwrap());
            let d = (0..3)
                .map(|c| (i32::from(p[c]) - i32::from(q[c])).unsigned_abs())
                .max()
                .unwrap_or(0);
            sum += f64::from(d);
            far += usize::from(d > 24);
            n += 1;
        }
    }
    (sum / n as f64, far as f64 / n as f64)
}

/// Reverse-Z against forward depth of the same view: the projections' x, y and w rows are the
/// same numbers, so coverage is computed from the same values on any device; only depth
/// differs, which may reorder fragments of near-coincident surfaces (none in this scene but
/// at a few silhouette pixels). The share allows for those.
const DEPTH_SWAP_SHARE: f64 = 0.01;
/// A mean difference this small means the two images are the same picture.
const SAME_PICTURE_MEAN: f64 = 1.0;

#[test]
fn reverse_z_with_an_infinite_far_plane_draws_what_forward_depth_draws() {
    let Some(ctx) = context_or_skip("reverse-Z infinite far") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let camera = camera();
    let engine = reverse_infinite(&camera);
    let forward = renderers(&scene, &TargetFormat::CAPTURE);
    let reverse_format = TargetFormat::CAPTURE.with_depth_convention(DepthConvention::Reverse);
    let reverse = renderers(&scene, &reverse_format);
    for (mut f, mut r) in forward.into_iter().zip(reverse) {
        let (frame_f, image_f) = draw(&scene, &mut f, &camera, DepthConvention::Forward).unwrap();
        let (frame_r, image_r) = draw(&scene, &mut r, &engine, DepthConvention::Reverse).unwrap();
        let mode = frame_f.mode;
        let terrain = terrain_pixels(&image_r);
        assert!(
            terrain as f64 > 0.3 * f64::from(SIZE.x * SIZE.y),
            "{mode}: reverse-Z shows terrain ({terrain} pixels)"
        );
        // The LOD and the culling follow the projection: the same mesh either way (the far
        // plane at 30 km or at infinity culls nothing of a 256 m map). The two projections'
        // x scales are computed by different formulas, hence the rounding on the error.
        let counts = |f: &TerrainFrame| (f.mode, f.triangles, f.vertices);
        assert_eq!(counts(&frame_r), counts(&frame_f), "{mode}");
        let errors = (frame_r.max_screen_error_px, frame_f.max_screen_error_px);
        assert!(
            match errors {
                (Some(r), Some(f)) => (r - f).abs() <= 1e-5 * f.abs(),
                (r, f) => r == f,
            },
            "{mode}: {errors:?}"
        );
        let (mean, share) = difference(&image_r, &image_f, 0, 0);
        eprintln!(
            "{mode}: reverse vs forward mean {mean:.3}, {:.2} %",
            share * 100.0
        );
        assert!(
            mean <= SAME_PICTURE_MEAN && share <= DEPTH_SWAP_SHARE,
            "{mode}: reverse-Z differs from forward depth: mean {mean:.3}, share {share:.4}"
        );
        // A view with the other convention than the target's is refused, not drawn blank.
        let err = draw(&scene, &mut f, &engine, DepthConvention::Forward);
        assert!(
            matches!(err, Err(GpuError::DepthConventionMismatch { .. })),
            "{mode}: {err:?}"
        );
    }
}

/// How far apart a view and the same view jittered by one whole pixel may be once the image
/// is moved back: the clip-space x of every vertex moves by exactly 2 / width · w, which may
/// round differently at silhouettes (and the frustum's side planes move by a pixel, which the
/// margin leaves out).
const WHOLE_PIXEL_SHARE: f64 = 0.02;
const WHOLE_PIXEL_MEAN: f64 = 2.0;

#[test]
fn a_jittered_projection_moves_the_picture_and_nothing_else() {
    let Some(ctx) = context_or_skip("jittered projection") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    let camera = camera();
    let plain = ViewMatrices {
        view: camera.view_matrix(),
        projection: camera.projection_matrix(SIZE),
    };
    // TAA jitter in pixels, as an engine adds it: NDC x moves by −P[2][0] (z_view = −w).
    let jittered = |px: f32| {
        let mut projection = plain.projection;
        projection.z_axis.x -= 2.0 * px / SIZE.x as f32;
        ViewMatrices {
            projection,
            ..plain
        }
    };
    for mut renderer in renderers(&scene, &TargetFormat::CAPTURE) {
        let forward = DepthConvention::Forward;
        let (frame, image) = draw(&scene, &mut renderer, &plain, forward).unwrap();
        let (_, moved) = draw(&scene, &mut renderer, &jittered(1.0), forward).unwrap();
        let (_, half) = draw(&scene, &mut renderer, &jittered(0.5), forward).unwrap();
        let mode = frame.mode;
        let (mean, share) = difference(&moved, &image, 1, 8);
        eprintln!(
            "{mode}: 1 px jitter moved back: mean {mean:.3}, {:.2} %",
            share * 100.0
        );
        assert!(
            mean <= WHOLE_PIXEL_MEAN && share <= WHOLE_PIXEL_SHARE,
            "{mode}: a 1 px jitter is not a 1 px move: mean {mean:.3}, share {share:.4}"
        );
        // Half a pixel: a different picture (the jitter is applied), close to the plain one.
        let (mean, _) = difference(&half, &image, 0, 8);
        assert!(
            mean > 0.0 && mean < 8.0,
            "{mode}: half-pixel jitter mean {mean:.3}"
        );
    }
}

#[test]
fn an_orthographic_view_from_above_sees_only_terrain() {
    let Some(ctx) = context_or_skip("orthographic view") else {
        return;
    };
    let scene = Scene::new(ctx, 31, 5);
    // Straight down onto the middle of the map, 80 m x 45 m: no sky can show.
    let view = ViewMatrices {
        view: glam::camera::rh::view::look_to_mat4(
            Vec3::new(128.0, 300.0, 128.0),
            Vec3::NEG_Y,
            Vec3::Z,
        ),
        projection: directx::orthographic(-40.0, 40.0, -22.5, 22.5, 1.0, 1000.0),
    };
    for mut renderer in renderers(&scene, &TargetFormat::CAPTURE) {
        let (frame, image) = draw(&scene, &mut renderer, &view, DepthConvention::Forward).unwrap();
        let terrain = terrain_pixels(&image);
        assert!(
            terrain as f64 > 0.98 * f64::from(SIZE.x * SIZE.y),
            "{}: {terrain} terrain pixels from above",
            frame.mode
        );
        assert!(frame.triangles > 100, "{frame:?}");
    }
}
