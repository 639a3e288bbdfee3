//! Shared plumbing of the passes: shader modules and pipelines, the per-pass bindings (a
//! uniform ring with dynamic offsets and bind groups cached by buffer), and dispatch sizes.

use crate::device::scope::scoped;
use crate::error::GpuError;
use bytemuck::Pod;
use std::collections::HashMap;
use std::marker::PhantomData;

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

/// Compiles one WGSL module (once per module: every entry point's pipeline is built from it).
pub fn shader_module(
    device: &wgpu::Device,
    label: &'static str,
    source: &str,
) -> Result<wgpu::ShaderModule, GpuError> {
    scoped(device, label, || {
        device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        })
    })
}

/// Builds a compute pipeline of entry point `entry` of `module` over `layout`; pipeline errors
/// become [`GpuError::Validation`].
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &'static str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    entry: &str,
) -> Result<wgpu::ComputePipeline, GpuError> {
    scoped(device, label, || {
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        });
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
    })
}

/// One storage buffer binding of a pass (bindings 1, 2, ... after the uniform block).
#[derive(Debug, Clone, Copy)]
pub struct StorageBinding {
    /// Stages that read (or write) it.
    pub visibility: wgpu::ShaderStages,
    /// Whether the shader only reads it.
    pub read_only: bool,
}

impl StorageBinding {
    /// A compute-stage binding, read-only or read-write.
    pub const fn compute(read_only: bool) -> Self {
        Self {
            visibility: wgpu::ShaderStages::COMPUTE,
            read_only,
        }
    }
}

/// Slots a uniform ring starts with, and the most it grows to before it asks for
/// [`PassBindings::recall`] (4 MiB of uniforms at the usual 256-byte alignment).
const RING_START: u32 = 256;
const RING_MAX: u32 = 16_384;
/// Distinct sets of bound buffers a pass keeps bind groups for; past it the least recently
/// used one is dropped (a bind group holds its buffers alive, so the cache is bounded).
const BIND_CACHE: usize = 32;

/// The bindings of one pass, built once: a bind group layout of a uniform block at binding 0
/// (a ring of slots addressed by dynamic offset, one slot per recorded dispatch) and storage
/// buffers at bindings 1, 2, ..., and the bind groups over the buffer sets the pass has been
/// given, cached by buffer.
///
/// Why a ring: `queue.write_buffer` lands before the next submit, so dispatches recorded into
/// one submission must not share a uniform buffer. Every recorded dispatch takes the next slot;
/// [`PassBindings::recall`] frees them all once the work that used them has been submitted (the
/// shape of `wgpu::util::StagingBelt`). A ring that fills up grows (a one-off allocation), up to
/// a bound, so steady-state frames allocate nothing.
#[derive(Debug)]
pub struct PassBindings<T: Pod> {
    label: &'static str,
    layout: wgpu::BindGroupLayout,
    ring: wgpu::Buffer,
    stride: u64,
    capacity: u32,
    next: u32,
    /// Bind groups by the buffers they bind, with the use count of their last use.
    groups: HashMap<Vec<wgpu::Buffer>, (wgpu::BindGroup, u64)>,
    uses: u64,
    /// The binding number of each storage buffer, in the order `bind` takes them.
    numbers: Vec<u32>,
    _uniform: PhantomData<T>,
}

impl<T: Pod> PassBindings<T> {
    /// The layout (uniform `T` at binding 0 with a dynamic offset, then `storage` in order) and
    /// an empty ring.
    pub fn new(
        device: &wgpu::Device,
        label: &'static str,
        uniform_visibility: wgpu::ShaderStages,
        storage: &[StorageBinding],
    ) -> Self {
        let numbered: Vec<(u32, StorageBinding)> = (1..).zip(storage.iter().copied()).collect();
        Self::numbered(device, label, uniform_visibility, &numbered)
    }

    /// As [`PassBindings::new`], each storage buffer at the binding number given with it (a
    /// shader that includes a resource file with fixed numbers, as the tile atlas's).
    pub fn numbered(
        device: &wgpu::Device,
        label: &'static str,
        uniform_visibility: wgpu::ShaderStages,
        storage: &[(u32, StorageBinding)],
    ) -> Self {
        let mut entries = vec![wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: uniform_visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: true,
                min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<T>() as u64),
            },
            count: None,
        }];
        entries.extend(
            storage
                .iter()
                .map(|&(binding, s)| wgpu::BindGroupLayoutEntry {
                    binding,
                    visibility: s.visibility,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage {
                            read_only: s.read_only,
                        },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }),
        );
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &entries,
        });
        let align = u64::from(device.limits().min_uniform_buffer_offset_alignment.max(1));
        let stride = (std::mem::size_of::<T>() as u64).div_ceil(align) * align;
        Self {
            label,
            ring: ring_buffer(device, label, stride, RING_START),
            layout,
            stride,
            capacity: RING_START,
            next: 0,
            groups: HashMap::new(),
            uses: 0,
            numbers: storage.iter().map(|&(n, _)| n).collect(),
            _uniform: PhantomData,
        }
    }

    /// The bind group layout (for the pass's pipelines).
    pub fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout
    }

    /// Writes `params` into the next slot of the ring and returns the bind group over `buffers`
    /// (built on first use of that set) with the slot's dynamic offset, for
    /// `set_bind_group(0, &group, &[offset])`.
    pub fn bind(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        params: &T,
        buffers: &[&wgpu::Buffer],
    ) -> Result<(wgpu::BindGroup, u32), GpuError> {
        if self.next == self.capacity {
            if self.capacity >= RING_MAX {
                return Err(GpuError::UniformRingFull {
                    pass: self.label,
                    slots: self.capacity,
                });
            }
            // Earlier slots stay valid: recorded commands keep the old buffer alive.
            self.capacity = (self.capacity * 2).min(RING_MAX);
            self.ring = ring_buffer(device, self.label, self.stride, self.capacity);
            self.next = 0;
            self.groups.clear();
        }
        let offset = u64::from(self.next) * self.stride;
        queue.write_buffer(&self.ring, offset, bytemuck::bytes_of(params));
        self.next += 1;
        Ok((self.group_for(device, buffers)?, offset as u32))
    }

    /// Builds the bind group over `buffers` now if it is not cached yet, without taking a ring
    /// slot: for the other half of a ping-pong pair, so that which half a frame ends on never
    /// makes a bind group later.
    pub fn warm(
        &mut self,
        device: &wgpu::Device,
        buffers: &[&wgpu::Buffer],
    ) -> Result<(), GpuError> {
        self.group_for(device, buffers).map(|_| ())
    }

    /// The cached bind group over `buffers`, built on first use.
    fn group_for(
        &mut self,
        device: &wgpu::Device,
        buffers: &[&wgpu::Buffer],
    ) -> Result<wgpu::BindGroup, GpuError> {
        let key: Vec<wgpu::Buffer> = buffers.iter().map(|b| (*b).clone()).collect();
        self.uses += 1;
        if let Some((group, last)) = self.groups.get_mut(&key) {
            *last = self.uses;
            return Ok(group.clone());
        }
        if self.groups.len() >= BIND_CACHE {
            let oldest = self
                .groups
                .iter()
                .min_by_key(|(_, (_, last))| *last)
                .map(|(k, _)| k.clone());
            if let Some(k) = oldest {
                self.groups.remove(&k);
            }
        }
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &self.ring,
                offset: 0,
                size: wgpu::BufferSize::new(std::mem::size_of::<T>() as u64),
            }),
        }];
        entries.extend(buffers.iter().zip(&self.numbers).map(|(b, &binding)| {
            wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            }
        }));
        let group = scoped(device, self.label, || {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(self.label),
                layout: &self.layout,
                entries: &entries,
            })
        })?;
        self.groups.insert(key, (group.clone(), self.uses));
        Ok(group)
    }

    /// Frees every slot of the ring. Call it after the submit that carries the work recorded
    /// since the last recall (as `wgpu::util::StagingBelt::recall`).
    pub fn recall(&mut self) {
        self.next = 0;
    }

    /// Drops the cached bind groups (and with them the buffers they hold), for when the
    /// buffers a pass binds were replaced, e.g. by larger scratch buffers.
    pub fn clear_bind_groups(&mut self) {
        self.groups.clear();
    }
}

fn ring_buffer(
    device: &wgpu::Device,
    label: &'static str,
    stride: u64,
    slots: u32,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: stride * u64::from(slots),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Records one compute pass of `dispatches` (pipeline, bind group, dynamic offset), each over
/// `groups` workgroups.
pub fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    label: &'static str,
    groups: (u32, u32),
    dispatches: &[(&wgpu::ComputePipeline, &wgpu::BindGroup, u32)],
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    for (pipeline, group, offset) in dispatches {
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, *group, &[*offset]);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
    }
}

/// The shaders' code of a wrap mode (`terrain_shaders::codes`).
pub fn wrap_code(wrap: terrain_core::WrapMode) -> u32 {
    match wrap {
        terrain_core::WrapMode::Repeat => terrain_shaders::codes::WRAP_REPEAT,
        terrain_core::WrapMode::Clamp => terrain_shaders::codes::WRAP_CLAMP,
    }
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
