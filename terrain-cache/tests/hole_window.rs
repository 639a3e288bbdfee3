//! `HoleWindow`: a streamed world's holes around the camera. The window is placed centred on
//! the camera (inside a clamped world) with the world's holes, stays put until the place it
//! should be is an eighth of its side away, takes the cuts in between by rect, and refuses a
//! camera that is not finite or a side out of range without changing anything; a target's
//! error comes back unchanged.

mod common;

use common::{encoding, test_map};
use glam::{IVec2, UVec2, Vec2};
use std::sync::Arc;
use terrain_cache::{
    HoleWindow, HoleWindowError, Manifest, MapSource, ObjectTileStore, TileStore, World,
    build_world, read_holes, write_holes,
};
use terrain_core::{Grid, HOLE, HoleWindowTarget, Rect, WrapMode};

const WORLD: u32 = 512;

fn world(wrap: WrapMode) -> World {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let size = UVec2::splat(WORLD);
    let map = test_map(size);
    let m = Manifest::new(size, 64, 1.0, encoding(), wrap).unwrap();
    build_world(store, m, &MapSource::new(&map), &|_| true)
        .unwrap()
        .0
}

/// A CPU stand-in for the GPU's window: the cells it holds, where, and how it was written.
#[derive(Default)]
struct Window {
    origin: Option<IVec2>,
    cells: Option<Grid<u8>>,
    places: u32,
    updates: u32,
    fail: bool,
}

impl HoleWindowTarget for Window {
    type Error = String;

    fn place(&mut self, origin: IVec2, mask: &Grid<u8>) -> Result<(), String> {
        if self.fail {
            return Err("refused".into());
        }
        self.origin = Some(origin);
        self.cells = Some(mask.clone());
        self.places += 1;
        Ok(())
    }

    fn update(&mut self, rect: Rect, mask: &Grid<u8>) -> Result<(), String> {
        if self.fail {
            return Err("refused".into());
        }
        let (origin, cells) = (self.origin.unwrap(), self.cells.as_mut().unwrap());
        for y in 0..rect.size.y {
            for x in 0..rect.size.x {
                let at = rect.min + IVec2::new(x as i32, y as i32) - origin;
                if let Some(c) = cells.get_mut(at.x as u32, at.y as u32)
                    && at.min_element() >= 0
                {
                    *c = mask.get(x, y).unwrap();
                }
            }
        }
        self.updates += 1;
        Ok(())
    }
}

/// Cuts a square hole of `side` cells at `min` into the world's files; returns the change as
/// an `OverlayWriter` reports it.
fn cut(world: &World, min: IVec2, side: u32) -> (Rect, Grid<u8>) {
    let rect = Rect::new(min, UVec2::splat(side));
    let mask = Grid::new(side, side, HOLE).unwrap();
    write_holes(world, rect, &mask).unwrap();
    (rect, mask)
}

#[test]
fn the_window_follows_the_camera_and_takes_the_cuts() {
    let world = world(WrapMode::Clamp);
    cut(&world, IVec2::new(200, 200), 4);
    let mut holes = HoleWindow::new(128).unwrap();
    let mut gpu = Window::default();
    assert!(holes.rect(&world).is_none());
    // Placed centred on the camera, with the world's holes.
    assert!(
        holes
            .follow(&world, Vec2::splat(210.0), &[], &mut gpu)
            .unwrap()
    );
    assert_eq!(gpu.origin, Some(IVec2::splat(146)));
    let rect = holes.rect(&world).unwrap();
    assert_eq!(
        gpu.cells.as_ref().unwrap(),
        &read_holes(&world, rect).unwrap()
    );
    assert_eq!(gpu.cells.as_ref().unwrap().get(54, 54).unwrap(), HOLE);
    // A step of less than an eighth of a side: the window stays; a cut goes in by its rect.
    let change = cut(&world, IVec2::new(220, 180), 3);
    let moved = holes.follow(&world, Vec2::splat(220.0), &[change], &mut gpu);
    assert!(!moved.unwrap());
    assert_eq!((gpu.places, gpu.updates), (1, 1));
    assert_eq!(
        gpu.cells.as_ref().unwrap(),
        &read_holes(&world, rect).unwrap()
    );
    // Further: placed again, where it should be, with every cut read from the world.
    assert!(
        holes
            .follow(&world, Vec2::splat(240.0), &[], &mut gpu)
            .unwrap()
    );
    assert_eq!(gpu.origin, Some(IVec2::splat(176)));
    let rect = holes.rect(&world).unwrap();
    assert_eq!(
        gpu.cells.as_ref().unwrap(),
        &read_holes(&world, rect).unwrap()
    );
    // At a clamped world's corner it stays inside, and stays put however far off the camera.
    for xz in [Vec2::splat(5000.0), Vec2::splat(1e30), Vec2::splat(-1e30)] {
        holes.follow(&world, xz, &[], &mut gpu).unwrap();
        let o = gpu.origin.unwrap();
        assert!(
            o.min_element() >= 0 && o.max_element() <= (WORLD - 128) as i32,
            "{o}"
        );
    }
    let places = gpu.places;
    holes
        .follow(&world, Vec2::splat(-1e30), &[], &mut gpu)
        .unwrap();
    assert_eq!(
        gpu.places, places,
        "a camera still off the corner moves nothing"
    );
}

#[test]
fn bad_input_and_a_failing_target_change_nothing() {
    let world = world(WrapMode::Clamp);
    for side in [0, 7, terrain_cache::MAX_HOLE_WINDOW_SIDE + 1] {
        assert!(HoleWindow::new(side).is_err(), "{side}");
    }
    let mut holes = HoleWindow::new(64).unwrap();
    let mut gpu = Window::default();
    for xz in [Vec2::new(f32::NAN, 1.0), Vec2::new(1.0, f32::INFINITY)] {
        let r = holes.follow(&world, xz, &[], &mut gpu);
        assert!(matches!(r, Err(HoleWindowError::Cache(_))), "{xz}");
    }
    gpu.fail = true;
    let r = holes.follow(&world, Vec2::splat(100.0), &[], &mut gpu);
    assert!(matches!(r, Err(HoleWindowError::Target(ref e)) if e == "refused"));
    assert!(holes.rect(&world).is_none(), "not placed");
    // A window wider than the world covers the world.
    let mut wide = HoleWindow::new(4096).unwrap();
    gpu.fail = false;
    wide.follow(&world, Vec2::splat(10.0), &[], &mut gpu)
        .unwrap();
    assert_eq!(
        wide.rect(&world),
        Some(Rect::from_size(UVec2::splat(WORLD)))
    );
}

#[test]
fn on_a_repeating_world_it_goes_anywhere_and_rereads_on_a_cut() {
    let world = world(WrapMode::Repeat);
    cut(&world, IVec2::new(10, 10), 2);
    let mut holes = HoleWindow::new(64).unwrap();
    let mut gpu = Window::default();
    // A camera periods away: the window wraps there, with the world's holes.
    let far = Vec2::splat(WORLD as f32 * 3.0 + 11.0);
    assert!(holes.follow(&world, far, &[], &mut gpu).unwrap());
    let rect = holes.rect(&world).unwrap();
    assert_eq!(
        gpu.cells.as_ref().unwrap(),
        &read_holes(&world, rect).unwrap()
    );
    assert!(gpu.cells.as_ref().unwrap().as_slice().contains(&HOLE));
    // A cut made now, a period away from the window: it is read again whole, the cut in it.
    let change = cut(&world, IVec2::new(20, 5), 2);
    assert!(holes.follow(&world, far, &[change], &mut gpu).unwrap());
    assert_eq!(gpu.updates, 0);
    let at = IVec2::new(20, 5) + IVec2::splat(WORLD as i32 * 3) - rect.min;
    assert_eq!(
        gpu.cells.as_ref().unwrap().get(at.x as u32, at.y as u32),
        Some(HOLE)
    );
    assert_eq!(
        gpu.cells.as_ref().unwrap(),
        &read_holes(&world, rect).unwrap()
    );
    // Absurd but finite cameras place it without overflow, where they are, with the holes.
    for xz in [Vec2::splat(f32::MAX), Vec2::splat(-f32::MAX)] {
        holes.follow(&world, xz, &[], &mut gpu).unwrap();
        let rect = holes.rect(&world).unwrap();
        assert_eq!(gpu.origin, Some(rect.min));
        let limit = i32::MAX / 2;
        assert!(rect.min.abs().max_element() >= limit - 64, "{rect:?}");
        assert_eq!(
            gpu.cells.as_ref().unwrap(),
            &read_holes(&world, rect).unwrap()
        );
    }
}

#[test]
fn the_window_moves_past_an_eighth_of_a_side_and_rereads_after_a_failed_cut() {
    let world = world(WrapMode::Clamp);
    let mut holes = HoleWindow::new(128).unwrap();
    let mut gpu = Window::default();
    holes
        .follow(&world, Vec2::splat(200.0), &[], &mut gpu)
        .unwrap();
    assert_eq!(gpu.origin, Some(IVec2::splat(136)));
    // Exactly an eighth (16 cells) off: it stays; one cell more: it moves.
    assert!(
        !holes
            .follow(&world, Vec2::new(216.0, 200.0), &[], &mut gpu)
            .unwrap()
    );
    assert!(
        holes
            .follow(&world, Vec2::new(217.0, 200.0), &[], &mut gpu)
            .unwrap()
    );
    assert_eq!(gpu.origin, Some(IVec2::new(153, 136)));
    // A move that also brings cuts reads them from the world with the rest.
    let change = cut(&world, IVec2::new(250, 150), 2);
    assert!(
        holes
            .follow(&world, Vec2::new(260.0, 200.0), &[change], &mut gpu)
            .unwrap()
    );
    assert_eq!(gpu.updates, 0);
    let rect = holes.rect(&world).unwrap();
    assert_eq!(
        gpu.cells.as_ref().unwrap(),
        &read_holes(&world, rect).unwrap()
    );
    // A cut the target refuses: the next call places the window again, the cut in it.
    let change = cut(&world, IVec2::new(255, 190), 3);
    gpu.fail = true;
    let r = holes.follow(&world, Vec2::new(260.0, 200.0), &[change], &mut gpu);
    assert!(matches!(r, Err(HoleWindowError::Target(_))));
    gpu.fail = false;
    assert!(
        holes
            .follow(&world, Vec2::new(260.0, 200.0), &[], &mut gpu)
            .unwrap()
    );
    assert_eq!(
        gpu.cells.as_ref().unwrap(),
        &read_holes(&world, rect).unwrap()
    );
    assert_eq!(
        gpu.cells
            .as_ref()
            .unwrap()
            .get(255 - 196, 190 - 136)
            .unwrap(),
        HOLE
    );
    // A move the target refuses, with a cut: the cut is not lost, the next call (the camera
    // where it is) places the window with it.
    let change = cut(&world, IVec2::new(300, 210), 2);
    gpu.fail = true;
    let r = holes.follow(&world, Vec2::new(300.0, 200.0), &[change], &mut gpu);
    assert!(matches!(r, Err(HoleWindowError::Target(_))));
    assert!(holes.rect(&world).is_none(), "to be placed again");
    gpu.fail = false;
    assert!(
        holes
            .follow(&world, Vec2::new(300.0, 200.0), &[], &mut gpu)
            .unwrap()
    );
    let rect = holes.rect(&world).unwrap();
    let at = IVec2::new(300, 210) - rect.min;
    assert_eq!(
        gpu.cells.as_ref().unwrap().get(at.x as u32, at.y as u32),
        Some(HOLE)
    );
}
