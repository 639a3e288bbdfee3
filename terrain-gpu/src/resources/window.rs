//! The place of a layer window: a texture of `size` cells that covers the world cells
//! `origin .. origin + size` and follows the camera over a world larger than memory (the hole
//! mask's and the material layer's windows). World cell `c` lies at texel `c mod size`, so a
//! move rewrites the texture in at most four pieces and a whole map's layer is the window at
//! origin 0.

use glam::{IVec2, UVec2};
use std::sync::Arc;
use std::sync::atomic::{AtomicI32, Ordering};
use terrain_core::{CoreError, Rect};

/// A window's origin in world cells, shared by the clones of its layer (the renderers hold
/// clones), and unset until the first move.
#[derive(Debug, Clone)]
pub(crate) struct WindowOrigin(Arc<[AtomicI32; 2]>);

impl WindowOrigin {
    /// An origin not placed yet: the window covers no cell.
    pub(crate) fn unset() -> Self {
        Self(Arc::new([
            AtomicI32::new(i32::MIN),
            AtomicI32::new(i32::MIN),
        ]))
    }

    /// The origin, or `None` before the first move.
    pub(crate) fn get(&self) -> Option<IVec2> {
        let x = self.0[0].load(Ordering::Relaxed);
        let z = self.0[1].load(Ordering::Relaxed);
        (x != i32::MIN).then_some(IVec2::new(x, z))
    }

    /// Places the window (the caller has uploaded its texels).
    pub(crate) fn set(&self, origin: IVec2) {
        self.0[0].store(origin.x, Ordering::Relaxed);
        self.0[1].store(origin.y, Ordering::Relaxed);
    }
}

/// The pieces a window's cells are uploaded in: the offset of each piece's first cell in the
/// window's row-major cells, and the texels it goes to.
pub(crate) type Pieces = Vec<(u64, Rect)>;

/// A checked move of a layer of `size` cells whose place is `window` (`None`: a whole map's
/// layer) to world cell `origin`, with new cells of `data` in size: the window's origin to set
/// once they are uploaded, and the pieces to upload them in ([`window_pieces`]). Fails on a
/// whole map's layer (`what` names it), on cells of another size, and on an origin whose window
/// would leave the `i32` range of cells.
pub(crate) fn planned_move<'a>(
    window: Option<&'a WindowOrigin>,
    what: &'static str,
    size: UVec2,
    origin: IVec2,
    data: UVec2,
) -> Result<(&'a WindowOrigin, Pieces), CoreError> {
    let Some(at) = window else {
        return Err(CoreError::OutOfRange {
            what,
            value: 0.0,
            expected: "a window, not a whole map's layer",
        });
    };
    if data != size {
        return Err(CoreError::SizeMismatch {
            expected: size,
            actual: data,
        });
    }
    Ok((at, window_pieces(origin, size)?))
}

/// A checked write of the world cells `rect` (in the window's own unwrapped frame, as its
/// origin was given) with new cells of `data` in size into a window of `size` whose place is
/// `window`: the pieces of `rect` the window covers, their offsets into `data`'s row-major
/// cells. None before the window is placed or where `rect` misses it. Fails on a whole map's
/// layer (`what` names it) and on cells of another size than `rect`.
pub(crate) fn planned_write(
    window: Option<&WindowOrigin>,
    what: &'static str,
    size: UVec2,
    rect: Rect,
    data: UVec2,
) -> Result<Pieces, CoreError> {
    let Some(at) = window else {
        return Err(CoreError::OutOfRange {
            what,
            value: 0.0,
            expected: "a window, not a whole map's layer",
        });
    };
    if data != rect.size {
        return Err(CoreError::SizeMismatch {
            expected: rect.size,
            actual: data,
        });
    }
    let Some(inside) = at.get().and_then(|o| rect.intersect(&Rect::new(o, size))) else {
        return Ok(Vec::new());
    };
    Ok(inside
        .split_toroidal(size)
        .into_iter()
        .map(|piece| {
            let src = (piece.unwrapped.min - rect.min).as_uvec2();
            (
                u64::from(src.y) * u64::from(rect.size.x) + u64::from(src.x),
                piece.map,
            )
        })
        .collect())
}

/// The pieces a window of `size` at `origin` is uploaded in: for each, the offset of its first
/// cell in the window's row-major cells, and the texels it goes to. Fails on an origin whose
/// window would leave the `i32` range of cells.
fn window_pieces(origin: IVec2, size: UVec2) -> Result<Pieces, CoreError> {
    let end = origin.as_i64vec2() + size.as_i64vec2();
    if origin.min_element() == i32::MIN || end.max_element() > i64::from(i32::MAX) {
        return Err(CoreError::OutOfRange {
            what: "layer window origin",
            value: f64::from(origin.abs().max_element()),
            expected: "a window inside the i32 range of cells",
        });
    }
    Ok(Rect::new(origin, size)
        .split_toroidal(size)
        .into_iter()
        .map(|piece| {
            let src = (piece.unwrapped.min - origin).as_uvec2();
            (
                u64::from(src.y) * u64::from(size.x) + u64::from(src.x),
                piece.map,
            )
        })
        .collect())
}

/// Uploads `pieces` of `data` (row-major cells of `T`, `row` cells a row) into `texture`, a
/// texture of one `T` per texel: each piece's cells from its offset to its texels.
pub(crate) fn upload_pieces<T: bytemuck::Pod>(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    data: &[T],
    row: u32,
    pieces: &[(u64, Rect)],
) {
    let texel = std::mem::size_of::<T>() as u32;
    for &(offset, texels) in pieces {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: texels.min.x as u32,
                    y: texels.min.y as u32,
                    z: 0,
                },
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(data),
            wgpu::TexelCopyBufferLayout {
                offset: u64::from(texel) * offset,
                bytes_per_row: Some(texel * row),
                rows_per_image: Some(texels.size.y),
            },
            wgpu::Extent3d {
                width: texels.size.x,
                height: texels.size.y,
                depth_or_array_layers: 1,
            },
        );
    }
}

/// The world cells a layer of `size` covers for the frame uniform: the whole map's (`None`:
/// origin 0), or a window's (nothing before its first move).
pub(crate) fn covered(origin: Option<&WindowOrigin>, size: UVec2) -> [i32; 4] {
    let (w, h) = (size.x as i32, size.y as i32);
    match origin.map(WindowOrigin::get) {
        None => [0, 0, w, h],
        Some(Some(o)) => [o.x, o.y, w, h],
        Some(None) => [0, 0, 0, 0],
    }
}
