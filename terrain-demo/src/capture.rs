//! Writing a run's captures: each frame's PNG and its line in `frames.jsonl` as the frame
//! completes, thumbnails for the contact sheet, timing totals, and at the end `summary.png`
//! and `report.json` (also after Ctrl-C, listing the frames done).

use crate::images::{self, Image};
use crate::memory_limit;
use crate::report::{FrameReport, Report};
use crate::timings::{Step, Timings};
use anyhow::{Context, Result};
use glam::UVec2;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use terrain_core::io;

/// Steps shown in the timing plot of `summary.png`, bottom to top.
const PLOTTED: [Step; 5] = [
    Step::Stamp,
    Step::Normals,
    Step::Render,
    Step::Capture,
    Step::Write,
];

/// The most frames kept as thumbnails for the contact sheet.
const MAX_THUMBS: u32 = 12;
/// Columns of the contact sheet.
const SHEET_COLUMNS: u32 = 4;
/// Thumbnails fit a square of this side, keeping the frame's aspect.
const THUMB_SIDE: u32 = 320;
/// Height of the timing plot under the thumbnails.
const PLOT_HEIGHT: u32 = 160;
/// Pixels between thumbnails (as `images::contact_sheet` lays them out).
const GAP: u32 = 4;

/// The most memory the summary takes, whatever the frames' size: the thumbnails, the sheet
/// and its PNG (a little more than its pixels at worst), the plot; a quarter more for the
/// encoder's state.
pub const SUMMARY_BYTES: u64 = {
    let thumb = (THUMB_SIDE as u64) * (THUMB_SIDE as u64) * 4;
    let rows = MAX_THUMBS.div_ceil(SHEET_COLUMNS) as u64;
    let width = (SHEET_COLUMNS * (THUMB_SIDE + GAP) + GAP) as u64;
    let height = rows * (THUMB_SIDE + GAP) as u64 + (GAP + PLOT_HEIGHT + GAP) as u64;
    let sheet = width * height * 4;
    let plot = width * PLOT_HEIGHT as u64 * 4;
    (MAX_THUMBS as u64 * thumb + 2 * sheet + plot) * 5 / 4
};

/// The per-frame lines beside report.json.
pub const FRAMES_JSONL: &str = "frames.jsonl";

/// Collects a run's frames.
pub struct Capture<'a> {
    out: &'a Path,
    frames: Vec<FrameReport>,
    thumbs: Vec<Image>,
    thumb_every: u32,
    total: u32,
    /// `frames.jsonl`: one line per frame, written as the frame completes, so a run that ends
    /// early (Ctrl-C, a failure, a kill) still lists what it did.
    lines: File,
}

impl<'a> Capture<'a> {
    /// A capture of `total` frames into `out` (which exists). A report.json of an earlier run
    /// there is removed first: it would describe frames this run may not reach.
    pub fn new(out: &'a Path, total: u32) -> Result<Self> {
        let old = out.join("report.json");
        match std::fs::remove_file(&old) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e).with_context(|| format!("removing {}", old.display())),
        }
        let path = out.join(FRAMES_JSONL);
        let lines = File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        Ok(Self {
            out,
            frames: Vec::with_capacity(total.min(1 << 16) as usize),
            thumbs: Vec::new(),
            thumb_every: total.div_ceil(MAX_THUMBS).max(1),
            total,
            lines,
        })
    }

    /// Writes `image` as the next frame and records `frame` with `timings` (its `index`, `file`
    /// and timings are filled in here, the `write` step included), then appends the frame's
    /// line to `frames.jsonl`.
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
            .time(Step::Write, || {
                write_file(&path, &io::encode_png_rgba8(image)?)
            })
            .with_context(|| format!("writing {}", path.display()))?;
        frame.index = index;
        frame.file = file;
        frame.timings_ms = timings.wall_by_name();
        frame.gpu_timestamps_ms = timings.gpu_by_name();
        if index % self.thumb_every == self.thumb_every - 1 || index + 1 == self.total {
            let size = images::fit_within(image.size(), THUMB_SIDE);
            self.thumbs.push(images::downscale(image, size));
        }
        // One write per line: a line is whole unless the process dies inside that call.
        let mut line = serde_json::to_vec(&frame)?;
        line.push(b'\n');
        self.lines
            .write_all(&line)
            .with_context(|| format!("writing {}", self.out.join(FRAMES_JSONL).display()))?;
        self.frames.push(frame);
        Ok(())
    }

    /// Frames captured so far.
    pub fn done(&self) -> u32 {
        self.frames.len() as u32
    }

    /// Writes `summary.png` and `report.json` (with the frames captured and their totals, and
    /// the peak resident memory measured just before) and returns the report.
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
        let plot_width = SHEET_COLUMNS * (THUMB_SIDE + GAP) - GAP;
        let plot = images::timing_plot(&series, UVec2::new(plot_width, PLOT_HEIGHT))?;
        let sheet = images::contact_sheet(&self.thumbs, SHEET_COLUMNS, &plot)?;
        let summary = self.out.join("summary.png");
        write_file(&summary, &io::encode_png_rgba8(&sheet)?)
            .with_context(|| format!("writing {}", summary.display()))?;
        drop(sheet);
        let mut totals: BTreeMap<&'static str, f64> = BTreeMap::new();
        for f in &self.frames {
            for (k, v) in &f.timings_ms {
                *totals.entry(*k).or_default() += v;
            }
        }
        // The lines are complete; make them as durable as the report.
        let _ = self.lines.sync_data();
        report.frames = self.frames;
        report.totals_ms = totals;
        report.memory.peak_rss_bytes = memory_limit::peak_resident();
        let json = serde_json::to_vec_pretty(&report)?;
        write_file(&self.out.join("report.json"), &json)?;
        Ok(report)
    }
}

/// Set once a failed folder sync has been reported (it would repeat for every file).
static SYNC_WARNED: AtomicBool = AtomicBool::new(false);

/// Writes `bytes` to `path` atomically. A folder that cannot be synced after the rename is a
/// warning (once per run): the file is in place, but might not survive a power loss.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), io::MapIoError> {
    let written = io::write_atomic_report(path, bytes)?;
    if let Some(e) = written.dir_sync_error
        && !SYNC_WARNED.swap(true, Ordering::Relaxed)
    {
        eprintln!(
            "warning: {} is written, but its folder could not be synced ({e}): files of this \
             run might not survive a power loss",
            path.display()
        );
    }
    Ok(())
}
