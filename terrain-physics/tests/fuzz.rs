//! Fuzz target `physics`: every public query of terrain-physics (HeightfieldCollider height,
//! normal, raycast and sphere contact; BoundedGround; CameraBody and SphereBody steps;
//! CollisionWindow; field construction) with inputs over the whole finite f32 range, NaN and
//! infinities, positions far outside the map, huge distances and radii, and texel sizes from
//! `f32::MIN_POSITIVE` to `f32::MAX`. Every call must return `Ok` or `Err` (`Err` whenever an
//! input is not finite) within [`CALL_LIMIT`]; a call that takes longer twice in a row fails,
//! and one that does not return is caught by the harness's watchdog. The target is
//! time-bounded (`TERRAIN_FUZZ_SECONDS`, default 2 s; `cargo xtask fuzz --seconds N` runs it
//! longer, in release mode); see `fuzz/harness.rs` for the seed, replay and class selection
//! variables.
//!
//! Input classes are cut along the known defects, so that the classes a defect hangs or
//! panics in can be switched off alone ([`DISABLED`]) while every other input keeps running;
//! the boundaries are [`WALK_CELLS`] (cells a ray may cross), [`REACH_TEXELS`] (how far a
//! sphere's search may reach) and [`FAR_TEXELS`] (coordinates in texels).

#[path = "fuzz/harness.rs"]
mod harness;

use glam::{IVec2, UVec2, Vec2, Vec3};
use harness::{Case, Class, Rng, Target};
use std::time::{Duration, Instant};
use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect};
use terrain_physics::{
    BoundedGround, CameraBody, CollisionMirror, CollisionWindow, DeformationBound, GroundClamp,
    GroundQuery, HeightField, HeightfieldCollider, PendingDeformation, SphereBody,
};

/// The longest a single query may take. Queries take microseconds; a query over a bounded
/// input that takes 50 ms is a defect.
const CALL_LIMIT: Duration = Duration::from_millis(50);

/// Most cells a ray of the enabled classes may cross (`max_dist * (|d.x| + |d.z|) / texel`):
/// a few milliseconds of walking. Longer walks are the class `ray_long_walk`.
const WALK_CELLS: f64 = 1e5;

/// Largest reach of a sphere query of the enabled classes, in texels: the depth of a centre
/// below the ground, or the smaller of its height above the ground and its radius (the search
/// visits `(2 * reach + 1)^2` cells). Deeper or wider are `sphere_deep_below` and
/// `sphere_huge_radius`.
const REACH_TEXELS: f64 = 256.0;

/// Texel coordinates (local to the field) from this magnitude on are "far": cell indices of
/// this size are near the ends of `i64`. Far inputs are the `*_far*` classes.
const FAR_TEXELS: f64 = 4.611_686_018_427_388e18; // 2^62

/// Classes to skip, each with the defect that makes it hang or panic (a class is listed here
/// only while its defect is being fixed; `TERRAIN_FUZZ_CLASSES=<name>` runs it anyway).
const DISABLED: &[(&str, &str)] = &[
    // Empty: the three defects these classes found (a near-horizontal ray walking practically
    // forever, a sphere far below the ground visiting (2 depth / texel)^2 cells, far positions
    // overflowing cell indices) are fixed; every class runs.
];

// ---------------------------------------------------------------------------------------------
// Fields

/// A collider and what the generators need to know about it.
struct Field {
    collider: HeightfieldCollider,
    label: String,
    ts: f64,
    translation: Vec3,
    size: UVec2,
    /// Height bounds in metres, f64 (the field's f32 bounds may overflow to infinity).
    lo: f64,
    hi: f64,
}

impl Field {
    fn new(label: String, grid: Grid<u16>, enc: HeightEncoding, ts: f32, t: Vec3) -> Self {
        let size = grid.size();
        let (mut raw_lo, mut raw_hi) = (u16::MAX, 0);
        for &v in grid.as_slice() {
            raw_lo = raw_lo.min(v);
            raw_hi = raw_hi.max(v);
        }
        let metres = |raw: u16| f64::from(enc.offset) + f64::from(enc.scale) * f64::from(raw);
        let collider = HeightfieldCollider::new(std::sync::Arc::new(
            HeightField::new(grid, enc, ts).expect("field"),
        ))
        .with_translation(t)
        .expect("finite translation");
        Self {
            collider,
            label,
            ts: f64::from(ts),
            translation: t,
            size,
            lo: metres(raw_lo) + f64::from(t.y),
            hi: metres(raw_hi) + f64::from(t.y),
        }
    }

    /// Local coordinates as the collider makes them: `world - translation` in f32 (which may
    /// lose the low bits, or overflow, when the translation is large).
    fn local(&self, x: f32, z: f32) -> (f32, f32) {
        (x - self.translation.x, z - self.translation.z)
    }

    /// The surface height at local `(x, z)` in f64, computed exactly as the collider's contact
    /// search does (the bilinear patch `a + b u + c v + d u v` of cell `floor(x / texel)` as an
    /// `i64`, wrapped, from corner heights `offset + scale * stored`), so that inputs are
    /// classified with the same rounding as the code under test sees.
    fn surface_local(&self, lx: f32, lz: f32) -> f64 {
        let g = self.collider.field().heights();
        let e = self.collider.field().encoding();
        let (px, pz) = (f64::from(lx) / self.ts, f64::from(lz) / self.ts);
        let (cell, row) = (px.floor(), pz.floor());
        // `as i64` saturates as the collider's does; the wrap is exact in integers.
        let wrap = |i: f64, n: u32| {
            let i0 = (i as i64).rem_euclid(i64::from(n)) as u32;
            (i0, if i0 + 1 < n { i0 + 1 } else { 0 })
        };
        let ((x0, x1), (z0, z1)) = (wrap(cell, g.width()), wrap(row, g.height()));
        let (off, scale) = (f64::from(e.offset), f64::from(e.scale));
        let m = |x: u32, z: u32| off + scale * f64::from(g.get(x, z).unwrap_or(0));
        let (h00, h10, h01, h11) = (m(x0, z0), m(x1, z0), m(x0, z1), m(x1, z1));
        let (a, b, c, d) = (h00, h10 - h00, h01 - h00, h00 - h10 - h01 + h11);
        let (u, v) = (px - cell, pz - row);
        a + b * u + c * v + d * u * v
    }

    /// The highest texel under the cells that local box `[x0, x1] x [z0, z1]` (metres)
    /// touches, in f64 metres; `None` when the box spans more than 64 cells a side or lies
    /// far (see [`FAR_TEXELS`]).
    fn max_surface_box(&self, x0: f64, x1: f64, z0: f64, z1: f64) -> Option<f64> {
        let g = self.collider.field().heights();
        let e = self.collider.field().encoding();
        let cells = |a: f64, b: f64| {
            let (lo, hi) = ((a / self.ts).floor(), (b / self.ts).floor() + 1.0);
            (lo.abs() < FAR_TEXELS && hi.abs() < FAR_TEXELS && hi - lo <= 64.0)
                .then_some((lo as i64, hi as i64))
        };
        let ((cx0, cx1), (cz0, cz1)) = (cells(x0, x1)?, cells(z0, z1)?);
        let mut top = f64::NEG_INFINITY;
        for iz in cz0..=cz1 {
            for ix in cx0..=cx1 {
                let x = ix.rem_euclid(i64::from(g.width())) as u32;
                let z = iz.rem_euclid(i64::from(g.height())) as u32;
                let raw = f64::from(g.get(x, z).unwrap_or(0));
                top = top.max(f64::from(e.offset) + f64::from(e.scale) * raw);
            }
        }
        Some(top)
    }

    /// The surface height under world `(x, z)` in f64, in world metres.
    fn surface(&self, x: f32, z: f32) -> f64 {
        let (lx, lz) = self.local(x, z);
        self.surface_local(lx, lz) + f64::from(self.translation.y)
    }

    /// `|x|` (axis 0) or `|z|` (axis 1) of a world position, local, in texels of this field
    /// (infinite where the local coordinate overflows f32).
    fn texels(&self, x: f32, z: f32, axis: usize) -> f64 {
        let (lx, lz) = self.local(x, z);
        (f64::from(if axis == 0 { lx } else { lz }) / self.ts).abs()
    }

    /// Whether the collider's local coordinates of world point `p` (`p - translation` in f32)
    /// overflow: such a point is out of every query's reach, and refusing it is a right answer
    /// (answering NaN is noted).
    fn overflows(&self, p: Vec3) -> bool {
        !(p - self.translation).is_finite()
    }

    fn is_far(&self, x: f32, z: f32) -> bool {
        !(self.texels(x, z, 0) < FAR_TEXELS && self.texels(x, z, 1) < FAR_TEXELS)
    }
}

/// Rolling hills, noise, flat ground, spikes and degenerate sizes (1 x 1, 1 x 7), each at texel
/// sizes from `f32::MIN_POSITIVE` to `f32::MAX`, under plain and edge encodings, some moved.
fn fields() -> Vec<Field> {
    let mut rng = Rng::new(0x5eed);
    let hills = Grid::from_fn(64, 64, |x, y| {
        let (u, v) = (
            x as f32 / 64.0 * std::f32::consts::TAU,
            y as f32 / 64.0 * std::f32::consts::TAU,
        );
        (30000.0 + 12000.0 * (u * 2.0).sin() * (v * 3.0).cos() + 8000.0 * (u * 5.0 + v).sin())
            as u16
    })
    .unwrap();
    let noise = Grid::from_fn(16, 16, |_, _| rng.next_u32() as u16).unwrap();
    let flat = Grid::new(8, 8, 1000u16).unwrap();
    let spikes = Grid::from_fn(32, 32, |x, y| if (x + y) % 2 == 0 { 0 } else { u16::MAX }).unwrap();
    let one = Grid::new(1, 1, 777u16).unwrap();
    let strip = Grid::from_fn(1, 7, |_, y| (y * 9000) as u16).unwrap();
    let maps = [
        ("hills", hills),
        ("noise", noise),
        ("flat", flat),
        ("spikes", spikes),
        ("one", one),
        ("strip", strip),
    ];
    let texel_sizes = [
        f32::MIN_POSITIVE,
        1e-30,
        1e-3,
        0.5,
        7.0,
        1e4,
        1e30,
        f32::MAX,
    ];
    let plain = HeightEncoding::new(0.001, -5.0).unwrap();
    let edge_encodings = [
        HeightEncoding::new(1e-30, 0.0).unwrap(),
        HeightEncoding::new(f32::MAX / 65536.0, -1.7e38).unwrap(),
        HeightEncoding::new(1e-3, -1e30).unwrap(),
        HeightEncoding::new(1.0, 1e30).unwrap(),
    ];
    let mut out = Vec::new();
    for (name, grid) in &maps {
        for &ts in &texel_sizes {
            out.push(Field::new(
                format!("{name} ts={ts:e}"),
                grid.clone(),
                plain,
                ts,
                Vec3::ZERO,
            ));
        }
        for (i, &enc) in edge_encodings.iter().enumerate() {
            let ts = texel_sizes[rng.index(texel_sizes.len())];
            out.push(Field::new(
                format!("{name} ts={ts:e} encoding#{i}"),
                grid.clone(),
                enc,
                ts,
                Vec3::ZERO,
            ));
        }
        for _ in 0..2 {
            let ts = texel_sizes[rng.index(texel_sizes.len())];
            let t = Vec3::new(rng.f32_bits(), rng.f32_edge(), rng.f32_bits());
            out.push(Field::new(
                format!("{name} ts={ts:e} moved to {t}"),
                grid.clone(),
                plain,
                ts,
                t,
            ));
        }
    }
    out
}

struct Ctx {
    fields: Vec<Field>,
}

impl Ctx {
    fn field(&self, rng: &mut Rng) -> &Field {
        &self.fields[rng.index(self.fields.len())]
    }
}

// ---------------------------------------------------------------------------------------------
// Generators and checks

/// A finite f32 nearest to `v` (infinities and overflow clamp to `+-f32::MAX`).
fn finite_f32(v: f64) -> f32 {
    if v.is_nan() {
        return 0.0;
    }
    v.clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
}

/// Any finite f32: random bits (every exponent alike), edge values, or modest numbers.
fn any_f32(rng: &mut Rng) -> f32 {
    match rng.below(3) {
        0 => rng.f32_bits(),
        1 => rng.f32_edge(),
        _ => rng.uniform(-1e3, 1e3) as f32,
    }
}

/// A world coordinate along `axis` within a few map periods of the field, often on a cell
/// edge or a texel exactly.
fn near_coord(f: &Field, axis: usize, rng: &mut Rng) -> f32 {
    let n = f64::from(if axis == 0 { f.size.x } else { f.size.y });
    let t = match rng.below(3) {
        0 => rng.uniform(-3.0 * n, 4.0 * n),
        1 => rng.range_u32(0, 7 * n as u32) as f64 - 3.0 * n,
        _ => rng.range_u32(0, 7 * n as u32) as f64 - 3.0 * n + rng.pick(&[0.5, 1e-9, -1e-9]),
    };
    let origin = if axis == 0 {
        f.translation.x
    } else {
        f.translation.z
    };
    finite_f32(t * f.ts + f64::from(origin))
}

/// A world height: near the surface at `(x, z)` (within `reach` texels), inside the field's
/// height band, or anywhere.
fn near_height(f: &Field, x: f32, z: f32, reach: f64, rng: &mut Rng) -> f32 {
    match rng.below(4) {
        0 | 1 => finite_f32(f.surface(x, z) + rng.uniform(-reach, reach) * f.ts),
        2 => finite_f32(rng.uniform(f.lo, f.hi)),
        _ => any_f32(rng),
    }
}

fn near_pos(f: &Field, rng: &mut Rng) -> Vec2 {
    Vec2::new(near_coord(f, 0, rng), near_coord(f, 1, rng))
}

/// A position anywhere: near the map, or any finite value per axis.
fn any_pos(f: &Field, rng: &mut Rng) -> Vec2 {
    let axis = |a: usize, rng: &mut Rng| {
        if rng.chance(1, 2) {
            near_coord(f, a, rng)
        } else {
            any_f32(rng)
        }
    };
    Vec2::new(axis(0, rng), axis(1, rng))
}

/// Runs one call of the code under test, timed. A call over [`CALL_LIMIT`] is run twice
/// more and fails only if every run is over: a loaded machine stalls a call now and then, a
/// slow input is slow every time.
fn timed<T>(what: &str, mut call: impl FnMut() -> T) -> Result<T, String> {
    let mut took = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        let r = call();
        let d = t.elapsed();
        if d <= CALL_LIMIT {
            return Ok(r);
        }
        took.push(format!("{:.1} ms", d.as_secs_f64() * 1e3));
    }
    Err(format!(
        "{what} took {} (limit {} ms)",
        took.join(", then "),
        CALL_LIMIT.as_millis()
    ))
}

/// A unit-ish direction: uniform on the sphere, along an axis, near horizontal, or random
/// bits per component (the collider normalises; a zero one is an error).
fn direction(rng: &mut Rng) -> Vec3 {
    match rng.below(4) {
        0 => loop {
            let v = Vec3::new(
                rng.uniform(-1.0, 1.0) as f32,
                rng.uniform(-1.0, 1.0) as f32,
                rng.uniform(-1.0, 1.0) as f32,
            );
            if v.length_squared() > 1e-6 {
                break v;
            }
        },
        1 => rng.pick(&[
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ]),
        2 => {
            let a = rng.uniform(0.0, std::f64::consts::TAU);
            let dy = rng.pick(&[0.0f32, 1e-6, -1e-6, 1e-3, -1e-3, -1e-30, 1e-30]);
            Vec3::new(a.cos() as f32, dy, a.sin() as f32)
        }
        _ => Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)),
    }
}

/// Cells a ray walks at most: `max_dist * (|d.x| + |d.z|) / texel` for the normalised
/// direction (`None` if it does not normalise: the query is an error then).
fn walk_cells(f: &Field, dir: Vec3, max_dist: f32) -> Option<f64> {
    let d = dir.try_normalize()?;
    Some(f64::from(max_dist) * (f64::from(d.x.abs()) + f64::from(d.z.abs())) / f.ts)
}

/// The largest `max_dist` that keeps a ray within [`WALK_CELLS`] cells.
fn walk_cap(f: &Field, dir: Vec3) -> f32 {
    match dir.try_normalize() {
        Some(d) => {
            let across = f64::from(d.x.abs()) + f64::from(d.z.abs());
            if across == 0.0 {
                f32::MAX
            } else {
                finite_f32(WALK_CELLS * f.ts / across * 0.999)
            }
        }
        None => f32::MAX,
    }
}

/// A max distance: modest, edge, random bits, zero.
fn max_distance(f: &Field, rng: &mut Rng) -> f32 {
    match rng.below(4) {
        0 => finite_f32(rng.uniform(0.0, 200.0) * f.ts),
        1 => rng.f32_edge().abs(),
        2 => rng.f32_bits().abs(),
        _ => 0.0,
    }
}

/// Checks a raycast that returned.
fn check_hit(
    what: &str,
    r: Result<Option<terrain_physics::RayHit>, terrain_physics::PhysicsError>,
    max_dist: f32,
    case: &mut Case,
) -> Result<(), String> {
    match r {
        Ok(Some(hit)) => {
            if !(hit.distance >= 0.0 && hit.distance <= max_dist * (1.0 + 1e-5) + 1e-30) {
                return Err(format!(
                    "{what}: hit at distance {} of {max_dist}",
                    hit.distance
                ));
            }
            if !(hit.point.is_finite() && hit.normal.is_finite()) {
                case.note(|| format!("{what}: non-finite hit {hit:?}"));
            }
            Ok(())
        }
        Ok(None) => Ok(()),
        // A ray undecided after the bounded walk is refused by design (never a false miss).
        Err(terrain_physics::PhysicsError::RayTooLong { .. }) => Ok(()),
        Err(e) => Err(format!("{what}: finite input refused: {e}")),
    }
}

/// How far a sphere query searches, in texels (see [`REACH_TEXELS`]): from the centre in
/// the collider's local frame (`centre - translation` in f32, as the collider computes it).
fn sphere_reach(f: &Field, c: Vec3, r: f32) -> f64 {
    let lc = c - f.translation;
    if !lc.is_finite() {
        return 0.0; // the query is refused before any search
    }
    let h = f.surface_local(lc.x, lc.z);
    let y = f64::from(lc.y);
    let reach = if y < h {
        h - y
    } else {
        (y - h).min(f64::from(r))
    };
    if reach.is_nan() { 0.0 } else { reach / f.ts }
}

/// Whether the collider's local coordinates of world point `p` (`p - translation` in f32)
/// overflow: the query is then refused as non-finite although its input is finite (noted).
fn local_overflow_refused<T: std::fmt::Debug, E: std::fmt::Display>(
    f: &Field,
    p: Vec3,
    r: &Result<T, E>,
    case: &mut Case,
) -> bool {
    if !f.overflows(p) {
        return false;
    }
    if let Err(e) = r {
        case.note(|| {
            format!(
                "{p} on field {}: local coordinates overflow, refused: {e}",
                f.label
            )
        });
        return true;
    }
    false
}

/// Checks a sphere contact that returned.
fn check_contact(
    what: &str,
    r: Result<Option<terrain_physics::Contact>, terrain_physics::PhysicsError>,
    case: &mut Case,
) -> Result<(), String> {
    match r {
        Ok(Some(c)) => {
            if c.depth.is_nan() || c.depth < 0.0 {
                return Err(format!("{what}: contact of depth {}", c.depth));
            }
            if !(c.point.is_finite() && c.normal.is_finite() && c.depth.is_finite()) {
                case.note(|| format!("{what}: non-finite contact {c:?}"));
            }
            Ok(())
        }
        Ok(None) => Ok(()),
        Err(e) => Err(format!("{what}: finite input refused: {e}")),
    }
}

// ---------------------------------------------------------------------------------------------
// Collider classes

/// Height and normal anywhere in the finite range.
fn height_normal(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let f = ctx.field(&mut case.rng);
    let p = any_pos(f, &mut case.rng);
    case.show(|| format!("field {}, pos {p:?}", f.label));
    let h = timed("height", || f.collider.height(p))?;
    let n = timed("normal", || f.collider.normal(p))?;
    let p3 = Vec3::new(p.x, 0.0, p.y);
    if f.overflows(p3) {
        // Out of every query's reach: an error is the right answer, a value (NaN) is noted.
        if !local_overflow_refused(f, p3, &h, case) {
            case.note(|| format!("height at {p:?} on field {} is {h:?}", f.label));
        }
        return Ok(());
    }
    let h = h.map_err(|e| format!("height at {p}: finite input refused: {e}"))?;
    let n = n.map_err(|e| format!("normal at {p}: finite input refused: {e}"))?;
    if !h.is_finite() && f.lo.abs() < 1e38 && f.hi.abs() < 1e38 {
        case.note(|| format!("height at {p:?} on field {} is {h}", f.label));
    }
    if !n.is_finite() {
        case.note(|| format!("normal at {p:?} on field {} is {n}", f.label));
    }
    Ok(())
}

/// NaN or an infinity in one input of any query: always an error.
fn non_finite_inputs(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let bad = rng.f32_non_finite();
    let p = near_pos(f, rng);
    let v3 = |rng: &mut Rng| {
        let mut v = Vec3::new(p.x, near_height(f, p.x, p.y, 4.0, rng), p.y);
        let i = rng.index(3);
        v[i] = bad;
        v
    };
    let mut v2 = p;
    v2[rng.index(2)] = bad;
    let pending = [PendingDeformation {
        rect: Rect::new(IVec2::ZERO, UVec2::splat(4)),
        bound: DeformationBound::new(1.0, 1.0).expect("bound"),
    }];
    let ground = BoundedGround::new(&f.collider, &pending, &[]);
    let which = rng.below(12);
    // Each query's result, formatted: it must be an error.
    let shown = match which {
        0 => format!("{:?}", f.collider.height(v2)),
        1 => format!("{:?}", f.collider.normal(v2)),
        2 => {
            let o = v3(rng);
            format!("{:?}", f.collider.raycast(o, Vec3::NEG_Y, 1.0))
        }
        3 => {
            let mut d = Vec3::NEG_Y;
            d[rng.index(3)] = bad;
            format!("{:?}", f.collider.raycast(Vec3::new(p.x, 0.0, p.y), d, 1.0))
        }
        4 => format!(
            "{:?}",
            f.collider
                .raycast(Vec3::new(p.x, 0.0, p.y), Vec3::NEG_Y, bad)
        ),
        5 => {
            let c = v3(rng);
            format!("{:?}", f.collider.sphere_contact(c, 1.0))
        }
        6 => format!(
            "{:?}",
            f.collider.sphere_contact(Vec3::new(p.x, 0.0, p.y), bad)
        ),
        7 => format!("{:?}", ground.raise_at(v2)),
        8 => {
            let c = v3(rng);
            format!("{:?}", ground.ground_contact(c, 1.0))
        }
        9 => format!("{:?}", ground.height_interval(v2)),
        10 => {
            let mut cam = CameraBody::new(Vec3::new(p.x, 0.0, p.y));
            match rng.below(4) {
                0 => cam.velocity.y = bad,
                1 => cam.eye_height = bad,
                2 => cam.mass = bad,
                _ => cam.position.x = bad,
            }
            let before = format!("{cam:?}");
            let r = cam.step(1.0 / 60.0, Vec3::ZERO, &f.collider);
            if format!("{cam:?}") != before {
                return Err(format!(
                    "a failed step changed the camera: {before} -> {cam:?}"
                ));
            }
            format!("{r:?}")
        }
        _ => {
            let mut s =
                SphereBody::new(Vec3::new(p.x, 0.0, p.y), 1.0).map_err(|e| e.to_string())?;
            let (dt, force) = match rng.below(3) {
                0 => (bad, Vec3::ZERO),
                1 => (1.0 / 60.0, Vec3::new(bad, 0.0, 0.0)),
                _ => {
                    s.velocity.z = bad;
                    (1.0 / 60.0, Vec3::ZERO)
                }
            };
            let before = format!("{s:?}");
            let r = s.step(dt, force, &f.collider);
            if format!("{s:?}") != before {
                return Err(format!("a failed step changed the ball: {before} -> {s:?}"));
            }
            format!("{r:?}")
        }
    };
    if shown.starts_with("Err(") {
        Ok(())
    } else {
        Err(format!(
            "query {which} with a {bad} input on field {} returned {shown}",
            f.label
        ))
    }
}

/// Rays near the map, any direction, within [`WALK_CELLS`] cells.
fn ray_near_map(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let o = Vec3::new(p.x, near_height(f, p.x, p.y, 64.0, rng), p.y);
    if f.is_far(o.x, o.z) {
        case.skipped = true;
        return Ok(()); // a large translation rounded it far: the domain of ray_far_origin
    }
    let d = direction(rng);
    let max_dist = max_distance(f, rng).min(walk_cap(f, d));
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    if d.try_normalize().is_none() {
        return match r {
            Err(_) => Ok(()),
            Ok(h) => Err(format!("a zero direction {d:?} gave {h:?}")),
        };
    }
    check_hit("raycast", r, max_dist, case)
}

/// Rays from anywhere in the finite range (not far, see [`FAR_TEXELS`]), any direction and
/// max distance within [`WALK_CELLS`] cells.
fn ray_whole_range(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let mut p = any_pos(f, rng);
    if f.is_far(p.x, p.y) {
        p = near_pos(f, rng);
    }
    if f.is_far(p.x, p.y) {
        case.skipped = true;
        return Ok(()); // a large translation rounded it far: the domain of ray_far_origin
    }
    let o = Vec3::new(p.x, any_f32(rng), p.y);
    let d = direction(rng);
    let max_dist = any_f32(rng).abs().min(walk_cap(f, d));
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    if d.try_normalize().is_none() {
        return r.map(|_| ()).or(Ok(()));
    }
    check_hit("raycast", r, max_dist, case)
}

/// Defect 1: near-horizontal rays inside the height band with a huge max distance.
fn ray_long_walk(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    // Just above the ground under the origin, or anywhere in the band.
    let y = if rng.chance(1, 2) {
        finite_f32(f.surface(p.x, p.y) + 1e-3 * f.ts.min(1.0))
    } else {
        finite_f32(rng.uniform(f.lo, f.hi))
    };
    let o = Vec3::new(p.x, y, p.y);
    let a = rng.uniform(0.0, std::f64::consts::TAU);
    let dy = rng.pick(&[0.0f32, 1e-6, -1e-6, 1e-9, -1e-30]);
    let d = Vec3::new(a.cos() as f32, dy, a.sin() as f32);
    let cells = rng.pick(&[1e6, 1e8, 1e12, 1e20, 1e30]);
    let max_dist = if rng.chance(1, 4) {
        f32::MAX
    } else {
        finite_f32(cells * f.ts)
    };
    if walk_cells(f, d, max_dist).is_some_and(|c| c <= WALK_CELLS) {
        case.skipped = true;
        return Ok(()); // a texel size so large the walk is short: the enabled classes' domain
    }
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    check_hit("raycast", r, max_dist, case)
}

/// Defect 3: rays from far outside the map (texel coordinates of 2^62 and more).
fn ray_far_origin(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let far = |rng: &mut Rng, axis: usize| {
        let origin = if axis == 0 {
            f.translation.x
        } else {
            f.translation.z
        };
        let t = FAR_TEXELS * rng.uniform(1.0, 64.0) * if rng.chance(1, 2) { 1.0 } else { -1.0 };
        if rng.chance(1, 3) {
            any_f32(rng)
        } else {
            finite_f32(t * f.ts + f64::from(origin))
        }
    };
    let mut p = near_pos(f, rng);
    match rng.below(3) {
        0 => p.x = far(rng, 0),
        1 => p.y = far(rng, 1),
        _ => p = Vec2::new(far(rng, 0), far(rng, 1)),
    }
    if !f.is_far(p.x, p.y) {
        case.skipped = true;
        return Ok(()); // a texel size so large the coordinate is not far
    }
    let o = Vec3::new(p.x, near_height(f, p.x, p.y, 64.0, rng), p.y);
    let d = direction(rng);
    let max_dist = max_distance(f, rng).min(walk_cap(f, d));
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    if d.try_normalize().is_none() {
        return r.map(|_| ()).or(Ok(()));
    }
    if local_overflow_refused(f, o, &r, case) {
        return Ok(());
    }
    check_hit("raycast", r, max_dist, case)
}

/// Spheres near the surface, radius up to [`REACH_TEXELS`] texels.
fn sphere_near_surface(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let c = Vec3::new(
        p.x,
        finite_f32(f.surface(p.x, p.y) + rng.uniform(-REACH_TEXELS, REACH_TEXELS) * f.ts),
        p.y,
    );
    let r = match rng.below(3) {
        0 => 0.0,
        1 => finite_f32(rng.uniform(0.0, 4.0) * f.ts),
        _ => finite_f32(rng.uniform(0.0, REACH_TEXELS) * f.ts),
    };
    if sphere_reach(f, c, r) > REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(()); // rounding put it past a bound: the domain of another class
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Spheres anywhere in the finite range whose search stays within [`REACH_TEXELS`] and whose
/// centre is not far.
fn sphere_whole_range(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let mut p = any_pos(f, rng);
    if f.is_far(p.x, p.y) {
        p = near_pos(f, rng);
    }
    let c = Vec3::new(p.x, any_f32(rng), p.y);
    let r = any_f32(rng).abs();
    if sphere_reach(f, c, r) > REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(()); // the domain of sphere_deep_below / sphere_huge_radius / sphere_far_center
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Defect 2: sphere centres far below the ground.
fn sphere_deep_below(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let depth = rng.pick(&[1e3, 1e4, 1e6, 1e12, 1e30]) * f.ts;
    let c = Vec3::new(p.x, finite_f32(f.surface(p.x, p.y) - depth), p.y);
    let r = finite_f32(rng.uniform(0.0, 4.0) * f.ts);
    if sphere_reach(f, c, r) <= REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Defect 2: sphere centres high above the ground with a radius reaching down to it.
fn sphere_huge_radius(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let up = rng.pick(&[1e3, 1e4, 1e6, 1e12, 1e30]) * f.ts;
    let c = Vec3::new(p.x, finite_f32(f.surface(p.x, p.y) + up), p.y);
    let r = finite_f32(up * rng.uniform(1.0, 3.0));
    if sphere_reach(f, c, r) <= REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Defect 3: sphere centres far outside the map, small radius and near the ground height.
fn sphere_far_center(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let t = FAR_TEXELS * rng.uniform(1.0, 64.0);
    let x = if rng.chance(1, 3) {
        any_f32(rng)
    } else {
        let sign = if rng.chance(1, 2) { 1.0 } else { -1.0 };
        finite_f32(t * f.ts * sign + f64::from(f.translation.x))
    };
    let z = near_coord(f, 1, rng);
    let (x, z) = if rng.chance(1, 2) { (x, z) } else { (z, x) };
    if !f.is_far(x, z) {
        case.skipped = true;
        return Ok(());
    }
    // On or just above the ground there (as the collider finds it), or anywhere in the band.
    let y = if rng.chance(3, 4) {
        f.surface(x, z) + rng.uniform(0.0, 4.0) * f.ts
    } else {
        rng.uniform(f.lo, f.hi)
    };
    let c = Vec3::new(x, finite_f32(y), z);
    let r = finite_f32(rng.uniform(0.0, 4.0) * f.ts);
    if sphere_reach(f, c, r) > REACH_TEXELS {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    if local_overflow_refused(f, c, &got, case) {
        return Ok(());
    }
    check_contact("sphere_contact", got, case)
}

// ---------------------------------------------------------------------------------------------
// BoundedGround

/// Up to five pending deformations: rects anywhere in `i32`, of any size, bounds up to
/// `f32::MAX`.
fn pending(rng: &mut Rng, f: &Field) -> Vec<PendingDeformation> {
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
fn bounded_ground_near(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
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
fn bounded_ground_far(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
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

// ---------------------------------------------------------------------------------------------
// Bodies

/// A camera of random state (any finite values, some invalid: negative mass, friction or
/// gravity) stepping by any time step under any force over the collider (no loop in the
/// height query, so the whole range).
fn camera_body(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = any_pos(f, rng);
    let mut cam = CameraBody::new(Vec3::new(p.x, near_height(f, p.x, p.y, 8.0, rng), p.y));
    cam.velocity =
        Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)) * rng.pick(&[0.0, 1e-3, 1.0]);
    if rng.chance(1, 3) {
        cam.eye_height = any_f32(rng);
    }
    if rng.chance(1, 3) {
        cam.mass = any_f32(rng);
    }
    if rng.chance(1, 3) {
        cam.friction = any_f32(rng);
    }
    if rng.chance(1, 3) {
        cam.gravity = any_f32(rng);
    }
    cam.gravity_enabled = rng.chance(3, 4);
    cam.clamp = if rng.chance(1, 2) {
        GroundClamp::OffsetOnly
    } else {
        GroundClamp::OffsetAndStop
    };
    let dt = match rng.below(3) {
        0 => 1.0 / 60.0,
        1 => any_f32(rng),
        _ => rng.f32_edge().abs(),
    };
    let force = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)) * rng.pick(&[0.0, 1.0]);
    case.show(|| {
        format!(
            "field {}, camera {cam:?}, dt {dt:e}, force {force:?}",
            f.label
        )
    });
    let before = cam;
    let r = timed("CameraBody::step", || {
        let mut c = before;
        let r = c.step(dt, force, &f.collider);
        (r, c)
    })?;
    match r {
        (Err(_), after) if format!("{after:?}") != format!("{before:?}") => Err(format!(
            "a failed step changed the camera: {before:?} -> {after:?}"
        )),
        (Ok(_), after) if !after.position.is_finite() => {
            case.note(|| format!("a step returned Ok with the camera at {}: {before:?}, dt {dt:e}, force {force}", after.position));
            Ok(())
        }
        _ => Ok(()),
    }
}

/// A camera over a BoundedGround near the map: small steps, so that it stays near.
fn camera_bounded_ground(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let pend = pending(rng, f);
    let p = near_pos(f, rng);
    let mut cam = CameraBody::new(Vec3::new(p.x, near_height(f, p.x, p.y, 8.0, rng), p.y));
    cam.gravity_enabled = rng.chance(1, 2);
    cam.velocity = Vec3::new(
        rng.uniform(-4.0, 4.0) as f32,
        0.0,
        rng.uniform(-4.0, 4.0) as f32,
    ) * f.ts as f32;
    let dt = rng.pick(&[0.0, 1.0 / 240.0, 1.0 / 60.0, 0.25]);
    let moved = cam.position + cam.velocity * dt * 2.0;
    if f.is_far(moved.x, moved.z) || f.is_far(cam.position.x, cam.position.z) {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| {
        format!(
            "field {}, pending {pend:?}, camera {cam:?}, dt {dt}",
            f.label
        )
    });
    let g = BoundedGround::new(&f.collider, &pend, &[]);
    let before = cam;
    let (r, after) = timed("CameraBody::step", || {
        let mut c = before;
        (c.step(dt, Vec3::ZERO, &g), c)
    })?;
    if r.is_err() && format!("{after:?}") != format!("{before:?}") {
        return Err(format!(
            "a failed step changed the camera: {before:?} -> {after:?}"
        ));
    }
    Ok(())
}

/// A ball resting, rolling or falling near the surface: radius and steps small enough that
/// both of its contact queries stay within [`REACH_TEXELS`].
fn sphere_body_near(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let r = finite_f32(rng.uniform(0.05, 8.0) * f.ts);
    let y = finite_f32(f.surface(p.x, p.y) + rng.uniform(-2.0, 16.0) * f.ts);
    let Ok(mut ball) = SphereBody::new(Vec3::new(p.x, y, p.y), r) else {
        return Ok(()); // a radius that rounded to 0 or below
    };
    ball.velocity = Vec3::new(
        rng.uniform(-8.0, 8.0) as f32,
        rng.uniform(-8.0, 8.0) as f32,
        rng.uniform(-8.0, 8.0) as f32,
    ) * f.ts as f32;
    ball.gravity_enabled = rng.chance(1, 2);
    ball.damping = rng.uniform(0.0, 2.0) as f32;
    let dt = rng.pick(&[0.0, 1.0 / 240.0, 1.0 / 60.0]);
    // Both contact queries of the step stay within REACH_TEXELS if the highest texel under
    // where the step can take the ball is within it of the lowest centre: the box spans the
    // centre, the centre moved by the velocity, slack for the acceleration over the step,
    // the radius, and the rounding of world to local f32 coordinates.
    let lc = (ball.center - f.translation).as_dvec3();
    let step = (ball.velocity * dt).as_dvec3();
    let accel =
        f64::from(ball.damping) * f64::from(ball.velocity.length()) + f64::from(ball.gravity);
    let magnitude = ball.center.abs().max(f.translation.abs()).max_element();
    let tol = f64::from(ball.radius) + f64::from(terrain_physics::CONTACT_TOLERANCE);
    let slack = 2.0 * accel * f64::from(dt) * f64::from(dt)
        + tol
        + 4.0 * f64::from(magnitude) * f64::from(f32::EPSILON);
    let (a, b) = (lc, lc + step);
    let lowest = a.y.min(b.y) - slack;
    let bounded = f
        .max_surface_box(
            a.x.min(b.x) - slack,
            a.x.max(b.x) + slack,
            a.z.min(b.z) - slack,
            a.z.max(b.z) + slack,
        )
        .is_some_and(|top| (top - lowest) / f.ts <= REACH_TEXELS && tol / f.ts <= REACH_TEXELS);
    if !bounded {
        case.skipped = true;
        return Ok(()); // the domain of sphere_body_whole_range
    }
    case.show(|| format!("field {}, ball {ball:?}, dt {dt}", f.label));
    let before = ball;
    let (res, after) = timed("SphereBody::step", || {
        let mut b = before;
        (b.step(dt, Vec3::ZERO, &f.collider), b)
    })?;
    match res {
        Err(_) if format!("{after:?}") != format!("{before:?}") => Err(format!(
            "a failed step changed the ball: {before:?} -> {after:?}"
        )),
        Ok(c) => check_contact("SphereBody::step", Ok(c), case),
        Err(_) => Ok(()),
    }
}

/// A ball of any state (centre, velocity, radius over the finite range) stepping by any time
/// step: its contact queries can take any reach (defects 2 and 3).
fn sphere_body_whole_range(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = any_pos(f, rng);
    let c = Vec3::new(p.x, any_f32(rng), p.y);
    let Ok(mut ball) = SphereBody::new(c, any_f32(rng).abs()) else {
        return Ok(());
    };
    ball.velocity = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng));
    let dt = any_f32(rng).abs();
    let force = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng));
    case.show(|| {
        format!(
            "field {}, ball {ball:?}, dt {dt:e}, force {force:?}",
            f.label
        )
    });
    let before = ball;
    let (res, after) = timed("SphereBody::step", || {
        let mut b = before;
        (b.step(dt, force, &f.collider), b)
    })?;
    match res {
        Err(_) if format!("{after:?}") != format!("{before:?}") => Err(format!(
            "a failed step changed the ball: {before:?} -> {after:?}"
        )),
        _ => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// CollisionWindow and construction

/// A window over a world of any valid or invalid size, moved to any finite centre, refreshed
/// and updated with rects anywhere in `i32` of any size, filled by a callback that sometimes
/// fails; its height and `contains` asked anywhere.
fn collision_window(_: &Ctx, case: &mut Case) -> Result<(), String> {
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
    for _ in 0..rng.range_u32(1, 5) {
        let center = Vec2::new(any_f32(rng), any_f32(rng));
        let fail = rng.chance(1, 6);
        match rng.below(5) {
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
            _ => {
                let _ = timed("window_at", || w.window_at(center))?;
            }
        }
        let p = Vec2::new(any_f32(rng), any_f32(rng));
        let inside = timed("contains", || w.contains(p))?;
        let h = timed("height", || w.height(p))?
            .map_err(|e| format!("window height at {p}: finite input refused: {e}"))?;
        if h.is_some() != inside {
            return Err(format!("height at {p} is {h:?} but contains says {inside}"));
        }
    }
    Ok(())
}

/// Fields built from small random grids with any texel size and encoding (invalid ones must
/// be errors), moved anywhere, then asked a height, a normal, a short ray down and a small
/// sphere near the map.
fn field_construction(_: &Ctx, case: &mut Case) -> Result<(), String> {
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

#[test]
fn fuzz_physics() {
    fn c(name: &'static str, f: fn(&Ctx, &mut Case) -> Result<(), String>) -> Class<Ctx> {
        Class { name, run: f }
    }
    harness::run(
        Target {
            name: "physics",
            // A case makes up to about twenty calls, each within CALL_LIMIT.
            per_case_limit: CALL_LIMIT * 20,
            classes: vec![
                c("height_normal_whole_range", height_normal),
                c("non_finite_inputs", non_finite_inputs),
                c("ray_near_map", ray_near_map),
                c("ray_whole_range", ray_whole_range),
                c("ray_long_walk", ray_long_walk),
                c("ray_far_origin", ray_far_origin),
                c("sphere_near_surface", sphere_near_surface),
                c("sphere_whole_range", sphere_whole_range),
                c("sphere_deep_below", sphere_deep_below),
                c("sphere_huge_radius", sphere_huge_radius),
                c("sphere_far_center", sphere_far_center),
                c("bounded_ground_near", bounded_ground_near),
                c("bounded_ground_far", bounded_ground_far),
                c("camera_body_whole_range", camera_body),
                c("camera_bounded_ground", camera_bounded_ground),
                c("sphere_body_near", sphere_body_near),
                c("sphere_body_whole_range", sphere_body_whole_range),
                c("collision_window", collision_window),
                c("field_construction", field_construction),
            ],
            disabled: DISABLED,
        },
        Ctx { fields: fields() },
    );
}
