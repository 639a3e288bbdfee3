//! The spill rule: a detail stamp that leaves the tiles' 1 m range moves the excess into the
//! coarse-map, conserving volume to the encodings' rounding, instead of clipping it.

use glam::{IVec2, UVec2, Vec2};
use terrain_core::detail::{DETAIL_ZERO_RAW, DetailLayer, DetailLayout};
use terrain_core::detail_spill::spill_rect;
use terrain_core::{
    Blend, GaussianStamp, Grid, HeightEncoding, HeightMap, StampPlacement, TextureStamp, WrapMode,
};

/// 64 x 64 coarse texels of 0.1 m refined x3: 192 x 192 detail texels in 6 x 6 tiles of 32.
fn layout() -> DetailLayout {
    DetailLayout::new(UVec2::splat(64), 0.1, 3, 32).unwrap()
}

/// The coarse-map under it: 1 mm units, 20 m of headroom either way.
fn coarse(wrap: WrapMode) -> HeightMap<u16> {
    let enc = HeightEncoding::new(0.001, -30.0).unwrap();
    HeightMap::new(Grid::new(64, 64, 30_000u16).unwrap(), enc, 0.1, wrap).unwrap()
}

/// Volume of the detail layer above 0 m and of the coarse-map above its start, in m^3.
fn volumes(layer: &DetailLayer, map: &HeightMap<u16>) -> (f64, f64) {
    let l = layer.layout();
    let d = l.detail_size();
    let ts = f64::from(l.detail_texel_m());
    let mut detail = 0.0;
    for y in 0..d.y as i32 {
        for x in 0..d.x as i32 {
            detail += f64::from(i32::from(layer.raw(IVec2::new(x, y))) - 128);
        }
    }
    let coarse_units = map.raw_sum() as f64 - 30_000.0 * 64.0 * 64.0;
    (detail / 255.0 * ts * ts, coarse_units * 0.001 * 0.1 * 0.1)
}

/// A layer whose four tiles around detail texel (96, 96) hold uneven detail (raw 60 to 199),
/// so a stamp's base differs texel by texel.
fn uneven_layer() -> DetailLayer {
    let mut layer = DetailLayer::new(layout()).unwrap();
    for (i, t) in [(2, 2), (3, 2), (2, 3), (3, 3)].into_iter().enumerate() {
        let g = Grid::from_fn(32, 32, |x, y| {
            (60 + (x * 7 + y * 13 + i as u32 * 29) % 140) as u8
        })
        .unwrap();
        layer.set_tile(UVec2::new(t.0, t.1), g).unwrap();
    }
    layer
}

/// The largest coarse rounding a spill may leave: half a unit on every texel it reaches.
fn rounding_m3(rects_area: u64) -> f64 {
    rects_area as f64 * 0.5 * 0.001 * 0.1 * 0.1
}

#[test]
fn a_deep_mark_over_a_tile_corner_spills_its_excess_and_keeps_the_volume() {
    let l = layout();
    // 1.5 m deep: a metre below what a tile holds, centred on the corner of four tiles.
    let p = StampPlacement::new(Vec2::splat(3.2), Vec2::new(0.6, 0.4), -1.5)
        .unwrap()
        .with_rotation(0.4)
        .unwrap();
    let footprint = p.footprint(l.detail_texel_m()).unwrap();
    for (wrap, uneven) in [
        (WrapMode::Repeat, false),
        (WrapMode::Clamp, false),
        (WrapMode::Repeat, true),
    ] {
        let mut layer = if uneven {
            uneven_layer()
        } else {
            DetailLayer::new(l).unwrap()
        };
        let (before_m3, _) = volumes(&layer, &coarse(wrap));
        let mut map = coarse(wrap);
        let (change, rects) = layer
            .apply_stamp_spilling(&mut map, &mut GaussianStamp::default(), &p, Blend::Add)
            .unwrap();
        assert_eq!(change.tiles.len(), 4, "{wrap:?}");
        assert!(!rects.is_empty());
        // The unclipped mark: the same stamp on a wide enough map.
        let enc = HeightEncoding::new(1.0 / 255.0, -32_768.0 / 255.0).unwrap();
        let d = l.detail_size();
        let mut wide = HeightMap::new(
            Grid::new(d.x, d.y, 32_768u16).unwrap(),
            enc,
            l.detail_texel_m(),
            WrapMode::Repeat,
        )
        .unwrap();
        terrain_core::apply_stamp(&mut wide, &mut GaussianStamp::default(), &p, Blend::Add)
            .unwrap();
        let ts = f64::from(l.detail_texel_m());
        let mark_m3 = (wide.raw_sum() as f64 - 32_768.0 * f64::from(d.x * d.y)) / 255.0 * ts * ts;
        let (after_m3, coarse_m3) = volumes(&layer, &map);
        let detail_m3 = after_m3 - before_m3;
        let bound = rounding_m3(spill_rect(footprint, 3).area()) + 1e-9;
        assert!(
            (detail_m3 + coarse_m3 - mark_m3).abs() <= bound,
            "{wrap:?}: detail {detail_m3} + coarse {coarse_m3} vs mark {mark_m3} (bound {bound})"
        );
        // The tile is at the bottom of its range under the mark's centre, and the coarse
        // surface went down there: about 1 m of the 1.5 m, smoothed over coarse texels.
        assert_eq!(layer.raw(IVec2::new(96, 96)), 0);
        assert!(map.grid().get(32, 32).unwrap() < 30_000 - 300, "{wrap:?}");
        // Clipping instead loses a part of the mark (heights are negative: the clipped volume
        // is the smaller in magnitude).
        let mut clipped = if uneven {
            uneven_layer()
        } else {
            DetailLayer::new(l).unwrap()
        };
        clipped
            .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
            .unwrap();
        let (clipped_m3, _) = volumes(&clipped, &coarse(wrap));
        let clipped_m3 = clipped_m3 - before_m3;
        assert!(clipped_m3 > 0.9 * mark_m3, "{clipped_m3} vs {mark_m3}");
        let texel_m3 = f64::from(l.detail_texel_m()).powi(2) / 255.0;
        assert!(
            (clipped_m3 - detail_m3).abs() <= 40.0 * texel_m3,
            "{wrap:?} {uneven}"
        );
    }
}

#[test]
fn a_mark_within_the_range_spills_nothing_and_equals_the_clipping_stamp() {
    let l = layout();
    let tex =
        TextureStamp::from_gray8(&Grid::from_fn(9, 5, |x, y| (x * 29 + y * 41) as u8).unwrap());
    for (i, (p, uneven)) in [
        (
            StampPlacement::new(Vec2::splat(3.2), Vec2::new(0.5, 0.3), -0.2).unwrap(),
            true,
        ),
        (
            StampPlacement::new(Vec2::splat(3.2), Vec2::new(0.5, 0.3), -0.3).unwrap(),
            false,
        ),
        (
            StampPlacement::new(Vec2::new(0.05, 6.3), Vec2::new(0.4, 0.2), 0.2)
                .unwrap()
                .with_rotation(1.1)
                .unwrap(),
            false,
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let fresh = || {
            if uneven {
                uneven_layer()
            } else {
                DetailLayer::new(l).unwrap()
            }
        };
        let (mut a, mut b) = (fresh(), fresh());
        let mut map = coarse(WrapMode::Repeat);
        let (ca, rects) = a
            .apply_stamp_spilling(&mut map, &mut tex.clone(), &p, Blend::Add)
            .unwrap();
        let cb = b.apply_stamp(&mut tex.clone(), &p, Blend::Add).unwrap();
        assert!(rects.is_empty(), "{i}");
        assert_eq!(map, coarse(WrapMode::Repeat), "{i}");
        assert_eq!(ca.tiles, cb.tiles, "{i}");
        let d = l.detail_size();
        for y in 0..d.y as i32 {
            for x in 0..d.x as i32 {
                let q = IVec2::new(x, y);
                let (va, vb) = (i32::from(a.raw(q)), i32::from(b.raw(q)));
                assert!((va - vb).abs() <= 1, "{i}: ({x}, {y}) {va} vs {vb}");
            }
        }
    }
}

#[test]
fn a_raised_mark_spills_upwards_and_a_min_blend_far_below_spills_down() {
    let l = layout();
    let mut layer = DetailLayer::new(l).unwrap();
    let mut map = coarse(WrapMode::Repeat);
    let up = StampPlacement::new(Vec2::new(1.0, 5.0), Vec2::splat(0.5), 2.0).unwrap();
    layer
        .apply_stamp_spilling(&mut map, &mut GaussianStamp::default(), &up, Blend::Add)
        .unwrap();
    assert_eq!(layer.raw(IVec2::new(30, 150)), 255);
    assert!(map.grid().get(10, 50).unwrap() > 30_000 + 500);
    let down = StampPlacement::new(Vec2::new(4.0, 1.0), Vec2::splat(0.3), 1.0).unwrap();
    let (_, rects) = layer
        .apply_stamp_spilling(
            &mut map,
            &mut GaussianStamp::default(),
            &down,
            Blend::Min { base_m: -3.0 },
        )
        .unwrap();
    assert!(!rects.is_empty());
    assert_eq!(layer.raw(IVec2::new(120, 30)), 0);
    assert!(map.grid().get(40, 10).unwrap() < 30_000 - 1_000);
    assert_eq!(
        layer.raw(IVec2::new(0, 0)),
        DETAIL_ZERO_RAW,
        "untouched texels stay at 0 m"
    );
}

#[test]
fn a_mismatched_coarse_map_or_an_oversized_spill_is_refused_and_changes_nothing() {
    let l = layout();
    let p = StampPlacement::new(Vec2::splat(3.2), Vec2::splat(0.5), -2.0).unwrap();
    let mut layer = DetailLayer::new(l).unwrap();
    let enc = HeightEncoding::new(0.001, -30.0).unwrap();
    let mut small = HeightMap::new(
        Grid::new(32, 64, 30_000u16).unwrap(),
        enc,
        0.1,
        WrapMode::Repeat,
    )
    .unwrap();
    let mut other_ts = HeightMap::new(
        Grid::new(64, 64, 30_000u16).unwrap(),
        enc,
        0.2,
        WrapMode::Repeat,
    )
    .unwrap();
    let g = &mut GaussianStamp::default();
    assert!(
        layer
            .apply_stamp_spilling(&mut small, g, &p, Blend::Add)
            .is_err()
    );
    assert!(
        layer
            .apply_stamp_spilling(&mut other_ts, g, &p, Blend::Add)
            .is_err()
    );
    // A mark as wide as the layer would spill around the repeating coarse-map.
    let whole = StampPlacement::new(Vec2::splat(3.2), Vec2::splat(6.35), -2.0).unwrap();
    let mut map = coarse(WrapMode::Repeat);
    assert!(
        layer
            .apply_stamp_spilling(&mut map, g, &whole, Blend::Add)
            .is_err()
    );
    assert_eq!(map, coarse(WrapMode::Repeat));
    assert_eq!(layer.resident_tiles(), 0);
    // A centre far off the map wraps onto it like any other (bounded work: one mark).
    let far = StampPlacement::new(Vec2::splat(1e6), Vec2::splat(0.2), -5.0).unwrap();
    let (change, rects) = layer
        .apply_stamp_spilling(&mut map, g, &far, Blend::Add)
        .unwrap();
    assert!(!change.tiles.is_empty() && change.tiles.len() <= 4);
    assert!(!rects.is_empty());
    // The ends of the f32 range: bounded work and an answer (or an error), never a panic.
    for (c, s, i) in [
        (1e30, 0.2, -1e30),
        (-3e38, 0.3, 3e38),
        (5.0, 1e30, -1.0),
        (5.0, 1e-30, -1.0),
    ] {
        let p = StampPlacement::new(Vec2::splat(c), Vec2::splat(s), i).unwrap();
        let _ = layer.apply_stamp_spilling(&mut map, g, &p, Blend::Add);
    }
}
