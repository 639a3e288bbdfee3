#[path = "../tests/common/mod.rs"]
mod common;
fn main() {
    for n in [32, 64] {
        let map = common::hills(n);
        let size = map.size();
        let mut m = 0.0f32;
        for y in 0..size.y {
            for x in 0..size.x {
                let h = map.height_m(x, y).unwrap();
                let hx = map.height_m((x + 1) % size.x, y).unwrap();
                let hy = map.height_m(x, (y + 1) % size.y).unwrap();
                m = m.max((hx - h).abs()).max((hy - h).abs());
            }
        }
        println!("{n}: {}", m / map.texel_size());
    }
}
