//! `VolumePass`: the exact u64 sum of a GPU height map's stored values (the volume a granular
//! step conserves), reduced on the GPU and read back as 8 bytes.

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, shader_module,
};
use crate::device::download::map_and_read;
use crate::device::scope::scoped;
use crate::device::small_readback::SmallReadback;
use crate::error::GpuError;
use crate::resources::maps::GpuHeightMap;
use bytemuck::{Pod, Zeroable};
use terrain_core::HeightSample;

/// The uniform block of `granular_volume.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct VolumeParams {
    count: u32,
    stride: u32,
    rounds: u32,
    _pad: u32,
}

const _: () = assert!(std::mem::size_of::<VolumeParams>() == 16);

/// Invocations per workgroup of `granular_volume.wgsl`.
const WORKGROUP: u32 = 256;
/// Most workgroups one sum dispatches; each invocation then visits every `stride`-th value.
const MAX_GROUPS: u32 = 1024;

/// Sums a [`GpuHeightMap`] on the GPU, exactly: each workgroup reduces its share to a u64 held
/// as two u32 words with carry, and adds it to an 8-byte total with atomics that carry out of
/// the low word exactly. The CPU reference is [`terrain_core::HeightMap::raw_sum`]. The total
/// is copied into the pass's own 8-byte readback buffer, so a volume check reads 8 bytes
/// instead of the whole map.
///
/// ```no_run
/// # fn demo(device: &wgpu::Device, queue: &wgpu::Queue, map: &terrain_gpu::GpuHeightMap<u32>)
/// # -> Result<(), terrain_gpu::GpuError> {
/// let mut volume = terrain_gpu::granular::VolumePass::new(device)?;
/// let v0 = volume.sum(device, queue, map)?;
/// # Ok(()) }
/// ```
#[derive(Debug)]
pub struct VolumePass {
    pipeline: wgpu::ComputePipeline,
    bindings: PassBindings<VolumeParams>,
    total: wgpu::Buffer,
    readback: wgpu::Buffer,
}

impl VolumePass {
    /// Builds the pipeline, its bindings, uniform ring and the 8-byte total and readback
    /// buffers.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = PassBindings::new(
            device,
            "VolumePass",
            wgpu::ShaderStages::COMPUTE,
            &[
                StorageBinding::compute(true),
                StorageBinding::compute(false),
            ],
        );
        let module = shader_module(
            device,
            "granular_volume.wgsl",
            terrain_shaders::GRANULAR_VOLUME,
        )?;
        let pipeline = compute_pipeline(device, "VolumePass", &module, bindings.layout(), "main")?;
        let (total, readback) = scoped(device, "VolumePass", || {
            let buffer = |label, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: 8,
                    usage,
                    mapped_at_creation: false,
                })
            };
            (
                buffer(
                    "VolumePass total",
                    wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                ),
                buffer(
                    "VolumePass readback",
                    wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                ),
            )
        })?;
        Ok(Self {
            pipeline,
            bindings,
            total,
            readback,
        })
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records the sum of `map` and its copy into the readback buffer; after the submit,
    /// [`Self::read`] returns it. Only the last sum recorded before a read is kept.
    pub fn encode<T: HeightSample>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
    ) -> Result<(), GpuError> {
        let texels = u64::from(map.size().x) * u64::from(map.size().y);
        let groups = u32::try_from(texels.div_ceil(u64::from(WORKGROUP)))
            .unwrap_or(u32::MAX)
            .clamp(1, MAX_GROUPS);
        let stride = groups * WORKGROUP;
        // Indices stay below count + stride, which must fit the shader's u32 arithmetic.
        let count = match u32::try_from(texels) {
            Ok(c) if u64::from(c) + u64::from(stride) <= u64::from(u32::MAX) => c,
            _ => {
                return Err(GpuError::MapTooLarge {
                    size: map.size(),
                    bytes: texels * 4,
                    limit: (u64::from(u32::MAX) - u64::from(stride)) * 4,
                });
            }
        };
        let params = VolumeParams {
            count,
            stride,
            rounds: count.div_ceil(stride),
            _pad: 0,
        };
        let (group, offset) =
            self.bindings
                .bind(device, queue, &params, &[map.buffer(), &self.total])?;
        encoder.clear_buffer(&self.total, 0, None);
        dispatch(
            encoder,
            "VolumePass",
            (groups, 1),
            &[(&self.pipeline, &group, offset)],
        );
        encoder.copy_buffer_to_buffer(&self.total, 0, &self.readback, 0, 8);
        Ok(())
    }

    /// Records the copy of the sum the last [`Self::encode`] (in this encoder or an earlier
    /// one) wrote into `ring` (a [`SmallReadback`] of 8 bytes), to be read without a wait by
    /// its later poll ([`VolumePass::sum_of`] decodes it). `None` when every buffer of the
    /// ring is in flight.
    pub fn request(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        ring: &mut SmallReadback,
    ) -> Result<Option<u64>, GpuError> {
        ring.request(encoder, &self.total, 0)
    }

    /// The sum in the 8 bytes a [`VolumePass::request`] brought back (as [`Self::read`]).
    pub fn sum_of(bytes: &[u8]) -> u64 {
        bytes
            .get(..8)
            .and_then(|b| <[u8; 8]>::try_from(b).ok())
            .map_or(0, u64::from_le_bytes)
    }

    /// Maps the readback buffer and returns the sum recorded by the last [`Self::encode`]
    /// (submit it first), waiting for the GPU.
    pub fn read(&self, device: &wgpu::Device) -> Result<u64, GpuError> {
        let bytes = map_and_read(device, &self.readback)?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(words
            .iter()
            .rev()
            .fold(0u64, |a, &w| (a << 32) | u64::from(w)))
    }

    /// Convenience: records the sum of `map`, submits it, recalls and reads it back.
    pub fn sum<T: HeightSample>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &GpuHeightMap<T>,
    ) -> Result<u64, GpuError> {
        let mut encoder = device.create_command_encoder(&Default::default());
        let recorded = self.encode(device, queue, &mut encoder, map);
        if recorded.is_ok() {
            queue.submit([encoder.finish()]);
            crate::device::trace::record("granular volume: submitted", 0);
        }
        self.recall();
        recorded?;
        self.read(device)
    }
}
