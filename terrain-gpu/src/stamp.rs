//! `StampPass`: every stamp kind of terrain-core (Gaussian, texture, shockwave as a texture,
//! user procedural WGSL) applied on the GPU to the stamp's region only, in place.

use crate::compute::{bind_buffers, buffer_entry, compute_pipeline, dispatch_size, wrap_offset};
use crate::error::GpuError;
use crate::maps::GpuHeightMap;
use crate::scope::scoped;
use bytemuck::{Pod, Zeroable};
use glam::UVec2;
use terrain_core::{
    Blend, DirtyRect, GaussianStamp, StampPlacement, TextureStamp, WrapMode, stamp_region,
};
use wgpu::util::DeviceExt;

/// The uniform block of `stamp.wgsl` (`StampParams`), byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct StampParams {
    region_min: [i32; 2],
    region_size: [u32; 2],
    map_size: [u32; 2],
    wrap: u32,
    kind: u32,
    center: [f32; 2],
    inv_half: [f32; 2],
    cos_sin: [f32; 2],
    blend: u32,
    raw_per_value: f32,
    base_raw: f32,
    max_raw: f32,
    beta: f32,
    pad: f32,
    tex_size: [u32; 2],
    wrap_offset: [i32; 2],
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<StampParams>() == 96);

const KIND_GAUSSIAN: u32 = 0;
const KIND_TEXTURE: u32 = 1;
const KIND_USER: u32 = 2;

/// A texture stamp's values uploaded once (the shockwave uploads its change every frame).
#[derive(Debug)]
pub struct GpuTextureStamp {
    values: wgpu::Buffer,
    size: UVec2,
}

impl GpuTextureStamp {
    /// Uploads the values of `stamp`.
    pub fn new(device: &wgpu::Device, stamp: &TextureStamp) -> Result<Self, GpuError> {
        let values = scoped(device, "texture stamp upload", || {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("GpuTextureStamp"),
                contents: bytemuck::cast_slice(stamp.values().as_slice()),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
        })?;
        Ok(Self {
            values,
            size: stamp.values().size(),
        })
    }
}

/// A user-defined procedural stamp: a WGSL function
/// `fn user_stamp_value(local: vec2<f32>) -> f32` (local coordinates in `[-1, 1]^2`, the value
/// multiplied by the intensity), compiled into its own variant of the stamp pipeline. It is the
/// GPU side of a [`terrain_core::Stamp`] implementation; keep both in step.
#[derive(Debug)]
pub struct GpuProceduralStamp {
    pipeline: wgpu::ComputePipeline,
}

impl GpuProceduralStamp {
    /// Compiles `wgsl_function` into the stamp shader of `pass`.
    pub fn new(
        device: &wgpu::Device,
        pass: &StampPass,
        wgsl_function: &str,
    ) -> Result<Self, GpuError> {
        let (begin, end) = terrain_shaders::USER_STAMP_MARKERS;
        let src = terrain_shaders::STAMP;
        let (Some(a), Some(b)) = (src.find(begin), src.find(end)) else {
            return Err(GpuError::Shader(
                "the stamp shader lost its user markers".into(),
            ));
        };
        let source = format!("{}{begin}\n{wgsl_function}\n{}", &src[..a], &src[b..]);
        let pipeline = compute_pipeline(device, "user procedural stamp", &source, &pass.layout)
            .map_err(|e| GpuError::Shader(e.to_string()))?;
        Ok(Self { pipeline })
    }
}

/// The stamp to apply.
#[derive(Debug, Clone, Copy)]
pub enum GpuStamp<'a> {
    /// The Gaussian of seed 000 eq. 3.5 with its edge epsilon.
    Gaussian(&'a GaussianStamp),
    /// An uploaded texture stamp.
    Texture(&'a GpuTextureStamp),
    /// A user procedural stamp.
    Procedural(&'a GpuProceduralStamp),
}

/// Applies stamps to a [`GpuHeightMap`]: one dispatch over the stamp's footprint, wrapped on a
/// repeating map inside the shader (no split into pieces and no backup copy of the map).
#[derive(Debug)]
pub struct StampPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    empty_values: wgpu::Buffer,
}

impl StampPass {
    /// Builds the pipeline.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        use wgpu::BufferBindingType as B;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("StampPass"),
            entries: &[
                buffer_entry(0, B::Uniform),
                buffer_entry(1, B::Storage { read_only: false }),
                buffer_entry(2, B::Storage { read_only: true }),
            ],
        });
        let pipeline = compute_pipeline(device, "StampPass", terrain_shaders::STAMP, &layout)?;
        let empty_values = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("StampPass empty texture"),
            contents: bytemuck::cast_slice(&[0.0f32; 4]),
            usage: wgpu::BufferUsages::STORAGE,
        });
        Ok(Self {
            pipeline,
            layout,
            empty_values,
        })
    }

    /// Records one stamp into `encoder` and returns the map rects it covers (as
    /// [`terrain_core::apply_stamp`]: 1, 2 or 4 on a repeating map, none off a clamped map).
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap,
        stamp: GpuStamp<'_>,
        placement: &StampPlacement,
        blend: Blend,
    ) -> Result<Vec<DirtyRect>, GpuError> {
        let ts = map.texel_size();
        let Some(region) = stamp_region(map.size(), map.wrap(), ts, placement)? else {
            return Ok(Vec::new());
        };
        let (center, inv_half, sin, cos) = placement.local_frame(ts);
        let enc = map.encoding();
        let (blend_code, base_m) = match blend {
            Blend::Add => (0, 0.0),
            Blend::Min { base_m } => (1, base_m),
            Blend::Max { base_m } => (2, base_m),
        };
        if !base_m.is_finite() {
            return Err(terrain_core::CoreError::NonFinite {
                what: "blend base height",
                value: base_m,
            }
            .into());
        }
        let (kind, beta, values, tex_size, pipeline) = match stamp {
            GpuStamp::Gaussian(g) => (
                KIND_GAUSSIAN,
                g.beta_for(placement.intensity),
                &self.empty_values,
                UVec2::ONE,
                &self.pipeline,
            ),
            GpuStamp::Texture(t) => (KIND_TEXTURE, 0.0, &t.values, t.size, &self.pipeline),
            GpuStamp::Procedural(p) => {
                (KIND_USER, 0.0, &self.empty_values, UVec2::ONE, &p.pipeline)
            }
        };
        let params = StampParams {
            region_min: region.footprint.min.to_array(),
            region_size: region.footprint.size.to_array(),
            map_size: map.size().to_array(),
            wrap: match map.wrap() {
                WrapMode::Repeat => 0,
                WrapMode::Clamp => 1,
            },
            kind,
            center: center.to_array(),
            inv_half: inv_half.to_array(),
            cos_sin: [cos, sin],
            blend: blend_code,
            raw_per_value: placement.intensity / enc.scale,
            base_raw: enc.to_raw(base_m) as f32,
            max_raw: map.max_raw() as f32,
            beta,
            pad: 0.0,
            tex_size: tex_size.to_array(),
            wrap_offset: wrap_offset(region.footprint.min, map.size())?,
        };
        let (gx, gy) = dispatch_size(device, region.footprint.size)?;
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("StampParams"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = bind_buffers(
            device,
            "StampPass",
            &self.layout,
            &[&uniform, map.buffer(), values],
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("StampPass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
        Ok(region.pieces.iter().map(|p| p.map).collect())
    }
}
