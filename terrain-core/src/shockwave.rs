//! The shockwave dynamic stamp (Flower 2010, sec. 3.4.3): a wave texture stepped with the discrete
//! wave equation (eq. 3.6-3.7) and stamped onto the map as the change since it was last applied,
//! so the terrain shows `base + u_t` while the wave travels.

use crate::error::CoreError;
use crate::grid::Grid;
use crate::stamp::TextureStamp;

/// Parameters of a [`Shockwave`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
#[cfg_attr(feature = "schemars", derive(schemars::JsonSchema))]
pub struct ShockwaveParams {
    /// Samples per side of the wave texture (at least 8).
    pub resolution: u32,
    /// Wave speed x time step / spacing, squared (eq. 3.7's gamma). Stable for `gamma <= 0.5`;
    /// Flower 2010 uses 0.5 for the fastest travel.
    pub gamma: f32,
    /// Standard deviation of the initial narrow Gaussian, in wave-texture samples.
    pub initial_sigma: f32,
    /// Fraction of the displacement lost per step, in `[0, 1)`: 0 is eq. 3.7 as written; a
    /// little damping lets the wave die out instead of ringing inside its texture.
    pub damping: f32,
}

impl Default for ShockwaveParams {
    fn default() -> Self {
        Self {
            resolution: 128,
            gamma: 0.5,
            initial_sigma: 2.0,
            damping: 0.0,
        }
    }
}

/// Largest stable `gamma` of the 2D five-point scheme (Flower 2010, sec. 3.4.3).
pub const MAX_SHOCKWAVE_GAMMA: f32 = 0.5;

impl ShockwaveParams {
    /// Checks every parameter; `gamma > 0.5` is unstable and an error.
    pub fn validate(&self) -> Result<(), CoreError> {
        if !(8..=4096).contains(&self.resolution) {
            return Err(CoreError::OutOfRange {
                what: "shockwave resolution",
                value: f64::from(self.resolution),
                expected: "8 to 4096 samples per side",
            });
        }
        if !(self.gamma > 0.0 && self.gamma <= MAX_SHOCKWAVE_GAMMA) {
            return Err(CoreError::OutOfRange {
                what: "shockwave gamma",
                value: f64::from(self.gamma),
                expected: "in (0, 0.5]: larger values make eq. 3.7 unstable",
            });
        }
        if !(self.initial_sigma > 0.0 && self.initial_sigma.is_finite()) {
            return Err(CoreError::OutOfRange {
                what: "shockwave initial sigma",
                value: f64::from(self.initial_sigma),
                expected: "finite and greater than 0 samples",
            });
        }
        if !(0.0..1.0).contains(&self.damping) {
            return Err(CoreError::OutOfRange {
                what: "shockwave damping",
                value: f64::from(self.damping),
                expected: "in [0, 1)",
            });
        }
        Ok(())
    }
}

/// A travelling wave: the state of eq. 3.7 and how much of it has been stamped onto a map.
#[derive(Debug, Clone, PartialEq)]
pub struct Shockwave {
    params: ShockwaveParams,
    previous: Grid<f32>,
    current: Grid<f32>,
    applied: Grid<f32>,
    steps: u64,
}

impl Shockwave {
    /// A wave at rest, initialised to a narrow Gaussian of height 1 in the middle.
    pub fn new(params: ShockwaveParams) -> Result<Self, CoreError> {
        params.validate()?;
        let n = params.resolution;
        let c = (n as f32 - 1.0) * 0.5;
        let k = 1.0 / (2.0 * params.initial_sigma * params.initial_sigma);
        let current = Grid::from_fn(n, n, |x, y| {
            if x == 0 || y == 0 || x == n - 1 || y == n - 1 {
                return 0.0;
            }
            let (dx, dy) = (x as f32 - c, y as f32 - c);
            // libm's `expf`, not the platform's: the same starting wave on every platform.
            libm::expf(-(dx * dx + dy * dy) * k)
        })?;
        Ok(Self {
            params,
            previous: current.clone(),
            applied: Grid::new(n, n, 0.0)?,
            current,
            steps: 0,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &ShockwaveParams {
        &self.params
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The current displacement `u_t`.
    pub fn current(&self) -> &Grid<f32> {
        &self.current
    }

    /// One step of eq. 3.7 with the Laplacian written out:
    /// `u+ = 2u - u- + gamma (u(x-1) + u(x+1) + u(y-1) + u(y+1) - 4u)`, scaled by
    /// `1 - damping`. The printed eq. 3.7 omits the `- 4u` term, without which the scheme is
    /// not the wave equation; the border is held at zero.
    pub fn step(&mut self) {
        let n = self.params.resolution as usize;
        let g = self.params.gamma;
        let keep = 1.0 - self.params.damping;
        let cur = self.current.as_slice();
        let next = self.previous.as_mut_slice(); // u- is overwritten by u+ in place
        for y in 1..n - 1 {
            for x in 1..n - 1 {
                let i = y * n + x;
                let lap = cur[i - 1] + cur[i + 1] + cur[i - n] + cur[i + n] - 4.0 * cur[i];
                next[i] = (2.0 * cur[i] - next[i] + g * lap) * keep;
            }
        }
        std::mem::swap(&mut self.previous, &mut self.current);
        self.steps += 1;
    }

    /// The displacement not yet on the map (`u_t` minus what earlier calls returned), as a
    /// texture stamp to apply with [`crate::Blend::Add`] and the wave's amplitude in metres as
    /// intensity. Each call marks the returned change as applied.
    pub fn take_delta(&mut self) -> Result<TextureStamp, CoreError> {
        let delta = Grid::from_fn(self.current.width(), self.current.height(), |x, y| {
            let i = self.current.index(x, y);
            self.current.as_slice()[i] - self.applied.as_slice()[i]
        })?;
        self.applied = self.current.clone();
        TextureStamp::from_values(delta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_above_one_half_is_an_error() {
        for gamma in [0.51, 1.0, 0.0, -0.1, f32::NAN] {
            let p = ShockwaveParams {
                gamma,
                ..Default::default()
            };
            assert!(Shockwave::new(p).is_err(), "gamma {gamma}");
        }
        let small = ShockwaveParams {
            resolution: 4,
            ..Default::default()
        };
        assert!(Shockwave::new(small).is_err());
        for initial_sigma in [0.0, -1.0, f32::INFINITY, f32::NAN] {
            let p = ShockwaveParams {
                initial_sigma,
                ..Default::default()
            };
            assert!(Shockwave::new(p).is_err(), "initial sigma {initial_sigma}");
        }
    }

    #[test]
    fn wave_travels_outwards_and_stays_bounded() {
        let mut w = Shockwave::new(ShockwaveParams {
            resolution: 64,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(w.steps(), 0);
        for _ in 0..20 {
            w.step();
        }
        assert_eq!(w.steps(), 20);
        let u = w.current();
        let centre = u.get(32, 32).unwrap().abs();
        let ring = (0..32)
            .map(|r| u.get(32 + r, 32).unwrap().abs())
            .fold(0.0, f32::max);
        assert!(ring > centre, "the crest has left the centre");
        let peak = u.as_slice().iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(peak <= 1.0 && peak.is_finite());
        for _ in 0..2000 {
            w.step();
        }
        let peak = w
            .current()
            .as_slice()
            .iter()
            .fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(
            peak.is_finite() && peak < 2.0,
            "gamma = 0.5 is stable: peak {peak}"
        );
    }

    #[test]
    fn deltas_sum_to_the_current_displacement() {
        let mut w = Shockwave::new(ShockwaveParams {
            resolution: 32,
            ..Default::default()
        })
        .unwrap();
        let mut sum = Grid::new(32, 32, 0.0f32).unwrap();
        for _ in 0..5 {
            w.step();
            let d = w.take_delta().unwrap();
            for (s, v) in sum.as_mut_slice().iter_mut().zip(d.values().as_slice()) {
                *s += v;
            }
        }
        for (s, u) in sum.as_slice().iter().zip(w.current().as_slice()) {
            assert!((s - u).abs() < 1e-5);
        }
    }
}
