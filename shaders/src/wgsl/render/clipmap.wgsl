// ClipmapRenderer: geometry clipmap blocks displaced by the coarse-map (GPU Gems 2 ch. 2,
// Flower 2010, sec. 3.1.3), lit with the partial-derivative normals (diffuse + Phong specular) and
// coloured by height and slope. A surface with a detail layer adds its height and gradient in
// the fragment shader (`fragment_detail`; the normal is eq. 3.4's composite).

struct Frame {
    view_proj: mat4x4<f32>,
    // Camera position in texels: integer part (exact) and fraction; positions are computed
    // relative to the camera so large worlds keep their precision.
    camera_texel: vec2<i32>,
    camera_frac: vec2<f32>,
    camera_height: f32,
    texel_size: f32,
    // Height encoding: metres = offset + scale * stored.
    height_scale: f32,
    height_offset: f32,
    map_size: vec2<u32>,
    // A multiple of the map size added before `%` (GLSL's `%` of negatives is undefined).
    wrap_offset: vec2<i32>,
    // Clipmap N (vertices per side) and number of levels.
    n: u32,
    levels: u32,
    // Transition width of the level morph, in level grid units.
    morph_width: f32,
    // Heights (metres) the colour ramp spans.
    ramp_low: f32,
    ramp_high: f32,
    // 1 when the colour target is sRGB (see to_target).
    srgb_target: u32,
    // WRAP_REPEAT (toroidal coarse-map) or WRAP_CLAMP (edges extend flat).
    wrap: u32,
    // 1: fragments outside the map's own texels [0, size - 1] are discarded (the map drawn
    // once, as an island, instead of its repeats or its extended edges); 0: drawn.
    hide_outside: u32,
    light_dir: vec4<f32>,
    fog_color: vec4<f32>,
    // Texels (relative to the camera's whole texel) another renderer draws: fragments inside
    // (min.xy, max.zw) are discarded (RefineRenderer's region). Empty when min > max.
    excluded: vec4<f32>,
    // Material shading (materials.wgsl): where the camera's whole texel falls in the material
    // images' repeat (x, y), repeats per metre (z), how strongly their normals bend the
    // surface's (w).
    material: vec4<f32>,
    // The autoshader's edges: rock slope (x, y), snow height (z, w).
    autoshade: vec4<f32>,
    // The dirt curvature's edges (x, y); z: 1 to shade with materials, 0 with the height ramp;
    // w: texels between the heights the curvature is measured from.
    autoshade_dirt: vec4<f32>,
    // x: 1 when a colour layer (materials.wgsl) gives the albedo; y: 1 when a material layer's
    // paint is blended over the weights; z: 1 when a hole mask leaves cells out.
    color_layer: vec4<f32>,
    // The world cells the hole mask and the material layer cover: origin (x, y) and size (z, w).
    holes: vec4<i32>,
    paint_window: vec4<i32>,
    color_window: vec4<i32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
// The surface (`height_at`, `derivative_at` and their bindings) comes from a
// clipmap_surface_*.wgsl placed after this file.

// The map texel a grid texel reads: wrapped on a toroidal map, clamped to the edges otherwise.
fn map_texel(t: vec2<i32>) -> vec2<u32> {
    if frame.wrap == WRAP_REPEAT {
        return vec2<u32>(t + frame.wrap_offset) % frame.map_size;
    }
    return vec2<u32>(clamp(t, vec2<i32>(0, 0), vec2<i32>(frame.map_size) - vec2<i32>(1, 1)));
}

// Its index in a buffer of one element per texel.
fn texel_index(t: vec2<i32>) -> u32 {
    let c = map_texel(t);
    return c.y * frame.map_size.x + c.x;
}

struct VsIn {
    @location(0) pos: vec2<f32>,
    @location(1) offset: vec2<i32>,
    @location(2) scale: u32,
    @location(3) level: u32,
}

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    // Texel position relative to the camera's integer texel, for the normal lookup.
    @location(0) rel_texel: vec2<f32>,
    @location(1) height: f32,
    @location(2) view_dist: f32,
}

@vertex
fn vs_main(in: VsIn) -> VsOut {
    let s = i32(in.scale);
    let grid = vec2<i32>(in.pos);
    let texel = in.offset + grid * s;
    var h = height_at(texel);
    // Morph towards the next coarser level near this level's outer edge, so that the edge
    // vertices lie exactly on the coarser level's edges (no cracks, no popping). CPU
    // reference and tests: terrain_lod::morph (morph_alpha, coarse_height).
    if in.level + 1u < frame.levels {
        let rel = (vec2<f32>(texel - frame.camera_texel) - frame.camera_frac) / f32(s);
        let d = max(abs(rel.x), abs(rel.y));
        let half_size = f32(frame.n - 1u) * 0.5;
        // As 1 - (edge - d) / w: exactly 1 from the edge on, whatever the rounding of w.
        let alpha = clamp(1.0 - ((half_size - 1.0) - d) / frame.morph_width, 0.0, 1.0);
        if alpha > 0.0 {
            let odd = vec2<i32>(texel.x / s, texel.y / s) & vec2<i32>(1, 1);
            let step = odd * s;
            var coarse: f32;
            if odd.x == 1 && odd.y == 1 {
                coarse = 0.25 * (height_at(texel - step) + height_at(texel + step)
                    + height_at(texel + vec2<i32>(step.x, -step.y)) + height_at(texel + vec2<i32>(-step.x, step.y)));
            } else {
                coarse = 0.5 * (height_at(texel - step) + height_at(texel + step));
            }
            h = mix(h, coarse, alpha);
        }
    }
    let rel_texel = vec2<f32>(texel - frame.camera_texel) - frame.camera_frac;
    let world = vec3<f32>(rel_texel.x * frame.texel_size, h - frame.camera_height, rel_texel.y * frame.texel_size);
    var out: VsOut;
    out.clip = frame.view_proj * vec4<f32>(world, 1.0);
    out.rel_texel = rel_texel;
    out.height = h;
    out.view_dist = length(world);
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    // Bilinear gradient at the fragment. `rel_texel` is relative to the camera's exact
    // position; adding the camera's fraction makes it relative to the camera's whole texel.
    let p = in.rel_texel;
    let q = p + frame.camera_frac;
    // The fragment relative to the camera, in metres.
    let world = vec3<f32>(p.x * frame.texel_size, in.height - frame.camera_height, p.y * frame.texel_size);
    // Screen derivatives for the material images, taken here in uniform control flow.
    let dworld_dx = dpdx(world);
    let dworld_dy = dpdy(world);
    if frame.hide_outside != 0u {
        // The fragment's texel position on the unwrapped map plane.
        let t = vec2<f32>(frame.camera_texel) + q;
        let last = vec2<f32>(frame.map_size) - vec2<f32>(1.0, 1.0);
        if any(t < vec2<f32>(0.0, 0.0)) || any(t > last) {
            discard;
        }
    }
    if all(q > frame.excluded.xy) && all(q < frame.excluded.zw) {
        discard;
    }
    // Cells cut away (terrain_core::holes) are not drawn: what lies behind shows through.
    if frame.color_layer.z > 0.5 && in_hole(q) {
        discard;
    }
    // The surface's detail (none for most surfaces): what it adds, and where to shade.
    let fd = fragment_detail(q, world, in.view_dist);
    let qs = fd.q;
    let p0 = floor(qs);
    let f = qs - p0;
    let t0 = frame.camera_texel + vec2<i32>(p0);
    let d00 = derivative_at(t0);
    let d10 = derivative_at(t0 + vec2<i32>(1, 0));
    let d01 = derivative_at(t0 + vec2<i32>(0, 1));
    let d11 = derivative_at(t0 + vec2<i32>(1, 1));
    let d = mix(mix(d00, d10, f.x), mix(d01, d11, f.x), f.y);
    let n_surface = composite_normal(d, fd.sample.gradient);
    let height = in.height + fd.sample.height;

    let t = clamp((height - frame.ramp_low) / max(frame.ramp_high - frame.ramp_low, 1e-3), 0.0, 1.0);
    var albedo: vec3<f32>;
    var n = n_surface;
    if frame.autoshade_dirt.z > 0.5 {
        // Materials weighted by the autoshader from the slope and curvature the detail and the
        // deformations give the surface.
        let slope = length(d + fd.sample.gradient);
        let curvature = surface_curvature(qs, d00, d10, d01, d11);
        let position = (vec2<f32>(frame.camera_texel) + qs) * frame.texel_size;
        var w = surface_weights(SurfacePoint(position, height, t, slope, curvature));
        if frame.color_layer.y > 0.5 {
            w = painted_weights(qs, w);
        }
        let k = frame.material.z;
        // Ground coordinates of the fragment in repeats, from the camera's place in the repeat
        // (exact for any world size) plus the fragment's offset.
        let ground = frame.material.xy + qs * frame.texel_size * k;
        let up = height * k;
        let top = Projection(ground, dworld_dx.xz * k, dworld_dy.xz * k);
        let side_x = Projection(vec2<f32>(ground.y, up), dworld_dx.zy * k, dworld_dy.zy * k);
        let side_z = Projection(vec2<f32>(ground.x, up), dworld_dx.xy * k, dworld_dy.xy * k);
        let m = material_surface(w, top, side_x, side_z, n_surface, frame.material.w);
        albedo = m.albedo;
        n = m.normal;
    } else {
        let grass = mix(vec3<f32>(0.20, 0.36, 0.16), vec3<f32>(0.45, 0.55, 0.25), smoothstep(0.0, 0.45, t));
        let high = mix(vec3<f32>(0.55, 0.46, 0.36), vec3<f32>(0.93, 0.93, 0.96), smoothstep(0.55, 0.9, t));
        albedo = mix(grass, high, smoothstep(0.35, 0.65, t));
        // Steep slopes are bare rock.
        let slope = length(d);
        albedo = mix(albedo, vec3<f32>(0.42, 0.38, 0.34), smoothstep(0.6, 1.1, slope));
    }

    if frame.color_layer.x > 0.5 {
        albedo = colored_albedo(qs, albedo);
    }

    let l = normalize(frame.light_dir.xyz);
    let diffuse = max(dot(n, l), 0.0);
    // Phong specular towards the camera (at the origin of the camera-relative frame).
    let v = normalize(-world);
    let r = reflect(-l, n);
    let specular = 0.15 * pow(max(dot(r, v), 0.0), 24.0);
    var color = albedo * (0.28 + 0.8 * diffuse) + vec3<f32>(specular);
    // Aerial perspective: fade towards the fog colour with distance.
    let fog = 1.0 - exp(-in.view_dist * frame.fog_color.a);
    color = mix(color, frame.fog_color.rgb, fog);
    return vec4<f32>(to_target(color, frame.srgb_target), 1.0);
}
