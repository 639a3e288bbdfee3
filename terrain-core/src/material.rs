//! Surface materials: the CPU reference of the renderers' material shading.
//!
//! Four materials (grass, dirt, rock, snow) are blended per fragment by weights that sum to 1.
//! Without a material layer the weights come from the autoshader ([`autoshade_weights`]):
//! bare rock on steep slopes, snow above a height, dirt where the ground bends sharply (crater
//! walls, gullies), grass elsewhere. The slope comes from the partial-derivative normal map
//! (Flower 2010, eq. 3.3), the curvature from the heights, so a deformation that changes the
//! shape also changes what the ground shows. The renderers' WGSL (`materials.wgsl` in
//! terrain-shaders) evaluates the same formulas, operation for operation; a GPU test compares
//! the two.
//!
//! [`MaterialTextures`] holds each material's albedo and normal images (square, a power of two,
//! tileable). [`MaterialTextures::procedural`] makes the project's own set, so nothing is
//! downloaded; an engine passes its own images to [`MaterialTextures::new`].

use crate::error::CoreError;
use crate::terrain_gen::mix64;
use glam::{Vec2, Vec3, Vec4};

/// Materials a surface blends: grass, dirt, rock and snow, in the order of the weights'
/// components (x, y, z, w) and of the texture layers.
pub const MATERIALS: usize = 4;

/// Names of the materials, in layer order.
pub const MATERIAL_NAMES: [&str; MATERIALS] = ["grass", "dirt", "rock", "snow"];

/// Where the autoshader puts each material. Each pair is a smoothstep's edges, low to high.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
#[cfg_attr(feature = "schemars", derive(schemars::JsonSchema))]
pub struct AutoshadeParams {
    /// Slopes (metres per metre) over which bare rock replaces the cover: none below the first,
    /// all from the second.
    pub rock_slope: (f32, f32),
    /// Heights over which snow covers the ground, as fractions of the style's height ramp (0
    /// at its low end, 1 at its high end).
    pub snow_height: (f32, f32),
    /// Curvature magnitudes (1/m: the Laplacian of the heights) over which dirt shows through
    /// grass and snow.
    pub dirt_curvature: (f32, f32),
    /// How far apart (metres) the heights the curvature is measured from lie; the renderers
    /// round it to whole texels, from one to six. Larger spacings see only larger features.
    pub curvature_spacing_m: f32,
}

impl Default for AutoshadeParams {
    fn default() -> Self {
        Self {
            rock_slope: (0.6, 1.1),
            snow_height: (0.62, 0.8),
            // The demo's procedural ground at 0.1 m texels has |curvature| over 0.27 /m at one
            // point in ten and over 0.44 at one in a hundred (0.5 m apart); a Gaussian
            // crater's walls reach 0.6 to 3.
            dirt_curvature: (0.35, 0.9),
            curvature_spacing_m: 0.5,
        }
    }
}

impl AutoshadeParams {
    /// Fails unless every edge is finite, non-negative and each pair rises.
    pub fn validate(&self) -> Result<(), CoreError> {
        let pairs = [
            ("autoshade rock_slope", self.rock_slope),
            ("autoshade snow_height", self.snow_height),
            ("autoshade dirt_curvature", self.dirt_curvature),
        ];
        for (what, (lo, hi)) in pairs {
            for v in [lo, hi] {
                if !v.is_finite() {
                    return Err(CoreError::NonFinite { what, value: v });
                }
            }
            if lo < 0.0 || hi <= lo || hi > 1e6 {
                return Err(CoreError::OutOfRange {
                    what,
                    value: f64::from(hi),
                    expected: "a pair of edges with 0 <= low < high <= 1e6",
                });
            }
        }
        let spacing = self.curvature_spacing_m;
        if !(spacing > 0.0 && spacing <= 1e6) {
            return Err(CoreError::OutOfRange {
                what: "autoshade curvature_spacing_m",
                value: f64::from(spacing),
                expected: "metres in (0, 1e6]",
            });
        }
        Ok(())
    }
}

/// Hermite smoothstep written out (not a platform's builtin), as materials.wgsl writes it.
pub fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The autoshader's weights of grass, dirt, rock and snow (x, y, z, w) at a point whose height
/// is `t` of the way up the style's ramp, with `slope` (metres per metre) and `curvature`
/// (1/m). Rock takes the steep share first, snow the high share of the rest, dirt the sharply
/// bent share of what remains, and grass the remainder: the weights are each in [0, 1] and sum
/// to 1.
pub fn autoshade_weights(params: &AutoshadeParams, t: f32, slope: f32, curvature: f32) -> Vec4 {
    let rock = smoothstep(params.rock_slope.0, params.rock_slope.1, slope);
    let cover = 1.0 - rock;
    let snow = smoothstep(params.snow_height.0, params.snow_height.1, t) * cover;
    let open = cover - snow;
    let dirt = smoothstep(
        params.dirt_curvature.0,
        params.dirt_curvature.1,
        curvature.abs(),
    ) * open;
    Vec4::new(open - dirt, dirt, rock, snow)
}

/// The Laplacian of the heights (1/m): `centre` and its four neighbours `spacing_m` metres
/// away along x (`x_minus`, `x_plus`) and z (`z_minus`, `z_plus`), all in metres. What the
/// renderers feed [`autoshade_weights`] as curvature, with the neighbours
/// [`AutoshadeParams::curvature_spacing_m`] apart (at least one texel): heights, not the
/// 8-bit slope codes, whose steps would show as curvature noise on fine texels.
pub fn curvature_from_heights(
    centre: f32,
    [x_minus, x_plus, z_minus, z_plus]: [f32; 4],
    spacing_m: f32,
) -> f32 {
    ((x_minus + x_plus) + (z_minus + z_plus) - 4.0 * centre) / (spacing_m * spacing_m)
}

/// The Laplacian (1/m) inside a texel cell from the gradients (metres per metre) at its
/// corners `d00, d10, d01, d11` (x then z), `texel_size` metres apart: the curvature on
/// surfaces whose gradients are exact differences of their heights (a streamed world's atlas),
/// where reading more heights costs more than these four gradients.
pub fn curvature_from_gradients(
    d00: Vec2,
    d10: Vec2,
    d01: Vec2,
    d11: Vec2,
    texel_size: f32,
) -> f32 {
    let dxx = (d10.x - d00.x) + (d11.x - d01.x);
    let dzz = (d01.y - d00.y) + (d11.y - d10.y);
    (dxx + dzz) / (2.0 * texel_size)
}

/// One material's images, row-major, `size x size` texels each.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MaterialImages {
    /// Albedo in sRGB, alpha unused (255).
    pub albedo: Vec<[u8; 4]>,
    /// Tangent-space normal: x along +u (world X on the ground), y along +v (world Z), z out of
    /// the surface, each mapped from [-1, 1] to 0..=255; alpha unused (255).
    pub normal: Vec<[u8; 4]>,
}

/// The sides a material image may have.
pub const MATERIAL_SIZES: std::ops::RangeInclusive<u32> = 4..=4096;

/// The images of the [`MATERIALS`] materials, all of one power-of-two size (see the module
/// docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MaterialTextures {
    size: u32,
    layers: Vec<MaterialImages>,
}

impl MaterialTextures {
    /// Checks and wraps the images: exactly [`MATERIALS`] layers, `size` a power of two within
    /// [`MATERIAL_SIZES`], every image `size * size` texels.
    pub fn new(size: u32, layers: Vec<MaterialImages>) -> Result<Self, CoreError> {
        if !MATERIAL_SIZES.contains(&size) || !size.is_power_of_two() {
            return Err(CoreError::OutOfRange {
                what: "material image side",
                value: f64::from(size),
                expected: "a power of two from 4 to 4096",
            });
        }
        if layers.len() != MATERIALS {
            return Err(CoreError::OutOfRange {
                what: "material layers",
                value: layers.len() as f64,
                expected: "exactly 4 (grass, dirt, rock, snow)",
            });
        }
        let texels = size as usize * size as usize;
        for layer in &layers {
            for image in [&layer.albedo, &layer.normal] {
                if image.len() != texels {
                    return Err(CoreError::DataLength {
                        len: image.len(),
                        width: size,
                        height: size,
                    });
                }
            }
        }
        Ok(Self { size, layers })
    }

    /// The project's own tileable images, `size` texels a side (128 is plenty for a material
    /// repeated every few metres): value noise shaped per material (grass blades, dirt pebbles,
    /// rock strata, snow drifts), with normals from the same noise. The same `size` gives the
    /// same bytes on every platform.
    pub fn procedural(size: u32) -> Result<Self, CoreError> {
        // Checked before anything is allocated.
        if !MATERIAL_SIZES.contains(&size) || !size.is_power_of_two() {
            return Self::new(size, Vec::new());
        }
        let layers = (0..MATERIALS).map(|m| procedural_layer(m, size)).collect();
        Self::new(size, layers)
    }

    /// The side of every image, in texels.
    pub fn size(&self) -> u32 {
        self.size
    }

    /// The layers, grass, dirt, rock and snow.
    pub fn layers(&self) -> &[MaterialImages] {
        &self.layers
    }

    /// The mean albedo of `layer`, its sRGB values over 0..=1 averaged: what a material looks
    /// like from afar to the renderers, which shade in display-referred values.
    pub fn mean_albedo(&self, layer: usize) -> Option<Vec3> {
        let images = self.layers.get(layer)?;
        let sum = images.albedo.iter().fold(Vec3::ZERO, |acc, p| {
            acc + Vec3::new(p[0].into(), p[1].into(), p[2].into())
        });
        Some(sum / (255.0 * images.albedo.len() as f32))
    }
}

impl MaterialImages {
    /// The next mip level: each 2 x 2 block averaged (albedo in linear light, normals
    /// renormalised). `size` is this level's side, at least 2.
    pub fn downsample(&self, size: u32) -> Self {
        let half = (size / 2).max(1) as usize;
        let size = size as usize;
        let mut albedo = Vec::with_capacity(half * half);
        let mut normal = Vec::with_capacity(half * half);
        for y in 0..half {
            for x in 0..half {
                let at = |dx: usize, dy: usize| (2 * y + dy) * size + 2 * x + dx;
                let block = [at(0, 0), at(1, 0), at(0, 1), at(1, 1)];
                let a = block
                    .iter()
                    .fold(Vec3::ZERO, |s, &i| s + srgb_to_linear(self.albedo[i]))
                    / 4.0;
                albedo.push(linear_to_srgb(a));
                let n = block
                    .iter()
                    .fold(Vec3::ZERO, |s, &i| s + unit_from_bytes(self.normal[i]));
                normal.push(unit_to_bytes(n.normalize_or(Vec3::Z)));
            }
        }
        Self { albedo, normal }
    }
}

fn srgb_to_linear(p: [u8; 4]) -> Vec3 {
    let f = |c: u8| {
        let c = f32::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            libm::powf((c + 0.055) / 1.055, 2.4)
        }
    };
    Vec3::new(f(p[0]), f(p[1]), f(p[2]))
}

fn linear_to_srgb(c: Vec3) -> [u8; 4] {
    let f = |c: f32| {
        let s = if c <= 0.003_130_8 {
            c * 12.92
        } else {
            1.055 * libm::powf(c, 1.0 / 2.4) - 0.055
        };
        (s.clamp(0.0, 1.0) * 255.0).round() as u8
    };
    [f(c.x), f(c.y), f(c.z), 255]
}

fn unit_from_bytes(p: [u8; 4]) -> Vec3 {
    Vec3::new(p[0].into(), p[1].into(), p[2].into()) / 127.5 - Vec3::ONE
}

fn unit_to_bytes(n: Vec3) -> [u8; 4] {
    let b = |c: f32| ((c * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8;
    [b(n.x), b(n.y), b(n.z), 255]
}

/// Tileable value noise in [0, 1] at texel (x, y) of a `size`-texel image: `cells` lattice
/// cells across (a divisor of `size`), smooth-interpolated.
fn value_noise(seed: u64, cells: u32, size: u32, x: u32, y: u32) -> f32 {
    let lattice = |i: u32, j: u32| {
        let (i, j) = (i % cells, j % cells);
        let h =
            mix64(seed ^ (u64::from(i) << 32 | u64::from(j)).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        (h >> 40) as f32 / (1u64 << 24) as f32
    };
    let per = size as f32 / cells as f32;
    let (u, v) = (x as f32 / per, y as f32 / per);
    let (i, j) = (u.floor() as u32, v.floor() as u32);
    let fade = |t: f32| t * t * (3.0 - 2.0 * t);
    let (fu, fv) = (fade(u.fract()), fade(v.fract()));
    let top = lattice(i, j) + (lattice(i + 1, j) - lattice(i, j)) * fu;
    let bottom = lattice(i, j + 1) + (lattice(i + 1, j + 1) - lattice(i, j + 1)) * fu;
    top + (bottom - top) * fv
}

/// Octaves of [`value_noise`] from `cells` lattice cells up, halving in amplitude.
fn fbm(seed: u64, cells: u32, octaves: u32, size: u32, x: u32, y: u32) -> f32 {
    let mut sum = 0.0;
    let mut norm = 0.0;
    let mut amplitude = 1.0;
    for o in 0..octaves {
        let c = (cells << o).min(size);
        sum += amplitude * value_noise(seed.wrapping_add(u64::from(o)), c, size, x, y);
        norm += amplitude;
        amplitude *= 0.5;
    }
    sum / norm
}

/// One procedural material: its surface height field (for the normals) and its colour.
fn procedural_layer(material: usize, size: u32) -> MaterialImages {
    let seed = 0x7E44_A1E5 + material as u64 * 0x1000;
    let cells = |c: u32| c.min(size);
    // Surface heights in [0, 1] and the albedo's mix factor per texel.
    let texel = |x: u32, y: u32| -> (f32, [f32; 3]) {
        let n = fbm(seed, cells(4), 4, size, x, y);
        let fine = value_noise(seed + 7, cells(32), size, x, y);
        match material {
            // Grass: blotches of lighter and darker green, fine blade noise.
            0 => {
                let c = lerp3([0.20, 0.33, 0.12], [0.40, 0.50, 0.20], n * 0.7 + fine * 0.3);
                (0.6 * fine + 0.4 * n, c)
            }
            // Dirt: brown with scattered light pebbles.
            1 => {
                let pebble = smoothstep(0.72, 0.8, fine);
                let c = lerp3([0.33, 0.24, 0.16], [0.47, 0.37, 0.27], n);
                (
                    0.5 * n + 0.5 * pebble,
                    lerp3(c, [0.58, 0.54, 0.48], pebble * 0.8),
                )
            }
            // Rock: grey strata bent by the noise, darker cracks.
            2 => {
                let phase = y as f32 / size as f32 * 6.0 + n * 1.5;
                let strata = 0.5 + 0.5 * libm::sinf(phase * std::f32::consts::TAU);
                let crack = 1.0 - smoothstep(0.04, 0.12, (fine - 0.5).abs());
                let c = lerp3(
                    [0.36, 0.34, 0.32],
                    [0.56, 0.54, 0.51],
                    0.6 * strata + 0.4 * n,
                );
                (
                    0.6 * strata + 0.4 * n - 0.3 * crack,
                    lerp3(c, [0.2, 0.19, 0.18], crack * 0.6),
                )
            }
            // Snow: bluish white drifts.
            _ => {
                let c = lerp3([0.80, 0.84, 0.90], [0.97, 0.98, 1.0], n * 0.8 + fine * 0.2);
                (n, c)
            }
        }
    };
    let texels = size as usize * size as usize;
    let mut heights = Vec::with_capacity(texels);
    let mut albedo = Vec::with_capacity(texels);
    for y in 0..size {
        for x in 0..size {
            let (h, c) = texel(x, y);
            heights.push(h);
            albedo.push(linear_to_srgb(Vec3::from(c)));
        }
    }
    // Normals by central differences of the wrapped heights; bumpier for rock and dirt.
    let strength = [1.5, 2.5, 4.0, 1.0][material] * size as f32 / 128.0;
    let h = |x: i64, y: i64| {
        let s = i64::from(size);
        heights[(y.rem_euclid(s) * s + x.rem_euclid(s)) as usize]
    };
    let mut normal = Vec::with_capacity(texels);
    for y in 0..i64::from(size) {
        for x in 0..i64::from(size) {
            let dx = (h(x + 1, y) - h(x - 1, y)) * 0.5 * strength;
            let dy = (h(x, y + 1) - h(x, y - 1)) * 0.5 * strength;
            normal.push(unit_to_bytes(Vec3::new(-dx, -dy, 1.0).normalize()));
        }
    }
    MaterialImages { albedo, normal }
}

fn lerp3(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    let t = t.clamp(0.0, 1.0);
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_partition_unity_and_pick_the_expected_material() {
        let p = AutoshadeParams::default();
        for &(t, slope, curv) in &[
            (0.0, 0.0, 0.0),
            (1.0, 0.0, 0.0),
            (0.5, 2.0, 0.0),
            (0.3, 0.2, 1.0),
            (0.7, 0.8, -0.1),
        ] {
            let w = autoshade_weights(&p, t, slope, curv);
            assert!(w.min_element() >= 0.0 && w.max_element() <= 1.0, "{w}");
            assert!((w.element_sum() - 1.0).abs() < 1e-6, "{w}");
        }
        assert_eq!(autoshade_weights(&p, 0.1, 0.0, 0.0), Vec4::X);
        assert_eq!(autoshade_weights(&p, 0.1, 0.0, 2.0), Vec4::Y);
        assert_eq!(autoshade_weights(&p, 0.1, 3.0, 0.0), Vec4::Z);
        assert_eq!(autoshade_weights(&p, 0.95, 0.0, 0.0), Vec4::W);
    }

    #[test]
    fn bad_parameters_and_images_are_refused() {
        let mut p = AutoshadeParams::default();
        assert!(p.validate().is_ok());
        p.rock_slope = (1.0, 1.0);
        assert!(p.validate().is_err());
        p.rock_slope = (f32::NAN, 1.0);
        assert!(p.validate().is_err());
        p.rock_slope = (-1.0, 1.0);
        assert!(p.validate().is_err());
        p = AutoshadeParams::default();
        for spacing in [0.0, -1.0, f32::NAN, f32::INFINITY, 1e7] {
            p.curvature_spacing_m = spacing;
            assert!(p.validate().is_err(), "{spacing}");
        }
        for size in [0, 3, 100, 8192, u32::MAX] {
            assert!(MaterialTextures::procedural(size).is_err(), "{size}");
        }
        let layer = MaterialImages {
            albedo: vec![[0; 4]; 16],
            normal: vec![[0; 4]; 15],
        };
        assert!(MaterialTextures::new(4, vec![layer; 4]).is_err());
    }

    #[test]
    fn curvature_of_a_paraboloid_is_its_laplacian() {
        // h = a (x^2 + z^2): Laplacian 4a at any point and spacing.
        let a = 0.3;
        let h = |x: f32, z: f32| a * (x * x + z * z);
        let (x, z, s) = (1.5, -2.0, 0.5);
        let c = curvature_from_heights(
            h(x, z),
            [h(x - s, z), h(x + s, z), h(x, z - s), h(x, z + s)],
            s,
        );
        assert!((c - 4.0 * a).abs() < 1e-4, "{c}");
        let g = |x: f32, z: f32| Vec2::new(2.0 * a * x, 2.0 * a * z);
        let c = curvature_from_gradients(g(0.0, 0.0), g(s, 0.0), g(0.0, s), g(s, s), s);
        assert!((c - 4.0 * a).abs() < 1e-5, "{c}");
    }

    #[test]
    fn procedural_images_tile_are_deterministic_and_distinct() {
        let a = MaterialTextures::procedural(32).expect("32 is valid");
        assert_eq!(a, MaterialTextures::procedural(32).expect("32 is valid"));
        let means: Vec<Vec3> = (0..MATERIALS)
            .map(|m| a.mean_albedo(m).expect("layer"))
            .collect();
        // Snow is the brightest, grass the greenest.
        assert!(means[3].element_sum() > means[2].element_sum());
        assert!(means[0].y > means[0].x && means[0].y > means[0].z);
        // Tileable: the wrap seam differs no more than neighbouring rows do inside.
        let img = &a.layers()[2].albedo;
        let row = |y: usize| &img[y * 32..(y + 1) * 32];
        let diff = |r: &[[u8; 4]], s: &[[u8; 4]]| -> i32 {
            r.iter()
                .zip(s)
                .map(|(p, q)| (i32::from(p[0]) - i32::from(q[0])).abs())
                .sum()
        };
        let seam = diff(row(31), row(0));
        let inner = (0..31).map(|y| diff(row(y), row(y + 1))).max().unwrap_or(0);
        assert!(seam <= inner, "seam {seam} inner {inner}");
        let half = a.layers()[0].downsample(32);
        assert_eq!(half.albedo.len(), 16 * 16);
    }
}
