//! DEM import per format, with small files made here: PNG 8/16, RAW16 in both byte orders,
//! R32, and GeoTIFFs written by the tests' own baseline TIFF writer (`terrain_test_support::tiff`,
//! not the `tiff` crate the reader uses) in every sample type, both byte orders, strips and
//! tiles, classic and BigTIFF, and by the `tiff` crate's encoder with LZW and Deflate
//! compression; nodata fills, georeferencing (pixel scale, geographic rasters, feet), the
//! format choice, and bad files (truncated, multi-band, huge, special files) with clear errors.
//! `DemFile`: a DEM opened once is read through the handle it was measured by, so a file
//! swapped in at its path between the measure and the read is not the one read.

use glam::UVec2;
use std::path::{Path, PathBuf};
use terrain_core::dem::{
    DemFile, DemFormat, DemOptions, HeightRange, HeightUnits, dem_size, read_dem, resolve_format,
};
use terrain_core::geotiff::{
    MAX_DIRECTORY_VALUES, RasterModel, SampleType, TexelSize, decode_geotiff, read_geotiff,
};
use terrain_core::io::{
    ByteOrder, MapIoError, ReadLimits, encode_png8, encode_png16, encode_raw16,
};
use terrain_core::{CoarseMap, Grid};
use terrain_test_support::tiff as tiff_writer;
use tiff_writer::{Layout, Sample, TiffSpec};

/// A fresh folder for one test, removed at the end.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("terrain_dem_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch folder");
        Self(dir)
    }

    fn file(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.0.join(name);
        std::fs::write(&p, bytes).expect("write");
        p
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn opts() -> DemOptions {
    DemOptions::default()
}

fn raw_opts(size: UVec2, order: ByteOrder) -> DemOptions {
    DemOptions {
        raw_size: Some(size),
        byte_order: order,
        ..DemOptions::default()
    }
}

/// Heights of a hill, in metres, `lo..=hi` over a `w x h` grid.
fn hill(w: u32, h: u32, lo: f64, hi: f64) -> Vec<f64> {
    let c = glam::DVec2::new(f64::from(w - 1), f64::from(h - 1)) / 2.0;
    let r = c.length().max(1.0);
    (0..h)
        .flat_map(|y| {
            (0..w).map(move |x| {
                let d = (glam::DVec2::new(f64::from(x), f64::from(y)) - c).length() / r;
                lo + (hi - lo) * (1.0 - d).clamp(0.0, 1.0)
            })
        })
        .collect()
}

/// The values a sample type holds of `v` (what the writer stores).
fn as_stored(sample: Sample, v: f64) -> f32 {
    match sample {
        Sample::U8 => f32::from(v as u8),
        Sample::I8 => f32::from(v as i8),
        Sample::U16 => f32::from(v as u16),
        Sample::I16 => f32::from(v as i16),
        Sample::U32 => v as u32 as f32,
        Sample::I32 => v as i32 as f32,
        Sample::F32 => v as f32,
        Sample::F64 => v as f32,
    }
}

fn sample_type(s: Sample) -> SampleType {
    match s {
        Sample::U8 => SampleType::U8,
        Sample::I8 => SampleType::I8,
        Sample::U16 => SampleType::U16,
        Sample::I16 => SampleType::I16,
        Sample::U32 => SampleType::U32,
        Sample::I32 => SampleType::I32,
        Sample::F32 => SampleType::F32,
        Sample::F64 => SampleType::F64,
    }
}

// ---------------------------------------------------------------------------------------------
// PNG, RAW16, R32

#[test]
fn png16_and_png8_are_integers_mapped_by_the_range() {
    let dir = Scratch::new("png");
    let g16 = Grid::from_fn(20, 17, |x, y| (x * 3000 + y * 7) as u16).unwrap();
    let p16 = dir.file("dem.png", &encode_png16(&g16).unwrap());
    let dem = read_dem(&p16, &opts()).unwrap();
    assert_eq!(dem.format, DemFormat::Png);
    assert_eq!(dem.sample, SampleType::U16);
    assert_eq!(dem.units, HeightUnits::Stored { full_scale: 65535 });
    assert_eq!(dem.nodata, None);
    assert_eq!(dem.holes, None);
    // A span: the samples are kept exactly, the encoding spans it.
    let q = dem
        .to_coarse_heights(HeightRange::Span {
            min_m: 0.0,
            max_m: 12.0,
        })
        .unwrap();
    assert_eq!(q.grid, g16);
    assert_eq!(q.encoding.range::<u16>(), (0.0, 12.0));
    // Auto: one unit per metre, spanning the data.
    let q = dem.to_coarse_heights(HeightRange::Auto).unwrap();
    assert_eq!(
        (q.data_min_m, q.data_max_m),
        (0.0, 19.0 * 3000.0 + 16.0 * 7.0)
    );
    let m = CoarseMap::coarse(q.grid, q.encoding, 1.0).unwrap();
    let h = m.height_m(19, 16).unwrap();
    assert!((h - 57_112.0).abs() < 1.0, "{h}");

    let g8 = Grid::from_fn(16, 16, |x, y| (x * 10 + y) as u8).unwrap();
    let p8 = dir.file("dem8.png", &encode_png8(&g8).unwrap());
    let dem = read_dem(&p8, &opts()).unwrap();
    assert_eq!(dem.units, HeightUnits::Stored { full_scale: 255 });
    let q = dem
        .to_coarse_heights(HeightRange::Span {
            min_m: 100.0,
            max_m: 355.0,
        })
        .unwrap();
    // 8-bit full scale maps onto the 16-bit one exactly (times 257).
    assert_eq!(q.grid.get(15, 15), Some(165 * 257));
    assert_eq!(
        dem_size(&p8, &opts()).unwrap(),
        (DemFormat::Png, UVec2::new(16, 16))
    );
}

#[test]
fn raw16_reads_either_byte_order() {
    let dir = Scratch::new("raw16");
    let size = UVec2::new(5, 3);
    let values: Vec<u16> = (0..15).map(|i| 0x0102 * i + 1).collect();
    let le: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let be: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    let ple = dir.file("le.r16", &le);
    let pbe = dir.file("be.raw", &be);
    let want: Vec<f32> = values.iter().map(|&v| f32::from(v)).collect();
    let a = read_dem(&ple, &raw_opts(size, ByteOrder::Little)).unwrap();
    let b = read_dem(&pbe, &raw_opts(size, ByteOrder::Big)).unwrap();
    assert_eq!(a.format, DemFormat::Raw16);
    assert_eq!(a.heights.as_slice(), want);
    assert_eq!(b.heights.as_slice(), want);
    // The wrong byte order reads other (byte-swapped) values: the option matters.
    let swapped = read_dem(&pbe, &raw_opts(size, ByteOrder::Little)).unwrap();
    assert_eq!(
        swapped.heights.as_slice()[1],
        f32::from(0x0103u16.swap_bytes())
    );
    assert_ne!(swapped.heights.as_slice(), want);

    // A size is required, and must match the file's length.
    assert!(matches!(
        read_dem(&ple, &opts()),
        Err(MapIoError::RawSizeRequired { format: "RAW16" })
    ));
    let e = read_dem(&ple, &raw_opts(UVec2::new(4, 4), ByteOrder::Little)).unwrap_err();
    assert!(
        matches!(
            e,
            MapIoError::RawSizeMismatch {
                expected_bytes: 32,
                actual_bytes: 30,
                ..
            }
        ),
        "{e}"
    );
    assert!(matches!(
        dem_size(&ple, &raw_opts(UVec2::new(4, 4), ByteOrder::Little)),
        Err(MapIoError::RawSizeMismatch { .. })
    ));
    assert_eq!(
        dem_size(&ple, &raw_opts(size, ByteOrder::Little)).unwrap(),
        (DemFormat::Raw16, size)
    );
}

#[test]
fn r32_keeps_metres_and_fills_nodata() {
    let dir = Scratch::new("r32");
    let size = UVec2::new(4, 2);
    let values = [
        120.5f32,
        f32::NAN,
        99.25,
        -3.4e38,
        300.0,
        f32::INFINITY,
        150.0,
        101.0,
    ];
    for order in [ByteOrder::Little, ByteOrder::Big] {
        let bytes: Vec<u8> = values
            .iter()
            .flat_map(|v| match order {
                ByteOrder::Little => v.to_le_bytes(),
                ByteOrder::Big => v.to_be_bytes(),
            })
            .collect();
        let p = dir.file("dem.r32", &bytes);
        let dem = read_dem(&p, &raw_opts(size, order)).unwrap();
        assert_eq!(dem.format, DemFormat::R32);
        assert_eq!(dem.units, HeightUnits::Metres);
        let fill = dem.nodata.expect("nodata reported");
        assert_eq!((fill.count, fill.fill, fill.value), (3, 99.25, None));
        assert_eq!(
            dem.heights.as_slice(),
            [120.5, 99.25, 99.25, 99.25, 300.0, 99.25, 150.0, 101.0]
        );
        // The filled samples are the DEM's holes.
        let holes = dem.holes.as_ref().expect("holes from nodata");
        assert_eq!(holes.as_slice(), [0, 255, 0, 255, 0, 255, 0, 0]);
        let q = dem.to_coarse_heights(HeightRange::Auto).unwrap();
        assert_eq!((q.data_min_m, q.data_max_m), (99.25, 300.0));
    }
    let p = dir.file("short.r32", &[0u8; 30]);
    let e = read_dem(&p, &raw_opts(size, ByteOrder::Little)).unwrap_err();
    assert!(
        matches!(
            e,
            MapIoError::R32SizeMismatch {
                expected_bytes: 32,
                actual_bytes: 30,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("4 per sample"), "{e}");
    let nan = dir.file("nan.r32", &f32::NAN.to_le_bytes().repeat(8));
    assert!(matches!(
        read_dem(&nan, &raw_opts(size, ByteOrder::Little)),
        Err(MapIoError::NoValidHeights { count: 8, .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// GeoTIFF from the tests' own writer

#[test]
fn geotiff_every_sample_type_order_and_layout_reads_back() {
    let (w, h) = (37, 21);
    let layouts = [
        Layout::Strips(1),
        Layout::Strips(8),
        Layout::Strips(21),
        Layout::Tiles(16, 16),
    ];
    let mut cases = 0;
    for sample in Sample::ALL {
        // Values the type can hold: small types get a small hill, signed ones dip below 0.
        let (lo, hi) = match sample {
            Sample::U8 => (3.0, 250.0),
            Sample::I8 => (-100.0, 120.0),
            Sample::U16 => (100.0, 60_000.0),
            Sample::I16 => (-400.0, 8_800.0),
            Sample::U32 => (0.0, 4_000_000.0),
            Sample::I32 => (-11_000.0, 9_000.0),
            Sample::F32 | Sample::F64 => (-12.375, 4_807.5),
        };
        let values = hill(w, h, lo, hi);
        let want: Vec<f32> = values.iter().map(|&v| as_stored(sample, v)).collect();
        for (i, layout) in layouts.iter().enumerate() {
            for big_endian in [false, true] {
                let bigtiff = i % 2 == 1;
                let spec = TiffSpec {
                    layout: *layout,
                    big_endian,
                    bigtiff,
                    ..TiffSpec::new(w, h, sample, values.clone())
                };
                let tiff = decode_geotiff(&spec.write(), &ReadLimits::default())
                    .unwrap_or_else(|e| panic!("{sample:?} {layout:?} big {big_endian}: {e}"));
                assert_eq!(tiff.sample, sample_type(sample));
                assert_eq!(tiff.heights.size(), UVec2::new(w, h));
                assert_eq!(
                    tiff.heights.as_slice(),
                    want,
                    "{sample:?} {layout:?} big-endian {big_endian} BigTIFF {bigtiff}"
                );
                cases += 1;
            }
        }
    }
    assert_eq!(cases, 8 * 4 * 2);
}

#[test]
fn geotiff_heights_are_metres_and_the_range_follows_them() {
    let dir = Scratch::new("geotiff_metres");
    let values = hill(64, 48, 100.0, 900.0);
    let (lo, hi) = values
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    let spec = TiffSpec {
        pixel_scale: Some([10.0, 10.0, 0.0]),
        geokeys: vec![(1024, 1), (3076, 9001)],
        ..TiffSpec::new(64, 48, Sample::F32, values)
    };
    let p = dir.file("dem.tif", &spec.write());
    let dem = read_dem(&p, &opts()).unwrap();
    assert_eq!(dem.format, DemFormat::GeoTiff);
    assert_eq!(dem.units, HeightUnits::Metres);
    let geo = dem.georeference.expect("georeference");
    assert_eq!(geo.model, RasterModel::Projected);
    assert_eq!(
        geo.texel_size(),
        Some(TexelSize::Metres {
            x_m: 10.0,
            y_m: 10.0
        })
    );
    let q = dem.to_coarse_heights(HeightRange::Auto).unwrap();
    assert_eq!((q.data_min_m, q.data_max_m), (lo as f32, hi as f32));
    let (elo, ehi) = q.encoding.range::<u16>();
    assert!(
        (f64::from(elo) - lo).abs() < 1e-3 && (f64::from(ehi) - hi).abs() < 0.05,
        "{elo}..{ehi}"
    );
    let map = CoarseMap::coarse(q.grid, q.encoding, 10.0).unwrap();
    let centre = map.height_m(32, 24).unwrap();
    assert!(centre > 850.0, "the hill's top: {centre}");
    // A span clamps metres outside it, and says how many.
    let q = dem
        .to_coarse_heights(HeightRange::Span {
            min_m: 0.0,
            max_m: 500.0,
        })
        .unwrap();
    assert!(q.clamped > 0);
    assert_eq!(q.grid.get(32, 24), Some(u16::MAX));
    assert_eq!(
        dem_size(&p, &opts()).unwrap(),
        (DemFormat::GeoTiff, UVec2::new(64, 48))
    );
}

#[test]
fn geotiff_nodata_is_filled_and_reported() {
    // An i16 DEM with GDAL's -32768 nodata around a hill (as SRTM tiles have voids).
    let mut values = hill(20, 20, 50.0, 1500.0);
    for v in values.iter_mut().take(25) {
        *v = -32768.0;
    }
    let spec = TiffSpec {
        nodata: Some("-32768".into()),
        ..TiffSpec::new(20, 20, Sample::I16, values.clone())
    };
    let dem = terrain_core::dem::Dem::from_geotiff(
        decode_geotiff(&spec.write(), &ReadLimits::default()).unwrap(),
    )
    .unwrap();
    let fill = dem.nodata.expect("nodata reported");
    let lowest = values[25..]
        .iter()
        .map(|&v| v as i16 as f32)
        .fold(f32::INFINITY, f32::min);
    assert_eq!(
        (fill.count, fill.value, fill.fill),
        (25, Some(-32768.0), lowest)
    );
    assert!(dem.heights.as_slice().iter().all(|&h| h >= lowest));
    let holes = dem.holes.as_ref().expect("holes from nodata");
    assert_eq!(terrain_core::count_holes(holes), 25);
    assert!(terrain_core::is_hole(holes.get(4, 1).unwrap()));
    assert!(!terrain_core::is_hole(holes.get(5, 1).unwrap()));
    // Without the tag, -32768 is a height like any other: the tag is what matters.
    let untagged = TiffSpec::new(20, 20, Sample::I16, values);
    let tiff = decode_geotiff(&untagged.write(), &ReadLimits::default()).unwrap();
    assert_eq!(tiff.nodata, None);
    assert_eq!(tiff.heights.as_slice()[0], -32768.0);

    // f32 with `nan` as GDAL writes it, and GDAL's f32 nodata (f32::MIN written as text).
    for text in ["nan", "-3.4028234663852886e+38", " -9999 "] {
        let mut v = hill(8, 8, 10.0, 20.0);
        let marker = match text {
            "nan" => f64::NAN,
            " -9999 " => -9999.0,
            _ => f64::from(f32::MIN),
        };
        v[0] = marker;
        v[9] = marker;
        let spec = TiffSpec {
            nodata: Some(text.into()),
            ..TiffSpec::new(8, 8, Sample::F32, v)
        };
        let dem = terrain_core::dem::Dem::from_geotiff(
            decode_geotiff(&spec.write(), &ReadLimits::default()).unwrap(),
        )
        .unwrap();
        assert_eq!(dem.nodata.map(|n| n.count), Some(2), "{text}");
    }
    // All nodata: an error that says so.
    let spec = TiffSpec {
        nodata: Some("-9999".into()),
        ..TiffSpec::new(4, 4, Sample::F64, vec![-9999.0; 16])
    };
    let e = terrain_core::dem::Dem::from_geotiff(
        decode_geotiff(&spec.write(), &ReadLimits::default()).unwrap(),
    )
    .unwrap_err();
    assert!(
        matches!(e, MapIoError::NoValidHeights { count: 16, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("-9999"), "{e}");
    // A nodata tag that is no number.
    let spec = TiffSpec {
        nodata: Some("none".into()),
        ..TiffSpec::new(4, 4, Sample::F32, vec![1.0; 16])
    };
    let e = decode_geotiff(&spec.write(), &ReadLimits::default()).unwrap_err();
    assert!(
        e.to_string().contains("42113") && e.to_string().contains("none"),
        "{e}"
    );
}

#[test]
fn geotiff_georeferencing_gives_the_texel_size() {
    let decode = |spec: TiffSpec| decode_geotiff(&spec.write(), &ReadLimits::default()).unwrap();
    let base = || TiffSpec::new(16, 16, Sample::U16, hill(16, 16, 0.0, 300.0));
    // No georeferencing at all: no texel size.
    assert_eq!(decode(base()).geo.texel_size(), None);
    // A geographic raster of 1 arc-second at 46.5° N: metres from the latitude.
    let arcsec = 1.0 / 3600.0;
    let t = decode(TiffSpec {
        pixel_scale: Some([arcsec, arcsec, 0.0]),
        tiepoint: Some([0.0, 0.0, 0.0, 7.0, 46.5 + 8.0 * arcsec, 0.0]),
        geokeys: vec![(1024, 2)],
        ..base()
    });
    assert_eq!(t.geo.model, RasterModel::Geographic);
    match t.geo.texel_size() {
        Some(TexelSize::Degrees {
            north_south_m,
            east_west_m,
            latitude: Some(lat),
            guessed: false,
            ..
        }) => {
            assert!((lat - 46.5).abs() < 1e-6, "{lat}");
            assert!((north_south_m - 30.87).abs() < 0.05, "{north_south_m}");
            assert!((east_west_m - 21.3).abs() < 0.1, "{east_west_m}");
        }
        other => panic!("{other:?}"),
    }
    // No GeoKeys but a tiny scale: degrees, guessed.
    let t = decode(TiffSpec {
        pixel_scale: Some([arcsec, arcsec, 0.0]),
        ..base()
    });
    assert!(matches!(
        t.geo.texel_size(),
        Some(TexelSize::Degrees {
            guessed: true,
            latitude: None,
            ..
        })
    ));
    // Feet: the pixel scale (linear unit) and the heights (vertical unit) become metres.
    let t = decode(TiffSpec {
        pixel_scale: Some([30.0, 30.0, 0.0]),
        geokeys: vec![(1024, 1), (3076, 9002), (4099, 9002)],
        ..TiffSpec::new(2, 1, Sample::F32, vec![1000.0, 10.0])
    });
    match t.geo.texel_size() {
        Some(TexelSize::Metres { x_m, .. }) => assert!((x_m - 9.144).abs() < 1e-9),
        other => panic!("{other:?}"),
    }
    assert_eq!(t.heights.as_slice(), [304.8, 3.048]);
    // A model transformation instead of a pixel scale.
    let mut m = [0.0f64; 16];
    m[0] = 25.0;
    m[5] = -25.0;
    m[15] = 1.0;
    let bytes: Vec<u8> = m.iter().flat_map(|v| v.to_le_bytes()).collect();
    let t = decode(TiffSpec {
        extra: vec![(34264, tiff_writer::DOUBLE, 16, bytes)],
        ..base()
    });
    assert_eq!(t.geo.pixel_scale, Some([25.0, 25.0]));
}

// ---------------------------------------------------------------------------------------------
// GeoTIFF from the `tiff` crate's encoder: compression and predictors

#[test]
fn compressed_geotiffs_from_the_tiff_encoder_read_back() {
    use tiff::encoder::{Compression, DeflateLevel, Predictor, TiffEncoder, colortype};
    use tiff::tags::Tag;
    let (w, h) = (70u32, 45u32);
    let metres: Vec<f32> = hill(w, h, -5.5, 2_400.25)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let ints: Vec<u16> = metres.iter().map(|&v| (v + 10.0) as u16).collect();
    let compressions = [
        ("LZW", Compression::Lzw),
        ("Deflate", Compression::Deflate(DeflateLevel::Fast)),
        ("PackBits", Compression::Packbits),
    ];
    for (name, compression) in compressions {
        for predictor in [Predictor::None, Predictor::Horizontal] {
            let mut f32_file = std::io::Cursor::new(Vec::new());
            // (The encoder has no floating-point predictor: floats go without one.)
            let mut enc = TiffEncoder::new(&mut f32_file)
                .unwrap()
                .with_compression(compression);
            let mut image = enc.new_image::<colortype::Gray32Float>(w, h).unwrap();
            image
                .encoder()
                .write_tag(Tag::ModelPixelScaleTag, &[5.0f64, 5.0, 0.0][..])
                .unwrap();
            image.encoder().write_tag(Tag::GdalNodata, "-9999").unwrap();
            image.write_data(&metres).unwrap();
            let t = decode_geotiff(f32_file.get_ref(), &ReadLimits::default())
                .unwrap_or_else(|e| panic!("{name} {predictor:?}: {e}"));
            assert_eq!(t.heights.as_slice(), metres, "{name} {predictor:?}");
            assert_eq!(t.geo.pixel_scale, Some([5.0, 5.0]));
            assert_eq!(t.nodata, Some(-9999.0));

            let mut u16_file = std::io::Cursor::new(Vec::new());
            TiffEncoder::new(&mut u16_file)
                .unwrap()
                .with_compression(compression)
                .with_predictor(predictor)
                .write_image::<colortype::Gray16>(w, h, &ints)
                .unwrap();
            let t = decode_geotiff(u16_file.get_ref(), &ReadLimits::default()).unwrap();
            let want: Vec<f32> = ints.iter().map(|&v| f32::from(v)).collect();
            assert_eq!(t.heights.as_slice(), want, "{name} {predictor:?}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The format choice

#[test]
fn the_format_follows_the_extension_then_the_signature_then_the_size() {
    let dir = Scratch::new("format");
    let png = encode_png16(&Grid::new(4, 4, 9u16).unwrap()).unwrap();
    let tif = TiffSpec::new(4, 4, Sample::U8, vec![1.0; 16]).write();
    let p = dir.file("heights.dat", &png);
    assert_eq!(resolve_format(&p, &opts()).unwrap(), DemFormat::Png);
    let t = dir.file("heights.bin", &tif);
    assert_eq!(resolve_format(&t, &opts()).unwrap(), DemFormat::GeoTiff);
    let r = dir.file("heights", &[0u8; 32]);
    assert!(matches!(
        resolve_format(&r, &opts()),
        Err(MapIoError::UnknownFormat { .. })
    ));
    let sized = raw_opts(UVec2::new(4, 4), ByteOrder::Little);
    assert_eq!(resolve_format(&r, &sized).unwrap(), DemFormat::Raw16);
    // An explicit format wins over the extension.
    let forced = DemOptions {
        format: Some(DemFormat::R32),
        raw_size: Some(UVec2::new(2, 4)),
        ..DemOptions::default()
    };
    let r16 = dir.file("actually_floats.r16", &1.5f32.to_le_bytes().repeat(8));
    assert_eq!(
        read_dem(&r16, &forced).unwrap().heights.as_slice(),
        [1.5; 8]
    );
    // A size for a format that stores its own is refused: it would be ignored otherwise.
    let named = dir.file("dem.png", &png);
    assert!(matches!(
        resolve_format(&named, &sized),
        Err(MapIoError::RawSizeUnused { format: "PNG" })
    ));
    let e = resolve_format(&r, &opts()).unwrap_err().to_string();
    assert!(e.contains(".tif") && e.contains(".r32"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Bad files

#[test]
fn bad_geotiffs_get_clear_errors() {
    let l = ReadLimits::default();
    let good = TiffSpec {
        pixel_scale: Some([1.0, 1.0, 0.0]),
        ..TiffSpec::new(9, 7, Sample::F32, hill(9, 7, 1.0, 2.0))
    };
    let bytes = good.write();
    // Every cut of the file is an error (never a panic); a cut inside the header or the
    // directory says the data is truncated.
    for n in 0..bytes.len() {
        let e = decode_geotiff(&bytes[..n], &l).expect_err("a cut file is refused");
        if n < 8 {
            assert!(
                matches!(e, MapIoError::Truncated { .. } | MapIoError::Corrupt { .. }),
                "{n}: {e}"
            );
        }
    }
    // Not a TIFF at all.
    let e = decode_geotiff(b"GIF89a, not a TIFF at all", &l).unwrap_err();
    assert!(e.to_string().contains("not a TIFF"), "{e}");
    // Three bands (an RGB image) and a 1-bit image are not DEMs.
    let rgb = TiffSpec {
        bands: 3,
        ..TiffSpec::new(4, 4, Sample::U8, vec![1.0; 16])
    };
    let e = decode_geotiff(&rgb.write(), &l).unwrap_err();
    assert!(matches!(e, MapIoError::UnsupportedTiff { .. }), "{e}");
    assert!(e.to_string().contains("one band"), "{e}");
    let two = TiffSpec {
        bands: 2,
        ..TiffSpec::new(4, 4, Sample::F32, vec![1.0; 16])
    };
    let e = decode_geotiff(&two.write(), &l).unwrap_err();
    assert!(matches!(e, MapIoError::UnsupportedTiff { .. }), "{e}");
    // A size above the limits is refused from the directory, before any allocation; under
    // raised limits a size no machine can hold is OutOfMemory, not an abort.
    let mut huge = TiffSpec::new(1, 1, Sample::F64, vec![1.0]);
    huge.extra.clear();
    let mut bytes = huge.write();
    patch_dimension(&mut bytes, 256, 1 << 30);
    patch_dimension(&mut bytes, 257, 1 << 30);
    let e = decode_geotiff(&bytes, &l).unwrap_err();
    assert!(matches!(e, MapIoError::TooLarge { .. }), "{e}");
    let raised = ReadLimits {
        max_side: u32::MAX,
        ..ReadLimits::default()
    };
    let e = decode_geotiff(&bytes, &raised).unwrap_err();
    assert!(
        matches!(
            e,
            MapIoError::OutOfMemory { .. } | MapIoError::Corrupt { .. }
        ),
        "{e}"
    );
    // A tag claiming more values than a DEM needs, or values past the end of the file.
    let many = TiffSpec {
        extra: vec![(
            65000,
            tiff_writer::LONG,
            MAX_DIRECTORY_VALUES + 1,
            vec![0; 8],
        )],
        ..TiffSpec::new(2, 2, Sample::U8, vec![1.0; 4])
    };
    let e = decode_geotiff(&many.write(), &l).unwrap_err();
    assert!(e.to_string().contains("65000"), "{e}");
    let past = TiffSpec {
        extra: vec![(65001, tiff_writer::DOUBLE, 1000, vec![0; 8])],
        ..TiffSpec::new(2, 2, Sample::U8, vec![1.0; 4])
    };
    let e = decode_geotiff(&past.write(), &l).unwrap_err();
    assert!(
        matches!(e, MapIoError::Truncated { .. }) && e.to_string().contains("65001"),
        "{e}"
    );
}

/// Sets the inline LONG value of tag `tag` in a little-endian classic TIFF.
fn patch_dimension(bytes: &mut [u8], tag: u16, value: u32) {
    let ifd = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]) as usize;
    let n = usize::from(u16::from_le_bytes([bytes[ifd], bytes[ifd + 1]]));
    for i in 0..n {
        let e = ifd + 2 + 12 * i;
        if u16::from_le_bytes([bytes[e], bytes[e + 1]]) == tag {
            bytes[e + 8..e + 12].copy_from_slice(&value.to_le_bytes());
            return;
        }
    }
    panic!("tag {tag} not found");
}

#[test]
fn a_truncated_geotiff_file_is_sized_but_not_read() {
    let dir = Scratch::new("truncated");
    let bytes = TiffSpec::new(30, 30, Sample::F32, hill(30, 30, 0.0, 9.0)).write();
    // The directory is at the end, so cut the image data out of the middle instead: the
    // strips then point past the end of a shorter file.
    let ifd = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]) as usize;
    let cut = 8 + 1000;
    let mut short = bytes[..cut].to_vec();
    short.extend(&bytes[ifd..]);
    let new_ifd = (cut as u32).to_le_bytes();
    short[4..8].copy_from_slice(&new_ifd);
    // The directory's external values moved with it: point them at their new place.
    fix_external_offsets(&mut short, cut, ifd - cut);
    let p = dir.file("cut.tif", &short);
    assert_eq!(
        dem_size(&p, &opts()).unwrap(),
        (DemFormat::GeoTiff, UVec2::new(30, 30))
    );
    let e = read_dem(&p, &opts()).unwrap_err();
    assert!(
        matches!(e, MapIoError::Truncated { .. } | MapIoError::Corrupt { .. }),
        "{e}"
    );
}

/// After moving a classic little-endian directory down by `by` bytes to `at`, moves the
/// offsets of its out-of-line values down by the same amount (those past the directory).
fn fix_external_offsets(bytes: &mut [u8], at: usize, by: usize) {
    let n = usize::from(u16::from_le_bytes([bytes[at], bytes[at + 1]]));
    for i in 0..n {
        let e = at + 2 + 12 * i;
        let ty = u16::from_le_bytes([bytes[e + 2], bytes[e + 3]]);
        let count = u32::from_le_bytes([bytes[e + 4], bytes[e + 5], bytes[e + 6], bytes[e + 7]]);
        let size = match ty {
            3 => 2,
            4 => 4,
            12 => 8,
            _ => 1,
        };
        if count * size > 4 {
            let off =
                u32::from_le_bytes([bytes[e + 8], bytes[e + 9], bytes[e + 10], bytes[e + 11]]);
            if off as usize > at + by {
                bytes[e + 8..e + 12].copy_from_slice(&(off - by as u32).to_le_bytes());
            }
        }
    }
}

#[test]
fn special_files_are_refused_by_every_format() {
    let dir = Scratch::new("special");
    let sized = raw_opts(UVec2::new(4, 4), ByteOrder::Little);
    for (path, kind) in [
        (dir.0.as_path(), "directory"),
        (Path::new("/dev/null"), "device"),
    ] {
        for o in [opts(), sized] {
            let e = read_dem(path, &o).unwrap_err();
            assert!(
                matches!(e, MapIoError::NotRegularFile { .. }) && e.to_string().contains(kind),
                "{path:?}: {e}"
            );
            assert!(matches!(
                dem_size(path, &o),
                Err(MapIoError::NotRegularFile { .. })
            ));
        }
    }
    let e = read_geotiff(dir.0.join("missing.tif"), &ReadLimits::default()).unwrap_err();
    assert!(e.to_string().contains("missing.tif"), "{e}");
}

// --- DemFile: measured and read through one handle ---

fn file_grid(w: u32, h: u32, base: u16) -> Grid<u16> {
    Grid::from_fn(w, h, |x, y| base + (x * 7 + y * 3) as u16).unwrap()
}

fn file_heights(g: &Grid<u16>) -> Vec<f32> {
    g.as_slice().iter().map(|&v| f32::from(v)).collect()
}

#[test]
fn a_png_replaced_after_open_is_read_as_opened() {
    let s = Scratch::new("png");
    let first = file_grid(5, 3, 100);
    let path = s.file("dem.png", &encode_png16(&first).unwrap());
    let dem = DemFile::open(&path, &DemOptions::default()).unwrap();
    assert_eq!(
        (dem.format(), dem.size()),
        (DemFormat::Png, UVec2::new(5, 3))
    );
    // Another valid DEM, of another size, renamed over the path.
    let other = s.file("other.png", &encode_png16(&file_grid(9, 4, 5000)).unwrap());
    std::fs::rename(&other, &path).unwrap();
    assert_eq!(
        terrain_core::dem::dem_size(&path, &DemOptions::default()).unwrap(),
        (DemFormat::Png, UVec2::new(9, 4))
    );
    let read = dem.read().unwrap();
    assert_eq!(read.size(), UVec2::new(5, 3));
    assert_eq!(read.heights.as_slice(), file_heights(&first));
}

#[test]
fn a_raw16_replaced_after_open_is_read_as_opened() {
    let s = Scratch::new("raw");
    let first = file_grid(4, 4, 7);
    let path = s.file("dem.r16", &encode_raw16(&first));
    let options = DemOptions {
        raw_size: Some(UVec2::new(4, 4)),
        byte_order: ByteOrder::Little,
        ..DemOptions::default()
    };
    let dem = DemFile::open(&path, &options).unwrap();
    assert_eq!(
        (dem.format(), dem.size()),
        (DemFormat::Raw16, UVec2::new(4, 4))
    );
    let other = s.file("other.r16", &encode_raw16(&file_grid(8, 2, 900)));
    std::fs::rename(&other, &path).unwrap();
    let read = dem.read().unwrap();
    assert_eq!(read.heights.as_slice(), file_heights(&first));
}

#[test]
fn a_format_sniffed_from_the_first_bytes_still_reads_from_the_start() {
    let s = Scratch::new("sniff");
    let first = file_grid(3, 2, 40);
    // No extension: the format comes from the signature, read through the same handle.
    let path = s.file("dem", &encode_png16(&first).unwrap());
    let dem = DemFile::open(&path, &DemOptions::default()).unwrap();
    assert_eq!(dem.format(), DemFormat::Png);
    assert_eq!(dem.read().unwrap().heights.as_slice(), file_heights(&first));
}
