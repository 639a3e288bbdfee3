//! Flies the three camera rigs over a procedural terrain and prints how close each came to the
//! ground: an orbit and a flyover sized from the map (`CameraPath`), and a follower walking
//! behind a subject (`CameraRig::follower`), all standing on the collision mirror. Midway a
//! mound is stamped under the follower's path, the changed region handed to the mirror: the
//! follower climbs it.
//!
//! ```text
//! cargo run -p terrain-physics --example camera_flight -- [--size N] [--frames F]
//! ```
//!
//! `--size`: side of the terrain in texels (default 256, at 0.5 m per texel); `--frames`: 1/30 s
//! steps per rig (default 300).

use glam::{UVec2, Vec2};
use terrain_core::{
    Blend, CoarseMap, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams, apply_stamp,
    bilinear, generate_heights, hillshade_range,
};
use terrain_physics::{
    CameraPath, CameraRig, CollisionMirror, FollowShape, MapFrame, PathParams, read_region,
};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

const DT: f32 = 1.0 / 30.0;

fn main() -> Result<()> {
    let (size, frames) = args()?;
    let encoding = HeightEncoding::spanning::<u16>(0.0, 50.0)?;
    let params = TerrainParams {
        size: UVec2::splat(size),
        ..TerrainParams::default()
    };
    let heights = generate_heights(&params)?;
    let grid = heights.map(|h| encoding.to_raw(5.0 + 20.0 * h).round() as u16);
    let mut map = CoarseMap::coarse(grid, encoding, 0.5)?;
    let mirror = CollisionMirror::from_map(&map)?;

    // The paths are sized from the map's extent and height range.
    let (lo, hi) = hillshade_range(&map);
    let frame = MapFrame {
        extent: map.extent_m(),
        low: encoding.to_metres(lo),
        high: encoding.to_metres(hi),
    };
    for (name, path) in [
        ("orbit", CameraPath::orbit(frame, PathParams::default())?),
        (
            "flyover",
            CameraPath::flyover(frame, PathParams::default())?,
        ),
    ] {
        let mut rig = CameraRig::on_path(path, ground_of(&map, frame.low));
        let mut closest = f32::INFINITY;
        for _ in 0..frames {
            let view = rig.step(
                (Vec2::ZERO, Vec2::X),
                DT,
                &mirror.collider(),
                ground_of(&map, frame.low),
            )?;
            let eye = view.pose.eye;
            closest = closest.min(eye.y - ground_of(&map, frame.low)(Vec2::new(eye.x, eye.z)));
        }
        println!(
            "{name}: {frames} frames, closest {closest:.2} m above the ground (clearance {:.2} m), \
             view radius {:.0} m",
            path.clearance(),
            path.view_radius()
        );
    }

    // The follower walks behind a subject crossing the map; a mound rises under its path.
    let start = map.extent_m() * Vec2::new(0.2, 0.5);
    let shape = FollowShape {
        eye_height: 2.0,
        behind: 6.0,
        ahead: 10.0,
    };
    let mut rig = CameraRig::follower(start, bilinear(&map, start)?, shape)?;
    let (mut closest, mut highest) = (f32::INFINITY, f32::NEG_INFINITY);
    for i in 0..frames {
        let subject = start + Vec2::X * (4.0 * DT * i as f32);
        if i == frames / 2 {
            let mound = StampPlacement::new(subject, Vec2::splat(20.0), 4.0)?;
            let rects = apply_stamp(&mut map, &mut GaussianStamp::default(), &mound, Blend::Add)?;
            for rect in rects {
                mirror.apply_next(rect, &read_region(&map, rect)?)?;
            }
        }
        let view = rig.step(
            (subject, Vec2::X),
            DT,
            &mirror.collider(),
            ground_of(&map, frame.low),
        )?;
        let eye = view.pose.eye;
        closest = closest.min(eye.y - ground_of(&map, frame.low)(Vec2::new(eye.x, eye.z)));
        highest = highest.max(eye.y);
    }
    println!(
        "follower: {frames} frames behind its subject, closest {closest:.2} m above the ground, \
         highest eye {highest:.2} m"
    );
    if closest < 0.0 {
        return Err("a camera went below the ground".into());
    }
    Ok(())
}

/// The terrain's height at a point (metres), `low` off the map.
fn ground_of(map: &CoarseMap, low: f32) -> impl Fn(Vec2) -> f32 + '_ {
    move |p| bilinear(map, p).unwrap_or(low)
}

fn args() -> Result<(u32, u32)> {
    let (mut size, mut frames) = (256, 300);
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().ok_or(format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--size" => size = value.parse()?,
            "--frames" => frames = value.parse()?,
            _ => return Err(format!("unknown flag {flag}").into()),
        }
    }
    if !(16..=4096).contains(&size) {
        return Err("--size must be 16 to 4096".into());
    }
    Ok((size, frames.min(100_000)))
}
