//! Top-down hillshade images of a map, lit with its partial-derivative normals and coloured by
//! height, or by the autoshader's materials as the renderers place them: the demo's overview
//! map, and its frames without a GPU.

use crate::error::CoreError;
use crate::grid::Grid;
use crate::map::{HeightMap, HeightSample};
use crate::material::{AutoshadeParams, MATERIALS, MaterialTextures, autoshade_weights};
use crate::normals::{DerivativeMap, derivative_at, derivative_region, normal_from_derivatives};
use crate::rect::Rect;
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
    /// Colour by the autoshader's materials instead of the height ramp.
    pub materials: Option<HillshadeMaterials>,
}

/// What a materials hillshade colours with: the autoshader's weights (from the height within
/// the colour range, the slope and the curvature, as the renderers' `surface_weights`) blending
/// each material's colour from afar.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HillshadeMaterials {
    /// Where each material goes.
    pub autoshade: AutoshadeParams,
    /// Each material's colour (grass, dirt, rock, snow; sRGB over 0..=1): the mean of its
    /// albedo image ([`MaterialTextures::mean_albedo`]).
    pub albedo: [Vec3; MATERIALS],
}

impl HillshadeMaterials {
    /// The colours of `textures` (four layers), placed by `autoshade`.
    pub fn new(textures: &MaterialTextures, autoshade: AutoshadeParams) -> Result<Self, CoreError> {
        let mut albedo = [Vec3::ZERO; MATERIALS];
        for (m, a) in albedo.iter_mut().enumerate() {
            *a = textures.mean_albedo(m).ok_or(CoreError::OutOfRange {
                what: "material layers",
                value: textures.layers().len() as f64,
                expected: "four (grass, dirt, rock, snow)",
            })?;
        }
        Ok(Self { autoshade, albedo })
    }
}

impl HillshadeParams {
    /// Defaults for an image of `size` pixels.
    pub fn with_size(size: UVec2) -> Self {
        Self {
            light_dir: Vec3::new(-1.0, 1.4, -1.0),
            ambient: 0.25,
            size,
            materials: None,
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
/// map's lowest and highest stored values ([`hillshade_range`]).
pub fn hillshade<T: HeightSample>(
    map: &HeightMap<T>,
    normals: &DerivativeMap,
    params: &HillshadeParams,
) -> Result<Grid<[u8; 4]>, CoreError> {
    let range = hillshade_range(map);
    let shader = Shader::new(map, Some(normals), params, range)?;
    Grid::from_fn(params.size.x, params.size.y, |px, py| shader.pixel(px, py))
}

/// [`hillshade`] without a derivative map: each pixel's normal comes from the heights around
/// its texel by the same eq. 3.3 ([`derivative_at`]), so the image is the same, and its cost
/// follows the pixels, not the map (a 256-pixel overview of a 4096^2 map reads 1/256 of it).
/// What a caller uses whose normals live on the GPU.
pub fn hillshade_from_heights<T: HeightSample>(
    map: &HeightMap<T>,
    params: &HillshadeParams,
) -> Result<Grid<[u8; 4]>, CoreError> {
    let range = hillshade_range(map);
    let shader = Shader::new(map, None, params, range)?;
    Grid::from_fn(params.size.x, params.size.y, |px, py| shader.pixel(px, py))
}

/// The stored values a [`hillshade`] colours between: the map's lowest and highest.
pub fn hillshade_range<T: HeightSample>(map: &HeightMap<T>) -> (f64, f64) {
    map.grid()
        .as_slice()
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), v| {
            let v = v.to_raw_f64();
            (lo.min(v), hi.max(v))
        })
}

/// Redraws the pixels of `image`, a hillshade of `map` at `params.size`, that a change of the
/// heights inside `dirty` can affect (their normals included, so `dirty` grown by
/// [`DERIVATIVE_APRON`](crate::DERIVATIVE_APRON), wrapped as [`derivative_region`] does),
/// colouring heights between the stored values `range` (clamped outside it). `normals` must be
/// current over that region ([`DerivativeMap::update_rect`] with the same `dirty`).
///
/// Costs the pixels redrawn, not the map: with `range` kept from the first image
/// ([`hillshade_range`]) an overview follows deformations frame by frame. With the range of the
/// new map, the result equals a new [`hillshade`].
///
/// Fails as [`hillshade`] does, on an `image` not of `params.size`, on a `range` that is not
/// finite and ordered, or on a `dirty` rect outside a clamped map.
pub fn update_hillshade<T: HeightSample>(
    image: &mut Grid<[u8; 4]>,
    map: &HeightMap<T>,
    normals: &DerivativeMap,
    params: &HillshadeParams,
    range: (f64, f64),
    dirty: Rect,
) -> Result<(), CoreError> {
    let shader = Shader::new(map, Some(normals), params, range)?;
    redraw(image, &shader, dirty)
}

/// [`update_hillshade`] without a derivative map, as [`hillshade_from_heights`] draws: the
/// same pixels redrawn, their normals from the heights around them.
pub fn update_hillshade_from_heights<T: HeightSample>(
    image: &mut Grid<[u8; 4]>,
    map: &HeightMap<T>,
    params: &HillshadeParams,
    range: (f64, f64),
    dirty: Rect,
) -> Result<(), CoreError> {
    let shader = Shader::new(map, None, params, range)?;
    redraw(image, &shader, dirty)
}

/// Redraws the pixels of `image` that heights changed inside `dirty` can affect.
fn redraw<T: HeightSample>(
    image: &mut Grid<[u8; 4]>,
    shader: &Shader<'_, T>,
    dirty: Rect,
) -> Result<(), CoreError> {
    let (map, params) = (shader.map, shader.out);
    if image.size() != params {
        return Err(CoreError::SizeMismatch {
            expected: params,
            actual: image.size(),
        });
    }
    let Some(region) = derivative_region(map.size(), map.wrap(), dirty)? else {
        return Ok(());
    };
    let size = map.size();
    // Pixel `p` shows texel `p * size / out`, so texels `t0..t1` are shown by pixels
    // `ceil(t0 * out / size)..ceil(t1 * out / size)`.
    let pixels = |t0: i32, t1: i32, out: u32, n: u32| {
        let at = |t: i32| (u64::from(t as u32) * u64::from(out)).div_ceil(u64::from(n)) as u32;
        at(t0)..at(t1)
    };
    for piece in region.split_toroidal(size) {
        let (lo, hi) = (piece.map.min, piece.map.max());
        for py in pixels(lo.y, hi.y, params.y, size.y) {
            let row = image.row_mut(py);
            for px in pixels(lo.x, hi.x, params.x, size.x) {
                row[px as usize] = shader.pixel(px, py);
            }
        }
    }
    Ok(())
}

/// One hillshade's checked inputs: shades pixel by pixel.
struct Shader<'a, T> {
    map: &'a HeightMap<T>,
    /// `None`: each pixel's normal from the heights around its texel.
    normals: Option<&'a DerivativeMap>,
    light: Vec3,
    ambient: f32,
    out: UVec2,
    lo: f64,
    span: f64,
    materials: Option<HillshadeMaterials>,
}

impl<'a, T: HeightSample> Shader<'a, T> {
    fn new(
        map: &'a HeightMap<T>,
        normals: Option<&'a DerivativeMap>,
        params: &HillshadeParams,
        range: (f64, f64),
    ) -> Result<Self, CoreError> {
        if let Some(normals) = normals
            && normals.grid().size() != map.size()
        {
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
        let (lo, hi) = range;
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(CoreError::OutOfRange {
                what: "hillshade colour range (its low end)",
                value: lo,
                expected: "finite, and at most the high end",
            });
        }
        Ok(Self {
            map,
            normals,
            light: params.light_dir.normalize(),
            ambient: params.ambient,
            out: params.size,
            lo,
            span: (hi - lo).max(1.0),
            materials: params.materials,
        })
    }

    /// The colour of pixel `(px, py)`, which shows the nearest texel.
    fn pixel(&self, px: u32, py: u32) -> [u8; 4] {
        let size = self.map.size();
        let x = ((u64::from(px) * u64::from(size.x)) / u64::from(self.out.x)) as u32;
        let y = ((u64::from(py) * u64::from(size.y)) / u64::from(self.out.y)) as u32;
        let raw = self.map.grid().as_slice()[self.map.grid().index(x, y)].to_raw_f64();
        let t = ((raw - self.lo) / self.span) as f32;
        let d = match self.normals {
            Some(normals) => normals.derivative(x, y),
            None => derivative_at(self.map, x, y),
        };
        let n = d.map_or(Vec3::Y, normal_from_derivatives);
        let shade = self.ambient + (1.0 - self.ambient) * n.dot(self.light).max(0.0);
        let colour = match &self.materials {
            None => ramp(t),
            Some(m) => {
                let slope = d.map_or(0.0, |d| d.length());
                let w = autoshade_weights(&m.autoshade, t, slope, self.curvature(x, y));
                let sum = w.x + w.y + w.z + w.w;
                let mix = m.albedo[0] * w.x + m.albedo[1] * w.y + m.albedo[2] * w.z;
                (mix + m.albedo[3] * w.w) / sum.max(1e-6)
            }
        };
        let c = (colour * shade * 1.25).clamp(Vec3::ZERO, Vec3::ONE) * 255.0;
        [c.x as u8, c.y as u8, c.z as u8, 255]
    }

    /// The curvature (1/m) at texel `(x, y)` from its four neighbours one texel away (wrapped
    /// or clamped like the map), as the renderers' autoshader measures it at that spacing.
    fn curvature(&self, x: u32, y: u32) -> f32 {
        let (map, wrap) = (self.map, self.map.wrap());
        let h = |dx: i32, dy: i32| {
            let p = glam::IVec2::new(x as i32 + dx, y as i32 + dy);
            map.encoding()
                .to_metres(map.grid().get_wrapped(p, wrap).to_raw_f64())
        };
        crate::material::curvature_from_heights(
            h(0, 0),
            [h(-1, 0), h(1, 0), h(0, -1), h(0, 1)],
            map.texel_size(),
        )
    }
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
        // A ridge along X: the north slope (towards -Z, facing the light) is lit, the south
        // one not.
        let g = Grid::from_fn(64, 64, |_, y| (2000 - 60 * (y as i32 - 32).abs()) as u16).unwrap();
        let m2 = CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).unwrap(), 1.0).unwrap();
        let n2 = DerivativeMap::from_map(&m2);
        let img = hillshade(&m2, &n2, &HillshadeParams::with_size(UVec2::new(64, 64))).unwrap();
        let (north, south) = (img.get(32, 20).unwrap(), img.get(32, 44).unwrap());
        assert!(
            lum(north) > lum(south) + 30,
            "north {north:?} south {south:?}"
        );
        let bad = HillshadeParams {
            light_dir: Vec3::ZERO,
            ..HillshadeParams::with_size(UVec2::new(8, 8))
        };
        assert!(hillshade(&m, &n, &bad).is_err());
    }

    /// Flat ground (lit by the ambient share plus the light's height) in the ramp's
    /// colours: the lowest stored value valley green, the middle halfway between grass and
    /// rock, the highest snow.
    #[test]
    fn heights_are_coloured_along_the_ramp() {
        let g = Grid::from_fn(24, 8, |x, _| [1000u16, 1500, 2000][x as usize / 8]).unwrap();
        let m = CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).unwrap(), 1.0).unwrap();
        let n = DerivativeMap::from_map(&m);
        let params = HillshadeParams::with_size(UVec2::new(24, 8));
        let img = hillshade(&m, &n, &params).unwrap();
        let light = params.light_dir.normalize();
        let shade = params.ambient + (1.0 - params.ambient) * light.y;
        for (x, colour) in [
            (4, Vec3::from(RAMP[0])),
            (12, Vec3::from(RAMP[1]).lerp(Vec3::from(RAMP[2]), 0.5)),
            (20, Vec3::from(RAMP[3])),
        ] {
            let c = (colour * shade * 1.25).clamp(Vec3::ZERO, Vec3::ONE) * 255.0;
            let want = [c.x as u8, c.y as u8, c.z as u8, 255];
            assert_eq!(img.get(x, 4).unwrap(), want, "column {x}");
        }
    }

    /// With materials, flat low ground is grass, a steep slope rock and flat high ground
    /// snow, in the materials' colours; a crater's rim, curved, shows dirt.
    #[test]
    fn materials_colour_the_ground_as_the_autoshader_places_them() {
        // Low flat (x < 16) with a trench 0.5 m deep at x = 8, a cliff rising 20 m over 8
        // texels (slope 2.5), high flat (x > 24).
        let enc = HeightEncoding::new(0.01, 0.0).unwrap();
        let g = Grid::from_fn(40, 8, |x, _| {
            let f = ((x as f32 - 16.0) / 8.0).clamp(0.0, 1.0);
            let trench = if x == 8 { 0.5 } else { 0.0 };
            enc.to_raw(5.0 + 20.0 * f - trench).round() as u16
        })
        .unwrap();
        let m = CoarseMap::new(g, enc, 1.0, crate::WrapMode::Clamp).unwrap();
        let albedo = [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 1.0, 0.0),
        ];
        let params = HillshadeParams {
            materials: Some(HillshadeMaterials {
                autoshade: AutoshadeParams::default(),
                albedo,
            }),
            ..HillshadeParams::with_size(UVec2::new(40, 8))
        };
        let img = hillshade_from_heights(&m, &params).unwrap();
        let hue = |p: [u8; 4]| {
            let (r, g, b) = (p[0] as i32, p[1] as i32, p[2] as i32);
            match () {
                _ if r > 3 * (g + b + 1) => "grass",
                _ if b > 3 * (r + g + 1) => "rock",
                _ if r > 3 * (b + 1) && g > 3 * (b + 1) => "snow",
                _ if g > 3 * (r + b + 1) => "dirt",
                _ => "mixed",
            }
        };
        assert_eq!(hue(img.get(6, 4).unwrap()), "grass");
        assert_eq!(hue(img.get(20, 4).unwrap()), "rock");
        assert_eq!(hue(img.get(34, 4).unwrap()), "snow");
        // The trench bends the ground (curvature 1 /m) without steepening it: dirt.
        assert_eq!(hue(img.get(8, 4).unwrap()), "dirt");
        // Four layers are needed.
        let bad = MaterialTextures::new(16, Vec::new());
        assert!(
            bad.is_err()
                || HillshadeMaterials::new(&bad.unwrap(), AutoshadeParams::default()).is_err()
        );
        let procedural = MaterialTextures::procedural(16).unwrap();
        assert!(HillshadeMaterials::new(&procedural, AutoshadeParams::default()).is_ok());
    }

    #[test]
    fn updating_the_dirty_pixels_matches_a_new_hillshade() {
        use crate::{Blend, GaussianStamp, StampPlacement, apply_stamp};
        let g = Grid::from_fn(48, 40, |x, y| (1000 + 37 * x + 23 * y) as u16).unwrap();
        let enc = HeightEncoding::new(0.01, 0.0).unwrap();
        // Outputs smaller, larger and neither than the map.
        for out in [UVec2::new(20, 17), UVec2::new(96, 80), UVec2::new(33, 61)] {
            let mut m = CoarseMap::coarse(g.clone(), enc, 1.0).unwrap();
            let mut n = DerivativeMap::from_map(&m);
            let params = HillshadeParams::with_size(out);
            // A crater across the wrap corner, then a mound inside.
            let stamps = [
                (glam::Vec2::new(1.0, 2.0), -3.0),
                (glam::Vec2::new(30.0, 20.0), 4.0),
            ];
            let mut dirty = Vec::new();
            for (pos, depth) in stamps {
                let placement = StampPlacement::new(pos, glam::Vec2::splat(9.0), depth).unwrap();
                let mut crater = GaussianStamp::default();
                dirty.extend(apply_stamp(&mut m, &mut crater, &placement, Blend::Add).unwrap());
            }
            let range = hillshade_range(&m);
            // The image before the change, coloured with the final range.
            let before = CoarseMap::coarse(g.clone(), enc, 1.0).unwrap();
            let before_n = DerivativeMap::from_map(&before);
            let shader = Shader::new(&before, Some(&before_n), &params, range).unwrap();
            let mut img = Grid::from_fn(out.x, out.y, |x, y| shader.pixel(x, y)).unwrap();
            for r in &dirty {
                n.update_rect(&m, *r).unwrap();
                update_hillshade(&mut img, &m, &n, &params, range, *r).unwrap();
            }
            assert_eq!(img, hillshade(&m, &n, &params).unwrap(), "output {out}");
        }
        let m = CoarseMap::coarse(g, enc, 1.0).unwrap();
        let n = DerivativeMap::from_map(&m);
        let params = HillshadeParams::with_size(UVec2::new(8, 8));
        let mut img = hillshade(&m, &n, &params).unwrap();
        let r = Rect::from_size(UVec2::ONE);
        assert!(update_hillshade(&mut img, &m, &n, &params, (5.0, 1.0), r).is_err());
        assert!(update_hillshade(&mut img, &m, &n, &params, (f64::NAN, 1.0), r).is_err());
        let small = HillshadeParams::with_size(UVec2::new(4, 8));
        assert!(update_hillshade(&mut img, &m, &n, &small, (0.0, 1.0), r).is_err());
    }

    /// Without a derivative map the image is the same, bit for bit, on repeating and clamped
    /// maps of u16 and u8 samples (the edges read wrapped or clamped taps), and so are the
    /// redrawn pixels after a change.
    #[test]
    fn shading_from_the_heights_equals_shading_from_the_derivative_map() {
        use crate::{Blend, GaussianStamp, StampPlacement, apply_stamp};
        use crate::{DetailTile, WrapMode};
        let enc = HeightEncoding::new(0.01, 0.0).unwrap();
        let g = Grid::from_fn(37, 29, |x, y| {
            (20_000 + (x * x * 31 + y * 977 + x * y * 13) % 9_000) as u16
        })
        .unwrap();
        for wrap in [WrapMode::Repeat, WrapMode::Clamp] {
            let mut m = HeightMap::new(g.clone(), enc, 0.7, wrap).unwrap();
            for out in [UVec2::new(37, 29), UVec2::new(16, 40)] {
                let params = HillshadeParams::with_size(out);
                let n = DerivativeMap::from_map(&m);
                let want = hillshade(&m, &n, &params).unwrap();
                assert_eq!(
                    hillshade_from_heights(&m, &params).unwrap(),
                    want,
                    "{wrap:?}"
                );
            }
            // A change, redrawn both ways.
            let params = HillshadeParams::with_size(UVec2::new(30, 30));
            let range = hillshade_range(&m);
            let mut img = hillshade_from_heights(&m, &params).unwrap();
            let p = StampPlacement::new(glam::Vec2::new(12.0, 9.0), glam::Vec2::splat(6.0), 2.0)
                .unwrap();
            let mut crater = GaussianStamp::default();
            let dirty = apply_stamp(&mut m, &mut crater, &p, Blend::Add).unwrap();
            for r in &dirty {
                update_hillshade_from_heights(&mut img, &m, &params, range, *r).unwrap();
            }
            let n = DerivativeMap::from_map(&m);
            let shader = Shader::new(&m, Some(&n), &params, range).unwrap();
            let want = Grid::from_fn(30, 30, |x, y| shader.pixel(x, y)).unwrap();
            assert_eq!(img, want, "{wrap:?}");
        }
        let g8 = Grid::from_fn(20, 11, |x, y| ((x * 37 + y * 11) % 256) as u8).unwrap();
        let d = DetailTile::detail(g8, HeightEncoding::new(0.003, 0.0).unwrap(), 0.05).unwrap();
        let params = HillshadeParams::with_size(UVec2::new(20, 11));
        let want = hillshade(&d, &DerivativeMap::from_map(&d), &params).unwrap();
        assert_eq!(hillshade_from_heights(&d, &params).unwrap(), want);
    }
}
