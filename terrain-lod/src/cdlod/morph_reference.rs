//! The CPU reference of `cdlod.wgsl`'s vertex shader ([`morphed_vertex`]) and what the
//! tests measure with it: the drawn surface's height at a point and the largest jump of the
//! surface between two frames' selections.

use super::{CdlodFrame, CdlodInstance, LodRanges};
use glam::{IVec2, Mat4, Vec2, Vec3};

/// Where the vertex at grid position `grid` of `instance` is drawn: its texel position
/// (fractional once morphed) and height, with the camera at `camera` (metres) and heights from
/// `height(texel)` (metres at an integer texel; bilinear in between). The CPU reference of
/// `cdlod.wgsl`'s vertex shader.
pub fn morphed_vertex(
    instance: &CdlodInstance,
    grid: Vec2,
    camera: Vec3,
    ranges: &LodRanges,
    texel_size: f32,
    height: impl Fn(IVec2) -> f32,
) -> (Vec2, f32) {
    let origin = IVec2::from(instance.origin);
    let step = instance.step as i32;
    let texel = origin + grid.as_ivec2() * step;
    let h = height(texel);
    let pos = Vec3::new(texel.x as f32 * texel_size, h, texel.y as f32 * texel_size);
    let k = ranges.morph_k(instance.lod, pos.distance(camera));
    // Odd grid positions (within the node: quadrant origins are on even lines) move down.
    let odd = Vec2::new((grid.x as i32 & 1) as f32, (grid.y as i32 & 1) as f32);
    let t = texel.as_vec2() - odd * k * step as f32;
    let t0 = t.floor();
    let f = t - t0;
    let i = t0.as_ivec2();
    let h00 = height(i);
    let h10 = height(i + IVec2::new(1, 0));
    let h01 = height(i + IVec2::new(0, 1));
    let h11 = height(i + IVec2::new(1, 1));
    let morphed = if f == Vec2::ZERO {
        h00
    } else {
        let a = h00 + (h10 - h00) * f.x;
        let b = h01 + (h11 - h01) * f.x;
        a + (b - a) * f.y
    };
    (t, morphed)
}

/// Where [`CdlodFrame::max_height_jump`] measures and how it projects: the probes (texel
/// positions, unwrapped as the instances), and today's camera, `view_proj` from world metres
/// to clip space onto a render target of `target` pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JumpProbes<'a> {
    /// Texel positions where the surface is compared.
    pub probes: &'a [Vec2],
    /// World metres to clip space (wgpu's, y up).
    pub view_proj: Mat4,
    /// The render target's size in pixels.
    pub target: Vec2,
}

impl CdlodFrame {
    /// The height of the drawn (morphed) surface over texel position `p` (unwrapped, as the
    /// instances), or `None` where no instance is drawn. With `height(texel)` the map's heights
    /// and `camera` the position the frame's morph was computed for, this is what the vertex
    /// shader's triangles show at `p`: the CPU side of the popping metric
    /// ([`CdlodFrame::max_height_jump`]).
    pub fn surface_height(
        &self,
        p: Vec2,
        grid_size: u32,
        camera: Vec3,
        texel_size: f32,
        height: impl Fn(IVec2) -> f32,
    ) -> Option<f32> {
        let half = (grid_size / 2).max(1) as i32;
        let inst = self.instances.iter().find(|i| {
            let o = IVec2::from(i.origin).as_vec2();
            let side = (half * i.step as i32) as f32;
            p.cmpge(o).all() && p.cmple(o + side).all()
        })?;
        let o = IVec2::from(inst.origin).as_vec2();
        let step = inst.step as f32;
        let cell = ((p - o) / step)
            .floor()
            .as_ivec2()
            .clamp(IVec2::ZERO, IVec2::splat(half - 1));
        let vertex = |g: IVec2| {
            let (t, h) =
                morphed_vertex(inst, g.as_vec2(), camera, &self.ranges, texel_size, &height);
            (t, h)
        };
        // A morphed vertex moves at most one grid step: the triangle under `p` is in the cells
        // around the one it lies in.
        for dy in -1..=1 {
            for dx in -1..=1 {
                let c = cell + IVec2::new(dx, dy);
                if c.cmplt(IVec2::ZERO).any() || c.cmpge(IVec2::splat(half)).any() {
                    continue;
                }
                let v00 = vertex(c);
                let v10 = vertex(c + IVec2::new(1, 0));
                let v01 = vertex(c + IVec2::new(0, 1));
                let v11 = vertex(c + IVec2::new(1, 1));
                for tri in [[v00, v11, v10], [v00, v01, v11]] {
                    if let Some(h) = triangle_height(p, tri) {
                        return Some(h);
                    }
                }
            }
        }
        None
    }

    /// The popping metric: the largest screen-space jump, in pixels, of the surface between
    /// `previous` (its frame, camera) and this frame at the `probes`, both evaluated on today's
    /// heights and projected with today's camera (see [`JumpProbes`]), so neither the camera's
    /// motion nor a deformation counts: only a change of the mesh does.
    pub fn max_height_jump(
        &self,
        camera: Vec3,
        previous: (&CdlodFrame, Vec3),
        probes: &JumpProbes<'_>,
        grid_size: u32,
        texel_size: f32,
        height: impl Fn(IVec2) -> f32,
    ) -> f32 {
        let JumpProbes {
            probes,
            view_proj,
            target,
        } = *probes;
        let project = |p: Vec3| {
            let c = view_proj * p.extend(1.0);
            (c.w > 1e-6).then(|| (Vec2::new(c.x, -c.y) / c.w * 0.5 + 0.5) * target)
        };
        let mut max = 0.0f32;
        for &p in probes {
            let now = self.surface_height(p, grid_size, camera, texel_size, &height);
            let then = previous
                .0
                .surface_height(p, grid_size, previous.1, texel_size, &height);
            let (Some(a), Some(b)) = (now, then) else {
                continue;
            };
            let world = |h: f32| Vec3::new(p.x * texel_size, h, p.y * texel_size);
            if let (Some(pa), Some(pb)) = (project(world(a)), project(world(b))) {
                max = max.max(pa.distance(pb));
            }
        }
        max
    }
}

/// The height at `p` of the triangle of (texel position, height) corners, if `p` lies in it
/// (a degenerate triangle holds nothing).
fn triangle_height(p: Vec2, tri: [(Vec2, f32); 3]) -> Option<f32> {
    let [(a, ha), (b, hb), (c, hc)] = tri;
    let area = (b - a).perp_dot(c - a);
    if area.abs() < 1e-9 {
        return None;
    }
    let w0 = (b - p).perp_dot(c - p) / area;
    let w1 = (c - p).perp_dot(a - p) / area;
    let w2 = 1.0 - w0 - w1;
    let eps = -1e-5;
    (w0 >= eps && w1 >= eps && w2 >= eps).then_some(w0 * ha + w1 * hb + w2 * hc)
}
