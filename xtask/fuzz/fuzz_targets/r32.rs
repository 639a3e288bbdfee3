//! libFuzzer target `r32`: `terrain_test_support::decoders::r32` (see there for the input and
//! the checks).

#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    terrain_test_support::decoders::r32(data);
});
