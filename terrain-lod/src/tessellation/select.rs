//! A frame of a [`TessHierarchy`]: the decision inputs for a view, the split test of each
//! triangle (the CPU reference of `terrain-gpu`'s compute pass), the triangles emitted by
//! refining every visible patch, and what the tests measure on them (the drawn surface's
//! height, its screen-space error, the popping between two frames).

use super::{
    FLAT_SPHERE, FORCED_RATIO, NEAR_M, TessDecision, TessFrame, TessHierarchy, TessTriangle,
    TessVertex, split_threshold,
};
use crate::cdlod::CdlodView;
use crate::error::LodError;
use glam::{IVec2, Vec2, Vec3};

/// A triangle of the hierarchy while it is refined: right-angle apex `a`, hypotenuse from `l`
/// to `r` (`(l, r, a)` counter-clockwise seen from above), their drawn heights, its level.
#[derive(Debug, Clone, Copy)]
pub(super) struct Tri {
    pub(super) a: IVec2,
    pub(super) l: IVec2,
    pub(super) r: IVec2,
    pub(super) ha: f32,
    pub(super) hl: f32,
    pub(super) hr: f32,
    pub(super) level: u32,
}

impl Tri {
    /// The two children: apex at the hypotenuse's midpoint `v` (drawn at `hv`).
    pub(super) fn children(&self, v: IVec2, hv: f32) -> [Tri; 2] {
        let level = self.level + 1;
        [
            Tri {
                a: v,
                l: self.a,
                r: self.l,
                ha: hv,
                hl: self.ha,
                hr: self.hl,
                level,
            },
            Tri {
                a: v,
                l: self.r,
                r: self.a,
                ha: hv,
                hl: self.hr,
                hr: self.ha,
                level,
            },
        ]
    }

    pub(super) fn emit(&self) -> TessTriangle {
        let v = |p: IVec2, h: f32| TessVertex {
            texel: [p.x as f32, p.y as f32],
            height: h,
        };
        [v(self.l, self.hl), v(self.r, self.hr), v(self.a, self.ha)]
    }
}

impl TessHierarchy {
    /// The frame's decision inputs for `view` (with this hierarchy's config).
    pub fn decision(&self, view: &CdlodView<'_>) -> Result<TessDecision, LodError> {
        decision_for(&self.config, self.p, self.texel_size, view)
    }

    /// The split ratio `r` of vertex `v` (split in when > 1). Mirrors `tessellate.wgsl`.
    pub fn ratio(&self, d: &TessDecision, v: IVec2) -> f32 {
        let i = self.index(v);
        let [r, density, error] = self.bounds[i];
        let ts = self.texel_size;
        let c = Vec3::new(
            v.x as f32 * ts - d.camera.x,
            self.heights[i] - d.camera.y,
            v.y as f32 * ts - d.camera.z,
        );
        let dist = (c.length() - r).max(NEAR_M);
        if d.error_metric {
            return d.scale * error / dist;
        }
        let dens = if d.use_density { density } else { 1.0 };
        d.scale * r * dens / dist
    }

    /// Whether `t` splits, and if so the drawn height of its new vertex.
    fn split(&self, d: &TessDecision, t: &Tri) -> Option<(IVec2, f32)> {
        if t.level >= d.split_levels {
            return None;
        }
        let v = (t.l + t.r) / 2;
        let r = if d.forces(v, t.level, self.config.patch_size) {
            FORCED_RATIO
        } else {
            self.ratio(d, v)
        };
        let threshold = split_threshold(t.level);
        // NaN splits nothing, as on the GPU (`r > threshold` there).
        if r.is_nan() || r <= threshold {
            return None;
        }
        let h = self.heights[self.index(v)];
        let k = if d.inv_morph_range > 0.0 {
            ((r - threshold) * d.inv_morph_range).min(1.0)
        } else {
            1.0
        };
        let mid = 0.5 * (t.hl + t.hr);
        Some((v, mid + (h - mid) * k))
    }

    /// The two level-0 triangles of patch `(px, py)`.
    fn base(&self, px: i32, py: i32) -> [Tri; 2] {
        base_triangles(self.config.patch_size, px, py, |p| {
            self.heights[self.index(p)]
        })
    }

    /// Whether `t` (of patch `patch`) may be seen.
    fn visible(&self, view: &CdlodView<'_>, t: &Tri, patch: usize) -> bool {
        let Some(frustum) = view.frustum else {
            return true;
        };
        let ts = self.texel_size;
        let lo = t.a.min(t.l).min(t.r).as_vec2() * ts;
        let hi = t.a.max(t.l).max(t.r).as_vec2() * ts;
        let [hmin, hmax] = self.patch_bounds[patch];
        frustum.intersects_aabb(Vec3::new(lo.x, hmin, lo.y), Vec3::new(hi.x, hmax, hi.y))
    }

    /// The triangles of one frame for `view`: every patch's two triangles, split depth first
    /// while their edges ask for it, dropped where the frustum misses them.
    ///
    /// Fails on a non-finite camera or field of view, or when more than
    /// [`TessConfig::max_triangles`](super::TessConfig::max_triangles) would be emitted.
    pub fn select(&self, view: &CdlodView<'_>) -> Result<TessFrame, LodError> {
        self.select_with(view, None)
    }

    /// As [`TessHierarchy::select`], with the texels from the first to the last corner of
    /// `full_resolution` (both included) drawn at full resolution whatever the view asks (see
    /// [`TessDecision::full_resolution`]).
    pub fn select_with(
        &self,
        view: &CdlodView<'_>,
        full_resolution: Option<(IVec2, IVec2)>,
    ) -> Result<TessFrame, LodError> {
        let d = TessDecision {
            full_resolution,
            ..self.decision(view)?
        };
        let limit = self.config.max_triangles;
        let emitted = std::sync::atomic::AtomicUsize::new(0);
        let rows: Vec<u32> = (0..self.patches.y).collect();
        let per_row = crate::par::map_collect(&rows, |&py| {
            let mut tris = Vec::new();
            let mut culled = 0u32;
            let mut stack = Vec::with_capacity(2 * self.p as usize + 2);
            for px in 0..self.patches.x as i32 {
                let patch = py as usize * self.patches.x as usize + px as usize;
                let before = tris.len();
                for base in self.base(px, py as i32) {
                    stack.push(base);
                    while let Some(t) = stack.pop() {
                        if !self.visible(view, &t, patch) {
                            culled += 1;
                            continue;
                        }
                        match self.split(&d, &t) {
                            Some((v, hv)) => {
                                let [c0, c1] = t.children(v, hv);
                                stack.push(c1);
                                stack.push(c0);
                            }
                            None => {
                                tris.push(t.emit());
                                // A patch alone may hold 2 P^2 triangles: stop early.
                                let mine = tris.len() - before;
                                if mine % 1024 == 0
                                    && emitted.load(std::sync::atomic::Ordering::Relaxed) + mine
                                        > limit
                                {
                                    return None;
                                }
                            }
                        }
                    }
                }
                // Counted per patch: at most one patch per thread beyond the bound is held.
                let added = tris.len() - before;
                let total = emitted.fetch_add(added, std::sync::atomic::Ordering::Relaxed) + added;
                if total > limit {
                    return None;
                }
            }
            Some((tris, culled))
        });
        let mut frame = TessFrame::default();
        let mut rows = Vec::with_capacity(per_row.len());
        for row in per_row {
            let Some(row) = row else {
                return Err(LodError::SelectionTooLarge { limit });
            };
            rows.push(row);
        }
        frame
            .triangles
            .reserve_exact(rows.iter().map(|(t, _)| t.len()).sum());
        for (tris, culled) in rows {
            frame.triangles.extend_from_slice(&tris);
            frame.culled += culled;
        }
        if frame.triangles.len() > limit {
            return Err(LodError::SelectionTooLarge { limit });
        }
        Ok(frame)
    }

    /// The drawn height over texel position `p` for a frame decided for `view` (culling
    /// aside), or `None` off the patches: descends from the patch's triangle under `p`
    /// through the children under it. The CPU side of the popping metric.
    pub fn surface_height(&self, view: &CdlodView<'_>, p: Vec2) -> Option<f32> {
        let d = self.decision(view).ok()?;
        let ps = self.config.patch_size as f32;
        let patch = (p / ps).floor();
        if !(p.is_finite()
            && patch.cmpge(Vec2::ZERO).all()
            && patch.cmplt(self.patches.as_vec2()).all())
        {
            return None;
        }
        let (px, py) = (patch.x as i32, patch.y as i32);
        let mut t = self
            .base(px, py)
            .into_iter()
            .find(|t| contains(t, p))
            .unwrap_or(self.base(px, py)[0]);
        while let Some((v, hv)) = self.split(&d, &t) {
            let [c0, c1] = t.children(v, hv);
            t = if contains(&c0, p) { c0 } else { c1 };
        }
        let bary = barycentric(&t, p)?;
        Some(bary[0] * t.hl + bary[1] * t.hr + bary[2] * t.ha)
    }

    /// The largest projected height error of `frame`'s drawn triangles against the map, in
    /// pixels: at every texel inside every triangle, `K * |h_map - h_drawn| / distance`.
    pub fn max_screen_error_px(&self, frame: &TessFrame, view: &CdlodView<'_>) -> f32 {
        let k = view.k();
        let ts = self.texel_size;
        let chunks: Vec<&[TessTriangle]> = frame.triangles.chunks(1024).collect();
        crate::par::map_collect(&chunks, |chunk| {
            let mut max = 0.0f32;
            for tri in chunk.iter() {
                let p: [Vec2; 3] = tri.map(|v| Vec2::from(v.texel));
                let lo = p[0].min(p[1]).min(p[2]).as_ivec2();
                let hi = p[0].max(p[1]).max(p[2]).as_ivec2();
                let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
                if area == 0.0 {
                    continue;
                }
                for y in lo.y..=hi.y {
                    for x in lo.x..=hi.x {
                        let q = IVec2::new(x, y).as_vec2();
                        let w0 = (p[1] - q).perp_dot(p[2] - q) / area;
                        let w1 = (p[2] - q).perp_dot(p[0] - q) / area;
                        let w2 = 1.0 - w0 - w1;
                        if w0 < -1e-6 || w1 < -1e-6 || w2 < -1e-6 {
                            continue;
                        }
                        let drawn = w0 * tri[0].height + w1 * tri[1].height + w2 * tri[2].height;
                        let truth = self.heights[self.index(IVec2::new(x, y))];
                        let world = Vec3::new(x as f32 * ts, truth, y as f32 * ts);
                        let dist = world.distance(view.camera).max(NEAR_M);
                        max = max.max(k * (truth - drawn).abs() / dist);
                    }
                }
            }
            max
        })
        .into_iter()
        .fold(0.0, f32::max)
    }

    /// The popping metric: the largest screen-space jump, in pixels, of the drawn surface
    /// between a frame decided for `previous` and one for `view` at `probes` (texel positions),
    /// both on today's heights and projected with today's `view_proj` (world metres) onto a
    /// target `target` pixels, so only a change of the mesh counts. Probes off screen (either
    /// height outside the clip volume) do not count.
    pub fn max_height_jump(
        &self,
        view: &CdlodView<'_>,
        previous: &CdlodView<'_>,
        probes: &[Vec2],
        view_proj: glam::Mat4,
        target: Vec2,
    ) -> f32 {
        // Only what is on screen counts (a point beside the camera projects anywhere).
        let project = |p: Vec3| {
            let c = view_proj * p.extend(1.0);
            let on_screen = c.w > 1e-6 && c.x.abs() <= c.w && c.y.abs() <= c.w && c.z >= 0.0;
            on_screen.then(|| (Vec2::new(c.x, -c.y) / c.w * 0.5 + 0.5) * target)
        };
        let ts = self.texel_size;
        let mut max = 0.0f32;
        for &p in probes {
            let (Some(a), Some(b)) = (
                self.surface_height(view, p),
                self.surface_height(previous, p),
            ) else {
                continue;
            };
            let world = |h: f32| Vec3::new(p.x * ts, h, p.y * ts);
            if let (Some(pa), Some(pb)) = (project(world(a)), project(world(b))) {
                max = max.max(pa.distance(pb));
            }
        }
        max
    }
}

/// The frame's decision inputs for `view`, for patches of `2^p` texels of `texel_size` metres.
pub(super) fn decision_for(
    c: &super::TessConfig,
    p: u32,
    texel_size: f32,
    view: &CdlodView<'_>,
) -> Result<TessDecision, LodError> {
    for (what, value) in [
        ("camera.x", view.camera.x),
        ("camera.y", view.camera.y),
        ("camera.z", view.camera.z),
        ("viewport_width", view.viewport_width),
        ("hfov", view.hfov),
    ] {
        if !value.is_finite() {
            return Err(LodError::NonFinite { what, value });
        }
    }
    let k = view.k();
    if !(k.is_finite() && k > 0.0) {
        return Err(LodError::InvalidTessParam {
            what: "hfov",
            value: view.hfov.into(),
            allowed: "a field of view in (0, pi) and a positive viewport width",
        });
    }
    // Split only while the children's hypotenuse (P sqrt(2)^-l texels at level l + 1) is
    // at least the minimum size.
    let mut split_levels = 2 * p;
    while split_levels > 0 {
        let child_hyp = c.patch_size as f32
            * texel_size
            * std::f32::consts::FRAC_1_SQRT_2.powi(split_levels as i32 - 1);
        if child_hyp >= c.min_triangle_m {
            break;
        }
        split_levels -= 1;
    }
    Ok(TessDecision {
        camera: view.camera,
        scale: match c.max_error_px {
            Some(tau) => k / tau,
            None => k / (FLAT_SPHERE * c.triangle_width_px),
        },
        error_metric: c.max_error_px.is_some(),
        split_levels,
        use_density: c.use_density,
        inv_morph_range: if c.morph { 1.0 / c.morph_range } else { 0.0 },
        full_resolution: None,
    })
}

/// The two level-0 triangles of patch `(px, py)` of `ps` texels, with the heights `h` gives
/// their corners: the patch's diagonal alternates in a checkerboard, so the patches' triangles
/// meet edge to edge (a 4-8 mesh).
pub(super) fn base_triangles(ps: u32, px: i32, py: i32, h: impl Fn(IVec2) -> f32) -> [Tri; 2] {
    let ps = ps as i32;
    let o = IVec2::new(px * ps, py * ps);
    let c00 = o;
    let c10 = o + IVec2::new(ps, 0);
    let c01 = o + IVec2::new(0, ps);
    let c11 = o + IVec2::splat(ps);
    let (e, apexes) = if (px + py) & 1 == 0 {
        ([c00, c11], [c10, c01])
    } else {
        ([c10, c01], [c00, c11])
    };
    apexes.map(|a| {
        // Counter-clockwise seen from above: (r - l) x (a - l) < 0 in (x, z).
        let (l, r) = if (e[1] - e[0]).perp_dot(a - e[0]) < 0 {
            (e[0], e[1])
        } else {
            (e[1], e[0])
        };
        Tri {
            a,
            l,
            r,
            ha: h(a),
            hl: h(l),
            hr: h(r),
            level: 0,
        }
    })
}

/// Barycentric weights of `p` for `(l, r, a)`, if `p` lies in `t` (with a small tolerance).
pub(super) fn barycentric(t: &Tri, p: Vec2) -> Option<[f32; 3]> {
    let (l, r, a) = (t.l.as_vec2(), t.r.as_vec2(), t.a.as_vec2());
    let area = (r - l).perp_dot(a - l);
    if area == 0.0 {
        return None;
    }
    let w0 = (r - p).perp_dot(a - p) / area;
    let w1 = (a - p).perp_dot(l - p) / area;
    let w2 = 1.0 - w0 - w1;
    let eps = -1e-4;
    (w0 >= eps && w1 >= eps && w2 >= eps).then_some([w0, w1, w2])
}

pub(super) fn contains(t: &Tri, p: Vec2) -> bool {
    barycentric(t, p).is_some()
}
