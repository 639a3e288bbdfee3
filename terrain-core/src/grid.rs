//! The row-major 2D grid every map is stored in, and the wrap modes used to address it.

use crate::error::CoreError;
use crate::rect::Rect;
use glam::{IVec2, UVec2};

/// How a map is addressed outside `0..size`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum WrapMode {
    /// Toroidal addressing: the coarse-map repeats in both directions (Flower 2010, sec. 3.1.1).
    #[default]
    Repeat,
    /// Clamp to the edge texel: detail-map tiles end at their borders.
    Clamp,
}

impl WrapMode {
    /// Maps a possibly out-of-range coordinate on an axis of length `n > 0` to `0..n`.
    #[inline]
    pub fn resolve(self, i: i64, n: u32) -> u32 {
        match self {
            WrapMode::Repeat => i.rem_euclid(i64::from(n)) as u32,
            WrapMode::Clamp => i.clamp(0, i64::from(n) - 1) as u32,
        }
    }
}

/// A `width x height` grid of samples stored row by row: sample `(x, y)` is at `y * width + x`.
///
/// Column `x` maps to world X and row `y` to world Z (see the crate docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Grid<T> {
    width: u32,
    height: u32,
    data: Vec<T>,
}

/// Checks a grid size and returns its sample count.
pub(crate) fn sample_count(width: u32, height: u32) -> Result<usize, CoreError> {
    if width == 0 || height == 0 {
        return Err(CoreError::EmptyGrid { width, height });
    }
    (width as usize)
        .checked_mul(height as usize)
        .ok_or(CoreError::GridTooLarge { width, height })
}

impl<T: Copy> Grid<T> {
    /// A grid filled with `value`. Fails on a zero side or an unaddressable size.
    pub fn new(width: u32, height: u32, value: T) -> Result<Self, CoreError> {
        let n = sample_count(width, height)?;
        Ok(Self {
            width,
            height,
            data: vec![value; n],
        })
    }

    /// A grid over existing row-major data. Fails if `data.len() != width * height`.
    pub fn from_vec(width: u32, height: u32, data: Vec<T>) -> Result<Self, CoreError> {
        let n = sample_count(width, height)?;
        if data.len() != n {
            return Err(CoreError::DataLength {
                len: data.len(),
                width,
                height,
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// A grid whose sample `(x, y)` is `f(x, y)`.
    pub fn from_fn(
        width: u32,
        height: u32,
        mut f: impl FnMut(u32, u32) -> T,
    ) -> Result<Self, CoreError> {
        let n = sample_count(width, height)?;
        let mut data = Vec::with_capacity(n);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Width in samples.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in samples.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Width and height.
    pub fn size(&self) -> UVec2 {
        UVec2::new(self.width, self.height)
    }

    /// The whole grid as a rect.
    pub fn rect(&self) -> Rect {
        Rect::from_size(self.size())
    }

    /// Sample at `(x, y)`, or `None` outside the grid.
    pub fn get(&self, x: u32, y: u32) -> Option<T> {
        (x < self.width && y < self.height).then(|| self.data[self.index(x, y)])
    }

    /// Sample at a possibly out-of-range texel, addressed with `wrap`.
    #[inline]
    pub fn get_wrapped(&self, p: IVec2, wrap: WrapMode) -> T {
        let x = wrap.resolve(i64::from(p.x), self.width);
        let y = wrap.resolve(i64::from(p.y), self.height);
        self.data[self.index(x, y)]
    }

    /// Mutable sample at `(x, y)`, or `None` outside the grid.
    pub fn get_mut(&mut self, x: u32, y: u32) -> Option<&mut T> {
        if x < self.width && y < self.height {
            let i = self.index(x, y);
            Some(&mut self.data[i])
        } else {
            None
        }
    }

    /// Index of `(x, y)` in [`Grid::as_slice`]; the caller keeps `(x, y)` inside the grid.
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }

    /// Row `y` (panics if `y >= height`: rows are addressed by callers that checked the size).
    pub fn row(&self, y: u32) -> &[T] {
        let start = y as usize * self.width as usize;
        &self.data[start..start + self.width as usize]
    }

    /// Mutable row `y` (panics if `y >= height`).
    pub fn row_mut(&mut self, y: u32) -> &mut [T] {
        let start = y as usize * self.width as usize;
        let w = self.width as usize;
        &mut self.data[start..start + w]
    }

    /// All samples, row-major.
    pub fn as_slice(&self) -> &[T] {
        &self.data
    }

    /// All samples, row-major, mutable.
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// The samples, row-major.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }

    /// A copy of the samples in `rect`, which must lie inside the grid.
    pub fn copy_rect(&self, rect: Rect) -> Result<Grid<T>, CoreError> {
        if rect.is_empty() || !self.rect().contains_rect(&rect) {
            return Err(CoreError::RegionOutOfBounds {
                rect,
                map_size: self.size(),
            });
        }
        let (x0, y0) = (rect.min.x as usize, rect.min.y as usize);
        let w = rect.size.x as usize;
        let mut data = Vec::with_capacity(rect.area() as usize);
        for y in y0..y0 + rect.size.y as usize {
            let start = y * self.width as usize + x0;
            data.extend_from_slice(&self.data[start..start + w]);
        }
        Grid::from_vec(rect.size.x, rect.size.y, data)
    }

    /// Writes `src` with its first sample at `at`; `src` must fit inside the grid there.
    pub fn paste(&mut self, src: &Grid<T>, at: IVec2) -> Result<(), CoreError> {
        let rect = Rect::new(at, src.size());
        if !self.rect().contains_rect(&rect) {
            return Err(CoreError::RegionOutOfBounds {
                rect,
                map_size: self.size(),
            });
        }
        for y in 0..src.height {
            let start = self.index(at.x as u32, at.y as u32 + y);
            self.data[start..start + src.width as usize].copy_from_slice(src.row(y));
        }
        Ok(())
    }

    /// The grid shifted cyclically: sample `(x, y)` moves to `(x + shift.x, y + shift.y)` mod size.
    pub fn shifted_cyclic(&self, shift: IVec2) -> Grid<T> {
        let mut out = self.clone();
        for y in 0..self.height {
            for x in 0..self.width {
                let tx = WrapMode::Repeat.resolve(i64::from(x) + i64::from(shift.x), self.width);
                let ty = WrapMode::Repeat.resolve(i64::from(y) + i64::from(shift.y), self.height);
                let i = out.index(tx, ty);
                out.data[i] = self.data[self.index(x, y)];
            }
        }
        out
    }

    /// A grid of the same size with `f` applied to every sample.
    pub fn map<U: Copy>(&self, f: impl FnMut(&T) -> U) -> Grid<U> {
        Grid {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(f).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_empty_and_mismatched() {
        assert!(matches!(
            Grid::new(0, 3, 0u8),
            Err(CoreError::EmptyGrid { .. })
        ));
        assert!(matches!(
            Grid::from_vec(2, 2, vec![0u8; 3]),
            Err(CoreError::DataLength { len: 3, .. })
        ));
    }

    #[test]
    fn wrap_modes_address_outside() {
        let g = Grid::from_fn(3, 2, |x, y| x + 10 * y).unwrap();
        assert_eq!(g.get_wrapped(IVec2::new(-1, 0), WrapMode::Repeat), 2);
        assert_eq!(g.get_wrapped(IVec2::new(4, 3), WrapMode::Repeat), 11);
        assert_eq!(g.get_wrapped(IVec2::new(-5, 9), WrapMode::Clamp), 10);
    }

    #[test]
    fn copy_paste_and_shift() {
        let g = Grid::from_fn(4, 4, |x, y| x + 4 * y).unwrap();
        let sub = g
            .copy_rect(Rect::new(IVec2::new(1, 1), UVec2::new(2, 2)))
            .unwrap();
        assert_eq!(sub.as_slice(), &[5, 6, 9, 10]);
        let mut h = Grid::new(4, 4, 0).unwrap();
        h.paste(&sub, IVec2::new(2, 2)).unwrap();
        assert_eq!(h.get(3, 3), Some(10));
        assert!(h.paste(&sub, IVec2::new(3, 3)).is_err());
        let s = g.shifted_cyclic(IVec2::new(1, -1));
        assert_eq!(s.get(1, 3), Some(0));
        assert_eq!(s.shifted_cyclic(IVec2::new(-1, 1)), g);
    }
}
