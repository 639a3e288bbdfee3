//! User parameters of granular deformation (Persson 2019, table 4.4), method choices and presets
//! (Persson 2019 figure captions 5.11-5.15).

use super::GranularError;

/// Distance metric of the distance transform (Persson 2019, sec. 2.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
#[cfg_attr(feature = "schemars", derive(schemars::JsonSchema))]
pub enum DistanceMetric {
    /// `dx^2 + dy^2` (compared squared, so exactly in integers).
    #[default]
    Euclidean,
    /// `|dx| + |dy|` (city block).
    Manhattan,
    /// `max(|dx|, |dy|)` (chessboard).
    Chebyshev,
}

/// How a step finds each column's nearest seed (Persson 2019, sec. 4.1.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum DistanceTransform {
    /// Jump flooding with the hashed neighbour order ([`super::jump_flood`]): what the GPU
    /// runs, bit for bit; approximate (a few columns get a seed slightly farther than the
    /// nearest).
    #[default]
    JumpFlood,
    /// The exact separable transform ([`super::exact_nearest_seed`]): every column gets a
    /// nearest seed (among equally near seeds, possibly another than jump flooding's). CPU only.
    Exact,
}

/// How intersected material reaches the contour (Persson 2019, sec. 4.1.4). A method carries the
/// settings only it uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum DisplacementMethod {
    /// Method 1: iterative transfer to neighbours closer to a seed, remainders kept (listing 4.2).
    Iterative {
        /// `numIterationsDisplaceMaterialToContour` (table 4.4; 10 in table 5.3, see
        /// [`DisplacementMethod::iterative`]): gather passes before the carried material is
        /// flushed to the seeds. At most [`MAX_ITERATIONS`].
        iterations: u32,
    },
    /// Method 2: everything to the closest seed with atomic adds (listing 4.4).
    #[default]
    ClosestSeed,
    /// Method 3: split over several targets marching away from the object (listing 4.5).
    MultipleTargets,
}

impl DisplacementMethod {
    /// The iterative method with the 10 passes of Persson 2019, table 5.3.
    pub const fn iterative() -> Self {
        Self::Iterative { iterations: 10 }
    }

    /// Checks the method's settings: at most [`MAX_ITERATIONS`] iterative passes.
    pub fn validate(&self) -> Result<(), GranularError> {
        match *self {
            Self::Iterative { iterations } => check_range(
                "numIterationsDisplaceMaterialToContour",
                f64::from(iterations),
                0.0,
                f64::from(MAX_ITERATIONS),
                "0..=1024",
            ),
            Self::ClosestSeed | Self::MultipleTargets => Ok(()),
        }
    }
}

/// How steep slopes are evened out (Persson 2019, sec. 4.1.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SlopeMethod {
    /// Method 1: an amounts pass then an apply (gather) pass, senders alternating by
    /// checkerboard parity.
    Interleaved,
    /// Method 2: every column scatters its outflow with atomic adds in one pass.
    #[default]
    Scatter,
}

/// Parameters of granular deformation. Names follow Persson 2019, table 4.4 (sec. 4.2);
/// `terrainSize`, `numVerticesPerRow` and `heightmapSize` belong to the map
/// ([`crate::FixedPointMap`] size and texel size) and the renderer, not here;
/// `numIterationsDisplaceMaterialToContour` belongs to the method that uses it
/// ([`DisplacementMethod::Iterative`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
#[cfg_attr(feature = "schemars", derive(schemars::JsonSchema))]
pub struct GranularParams {
    /// `compression` in `[0, 1]` (table 4.4, sec. 4.1.4): share of intersected material that is
    /// compressed (removed) instead of displaced; 0 keeps the volume exactly. Default 0.
    pub compression: f32,
    /// `roughness` in `[0, 1]` (table 4.4, sec. 4.1.5): scales the material moved when evening
    /// out slopes; lower is smoother. Default 0.6 (figure 5.11).
    pub roughness: f32,
    /// `slopeThreshold` `>= 0` (table 4.4, eq. 4.1): columns even out with neighbours whose slope
    /// `atan(dh / distance) / d` exceeds it. Default 3.1 (figure 5.11).
    pub slope_threshold: f32,
    /// `d` of eq. 4.1 (artistic, `> 0`). Default 0.2, so the threshold of 3.1 is an angle of
    /// 0.62 rad (35.5 degrees, about the angle of repose of snow).
    pub slope_d: f32,
    /// `numIterations-EvenOutSlopes` (table 4.4; default 10 from table 5.3).
    pub num_iterations_even_out_slopes: u32,
    /// `numIterations-BlurNormals` (table 4.4; default 1 from table 5.3).
    pub num_iterations_blur_normals: u32,
    /// Columns whose object bottom is at most this many metres above the terrain are
    /// obstacles (sec. 4.1.3, "just above the terrain"). Default 0.5 m.
    pub obstacle_margin_m: f32,
    /// Texels added on every side of an object's footprint to form its active area (sec. 4.5).
    /// Default 8.
    pub active_area_margin: u32,
    /// Active areas whose gap is at most this many texels are merged (sec. 4.5). Default 4.
    pub merge_distance: u32,
    /// Distance metric of the jump flooding (sec. 2.3, 4.1.4). Default Euclidean.
    pub metric: DistanceMetric,
    /// Run one extra jump flooding pass with step 1 after the `log2 n` passes. Default true.
    pub jfa_extra_pass: bool,
}

impl Default for GranularParams {
    fn default() -> Self {
        Self {
            compression: 0.0,
            roughness: 0.6,
            slope_threshold: 3.1,
            slope_d: 0.2,
            num_iterations_even_out_slopes: 10,
            num_iterations_blur_normals: 1,
            obstacle_margin_m: 0.5,
            active_area_margin: 8,
            merge_distance: 4,
            metric: DistanceMetric::Euclidean,
            jfa_extra_pass: true,
        }
    }
}

/// Largest iteration count accepted for any of the iterative passes.
pub const MAX_ITERATIONS: u32 = 1024;
/// Largest active-area margin and merge distance accepted, in texels.
pub const MAX_MARGIN: u32 = 4096;

fn check_range(
    name: &'static str,
    v: f64,
    lo: f64,
    hi: f64,
    range: &'static str,
) -> Result<(), GranularError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(GranularError::ParamOutOfRange {
            name,
            value: v,
            range,
        })
    }
}

impl GranularParams {
    /// Snow: figure 5.11 (compression 0, roughness 0.6, slopeThreshold 3.1).
    pub fn snow() -> Self {
        Self::default()
    }

    /// Sand, loose material that falls back: figure 5.15 right (slopeThreshold 1.1,
    /// compression 0, roughness 0.1).
    pub fn sand() -> Self {
        Self {
            compression: 0.0,
            roughness: 0.1,
            slope_threshold: 1.1,
            ..Self::default()
        }
    }

    /// Mud, compressed and rigid imprints: figure 5.15 left and middle (slopeThreshold 8,
    /// compression 0.95, roughness 0.1).
    pub fn mud() -> Self {
        Self {
            compression: 0.95,
            roughness: 0.1,
            slope_threshold: 8.0,
            ..Self::default()
        }
    }

    /// Checks every parameter; out-of-range values are errors.
    pub fn validate(&self) -> Result<(), GranularError> {
        check_range(
            "compression",
            f64::from(self.compression),
            0.0,
            1.0,
            "[0, 1]",
        )?;
        check_range("roughness", f64::from(self.roughness), 0.0, 1.0, "[0, 1]")?;
        check_range(
            "slopeThreshold",
            f64::from(self.slope_threshold),
            0.0,
            1e6,
            "[0, 1e6]",
        )?;
        // The bound as an f32 holds it: 1e-6 written in a file is read as 9.99999997e-7.
        check_range(
            "d",
            f64::from(self.slope_d),
            f64::from(1e-6f32),
            1e6,
            "[1e-6, 1e6]",
        )?;
        check_range(
            "obstacle_margin_m",
            f64::from(self.obstacle_margin_m),
            0.0,
            1e4,
            "[0, 1e4] m",
        )?;
        let iters = f64::from(MAX_ITERATIONS);
        check_range(
            "numIterationsEvenOutSlopes",
            f64::from(self.num_iterations_even_out_slopes),
            0.0,
            iters,
            "0..=1024",
        )?;
        check_range(
            "numIterationsBlurNormals",
            f64::from(self.num_iterations_blur_normals),
            0.0,
            iters,
            "0..=1024",
        )?;
        let m = f64::from(MAX_MARGIN);
        check_range(
            "active_area_margin",
            f64::from(self.active_area_margin),
            0.0,
            m,
            "0..=4096",
        )?;
        check_range(
            "merge_distance",
            f64::from(self.merge_distance),
            0.0,
            m,
            "0..=4096",
        )?;
        Ok(())
    }

    /// The compression as the Q15 keep factor `round((1 - compression) * 32768)` used by every
    /// displacement pass: a column displaces `floor(p * keep / 32768)` of its penetration `p`.
    pub fn keep_q15(&self) -> u32 {
        to_q15(1.0 - self.compression)
    }

    /// The roughness as Q15: `round(roughness * 32768)`.
    pub fn roughness_q15(&self) -> u32 {
        to_q15(self.roughness)
    }

    /// Integer slope thresholds `(orthogonal, diagonal)` in height units: a neighbour receives
    /// material when `h_self - h_neighbour` is strictly greater. Eq. 4.1: the slope
    /// `atan(dh / dist) / d` exceeds `slopeThreshold` exactly when
    /// `dh > tan(slopeThreshold * d) * dist`; `u32::MAX` when the angle reaches 90 degrees.
    /// Computed once on the CPU and handed to GPU passes as uniforms.
    pub fn slope_thresholds_units(&self, texel_size: f32, units_per_metre: f64) -> [u32; 2] {
        let angle = f64::from(self.slope_threshold) * f64::from(self.slope_d);
        if angle >= std::f64::consts::FRAC_PI_2 {
            return [u32::MAX; 2];
        }
        let t = angle.tan() * f64::from(texel_size) * units_per_metre;
        let conv = |v: f64| {
            if v >= f64::from(u32::MAX) {
                u32::MAX
            } else {
                v.floor().max(0.0) as u32
            }
        };
        [conv(t), conv(t * std::f64::consts::SQRT_2)]
    }
}

fn to_q15(v: f32) -> u32 {
    (f64::from(v.clamp(0.0, 1.0)) * 32768.0).round() as u32
}

/// `floor(value * q / 32768)` for `q <= 32768`, computed as a GPU does in u32 arithmetic:
/// `(value >> 15) * q + (((value & 0x7fff) * q) >> 15)`.
pub fn mul_q15(value: u32, q: u32) -> u32 {
    let q = q.min(32768);
    (value >> 15) * q + (((value & 0x7fff) * q) >> 15)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mul_q15_is_exact_floor() {
        for &v in &[0u32, 1, 7, 32767, 32768, 99_999, u32::MAX] {
            for &q in &[0u32, 1, 16384, 32767, 32768] {
                let exact = (u64::from(v) * u64::from(q)) >> 15;
                assert_eq!(u64::from(mul_q15(v, q)), exact, "v {v} q {q}");
            }
        }
    }

    #[test]
    fn thresholds_monotone() {
        let mut p = GranularParams::default();
        let [a, b] = p.slope_thresholds_units(0.1, 10_000.0);
        assert!(a > 0 && b > a);
        p.slope_threshold = 8.0;
        assert_eq!(p.slope_thresholds_units(0.1, 10_000.0), [u32::MAX; 2]);
    }

    /// The documented bounds are accepted as an f32 field holds them (1e-6 is 9.99999997e-7),
    /// and a value below them is not.
    #[test]
    fn the_range_ends_of_d_are_accepted() {
        for d in [1e-6f32, 1e6] {
            let p = GranularParams {
                slope_d: d,
                ..GranularParams::default()
            };
            assert!(p.validate().is_ok(), "{d}");
        }
        let below = GranularParams {
            slope_d: 9e-7,
            ..GranularParams::default()
        };
        assert!(below.validate().is_err());
    }
}
