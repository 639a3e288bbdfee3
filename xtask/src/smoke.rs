//! `cargo xtask smoke`: runs the demo at a tiny size on the default adapter and on GL, then
//! the snow scenario on the GPU and the CPU, and checks what each run reports, so the demo's
//! whole frame stays working on both backends.

use crate::util::{demo, root};
use anyhow::{Context, Result, bail};

/// Runs the demo at a tiny size on the default adapter (Vulkan in CI) and again on GL, so the
/// fallback formats stay honest, and checks frames, summary and report each time.
pub fn smoke() -> Result<()> {
    smoke_on(None)?;
    smoke_on(Some("gl"))?;
    smoke_snow()
}

/// The snow scenario at a tiny size: frames, and a granular volume that never changes.
fn smoke_snow() -> Result<()> {
    let gpu = snow_run("gpu", &[])?;
    let cpu = snow_run("cpu", &["--no-gpu"])?;
    if gpu != cpu {
        bail!("snow: the GPU run's volume {gpu} differs from the CPU run's {cpu}");
    }
    Ok(())
}

/// Runs the snow scenario (6 frames, 128^2) with `extra` flags; checks every frame reports
/// `backend` as its granular backend and the same granular volume; returns that volume.
fn snow_run(backend: &str, extra: &[&str]) -> Result<u64> {
    let out = root()
        .join("target")
        .join(format!("ci-smoke-snow-{backend}"));
    if out.exists() {
        std::fs::remove_dir_all(&out).context("could not clear the smoke output folder")?;
    }
    let out_s = out.to_string_lossy().into_owned();
    let mut args = vec![
        "--scenario",
        "snow",
        "--size",
        "128",
        "--frames",
        "6",
        "--resolution",
        "160x96",
        "--out",
        &out_s,
    ];
    args.extend_from_slice(extra);
    demo(&args, &[])?;
    let text = std::fs::read_to_string(out.join("report.json")).context("no snow report")?;
    let report: serde_json::Value = serde_json::from_str(&text).context("invalid report.json")?;
    let frames = report["frames"].as_array().cloned().unwrap_or_default();
    let volumes: Vec<u64> = frames
        .iter()
        .filter_map(|f| f["granular_volume"].as_u64())
        .collect();
    if volumes.len() != 6 || volumes.iter().any(|v| *v != volumes[0]) {
        bail!("snow ({backend}): granular volume must be reported and constant, got {volumes:?}");
    }
    if let Some(f) = frames
        .iter()
        .find(|f| f["granular_backend"].as_str() != Some(backend))
    {
        bail!(
            "snow: granular steps expected on the {backend}, frame {} reports {}",
            f["index"],
            f["granular_backend"]
        );
    }
    eprintln!(
        "smoke (snow on the {backend}): 6 frames, granular volume constant at {}",
        volumes[0]
    );
    Ok(volumes[0])
}

fn smoke_on(backend: Option<&str>) -> Result<()> {
    let name = backend.unwrap_or("default");
    let out = root().join("target").join(format!("ci-smoke-{name}"));
    if out.exists() {
        std::fs::remove_dir_all(&out).context("could not clear the smoke output folder")?;
    }
    let out_s = out.to_string_lossy().into_owned();
    let frames = 4;
    let env: Vec<(&str, &str)> = backend.map(|b| ("WGPU_BACKEND", b)).into_iter().collect();
    demo(
        &[
            "--size",
            "96",
            "--frames",
            "4",
            "--seed",
            "7",
            "--resolution",
            "160x96",
            "--out",
            &out_s,
        ],
        &env,
    )?;
    let report_path = out.join("report.json");
    let text = std::fs::read_to_string(&report_path)
        .with_context(|| format!("no report at {}", report_path.display()))?;
    let report: serde_json::Value =
        serde_json::from_str(&text).context("report.json is not valid JSON")?;
    let backend_found = report["backend"].as_str().unwrap_or("none");
    if backend_found == "none" {
        bail!("the demo found no GPU adapter ({name} backend): 3D frames were not rendered");
    }
    if let Some(b) = backend
        && backend_found != b
    {
        bail!("asked for the {b} backend, the demo ran on {backend_found}");
    }
    let listed = report["frames"].as_array().map_or(0, Vec::len);
    if listed != frames {
        bail!("report.json lists {listed} frames, {frames} expected");
    }
    for (i, frame) in report["frames"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
    {
        let timings = frame["timings_ms"]
            .as_object()
            .with_context(|| format!("frame {i} has no timings_ms"))?;
        for step in ["stamp_gpu", "normals_gpu", "render"] {
            if !timings
                .get(step)
                .and_then(|v| v.as_f64())
                .is_some_and(|t| t >= 0.0)
            {
                bail!("frame {i} lacks a valid `{step}` timing: {timings:?}");
            }
        }
        if frame["triangles"].as_u64().unwrap_or(0) == 0 {
            bail!("frame {i} drew no triangles");
        }
        match frame["camera_clearance_m"].as_f64() {
            Some(c) if c >= 0.0 => {}
            other => {
                bail!("frame {i}: camera clearance {other:?} (must be present, never negative)")
            }
        }
        let file = frame["file"].as_str().unwrap_or_default();
        if !out.join(file).is_file() {
            bail!("frame {i}: image `{file}` is missing");
        }
    }
    let landed = report["frames"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|f| f["readback_ms"].as_f64().is_some())
        .count();
    if landed == 0 {
        bail!("no collision readback landed in {frames} frames");
    }
    for file in ["terrain.png", "terrain_final.png", "summary.png"] {
        if !out.join(file).is_file() {
            bail!("{file} is missing");
        }
    }
    eprintln!("smoke ({name}): {frames} frames on {backend_found} and a valid report in {out_s}");
    Ok(())
}
