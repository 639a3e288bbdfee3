//! [`ProceduralSource`]: the default terrain magnified to any world size plus value-noise
//! octaves, evaluated per region. A region is computed row by row from per-column and per-row
//! positions and a lattice table per octave, which is what makes a 16384^2 world's level 0
//! (268 M samples) take seconds instead of most of the build; [`ProceduralSource::sample`] is
//! the per-texel reference it equals bit for bit.

use super::{TileSource, check_region, unreachable_grid};
use crate::CacheError;
use glam::{IVec2, UVec2};
use terrain_core::{CoarseMap, Grid, Rect, TerrainParams, WrapMode, generate_coarse_map};

/// A procedural world of any size, evaluated per region: terrain-core's default terrain at a
/// base size (held in memory, `base.size` texels) magnified to the world size by bilinear
/// interpolation with wrap addressing, plus `detail_octaves` of periodic value noise for the
/// finer scales. Deterministic, seamless under wrap, and bounded in memory by the base map.
#[derive(Debug, Clone)]
pub struct ProceduralSource {
    base: CoarseMap,
    size: UVec2,
    seed: u64,
    detail_octaves: u32,
    detail_amplitude: f64,
}

impl ProceduralSource {
    /// A world of `size` texels from the default terrain `base` (its `size` is the base map's,
    /// e.g. 1024 x 1024), with `detail_octaves` (0..=8) of value noise of total amplitude
    /// `detail_amplitude` (fraction of the u16 range, `0..=0.5`).
    pub fn new(
        size: UVec2,
        base: &TerrainParams,
        detail_octaves: u32,
        detail_amplitude: f32,
    ) -> Result<Self, CacheError> {
        if size.min_element() == 0 {
            return Err(CacheError::OutOfRange {
                what: "procedural world size",
                value: f64::from(size.min_element()),
                expected: "at least 1 texel on each side",
            });
        }
        if detail_octaves > 8 || !(0.0..=0.5).contains(&detail_amplitude) {
            return Err(CacheError::OutOfRange {
                what: "detail octaves / amplitude",
                value: f64::from(detail_amplitude),
                expected: "octaves 0..=8, amplitude 0..=0.5",
            });
        }
        let enc = terrain_core::HeightEncoding::new(1.0, 0.0)?;
        let base_map = generate_coarse_map(base, enc, 1.0)?;
        Ok(Self {
            base: base_map,
            size,
            seed: base.seed,
            detail_octaves,
            detail_amplitude: f64::from(detail_amplitude),
        })
    }

    /// The stored height at world texel `(x, y)` (what [`TileSource::region`] returns).
    pub fn sample(&self, x: u32, y: u32) -> u16 {
        let bs = self.base.size().as_dvec2();
        let ws = self.size.as_dvec2();
        let u = f64::from(x) * bs.x / ws.x;
        let v = f64::from(y) * bs.y / ws.y;
        let g = self.base.grid();
        let (x0, y0) = (u.floor(), v.floor());
        let (fx, fy) = (u - x0, v - y0);
        let at = |dx: i64, dy: i64| {
            f64::from(g.get_wrapped(
                IVec2::new(
                    WrapMode::Repeat.resolve(x0 as i64 + dx, g.width()) as i32,
                    WrapMode::Repeat.resolve(y0 as i64 + dy, g.height()) as i32,
                ),
                WrapMode::Repeat,
            ))
        };
        let top = at(0, 0) + (at(1, 0) - at(0, 0)) * fx;
        let bot = at(0, 1) + (at(1, 1) - at(0, 1)) * fx;
        let mut h = (top + (bot - top) * fy) / 65535.0;
        // Value-noise octaves, periodic over the world: octave o has 2 * base * 2^o cells.
        let mut amp = self.detail_amplitude;
        let mut norm = 0.0;
        let mut a = 1.0;
        for _ in 0..self.detail_octaves {
            norm += a;
            a *= 0.5;
        }
        if norm > 0.0 {
            amp /= norm;
        }
        for o in 0..self.detail_octaves {
            let period = (bs * f64::from(2u32 << o)).as_uvec2();
            let cu = f64::from(x) * f64::from(period.x) / ws.x;
            let cv = f64::from(y) * f64::from(period.y) / ws.y;
            h += amp * value_noise(self.seed, o, cu, cv, period);
            amp *= 0.5;
        }
        (h.clamp(0.0, 1.0) * 65535.0).round() as u16
    }
}

/// Periodic value noise in `[-1, 1]` with smoothstep interpolation.
fn value_noise(seed: u64, octave: u32, u: f64, v: f64, period: UVec2) -> f64 {
    let (i, j) = (u.floor(), v.floor());
    let (fx, fy) = (u - i, v - j);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let lat = |di: u64, dj: u64| lattice(seed, octave, i as u64 + di, j as u64 + dj, period);
    let top = lat(0, 0) + (lat(1, 0) - lat(0, 0)) * sx;
    let bot = lat(0, 1) + (lat(1, 1) - lat(0, 1)) * sx;
    top + (bot - top) * sy
}

/// The value in `[-1, 1]` at lattice point `(i, j)` of an octave, wrapped by its period.
fn lattice(seed: u64, octave: u32, i: u64, j: u64, period: UVec2) -> f64 {
    let ii = i % u64::from(period.x.max(1));
    let jj = j % u64::from(period.y.max(1));
    let h = mix64(seed ^ (u64::from(octave) << 58) ^ (ii << 29) ^ jj ^ 0x9E37_79B9_7F4A_7C15);
    (h >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Where one world column (or row) falls in the base map and in each octave's lattice: the
/// arithmetic of [`ProceduralSource::sample`] for one axis, done once per column or row.
#[derive(Debug, Clone, Copy, Default)]
struct AxisPos {
    /// Base-map samples below and above, wrapped.
    b0: usize,
    b1: usize,
    /// Fraction between them.
    bf: f64,
    /// Per octave: the lattice cell (before wrapping) and the smoothstepped fraction in it.
    cell: [u64; MAX_OCTAVES],
    s: [f64; MAX_OCTAVES],
}

/// The most detail octaves ([`ProceduralSource::new`] refuses more).
const MAX_OCTAVES: usize = 8;

impl ProceduralSource {
    /// Positions along one axis: `t` the world coordinate, `base` / `world` that axis's base-map
    /// and world sizes, `axis` 0 for X (columns), 1 for Y (rows).
    fn axis_pos(&self, t: u32, axis: usize) -> AxisPos {
        let bs = self.base.size().as_dvec2().to_array()[axis];
        let ws = self.size.as_dvec2().to_array()[axis];
        let n = self.base.size().to_array()[axis];
        let u = f64::from(t) * bs / ws;
        let u0 = u.floor();
        let mut p = AxisPos {
            b0: WrapMode::Repeat.resolve(u0 as i64, n) as usize,
            b1: WrapMode::Repeat.resolve(u0 as i64 + 1, n) as usize,
            bf: u - u0,
            ..AxisPos::default()
        };
        for o in 0..self.detail_octaves as usize {
            let period = self.period(o as u32).to_array()[axis];
            let c = f64::from(t) * f64::from(period) / ws;
            let i = c.floor();
            let f = c - i;
            p.cell[o] = i as u64;
            p.s[o] = f * f * (3.0 - 2.0 * f);
        }
        p
    }

    /// Lattice cells across and down octave `o` over the whole world.
    fn period(&self, o: u32) -> UVec2 {
        (self.base.size().as_dvec2() * f64::from(2u32 << o)).as_uvec2()
    }

    /// The amplitude of each octave, as `sample` steps through them.
    fn amplitudes(&self) -> [f64; MAX_OCTAVES] {
        let mut amp = self.detail_amplitude;
        let mut norm = 0.0;
        let mut a = 1.0;
        for _ in 0..self.detail_octaves {
            norm += a;
            a *= 0.5;
        }
        if norm > 0.0 {
            amp /= norm;
        }
        let mut out = [0.0; MAX_OCTAVES];
        for slot in out.iter_mut().take(self.detail_octaves as usize) {
            *slot = amp;
            amp *= 0.5;
        }
        out
    }
}

/// One octave's lattice values over the cells a region's texels read: each texel its cell and
/// the next, per axis. Only those cells are kept, so the table has at most (2 cols) x (2 rows)
/// values however fine the octave is against the texels (a small world under a large base has
/// many cells per texel).
struct Lattice {
    /// Per column / row of the region: the index of its cell in the table's axis (the next
    /// cell is the index after it).
    col_at: Vec<usize>,
    row_at: Vec<usize>,
    width: usize,
    values: Vec<f64>,
}

/// The cells an axis's texels read, increasing, and where each texel's pair starts. The cells
/// do not decrease along the axis, so a texel shares its pair with the one before or adds one
/// or two cells.
fn axis_cells(p: &[AxisPos], o: usize) -> (Vec<u64>, Vec<usize>) {
    let mut cells: Vec<u64> = Vec::with_capacity(2 * p.len());
    let mut at = Vec::with_capacity(p.len());
    for a in p {
        let c = a.cell[o];
        let n = cells.len();
        if n >= 2 && cells[n - 2] == c {
            // The same pair as the texel before.
        } else if cells.last() == Some(&c) {
            cells.push(c + 1);
        } else {
            cells.extend([c, c + 1]);
        }
        at.push(cells.len() - 2);
    }
    (cells, at)
}

impl Lattice {
    fn new(src: &ProceduralSource, o: u32, cols: &[AxisPos], rows: &[AxisPos]) -> Self {
        let (xs, col_at) = axis_cells(cols, o as usize);
        let (ys, row_at) = axis_cells(rows, o as usize);
        let period = src.period(o);
        let mut values = Vec::with_capacity(xs.len() * ys.len());
        for &j in &ys {
            for &i in &xs {
                values.push(lattice(src.seed, o, i, j, period));
            }
        }
        Self {
            col_at,
            row_at,
            width: xs.len(),
            values,
        }
    }
}

impl TileSource for ProceduralSource {
    type Error = CacheError;
    fn size(&self) -> UVec2 {
        self.size
    }
    fn region(&self, rect: Rect) -> Result<Grid<u16>, Self::Error> {
        check_region(rect, self.size)?;
        let (x0, y0) = (rect.min.x as u32, rect.min.y as u32);
        let cols: Vec<AxisPos> = (0..rect.size.x).map(|x| self.axis_pos(x0 + x, 0)).collect();
        let rows: Vec<AxisPos> = (0..rect.size.y).map(|y| self.axis_pos(y0 + y, 1)).collect();
        let octaves = self.detail_octaves as usize;
        let lattices: Vec<Lattice> = (0..octaves as u32)
            .map(|o| Lattice::new(self, o, &cols, &rows))
            .collect();
        let amps = self.amplitudes();
        let g = self.base.grid().as_slice();
        let bw = self.base.size().x as usize;
        let mut data = Vec::with_capacity(cols.len() * rows.len());
        for (y, r) in rows.iter().enumerate() {
            let (row0, row1) = (&g[r.b0 * bw..][..bw], &g[r.b1 * bw..][..bw]);
            // Each octave's two lattice rows of this texel row.
            let lat_rows: Vec<(&[f64], &[f64])> = lattices
                .iter()
                .map(|l| {
                    let j = l.row_at[y];
                    (
                        &l.values[j * l.width..][..l.width],
                        &l.values[(j + 1) * l.width..][..l.width],
                    )
                })
                .collect();
            for (x, c) in cols.iter().enumerate() {
                let at = |row: &[u16], i: usize| f64::from(row[i]);
                let top = at(row0, c.b0) + (at(row0, c.b1) - at(row0, c.b0)) * c.bf;
                let bot = at(row1, c.b0) + (at(row1, c.b1) - at(row1, c.b0)) * c.bf;
                let mut h = (top + (bot - top) * r.bf) / 65535.0;
                for (o, (l0, l1)) in lat_rows.iter().enumerate() {
                    let i = lattices[o].col_at[x];
                    let (sx, sy) = (c.s[o], r.s[o]);
                    let top = l0[i] + (l0[i + 1] - l0[i]) * sx;
                    let bot = l1[i] + (l1[i + 1] - l1[i]) * sx;
                    h += amps[o] * (top + (bot - top) * sy);
                }
                data.push((h.clamp(0.0, 1.0) * 65535.0).round() as u16);
            }
        }
        // The rect is non-empty and its area fits (a tile at most), so this cannot fail.
        Ok(Grid::from_vec(rect.size.x, rect.size.y, data).unwrap_or_else(|_| unreachable_grid()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn region_equals_sample_bit_for_bit() {
        for (world, base, octaves) in [(1000u32, 64u32, 4u32), (256, 32, 0), (777, 100, 8)] {
            let params = TerrainParams {
                size: UVec2::splat(base),
                ..TerrainParams::default()
            };
            let src =
                ProceduralSource::new(UVec2::new(world, world / 2 + 3), &params, octaves, 0.1)
                    .unwrap();
            let rect = Rect::new(IVec2::new(37, 11), UVec2::new(90, 70));
            let got = src.region(rect).unwrap();
            for y in 0..70 {
                for x in 0..90 {
                    assert_eq!(
                        got.get(x, y),
                        Some(src.sample(37 + x, 11 + y)),
                        "world {world} ({x}, {y})"
                    );
                }
            }
            // The world's last row and column (the lattice wraps there).
            let s = src.size();
            let corner = Rect::new((s - UVec2::splat(5)).as_ivec2(), UVec2::splat(5));
            let got = src.region(corner).unwrap();
            assert_eq!(got.get(4, 4), Some(src.sample(s.x - 1, s.y - 1)));
        }
    }

    /// A world smaller than its base has many lattice cells per texel in its finest octaves
    /// (here 131 072 cells across 256 texels): a tile's table keeps only the cells its texels
    /// read (it used to span every cell between them, about 136 GB), and equals the reference.
    #[test]
    fn fine_octaves_over_a_small_world_keep_the_table_small() {
        let params = TerrainParams {
            size: UVec2::splat(512),
            ..TerrainParams::default()
        };
        let src = ProceduralSource::new(UVec2::splat(256), &params, 8, 0.1).unwrap();
        let rect = Rect::from_size(UVec2::splat(256));
        let got = src.region(rect).unwrap();
        for (x, y) in [(0, 0), (1, 0), (255, 3), (128, 255), (255, 255)] {
            assert_eq!(got.get(x, y), Some(src.sample(x, y)), "({x}, {y})");
        }
        let cols: Vec<AxisPos> = (0..256).map(|x| src.axis_pos(x, 0)).collect();
        let rows: Vec<AxisPos> = (0..256).map(|y| src.axis_pos(y, 1)).collect();
        let l = Lattice::new(&src, 7, &cols, &rows);
        assert!(l.values.len() <= 512 * 512, "{} values", l.values.len());
    }

    /// Rects off the world, empty or too large are refused before anything is computed.
    #[test]
    fn regions_off_the_world_are_refused() {
        let params = TerrainParams {
            size: UVec2::splat(32),
            ..TerrainParams::default()
        };
        let src = ProceduralSource::new(UVec2::splat(100), &params, 2, 0.1).unwrap();
        for rect in [
            Rect::new(IVec2::new(-1, 0), UVec2::splat(4)),
            Rect::new(IVec2::new(98, 0), UVec2::splat(4)),
            Rect::new(IVec2::ZERO, UVec2::ZERO),
            Rect::new(IVec2::ZERO, UVec2::splat(u32::MAX)),
            Rect::new(IVec2::splat(i32::MAX), UVec2::splat(1)),
        ] {
            assert!(src.region(rect).is_err(), "{rect:?}");
        }
    }
}
