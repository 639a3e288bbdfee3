// The fragment hook of a coarse-map with a detail layer (detail_tiles.wgsl): parallax occlusion
// mapping of the detail heights on the coarse grid, and the detail's height and gradient at the
// point the march finds, faded out with distance so there is no edge where the detail ends.

struct FragmentDetail {
    sample: DetailSample,
    // Where to shade, in texels relative to the camera's whole texel.
    q: vec2<f32>,
}

fn detail_height_q(q: vec2<f32>) -> f32 {
    let pt = detail_point(q);
    return detail_height(pt.b, pt.f);
}

// `q`: the fragment in texels relative to the camera's whole texel; `world`: the fragment
// relative to the camera, in metres; `view_dist`: its length.
fn fragment_detail(q: vec2<f32>, world: vec3<f32>, view_dist: f32) -> FragmentDetail {
    let w = detail_fade(view_dist);
    if w <= 0.0 {
        return FragmentDetail(DetailSample(0.0, vec2<f32>(0.0, 0.0)), q);
    }
    var hit = q;
    let v = world / max(view_dist, 1e-6);
    if detail.parallax_steps > 0u && v.y < -1e-4 {
        // The view ray near the fragment, by its height r above the coarse surface (taken as
        // the fragment's level plane): position(r) = q + per_m * r, in texels.
        var per_m = v.xz / (v.y * frame.texel_size);
        // A grazing ray would travel far for 1 m of descent; its reach is capped.
        let top = w * (detail.offset + detail.scale * 255.0);
        let bottom = w * detail.offset;
        let reach = length(per_m) * (top - bottom);
        if reach > detail.max_reach {
            per_m = per_m * (detail.max_reach / reach);
        }
        // Most of the ground has no detail: no march over zero tiles.
        if detail_box_is_zero(q + per_m * top, q + per_m * bottom) {
            return FragmentDetail(DetailSample(0.0, vec2<f32>(0.0, 0.0)), q);
        }
        // Linear search from the top of the detail range down, then the crossing of the last
        // step interpolated linearly (Flower 2010, sec. 3.2.4's parallax, as a march).
        let steps = detail.parallax_steps;
        let dr = (top - bottom) / f32(steps);
        var r_prev = top;
        var gap_prev = top - w * detail_height_q(q + per_m * top);
        var r_hit = bottom;
        for (var i = 1u; i <= steps; i = i + 1u) {
            let r = top - dr * f32(i);
            let gap = r - w * detail_height_q(q + per_m * r);
            if gap <= 0.0 {
                let t = gap_prev / max(gap_prev - gap, 1e-6);
                r_hit = r_prev + (r - r_prev) * t;
                break;
            }
            r_prev = r;
            gap_prev = gap;
        }
        hit = q + per_m * r_hit;
    }
    let pt = detail_point(hit);
    let s = detail_sample(pt.b, pt.f);
    return FragmentDetail(DetailSample(w * s.height, w * s.gradient), hit);
}
