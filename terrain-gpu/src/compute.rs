//! Shared plumbing of the compute passes: pipeline creation from WGSL and dispatch sizes.

use crate::error::GpuError;
use crate::scope::scoped;

/// Workgroup side of every 2D compute pass (`@workgroup_size(8, 8, 1)`).
pub const WORKGROUP: u32 = 8;

/// Workgroups needed to cover `n` items.
pub fn groups(n: u32) -> u32 {
    n.div_ceil(WORKGROUP)
}

/// A storage or uniform buffer binding entry for a compute shader.
pub fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Compiles `source` and builds a compute pipeline with entry point `main` over `layout`;
/// shader or pipeline errors become [`GpuError::Validation`].
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &'static str,
    source: &str,
    layout: &wgpu::BindGroupLayout,
) -> Result<wgpu::ComputePipeline, GpuError> {
    compute_pipeline_entry(device, label, source, layout, "main")
}

/// Compiles `source` and builds a compute pipeline of entry point `entry` over `layout`.
pub fn compute_pipeline_entry(
    device: &wgpu::Device,
    label: &'static str,
    source: &str,
    layout: &wgpu::BindGroupLayout,
    entry: &str,
) -> Result<wgpu::ComputePipeline, GpuError> {
    scoped(device, label, || {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        });
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
    })
}

/// The smallest multiple of `map_size` (per axis) that makes `min` non-negative: shaders add it
/// before taking remainders, since `%` of negative integers is undefined in GLSL. Fails when
/// the offset would not fit the shaders' `i32` arithmetic.
pub fn wrap_offset(min: glam::IVec2, map_size: glam::UVec2) -> Result<[i32; 2], GpuError> {
    let axis = |m: i32, n: u32| -> Option<i32> {
        let n = i64::from(n.max(1));
        let m = i64::from(m);
        let k = if m < 0 { (-m + n - 1) / n } else { 0 };
        i32::try_from(k * n).ok().filter(|o| *o <= i32::MAX / 2)
    };
    match (axis(min.x, map_size.x), axis(min.y, map_size.y)) {
        (Some(x), Some(y)) => Ok([x, y]),
        _ => Err(terrain_core::CoreError::OutOfRange {
            what: "texel coordinate for wrapping",
            value: f64::from(min.x.min(min.y)),
            expected: "no lower than -2^30 texels",
        }
        .into()),
    }
}

/// Workgroups to cover `size` items per axis, checked against the device's limit (a long thin
/// map could otherwise need more than 65 535 groups on one axis).
pub fn dispatch_size(device: &wgpu::Device, size: glam::UVec2) -> Result<(u32, u32), GpuError> {
    let (x, y) = (groups(size.x), groups(size.y));
    let limit = device.limits().max_compute_workgroups_per_dimension;
    if x.max(y) > limit {
        return Err(terrain_core::CoreError::OutOfRange {
            what: "compute dispatch (workgroups per axis)",
            value: f64::from(x.max(y)),
            expected: "within the device's max_compute_workgroups_per_dimension",
        }
        .into());
    }
    Ok((x, y))
}

/// A bind group of whole buffers at bindings 0, 1, 2, ... in order (every pass binds a uniform
/// block and its storage buffers this way).
pub fn bind_buffers(
    device: &wgpu::Device,
    label: &'static str,
    layout: &wgpu::BindGroupLayout,
    buffers: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}
