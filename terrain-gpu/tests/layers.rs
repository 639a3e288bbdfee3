//! Layers drawn over a surface, in every LOD mode: a hole mask leaves its cells out (the whole
//! map's, and a window over a larger world), and a material layer's window shows its paint
//! where it covers the map and fades it out towards its edges.

#[path = "common/shading.rs"]
mod shading;

use glam::{UVec2, Vec2, Vec3};
use shading::*;
use terrain_core::{Grid, StampPlacement, WrapMode};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    GpuColorLayer, GpuError, GpuHoleMask, GpuMaterialLayer, GpuMaterials, SurfaceShading,
};

/// The whole map's hole mask with a 20 m disc cut from the lowland at (60, 128).
fn disc_mask() -> Grid<u8> {
    let mut mask = Grid::new(MAP, MAP, terrain_core::GROUND).expect("grid");
    let disc =
        StampPlacement::new(Vec2::new(60.0, 128.0), Vec2::splat(20.0), -1.0).expect("placement");
    terrain_core::apply_hole_stamp(
        &mut mask,
        WrapMode::Clamp,
        1.0,
        &disc,
        terrain_core::HoleOp::Cut,
    )
    .expect("cut");
    mask
}

#[test]
fn a_hole_shows_what_lies_behind_in_every_lod_mode_and_shading() {
    let Some(ctx) = context_or_skip("hole render") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    // A 20 m disc cut from the lowland at (60, 128), and one cell at (30, 100) alone.
    let mut mask = disc_mask();
    let holes =
        GpuHoleMask::new(device, queue, &Grid::new(MAP, MAP, 0u8).expect("grid")).expect("mask");
    // Uploaded by rect, as an engine updates it after a stamp: the disc's, then the cell's.
    *mask.get_mut(30, 100).expect("inside") = terrain_core::HOLE;
    holes
        .write(
            queue,
            &mask,
            terrain_core::Rect::new(glam::IVec2::new(48, 116), UVec2::splat(24)),
        )
        .expect("write");
    holes
        .write(
            queue,
            &mask,
            terrain_core::Rect::new(glam::IVec2::new(30, 100), UVec2::ONE),
        )
        .expect("write");
    // A rect off the mask and a mask of another size are refused.
    assert!(
        holes
            .write(
                queue,
                &mask,
                terrain_core::Rect::new(glam::IVec2::new(250, 0), UVec2::splat(8))
            )
            .is_err()
    );
    assert!(
        holes
            .write(
                queue,
                &Grid::new(8, 8, 0u8).expect("grid"),
                terrain_core::Rect::new(glam::IVec2::ZERO, UVec2::ONE)
            )
            .is_err()
    );
    let black = |c: Vec3| c.max_element() <= 1.0;
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer
            .set_materials(&GpuMaterials::new(device, queue, &solid_materials()).expect("upload"));
        for shading in [SurfaceShading::Materials, SurfaceShading::Ramp] {
            let whole = draw(&ctx, &mut renderer, &gpu, shading);
            assert!(
                !black(around(&whole, 60.0, 128.0, 3.0)),
                "{mode}: ground before the cut"
            );
            renderer.set_hole_mask(Some(&holes));
            let cut = draw(&ctx, &mut renderer, &gpu, shading);
            // The clear colour (black) shows through the disc, and through the lone cell's
            // middle (the pixel whose centre is at (30.8, 100.4)).
            let inside = around(&cut, 60.0, 128.0, 10.0);
            assert!(black(inside), "{mode} {shading:?}: the hole shows {inside}");
            let cell = around(&cut, 30.5, 100.5, 0.5);
            assert!(black(cell), "{mode} {shading:?}: the cut cell shows {cell}");
            // Ground beyond the disc, and beside the cell, is drawn as before.
            for (x, z) in [(60.0, 106.0), (84.0, 128.0), (33.5, 100.5), (30.5, 103.5)] {
                let before = around(&whole, x, z, 1.0);
                let after = around(&cut, x, z, 1.0);
                assert!(
                    (before - after).abs().max_element() <= 1.0,
                    "{mode} {shading:?}: ({x}, {z}) changed from {before} to {after}"
                );
            }
            renderer.set_hole_mask(None);
        }
    }
    // A mask of another size than the surface fails the prepare.
    let small =
        GpuHoleMask::new(device, queue, &Grid::new(8, 8, 0u8).expect("grid")).expect("mask");
    let mut renderer = renderers(&ctx, &map).remove(0);
    renderer.set_hole_mask(Some(&small));
    let err = try_prepare(&ctx, &mut renderer, &gpu).unwrap_err();
    assert!(
        matches!(
            err,
            GpuError::Core(terrain_core::CoreError::SizeMismatch { .. })
        ),
        "{err}"
    );
}

/// A renderer made to switch the LOD mode takes the layers of the one it replaces
/// (`adopt_layers`): the hole and the materials show in every mode; without it they do not.
#[test]
fn a_renderer_switching_the_lod_mode_keeps_the_layers() {
    let Some(ctx) = context_or_skip("adopt layers") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let mask = disc_mask();
    let holes = GpuHoleMask::new(device, queue, &mask).expect("mask");
    let materials = GpuMaterials::new(device, queue, &solid_materials()).expect("upload");
    let mut previous = renderers(&ctx, &map).remove(0);
    previous.set_hole_mask(Some(&holes));
    previous.set_materials(&materials);
    // A magenta colour layer over the whole map.
    let magenta = Grid::new(MAP, MAP, [255, 0, 255, 255]).expect("grid");
    let colors = GpuColorLayer::new(device, queue, &magenta).expect("layer");
    let mut coloured = renderers(&ctx, &map).remove(0);
    coloured.set_color_layer(Some(&colors));
    let black = |c: Vec3| c.max_element() <= 1.0;
    for (mut fresh, mut adopted) in renderers(&ctx, &map).into_iter().zip(renderers(&ctx, &map)) {
        let mode = adopted.mode();
        adopted.adopt_layers(&previous);
        let image = draw(&ctx, &mut adopted, &gpu, SurfaceShading::Materials);
        let inside = around(&image, 60.0, 128.0, 10.0);
        assert!(black(inside), "{mode}: the adopted hole shows {inside}");
        // The solid materials, not the procedural set a fresh renderer makes.
        let ground = around(&image, 84.0, 128.0, 1.0);
        let plain = draw(&ctx, &mut fresh, &gpu, SurfaceShading::Materials);
        assert!(
            !black(around(&plain, 60.0, 128.0, 3.0)),
            "{mode}: no hole without it"
        );
        let differs = (ground - around(&plain, 84.0, 128.0, 1.0))
            .abs()
            .max_element();
        assert!(
            differs > COLOUR_TOLERANCE,
            "{mode}: the materials were not adopted"
        );
        // The colour layer: magenta ground, no green in it.
        adopted.adopt_layers(&coloured);
        let image = draw(&ctx, &mut adopted, &gpu, SurfaceShading::Materials);
        let c = around(&image, 84.0, 128.0, 1.0);
        assert!(
            c.y < 0.5 * c.x && c.y < 0.5 * c.z,
            "{mode}: the colour layer shows {c}"
        );
        assert!(
            !black(around(&image, 60.0, 128.0, 3.0)),
            "{mode}: the hole went with it"
        );
    }
}

#[test]
fn a_hole_window_shows_its_holes_and_nothing_beyond_it() {
    let Some(ctx) = context_or_skip("hole window render") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    // The whole map's mask with the disc, as a streamed world stores it.
    let mask = disc_mask();
    let window = GpuHoleMask::window(device, 48).expect("window");
    assert!(window.is_window());
    assert_eq!(
        window.covered(),
        [0, 0, 0, 0],
        "covers nothing until placed"
    );
    let black = |c: Vec3| c.max_element() <= 1.0;
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_hole_mask(Some(&window));
        // Placed over the disc (its origin not a multiple of its side, so the cells wrap in
        // the texture): the disc shows through; then moved off it: ground again.
        for (origin, hole) in [
            (glam::IVec2::new(37, 101), true),
            (glam::IVec2::new(150, 20), false),
        ] {
            let region = mask
                .copy_rect(terrain_core::Rect::new(origin, UVec2::splat(48)))
                .expect("inside");
            window.move_window(queue, origin, &region).expect("move");
            let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
            let inside = around(&image, 60.0, 128.0, 10.0);
            assert_eq!(black(inside), hole, "{mode}: window at {origin}: {inside}");
            // Ground beside the disc is drawn wherever the window is.
            assert!(!black(around(&image, 84.0, 128.0, 1.0)), "{mode}");
        }
    }
    // A window placed over ground, then only the disc's rect rewritten (as after a cut).
    let mut renderer = renderers(&ctx, &map).remove(0);
    renderer.set_hole_mask(Some(&window));
    let origin = glam::IVec2::new(37, 101);
    window
        .move_window(queue, origin, &Grid::new(48, 48, 0u8).expect("grid"))
        .expect("move");
    let disc_rect = terrain_core::Rect::new(glam::IVec2::new(48, 116), UVec2::splat(24));
    let cut = mask.copy_rect(disc_rect).expect("inside");
    window
        .update_window(queue, disc_rect, &cut)
        .expect("update");
    let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
    let inside = around(&image, 60.0, 128.0, 8.0);
    assert!(black(inside), "an updated window shows {inside}");
    // A whole-map write to a window and a window move of another size are refused.
    let rect = terrain_core::Rect::new(glam::IVec2::ZERO, UVec2::ONE);
    assert!(window.write(queue, &mask, rect).is_err());
    let small = Grid::new(8, 8, 0u8).expect("grid");
    assert!(
        window
            .move_window(queue, glam::IVec2::ZERO, &small)
            .is_err()
    );
    let whole = GpuHoleMask::new(device, queue, &mask).expect("mask");
    assert!(whole.move_window(queue, glam::IVec2::ZERO, &mask).is_err());
    assert!(GpuHoleMask::window(device, 0).is_err());
}

#[test]
fn a_material_window_shows_its_paint_and_fades_it_towards_its_edges() {
    let Some(ctx) = context_or_skip("material window render") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let solid = GpuMaterials::new(device, queue, &solid_materials()).expect("upload");
    // The whole map's paint, as a streamed world's material tiles hold it: a 24 m disc of rock
    // at (60, 128), full at its middle.
    let mut paint = Grid::new(MAP, MAP, [0u8; 4]).expect("grid");
    let disc =
        StampPlacement::new(Vec2::new(60.0, 128.0), Vec2::splat(24.0), -1.0).expect("placement");
    let rock_effect = terrain_core::MaterialEffect::new(2, 1.0).expect("effect");
    terrain_core::apply_material_effect(&mut paint, WrapMode::Clamp, 1.0, &disc, &rock_effect)
        .expect("paint");
    let window = GpuMaterialLayer::window(device, queue, 128).expect("window");
    assert!(window.is_window());
    assert_eq!(window.covered(), [0, 0, 0, 0]);
    let l = Vec3::new(-0.8, 0.6, 0.0).normalize();
    let (grass, rock) = (lit(0, l.y), lit(2, l.y));
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_materials(&solid);
        renderer.set_material_layer(Some(&window));
        // Over the disc with 64 cells to spare (its origin not a multiple of its side, so the
        // cells wrap in the texture); off it; and with the disc's middle 4 cells inside the
        // window's edge, where the paint has faded to a quarter.
        for (origin, want) in [
            (glam::IVec2::new(5, 70), Some(rock)),
            (glam::IVec2::new(128, 0), Some(grass)),
            (glam::IVec2::new(56, 70), None),
        ] {
            let region = paint
                .copy_rect(terrain_core::Rect::new(origin, UVec2::splat(128)))
                .expect("inside");
            window.move_window(queue, origin, &region).expect("move");
            let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
            let centre = around(&image, 60.0, 128.0, 1.0);
            match want {
                Some(c) => assert!(
                    (centre - c).abs().max_element() <= COLOUR_TOLERANCE + 2.0,
                    "{mode}: window at {origin}: {centre}, not {c}"
                ),
                None => {
                    // A quarter of rock over grass: neither.
                    let quarter = grass * 0.75 + rock * 0.25;
                    assert!(
                        (centre - quarter).abs().max_element() <= 3.0 * COLOUR_TOLERANCE,
                        "{mode}: faded paint {centre}, not about {quarter}"
                    );
                }
            }
        }
    }
    // A window placed unpainted, then only the disc's rect rewritten (as after a crater):
    // the rock shows; a rect it does not cover changes nothing and is no error.
    let mut renderer = renderers(&ctx, &map).remove(0);
    renderer.set_materials(&solid);
    renderer.set_material_layer(Some(&window));
    let origin = glam::IVec2::new(5, 70);
    let blank = Grid::new(128, 128, [0u8; 4]).expect("grid");
    window.move_window(queue, origin, &blank).expect("move");
    let disc_rect = terrain_core::Rect::new(glam::IVec2::new(46, 114), UVec2::splat(28));
    let disc_paint = paint.copy_rect(disc_rect).expect("inside");
    window
        .update_window(queue, disc_rect, &disc_paint)
        .expect("update");
    let far = terrain_core::Rect::new(glam::IVec2::new(200, 0), UVec2::splat(28));
    window
        .update_window(queue, far, &disc_paint)
        .expect("outside the window: nothing");
    let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
    let centre = around(&image, 60.0, 128.0, 1.0);
    assert!(
        (centre - rock).abs().max_element() <= COLOUR_TOLERANCE + 2.0,
        "an updated window shows {centre}, not {rock}"
    );
    assert!(
        window.update_window(queue, disc_rect, &blank).is_err(),
        "another size"
    );
    // Effect passes and read-back refuse a window; a move of another size too.
    let mut effects = terrain_gpu::MaterialEffectPass::new(device).expect("pass");
    let mut encoder = device.create_command_encoder(&Default::default());
    let op = terrain_gpu::EffectOp {
        placement: disc,
        effect: rock_effect,
    };
    assert!(
        effects
            .encode(device, queue, &mut encoder, &window, &gpu.0, &op)
            .is_err()
    );
    assert!(window.read(device, queue).is_err());
    let small = Grid::new(8, 8, [0u8; 4]).expect("grid");
    assert!(
        window
            .move_window(queue, glam::IVec2::ZERO, &small)
            .is_err()
    );
    assert!(GpuMaterialLayer::window(device, queue, 0).is_err());
    let whole = GpuMaterialLayer::new(device, queue, &paint).expect("layer");
    assert!(whole.move_window(queue, glam::IVec2::ZERO, &paint).is_err());
}

#[test]
fn a_colour_window_colours_what_it_covers_and_fades_towards_its_edges() {
    let Some(ctx) = context_or_skip("colour window render") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = cliff_map();
    let gpu = upload(&ctx, &map);
    let solid = GpuMaterials::new(device, queue, &solid_materials()).expect("upload");
    // A streamed world's colour: opaque white over the lowland (x < 100), none beyond.
    let colors =
        Grid::from_fn(MAP, MAP, |x, _| if x < 100 { [255u8; 4] } else { [0; 4] }).expect("grid");
    let window = GpuColorLayer::window(device, queue, 128).expect("window");
    assert!(window.is_window());
    let l = Vec3::new(-0.8, 0.6, 0.0).normalize();
    let grass = lit(0, l.y);
    let white = Vec3::splat(255.0) * (0.28 + 0.8 * l.y);
    for mut renderer in renderers(&ctx, &map) {
        let mode = renderer.mode();
        renderer.set_materials(&solid);
        renderer.set_color_layer(Some(&window));
        // Over (60, 128) with room to spare; off it; and 4 cells inside the window's edge,
        // where the colour has faded to a quarter.
        for (origin, want) in [
            (glam::IVec2::new(5, 70), white.min(Vec3::splat(255.0))),
            (glam::IVec2::new(128, 0), grass),
            (
                glam::IVec2::new(56, 70),
                grass * 0.75 + white.min(Vec3::splat(255.0)) * 0.25,
            ),
        ] {
            let region = colors
                .copy_rect(terrain_core::Rect::new(origin, UVec2::splat(128)))
                .expect("inside");
            window.move_window(queue, origin, &region).expect("move");
            let image = draw(&ctx, &mut renderer, &gpu, SurfaceShading::Materials);
            let centre = around(&image, 60.0, 128.0, 1.0);
            assert!(
                (centre - want).abs().max_element() <= 3.0 * COLOUR_TOLERANCE,
                "{mode}: window at {origin}: {centre}, not about {want}"
            );
        }
    }
    let small = Grid::new(8, 8, [0u8; 4]).expect("grid");
    assert!(
        window
            .move_window(queue, glam::IVec2::ZERO, &small)
            .is_err()
    );
    assert!(GpuColorLayer::window(device, queue, 0).is_err());
    // A side beyond the device's textures is refused before anything is allocated.
    assert!(GpuColorLayer::window(device, queue, u32::MAX).is_err());
    assert!(GpuMaterialLayer::window(device, queue, u32::MAX).is_err());
    assert!(GpuHoleMask::window(device, u32::MAX).is_err());
    let whole = GpuColorLayer::new(device, queue, &colors).expect("layer");
    assert!(
        whole
            .move_window(queue, glam::IVec2::ZERO, &colors)
            .is_err()
    );
}

#[test]
fn a_hole_window_upload_places_and_updates_through_the_contract() {
    use terrain_core::HoleWindowTarget;
    let Some(ctx) = context_or_skip("hole window contract") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let window = GpuHoleMask::window(device, 32).expect("window");
    let mut target = terrain_gpu::HoleWindowUpload {
        queue,
        mask: &window,
    };
    let mask = Grid::new(32, 32, terrain_core::HOLE).expect("grid");
    target
        .place(glam::IVec2::new(100, 40), &mask)
        .expect("place");
    assert_eq!(window.covered(), [100, 40, 32, 32]);
    let rect = terrain_core::Rect::new(glam::IVec2::new(110, 50), UVec2::splat(4));
    let cut = Grid::new(4, 4, terrain_core::GROUND).expect("grid");
    target.update(rect, &cut).expect("update");
    // The window's own errors come back unchanged: a mask of another size than the window.
    let small = Grid::new(8, 8, 0u8).expect("grid");
    assert!(matches!(
        target.place(glam::IVec2::ZERO, &small),
        Err(GpuError::Core(_))
    ));
    assert_eq!(
        window.covered(),
        [100, 40, 32, 32],
        "a refused move moves nothing"
    );
    ctx.check().expect("no GPU error");
}
