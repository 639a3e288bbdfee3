//! LOD configuration chosen for a map and a view distance: how many clipmap levels reach a
//! radius, and the CDLOD quadtree (leaf size, LOD count, finest range) that covers a map and
//! draws as far. What every engine drawing a map of its own size would otherwise work out.

use crate::cdlod::{CdlodConfig, MAX_CDLOD_LODS};
use crate::clipmap::MAX_LEVELS;
use crate::error::LodError;
use glam::UVec2;
use terrain_core::WrapMode;

/// The clipmap levels (at least `min_levels`, at most [`MAX_LEVELS`]) whose coarsest reaches
/// `radius_m` metres from the camera with `n` vertices per level side at `texel_size` metres:
/// level `l` spans `(n - 1) * 2^l` texels, so its half side is `(n - 1) / 2 * 2^l` texels.
/// Bounded for every input: a radius beyond what [`MAX_LEVELS`] reach (or NaN) gives
/// [`MAX_LEVELS`]; `min_levels` is clamped to `1..=MAX_LEVELS`.
pub fn clipmap_levels_to_reach(n: u32, radius_m: f32, texel_size: f32, min_levels: u32) -> u32 {
    let half = n.saturating_sub(1) as f32 / 2.0 * texel_size;
    let mut levels = min_levels.clamp(1, MAX_LEVELS);
    while levels < MAX_LEVELS
        && (radius_m.is_nan() || half * ((1u32 << (levels - 1)) as f32) < radius_m)
    {
        levels += 1;
    }
    levels
}

impl CdlodConfig {
    /// The quadtree for a map of `size` texels at `texel_size` metres that draws `reach_m`
    /// metres from the camera: leaves of 32 texels (16, 8 or 4 where a repeating map's sides
    /// are not multiples of 32) drawn with one vertex per texel, the finest range 8 leaves wide,
    /// and as many LODs (up to 8) as tile a repeating map (its root must divide the map) or
    /// cover a clamped one, fewer where the ranges would reach beyond `reach_m`. Every other
    /// field is the default (distance metric, morph on).
    ///
    /// Fails on a repeating map whose sides are not multiples of 4 texels, and on a texel size
    /// or reach that is not finite and positive.
    pub fn for_map(
        size: UVec2,
        wrap: WrapMode,
        texel_size: f32,
        reach_m: f32,
    ) -> Result<CdlodConfig, LodError> {
        let bad = |what: &'static str, value: f32| LodError::InvalidCdlodParam {
            what,
            value: value.into(),
            allowed: "a finite number of metres above 0",
        };
        if !(texel_size.is_finite() && texel_size > 0.0) {
            return Err(bad("texel_size", texel_size));
        }
        if !(reach_m.is_finite() && reach_m > 0.0) {
            return Err(bad("reach_m", reach_m));
        }
        const MAX_LODS: u32 = 8;
        let lods_for = |leaf: u32| -> u32 {
            match wrap {
                WrapMode::Repeat => (1..=MAX_LODS)
                    .rev()
                    .find(|&n| {
                        let root = leaf << (n - 1);
                        size.x.is_multiple_of(root) && size.y.is_multiple_of(root)
                    })
                    .unwrap_or(0),
                WrapMode::Clamp => (1..=MAX_LODS)
                    .find(|&n| (leaf << (n - 1)) >= size.max_element())
                    .unwrap_or(MAX_LODS),
            }
        };
        let Some((leaf, mut lods)) = [32u32, 16, 8, 4]
            .into_iter()
            .map(|leaf| (leaf, lods_for(leaf)))
            .find(|&(_, n)| n >= 1)
        else {
            return Err(LodError::InvalidCdlodParam {
                what: "map side (texels)",
                value: f64::from(size.min_element()),
                allowed: "a repeating map's sides must be multiples of 4 texels",
            });
        };
        let finest_range = 8.0 * leaf as f32 * texel_size;
        // The view distance (the last range) is finest_range * 2^(lods - 1).
        while lods > 1 && finest_range * (1u32 << (lods - 2)) as f32 >= reach_m {
            lods -= 1;
        }
        debug_assert!(lods <= MAX_CDLOD_LODS);
        let config = CdlodConfig {
            leaf_size: leaf,
            grid_size: leaf.min(32),
            lod_count: lods,
            finest_range,
            ..CdlodConfig::default()
        };
        config.validate()?;
        Ok(config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipmap_levels_grow_until_the_coarsest_reaches_the_radius() {
        // N = 255 at 0.1 m: level l's half side is 12.7 * 2^l m.
        assert_eq!(clipmap_levels_to_reach(255, 10.0, 0.1, 5), 5);
        assert_eq!(clipmap_levels_to_reach(255, 203.2, 0.1, 5), 5);
        assert_eq!(clipmap_levels_to_reach(255, 203.3, 0.1, 5), 6);
        assert_eq!(clipmap_levels_to_reach(255, 1000.0, 0.1, 1), 8);
        for r in [f32::MAX, f32::INFINITY, f32::NAN] {
            assert_eq!(clipmap_levels_to_reach(255, r, 0.1, 5), MAX_LEVELS);
        }
        assert_eq!(clipmap_levels_to_reach(255, 1.0, 0.1, 0), 1);
        assert_eq!(clipmap_levels_to_reach(255, 1.0, 0.1, 99), MAX_LEVELS);
    }

    #[test]
    fn cdlod_tiles_a_repeating_map_and_covers_a_clamped_one() {
        // 2048^2 repeating: 32-texel leaves, root 32 * 2^(n-1) divides 2048 up to n = 7, then
        // LODs drop while the second-to-last range already reaches 400 m.
        let c = CdlodConfig::for_map(UVec2::splat(2048), WrapMode::Repeat, 0.1, 400.0).unwrap();
        assert_eq!((c.leaf_size, c.grid_size), (32, 32));
        assert_eq!(c.finest_range, 25.6);
        let reach = |c: &CdlodConfig| c.finest_range * (1u32 << (c.lod_count - 1)) as f32;
        assert!(reach(&c) >= 400.0 && reach(&c) / 2.0 < 400.0, "{c:?}");
        let root = c.leaf_size << (c.lod_count - 1);
        assert!(2048 % root == 0);
        // 96 x 80 repeating: 16-texel leaves (96 and 80 are not multiples of 32).
        let c = CdlodConfig::for_map(UVec2::new(96, 80), WrapMode::Repeat, 1.0, 1e6).unwrap();
        assert_eq!((c.leaf_size, c.lod_count), (16, 1));
        // A clamped map is covered by the root.
        let c = CdlodConfig::for_map(UVec2::new(1000, 300), WrapMode::Clamp, 1.0, 1e6).unwrap();
        assert!(c.leaf_size << (c.lod_count - 1) >= 1000, "{c:?}");
        // A far reach never asks for more than 8 LODs; a huge clamped map stops there.
        let c = CdlodConfig::for_map(UVec2::splat(1 << 20), WrapMode::Clamp, 1.0, 1e9).unwrap();
        assert_eq!(c.lod_count, 8);
    }

    #[test]
    fn cdlod_refuses_what_it_cannot_tile_and_bad_numbers() {
        assert!(CdlodConfig::for_map(UVec2::new(98, 64), WrapMode::Repeat, 1.0, 100.0).is_err());
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert!(CdlodConfig::for_map(UVec2::splat(64), WrapMode::Repeat, bad, 100.0).is_err());
            assert!(CdlodConfig::for_map(UVec2::splat(64), WrapMode::Repeat, 1.0, bad).is_err());
        }
        // The largest finite texel size: the finest range overflows f32 and is refused.
        assert!(CdlodConfig::for_map(UVec2::splat(64), WrapMode::Clamp, f32::MAX, 1.0).is_err());
    }
}
