//! Image composition for the report: the overview inset in each frame, the contact sheet and
//! the timing plot of `summary.png`.

use anyhow::Result;
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

/// Series colours of the timing plot.
pub const SERIES_COLORS: [[u8; 4]; 6] = [
    [220, 80, 60, 255],
    [60, 140, 220, 255],
    [80, 180, 90, 255],
    [200, 160, 40, 255],
    [150, 90, 200, 255],
    [90, 90, 90, 255],
];

/// A stacked bar chart: one bar per frame, one colour per series (ms); a legend strip of the
/// series colours in order runs along the left edge.
pub fn timing_plot(series: &[Vec<f64>], size: UVec2) -> Result<Image> {
    let mut img = Grid::new(size.x, size.y, [250, 250, 250, 255])?;
    let frames = series.iter().map(Vec::len).max().unwrap_or(0);
    if frames == 0 {
        return Ok(img);
    }
    let totals: Vec<f64> = (0..frames)
        .map(|i| {
            series
                .iter()
                .map(|s| s.get(i).copied().unwrap_or(0.0))
                .sum()
        })
        .collect();
    let max = totals.iter().copied().fold(1e-9, f64::max);
    let left = 12u32;
    let width = size.x.saturating_sub(left + 4).max(1);
    let height = size.y.saturating_sub(8).max(1);
    for (k, _) in series.iter().enumerate() {
        fill(
            &mut img,
            2,
            4 + k as u32 * 10,
            6,
            8,
            SERIES_COLORS[k % SERIES_COLORS.len()],
        );
    }
    for i in 0..frames {
        let x0 = left + (i as u32 * width) / frames as u32;
        let x1 = (left + ((i as u32 + 1) * width) / frames as u32).max(x0 + 1);
        let mut base = 0.0;
        for (k, s) in series.iter().enumerate() {
            let v = s.get(i).copied().unwrap_or(0.0);
            let y_top = size.y - 4 - ((base + v) / max * f64::from(height)) as u32;
            let y_bot = size.y - 4 - (base / max * f64::from(height)) as u32;
            fill(
                &mut img,
                x0,
                y_top,
                (x1 - x0).saturating_sub(1).max(1),
                y_bot.saturating_sub(y_top),
                SERIES_COLORS[k % SERIES_COLORS.len()],
            );
            base += v;
        }
    }
    Ok(img)
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

/// A contact sheet: `thumbs` (already downscaled, see [`fit_within`]) in `columns` columns,
/// each in a cell the size of the largest, with the timing plot below.
pub fn contact_sheet(thumbs: &[Image], columns: u32, plot: &Image) -> Result<Image> {
    if thumbs.is_empty() {
        return Ok(plot.clone());
    }
    let tw = thumbs.iter().map(Grid::width).max().unwrap_or(1);
    let th = thumbs.iter().map(Grid::height).max().unwrap_or(1);
    let columns = columns.max(1);
    let rows = (thumbs.len() as u32).div_ceil(columns);
    let gap = 4;
    let width = (columns * (tw + gap) + gap).max(plot.width() + 2 * gap);
    let height = rows * (th + gap) + gap + plot.height() + gap;
    let mut sheet = Grid::new(width, height, [32, 32, 36, 255])?;
    for (i, t) in thumbs.iter().enumerate() {
        let (c, r) = (i as u32 % columns, i as u32 / columns);
        blit(&mut sheet, t, gap + c * (tw + gap), gap + r * (th + gap));
    }
    blit(&mut sheet, plot, gap, gap + rows * (th + gap));
    Ok(sheet)
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

    #[test]
    fn a_sheet_of_thin_frames_stays_small() {
        // Twelve thumbnails of 16 x 8192 frames (the old sheet scaled each to 320 pixels wide:
        // 163 840 tall).
        let frame = Grid::new(16, 8192, [200u8, 10, 10, 255]).unwrap();
        let thumb = downscale(&frame, fit_within(frame.size(), 320));
        let thumbs = vec![thumb; 12];
        let plot = Grid::new(1292, 160, [250u8, 250, 250, 255]).unwrap();
        let sheet = contact_sheet(&thumbs, 4, &plot).unwrap();
        assert!(
            sheet.width() <= 1300 && sheet.height() <= 3 * 324 + 168,
            "{}",
            sheet.size()
        );
        // The thumbnails are on it, in their colour.
        assert_eq!(sheet.get(4, 4), Some([200, 10, 10, 255]));
    }
}
