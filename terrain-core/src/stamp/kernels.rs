//! The body of [`apply_stamp`](super::apply_stamp): the exact stamp program ([`super::fixed`])
//! row by row, rows in parallel on the caller's pool, each row only over its footprint span.
//! Every texel gets the program's integer result, whatever path, thread count or instruction
//! set: the same bits as the GPU pass and as [`apply_stamp_reference`](super::apply_stamp_reference).

use super::fixed::{self, FixedBlend, FixedFrame};
use super::{Prepared, Stamp, StampKernel};
use crate::error::CoreError;
use crate::map::{HeightMap, HeightSample};
use crate::rect::DirtyRect;

/// How a stamp's value is evaluated, from [`Stamp::kernel`].
pub(super) enum Kernel {
    /// `round(beta 2^23)`.
    Gaussian(u32),
    /// Quantised values (Q24), width, height.
    Texture(Vec<i32>, u32, u32),
    /// [`Stamp::value`] per texel, converted by [`fixed::user_v31`].
    PerTexel,
}

impl Kernel {
    pub(super) fn of<S: Stamp + ?Sized>(stamp: &S) -> Self {
        match stamp.kernel() {
            StampKernel::Gaussian { beta } => Kernel::Gaussian(fixed::gaussian_beta_q(beta)),
            StampKernel::Texture(values) if values.width() > 0 && values.height() > 0 => {
                Kernel::Texture(
                    values
                        .as_slice()
                        .iter()
                        .map(|&v| fixed::quantize_texture_value(v))
                        .collect(),
                    values.width(),
                    values.height(),
                )
            }
            _ => Kernel::PerTexel,
        }
    }

    /// The value `* 2^31` at Q32 local `l` (inside the footprint), or `None` for a user value
    /// that is NaN or infinite (the texel stays unchanged).
    #[inline(always)]
    pub(super) fn v31<S: Stamp + ?Sized>(&self, stamp: &S, l: [i64; 2]) -> Option<i64> {
        match self {
            Kernel::Gaussian(beta_q) => Some(fixed::gaussian_v31(*beta_q, l)),
            Kernel::Texture(v, w, h) => Some(fixed::texture_v31(v, *w, *h, l)),
            Kernel::PerTexel => {
                let v = stamp.value(fixed::local_f32(l));
                v.is_finite().then(|| fixed::user_v31(v))
            }
        }
    }
}

/// One texel of the program: `old` blended with the value at `l`, clamped to `T`'s range.
#[inline(always)]
pub(super) fn texel<T: HeightSample, S: Stamp + ?Sized>(
    kernel: &Kernel,
    stamp: &S,
    op: &FixedBlend,
    l: [i64; 2],
    old: T,
) -> T {
    if !fixed::inside(l) {
        return old;
    }
    match kernel.v31(stamp, l) {
        Some(v) => {
            let new = op.blend(old.to_raw_f64() as i64, v);
            T::from_raw_f64_clamped(new.clamp(0, T::MAX_RAW as i64) as f64)
        }
        None => old,
    }
}

/// The shared body of [`apply_stamp`](super::apply_stamp) and
/// [`apply_stamp_window`](super::apply_stamp_window).
pub(super) fn apply_prepared<T: HeightSample, S: Stamp + ?Sized>(
    map: &mut HeightMap<T>,
    stamp: &mut S,
    prepared: Option<Prepared>,
) -> Result<Vec<DirtyRect>, CoreError> {
    let Some((pieces, frame, op)) = prepared else {
        return Ok(Vec::new());
    };
    let kernel = Kernel::of(stamp);
    let width = map.size().x as usize;
    let grid = map.grid_mut();
    for &(rect, offset) in &pieces {
        let (y0, y1) = (rect.min.y as usize, rect.max().y as usize);
        let (x0, x1) = (rect.min.x, rect.max().x);
        let rows = &mut grid.as_mut_slice()[y0 * width..y1 * width];
        let run = |j: usize, row: &mut [T]| {
            let uy = (y0 + j) as i32 + offset.y;
            row_of(
                &frame,
                &kernel,
                &*stamp,
                &op,
                uy,
                x0 + offset.x,
                x1 + offset.x,
                |ux| (ux - offset.x) as usize,
                row,
            );
        };
        match kernel {
            // A user stamp is only `Stamp`, not `Sync`: on the calling thread.
            Kernel::PerTexel => rows
                .chunks_mut(width)
                .enumerate()
                .for_each(|(j, r)| run(j, r)),
            _ => {
                let frame = &frame;
                let kernel = &kernel;
                let op = &op;
                crate::par::for_each_chunk(rows, width, |j, row| {
                    let uy = (y0 + j) as i32 + offset.y;
                    row_of(
                        frame,
                        kernel,
                        &NoStamp,
                        op,
                        uy,
                        x0 + offset.x,
                        x1 + offset.x,
                        |ux| (ux - offset.x) as usize,
                        row,
                    );
                });
            }
        }
    }
    Ok(pieces.into_iter().map(|(r, _)| r).collect())
}

/// A placeholder stamp for the kernels that never call [`Stamp::value`] (shareable between
/// threads, unlike a user's stamp).
struct NoStamp;
impl Stamp for NoStamp {
    fn value(&self, _: glam::Vec2) -> f32 {
        0.0
    }
}

/// The program over unwrapped columns `[lo, hi)` of row `uy`, texel `ux` at `row[index(ux)]`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn row_of<T: HeightSample, S: Stamp + ?Sized>(
    frame: &FixedFrame,
    kernel: &Kernel,
    stamp: &S,
    op: &FixedBlend,
    uy: i32,
    lo: i32,
    hi: i32,
    index: impl Fn(i32) -> usize,
    row: &mut [T],
) {
    let (a, b) = frame.row_span(uy, lo, hi);
    for ux in a..b {
        let d = &mut row[index(ux)];
        *d = texel(kernel, stamp, op, frame.local_q(ux, uy), *d);
    }
}
