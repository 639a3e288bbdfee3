//! A byte-level mutator in the manner of libFuzzer's, for the harness's short runs of the
//! decoder targets under `cargo test`: it knows no format (no checksum is fixed, no stream
//! recompressed), which is what the coverage-guided engine does too, without its coverage
//! feedback. The structure-aware classes of terrain-core's and terrain-cache's fuzz targets do
//! the format-aware damage.

use crate::fuzz::Rng;

/// Values that code reading sizes, counts and offsets tends to get wrong, as bytes.
const EDGE_BYTES: [u8; 9] = [0, 1, 2, 0x7F, 0x80, 0xFE, 0xFF, 16, 64];

/// Applies 1 to 4 mutations to `input`: bit flips, an edge value written over a byte or a
/// 16-, 32- or 64-bit field (either byte order), bytes inserted, erased, copied from elsewhere
/// in the input or spliced in from `others` (the other seeds), or a cut.
pub fn mutate(input: &mut Vec<u8>, others: &[Vec<u8>], rng: &mut Rng) {
    for _ in 0..rng.range_u32(1, 4) {
        mutate_once(input, others, rng);
    }
}

fn mutate_once(b: &mut Vec<u8>, others: &[Vec<u8>], rng: &mut Rng) {
    let len = b.len();
    match rng.below(9) {
        0 => rng.flip_bits(b),
        1 if len > 0 => {
            let at = rng.index(len);
            b[at] = rng.pick(&EDGE_BYTES);
        }
        2 if len > 0 => {
            let width = rng.pick(&[2usize, 4, 8]).min(len);
            let at = rng.index(len - width + 1);
            // A u32 edge value, sign-extended a quarter of the time (-1, -2, ...).
            let high = if rng.chance(1, 4) { u64::MAX << 32 } else { 0 };
            let v = u64::from(rng.u32_edge()) | high;
            let (le, be) = (v.to_le_bytes(), v.to_be_bytes());
            let field = if rng.chance(1, 2) {
                &le[..width]
            } else {
                &be[8 - width..]
            };
            b[at..at + width].copy_from_slice(field);
        }
        3 => {
            let at = rng.index(len + 1);
            let n = rng.range_usize(1, 16);
            let fill = rng.bytes(n);
            b.splice(at..at, fill);
        }
        4 if len > 0 => {
            let at = rng.index(len);
            let n = rng.range_usize(1, (len - at).min(64));
            b.drain(at..at + n);
        }
        5 if len > 0 => {
            // A run of the input copied over another place in it.
            let from = rng.index(len);
            let n = rng.range_usize(1, (len - from).min(64));
            let run = b[from..from + n].to_vec();
            let to = rng.index(len);
            let end = (to + n).min(len);
            b.splice(to..end, run);
        }
        6 if !others.is_empty() => {
            // Crossover: the head of this input, the tail of another.
            let other = &others[rng.index(others.len())];
            let cut = rng.index(len + 1);
            let from = rng.index(other.len() + 1);
            b.truncate(cut);
            b.extend_from_slice(&other[from..]);
        }
        7 => {
            let keep = rng.index(len + 1);
            b.truncate(keep);
        }
        _ => {
            let n = rng.range_usize(1, 8);
            let tail = rng.bytes(n);
            b.extend(tail);
        }
    }
}
