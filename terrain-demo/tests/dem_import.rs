//! DEM import as a user runs it: each format through `--heightmap` (what was chosen printed
//! and written to report.json), nodata reported, a geographic GeoTIFF explained, bad files and
//! flags refused with one line and exit 2, and, with a GPU, a 10 m DEM rendered with the
//! default camera showing its relief instead of the flat plain it used to be.

mod common;

use common::{demo, fresh_dir, report, run_within};
use std::path::Path;
use std::time::Duration;
use terrain_core::Grid;
use tiff::encoder::{Compression, TiffEncoder, colortype};
use tiff::tags::Tag;

const LIMIT: Duration = Duration::from_secs(300);

/// Heights of a rough mountain, `lo..hi` metres over `n x n` samples: ridges and valleys at
/// several scales (a DEM's relief, not a smooth bump).
fn mountain(n: u32, lo: f32, hi: f32) -> Vec<f32> {
    let mut v = Vec::with_capacity((n * n) as usize);
    for y in 0..n {
        for x in 0..n {
            let (u, w) = (x as f32 / n as f32, y as f32 / n as f32);
            let d = ((u - 0.5).powi(2) + (w - 0.5).powi(2)).sqrt();
            let mut h = (1.0 - 1.6 * d).max(0.0);
            for k in 1..5 {
                let f = (1 << k) as f32 * 3.0;
                h += 0.35 / k as f32 * ((u * f + w * 1.7).sin() * (w * f - u * 0.9).cos()).abs();
            }
            v.push(h);
        }
    }
    let (a, b) = v
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &h| (a.min(h), b.max(h)));
    v.iter()
        .map(|h| lo + (hi - lo) * (h - a) / (b - a))
        .collect()
}

/// Writes an f32 GeoTIFF (LZW, as GDAL writes DEMs) with a pixel scale and, when given, a
/// GDAL nodata value and GeoKeys.
fn write_geotiff(
    path: &Path,
    n: u32,
    heights: &[f32],
    scale: f64,
    nodata: Option<&str>,
    geokeys: &[u16],
) {
    let file = std::fs::File::create(path).expect("create tif");
    let mut enc = TiffEncoder::new(std::io::BufWriter::new(file))
        .expect("encoder")
        .with_compression(Compression::Lzw);
    let mut image = enc
        .new_image::<colortype::Gray32Float>(n, n)
        .expect("image");
    image
        .encoder()
        .write_tag(Tag::ModelPixelScaleTag, &[scale, scale, 0.0][..])
        .expect("scale");
    image
        .encoder()
        .write_tag(
            Tag::ModelTiepointTag,
            &[0.0, 0.0, 0.0, 500_000.0, 46.5, 0.0][..],
        )
        .expect("tiepoint");
    if !geokeys.is_empty() {
        image
            .encoder()
            .write_tag(Tag::GeoKeyDirectoryTag, geokeys)
            .expect("geokeys");
    }
    if let Some(text) = nodata {
        image
            .encoder()
            .write_tag(Tag::GdalNodata, text)
            .expect("nodata");
    }
    image.write_data(heights).expect("samples");
}

/// GeoKeys of a projected raster in metres.
const PROJECTED: [u16; 12] = [1, 1, 0, 2, 1024, 0, 1, 1, 3076, 0, 1, 9001];
/// GeoKeys of a geographic raster.
const GEOGRAPHIC: [u16; 8] = [1, 1, 0, 1, 1024, 0, 1, 2];

/// Runs the demo with `args` into `dir/out`: exit code, stderr, report (when written).
fn run(dir: &Path, args: &[&str]) -> (Option<i32>, String, Option<serde_json::Value>) {
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&out);
    let mut cmd = demo();
    cmd.args(args).arg("--out").arg(&out);
    let done = run_within(cmd, dir, LIMIT);
    let report = out.join("report.json").is_file().then(|| report(&out));
    (done.status.code(), done.stderr, report)
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// A run without a GPU that must succeed; returns stderr and report.
fn ok(dir: &Path, args: &[&str]) -> (String, serde_json::Value) {
    let mut all = vec!["--no-gpu", "--frames", "1", "--overview-size", "32"];
    all.extend(args);
    let (code, stderr, report) = run(dir, &all);
    assert_eq!(code, Some(0), "{args:?}: {stderr}");
    (stderr, report.expect("report.json"))
}

fn f(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

#[test]
fn every_format_is_imported_and_reported() {
    let dir = fresh_dir("dem_formats");
    let n = 64;
    let metres = mountain(n, 100.0, 900.0);
    let path = |name: &str| dir.join(name);

    // GeoTIFF: metres kept, texel size from the pixel scale, encoding over the data's range.
    let tif = path("dem.tif");
    write_geotiff(&tif, n, &metres, 10.0, None, &PROJECTED);
    let (stderr, r) = ok(&dir, &["--heightmap", &s(&tif)]);
    assert!(
        stderr.contains("GeoTIFF f32") && stderr.contains("texel 10 m"),
        "{stderr}"
    );
    assert_eq!(r["texel_size_m"].as_f64(), Some(10.0));
    assert_eq!(
        r["camera"].as_str(),
        Some("orbit"),
        "the default with a heightmap"
    );
    let e = &r["height_encoding"];
    assert_eq!(e["source"].as_str(), Some("data"));
    assert!((f(&e["min_m"]) - 100.0).abs() < 0.01 && (f(&e["max_m"]) - 900.0).abs() < 0.05);
    assert!((f(&e["offset"]) - 100.0).abs() < 0.01, "{e}");
    assert!((f(&e["scale"]) - 800.0 / 65535.0).abs() < 1e-6, "{e}");
    assert_eq!(r["heightmap"]["format"].as_str(), Some("GeoTIFF"));
    assert!(r.get("nodata").is_none(), "no nodata: no field");
    // --texel-size overrides the file's pixel scale; --height-range spans what it says.
    let (_, r) = ok(
        &dir,
        &[
            "--heightmap",
            &s(&tif),
            "--texel-size",
            "2.5",
            "--height-range",
            "0:1000",
        ],
    );
    assert_eq!(r["texel_size_m"].as_f64(), Some(2.5));
    assert_eq!(
        r["height_encoding"]["source"].as_str(),
        Some("height-range")
    );
    assert!((f(&r["height_encoding"]["max_m"]) - 1000.0).abs() < 0.05);

    // PNG16 of metres (as GDAL exports a DEM to UInt16): `auto` takes them as metres.
    let g16 = Grid::from_vec(n, n, metres.iter().map(|&m| m.round() as u16).collect()).unwrap();
    let png = path("dem.png");
    terrain_core::io::write_png16(&png, &g16).unwrap();
    let (stderr, r) = ok(&dir, &["--heightmap", &s(&png), "--texel-size", "10"]);
    assert!(stderr.contains("integers taken as metres"), "{stderr}");
    assert!((f(&r["height_encoding"]["data_max_m"]) - 900.0).abs() < 0.6);
    // --max-height keeps its meaning: the 16-bit range is 0..M.
    let (_, r) = ok(&dir, &["--heightmap", &s(&png), "--max-height", "12"]);
    assert_eq!(r["height_encoding"]["source"].as_str(), Some("max-height"));
    assert!((f(&r["height_encoding"]["max_m"]) - 12.0).abs() < 1e-3);
    assert_eq!(r["texel_size_m"].as_f64(), Some(0.1), "the old default");

    // PNG8 mapped onto a range.
    let g8 = Grid::from_vec(
        n,
        n,
        g16.as_slice().iter().map(|&v| (v / 4) as u8).collect(),
    )
    .unwrap();
    let png8 = path("dem8.png");
    terrain_core::io::write_png8(&png8, &g8).unwrap();
    let (_, r) = ok(
        &dir,
        &["--heightmap", &s(&png8), "--height-range", "-10:245"],
    );
    assert_eq!(r["heightmap"]["sample"].as_str(), Some("u8"));
    assert!((f(&r["height_encoding"]["min_m"]) + 10.0).abs() < 1e-3);

    // RAW16 both byte orders: the same heights either way.
    let le: Vec<u8> = g16
        .as_slice()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let be: Vec<u8> = g16
        .as_slice()
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    std::fs::write(path("le.r16"), le).unwrap();
    std::fs::write(path("be.raw"), be).unwrap();
    let size = format!("{n}x{n}");
    let (_, a) = ok(
        &dir,
        &["--heightmap", &s(&path("le.r16")), "--raw-size", &size],
    );
    let (_, b) = ok(
        &dir,
        &[
            "--heightmap",
            &s(&path("be.raw")),
            "--raw-size",
            &size,
            "--byte-order",
            "big",
        ],
    );
    assert_eq!(
        a["height_encoding"]["data_max_m"],
        b["height_encoding"]["data_max_m"]
    );
    assert_eq!(a["heightmap"]["format"].as_str(), Some("RAW16"));
    let (_, wrong) = ok(
        &dir,
        &["--heightmap", &s(&path("be.raw")), "--raw-size", &size],
    );
    assert_ne!(
        a["height_encoding"]["data_max_m"], wrong["height_encoding"]["data_max_m"],
        "the byte order matters"
    );

    // R32 with NaN holes: metres kept, the holes filled and reported.
    let mut holes = metres.clone();
    for h in holes.iter_mut().take(10) {
        *h = f32::NAN;
    }
    let r32: Vec<u8> = holes.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path("dem.r32"), r32).unwrap();
    let (stderr, r) = ok(
        &dir,
        &[
            "--heightmap",
            &s(&path("dem.r32")),
            "--raw-size",
            &size,
            "--camera",
            "walker",
        ],
    );
    assert_eq!(r["camera"].as_str(), Some("walker"));
    assert_eq!(r["nodata"]["count"].as_u64(), Some(10), "{r}");
    assert!(stderr.contains("10 nodata samples"), "{stderr}");
    // An explicit --format reads a file whatever its name.
    std::fs::copy(path("dem.r32"), path("heights.bin")).unwrap();
    let (_, r) = ok(
        &dir,
        &[
            "--heightmap",
            &s(&path("heights.bin")),
            "--format",
            "r32",
            "--raw-size",
            &size,
        ],
    );
    assert_eq!(r["heightmap"]["format"].as_str(), Some("R32"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn geotiff_nodata_and_geographic_rasters_are_explained() {
    let dir = fresh_dir("dem_geo");
    let n = 48;
    let mut metres = mountain(n, 300.0, 1200.0);
    for h in metres.iter_mut().take(n as usize) {
        *h = -9999.0;
    }
    let lowest = metres[n as usize..]
        .iter()
        .copied()
        .fold(f32::MAX, f32::min);
    let tif = dir.join("srtm.tif");
    write_geotiff(&tif, n, &metres, 1.0 / 3600.0, Some("-9999"), &GEOGRAPHIC);
    let (stderr, r) = ok(&dir, &["--heightmap", &s(&tif)]);
    let nodata = &r["nodata"];
    assert_eq!(nodata["count"].as_u64(), Some(u64::from(n)), "{r}");
    assert_eq!(nodata["value"].as_f64(), Some(-9999.0));
    assert!(
        (f(&nodata["fill_m"]) - f64::from(lowest)).abs() < 0.01,
        "{nodata}"
    );
    // Filled with the lowest valid height, the range is the valid heights'.
    assert!((f(&r["height_encoding"]["min_m"]) - f64::from(lowest)).abs() < 0.01);
    // Degrees: the texel size is worked out at the raster's latitude, and a warning says so.
    assert!(stderr.contains("geographic raster"), "{stderr}");
    assert!(stderr.contains("--texel-size"), "{stderr}");
    let texel = f(&r["texel_size_m"]);
    assert!(
        (texel - 30.87).abs() < 0.1,
        "1 arc-second north-south at 46.5°: {texel}"
    );
    assert!(
        r["heightmap"]["texel_size_source"]
            .as_str()
            .is_some_and(|t| t.contains("degrees")),
        "{r}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_dems_nodata_and_colours_become_the_streamed_worlds_holes_and_colour_tiles() {
    let dir = fresh_dir("dem_holes");
    let n = 260;
    let mut metres = mountain(n, 300.0, 1200.0);
    for h in metres.iter_mut().take(n as usize) {
        *h = -9999.0;
    }
    let tif = dir.join("srtm.tif");
    write_geotiff(&tif, n, &metres, 10.0, Some("-9999"), &PROJECTED);
    let color = dir.join("ortho.tif");
    write_rgb_tiff(&color, n, [200, 150, 90]);
    let world_dir = dir.join("world");
    let flyover = ["--scenario", "flyover", "--world"];
    let mut args = flyover.to_vec();
    let (world_arg, tif_arg, color_arg) = (s(&world_dir), s(&tif), s(&color));
    args.extend([
        world_arg.as_str(),
        "--heightmap",
        &tif_arg,
        "--color",
        &color_arg,
    ]);
    let (stderr, _) = ok(&dir, &args);
    assert!(stderr.contains("left out as holes"), "{stderr}");
    assert!(stderr.contains("colour tiles written"), "{stderr}");
    let store =
        std::sync::Arc::new(terrain_cache::FsStore::open_read_only(&world_dir).expect("store"));
    let world = terrain_cache::World::open(store).expect("world");
    let all = terrain_core::Rect::from_size(world.manifest().world_size);
    let holes = terrain_cache::read_holes(&world, all).expect("holes");
    // The first row, and the hole the flyover cuts on its frame 8 not yet (one frame).
    assert_eq!(terrain_core::count_holes(&holes), u64::from(n));
    assert!((0..n).all(|x| terrain_core::is_hole(holes.get(x, 0).expect("cell"))));
    // The image, opaque, in the colour tiles.
    let colors = terrain_cache::read_color(&world, all).expect("colours");
    assert!(colors.as_slice().iter().all(|&c| c == [200, 150, 90, 255]));
    // A colour image of another size than the world is a usage error.
    let small = dir.join("small.tif");
    write_rgb_tiff(&small, 64, [0, 0, 0]);
    let small_arg = s(&small);
    let mut args = flyover.to_vec();
    args.extend([world_arg.as_str(), "--color", &small_arg, "--no-gpu"]);
    let (code, stderr, _) = run(&dir, &args);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("--color") && stderr.contains("260x260"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_dem_files_and_flags_are_one_line_usage_errors() {
    let dir = fresh_dir("dem_bad");
    let n = 32;
    let tif = dir.join("good.tif");
    write_geotiff(&tif, n, &mountain(n, 0.0, 10.0), 1.0, None, &PROJECTED);
    let bytes = std::fs::read(&tif).unwrap();
    let cut = dir.join("cut.tif");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let rgb = dir.join("rgb.tif");
    {
        let file = std::fs::File::create(&rgb).unwrap();
        TiffEncoder::new(file)
            .unwrap()
            .write_image::<colortype::RGB8>(4, 4, &[7u8; 48])
            .unwrap();
    }
    let r16 = dir.join("dem.r16");
    std::fs::write(&r16, [0u8; 2 * 32 * 32]).unwrap();
    let unknown = dir.join("dem.xyz");
    std::fs::write(&unknown, [0u8; 64]).unwrap();
    let nan = dir.join("nan.r32");
    std::fs::write(&nan, f32::NAN.to_le_bytes().repeat(32 * 32)).unwrap();
    // Heights no encoding spans: +-1e29 m (below the 1e30 nodata cut); and heights an
    // encoding spans but no terrain has (+-1e8 m, raw values of a u32 file, say).
    let extremes = |h: f32| -> Vec<u8> {
        (0..32 * 32)
            .flat_map(|i| if i % 2 == 0 { h } else { -h }.to_le_bytes())
            .collect()
    };
    let huge = dir.join("huge.r32");
    std::fs::write(&huge, extremes(1e29)).unwrap();
    let far = dir.join("far.r32");
    std::fs::write(&far, extremes(1e8)).unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["--heightmap".into(), s(&cut)], "truncated"),
        (vec!["--heightmap".into(), s(&rgb)], "one band"),
        (
            vec!["--heightmap".into(), s(&r16)],
            "do not store their size",
        ),
        (
            vec![
                "--heightmap".into(),
                s(&r16),
                "--raw-size".into(),
                "40x40".into(),
            ],
            "does not match size 40x40",
        ),
        (
            vec!["--heightmap".into(), s(&unknown)],
            "cannot tell the format",
        ),
        (
            vec![
                "--heightmap".into(),
                s(&tif),
                "--raw-size".into(),
                "32x32".into(),
            ],
            "store their size",
        ),
        (
            vec![
                "--heightmap".into(),
                s(&nan),
                "--raw-size".into(),
                "32x32".into(),
            ],
            "nodata",
        ),
        (
            vec![
                "--heightmap".into(),
                s(&huge),
                "--raw-size".into(),
                "32x32".into(),
            ],
            "huge.r32",
        ),
        (
            vec![
                "--heightmap".into(),
                s(&far),
                "--raw-size".into(),
                "32x32".into(),
            ],
            "--height-range MIN:MAX",
        ),
        (
            vec![
                "--heightmap".into(),
                s(&tif),
                "--height-range".into(),
                "5:5".into(),
            ],
            "MAX must be above MIN",
        ),
        (
            vec![
                "--scenario".into(),
                "snow".into(),
                "--camera".into(),
                "orbit".into(),
            ],
            "--camera",
        ),
        (
            vec![
                "--heightmap".into(),
                s(&tif),
                "--texel-size".into(),
                "0".into(),
            ],
            "--texel-size",
        ),
    ];
    for (args, says) in cases {
        let mut all: Vec<&str> = vec!["--no-gpu", "--frames", "1"];
        all.extend(args.iter().map(String::as_str));
        let (code, stderr, report) = run(&dir, &all);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        let first = common::usage_error(&stderr);
        assert!(first.contains(says), "{args:?}: `{says}` in: {stderr}");
        assert!(report.is_none(), "{args:?}: refused before any frame");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_geotiff_run_stays_within_its_memory_estimate() {
    let dir = fresh_dir("dem_memory");
    let n = 1024;
    let tif = dir.join("big.tif");
    write_geotiff(&tif, n, &mountain(n, 0.0, 2500.0), 30.0, None, &PROJECTED);
    let (_, r) = ok(&dir, &["--heightmap", &s(&tif), "--max-memory", "2G"]);
    let m = &r["memory"];
    let (estimate, peak) = (
        m["estimate_bytes"].as_u64().expect("estimate"),
        m["peak_rss_bytes"].as_u64().expect("peak (Linux)"),
    );
    let import = m["estimate"]["dem_import"]
        .as_u64()
        .expect("the import is counted");
    assert!(import >= u64::from(n * n) * 8, "{m}");
    assert!(
        peak <= estimate,
        "peak {peak} above the estimate {estimate}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// How a frame looks, over the pixels the overview inset (top right) leaves.
#[derive(Debug)]
struct Look {
    /// Share of the terrain's pixels that are not green: rock, earth, snow.
    not_green: f64,
    /// Standard deviation of the terrain pixels' brightness.
    brightness_spread: f64,
    /// Terrain pixels (neither sky nor inset).
    terrain: usize,
}

fn look(frame: &Path, inset: u32) -> Look {
    let image = terrain_core::io::read_png_rgba8(frame, &Default::default()).expect("frame");
    let (w, _) = (image.width(), image.height());
    let mut lum = Vec::new();
    let mut not_green = 0usize;
    for (i, p) in image.as_slice().iter().enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        if x + inset + 12 >= w && y < inset + 12 {
            continue;
        }
        let [r, g, b, _] = p.map(i32::from);
        // The sky (and terrain faded into the fog, which is the sky's colour) is blue.
        if b > r + 12 && b >= g {
            continue;
        }
        lum.push(0.3 * r as f64 + 0.59 * g as f64 + 0.11 * b as f64);
        if !(g > r + 8 && g > b) {
            not_green += 1;
        }
    }
    let n = lum.len().max(1) as f64;
    let mean = lum.iter().sum::<f64>() / n;
    let var = lum.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / n;
    Look {
        not_green: not_green as f64 / n,
        brightness_spread: var.sqrt(),
        terrain: lum.len(),
    }
}

/// The relief shows: a good part of the terrain is above the grass (rock, snow), shaded
/// in many tones.
fn shows_relief(l: &Look) -> bool {
    l.terrain > 500 && l.not_green > 0.15 && l.brightness_spread > 12.0
}

#[test]
fn a_10m_dem_with_the_default_camera_is_not_a_flat_plain() {
    let Some(ctx) = terrain_gpu::testing::context_or_skip("dem_not_a_flat_plain") else {
        return;
    };
    // The child makes its own device; this one only told us there is an adapter.
    drop(ctx);
    let dir = fresh_dir("dem_render");
    let n = 256;
    let metres = mountain(n, 100.0, 900.0);
    let tif = dir.join("dem.tif");
    write_geotiff(&tif, n, &metres, 10.0, None, &PROJECTED);
    let frame_args = [
        "--frames",
        "2",
        "--resolution",
        "160x90",
        "--overview-size",
        "16",
    ];
    let mut args = vec!["--heightmap", tif.to_str().unwrap()];
    args.extend(frame_args);
    let (code, stderr, r) = run(&dir, &args);
    assert_eq!(code, Some(0), "{stderr}");
    let r = r.expect("report");
    assert_ne!(r["adapter"].as_str(), Some("none"), "rendered on the GPU");
    assert_eq!(r["camera"].as_str(), Some("orbit"));
    let e = &r["height_encoding"];
    assert!(
        (f(&e["min_m"]) - 100.0).abs() < 0.01 && (f(&e["max_m"]) - 900.0).abs() < 0.05,
        "the encoding spans the file's range: {e}"
    );
    for frame in r["frames"].as_array().expect("frames") {
        assert!(f(&frame["camera_clearance_m"]) > 0.0, "{frame}");
    }
    let dem = look(&dir.join("out/frame_0001.png"), 16);
    assert!(shows_relief(&dem), "the DEM's relief: {dem:?}");

    // The same DEM as it was seen before: a 16-bit PNG of metres under the old 0..12 m
    // mapping, from eye height. The measure must tell it apart (it can fail).
    let png = dir.join("dem.png");
    let g = Grid::from_vec(n, n, metres.iter().map(|&m| m.round() as u16).collect()).unwrap();
    terrain_core::io::write_png16(&png, &g).unwrap();
    let mut old = vec![
        "--heightmap",
        png.to_str().unwrap(),
        "--texel-size",
        "10",
        "--max-height",
        "12",
        "--camera",
        "walker",
    ];
    old.extend(frame_args);
    let (code, stderr, _) = run(&dir, &old);
    assert_eq!(code, Some(0), "{stderr}");
    let plain = look(&dir.join("out/frame_0001.png"), 16);
    assert!(!shows_relief(&plain), "the old flat plain: {plain:?}");
    eprintln!("DEM {dem:?}; old plain {plain:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// An RGB TIFF of `n` x `n` pixels, all `rgb`.
fn write_rgb_tiff(path: &Path, n: u32, rgb: [u8; 3]) {
    let data: Vec<u8> = (0..n * n).flat_map(|_| rgb).collect();
    let file = std::fs::File::create(path).expect("create");
    let mut enc = TiffEncoder::new(std::io::BufWriter::new(file)).expect("encoder");
    enc.write_image::<colortype::RGB8>(n, n, &data)
        .expect("write");
}

#[test]
fn an_rgb_geotiff_over_a_dem_colours_every_lod_mode() {
    let Some(ctx) = terrain_gpu::testing::context_or_skip("dem_color_layer") else {
        return;
    };
    drop(ctx);
    let dir = fresh_dir("dem_color");
    let n = 128;
    let tif = dir.join("dem.tif");
    write_geotiff(&tif, n, &mountain(n, 100.0, 400.0), 10.0, None, &PROJECTED);
    let color = dir.join("ortho.tif");
    write_rgb_tiff(&color, n, [200, 40, 200]);
    for lod in ["clipmap", "cdlod", "tessellated"] {
        let args = [
            "--heightmap",
            tif.to_str().unwrap(),
            "--color",
            color.to_str().unwrap(),
            "--lod",
            lod,
            "--frames",
            "2",
            "--resolution",
            "160x90",
            "--overview-size",
            "16",
        ];
        let (code, stderr, r) = run(&dir, &args);
        assert_eq!(code, Some(0), "{lod}: {stderr}");
        assert_eq!(r.expect("report")["config"]["flags"]["lod"], lod);
        // The terrain's pixels are the layer's magenta, lit (the sky and the inset left out).
        let image =
            terrain_core::io::read_png_rgba8(dir.join("out/frame_0001.png"), &Default::default())
                .expect("frame");
        let (mut terrain, mut magenta) = (0usize, 0usize);
        for (i, p) in image.as_slice().iter().enumerate() {
            let (x, y) = (i as u32 % 160, i as u32 / 160);
            let [r, g, b, _] = p.map(i32::from);
            if (x >= 160 - 28 && y < 28) || (b > r + 12 && b >= g) {
                continue;
            }
            terrain += 1;
            magenta += usize::from(r > g + 40 && b > g + 40);
        }
        assert!(terrain > 1000, "{lod}: {terrain} terrain pixels");
        let share = magenta as f64 / terrain as f64;
        assert!(
            share > 0.8,
            "{lod}: {share:.2} of the terrain shows the layer"
        );
    }
    // A layer of another size than the DEM, or without a heightmap, is a usage error.
    let small = dir.join("small.tif");
    write_rgb_tiff(&small, n / 2, [0, 0, 0]);
    let (code, stderr, _) = run(
        &dir,
        &[
            "--heightmap",
            tif.to_str().unwrap(),
            "--color",
            small.to_str().unwrap(),
            "--no-gpu",
        ],
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("--color") && stderr.contains("64x64"),
        "{stderr}"
    );
    let (code, stderr, _) = run(&dir, &["--color", color.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A heightmap whose ground is its highest value almost everywhere (a plateau at the top of
/// the data) becomes a streamed world with room above it: the world scenario's trails pile
/// material there (they failed on frame 0, the rims past what u16 stores), the volume exact.
#[test]
fn a_world_from_a_plateau_at_the_datas_top_leaves_room_for_the_trails() {
    let dir = fresh_dir("dem_plateau");
    let n = 512;
    let mut metres = vec![300.0f32; (n * n) as usize];
    metres[0] = 0.0;
    let tif = dir.join("plateau.tif");
    write_geotiff(&tif, n, &metres, 0.5, None, &PROJECTED);
    let world_dir = dir.join("world");
    let (world_arg, tif_arg) = (s(&world_dir), s(&tif));
    let args = [
        "--no-gpu",
        "--frames",
        "20",
        "--overview-size",
        "32",
        "--scenario",
        "world",
        "--world",
        &world_arg,
        "--heightmap",
        &tif_arg,
    ];
    let (code, stderr, report) = run(&dir, &args);
    assert_eq!(code, Some(0), "{stderr}");
    let report = report.expect("report.json");
    let frames = report["frames"].as_array().unwrap();
    assert!(
        frames
            .iter()
            .any(|f| f["granular_volume"].as_u64().is_some()),
        "the trails ran"
    );
    for f in frames {
        assert_eq!(f["granular_volume"], f["granular_volume_taken"], "{f}");
    }
    let enc = &report["height_encoding"];
    assert!(f(&enc["max_m"]) > 310.0, "room above the plateau: {enc}");
    let _ = std::fs::remove_dir_all(&dir);
}
