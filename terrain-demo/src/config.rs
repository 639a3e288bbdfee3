//! `--config FILE.toml` and `print-config`: the scenarios' parameters as one document, so a
//! scenario can be written down and shared. Every key is optional: a file holds only what it
//! changes, over the defaults (`print-config` prints them all). Unknown keys and values out
//! of range are errors that name the key.

use anyhow::{Context, Result, anyhow, bail};
use glam::{Vec2, Vec3};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::Path;
use terrain_core::ShockwaveParams;
use terrain_core::granular::GranularParams;
use terrain_physics::SchedulerConfig;

/// The largest configuration file read (a parameter file is a few kilobytes).
const MAX_FILE_BYTES: u64 = 1 << 20;

/// Every parameter of the scenarios: those of `--config FILE.toml` (see `print-config`),
/// defaults included.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DemoParams {
    /// The default scenario's script: footprints, craters, the shockwave.
    pub stamps: StampParams,
    /// The snow scenario's granular material (terrain-core's `GranularParams`).
    pub granular: GranularParams,
    /// The default scenario's collision readback scheduler (terrain-physics'
    /// `SchedulerConfig`; durations in milliseconds).
    pub scheduler: SchedulerConfig,
    /// Lighting and colours of the terrain.
    pub style: StyleParams,
    /// The default scenario's cameras.
    pub camera: CameraParams,
}

/// Staging buffers of the collision readback's ring by default (the scheduler keeps no more
/// requests in flight; the GPU scene makes its ring this size).
pub const COLLISION_READBACK_RING: usize = 4;

impl Default for DemoParams {
    fn default() -> Self {
        Self {
            stamps: StampParams::default(),
            granular: GranularParams::snow(),
            scheduler: SchedulerConfig {
                max_in_flight: COLLISION_READBACK_RING,
                ..SchedulerConfig::default()
            },
            style: StyleParams::default(),
            camera: CameraParams::default(),
        }
    }
}

/// The default scenario's script.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StampParams {
    /// Footprint size in metres: length along the walking direction, width.
    #[schemars(with = "[f32; 2]")]
    pub foot_size_m: Vec2,
    /// How deep a footprint presses, in metres.
    pub foot_depth_m: f32,
    /// Footprints per frame.
    pub steps_per_frame: u32,
    /// Walking stride in metres.
    pub stride_m: f32,
    /// A crater lands every this many frames (0: none).
    pub crater_every: u32,
    /// Crater diameters are drawn between these (metres; at most half the map's side).
    #[schemars(with = "[f32; 2]")]
    pub crater_size_m: Vec2,
    /// A crater is this many times as deep as it is wide.
    pub crater_depth_ratio: f32,
    /// The shockwave: its footprint as a fraction of the map's smaller side (0: no
    /// shockwave).
    pub shock_size_fraction: f32,
    /// The shockwave's amplitude in metres.
    pub shock_amplitude_m: f32,
    /// Wave steps (Flower 2010, eq. 3.7) per frame.
    pub shock_steps_per_frame: u32,
    /// The wave simulation (terrain-core's `ShockwaveParams`).
    pub shockwave: ShockwaveParams,
    /// On this frame a hole (a cave mouth) is cut beside the walker's path, 30 m ahead and
    /// 10 m to the side, so the camera walks past it (0: none).
    pub hole_frame: u32,
    /// The hole's diameter in metres (at most half the map's side).
    pub hole_size_m: f32,
}

impl Default for StampParams {
    fn default() -> Self {
        Self {
            foot_size_m: Vec2::new(1.1, 0.45),
            foot_depth_m: 0.12,
            steps_per_frame: 2,
            stride_m: 0.9,
            crater_every: 5,
            crater_size_m: Vec2::new(6.0, 14.0),
            crater_depth_ratio: 0.3,
            shock_size_fraction: 0.45,
            shock_amplitude_m: 2.5,
            shock_steps_per_frame: 2,
            shockwave: ShockwaveParams {
                resolution: 128,
                initial_sigma: 3.0,
                damping: 0.002,
                ..ShockwaveParams::default()
            },
            hole_frame: 3,
            hole_size_m: 9.0,
        }
    }
}

/// Lighting and colours (what the scenario does not derive from the map).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StyleParams {
    /// Direction towards the sun (any length but zero).
    #[schemars(with = "[f32; 3]")]
    pub light_dir: Vec3,
    /// Colour the terrain fades to with distance (linear RGB, 0..1).
    #[schemars(with = "[f32; 3]")]
    pub fog_color: Vec3,
    /// Fog density per metre; absent: chosen from the map's size and the camera.
    pub fog_density: Option<f32>,
    /// Heights (metres) the colour ramp spans; absent: the map's height range.
    #[schemars(with = "Option<[f32; 2]>")]
    pub ramp_m: Option<Vec2>,
    /// `materials`: grass, dirt, rock and snow images placed by height, slope and curvature
    /// (so craters and trails change what the ground shows); `ramp`: a colour ramp over
    /// height, the cheapest.
    pub shading: ShadingParam,
    /// Metres one material image covers before it repeats.
    pub material_scale_m: f32,
}

/// `style.shading`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ShadingParam {
    /// The material images, weighted by the autoshader.
    Materials,
    /// The height ramp.
    Ramp,
}

impl Default for StyleParams {
    fn default() -> Self {
        let style = terrain_gpu::TerrainStyle::default();
        Self {
            light_dir: style.light_dir,
            fog_color: style.fog_color,
            fog_density: None,
            ramp_m: None,
            shading: ShadingParam::Materials,
            material_scale_m: style.materials.scale_m,
        }
    }
}

/// The default scenario's cameras.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CameraParams {
    /// Eye height of the walker camera above the ground, in metres.
    pub walker_eye_height_m: f32,
    /// How far behind the walker the camera walks, in metres.
    pub walker_behind_m: f32,
    /// How far ahead of the walker it looks, in metres.
    pub walker_ahead_m: f32,
    /// The orbit looks down this many degrees below the horizon.
    pub orbit_pitch_deg: f32,
    /// Seconds per revolution of the orbit.
    pub orbit_period_s: f32,
    /// Seconds per loop of the flyover.
    pub flyover_period_s: f32,
    /// The flyover's height above the ground, as a fraction of the map's longer side.
    pub flyover_height: f32,
    /// The flyover looks down this many degrees below the horizon.
    pub flyover_pitch_deg: f32,
}

impl Default for CameraParams {
    fn default() -> Self {
        Self {
            walker_eye_height_m: 3.0,
            walker_behind_m: 9.0,
            walker_ahead_m: 12.0,
            orbit_pitch_deg: 35.0,
            orbit_period_s: 40.0,
            flyover_period_s: 30.0,
            flyover_height: 0.08,
            flyover_pitch_deg: 25.0,
        }
    }
}

impl DemoParams {
    /// The parameters of `--config FILE` over the defaults, or the defaults without a file.
    pub fn load(file: Option<&Path>) -> Result<Self> {
        let Some(path) = file else {
            return Ok(Self::default());
        };
        let meta =
            std::fs::metadata(path).with_context(|| format!("reading {}", path.display()))?;
        if !meta.is_file() {
            bail!("{} is not a regular file", path.display());
        }
        if meta.len() > MAX_FILE_BYTES {
            bail!(
                "{} is {} bytes: a parameter file is at most {MAX_FILE_BYTES}",
                path.display(),
                meta.len()
            );
        }
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::from_toml(&text).with_context(|| format!("in {}", path.display()))
    }

    /// The parameters of a TOML document over the defaults: a key it leaves out keeps its
    /// default; a key the defaults do not have is an error.
    pub fn from_toml(text: &str) -> Result<Self> {
        // A value TOML itself cannot hold (an integer beyond i64) is named by its line too.
        let given: toml::Table = toml::from_str(text).map_err(|e| locate(text, &e))?;
        let mut merged = toml::Table::try_from(Self::default())?;
        merge(&mut merged, given, "")?;
        // Read back from text, so that an error has a place: the line it names says which key.
        let text = toml::to_string(&merged)?;
        let params: Self = toml::from_str(&text).map_err(|e| locate(&text, &e))?;
        params.validate()?;
        Ok(params)
    }

    /// The parameters as TOML, every key written, after a header saying how to use them.
    pub fn to_toml(&self) -> Result<String> {
        Ok(format!(
            "# terrain-demo parameters: `terrain-demo --config FILE.toml` reads a file like this.\n\
             # Every key is optional (a file holds what it changes). Two more keys exist, unset\n\
             # by default: style.fog_density (per metre) and style.ramp_m = [LOW, HIGH] (metres),\n\
             # else chosen from the map and the camera.\n\n{}",
            toml::to_string_pretty(self)?
        ))
    }

    /// Values the scenarios cannot run with: an error naming the key and its range (see
    /// [`crate::ranges::KEYS`], which `--help` prints).
    pub fn validate(&self) -> Result<()> {
        use crate::ranges::{check, check_as};
        let each = |name: &str, values: &[f32]| {
            values
                .iter()
                .enumerate()
                .try_for_each(|(i, &v)| check_as(name, &format!("{name}[{i}]"), v))
        };
        let s = &self.stamps;
        each("stamps.foot_size_m", &s.foot_size_m.to_array())?;
        check("stamps.foot_depth_m", s.foot_depth_m)?;
        check("stamps.steps_per_frame", s.steps_per_frame)?;
        check("stamps.stride_m", s.stride_m)?;
        check("stamps.crater_every", s.crater_every)?;
        each("stamps.crater_size_m", &s.crater_size_m.to_array())?;
        if s.crater_size_m.y < s.crater_size_m.x {
            bail!("stamps.crater_size_m: the largest size is below the smallest");
        }
        check("stamps.crater_depth_ratio", s.crater_depth_ratio)?;
        check("stamps.shock_size_fraction", s.shock_size_fraction)?;
        check("stamps.shock_amplitude_m", s.shock_amplitude_m)?;
        check("stamps.shock_steps_per_frame", s.shock_steps_per_frame)?;
        check("stamps.hole_frame", s.hole_frame)?;
        check("stamps.hole_size_m", s.hole_size_m)?;
        let w = &s.shockwave;
        check("stamps.shockwave.resolution", w.resolution)?;
        check("stamps.shockwave.gamma", w.gamma)?;
        check("stamps.shockwave.initial_sigma", w.initial_sigma)?;
        check("stamps.shockwave.damping", w.damping)?;
        terrain_core::Shockwave::new(s.shockwave).context("stamps.shockwave")?;
        let g = &self.granular;
        check("granular.compression", g.compression)?;
        check("granular.roughness", g.roughness)?;
        check("granular.slope_threshold", g.slope_threshold)?;
        check("granular.slope_d", g.slope_d)?;
        check(
            "granular.num_iterations_even_out_slopes",
            g.num_iterations_even_out_slopes,
        )?;
        check(
            "granular.num_iterations_blur_normals",
            g.num_iterations_blur_normals,
        )?;
        check("granular.obstacle_margin_m", g.obstacle_margin_m)?;
        check("granular.active_area_margin", g.active_area_margin)?;
        check("granular.merge_distance", g.merge_distance)?;
        self.granular.validate().context("granular")?;
        let c = &self.scheduler;
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        check("scheduler.quiet_gap_ms", ms(c.quiet_gap))?;
        check("scheduler.max_delay_ms", ms(c.max_delay))?;
        check("scheduler.merge_distance", c.merge_distance)?;
        check("scheduler.max_requests", c.max_requests)?;
        check("scheduler.request_timeout_ms", ms(c.request_timeout))?;
        check("scheduler.max_in_flight", c.max_in_flight)?;
        if c.max_requests > c.max_in_flight {
            bail!(
                "scheduler.max_requests = {} is above scheduler.max_in_flight = {}",
                c.max_requests,
                c.max_in_flight
            );
        }
        terrain_physics::ReadbackScheduler::new(glam::UVec2::splat(16), *c).context("scheduler")?;
        let st = &self.style;
        each("style.light_dir", &st.light_dir.to_array())?;
        if st.light_dir.length_squared() == 0.0 {
            bail!("style.light_dir must be a non-zero direction");
        }
        each("style.fog_color", &st.fog_color.to_array())?;
        if let Some(d) = st.fog_density {
            check("style.fog_density", d)?;
        }
        if let Some(r) = st.ramp_m {
            each("style.ramp_m", &r.to_array())?;
            if r.y <= r.x {
                bail!("style.ramp_m = [{}, {}]: low below high", r.x, r.y);
            }
        }
        check("style.material_scale_m", st.material_scale_m)?;
        let cam = &self.camera;
        for (name, v) in [
            ("camera.walker_eye_height_m", cam.walker_eye_height_m),
            ("camera.walker_behind_m", cam.walker_behind_m),
            ("camera.walker_ahead_m", cam.walker_ahead_m),
            ("camera.orbit_pitch_deg", cam.orbit_pitch_deg),
            ("camera.orbit_period_s", cam.orbit_period_s),
            ("camera.flyover_period_s", cam.flyover_period_s),
            ("camera.flyover_height", cam.flyover_height),
            ("camera.flyover_pitch_deg", cam.flyover_pitch_deg),
        ] {
            check(name, v)?;
        }
        Ok(())
    }
}

/// The error `e` of reading `text`, with the key it is about: `[section] line: message`.
fn locate(text: &str, e: &toml::de::Error) -> anyhow::Error {
    let Some(span) = e.span() else {
        return anyhow!("{}", e.message());
    };
    let start = span.start.min(text.len());
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[start..].find('\n').map_or(text.len(), |i| start + i);
    let line = text[line_start..line_end].trim();
    let section = text[..line_start]
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('['))
        .map(str::trim);
    match section {
        Some(section) if section != line => anyhow!("{section} {line}: {}", e.message()),
        _ => anyhow!("{line}: {}", e.message()),
    }
}

/// The arrays whose default is absent (so the defaults do not show their length).
const OPTIONAL_ARRAYS: [(&str, usize); 1] = [("style.ramp_m", 2)];

/// Writes `given` over `base`, table by table; `at` is the key path for errors.
fn merge(base: &mut toml::Table, given: toml::Table, at: &str) -> Result<()> {
    for (key, value) in given {
        let path = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        // A fixed-size array takes exactly its values: the reader would drop extra ones.
        if let toml::Value::Array(g) = &value {
            let want = match base.get(&key) {
                Some(toml::Value::Array(b)) => Some(b.len()),
                _ => OPTIONAL_ARRAYS
                    .iter()
                    .find(|(k, _)| *k == path)
                    .map(|(_, n)| *n),
            };
            if let Some(n) = want
                && g.len() != n
            {
                bail!("`{path}` has {} values: it takes {n}", g.len());
            }
        }
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(g)) => merge(b, g, &path)?,
            (Some(slot), v) => *slot = v,
            // Absent from the defaults: an optional key left unset (written by nobody), or
            // a typo; deserialising with deny_unknown_fields tells them apart.
            (None, v) => {
                base.insert(key, v);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An array of the wrong length is refused, naming the key (extra values were dropped).
    #[test]
    fn arrays_take_exactly_their_values() {
        for (text, key) in [
            (
                "[stamps]\nfoot_size_m = [1.0, 0.5, 99.0]",
                "stamps.foot_size_m",
            ),
            ("[stamps]\nfoot_size_m = [1.0]", "stamps.foot_size_m"),
            (
                "[style]\nlight_dir = [1.0, 1.0, 1.0, 1.0]",
                "style.light_dir",
            ),
            ("[style]\nramp_m = [1.0, 2.0, 3.0]", "style.ramp_m"),
        ] {
            let e = DemoParams::from_toml(text).unwrap_err();
            assert!(format!("{e:#}").contains(key), "{text}: {e:#}");
        }
        let p = DemoParams::from_toml("[style]\nramp_m = [1.0, 2.0]").unwrap();
        assert_eq!(p.style.ramp_m, Some(glam::Vec2::new(1.0, 2.0)));
    }

    #[test]
    fn the_printed_defaults_read_back_as_the_defaults() {
        let text = DemoParams::default().to_toml().unwrap();
        assert_eq!(DemoParams::from_toml(&text).unwrap(), DemoParams::default());
        assert_eq!(DemoParams::from_toml("").unwrap(), DemoParams::default());
    }

    #[test]
    fn a_file_changes_only_what_it_names() {
        let p = DemoParams::from_toml(
            "[stamps]\nfoot_depth_m = 0.3\n[stamps.shockwave]\ndamping = 0.01\n\
             [scheduler]\nquiet_gap_ms = 40\n[style]\nfog_density = 0.001\n\
             [granular]\nmetric = \"manhattan\"\n",
        )
        .unwrap();
        let d = DemoParams::default();
        assert_eq!(p.stamps.foot_depth_m, 0.3);
        assert_eq!(p.stamps.shockwave.damping, 0.01);
        assert_eq!(p.stamps.shockwave.resolution, d.stamps.shockwave.resolution);
        assert_eq!(p.stamps.stride_m, d.stamps.stride_m);
        assert_eq!(p.scheduler.quiet_gap, std::time::Duration::from_millis(40));
        assert_eq!(p.scheduler.max_delay, d.scheduler.max_delay);
        assert_eq!(p.style.fog_density, Some(0.001));
        assert_eq!(
            p.granular.metric,
            terrain_core::granular::DistanceMetric::Manhattan
        );
        assert_eq!(p.camera, d.camera);
    }

    #[test]
    fn bad_files_name_the_key() {
        let err = |text: &str| format!("{:#}", DemoParams::from_toml(text).unwrap_err());
        assert!(err("[stamps]\nfoot_dept_m = 1").contains("foot_dept_m"));
        assert!(err("[stampz]\nx = 1").contains("stampz"));
        assert!(err("[stamps]\nstride_m = -1").contains("stamps.stride_m"));
        assert!(err("[stamps]\nstride_m = nan").contains("stamps.stride_m"));
        assert!(err("[stamps]\nstride_m = \"far\"").contains("stride_m"));
        assert!(err("[stamps]\nsteps_per_frame = 100000").contains("steps_per_frame"));
        assert!(err("[scheduler]\nmax_in_flight = 0").contains("max_in_flight"));
        assert!(err("[scheduler]\nquiet_gap_ms = -5").contains("quiet_gap_ms"));
        assert!(err("[style]\nlight_dir = [0, 0, 0]").contains("light_dir"));
        assert!(err("[style]\nramp_m = [5, 1]").contains("ramp_m"));
        assert!(err("[camera]\norbit_pitch_deg = 90").contains("orbit_pitch_deg"));
        assert!(err("[granular]\nroughness = 7").contains("granular"));
        assert!(err("not toml [").len() > 5);
    }
}
