//! libFuzzer target `bounds`: `terrain_test_support::decoders::bounds` (see there for the input and
//! the checks).

#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    terrain_test_support::decoders::bounds(data);
});
