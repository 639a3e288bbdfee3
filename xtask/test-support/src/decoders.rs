//! The decoders' fuzz target bodies: one function per decoder that decodes one input and checks
//! what came back. Two engines run the same functions:
//!
//! - libFuzzer, coverage-guided: each target of the fuzz crate in `xtask/fuzz/` is one line
//!   calling one function here (`cargo xtask fuzz --engine libfuzzer --seconds N`, nightly);
//! - the time-bounded harness of [`crate::fuzz`], under `cargo test`: test-support's own
//!   `tests/fuzz.rs` target `decoders` feeds each function its seeds and byte-level mutations of
//!   them ([`mutate`]) for a share of 2 s.
//!
//! A function takes any bytes and panics only when an invariant breaks:
//!
//! - the decoder does not panic (both engines build with overflow checks);
//! - an error is clean: it and each of its sources display as a non-empty message of at most
//!   [`MAX_MESSAGE`] bytes;
//! - a decoded result is well-formed: the size the file declares, within the read limits (and
//!   refused under limits one texel tighter), the same as what the decoder's siblings make of the
//!   same bytes (the generic PNG decoder, the other bit depth), and decoded again unchanged from
//!   its own re-encoding;
//! - memory stays bounded: every side is capped by [`LIMITS`], and libFuzzer's
//!   `-malloc_limit_mb` fails any single allocation past what they allow.
//!
//! An input is the file's bytes as stored, so any real file can join a corpus, except where the
//! decoder takes more than the file: the headerless formats (their size and byte order), the
//! bounds file (the level's tile count) and the tile file (its layer and tile size) read a few
//! bytes of parameters first, as each function says. Each returns whether the input decoded, so
//! that a test can check that the seeds ([`Decoder::seeds`]) reach the decoders' success paths.

mod maps;
mod mutate;
mod seeds;
mod world;

pub use maps::{RawAnswer, check_raw, geotiff, png8, png16, r32, raw16};
pub use mutate::mutate;
pub use world::{bounds, manifest, tile};

use glam::UVec2;
use terrain_core::io::ReadLimits;

/// The read limits of the map decoders' targets: 1024 texels a side keeps the largest decoded
/// image at 4 MiB (RGBA8), so a run stays fast and an allocation far beyond it is a finding.
pub const LIMITS: ReadLimits = ReadLimits {
    max_side: 1024,
    max_samples: 1024 * 1024,
};

/// The longest error message accepted, in bytes: an error that quotes its input is not clean.
pub const MAX_MESSAGE: usize = 2048;

/// What a target made of one input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The input decoded, and the result passed every check.
    Decoded,
    /// The decoder refused the input with a clean error (or it was too short to hold the
    /// target's parameters).
    Refused,
}

/// One decoder's target: its name (the libFuzzer target's and the harness class's), its body,
/// and the valid inputs its corpus starts from.
#[derive(Debug, Clone, Copy)]
pub struct Decoder {
    /// The target's name.
    pub name: &'static str,
    /// Decodes one input and checks the result; panics when an invariant breaks.
    pub run: fn(&[u8]) -> Outcome,
    /// Small valid inputs (each decodes), made by the crates' encoders and the tests' own.
    pub seeds: fn() -> Vec<Vec<u8>>,
}

/// Every decoder target, in the order the harness runs them.
pub const DECODERS: [Decoder; 8] = [
    Decoder {
        name: "png16",
        run: png16,
        seeds: seeds::png16,
    },
    Decoder {
        name: "png8",
        run: png8,
        seeds: seeds::png8,
    },
    Decoder {
        name: "raw16",
        run: raw16,
        seeds: seeds::raw16,
    },
    Decoder {
        name: "r32",
        run: r32,
        seeds: seeds::r32,
    },
    Decoder {
        name: "geotiff",
        run: geotiff,
        seeds: seeds::geotiff,
    },
    Decoder {
        name: "manifest",
        run: manifest,
        seeds: seeds::manifest,
    },
    Decoder {
        name: "bounds",
        run: bounds,
        seeds: seeds::bounds,
    },
    Decoder {
        name: "tile",
        run: tile,
        seeds: seeds::tile,
    },
];

/// Panics unless `e` and each of its sources display as a clean message.
fn check_error(what: &str, e: &dyn std::error::Error) {
    let mut next = Some(e);
    while let Some(e) = next {
        check_message(what, &e.to_string());
        next = e.source();
    }
}

/// Panics unless `m` is a clean error message: not empty, at most [`MAX_MESSAGE`] bytes.
fn check_message(what: &str, m: &str) {
    assert!(
        !m.trim().is_empty() && m.len() <= MAX_MESSAGE,
        "{what}: an unclean error message ({} bytes): {:?}",
        m.len(),
        m.chars().take(200).collect::<String>()
    );
}

/// Panics unless a decoded `size` has no zero side and none over `limits`.
fn check_within(what: &str, size: UVec2, limits: &ReadLimits) {
    assert!(
        size.min_element() >= 1 && size.max_element() <= limits.max_side,
        "{what}: decoded a {size} image under max_side {}",
        limits.max_side
    );
}

/// Limits one texel tighter than `size`'s longer side (`None` for a 1x1 image).
fn tighter(size: UVec2) -> Option<ReadLimits> {
    (size.max_element() > 1).then(|| ReadLimits {
        max_side: size.max_element() - 1,
        ..ReadLimits::default()
    })
}

/// Splits `N` bytes of parameters off the front of `data`.
fn params<const N: usize>(data: &[u8]) -> Option<(&[u8; N], &[u8])> {
    data.split_first_chunk::<N>()
}

/// The little-endian u32 at `at` of `b`.
fn le32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}
