//! The device features and limits terrain-gpu needs, and a helper that computes them for a map
//! size, so an engine can ask for them when it creates its device.
//!
//! No feature is required. [`OPTIONAL_FEATURES`] are used when the device has them. Every map
//! lives in one storage buffer per quantity, so the limits that grow with the map are
//! `max_storage_buffer_binding_size` and `max_buffer_size`: an 8192^2 coarse-map (16-bit heights
//! and 16-bit slope codes, packed two per u32 word) needs a 128 MiB binding for each (wgpu's
//! default limit), a granular map of u32 heights 256 MiB, and its normals (`vec4<f32>`) 1 GiB. A map side also bounds the dispatch size:
//! `max_compute_workgroups_per_dimension` of 65 535 covers sides up to 524 280 texels.

use crate::device::compute::WORKGROUP;
use crate::error::GpuError;
use glam::UVec2;

/// Features used when present: timestamp queries for [`crate::GpuTimer`], adapter-specific
/// format features for the formats the adapter offers beyond WebGPU's.
pub const OPTIONAL_FEATURES: wgpu::Features = wgpu::Features::TIMESTAMP_QUERY
    .union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS)
    .union(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES);

/// Bytes per texel of the buffers of a map, by what the map is used for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapUse {
    /// Stamps, derivative normals and the clipmap: 16-bit heights (2 B) and two 8-bit slope
    /// codes (2 B).
    Coarse,
    /// Granular deformation: u32 heights (4 B) and `vec4<f32>` normals with float heights (16 B).
    Granular,
}

impl MapUse {
    /// Storage buffers one shader stage binds at most: 3 for the coarse passes (the stamp, the
    /// normals, the atlas lookup), 7 for the granular displacement pass.
    pub fn storage_buffers_per_stage(self) -> u32 {
        match self {
            MapUse::Coarse => 3,
            MapUse::Granular => 7,
        }
    }

    /// The largest per-texel buffer of this use, in bytes per texel.
    pub fn max_bytes_per_texel(self) -> u64 {
        match self {
            MapUse::Coarse => 2,
            MapUse::Granular => 16,
        }
    }
}

/// The limits a device needs for maps of `map_size` used as `usage`: `base` (e.g.
/// `wgpu::Limits::default()`, or an engine's own) with the storage binding, buffer size and
/// dispatch limits raised as far as the map needs. Fails for an empty map or one whose buffers
/// could not be addressed at all.
pub fn required_limits(
    map_size: UVec2,
    usage: MapUse,
    base: wgpu::Limits,
) -> Result<wgpu::Limits, GpuError> {
    if map_size.x == 0 || map_size.y == 0 {
        return Err(terrain_core::CoreError::EmptyGrid {
            width: map_size.x,
            height: map_size.y,
        }
        .into());
    }
    let (bytes, groups) = needs(map_size, usage);
    Ok(wgpu::Limits {
        max_storage_buffers_per_shader_stage: base
            .max_storage_buffers_per_shader_stage
            .max(usage.storage_buffers_per_stage()),
        max_storage_buffer_binding_size: base.max_storage_buffer_binding_size.max(bytes),
        max_buffer_size: base.max_buffer_size.max(bytes),
        max_compute_workgroups_per_dimension: base.max_compute_workgroups_per_dimension.max(groups),
        ..base
    })
}

/// Checks that a device (or adapter) with `limits` can hold maps of `map_size` used as `usage`,
/// naming the first limit that is too small.
pub fn check_limits(limits: &wgpu::Limits, map_size: UVec2, usage: MapUse) -> Result<(), GpuError> {
    if map_size.x == 0 || map_size.y == 0 {
        return Err(terrain_core::CoreError::EmptyGrid {
            width: map_size.x,
            height: map_size.y,
        }
        .into());
    }
    let (bytes, groups) = needs(map_size, usage);
    let limit = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    if bytes > limit {
        return Err(GpuError::MapTooLarge {
            size: map_size,
            bytes,
            limit,
        });
    }
    if groups > limits.max_compute_workgroups_per_dimension {
        return Err(terrain_core::CoreError::OutOfRange {
            what: "map side (compute workgroups per axis)",
            value: f64::from(groups),
            expected: "within the device's max_compute_workgroups_per_dimension",
        }
        .into());
    }
    if usage.storage_buffers_per_stage() > limits.max_storage_buffers_per_shader_stage {
        return Err(terrain_core::CoreError::OutOfRange {
            what: "storage buffers per shader stage",
            value: f64::from(usage.storage_buffers_per_stage()),
            expected: "within the device's max_storage_buffers_per_shader_stage",
        }
        .into());
    }
    Ok(())
}

/// The bytes of the largest per-texel buffer and the workgroups per axis of a map (the bytes
/// saturate: a map past 2^64 bytes needs more than any device has, which check_limits says).
fn needs(map_size: UVec2, usage: MapUse) -> (u64, u32) {
    let bytes =
        (u64::from(map_size.x) * u64::from(map_size.y)).saturating_mul(usage.max_bytes_per_texel());
    (bytes, map_size.max_element().div_ceil(WORKGROUP))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_8192_coarse_map_fits_the_default_binding_and_granular_needs_more() {
        let base = wgpu::Limits::default();
        let coarse = required_limits(UVec2::splat(8192), MapUse::Coarse, base.clone()).unwrap();
        assert_eq!(coarse.max_storage_buffer_binding_size, 8192 * 8192 * 2);
        assert!(check_limits(&base, UVec2::splat(8192), MapUse::Coarse).is_ok());
        let granular = required_limits(UVec2::splat(8192), MapUse::Granular, base.clone()).unwrap();
        assert_eq!(granular.max_storage_buffer_binding_size, 1 << 30);
        assert!(check_limits(&base, UVec2::splat(16_384), MapUse::Coarse).is_err());
        let big = required_limits(UVec2::splat(16_384), MapUse::Coarse, base.clone()).unwrap();
        assert!(check_limits(&big, UVec2::splat(16_384), MapUse::Coarse).is_ok());
        // A small map fits the smallest devices; granular needs 7 storage buffers a stage.
        let low = wgpu::Limits::downlevel_defaults();
        assert!(check_limits(&low, UVec2::splat(64), MapUse::Coarse).is_ok());
        assert!(check_limits(&low, UVec2::splat(64), MapUse::Granular).is_err());
        let raised = required_limits(UVec2::splat(64), MapUse::Granular, low).unwrap();
        assert!(check_limits(&raised, UVec2::splat(64), MapUse::Granular).is_ok());
    }

    #[test]
    fn small_maps_keep_the_base_limits_and_extremes_are_errors_not_panics() {
        let base = wgpu::Limits::default();
        let small = required_limits(UVec2::splat(256), MapUse::Coarse, base.clone()).unwrap();
        assert_eq!(small, base);
        assert!(required_limits(UVec2::new(0, 5), MapUse::Coarse, base.clone()).is_err());
        let huge = required_limits(UVec2::splat(u32::MAX), MapUse::Granular, base.clone()).unwrap();
        assert!(check_limits(&base, UVec2::splat(u32::MAX), MapUse::Granular).is_err());
        assert!(huge.max_compute_workgroups_per_dimension > 65_535);
    }
}
