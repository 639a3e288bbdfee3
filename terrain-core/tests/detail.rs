//! The detail layer: eq. 2.1's tile grid, stamps across tile edges, corners and the map's wrap
//! against the same stamps on one large detail map, the shared zero tile, and refusals.

use glam::{IVec2, UVec2, Vec2};
use terrain_core::detail::{DETAIL_ZERO_RAW, DetailLayer, DetailLayout, detail_encoding};
use terrain_core::{
    Blend, CoreError, GaussianStamp, Grid, HeightMap, Rect, Stamp, StampPlacement, TextureStamp,
    WrapMode, apply_stamp,
};

/// 64 x 64 coarse texels of 0.1 m refined x3: 192 x 192 detail texels in 6 x 6 tiles of 32.
fn layout() -> DetailLayout {
    DetailLayout::new(UVec2::splat(64), 0.1, 3, 32).unwrap()
}

fn big(l: &DetailLayout, wrap: WrapMode) -> HeightMap<u8> {
    let d = l.detail_size();
    let g = Grid::new(d.x, d.y, DETAIL_ZERO_RAW).unwrap();
    HeightMap::new(g, detail_encoding(), l.detail_texel_m(), wrap).unwrap()
}

fn texture() -> TextureStamp {
    TextureStamp::from_gray8(&Grid::from_fn(9, 5, |x, y| (x * 29 + y * 41) as u8).unwrap())
}

/// A default Gaussian or the test texture.
fn stamp(gaussian: bool) -> Box<dyn Stamp> {
    if gaussian {
        Box::new(GaussianStamp::default())
    } else {
        Box::new(texture())
    }
}

fn assert_same(layer: &DetailLayer, map: &HeightMap<u8>, what: &str) {
    let d = layer.layout().detail_size();
    for y in 0..d.y {
        for x in 0..d.x {
            let want = map.grid().get(x, y).unwrap();
            let got = layer.raw(IVec2::new(x as i32, y as i32));
            assert_eq!(got, want, "{what}: texel ({x}, {y})");
        }
    }
}

#[test]
fn eq_2_1_gives_seed_000s_six_tiles_a_side() {
    let l = DetailLayout::new(UVec2::splat(4096), 0.1, 3, 2048).unwrap();
    assert_eq!(l.tiles(), UVec2::splat(6));
    assert_eq!(
        (l.coarse_texel_m(), l.refine(), l.tile_size()),
        (0.1, 3, 2048)
    );
    assert_eq!(l.detail_size(), UVec2::splat(12_288));
    assert!((l.detail_texel_m() - 0.1 / 3.0).abs() < 1e-7);
    // Tile (1, 0) holds detail texels 2048 .. 4096 along X, over coarse texels 682 .. 1366.
    assert_eq!(
        l.tile_rect(UVec2::new(1, 0)),
        Some(Rect::from_min_max(
            IVec2::new(2048, 0),
            IVec2::new(4096, 2048)
        ))
    );
    assert_eq!(
        l.coarse_texels_of_tile(UVec2::new(1, 0)),
        Some(Rect::from_min_max(
            IVec2::new(682, 0),
            IVec2::new(1366, 683)
        ))
    );
    assert_eq!(l.tile_rect(UVec2::new(6, 0)), None);
    // A map that is not a whole number of tiles: the last tile is cut at the map's edge.
    let odd = DetailLayout::new(UVec2::new(100, 10), 1.0, 3, 64).unwrap();
    assert_eq!(odd.tiles(), UVec2::new(5, 1));
    assert_eq!(
        odd.tile_rect(UVec2::new(4, 0)),
        Some(Rect::from_min_max(IVec2::new(256, 0), IVec2::new(300, 30)))
    );
    // Any coordinates wrap onto the map, as the coarse-map does.
    assert_eq!(
        l.locate(IVec2::new(-1, 12_288 + 5)),
        (UVec2::new(5, 0), UVec2::new(2047, 5))
    );
}

#[test]
fn stamps_over_tile_corners_equal_the_same_stamps_on_one_large_map() {
    let l = layout();
    let ts = l.detail_texel_m();
    let mut layer = DetailLayer::new(l).unwrap();
    let mut map = big(&l, WrapMode::Clamp);
    // Centres on the corner of four tiles (texel 64, 64), on a tile edge, and inside a tile;
    // rotated and stretched; every blend; repeated so later stamps land on earlier ones.
    let corner = Vec2::splat(64.0 * ts);
    let cases: [(Vec2, Vec2, f32, f32, Blend); 6] = [
        (corner, Vec2::new(1.4, 0.9), 0.3, -0.2, Blend::Add),
        (
            corner + Vec2::new(0.37, -0.11),
            Vec2::new(2.0, 1.1),
            1.1,
            0.15,
            Blend::Add,
        ),
        (
            Vec2::new(96.0 * ts, 40.0 * ts),
            Vec2::new(0.8, 2.5),
            -0.4,
            -0.3,
            Blend::Add,
        ),
        (
            corner,
            Vec2::splat(1.7),
            0.0,
            -0.25,
            Blend::Min { base_m: 0.1 },
        ),
        (
            corner,
            Vec2::new(1.2, 2.2),
            2.0,
            0.3,
            Blend::Max { base_m: -0.2 },
        ),
        (
            Vec2::new(140.0 * ts, 150.0 * ts),
            Vec2::splat(1.5),
            0.7,
            0.05,
            Blend::Add,
        ),
    ];
    for (k, (c, scale, rot, intensity, blend)) in cases.into_iter().enumerate() {
        let p = StampPlacement::new(c, scale, intensity)
            .unwrap()
            .with_rotation(rot)
            .unwrap();
        for gaussian in [true, false] {
            let mk = || stamp(gaussian);
            let change = layer.apply_stamp(mk().as_mut(), &p, blend).unwrap();
            apply_stamp(&mut map, mk().as_mut(), &p, blend).unwrap();
            assert!(change.changed_texels > 0, "case {k}");
            // Each tile's rect is the part of the footprint it holds, in tile coordinates.
            let fp = p.footprint(ts).unwrap();
            for (t, r) in &change.tiles {
                let tr = l.tile_rect(*t).unwrap();
                let want = fp.intersect(&tr).unwrap();
                assert_eq!(
                    *r,
                    Rect::new(want.min - tr.min, want.size),
                    "case {k} tile {t}"
                );
            }
            assert_same(&layer, &map, &format!("case {k}, gaussian {gaussian}"));
            if k == 0 {
                let tiles: Vec<UVec2> = change.tiles.iter().map(|t| t.0).collect();
                assert_eq!(
                    tiles,
                    [
                        UVec2::new(1, 1),
                        UVec2::new(2, 1),
                        UVec2::new(1, 2),
                        UVec2::new(2, 2)
                    ]
                );
            }
        }
    }
    // Only the tiles the stamps reached hold texels; the rest are the shared zero tile.
    let reached = (0..6)
        .flat_map(|y| (0..6).map(move |x| UVec2::new(x, y)))
        .filter(|&t| layer.tile(t).is_some())
        .count();
    assert_eq!(reached, layer.resident_tiles());
    assert!(layer.resident_tiles() < 36);
    assert!(layer.tile(UVec2::new(0, 5)).is_none());
}

#[test]
fn stamps_across_the_maps_wrap_equal_the_same_stamps_on_a_repeating_map() {
    let l = layout();
    let ts = l.detail_texel_m();
    let mut layer = DetailLayer::new(l).unwrap();
    let mut map = big(&l, WrapMode::Repeat);
    // At the map's corner: the footprint covers the four corner tiles, across the wrap.
    // Unrotated Gaussians are evaluated position-independently, textures per texel.
    for (c, intensity) in [
        (Vec2::ZERO, -0.2f32),
        (Vec2::new(191.5 * ts, 3.0 * ts), 0.1),
    ] {
        let p = StampPlacement::new(c, Vec2::new(1.3, 0.9), intensity).unwrap();
        for gaussian in [true, false] {
            let mk = || stamp(gaussian);
            let change = layer.apply_stamp(mk().as_mut(), &p, Blend::Add).unwrap();
            apply_stamp(&mut map, mk().as_mut(), &p, Blend::Add).unwrap();
            assert!(change.tiles.len() >= 2, "{change:?}");
            assert_same(&layer, &map, &format!("at {c}, gaussian {gaussian}"));
        }
    }
    assert!(layer.tile(UVec2::new(5, 5)).is_some() && layer.tile(UVec2::new(0, 0)).is_some());
}

#[test]
fn a_stamp_that_changes_nothing_leaves_the_zero_tiles_shared() {
    let mut layer = DetailLayer::new(layout()).unwrap();
    // 1 micrometre: rounds to no stored unit anywhere.
    let p = StampPlacement::new(Vec2::splat(6.4), Vec2::splat(1.0), 1e-6).unwrap();
    let change = layer
        .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
        .unwrap();
    assert_eq!(change.changed_texels, 0);
    assert_eq!(change.tiles.len(), 4);
    assert_eq!(layer.resident_tiles(), 0);
    assert!(layer.tile_ids().as_slice().iter().all(|&id| id == 0));
    // A never-touched tile reads as 0 m everywhere.
    let zero = layer.tile_map(UVec2::new(3, 3)).unwrap();
    assert!(zero.grid().as_slice().iter().all(|&v| v == DETAIL_ZERO_RAW));
    assert_eq!(layer.height_m(Vec2::new(1.0, 2.0)), 0.0);
    assert_eq!(detail_encoding().to_metres(f64::from(DETAIL_ZERO_RAW)), 0.0);
}

#[test]
fn heights_are_bilinear_across_tile_edges_and_the_wrap() {
    let l = layout();
    let ts = l.detail_texel_m();
    let mut layer = DetailLayer::new(l).unwrap();
    // Texel 31 of tile 0 and texel 0 of tile 1 (x = 31, 32), and the wrap (x = 191, 0).
    let mut a = Grid::new(32, 32, DETAIL_ZERO_RAW).unwrap();
    *a.get_mut(31, 4).unwrap() = 128 + 51; // +0.2 m
    layer.set_tile(UVec2::new(0, 0), a.clone()).unwrap();
    let mut b = Grid::new(32, 32, DETAIL_ZERO_RAW).unwrap();
    *b.get_mut(0, 4).unwrap() = 128 - 51; // -0.2 m
    layer.set_tile(UVec2::new(1, 0), b).unwrap();
    let h = layer.height_m(Vec2::new(31.5 * ts, 4.0 * ts));
    assert!(h.abs() < 1e-6, "{h}");
    let h = layer.height_m(Vec2::new(31.25 * ts, 4.0 * ts));
    assert!((h - 0.1).abs() < 1e-5, "{h}");
    // Between rows 3 and 4: a quarter of the way down to +0.2 m is +0.05 m.
    let h = layer.height_m(Vec2::new(31.0 * ts, 3.25 * ts));
    assert!((h - 0.05).abs() < 1e-5, "{h}");
    layer.set_tile(UVec2::new(5, 0), a).unwrap();
    // Texel 191 (+0.2 m) is texel 31 of tile 5, next to texel 0 of tile 0 (0 m) across the
    // wrap: x = -1 is texel 191, x = -0.5 halfway to texel 0.
    let h = layer.height_m(Vec2::new(-ts, 4.0 * ts));
    assert!((h - 0.2).abs() < 1e-5, "{h}");
    let h = layer.height_m(Vec2::new(-0.5 * ts, 4.0 * ts));
    assert!((h - 0.1).abs() < 1e-5, "{h}");
    // Far and non-finite positions answer, in bounded time.
    assert!(layer.height_m(Vec2::splat(1e30)).is_finite());
    assert_eq!(layer.height_m(Vec2::new(f32::NAN, 0.0)), 0.0);
    assert_eq!(layer.height_m(Vec2::new(f32::INFINITY, 0.0)), 0.0);
}

#[test]
fn clearing_a_tile_frees_it_and_keeps_the_others() {
    let mut layer = DetailLayer::new(layout()).unwrap();
    for (k, t) in [UVec2::new(0, 0), UVec2::new(4, 1), UVec2::new(2, 5)]
        .into_iter()
        .enumerate()
    {
        layer
            .set_tile(t, Grid::new(32, 32, k as u8 * 10).unwrap())
            .unwrap();
    }
    assert_eq!(layer.resident_tiles(), 3);
    layer.clear_tile(UVec2::new(0, 0));
    layer.clear_tile(UVec2::new(3, 3)); // already the zero tile: nothing happens
    assert_eq!(layer.resident_tiles(), 2);
    assert!(layer.tile(UVec2::new(0, 0)).is_none());
    assert_eq!(layer.tile(UVec2::new(4, 1)).unwrap().get(0, 0), Some(10));
    assert_eq!(layer.tile(UVec2::new(2, 5)).unwrap().get(0, 0), Some(20));
    let mut ids: Vec<u32> = layer
        .tile_ids()
        .as_slice()
        .iter()
        .copied()
        .filter(|&i| i > 0)
        .collect();
    ids.sort_unstable();
    assert_eq!(ids, [1, 2]);
}

#[test]
fn bad_layouts_tiles_and_stamps_are_refused_and_change_nothing() {
    assert!(matches!(
        DetailLayout::new(UVec2::new(0, 5), 0.1, 3, 32),
        Err(CoreError::EmptyGrid { .. })
    ));
    for ts in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert!(
            DetailLayout::new(UVec2::splat(8), ts, 3, 32).is_err(),
            "{ts}"
        );
    }
    for refine in [0, 17, u32::MAX] {
        assert!(matches!(
            DetailLayout::new(UVec2::splat(8), 0.1, refine, 32),
            Err(CoreError::OutOfRange { what, .. }) if what.contains("refinement")
        ));
    }
    for tile in [0, 16_385, u32::MAX] {
        assert!(
            DetailLayout::new(UVec2::splat(8), 0.1, 3, tile).is_err(),
            "{tile}"
        );
    }
    // 2^32 - 1 coarse texels a side refined x16 in tiles of 1: far too many tiles.
    assert!(matches!(
        DetailLayout::new(UVec2::splat(u32::MAX), 0.1, 16, 1),
        Err(CoreError::OutOfRange {
            what: "detail tiles per side",
            ..
        })
    ));

    let mut layer = DetailLayer::new(layout()).unwrap();
    let p = StampPlacement::new(Vec2::splat(6.4), Vec2::splat(1.0), -0.1).unwrap();
    layer
        .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
        .unwrap();
    let before = layer.clone();
    // Wider than the layer, a NaN base, a tile of the wrong size or off the grid.
    let wide = StampPlacement::new(Vec2::splat(6.4), Vec2::splat(100.0), -0.1).unwrap();
    assert!(
        layer
            .apply_stamp(&mut GaussianStamp::default(), &wide, Blend::Add)
            .is_err()
    );
    let nan_base = Blend::Min { base_m: f32::NAN };
    assert!(
        layer
            .apply_stamp(&mut GaussianStamp::default(), &p, nan_base)
            .is_err()
    );
    assert!(matches!(
        layer.set_tile(UVec2::ZERO, Grid::new(31, 32, 0).unwrap()),
        Err(CoreError::SizeMismatch { .. })
    ));
    assert!(
        layer
            .set_tile(UVec2::new(6, 0), Grid::new(32, 32, 0).unwrap())
            .is_err()
    );
    assert_eq!(layer, before);
    assert!(layer.tile_map(UVec2::new(0, 6)).is_none());
    // A mark narrower than a texel between texel centres, and absurd centres: nothing lands,
    // nothing fails, but a NaN base is still refused.
    let ts = layer.layout().detail_texel_m();
    for c in [
        Vec2::splat(10.5 * ts),
        Vec2::splat(1e30),
        Vec2::new(-1e30, 3.0),
    ] {
        let p = StampPlacement::new(c, Vec2::splat(0.2 * ts), -0.1).unwrap();
        let change = layer.apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add);
        assert_eq!(change.unwrap(), Default::default(), "at {c}");
        assert!(
            layer
                .apply_stamp(&mut GaussianStamp::default(), &p, nan_base)
                .is_err()
        );
    }
    assert_eq!(layer, before);
}

/// The band of tiles around a point against a brute force over every detail texel: a tile is
/// in it when one of its texels lies within the radius along both axes (on the wrapped plane).
#[test]
fn the_tiles_within_a_band_are_those_holding_its_texels() {
    // 0.25 m detail texels (exact), 50 x 36 of them in tiles of 8: a partial last tile on
    // both axes.
    let l = DetailLayout::new(UVec2::new(25, 18), 0.5, 2, 8).unwrap();
    let d = l.detail_size().as_ivec2();
    let ts = l.detail_texel_m();
    for (c, r) in [
        (Vec2::new(3.1, 2.2), 0.9),
        (Vec2::new(0.1, 0.1), 1.3),
        (Vec2::new(-30.0, 100.7), 2.0),
        (Vec2::new(12.4, 8.9), 0.0),
        (Vec2::new(6.0, 4.0), 5.9),
        (Vec2::new(6.0, 4.0), 1e9),
    ] {
        let got = l.tiles_within(c, r).unwrap();
        // In f64, as the layer computes the band's ends (the f32 sum may round up onto an edge).
        let ends = |c: f32| {
            let (c, r, ts) = (f64::from(c), f64::from(r), f64::from(ts));
            (((c - r) / ts).floor(), ((c + r) / ts).floor())
        };
        let mut want = std::collections::BTreeSet::new();
        let span = |(a, b): (f64, f64), n: i32| -> Vec<i32> {
            if b - a + 1.0 >= f64::from(n) {
                (0..n).collect()
            } else {
                (a as i64..=b as i64)
                    .map(|v| v.rem_euclid(i64::from(n)) as i32)
                    .collect()
            }
        };
        for y in span(ends(c.y), d.y) {
            for x in span(ends(c.x), d.x) {
                let (tile, _) = l.locate(IVec2::new(x, y));
                want.insert((tile.y, tile.x));
            }
        }
        let want: Vec<UVec2> = want.into_iter().map(|(y, x)| UVec2::new(x, y)).collect();
        assert_eq!(got, want, "centre {c} radius {r}");
    }
    assert!(l.tiles_within(Vec2::new(f32::NAN, 0.0), 1.0).is_err());
    assert!(l.tiles_within(Vec2::ZERO, -1.0).is_err());
    assert!(l.tiles_within(Vec2::ZERO, f32::INFINITY).is_err());
}

/// The tiles under a stamp are those its stamp writes (the dirty tiles a CPU stamp reports),
/// across the wrap.
#[test]
fn the_tiles_under_a_stamp_are_those_it_writes() {
    let l = DetailLayout::new(UVec2::new(25, 18), 0.5, 2, 8).unwrap();
    for (centre, size) in [
        (Vec2::new(3.1, 2.2), Vec2::splat(0.9)),
        (Vec2::new(0.1, 0.1), Vec2::new(2.0, 1.0)),
        (Vec2::new(12.4, 8.9), Vec2::splat(4.0)),
    ] {
        let p = StampPlacement::new(centre, size, -0.1).unwrap();
        let mut layer = DetailLayer::new(l).unwrap();
        let mut stamp = GaussianStamp::default();
        let change = layer.apply_stamp(&mut stamp, &p, Blend::Add).unwrap();
        let written: Vec<UVec2> = change.tiles.iter().map(|(t, _)| *t).collect();
        assert_eq!(l.tiles_under(&p).unwrap(), written, "{centre} {size}");
    }
}

/// A large mark over tiny tiles would be cut into millions of pieces: refused up front, the
/// layer untouched; the same mark over larger tiles is taken.
#[test]
fn a_footprint_over_too_many_tiles_is_refused_before_any_work() {
    let tiny = DetailLayout::new(UVec2::splat(4096), 0.1, 1, 1).unwrap();
    let mut layer = DetailLayer::new(tiny).unwrap();
    let p = StampPlacement::new(Vec2::splat(100.0), Vec2::splat(51.2), -0.1).unwrap();
    let err = layer
        .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
        .unwrap_err();
    assert!(matches!(err, CoreError::OutOfRange { .. }), "{err}");
    assert_eq!(layer.resident_tiles(), 0);
    let larger = DetailLayout::new(UVec2::splat(4096), 0.1, 1, 64).unwrap();
    let mut layer = DetailLayer::new(larger).unwrap();
    let change = layer
        .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
        .unwrap();
    assert!(change.tiles.len() >= 64, "{}", change.tiles.len());
}

#[test]
fn box_may_touch_is_exact_for_narrow_boxes_on_whole_tiles_and_never_misses() {
    // 24 x 20 coarse texels x3 = 72 x 60 detail texels: 12-texel tiles are whole, 16 are not.
    for (tile, whole) in [(12, true), (16, false)] {
        let l = DetailLayout::new(UVec2::new(24, 20), 0.5, 3, tile).unwrap();
        let has = |t: UVec2| (t.x * 7 + t.y * 3).is_multiple_of(5);
        for i in 0..400i32 {
            let lo = IVec2::new(i * 37 % 300 - 150, i * 53 % 260 - 130);
            let size = IVec2::new(i % 17, (i / 3) % 19);
            let hi = lo + size;
            let brute =
                (lo.y..=hi.y).any(|y| (lo.x..=hi.x).any(|x| has(l.locate(IVec2::new(x, y)).0)));
            let got = l.box_may_touch(lo, hi, has);
            assert!(
                got || !brute,
                "tile {tile} box {lo} {hi}: a touched tile missed"
            );
            if whole && size.max_element() < tile as i32 {
                assert_eq!(got, brute, "tile {tile} box {lo} {hi}");
            } else if !whole {
                assert!(got, "layers of partial tiles never skip");
            }
        }
    }
}
