//! Writing a run's captures: each frame's PNG, thumbnails for the contact sheet, timing totals,
//! and at the end `summary.png` and `report.json`.

use crate::images::{self, Image};
use crate::report::{FrameReport, Report};
use anyhow::{Context, Result};
use glam::UVec2;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;
use terrain_core::io;

/// Steps shown in the timing plot of `summary.png`, bottom to top.
const PLOTTED: [&str; 5] = ["stamp", "normals", "render", "capture", "write"];

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

    /// Writes `image` as the next frame and records `frame` (its `file` and `write` timing are
    /// filled in here).
    pub fn push(&mut self, image: &Image, mut frame: FrameReport) -> Result<()> {
        let index = self.frames.len() as u32;
        let t = Instant::now();
        let file = format!("frame_{index:04}.png");
        let path = self.out.join(&file);
        io::write_png_rgba8(&path, image).with_context(|| format!("writing {}", path.display()))?;
        frame
            .timings_ms
            .insert("write".to_string(), t.elapsed().as_secs_f64() * 1e3);
        frame.index = index;
        frame.file = file;
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
            .map(|k| {
                self.frames
                    .iter()
                    .map(|f| f.timings_ms.get(*k).copied().unwrap_or(0.0))
                    .collect()
            })
            .collect();
        let columns = 4;
        let plot = images::timing_plot(&series, UVec2::new(columns * 324 - 4, 160))?;
        let sheet = images::contact_sheet(&self.thumbs, columns, 320, &plot)?;
        io::write_png_rgba8(self.out.join("summary.png"), &sheet)?;
        let mut totals: BTreeMap<String, f64> = BTreeMap::new();
        for f in &self.frames {
            for (k, v) in &f.timings_ms {
                *totals.entry(k.clone()).or_default() += v;
            }
        }
        report.frames = self.frames;
        report.totals_ms = totals;
        let json = serde_json::to_vec_pretty(&report)?;
        io::write_atomic(self.out.join("report.json"), &json)?;
        Ok(report)
    }
}
