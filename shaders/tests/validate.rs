//! Parses and validates every shader with naga; needs no GPU adapter.

use naga::valid::{Capabilities, ValidationFlags, Validator};

fn validate(name: &str, source: &str) {
    let module = naga::front::wgsl::parse_str(source)
        .unwrap_or_else(|e| panic!("{name}.wgsl does not parse:\n{}", e.emit_to_string(source)));
    Validator::new(ValidationFlags::all(), Capabilities::empty())
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}.wgsl does not validate: {e:?}"));
}

#[test]
fn every_shader_parses_and_validates() {
    assert!(!terrain_shaders::ALL.is_empty());
    for (name, source) in terrain_shaders::ALL {
        validate(name, source);
    }
}

#[test]
fn the_user_stamp_markers_enclose_a_replaceable_function() {
    let (begin, end) = terrain_shaders::USER_STAMP_MARKERS;
    let src = terrain_shaders::STAMP;
    let (a, b) = (src.find(begin).unwrap(), src.find(end).unwrap());
    assert!(a < b);
    let custom = format!(
        "{}{begin}\nfn user_stamp_value(local: vec2<f32>) -> f32 {{ return 1.0 - length(local); }}\n{}",
        &src[..a],
        &src[b..]
    );
    validate("stamp (user)", &custom);
}

#[test]
fn a_broken_shader_is_caught() {
    let broken =
        terrain_shaders::NORMALS.replace("return u32(clamp(v, 0, i32(n) - 1));", "return v;");
    let parsed = naga::front::wgsl::parse_str(&broken);
    let invalid = match parsed {
        Err(_) => true,
        Ok(m) => Validator::new(ValidationFlags::all(), Capabilities::empty())
            .validate(&m)
            .is_err(),
    };
    assert!(invalid, "a type error must not validate");
}
