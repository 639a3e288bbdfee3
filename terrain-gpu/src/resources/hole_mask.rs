//! [`GpuHoleMask`]: a hole mask (`terrain_core::holes`) on the GPU, bound by every renderer at
//! binding 15 (`set_hole_mask`), whose fragments discard over a hole.
//!
//! The mask is authored on the CPU and uploaded by rect ([`GpuHoleMask::write`]): collision
//! needs it on the CPU anyway, it is one byte per cell and it changes rarely, so an upload of
//! the cells a stamp changed costs less than a compute pass and a readback would.
//!
//! Two shapes: the whole map's mask ([`GpuHoleMask::new`]), or a window of cells that follows
//! the camera over a world larger than memory ([`GpuHoleMask::window`], placed by
//! [`GpuHoleMask::move_window`]); cells outside a window are drawn as ground. Either way world
//! cell `c` lies at texel `c mod size`, so the whole map's mask is the window at origin 0.

use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::resources::window::{WindowOrigin, covered, planned_move, planned_write, upload_pieces};
use glam::{IVec2, UVec2};
use terrain_core::{CoreError, Grid, HoleWindowTarget, Rect};

/// A hole mask on the GPU: an R8 texture of one texel per cell, nonzero where the ground is
/// cut away. Cloning shares the texture and the window's place.
#[derive(Debug, Clone)]
pub struct GpuHoleMask {
    pub(crate) view: wgpu::TextureView,
    texture: wgpu::Texture,
    pub(crate) size: UVec2,
    /// A window's origin, or `None` for the whole map's mask.
    origin: Option<WindowOrigin>,
}

/// A hole mask window with the queue its uploads go through: terrain-core's
/// [`HoleWindowTarget`], which terrain-cache's `HoleWindow` places around the camera.
#[derive(Debug, Clone, Copy)]
pub struct HoleWindowUpload<'a> {
    /// The queue the uploads are written through.
    pub queue: &'a wgpu::Queue,
    /// The window ([`GpuHoleMask::window`]).
    pub mask: &'a GpuHoleMask,
}

impl HoleWindowTarget for HoleWindowUpload<'_> {
    type Error = GpuError;

    /// [`GpuHoleMask::move_window`].
    fn place(&mut self, origin: IVec2, mask: &Grid<u8>) -> Result<(), GpuError> {
        self.mask.move_window(self.queue, origin, mask)
    }

    /// [`GpuHoleMask::update_window`].
    fn update(&mut self, rect: Rect, mask: &Grid<u8>) -> Result<(), GpuError> {
        self.mask.update_window(self.queue, rect, mask)
    }
}

impl GpuHoleMask {
    /// Uploads `mask` (row-major, one byte per map cell, 0 for ground), the whole map's. Fails
    /// on a side above the device's `max_texture_dimension_2d`.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mask: &Grid<u8>,
    ) -> Result<Self, GpuError> {
        let out = Self::with_texture(device, mask.size(), None)?;
        out.write(queue, mask, Rect::from_size(out.size))?;
        Ok(out)
    }

    /// A window of `side` x `side` cells over a larger world: all ground, and covering no cell
    /// until [`GpuHoleMask::move_window`] places it. Fails on a side of 0 or above the device's
    /// `max_texture_dimension_2d`.
    pub fn window(device: &wgpu::Device, side: u32) -> Result<Self, GpuError> {
        Self::with_texture(device, UVec2::splat(side), Some(WindowOrigin::unset()))
    }

    fn with_texture(
        device: &wgpu::Device,
        size: UVec2,
        origin: Option<WindowOrigin>,
    ) -> Result<Self, GpuError> {
        let max = device.limits().max_texture_dimension_2d;
        if size.min_element() == 0 || size.max_element() > max {
            return Err(CoreError::OutOfRange {
                what: "hole mask side",
                value: f64::from(size.max_element().max(size.min_element())),
                expected: "1 up to the device's max_texture_dimension_2d",
            }
            .into());
        }
        let texture = scoped(device, "hole mask", || {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("hole mask"),
                size: wgpu::Extent3d {
                    width: size.x,
                    height: size.y,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        })?;
        let view = texture.create_view(&Default::default());
        Ok(Self {
            view,
            texture,
            size,
            origin,
        })
    }

    /// The mask's size in cells: the map's, or the window's.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// GPU bytes: one per cell.
    pub fn bytes(&self) -> u64 {
        u64::from(self.size.x) * u64::from(self.size.y)
    }

    /// Whether this is a window ([`GpuHoleMask::window`]).
    pub fn is_window(&self) -> bool {
        self.origin.is_some()
    }

    /// The world cells it covers: origin (x, z) and size. A window covers none (size 0) until
    /// its first [`GpuHoleMask::move_window`].
    pub fn covered(&self) -> [i32; 4] {
        covered(self.origin.as_ref(), self.size)
    }

    /// Places a window at world cell `origin` with `mask`, the hole mask of the cells
    /// `origin .. origin + side` (row-major, as `terrain_cache::read_holes` returns it), drawn
    /// from the next submission on. Fails, with nothing changed, on the whole map's mask, on a
    /// mask of another size than the window, and on an origin whose window would leave `i32`.
    pub fn move_window(
        &self,
        queue: &wgpu::Queue,
        origin: IVec2,
        mask: &Grid<u8>,
    ) -> Result<(), GpuError> {
        let (at, pieces) = planned_move(
            self.origin.as_ref(),
            "hole mask to move",
            self.size,
            origin,
            mask.size(),
        )?;
        upload_pieces(queue, &self.texture, mask.as_slice(), self.size.x, &pieces);
        at.set(origin);
        Ok(())
    }

    /// Uploads `rect` of `mask` (the whole map's mask, as the CPU holds it; e.g. a rect that
    /// `terrain_core::apply_hole_stamp` returned), drawn from the next submission on. Fails,
    /// with nothing uploaded, on a window (rewritten whole by [`GpuHoleMask::move_window`]), a
    /// mask of another size, or a rect not inside it.
    pub fn write(&self, queue: &wgpu::Queue, mask: &Grid<u8>, rect: Rect) -> Result<(), GpuError> {
        if self.is_window() {
            return Err(CoreError::OutOfRange {
                what: "hole mask to write by rect",
                value: 0.0,
                expected: "a whole map's mask (a window is written by move_window)",
            }
            .into());
        }
        if mask.size() != self.size {
            return Err(CoreError::SizeMismatch {
                expected: self.size,
                actual: mask.size(),
            }
            .into());
        }
        if !Rect::from_size(self.size).contains_rect(&rect) {
            return Err(CoreError::RegionOutOfBounds {
                rect,
                map_size: self.size,
            }
            .into());
        }
        if rect.is_empty() {
            return Ok(());
        }
        let offset = u64::from(rect.min.y as u32) * u64::from(self.size.x) + rect.min.x as u64;
        upload_pieces(
            queue,
            &self.texture,
            mask.as_slice(),
            self.size.x,
            &[(offset, rect)],
        );
        Ok(())
    }

    /// Rewrites the world cells `rect` of a placed window with `mask`, their hole mask (after a
    /// cut changed them; the cells outside the window are left out). Fails on the whole map's
    /// mask and on a mask of another size than `rect`.
    pub fn update_window(
        &self,
        queue: &wgpu::Queue,
        rect: Rect,
        mask: &Grid<u8>,
    ) -> Result<(), GpuError> {
        let pieces = planned_write(
            self.origin.as_ref(),
            "hole mask to update",
            self.size,
            rect,
            mask.size(),
        )?;
        upload_pieces(queue, &self.texture, mask.as_slice(), rect.size.x, &pieces);
        Ok(())
    }
}
