//! [`GpuOverlayAtlas`]: a streamed world's paint or colour on the GPU, in tile slots beside the
//! heights' `GpuTileAtlas`, implementing terrain-core's [`OverlayUploadTarget`] (CPU reference:
//! [`terrain_core::OverlayAtlas`], whose `sample` is what the renderers' `streamed_layer_at`
//! computes). terrain-cache's `VramPool::update_overlay` fills it with the selection and
//! budget that fill the heights'.
//!
//! Textures, not storage buffers: the atlas surface's fragment stage already binds the heights'
//! three storage buffers, and four is all some devices allow per stage.
//! - **Slots:** an RGBA8 2D array; each layer a square of `cols x cols` tiles (as many as
//!   `max_texture_dimension_2d` allows, at most what the slots need), so the slot count is not
//!   bound by `max_texture_array_layers` alone.
//! - **Table:** an R32Uint 2D texture read as a list of [`TABLE_WIDTH`] per row. Entries 0..128
//!   describe the pyramid (levels, log2 tile side, `cols`, slots; per level its tiles across,
//!   down and first entry from index 4), so the lookup needs no other binding; entry
//!   `128 + TileLayout::table_index` holds a tile's slot or `INVALID_SLOT`.

use crate::device::scope::scoped;
use crate::error::GpuError;
use glam::UVec2;
use terrain_core::{CoreError, Grid, INVALID_SLOT, OverlayUploadTarget, TileLayout};

/// Entries per row of the table texture (at most downlevel `max_texture_dimension_2d`).
pub(crate) const TABLE_WIDTH: u32 = 1024;

/// Table entries before the tiles' (the pyramid's description).
const TABLE_HEADER: u32 = 128;

/// A world's paint or colour tiles on the GPU (see the module docs). Cloning shares the
/// textures: a renderer keeps a clone, and the pool's uploads into the original show in it.
#[derive(Debug, Clone)]
pub struct GpuOverlayAtlas {
    layout: TileLayout,
    slots: u32,
    cols: u32,
    queue: wgpu::Queue,
    texels: wgpu::Texture,
    table: wgpu::Texture,
    pub(crate) texels_view: wgpu::TextureView,
    pub(crate) table_view: wgpu::TextureView,
    bytes: u64,
}

impl GpuOverlayAtlas {
    /// `slots` tile slots of RGBA8 texels over `layout`, nothing resident. Fails on a bad
    /// layout or slot count, a tile side above the device's `max_texture_dimension_2d`, more
    /// slots than its array layers hold, or a pyramid whose table does not fit one texture.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        layout: TileLayout,
        slots: u32,
    ) -> Result<Self, GpuError> {
        layout.validate()?;
        let out = |what, value: f64, expected| -> GpuError {
            CoreError::OutOfRange {
                what,
                value,
                expected,
            }
            .into()
        };
        if slots == 0 || slots == INVALID_SLOT {
            return Err(out(
                "overlay atlas slots",
                f64::from(slots),
                "1 ..= 2^32 - 2",
            ));
        }
        let limits = device.limits();
        let ts = layout.tile_size;
        if ts > limits.max_texture_dimension_2d {
            return Err(out(
                "overlay tile side",
                f64::from(ts),
                "at most the device's max_texture_dimension_2d",
            ));
        }
        let fit = limits.max_texture_dimension_2d / ts;
        let need = (f64::from(slots).sqrt().ceil() as u32).max(1);
        let cols = fit.min(need).max(1);
        let layers = slots.div_ceil(cols * cols);
        if layers > limits.max_texture_array_layers {
            return Err(out(
                "overlay atlas slots",
                f64::from(slots),
                "at most what the device's 2D array layers hold",
            ));
        }
        let entries = u64::from(TABLE_HEADER) + layout.table_len();
        let rows = entries.div_ceil(u64::from(TABLE_WIDTH));
        if rows > u64::from(limits.max_texture_dimension_2d) {
            return Err(out(
                "tiles in the pyramid",
                layout.table_len() as f64,
                "a table of at most max_texture_dimension_2d rows of 1024",
            ));
        }
        let rows = rows as u32;
        let side = cols * ts;
        let texels = scoped(device, "GpuOverlayAtlas slots", || {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("GpuOverlayAtlas slots"),
                size: wgpu::Extent3d {
                    width: side,
                    height: side,
                    depth_or_array_layers: layers,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        })?;
        let table = scoped(device, "GpuOverlayAtlas table", || {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("GpuOverlayAtlas table"),
                size: wgpu::Extent3d {
                    width: TABLE_WIDTH,
                    height: rows,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R32Uint,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        })?;
        let mut entries = vec![INVALID_SLOT; (rows * TABLE_WIDTH) as usize];
        entries[..4].copy_from_slice(&[layout.levels, ts.trailing_zeros(), cols, slots]);
        for l in 0..layout.levels {
            let t = layout.tiles_at(l);
            // The table fits a texture (checked), so every offset fits u32.
            let at = 4 + 3 * l as usize;
            entries[at..at + 3].copy_from_slice(&[t.x, t.y, layout.level_offset(l) as u32]);
        }
        write_table(queue, &table, 0, &entries);
        let texels_view = texels.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let table_view = table.create_view(&wgpu::TextureViewDescriptor::default());
        let bytes = u64::from(side) * u64::from(side) * u64::from(layers) * 4
            + u64::from(rows) * u64::from(TABLE_WIDTH) * 4;
        Ok(Self {
            layout,
            slots,
            cols,
            queue: queue.clone(),
            texels,
            table,
            texels_view,
            table_view,
            bytes,
        })
    }

    /// The slots (an RGBA8 2D array view), for an engine binding them in its own shader
    /// (terrain-shaders' `overlay_atlas.wgsl` reads them).
    pub fn slots_view(&self) -> &wgpu::TextureView {
        &self.texels_view
    }

    /// The table (an R32Uint 2D view), likewise.
    pub fn table_view(&self) -> &wgpu::TextureView {
        &self.table_view
    }

    /// GPU bytes of the slots and the table.
    pub fn gpu_bytes(&self) -> u64 {
        self.bytes
    }

    fn check(&self, slot: Option<u32>, level: u32, tile: UVec2) -> Result<u64, GpuError> {
        if let Some(s) = slot
            && s >= self.slots
        {
            return Err(CoreError::OutOfRange {
                what: "overlay atlas slot",
                value: f64::from(s),
                expected: "below the atlas's slot count",
            }
            .into());
        }
        self.layout.table_index(level, tile).ok_or_else(|| {
            CoreError::OutOfRange {
                what: "tile (level, x, y)",
                value: f64::from(level),
                expected: "a tile of the layout's pyramid",
            }
            .into()
        })
    }
}

/// Writes `entries` into the table texture from list index `first` (within one row, or whole
/// rows from a row's start).
fn write_table(queue: &wgpu::Queue, table: &wgpu::Texture, first: u64, entries: &[u32]) {
    let w = u64::from(TABLE_WIDTH);
    let rows = (entries.len() as u64).div_ceil(w) as u32;
    let width = (entries.len() as u64).min(w) as u32;
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: table,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: (first % w) as u32,
                y: (first / w) as u32,
                z: 0,
            },
            aspect: wgpu::TextureAspect::All,
        },
        bytemuck::cast_slice(entries),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(width * 4),
            rows_per_image: None,
        },
        wgpu::Extent3d {
            width,
            height: rows,
            depth_or_array_layers: 1,
        },
    );
}

impl OverlayUploadTarget for GpuOverlayAtlas {
    type Error = GpuError;

    fn layout(&self) -> &TileLayout {
        &self.layout
    }

    fn slot_count(&self) -> u32 {
        self.slots
    }

    /// 4 bytes per texel.
    fn upload_bytes(&self) -> u64 {
        self.layout.tile_texels() * 4
    }

    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        texels: &Grid<[u8; 4]>,
    ) -> Result<u64, GpuError> {
        self.check(Some(slot), level, tile)?;
        let ts = self.layout.tile_size;
        if texels.size() != UVec2::splat(ts) {
            return Err(GpuError::SizeMismatch {
                expected: UVec2::splat(ts),
                actual: texels.size(),
            });
        }
        let per_layer = self.cols * self.cols;
        let within = slot % per_layer;
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texels,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: within % self.cols * ts,
                    y: within / self.cols * ts,
                    z: slot / per_layer,
                },
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(texels.as_slice()),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(ts * 4),
                rows_per_image: None,
            },
            wgpu::Extent3d {
                width: ts,
                height: ts,
                depth_or_array_layers: 1,
            },
        );
        Ok(self.upload_bytes())
    }

    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), GpuError> {
        let i = self.check(slot, level, tile)?;
        let entry = [slot.unwrap_or(INVALID_SLOT)];
        write_table(
            &self.queue,
            &self.table,
            u64::from(TABLE_HEADER) + i,
            &entry,
        );
        Ok(())
    }
}
