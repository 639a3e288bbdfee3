//! `cargo xtask bench-report [--quick] [--write-docs]`: runs the headline CPU benches briefly
//! and compares each figure with the thesis figure and with plain copies of the same bytes
//! measured in the same run, since absolute times on a shared machine mean little; then the bytes
//! per texel of every GPU resource (terrain-gpu's `gpu_memory` example). With `--write-docs`
//! the tables become `docs/BENCHMARKS.md`, a whole generated file.

use crate::util::{cargo, root, target_dir, write_atomically};
use anyhow::{Context, Result, bail};
use std::path::Path;

/// One headline figure of `bench-report`: a criterion benchmark id (`group/function/param`),
/// the thesis figure it is compared with (milliseconds, and where it comes from), and the ids
/// of the plain copies of the same bytes measured in the same run: contiguous, and (for the
/// stamp benches) in place in the map's rows.
struct Headline {
    id: String,
    thesis_ms: Option<f64>,
    thesis: String,
    copy_id: String,
    map_copy_id: Option<String>,
}

/// The figures `bench-report` reports. Thesis figures: Flower 2010, table 4.3 (GTX295, deform and
/// normal generation at 0.1 m per texel: 50 m = 500^2 texels, 100 m = 1000^2, 200 m =
/// 2000^2), Persson 2019, tables 5.4 (iterative approach) and 5.5 (SSBO approach) at heightmapSize
/// 4096 (241 591 columns).
fn headlines() -> Vec<Headline> {
    let mut out = Vec::new();
    // (side, GTX295 deform ms, GTX295 normal generation ms, region in metres)
    let table_4_3 = [
        (500, 0.971, 0.828, "50 m"),
        (1000, 1.192, 0.953, "100 m"),
        (2000, 1.875, 1.329, "200 m"),
    ];
    for (side, deform, normals, metres) in table_4_3 {
        let stamps = [
            ("stamp", "Gaussian"),
            ("stamp_reference", "Gaussian, per-texel reference"),
            ("stamp_gaussian_rotated", "rotated Gaussian"),
            ("stamp_texture_rotated", "rotated texture"),
            ("stamp_min_max", "min / max blend"),
            ("normals", "normals"),
        ];
        for (bench, what) in stamps {
            // The per-texel reference runs at the small sizes only (it is slow).
            if bench == "stamp_reference" && side > 500 {
                continue;
            }
            let (thesis_ms, figure) = if bench == "normals" {
                (normals, "Normal Gen")
            } else {
                (deform, "Deform")
            };
            out.push(Headline {
                id: format!("stamp_normals/{bench}/{side}"),
                thesis_ms: Some(thesis_ms),
                thesis: format!("Flower 2010, table 4.3, {figure} {metres}, GTX295 ({what})"),
                copy_id: format!("stamp_normals/memcpy/{side}"),
                map_copy_id: Some(format!("stamp_normals/memcpy_in_map/{side}")),
            });
        }
    }
    let granular = [
        (
            "granular/jump_flood/4096",
            10.692,
            "Persson 2019, table 5.4, Jump flooding, 4096",
        ),
        (
            "granular/jump_flood_reference/4096",
            10.692,
            "Persson 2019, table 5.4, Jump flooding (sequential reference)",
        ),
        (
            "granular/exact_nearest_seed/4096",
            10.692,
            "Persson 2019, table 5.4, Jump flooding (scipy EDT: 13.4 ms)",
        ),
        (
            "granular/displace_iterative10/4096",
            11.864,
            "Persson 2019, table 5.4, Displace material (iterative, 10 passes), 4096",
        ),
        (
            "granular/displace_iterative1/4096",
            2.84,
            "Persson 2019, table 5.6, Iterative approach (1 pass), 4096",
        ),
        (
            "granular/displace_closest_seed/4096",
            1.04,
            "Persson 2019, table 5.6, SSBO (table 5.5 gives 1.659 for the same method)",
        ),
        (
            "granular/displace_multiple_targets/4096",
            1.15,
            "Persson 2019, table 5.6, SSBO with multiple targets, 4096",
        ),
        (
            "granular/slopes_interleaved10/4096",
            14.48,
            "Persson 2019, table 5.4, Even out steep slopes (interleaved, 10 passes), 4096",
        ),
        (
            "granular/slopes_scatter10/4096",
            5.486,
            "Persson 2019, table 5.5, Even out steep slopes (scatter, 10 passes), 4096",
        ),
        // The thesis has no whole-step table: its step is the sum of table 5.4's rows (the
        // iterative pair) or table 5.5's (the SSBO pair), depth to slopes.
        (
            "granular/step_jfa_closest_seed_scatter10/4096",
            17.07,
            "Persson 2019, table 5.5, sum of depth + penetration + JFA + displace + slopes",
        ),
        (
            "granular/step_exact_closest_seed_scatter10/4096",
            17.07,
            "Persson 2019, table 5.5, the same sum (exact transform in place of JFA)",
        ),
        (
            "granular_step/jfa_iterative10_interleaved10/4096",
            38.08,
            "Persson 2019, table 5.4, sum of depth + penetration + JFA + displace + slopes (GranularSim::step, volume included)",
        ),
        (
            "granular_step/jfa_closest_seed_scatter10/4096",
            17.07,
            "Persson 2019, table 5.5, the same sum (GranularSim::step, volume included)",
        ),
        (
            "granular_step/exact_closest_seed_scatter10/4096",
            17.07,
            "Persson 2019, table 5.5, the same sum (GranularSim::step, exact transform)",
        ),
    ];
    for (id, ms, thesis) in granular {
        out.push(Headline {
            id: id.into(),
            thesis_ms: Some(ms),
            thesis: thesis.into(),
            copy_id: "granular/memcpy_u32/4096".into(),
            map_copy_id: None,
        });
    }
    out
}

/// Reads criterion's median estimate (ns) of `id` from `criterion_dir`.
fn criterion_median_ns(criterion_dir: &Path, id: &str) -> Result<f64> {
    let path = criterion_dir.join(id).join("new").join("estimates.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    v["median"]["point_estimate"]
        .as_f64()
        .with_context(|| format!("no median in {}", path.display()))
}

/// Where `--write-docs` writes the table, relative to the workspace root.
const DOCS_PATH: &str = "docs/BENCHMARKS.md";

/// The first line of [`DOCS_PATH`].
const DOCS_HEADER: &str =
    "<!-- Generated by `cargo xtask bench-report --write-docs`: do not edit by hand. -->";

/// The whole of [`DOCS_PATH`] for the report `md` (its table and notes).
fn benchmarks_doc(md: &str) -> String {
    format!("{DOCS_HEADER}\n\n# Benchmarks\n\n{}\n", md.trim())
}

/// Runs the headline CPU benches briefly (criterion's `--quick` mode with `--quick`), on all
/// cores and then on one (`RAYON_NUM_THREADS=1`, its own criterion folder), and writes
/// `target/bench-report.json` and `target/bench-report.md`: each figure, the thesis figure it
/// is compared with, and its ratio to plain copies of the same bytes measured in the same run.
/// With `--write-docs` the table and its notes also become [`DOCS_PATH`] (written whole,
/// atomically; the file need not exist before).
pub fn bench_report(args: &[String]) -> Result<()> {
    let quick = args.iter().any(|a| a == "--quick");
    let write_docs = args.iter().any(|a| a == "--write-docs");
    if let Some(bad) = args
        .iter()
        .find(|a| !matches!(a.as_str(), "--quick" | "--write-docs"))
    {
        bail!("bench-report: unknown argument {bad} (expected --quick, --write-docs)");
    }
    let target = target_dir();
    let one_core_dir = target.join("criterion-1-thread");
    let benches: [(&str, &str); 2] = [
        (
            "stamp_normals",
            "^stamp_normals/(stamp|stamp_reference|stamp_gaussian_rotated|stamp_texture_rotated|stamp_min_max|normals|memcpy|memcpy_in_map)/(500|1000|2000)$",
        ),
        (
            "granular",
            "^granular/(jump_flood|jump_flood_reference|exact_nearest_seed|displace_iterative10|displace_iterative1|displace_closest_seed|displace_multiple_targets|slopes_interleaved10|slopes_scatter10|step_jfa_closest_seed_scatter10|step_exact_closest_seed_scatter10|memcpy_u32)/4096$|^granular_step/",
        ),
    ];
    let one_core = one_core_dir.to_string_lossy().into_owned();
    let runs: [&[(&str, &str)]; 2] = [
        &[],
        &[("RAYON_NUM_THREADS", "1"), ("CRITERION_HOME", &one_core)],
    ];
    for env in runs {
        for (bench, filter) in benches {
            let mut args = vec![
                "bench",
                "--locked",
                "-p",
                "terrain-core",
                "--bench",
                bench,
                "--",
            ];
            if quick {
                args.push("--quick");
            }
            args.push(filter);
            cargo(&args, env)?;
        }
    }
    let criterion_dir = target.join("criterion");
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut rows = Vec::new();
    let mut md = format!(
        "| benchmark | {threads} cores (ms) | 1 core (ms) | thesis (ms) | thesis figure | x thesis | x copy | x copy, 1 core | x copy in the map |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for h in headlines() {
        let ns = criterion_median_ns(&criterion_dir, &h.id)?;
        let one_ns = criterion_median_ns(&one_core_dir, &h.id)?;
        let copy_ns = criterion_median_ns(&criterion_dir, &h.copy_id)?;
        // The one-core figure over the copy of the same run: both on one thread.
        let one_copy_ns = criterion_median_ns(&one_core_dir, &h.copy_id)?;
        let map_copy_ns = match &h.map_copy_id {
            Some(id) => Some(criterion_median_ns(&criterion_dir, id)?),
            None => None,
        };
        let ms = ns / 1e6;
        let vs_thesis = h.thesis_ms.map(|t| ms / t);
        md.push_str(&format!(
            "| `{}` | {:.3} | {:.3} | {} | {} | {} | {:.1} ({:.1} us) | {:.1} ({:.1} us) | {} |\n",
            h.id,
            ms,
            one_ns / 1e6,
            h.thesis_ms.map_or("-".into(), |t| format!("{t:.3}")),
            h.thesis,
            vs_thesis.map_or("-".into(), |r| format!("{r:.2}")),
            ns / copy_ns,
            copy_ns / 1e3,
            one_ns / one_copy_ns,
            one_copy_ns / 1e3,
            map_copy_ns.map_or("-".into(), |c| format!("{:.1} ({:.1} us)", ns / c, c / 1e3)),
        ));
        rows.push(serde_json::json!({
            "id": h.id,
            "median_ms": ms,
            "one_core_median_ms": one_ns / 1e6,
            "thesis_ms": h.thesis_ms,
            "thesis": h.thesis,
            "ratio_to_thesis": vs_thesis,
            "copy_id": h.copy_id,
            "copy_ms": copy_ns / 1e6,
            "ratio_to_copy": ns / copy_ns,
            "one_core_copy_ms": one_copy_ns / 1e6,
            "one_core_ratio_to_copy": one_ns / one_copy_ns,
            "map_copy_id": h.map_copy_id,
            "map_copy_ms": map_copy_ns.map(|c| c / 1e6),
            "ratio_to_map_copy": map_copy_ns.map(|c| ns / c),
        }));
    }
    md.push_str(&format!(
        "\nCriterion medians{}, on {threads} CPU threads and on 1 (`RAYON_NUM_THREADS=1`). \
         \"x copy\": the figure over a plain `copy_from_slice` of the same texels (the region's \
         u16 heights, its rows read from the map into a buffer of their own, or the area's u32 \
         columns between two buffers); \"x copy, 1 core\": the one-core figure over the copy \
         of its own run (both on one thread: the fair ratio); \"x copy in the map\": over \
         copying the region's rows in place into a second 4096^2 map (the strided, \
         cache-missing access a stamp makes). The copies run on one thread, in the same run. \
         Figures from a shared machine are noisy; compare ratios measured in the same run.\n",
        if quick { " (--quick)" } else { "" },
    ));
    md.push_str(&format!(
        "\n## GPU memory per texel\n\n{}",
        gpu_memory_table()?
    ));
    let json = serde_json::json!({ "quick": quick, "threads": threads, "figures": rows });
    std::fs::create_dir_all(&target)?;
    let json_path = target.join("bench-report.json");
    let md_path = target.join("bench-report.md");
    std::fs::write(&json_path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", json_path.display()))?;
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    println!("{md}");
    eprintln!("wrote {} and {}", json_path.display(), md_path.display());
    if write_docs {
        let path = root().join(DOCS_PATH);
        write_atomically(&path, benchmarks_doc(&md).as_bytes())?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// The bytes per texel of every GPU resource, measured by terrain-gpu's `gpu_memory` example
/// from the buffers it allocates on this machine's adapter (a software one will do: sizes do
/// not depend on the adapter).
fn gpu_memory_table() -> Result<String> {
    let out = std::process::Command::new(crate::util::cargo_exe())
        .args([
            "run",
            "--locked",
            "--release",
            "-p",
            "terrain-gpu",
            "--example",
            "gpu_memory",
        ])
        .current_dir(root())
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("running terrain-gpu's gpu_memory example")?;
    if !out.status.success() {
        bail!("terrain-gpu's gpu_memory example failed ({})", out.status);
    }
    String::from_utf8(out.stdout).context("gpu_memory's table is not UTF-8")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headlines_name_their_copies_and_thesis_figures() {
        let h = headlines();
        assert!(
            h.iter()
                .all(|h| h.thesis_ms.is_some() && !h.copy_id.is_empty())
        );
        for side in [500, 1000, 2000] {
            let id = format!("stamp_normals/stamp_texture_rotated/{side}");
            let t = h.iter().find(|h| h.id == id).unwrap();
            assert_eq!(t.copy_id, format!("stamp_normals/memcpy/{side}"));
            assert_eq!(
                t.map_copy_id.as_deref(),
                Some(&*format!("stamp_normals/memcpy_in_map/{side}"))
            );
        }
        let ids: std::collections::HashSet<_> = h.iter().map(|h| &h.id).collect();
        assert_eq!(ids.len(), h.len(), "no figure twice");
    }

    #[test]
    fn benchmarks_doc_is_the_table_under_its_generated_header() {
        let doc = benchmarks_doc("| a | b |\n|---|---|\n| 1 | 2 |\n\nnotes\n\n");
        assert_eq!(doc.lines().next(), Some(DOCS_HEADER));
        assert!(DOCS_HEADER.contains("cargo xtask bench-report"));
        assert!(DOCS_HEADER.contains("do not edit by hand"));
        assert!(
            doc.contains("\n| a | b |\n|---|---|\n| 1 | 2 |\n\nnotes\n"),
            "{doc}"
        );
        assert!(doc.ends_with("notes\n"), "one newline at the end: {doc:?}");
        // Written twice from the same report, the file does not change.
        assert_eq!(benchmarks_doc(&doc[doc.find('|').unwrap()..]), doc);
    }

    /// The generated file may be missing (nothing measured yet); when present it is the
    /// generator's, header first.
    #[test]
    fn docs_benchmarks_is_missing_or_generated() {
        match std::fs::read_to_string(root().join(DOCS_PATH)) {
            Ok(text) => assert_eq!(
                text.lines().next(),
                Some(DOCS_HEADER),
                "{DOCS_PATH} is generated by `cargo xtask bench-report --write-docs`"
            ),
            Err(e) => assert_eq!(e.kind(), std::io::ErrorKind::NotFound, "{DOCS_PATH}: {e}"),
        }
    }
}
