//! Maps shared by the integration tests.
#![allow(dead_code)]

use terrain_core::{CoarseMap, Grid, HeightEncoding};

/// A rolling `size` x `size` terrain (sums of sines, periodic so the wrap edge is smooth but
/// not flat), heights 0..20 m, 0.5 m per texel.
pub fn hills(size: u32) -> CoarseMap {
    let enc = HeightEncoding::spanning::<u16>(0.0, 20.0).expect("encoding");
    let n = size as f32;
    let tau = std::f32::consts::TAU;
    let g = Grid::from_fn(size, size, |x, y| {
        let (u, v) = (x as f32 / n * tau, y as f32 / n * tau);
        let h = 10.0
            + 4.0 * (u * 2.0).sin() * (v * 3.0).cos()
            + 2.5 * (u * 5.0 + v * 2.0).sin()
            + 1.5 * ((u * 7.0).cos() * (v * 6.0).sin());
        enc.to_raw(h).round() as u16
    })
    .expect("grid");
    CoarseMap::coarse(g, enc, 0.5).expect("map")
}

/// A flat map of `size` x `size` texels at `height_m`, 0.5 m per texel, heights 0..50 m.
pub fn flat(size: u32, height_m: f32) -> CoarseMap {
    let enc = HeightEncoding::spanning::<u16>(0.0, 50.0).expect("encoding");
    let g = Grid::new(size, size, enc.to_raw(height_m).round() as u16).expect("grid");
    CoarseMap::coarse(g, enc, 0.5).expect("map")
}

/// A plane rising `slope` metres per metre along +X (exact in the encoding: 1 mm units),
/// `size` texels square at 0.5 m per texel; it has a cliff at the wrap edge, so keep away.
pub fn ramp(size: u32, slope: f32) -> CoarseMap {
    let enc = HeightEncoding::new(0.001, 0.0).expect("encoding");
    let g = Grid::from_fn(size, size, |x, _| {
        (x as f32 * 0.5 * slope * 1000.0).round() as u16
    })
    .expect("grid");
    CoarseMap::coarse(g, enc, 0.5).expect("map")
}
