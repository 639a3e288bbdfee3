//! Sphere contact against the heightfield: the local-space query
//! ([`HeightField::contact_local_sphere`]) and its [`Contact`].
//!
//! The contact is found from the closest point of the bilinear surface to the sphere's centre.
//! The ground is solid: a centre above the surface touches when that distance is below the
//! radius; a centre below the surface is always in contact, and the depth then counts the
//! distance back up to the surface as well. Cells are visited around the centre and skipped
//! when a lower bound of their distance already exceeds the best found: the larger of the gap
//! to the cell's box (horizontal gap, corner height range) and the gap to the slab between two
//! parallel planes that holds the patch; within a cell the patch is a family of straight
//! segments (fixed `v`, varying `u`), so the closest point on each segment is exact and only
//! `v` is searched (9 samples, then Brent's parabolic / golden-section refinement to about
//! 1e-9 of a cell).

use crate::field::{HeightField, Patch};
use glam::{DVec3, Vec3};

/// How a sphere touches the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// The closest point of the surface to the sphere's centre.
    pub point: Vec3,
    /// Unit direction to move the sphere out of the ground (from the surface towards the
    /// centre when the centre is above ground).
    pub normal: Vec3,
    /// How far to move the sphere along `normal` until it just touches: `radius - distance`
    /// above ground, `radius + distance` below (always > 0 for a reported contact, except a
    /// zero-radius sphere exactly on the surface, which reports none).
    pub depth: f32,
}

/// Samples of `v` per cell before the refinement.
const V_SAMPLES: usize = 8;
/// Newton step (in cells of `v`) below which the convex patch search stops.
const NEWTON_TOLERANCE: f64 = 1e-12;
/// Most Newton or bisection steps of the convex patch search (each keeps `v` inside a
/// bracket that bisection halves; Newton's method converges in about 4).
const NEWTON_STEPS: usize = 64;
/// Width of `v` (in cells) at which the refinement stops.
const V_TOLERANCE: f64 = 1e-9;
/// Most refinement steps: Brent's method needs about 10 on a smooth patch, and a golden step
/// at least every other step shrinks the bracket (a quarter of a cell) below the tolerance in
/// under 90, so this bounds the time without cutting a search short.
const REFINE_STEPS: usize = 100;

impl HeightField {
    /// The contact of a sphere at local `center` with `radius` (>= 0) against the surface, or
    /// `None` if they do not touch. Cells cut away ([`HeightField::with_holes`]) are no
    /// surface: a sphere over a hole touches only the ground around it. Inputs must be finite
    /// and the radius not negative ([`HeightfieldCollider::sphere_contact`] checks them);
    /// other inputs give `None`.
    ///
    /// Cost: the cells under the sphere (radius / texel size squared), or for a centre below
    /// ground, the cells within its depth below the surface; at most one period of the
    /// repeating field (its width x height cells), however large the radius or the depth.
    ///
    /// [`HeightfieldCollider::sphere_contact`]: crate::HeightfieldCollider::sphere_contact
    pub fn contact_local_sphere(&self, center: Vec3, radius: f32) -> Option<Contact> {
        if !(center.is_finite() && radius.is_finite() && radius >= 0.0) {
            return None;
        }
        let c = center.as_dvec3();
        let r = f64::from(radius);
        let (_, hi) = self.height_bounds();
        if c.y - r > f64::from(hi) + 1e-6 {
            return None;
        }
        let closest = self.closest_point_local(center, r)?;
        let (p, dist, normal_at_p) = (closest.point, closest.distance, closest.normal);
        let (depth, normal) = if closest.below {
            let n = if dist > 1e-12 {
                (p - c) / dist
            } else {
                normal_at_p
            };
            (r + dist, n)
        } else {
            if dist >= r {
                return None;
            }
            let n = if dist > 1e-12 {
                (c - p) / dist
            } else {
                normal_at_p
            };
            (r - dist, n)
        };
        Some(Contact {
            point: p.as_vec3(),
            normal: normal.as_vec3(),
            depth: depth as f32,
        })
    }

    /// The closest surface point to `q`, searched within `radius` above ground and within the
    /// depth below ground (the point straight above or below is always a candidate).
    fn closest_point_local(&self, q: Vec3, radius: f64) -> Option<Closest> {
        // The field repeats: search around the centre moved into the first period, and move
        // the point found back.
        let (px, pz) = self.period_m();
        let q = q.as_dvec3();
        let (cx, shift_x) = crate::field::reduce(q.x, px);
        let (cz, shift_z) = crate::field::reduce(q.z, pz);
        let mut best = self.closest_point_reduced(DVec3::new(cx, q.y, cz), radius)?;
        best.point += DVec3::new(shift_x, 0.0, shift_z);
        Some(best)
    }

    /// [`closest_point_local`](Self::closest_point_local) for a centre in the first period.
    fn closest_point_reduced(&self, c: DVec3, radius: f64) -> Option<Closest> {
        let ts = f64::from(self.texel_size());
        // The patch under the centre decides above / below, in the same f64 arithmetic as the
        // search.
        let cell = (c.x / ts).floor();
        let row = (c.z / ts).floor();
        let under = self.patch(cell as i64, row as i64);
        let h_c = under.height(c.x / ts - cell, c.z / ts - row);
        // Over a hole nothing is below ground, and the point straight below is no candidate.
        let over_hole = self.hole_cell(cell as i64, row as i64);
        let below = c.y < h_c && !over_hole;
        let mut best = Closest {
            point: DVec3::new(c.x, h_c, c.z),
            distance: if over_hole {
                f64::INFINITY
            } else {
                (h_c - c.y).abs()
            },
            normal: under.normal(c.x / ts - cell, c.z / ts - row, ts),
            below,
        };
        // Above ground only distances below the radius matter; below ground the closest point
        // is no farther than the surface straight above.
        let reach = if below {
            best.distance
        } else {
            best.distance.min(radius)
        };
        // The field repeats, and a surface point's nearest copy to the centre lies within half
        // a period of it on each axis (a farther copy has the same height and a larger gap):
        // so the reach is clamped to half a period per axis. The search covers at most one
        // period (and a cell) of cells, whatever the reach (a sphere far below ground or a
        // huge radius): bounded by the map, not by the input, and exact.
        let (px, pz) = self.period_m();
        let (rx, rz) = (reach.min(0.5 * px), reach.min(0.5 * pz));
        let x_lo = ((c.x - rx) / ts).floor() as i64;
        let x_hi = ((c.x + rx) / ts).floor() as i64;
        let z_lo = ((c.z - rz) / ts).floor() as i64;
        let z_hi = ((c.z + rz) / ts).floor() as i64;
        let mut best_d2 = best.distance * best.distance;
        let inv_ts2 = 1.0 / (ts * ts);
        let visit = |ix: i64, iz: i64, best: &mut Closest, best_d2: &mut f64| {
            if self.hole_cell(ix, iz) {
                return;
            }
            let patch = self.patch(ix, iz);
            let (x0, z0) = (ix as f64 * ts, iz as f64 * ts);
            let gx = (x0 - c.x).max(c.x - (x0 + ts)).max(0.0);
            let gz = (z0 - c.z).max(c.z - (z0 + ts)).max(0.0);
            let gy = (patch.min - c.y).max(c.y - patch.max).max(0.0);
            let box_d2 = gx * gx + gz * gz + gy * gy;
            let local = DVec3::new(c.x - x0, c.y, c.z - z0);
            // The patch is the plane a + b u + c v raised by d u v, which lies between 0 and
            // d: the gap to that slab along the plane's normal bounds the distance too, and
            // prunes the cells beside the centre that the box bound keeps on a slope.
            let (u, v) = (local.x / ts, local.z / ts);
            let s = local.y - (patch.a + patch.b * u + patch.c * v);
            let gap = (s - patch.d.max(0.0)).max(patch.d.min(0.0) - s).max(0.0);
            let slab_d2 = gap * gap / (1.0 + (patch.b * patch.b + patch.c * patch.c) * inv_ts2);
            if box_d2.max(slab_d2) >= *best_d2 {
                return;
            }
            let (u, v, d2) = closest_on_patch(&patch, local, ts);
            if d2 < *best_d2 {
                *best_d2 = d2;
                best.point = DVec3::new(x0 + u * ts, patch.height(u, v), z0 + v * ts);
                best.distance = d2.sqrt();
                best.normal = patch.normal(u, v, ts);
            }
        };
        // The cell under the centre first, so the bound prunes the rest early.
        let (cell, row) = (cell as i64, row as i64);
        visit(cell, row, &mut best, &mut best_d2);
        for iz in z_lo..=z_hi {
            for ix in x_lo..=x_hi {
                // That cell's closest point is already the best or beaten by it.
                if (ix, iz) != (cell, row) {
                    visit(ix, iz, &mut best, &mut best_d2);
                }
            }
        }
        Some(best)
    }
}

/// The closest point found so far.
#[derive(Debug, Clone, Copy)]
struct Closest {
    point: DVec3,
    distance: f64,
    normal: DVec3,
    below: bool,
}

/// The closest point of a cell's patch to `q` (cell-local metres: the cell spans
/// `[0, ts] x [0, ts]` in X and Z): returns `(u, v, squared distance)`.
fn closest_on_patch(patch: &Patch, q: DVec3, ts: f64) -> (f64, f64, f64) {
    // The squared distance's Hessian in (u, v) is 2 (ts^2 I + g g^T) (g the slope) plus
    // 2 (h - q.y) d [[0, 1], [1, 0]]: positive definite while |h - q.y| |d| < ts^2 on the whole
    // patch (h lies between its corners). There the distance is convex, so is its minimum
    // over u as a function of v, and its one minimum needs no samples (half ts^2: a margin
    // for rounding).
    let reach = (patch.max - q.y).abs().max((patch.min - q.y).abs());
    if reach * patch.d.abs() < 0.5 * ts * ts {
        return closest_on_convex_patch(patch, q, ts);
    }
    // For fixed v the patch is the segment S(u) = A(v) + u B(v), u in [0, 1].
    let on_segment = |v: f64| -> (f64, f64) {
        let a = DVec3::new(0.0, patch.a + patch.c * v, v * ts);
        let b = DVec3::new(ts, patch.b + patch.d * v, 0.0);
        let w = q - a;
        let u = (w.dot(b) / b.length_squared()).clamp(0.0, 1.0);
        (u, (w - b * u).length_squared())
    };
    let sample = |i: usize| i as f64 / V_SAMPLES as f64;
    let d2s: [f64; V_SAMPLES + 1] = std::array::from_fn(|i| on_segment(sample(i)).1);
    let mut best_i = 0;
    for (i, &d2) in d2s.iter().enumerate() {
        if d2 < d2s[best_i] {
            best_i = i;
        }
    }
    // Brent's minimisation in the bracket around the best sample, from that sample and its
    // neighbours (their distances are known, so the first step is already parabolic).
    let (i_lo, i_hi) = (best_i.saturating_sub(1), (best_i + 1).min(V_SAMPLES));
    let (v_ref, d_ref) = brent(
        &|v| on_segment(v).1,
        sample(i_lo),
        sample(i_hi),
        (sample(best_i), d2s[best_i]),
        [(sample(i_lo), d2s[i_lo]), (sample(i_hi), d2s[i_hi])],
    );
    let (u_ref, _) = on_segment(v_ref);
    (u_ref, v_ref, d_ref)
}

/// [`closest_on_patch`] where the squared distance is convex over the patch: Newton's method
/// on its derivative along `v` (with `u` at the segment's closest point, where the derivative
/// along `u` is 0 or `u` is clamped), kept inside a shrinking bracket by bisection, from the
/// foot of the perpendicular on the plane through the patch.
fn closest_on_convex_patch(p: &Patch, q: DVec3, ts: f64) -> (f64, f64, f64) {
    let ts2 = ts * ts;
    // At `v`: the segment's closest `u`, half the derivative of the squared distance along
    // `v` and that half's own derivative (along the curve of closest points).
    let at = |v: f64| -> (f64, f64, f64) {
        let hu = p.b + p.d * v;
        let base = p.a + p.c * v - q.y;
        let auu = ts2 + hu * hu;
        let free = (q.x * ts - base * hu) / auu;
        let u = free.clamp(0.0, 1.0);
        let hv = p.c + p.d * u;
        let e = base + hu * u;
        let g = e * hv + ts * (v * ts - q.z);
        let avv = ts2 + hv * hv;
        let slope = if u == free {
            let auv = hu * hv + e * p.d;
            avv - auv * auv / auu
        } else {
            avv
        };
        (u, g, slope)
    };
    let n2 = 1.0 + (p.b * p.b + p.c * p.c) / ts2;
    let s = q.y - (p.a + (p.b * q.x + p.c * q.z) / ts);
    let mut v = ((q.z + s * p.c / (ts * n2)) / ts).clamp(0.0, 1.0);
    let (mut u, mut g, mut slope) = at(v);
    // The bracket holds the minimum; an end counts as known once its derivative's sign is
    // (below the minimum negative, above it positive).
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    let (mut lo_known, mut hi_known) = (false, false);
    for _ in 0..NEWTON_STEPS {
        if g > 0.0 {
            if v <= 0.0 {
                break;
            }
            (hi, hi_known) = (v, true);
        } else if g < 0.0 {
            if v >= 1.0 {
                break;
            }
            (lo, lo_known) = (v, true);
        } else {
            break;
        }
        let mut next = v - g / slope;
        if !(next > lo && next < hi) {
            // Past an end not yet tried: the minimum may be that end; else bisect.
            next = if next <= lo && !lo_known {
                lo
            } else if next >= hi && !hi_known {
                hi
            } else {
                0.5 * (lo + hi)
            };
        }
        let done = (next - v).abs() <= NEWTON_TOLERANCE;
        v = next;
        (u, g, slope) = at(v);
        if done {
            break;
        }
    }
    let w = DVec3::new(q.x - u * ts, q.y - p.height(u, v), q.z - v * ts);
    (u, v, w.length_squared())
}

/// Brent's minimisation of `f` over `[a, b]` (Brent 1973, ch. 5: parabolic steps through the
/// three best points, golden-section steps where a parabola is not trusted), from the point
/// `x` and two more known points `others`, to [`V_TOLERANCE`] or [`REFINE_STEPS`] steps.
/// Returns the best point found and its value (never worse than `x`).
fn brent(
    f: &impl Fn(f64) -> f64,
    mut a: f64,
    mut b: f64,
    (mut x, mut fx): (f64, f64),
    others: [(f64, f64); 2],
) -> (f64, f64) {
    // The golden-section fraction (3 - sqrt 5) / 2.
    const GOLD: f64 = 0.381_966_011_250_105_1;
    // The second and third best points (w, then v), from those given.
    let [(mut w, mut fw), (mut v, mut fv)] = if others[0].1 <= others[1].1 {
        others
    } else {
        [others[1], others[0]]
    };
    // `e` is the step before last: the bracket's width lets the first step be parabolic.
    let (mut d, mut e) = (0.0_f64, b - a);
    let tol = 0.5 * V_TOLERANCE;
    for _ in 0..REFINE_STEPS {
        let xm = 0.5 * (a + b);
        if (x - xm).abs() <= 2.0 * tol - 0.5 * (b - a) {
            break;
        }
        let golden = |x: f64| if x >= xm { a - x } else { b - x };
        let mut parabolic = false;
        if e.abs() > tol {
            let r = (x - w) * (fx - fv);
            let q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            let mut q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            // A parabola is taken only inside the bracket and moving less than half the step
            // before last (otherwise it may crawl).
            if p.abs() < (0.5 * q * e).abs() && p > q * (a - x) && p < q * (b - x) {
                e = d;
                d = p / q;
                let u = x + d;
                if u - a < 2.0 * tol || b - u < 2.0 * tol {
                    d = tol.copysign(xm - x);
                }
                parabolic = true;
            }
        }
        if !parabolic {
            e = golden(x);
            d = GOLD * e;
        }
        let u = if d.abs() >= tol {
            x + d
        } else {
            x + tol.copysign(d)
        };
        let fu = f(u);
        if fu <= fx {
            if u >= x {
                a = x;
            } else {
                b = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    (x, fx)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;
    use terrain_core::{Grid, HeightEncoding};

    fn flat(raw: u16) -> HeightField {
        let g = Grid::new(8, 8, raw).expect("grid");
        HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("field")
    }

    #[test]
    fn sphere_on_flat_ground() {
        let f = flat(200); // 2 m
        let c = f
            .contact_local_sphere(Vec3::new(3.5, 2.4, 4.5), 0.5)
            .expect("contact");
        assert!((c.depth - 0.1).abs() < 1e-5, "{c:?}");
        assert!((c.normal - Vec3::Y).length() < 1e-5);
        assert!((c.point - Vec3::new(3.5, 2.0, 4.5)).length() < 1e-5);
        assert!(
            f.contact_local_sphere(Vec3::new(3.5, 2.6, 4.5), 0.5)
                .is_none()
        );
    }

    #[test]
    fn centre_below_ground_is_pushed_up_past_the_surface() {
        let f = flat(200);
        let c = f
            .contact_local_sphere(Vec3::new(1.2, 1.0, 6.9), 0.5)
            .expect("contact");
        assert!((c.depth - 1.5).abs() < 1e-5, "{c:?}");
        assert!((c.normal - Vec3::Y).length() < 1e-5);
    }

    #[test]
    fn zero_radius_on_the_surface_is_no_contact() {
        let f = flat(200);
        assert!(
            f.contact_local_sphere(Vec3::new(1.0, 2.0, 1.0), 0.0)
                .is_none()
        );
        assert!(
            f.contact_local_sphere(Vec3::new(1.0, 1.0, 1.0), -1.0)
                .is_none()
        );
    }

    /// Rough ground over 64 x 64 texels of `ts` metres: random heights 0..`amp_raw` cm, and
    /// one texel in `spikes` a spike 5..9 m tall (so the closest point is often a spike's flank
    /// several cells away on both axes).
    fn rough(ts: f32, amp_raw: u32, spikes: u32, salt: u32) -> HeightField {
        let g = Grid::from_fn(64, 64, |x, z| {
            let h = (x ^ salt.wrapping_mul(2_654_435_761)).wrapping_mul(374_761_393)
                ^ z.wrapping_mul(668_265_263);
            let h = (h ^ (h >> 13)).wrapping_mul(1_274_126_177);
            let h = h ^ (h >> 16);
            let spike = if (h >> 8).is_multiple_of(spikes) {
                500 + (h >> 4) % 400
            } else {
                0
            };
            (h % amp_raw + spike) as u16
        })
        .expect("grid");
        HeightField::new(g, HeightEncoding::new(0.01, -3.0).expect("enc"), ts).expect("field")
    }

    /// The closest surface point to `c` by brute force: every cell within `reach` metres (no
    /// pruning), the field's own per-patch search. Returns the distance.
    fn brute_force_distance(f: &HeightField, c: DVec3, reach: f64) -> f64 {
        let ts = f64::from(f.texel_size());
        let (x_lo, x_hi) = (
            ((c.x - reach) / ts).floor() as i64,
            ((c.x + reach) / ts).floor() as i64,
        );
        let (z_lo, z_hi) = (
            ((c.z - reach) / ts).floor() as i64,
            ((c.z + reach) / ts).floor() as i64,
        );
        let mut best = f64::INFINITY;
        for iz in z_lo..=z_hi {
            for ix in x_lo..=x_hi {
                let patch = f.patch(ix, iz);
                let local = DVec3::new(c.x - ix as f64 * ts, c.y, c.z - iz as f64 * ts);
                best = best.min(closest_on_patch(&patch, local, ts).2);
            }
        }
        best.sqrt()
    }

    /// The per-patch search refines the best of its samples along v: its answer is at
    /// least as near as every point of a dense grid over the patch, for optima that fall
    /// between the samples (planes, slopes and twisted patches, texel sizes 0.5 to 2).
    #[test]
    fn the_patch_search_refines_between_its_samples() {
        let patches = [
            (0.0, 0.0, 0.0, 0.0),
            (0.2, 0.3, -0.4, 0.0),
            (-0.1, 0.5, 0.2, -0.7),
            (0.0, -0.3, 0.1, 0.9),
        ];
        let n = 600;
        let mut checked = 0;
        for (k, &(a, b, c, d)) in patches.iter().enumerate() {
            let patch = Patch {
                ix: 0,
                iz: 0,
                a,
                b,
                c,
                d,
                min: a.min(a + b).min(a + c).min(a + b + c + d),
                max: a.max(a + b).max(a + c).max(a + b + c + d),
            };
            for (j, ts) in [0.5, 1.0, 2.0].into_iter().enumerate() {
                for (qu, qv) in [(0.5, 0.43), (0.21, 0.07), (0.8, 0.69), (0.35, 0.93)] {
                    let q = DVec3::new(qu * ts, 0.6 + 0.1 * (k + j) as f64, qv * ts);
                    let (u, v, d2) = closest_on_patch(&patch, q, ts);
                    let at = |u: f64, v: f64| {
                        let p = DVec3::new(u * ts, a + b * u + c * v + d * u * v, v * ts);
                        (p - q).length_squared()
                    };
                    assert!((at(u, v) - d2).abs() < 1e-12, "the answer's point is off");
                    let mut dense = f64::INFINITY;
                    for iv in 0..=n {
                        for iu in 0..=n {
                            dense = dense.min(at(iu as f64 / n as f64, iv as f64 / n as f64));
                        }
                    }
                    assert!(
                        d2 <= dense + 1e-12,
                        "patch {k} ts {ts} q ({qu}, {qv}): {d2} above the dense grid's {dense}"
                    );
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 48);
    }

    /// The per-patch search before the convex path and Brent's refinement: 9 samples along
    /// `v`, then 48 golden-section steps in the best sample's bracket.
    fn golden_reference(patch: &Patch, q: DVec3, ts: f64) -> f64 {
        let on_segment = |v: f64| -> f64 {
            let a = DVec3::new(0.0, patch.a + patch.c * v, v * ts);
            let b = DVec3::new(ts, patch.b + patch.d * v, 0.0);
            let w = q - a;
            let u = (w.dot(b) / b.length_squared()).clamp(0.0, 1.0);
            (w - b * u).length_squared()
        };
        let (mut best_i, mut best) = (0, f64::INFINITY);
        for i in 0..=8 {
            let d2 = on_segment(i as f64 / 8.0);
            if d2 < best {
                (best_i, best) = (i, d2);
            }
        }
        let lo = ((best_i as f64 - 1.0) / 8.0).max(0.0);
        let hi = ((best_i as f64 + 1.0) / 8.0).min(1.0);
        let g = 0.5 * (5.0_f64.sqrt() - 1.0);
        let (mut lo, mut hi) = (lo, hi);
        let (mut m1, mut m2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        let (mut f1, mut f2) = (on_segment(m1), on_segment(m2));
        for _ in 0..48 {
            if f1 <= f2 {
                (hi, m2, f2) = (m2, m1, f1);
                m1 = hi - g * (hi - lo);
                f1 = on_segment(m1);
            } else {
                (lo, m1, f1) = (m1, m2, f2);
                m2 = lo + g * (hi - lo);
                f2 = on_segment(m2);
            }
        }
        on_segment(0.5 * (lo + hi)).min(best)
    }

    /// On random patches (flat to steeper than 45 degrees, twisted or not) and points above,
    /// below and beside them, the search finds a point as near as the golden-section search
    /// it replaced, and no nearer than it by more than that search's own tolerance, on both
    /// paths (convex patches by Newton's method, the others by samples and Brent's method).
    #[test]
    fn the_patch_search_matches_the_golden_section_search() {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut convex, mut other) = (0, 0);
        for k in 0..20_000 {
            let ts = [0.25, 1.0, 83.0][k % 3];
            let relief = ts * [0.05, 0.5, 2.0][(k / 3) % 3];
            let mut h = || (next() - 0.5) * 2.0 * relief;
            let (h00, h10, h01, h11) = (h(), h(), h(), h());
            let patch = Patch {
                ix: 0,
                iz: 0,
                a: h00,
                b: h10 - h00,
                c: h01 - h00,
                d: h00 - h10 - h01 + h11,
                min: h00.min(h10).min(h01).min(h11),
                max: h00.max(h10).max(h01).max(h11),
            };
            let q = DVec3::new(
                (next() * 3.0 - 1.0) * ts,
                (next() - 0.5) * 6.0 * relief,
                (next() * 3.0 - 1.0) * ts,
            );
            let reach = (patch.max - q.y).abs().max((patch.min - q.y).abs());
            if reach * patch.d.abs() < 0.5 * ts * ts {
                convex += 1;
            } else {
                other += 1;
            }
            let (u, v, d2) = closest_on_patch(&patch, q, ts);
            let want = golden_reference(&patch, q, ts);
            let p = DVec3::new(u * ts, patch.height(u, v), v * ts);
            let scale = ts * ts + relief * relief;
            assert!(((p - q).length_squared() - d2).abs() <= 1e-12 * scale);
            assert!(
                d2 <= want + 1e-12 * scale && d2 >= want - 1e-9 * scale,
                "patch {patch:?} ts {ts} q {q}: {d2} against {want}"
            );
        }
        assert!(convex > 5_000 && other > 5_000, "{convex} {other}");
    }

    #[test]
    fn large_spheres_over_rough_ground_match_brute_force() {
        let mut checked = 0;
        let cases = [
            (0.5f32, 400u32, 1_000_000u32),
            (0.5, 50, 60),
            (0.25, 30, 150),
            (1.0, 100, 25),
            (1.0, 900, 1_000_000),
        ];
        for (k, (ts, amp, spikes)) in cases.into_iter().enumerate() {
            let f = rough(ts, amp, spikes, k as u32);
            let (lo, hi) = f.height_bounds();
            for i in 0..24u32 {
                let t = (i as f32 + 0.37) * 0.61803;
                let r = 2.0 + 8.0 * (t * 3.1).fract();
                let x = 8.0 + (t * 7.3).fract() * 12.0 * ts;
                let z = 8.0 + (t * 5.9).fract() * 12.0 * ts;
                // Centres above the ground under them by a share of the radius (among the
                // spikes), and every third one above the highest ground.
                let base = if i % 3 == 0 {
                    hi
                } else {
                    f.height_local(Vec2::new(x, z))
                };
                let y = base + r * (0.1 + 0.8 * (t * 2.3).fract());
                let centre = Vec3::new(x, y, z);
                let want = brute_force_distance(&f, centre.as_dvec3(), f64::from(r) + 1.0);
                let got = f.contact_local_sphere(centre, r);
                if want >= f64::from(r) {
                    assert!(got.is_none(), "{centre} r {r}: {got:?}, want none");
                    continue;
                }
                let c = got.expect("contact");
                checked += 1;
                let want_depth = f64::from(r) - want;
                assert!(
                    (f64::from(c.depth) - want_depth).abs() < 1e-4,
                    "ts {ts}, {centre} r {r}: depth {} want {want_depth}",
                    c.depth
                );
                // The point is on the surface, `r - depth` from the centre, along the normal.
                let p = c.point;
                assert!((f.height_local(Vec2::new(p.x, p.z)) - p.y).abs() < 1e-3);
                assert!(((centre - p).length() - (r - c.depth)).abs() < 1e-3);
                assert!((c.normal - (centre - p).normalize()).length() < 1e-3);
            }
            assert!(lo < hi);
        }
        assert!(checked > 20, "only {checked} contacts checked");
    }

    #[test]
    fn large_spheres_around_a_spike_match_brute_force() {
        // Flat ground at 0 with one 10 m spike at texel (20, 20), world (10, 10). A centre a
        // few metres up and a few metres away diagonally is closer to the spike's flank than
        // to the ground under it, in a cell far from the centre on both axes.
        let mut g = Grid::new(64, 64, 0u16).expect("grid");
        *g.get_mut(20, 20).expect("texel") = 1000;
        let f =
            HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 0.5).expect("field");
        let mut closer_to_spike = 0;
        for dx in [-4.0f32, -3.1, -2.5, -1.7, 1.7, 2.5, 3.3, 4.2] {
            for dz in [-3.7f32, -2.6, -1.9, 2.2, 2.9, 3.8] {
                for (y, r) in [(3.5f32, 5.0f32), (2.5, 4.0), (4.5, 9.0), (3.0, 2.5)] {
                    let centre = Vec3::new(10.0 + dx, y, 10.0 + dz);
                    let want = brute_force_distance(&f, centre.as_dvec3(), f64::from(r) + 1.0);
                    closer_to_spike += usize::from(want < f64::from(y) - 1e-3);
                    let got = f.contact_local_sphere(centre, r);
                    if want >= f64::from(r) {
                        assert!(got.is_none(), "{centre} r {r}: {got:?}");
                        continue;
                    }
                    let c = got.expect("contact");
                    let want_depth = f64::from(r) - want;
                    assert!(
                        (f64::from(c.depth) - want_depth).abs() < 1e-4,
                        "{centre} r {r}: depth {} want {want_depth}",
                        c.depth
                    );
                }
            }
        }
        assert!(closer_to_spike > 20, "{closer_to_spike}");
    }

    #[test]
    fn sphere_beside_a_step_touches_its_edge() {
        // Columns 4..12 at 4 m, the rest at 0 m: a ramp rises 4 m between x = 3 and x = 4. A
        // sphere left of it at 1 m height touches the ramp's face.
        let g =
            Grid::from_fn(16, 4, |x, _| if (4..12).contains(&x) { 400 } else { 0 }).expect("grid");
        let f =
            HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("field");
        let centre = Vec3::new(2.5, 1.0, 1.5);
        let c = f.contact_local_sphere(centre, 1.2).expect("contact");
        // The face is the plane y = 4 (x - 3) for x in [3, 4]; distance from the centre to it.
        let n = Vec3::new(-4.0, 1.0, 0.0).normalize();
        let dist = (centre - Vec3::new(3.0, 0.0, 1.5)).dot(n).abs();
        assert!((c.depth - (1.2 - dist)).abs() < 1e-4, "{c:?} dist {dist}");
        assert!((c.normal - n).length() < 1e-3);
    }
}
