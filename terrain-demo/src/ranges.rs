//! The valid range of every numeric flag and `--config` key, in one table: `validate` and
//! `config` check values against it before anything is read or allocated (a usage error, exit
//! status 2, that names the flag or key and its range), and `--help` prints it, so the ranges
//! documented are the ranges checked.
//!
//! Each range is what the pipeline can represent: texel indices and sizes in u32 (a side of at
//! most 65536 texels, whose square still fits a u32 count of samples per row times rows in
//! u64 byte counts), positions in f32 metres (extents up to about 6.6e8 m, where one f32 step
//! is still under 64 m), heights quantised to u16 over a span of f32 metres, GPU buffers
//! bound through wgpu's u32 binding sizes (under 4 GiB), and frame and step counts that bound
//! the work of a run.

use anyhow::{Result, anyhow};

/// The most collision readbacks in flight (the GPU scene's ring of readback buffers).
use terrain_gpu::MAX_READBACK_RING;

/// A closed or half-open range of a flag's or key's values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// The flag (`--size`) or key (`stamps.stride_m`), as the user writes it.
    pub name: &'static str,
    /// The lowest value allowed (or the bound above which values start, when `min_open`).
    pub min: f64,
    /// Whether `min` itself is refused.
    pub min_open: bool,
    /// The highest value allowed (or the bound below which values stay, when `max_open`).
    pub max: f64,
    /// Whether `max` itself is refused.
    pub max_open: bool,
    /// The unit, as shown after the range.
    pub unit: &'static str,
}

const fn closed(name: &'static str, min: f64, max: f64, unit: &'static str) -> Range {
    Range {
        name,
        min,
        min_open: false,
        max,
        max_open: false,
        unit,
    }
}

const fn above(name: &'static str, min: f64, max: f64, unit: &'static str) -> Range {
    Range {
        min_open: true,
        ..closed(name, min, max, unit)
    }
}

const fn open(name: &'static str, min: f64, max: f64, unit: &'static str) -> Range {
    Range {
        min_open: true,
        max_open: true,
        ..closed(name, min, max, unit)
    }
}

const fn below(name: &'static str, min: f64, max: f64, unit: &'static str) -> Range {
    Range {
        max_open: true,
        ..closed(name, min, max, unit)
    }
}

/// The largest side of a map, a raw heightmap or a world in texels (u32 texel indices; the
/// 65536^2 u16 map is 8 GiB, beyond which `--max-memory` decides anyway).
pub const MAX_SIDE: f64 = 65_536.0;
/// The largest magnitude of a height in metres (the Earth's relief is within 11 km; ten times
/// that keeps a u16 step of the widest span under 4 m and f32 metres exact to a millimetre).
pub const MAX_HEIGHT_M: f64 = 100_000.0;
/// The narrowest height span in metres (65535 u16 steps of at least 1.5e-8 m).
pub const MIN_HEIGHT_SPAN_M: f64 = 0.001;

/// The numeric flags.
pub const FLAGS: &[Range] = &[
    closed("--size", 16.0, MAX_SIDE, "texels"),
    closed("--raw-size", 16.0, MAX_SIDE, "texels per side"),
    closed("--texel-size", 0.001, 10_000.0, "m"),
    closed(
        "--height-range",
        -MAX_HEIGHT_M,
        MAX_HEIGHT_M,
        "m, MAX - MIN >= 0.001",
    ),
    closed("--max-height", MIN_HEIGHT_SPAN_M, MAX_HEIGHT_M, "m"),
    closed("--frames", 1.0, 100_000.0, "frames"),
    closed("--warmup", 0.0, 100_000.0, "frames"),
    closed("--resolution", 16.0, 8192.0, "px per side"),
    closed("--overview-size", 16.0, 8192.0, "px"),
    closed("--ram-budget", 1.0, 1_048_576.0, "MiB"),
    // The atlas is one storage buffer: wgpu binds at most u32::MAX bytes.
    closed("--vram-budget", 1.0, 4095.0, "MiB"),
    above("--speed", 0.0, 1000.0, "m/s"),
    closed("--target-error", 0.01, 1000.0, "px"),
    closed("--triangle-width", 0.01, 10_000.0, "px"),
    // Sums of an estimate stay exact in u64 below 2^63 bytes.
    below(
        "--max-memory",
        1.0,
        9_223_372_036_854_775_808.0,
        "bytes (1 to 8E, 8E itself excluded)",
    ),
];

/// The numeric keys of `--config` (`[a, b]` keys: each element).
pub const KEYS: &[Range] = &[
    above("stamps.foot_size_m", 0.0, 100.0, "m"),
    closed("stamps.foot_depth_m", 0.0, 100.0, "m"),
    closed("stamps.steps_per_frame", 1.0, 64.0, "per frame"),
    above("stamps.stride_m", 0.0, 1000.0, "m"),
    closed("stamps.crater_every", 0.0, 100_000.0, "frames (0: none)"),
    above("stamps.crater_size_m", 0.0, 100_000.0, "m"),
    closed("stamps.crater_depth_ratio", 0.0, 10.0, ""),
    closed("stamps.shock_size_fraction", 0.0, 1.0, ""),
    closed("stamps.shock_amplitude_m", 0.0, 1000.0, "m"),
    closed("stamps.shock_steps_per_frame", 0.0, 64.0, "per frame"),
    closed("stamps.hole_frame", 0.0, 4_294_967_295.0, "frame (0: none)"),
    above("stamps.hole_size_m", 0.0, 100_000.0, "m"),
    closed("stamps.shockwave.resolution", 8.0, 4096.0, "samples"),
    above("stamps.shockwave.gamma", 0.0, 0.5, ""),
    above("stamps.shockwave.initial_sigma", 0.0, 4096.0, "samples"),
    below("stamps.shockwave.damping", 0.0, 1.0, ""),
    closed("granular.compression", 0.0, 1.0, ""),
    closed("granular.roughness", 0.0, 1.0, ""),
    closed("granular.slope_threshold", 0.0, 1e6, ""),
    closed("granular.slope_d", 1e-6, 1e6, ""),
    closed("granular.num_iterations_even_out_slopes", 0.0, 1024.0, ""),
    closed("granular.num_iterations_blur_normals", 0.0, 1024.0, ""),
    closed("granular.obstacle_margin_m", 0.0, 1e4, "m"),
    closed("granular.active_area_margin", 0.0, 4096.0, "texels"),
    closed("granular.merge_distance", 0.0, 4096.0, "texels"),
    closed("scheduler.quiet_gap_ms", 0.0, 60_000.0, "ms"),
    closed("scheduler.max_delay_ms", 0.0, 60_000.0, "ms"),
    closed("scheduler.merge_distance", 0.0, MAX_SIDE, "texels"),
    closed(
        "scheduler.max_requests",
        1.0,
        MAX_READBACK_RING as f64,
        "(at most max_in_flight)",
    ),
    above("scheduler.request_timeout_ms", 0.0, 600_000.0, "ms"),
    closed(
        "scheduler.max_in_flight",
        1.0,
        MAX_READBACK_RING as f64,
        "GPU buffers",
    ),
    closed("style.light_dir", -1e6, 1e6, "(not all 0)"),
    closed("style.fog_color", 0.0, 1.0, "linear RGB"),
    closed("style.fog_density", 0.0, 10.0, "per m"),
    closed("style.material_scale_m", 0.01, 10_000.0, "m"),
    closed(
        "style.ramp_m",
        -MAX_HEIGHT_M,
        MAX_HEIGHT_M,
        "m, low below high",
    ),
    above("camera.walker_eye_height_m", 0.0, 1000.0, "m"),
    closed("camera.walker_behind_m", 0.0, 10_000.0, "m"),
    above("camera.walker_ahead_m", 0.0, 10_000.0, "m"),
    open("camera.orbit_pitch_deg", 0.0, 90.0, "degrees"),
    above("camera.orbit_period_s", 0.0, 86_400.0, "s"),
    above("camera.flyover_period_s", 0.0, 86_400.0, "s"),
    above(
        "camera.flyover_height",
        0.0,
        100.0,
        "x the map's longer side",
    ),
    open("camera.flyover_pitch_deg", 0.0, 90.0, "degrees"),
];

impl Range {
    /// Whether `v` is inside (NaN never is).
    pub fn contains(&self, v: f64) -> bool {
        let lo = if self.min_open {
            v > self.min
        } else {
            v >= self.min
        };
        let hi = if self.max_open {
            v < self.max
        } else {
            v <= self.max
        };
        lo && hi
    }

    /// The range as shown: `16 to 65536 texels`, `above 0 to 1000 m/s`.
    pub fn describe(&self) -> String {
        let lo = if self.min_open {
            format!("above {}", self.min)
        } else {
            format!("{}", self.min)
        };
        let hi = if self.max_open {
            format!("below {}", self.max)
        } else {
            format!("{}", self.max)
        };
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        format!("{lo} to {hi}{unit}")
    }
}

/// The range of the flag or key `name`.
///
/// # Panics
/// When `name` is not in the tables (a programming error the unit tests catch).
pub fn of(name: &str) -> &'static Range {
    FLAGS
        .iter()
        .chain(KEYS)
        .find(|r| r.name == name)
        .unwrap_or_else(|| panic!("{name} has no range in ranges::FLAGS or ranges::KEYS"))
}

/// A value a [`Range`] checks, compared in its own type (an f32 against the bounds rounded to
/// f32, so a bound written as 0.01 accepts the f32 nearest 0.01).
pub trait Value: Copy + std::fmt::Display {
    /// Whether `self` is inside `range`.
    fn within(self, range: &Range) -> bool;
}

impl Value for f32 {
    fn within(self, r: &Range) -> bool {
        let (lo, hi) = (r.min as f32, r.max as f32);
        let above = if r.min_open { self > lo } else { self >= lo };
        let below = if r.max_open { self < hi } else { self <= hi };
        above && below
    }
}

impl Value for f64 {
    fn within(self, r: &Range) -> bool {
        r.contains(self)
    }
}

macro_rules! integer_value {
    ($($t:ty),*) => {$(
        impl Value for $t {
            // Every bound of an integer flag or key is an integer below 2^53: exact in f64,
            // and a value beyond 2^53 is far above each of them.
            fn within(self, r: &Range) -> bool {
                r.contains(self as f64)
            }
        }
    )*};
}
integer_value!(u32, u64, usize);

/// Checks `value` of the flag or key `name` (`shown` is how the user wrote it, as
/// `stamps.foot_size_m[1]` for an element of an array key): an error naming it and its range
/// when outside.
pub fn check_as(name: &str, shown: &str, value: impl Value) -> Result<()> {
    let range = of(name);
    if value.within(range) {
        Ok(())
    } else {
        Err(anyhow!(
            "{shown} = {value} is out of range: give {}",
            range.describe()
        ))
    }
}

/// Checks `value` of the flag or key `name` (see [`check_as`]).
pub fn check(name: &str, value: impl Value) -> Result<()> {
    check_as(name, name, value)
}

/// The tables as `--help` prints them after the flags.
pub fn help_table() -> String {
    let mut text = String::from(
        "Valid ranges (checked before the run; a value outside exits with status 2, naming \
         the flag or key):\n",
    );
    for r in FLAGS {
        text.push_str(&format!("  {:<40} {}\n", r.name, r.describe()));
    }
    text.push_str(&format!("  {:<40} any u64 (0 to {})\n", "--seed", u64::MAX));
    text.push_str("--config keys (see the print-config command):\n");
    for r in KEYS {
        text.push_str(&format!("  {:<40} {}\n", r.name, r.describe()));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_ranges_non_empty() {
        let all: Vec<&Range> = FLAGS.iter().chain(KEYS).collect();
        for (i, r) in all.iter().enumerate() {
            assert!(r.min < r.max, "{}", r.name);
            assert!(
                all[..i].iter().all(|o| o.name != r.name),
                "{} twice",
                r.name
            );
        }
    }

    #[test]
    fn bounds_follow_openness_and_nan_is_outside() {
        let speed = of("--speed");
        assert!(!speed.contains(0.0) && speed.contains(1000.0) && !speed.contains(f64::NAN));
        assert!(speed.contains(f64::MIN_POSITIVE));
        let size = of("--size");
        assert!(size.contains(16.0) && size.contains(65536.0) && !size.contains(65537.0));
        assert!(!of("stamps.shockwave.damping").contains(1.0));
        // An f32 is compared with the bounds rounded to f32.
        check("--target-error", 0.01f32).unwrap();
        assert!(check("--target-error", 0.0099f32).is_err());
        let e = check("--speed", f64::INFINITY).unwrap_err().to_string();
        assert!(
            e.contains("--speed") && e.contains("above 0 to 1000 m/s"),
            "{e}"
        );
        assert!(help_table().contains("camera.flyover_pitch_deg"));
    }
}
