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
fn every_renderer_carries_the_user_surface_markers_once_around_a_replaceable_function() {
    let (begin, end) = terrain_shaders::USER_SURFACE_MARKERS;
    let renderers = [
        ("clipmap", terrain_shaders::CLIPMAP),
        ("clipmap_atlas", terrain_shaders::CLIPMAP_ATLAS),
        ("clipmap_detail", terrain_shaders::CLIPMAP_DETAIL),
        ("clipmap_granular", terrain_shaders::CLIPMAP_GRANULAR),
        ("cdlod", terrain_shaders::CDLOD),
        ("cdlod_atlas", terrain_shaders::CDLOD_ATLAS),
        ("cdlod_detail", terrain_shaders::CDLOD_DETAIL),
        ("tessellated", terrain_shaders::TESSELLATED),
        ("tessellated_detail", terrain_shaders::TESSELLATED_DETAIL),
        ("refine", terrain_shaders::REFINE),
    ];
    for (name, src) in renderers {
        assert_eq!(src.matches(begin).count(), 1, "{name}");
        let (a, b) = (src.find(begin).unwrap(), src.find(end).unwrap());
        assert!(a < b, "{name}");
        let custom = format!(
            "{}{begin}\nfn surface_weights(p: SurfacePoint) -> vec4<f32> {{ \
             return vec4<f32>(p.ramp, 0.0, p.slope, fract(p.position.x)); }}\n{}",
            &src[..a],
            &src[b..]
        );
        validate(name, &custom);
    }
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

#[test]
fn the_prelude_declares_every_code_with_its_rust_value() {
    use terrain_shaders::codes;
    let module = naga::front::wgsl::parse_str(terrain_shaders::PRELUDE).expect("prelude parses");
    let value = |name: &str| -> i64 {
        let (_, c) = module
            .constants
            .iter()
            .find(|(_, c)| c.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("{name} missing from the prelude"));
        match module.global_expressions[c.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => i64::from(v),
            naga::Expression::Literal(naga::Literal::I32(v)) => i64::from(v),
            ref other => panic!("{name}: unexpected {other:?}"),
        }
    };
    for (name, rust) in [
        ("WRAP_REPEAT", i64::from(codes::WRAP_REPEAT)),
        ("WRAP_CLAMP", i64::from(codes::WRAP_CLAMP)),
        ("BLEND_ADD", i64::from(codes::BLEND_ADD)),
        ("BLEND_MIN", i64::from(codes::BLEND_MIN)),
        ("BLEND_MAX", i64::from(codes::BLEND_MAX)),
        ("STAMP_GAUSSIAN", i64::from(codes::STAMP_GAUSSIAN)),
        ("STAMP_TEXTURE", i64::from(codes::STAMP_TEXTURE)),
        ("STAMP_USER", i64::from(codes::STAMP_USER)),
        ("METRIC_EUCLIDEAN", i64::from(codes::METRIC_EUCLIDEAN)),
        ("METRIC_MANHATTAN", i64::from(codes::METRIC_MANHATTAN)),
        ("METRIC_CHEBYSHEV", i64::from(codes::METRIC_CHEBYSHEV)),
        ("SEED", i64::from(codes::SEED)),
        ("OBSTACLE", i64::from(codes::OBSTACLE)),
        ("PENETRATING", i64::from(codes::PENETRATING)),
        ("NO_SEED", i64::from(codes::NO_SEED)),
        ("NO_OBJECT", i64::from(codes::NO_OBJECT)),
        ("INVALID_SLOT", i64::from(codes::INVALID_SLOT)),
    ] {
        assert_eq!(value(name), rust, "{name}");
    }
}
