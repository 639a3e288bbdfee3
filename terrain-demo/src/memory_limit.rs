//! The memory limit of a run (`--max-memory SIZE`), the machine's memory it defaults to a
//! fraction of, and the peak resident memory the process reached (reported in report.json).

use anyhow::{Result, bail};
use std::path::Path;

/// The default limit is this fraction of the machine's memory: half leaves the rest to the
/// system and to whatever else runs beside the demo (a shared machine, a build).
pub const DEFAULT_FRACTION: (u64, u64) = (1, 2);

/// The machine's memory assumed where it cannot be read (no /proc/meminfo): 4 GiB, so the
/// default limit is then 2 GiB, enough for the default runs.
pub const FALLBACK_MACHINE_MEMORY: u64 = 4 << 30;

/// Parses a byte count as `--max-memory` takes it: a number with an optional binary unit,
/// `K`, `M`, `G`, `T`, `P` or `E` (KiB to EiB; `MB`, `MiB` and lower case are read the same),
/// as `1536M`, `8G`, `1.5G` or `1073741824`.
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let digits = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(digits);
    let shift = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 0,
        "k" | "kb" | "kib" => 10,
        "m" | "mb" | "mib" => 20,
        "g" | "gb" | "gib" => 30,
        "t" | "tb" | "tib" => 40,
        "p" | "pb" | "pib" => 50,
        "e" | "eb" | "eib" => 60,
        _ => {
            return Err(format!(
                "`{s}`: the unit must be K, M, G, T, P or E (as 1536M or 8G)"
            ));
        }
    };
    let value: f64 = number
        .parse()
        .map_err(|_| format!("`{s}` is not a size (as 1536M or 8G)"))?;
    let bytes = value * (1u64 << shift) as f64;
    // 2^63 bytes is far beyond any machine and keeps the sums of an estimate exact in u64.
    let range = crate::ranges::of("--max-memory");
    if !range.contains(bytes) {
        return Err(format!("`{s}`: give {}", range.describe()));
    }
    Ok(bytes as u64)
}

/// `bytes` for people: `512 KiB`, `1.5 GiB`.
pub fn format_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

/// The value in bytes of the line starting with `key` in a /proc file whose values are in kB
/// (`MemTotal:  16384 kB`).
fn proc_kib(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let mut words = line[key.len()..].split_whitespace();
    let kib: u64 = words.next()?.parse().ok()?;
    match words.next() {
        Some("kB") => kib.checked_mul(1024),
        _ => None,
    }
}

/// Reads a small /proc file (never blocks: they are regular files of the kernel).
fn read_proc(path: &str) -> Option<String> {
    std::fs::read_to_string(Path::new(path)).ok()
}

/// The machine's memory (MemTotal of /proc/meminfo), `None` where it cannot be read.
pub fn machine_memory() -> Option<u64> {
    proc_kib(&read_proc("/proc/meminfo")?, "MemTotal:")
}

/// The limit when `--max-memory` is not given: [`DEFAULT_FRACTION`] of the machine's memory,
/// or of [`FALLBACK_MACHINE_MEMORY`] where that is unknown.
pub fn default_limit() -> u64 {
    let total = machine_memory().unwrap_or(FALLBACK_MACHINE_MEMORY);
    total / DEFAULT_FRACTION.1 * DEFAULT_FRACTION.0
}

/// The peak resident memory of this process so far (VmHWM of /proc/self/status: every thread,
/// the GPU driver's allocations included), `None` where it cannot be read.
pub fn peak_resident() -> Option<u64> {
    proc_kib(&read_proc("/proc/self/status")?, "VmHWM:")
}

/// Fails when `needed` bytes are above `limit`, with the largest parts of the need named.
pub fn check(needed: &[(&'static str, u64)], limit: u64) -> Result<()> {
    let total: u64 = needed.iter().map(|(_, b)| b).sum();
    if total <= limit {
        return Ok(());
    }
    let mut parts = needed.to_vec();
    parts.sort_by_key(|p| std::cmp::Reverse(p.1));
    let largest: Vec<String> = parts
        .iter()
        .take(3)
        .map(|(name, b)| format!("{name} {}", format_bytes(*b)))
        .collect();
    bail!(
        "this run needs about {} ({}, ...), above the memory limit of {} (--max-memory): \
         ask for less (--size, --resolution, --overview-size, budgets) or raise --max-memory",
        format_bytes(total),
        largest.join(", "),
        format_bytes(limit)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_binary_units() {
        assert_eq!(parse_bytes("1536M"), Ok(1536 << 20));
        assert_eq!(parse_bytes("8G"), Ok(8 << 30));
        assert_eq!(parse_bytes("8g"), Ok(8 << 30));
        assert_eq!(parse_bytes("2GiB"), Ok(2 << 30));
        assert_eq!(parse_bytes("1.5G"), Ok(3 << 29));
        assert_eq!(parse_bytes("512K"), Ok(512 << 10));
        assert_eq!(parse_bytes("1T"), Ok(1 << 40));
        assert_eq!(parse_bytes("1000"), Ok(1000));
        // The top of the range, as the help gives it (8E itself is past it).
        assert_eq!(parse_bytes("7E"), Ok(7 << 60));
        assert_eq!(parse_bytes("2P"), Ok(2 << 50));
        for bad in [
            "",
            "G",
            "-1G",
            "0",
            "0M",
            "1X",
            "1..5G",
            "NaNG",
            "inf",
            "9999999999T",
            "8E",
        ] {
            assert!(parse_bytes(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn proc_values_are_read_in_kib() {
        let meminfo = "MemTotal:       24576000 kB\nMemFree:  100 kB\n";
        assert_eq!(proc_kib(meminfo, "MemTotal:"), Some(24_576_000 * 1024));
        assert_eq!(proc_kib(meminfo, "MemAvailable:"), None);
        assert_eq!(proc_kib("VmHWM:\t  1234 kB\n", "VmHWM:"), Some(1234 * 1024));
        assert_eq!(proc_kib("VmHWM: 12 pages\n", "VmHWM:"), None);
    }

    #[test]
    fn the_default_is_a_fraction_of_the_machine() {
        let limit = default_limit();
        let total = machine_memory().unwrap_or(FALLBACK_MACHINE_MEMORY);
        assert!(limit > 0 && limit < total, "{limit} of {total}");
        // This process has been resident, so on Linux its peak reads.
        if cfg!(target_os = "linux") {
            assert!(peak_resident().is_some_and(|p| p > 0));
        }
    }

    #[test]
    fn a_refusal_names_the_total_the_limit_and_the_largest_parts() {
        let needed = [("map", 3 << 30), ("frames", 1 << 20), ("normals", 2 << 30)];
        assert!(check(&needed, 6 << 30).is_ok());
        let e = check(&needed, 4 << 30).unwrap_err().to_string();
        assert!(e.contains("5.0 GiB") && e.contains("4.0 GiB"), "{e}");
        assert!(
            e.contains("map 3.0 GiB, normals 2.0 GiB, frames 1.0 MiB"),
            "{e}"
        );
        assert!(e.contains("--max-memory") && !e.contains('\n'), "{e}");
        assert_eq!(format_bytes(1023), "1023 B");
        assert_eq!(format_bytes(1536), "1.5 KiB");
    }
}
