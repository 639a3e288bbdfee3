//! `GpuTileAtlas`: the VRAM side of the tile cache (Fikkan 2013, sec. 4.2, 5.6) — a fixed number of
//! tile slots in one storage buffer of 16-bit heights (two per u32 word) and an indirection table over every tile of
//! every level of the world, implementing terrain-core's [`TileUploadTarget`] — and
//! `AtlasProbe`, which reads back what the atlas surface of the clipmap renderer sees at given
//! texels. The CPU reference is [`terrain_core::TileAtlas`].
//!
//! Which tiles to hold is not decided here (terrain-cache's `VramPool` does, through the
//! trait); the atlas stores what it is given, with `queue.write_buffer` into buffers made once.

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, shader_module, wrap_offset,
};
use crate::device::download::map_and_read;
use crate::device::scope::{buffer_init, scoped};
use crate::error::GpuError;
use crate::resources::maps::{MapView, map_buffer};
use crate::resources::packing;
use bytemuck::{Pod, Zeroable};
use glam::{IVec2, UVec2, Vec2};
use terrain_core::{
    CoreError, Grid, INVALID_SLOT, MAX_TILE_LEVELS, TileLayout, TileUploadTarget, WrapMode,
};

// The sentinel is declared once per language; they must agree.
const _: () = assert!(INVALID_SLOT == terrain_shaders::codes::INVALID_SLOT);

/// The storage block `AtlasInfo` of `tile_atlas.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct AtlasInfo {
    world_size: [u32; 2],
    tile_shift: u32,
    levels: u32,
    fill: u32,
    slot_count: u32,
    pad: [u32; 2],
    level: [[u32; 4]; MAX_TILE_LEVELS as usize],
}

const _: () = assert!(std::mem::size_of::<AtlasInfo>() == 32 + 16 * 32);

/// What a [`GpuTileAtlas`] holds: `slots` tiles of the world `world`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AtlasConfig {
    /// Tile slots (the VRAM pool's size), at least 1.
    pub slots: u32,
    /// The world's tile pyramid (tile size, levels, encoding, texel size, wrap, fill);
    /// terrain-cache's `Manifest::tile_layout` gives it for a world on disk.
    pub world: TileLayout,
}

impl AtlasConfig {
    /// Bytes of the slots' storage buffer (16-bit texels packed two per u32 word: 2 bytes per
    /// texel).
    pub fn slot_bytes(&self) -> u64 {
        u64::from(self.slots)
            .saturating_mul(self.slot_words())
            .saturating_mul(4)
    }

    /// u32 words of one tile slot: rows of 16-bit texels packed two per word.
    pub fn slot_words(&self) -> u64 {
        let ts = self.world.tile_size;
        packing::words(ts, ts, GpuTileAtlas::BITS)
    }

    /// Bytes of the indirection table (u32 per tile of every level).
    pub fn table_bytes(&self) -> u64 {
        self.world.table_len().saturating_mul(4)
    }

    /// `base` with the storage binding and buffer size limits raised as far as this atlas
    /// needs, for an engine creating its device.
    pub fn required_limits(&self, base: wgpu::Limits) -> Result<wgpu::Limits, GpuError> {
        self.validate()?;
        let bytes = self.slot_bytes().max(self.table_bytes());
        Ok(wgpu::Limits {
            max_storage_buffer_binding_size: base.max_storage_buffer_binding_size.max(bytes),
            max_buffer_size: base.max_buffer_size.max(bytes),
            ..base
        })
    }

    /// Checks the layout, the slot count, and that every texel index fits the shaders' u32.
    pub fn validate(&self) -> Result<(), GpuError> {
        self.world.validate()?;
        if self.slots == 0 || self.slots == INVALID_SLOT {
            return Err(CoreError::OutOfRange {
                what: "atlas slots",
                value: f64::from(self.slots),
                expected: "1 ..= 2^32 - 2",
            }
            .into());
        }
        if u64::from(self.slots) * self.world.tile_texels() > u64::from(u32::MAX) {
            return Err(CoreError::OutOfRange {
                what: "atlas texels (slots x tile texels)",
                value: (u64::from(self.slots) * self.world.tile_texels()) as f64,
                expected: "fewer than 2^32",
            }
            .into());
        }
        Ok(())
    }
}

/// A tile in the atlas, as the passes that work on resident tiles name it: the slot it is in
/// (from the VRAM pool, e.g. terrain-cache's `VramPool::hold`) and its level, which sets its
/// texel size (the world's times `2^level`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TileSlot {
    /// The slot, below the atlas's slot count.
    pub slot: u32,
    /// The tile's level, below the atlas's levels.
    pub level: u32,
}

/// Tile slots and the indirection table on the GPU: the [`TileUploadTarget`] the VRAM pool
/// uploads into and the surface [`crate::ClipmapSurface::Atlas`] draws from.
///
/// Made once in [`GpuTileAtlas::new`]: the slots (`slots * tile_size^2` u32, checked against
/// the device's storage buffer limits), the table (one u32 per tile of every level, all
/// [`INVALID_SLOT`]) and the description the shaders read. An upload widens the tile's u16
/// heights into a staging vector made in `new` and writes it with `queue.write_buffer`; a map
/// writes one table entry. Both land before the next submit.
#[derive(Debug)]
pub struct GpuTileAtlas {
    config: AtlasConfig,
    queue: wgpu::Queue,
    info: wgpu::Buffer,
    heights: wgpu::Buffer,
    table: wgpu::Buffer,
    staging: Vec<u32>,
    uploads: u64,
    uploaded_bytes: u64,
}

impl GpuTileAtlas {
    /// Bits per texel in the slots' buffer.
    pub const BITS: u32 = 16;

    /// Builds the atlas on `device`; uploads go through `queue` (a clone is kept).
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        config: &AtlasConfig,
    ) -> Result<Self, GpuError> {
        config.validate()?;
        let layout = &config.world;
        let ts = layout.tile_size;
        let heights = map_buffer(
            device,
            "GpuTileAtlas slots",
            UVec2::new(ts, ts.saturating_mul(config.slots)),
            config.slot_bytes(),
        )?;
        let limits = device.limits();
        let limit = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if config.table_bytes() > limit {
            return Err(GpuError::MapTooLarge {
                size: layout.tiles_at(0),
                bytes: config.table_bytes(),
                limit,
            });
        }
        let mut info = AtlasInfo {
            world_size: layout.world_size.to_array(),
            tile_shift: ts.trailing_zeros(),
            levels: layout.levels,
            fill: u32::from(layout.fill),
            slot_count: config.slots,
            pad: [0; 2],
            level: [[0; 4]; MAX_TILE_LEVELS as usize],
        };
        for l in 0..layout.levels {
            let t = layout.tiles_at(l);
            // The table fits u32 indices (validated), so every offset does.
            info.level[l as usize] = [t.x, t.y, layout.level_offset(l) as u32, 0];
        }
        let info = buffer_init(
            device,
            "GpuTileAtlas info",
            bytemuck::bytes_of(&info),
            wgpu::BufferUsages::STORAGE,
        )?;
        let table = buffer_init(
            device,
            "GpuTileAtlas table",
            bytemuck::cast_slice(&vec![INVALID_SLOT; layout.table_len() as usize]),
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
        )?;
        Ok(Self {
            config: *config,
            queue: queue.clone(),
            info,
            heights,
            table,
            staging: vec![0; config.slot_words() as usize],
            uploads: 0,
            uploaded_bytes: 0,
        })
    }

    /// The configuration it was made with.
    pub fn config(&self) -> &AtlasConfig {
        &self.config
    }

    /// The slots' storage buffer: slot `s` holds `tile_size^2` 16-bit heights from word
    /// `s * AtlasConfig::slot_words()`, rows of texels packed two per u32 word.
    pub fn heights_buffer(&self) -> &wgpu::Buffer {
        &self.heights
    }

    /// The indirection table: per level (finest first) a row-major u32 per tile, a slot or
    /// [`INVALID_SLOT`].
    pub fn table_buffer(&self) -> &wgpu::Buffer {
        &self.table
    }

    /// The description the shaders read (`AtlasInfo` of `tile_atlas.wgsl`).
    pub fn info_buffer(&self) -> &wgpu::Buffer {
        &self.info
    }

    /// Tiles uploaded since the atlas was made.
    pub fn uploads(&self) -> u64 {
        self.uploads
    }

    /// Bytes uploaded since the atlas was made.
    pub fn uploaded_bytes(&self) -> u64 {
        self.uploaded_bytes
    }

    /// Bytes of GPU memory the atlas holds (slots, table, description).
    pub fn gpu_bytes(&self) -> u64 {
        self.heights.size() + self.table.size() + self.info.size()
    }

    /// Downloads the indirection table (waits for the GPU; for tests and tools).
    pub fn read_table(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<u32>, GpuError> {
        let bytes = crate::device::download::download_bytes(
            device,
            queue,
            &self.table,
            0,
            self.table.size(),
        )?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// The tile in `tile.slot`, a tile of level `tile.level`, as the stamp pass and the readback address
    /// it: a clamped `tile_size^2` map at the level's texel size.
    pub(crate) fn slot_view(&self, tile: TileSlot) -> Result<MapView<'_>, GpuError> {
        let TileSlot { slot, level } = tile;
        self.check_slot(slot)?;
        let layout = &self.config.world;
        if level >= layout.levels {
            return Err(CoreError::OutOfRange {
                what: "atlas tile level",
                value: f64::from(level),
                expected: "below the atlas's levels",
            }
            .into());
        }
        let ts = layout.tile_size;
        Ok(MapView {
            buffer: &self.heights,
            // Below 2^32 texels in all: `validate` checked slots x tile texels.
            base: slot * self.config.slot_words() as u32,
            size: UVec2::splat(ts),
            wrap: WrapMode::Clamp,
            encoding: layout.encoding,
            texel_size: layout.texel_size * (1u32 << level) as f32,
            max_raw: u32::from(u16::MAX),
            bits: Self::BITS,
        })
    }

    fn table_index(&self, level: u32, tile: UVec2) -> Result<u64, GpuError> {
        self.config.world.table_index(level, tile).ok_or_else(|| {
            CoreError::OutOfRange {
                what: "atlas tile level",
                value: f64::from(level),
                expected: "a tile of the atlas's pyramid (level below its levels, x and y below its tiles)",
            }
            .into()
        })
    }

    fn check_slot(&self, slot: u32) -> Result<(), GpuError> {
        if slot < self.config.slots {
            Ok(())
        } else {
            Err(CoreError::OutOfRange {
                what: "atlas slot",
                value: f64::from(slot),
                expected: "below the atlas's slot count",
            }
            .into())
        }
    }
}

impl TileUploadTarget for GpuTileAtlas {
    type Error = GpuError;

    fn layout(&self) -> &TileLayout {
        &self.config.world
    }

    fn slot_count(&self) -> u32 {
        self.config.slots
    }

    /// 2 bytes per texel (a slot's packed words).
    fn upload_bytes(&self) -> u64 {
        self.config.slot_words() * 4
    }

    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        heights: &Grid<u16>,
    ) -> Result<u64, GpuError> {
        self.check_slot(slot)?;
        self.table_index(level, tile)?;
        let ts = self.config.world.tile_size;
        if heights.size() != UVec2::splat(ts) {
            return Err(GpuError::SizeMismatch {
                expected: UVec2::splat(ts),
                actual: heights.size(),
            });
        }
        packing::pack_into(heights.as_slice(), ts, 16, &mut self.staging);
        let bytes = self.upload_bytes();
        self.queue.write_buffer(
            &self.heights,
            u64::from(slot) * bytes,
            bytemuck::cast_slice(&self.staging),
        );
        self.uploads += 1;
        self.uploaded_bytes += bytes;
        Ok(bytes)
    }

    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), GpuError> {
        let i = self.table_index(level, tile)?;
        if let Some(s) = slot {
            self.check_slot(s)?;
        }
        let value = slot.unwrap_or(INVALID_SLOT);
        self.queue
            .write_buffer(&self.table, i * 4, bytemuck::bytes_of(&value));
        Ok(())
    }
}

/// The uniform block of `atlas_probe.wgsl` (the clipmap `Frame` fields the surface reads).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ProbeParams {
    map_size: [u32; 2],
    wrap_offset: [i32; 2],
    wrap: u32,
    count: u32,
    height_scale: f32,
    height_offset: f32,
    texel_size: f32,
    pad: [u32; 3],
}

const _: () = assert!(std::mem::size_of::<ProbeParams>() == 48);

/// What the atlas surface reads at one texel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeSample {
    /// The stored height of the finest resident level (the layout's fill where none is).
    pub stored: u32,
    /// `height_at`: metres.
    pub height: f32,
    /// `derivative_at`: the gradient `(dh/dX, dh/dZ)` by central differences, metres per metre.
    pub derivative: Vec2,
}

/// Texel coordinates a probe accepts on each axis: `±2^29`, so the shaders' `i32` arithmetic
/// (neighbours, wrap offsets of up to `2^29` plus the world size) cannot overflow.
pub const PROBE_TEXEL_LIMIT: i32 = 1 << 29;

/// Reads what [`crate::ClipmapSurface::Atlas`] draws at a list of level-0 texels, with the
/// renderer's own WGSL functions (`height_at`, `derivative_at`): for the comparison with
/// [`terrain_core::TileAtlas`] and for height queries against the resident tiles.
///
/// Made once for at most `capacity` texels per call (texel, output and staging buffers); each
/// [`AtlasProbe::read`] writes the texels, dispatches, and waits for the result.
#[derive(Debug)]
pub struct AtlasProbe {
    pipeline: wgpu::ComputePipeline,
    bindings: PassBindings<ProbeParams>,
    texels: wgpu::Buffer,
    out: wgpu::Buffer,
    staging: wgpu::Buffer,
    capacity: u32,
}

impl AtlasProbe {
    /// Builds the pipeline and buffers for up to `capacity` texels per read.
    pub fn new(device: &wgpu::Device, capacity: u32) -> Result<Self, GpuError> {
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        if capacity == 0 || capacity.div_ceil(64) > max_groups {
            return Err(CoreError::OutOfRange {
                what: "AtlasProbe capacity (texels)",
                value: f64::from(capacity),
                expected: "1 ..= 64 x the device's max_compute_workgroups_per_dimension",
            }
            .into());
        }
        let ro = StorageBinding::compute(true);
        let bindings = PassBindings::new(
            device,
            "AtlasProbe",
            wgpu::ShaderStages::COMPUTE,
            &[ro, ro, ro, ro, StorageBinding::compute(false)],
        );
        let module = shader_module(device, "atlas_probe.wgsl", terrain_shaders::ATLAS_PROBE)?;
        let pipeline = compute_pipeline(
            device,
            "AtlasProbe",
            &module,
            bindings.layout(),
            "probe_main",
        )?;
        let n = u64::from(capacity);
        let size = UVec2::new(capacity, 1);
        let texels = map_buffer(device, "AtlasProbe texels", size, n * 8)?;
        let out = map_buffer(device, "AtlasProbe out", size, n * 16)?;
        let staging = scoped(device, "AtlasProbe staging", || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("AtlasProbe staging"),
                size: n * 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        Ok(Self {
            pipeline,
            bindings,
            texels,
            out,
            staging,
            capacity,
        })
    }

    /// What the atlas surface reads at each of `texels` (level-0 texels, addressed like the
    /// world: clamped or wrapped; each coordinate within ±[`PROBE_TEXEL_LIMIT`]). Submits the
    /// atlas's pending uploads with the dispatch and waits for the GPU.
    pub fn read(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        atlas: &GpuTileAtlas,
        texels: &[IVec2],
    ) -> Result<Vec<ProbeSample>, GpuError> {
        if texels.is_empty() {
            return Ok(Vec::new());
        }
        if texels.len() > self.capacity as usize {
            return Err(CoreError::OutOfRange {
                what: "AtlasProbe texels per read",
                value: texels.len() as f64,
                expected: "at most the probe's capacity",
            }
            .into());
        }
        let mut lo = IVec2::MAX;
        for t in texels {
            let reach = t.x.unsigned_abs().max(t.y.unsigned_abs());
            if reach > PROBE_TEXEL_LIMIT as u32 {
                return Err(CoreError::OutOfRange {
                    what: "AtlasProbe texel coordinate",
                    value: f64::from(reach),
                    expected: "within ±2^29",
                }
                .into());
            }
            lo = lo.min(*t);
        }
        let layout = atlas.config().world;
        let params = ProbeParams {
            map_size: layout.world_size.to_array(),
            wrap_offset: match layout.wrap {
                // Covers the central differences' reach of one texel.
                WrapMode::Repeat => wrap_offset(lo - 1, layout.world_size)?,
                WrapMode::Clamp => [0, 0],
            },
            wrap: crate::device::compute::wrap_code(layout.wrap),
            count: texels.len() as u32,
            height_scale: layout.encoding.scale,
            height_offset: layout.encoding.offset,
            texel_size: layout.texel_size,
            pad: [0; 3],
        };
        let bytes = texels.len() as u64 * 16;
        queue.write_buffer(&self.texels, 0, bytemuck::cast_slice(texels));
        let (group, offset) = self.bindings.bind(
            device,
            queue,
            &params,
            &[
                atlas.info_buffer(),
                atlas.heights_buffer(),
                atlas.table_buffer(),
                &self.texels,
                &self.out,
            ],
        )?;
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("AtlasProbe"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[offset]);
            pass.dispatch_workgroups((texels.len() as u32).div_ceil(64), 1, 1);
        }
        encoder.copy_buffer_to_buffer(&self.out, 0, &self.staging, 0, bytes);
        queue.submit([encoder.finish()]);
        self.bindings.recall();
        let raw = map_and_read_prefix(device, &self.staging, bytes)?;
        Ok(raw
            .chunks_exact(4)
            .map(|c| ProbeSample {
                stored: c[0],
                height: f32::from_bits(c[1]),
                derivative: Vec2::new(f32::from_bits(c[2]), f32::from_bits(c[3])),
            })
            .collect())
    }
}

/// The first `bytes` of a staging buffer whose copy was submitted, as u32.
fn map_and_read_prefix(
    device: &wgpu::Device,
    staging: &wgpu::Buffer,
    bytes: u64,
) -> Result<Vec<u32>, GpuError> {
    let all = map_and_read(device, staging)?;
    Ok(bytemuck::pod_collect_to_vec(&all[..bytes as usize]))
}
