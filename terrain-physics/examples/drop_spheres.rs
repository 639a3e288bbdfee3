//! Drop spheres on a heightfield, step them until they settle, and print their contacts; then
//! dig a crater beside one, hand the changed regions to the collision mirror, and step again:
//! the ball rolls into it.
//!
//! ```text
//! cargo run -p terrain-physics --example drop_spheres -- [--size N] [--spheres K] [--steps S]
//! ```
//!
//! `--size`: side of the procedural terrain in texels (default 256, at 0.5 m per texel);
//! `--spheres`: how many balls (default 4); `--steps`: 1/60 s steps per phase (default 120).

use glam::{Vec2, Vec3};
use terrain_core::{
    Blend, CoarseMap, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams, apply_stamp,
    generate_heights,
};
use terrain_physics::{CollisionMirror, SphereBody, read_region};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Seconds per step.
const DT: f32 = 1.0 / 60.0;

fn main() -> Result<()> {
    let args = Args::parse()?;

    // A gentle procedural terrain, 10..16 m in a 0..50 m 16-bit encoding, 0.5 m per texel.
    let encoding = HeightEncoding::spanning::<u16>(0.0, 50.0)?;
    let params = TerrainParams {
        size: glam::UVec2::splat(args.size),
        octaves: 4,
        ..TerrainParams::default()
    };
    let heights = generate_heights(&params)?;
    let grid = heights.map(|h| encoding.to_raw(10.0 + 6.0 * h).round() as u16);
    let mut map = CoarseMap::coarse(grid, encoding, 0.5)?;

    // Collision reads the mirror: immutable snapshots, updated region by region.
    let mirror = CollisionMirror::from_map(&map)?;

    // Balls of 0.5 to 1 m, 5 m above the ground along a diagonal.
    let extent = map.extent_m();
    let mut balls = Vec::new();
    for i in 0..args.spheres {
        let t = (i as f32 + 0.5) / args.spheres as f32;
        let xz = extent * Vec2::new(0.2 + 0.6 * t, 0.3 + 0.4 * t);
        let ground = mirror.collider().height(xz)?;
        let radius = 0.5 + 0.5 * t;
        let mut ball = SphereBody::new(Vec3::new(xz.x, ground + 5.0, xz.y), radius)?;
        ball.damping = 1.0; // N s/m on 1 kg: the balls come to rest
        balls.push(ball);
    }

    println!("dropping {} spheres on a {} m terrain", balls.len(), extent);
    step_all(&mut balls, &mirror, args.steps)?;

    // A crater 3 m deep just beside the first ball: the stamp reports the rects it changed, and only
    // those go to the mirror (a GPU map would read them back; here they are copied from `map`).
    let Some(first) = balls.first() else {
        return Ok(());
    };
    let at = Vec2::new(first.center.x + 1.0, first.center.z);
    let placement = StampPlacement::new(at, Vec2::splat(16.0), -3.0)?;
    let dirty = apply_stamp(
        &mut map,
        &mut GaussianStamp::default(),
        &placement,
        Blend::Add,
    )?;
    for rect in dirty {
        mirror.apply_next(rect, &read_region(&map, rect)?)?;
    }
    println!("crater at {at}: mirror version {}", mirror.version());
    step_all(&mut balls, &mirror, args.steps)?;
    Ok(())
}

/// Steps every ball `steps` times against the mirror's current snapshot, then prints where
/// each one is and its contact.
fn step_all(balls: &mut [SphereBody], mirror: &CollisionMirror, steps: u32) -> Result<()> {
    let collider = mirror.collider();
    for (i, ball) in balls.iter_mut().enumerate() {
        let mut contact = None;
        for _ in 0..steps {
            contact = ball.step(DT, Vec3::ZERO, &collider)?;
        }
        match contact.or(collider.sphere_contact(ball.center, ball.radius + 1e-3)?) {
            Some(c) => println!(
                "  ball {i}: centre {:.2}, speed {:.2} m/s, touching at {:.2} (normal {:.2}, depth {:.4} m)",
                ball.center,
                ball.velocity.length(),
                c.point,
                c.normal,
                c.depth
            ),
            None => println!("  ball {i}: centre {:.2}, in the air", ball.center),
        }
    }
    Ok(())
}

/// The command line.
struct Args {
    size: u32,
    spheres: u32,
    steps: u32,
}

impl Args {
    fn parse() -> Result<Self> {
        let mut args = Args {
            size: 256,
            spheres: 4,
            steps: 120,
        };
        let mut it = std::env::args().skip(1);
        while let Some(arg) = it.next() {
            let mut value = || it.next().ok_or(format!("{arg} needs a value"));
            match arg.as_str() {
                "--size" => args.size = value()?.parse()?,
                "--spheres" => args.spheres = value()?.parse()?,
                "--steps" => args.steps = value()?.parse()?,
                _ => return Err(format!("unknown argument {arg}").into()),
            }
        }
        Ok(args)
    }
}
