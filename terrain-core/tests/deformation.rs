//! Stamps and normal maps together: wrap-around stamps, exact derivatives, volumes, dirty-rect
//! regeneration.

use glam::{IVec2, UVec2, Vec2};
use proptest::prelude::*;
use terrain_core::{
    Blend, CoarseMap, DerivativeMap, GaussianStamp, Grid, HeightEncoding, HeightMap, Rect, Stamp,
    StampPlacement, TextureStamp, WrapMode, apply_stamp, composite_normal, normal_from_derivatives,
};

/// A map with varied content from an integer hash, so shifts and overwrites are visible.
fn hashed_map(w: u32, h: u32, ts: f32, wrap: WrapMode) -> HeightMap<u16> {
    let g = Grid::from_fn(w, h, |x, y| {
        let mut z = u64::from(x) * 0x9E37_79B9 + u64::from(y) * 0x85EB_CA6B;
        z ^= z >> 13;
        20_000 + (z % 20_000) as u16
    })
    .unwrap();
    HeightMap::new(g, HeightEncoding::new(0.001, 0.0).unwrap(), ts, wrap).unwrap()
}

fn ramp_stamp() -> TextureStamp {
    // Asymmetric, so a wrong rotation, flip or offset shows.
    TextureStamp::from_gray8(&Grid::from_fn(9, 5, |x, y| (x * 25 + y * 7) as u8).unwrap())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A stamp across the wrap edge or corner equals the same stamp applied, away from the
    /// edges, to the cyclically shifted map.
    #[test]
    fn wrapped_stamp_equals_stamp_on_shifted_map(
        cx in 0i32..64 * 16, cz in 0i32..48 * 16,
        sx in 4i32..40, sz in 4i32..40,
        rot in -3.2f32..3.2,
        intensity in -8.0f32..8.0,
        gaussian in any::<bool>(),
    ) {
        let ts = 0.5;
        let map = hashed_map(64, 48, ts, WrapMode::Repeat);
        // Centres on a 1/16-texel grid, sizes in whole texels: all arithmetic stays exact.
        let center = Vec2::new(cx as f32, cz as f32) / 16.0 * ts;
        let scale = Vec2::new(sx as f32, sz as f32) * ts * 0.5;
        let p = StampPlacement::new(center, scale, intensity).unwrap().with_rotation(rot).unwrap();
        let mut stamp: Box<dyn Stamp> = if gaussian {
            Box::new(GaussianStamp::default())
        } else {
            Box::new(ramp_stamp())
        };

        let mut wrapped = map.clone();
        let dirty = apply_stamp(&mut wrapped, stamp.as_mut(), &p, Blend::Add).unwrap();
        prop_assert!(!dirty.is_empty() && dirty.len() <= 4);

        // Shift so the stamp's centre lands in the middle of the map.
        let shift = IVec2::new(32 - (cx / 16), 24 - (cz / 16));
        let shifted_grid = map.grid().shifted_cyclic(shift);
        let mut shifted = CoarseMap::coarse(shifted_grid, map.encoding(), ts).unwrap();
        let p2 = StampPlacement { center: center + shift.as_vec2() * ts, ..p };
        let d2 = apply_stamp(&mut shifted, stamp.as_mut(), &p2, Blend::Add).unwrap();
        prop_assert_eq!(d2.len(), 1, "the shifted stamp does not cross an edge");

        prop_assert!(wrapped.grid().shifted_cyclic(shift) == *shifted.grid());
    }

    /// The 4th-order difference is exact for polynomials up to cubic (interior texels of a
    /// clamped map, where no clamping enters the stencil).
    #[test]
    fn derivatives_are_exact_for_cubics(
        c1 in -60i64..60, c2 in -4i64..4, c3 in -1i64..=1,
        d1 in -60i64..60, d2 in -4i64..4, d3 in -1i64..=1, cxy in -3i64..3,
        ts in prop::sample::select(vec![0.1f32, 0.25, 1.0, 3.0]),
    ) {
        let n = 24u32;
        let poly = |x: i64, y: i64| 30_000 + c1 * x + c2 * x * x + c3 * x * x * x
            + d1 * y + d2 * y * y + d3 * y * y * y + cxy * x * y;
        let g = Grid::from_fn(n, n, |x, y| poly(i64::from(x), i64::from(y)) as u16).unwrap();
        let scale = 0.01;
        let map = HeightMap::new(g, HeightEncoding::new(scale, 5.0).unwrap(), ts, WrapMode::Clamp)
            .unwrap();
        let d = DerivativeMap::from_map(&map);
        for y in 2..n - 2 {
            for x in 2..n - 2 {
                let (xf, yf) = (f64::from(x), f64::from(y));
                let ex = (c1 as f64 + 2.0 * c2 as f64 * xf + 3.0 * c3 as f64 * xf * xf
                    + cxy as f64 * yf) * f64::from(scale) / f64::from(ts);
                let ez = (d1 as f64 + 2.0 * d2 as f64 * yf + 3.0 * d3 as f64 * yf * yf
                    + cxy as f64 * xf) * f64::from(scale) / f64::from(ts);
                let got = d.derivative(x, y).unwrap();
                // Exact up to the f32 the result is stored in.
                prop_assert!((f64::from(got.x) - ex).abs() <= 1e-6 * ex.abs().max(1e-3), "x {x} {y}: {} vs {ex}", got.x);
                prop_assert!((f64::from(got.y) - ez).abs() <= 1e-6 * ez.abs().max(1e-3), "z {x} {y}: {} vs {ez}", got.y);
            }
        }
    }

    /// Regenerating only the dirty rects (plus apron) gives the same map as a full rebuild.
    #[test]
    fn dirty_rect_regeneration_equals_full(
        stamps in prop::collection::vec((0f32..1.0, 0f32..1.0, 1f32..20.0, -3f32..3.0), 1..6),
        repeat in any::<bool>(),
    ) {
        let wrap = if repeat { WrapMode::Repeat } else { WrapMode::Clamp };
        let mut map = hashed_map(70, 50, 0.5, wrap);
        let mut normals = DerivativeMap::from_map(&map);
        for (u, v, size, intensity) in stamps {
            let p = StampPlacement::new(Vec2::new(u * 35.0, v * 25.0), Vec2::splat(size), intensity)
                .unwrap();
            for rect in apply_stamp(&mut map, &mut GaussianStamp::default(), &p, Blend::Add).unwrap() {
                normals.update_rect(&map, rect).unwrap();
            }
        }
        prop_assert!(normals == DerivativeMap::from_map(&map));
    }
}

/// Volume added by a Gaussian stamp, in cubic metres, against its analytic integral.
fn measured_volume(before: &CoarseMap, after: &CoarseMap) -> f64 {
    let scale = f64::from(before.encoding().scale);
    let area = f64::from(before.texel_size()).powi(2);
    before
        .grid()
        .as_slice()
        .iter()
        .zip(after.grid().as_slice())
        .map(|(&a, &b)| (f64::from(b) - f64::from(a)) * scale * area)
        .sum()
}

#[test]
fn gaussian_volume_matches_its_integral_within_half_a_percent() {
    let g = Grid::new(600, 600, 30_000u16).unwrap();
    // 0.1 mm per unit: quantisation is small against the stamp, as on a real coarse-map.
    let enc = HeightEncoding::new(1e-4, 0.0).unwrap();
    let before = CoarseMap::coarse(g, enc, 0.1).unwrap();
    let cases = [
        (Vec2::new(30.0, 30.0), Vec2::splat(20.0), -1.0, 0.0),
        (Vec2::new(30.0, 30.0), Vec2::new(12.0, 30.0), 0.5, 0.7),
        (Vec2::new(1.0, 59.0), Vec2::splat(8.0), 0.8, 0.0), // across the wrap corner
        (Vec2::new(20.0, 25.0), Vec2::splat(3.0), -0.3, 1.2),
    ];
    // The default epsilon gives beta = ln(|intensity| / epsilon), 4 to 9 here, where the
    // erf factors are within 1 % of 1; an epsilon of the intensity's order gives the
    // smallest falloff, beta = 1, where erf(1) = 0.84 counts.
    let epsilons = [None, None, None, None, Some(0.4), Some(0.1)];
    let cases = cases.into_iter().chain([
        (Vec2::new(30.0, 30.0), Vec2::new(16.0, 10.0), 0.6, 0.3),
        (Vec2::new(30.0, 30.0), Vec2::splat(14.0), -0.6, 0.0),
    ]);
    for ((center, scale, intensity, rot), epsilon) in cases.zip(epsilons) {
        let mut after = before.clone();
        let mut s = match epsilon {
            None => GaussianStamp::default(),
            Some(e) => GaussianStamp::new(e).unwrap(),
        };
        let p = StampPlacement::new(center, scale, intensity)
            .unwrap()
            .with_rotation(rot)
            .unwrap();
        apply_stamp(&mut after, &mut s, &p, Blend::Add).unwrap();
        let got = measured_volume(&before, &after);
        let want = s.volume(&p);
        let err = (got - want).abs() / want.abs();
        assert!(
            err < 0.005,
            "{center} {scale} {intensity}: {got} m3 vs {want} m3 ({:.3} %)",
            err * 100.0
        );
    }
}

#[test]
fn stamp_over_the_corner_lands_on_all_four_corners() {
    let g = Grid::new(32, 32, 1000u16).unwrap();
    let mut m = CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).unwrap(), 1.0).unwrap();
    let box_stamp = &mut TextureStamp::from_gray8(&Grid::new(2, 2, 255u8).unwrap());
    let p = StampPlacement::new(Vec2::ZERO, Vec2::splat(4.0), 1.0).unwrap();
    let dirty = apply_stamp(&mut m, box_stamp, &p, Blend::Add).unwrap();
    assert_eq!(dirty.len(), 4);
    for (x, y) in [(0, 0), (31, 0), (0, 31), (31, 31), (2, 2), (30, 30)] {
        assert_eq!(m.grid().get(x, y), Some(1100), "texel {x},{y}");
    }
    assert_eq!(m.grid().get(3, 3), Some(1000));
    assert_eq!(m.grid().get(16, 16), Some(1000));
}

#[test]
fn snorm8_packing_round_trips_within_one_step() {
    let map = hashed_map(40, 30, 0.5, WrapMode::Repeat);
    let d = DerivativeMap::from_map(&map);
    let max_slope = 4.0;
    let packed = d.to_snorm8(max_slope).unwrap();
    let back = DerivativeMap::from_snorm8(&packed, max_slope, 0.5, WrapMode::Repeat).unwrap();
    for (a, b) in d.grid().as_slice().iter().zip(back.grid().as_slice()) {
        let clamped = a.clamp(Vec2::splat(-max_slope), Vec2::splat(max_slope));
        assert!((clamped - *b).abs().max_element() <= max_slope / 254.0 + 1e-6);
    }
    assert!(d.to_snorm8(0.0).is_err());
    assert!(d.to_snorm8(f32::NAN).is_err());
}

#[test]
fn composite_normal_equals_normal_of_summed_heights() {
    let a = hashed_map(32, 32, 0.5, WrapMode::Clamp);
    let b = Grid::from_fn(32, 32, |x, y| ((x * 37 + y * 11) % 200) as u16).unwrap();
    let b = HeightMap::new(b, a.encoding(), 0.5, WrapMode::Clamp).unwrap();
    let sum = Grid::from_fn(32, 32, |x, y| {
        a.grid().get(x, y).unwrap() + b.grid().get(x, y).unwrap()
    })
    .unwrap();
    let sum = HeightMap::new(sum, a.encoding(), 0.5, WrapMode::Clamp).unwrap();
    let (da, db, ds) = (
        DerivativeMap::from_map(&a),
        DerivativeMap::from_map(&b),
        DerivativeMap::from_map(&sum),
    );
    for y in 0..32 {
        for x in 0..32 {
            let n = composite_normal(da.derivative(x, y).unwrap(), db.derivative(x, y).unwrap());
            let m = normal_from_derivatives(ds.derivative(x, y).unwrap());
            assert!((n - m).length() < 1e-5);
            assert!((n.length() - 1.0).abs() < 1e-5 && n.y > 0.0);
        }
    }
}

#[test]
fn update_rect_rejects_bad_regions_and_sizes() {
    let map = hashed_map(20, 20, 1.0, WrapMode::Clamp);
    let mut d = DerivativeMap::from_map(&map);
    let off = Rect::new(IVec2::new(18, 18), UVec2::new(5, 5));
    assert!(d.update_rect(&map, off).is_err());
    let other = hashed_map(21, 20, 1.0, WrapMode::Clamp);
    assert!(
        d.update_rect(&other, Rect::new(IVec2::ZERO, UVec2::ONE))
            .is_err()
    );
    // On a repeating map any rect wraps.
    let rmap = hashed_map(20, 20, 1.0, WrapMode::Repeat);
    let mut rd = DerivativeMap::from_map(&rmap);
    assert!(rd.update_rect(&rmap, off).is_ok());
}
