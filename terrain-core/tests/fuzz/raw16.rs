//! Classes of the `raw16` target: round trips, size limits and the file reader. Random bytes at
//! any size, byte count and limit are the decoder target `raw16` of
//! `terrain_test_support::decoders` (coverage-guided under libFuzzer, briefly under `cargo
//! test`), whose check this file shares: it replaced the `random_bytes` and `length_mismatch`
//! classes that were here.

use crate::png_mutations::{limits_for, side};
use crate::{Ctx, class};
use glam::UVec2;
use terrain_core::Grid;
use terrain_core::io::{
    DEFAULT_MAX_SIDE, MapIoError, ReadLimits, decode_raw16, encode_raw16, read_raw16,
};
use terrain_test_support::decoders::check_raw;
use terrain_test_support::fuzz::{Case, Class, Rng};

/// Checks a RAW16 decode of `bytes` at `size` (little-endian samples) against the contract.
fn check_raw16(
    bytes: &[u8],
    size: UVec2,
    limits: &ReadLimits,
    got: Result<Grid<u16>, MapIoError>,
) -> Result<(), String> {
    check_raw(bytes, size, limits, &got, u16::to_le_bytes)
}

/// Round trips through `encode_raw16`.
fn raw16_roundtrip(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let (w, h) = (side(rng), side(rng));
    let samples = (0..w * h).map(|_| rng.next_u32() as u16).collect();
    let g = Grid::from_vec(w, h, samples).unwrap();
    let bytes = encode_raw16(&g);
    match decode_raw16(&bytes, g.size(), &ReadLimits::default()) {
        Ok(d) if d == g => Ok(()),
        other => Err(format!("{w}x{h}: round trip gave {other:?}")),
    }
}

/// Sizes at and past the limits: zero sides, `max_side` and its neighbours, sizes whose byte
/// count overflows, limits raised to `u32::MAX`.
fn raw16_size_limits(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let max_side = match rng.below(3) {
        0 => rng.range_u32(1, 64),
        1 => DEFAULT_MAX_SIDE,
        _ => u32::MAX,
    };
    let limits = ReadLimits {
        max_side,
        ..ReadLimits::default()
    };
    let pick_side = |rng: &mut Rng| match rng.below(4) {
        0 => rng.u32_edge(),
        1 => max_side
            .saturating_add(rng.range_u32(0, 2))
            .saturating_sub(1),
        2 => 0,
        _ => rng.range_u32(1, 40),
    };
    let size = UVec2::new(pick_side(rng), pick_side(rng));
    // Only the right byte count for sizes small enough to hold; otherwise a few bytes.
    let need = u128::from(size.x) * u128::from(size.y) * 2;
    let len = if need <= 8192 && rng.chance(1, 2) {
        need as usize
    } else {
        rng.index(64)
    };
    let bytes = rng.bytes(len);
    check_raw16(&bytes, size, &limits, decode_raw16(&bytes, size, &limits))
}

/// `read_raw16` (length checked from the file's metadata) against `decode_raw16`; a missing
/// file is an I/O error.
fn raw16_file_reader(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let size = UVec2::new(rng.range_u32(0, 40), rng.range_u32(0, 40));
    let right = (size.x * size.y * 2) as usize;
    let len = if rng.chance(1, 2) {
        right
    } else {
        rng.index(right + 8)
    };
    let bytes = rng.bytes(len);
    let limits = limits_for(rng);
    let path = ctx.dir.join(format!("{:016x}.r16", rng.next_u64()));
    if rng.chance(1, 10) {
        return match read_raw16(&path, size, &limits) {
            Err(MapIoError::Io { .. }) | Err(MapIoError::ZeroSize { .. }) => Ok(()),
            Err(MapIoError::TooLarge { .. }) => Ok(()),
            other => Err(format!("a missing file gave {:?}", other.map(|g| g.size()))),
        };
    }
    std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
    let got = read_raw16(&path, size, &limits);
    let _ = std::fs::remove_file(&path);
    check_raw16(&bytes, size, &limits, got)
}

/// The target's classes, in the order they run.
pub(crate) fn classes() -> Vec<Class<Ctx>> {
    vec![
        class("roundtrip", raw16_roundtrip),
        class("size_limits", raw16_size_limits),
        class("file_reader", raw16_file_reader),
    ]
}
