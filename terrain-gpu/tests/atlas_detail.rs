//! A streamed world's atlas drawn with a detail layer (`ClipmapSurface::AtlasDetail`) under the
//! clipmap, CDLOD and the streamed tessellation: the footprints pressed into the detail tiles
//! change the frame as they do over a coarse-map, a layer faded out before the nearest fragment
//! leaves the frame of the bare atlas, and a layer that does not lie over the world is refused;
//! refined geometry (`--detail refine`) over a fully resident atlas is the coarse-map's, bit for
//! bit (the same stored heights read through the tile table). On whatever adapter the machine has
//! (lavapipe in CI); without one they skip, or fail under `TERRAIN_REQUIRE_GPU=1`.
//!
//! Tolerances (`common/footprints.rs`, shared with `detail_lod.rs`): the atlas and
//! atlas-with-detail pipelines are two shader modules of the same fragment code; with nothing added by the layer they compute
//! the same colour, up to a driver contracting the two modules' arithmetic differently (one
//! 8-bit step). The footprints are 30 cm deep at 3 m from the camera: they must move many
//! pixels a lot, whatever the rasterizer.

#[path = "common/footprints.rs"]
mod footprints;
#[path = "common/scene.rs"]
#[allow(dead_code)] // the golden view's parts of the shared scene
mod scene;

use footprints::{assert_footprints_show, camera, cdlod_for, faded_shading, scene_with_footprints};
use glam::{UVec2, Vec2};
use scene::Scene;
use terrain_core::detail::DetailLayout;
use terrain_core::{Grid, TileLayout, TileUploadTarget, WrapMode};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    AtlasConfig, Camera, CdlodDraw, CdlodRenderer, ClipmapSurface, ClipmapView, DetailShading,
    GpuDetailTiles, GpuError, GpuTessellation, GpuTileAtlas, OffscreenTarget, RefineDraw,
    RefinePass, RefineRenderer, SkyColors, TargetFormat, TerrainStyle, TessDraw, TessRenderer,
    TessWorld, TessellationPass,
};
use terrain_lod::{CdlodConfig, CdlodTree, CdlodView, Frustum, StreamedTessellation, TessConfig};

const SIZE: UVec2 = UVec2::new(256, 160);
const TILE: u32 = 32;

/// The scene's map as a world of 32-texel tiles, every level-0 tile resident (so every texel
/// reads the map itself).
fn full_atlas(scene: &Scene) -> GpuTileAtlas {
    let world = TileLayout {
        world_size: scene.map.size(),
        tile_size: TILE,
        levels: 4,
        texel_size: scene.map.texel_size(),
        encoding: scene.map.encoding(),
        wrap: WrapMode::Clamp,
        fill: 0,
    };
    let tiles = scene.map.size() / TILE;
    let config = AtlasConfig {
        slots: tiles.x * tiles.y,
        world,
    };
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let mut atlas = GpuTileAtlas::new(device, queue, &config).unwrap();
    for y in 0..tiles.y {
        for x in 0..tiles.x {
            let t = UVec2::new(x, y);
            let tile = Grid::from_fn(TILE, TILE, |i, j| {
                scene.map.grid().get(x * TILE + i, y * TILE + j).unwrap()
            })
            .unwrap();
            let slot = y * tiles.x + x;
            atlas.upload(slot, 0, t, &tile).unwrap();
            atlas.map(0, t, Some(slot)).unwrap();
        }
    }
    atlas
}

/// Which renderer draws the frame.
enum Lod {
    Clipmap,
    Cdlod(Box<(CdlodTree, CdlodRenderer)>),
    Tessellated(Box<Tessellated>),
}

/// A streamed tessellation of the scene's world and what draws it.
struct Tessellated {
    tess: StreamedTessellation,
    gpu: GpuTessellation,
    pass: TessellationPass,
    renderer: TessRenderer,
}

fn tessellated_for(scene: &Scene) -> Tessellated {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let enc = scene.map.encoding();
    let config = CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 5,
        ..CdlodConfig::default()
    };
    let bounds = terrain_test_support::heights::exact_bounds(&scene.map);
    let tree = CdlodTree::from_leaf_bounds(config, scene.map.size(), 1.0, bounds).unwrap();
    let tess = StreamedTessellation::new(TessConfig::default(), &tree).unwrap();
    Tessellated {
        gpu: GpuTessellation::streamed(device, queue, &tess, &tree, enc, 1 << 20).unwrap(),
        tess,
        pass: TessellationPass::new(device).unwrap(),
        renderer: TessRenderer::new(device, &TargetFormat::CAPTURE).unwrap(),
    }
}

/// One frame of `camera` over `surface` with `lod`.
fn render(
    scene: &mut Scene,
    lod: &mut Lod,
    surface: ClipmapSurface<'_>,
    camera: &Camera,
) -> Result<Grid<[u8; 4]>, GpuError> {
    let (device, queue) = (&scene.ctx.device, &scene.ctx.queue);
    let aspect = SIZE.x as f32 / SIZE.y as f32;
    let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
    let style = TerrainStyle {
        ramp: (0.0, scene::HEIGHT),
        ..TerrainStyle::default()
    };
    scene.sky.prepare(
        queue,
        camera.view_proj_relative(aspect),
        &SkyColors::default(),
    )?;
    let target = OffscreenTarget::new(device, SIZE)?;
    let mut encoder = device.create_command_encoder(&Default::default());
    match lod {
        Lod::Clipmap => {
            let eye = Vec2::new(camera.position.x, camera.position.z);
            let frame = scene
                .layout
                .place(eye, 1.0, (0.0, scene::HEIGHT), Some(&frustum))
                .unwrap();
            let view = ClipmapView {
                surface,
                frame: &frame,
                camera,
                style: &style,
                target_size: SIZE,
            };
            scene.renderer.prepare(device, queue, &view)?;
            let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
            scene.sky.draw(&mut pass);
            scene.renderer.draw(&mut pass);
        }
        Lod::Cdlod(parts) => {
            let (tree, renderer) = &mut **parts;
            let view = CdlodView {
                camera: camera.position,
                frustum: Some(&frustum),
                viewport_width: SIZE.x as f32,
                hfov: 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan(),
            };
            let frame = tree.select(&view).unwrap();
            let draw = CdlodDraw {
                surface,
                frame: &frame,
                camera,
                style: &style,
                target_size: SIZE,
            };
            renderer.prepare(device, queue, &draw)?;
            let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
            scene.sky.draw(&mut pass);
            renderer.draw(&mut pass);
        }
        Lod::Tessellated(t) => {
            let (ClipmapSurface::Atlas { atlas } | ClipmapSurface::AtlasDetail { atlas, .. }) =
                surface
            else {
                unreachable!("the tessellation draws the atlas")
            };
            let view = CdlodView {
                camera: camera.position,
                frustum: Some(&frustum),
                viewport_width: SIZE.x as f32,
                hfov: 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan(),
            };
            t.pass.encode_streamed(
                device,
                queue,
                &mut encoder,
                &t.gpu,
                &TessWorld {
                    tess: &t.tess,
                    atlas,
                },
                &view,
            )?;
            let draw = TessDraw {
                surface,
                camera,
                style: &style,
                target_size: SIZE,
            };
            t.renderer.prepare(device, queue, &draw)?;
            let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
            scene.sky.draw(&mut pass);
            t.renderer.draw(&mut pass, &t.gpu);
        }
    }
    queue.submit([encoder.finish()]);
    if let Lod::Tessellated(t) = lod {
        t.pass.recall();
    }
    let image = target.read_rgba8(device, queue)?;
    scene.ctx.check().expect("no GPU validation errors");
    Ok(image)
}

fn footprints_show_on_the_atlas(name: &str, make: impl Fn(&Scene) -> Lod) {
    let Some(ctx) = context_or_skip(name) else {
        return;
    };
    let (mut scene, _) = scene_with_footprints(ctx, 128);
    let atlas = full_atlas(&scene);
    let mut lod = make(&scene);
    let cam = camera(&scene);
    let (tiles, shading) = scene.detail.take().unwrap();
    let with_detail = ClipmapSurface::AtlasDetail {
        atlas: &atlas,
        detail: &tiles,
        shading: &shading,
    };
    let detailed = render(&mut scene, &mut lod, with_detail, &cam).unwrap();
    let bare = render(
        &mut scene,
        &mut lod,
        ClipmapSurface::Atlas { atlas: &atlas },
        &cam,
    )
    .unwrap();
    let faded = faded_shading();
    let far = ClipmapSurface::AtlasDetail {
        atlas: &atlas,
        detail: &tiles,
        shading: &faded,
    };
    let far = render(&mut scene, &mut lod, far, &cam).unwrap();
    assert_footprints_show(name, &detailed, &bare, &far);
}

#[test]
fn clipmap_draws_footprints_on_a_streamed_world() {
    footprints_show_on_the_atlas("atlas_detail_clipmap", |_| Lod::Clipmap);
}

#[test]
fn cdlod_draws_footprints_on_a_streamed_world() {
    footprints_show_on_the_atlas("atlas_detail_cdlod", |scene| {
        Lod::Cdlod(Box::new(cdlod_for(scene)))
    });
}

#[test]
fn the_streamed_tessellation_draws_footprints_on_a_streamed_world() {
    footprints_show_on_the_atlas("atlas_detail_tessellated", |scene| {
        Lod::Tessellated(Box::new(tessellated_for(scene)))
    });
}

#[test]
fn a_layer_that_does_not_lie_over_the_world_is_refused() {
    let Some(ctx) = context_or_skip("atlas_detail_refused") else {
        return;
    };
    let mut scene = Scene::new(ctx, 31, 5);
    let atlas = full_atlas(&scene);
    let cam = camera(&scene);
    let shading = DetailShading::default();
    // Half the world's size, then the right size at another spacing.
    for (size, texel) in [(UVec2::splat(128), 1.0), (UVec2::splat(256), 0.5)] {
        let layout = DetailLayout::new(size, texel, 8, 128).unwrap();
        let tiles = GpuDetailTiles::new(&scene.ctx.device, layout, 2).unwrap();
        let surface = ClipmapSurface::AtlasDetail {
            atlas: &atlas,
            detail: &tiles,
            shading: &shading,
        };
        let err = render(&mut scene, &mut Lod::Clipmap, surface, &cam).unwrap_err();
        assert!(
            matches!(
                err,
                GpuError::SizeMismatch { .. } | GpuError::Unsupported { .. }
            ),
            "{size} at {texel} m: {err}"
        );
    }
}

#[test]
fn refined_geometry_over_a_full_atlas_is_the_coarse_maps() {
    let Some(ctx) = context_or_skip("atlas_detail_refine") else {
        return;
    };
    let (mut scene, _) = scene_with_footprints(ctx, 128);
    let atlas = full_atlas(&scene);
    let (tiles, _) = scene.detail.take().unwrap();
    let shading = DetailShading {
        parallax_steps: 0,
        ..DetailShading::default()
    };
    let cam = camera(&scene);
    let style = TerrainStyle::default();
    let (device, queue) = (scene.ctx.device.clone(), scene.ctx.queue.clone());
    let mut pass = RefinePass::new(&device, 16).unwrap();
    let mut renderer = RefineRenderer::new(&device, &TargetFormat::CAPTURE).unwrap();
    let target = OffscreenTarget::new(&device, SIZE).unwrap();
    let mut refine = |surface: ClipmapSurface<'_>| {
        let draw = RefineDraw {
            surface,
            radius_m: 6.0,
            camera: &cam,
            style: &style,
            target_size: SIZE,
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        pass.encode(&device, &queue, &mut encoder, &draw).unwrap();
        renderer.prepare(&device, &queue, &draw, &pass).unwrap();
        {
            let mut rp = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
            renderer.draw(&mut rp, &pass);
        }
        queue.submit([encoder.finish()]);
        let (mut tris, overflow) = pass.read_triangles(&device, &queue).unwrap();
        assert!(!overflow);
        // In no particular order: sorted by their bits.
        let key = |t: &[glam::Vec3; 3]| t.map(|v| v.to_array().map(f32::to_bits));
        tris.sort_by_key(key);
        tris.iter().map(key).collect::<Vec<_>>()
    };
    let coarse = refine(ClipmapSurface::Detail {
        map: &scene.gpu_map,
        normals: &scene.normals,
        detail: &tiles,
        shading: &shading,
    });
    let from_atlas = refine(ClipmapSurface::AtlasDetail {
        atlas: &atlas,
        detail: &tiles,
        shading: &shading,
    });
    // The footprints are within the radius: cells are split (2 x 12^2 = 288 unsplit).
    assert!(coarse.len() > 400, "{} triangles", coarse.len());
    assert_eq!(coarse.len(), from_atlas.len());
    assert!(coarse == from_atlas, "the atlas refines other triangles");
    // A surface without detail has nothing to refine.
    let bare = RefineDraw {
        surface: ClipmapSurface::Atlas { atlas: &atlas },
        radius_m: 6.0,
        camera: &cam,
        style: &style,
        target_size: SIZE,
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    let err = pass
        .encode(&device, &queue, &mut encoder, &bare)
        .unwrap_err();
    assert!(matches!(err, GpuError::Unsupported { .. }), "{err}");
    scene.ctx.check().expect("no GPU validation errors");
}
