//! The fields the classes query: heightfield colliders of every texel size from
//! `f32::MIN_POSITIVE` to `f32::MAX`, flat, rough and extreme, far from the origin or not, with
//! what the generators need to know about each (size, texel size, height bounds in f64).

use crate::FAR_TEXELS;
use glam::{UVec2, Vec3};
use terrain_core::{Grid, HeightEncoding};
use terrain_physics::{HeightField, HeightfieldCollider};
use terrain_test_support::fuzz::Rng;

/// A collider and what the generators need to know about it.
pub(crate) struct Field {
    pub(crate) collider: HeightfieldCollider,
    pub(crate) label: String,
    pub(crate) ts: f64,
    pub(crate) translation: Vec3,
    pub(crate) size: UVec2,
    /// Height bounds in metres, f64 (the field's f32 bounds may overflow to infinity).
    pub(crate) lo: f64,
    pub(crate) hi: f64,
}

impl Field {
    pub(crate) fn new(
        label: String,
        grid: Grid<u16>,
        enc: HeightEncoding,
        ts: f32,
        t: Vec3,
    ) -> Self {
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
    pub(crate) fn local(&self, x: f32, z: f32) -> (f32, f32) {
        (x - self.translation.x, z - self.translation.z)
    }

    /// The surface height at local `(x, z)` in f64, computed exactly as the collider's contact
    /// search does (the bilinear patch `a + b u + c v + d u v` of cell `floor(x / texel)` as an
    /// `i64`, wrapped, from corner heights `offset + scale * stored`), so that inputs are
    /// classified with the same rounding as the code under test sees.
    pub(crate) fn surface_local(&self, lx: f32, lz: f32) -> f64 {
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
    pub(crate) fn max_surface_box(&self, x0: f64, x1: f64, z0: f64, z1: f64) -> Option<f64> {
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
    pub(crate) fn surface(&self, x: f32, z: f32) -> f64 {
        let (lx, lz) = self.local(x, z);
        self.surface_local(lx, lz) + f64::from(self.translation.y)
    }

    /// `|x|` (axis 0) or `|z|` (axis 1) of a world position, local, in texels of this field
    /// (infinite where the local coordinate overflows f32).
    pub(crate) fn texels(&self, x: f32, z: f32, axis: usize) -> f64 {
        let (lx, lz) = self.local(x, z);
        (f64::from(if axis == 0 { lx } else { lz }) / self.ts).abs()
    }

    /// Whether the collider's local coordinates of world point `p` (`p - translation` in f32)
    /// overflow: such a point is out of every query's reach, and refusing it is a right answer
    /// (answering NaN is noted).
    pub(crate) fn overflows(&self, p: Vec3) -> bool {
        !(p - self.translation).is_finite()
    }

    pub(crate) fn is_far(&self, x: f32, z: f32) -> bool {
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

/// The target's context: the fields, built once.
pub(crate) struct Ctx {
    fields: Vec<Field>,
}

impl Ctx {
    /// The context with every field built.
    pub(crate) fn new() -> Self {
        Self { fields: fields() }
    }

    /// A field picked at random.
    pub(crate) fn field(&self, rng: &mut Rng) -> &Field {
        &self.fields[rng.index(self.fields.len())]
    }
}
