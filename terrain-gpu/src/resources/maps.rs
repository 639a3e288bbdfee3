//! GPU mirrors of terrain-core maps: `GpuHeightMap` (heights, packed at the sample's own
//! width: 2 bytes per u16 texel, 1 per u8) and `GpuDerivativeMap` (two 8-bit slope codes per
//! texel, 2 bytes), with upload and download. A 16-bit coarse-map takes 4 bytes per texel with
//! its normals, the thesis format (Flower 2010, sec. 3.1: R16 heights, RG8 derivatives).
//!
//! Why storage buffers rather than textures: the passes need exact integer read-modify-write of
//! the heights, which an `R16Uint`/`R16Unorm` storage texture cannot give on every backend (GL
//! has no writable 16-bit storage formats; WebGPU none at all), and a buffer needs no backup
//! copy for in-place stamping. Texels are packed into u32 words by rows
//! (`resources::packing`); a writer owns whole words, so no invocation's write races
//! another's.

use crate::device::download::download_bytes;
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::resources::packing;
use glam::{UVec2, Vec2};
use std::marker::PhantomData;
use terrain_core::{
    DerivativeMap, Grid, HeightEncoding, HeightMap, HeightSample, WrapMode, decode_slope,
};

/// A storage buffer of `bytes` for a map of `size` texels (copyable both ways), after checking
/// it fits the device's storage binding and buffer limits. Every per-texel buffer of the crate
/// is made here.
pub(crate) fn map_buffer(
    device: &wgpu::Device,
    label: &'static str,
    size: UVec2,
    bytes: u64,
) -> Result<wgpu::Buffer, GpuError> {
    let limits = device.limits();
    let limit = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    if bytes > limit {
        return Err(GpuError::MapTooLarge { size, bytes, limit });
    }
    scoped(device, label, || {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    })
}

/// Sample types whose every stored value is exact in the `f32` arithmetic of the stamp, normal
/// and clipmap shaders (u8 and u16; u32 fixed-point heights are not, and have their own
/// granular passes). Sealed: the passes' exactness depends on it.
///
/// A u32 map cannot reach the stamp pass, while the same call on a u16 map compiles (the two
/// blocks differ in the map's sample type only, which `cargo xtask ci` checks, so the first
/// fails for that reason and no other):
///
/// ```compile_fail
/// # fn f(device: &wgpu::Device, queue: &wgpu::Queue, pass: &mut terrain_gpu::StampPass,
/// #      p: terrain_core::StampPlacement) -> Result<(), terrain_gpu::GpuError> {
/// let map: &terrain_gpu::GpuHeightMap<u32> = todo!();
/// let mut encoder = device.create_command_encoder(&Default::default());
/// let g = terrain_core::GaussianStamp::default();
/// let op = terrain_gpu::StampOp {
///     stamp: terrain_gpu::GpuStamp::Gaussian(&g),
///     placement: p,
///     blend: terrain_core::Blend::Add,
/// };
/// pass.encode(device, queue, &mut encoder, map, &op)?;
/// # Ok(()) }
/// ```
///
/// ```no_run
/// # fn f(device: &wgpu::Device, queue: &wgpu::Queue, pass: &mut terrain_gpu::StampPass,
/// #      p: terrain_core::StampPlacement) -> Result<(), terrain_gpu::GpuError> {
/// let map: &terrain_gpu::GpuHeightMap<u16> = todo!();
/// let mut encoder = device.create_command_encoder(&Default::default());
/// let g = terrain_core::GaussianStamp::default();
/// let op = terrain_gpu::StampOp {
///     stamp: terrain_gpu::GpuStamp::Gaussian(&g),
///     placement: p,
///     blend: terrain_core::Blend::Add,
/// };
/// pass.encode(device, queue, &mut encoder, map, &op)?;
/// # Ok(()) }
/// ```
pub trait ExactInF32: HeightSample + sealed::Sealed {}
impl ExactInF32 for u8 {}
impl ExactInF32 for u16 {}

mod sealed {
    pub trait Sealed {}
    impl Sealed for u8 {}
    impl Sealed for u16 {}
}

/// A heightmap on the GPU: a storage buffer of rows of texels packed at the sample's width
/// (16-bit texels two per u32 word, 8-bit four, 32-bit one), with the map's encoding, spacing
/// and wrap mode. Pairs with [`terrain_core::HeightMap<T>`]: `u16` for the
/// coarse-map, `u8` for detail tiles, `u32` for the fixed-point heights of granular
/// deformation. The sample type is part of the type, so a download cannot clamp silently.
#[derive(Debug)]
pub struct GpuHeightMap<T: HeightSample> {
    buffer: wgpu::Buffer,
    size: UVec2,
    encoding: HeightEncoding,
    texel_size: f32,
    wrap: WrapMode,
    _sample: PhantomData<T>,
}

impl<T: HeightSample> GpuHeightMap<T> {
    /// Uploads `map`.
    pub fn from_map(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &HeightMap<T>,
    ) -> Result<Self, GpuError> {
        let size = map.size();
        let bytes = packing::words(size.x, size.y, Self::BITS) * 4;
        let buffer = map_buffer(device, "GpuHeightMap", size, bytes)?;
        let gpu = Self {
            buffer,
            size,
            encoding: map.encoding(),
            texel_size: map.texel_size(),
            wrap: map.wrap(),
            _sample: PhantomData,
        };
        gpu.write(queue, map)?;
        Ok(gpu)
    }

    /// Replaces the heights with those of `map` (same size, encoding and spacing).
    pub fn write(&self, queue: &wgpu::Queue, map: &HeightMap<T>) -> Result<(), GpuError> {
        if map.encoding() != self.encoding || map.texel_size() != self.texel_size {
            return Err(GpuError::Unsupported {
                what: "GpuHeightMap::write",
                reason: "the map's encoding or texel size differs from the uploaded map's",
            });
        }
        if map.size() != self.size {
            return Err(GpuError::SizeMismatch {
                expected: self.size,
                actual: map.size(),
            });
        }
        let values = map.grid().as_slice();
        if Self::BITS == 32 {
            // u32 heights go up as they are.
            queue.write_buffer(&self.buffer, 0, bytemuck::cast_slice(values));
        } else {
            let raw = values.iter().map(|v| v.to_raw_f64() as u32);
            let data = packing::pack(raw, self.size.x, Self::BITS);
            queue.write_buffer(&self.buffer, 0, bytemuck::cast_slice(&data));
        }
        Ok(())
    }

    /// Downloads the heights (waits for the GPU).
    pub fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<HeightMap<T>, GpuError> {
        let raw = self.read_raw(device, queue)?;
        let grid = Grid::from_vec(
            self.size.x,
            self.size.y,
            raw.iter()
                .map(|&v| T::from_raw_f64_clamped(f64::from(v)))
                .collect(),
        )?;
        Ok(HeightMap::new(
            grid,
            self.encoding,
            self.texel_size,
            self.wrap,
        )?)
    }

    /// Downloads the stored values as u32, one per texel, row-major (waits for the GPU).
    pub fn read_raw(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<u32>, GpuError> {
        let bytes = download_bytes(device, queue, &self.buffer, 0, self.buffer.size())?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(packing::unpack(&words, self.size.x, Self::BITS))
    }

    /// Bits per texel in the buffer: 8, 16 or 32, the sample's width.
    pub const BITS: u32 = packing::bits_of(std::mem::size_of::<T>());

    /// Bytes the buffer takes per texel (1, 2 or 4; rows are padded to whole u32 words).
    pub fn bytes_per_texel(&self) -> f64 {
        self.buffer.size() as f64 / (f64::from(self.size.x) * f64::from(self.size.y))
    }

    /// The storage buffer: rows of packed texels (see [`GpuHeightMap`]).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Size in texels.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// Height encoding.
    pub fn encoding(&self) -> HeightEncoding {
        self.encoding
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// Wrap mode.
    pub fn wrap(&self) -> WrapMode {
        self.wrap
    }

    /// Largest stored value of the sample type (255, 65 535 or 2^32 - 1).
    pub fn max_raw(&self) -> u32 {
        T::MAX_RAW as u32
    }

    /// The whole map as the passes address it.
    pub(crate) fn view(&self) -> MapView<'_> {
        MapView {
            buffer: &self.buffer,
            base: 0,
            size: self.size,
            wrap: self.wrap,
            encoding: self.encoding,
            texel_size: self.texel_size,
            max_raw: self.max_raw(),
            bits: Self::BITS,
        }
    }
}

/// A height map as the stamp pass and the region readback address it: `size` texels of `bits`
/// bits, packed by rows (`packing`), from word `base` of `buffer`. A [`GpuHeightMap`] is one
/// from word 0; a tile slot of a [`crate::GpuTileAtlas`] is one from its slot's first word, so
/// both passes work on either without a copy.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MapView<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub base: u32,
    pub size: UVec2,
    pub wrap: WrapMode,
    pub encoding: HeightEncoding,
    pub texel_size: f32,
    pub max_raw: u32,
    pub bits: u32,
}

impl GpuHeightMap<u32> {
    /// Fixed-point units per metre (`1 / scale`, rounded) of granular heights.
    pub fn units_per_metre(&self) -> f64 {
        (1.0 / f64::from(self.encoding.scale)).round()
    }
}

/// Partial-derivative normals on the GPU: per texel, the 8-bit slope codes
/// ([`terrain_core::SlopeCodec`]) of `(dh/dX, dh/dZ)`, dX in the low byte, as 16-bit texels
/// packed two per u32 word (2 bytes per texel; Flower 2010 stores the two components in
/// `GL_RG8`). Pairs with [`terrain_core::DerivativeMap`] ([`GpuDerivativeMap::read`] decodes)
/// and [`terrain_core::SlopeCodec::codes`] ([`GpuDerivativeMap::read_codes`], bit for bit).
#[derive(Debug)]
pub struct GpuDerivativeMap {
    buffer: wgpu::Buffer,
    size: UVec2,
    texel_size: f32,
    wrap: WrapMode,
}

impl GpuDerivativeMap {
    /// Bits per texel of the buffer: two 8-bit codes.
    pub const BITS: u32 = 16;

    /// An all-zero (flat) derivative map for a height map of `size`, spacing and wrap.
    pub fn new(
        device: &wgpu::Device,
        size: UVec2,
        texel_size: f32,
        wrap: WrapMode,
    ) -> Result<Self, GpuError> {
        // Validate up front: the spacing is only used when reading back.
        DerivativeMap::from_grid(Grid::new(1, 1, Vec2::ZERO)?, texel_size, wrap)?;
        let bytes = packing::words(size.x, size.y, Self::BITS) * 4;
        let buffer = map_buffer(device, "GpuDerivativeMap", size, bytes)?;
        Ok(Self {
            buffer,
            size,
            texel_size,
            wrap,
        })
    }

    /// A derivative map shaped for `map`.
    pub fn for_map<T: HeightSample>(
        device: &wgpu::Device,
        map: &GpuHeightMap<T>,
    ) -> Result<Self, GpuError> {
        Self::new(device, map.size(), map.texel_size(), map.wrap())
    }

    /// Downloads the slope codes `[dX, dZ]` per texel, waiting for the GPU.
    pub fn read_codes(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Grid<[i8; 2]>, GpuError> {
        let bytes = download_bytes(device, queue, &self.buffer, 0, self.buffer.size())?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        let codes = packing::unpack(&words, self.size.x, Self::BITS)
            .into_iter()
            .map(|v| [v as u8 as i8, (v >> 8) as u8 as i8])
            .collect();
        Ok(Grid::from_vec(self.size.x, self.size.y, codes)?)
    }

    /// Downloads the gradients (the slopes the codes stand for), waiting for the GPU.
    pub fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<DerivativeMap, GpuError> {
        let codes = self.read_codes(device, queue)?;
        let grid = codes.map(|&[x, z]| Vec2::new(decode_slope(x), decode_slope(z)));
        Ok(DerivativeMap::from_grid(grid, self.texel_size, self.wrap)?)
    }

    /// Bytes the buffer takes per texel (2; rows are padded to whole u32 words).
    pub fn bytes_per_texel(&self) -> f64 {
        self.buffer.size() as f64 / (f64::from(self.size.x) * f64::from(self.size.y))
    }

    /// The storage buffer (see [`GpuDerivativeMap`] for its layout).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Size in texels.
    pub fn size(&self) -> UVec2 {
        self.size
    }
}
