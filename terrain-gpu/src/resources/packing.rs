//! Packed texels: the layout of every per-texel height buffer of the crate (and the derivative
//! map's codes), mirrored by `packed.wgsl`.
//!
//! A texel of `bits` bits (8, 16 or 32) takes a lane of a u32 word, `32 / bits` lanes per
//! word: texel x of a row is in word `x / lanes` at bit `(x % lanes) * bits`, and each row
//! starts on a whole word. So a 16-bit coarse-map takes 2 bytes per texel and an 8-bit detail
//! tile 1 (Flower 2010, sec. 2.3.1: 16-bit coarse-map, 8-bit detail-maps), where one u32 per
//! texel took 4. Why rows of whole words: a word never holds texels of two rows, so a writer
//! owns a word by owning a run of columns of one row (no atomics, no races), and a region's
//! rows copy as word ranges.

/// Bits per texel of a sample of `size` bytes (u8, u16 or u32).
pub(crate) const fn bits_of(bytes: usize) -> u32 {
    match bytes {
        1 => 8,
        2 => 16,
        _ => 32,
    }
}

/// Texels per u32 word at `bits` bits per texel.
pub(crate) const fn lanes(bits: u32) -> u32 {
    32 / bits
}

/// Words per row of `width` texels.
pub(crate) const fn pitch(width: u32, bits: u32) -> u32 {
    width.div_ceil(lanes(bits))
}

/// Words of a map of `width` x `height` texels.
pub(crate) fn words(width: u32, height: u32, bits: u32) -> u64 {
    u64::from(pitch(width, bits)) * u64::from(height)
}

/// Packs row-major texel values (each below `2^bits`) of a map `width` texels wide.
pub(crate) fn pack(values: impl IntoIterator<Item = u32>, width: u32, bits: u32) -> Vec<u32> {
    let lanes = lanes(bits) as usize;
    let width = width as usize;
    let mut out = Vec::new();
    let mut word = 0u32;
    for (i, v) in values.into_iter().enumerate() {
        let x = i % width;
        let lane = x % lanes;
        word |= v << (lane as u32 * bits);
        if lane + 1 == lanes || x + 1 == width {
            out.push(word);
            word = 0;
        }
    }
    out
}

/// [`pack`] of whole rows of `width` texels from a slice, into `out` (cleared, its capacity
/// kept): the uploads' path, a word at a time instead of a texel (a 256^2 atlas tile or a
/// 1024^2 detail tile is packed per upload, on the frame thread).
pub(crate) fn pack_into<T: Copy + Into<u32>>(
    values: &[T],
    width: u32,
    bits: u32,
    out: &mut Vec<u32>,
) {
    out.clear();
    let lanes = lanes(bits) as usize;
    let width = width as usize;
    if width == 0 {
        return;
    }
    out.reserve(values.len().div_ceil(width) * width.div_ceil(lanes));
    let word = |texels: &[T]| {
        texels
            .iter()
            .enumerate()
            .fold(0u32, |w, (lane, &v)| w | (v.into() << (lane as u32 * bits)))
    };
    for row in values.chunks(width) {
        let words = row.chunks_exact(lanes);
        let rest = words.remainder();
        out.extend(words.map(word));
        if !rest.is_empty() {
            out.push(word(rest));
        }
    }
}

/// The texel values of `words`, rows of `width` texels (the inverse of [`pack`]).
pub(crate) fn unpack(words: &[u32], width: u32, bits: u32) -> Vec<u32> {
    let pitch = pitch(width, bits) as usize;
    if pitch == 0 {
        return Vec::new();
    }
    let mask = u32::MAX >> (32 - bits);
    words
        .chunks_exact(pitch)
        .flat_map(|row| (0..width).map(move |x| get(row, x, bits, mask)))
        .collect()
}

/// Texel x of a packed row.
fn get(row: &[u32], x: u32, bits: u32, mask: u32) -> u32 {
    let lanes = lanes(bits);
    (row[(x / lanes) as usize] >> ((x % lanes) * bits)) & mask
}

/// How many words the run of `count` columns from `start` touches, in coordinates made
/// non-negative by a multiple of `width` (column c is map column `c % width`), split at word
/// edges and at the map's wrap: the invocations a writer over the run dispatches, one per word
/// (`packed_group` in WGSL maps invocation i to its word). 0 for an empty run.
pub(crate) fn word_groups(start: u32, count: u32, width: u32, bits: u32) -> u32 {
    if count == 0 || width == 0 {
        return 0;
    }
    let lanes = lanes(bits);
    let pitch = u64::from(pitch(width, bits));
    let group = |c: u64| (c / u64::from(width)) * pitch + (c % u64::from(width)) / u64::from(lanes);
    let first = group(u64::from(start));
    let last = group(u64::from(start) + u64::from(count) - 1);
    // A run is at most one period of the map, so this is at most pitch + 1.
    (last - first + 1) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_and_unpack_are_inverse_for_every_width_and_depth() {
        for bits in [8, 16, 32] {
            for width in 1..=9u32 {
                let height = 3;
                let max = u32::MAX >> (32 - bits);
                let values: Vec<u32> = (0..width * height)
                    .map(|i| max - i.wrapping_mul(2_654_435_761) % max.max(1))
                    .collect();
                let words = pack(values.iter().copied(), width, bits);
                assert_eq!(words.len() as u64, super::words(width, height, bits));
                assert_eq!(
                    unpack(&words, width, bits),
                    values,
                    "bits {bits} width {width}"
                );
            }
        }
    }

    #[test]
    fn pack_into_packs_as_pack_does_and_keeps_its_buffer() {
        let mut out = vec![7u32; 3];
        for width in 1..=9u32 {
            let values: Vec<u8> = (0..width * 3).map(|i| (i * 37 + 5) as u8).collect();
            pack_into(&values, width, 8, &mut out);
            let wide = values.iter().map(|&v| u32::from(v));
            assert_eq!(out, pack(wide, width, 8), "8 bits, width {width}");
            let values: Vec<u16> = (0..width * 3).map(|i| (i * 40_503 + 11) as u16).collect();
            pack_into(&values, width, 16, &mut out);
            let wide = values.iter().map(|&v| u32::from(v));
            assert_eq!(out, pack(wide, width, 16), "16 bits, width {width}");
            let values: Vec<u32> = (0..width * 3)
                .map(|i| i.wrapping_mul(2_654_435_761))
                .collect();
            pack_into(&values, width, 32, &mut out);
            assert_eq!(out, pack(values.iter().copied(), width, 32), "32 bits");
        }
        pack_into::<u16>(&[], 4, 16, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn word_groups_split_at_word_edges_and_the_wrap() {
        // 16 bits, width 5: words [0 1] [2 3] [4] per row period.
        assert_eq!(word_groups(0, 5, 5, 16), 3);
        assert_eq!(word_groups(1, 2, 5, 16), 2);
        // Columns 4, 5 (= map 4, 0): two words across the wrap.
        assert_eq!(word_groups(4, 2, 5, 16), 2);
        // A whole period from an odd column: 4 | 0 1 | 2 3 (map columns 4, 0..3).
        assert_eq!(word_groups(9, 5, 5, 16), 3);
        assert_eq!(word_groups(0, 0, 5, 16), 0);
        assert_eq!(word_groups(7, 3, 8, 32), 3);
        assert_eq!(word_groups(2, 8, 8, 8), 3);
    }
}
