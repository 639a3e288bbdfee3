//! libFuzzer target `png8`: `terrain_test_support::decoders::png8` (see there for the input and
//! the checks).

#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    terrain_test_support::decoders::png8(data);
});
