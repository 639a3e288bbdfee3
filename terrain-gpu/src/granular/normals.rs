//! `GranularNormalsPass`: normals of the granular map by the symmetric difference and 3x3
//! Gaussian blur passes, as `terrain_core::granular::{symmetric_normals, blur_normals}` within a
//! float tolerance, into a `GpuGranularNormals`.

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, dispatch_size, shader_module,
};
use crate::device::download::download_bytes;
use crate::error::GpuError;
use crate::resources::maps::{GpuHeightMap, map_buffer};
use bytemuck::{Pod, Zeroable};
use glam::{UVec2, Vec4};
use terrain_core::granular::{GranularError, MAX_ITERATIONS};
use terrain_core::{Grid, Rect};

/// The uniform block of `granular_normals.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct NormalParams {
    area_min: [u32; 2],
    area_size: [u32; 2],
    map_size: [u32; 2],
    k: f32,
    scale: f32,
}

const _: () = assert!(std::mem::size_of::<NormalParams>() == 32);

/// The normals of a granular map on the GPU: one `vec4<f32>` per map texel, row-major (unit
/// normal xyz, height in metres in w: the float copy of the heights for filtered rendering,
/// Persson 2019, sec. 4.3), and the blur's scratch of the same size. Pairs with the grids of
/// [`terrain_core::granular::symmetric_normals`] and [`terrain_core::granular::float_heights`].
#[derive(Debug)]
pub struct GpuGranularNormals {
    normals: wgpu::Buffer,
    scratch: wgpu::Buffer,
    size: UVec2,
}

impl GpuGranularNormals {
    /// Bytes of GPU memory it takes (the normals and the blur's scratch).
    pub fn memory_bytes(&self) -> u64 {
        self.normals.size() + self.scratch.size()
    }

    /// Zeroed normals for a map of `size` texels.
    pub fn new(device: &wgpu::Device, size: UVec2) -> Result<Self, GpuError> {
        let bytes = u64::from(size.x) * u64::from(size.y) * 16;
        if bytes == 0 {
            return Err(terrain_core::CoreError::EmptyGrid {
                width: size.x,
                height: size.y,
            }
            .into());
        }
        Ok(Self {
            normals: map_buffer(device, "granular normals", size, bytes)?,
            scratch: map_buffer(device, "granular normals blur scratch", size, bytes)?,
            size,
        })
    }

    /// Zeroed normals shaped for `map`.
    pub fn for_map(device: &wgpu::Device, map: &GpuHeightMap<u32>) -> Result<Self, GpuError> {
        Self::new(device, map.size())
    }

    /// The normal buffer (`vec4<f32>` per texel; copyable both ways).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.normals
    }

    /// Size in texels.
    pub fn size(&self) -> UVec2 {
        self.size
    }

    /// Downloads the normals (xyz) and float heights (w), waiting for the GPU.
    pub fn read(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Grid<Vec4>, GpuError> {
        let bytes = download_bytes(device, queue, &self.normals, 0, self.normals.size())?;
        let raw: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(Grid::from_vec(
            self.size.x,
            self.size.y,
            raw.iter().map(|&v| Vec4::from(v)).collect(),
        )?)
    }
}

/// Writes unit normals and the float copy of the heights of an area of a granular map into a
/// [`GpuGranularNormals`] ([`Self::encode`]), and blurs them ([`Self::encode_blur`]).
#[derive(Debug)]
pub struct GranularNormalsPass {
    normals: wgpu::ComputePipeline,
    blur: wgpu::ComputePipeline,
    copy_back: wgpu::ComputePipeline,
    normal_bindings: PassBindings<NormalParams>,
    blur_bindings: PassBindings<NormalParams>,
}

/// The uniform block for `area` of `out` (other fields zero), after checking the area lies
/// inside it; with the area's dispatch.
fn area_params(
    device: &wgpu::Device,
    out: &GpuGranularNormals,
    area: Rect,
) -> Result<(NormalParams, (u32, u32)), GpuError> {
    if area.is_empty() || !Rect::from_size(out.size).contains_rect(&area) {
        return Err(GpuError::BadRegion {
            rect: area,
            map_size: out.size,
        });
    }
    let params = NormalParams {
        area_min: [area.min.x as u32, area.min.y as u32],
        area_size: area.size.to_array(),
        map_size: out.size.to_array(),
        k: 0.0,
        scale: 0.0,
    };
    Ok((params, dispatch_size(device, area.size)?))
}

impl GranularNormalsPass {
    /// Builds the pipelines (one shader module), their bindings and uniform rings.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let rw = StorageBinding::compute(false);
        let normal_bindings = PassBindings::new(
            device,
            "GranularNormalsPass",
            wgpu::ShaderStages::COMPUTE,
            &[rw, rw, StorageBinding::compute(true)],
        );
        let blur_bindings = PassBindings::new(
            device,
            "GranularNormalsPass blur",
            wgpu::ShaderStages::COMPUTE,
            &[rw, rw],
        );
        let module = shader_module(
            device,
            "granular_normals.wgsl",
            terrain_shaders::GRANULAR_NORMALS,
        )?;
        Ok(Self {
            normals: compute_pipeline(
                device,
                "GranularNormalsPass",
                &module,
                normal_bindings.layout(),
                "main",
            )?,
            blur: compute_pipeline(
                device,
                "GranularNormalsPass blur",
                &module,
                blur_bindings.layout(),
                "blur",
            )?,
            copy_back: compute_pipeline(
                device,
                "GranularNormalsPass copy",
                &module,
                blur_bindings.layout(),
                "copy_back",
            )?,
            normal_bindings,
            blur_bindings,
        })
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.normal_bindings.recall();
        self.blur_bindings.recall();
    }

    /// Records the normals and float heights of `area` of `map` into `out` (shaped for `map`),
    /// as [`terrain_core::granular::symmetric_normals`] and
    /// [`terrain_core::granular::float_heights`].
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<u32>,
        out: &GpuGranularNormals,
        area: Rect,
    ) -> Result<(), GpuError> {
        if out.size != map.size() {
            return Err(GpuError::SizeMismatch {
                expected: map.size(),
                actual: out.size,
            });
        }
        let (params, groups) = area_params(device, out, area)?;
        let scale = f64::from(map.encoding().scale);
        let params = NormalParams {
            k: (scale * 0.5 / f64::from(map.texel_size())) as f32,
            scale: map.encoding().scale,
            ..params
        };
        let (group, offset) = self.normal_bindings.bind(
            device,
            queue,
            &params,
            &[&out.normals, &out.scratch, map.buffer()],
        )?;
        dispatch(
            encoder,
            "GranularNormalsPass",
            groups,
            &[(&self.normals, &group, offset)],
        );
        Ok(())
    }

    /// Records `iterations` 3x3 Gaussian blur passes of the normals of `area` of `out` (the
    /// heights in w stay), as [`terrain_core::granular::blur_normals`]. Fails with
    /// [`GpuError::Granular`] for more than [`MAX_ITERATIONS`] iterations.
    pub fn encode_blur(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        out: &GpuGranularNormals,
        area: Rect,
        iterations: u32,
    ) -> Result<(), GpuError> {
        if iterations > MAX_ITERATIONS {
            return Err(GranularError::ParamOutOfRange {
                name: "numIterationsBlurNormals",
                value: f64::from(iterations),
                range: "0..=1024",
            }
            .into());
        }
        let (params, groups) = area_params(device, out, area)?;
        if iterations == 0 {
            return Ok(());
        }
        let (group, offset) =
            self.blur_bindings
                .bind(device, queue, &params, &[&out.normals, &out.scratch])?;
        let mut dispatches = Vec::with_capacity(2 * iterations as usize);
        for _ in 0..iterations {
            dispatches.push((&self.blur, &group, offset));
            dispatches.push((&self.copy_back, &group, offset));
        }
        dispatch(encoder, "GranularNormalsPass blur", groups, &dispatches);
        Ok(())
    }
}
