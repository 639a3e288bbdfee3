//! Image composition: the overview inset in each frame, and the thumbnails of `summary.png`
//! (drawn by `crate::summary`).

use glam::UVec2;
use terrain_core::Grid;

/// An RGBA8 image.
pub type Image = Grid<[u8; 4]>;

/// A box-filtered copy of `src` at `size` pixels.
pub fn downscale(src: &Image, size: UVec2) -> Image {
    // `size` is clamped to at least 1 x 1, so the grid is valid.
    let (sw, sh) = (src.width() as u64, src.height() as u64);
    let (dw, dh) = (u64::from(size.x.max(1)), u64::from(size.y.max(1)));
    let out = Grid::from_fn(dw as u32, dh as u32, |x, y| {
        let (x0, x1) = (
            u64::from(x) * sw / dw,
            ((u64::from(x) + 1) * sw / dw).max(u64::from(x) * sw / dw + 1),
        );
        let (y0, y1) = (
            u64::from(y) * sh / dh,
            ((u64::from(y) + 1) * sh / dh).max(u64::from(y) * sh / dh + 1),
        );
        let mut acc = [0u64; 4];
        let mut n = 0u64;
        for yy in y0..y1.min(sh) {
            for xx in x0..x1.min(sw) {
                let p = src.as_slice()[(yy * sw + xx) as usize];
                for c in 0..4 {
                    acc[c] += u64::from(p[c]);
                }
                n += 1;
            }
        }
        let n = n.max(1);
        [
            (acc[0] / n) as u8,
            (acc[1] / n) as u8,
            (acc[2] / n) as u8,
            (acc[3] / n) as u8,
        ]
    });
    out.unwrap_or_else(|_| src.clone())
}

/// Copies `src` into `dst` at `(x, y)`, clipped to `dst`.
pub fn blit(dst: &mut Image, src: &Image, x: u32, y: u32) {
    for sy in 0..src.height() {
        let dy = y + sy;
        if dy >= dst.height() {
            break;
        }
        let row = src.row(sy);
        let drow = dst.row_mut(dy);
        for (sx, p) in row.iter().enumerate() {
            let dx = x as usize + sx;
            if dx >= drow.len() {
                break;
            }
            drow[dx] = *p;
        }
    }
}

/// Fills a rectangle (clipped).
pub fn fill(dst: &mut Image, x: u32, y: u32, w: u32, h: u32, color: [u8; 4]) {
    for yy in y..(y + h).min(dst.height()) {
        let row = dst.row_mut(yy);
        for p in row.iter_mut().take((x + w) as usize).skip(x as usize) {
            *p = color;
        }
    }
}

/// Puts `overview` (already at its inset size) into the top-right corner of `frame` with a
/// one-pixel frame, and marks the camera at `camera_uv` (0..1 across the map) with a dot.
pub fn inset_overview(frame: &mut Image, overview: &Image, camera_uv: glam::Vec2) {
    let margin = 8;
    let x = frame.width().saturating_sub(overview.width() + margin);
    let y = margin;
    fill(
        frame,
        x.saturating_sub(1),
        y - 1,
        overview.width() + 2,
        overview.height() + 2,
        [20, 20, 20, 255],
    );
    blit(frame, overview, x, y);
    let uv = camera_uv - camera_uv.floor();
    let cx = x + (uv.x * overview.width() as f32) as u32;
    let cy = y + (uv.y * overview.height() as f32) as u32;
    fill(
        frame,
        cx.saturating_sub(2),
        cy.saturating_sub(2),
        5,
        5,
        [230, 30, 30, 255],
    );
}

/// The size of a thumbnail of an image of `size` pixels: the image's aspect, fitted into a
/// `side` x `side` square (never enlarged), at least 1 x 1. A long, thin frame makes a thin
/// thumbnail, not a tall one.
pub fn fit_within(size: UVec2, side: u32) -> UVec2 {
    let longest = size.max_element().max(1);
    if longest <= side {
        return size.max(UVec2::ONE);
    }
    let scaled = |v: u32| {
        ((u64::from(v) * u64::from(side) + u64::from(longest) / 2) / u64::from(longest)) as u32
    };
    UVec2::new(scaled(size.x), scaled(size.y)).max(UVec2::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thumbnails_fit_a_square_whatever_the_aspect() {
        assert_eq!(fit_within(UVec2::new(1280, 720), 320), UVec2::new(320, 180));
        assert_eq!(fit_within(UVec2::new(16, 8192), 320), UVec2::new(1, 320));
        assert_eq!(fit_within(UVec2::new(8192, 16), 320), UVec2::new(320, 1));
        assert_eq!(fit_within(UVec2::new(100, 50), 320), UVec2::new(100, 50));
        assert_eq!(fit_within(UVec2::new(1, 65536), 320), UVec2::new(1, 320));
    }
}
