//! What the renderer shades a detail layer with, against the CPU: `DetailProbe` (the detail
//! clipmap's own WGSL functions) against `DetailLayer::height_m`, `gradient_m` and eq. 3.4's
//! `composite_normal`; and the detail clipmap's frames against the coarse one's. On whatever
//! adapter the machine has (lavapipe in CI); without one they skip, or fail under
//! `TERRAIN_REQUIRE_GPU=1`.

use glam::{IVec2, UVec2, Vec2};
use terrain_core::detail::{DetailLayer, DetailLayout};
use terrain_core::{Grid, composite_normal};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{DetailProbe, DetailProbePoint, GpuDetailTiles};

/// A 24 x 20 coarse-map at 0.75 m refined x3 (0.25 m detail texels: every probe position below
/// is exact in f32 on both sides), 72 x 60 detail texels in 5 x 4 tiles of 16 (the last column
/// and row reach past the map).
fn layout() -> DetailLayout {
    DetailLayout::new(UVec2::new(24, 20), 0.75, 3, 16).unwrap()
}

/// Smooth marks of up to ±40 units around 0 m, different per tile.
fn marks(tile: UVec2) -> Grid<u8> {
    Grid::from_fn(16, 16, |x, y| {
        let (fx, fy) = ((x + 16 * tile.x) as f32, (y + 16 * tile.y) as f32);
        let v = 40.0 * (fx * 0.37 + tile.y as f32).sin() * (fy * 0.23 - tile.x as f32).cos();
        (128.0 + v).round() as u8
    })
    .unwrap()
}

#[test]
fn the_shaders_detail_height_gradient_and_composite_normal_equal_the_cpu_reference() {
    let Some(ctx) = context_or_skip("detail_probe") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let layout = layout();
    let mut layer = DetailLayer::new(layout).unwrap();
    let mut tiles = GpuDetailTiles::new(device, layout, 8).unwrap();
    // Six tiles with marks (one of them then unloaded: drawn as 0 m, as the CPU layer without
    // it), the rest the zero tile; marks meet the map's wrap at the tiles of row 0 and column 0.
    let marked = [(0, 0), (1, 0), (4, 0), (0, 3), (2, 2), (3, 1)];
    for &(x, y) in &marked {
        let t = UVec2::new(x, y);
        tiles.load(queue, t, Some(&marks(t))).unwrap();
        if (x, y) == (3, 1) {
            tiles.unload(queue, t);
        } else {
            layer.set_tile(t, marks(t)).unwrap();
        }
    }
    let mut probe = DetailProbe::new(device, 4096).unwrap();
    let coarse = layout.coarse_size().as_ivec2();
    // Bases far from the map and negative: the layer repeats.
    for base in [
        IVec2::ZERO,
        IVec2::new(7, 13),
        IVec2::new(-1_000_003, 77),
        IVec2::new(123_456, -98_765),
    ] {
        let mut points = Vec::new();
        for i in 0..1500u32 {
            // Offsets in eighths of a coarse texel over two periods of the map, both signs.
            let h = i.wrapping_mul(0x9E37_79B9) ^ (i >> 3).wrapping_mul(0x85EB_CA6B);
            let q = Vec2::new(
                ((h % 400) as f32 - 200.0) / 8.0,
                (((h >> 9) % 340) as f32 - 170.0) / 8.0,
            );
            let coarse_gradient = Vec2::new(((h >> 20) % 9) as f32 * 0.1 - 0.4, 0.3);
            points.push(DetailProbePoint { q, coarse_gradient });
        }
        let got = probe.read(device, queue, &tiles, base, &points).unwrap();
        assert_eq!(got.len(), points.len());
        let wrapped = IVec2::new(base.x.rem_euclid(coarse.x), base.y.rem_euclid(coarse.y));
        let mut nonzero = 0;
        for (p, g) in points.iter().zip(&got) {
            let pos = (wrapped.as_vec2() + p.q) * layout.coarse_texel_m();
            let h = layer.height_m(pos);
            let d = layer.gradient_m(pos);
            let n = composite_normal(p.coarse_gradient, d);
            assert!(
                (g.height - h).abs() <= 1e-5,
                "base {base} q {}: height {} vs {h}",
                p.q,
                g.height
            );
            assert!(
                (g.gradient - d).abs().max_element() <= 1e-5 * (1.0 + d.abs().max_element()),
                "base {base} q {}: gradient {} vs {d}",
                p.q,
                g.gradient
            );
            assert!(
                (g.normal - n).abs().max_element() <= 1e-5,
                "base {base} q {}: normal {} vs {n}",
                p.q,
                g.normal
            );
            nonzero += usize::from(d != Vec2::ZERO);
        }
        assert!(nonzero > 300, "the points cross the marks ({nonzero})");
    }
    // Out of range points are refused.
    let far = DetailProbePoint {
        q: Vec2::new(5000.0, 0.0),
        coarse_gradient: Vec2::ZERO,
    };
    assert!(probe.read(device, queue, &tiles, IVec2::ZERO, &[far]).is_err());
    let nan = DetailProbePoint {
        q: Vec2::new(f32::NAN, 0.0),
        coarse_gradient: Vec2::ZERO,
    };
    assert!(probe.read(device, queue, &tiles, IVec2::ZERO, &[nan]).is_err());
    ctx.check().expect("no GPU validation errors");
}
