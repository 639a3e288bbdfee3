//! What the tessellation tests share: the conformity check of a drawn mesh and its area, and
//! an unculled 1280-pixel view.

use glam::{UVec2, Vec2, Vec3};
use std::collections::HashMap;
use terrain_lod::{CdlodView, TessFrame};

/// Every directed edge `(from, to)` with its endpoint heights must meet its reverse in exactly
/// one other triangle, unless it lies on the border of the `extent` texels drawn (a repeating
/// map is drawn once: its seam is a border too). Returns the number of border edges.
pub fn assert_conforming(frame: &TessFrame, extent: UVec2) -> usize {
    let key = |v: &terrain_lod::TessVertex| (v.texel[0] as i32, v.texel[1] as i32);
    // Per directed edge: how often it is drawn, and its endpoints' height bits.
    type Edge = ((i32, i32), (i32, i32));
    let mut edges: HashMap<Edge, (u32, [u32; 2])> = HashMap::new();
    for tri in &frame.triangles {
        let a = Vec2::from(tri[0].texel);
        let b = Vec2::from(tri[1].texel);
        let c = Vec2::from(tri[2].texel);
        assert!(
            (b - a).perp_dot(c - a) < 0.0,
            "wound counter-clockwise seen from above: {tri:?}"
        );
        for i in 0..3 {
            let (p, q) = (&tri[i], &tri[(i + 1) % 3]);
            let e = edges.entry((key(p), key(q))).or_insert((0, [0, 0]));
            e.0 += 1;
            e.1 = [p.height.to_bits(), q.height.to_bits()];
        }
    }
    let mut border = 0;
    for (&(p, q), &(n, h)) in &edges {
        assert_eq!(n, 1, "edge {p:?} -> {q:?} drawn {n} times");
        match edges.get(&(q, p)) {
            Some(&(_, hr)) => assert_eq!(
                [h[0], h[1]],
                [hr[1], hr[0]],
                "edge {p:?} -> {q:?}: the two sides draw different heights (a crack)"
            ),
            None => {
                let on_border = |a: (i32, i32), b: (i32, i32)| {
                    (a.0 == b.0 && (a.0 == 0 || a.0 == extent.x as i32))
                        || (a.1 == b.1 && (a.1 == 0 || a.1 == extent.y as i32))
                };
                assert!(
                    on_border(p, q),
                    "edge {p:?} -> {q:?} has no neighbour inside the map: a T-junction or a crack"
                );
                border += 1;
            }
        }
    }
    border
}

/// The area the triangles cover, texels squared.
pub fn area(frame: &TessFrame) -> f64 {
    frame
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| Vec2::from(v.texel));
            f64::from((b - a).perp_dot(c - a).abs() * 0.5)
        })
        .sum()
}

/// An unculled view from `camera` on a 1280-pixel-wide target.
pub fn view(camera: Vec3) -> CdlodView<'static> {
    CdlodView {
        camera,
        frustum: None,
        viewport_width: 1280.0,
        hfov: 1.2,
    }
}
