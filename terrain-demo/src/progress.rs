//! How far a run is, on stderr: a progress bar when stderr is a terminal, a line every few
//! seconds otherwise (logs, CI), nothing with `-q`.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// Seconds between two lines when stderr is not a terminal.
const LINE_EVERY: Duration = Duration::from_secs(5);

/// A run's progress display.
#[derive(Debug)]
pub enum Progress {
    /// `-q`.
    Silent,
    /// stderr is a terminal.
    Bar(ProgressBar),
    /// stderr is a file or a pipe: a line now and then.
    Lines {
        /// Frames in the run.
        total: u32,
        /// When the run started.
        start: Instant,
        /// When the last line was printed.
        last: Instant,
    },
}

impl Progress {
    /// The display for a run of `total` frames.
    pub fn new(total: u32, quiet: bool) -> Self {
        if quiet {
            return Progress::Silent;
        }
        if std::io::stderr().is_terminal() {
            let bar =
                ProgressBar::with_draw_target(Some(u64::from(total)), ProgressDrawTarget::stderr());
            let style = ProgressStyle::with_template(
                "{spinner} frame {pos}/{len} [{bar:32}] {per_sec:.1}, {elapsed} elapsed, eta {eta}",
            )
            .map(|s| s.progress_chars("=> "));
            if let Ok(style) = style {
                bar.set_style(style);
            }
            return Progress::Bar(bar);
        }
        let now = Instant::now();
        Progress::Lines {
            total,
            start: now,
            last: now,
        }
    }

    /// `done` frames are finished.
    pub fn frames_done(&mut self, done: u32) {
        match self {
            Progress::Silent => {}
            Progress::Bar(bar) => bar.set_position(u64::from(done)),
            Progress::Lines { total, start, last } => {
                if last.elapsed() >= LINE_EVERY && done < *total {
                    *last = Instant::now();
                    let elapsed = start.elapsed().as_secs_f64();
                    let rate = f64::from(done) / elapsed.max(1e-9);
                    let eta = f64::from(*total - done) / rate.max(1e-9);
                    crate::console::note!(
                        "frame {done}/{total} ({:.0} %), {rate:.1} frames/s, {elapsed:.0} s elapsed, about {eta:.0} s left",
                        100.0 * f64::from(done) / f64::from((*total).max(1))
                    );
                }
            }
        }
    }

    /// Removes the bar (the final summary line follows it).
    pub fn finish(&self) {
        if let Progress::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}
