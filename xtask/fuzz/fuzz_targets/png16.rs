//! libFuzzer target `png16`: `terrain_test_support::decoders::png16` (see there for the input and
//! the checks).

#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    terrain_test_support::decoders::png16(data);
});
