//! Writing a run's captures: each frame's PNG and its line in `frames.jsonl` as the frame
//! completes, thumbnails for the contact sheet, timing totals, and at the end `summary.png`
//! and `report.json` (also after Ctrl-C, listing the frames done).

use crate::images::{self, Image};
use crate::memory_limit;
use crate::report::{FrameReport, Report, StepStats};
use crate::summary::{self, Series, Thumb};
use crate::timings::{GpuFigure, Step, Timings};
use crate::usage_error::UsageExt;
use anyhow::{Context, Result};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use terrain_core::io;

/// The memory `summary.png` takes, whatever the frames' size (see [`summary::MAX_BYTES`]).
pub const SUMMARY_BYTES: u64 = summary::MAX_BYTES;

/// The per-frame lines beside report.json.
pub const FRAMES_JSONL: &str = "frames.jsonl";

/// Collects a run's frames.
pub struct Capture<'a> {
    out: &'a Path,
    frames: Vec<FrameReport>,
    thumbs: Vec<Thumb>,
    /// Leading frames left out of the per-step statistics.
    warmup: u32,
    thumb_every: u32,
    total: u32,
    /// `frames.jsonl`: one line per frame, written as the frame completes, so a run that ends
    /// early (Ctrl-C, a failure, a kill) still lists what it did.
    lines: File,
}

impl<'a> Capture<'a> {
    /// A capture of `total` frames into `out` (which exists, cleared of an earlier run's
    /// outputs by [`remove_old_outputs`]), the first `warmup` left out of the statistics.
    pub fn new(out: &'a Path, total: u32, warmup: u32) -> Result<Self> {
        let lines = create_regular(&out.join(FRAMES_JSONL))?;
        Ok(Self {
            out,
            frames: Vec::with_capacity(total.min(1 << 16) as usize),
            thumbs: Vec::new(),
            thumb_every: total.div_ceil(summary::MAX_THUMBS).max(1),
            warmup,
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
        // GPU timestamps of earlier frames that arrived during this one go to their frames
        // (in report.json; their lines in frames.jsonl are written already).
        crate::report::credit_gpu(&mut self.frames, &timings.take_late_gpu());
        // As are granular steps' measures (read back without a wait).
        crate::report::credit_granular(&mut self.frames, &timings.take_late_granular());
        if index % self.thumb_every == self.thumb_every - 1 || index + 1 == self.total {
            let size = images::fit_within(image.size(), summary::THUMB_SIDE);
            self.thumbs.push(Thumb {
                frame: index,
                image: images::downscale(image, size),
            });
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

    /// Credits granular measures that arrived after the run's last frame (the scenario's
    /// `finish`) to their frames in report.json.
    pub fn credit_granular(&mut self, figures: &[crate::timings::GranularFigure]) {
        crate::report::credit_granular(&mut self.frames, figures);
    }

    /// Credits GPU timestamps that arrived after the run's last frame (the GPU scene's
    /// `flush_gpu_timings`) to their frames in report.json.
    pub fn credit_gpu(&mut self, figures: &[GpuFigure]) {
        crate::report::credit_gpu(&mut self.frames, figures);
    }

    /// Frames captured so far.
    pub fn done(&self) -> u32 {
        self.frames.len() as u32
    }

    /// Writes `summary.png` and `report.json` (with the frames captured and their totals, and
    /// the peak resident memory measured just before) and returns the report.
    pub fn finish(self, mut report: Report) -> Result<Report> {
        // Warm-up frames are marked on the chart and left out of `steps_ms`, but at least the
        // last frame is always measured.
        let warmup = self.warmup.min(self.done().saturating_sub(1));
        // Every step any frame timed, in the plot's order.
        let series: Vec<Series> = Step::ALL
            .iter()
            .filter(|s| {
                self.frames
                    .iter()
                    .any(|f| f.timings_ms.contains_key(s.name()))
            })
            .map(|&step| Series {
                step,
                ms: self
                    .frames
                    .iter()
                    .map(|f| f.timings_ms.get(step.name()).copied().unwrap_or(0.0))
                    .collect(),
            })
            .collect();
        // A contact sheet that cannot be written (a full disk, a folder in its place) still
        // leaves report.json, which records why.
        let summary = self.out.join("summary.png");
        let written = summary::render(&self.thumbs, &series, self.frames.len(), warmup as usize)
            .and_then(|sheet| Ok(write_file(&summary, &io::encode_png_rgba8(&sheet)?)?))
            .with_context(|| format!("writing {}", summary.display()));
        let summary_error = written.err();
        if let Some(e) = &summary_error
            && report.error.is_none()
        {
            report.error = Some(format!("{e:#}"));
        }
        report.warmup_frames = warmup;
        report.steps_ms = step_stats(&self.frames[warmup as usize..]);
        let mut cpu: Vec<f64> = self.frames[warmup as usize..]
            .iter()
            .filter_map(|f| f.frame_thread_cpu_ms)
            .collect();
        cpu.sort_by(f64::total_cmp);
        report.frame_thread_cpu_ms = (!cpu.is_empty()).then(|| StepStats::of_sorted(&cpu));
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
        match summary_error {
            Some(e) => Err(e),
            None => Ok(report),
        }
    }
}

/// Removes what an earlier run wrote into `out` and this run may not overwrite: its frames
/// (`frame_NNNN.png`, any count), `summary.png`, `terrain_final.png`, `report.json`, so a
/// folder never mixes two runs. Only files that are what those names say are removed (a PNG,
/// a report): a user's file under such a name is left alone (unless this run writes that
/// name itself: its first frames, the summary and the report replace what is there), and so
/// is everything else. Returns how many were removed.
pub fn remove_old_outputs(out: &Path) -> Result<usize> {
    let is_ours = |name: &str| {
        let frame = name
            .strip_prefix("frame_")
            .and_then(|n| n.strip_suffix(".png"))
            .is_some_and(|n| n.len() >= 4 && n.bytes().all(|b| b.is_ascii_digit()));
        frame || ["summary.png", "terrain_final.png", "report.json"].contains(&name)
    };
    let entries = std::fs::read_dir(out).with_context(|| format!("listing {}", out.display()))?;
    let mut removed = 0;
    for entry in entries {
        let entry = entry.with_context(|| format!("listing {}", out.display()))?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        // Only files: a folder or anything else with such a name is not ours.
        let is_file = entry
            .file_type()
            .is_ok_and(|t| t.is_file() || t.is_symlink());
        if is_file
            && is_ours(name)
            && (entry.file_type()?.is_symlink() || written_by_a_run(&entry.path()))
        {
            let path = entry.path();
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Whether the file at `path` holds what a run writes under its name: a PNG's signature, or a
/// report's first field (the first 4 KiB are read; an unreadable file is not the run's).
fn written_by_a_run(path: &Path) -> bool {
    use std::io::Read;
    let mut head = Vec::with_capacity(4096);
    let read = File::open(path).and_then(|f| f.take(4096).read_to_end(&mut head));
    if read.is_err() {
        return false;
    }
    if path.extension().is_some_and(|e| e == "png") {
        head.starts_with(b"\x89PNG\r\n\x1a\n")
    } else {
        head.starts_with(b"{") && head.windows(16).any(|w| w == b"\"schema_version\"")
    }
}

/// Mean, median, 95th percentile and maximum of every step over `frames` (the frames after
/// warm-up), each over the frames that timed it.
pub fn step_stats(frames: &[FrameReport]) -> BTreeMap<&'static str, StepStats> {
    let mut by_step: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    for f in frames {
        for (k, v) in &f.timings_ms {
            by_step.entry(*k).or_default().push(*v);
        }
    }
    by_step
        .into_iter()
        .map(|(k, mut v)| {
            v.sort_by(f64::total_cmp);
            (k, StepStats::of_sorted(&v))
        })
        .collect()
}

/// Creates `path` as a new regular file, replacing an earlier run's regular file. Anything
/// else there (a link, which would be written through to a file outside `--out`; a named
/// pipe, on which opening blocks; a device; a folder) is refused, untouched, with a usage
/// error. The creation refuses whatever appears at `path` in between (`O_EXCL` never follows
/// a link).
fn create_regular(path: &Path) -> Result<File> {
    match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_file() => {
            std::fs::remove_file(path).with_context(|| format!("replacing {}", path.display()))?
        }
        Ok(meta) => {
            let kind = if meta.file_type().is_symlink() {
                "a symbolic link"
            } else if meta.is_dir() {
                "a folder"
            } else {
                "a special file (a named pipe, a socket or a device)"
            };
            return Err(anyhow::anyhow!(
                "{} is {kind}: the demo writes only regular files of its own there; remove it \
                 or choose another --out",
                path.display()
            ))
            .usage();
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(e).with_context(|| format!("checking {}", path.display())),
    }
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .with_context(|| format!("creating {}", path.display()))
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
        crate::console::note!(
            "warning: {} is written, but its folder could not be synced ({e}): files of this \
             run might not survive a power loss",
            path.display()
        );
    }
    Ok(())
}
