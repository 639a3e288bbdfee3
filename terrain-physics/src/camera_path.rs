//! Camera paths that show a whole map (an orbit and a flyover): where the eye should be and
//! what it looks at, at a time, sized from the map's extent and height range so a 200 m map
//! and a 50 km DEM are framed alike. For repeatable captures and benchmark flights over any
//! terrain; [`crate::CameraRig`] moves a [`crate::CameraBody`] along them, which keeps the eye
//! above the ground.

use crate::PhysicsError;
use crate::error::{check_finite, check_finite2};
use glam::{Vec2, Vec3};
use std::f32::consts::TAU;

/// Vertical field of view the orbit frames the map for (60 degrees, terrain-gpu's
/// `Camera::looking`).
const FOV_Y: f32 = 60.0 * std::f32::consts::PI / 180.0;
/// The orbit looks down this far below the horizon.
const ORBIT_PITCH: f32 = 35.0 * std::f32::consts::PI / 180.0;
/// The orbit's distance from the centre, as a fraction of the distance at which the map's
/// bounding sphere just spans the vertical field of view (radius / sin(FOV_Y / 2)): the map, a
/// flat box inside the sphere, still fills the frame a little closer.
const ORBIT_FILL: f32 = 1.0;
/// Seconds per revolution of the orbit and per loop of the flyover.
const ORBIT_PERIOD_S: f32 = 40.0;
const FLYOVER_PERIOD_S: f32 = 30.0;
/// Where the orbit starts: south-east of the centre, so the default sun (from the north-west,
/// `TerrainStyle::light_dir`) lights the slopes facing the camera from the side.
const ORBIT_START: f32 = 0.15 * TAU;
/// The flyover's loop: an ellipse of this fraction of the map around its centre.
const FLYOVER_RADIUS: f32 = 0.3;
/// The flyover's height above the ground, as a fraction of the map's longer side.
const FLYOVER_HEIGHT: f32 = 0.08;
/// How far ahead the flyover looks, as a fraction of the map's longer side, and how far below
/// the horizon.
const FLYOVER_LOOK_AHEAD: f32 = 0.25;
const FLYOVER_PITCH: f32 = 25.0 * std::f32::consts::PI / 180.0;
/// Ground samples the flyover takes along its next stretch to clear the highest.
const FLYOVER_GROUND_SAMPLES: u32 = 6;

/// The highest flyover a [`PathParams`] takes, in map sides above the ground.
pub const MAX_FLYOVER_HEIGHT: f32 = 100.0;

/// The largest extent and height (metres) a [`MapFrame`] takes.
pub const MAX_FRAME_M: f32 = 1.0e15;

/// The shape of the paths (the defaults: an orbit 35 degrees down, 40 s a turn; a flyover
/// 0.08 map sides above the ground, 25 degrees down, 30 s a loop).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathParams {
    /// The orbit looks down this far below the horizon (radians).
    pub orbit_pitch: f32,
    /// Seconds per revolution of the orbit.
    pub orbit_period_s: f32,
    /// Seconds per loop of the flyover.
    pub flyover_period_s: f32,
    /// The flyover's height above the ground, as a fraction of the map's longer side.
    pub flyover_height: f32,
    /// The flyover looks down this far below the horizon (radians).
    pub flyover_pitch: f32,
}

impl Default for PathParams {
    fn default() -> Self {
        Self {
            orbit_pitch: ORBIT_PITCH,
            orbit_period_s: ORBIT_PERIOD_S,
            flyover_period_s: FLYOVER_PERIOD_S,
            flyover_height: FLYOVER_HEIGHT,
            flyover_pitch: FLYOVER_PITCH,
        }
    }
}

impl PathParams {
    /// Refuses a shape no path can take: non-finite values, periods not above zero, a
    /// flyover height outside (0, [`MAX_FLYOVER_HEIGHT`]], pitches outside (0, 90) degrees.
    pub fn validate(&self) -> Result<(), PhysicsError> {
        let positive = [
            ("orbit_period_s", self.orbit_period_s),
            ("flyover_period_s", self.flyover_period_s),
        ];
        for (what, v) in positive {
            check_finite(what, v)?;
            if v <= 0.0 {
                return Err(out_of_range(what, v, "above zero"));
            }
        }
        let h = self.flyover_height;
        check_finite("flyover_height", h)?;
        if h <= 0.0 || h > MAX_FLYOVER_HEIGHT {
            let expected = "above zero, at most 100 (times the map's longer side)";
            return Err(out_of_range("flyover_height", h, expected));
        }
        for (what, v) in [
            ("orbit_pitch", self.orbit_pitch),
            ("flyover_pitch", self.flyover_pitch),
        ] {
            check_finite(what, v)?;
            if v <= 0.0 || v >= std::f32::consts::FRAC_PI_2 {
                return Err(out_of_range(what, v, "between 0 and pi / 2 radians"));
            }
        }
        Ok(())
    }
}

/// The fraction of a turn of `period` seconds at `t` seconds, in [0, 1): whole turns dropped
/// first, so a huge time or a tiny period still gives a finite angle.
fn turn(t: f32, period: f32) -> f32 {
    (t.rem_euclid(period) / period).clamp(0.0, 1.0)
}

fn out_of_range(what: &'static str, value: f32, expected: &'static str) -> PhysicsError {
    PhysicsError::OutOfRange {
        what,
        value: f64::from(value),
        expected,
    }
}

/// What a path is sized from: the map's extent (metres, X Z) and the lowest and highest height
/// on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapFrame {
    /// Extent in metres.
    pub extent: Vec2,
    /// Lowest height (metres).
    pub low: f32,
    /// Highest height (metres).
    pub high: f32,
}

impl MapFrame {
    /// Refuses a map no path can frame: a non-finite or non-positive extent, non-finite
    /// heights, `low` above `high`, sizes beyond [`MAX_FRAME_M`] (where the paths' distances
    /// would leave f32).
    pub fn validate(&self) -> Result<(), PhysicsError> {
        check_finite2("map extent", self.extent)?;
        let (small, large) = (self.extent.min_element(), self.extent.max_element());
        if small <= 0.0 || large > MAX_FRAME_M {
            let v = if small <= 0.0 { small } else { large };
            return Err(out_of_range("map extent", v, "above zero, at most 1e15 m"));
        }
        for (what, v) in [("lowest height", self.low), ("highest height", self.high)] {
            check_finite(what, v)?;
            if v.abs() > MAX_FRAME_M {
                return Err(out_of_range(what, v, "within +-1e15 m"));
            }
        }
        if self.low > self.high {
            return Err(out_of_range(
                "lowest height",
                self.low,
                "at most the highest height",
            ));
        }
        Ok(())
    }

    /// The map's centre at mid height.
    fn centre(&self) -> Vec3 {
        Vec3::new(
            self.extent.x * 0.5,
            0.5 * (self.low + self.high),
            self.extent.y * 0.5,
        )
    }

    /// The longer side in metres.
    fn side(&self) -> f32 {
        self.extent.max_element()
    }

    /// Radius of the sphere around the map's box.
    fn radius(&self) -> f32 {
        let half = Vec3::new(
            self.extent.x * 0.5,
            0.5 * (self.high - self.low),
            self.extent.y * 0.5,
        );
        half.length()
    }
}

/// Where the eye is and what it looks at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// The eye (metres).
    pub eye: Vec3,
    /// The point looked at (metres).
    pub look_at: Vec3,
}

/// A camera path over a map: an orbit or a flyover ([`CameraPath::orbit`],
/// [`CameraPath::flyover`]), checked when made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPath(Path);

#[derive(Debug, Clone, Copy, PartialEq)]
enum Path {
    /// Circles the map's centre at a distance and height that frame the whole map, looking at
    /// the centre.
    Orbit {
        frame: MapFrame,
        /// Distance from the eye to the centre.
        distance: f32,
        params: PathParams,
    },
    /// Loops over the map at a height above the ground proportional to its extent, looking
    /// ahead and down.
    Flyover { frame: MapFrame, params: PathParams },
}

impl CameraPath {
    /// The orbit around `frame`, framing it for a vertical field of view of 60 degrees.
    pub fn orbit(frame: MapFrame, params: PathParams) -> Result<Self, PhysicsError> {
        frame.validate()?;
        params.validate()?;
        Ok(CameraPath(Path::Orbit {
            frame,
            distance: ORBIT_FILL * frame.radius() / (FOV_Y * 0.5).sin(),
            params,
        }))
    }

    /// The flyover over `frame`.
    pub fn flyover(frame: MapFrame, params: PathParams) -> Result<Self, PhysicsError> {
        frame.validate()?;
        params.validate()?;
        Ok(CameraPath(Path::Flyover { frame, params }))
    }

    /// Seconds of one loop: the pose at `t` and at `t` plus this are the same.
    pub(crate) fn period(&self) -> f32 {
        match &self.0 {
            Path::Orbit { params, .. } => params.orbit_period_s,
            Path::Flyover { params, .. } => params.flyover_period_s,
        }
    }

    fn frame(&self) -> &MapFrame {
        match &self.0 {
            Path::Orbit { frame, .. } | Path::Flyover { frame, .. } => frame,
        }
    }

    /// The pose at `t` seconds (a non-finite `t` gives the start pose); `ground` gives the
    /// terrain's height at a point (X, Z).
    pub fn pose(&self, t: f32, ground: impl Fn(Vec2) -> f32) -> Pose {
        let t = if t.is_finite() { t } else { 0.0 };
        match self.0 {
            Path::Orbit {
                frame,
                distance,
                params,
            } => {
                let a = ORBIT_START + TAU * turn(t, params.orbit_period_s);
                let centre = frame.centre();
                let horizontal = distance * params.orbit_pitch.cos();
                let eye = centre
                    + Vec3::new(
                        horizontal * a.cos(),
                        distance * params.orbit_pitch.sin(),
                        horizontal * a.sin(),
                    );
                Pose {
                    eye,
                    look_at: centre,
                }
            }
            Path::Flyover { frame, params } => {
                let side = frame.side();
                let centre = Vec2::new(frame.extent.x, frame.extent.y) * 0.5;
                let radii = frame.extent * FLYOVER_RADIUS;
                let a = TAU * turn(t, params.flyover_period_s);
                let xz = centre + Vec2::new(a.cos(), a.sin()) * radii;
                // The loop's tangent, d/da of the point: exact for any period (a step ahead in
                // time is half a loop at a short period, and nothing at a huge time).
                let ahead = (Vec2::new(-a.sin(), a.cos()) * radii).normalize_or(Vec2::X);
                // Clear the highest ground under the next stretch, not only the ground below:
                // the camera rises before a ridge instead of after it.
                let reach = side * FLYOVER_LOOK_AHEAD;
                // Non-finite ground heights are left out and the rest clamped to a frame's
                // +-MAX_FRAME_M, so every pose is finite.
                let highest = (0..=FLYOVER_GROUND_SAMPLES)
                    .map(|i| {
                        let f = i as f32 / FLYOVER_GROUND_SAMPLES as f32;
                        ground(xz + ahead * reach * f)
                    })
                    .filter(|h| h.is_finite())
                    .map(|h| h.clamp(-MAX_FRAME_M, MAX_FRAME_M))
                    .fold(f32::NEG_INFINITY, f32::max);
                let highest = if highest.is_finite() {
                    highest
                } else {
                    frame.low
                };
                let eye = Vec3::new(xz.x, highest + side * params.flyover_height, xz.y);
                let look = Vec3::new(ahead.x, -params.flyover_pitch.tan(), ahead.y) * reach;
                Pose {
                    eye,
                    look_at: eye + look,
                }
            }
        }
    }

    /// The farthest distance (metres, horizontal) from the eye to a point of the map anywhere
    /// on the path: what the clipmap and the far plane must reach.
    pub fn view_radius(&self) -> f32 {
        let frame = self.frame();
        let half_diagonal = frame.extent.length() * 0.5;
        match self.0 {
            Path::Orbit {
                distance, params, ..
            } => distance * params.orbit_pitch.cos() + half_diagonal,
            Path::Flyover { .. } => FLYOVER_RADIUS * frame.extent.max_element() + half_diagonal,
        }
    }

    /// The distance at which the view's subject sits (the orbit's centre, the flyover's look
    /// ahead): fog and planes are set from it.
    pub fn subject_distance(&self) -> f32 {
        match self.0 {
            Path::Orbit { distance, .. } => distance,
            Path::Flyover { frame, .. } => frame.side() * FLYOVER_LOOK_AHEAD,
        }
    }

    /// The least height of the eye above the ground (the body's ground clamp): a hundredth of
    /// the map's longer side, at least 2 m.
    pub fn clearance(&self) -> f32 {
        (self.frame().side() * 0.01).max(2.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(side: f32) -> MapFrame {
        MapFrame {
            extent: Vec2::new(side, side * 0.75),
            low: 100.0,
            high: 900.0,
        }
    }

    #[test]
    fn the_orbit_frames_the_whole_map_and_looks_at_its_centre() {
        for side in [200.0, 2560.0, 50_000.0] {
            let f = frame(side);
            let path = CameraPath::orbit(f, PathParams::default()).unwrap();
            for t in [0.0, 7.0, 23.0] {
                let pose = path.pose(t, |_| 0.0);
                assert_eq!(pose.look_at, f.centre());
                let to_centre = pose.eye - pose.look_at;
                // Far enough that the map's bounding sphere fits the vertical field of view
                // (within the framing factor), above the highest point.
                let needed = f.radius() / (FOV_Y * 0.5).sin();
                assert!(to_centre.length() >= 0.8 * needed, "{side} {t}");
                assert!(to_centre.length() <= 1.2 * needed, "{side} {t}");
                assert!(pose.eye.y > f.high, "{side} {t}");
            }
            // It moves around the centre.
            let (a, b) = (path.pose(0.0, |_| 0.0), path.pose(10.0, |_| 0.0));
            assert!((a.eye - b.eye).length() > 0.1 * side);
            assert!(path.view_radius() > (a.eye - a.look_at).length() * ORBIT_PITCH.cos());
        }
    }

    #[test]
    fn every_corner_of_the_map_stays_in_the_orbit_frame() {
        // Maps square and long, flat and steep, in 16:9 and square frames: each corner of the
        // map's box projects inside the frame at every point of a revolution.
        let maps = [
            (Vec2::splat(2560.0), 100.0, 900.0),
            (Vec2::new(10_240.0, 2_560.0), 0.0, 300.0),
            (Vec2::splat(204.8), 0.0, 12.0),
            (Vec2::splat(1000.0), 0.0, 800.0),
        ];
        for (extent, low, high) in maps {
            let frame = MapFrame { extent, low, high };
            let path = CameraPath::orbit(frame, PathParams::default()).unwrap();
            for aspect in [16.0 / 9.0, 1.0] {
                for i in 0..72 {
                    let pose = path.pose(i as f32 / 72.0 * ORBIT_PERIOD_S, |_| 0.0);
                    // A right-handed perspective of the framed field of view, Y up.
                    let proj =
                        glam::camera::rh::proj::directx::perspective(FOV_Y, aspect, 0.25, 1e6);
                    let view =
                        glam::camera::rh::view::look_at_mat4(pose.eye, pose.look_at, Vec3::Y);
                    let m = proj * view;
                    for x in [0.0, extent.x] {
                        for y in [low, high] {
                            for z in [0.0, extent.y] {
                                let p = m.project_point3(Vec3::new(x, y, z));
                                assert!(
                                    p.x.abs() < 1.0 && p.y.abs() < 1.0,
                                    "{extent} {aspect}: corner ({x}, {y}, {z}) at {p}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_flyover_keeps_its_height_above_the_highest_ground_ahead() {
        let f = frame(2560.0);
        let path = CameraPath::flyover(f, PathParams::default()).unwrap();
        // A ridge along x = 1800 m.
        let ground = |p: Vec2| {
            if (p.x - 1800.0).abs() < 100.0 {
                850.0
            } else {
                150.0
            }
        };
        let mut risen_before = 0;
        for i in 0..300 {
            let t = i as f32 * 0.1;
            let pose = path.pose(t, ground);
            let xz = Vec2::new(pose.eye.x, pose.eye.z);
            // Off the ridge, but already above it: it rose before the ridge.
            if xz.x < 1700.0 && pose.eye.y >= 850.0 + 2560.0 * FLYOVER_HEIGHT - 1e-3 {
                risen_before += 1;
            }
            assert!(xz.x >= 0.0 && xz.y >= 0.0 && xz.x <= f.extent.x && xz.y <= f.extent.y);
            assert!(
                pose.eye.y >= ground(xz) + 2560.0 * FLYOVER_HEIGHT - 1e-3,
                "{t}"
            );
            // Looks ahead and down.
            assert!(pose.look_at.y < pose.eye.y);
        }
        assert!(risen_before > 0, "the camera rose only over the ridge");
        assert!(path.clearance() >= 2.0);
    }

    #[test]
    fn shapes_and_maps_no_path_can_take_are_refused() {
        let ok = frame(100.0);
        let bad_frames = [
            MapFrame {
                extent: Vec2::new(f32::NAN, 1.0),
                ..ok
            },
            MapFrame {
                extent: Vec2::new(0.0, 1.0),
                ..ok
            },
            MapFrame {
                low: f32::INFINITY,
                ..ok
            },
            MapFrame {
                low: 10.0,
                high: 5.0,
                ..ok
            },
        ];
        for f in bad_frames {
            assert!(
                CameraPath::orbit(f, PathParams::default()).is_err(),
                "{f:?}"
            );
            assert!(
                CameraPath::flyover(f, PathParams::default()).is_err(),
                "{f:?}"
            );
        }
        let d = PathParams::default();
        let bad_params = [
            PathParams {
                orbit_period_s: 0.0,
                ..d
            },
            PathParams {
                flyover_period_s: f32::NAN,
                ..d
            },
            PathParams {
                flyover_height: -1.0,
                ..d
            },
            PathParams {
                flyover_height: MAX_FLYOVER_HEIGHT * 1.5,
                ..d
            },
            PathParams {
                orbit_pitch: std::f32::consts::FRAC_PI_2,
                ..d
            },
            PathParams {
                flyover_pitch: 0.0,
                ..d
            },
        ];
        for p in bad_params {
            assert!(CameraPath::orbit(ok, p).is_err(), "{p:?}");
        }
        // Extreme but finite maps and times give finite poses.
        let huge = MapFrame {
            extent: Vec2::splat(MAX_FRAME_M),
            low: -MAX_FRAME_M,
            high: MAX_FRAME_M,
        };
        let beyond = MapFrame {
            extent: Vec2::splat(3.0e38),
            ..ok
        };
        assert!(CameraPath::orbit(beyond, d).is_err());
        for path in [
            CameraPath::orbit(ok, d).unwrap(),
            CameraPath::flyover(ok, d).unwrap(),
            CameraPath::orbit(huge, d).unwrap(),
            CameraPath::flyover(huge, d).unwrap(),
        ] {
            for (t, ground) in [
                (f32::MAX, 0.0),
                (-f32::MAX, f32::MAX),
                (f32::NAN, f32::NAN),
                (1.0, -f32::MAX),
            ] {
                let pose = path.pose(t, |_| ground);
                assert!(
                    pose.eye.is_finite() && pose.look_at.is_finite(),
                    "{t}: {pose:?}"
                );
            }
            assert!(path.view_radius().is_finite() && path.subject_distance().is_finite());
        }
    }
}
