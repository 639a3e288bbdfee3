//! Classes of `CollisionWindow` (any world size, centre and update rect, a fill callback or a
//! `WindowSource` that sometimes fails) and of field construction (any grid, encoding and
//! texel size).

use crate::REACH_TEXELS;
use crate::fields::{Ctx, Field};
use crate::inputs::{any_f32, near_pos, sphere_reach, timed};
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect, WindowSource};
use terrain_physics::{CollisionMirror, CollisionWindow, HeightField};
use terrain_test_support::fuzz::{Case, Rng, finite_f32};

/// A window over a world of any valid or invalid size, moved to any finite centre (by
/// `recenter`, or `follow` with stand-ins and improved rects anywhere), refreshed and updated
/// with rects anywhere in `i32` of any size, filled by a callback that sometimes fails; its
/// height, `contains` and `ground` asked anywhere (a ground is a height inside the window).
pub(crate) fn collision_window(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let verbose = case.verbose();
    let rng = &mut case.rng;
    let side = if rng.chance(1, 8) {
        rng.u32_edge()
    } else {
        rng.range_u32(16, 160)
    };
    let world = if rng.chance(1, 4) {
        UVec2::new(rng.u32_edge(), rng.u32_edge())
    } else {
        UVec2::new(rng.range_u32(1, 400), rng.range_u32(1, 400))
    };
    let ts = match rng.below(3) {
        0 => any_f32(rng),
        1 => rng.pick(&[f32::MIN_POSITIVE, 1e-30, 0.5, 1e30, f32::MAX]),
        _ => 0.5,
    };
    let enc = HeightEncoding::new(0.01, 0.0).expect("encoding");
    if verbose {
        eprintln!("window side {side}, world {world}, texel {ts:e}");
    }
    // Valid sides are kept small (a window of 8192^2 is 256 MiB); invalid ones go as they are.
    let side = if side > terrain_physics::MAX_WINDOW_SIDE {
        side
    } else {
        side.min(512)
    };
    let w = match timed("CollisionWindow::new", || {
        CollisionWindow::new(side, world, enc, ts)
    })? {
        Ok(w) => w,
        Err(_) => return Ok(()),
    };
    let mut w = w;
    let any_rect = |rng: &mut Rng| {
        let min = if rng.chance(1, 2) {
            IVec2::new(
                rng.range_u32(0, 500) as i32 - 50,
                rng.range_u32(0, 500) as i32 - 50,
            )
        } else {
            IVec2::new(rng.u32_edge() as i32, rng.u32_edge() as i32)
        };
        let size = if rng.chance(1, 2) {
            UVec2::new(rng.range_u32(0, 64), rng.range_u32(0, 64))
        } else {
            UVec2::new(rng.u32_edge(), rng.u32_edge())
        };
        Rect::new(min, size)
    };
    let mut source = FlakySource {
        fail: false,
        stand_in_below: 0,
        improved: Vec::new(),
    };
    for _ in 0..rng.range_u32(1, 5) {
        let center = Vec2::new(any_f32(rng), any_f32(rng));
        let fail = rng.chance(1, 6);
        match rng.below(6) {
            0 | 1 => {
                let r = timed("recenter", || {
                    w.recenter(center, |rect, out: &mut Grid<u16>| {
                        if fail {
                            return Err("fill failed");
                        }
                        if out.size() != rect.size {
                            return Err("wrong out size");
                        }
                        out.as_mut_slice().fill((rect.min.x as u16) ^ 0x5a5a);
                        Ok(())
                    })
                })?;
                if let Err(terrain_physics::WindowError::Fill("wrong out size")) = r {
                    return Err("recenter handed a buffer of the wrong size".into());
                }
            }
            2 => {
                let rect = any_rect(rng);
                timed("refresh", || {
                    w.refresh(rect, |_, out: &mut Grid<u16>| {
                        out.as_mut_slice().fill(7);
                        if fail { Err(()) } else { Ok(()) }
                    })
                })?
                .ok();
            }
            3 => {
                let rect = any_rect(rng);
                // Heights of the rect's size only when small enough to allocate.
                let grid = if rect.area() <= 1 << 16 && !rect.is_empty() {
                    Grid::new(rect.size.x, rect.size.y, 9u16).expect("small grid")
                } else {
                    Grid::new(3, 2, 9u16).expect("grid")
                };
                let _ = timed("apply", || w.apply(rect, &grid))?;
            }
            4 => {
                let _ = timed("window_at", || w.window_at(center))?;
            }
            _ => {
                source.fail = fail;
                source.stand_in_below = rng.range_u32(0, 500) as i32 - 50;
                source.improved = (0..rng.below(4)).map(|_| any_rect(rng)).collect();
                let r = timed("follow", || w.follow(center, &mut source))?;
                if let Err(terrain_physics::WindowError::Fill("wrong out size")) = r {
                    return Err("follow handed a buffer of the wrong size".into());
                }
            }
        }
        let p = Vec2::new(any_f32(rng), any_f32(rng));
        let inside = timed("contains", || w.contains(p))?;
        let h = timed("height", || w.height(p))?
            .map_err(|e| format!("window height at {p}: finite input refused: {e}"))?;
        if h.is_some() != inside {
            return Err(format!("height at {p} is {h:?} but contains says {inside}"));
        }
        let ground = timed("ground", || w.ground(p, |t| source.is_stand_in(t)))?
            .map_err(|e| format!("window ground at {p}: finite input refused: {e}"))?;
        if ground.is_some() && (!inside || ground != h) {
            return Err(format!("ground at {p} is {ground:?}, height {h:?}"));
        }
    }
    Ok(())
}

/// A source for `CollisionWindow::follow`: stand-ins left of a column, improved rects handed
/// once, fills that fail while `fail`.
struct FlakySource {
    fail: bool,
    stand_in_below: i32,
    improved: Vec<Rect>,
}

impl WindowSource for FlakySource {
    type Error = &'static str;

    fn fill(&mut self, rect: Rect, out: &mut Grid<u16>) -> Result<(), Self::Error> {
        if self.fail {
            return Err("fill failed");
        }
        if out.size() != rect.size {
            return Err("wrong out size");
        }
        out.as_mut_slice().fill((rect.min.y as u16) ^ 0x3c3c);
        Ok(())
    }

    fn improved(&mut self, _window: Option<Rect>) -> Vec<Rect> {
        std::mem::take(&mut self.improved)
    }

    fn is_stand_in(&self, texel: UVec2) -> bool {
        i64::from(texel.x) < i64::from(self.stand_in_below)
    }
}

/// Fields built from small random grids with any texel size and encoding (invalid ones must
/// be errors), moved anywhere, then asked a height, a normal, a short ray down and a small
/// sphere near the map.
pub(crate) fn field_construction(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let verbose = case.verbose();
    let rng = &mut case.rng;
    let (w, h) = (rng.range_u32(1, 9), rng.range_u32(1, 9));
    let grid = Grid::from_fn(w, h, |_, _| rng.next_u32() as u16).expect("grid");
    let ts = if rng.chance(1, 2) {
        any_f32(rng)
    } else {
        rng.f32_edge().abs()
    };
    let (scale, offset) = (any_f32(rng), any_f32(rng));
    if verbose {
        eprintln!(
            "{w}x{h} {:?}, texel {ts:e}, scale {scale:e}, offset {offset:e}",
            grid.as_slice()
        );
    }
    let enc = match HeightEncoding::new(scale, offset) {
        Ok(e) => e,
        // Drawn finite: only a scale of 0 or below is refused.
        Err(_) if scale <= 0.0 => return Ok(()),
        Err(e) => return Err(format!("encoding {scale}, {offset} refused: {e}")),
    };
    let built = timed("HeightField::new", || {
        HeightField::new(grid.clone(), enc, ts)
    })?;
    let field = match built {
        Ok(f) => f,
        // Drawn finite: only a texel size of 0 or below is refused.
        Err(_) if ts <= 0.0 => return Ok(()),
        Err(e) => return Err(format!("texel size {ts:e} refused: {e}")),
    };
    if ts <= 0.0 {
        return Err(format!("texel size {ts:e} accepted"));
    }
    let map = CoarseMap::coarse(grid, enc, ts).map_err(|e| e.to_string())?;
    let _ = timed("CollisionMirror::from_map", || {
        CollisionMirror::from_map(&map)
    })?;
    let t = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)) * rng.pick(&[0.0, 1.0]);
    let f = Field::new("constructed".into(), field.heights().clone(), enc, ts, t);
    let p = near_pos(&f, rng);
    let _ = timed("height", || f.collider.height(p))?;
    let _ = timed("normal", || f.collider.normal(p))?;
    if f.is_far(p.x, p.y) {
        return Ok(());
    }
    let top = Vec3::new(p.x, finite_f32(f.hi + f.ts), p.y);
    let down = finite_f32((f.hi - f.lo) + 2.0 * f.ts);
    if verbose {
        eprintln!("translation {t}, height/normal at {p}, raycast from {top} down {down:e}");
    }
    let _ = timed("raycast", || f.collider.raycast(top, Vec3::NEG_Y, down))?;
    let c = Vec3::new(p.x, finite_f32(f.surface(p.x, p.y) + 0.5 * f.ts), p.y);
    let r = finite_f32(f.ts);
    if sphere_reach(&f, c, r) <= REACH_TEXELS && !f.is_far(c.x, c.z) {
        if verbose {
            eprintln!(
                "sphere at {c} radius {r:e} (reach {} texels, surface {})",
                sphere_reach(&f, c, r),
                f.surface(c.x, c.z)
            );
        }
        let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
        if let Err(e) = got
            && c.is_finite()
            && !f.overflows(c)
        {
            return Err(format!("sphere_contact: finite input refused: {e}"));
        }
    }
    Ok(())
}
