//! [`GpuOverlayAtlas`]: a streamed world's paint or colour on the GPU, in tile slots beside the
//! heights' `GpuTileAtlas`, implementing terrain-core's [`OverlayUploadTarget`] (CPU reference:
//! [`terrain_core::OverlayAtlas`], whose `sample` is what the renderers' `streamed_layer_at`
//! computes). terrain-cache's `VramPool::update_overlay` fills it with the selection and
//! budget that fill the heights'.
//!
//! Textures, not storage buffers: the atlas surface's fragment stage already binds the heights'
//! three storage buffers, and four is all some devices allow per stage.
//! - **Slots:** an RGBA8 2D array of at least two layers (GL reads no array of one): one tile a
//!   layer where the device's `max_texture_array_layers` allows (no texel unused), else layers
//!   of `cols x rows` tiles.
//! - **Table:** an R32Uint 2D texture with one entry per level-0 tile (from row 1; row 0 holds
//!   log2 of the tile side, `cols` and `rows`): the finest resident level covering that tile and its
//!   slot (`level << 27 | slot`), or `INVALID_SLOT`. A level-`l` tile covers whole level-0
//!   tiles, so every texel of a level-0 tile resolves the same way, and the lookup is one load
//!   instead of a walk up the levels (lavapipe's compiler took minutes over a version with
//!   walks in the atlas surface's fragment shader, which already walks the heights 16 times).
//!   The atlas keeps the pyramid's table on the CPU and rewrites the entries a `map` changes.

use crate::device::scope::scoped;
use crate::error::GpuError;
use glam::UVec2;
use terrain_core::{CoreError, Grid, INVALID_SLOT, OverlayUploadTarget, TileLayout};

/// Bits of an entry's slot; the level is above them.
const SLOT_BITS: u32 = 27;

/// A world's paint or colour tiles on the GPU (see the module docs). A renderer given it keeps
/// its texture views, so the pool's uploads and maps show in the next frame.
#[derive(Debug)]
pub struct GpuOverlayAtlas {
    layout: TileLayout,
    slots: u32,
    cols: u32,
    rows: u32,
    queue: wgpu::Queue,
    texels: wgpu::Texture,
    table: wgpu::Texture,
    /// The pyramid's indirection table (slot or `INVALID_SLOT` per tile of every level), from
    /// which the texture's entries are made.
    tiles: Vec<u32>,
    /// The texture's entries (per level-0 tile, row-major), kept to update them in place.
    finest: Vec<u32>,
    texels_view: wgpu::TextureView,
    table_view: wgpu::TextureView,
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
        // One tile a layer where the device has the layers (no texel unused), else layers of
        // `cols x rows` tiles. At least two layers: wgpu's GL backend makes a texture of one
        // layer a plain 2D texture, which an array view does not read (every texel reads zero).
        let max_layers = limits.max_texture_array_layers.max(2);
        let (cols, rows) = if slots <= max_layers {
            (1, 1)
        } else {
            let fit = limits.max_texture_dimension_2d / ts;
            let per = slots.div_ceil(max_layers);
            let cols = fit.min(f64::from(per).sqrt().ceil() as u32).max(1);
            (cols, fit.min(per.div_ceil(cols)).max(1))
        };
        let layers = slots.div_ceil(cols * rows).max(2);
        if layers > limits.max_texture_array_layers {
            return Err(out(
                "overlay atlas slots",
                f64::from(slots),
                "at most what the device's 2D array layers hold",
            ));
        }
        let level0 = layout.tiles_at(0);
        if level0.x.max(3) > limits.max_texture_dimension_2d
            || level0.y + 1 > limits.max_texture_dimension_2d
        {
            return Err(out(
                "level-0 tiles across the world",
                f64::from(level0.max_element()),
                "a table within the device's max_texture_dimension_2d",
            ));
        }
        let tiles = usize::try_from(layout.table_len())
            .map_err(|_| out("tiles in the pyramid", layout.table_len() as f64, "fewer"))?;
        let (width, height) = (cols * ts, rows * ts);
        let texels = scoped(device, "GpuOverlayAtlas slots", || {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("GpuOverlayAtlas slots"),
                size: wgpu::Extent3d {
                    width,
                    height,
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
                    width: level0.x.max(3),
                    height: level0.y + 1,
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
        write_rows(queue, &table, 0, &[ts.trailing_zeros(), cols, rows], 3);
        let finest = vec![INVALID_SLOT; (level0.x as usize) * (level0.y as usize)];
        write_rows(queue, &table, 1, &finest, level0.x);
        let texels_view = texels.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let table_view = table.create_view(&wgpu::TextureViewDescriptor::default());
        let bytes = u64::from(width) * u64::from(height) * u64::from(layers) * 4
            + u64::from(level0.x.max(3)) * u64::from(level0.y + 1) * 4;
        Ok(Self {
            layout,
            slots,
            cols,
            rows,
            queue: queue.clone(),
            texels,
            table,
            tiles: vec![INVALID_SLOT; tiles],
            finest,
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

/// Writes `entries`, whole rows of `width`, into the table texture from row `row`.
pub(crate) fn write_rows(
    queue: &wgpu::Queue,
    table: &wgpu::Texture,
    row: u32,
    entries: &[u32],
    width: u32,
) {
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: table,
            mip_level: 0,
            origin: wgpu::Origin3d { x: 0, y: row, z: 0 },
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
            height: entries.len() as u32 / width,
            depth_or_array_layers: 1,
        },
    );
}

/// What a renderer binds of a [`GpuOverlayAtlas`]: views of its textures (they share them) and
/// the world's size, checked against the drawn surface's.
#[derive(Debug, Clone)]
pub(crate) struct OverlayViews {
    pub(crate) slots: wgpu::TextureView,
    pub(crate) table: wgpu::TextureView,
    pub(crate) world_size: UVec2,
}

impl GpuOverlayAtlas {
    /// The views a renderer binds.
    pub(crate) fn views(&self) -> OverlayViews {
        OverlayViews {
            slots: self.texels_view.clone(),
            table: self.table_view.clone(),
            world_size: self.layout.world_size,
        }
    }

    /// The finest mapped level covering level-0 tile `t`, with its slot, packed as the shader
    /// reads it; `INVALID_SLOT` where none is.
    fn finest_at(&self, t: UVec2) -> u32 {
        for level in 0..self.layout.levels {
            let Some(i) = self.layout.table_index(level, t >> level) else {
                continue;
            };
            let slot = self.tiles[i as usize];
            if slot < self.slots {
                return level << SLOT_BITS | slot;
            }
        }
        INVALID_SLOT
    }
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
        let (corner, layer) = slot_place(slot, self.cols, self.rows);
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texels,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: corner.x * ts,
                    y: corner.y * ts,
                    z: layer,
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
        self.tiles[i as usize] = slot.unwrap_or(INVALID_SLOT);
        // The level-0 tiles it covers: a mapped tile answers where nothing finer does; an
        // unmapped one leaves those it answered to the next coarser level mapped.
        let level0 = self.layout.tiles_at(0);
        let min = (tile << level).min(level0);
        let max = ((tile + UVec2::ONE) << level).min(level0);
        if min.x >= max.x || min.y >= max.y {
            return Ok(());
        }
        let width = max.x - min.x;
        let mut rows = Vec::with_capacity((width * (max.y - min.y)) as usize);
        for y in min.y..max.y {
            for x in min.x..max.x {
                let at = (y * level0.x + x) as usize;
                let e = self.finest[at];
                let answered_by = (e != INVALID_SLOT).then_some(e >> SLOT_BITS);
                let e = match slot {
                    Some(s) if answered_by.is_none_or(|l| l >= level) => level << SLOT_BITS | s,
                    None if answered_by == Some(level) => self.finest_at(UVec2::new(x, y)),
                    _ => e,
                };
                self.finest[at] = e;
                rows.push(e);
            }
        }
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.table,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: min.x,
                    y: min.y + 1,
                    z: 0,
                },
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(&rows),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * 4),
                rows_per_image: None,
            },
            wgpu::Extent3d {
                width,
                height: max.y - min.y,
                depth_or_array_layers: 1,
            },
        );
        Ok(())
    }
}

/// Where slot `slot` lies in layers of `cols x rows` tiles: its corner in tiles, and its layer
/// (as `streamed_layer_at` finds it).
fn slot_place(slot: u32, cols: u32, rows: u32) -> (UVec2, u32) {
    let per_layer = cols * rows;
    let within = slot % per_layer;
    (UVec2::new(within % cols, within / cols), slot / per_layer)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_slot_has_a_place_of_its_own_inside_its_layer() {
        for (cols, rows, slots) in [(1, 1, 5), (3, 2, 7), (8, 8, 200), (4, 1, 4)] {
            let mut seen = std::collections::HashSet::new();
            for slot in 0..slots {
                let (corner, layer) = slot_place(slot, cols, rows);
                assert!(corner.x < cols && corner.y < rows, "{slot}");
                assert!(layer < slots.div_ceil(cols * rows));
                assert!(seen.insert((corner, layer)), "{slot} shares its place");
            }
        }
    }
}
