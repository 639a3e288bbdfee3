//! How many vertices the density map saves at equal screen-space error (Cervin 2012, table 4.2:
//! 249 222 / 667 060 = 0.37 and 209 485 / 511 723 = 0.41 at equal triangle width): the
//! adaptive tessellation of two views, an "action" view near the ground and a "terrain" view
//! from above the map's edge, at triangle widths from 0.25 to 64 pixels with the density map on
//! and off (morph off: the mesh's own error), then for each error bound the fewest vertices
//! that meet it either way, and the vertices of the error metric (`max_error_px`) at that bound.
//!
//! `cargo run --release -p terrain-lod --example tessellation_ratio -- [--size N]
//! [--heightmap FILE.png --texel-size M --height-scale M]` (default: the demo's default
//! terrain, 2048 texels of 0.1 m, 0 to 12 m high; a 16-bit PNG DEM with its texel size and
//! metres per stored unit otherwise).

use glam::camera::rh::{proj::directx, view::look_at_mat4};
use glam::{UVec2, Vec2, Vec3};
use terrain_core::io::{ReadLimits, read_png16};
use terrain_core::{
    CoarseMap, HeightEncoding, HeightMap, TerrainParams, WrapMode, generate_coarse_map,
};
use terrain_lod::{CdlodView, DensityMap, DensityParams, Frustum, TessConfig, TessHierarchy};

const WIDTH: f32 = 1280.0;
const HEIGHT: f32 = 720.0;
const FOV_Y: f32 = 1.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (mut size, mut heightmap, mut texel, mut scale) = (2048u32, None, 1.0f32, 1.0f32);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--size" => size = value()?.parse()?,
            "--heightmap" => heightmap = Some(std::path::PathBuf::from(value()?)),
            "--texel-size" => texel = value()?.parse()?,
            "--height-scale" => scale = value()?.parse()?,
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    let map: CoarseMap = match &heightmap {
        Some(path) => {
            let grid = read_png16(path, &ReadLimits::default())?;
            HeightMap::new(
                grid,
                HeightEncoding::new(scale, 0.0)?,
                texel,
                WrapMode::Clamp,
            )?
        }
        None => {
            // The demo's default terrain (terrain-demo's heightmap.rs).
            let defaults = TerrainParams::default();
            let cells = (size / 16 / defaults.base_period).max(1);
            let params = TerrainParams {
                size: UVec2::splat(size),
                seed: 1,
                octaves: (u32::BITS - cells.leading_zeros()).clamp(1, defaults.octaves),
                persistence: 0.4,
                ..defaults
            };
            generate_coarse_map(&params, HeightEncoding::spanning::<u16>(0.0, 12.0)?, 0.1)?
        }
    };
    let extent = map.extent_m();
    let ground = |p: Vec2| {
        let t = (p / map.texel_size()).as_uvec2().min(map.size() - 1);
        map.height_m(t.x, t.y).unwrap_or(0.0)
    };
    let (lo, hi) = map
        .grid()
        .as_slice()
        .iter()
        .fold((u16::MAX, 0), |(a, b), &h| (a.min(h), b.max(h)));
    let relief = (hi - lo) as f32 * map.encoding().scale;
    println!(
        "{} x {} texels of {} m, relief {relief:.1} m",
        map.size().x,
        map.size().y,
        map.texel_size()
    );
    let at = extent * 0.15;
    let views = [
        (
            "action",
            Vec3::new(at.x, ground(at) + (extent.x * 0.001).max(1.7), at.y),
            Vec3::new(extent.x * 0.6, ground(extent * 0.5), extent.y * 0.5),
        ),
        (
            "terrain",
            Vec3::new(-0.1 * extent.x, relief + 0.4 * extent.x, 0.5 * extent.y),
            Vec3::new(0.5 * extent.x, 0.0, 0.5 * extent.y),
        ),
    ];
    let density = DensityMap::from_map(&map, DensityParams::default())?;
    let widths: Vec<f32> = (0..17).map(|i| 0.25 * 2f32.powf(i as f32 * 0.5)).collect();
    for (name, eye, target) in views {
        let proj = directx::perspective(FOV_Y, WIDTH / HEIGHT, 0.1, 1e6);
        let frustum = Frustum::from_view_proj(proj * look_at_mat4(eye, target, Vec3::Y));
        let view = CdlodView {
            camera: eye,
            frustum: Some(&frustum),
            viewport_width: WIDTH,
            hfov: 2.0 * ((FOV_Y * 0.5).tan() * WIDTH / HEIGHT).atan(),
        };
        println!("\n{name} view from {eye} towards {target}");
        println!("width px | vertices on | error on px | vertices off | error off px");
        // (vertices, error) per width with the density map on and off.
        let mut runs = [Vec::new(), Vec::new()];
        for &w in &widths {
            let mut row = Vec::new();
            for (i, use_density) in [true, false].into_iter().enumerate() {
                let config = TessConfig {
                    triangle_width_px: w,
                    use_density,
                    morph: false,
                    max_triangles: 1 << 24,
                    ..TessConfig::default()
                };
                let tess = TessHierarchy::from_map(&map, Some(&density), config)?;
                let Ok(frame) = tess.select(&view) else {
                    row.push("over 2^24 triangles".to_string());
                    continue;
                };
                let e = tess.max_screen_error_px(&frame, &view);
                runs[i].push((frame.vertex_count(), e));
                row.push(format!("{:>9} | {e:>7.3}", frame.vertex_count()));
            }
            println!("{w:>8.2} | {}", row.join(" | "));
        }
        println!(
            "error bound px | fewest vertices on | off | ratio | error metric: vertices, error px, ratio to off"
        );
        for bound in [0.5f32, 1.0, 2.0, 4.0] {
            let config = TessConfig {
                max_error_px: Some(bound),
                morph: false,
                max_triangles: 1 << 24,
                ..TessConfig::default()
            };
            let tess = TessHierarchy::from_map(&map, None, config)?;
            let frame = tess.select(&view)?;
            let (ev, ee) = (
                frame.vertex_count(),
                tess.max_screen_error_px(&frame, &view),
            );
            let fewest =
                |r: &[(u64, f32)]| r.iter().filter(|(_, e)| *e <= bound).map(|(v, _)| *v).min();
            match (fewest(&runs[0]), fewest(&runs[1])) {
                (Some(on), Some(off)) => println!(
                    "{bound:>14} | {on:>18} | {off:>9} | {:.3} | {ev}, {ee:.3}, {:.3}",
                    on as f64 / off as f64,
                    ev as f64 / off as f64
                ),
                _ => println!("{bound:>14} | not reached by the widths tried | {ev}, {ee:.3}"),
            }
        }
    }
    Ok(())
}
