//! The morph's CPU reference: every vertex on a level's outer edge is fully morphed onto the
//! coarser level (so edges match and nothing cracks), and the interior is untouched.

use glam::{IVec2, Vec2};
use proptest::prelude::*;
use terrain_lod::ClipmapLayout;
use terrain_lod::morph::{
    MorphLevel, coarse_height, default_morph_width, morph_alpha, morphed_height,
};

/// A height field with no symmetry, so a wrong neighbour shows.
fn h(t: IVec2) -> f32 {
    (t.x as f32 * 0.37).sin() * 3.0 + (t.y as f32 * 0.21).cos() * 2.0 + t.x as f32 * 0.01
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn edges_are_fully_morphed_and_interiors_untouched(
        cx in -5000.0f32..5000.0, cz in -5000.0f32..5000.0,
        k in 3u32..=8, levels in 2u32..=6,
    ) {
        let n = (1 << k) - 1;
        let layout = ClipmapLayout::new(n, levels).unwrap();
        let camera = Vec2::new(cx, cz);
        let frame = layout.place(camera, 1.0, (0.0, 10.0), None).unwrap();
        let w = default_morph_width(n);
        let side = (n - 1) as i32;
        for level in frame.levels.iter().take(levels as usize - 1) {
            let s = level.scale as i32;
            for i in 0..=side {
                for edge in [
                    IVec2::new(i, 0), IVec2::new(i, side), IVec2::new(0, i), IVec2::new(side, i),
                ] {
                    let t = level.origin + edge * s;
                    let a = morph_alpha(t, camera, level.scale, n, w);
                    prop_assert_eq!(a, 1.0, "level {} edge vertex {} alpha {}", level.level, t, a);
                    // Fully morphed: the vertex lies on the coarser level's surface.
                    let m = morphed_height(
                        t,
                        camera,
                        &MorphLevel {
                            scale: level.scale,
                            n,
                            width: w,
                            coarsest: false,
                        },
                        h,
                    );
                    prop_assert!((m - coarse_height(t, level.scale, h)).abs() < 1e-4);
                }
            }
            // The vertex nearest the camera is not morphed.
            let centre = ((camera - level.origin.as_vec2()) / s as f32).round().as_ivec2();
            let t = level.origin + centre.clamp(IVec2::ZERO, IVec2::splat(side)) * s;
            prop_assert_eq!(morph_alpha(t, camera, level.scale, n, w), 0.0);
        }
    }
}

#[test]
fn coarse_height_interpolates_the_coarser_grid() {
    for scale in [1u32, 2, 8] {
        let s = scale as i32;
        // Coarser vertices (even in this level's grid units) keep their own height.
        let even = IVec2::new(4 * s, -6 * s);
        assert_eq!(coarse_height(even, scale, h), h(even));
        // Odd on one axis: the mean of the two coarser neighbours along it.
        let odd_x = IVec2::new(3 * s, 2 * s);
        let want = 0.5 * (h(odd_x - IVec2::new(s, 0)) + h(odd_x + IVec2::new(s, 0)));
        assert!((coarse_height(odd_x, scale, h) - want).abs() < 1e-6);
        // Odd on both: the mean of the four around it; negative coordinates too.
        let odd = IVec2::new(-3 * s, -5 * s);
        let d = [
            IVec2::new(s, s),
            IVec2::new(-s, -s),
            IVec2::new(s, -s),
            IVec2::new(-s, s),
        ];
        let want = d.iter().map(|o| h(odd + *o)).sum::<f32>() / 4.0;
        assert!((coarse_height(odd, scale, h) - want).abs() < 1e-5);
    }
    // The coarsest level is never morphed.
    let t = IVec2::new(1, 0);
    assert_eq!(
        morphed_height(
            t,
            Vec2::new(1000.0, 0.0),
            &MorphLevel {
                scale: 1,
                n: 15,
                width: 1.5,
                coarsest: true,
            },
            h,
        ),
        h(t)
    );
}

/// The transition region is a tenth of the level's side (GPU Gems 2), at least one grid unit.
#[test]
fn the_default_morph_width_is_a_tenth_of_n_and_at_least_one() {
    assert_eq!(default_morph_width(255), 25.5);
    assert_eq!(default_morph_width(63), 6.3);
    assert_eq!(default_morph_width(15), 1.5);
    assert_eq!(default_morph_width(7), 1.0);
    assert_eq!(default_morph_width(0), 1.0);
}
