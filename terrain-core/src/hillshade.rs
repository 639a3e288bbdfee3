//! Top-down hillshade images of a map, lit with its partial-derivative normals and coloured by
//! height: the demo's overview map.

use crate::error::CoreError;
use crate::grid::Grid;
use crate::map::{HeightMap, HeightSample};
use crate::normals::DerivativeMap;
use glam::{UVec2, Vec3};

/// Lighting and colouring of a hillshade.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HillshadeParams {
    /// Direction towards the light (normalised on use); default from the north-west, 45° up.
    pub light_dir: Vec3,
    /// Share of light that reaches every texel regardless of its normal, in `[0, 1]`.
    pub ambient: f32,
    /// Output size in pixels; each pixel shows the nearest texel.
    pub size: UVec2,
}

impl HillshadeParams {
    /// Defaults for an image of `size` pixels.
    pub fn with_size(size: UVec2) -> Self {
        Self {
            light_dir: Vec3::new(-1.0, 1.4, -1.0),
            ambient: 0.25,
            size,
        }
    }
}

/// Height colour ramp from low to high: valley green, grass, rock, snow.
const RAMP: [[f32; 3]; 4] = [
    [0.20, 0.36, 0.18],
    [0.45, 0.55, 0.25],
    [0.55, 0.45, 0.35],
    [0.95, 0.95, 0.97],
];

fn ramp(t: f32) -> Vec3 {
    let t = t.clamp(0.0, 1.0) * (RAMP.len() - 1) as f32;
    let i = (t.floor() as usize).min(RAMP.len() - 2);
    let f = t - i as f32;
    Vec3::from(RAMP[i]).lerp(Vec3::from(RAMP[i + 1]), f)
}

/// Renders `map` as an RGBA8 hillshade of `params.size` pixels, colouring heights between the
/// map's lowest and highest stored values.
pub fn hillshade<T: HeightSample>(
    map: &HeightMap<T>,
    normals: &DerivativeMap,
    params: &HillshadeParams,
) -> Result<Grid<[u8; 4]>, CoreError> {
    if normals.grid().size() != map.size() {
        return Err(CoreError::SizeMismatch {
            expected: map.size(),
            actual: normals.grid().size(),
        });
    }
    if !params.light_dir.is_finite() || params.light_dir.length_squared() == 0.0 {
        return Err(CoreError::OutOfRange {
            what: "hillshade light direction length",
            value: f64::from(params.light_dir.length()),
            expected: "a finite, non-zero vector",
        });
    }
    if !(0.0..=1.0).contains(&params.ambient) {
        return Err(CoreError::OutOfRange {
            what: "hillshade ambient",
            value: f64::from(params.ambient),
            expected: "in [0, 1]",
        });
    }
    let light = params.light_dir.normalize();
    let raw = map.grid().as_slice();
    let (lo, hi) = raw.iter().fold((f64::MAX, f64::MIN), |(lo, hi), v| {
        let v = v.to_raw_f64();
        (lo.min(v), hi.max(v))
    });
    let span = (hi - lo).max(1.0);
    let size = map.size();
    Grid::from_fn(params.size.x, params.size.y, |px, py| {
        let x = ((u64::from(px) * u64::from(size.x)) / u64::from(params.size.x)) as u32;
        let y = ((u64::from(py) * u64::from(size.y)) / u64::from(params.size.y)) as u32;
        let i = map.grid().index(x, y);
        let t = ((raw[i].to_raw_f64() - lo) / span) as f32;
        let n = normals.normal(x, y).unwrap_or(Vec3::Y);
        let shade = params.ambient + (1.0 - params.ambient) * n.dot(light).max(0.0);
        let c = (ramp(t) * shade * 1.25).clamp(Vec3::ZERO, Vec3::ONE) * 255.0;
        [c.x as u8, c.y as u8, c.z as u8, 255]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{CoarseMap, HeightEncoding};

    #[test]
    fn slopes_facing_the_light_are_brighter() {
        // A ridge along Z: the west slope (facing the default light) is lit, the east one not.
        let g = Grid::from_fn(64, 64, |x, _| (2000 - 60 * (x as i32 - 32).abs()) as u16).unwrap();
        let m = CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).unwrap(), 1.0).unwrap();
        let n = DerivativeMap::from_map(&m);
        let img = hillshade(&m, &n, &HillshadeParams::with_size(UVec2::new(64, 64))).unwrap();
        let west = img.get(20, 32).unwrap();
        let east = img.get(44, 32).unwrap();
        let lum = |p: [u8; 4]| u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]);
        assert!(lum(west) > lum(east) + 30, "west {west:?} east {east:?}");
        let bad = HillshadeParams {
            light_dir: Vec3::ZERO,
            ..HillshadeParams::with_size(UVec2::new(8, 8))
        };
        assert!(hillshade(&m, &n, &bad).is_err());
    }
}
