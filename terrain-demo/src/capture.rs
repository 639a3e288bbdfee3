//! Writing a run's captures: each frame's PNG, thumbnails for the contact sheet, timing totals,
//! and at the end `summary.png` and `report.json`.

use crate::images::{self, Image};
use crate::report::{FrameReport, Report};
use crate::timings::{Step, Timings};
use anyhow::{Context, Result};
use glam::UVec2;
use std::collections::BTreeMap;
use std::path::Path;
use terrain_core::io;

/// Steps shown in the timing plot of `summary.png`, bottom to top.
const PLOTTED: [Step; 5] = [
    Step::Stamp,
    Step::Normals,
    Step::Render,
    Step::Capture,
    Step::Write,
];

/// Collects a run's frames.
pub struct Capture<'a> {
    out: &'a Path,
    frames: Vec<FrameReport>,
    thumbs: Vec<Image>,
    thumb_every: u32,
    total: u32,
}

impl<'a> Capture<'a> {
    /// A capture of `total` frames into `out`.
    pub fn new(out: &'a Path, total: u32) -> Self {
        Self {
            out,
            frames: Vec::with_capacity(total as usize),
            thumbs: Vec::new(),
            thumb_every: total.div_ceil(12).max(1),
            total,
        }
    }

    /// Writes `image` as the next frame and records `frame` with `timings` (its `index`, `file`
    /// and timings are filled in here, the `write` step included).
    pub fn push(
        &mut self,
        image: &Image,
        mut frame: FrameReport,
        mut timings: Timings,
    ) -> Result<()> {
        let index = self.frames.len() as u32;
        let file = format!("frame_{index:04}.png");
        let path = self.out.join(&file);
        timings
            .time(Step::Write, || io::write_png_rgba8(&path, image))
            .with_context(|| format!("writing {}", path.display()))?;
        frame.index = index;
        frame.file = file;
        frame.timings_ms = timings.wall_by_name();
        frame.gpu_timestamps_ms = timings.gpu_by_name();
        if index % self.thumb_every == self.thumb_every - 1 || index + 1 == self.total {
            let w = 320.min(image.width());
            let h = (u64::from(image.height()) * u64::from(w) / u64::from(image.width())) as u32;
            self.thumbs
                .push(images::downscale(image, UVec2::new(w, h.max(1))));
        }
        self.frames.push(frame);
        Ok(())
    }

    /// Writes `summary.png` and `report.json` (with the frames and their totals) and returns
    /// the report.
    pub fn finish(self, mut report: Report) -> Result<Report> {
        let series: Vec<Vec<f64>> = PLOTTED
            .iter()
            .map(|step| {
                self.frames
                    .iter()
                    .map(|f| f.timings_ms.get(step.name()).copied().unwrap_or(0.0))
                    .collect()
            })
            .collect();
        let columns = 4;
        let plot = images::timing_plot(&series, UVec2::new(columns * 324 - 4, 160))?;
        let sheet = images::contact_sheet(&self.thumbs, columns, 320, &plot)?;
        io::write_png_rgba8(self.out.join("summary.png"), &sheet)?;
        let mut totals: BTreeMap<&'static str, f64> = BTreeMap::new();
        for f in &self.frames {
            for (k, v) in &f.timings_ms {
                *totals.entry(*k).or_default() += v;
            }
        }
        report.frames = self.frames;
        report.totals_ms = totals;
        let json = serde_json::to_vec_pretty(&report)?;
        io::write_atomic(self.out.join("report.json"), &json)?;
        Ok(report)
    }
}
