//! `summary.png`: thumbnails of the run with their frame numbers above a chart of every timed
//! step per frame (stacked, labelled axes, a legend with the step names, the warm-up frames
//! shaded). Drawn with plotters into our own RGB buffer; the font is embedded (DejaVu Sans),
//! so no system font is needed.

use crate::images::Image;
use crate::timings::Step;
use anyhow::{Context, Result, anyhow};
use plotters::prelude::*;
use std::sync::OnceLock;
use terrain_core::Grid;

/// Columns of thumbnails.
pub const COLUMNS: u32 = 4;
/// Thumbnails fit a square of this side, keeping the frame's aspect.
pub const THUMB_SIDE: u32 = 320;
/// The most thumbnails on the sheet.
pub const MAX_THUMBS: u32 = 12;
/// Pixels between thumbnails.
const GAP: u32 = 4;
/// Height of the frame-number line above each thumbnail.
const LABEL_HEIGHT: u32 = 20;
/// Height of the chart under the thumbnails.
pub const CHART_HEIGHT: u32 = 420;
/// The sheet's width.
pub const WIDTH: u32 = COLUMNS * (THUMB_SIDE + GAP) + GAP;
/// Width of the legend beside the chart.
const LEGEND_WIDTH: u32 = 250;
/// The colour of the warm-up frames' band.
const WARMUP_SHADE: RGBColor = RGBColor(225, 225, 225);
/// The most bars the chart draws: longer runs are averaged into this many buckets of frames
/// (about one bar per two pixels), so drawing time and memory do not grow with `--frames`.
const MAX_BARS: usize = 640;

/// The most bytes the sheet takes, whatever the run: the RGB buffer, its RGBA copy for the
/// encoder, the PNG (at most a little more than its pixels), the thumbnails.
pub const MAX_BYTES: u64 = {
    let rows = MAX_THUMBS.div_ceil(COLUMNS) as u64;
    let height = rows * (LABEL_HEIGHT + THUMB_SIDE + GAP) as u64 + GAP as u64 + CHART_HEIGHT as u64;
    let pixels = WIDTH as u64 * height;
    let thumbs = MAX_THUMBS as u64 * (THUMB_SIDE as u64) * (THUMB_SIDE as u64) * 4;
    (pixels * 3 + pixels * 4 * 2 + thumbs) * 5 / 4
};

/// Step colours, by position in [`Step::ALL`] (distinct at a glance, readable on white).
const PALETTE: [RGBColor; 14] = [
    RGBColor(214, 39, 40),
    RGBColor(255, 127, 14),
    RGBColor(31, 119, 180),
    RGBColor(23, 190, 207),
    RGBColor(44, 160, 44),
    RGBColor(152, 223, 138),
    RGBColor(227, 119, 194),
    RGBColor(140, 86, 75),
    RGBColor(148, 103, 189),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
    RGBColor(197, 176, 213),
    RGBColor(255, 187, 120),
    RGBColor(57, 59, 121),
];

/// One thumbnail and the frame it shows.
#[derive(Debug, Clone)]
pub struct Thumb {
    /// Frame number.
    pub frame: u32,
    /// The frame, downscaled.
    pub image: Image,
}

/// Milliseconds of one step in each frame (0 where the step did not run).
#[derive(Debug, Clone)]
pub struct Series {
    /// The step.
    pub step: Step,
    /// Per frame.
    pub ms: Vec<f64>,
}

/// Registers the embedded font once for the whole process.
fn font_ready() -> Result<()> {
    static FONT: OnceLock<bool> = OnceLock::new();
    let ok = *FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    ok.then_some(())
        .ok_or_else(|| anyhow!("the embedded chart font could not be loaded"))
}

/// The sheet: `thumbs` in [`COLUMNS`] columns (each with its frame number above it), then the
/// chart of `series` over `frames` frames, the first `warmup` of them shaded as warm-up.
pub fn render(thumbs: &[Thumb], series: &[Series], frames: usize, warmup: usize) -> Result<Image> {
    font_ready()?;
    let cell_w = thumbs.iter().map(|t| t.image.width()).max().unwrap_or(1);
    let cell_h = thumbs.iter().map(|t| t.image.height()).max().unwrap_or(0);
    let rows = (thumbs.len() as u32).div_ceil(COLUMNS);
    let top = if thumbs.is_empty() {
        0
    } else {
        rows * (LABEL_HEIGHT + cell_h + GAP) + GAP
    };
    let (w, h) = (WIDTH, top + CHART_HEIGHT);
    let mut rgb = vec![255u8; w as usize * h as usize * 3];
    // The thumbnails' band is dark, like a contact sheet.
    rgb[..w as usize * top as usize * 3].fill(36);
    for (i, t) in thumbs.iter().enumerate() {
        let (c, r) = (i as u32 % COLUMNS, i as u32 / COLUMNS);
        let x = GAP + c * (cell_w + GAP);
        let y = GAP + r * (LABEL_HEIGHT + cell_h + GAP) + LABEL_HEIGHT;
        blit_rgb(&mut rgb, w, &t.image, x, y);
    }
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let label = ("sans-serif", 15)
            .into_font()
            .color(&RGBColor(235, 235, 235));
        for (i, t) in thumbs.iter().enumerate() {
            let (c, r) = (i as u32 % COLUMNS, i as u32 / COLUMNS);
            let x = GAP + c * (cell_w + GAP);
            let y = GAP + r * (LABEL_HEIGHT + cell_h + GAP) + 2;
            root.draw(&Text::new(
                format!("frame {}", t.frame),
                (x as i32, y as i32),
                label.clone(),
            ))
            .map_err(|e| anyhow!("drawing a frame number: {e}"))?;
        }
        let (_, chart_area) = root.split_vertically(top);
        let (plot_area, legend_area) = chart_area.split_horizontally(WIDTH - LEGEND_WIDTH);
        draw_chart(&plot_area, series, frames, warmup)?;
        draw_legend(&legend_area, series, warmup)?;
        root.present()
            .map_err(|e| anyhow!("drawing summary.png: {e}"))?;
    }
    let rgba: Vec<[u8; 4]> = rgb
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2], 255])
        .collect();
    Grid::from_vec(w, h, rgba).context("summary.png's size")
}

/// The stacked chart of `series` per frame, bucketed to at most [`MAX_BARS`] bars.
fn draw_chart<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    series: &[Series],
    frames: usize,
    warmup: usize,
) -> Result<()> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing the timing chart: {e}");
    let frames = frames.max(1);
    let per_bar = frames.div_ceil(MAX_BARS).max(1);
    let bars = frames.div_ceil(per_bar);
    // Mean of each step over each bucket of frames.
    let bucketed: Vec<Vec<f64>> = series
        .iter()
        .map(|s| {
            (0..bars)
                .map(|b| {
                    let range = b * per_bar..((b + 1) * per_bar).min(frames);
                    let n = range.len().max(1) as f64;
                    range
                        .map(|i| s.ms.get(i).copied().unwrap_or(0.0))
                        .sum::<f64>()
                        / n
                })
                .collect()
        })
        .collect();
    let total = |b: usize| bucketed.iter().map(|s| s[b]).sum::<f64>();
    // The scale fits the frames after warm-up: a first frame that compiles shaders would
    // otherwise flatten every other bar. Warm-up bars taller than that are cut at the top.
    let first_measured = warmup.div_ceil(per_bar).min(bars.saturating_sub(1));
    let peak = (first_measured..bars).map(total).fold(0.0, f64::max);
    let y_max = if peak > 0.0 { peak * 1.15 } else { 1.0 };
    let x_max = (bars * per_bar) as f64;

    let mut chart = ChartBuilder::on(area)
        .caption(
            "Wall-clock time per frame, by step",
            ("sans-serif", 18).into_font(),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(if per_bar > 1 {
            format!("frame (each bar the mean of {per_bar} frames)")
        } else {
            "frame".to_string()
        })
        .y_desc("ms")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(err)?;
    if warmup > 0 {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(0.0, 0.0), (warmup as f64, y_max)],
                WARMUP_SHADE.filled(),
            )))
            .map_err(err)?;
    }
    let mut base = vec![0.0f64; bars];
    for (s, values) in series.iter().zip(&bucketed) {
        let color = color_of(s.step);
        let rects: Vec<_> = (0..bars)
            .filter(|&b| values[b] > 0.0)
            .map(|b| {
                let x0 = (b * per_bar) as f64;
                let x1 = x0 + per_bar as f64 * 0.85;
                let y0 = base[b].min(y_max);
                let y1 = (base[b] + values[b]).min(y_max);
                Rectangle::new([(x0, y0), (x1, y1)], color.filled())
            })
            .collect();
        for b in 0..bars {
            base[b] += values[b];
        }
        chart.draw_series(rects).map_err(err)?;
    }
    Ok(())
}

/// A step's colour.
fn color_of(step: Step) -> RGBColor {
    PALETTE[Step::ALL.iter().position(|x| *x == step).unwrap_or(0) % PALETTE.len()]
}

/// The legend: a swatch and the report key of each step (top of the stack first, as the bars
/// read), then the warm-up band.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    series: &[Series],
    warmup: usize,
) -> Result<()> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing the legend: {e}");
    let font = ("sans-serif", 14).into_font();
    let mut y = 48;
    let mut entry = |color: RGBColor, text: String| -> Result<()> {
        area.draw(&Rectangle::new([(8, y), (22, y + 14)], color.filled()))
            .map_err(err)?;
        area.draw(&Rectangle::new(
            [(8, y), (22, y + 14)],
            BLACK.stroke_width(1),
        ))
        .map_err(err)?;
        area.draw(&Text::new(text, (30, y), font.clone()))
            .map_err(err)?;
        y += 22;
        Ok(())
    };
    for s in series.iter().rev() {
        entry(color_of(s.step), s.step.name().to_string())?;
    }
    if warmup > 0 {
        entry(
            WARMUP_SHADE,
            format!(
                "warm-up: {warmup} frame{}",
                if warmup == 1 { "" } else { "s" }
            ),
        )?;
        area.draw(&Text::new("(not in steps_ms)", (30, y - 4), font.clone()))
            .map_err(err)?;
    }
    Ok(())
}

/// Copies an RGBA image into the RGB buffer of width `w` at `(x, y)`, clipped.
fn blit_rgb(rgb: &mut [u8], w: u32, src: &Image, x: u32, y: u32) {
    let h = (rgb.len() / 3 / w.max(1) as usize) as u32;
    for sy in 0..src.height() {
        let dy = y + sy;
        if dy >= h {
            break;
        }
        for (sx, p) in src.row(sy).iter().enumerate() {
            let dx = x as usize + sx;
            if dx >= w as usize {
                break;
            }
            let i = (dy as usize * w as usize + dx) * 3;
            rgb[i..i + 3].copy_from_slice(&p[..3]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(frames: usize) -> Vec<Series> {
        vec![
            Series {
                step: Step::StampGpu,
                ms: (0..frames).map(|i| 1.0 + (i % 3) as f64).collect(),
            },
            Series {
                step: Step::Render,
                ms: vec![4.0; frames],
            },
        ]
    }

    #[test]
    fn the_sheet_has_thumbnails_labels_and_a_chart() {
        let thumb = Grid::new(320, 180, [200u8, 10, 10, 255]).unwrap();
        let thumbs: Vec<_> = (0..5)
            .map(|i| Thumb {
                frame: i * 3,
                image: thumb.clone(),
            })
            .collect();
        let sheet = render(&thumbs, &series(15), 15, 2).unwrap();
        assert_eq!(sheet.width(), WIDTH);
        assert_eq!(
            sheet.height(),
            2 * (LABEL_HEIGHT + 180 + GAP) + GAP + CHART_HEIGHT
        );
        // A thumbnail in its colour, under its label band.
        assert_eq!(
            sheet.get(GAP + 10, GAP + LABEL_HEIGHT + 10),
            Some([200, 10, 10, 255])
        );
        // The frame number is drawn in the label band (light text on the dark band).
        let band: Vec<_> = (GAP..GAP + 80)
            .flat_map(|x| (GAP..GAP + LABEL_HEIGHT).map(move |y| (x, y)))
            .filter_map(|(x, y)| sheet.get(x, y))
            .collect();
        assert!(band.iter().any(|p| p[0] > 150), "no label text");
        // The chart has the stacked colours of both steps.
        let chart: Vec<_> =
            sheet.as_slice()[(sheet.width() * (sheet.height() - CHART_HEIGHT)) as usize..].to_vec();
        let has = |c: RGBColor| chart.iter().any(|p| p[..3] == [c.0, c.1, c.2]);
        assert!(has(PALETTE[0]), "stamp_gpu bars");
        assert!(has(PALETTE[10]), "render bars");
    }

    #[test]
    fn long_runs_draw_a_bounded_chart() {
        // 100 000 frames are averaged into at most MAX_BARS bars: same sheet size, no thumbs.
        let sheet = render(&[], &series(100_000), 100_000, 3).unwrap();
        assert_eq!(sheet.size(), glam::UVec2::new(WIDTH, CHART_HEIGHT));
        let empty = render(&[], &[], 0, 0).unwrap();
        assert_eq!(empty.size(), glam::UVec2::new(WIDTH, CHART_HEIGHT));
    }

    #[test]
    fn the_bound_covers_the_largest_sheet() {
        let rows = u64::from(MAX_THUMBS.div_ceil(COLUMNS));
        let h = rows * u64::from(LABEL_HEIGHT + THUMB_SIDE + GAP) + u64::from(GAP + CHART_HEIGHT);
        assert!(MAX_BYTES >= u64::from(WIDTH) * h * 7);
    }
}
