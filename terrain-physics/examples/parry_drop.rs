//! Drop balls and boxes onto tiled parry heightfields of the collision mirror, let them
//! settle, dig a crater under them mid-run, rebuild only the parry tiles the crater touched,
//! and let them settle again.
//!
//! ```text
//! cargo run -p terrain-physics --features parry --example parry_drop -- [--size N] [--tile T] [--steps S]
//! ```
//!
//! `--size`: side of the procedural terrain in texels (default 256, at 0.5 m per texel);
//! `--tile`: cells per parry tile (default 64); `--steps`: 1/60 s steps per phase (default 180).
//!
//! The bodies are rapier-style in shape only: parry's `contact` query and explicit Euler steps
//! (no rotation, no rapier), enough to show the terrain staying current for a physics engine.

use glam::{Vec2, Vec3};
use std::time::Instant;
use terrain_core::{
    Blend, CoarseMap, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams, apply_stamp,
    generate_heights,
};
use terrain_physics::parry3d::math::{Pose, Vector};
use terrain_physics::parry3d::shape::{Ball, Cuboid, Shape};
use terrain_physics::{CollisionMirror, ParryTerrain, STANDARD_GRAVITY, read_region};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Seconds per step.
const DT: f32 = 1.0 / 60.0;

/// A body: a parry shape, translated only.
struct Body {
    name: &'static str,
    shape: Box<dyn Shape>,
    position: Vec3,
    velocity: Vec3,
    touching: bool,
}

impl Body {
    fn pose(&self) -> Pose {
        Pose::from_translation(Vector::new(
            self.position.x,
            self.position.y,
            self.position.z,
        ))
    }

    /// One explicit Euler step: gravity, then the deepest contact resolved by moving out along
    /// its normal and dropping the velocity into the ground (with some friction).
    fn step(&mut self, terrain: &ParryTerrain) -> Result<()> {
        self.velocity.y -= STANDARD_GRAVITY * DT;
        self.position += self.velocity * DT;
        self.touching = false;
        if let Some(c) = terrain.contact(&self.pose(), self.shape.as_ref(), 0.0)?
            && c.dist < 0.0
        {
            // normal1 points from the body into the ground.
            let out = -Vec3::new(c.normal1.x, c.normal1.y, c.normal1.z);
            self.position += out * -c.dist;
            let vn = self.velocity.dot(out);
            if vn < 0.0 {
                self.velocity -= out * vn;
            }
            let tangential = self.velocity - out * self.velocity.dot(out);
            self.velocity -= tangential * (4.0 * DT).min(1.0);
            self.touching = true;
        }
        Ok(())
    }
}

fn main() -> Result<()> {
    let args = Args::parse()?;
    let t0 = Instant::now();

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

    let mirror = CollisionMirror::from_map(&map)?;
    let built = Instant::now();
    let mut terrain = ParryTerrain::new(&mirror.snapshot(), args.tile)?;
    println!(
        "{} x {} parry tiles of {} cells built in {:.1} ms; parry vs bilinear bound {:.3} m",
        terrain.tile_count().x,
        terrain.tile_count().y,
        terrain.tile_size(),
        built.elapsed().as_secs_f64() * 1e3,
        terrain.max_deviation()
    );

    // Two balls and two boxes, 4 m above the ground near the map's centre.
    let centre = map.extent_m() * 0.5;
    let shapes: [(&'static str, Box<dyn Shape>, Vec2); 4] = [
        ("ball 0.5 m", Box::new(Ball::new(0.5)), Vec2::new(-3.0, 0.0)),
        ("ball 1 m", Box::new(Ball::new(1.0)), Vec2::new(3.0, 1.0)),
        (
            "box 1 m",
            Box::new(Cuboid::new(Vector::splat(0.5))),
            Vec2::new(0.0, -3.0),
        ),
        (
            "box 2x0.5x1 m",
            Box::new(Cuboid::new(Vector::new(1.0, 0.25, 0.5))),
            Vec2::new(0.5, 3.5),
        ),
    ];
    let collider = mirror.collider();
    let mut bodies = Vec::new();
    for (name, shape, offset) in shapes {
        let xz = centre + offset;
        let ground = collider.height(xz)?;
        bodies.push(Body {
            name,
            shape,
            position: Vec3::new(xz.x, ground + 4.0, xz.y),
            velocity: Vec3::ZERO,
            touching: false,
        });
    }

    println!("dropping {} bodies", bodies.len());
    run(&mut bodies, &terrain, args.steps)?;

    // A crater 3 m deep under the bodies: the stamp reports the rects it changed; they go to
    // the mirror (a GPU map would read them back) and then to the parry tiles.
    let placement = StampPlacement::new(centre, Vec2::splat(20.0), -3.0)?;
    let dirty = apply_stamp(
        &mut map,
        &mut GaussianStamp::default(),
        &placement,
        Blend::Add,
    )?;
    for &rect in &dirty {
        mirror.apply_next(rect, &read_region(&map, rect)?)?;
    }
    let updated = Instant::now();
    let rebuilt = terrain.update(&mirror.snapshot(), &dirty)?;
    println!(
        "crater at {centre}: mirror version {}, {} of {} parry tiles rebuilt in {:.2} ms",
        mirror.version(),
        rebuilt.len(),
        terrain.tiles().len(),
        updated.elapsed().as_secs_f64() * 1e3
    );
    run(&mut bodies, &terrain, args.steps)?;

    // Every body rests on the new surface: parry's ray down agrees with the crate's own ground
    // within the bound.
    let collider = mirror.collider();
    for b in &bodies {
        let xz = Vec2::new(b.position.x, b.position.z);
        let hit = terrain.cast_ray(b.position + Vec3::Y * 20.0, Vec3::NEG_Y, 100.0)?;
        let bilinear = collider.height(xz)?;
        if let Some(hit) = hit {
            println!(
                "{:>14}: ground under it parry {:.3} m, bilinear {:.3} m",
                b.name, hit.point.y, bilinear
            );
        }
    }
    println!("done in {:.0} ms", t0.elapsed().as_secs_f64() * 1e3);
    Ok(())
}

/// Steps every body `steps` times, then prints where each one is.
fn run(bodies: &mut [Body], terrain: &ParryTerrain, steps: u32) -> Result<()> {
    for _ in 0..steps {
        for b in bodies.iter_mut() {
            b.step(terrain)?;
        }
    }
    for b in bodies.iter() {
        println!(
            "{:>14}: at ({:7.2}, {:6.2}, {:7.2}), speed {:.2} m/s, {}",
            b.name,
            b.position.x,
            b.position.y,
            b.position.z,
            b.velocity.length(),
            if b.touching {
                "on the ground"
            } else {
                "in the air"
            }
        );
    }
    Ok(())
}

/// Command-line arguments.
struct Args {
    size: u32,
    tile: u32,
    steps: u32,
}

impl Args {
    fn parse() -> Result<Self> {
        let mut args = Args {
            size: 256,
            tile: 64,
            steps: 180,
        };
        let mut it = std::env::args().skip(1);
        while let Some(flag) = it.next() {
            let mut value = || -> Result<u32> {
                Ok(it
                    .next()
                    .ok_or_else(|| format!("{flag} needs a value"))?
                    .parse()?)
            };
            match flag.as_str() {
                "--size" => args.size = value()?,
                "--tile" => args.tile = value()?,
                "--steps" => args.steps = value()?,
                other => return Err(format!("unknown argument {other}").into()),
            }
        }
        Ok(args)
    }
}
