//! The popping probe of CDLOD (Strugar's per-vertex morph exists to remove popping; this
//! measures what is left): the largest screen-space jump of the drawn surface between two
//! consecutive frames' selections, at a grid of probes ahead of the camera, both frames
//! evaluated on the same heights and projected with the same camera, so only a change of the
//! mesh counts. What a renderer reports as its popping metric.

use crate::cdlod::{CdlodFrame, CdlodTree, JumpProbes};
use glam::{IVec2, Mat4, Vec2, Vec3};
use terrain_core::{HeightMap, HeightSample};

/// Probes per side of the grid [`CdlodTree::popping_px`] samples (48 x 48).
pub const POPPING_PROBES_PER_SIDE: u32 = 48;

/// The camera a popping probe projects with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoppingView {
    /// Where the camera looks (any length; only its horizontal part places the probes).
    pub forward: Vec3,
    /// World metres to clip space (wgpu's, y up).
    pub view_proj: Mat4,
    /// The render target's size in pixels.
    pub target: Vec2,
}

impl CdlodTree {
    /// The popping metric of `now` against `then` (each a selection of this tree with the
    /// camera it was made for), pixels: the largest jump of the surface at a
    /// [`POPPING_PROBES_PER_SIDE`]^2 grid ahead of `now`'s camera, as deep as the second LOD's
    /// range (so the probes see the first LOD switches and morphs), evaluated on `map` and
    /// projected with `view`. 0 for two identical selections; bounded by the probe count for
    /// every finite input.
    pub fn popping_px<T: HeightSample>(
        &self,
        map: &HeightMap<T>,
        now: (&CdlodFrame, Vec3),
        then: (&CdlodFrame, Vec3),
        view: &PoppingView,
    ) -> f32 {
        let ts = map.texel_size();
        let (frame, eye) = now;
        let forward = Vec2::new(view.forward.x, view.forward.z).normalize_or(Vec2::X);
        let right = forward.perp();
        let depth = frame
            .ranges
            .range
            .get(1)
            .or(frame.ranges.range.first())
            .copied()
            .filter(|d| d.is_finite())
            .unwrap_or(1.0);
        let n = POPPING_PROBES_PER_SIDE;
        let spacing = (depth / n as f32).max(ts * 0.5);
        let base = Vec2::new(eye.x, eye.z);
        let probes: Vec<Vec2> = (0..n * n)
            .map(|k| {
                let (i, j) = ((k / n) as f32, (k % n) as f32 - (n / 2) as f32);
                (base + forward * (1.0 + i) * spacing + right * j * spacing) / ts
            })
            .collect();
        let (w, h) = (map.size().x, map.size().y);
        let height = |t: IVec2| {
            let x = map.wrap().resolve(i64::from(t.x), w);
            let y = map.wrap().resolve(i64::from(t.y), h);
            map.height_m(x, y).unwrap_or(0.0)
        };
        let probes = JumpProbes {
            probes: &probes,
            view_proj: view.view_proj,
            target: view.target,
        };
        frame.max_height_jump(eye, then, &probes, self.config().grid_size, ts, height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdlod::{CdlodConfig, CdlodView};
    use terrain_core::{Grid, HeightEncoding, WrapMode};

    fn setup() -> (HeightMap<u16>, CdlodTree) {
        let g = Grid::from_fn(256, 256, |x, y| ((x * 37 + y * 91) % 3000 + 20_000) as u16).unwrap();
        let map = HeightMap::new(
            g,
            HeightEncoding::new(0.001, 0.0).unwrap(),
            0.5,
            WrapMode::Repeat,
        )
        .unwrap();
        let config = CdlodConfig::for_map(map.size(), map.wrap(), 0.5, 200.0).unwrap();
        let tree = CdlodTree::from_map(&map, config).unwrap();
        (map, tree)
    }

    fn select(tree: &CdlodTree, eye: Vec3) -> crate::cdlod::CdlodFrame {
        tree.select(&CdlodView {
            camera: eye,
            frustum: None,
            viewport_width: 640.0,
            hfov: 1.2,
        })
        .unwrap()
    }

    #[test]
    fn the_same_selection_does_not_pop_and_a_jump_of_lods_does() {
        let (map, tree) = setup();
        let eye = Vec3::new(30.0, 25.0, 40.0);
        let look = Vec3::new(1.0, -0.3, 0.2);
        let view = PoppingView {
            forward: look,
            view_proj: glam::camera::rh::proj::directx::perspective(0.9, 16.0 / 9.0, 0.1, 1e5)
                * glam::camera::rh::view::look_to_mat4(eye, look.normalize(), Vec3::Y),
            target: Vec2::new(640.0, 360.0),
        };
        let a = select(&tree, eye);
        assert_eq!(tree.popping_px(&map, (&a, eye), (&a, eye), &view), 0.0);
        // The previous frame's camera far away: coarser LODs drawn where the probes are.
        let far = Vec3::new(100.0, 25.0, 100.0);
        let b = select(&tree, far);
        let jump = tree.popping_px(&map, (&a, eye), (&b, far), &view);
        assert!(jump > 0.0 && jump.is_finite(), "{jump}");
        // Any finite camera answers (a huge forward, a camera far off the map).
        let odd = PoppingView {
            forward: Vec3::splat(f32::MAX),
            ..view
        };
        let eye_far = Vec3::new(-3e37, 1e30, 3e37);
        assert!(
            tree.popping_px(&map, (&a, eye_far), (&a, eye), &odd)
                .is_finite()
        );
    }
}
