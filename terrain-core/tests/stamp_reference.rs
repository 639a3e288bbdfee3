//! The fast stamp paths of `apply_stamp` against the per-texel `apply_stamp_reference`: both
//! run the exact integer program, so every stamp (texture, user, Gaussian, separable or
//! rotated) equals the reference bit for bit, and every path is identical for 1 and 4
//! threads, footprints large enough to be shared among threads included.

use glam::Vec2;
use proptest::prelude::*;
use terrain_core::{
    Blend, GaussianStamp, Grid, HeightEncoding, HeightMap, HeightSample, Stamp, StampPlacement,
    TextureStamp, WrapMode, apply_stamp, apply_stamp_reference, gaussian_rounding_bound,
};

fn hashed<T: HeightSample>(w: u32, h: u32, lo: u32, span: u32) -> Grid<T> {
    Grid::from_fn(w, h, |x, y| {
        let mut z = u64::from(x).wrapping_mul(0x9E37_79B9) ^ u64::from(y).wrapping_mul(0x85EB_CA6B);
        z ^= z >> 15;
        T::from_raw_f64_clamped(f64::from(lo + (z % u64::from(span)) as u32))
    })
    .unwrap()
}

fn map16(wrap: WrapMode) -> HeightMap<u16> {
    let e = HeightEncoding::new(0.01, -100.0).unwrap();
    HeightMap::new(hashed::<u16>(96, 80, 1_000, 60_000), e, 0.25, wrap).unwrap()
}

fn map8(wrap: WrapMode) -> HeightMap<u8> {
    let e = HeightEncoding::spanning::<u8>(-0.5, 0.5).unwrap();
    HeightMap::new(hashed::<u8>(64, 48, 20, 200), e, 0.03, wrap).unwrap()
}

fn blend(kind: u8, base_m: f32) -> Blend {
    match kind {
        0 => Blend::Add,
        1 => Blend::Min { base_m },
        _ => Blend::Max { base_m },
    }
}

fn ramp() -> TextureStamp {
    TextureStamp::from_gray8(&Grid::from_fn(13, 7, |x, y| (x * 19 + y * 11) as u8).unwrap())
}

/// A ring, evaluated through the trait per texel.
struct Ring;
impl Stamp for Ring {
    fn value(&self, local: Vec2) -> f32 {
        let r = local.length();
        if (0.4..0.8).contains(&r) {
            1.0 - r
        } else {
            f32::NAN
        }
    }
}

fn in_pool<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

prop_compose! {
    fn placement(ts: f32, w: f32, h: f32)(
        cx in -0.3f32..1.3, cz in -0.3f32..1.3,
        sx in 0.5f32..30.0, sz in 0.5f32..30.0,
        rot in -7.0f32..7.0, square in any::<bool>(), axis in any::<bool>(),
        intensity in -3.0f32..3.0,
    ) -> StampPlacement {
        let scale = Vec2::new(sx, if square { sx } else { sz }) * ts;
        let rot = if axis { (rot * 2.0 / std::f32::consts::PI).round() * std::f32::consts::FRAC_PI_2 } else { rot };
        StampPlacement::new(Vec2::new(cx * w, cz * h) * ts, scale, intensity)
            .unwrap()
            .with_rotation(rot)
            .unwrap()
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Texture and user stamps: the inline, row-parallel texture path and the per-texel path
    /// equal the reference bit for bit, on u16 and u8 maps, wrapping and clamped, every blend.
    #[test]
    fn texture_and_user_stamps_equal_the_reference(
        p in placement(0.25, 96.0, 80.0),
        wrap in any::<bool>(), kind in 0u8..3, base in -0.5f32..1.0, user in any::<bool>(),
        eight in any::<bool>(),
    ) {
        let wrap = if wrap { WrapMode::Repeat } else { WrapMode::Clamp };
        let b = blend(kind, base * 600.0 - 100.0);
        let mk = || -> Box<dyn Stamp> { if user { Box::new(Ring) } else { Box::new(ramp()) } };
        if eight {
            let mut fast = map8(wrap);
            let p = StampPlacement { center: p.center * 0.12, scale: p.scale * 0.12, intensity: p.intensity * 0.1, ..p };
            let b = blend(kind, base * 0.5);
            let mut reference = fast.clone();
            let r1 = apply_stamp(&mut fast, mk().as_mut(), &p, b);
            let r2 = apply_stamp_reference(&mut reference, mk().as_mut(), &p, b);
            prop_assert_eq!(r1.is_ok(), r2.is_ok());
            prop_assert!(fast == reference);
        } else {
            let mut fast = map16(wrap);
            let mut reference = fast.clone();
            let r1 = apply_stamp(&mut fast, mk().as_mut(), &p, b);
            let r2 = apply_stamp_reference(&mut reference, mk().as_mut(), &p, b);
            prop_assert_eq!(r1.is_ok(), r2.is_ok());
            prop_assert!(fast == reference);
        }
    }

    /// The Gaussian (separable when unrotated, radial otherwise) on a clamped map equals the
    /// reference bit for bit, on u16 maps and on u8 (detail) maps.
    #[test]
    fn gaussian_equals_the_reference(
        p in placement(0.25, 96.0, 80.0),
        kind in 0u8..3, base in 0.0f32..1.0, eps in 1e-4f32..1e-1,
    ) {
        check_gaussian_exact(map16(WrapMode::Clamp), &p, blend(kind, base * 600.0 - 100.0), eps)?;
    }

    #[test]
    fn gaussian_equals_the_reference_on_u8_maps(
        p in placement(0.03, 64.0, 48.0),
        kind in 0u8..3, base in 0.0f32..1.0, eps in 1e-4f32..1e-1,
    ) {
        // Detail-map scale: a few centimetres deep, within the map's metre of range.
        let p = StampPlacement { intensity: p.intensity * 0.1, ..p };
        check_gaussian_exact(map8(WrapMode::Clamp), &p, blend(kind, base - 0.5), eps)?;
    }

    /// u32 maps: the same program, the same bits.
    #[test]
    fn gaussian_equals_the_reference_on_u32_maps(
        p in placement(0.25, 96.0, 80.0),
        kind in 0u8..3, base in 0.0f32..1.0, eps in 1e-4f32..1e-1,
    ) {
        let e = HeightEncoding::new(0.01, -100.0).unwrap();
        let m = HeightMap::new(hashed::<u32>(96, 80, 1_000, 60_000), e, 0.25, WrapMode::Clamp)
            .unwrap();
        check_gaussian_exact(m, &p, blend(kind, base * 600.0 - 100.0), eps)?;
    }

    /// Results do not depend on the thread count.
    #[test]
    fn stamps_are_identical_for_1_and_4_threads(
        p in placement(0.25, 96.0, 80.0), gaussian in any::<bool>(), kind in 0u8..3,
    ) {
        let b = blend(kind, 150.0);
        let run = |threads| in_pool(threads, || {
            let mut m = map16(WrapMode::Repeat);
            let mut s: Box<dyn Stamp + Send> =
                if gaussian { Box::new(GaussianStamp::default()) } else { Box::new(ramp()) };
            let _ = apply_stamp(&mut m, s.as_mut(), &p, b);
            m
        });
        prop_assert!(run(1) == run(4));
    }
}

/// A 400 x 384 map whose stamps cover 150 to 250 texels a side (at least 2^14 texels on the
/// map: the rows are shared among threads).
fn large16(wrap: WrapMode) -> HeightMap<u16> {
    let e = HeightEncoding::new(0.01, -100.0).unwrap();
    HeightMap::new(hashed::<u16>(400, 384, 1_000, 60_000), e, 0.25, wrap).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Footprints large enough to run in parallel: every kind and blend, wrapping and clamped,
    /// the same bits on 1 and 4 threads and as the per-texel reference.
    #[test]
    fn large_stamps_are_identical_for_1_and_4_threads_and_the_reference(
        cx in 0.0f32..1.0, cz in 0.0f32..1.0, side in 150.0f32..250.0, aspect in 0.75f32..1.0,
        rot in -4.0f32..4.0, rotated in any::<bool>(), stamp in 0u8..3, kind in 0u8..3,
        wrap in any::<bool>(),
    ) {
        // Anywhere on a repeating map (across the wrap too); near the middle of a clamped one,
        // so the whole footprint (rotated: within sqrt(2) of its size) lands.
        let (cx, cz) = if wrap { (cx, cz) } else { (0.4 + 0.2 * cx, 0.4 + 0.2 * cz) };
        let wrap = if wrap { WrapMode::Repeat } else { WrapMode::Clamp };
        let p = StampPlacement::new(
            Vec2::new(cx * 400.0, cz * 384.0) * 0.25,
            Vec2::new(side, side * aspect) * 0.25,
            -2.5,
        )
        .unwrap()
        .with_rotation(if rotated { rot } else { 0.0 })
        .unwrap();
        let on_map = p
            .footprint(0.25)
            .unwrap()
            .intersect(&terrain_core::Rect::from_size(glam::UVec2::new(400, 384)))
            .map_or(0, |r| r.area());
        prop_assert!(wrap == WrapMode::Repeat || on_map >= 1 << 14);
        prop_assert!(p.footprint(0.25).unwrap().area() >= 1 << 14);
        let b = blend(kind, 150.0);
        let mk = || -> Box<dyn Stamp + Send> {
            match stamp {
                0 => Box::new(GaussianStamp::default()),
                1 => Box::new(ramp()),
                _ => Box::new(GaussianStamp::new(0.05).unwrap()),
            }
        };
        let run = |threads| in_pool(threads, || {
            let mut m = large16(wrap);
            let r = apply_stamp(&mut m, mk().as_mut(), &p, b);
            (r.is_ok(), m)
        });
        let (ok1, one) = run(1);
        let (ok4, four) = run(4);
        let mut reference = large16(wrap);
        let ok = apply_stamp_reference(&mut reference, mk().as_mut(), &p, b).is_ok();
        prop_assert!(ok1 && ok4 && ok);
        prop_assert!(one == four);
        prop_assert!(one == reference);
        prop_assert!(one != large16(wrap));
    }
}

/// The largest difference between two u16 maps, in stored units.
fn max_unit_difference(a: &HeightMap<u16>, b: &HeightMap<u16>) -> u16 {
    a.grid()
        .as_slice()
        .iter()
        .zip(b.grid().as_slice())
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap_or(0)
}

/// Min and max blends with a base far above or below the map and an intensity that brings
/// the surface back into it (or nearly): the small-sample path once clamped such terms and
/// left the centre untouched; every texel must equal the reference.
#[test]
fn far_bases_with_huge_intensities_equal_the_reference() {
    let e = HeightEncoding::new(0.01, 0.0).unwrap();
    for (base_m, intensity) in [
        (9_000.0f32, -9_000.0f32),
        (9_000.0, -8_700.0),
        (-9_000.0, 9_300.0),
        (20_000.0, -19_800.0),
        (1e9, -1e9),
        (-1e9, 1e9),
    ] {
        for min in [true, false] {
            let b = if min {
                Blend::Min { base_m }
            } else {
                Blend::Max { base_m }
            };
            let p =
                StampPlacement::new(Vec2::new(12.0, 10.0), Vec2::splat(18.0), intensity).unwrap();
            let before = HeightMap::new(
                hashed::<u16>(96, 80, 1_000, 60_000),
                e,
                0.25,
                WrapMode::Clamp,
            )
            .unwrap();
            let mut fast = before.clone();
            let mut reference = before.clone();
            apply_stamp(&mut fast, &mut GaussianStamp::default(), &p, b).unwrap();
            apply_stamp_reference(&mut reference, &mut GaussianStamp::default(), &p, b).unwrap();
            let max = max_unit_difference(&fast, &reference);
            assert_eq!(
                max, 0,
                "base {base_m} m, intensity {intensity} m, min {min}: {max} units"
            );
            assert!(
                reference != before || !min,
                "base {base_m} intensity {intensity}: nothing moved"
            );
        }
    }
}

/// Full-range intensities on u16 and absurd ones: equal to the reference, never a panic.
#[test]
fn extreme_gaussians_equal_the_reference() {
    for intensity in [650.0f32, -650.0, 1e30, -1e30, 1e-30] {
        for rot in [0.0f32, 0.3, 1.0] {
            for scale in [
                Vec2::splat(20.0),
                Vec2::new(20.0, 2.0),
                Vec2::new(0.3, 19.0),
            ] {
                let p = StampPlacement::new(Vec2::new(12.0, 10.0), scale, intensity)
                    .unwrap()
                    .with_rotation(rot)
                    .unwrap();
                let mut fast = map16(WrapMode::Clamp);
                let mut reference = fast.clone();
                apply_stamp(&mut fast, &mut GaussianStamp::default(), &p, Blend::Add).unwrap();
                apply_stamp_reference(
                    &mut reference,
                    &mut GaussianStamp::default(),
                    &p,
                    Blend::Add,
                )
                .unwrap();
                let max = max_unit_difference(&fast, &reference);
                assert_eq!(
                    max, 0,
                    "intensity {intensity} rot {rot} scale {scale}: {max}"
                );
            }
        }
    }
}

/// Eq. 3.3 per texel as `DerivativeMap` computed it before its row-parallel fast path.
fn naive_derivatives<T: HeightSample>(map: &HeightMap<T>) -> Vec<Vec2> {
    let (w, h) = (map.size().x as i64, map.size().y as i64);
    let k = f64::from(map.encoding().scale) / (12.0 * f64::from(map.texel_size()));
    let at = |x: i64, y: i64| {
        let g = map.grid();
        g.get(
            map.wrap().resolve(x, w as u32),
            map.wrap().resolve(y, h as u32),
        )
        .unwrap()
        .to_raw_f64()
    };
    let mut out = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let dx = at(x - 2, y) - 8.0 * at(x - 1, y) + 8.0 * at(x + 1, y) - at(x + 2, y);
            let dz = at(x, y - 2) - 8.0 * at(x, y - 1) + 8.0 * at(x, y + 1) - at(x, y + 2);
            out.push(Vec2::new((dx * k) as f32, (dz * k) as f32));
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Derivatives (whole map and dirty rects, wrapping and clamped, u16 and u32 at full range)
    /// equal the per-texel formula bit for bit, for 1 and 3 threads.
    #[test]
    fn derivatives_equal_the_per_texel_formula(
        w in 1u32..40, h in 1u32..40, wrap in any::<bool>(), full in any::<bool>(),
        rx in 0u32..40, ry in 0u32..40, rw in 0u32..40, rh in 0u32..40,
    ) {
        let wrap = if wrap { WrapMode::Repeat } else { WrapMode::Clamp };
        let e = HeightEncoding::new(0.003, 1.0).unwrap();
        let m16 = HeightMap::new(hashed::<u16>(w, h, 0, 65_536), e, 0.7, wrap).unwrap();
        let span = if full { u32::MAX } else { 1000 };
        let m32 = HeightMap::new(hashed::<u32>(w, h, 0, span), e, 0.7, wrap).unwrap();
        for threads in [1, 3] {
            let (d16, d32) = in_pool(threads, || {
                (terrain_core::DerivativeMap::from_map(&m16), terrain_core::DerivativeMap::from_map(&m32))
            });
            prop_assert!(d16.grid().as_slice() == naive_derivatives(&m16).as_slice());
            prop_assert!(d32.grid().as_slice() == naive_derivatives(&m32).as_slice());
            // A dirty rect refreshed into a zeroed map equals the full map inside its region.
            let rect = terrain_core::Rect::new(
                glam::IVec2::new((rx % w) as i32, (ry % h) as i32),
                glam::UVec2::new(rw.min(w - rx % w), rh.min(h - ry % h)),
            );
            let mut part = terrain_core::DerivativeMap::from_grid(
                Grid::new(w, h, Vec2::ZERO).unwrap(), 0.7, wrap).unwrap();
            in_pool(threads, || part.update_rect(&m16, rect)).unwrap();
            for (p, f) in part.grid().as_slice().iter().zip(d16.grid().as_slice()) {
                prop_assert!(*p == Vec2::ZERO || p == f);
            }
        }
    }
}

/// Maps large enough for the rows to be shared among threads (and whose interior rows hold
/// many blocks of the vectorised loop and a tail), u8 and u16, wrapping and clamped: the
/// derivatives equal the per-texel formula bit for bit, and so does a dirty rect on an edge.
#[test]
fn large_maps_on_threads_equal_the_per_texel_formula() {
    let e = HeightEncoding::new(0.013, -2.0).unwrap();
    for (w, h) in [(301, 263), (270, 250)] {
        for wrap in [WrapMode::Repeat, WrapMode::Clamp] {
            let m16 = HeightMap::new(hashed::<u16>(w, h, 0, 65_536), e, 0.3, wrap).unwrap();
            let m8 = HeightMap::new(hashed::<u8>(w, h, 0, 256), e, 0.3, wrap).unwrap();
            let rect =
                terrain_core::Rect::new(glam::IVec2::new(1, 0), glam::UVec2::new(w - 1, 270));
            for threads in [1, 3] {
                let (d16, d8) = in_pool(threads, || {
                    (
                        terrain_core::DerivativeMap::from_map(&m16),
                        terrain_core::DerivativeMap::from_map(&m8),
                    )
                });
                assert!(d16.grid().as_slice() == naive_derivatives(&m16).as_slice());
                assert!(d8.grid().as_slice() == naive_derivatives(&m8).as_slice());
                let mut part = terrain_core::DerivativeMap::from_grid(
                    Grid::new(w, h, Vec2::ZERO).unwrap(),
                    0.3,
                    wrap,
                )
                .unwrap();
                in_pool(threads, || {
                    part.update_rect(
                        &m16,
                        rect.intersect(&terrain_core::Rect::from_size(m16.size()))
                            .unwrap(),
                    )
                })
                .unwrap();
                assert!(part == d16, "{w} x {h} {wrap:?} on {threads} threads");
            }
        }
    }
}

/// The check of `gaussian_equals_the_reference*` for any sample type: `apply_stamp` equals
/// `apply_stamp_reference` at every texel, and the stamp lands within `gaussian_rounding_bound`
/// plus the program's own error (2^-26 relative, one unit of rounding) of the exact Gaussian.
fn check_gaussian_exact<T: HeightSample + PartialEq + Copy + std::fmt::Debug>(
    before: HeightMap<T>,
    p: &StampPlacement,
    b: Blend,
    eps: f32,
) -> Result<(), TestCaseError> {
    let mut fast = before.clone();
    let mut reference = before.clone();
    let mut g = GaussianStamp::new(eps).unwrap();
    let r1 = apply_stamp(&mut fast, &mut g, p, b);
    let r2 = apply_stamp_reference(&mut reference, &mut GaussianStamp::new(eps).unwrap(), p, b);
    prop_assert!(r1.is_ok() && r2.is_ok());
    for y in 0..before.size().y {
        for x in 0..before.size().x {
            let f = fast.grid().get(x, y).unwrap();
            let r = reference.grid().get(x, y).unwrap();
            prop_assert!(f == r, "({x}, {y}): {f:?} vs {r:?}");
        }
    }
    // The program is the Gaussian: within one unit (plus the f32 bound) of the exact value.
    let enc = before.encoding();
    let add_scale = f64::from(p.intensity) / f64::from(enc.scale);
    let tol = gaussian_rounding_bound(g.beta(), p) * add_scale.abs() + 2f64.powi(-22);
    let (center, inv_half, sin, cos) = p.local_frame(before.texel_size());
    let fp = p.footprint(before.texel_size()).unwrap();
    for y in 0..before.size().y {
        for x in 0..before.size().x {
            if !fp.contains(glam::IVec2::new(x as i32, y as i32)) {
                continue;
            }
            let dx = f64::from(x) - f64::from(center.x);
            let dy = f64::from(y) - f64::from(center.y);
            let (c, s) = (f64::from(cos), f64::from(sin));
            let lx = (dx * c + dy * s) * f64::from(inv_half.x);
            let ly = (dy * c - dx * s) * f64::from(inv_half.y);
            if lx.abs() > 0.999 || ly.abs() > 0.999 {
                continue;
            }
            let v = (-f64::from(g.beta()) * (lx * lx + ly * ly)).exp();
            let old = before.grid().get(x, y).unwrap().to_raw_f64();
            let exact = match b {
                Blend::Add => old + add_scale * v,
                Blend::Min { base_m } => old.min(enc.to_raw(base_m) + add_scale * v),
                Blend::Max { base_m } => old.max(enc.to_raw(base_m) + add_scale * v),
            };
            let exact = exact.clamp(0.0, T::MAX_RAW);
            let got = fast.grid().get(x, y).unwrap().to_raw_f64();
            prop_assert!(
                (got - exact).abs() <= 0.5 + tol + 1e-6 * (1.0 + add_scale.abs()),
                "({x}, {y}): {got} vs exact {exact}"
            );
        }
    }
    Ok(())
}

/// `gaussian_rounding_bound` is the formula its documentation derives:
/// `2 eps (beta (12 (1 + k) + 6) + 2) + 4 eps` with `eps = 2^-24` and `k` the footprint's
/// aspect ratio, either way round.
#[test]
fn the_rounding_bound_is_the_documented_formula() {
    let eps = 2f64.powi(-24);
    for (scale, beta, k) in [
        (Vec2::splat(4.0), 1.0f32, 1.0),
        (Vec2::new(2.0, 6.0), 4.6, 3.0),
        (Vec2::new(9.0, 3.0), 2.5, 3.0),
        (Vec2::new(0.5, 8.0), 10.0, 16.0),
    ] {
        let p = StampPlacement::new(Vec2::ZERO, scale, 1.0).unwrap();
        let want = 2.0 * eps * (f64::from(beta) * (12.0 * (1.0 + k) + 6.0) + 2.0) + 4.0 * eps;
        let got = gaussian_rounding_bound(beta, &p);
        assert!(
            (got - want).abs() <= 1e-12 * want,
            "{scale} beta {beta}: {got} vs {want}"
        );
    }
}

/// A Gaussian on a u32 map raises its centre texel by the intensity (the f64 path; the
/// small-sample path is for u8 and u16 only).
#[test]
fn a_gaussian_lands_on_a_u32_map() {
    let e = HeightEncoding::new(0.01, 0.0).unwrap();
    let mut m = HeightMap::new(
        Grid::new(32, 32, 3_000_000_000u32).unwrap(),
        e,
        1.0,
        WrapMode::Clamp,
    )
    .unwrap();
    let p = StampPlacement::new(Vec2::new(16.0, 16.0), Vec2::splat(8.0), 2.0).unwrap();
    apply_stamp(&mut m, &mut GaussianStamp::default(), &p, Blend::Add).unwrap();
    assert_eq!(m.grid().get(16, 16), Some(3_000_000_200));
    assert_eq!(m.grid().get(0, 0), Some(3_000_000_000));
}
