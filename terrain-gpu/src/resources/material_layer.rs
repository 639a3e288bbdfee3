//! [`GpuMaterialLayer`]: a material layer (a splat map, `terrain_core::material_effect`) on the
//! GPU, painted by [`crate::MaterialEffectPass`] and drawn by every renderer
//! (`set_material_layer`).
//!
//! Two copies: a storage buffer the effect pass reads and writes (rows padded to 256 bytes),
//! and a texture the renderers read at binding 14. The pass copies the rects it painted from
//! the one to the other in the same command encoder. Why not one: a texture cannot be read and
//! written by a compute pass on every backend (read-write storage textures of RGBA8 are not in
//! WebGPU, and GL has none), and a fifth storage buffer is more than the renderers' fragment
//! stage may bind on some devices (the detail surface already binds four).
//!
//! A world larger than memory draws its paint (its `Layer::Material` tiles) through a window
//! of cells that follows the camera ([`GpuMaterialLayer::window`], placed by
//! [`GpuMaterialLayer::move_window`], as `GpuHoleMask`'s): written on the CPU, not painted by
//! the effect passes, and faded out over the outer eighth of the window so its moves never
//! pop.

use crate::device::download::download_bytes;
use crate::error::GpuError;
use crate::resources::maps::map_buffer;
use crate::resources::materials::rgba8_texture_with;
use crate::resources::window::{WindowOrigin, covered, planned_move, planned_write, upload_pieces};
use glam::{IVec2, UVec2};
use terrain_core::{CoreError, Grid, Rect};

/// Texels per padded row of the layer's buffer: a multiple of 64 (256 bytes, the row alignment
/// of a buffer-to-texture copy).
fn pitch(width: u32) -> u32 {
    width.div_ceil(64) * 64
}

/// A material layer on the GPU (see the module docs). Cloning shares the buffer and texture.
#[derive(Debug, Clone)]
pub struct GpuMaterialLayer {
    pub(crate) buffer: wgpu::Buffer,
    pub(crate) texture: wgpu::Texture,
    pub(crate) view: wgpu::TextureView,
    pub(crate) size: UVec2,
    pub(crate) pitch: u32,
    /// A window's origin, or `None` for the whole map's layer.
    origin: Option<WindowOrigin>,
}

impl GpuMaterialLayer {
    /// Uploads `layer` (row-major, one `[grass, dirt, rock, snow]` weight per map texel; all
    /// zero for the autoshader everywhere). Fails on a side above the device's
    /// `max_texture_dimension_2d` or a layer larger than one storage buffer may be.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        layer: &Grid<[u8; 4]>,
    ) -> Result<Self, GpuError> {
        let size = layer.size();
        let max = device.limits().max_texture_dimension_2d;
        if size.max_element() > max {
            return Err(CoreError::OutOfRange {
                what: "material layer side",
                value: f64::from(size.max_element()),
                expected: "at most the device's max_texture_dimension_2d",
            }
            .into());
        }
        let pitch = pitch(size.x);
        let bytes = 4 * u64::from(pitch) * u64::from(size.y);
        let buffer = map_buffer(device, "GpuMaterialLayer", size, bytes)?;
        let mut padded = vec![[0u8; 4]; pitch as usize * size.y as usize];
        for (y, row) in padded.chunks_exact_mut(pitch as usize).enumerate() {
            row[..size.x as usize].copy_from_slice(layer.row(y as u32));
        }
        queue.write_buffer(&buffer, 0, bytemuck::cast_slice(&padded));
        let (texture, view) = rgba8_texture_with(
            device,
            queue,
            "material layer",
            size,
            layer.as_slice(),
            wgpu::TextureUsages::empty(),
        )?;
        Ok(Self {
            buffer,
            texture,
            view,
            size,
            pitch,
            origin: None,
        })
    }

    /// A window of `side` x `side` cells over a larger world: unpainted, and covering no cell
    /// until [`GpuMaterialLayer::move_window`] places it. Effect passes refuse it (its paint
    /// is written on the CPU). Fails as [`GpuMaterialLayer::new`] does, and on a side of 0.
    pub fn window(device: &wgpu::Device, queue: &wgpu::Queue, side: u32) -> Result<Self, GpuError> {
        if side == 0 {
            return Err(CoreError::OutOfRange {
                what: "material window side",
                value: 0.0,
                expected: "at least 1 cell",
            }
            .into());
        }
        let max = device.limits().max_texture_dimension_2d;
        if side > max {
            return Err(CoreError::OutOfRange {
                what: "material window side",
                value: f64::from(side),
                expected: "at most the device's max_texture_dimension_2d",
            }
            .into());
        }
        let size = UVec2::splat(side);
        let zeros = vec![[0u8; 4]; side as usize * side as usize];
        let (texture, view) = rgba8_texture_with(
            device,
            queue,
            "material window",
            size,
            &zeros,
            wgpu::TextureUsages::empty(),
        )?;
        // No pass paints a window, so its buffer is a stand-in of one padded row.
        let buffer = map_buffer(device, "GpuMaterialLayer window", UVec2::ONE, 256)?;
        Ok(Self {
            buffer,
            texture,
            view,
            size,
            pitch: 0,
            origin: Some(WindowOrigin::unset()),
        })
    }

    /// Whether this is a window ([`GpuMaterialLayer::window`]).
    pub fn is_window(&self) -> bool {
        self.origin.is_some()
    }

    /// The world cells it covers: origin (x, z) and size. A window covers none (size 0) until
    /// its first [`GpuMaterialLayer::move_window`].
    pub fn covered(&self) -> [i32; 4] {
        covered(self.origin.as_ref(), self.size)
    }

    /// Places a window at world cell `origin` with `paint`, the material layer of the cells
    /// `origin .. origin + side` (as `terrain_cache::read_paint` returns it), drawn from the
    /// next submission on. Fails, with nothing changed, on the whole map's layer, on paint of
    /// another size than the window and on an origin whose window would leave `i32`.
    pub fn move_window(
        &self,
        queue: &wgpu::Queue,
        origin: IVec2,
        paint: &Grid<[u8; 4]>,
    ) -> Result<(), GpuError> {
        let (at, pieces) = planned_move(
            self.origin.as_ref(),
            "material layer to move",
            self.size,
            origin,
            paint.size(),
        )?;
        upload_pieces(queue, &self.texture, paint.as_slice(), self.size.x, &pieces);
        at.set(origin);
        Ok(())
    }

    /// Rewrites the world cells `rect` of a placed window with `paint`, their material layer
    /// (after a crater painted them; the cells outside the window are left out). Fails on the
    /// whole map's layer and on paint of another size than `rect`.
    pub fn update_window(
        &self,
        queue: &wgpu::Queue,
        rect: Rect,
        paint: &Grid<[u8; 4]>,
    ) -> Result<(), GpuError> {
        let pieces = planned_write(
            self.origin.as_ref(),
            "material layer to update",
            self.size,
            rect,
            paint.size(),
        )?;
        upload_pieces(queue, &self.texture, paint.as_slice(), rect.size.x, &pieces);
        Ok(())
    }

    /// Refuses a window where a pass paints the layer (a window's paint is the CPU's).
    pub(crate) fn check_paintable(&self) -> Result<(), GpuError> {
        if self.is_window() {
            return Err(CoreError::OutOfRange {
                what: "material layer to paint on the GPU",
                value: 0.0,
                expected: "a whole map's layer (a window's paint is written by move_window)",
            }
            .into());
        }
        Ok(())
    }

    /// The layer's size in texels (the map's it is drawn over).
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// GPU bytes: the buffer's padded rows and the texture, 4 bytes per texel each (a
    /// window: its texture).
    pub fn bytes(&self) -> u64 {
        4 * (u64::from(self.pitch) + u64::from(self.size.x)) * u64::from(self.size.y)
    }

    /// Downloads the layer (waiting for the GPU): what to write back after effects painted it.
    /// Fails on a window (its paint is the CPU's already).
    pub fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Grid<[u8; 4]>, GpuError> {
        self.check_paintable()?;
        let bytes = download_bytes(device, queue, &self.buffer, 0, self.buffer.size())?;
        let texels: &[[u8; 4]] = bytemuck::cast_slice(&bytes);
        let mut out = Vec::with_capacity(self.size.x as usize * self.size.y as usize);
        for row in texels.chunks_exact(self.pitch as usize) {
            out.extend_from_slice(&row[..self.size.x as usize]);
        }
        Ok(Grid::from_vec(self.size.x, self.size.y, out)?)
    }

    /// Records the copy of `rect` (layer texels) from the buffer to the texture.
    pub(crate) fn copy_to_texture(&self, encoder: &mut wgpu::CommandEncoder, rect: Rect) {
        let offset = 4 * (u64::from(rect.min.y as u32) * u64::from(self.pitch) + rect.min.x as u64);
        encoder.copy_buffer_to_texture(
            wgpu::TexelCopyBufferInfo {
                buffer: &self.buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset,
                    bytes_per_row: Some(4 * self.pitch),
                    rows_per_image: Some(rect.size.y),
                },
            },
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: rect.min.x as u32,
                    y: rect.min.y as u32,
                    z: 0,
                },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::Extent3d {
                width: rect.size.x,
                height: rect.size.y,
                depth_or_array_layers: 1,
            },
        );
    }
}
