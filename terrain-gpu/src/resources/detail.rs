//! `GpuDetailTiles`: the VRAM side of terrain-core's detail layer (Flower 2010, sec. 2.3.1): a fixed
//! number of tile slots in one storage buffer (8-bit texels packed four per u32 word, one byte
//! per texel as the thesis's 8-bit detail-maps; rows of whole words, as every map of the crate:
//! `resources::packing`) and the slot of each tile of the layout. [`crate::StampPass::encode_detail`] stamps
//! them; the CPU reference is [`terrain_core::detail::DetailLayer`].
//!
//! A tile is in one of three states:
//! - the shared zero tile (every tile of a new layer): no slot, 0 m of detail everywhere; a
//!   stamp over it gives it a slot filled with zeros first;
//! - resident: in a slot, uploaded with [`GpuDetailTiles::load`] or materialised by a stamp;
//! - not loaded: [`GpuDetailTiles::unload`] freed its slot (its texels live in the cache or on
//!   disk). A stamp over a tile that is not loaded is refused, so a streamed-out tile is never
//!   overwritten by a fresh zero tile.
//!
//! Which tiles to hold is not decided here (the cache's band regions do).
//!
//! ```no_run
//! use glam::{UVec2, Vec2};
//! use terrain_core::detail::DetailLayout;
//! use terrain_core::{Blend, GaussianStamp, StampPlacement};
//! use terrain_gpu::{GpuContext, GpuDetailTiles, GpuStamp, StampOp, StampPass};
//!
//! let ctx = GpuContext::new_headless()?;
//! let (device, queue) = (&ctx.device, &ctx.queue);
//! // 256^2 coarse texels at 0.1 m refined x3, 128-texel tiles, 16 slots.
//! let layout = DetailLayout::new(UVec2::splat(256), 0.1, 3, 128)?;
//! let mut tiles = GpuDetailTiles::new(device, layout, 16)?;
//! let mut stamps = StampPass::new(device)?;
//! let gauss = GaussianStamp::default();
//! // A mark 4 cm deep over the corner of four tiles (128 detail texels = 4.27 m).
//! let op = StampOp {
//!     stamp: GpuStamp::Gaussian(&gauss),
//!     placement: StampPlacement::new(Vec2::splat(4.27), Vec2::splat(0.6), -0.04)?,
//!     blend: Blend::Add,
//! };
//! let mut encoder = device.create_command_encoder(&Default::default());
//! let touched = stamps.encode_detail(device, queue, &mut encoder, &mut tiles, &op)?;
//! queue.submit([encoder.finish()]);
//! stamps.recall();
//! assert_eq!(touched.len(), 4);
//! assert_eq!(tiles.resident(), 4);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! The renderer reads the tiles through a table of one u32 per tile (its slot, or a value at or
//! above the slot count for the zero tile and a tile not loaded, both drawn as 0 m), kept in
//! step with every state change: [`crate::ClipmapSurface::Detail`] shades with them and
//! [`crate::DetailProbe`] reads what it shades with.

use crate::device::download::download_bytes;
use crate::error::GpuError;
use crate::resources::maps::map_buffer;
use crate::resources::packing;
use bytemuck::{Pod, Zeroable};
use glam::{IVec2, UVec2};
use terrain_core::detail::{DETAIL_ZERO_RAW, DetailLayer, DetailLayout, detail_encoding};
use terrain_core::{CoreError, Grid, Rect};

/// What a tile of the layout is on the GPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DetailTileState {
    /// The shared zero tile: no slot, 0 m of detail.
    Zero,
    /// In this slot.
    Resident(u32),
    /// Unloaded: its texels are elsewhere, and stamps over it are refused until it is loaded.
    NotLoaded,
}

/// A slot value of the state matrix: the two states without a slot take the top values.
const ZERO: u32 = u32::MAX;
const NOT_LOADED: u32 = u32::MAX - 1;

/// Detail tiles in GPU slots, for the stamp pass (and later the renderer) to address.
#[derive(Debug)]
pub struct GpuDetailTiles {
    layout: DetailLayout,
    slots: u32,
    heights: wgpu::Buffer,
    /// The GPU copy of `state`, for the shaders.
    table: wgpu::Buffer,
    /// Per tile: a slot, [`ZERO`] or [`NOT_LOADED`].
    state: Grid<u32>,
    /// Free slots; the last is handed out first (the lowest, until slots are freed).
    free: Vec<u32>,
    /// A tile's texels packed, made once.
    staging: Vec<u32>,
}

impl GpuDetailTiles {
    /// `slots` tile slots for the tiles of `layout`, every tile the shared zero tile.
    ///
    /// Fails on 0 slots, on slots x tile texels at or above 2^32 (the shaders index with u32)
    /// or above the device's storage buffer limits.
    pub fn new(device: &wgpu::Device, layout: DetailLayout, slots: u32) -> Result<Self, GpuError> {
        let side = layout.tile_size();
        let tile_texels = u64::from(side) * u64::from(side);
        let texels = u64::from(slots) * tile_texels;
        if slots == 0 || slots >= NOT_LOADED || texels >= 1 << 32 {
            return Err(CoreError::OutOfRange {
                what: "detail tile slots",
                value: f64::from(slots),
                expected: "at least 1, with slots x tile texels below 2^32",
            }
            .into());
        }
        let slot_words = packing::words(side, side, Self::BITS);
        let heights = map_buffer(
            device,
            "GpuDetailTiles slots",
            UVec2::new(side, side.saturating_mul(slots)),
            u64::from(slots) * slot_words * 4,
        )?;
        let tiles = layout.tiles();
        let state = Grid::new(tiles.x, tiles.y, ZERO)?;
        let table = crate::device::scope::buffer_init(
            device,
            "GpuDetailTiles table",
            bytemuck::cast_slice(state.as_slice()),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        )?;
        Ok(Self {
            layout,
            slots,
            heights,
            table,
            state,
            free: (0..slots).rev().collect(),
            staging: vec![0; slot_words as usize],
        })
    }

    /// Bits per detail texel in the slots' buffer.
    pub const BITS: u32 = 8;

    /// u32 words one tile slot takes (rows of packed 8-bit texels).
    pub fn slot_words(&self) -> u32 {
        // Below 2^32: `new` checked slots x tile texels.
        packing::words(self.layout.tile_size(), self.layout.tile_size(), Self::BITS) as u32
    }

    /// Bytes the slots' buffer takes per detail texel it holds (1, plus row padding when the
    /// tile side is not a multiple of 4).
    pub fn bytes_per_texel(&self) -> f64 {
        let side = f64::from(self.layout.tile_size());
        self.heights.size() as f64 / (side * side * f64::from(self.slots))
    }

    /// The layout.
    pub fn layout(&self) -> &DetailLayout {
        &self.layout
    }

    /// Slots in all.
    pub fn slot_count(&self) -> u32 {
        self.slots
    }

    /// Tiles in a slot.
    pub fn resident(&self) -> u32 {
        self.slots - self.free.len() as u32
    }

    /// The slots' storage buffer: slot `s` holds `tile_size^2` u32 raw detail values from
    /// element `s * tile_size^2`, row-major.
    pub fn heights_buffer(&self) -> &wgpu::Buffer {
        &self.heights
    }

    /// The tile table's storage buffer: per tile (row-major over the layout's tiles) its slot,
    /// or a value at or above [`Self::slot_count`] for a tile without one.
    pub fn table_buffer(&self) -> &wgpu::Buffer {
        &self.table
    }

    /// What `tile` is now, or `None` off the tile grid.
    pub fn state(&self, tile: UVec2) -> Option<DetailTileState> {
        Some(match self.state.get(tile.x, tile.y)? {
            ZERO => DetailTileState::Zero,
            NOT_LOADED => DetailTileState::NotLoaded,
            slot => DetailTileState::Resident(slot),
        })
    }

    /// The slot `tile` is in, if resident.
    pub fn slot_of(&self, tile: UVec2) -> Option<u32> {
        match self.state(tile)? {
            DetailTileState::Resident(slot) => Some(slot),
            _ => None,
        }
    }

    /// Loads `tile`: `Some(texels)` uploads them into its slot (one is taken if it has none),
    /// `None` makes it the shared zero tile (its slot, if any, is freed). The upload lands
    /// before the next submit.
    ///
    /// Fails, changing nothing, on a tile off the grid, texels of the wrong size, or no free
    /// slot.
    pub fn load(
        &mut self,
        queue: &wgpu::Queue,
        tile: UVec2,
        texels: Option<&Grid<u8>>,
    ) -> Result<(), GpuError> {
        let state = self.check_tile(tile)?;
        let Some(texels) = texels else {
            self.release(queue, tile, ZERO);
            return Ok(());
        };
        let side = self.layout.tile_size();
        if texels.size() != UVec2::splat(side) {
            return Err(CoreError::SizeMismatch {
                expected: UVec2::splat(side),
                actual: texels.size(),
            }
            .into());
        }
        let slot = match state {
            DetailTileState::Resident(slot) => slot,
            _ => self.take_slot(queue, tile)?,
        };
        let side = self.layout.tile_size();
        packing::pack_into(texels.as_slice(), side, 8, &mut self.staging);
        self.write_slot(queue, slot);
        Ok(())
    }

    /// Frees `tile`'s slot: the tile is not loaded until [`Self::load`] (read it back first
    /// if it was deformed, and after the submit of every stamp recorded on it). Returns
    /// whether it held a slot. A tile off the grid is left alone.
    pub fn unload(&mut self, queue: &wgpu::Queue, tile: UVec2) -> bool {
        let had = self.slot_of(tile).is_some();
        if self.state.get(tile.x, tile.y).is_some() {
            self.release(queue, tile, NOT_LOADED);
        }
        had
    }

    /// Downloads the texels of `rect` (tile coordinates) of a resident tile, raw (waits for
    /// the GPU; a collision heightfield or the cache's write-back takes the dirty rects).
    /// The zero tile reads as [`DETAIL_ZERO_RAW`].
    ///
    /// Fails on a tile off the grid or not loaded, or a rect off the tile.
    pub fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tile: UVec2,
        rect: Rect,
    ) -> Result<Grid<u8>, GpuError> {
        let side = self.layout.tile_size();
        if rect.is_empty() || !Rect::from_size(UVec2::splat(side)).contains_rect(&rect) {
            return Err(CoreError::RegionOutOfBounds {
                rect,
                map_size: UVec2::splat(side),
            }
            .into());
        }
        let slot = match self.check_tile(tile)? {
            DetailTileState::Zero => {
                return Ok(Grid::new(rect.size.x, rect.size.y, DETAIL_ZERO_RAW)?);
            }
            DetailTileState::NotLoaded => return Err(not_loaded(tile)),
            DetailTileState::Resident(slot) => slot,
        };
        // The rows of the rect, first to last, in one download (whole rows: one copy).
        let pitch = u64::from(packing::pitch(side, Self::BITS));
        let first = u64::from(slot) * u64::from(self.slot_words()) + rect.min.y as u64 * pitch;
        let bytes = download_bytes(
            device,
            queue,
            &self.heights,
            first * 4,
            u64::from(rect.size.y) * pitch * 4,
        )?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        let values = packing::unpack(&words, side, Self::BITS);
        let (x0, w) = (rect.min.x as usize, side as usize);
        Ok(Grid::from_fn(rect.size.x, rect.size.y, |x, y| {
            values[y as usize * w + x0 + x as usize].min(255) as u8
        })?)
    }

    /// Resident `tile` as the readback addresses it: a clamped `tile_size^2` map of u8 values
    /// in its slot. Fails for a tile off the grid or without a slot (the zero tile, or not
    /// loaded: nothing the GPU stamped can be there).
    pub(crate) fn slot_view(
        &self,
        tile: UVec2,
    ) -> Result<crate::resources::maps::MapView<'_>, GpuError> {
        let DetailTileState::Resident(slot) = self.check_tile(tile)? else {
            return Err(not_loaded(tile));
        };
        let side = self.layout.tile_size();
        Ok(crate::resources::maps::MapView {
            buffer: &self.heights,
            // Below 2^32 texels in all: `new` checked slots x tile texels.
            base: slot * self.slot_words(),
            size: UVec2::splat(side),
            wrap: terrain_core::WrapMode::Clamp,
            encoding: detail_encoding(),
            texel_size: self.layout.detail_texel_m(),
            max_raw: 255,
            bits: Self::BITS,
        })
    }

    /// Makes the resident set follow `wanted` when the CPU `layer` holds every tile's truth
    /// (each stamp applied to both, as a CPU mirror does): tiles not wanted lose their slot
    /// (not loaded), wanted tiles that are not loaded, or that the layer holds while the GPU
    /// has the zero tile, are uploaded from the layer. Returns (tiles uploaded, tiles
    /// unloaded). A tile that was not loaded and that the layer does not hold counts as
    /// uploaded: it becomes the zero tile, without a slot.
    ///
    /// Fails, changing nothing, on a layer of another layout, a wanted tile off the grid, or
    /// more wanted tiles needing a slot than there are slots.
    pub fn stream_from(
        &mut self,
        queue: &wgpu::Queue,
        layer: &DetailLayer,
        wanted: &[UVec2],
    ) -> Result<(usize, usize), GpuError> {
        if layer.layout() != &self.layout {
            return Err(GpuError::Unsupported {
                what: "GpuDetailTiles::stream_from",
                reason: "the layer has another layout",
            });
        }
        let n = self.layout.tiles();
        let mut want = Grid::new(n.x, n.y, false)?;
        for &t in wanted {
            self.check_tile(t)?;
            if let Some(w) = want.get_mut(t.x, t.y) {
                *w = true;
            }
        }
        let slotted = (0..n.y)
            .flat_map(|y| (0..n.x).map(move |x| UVec2::new(x, y)))
            .filter(|t| {
                want.get(t.x, t.y) == Some(true)
                    && (layer.tile(*t).is_some() || self.slot_of(*t).is_some())
            })
            .count();
        if slotted > self.slots as usize {
            return Err(GpuError::DetailSlotsFull {
                needed: slotted,
                free: self.slots as usize,
            });
        }
        let mut unloaded = 0;
        for y in 0..n.y {
            for x in 0..n.x {
                let t = UVec2::new(x, y);
                if want.get(x, y) == Some(false) && self.slot_of(t).is_some() {
                    self.release(queue, t, NOT_LOADED);
                    unloaded += 1;
                }
            }
        }
        let mut uploaded = 0;
        for &t in wanted {
            let stale = match self.state(t) {
                Some(DetailTileState::NotLoaded) => true,
                Some(DetailTileState::Zero) => layer.tile(t).is_some(),
                _ => false,
            };
            if stale {
                self.load(queue, t, layer.tile(t))?;
                uploaded += 1;
            }
        }
        Ok((uploaded, unloaded))
    }

    /// Gives every tile of `tiles` a slot: a zero tile gets one filled with zeros. Fails,
    /// changing nothing, on a tile that is not loaded or too few free slots.
    pub(crate) fn make_resident(
        &mut self,
        queue: &wgpu::Queue,
        tiles: impl Iterator<Item = UVec2> + Clone,
    ) -> Result<(), GpuError> {
        let mut needed = 0usize;
        for tile in tiles.clone() {
            match self.check_tile(tile)? {
                DetailTileState::NotLoaded => return Err(not_loaded(tile)),
                DetailTileState::Zero => needed += 1,
                DetailTileState::Resident(_) => {}
            }
        }
        if needed > self.free.len() {
            return Err(GpuError::DetailSlotsFull {
                needed,
                free: self.free.len(),
            });
        }
        // Every lane of every word DETAIL_ZERO_RAW (row padding included: never read).
        self.staging.fill(u32::from(DETAIL_ZERO_RAW) * 0x0101_0101);
        for tile in tiles {
            if self.state(tile) == Some(DetailTileState::Zero) {
                let slot = self.take_slot(queue, tile)?;
                self.write_slot(queue, slot);
            }
        }
        Ok(())
    }

    fn check_tile(&self, tile: UVec2) -> Result<DetailTileState, GpuError> {
        self.state(tile).ok_or_else(|| {
            CoreError::RegionOutOfBounds {
                rect: Rect::new(tile.as_ivec2(), UVec2::ONE),
                map_size: self.layout.tiles(),
            }
            .into()
        })
    }

    fn take_slot(&mut self, queue: &wgpu::Queue, tile: UVec2) -> Result<u32, GpuError> {
        let slot = self
            .free
            .pop()
            .ok_or(GpuError::DetailSlotsFull { needed: 1, free: 0 })?;
        self.set_state(queue, tile, slot);
        Ok(slot)
    }

    /// Sets `tile` to `to` (zero or not loaded), freeing its slot if it had one.
    fn release(&mut self, queue: &wgpu::Queue, tile: UVec2, to: u32) {
        if let Some(slot) = self.slot_of(tile) {
            self.free.push(slot);
        }
        self.set_state(queue, tile, to);
    }

    /// Sets the state of `tile` here and in the GPU table (written before the next submit).
    fn set_state(&mut self, queue: &wgpu::Queue, tile: UVec2, value: u32) {
        if let Some(s) = self.state.get_mut(tile.x, tile.y) {
            *s = value;
            let index = u64::from(tile.y) * u64::from(self.state.width()) + u64::from(tile.x);
            queue.write_buffer(&self.table, index * 4, bytemuck::bytes_of(&value));
        }
    }

    /// The uniform the detail shaders read: this layer seen from a camera at coarse texel
    /// `camera_texel` (whole texels), shaded as `shading` says, reading at most `reach` coarse
    /// texels from the camera (fade distance, parallax reach and differences included).
    pub(crate) fn info(
        &self,
        camera_texel: IVec2,
        shading: &DetailShading,
        reach: u32,
    ) -> Result<DetailInfo, GpuError> {
        let size = self.layout.detail_size();
        let coarse = self.layout.coarse_size();
        let k = self.layout.refine() as i32;
        let wrap = |v: i32, n: u32| i64::from(v).rem_euclid(i64::from(n)) as i32;
        // Small: the layer is at most 2^26 detail texels a side.
        let camera_detail = IVec2::new(
            wrap(camera_texel.x, coarse.x),
            wrap(camera_texel.y, coarse.y),
        ) * k;
        let lowest =
            i64::from(camera_detail.min_element()) - (i64::from(reach) + 1) * i64::from(k) - 2;
        let lowest = i32::try_from(lowest).map_err(|_| too_far(reach))?;
        let wrap_offset = crate::device::compute::wrap_offset(IVec2::splat(lowest), size)?;
        let enc = detail_encoding();
        Ok(DetailInfo {
            size: size.to_array(),
            wrap_offset,
            camera_detail: camera_detail.to_array(),
            tiles_x: self.layout.tiles().x,
            tile_size: self.layout.tile_size(),
            slots: self.slots,
            refine: self.layout.refine(),
            scale: enc.scale,
            offset: enc.offset,
            gradient_k: (f64::from(enc.scale) / (12.0 * f64::from(self.layout.detail_texel_m())))
                as f32,
            fade_start: shading.fade_start_m,
            fade_end: shading.fade_end_m,
            parallax_steps: shading.parallax_steps,
            max_reach: shading.max_reach_texels,
            even_tiles: u32::from(
                size.x.is_multiple_of(self.layout.tile_size())
                    && size.y.is_multiple_of(self.layout.tile_size()),
            ),
            pad: [0; 2],
        })
    }

    fn write_slot(&self, queue: &wgpu::Queue, slot: u32) {
        let offset = u64::from(slot) * self.staging.len() as u64 * 4;
        queue.write_buffer(&self.heights, offset, bytemuck::cast_slice(&self.staging));
    }
}

fn not_loaded(tile: UVec2) -> GpuError {
    GpuError::DetailTileNotLoaded { tile }
}

fn too_far(reach: u32) -> GpuError {
    CoreError::OutOfRange {
        what: "detail reach from the camera (coarse texels)",
        value: f64::from(reach),
        expected: "small enough for i32 detail texel coordinates",
    }
    .into()
}

/// How the renderer draws a detail layer: where it fades out, and its parallax march.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetailShading {
    /// The detail is drawn fully up to this distance from the camera (metres)...
    pub fade_start_m: f32,
    /// ... and not at all from this one, smoothly in between (no edge where it ends).
    pub fade_end_m: f32,
    /// Linear search steps of the parallax occlusion march over the detail's 1 m range (0:
    /// composite normals only, no parallax).
    pub parallax_steps: u32,
    /// The farthest a grazing view's parallax moves a fragment, in coarse texels.
    pub max_reach_texels: f32,
}

impl Default for DetailShading {
    /// 32 steps (3 cm of height each, refined by interpolation), faded from 30 m to 60 m, at
    /// most 8 coarse texels of parallax.
    fn default() -> Self {
        Self {
            fade_start_m: 30.0,
            fade_end_m: 60.0,
            parallax_steps: 32,
            max_reach_texels: 8.0,
        }
    }
}

/// The most parallax steps a [`DetailShading`] accepts (fragment cost is linear in them).
pub const MAX_PARALLAX_STEPS: u32 = 256;
/// The farthest parallax reach a [`DetailShading`] accepts, in coarse texels.
pub const MAX_PARALLAX_REACH: f32 = 256.0;

impl DetailShading {
    /// Checks the fields: `0 <= fade_start_m < fade_end_m`, finite; at most
    /// [`MAX_PARALLAX_STEPS`] steps; a reach in `[0, MAX_PARALLAX_REACH]`. Returns the coarse
    /// texels from the camera the shaders may read at `texel_m` metres per coarse texel.
    pub fn check(&self, texel_m: f32) -> Result<u32, GpuError> {
        let bad = |what, value: f32, expected| {
            Err(CoreError::OutOfRange {
                what,
                value: f64::from(value),
                expected,
            }
            .into())
        };
        if !(self.fade_start_m.is_finite() && self.fade_start_m >= 0.0) {
            return bad(
                "detail fade start (m)",
                self.fade_start_m,
                "finite, at least 0",
            );
        }
        if !(self.fade_end_m.is_finite() && self.fade_end_m > self.fade_start_m) {
            return bad(
                "detail fade end (m)",
                self.fade_end_m,
                "finite, beyond the fade start",
            );
        }
        if self.parallax_steps > MAX_PARALLAX_STEPS {
            return bad(
                "detail parallax steps",
                self.parallax_steps as f32,
                "at most 256",
            );
        }
        if !(0.0..=MAX_PARALLAX_REACH).contains(&self.max_reach_texels) {
            return bad(
                "detail parallax reach (coarse texels)",
                self.max_reach_texels,
                "0 to 256",
            );
        }
        let texels = (f64::from(self.fade_end_m) / f64::from(texel_m)).ceil()
            + f64::from(self.max_reach_texels).ceil()
            + 2.0;
        if texels > f64::from(1u32 << 24) {
            return bad(
                "detail fade end (m)",
                self.fade_end_m,
                "at most 2^24 coarse texels from the camera",
            );
        }
        Ok(texels as u32)
    }
}

/// The `DetailInfo` uniform of detail_tiles.wgsl (80 bytes, as the WGSL struct).
pub(crate) const DETAIL_INFO_BYTES: u64 = 80;
const _: () = assert!(std::mem::size_of::<DetailInfo>() == DETAIL_INFO_BYTES as usize);

/// The `DetailInfo` uniform of detail_tiles.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct DetailInfo {
    pub size: [u32; 2],
    pub wrap_offset: [i32; 2],
    pub camera_detail: [i32; 2],
    pub tiles_x: u32,
    pub tile_size: u32,
    pub slots: u32,
    pub refine: u32,
    pub scale: f32,
    pub offset: f32,
    pub gradient_k: f32,
    pub fade_start: f32,
    pub fade_end: f32,
    pub parallax_steps: u32,
    pub max_reach: f32,
    pub even_tiles: u32,
    pub pad: [u32; 2],
}
