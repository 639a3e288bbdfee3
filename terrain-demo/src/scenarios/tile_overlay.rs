//! The flyover's overview overlay: the tile cache's states per level over the hillshade and
//! the camera's view (Flower 2010, fig. 3.3 shows the same for its detail tiles). Level-0 tiles are
//! tinted by state; the tiles of coarser levels the cache holds are outlined, so every level
//! is visible at once; two lines from the camera show the horizontal field of view.
//!
//! Colours: queued or loading yellow, loaded (in RAM) green, active (in the VRAM atlas) blue,
//! dirty (changed, not yet written back) red; a failed tile magenta.

use crate::images::Image;
use glam::{UVec2, Vec2};
use terrain_cache::{CameraState, TileId, TileState, TileStatus};

/// Tint of a state (RGB), `None` for states not shown.
pub fn state_color(status: &TileStatus, active: bool) -> Option<[u8; 3]> {
    if status.dirty {
        return Some([220, 40, 40]);
    }
    Some(match status.state {
        TileState::Queued | TileState::Loading => [230, 200, 40],
        TileState::Failed => [220, 40, 220],
        TileState::Cancelled => return None,
        _ if active => [50, 110, 240],
        _ => [60, 190, 80],
    })
}

/// What the overlay draws.
pub struct OverlayInput<'a> {
    /// Level-0 texels of the world.
    pub world_size: UVec2,
    /// Tile side in texels.
    pub tile_size: u32,
    /// Metres per level-0 texel.
    pub texel_size: f32,
    /// The RAM pool's tiles and states.
    pub statuses: &'a [(TileId, TileStatus)],
    /// Whether a tile is in the VRAM atlas.
    pub active: &'a dyn Fn(TileId) -> bool,
    /// The camera, for the view lines.
    pub camera: Option<CameraState>,
}

/// `overview` (the whole world, top-down) with the tile states and the view drawn over it.
pub fn draw(overview: &Image, input: &OverlayInput<'_>) -> Image {
    let mut img = overview.clone();
    let px_per_texel = img.size().as_vec2() / input.world_size.as_vec2();
    // Coarsest first, so the finer outlines and the level-0 tints end on top.
    let mut tiles: Vec<&(TileId, TileStatus)> = input.statuses.iter().collect();
    tiles.sort_by_key(|(id, _)| std::cmp::Reverse(id.level));
    for (id, status) in tiles {
        let Some(color) = state_color(status, (input.active)(*id)) else {
            continue;
        };
        let side = (u64::from(input.tile_size) << id.level.min(32)) as f32;
        let min = Vec2::new(id.x as f32, id.y as f32) * side * px_per_texel;
        let max = min + Vec2::splat(side) * px_per_texel;
        if id.level == 0 {
            tint(&mut img, min, max, color, 0.45);
        } else {
            outline(&mut img, min, max, color);
        }
    }
    if let Some(cam) = input.camera {
        let eye = Vec2::new(cam.position.x, cam.position.z) / input.texel_size * px_per_texel;
        let fwd = Vec2::new(cam.forward.x, cam.forward.z).normalize_or(Vec2::X);
        let half = cam.half_fov_x() as f32;
        let reach = img.size().max_element() as f32 * 0.35;
        for angle in [-half, half] {
            let dir = Vec2::from_angle(angle).rotate(fwd);
            line(&mut img, eye, eye + dir * reach, [255, 255, 255]);
        }
    }
    img
}

/// Blends `color` into the pixels of `[min, max)` (pixel coordinates, clipped).
fn tint(img: &mut Image, min: Vec2, max: Vec2, color: [u8; 3], alpha: f32) {
    let (x0, y0, x1, y1) = clip(img, min, max);
    for y in y0..y1 {
        for p in &mut img.row_mut(y)[x0 as usize..x1 as usize] {
            for c in 0..3 {
                p[c] = (f32::from(p[c]) * (1.0 - alpha) + f32::from(color[c]) * alpha) as u8;
            }
        }
    }
}

/// A one-pixel frame around `[min, max)` (clipped).
fn outline(img: &mut Image, min: Vec2, max: Vec2, color: [u8; 3]) {
    let (x0, y0, x1, y1) = clip(img, min, max);
    if x1 <= x0 || y1 <= y0 {
        return;
    }
    let px = [color[0], color[1], color[2], 255];
    for x in x0..x1 {
        set(img, x, y0, px);
        set(img, x, y1 - 1, px);
    }
    for y in y0..y1 {
        set(img, x0, y, px);
        set(img, x1 - 1, y, px);
    }
}

/// A line from `a` to `b` (pixels), one sample per pixel of its length, clipped.
fn line(img: &mut Image, a: Vec2, b: Vec2, color: [u8; 3]) {
    let steps = (b - a).abs().max_element().ceil().clamp(1.0, 4096.0) as u32;
    for i in 0..=steps {
        let p = a.lerp(b, i as f32 / steps as f32);
        if p.x >= 0.0 && p.y >= 0.0 {
            set(
                img,
                p.x as u32,
                p.y as u32,
                [color[0], color[1], color[2], 255],
            );
        }
    }
}

fn set(img: &mut Image, x: u32, y: u32, px: [u8; 4]) {
    if let Some(p) = img.get_mut(x, y) {
        *p = px;
    }
}

/// `[min, max)` as whole pixels inside the image.
fn clip(img: &Image, min: Vec2, max: Vec2) -> (u32, u32, u32, u32) {
    let size = img.size().as_vec2();
    let lo = min.floor().clamp(Vec2::ZERO, size).as_uvec2();
    let hi = max.ceil().clamp(Vec2::ZERO, size).as_uvec2();
    (lo.x, lo.y, hi.x, hi.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use terrain_core::Grid;

    fn status(state: TileState, dirty: bool) -> TileStatus {
        TileStatus {
            state,
            dirty,
            writing: false,
            zero: false,
            stale: false,
        }
    }

    #[test]
    fn tiles_are_drawn_in_their_state_colours_where_they_lie() {
        let overview = Grid::new(64, 64, [0u8, 0, 0, 255]).expect("image");
        let statuses = [
            (TileId::new(0, 0, 0), status(TileState::Loaded, false)),
            (TileId::new(0, 1, 0), status(TileState::Queued, false)),
            (TileId::new(0, 2, 0), status(TileState::Loaded, true)),
            (TileId::new(0, 3, 0), status(TileState::Loaded, false)),
            (TileId::new(2, 1, 1), status(TileState::Loaded, false)),
        ];
        let active = |id: TileId| id == TileId::new(0, 3, 0);
        let img = draw(
            &overview,
            &OverlayInput {
                world_size: UVec2::splat(256),
                tile_size: 16,
                texel_size: 1.0,
                statuses: &statuses,
                active: &active,
                camera: Some(CameraState::at(Vec3::new(128.0, 10.0, 200.0))),
            },
        );
        // 4 pixels per level-0 tile; the tint is 45 % of the colour over black.
        let at = |x, y| img.get(x, y).expect("pixel");
        assert!(
            at(1, 1)[1] > at(1, 1)[0] && at(1, 1)[1] > at(1, 1)[2],
            "loaded: green"
        );
        assert!(
            at(5, 1)[0] > 80 && at(5, 1)[1] > 80 && at(5, 1)[2] < 40,
            "queued: yellow"
        );
        assert!(at(9, 1)[0] > at(9, 1)[1], "dirty: red");
        assert!(at(13, 1)[2] > at(13, 1)[1], "active: blue");
        // The level-2 tile (1, 1) spans pixels 16..32: outlined, not filled.
        assert_eq!(at(16, 20), [60, 190, 80, 255]);
        assert_eq!(at(20, 20), [0, 0, 0, 255]);
        // Untouched elsewhere, and the view lines start at the camera (32, 50).
        assert_eq!(at(60, 10), [0, 0, 0, 255]);
        assert_eq!(at(32, 50), [255, 255, 255, 255]);
    }

    #[test]
    fn extreme_ids_and_cameras_are_clipped_not_panics() {
        let overview = Grid::new(8, 8, [0u8; 4]).expect("image");
        let statuses = [
            (
                TileId::new(31, u32::MAX, u32::MAX),
                status(TileState::Loaded, false),
            ),
            (TileId::new(0, u32::MAX, 0), status(TileState::Loaded, true)),
        ];
        for pos in [Vec3::splat(1e30), Vec3::splat(-1e30), Vec3::ZERO] {
            let img = draw(
                &overview,
                &OverlayInput {
                    world_size: UVec2::splat(64),
                    tile_size: 8,
                    texel_size: 0.5,
                    statuses: &statuses,
                    active: &|_| false,
                    camera: Some(CameraState::at(pos)),
                },
            );
            assert_eq!(img.size(), UVec2::splat(8));
        }
    }
}
