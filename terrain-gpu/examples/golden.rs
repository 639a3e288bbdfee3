//! Regenerates the golden image of the render test: `cargo xtask golden` (or
//! `cargo run -p terrain-gpu --example golden -- PATH`). The test never writes it.

#[path = "../tests/common/scene.rs"]
mod scene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "terrain-gpu/tests/data/golden_clipmap.png".into());
    let ctx = terrain_gpu::GpuContext::new_headless()?;
    eprintln!("rendering the golden view on {}", ctx.report().name);
    let mut scene = scene::Scene::new(ctx, 31, 5);
    let camera = scene::golden_camera(&scene);
    let (image, _) = scene.render(
        &camera,
        scene::GOLDEN_SIZE,
        &terrain_gpu::SkyColors::default(),
    );
    terrain_core::io::write_png_rgba8(&path, &image)?;
    eprintln!("wrote {path}");
    Ok(())
}
