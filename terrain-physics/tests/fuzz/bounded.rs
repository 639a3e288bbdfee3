//! Classes of `BoundedGround`: the collider's queries under pending deformations, near the
//! map and far from it.

use crate::fields::{Ctx, Field};
use crate::inputs::{any_pos, check_contact, near_height, near_pos, sphere_reach, timed};
use crate::{FAR_TEXELS, REACH_TEXELS};
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::Rect;
use terrain_physics::{BoundedGround, DeformationBound, GroundQuery, PendingDeformation};
use terrain_test_support::fuzz::{Case, Rng, finite_f32};

/// Up to five pending deformations: rects anywhere in `i32`, of any size, bounds up to
/// `f32::MAX`.
pub(crate) fn pending(rng: &mut Rng, f: &Field) -> Vec<PendingDeformation> {
    (0..rng.range_u32(0, 5))
        .map(|_| {
            let min = if rng.chance(1, 2) {
                IVec2::new(
                    rng.range_u32(0, 2 * f.size.x) as i32 - f.size.x as i32,
                    rng.range_u32(0, 2 * f.size.y) as i32 - f.size.y as i32,
                )
            } else {
                IVec2::new(rng.u32_edge() as i32, rng.u32_edge() as i32)
            };
            let size = if rng.chance(1, 2) {
                UVec2::new(rng.range_u32(0, 8), rng.range_u32(0, 8))
            } else {
                UVec2::new(rng.u32_edge(), rng.u32_edge())
            };
            let b = |rng: &mut Rng| match rng.below(3) {
                0 => 0.0,
                1 => rng.f32_edge().abs(),
                _ => rng.uniform(0.0, 10.0) as f32,
            };
            PendingDeformation {
                rect: Rect::new(min, size),
                bound: DeformationBound::new(b(rng), b(rng)).expect("finite, >= 0"),
            }
        })
        .collect()
}

/// Every query of a BoundedGround at `p` / a sphere at `c` of radius `r`.
fn bounded_queries(
    f: &Field,
    pend: &[PendingDeformation],
    extra: &[PendingDeformation],
    p: Vec2,
    c: Vec3,
    r: f32,
    case: &mut Case,
) -> Result<(), String> {
    let g = BoundedGround::new(&f.collider, pend, extra);
    let finite = |what: &str, r: Result<f32, terrain_physics::PhysicsError>| {
        r.map_err(|e| format!("{what}: finite input refused: {e}"))
    };
    let a = finite("raise_at", timed("raise_at", || g.raise_at(p))?)?;
    if a.is_nan() || a < 0.0 {
        return Err(format!("raise_at {p} is {a}"));
    }
    let u = finite("raise_under", timed("raise_under", || g.raise_under(c, r))?)?;
    if u.is_nan() || u < 0.0 {
        return Err(format!("raise_under {c} r {r} is {u}"));
    }
    let (lo, hi) = timed("height_interval", || g.height_interval(p))?
        .map_err(|e| format!("height_interval: finite input refused: {e}"))?;
    if lo > hi {
        return Err(format!("height_interval at {p} is ({lo}, {hi})"));
    }
    finite(
        "ground_height",
        timed("ground_height", || g.ground_height(p))?,
    )?;
    timed("ground_normal", || g.ground_normal(p))?
        .map_err(|e| format!("ground_normal: finite input refused: {e}"))?;
    let got = timed("ground_contact", || g.ground_contact(c, r))?;
    if !(c.y - u).is_finite() {
        // The contact is asked of the centre lowered by the pending raise, which overflows.
        if let Err(e) = &got {
            case.note(|| format!("ground_contact at {c} lowered by a pending raise of {u}: {e}"));
            return Ok(());
        }
    }
    check_contact("ground_contact", got, case)
}

/// BoundedGround near the map: positions not far, spheres within [`REACH_TEXELS`] (lifted
/// by the pending raise, so the reach is measured from the lifted centre too).
pub(crate) fn bounded_ground_near(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let pend = pending(rng, f);
    let extra = pending(rng, f);
    let p = near_pos(f, rng);
    let q = near_pos(f, rng);
    let c = Vec3::new(q.x, near_height(f, q.x, q.y, 16.0, rng), q.y);
    let r = finite_f32(rng.uniform(0.0, 8.0) * f.ts);
    // The contact is asked of the centre lowered by the summed raise of the deformations.
    let raise: f64 = pend
        .iter()
        .chain(&extra)
        .map(|d| f64::from(d.bound.raise))
        .sum();
    let lowered = Vec3::new(c.x, finite_f32(f64::from(c.y) - raise), c.z);
    let spans_far = [-r, r]
        .iter()
        .any(|&o| f.is_far(c.x + o, c.z + o) || f.is_far(c.x - o, c.z + o));
    if sphere_reach(f, c, r) > REACH_TEXELS
        || sphere_reach(f, lowered, r) > REACH_TEXELS
        || f.is_far(p.x, p.y)
        || spans_far
    {
        case.skipped = true;
        return Ok(()); // the domain of bounded_ground_far and the sphere classes
    }
    case.show(|| {
        format!(
            "field {}, pending {pend:?} + {extra:?}, p {p:?}, c {c:?}, r {r:e}",
            f.label
        )
    });
    bounded_queries(f, &pend, &extra, p, c, r, case)
}

/// Defect 3: BoundedGround queries far outside the map, or with a radius spanning far.
pub(crate) fn bounded_ground_far(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let pend = pending(rng, f);
    let mut p = any_pos(f, rng);
    if !f.is_far(p.x, p.y) {
        p.x = finite_f32(
            FAR_TEXELS * rng.uniform(1.0, 64.0) * f.ts * if rng.chance(1, 2) { 1.0 } else { -1.0 },
        );
    }
    let c = Vec3::new(p.x, finite_f32(f.surface(p.x, p.y) + f.ts), p.y);
    let r = if rng.chance(1, 2) {
        finite_f32(FAR_TEXELS * 2.0 * f.ts)
    } else {
        finite_f32(rng.uniform(0.0, 2.0) * f.ts)
    };
    if !f.is_far(p.x, p.y) {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| {
        format!(
            "field {}, pending {pend:?}, p {p:?}, c {c:?}, r {r:e}",
            f.label
        )
    });
    let g = BoundedGround::new(&f.collider, &pend, &[]);
    let p3 = Vec3::new(p.x, 0.0, p.y);
    let overflow = f.overflows(p3) || f.overflows(c);
    let ok = |what: &str, r: Result<(), terrain_physics::PhysicsError>| match r {
        Err(e) if !overflow => Err(format!("{what}: finite input refused: {e}")),
        _ => Ok(()),
    };
    ok("raise_at", timed("raise_at", || g.raise_at(p))?.map(|_| ()))?;
    ok(
        "raise_under",
        timed("raise_under", || g.raise_under(c, r))?.map(|_| ()),
    )?;
    ok(
        "height_interval",
        timed("height_interval", || g.height_interval(p))?.map(|_| ()),
    )?;
    ok(
        "ground_height",
        timed("ground_height", || g.ground_height(p))?.map(|_| ()),
    )?;
    Ok(())
}
