//! The decoder targets (`terrain_test_support::decoders`) under `cargo test`: the seeds must
//! decode, and the harness target `decoders` runs each decoder's function on byte-level
//! mutations of its seeds for its share of `TERRAIN_FUZZ_SECONDS` (default 2 s; `cargo xtask
//! fuzz --target decoders --seconds N` runs it longer). The same functions are the bodies of the
//! coverage-guided libFuzzer targets in `xtask/fuzz/` (`cargo xtask fuzz --engine libfuzzer`).
//!
//! A failing case prints its `TERRAIN_FUZZ_REPLAY`; replaying it prints the input and writes it
//! to a file that libFuzzer's target of the same name runs as well.

use std::time::Duration;
use terrain_test_support::decoders::{DECODERS, Outcome, mutate};
use terrain_test_support::fuzz::{self, Case, Class, Target};

/// The seeds of every decoder, in [`DECODERS`] order.
struct Seeds(Vec<Vec<Vec<u8>>>);

/// Decoding one small input takes well under a millisecond; 250 ms leaves room for debug
/// builds on a loaded machine while still catching a decoder that loops.
const PER_CASE_LIMIT: Duration = Duration::from_millis(250);

/// A seed of decoder `I` mutated, through the decoder's function.
fn mutated<const I: usize>(seeds: &Seeds, case: &mut Case) -> Result<(), String> {
    let d = &DECODERS[I];
    let pool = &seeds.0[I];
    let mut input = pool[case.rng.index(pool.len())].clone();
    mutate(&mut input, pool, &mut case.rng);
    if case.verbose() {
        let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(d.name);
        std::fs::write(&path, &input).map_err(|e| format!("{}: {e}", path.display()))?;
        let hex: String = input.iter().map(|b| format!("{b:02x}")).collect();
        eprintln!(
            "{} input, {} bytes: {hex}\nwritten to {}: `cargo +nightly fuzz run --fuzz-dir \
             xtask/fuzz {} <that file>` runs it in libFuzzer",
            d.name,
            input.len(),
            path.display(),
            d.name
        );
    }
    (d.run)(&input);
    Ok(())
}

fn class<const I: usize>() -> Class<Seeds> {
    Class {
        name: DECODERS[I].name,
        run: mutated::<I>,
    }
}

#[test]
fn fuzz_decoders() {
    const _: () = assert!(DECODERS.len() == 8, "one class per decoder below");
    let classes = vec![
        class::<0>(),
        class::<1>(),
        class::<2>(),
        class::<3>(),
        class::<4>(),
        class::<5>(),
        class::<6>(),
        class::<7>(),
    ];
    let seeds = Seeds(DECODERS.iter().map(|d| (d.seeds)()).collect());
    fuzz::run(
        Target {
            name: "decoders",
            per_case_limit: PER_CASE_LIMIT,
            classes,
            disabled: &[],
        },
        seeds,
    );
}

/// Every seed decodes (so the corpora start on the decoders' success paths, and a seed that a
/// format change made stale is caught here), and the seeds stay small.
#[test]
fn decoder_seeds_decode() {
    let mut total = 0;
    for d in &DECODERS {
        let seeds = (d.seeds)();
        assert!(seeds.len() >= 3, "{}: {} seeds", d.name, seeds.len());
        for (i, s) in seeds.iter().enumerate() {
            assert_eq!((d.run)(s), Outcome::Decoded, "{} seed {i}", d.name);
            total += s.len();
        }
    }
    assert!(total < 64 * 1024, "the seeds are {total} bytes");
}

/// A few inputs of each decoder that must be refused cleanly: empty, one byte, short
/// parameters, a truncated seed.
#[test]
fn decoders_refuse_short_inputs() {
    for d in &DECODERS {
        assert_eq!((d.run)(&[]), Outcome::Refused, "{}: empty", d.name);
        assert_eq!((d.run)(&[0]), Outcome::Refused, "{}: one byte", d.name);
        let seed = (d.seeds)().swap_remove(0);
        let cut = &seed[..seed.len() / 2];
        assert_eq!((d.run)(cut), Outcome::Refused, "{}: half a seed", d.name);
    }
}

// ---------------------------------------------------------------------------------------------
// Regressions: inputs the decoder targets found

/// `decoders/geotiff` (harness replay `geotiff:0x6e91441d0727cdc7`): a SampleFormat tag of
/// thousands of values made the TIFF decoder's error list every one of them, and
/// `decode_geotiff` passed the 14 kB message on (a file of a million values would make one of
/// megabytes). Reasons that quote the file are now cut to a few hundred bytes.
#[test]
fn regression_geotiff_error_quoting_a_long_tag_is_bounded() {
    use terrain_core::geotiff::decode_geotiff;
    use terrain_test_support::tiff::{SHORT, Sample, TiffSpec};
    let formats: Vec<u8> = (0..3000u16)
        .flat_map(|i| (i % 7 + 5).to_le_bytes())
        .collect();
    let spec = TiffSpec {
        extra: vec![(339, SHORT, 3000, formats)],
        ..TiffSpec::new(4, 3, Sample::U16, vec![1.0; 12])
    };
    let file = spec.write();
    let e = decode_geotiff(&file, &terrain_test_support::decoders::LIMITS)
        .expect_err("a file of 3000 sample formats is refused");
    let message = e.to_string();
    assert!(message.len() < 512, "{} bytes: {message}", message.len());
    assert_eq!(
        terrain_test_support::decoders::geotiff(&file),
        Outcome::Refused
    );
}

/// libFuzzer's `manifest` target (60 s, crash input of 3.4 kB): serde_json quotes an unknown
/// field's name in its error, and `Manifest::from_json` passed it on whole: a 2 kB message from
/// that input, 64 KiB from a manifest of one long name. The reason is now cut to a few hundred
/// bytes.
#[test]
fn regression_manifest_error_quoting_a_long_field_name_is_bounded() {
    use terrain_cache::Manifest;
    let text = format!("{{\"{}\": 1}}", "for\\\\height_fill".repeat(500));
    let e = Manifest::from_json(&text).expect_err("an unknown field is refused");
    let message = e.to_string();
    assert!(message.len() < 512, "{} bytes: {message}", message.len());
    assert_eq!(
        terrain_test_support::decoders::manifest(text.as_bytes()),
        Outcome::Refused
    );
}
