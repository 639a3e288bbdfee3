//! `DensityPass`: curvature density maps (Cervin 2012, ch. 3) on the GPU, into a `GpuDensityMap`
//! (level 0 before preprocessing as f32, and every pyramid level as one u32 per sample). The CPU
//! reference is [`terrain_lod::DensityMap`]; both recompute the same regions after a deformation
//! ([`terrain_lod::density::update_regions`]).

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, dispatch_size, shader_module,
    wrap_code, wrap_offset,
};
use crate::device::download::download_bytes;
use crate::error::GpuError;
use crate::resources::maps::{ExactInF32, GpuHeightMap, map_buffer};
use bytemuck::{Pod, Zeroable};
use glam::{IVec2, UVec2};
use terrain_core::{Grid, Rect, WrapMode};
use terrain_lod::DensityParams;
use terrain_lod::density::{density_size, parent_rect, update_regions};

/// The uniform block of `density.wgsl`, byte for byte: each `[_; 2]` is a WGSL `vec2`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, Default)]
struct Params {
    rect_min: [i32; 2],
    rect_size: [u32; 2],
    map_size: [u32; 2],
    wrap: u32,
    scale: f32,
    spacing: f32,
    filter: u32,
    map_offset: [i32; 2],
    src_size: [u32; 2],
    src_base: u32,
    radius: u32,
    border_radius: u32,
    tile: u32,
    dst_w: u32,
    dst_base: u32,
    density_scale: f32,
    exponent: f32,
    src_offset: [i32; 2],
    bits: u32,
    pad: u32,
}

// The WGSL struct's layout: its size, and its `vec2`s 8-aligned as WGSL places them (a
// mismatch fails the build, not a dispatch).
const _: () = {
    use std::mem::{offset_of, size_of};
    assert!(size_of::<Params>() == 104);
    assert!(offset_of!(Params, map_offset) % 8 == 0);
    assert!(offset_of!(Params, src_size) % 8 == 0);
    assert!(offset_of!(Params, src_offset) % 8 == 0);
};

/// A density map and its pyramid on the GPU, for a heightfield of a given size and wrap mode.
/// Pairs with [`terrain_lod::DensityMap`].
#[derive(Debug)]
pub struct GpuDensityMap {
    raw: wgpu::Buffer,
    levels: wgpu::Buffer,
    /// Size and first element of each level in `levels`.
    level_layout: Vec<(UVec2, u32)>,
    map_size: UVec2,
    wrap: WrapMode,
    params: DensityParams,
}

impl GpuDensityMap {
    /// Bytes of GPU memory it takes (the raw curvature values and every pyramid level).
    pub fn memory_bytes(&self) -> u64 {
        self.raw.size() + self.levels.size()
    }

    /// An all-zero density map for a heightfield of `map_size` texels (fill it with
    /// [`DensityPass::encode_full`]). Fails on invalid `params` or a map too large for the
    /// device's storage buffers.
    pub fn new(
        device: &wgpu::Device,
        map_size: UVec2,
        wrap: WrapMode,
        params: DensityParams,
    ) -> Result<Self, GpuError> {
        params.validate()?;
        let size = density_size(map_size);
        let mut level_layout = Vec::new();
        let (mut s, mut base) = (size, 0u64);
        loop {
            level_layout.push((s, base as u32));
            base += u64::from(s.x) * u64::from(s.y);
            if s.x <= 1 && s.y <= 1 {
                break;
            }
            s = UVec2::new(s.x.div_ceil(2), s.y.div_ceil(2));
        }
        let samples = u64::from(size.x) * u64::from(size.y);
        let raw = map_buffer(device, "GpuDensityMap raw", size, samples.max(1) * 4)?;
        let levels = map_buffer(device, "GpuDensityMap levels", size, base.max(1) * 4)?;
        Ok(Self {
            raw,
            levels,
            level_layout,
            map_size,
            wrap,
            params,
        })
    }

    /// A density map shaped for `map`.
    pub fn for_map<T: ExactInF32>(
        device: &wgpu::Device,
        map: &GpuHeightMap<T>,
        params: DensityParams,
    ) -> Result<Self, GpuError> {
        Self::new(device, map.size(), map.wrap(), params)
    }

    /// The number of pyramid levels.
    pub fn level_count(&self) -> usize {
        self.level_layout.len()
    }

    /// The parameters it is computed with.
    pub fn params(&self) -> &DensityParams {
        &self.params
    }

    /// The buffer of every level (one u32 per sample, level after level): for renderers and
    /// tessellation passes that read the density.
    pub fn levels_buffer(&self) -> &wgpu::Buffer {
        &self.levels
    }

    /// Size and first element in [`Self::levels_buffer`] of level `k`.
    pub fn level_layout(&self, k: usize) -> Option<(UVec2, u32)> {
        self.level_layout.get(k).copied()
    }

    /// Downloads level `k` (waits for the GPU); `None` past the coarsest level.
    pub fn read_level(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        k: usize,
    ) -> Result<Option<Grid<u8>>, GpuError> {
        let Some((size, base)) = self.level_layout(k) else {
            return Ok(None);
        };
        let n = u64::from(size.x) * u64::from(size.y);
        let bytes = download_bytes(device, queue, &self.levels, u64::from(base) * 4, n * 4)?;
        let values: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        let grid = Grid::from_vec(
            size.x,
            size.y,
            values.iter().map(|&v| v.min(255) as u8).collect(),
        )?;
        Ok(Some(grid))
    }

    /// Downloads level 0 before preprocessing (waits for the GPU).
    pub fn read_raw(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Grid<f32>, GpuError> {
        let size = density_size(self.map_size);
        let bytes = download_bytes(device, queue, &self.raw, 0, self.raw.size())?;
        let mut values: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes);
        values.truncate(size.x as usize * size.y as usize);
        Ok(Grid::from_vec(size.x, size.y, values)?)
    }
}

/// Computes a [`GpuDensityMap`] from a [`GpuHeightMap`], whole or in the regions a deformation
/// reaches. Three pipelines of one module: raw curvature maxima, preprocessing and
/// quantisation, and one pyramid level from the one below.
#[derive(Debug)]
pub struct DensityPass {
    raw: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
    reduce: wgpu::ComputePipeline,
    bindings: PassBindings<Params>,
}

impl DensityPass {
    /// Builds the pipelines, their bindings and uniform ring.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = PassBindings::new(
            device,
            "DensityPass",
            wgpu::ShaderStages::COMPUTE,
            &[
                StorageBinding::compute(true),
                StorageBinding::compute(false),
                StorageBinding::compute(false),
            ],
        );
        let module = shader_module(device, "density.wgsl", terrain_shaders::DENSITY)?;
        let layout = bindings.layout();
        Ok(Self {
            raw: compute_pipeline(device, "DensityPass raw", &module, layout, "raw_density")?,
            finish: compute_pipeline(
                device,
                "DensityPass finish",
                &module,
                layout,
                "finish_density",
            )?,
            reduce: compute_pipeline(
                device,
                "DensityPass reduce",
                &module,
                layout,
                "reduce_density",
            )?,
            bindings,
        })
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records the recomputation of what a height change inside `dirty` (texels of `map`; may
    /// wrap on a repeating map) can change, as [`terrain_lod::DensityMap::update_rect`].
    pub fn encode<T: ExactInF32>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
        out: &GpuDensityMap,
        dirty: Rect,
    ) -> Result<(), GpuError> {
        if map.size() != out.map_size {
            return Err(GpuError::SizeMismatch {
                expected: out.map_size,
                actual: map.size(),
            });
        }
        if map.wrap() != out.wrap {
            return Err(GpuError::Unsupported {
                what: "DensityPass::encode",
                reason: "the height map's wrap mode differs from the density map's",
            });
        }
        let p = out.params;
        let regions = update_regions(out.map_size, out.wrap, &p, dirty);
        let (radius, border_radius) = p.filter_radii();
        let (size0, _) = out.level_layout[0];
        let base = Params {
            map_size: map.size().to_array(),
            wrap: wrap_code(map.wrap()),
            scale: map.encoding().scale,
            spacing: map.texel_size(),
            filter: p.filter.code(),
            // Reads reach 2 texels before a sample's first (4 i - 1, and its stencil).
            map_offset: wrap_offset(IVec2::splat(-2), map.size())?,
            src_size: size0.to_array(),
            radius,
            border_radius,
            tile: p.tile_size,
            dst_w: size0.x,
            density_scale: p.gain / p.full_density_bend,
            exponent: p.exponent,
            src_offset: wrap_offset(IVec2::splat(-(border_radius as i32)), size0)?,
            bits: GpuHeightMap::<T>::BITS,
            ..Params::default()
        };
        let mut recording = Recording {
            bindings: &mut self.bindings,
            device,
            queue,
            encoder,
            buffers: [map.buffer(), &out.raw, &out.levels],
        };
        for rect in &regions.raw {
            recording.record(&self.raw, base, *rect)?;
        }
        for rect in &regions.finish {
            recording.record(&self.finish, base, *rect)?;
        }
        for rect in regions.finish {
            let mut rect = rect;
            for k in 1..out.level_layout.len() {
                let (child, child_base) = out.level_layout[k - 1];
                let (parent, parent_base) = out.level_layout[k];
                let Some(r) = parent_rect(rect, parent) else {
                    break;
                };
                rect = r;
                let params = Params {
                    src_size: child.to_array(),
                    src_base: child_base,
                    dst_w: parent.x,
                    dst_base: parent_base,
                    ..base
                };
                recording.record(&self.reduce, params, rect)?;
            }
        }
        Ok(())
    }

    /// Records the density map of the whole of `map`.
    pub fn encode_full<T: ExactInF32>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
        out: &GpuDensityMap,
    ) -> Result<(), GpuError> {
        self.encode(
            device,
            queue,
            encoder,
            map,
            out,
            Rect::from_size(map.size()),
        )
    }
}

/// Where one [`DensityPass::encode`] records its dispatches: the pass's uniform ring, the
/// caller's device, queue and encoder, and the buffers every dispatch binds (the height map,
/// the raw level 0 and the pyramid levels).
struct Recording<'a> {
    bindings: &'a mut PassBindings<Params>,
    device: &'a wgpu::Device,
    queue: &'a wgpu::Queue,
    encoder: &'a mut wgpu::CommandEncoder,
    buffers: [&'a wgpu::Buffer; 3],
}

impl Recording<'_> {
    /// Records one dispatch of `pipeline` over `rect`.
    fn record(
        &mut self,
        pipeline: &wgpu::ComputePipeline,
        params: Params,
        rect: Rect,
    ) -> Result<(), GpuError> {
        if rect.is_empty() {
            return Ok(());
        }
        let params = Params {
            rect_min: rect.min.to_array(),
            rect_size: rect.size.to_array(),
            ..params
        };
        let groups = dispatch_size(self.device, rect.size)?;
        let (group, offset) =
            self.bindings
                .bind(self.device, self.queue, &params, &self.buffers)?;
        dispatch(
            self.encoder,
            "DensityPass",
            groups,
            &[(pipeline, &group, offset)],
        );
        Ok(())
    }
}
