//! Classes of the `geotiff` target, seeded by the tests' own TIFF writer (`terrain_test_support::tiff`:
//! every sample type, strips and tiles, both byte orders, classic and BigTIFF, with GeoTIFF
//! tags): valid files, truncated, bit-flipped, directory fields set to edge values, random
//! bytes and the file reader.

use crate::png_mutations::{limits_for, side};
use crate::{Ctx, class};
use terrain_core::geotiff::{decode_geotiff, read_geotiff};
use terrain_core::io::ReadLimits;
use terrain_test_support::fuzz::{Case, Class, Rng};
use terrain_test_support::tiff as tiff_writer;

/// A valid GeoTIFF from the tests' writer, and the heights it must decode to.
fn geotiff_seed(rng: &mut Rng) -> (Vec<u8>, Vec<f32>) {
    use tiff_writer::{Layout, Sample, TiffSpec};
    let sample = rng.pick(&Sample::ALL);
    let (w, h) = (side(rng), side(rng));
    let values: Vec<f64> = (0..w * h)
        .map(|_| match sample {
            Sample::U8 => f64::from(rng.below(256) as u8),
            Sample::I8 => f64::from(rng.below(256) as u8 as i8),
            Sample::U16 => f64::from(rng.next_u32() as u16),
            Sample::I16 => f64::from(rng.next_u32() as u16 as i16),
            Sample::U32 => f64::from(rng.next_u32() >> 8),
            Sample::I32 => f64::from((rng.next_u32() >> 8) as i32 - (1 << 23)),
            Sample::F32 | Sample::F64 => f64::from(rng.uniform(-500.0, 9000.0) as f32),
        })
        .collect();
    let want = values.iter().map(|&v| v as f32).collect();
    let layout = if rng.chance(1, 3) {
        Layout::Tiles(16 * rng.range_u32(1, 2), 16 * rng.range_u32(1, 2))
    } else {
        Layout::Strips(rng.range_u32(1, h + 1))
    };
    let spec = TiffSpec {
        big_endian: rng.chance(1, 2),
        bigtiff: rng.chance(1, 4),
        layout,
        pixel_scale: rng
            .chance(1, 2)
            .then(|| [rng.uniform(0.0001, 50.0), 5.0, 0.0]),
        tiepoint: rng
            .chance(1, 3)
            .then(|| [0.0, 0.0, 0.0, 7.0, rng.uniform(-80.0, 80.0), 0.0]),
        geokeys: if rng.chance(1, 2) {
            vec![(1024, rng.range_u32(1, 3) as u16), (3076, 9001)]
        } else {
            Vec::new()
        },
        ..TiffSpec::new(w, h, sample, values)
    };
    (spec.write(), want)
}

/// Any input: `Ok` within the limits (with a texel size, when any, that is finite), or `Err`.
fn geotiff_any(bytes: &[u8], limits: &ReadLimits) -> Result<(), String> {
    match decode_geotiff(bytes, limits) {
        Ok(t) => {
            let s = t.heights.size();
            if s.x == 0 || s.y == 0 || s.x > limits.max_side || s.y > limits.max_side {
                return Err(format!("decoded {s} under {limits:?}"));
            }
            Ok(())
        }
        Err(_) => Ok(()),
    }
}

/// Valid files decode to exactly the heights written.
fn geotiff_valid(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (bytes, want) = geotiff_seed(&mut case.rng);
    match decode_geotiff(&bytes, &ReadLimits::default()) {
        Ok(t) if t.heights.as_slice() == want => Ok(()),
        Ok(_) => Err("wrong heights".into()),
        Err(e) => Err(format!("a valid file was refused: {e}")),
    }
}

/// Valid files cut anywhere.
fn geotiff_truncated(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (bytes, _) = geotiff_seed(&mut case.rng);
    let n = case.rng.index(bytes.len());
    match decode_geotiff(&bytes[..n], &ReadLimits::default()) {
        Err(_) => Ok(()),
        // The directory is written last: a cut file has lost part of it.
        Ok(_) => Err(format!("{n} of {} bytes decoded", bytes.len())),
    }
}

/// Valid files with bits flipped.
fn geotiff_bit_flips(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (mut bytes, _) = geotiff_seed(&mut case.rng);
    case.rng.flip_bits(&mut bytes);
    let limits = limits_for(&mut case.rng);
    geotiff_any(&bytes, &limits)
}

/// Valid files with directory entries' types, counts and offsets overwritten (sizes, strip
/// offsets and counts, tag value counts: where a decoder trusts the file most).
fn geotiff_directory_fields(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let (mut bytes, _) = geotiff_seed(&mut case.rng);
    let rng = &mut case.rng;
    let big = bytes[0] == b'M';
    let bigtiff = bytes[2..4] == [0, 43] || bytes[2..4] == [43, 0];
    let rd = |b: &[u8]| -> u64 {
        let mut v = 0u64;
        if big {
            for &x in b {
                v = v << 8 | u64::from(x);
            }
        } else {
            for &x in b.iter().rev() {
                v = v << 8 | u64::from(x);
            }
        }
        v
    };
    let (ifd, count_len, entry_len) = if bigtiff {
        (rd(&bytes[8..16]) as usize, 8, 20)
    } else {
        (rd(&bytes[4..8]) as usize, 2, 12)
    };
    let n = rd(&bytes[ifd..ifd + count_len]) as usize;
    for _ in 0..rng.range_u32(1, 4) {
        let e = ifd + count_len + entry_len * rng.index(n);
        // A field of the entry (type, count or value) gets an edge value.
        let (at, len) = match rng.below(3) {
            0 => (e + 2, 2),
            1 => (e + 4, if bigtiff { 8 } else { 4 }),
            _ => (
                e + if bigtiff { 12 } else { 8 },
                if bigtiff { 8 } else { 4 },
            ),
        };
        let v = match rng.below(4) {
            0 => u64::from(rng.u32_edge()),
            1 => rng.below(20),
            2 => rng.next_u64(),
            _ => bytes.len() as u64 + rng.below(16),
        };
        for i in 0..len {
            let shift = if big { 8 * (len - 1 - i) } else { 8 * i };
            bytes[at + i] = (v >> shift) as u8;
        }
    }
    let limits = limits_for(rng);
    geotiff_any(&bytes, &limits)
}

/// Random bytes, half of them behind a TIFF header.
fn geotiff_random(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let n = rng.range_usize(0, 600);
    let mut bytes = rng.bytes(n);
    if rng.chance(1, 2) && bytes.len() >= 8 {
        bytes[..4].copy_from_slice(if rng.chance(1, 2) { b"II*\0" } else { b"MM\0*" });
        bytes[4..8].copy_from_slice(&[8, 0, 0, 0]);
    }
    let limits = limits_for(rng);
    geotiff_any(&bytes, &limits)
}

/// `read_geotiff` on a file equals `decode_geotiff` on its bytes.
fn geotiff_file_reader(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let (mut bytes, _) = geotiff_seed(&mut case.rng);
    if case.rng.chance(1, 2) {
        case.rng.flip_bits(&mut bytes);
    }
    let limits = ReadLimits::default();
    let path = ctx.dir.join(format!("{:016x}.tif", case.rng.next_u64()));
    std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
    let from_file = read_geotiff(&path, &limits);
    let _ = std::fs::remove_file(&path);
    match (from_file, decode_geotiff(&bytes, &limits)) {
        (Ok(a), Ok(b))
            if a.heights.as_slice().iter().map(|v| v.to_bits()).eq(b
                .heights
                .as_slice()
                .iter()
                .map(|v| v.to_bits())) =>
        {
            Ok(())
        }
        (Err(_), Err(_)) => Ok(()),
        (a, b) => Err(format!(
            "file and memory disagree: {:?} / {:?}",
            a.map(|t| t.heights.size()),
            b.map(|t| t.heights.size())
        )),
    }
}

/// The target's classes, in the order they run.
pub(crate) fn classes() -> Vec<Class<Ctx>> {
    vec![
        class("valid", geotiff_valid),
        class("truncated", geotiff_truncated),
        class("bit_flips", geotiff_bit_flips),
        class("directory_fields", geotiff_directory_fields),
        class("random_bytes", geotiff_random),
        class("file_reader", geotiff_file_reader),
    ]
}
