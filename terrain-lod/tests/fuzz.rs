//! Fuzz target `lod`: clipmap layouts, per-frame placement and culling, the frustum and the
//! level morph, with camera positions up to and past the placement limit (2^26 texels) and
//! over the whole finite f32 range, texel sizes from `f32::MIN_POSITIVE` to `f32::MAX`, height
//! ranges and matrices of any values (NaN and infinities included). Every call must return
//! `Ok` or `Err` exactly as documented, never panic or hang; a frame that is `Ok` must be
//! well-formed (level count, scales, origins on the coarser grid, the camera inside level 0,
//! every draw accounted for, texel coordinates inside `i32`). The target is time-bounded
//! (`TERRAIN_FUZZ_SECONDS`, default 2 s; `cargo xtask fuzz --seconds N` runs it longer, in
//! release mode); see `terrain_test_support::fuzz` for the seed, replay and class selection
//! variables.

use glam::camera::rh::{proj::directx, view::look_to_mat4};
use glam::{IVec2, Mat4, UVec2, Vec2, Vec3, Vec4};
use std::time::Duration;
use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
use terrain_lod::clipmap::{MAX_CAMERA_TEXELS, MAX_LEVELS};
use terrain_lod::morph::{
    MorphLevel, coarse_height, default_morph_width, morph_alpha, morphed_height,
};
use terrain_lod::{
    CdlodConfig, CdlodTree, CdlodView, ClipmapFrame, ClipmapLayout, CurvatureFilter, DensityMap,
    DensityParams, Frustum, LodError, LodMetric, MAX_DRAWS_PER_LEVEL, PartKind, TessConfig,
    TessHierarchy,
};
use terrain_test_support::fuzz::{self, Case, Class, Rng, Target, finite_f32};

/// Placing 16 levels and culling their blocks takes microseconds; building a layout of up to
/// 255 vertices a side a few milliseconds. 250 ms leaves room for debug builds under load.
const PER_CASE_LIMIT: Duration = Duration::from_millis(250);

/// The valid clipmap sides, `2^k - 1` for `k` in 3..=10.
const SIDES: [u32; 8] = [7, 15, 31, 63, 127, 255, 511, 1023];

/// Layouts built once (the mesh of 1023 vertices a side holds a million vertices).
struct Ctx {
    layouts: Vec<ClipmapLayout>,
}

fn ctx() -> Ctx {
    let mut layouts = Vec::new();
    for n in SIDES {
        for levels in [1, 2, 5, MAX_LEVELS] {
            if n >= 511 && levels == 2 {
                continue; // the largest meshes cost the most to build: three level counts
            }
            layouts.push(ClipmapLayout::new(n, levels).expect("valid layout"));
        }
    }
    Ctx { layouts }
}

impl Ctx {
    fn layout(&self, rng: &mut Rng) -> &ClipmapLayout {
        &self.layouts[rng.index(self.layouts.len())]
    }
}

/// Any finite f32: random bits, edge values, or modest numbers (within 1e4).
fn any_f32(rng: &mut Rng) -> f32 {
    rng.f32_any(1e4)
}

/// Any f32, non-finite ones included now and then.
fn any_f32_or_not(rng: &mut Rng) -> f32 {
    if rng.chance(1, 16) {
        rng.f32_non_finite()
    } else {
        any_f32(rng)
    }
}

/// A texel size from `f32::MIN_POSITIVE` to `f32::MAX`.
fn texel_size(rng: &mut Rng) -> f32 {
    match rng.below(3) {
        0 => rng.pick(&[
            f32::MIN_POSITIVE,
            1e-30,
            1e-6,
            0.1,
            0.5,
            1.0,
            7.0,
            1e6,
            1e30,
            f32::MAX,
        ]),
        1 => rng.f32_bits().abs().max(f32::MIN_POSITIVE),
        _ => rng.uniform(0.01, 10.0) as f32,
    }
}

/// A camera coordinate in texels: anywhere within the limit, at it, just past it, on a snap
/// boundary of some level.
fn camera_texel(rng: &mut Rng) -> f64 {
    let sign = if rng.chance(1, 2) { 1.0 } else { -1.0 };
    match rng.below(5) {
        0 => rng.uniform(-MAX_CAMERA_TEXELS, MAX_CAMERA_TEXELS),
        1 => sign * MAX_CAMERA_TEXELS,
        2 => sign * (MAX_CAMERA_TEXELS - rng.uniform(0.0, 2.0)),
        3 => {
            let snap = (1u64 << rng.range_u32(1, MAX_LEVELS + 1)) as f64;
            sign * (rng.below(1 << 20) as f64 * snap).min(MAX_CAMERA_TEXELS)
        }
        _ => rng.uniform(-1e4, 1e4),
    }
}

/// The error `place` must return for these inputs, by the documented rules, if any.
fn place_expected(camera: Vec2, ts: f32, range: (f32, f32)) -> Option<&'static str> {
    if !camera.x.is_finite() || !camera.y.is_finite() || !ts.is_finite() {
        return Some("NonFinite");
    }
    if ts <= 0.0 {
        return Some("InvalidTexelSize");
    }
    if !range.0.is_finite() || !range.1.is_finite() {
        return Some("NonFinite");
    }
    if range.0 > range.1 {
        return Some("InvalidHeightRange");
    }
    let t = camera.as_dvec2() / f64::from(ts);
    if t.abs().max_element() > MAX_CAMERA_TEXELS {
        return Some("CameraOutOfRange");
    }
    None
}

fn variant(e: &LodError) -> &'static str {
    match e {
        LodError::NonFinite { .. } => "NonFinite",
        LodError::InvalidTexelSize { .. } => "InvalidTexelSize",
        LodError::InvalidHeightRange { .. } => "InvalidHeightRange",
        LodError::CameraOutOfRange { .. } => "CameraOutOfRange",
        LodError::InvalidClipmapSize { .. } => "InvalidClipmapSize",
        LodError::InvalidLevelCount { .. } => "InvalidLevelCount",
        LodError::InvalidDensityParam { .. } => "InvalidDensityParam",
        LodError::SizeMismatch { .. } => "SizeMismatch",
        LodError::InvalidCdlodParam { .. } => "InvalidCdlodParam",
        LodError::InvalidTessParam { .. } => "InvalidTessParam",
        LodError::SelectionTooLarge { .. } => "SelectionTooLarge",
        LodError::InvalidRefineRadius { .. } => "InvalidRefineRadius",
        LodError::UpdaterStopped(_) => "UpdaterStopped",
        LodError::Core(_) => "Core",
    }
}

/// Part instances a frame places before culling: level 0's grid and degenerates, 16 per ring.
fn total_parts(layout: &ClipmapLayout) -> usize {
    2 + 16 * (layout.levels() as usize - 1)
}

/// Checks a frame: levels, scales, origins on the coarser grid, the camera inside level 0,
/// every part instance drawn or culled, texel coordinates of a few draws inside `i32`.
fn check_frame(
    layout: &ClipmapLayout,
    frame: &ClipmapFrame,
    camera_texel: (f64, f64),
    culling: bool,
    rng: &mut Rng,
) -> Result<(), String> {
    if frame.levels.len() != layout.levels() as usize {
        return Err(format!(
            "{} levels placed of {}",
            frame.levels.len(),
            layout.levels()
        ));
    }
    for (l, level) in frame.levels.iter().enumerate() {
        let snap = 1i64 << (l + 1);
        if level.level != l as u32 || level.scale != 1 << l {
            return Err(format!("level {l} placed as {level:?}"));
        }
        if i64::from(level.origin.x).rem_euclid(snap) != 0
            || i64::from(level.origin.y).rem_euclid(snap) != 0
        {
            return Err(format!(
                "level {l} origin {} is off the {snap}-texel grid",
                level.origin
            ));
        }
        if (l == 0) != level.trim.is_none() {
            return Err(format!("level {l} trim {:?}", level.trim));
        }
    }
    let l0 = frame.levels[0];
    let side = layout.level_side_texels(0) as f64;
    let (lo, hi) = (l0.origin.as_dvec2(), l0.origin.as_dvec2() + side);
    if !(camera_texel.0 >= lo.x
        && camera_texel.0 <= hi.x
        && camera_texel.1 >= lo.y
        && camera_texel.1 <= hi.y)
    {
        return Err(format!(
            "camera at texel {camera_texel:?} outside level 0 [{lo}, {hi}]"
        ));
    }
    let placed = frame.draws.len() + frame.culled as usize;
    if placed != total_parts(layout) || frame.draws.len() > MAX_DRAWS_PER_LEVEL * frame.levels.len()
    {
        return Err(format!(
            "{} draws + {} culled, {} part instances expected",
            frame.draws.len(),
            frame.culled,
            total_parts(layout)
        ));
    }
    if !culling && frame.culled != 0 {
        return Err(format!("{} parts culled without a frustum", frame.culled));
    }
    let mut trims = 0;
    for draw in &frame.draws {
        if matches!(draw.part, PartKind::Trim(_)) {
            trims += 1;
        }
        if draw.instance.scale != 1 << draw.instance.level {
            return Err(format!("draw {draw:?} has the wrong scale"));
        }
    }
    if trims != layout.levels() as usize - 1 {
        return Err(format!("{trims} trims for {} levels", layout.levels()));
    }
    let _ = frame.triangle_count(layout.mesh());
    if !frame.draws.is_empty() {
        let draw = frame.draws[rng.index(frame.draws.len())];
        for tri in layout.mesh().draw_triangles(&draw).take(64) {
            for p in tri {
                if i32::try_from(p.x).is_err() || i32::try_from(p.y).is_err() {
                    return Err(format!("draw {draw:?} reaches texel {p}"));
                }
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Classes

/// `ClipmapLayout::new` with any side and level count: `Ok` exactly for `2^k - 1`
/// (`3 <= k <= 10`) and `1..=16` levels. Valid sides are built up to 255 (larger meshes are
/// the prebuilt ones).
fn layout_new(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let n = match rng.below(3) {
        0 => rng.u32_edge(),
        1 => (1u32 << rng.range_u32(0, 31)).wrapping_sub(rng.range_u32(0, 2)),
        _ => rng.range_u32(0, 300),
    };
    let levels = if rng.chance(1, 2) {
        rng.u32_edge()
    } else {
        rng.range_u32(0, 20)
    };
    let valid_n = SIDES.contains(&n);
    let valid_levels = (1..=MAX_LEVELS).contains(&levels);
    if valid_n && n > 255 && valid_levels {
        case.skipped = true;
        return Ok(());
    }
    match ClipmapLayout::new(n, levels) {
        Ok(l) if valid_n && valid_levels => {
            if l.vertex_count() as usize != l.mesh().vertices.len() {
                return Err(format!(
                    "n {n}: {} vertices, eq. 3.1 says {}",
                    l.mesh().vertices.len(),
                    l.vertex_count()
                ));
            }
            for level in [0, levels - 1, levels, 63, 64, u32::MAX, rng.next_u32()] {
                let _ = l.level_side_texels(level);
            }
            Ok(())
        }
        Err(LodError::InvalidClipmapSize { n: got }) if !valid_n && got == n => Ok(()),
        Err(LodError::InvalidLevelCount { levels: got })
            if valid_n && !valid_levels && got == levels =>
        {
            Ok(())
        }
        other => Err(format!(
            "new({n}, {levels}) gave {:?}",
            other.map(|l| l.n())
        )),
    }
}

/// Placement with valid inputs (camera within the limit, any texel size, any ordered finite
/// height range), no culling: `Ok` and a well-formed frame.
fn place_valid(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let layout = ctx.layout(rng);
    let ts = texel_size(rng);
    let (tx, tz) = (camera_texel(rng), camera_texel(rng));
    let camera = Vec2::new(
        finite_f32(tx * f64::from(ts)),
        finite_f32(tz * f64::from(ts)),
    );
    let (a, b) = (any_f32(rng), any_f32(rng));
    let range = (a.min(b), a.max(b));
    let want = place_expected(camera, ts, range);
    let got = layout.place(camera, ts, range, None);
    let c = camera.as_dvec2() / f64::from(ts);
    match (want, got) {
        (None, Ok(frame)) => check_frame(layout, &frame, (c.x, c.y), false, rng),
        // Rounding the camera to f32 may put it just past the limit.
        (Some(v), Err(e)) if v == variant(&e) => Ok(()),
        (want, got) => Err(format!(
            "n {} levels {}: camera {camera} texel size {ts:e} range {range:?}: expected {}, got {:?}",
            layout.n(),
            layout.levels(),
            want.unwrap_or("Ok"),
            got.map(|f| f.levels.len())
        )),
    }
}

/// Placement with any inputs (camera, texel size and height range over the whole f32 range,
/// non-finite ones too): exactly the documented error, else a well-formed frame.
fn place_whole_range(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let layout = ctx.layout(rng);
    let camera = Vec2::new(any_f32_or_not(rng), any_f32_or_not(rng));
    let ts = if rng.chance(1, 2) {
        any_f32_or_not(rng)
    } else {
        texel_size(rng)
    };
    let range = (any_f32_or_not(rng), any_f32_or_not(rng));
    let want = place_expected(camera, ts, range);
    let got = layout.place(camera, ts, range, None);
    match (want, got) {
        (None, Ok(frame)) => {
            let c = camera.as_dvec2() / f64::from(ts);
            check_frame(layout, &frame, (c.x, c.y), false, rng)
        }
        (Some(v), Err(e)) if v == variant(&e) => Ok(()),
        (want, got) => Err(format!(
            "camera {camera} texel size {ts:e} range {range:?}: expected {}, got {:?}",
            want.unwrap_or("Ok"),
            got.map(|f| f.levels.len())
        )),
    }
}

/// A random view-projection: a perspective camera (any fov, aspect, near and far, some
/// degenerate) looking any way from near the clipmap, or a matrix of arbitrary entries.
fn view_proj(rng: &mut Rng, eye: Vec3) -> Mat4 {
    match rng.below(3) {
        0 | 1 => {
            let dir = Vec3::new(
                rng.uniform(-1.0, 1.0) as f32,
                rng.uniform(-1.0, 0.3) as f32,
                rng.uniform(-1.0, 1.0) as f32,
            );
            let dir = dir.try_normalize().unwrap_or(Vec3::X);
            let up = if dir.cross(Vec3::Y).length_squared() > 1e-6 {
                Vec3::Y
            } else {
                Vec3::Z
            };
            let fov = rng.pick(&[1e-6f32, 0.1, 1.0, 2.0, 3.1]);
            let aspect = rng.pick(&[1e-6f32, 0.5, 1.0, 16.0 / 9.0, 1e6]);
            let near = rng.pick(&[1e-6f32, 0.1, 1.0, 100.0]);
            let far = near * rng.pick(&[1.0001f32, 10.0, 1e4, 1e12]);
            directx::perspective(fov, aspect, near, far) * look_to_mat4(eye, dir, up)
        }
        _ => Mat4::from_cols(
            Vec4::new(
                any_f32_or_not(rng),
                any_f32(rng),
                any_f32(rng),
                any_f32(rng),
            ),
            Vec4::new(
                any_f32(rng),
                any_f32_or_not(rng),
                any_f32(rng),
                any_f32(rng),
            ),
            Vec4::new(
                any_f32(rng),
                any_f32(rng),
                any_f32_or_not(rng),
                any_f32(rng),
            ),
            Vec4::new(
                any_f32(rng),
                any_f32(rng),
                any_f32(rng),
                any_f32_or_not(rng),
            ),
        ),
    }
}

/// Placement with culling: the culled frame draws a subset of the unculled one (same order),
/// and every part instance is drawn or counted as culled.
fn place_culled(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let layout = ctx.layout(rng);
    let ts = texel_size(rng);
    let (tx, tz) = (camera_texel(rng), camera_texel(rng));
    let camera = Vec2::new(
        finite_f32(tx * f64::from(ts)),
        finite_f32(tz * f64::from(ts)),
    );
    let (a, b) = (any_f32(rng), any_f32(rng));
    let range = (a.min(b), a.max(b));
    let eye = Vec3::new(
        camera.x,
        finite_f32(f64::from(range.1) + 10.0 * f64::from(ts)),
        camera.y,
    );
    let frustum = Frustum::from_view_proj(view_proj(rng, eye));
    let (all, culled) = match (
        layout.place(camera, ts, range, None),
        layout.place(camera, ts, range, Some(&frustum)),
    ) {
        (Ok(a), Ok(c)) => (a, c),
        (Err(a), Err(c)) if a == c => return Ok(()),
        (a, c) => {
            return Err(format!(
                "culling changed the outcome: {:?} vs {:?}",
                a.map(|f| f.draws.len()),
                c.map(|f| f.draws.len())
            ));
        }
    };
    let c = camera.as_dvec2() / f64::from(ts);
    check_frame(layout, &culled, (c.x, c.y), true, rng)?;
    if culled.levels != all.levels {
        return Err("culling moved the levels".into());
    }
    let mut rest = all.draws.iter();
    for d in &culled.draws {
        if !rest.any(|a| a == d) {
            return Err(format!(
                "culled frame draws {d:?}, which the full frame does not"
            ));
        }
    }
    let kept_uncullable = culled
        .draws
        .iter()
        .filter(|d| !d.part.is_cullable())
        .count();
    let all_uncullable = all.draws.iter().filter(|d| !d.part.is_cullable()).count();
    if kept_uncullable != all_uncullable {
        return Err(format!(
            "{kept_uncullable} of {all_uncullable} uncullable parts (trims, degenerates, level 0) drawn"
        ));
    }
    Ok(())
}

/// The frustum of any matrix: a point inside is inside every box around it (culling is
/// conservative), boxes are taken in either corner order, and a matrix with a NaN rejects
/// nothing.
fn frustum_any(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let eye = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)) * rng.pick(&[0.0, 1e-3, 1.0]);
    let m = view_proj(rng, eye);
    let f = Frustum::from_view_proj(m);
    let p = if rng.chance(1, 2) {
        eye + Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)) * rng.pick(&[1e-3, 1.0, 1e3])
    } else {
        Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng))
    };
    let e = Vec3::new(any_f32(rng).abs(), any_f32(rng).abs(), any_f32(rng).abs())
        * rng.pick(&[0.0, 1e-3, 1.0]);
    let (lo, hi) = (p - e, p + e);
    let inside = f.contains_point(p);
    let hits = f.intersects_aabb(lo, hi);
    let hits_swapped = f.intersects_aabb(hi, lo);
    if hits != hits_swapped {
        return Err(format!(
            "box {lo}..{hi}: {hits} one way, {hits_swapped} the other"
        ));
    }
    if inside && lo.is_finite() && hi.is_finite() && !hits {
        return Err(format!(
            "point {p} is inside but the box {lo}..{hi} around it is culled"
        ));
    }
    if f.intersects_aabb(p, p) != inside {
        return Err(format!("the point box at {p} and the point disagree"));
    }
    // A matrix of NaN gives planes that reject nothing (documented).
    let nan = Frustum::from_view_proj(Mat4::from_cols_array(&[f32::NAN; 16]));
    if !(nan.contains_point(p) && nan.intersects_aabb(lo, hi)) {
        return Err(format!("a NaN matrix rejected point {p} or box {lo}..{hi}"));
    }
    Ok(())
}

/// The level morph with any inputs: `morph_alpha`, `coarse_height` and `morphed_height` never
/// panic; with valid inputs (scale a power of two up to 2^15, texel on the level's grid
/// within the placement limit, finite camera) the alpha lies in [0, 1] and the coarse height
/// is the mean of the coarser neighbours.
fn morph_any(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let verbose = case.verbose();
    let rng = &mut case.rng;
    let valid = rng.chance(1, 2);
    let (scale, texel, camera, n, width) = if valid {
        let scale = 1u32 << rng.range_u32(0, MAX_LEVELS - 1);
        let lim = (1i64 << 27) / i64::from(scale);
        let grid = |rng: &mut Rng| (rng.below(2 * lim as u64) as i64 - lim) as i32 * scale as i32;
        let texel = IVec2::new(grid(rng), grid(rng));
        let camera = texel.as_vec2()
            + Vec2::new(rng.uniform(-1e4, 1e4) as f32, rng.uniform(-1e4, 1e4) as f32);
        let n = rng.pick(&SIDES);
        (scale, texel, camera, n, default_morph_width(n))
    } else {
        let scale = rng.u32_edge();
        let texel = IVec2::new(rng.u32_edge() as i32, rng.u32_edge() as i32);
        let camera = Vec2::new(any_f32_or_not(rng), any_f32_or_not(rng));
        (scale, texel, camera, rng.u32_edge(), any_f32_or_not(rng))
    };
    if verbose {
        eprintln!("texel {texel:?} camera {camera:?} scale {scale} n {n} width {width:e}");
    }
    let a = morph_alpha(texel, camera, scale, n, width);
    if valid && !(0.0..=1.0).contains(&a) {
        return Err(format!(
            "alpha {a} at texel {texel} camera {camera} scale {scale} n {n}"
        ));
    }
    let height = |t: IVec2| (t.x as f32 * 0.37).sin() + (t.y as f32 * 0.21).cos();
    let c = coarse_height(texel, scale, height);
    if valid {
        let s = scale as i32;
        let odd = IVec2::new(texel.x.div_euclid(s) & 1, texel.y.div_euclid(s) & 1);
        let step = odd * s;
        let want = match (odd.x, odd.y) {
            (0, 0) => height(texel),
            (1, 1) => {
                0.25 * (height(texel - step)
                    + height(texel + step)
                    + height(texel + IVec2::new(step.x, -step.y))
                    + height(texel + IVec2::new(-step.x, step.y)))
            }
            _ => 0.5 * (height(texel - step) + height(texel + step)),
        };
        if c != want {
            return Err(format!(
                "coarse height {c} at {texel} scale {scale}, expected {want}"
            ));
        }
    }
    let level = MorphLevel {
        scale,
        n,
        width,
        coarsest: rng.chance(1, 4),
    };
    let _ = morphed_height(texel, camera, &level, height);
    let _ = default_morph_width(rng.u32_edge());
    Ok(())
}

/// A small map of random heights (any u16), either wrap mode.
fn small_map(rng: &mut Rng, max_side: u32) -> HeightMap<u16> {
    let (w, h) = (rng.range_u32(1, max_side), rng.range_u32(1, max_side));
    let wrap = if rng.chance(1, 2) {
        WrapMode::Repeat
    } else {
        WrapMode::Clamp
    };
    let smooth = rng.chance(1, 2);
    let grid = Grid::from_fn(w, h, |x, y| {
        if smooth {
            (30_000.0 + 8_000.0 * ((x as f32 * 0.3).sin() + (y as f32 * 0.2).cos())) as u16
        } else {
            (x.wrapping_mul(40_503) ^ y.wrapping_mul(2_654_435_761)) as u16
        }
    })
    .expect("small grid");
    let scale = rng.pick(&[1e-6f32, 0.001, 1.0, 1e4]);
    let ts = rng.pick(&[1e-4f32, 0.1, 1.0, 1e3]);
    HeightMap::new(
        grid,
        HeightEncoding::new(scale, 0.0).expect("encoding"),
        ts,
        wrap,
    )
    .expect("map")
}

/// Any rect: corners anywhere in i32, sizes anywhere in u32.
fn any_rect(rng: &mut Rng) -> Rect {
    let c = |rng: &mut Rng| {
        if rng.chance(1, 2) {
            rng.range_u32(0, 80) as i32 - 40
        } else {
            rng.next_u32() as i32
        }
    };
    let s = |rng: &mut Rng| {
        if rng.chance(1, 2) {
            rng.range_u32(0, 60)
        } else {
            rng.u32_edge()
        }
    };
    Rect::new(IVec2::new(c(rng), c(rng)), glam::UVec2::new(s(rng), s(rng)))
}

/// Density maps of any small map with any parameters (each field valid or at an edge), then
/// updates in any rect: `Ok` equal to a rebuild, or a parameter error naming a field.
fn density_any(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let map = small_map(rng, 40);
    let mut p = DensityParams {
        filter: CurvatureFilter::ALL[rng.index(5)],
        ..DensityParams::default()
    };
    if rng.chance(1, 3) {
        p.gain = rng.f32_edge();
    }
    if rng.chance(1, 3) {
        p.exponent = rng.f32_edge();
    }
    if rng.chance(1, 3) {
        p.full_density_bend = rng.f32_edge();
    }
    if rng.chance(1, 3) {
        p.filter_size = rng.pick(&[0, 1, 2, 31, 32, u32::MAX]);
        p.border_lod_skip = rng.pick(&[0, 1, 4, 5, u32::MAX]);
        p.tile_size = rng.pick(&[0, 1, 2, 3, 4096, 4097, u32::MAX]);
    }
    p.preprocess = rng.chance(3, 4);
    let mut dm = match DensityMap::from_map(&map, p) {
        Ok(dm) => dm,
        Err(LodError::InvalidDensityParam { .. }) => {
            return if p.validate().is_err() {
                Ok(())
            } else {
                Err(format!("{p:?} refused"))
            };
        }
        Err(e) => return Err(format!("{p:?}: {e}")),
    };
    let mut changed = map.clone();
    let rect = any_rect(rng);
    for piece in rect.split_toroidal(map.size()) {
        if map.wrap() == WrapMode::Clamp && piece.map != piece.unwrapped {
            continue;
        }
        let r = piece.map;
        for y in r.min.y..r.max().y.min(r.min.y + 64) {
            for x in r.min.x..r.max().x.min(r.min.x + 64) {
                let v = changed
                    .grid_mut()
                    .get_mut(x as u32, y as u32)
                    .expect("inside");
                *v = v.wrapping_add(977);
            }
        }
    }
    // Only the rect the texels changed in is a valid dirty rect: give the whole rect (it
    // covers them).
    dm.update_rect(&changed, rect).map_err(|e| e.to_string())?;
    let fresh = DensityMap::from_map(&changed, p).map_err(|e| e.to_string())?;
    if rect.size.x <= 64 && rect.size.y <= 64 && dm != fresh {
        return Err(format!("update in {rect:?} differs from a rebuild"));
    }
    Ok(())
}

/// CDLOD trees of any small map and configuration, selections from any camera (finite or
/// not) and frustum: `Ok` with well-formed instances, or a documented error.
/// A frustum of any matrix.
fn any_frustum(rng: &mut Rng) -> Frustum {
    Frustum::from_view_proj(Mat4::from_cols_array(&std::array::from_fn(|_| {
        any_f32(rng)
    })))
}

/// A LOD view: a camera anywhere (or near a small map), `frustum` or none, extreme viewports
/// and fields of view.
fn any_view<'a>(rng: &mut Rng, frustum: &'a Frustum) -> CdlodView<'a> {
    let camera = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng));
    let near = Vec3::new(
        rng.uniform(-50.0, 80.0) as f32,
        rng.uniform(-10.0, 60.0) as f32,
        rng.uniform(-50.0, 80.0) as f32,
    );
    CdlodView {
        camera: if rng.chance(1, 2) { near } else { camera },
        frustum: rng.chance(1, 2).then_some(frustum),
        viewport_width: rng.pick(&[1.0f32, 1280.0, 1e9]),
        hfov: rng.pick(&[0.01f32, 1.2, 3.1]),
    }
}

fn cdlod_any(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let map = small_map(rng, 70);
    let mut c = CdlodConfig {
        leaf_size: rng.pick(&[0, 3, 4, 8, 16, 1024, 2048]),
        grid_size: rng.pick(&[2, 4, 8, 16, 256, 512]),
        lod_count: rng.pick(&[0, 1, 2, 4, 8, 16, 17]),
        finest_range: if rng.chance(1, 2) {
            rng.f32_edge()
        } else {
            rng.uniform(0.1, 50.0) as f32
        },
        morph: rng.chance(1, 2),
        ..CdlodConfig::default()
    };
    if rng.chance(1, 4) {
        c.range_ratio = rng.f32_edge();
        c.morph_start_ratio = rng.f32_edge();
    }
    if rng.chance(1, 2) {
        c.metric = LodMetric::ScreenSpace {
            tau_px: if rng.chance(1, 2) {
                rng.f32_edge()
            } else {
                rng.uniform(0.1, 10.0) as f32
            },
        };
    }
    let tree = match CdlodTree::from_map(&map, c) {
        Ok(t) => t,
        Err(LodError::InvalidCdlodParam { .. }) => return Ok(()),
        Err(e) => return Err(format!("{c:?}: {e}")),
    };
    let frustum = any_frustum(rng);
    let view = any_view(rng, &frustum);
    let camera = view.camera;
    match tree.select(&view) {
        Ok(frame) => {
            for i in &frame.instances {
                if i.lod >= c.lod_count || i.step == 0 {
                    return Err(format!("bad instance {i:?}"));
                }
            }
            let e = tree.max_screen_error_px(&frame, &view);
            if e.is_nan() || e < 0.0 {
                return Err(format!("screen error {e}"));
            }
            Ok(())
        }
        Err(LodError::NonFinite { .. }) if !camera.is_finite() => Ok(()),
        Err(LodError::CameraOutOfRange { .. } | LodError::SelectionTooLarge { .. }) => Ok(()),
        Err(e) => Err(format!("{camera} {c:?}: {e}")),
    }
}

fn tessellation_any(_: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let map = small_map(rng, 70);
    let c = TessConfig {
        patch_size: rng.pick(&[0, 1, 2, 3, 8, 32, 256, 512]),
        triangle_width_px: if rng.chance(1, 2) {
            rng.f32_edge()
        } else {
            rng.uniform(0.01, 100.0) as f32
        },
        min_triangle_m: if rng.chance(1, 4) {
            rng.f32_edge()
        } else {
            0.0
        },
        use_density: rng.chance(1, 2),
        morph: rng.chance(1, 2),
        morph_range: if rng.chance(1, 4) {
            rng.f32_edge()
        } else {
            1.0
        },
        max_triangles: rng.pick(&[0, 1, 100, 1 << 22, usize::MAX]),
        max_error_px: match rng.below(3) {
            0 => None,
            1 => Some(rng.f32_edge()),
            _ => Some(rng.uniform(0.01, 50.0) as f32),
        },
    };
    let density = if rng.chance(1, 2) {
        DensityMap::from_map(&map, DensityParams::default()).ok()
    } else {
        None
    };
    let tess = match TessHierarchy::from_map(&map, density.as_ref(), c) {
        Ok(t) => t,
        Err(LodError::InvalidTessParam { .. }) => return Ok(()),
        Err(e) => return Err(format!("{c:?}: {e}")),
    };
    let frustum = any_frustum(rng);
    let view = any_view(rng, &frustum);
    let camera = view.camera;
    // An update of any rect (off the map, huge, empty) answers and keeps the bounds finite.
    let mut tess = tess;
    let rect = Rect::new(
        IVec2::new(
            rng.pick(&[i32::MIN, -70, 0, 33, i32::MAX - 5]),
            rng.pick(&[-3, 0, 50]),
        ),
        UVec2::new(rng.pick(&[0, 1, 20, u32::MAX]), rng.pick(&[0, 7, u32::MAX])),
    );
    if let Err(e) = tess.update_rect(&map, density.as_ref(), rect) {
        return Err(format!("update_rect {rect:?}: {e}"));
    }
    if tess.bounds().iter().flatten().any(|v| !v.is_finite()) {
        return Err("a bound is not finite".into());
    }
    let probe = Vec2::new(any_f32(rng), any_f32(rng));
    if let Some(h) = tess.surface_height(&view, probe)
        && !h.is_finite()
    {
        return Err(format!("surface height {h} at {probe}"));
    }
    match tess.select(&view) {
        Ok(frame) => {
            if frame.triangles.len() > c.max_triangles {
                return Err(format!(
                    "{} triangles over the bound",
                    frame.triangles.len()
                ));
            }
            let e = tess.max_screen_error_px(&frame, &view);
            if !e.is_finite() || e < 0.0 {
                return Err(format!("screen error {e}"));
            }
            Ok(())
        }
        Err(LodError::NonFinite { .. }) if !camera.is_finite() => Ok(()),
        Err(LodError::SelectionTooLarge { .. }) => Ok(()),
        Err(e) => Err(format!("{camera} {c:?}: {e}")),
    }
}

#[test]
fn fuzz_lod() {
    fn c(name: &'static str, f: fn(&Ctx, &mut Case) -> Result<(), String>) -> Class<Ctx> {
        Class { name, run: f }
    }
    fuzz::run(
        Target {
            name: "lod",
            per_case_limit: PER_CASE_LIMIT,
            classes: vec![
                c("layout_new_any", layout_new),
                c("place_valid_extreme", place_valid),
                c("place_whole_range", place_whole_range),
                c("place_culled", place_culled),
                c("frustum_any_matrix", frustum_any),
                c("morph_any", morph_any),
                c("density_any", density_any),
                c("cdlod_any", cdlod_any),
                c("tessellation_any", tessellation_any),
            ],
            disabled: &[],
        },
        ctx(),
    );
}

// ---------------------------------------------------------------------------------------------
// Regressions: inputs the target found, kept as they were found

/// `lod/morph_any` (replay `morph_any:0xbd6f5fea614561df`): a scale of 0 divided by zero in
/// `coarse_height` (and in `morphed_height`, which calls it).
#[test]
fn regression_coarse_height_of_scale_zero() {
    let height = |t: IVec2| t.x as f32 + 2.0 * t.y as f32;
    let texel = IVec2::new(4_194_305, 67_108_864);
    let camera = Vec2::new(4_294_968_000.0, -6855.175);
    let _ = morph_alpha(texel, camera, 0, 4_194_303, 2.857_705_8e3);
    assert!(coarse_height(texel, 0, height).is_finite());
    let level = MorphLevel {
        scale: 0,
        n: 4_194_303,
        width: 2.857_705_8e3,
        coarsest: false,
    };
    let _ = morphed_height(texel, camera, &level, height);
}

/// Scales past `i32::MAX` (`i32::MIN / -1` overflowed) and neighbours past the ends of `i32`
/// (a texel at `i32::MAX` with an odd scale overflowed adding the step).
#[test]
fn regression_coarse_height_at_the_ends_of_i32() {
    let height = |t: IVec2| (t.x as f32).abs().sqrt() + (t.y as f32).abs().sqrt();
    for scale in [u32::MAX, 1 << 31, (1 << 31) + 1, 3, 1] {
        for texel in [
            IVec2::new(i32::MIN, i32::MIN),
            IVec2::new(i32::MAX, i32::MAX),
            IVec2::new(i32::MIN, i32::MAX),
        ] {
            assert!(
                coarse_height(texel, scale, height).is_finite(),
                "{texel} {scale}"
            );
        }
    }
}
