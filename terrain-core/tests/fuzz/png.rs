//! Classes of the PNG targets `png16` and `png8` (with the RGBA8 capture decoder's own classes),
//! shared by the decoders through the const parameter `K` (GRAY8, GRAY16 or RGBA8).

use crate::png_expect::{
    Kind, Pixels, RGBA8, check_any, check_valid, decode, expected_pixels, kind, read_file,
};
use crate::png_mutations::{
    CHUNK_TYPES, chunk_data, chunk_surgery, damage_zlib, limits_for, overwrite_header, seed_file,
    seed_image, side,
};
use crate::{Ctx, class};
use terrain_core::io::{
    DEFAULT_MAX_SIDE, ReadLimits, decode_png, encode_png_rgba8, encode_png8, encode_png16, read_png,
};
use terrain_test_support::fuzz::{Case, Class, Rng};
use terrain_test_support::png::{SIGNATURE, chunk, chunks_of, fix_crcs};
use terrain_test_support::png_encoder::Image;

/// Valid files of every format from the independent encoder: exact pixels or the right error.
fn png_valid<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let img = seed_image(k, rng);
    let bytes = img.encode(rng);
    let limits = limits_for(rng);
    check_valid(k, &img, &limits, decode(k, &bytes, &limits))?;
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Round trips through terrain-core's own encoder (compressed deflate).
fn png_roundtrip<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let (w, h) = (side(rng), side(rng));
    let (ct, bits) = k.format();
    let img = Image::random(rng, w, h, ct, bits);
    let bytes = match expected_pixels(k, &img) {
        Pixels::Gray8(g) => encode_png8(&g),
        Pixels::Gray16(g) => encode_png16(&g),
        Pixels::Rgba8(g) => encode_png_rgba8(&g),
    }
    .map_err(|e| format!("encoding {w}x{h} failed: {e}"))?;
    check_valid(
        k,
        &img,
        &ReadLimits::default(),
        decode(k, &bytes, &ReadLimits::default()),
    )
}

/// A valid file cut anywhere before its end must be an error.
fn png_truncated<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let full = seed_file(k, rng);
    let cut = if rng.chance(1, 4) {
        full.len() - rng.range_usize(1, 12.min(full.len()))
    } else {
        rng.index(full.len())
    };
    let limits = limits_for(rng);
    match check_any(k, &full[..cut], &limits)? {
        None => Ok(()),
        Some(p) => Err(format!(
            "a file cut to {cut} of {} bytes decoded as a {} image",
            full.len(),
            p.size()
        )),
    }
}

/// Random bit flips, CRCs left as they are (most stop at the CRC check).
fn png_bit_flips<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    rng.flip_bits(&mut bytes);
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Random bit flips with every chunk CRC fixed, so they reach the parsers.
fn png_bit_flips_crc_fixed<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    rng.flip_bits(&mut bytes);
    fix_crcs(&mut bytes);
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// IHDR fields overwritten with edge values (sizes near the limits, bad depths and types).
fn png_header_fields<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    for _ in 0..rng.range_u32(1, 3) {
        overwrite_header(&mut bytes, rng);
    }
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Chunks removed, duplicated, moved, inserted, split, grown; trailing bytes; no IEND.
fn png_chunk_surgery<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    for _ in 0..rng.range_u32(1, 4) {
        chunk_surgery(&mut bytes, rng);
    }
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// The zlib stream damaged (header, block lengths, block type, data, checksum, length), the
/// IDAT chunks rewritten with valid CRCs.
fn png_zlib_damage<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    damage_zlib(&mut bytes, rng);
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// Sizes at the limits: sides of `max_side - 1`, `max_side`, `max_side + 1` for a small
/// `max_side` (valid files: decoded exactly or TooLarge), and headers announcing sides around
/// the default limit (16384) or far beyond it over a few bytes of data (an error, quickly).
fn png_size_limits<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    if rng.chance(1, 2) {
        let max_side = rng.range_u32(1, 48);
        let near = |rng: &mut Rng| (max_side + rng.range_u32(0, 2)).saturating_sub(1).max(1);
        let (w, h) = (near(rng), near(rng));
        let (ct, bits) = k.format();
        let img = Image::random(rng, w, h, ct, bits);
        let bytes = img.encode(rng);
        let limits = ReadLimits {
            max_side,
            ..ReadLimits::default()
        };
        return check_valid(k, &img, &limits, decode(k, &bytes, &limits));
    }
    let mut bytes = seed_file(k, rng);
    let big = [
        DEFAULT_MAX_SIDE - 1,
        DEFAULT_MAX_SIDE,
        DEFAULT_MAX_SIDE + 1,
        u32::MAX,
        1 << 31,
        (1 << 31) - 1,
    ];
    let (w, h) = (rng.pick(&big), rng.pick(&big));
    if let Some((at, len)) = chunks_of(&bytes).first().copied()
        && len >= 13
    {
        bytes[at + 8..at + 12].copy_from_slice(&w.to_be_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&h.to_be_bytes());
        fix_crcs(&mut bytes);
    }
    match check_any(k, &bytes, &ReadLimits::default())? {
        None => Ok(()),
        Some(p) => Err(format!(
            "a small file announcing {w}x{h} decoded as a {} image",
            p.size()
        )),
    }
}

/// Random bytes: bare, after the PNG signature, as random chunks with valid CRCs, or as a
/// valid IHDR of random fields followed by random chunks.
fn png_random_bytes<const K: u8>(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let n = rng.range_usize(0, 2048);
    let bytes = match rng.below(4) {
        0 => rng.bytes(n),
        1 => {
            let mut b = SIGNATURE.to_vec();
            b.extend(rng.bytes(n));
            b
        }
        mode => {
            let mut b = SIGNATURE.to_vec();
            if mode == 3 {
                let mut ihdr = Vec::new();
                ihdr.extend_from_slice(&rng.range_u32(0, 70).to_be_bytes());
                ihdr.extend_from_slice(&rng.range_u32(0, 70).to_be_bytes());
                ihdr.push(rng.pick(&[1, 2, 4, 8, 16, 3]));
                ihdr.push(rng.pick(&[0, 2, 3, 4, 6, 1]));
                ihdr.extend_from_slice(&[0, 0, rng.range_u32(0, 1) as u8]);
                b.extend(chunk(b"IHDR", &ihdr));
            }
            for _ in 0..rng.range_u32(0, 6) {
                let ty = rng.pick(&CHUNK_TYPES);
                b.extend(chunk(ty, &chunk_data(rng)));
            }
            b
        }
    };
    let limits = limits_for(rng);
    check_any(k, &bytes, &limits).map(|_| ())
}

/// The file readers (buffered, with their own truncation report) against the in-memory
/// decoders on the same mutated bytes: the same pixels, or both an error.
fn png_file_reader<const K: u8>(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let k = kind(K);
    let rng = &mut case.rng;
    let mut bytes = seed_file(k, rng);
    match rng.below(5) {
        0 => {}
        1 => {
            let n = bytes.len();
            bytes.truncate(rng.index(n));
        }
        2 => {
            rng.flip_bits(&mut bytes);
            fix_crcs(&mut bytes);
        }
        3 => overwrite_header(&mut bytes, rng),
        _ => chunk_surgery(&mut bytes, rng),
    }
    let limits = limits_for(rng);
    let path = ctx.dir.join(format!("{:016x}.png", rng.next_u64()));
    std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
    let from_file = read_file(k, &path, &limits);
    let _ = std::fs::remove_file(&path);
    let in_memory = decode(k, &bytes, &limits);
    if k != Kind::Rgba8 {
        // The generic file reader must agree with the generic in-memory decoder.
        let path = ctx.dir.join(format!("{:016x}.png", rng.next_u64()));
        std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
        let a = read_png(&path, &limits).ok();
        let _ = std::fs::remove_file(&path);
        if a != decode_png(&bytes, &limits).ok() {
            return Err("read_png and decode_png disagree".into());
        }
    }
    match (from_file, in_memory) {
        (Ok(a), Ok(b)) if a == b => Ok(()),
        (Err(_), Err(_)) => Ok(()),
        (a, b) => Err(format!(
            "file reader and in-memory decoder disagree: {:?} vs {:?}",
            a.map(|p| p.size()),
            b.map(|p| p.size())
        )),
    }
}

/// The classes of the target of decoder `K`, in the order they run; `rgba_too` adds the RGBA8
/// capture decoder's own.
pub(crate) fn classes<const K: u8>(rgba_too: bool) -> Vec<Class<Ctx>> {
    let mut classes = vec![
        class("valid_any_format", png_valid::<K>),
        class("roundtrip_own_encoder", png_roundtrip::<K>),
        class("truncated", png_truncated::<K>),
        class("bit_flips", png_bit_flips::<K>),
        class("bit_flips_crc_fixed", png_bit_flips_crc_fixed::<K>),
        class("header_fields", png_header_fields::<K>),
        class("chunk_surgery", png_chunk_surgery::<K>),
        class("zlib_damage", png_zlib_damage::<K>),
        class("size_limits", png_size_limits::<K>),
        class("random_bytes", png_random_bytes::<K>),
        class("file_reader", png_file_reader::<K>),
    ];
    if rgba_too {
        // The RGBA8 capture decoder shares the PNG path; a few classes of its own.
        classes.extend([
            class("rgba8_valid_any_format", png_valid::<RGBA8>),
            class("rgba8_header_fields", png_header_fields::<RGBA8>),
            class("rgba8_zlib_damage", png_zlib_damage::<RGBA8>),
            class("rgba8_truncated", png_truncated::<RGBA8>),
        ]);
    }
    classes
}
