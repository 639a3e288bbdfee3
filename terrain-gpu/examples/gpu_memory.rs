//! GPU memory per texel of every per-texel resource of terrain-gpu, measured from the buffers
//! the resources really allocate on this device (not from a formula), beside the thesis formats.
//! `cargo xtask bench-report` appends its table to the report.
//!
//! ```sh
//! cargo run -p terrain-gpu --example gpu_memory -- [SIDE]   # default 1024
//! ```
//!
//! Bytes per texel do not depend on the side (a power of two: no row padding), so the default
//! keeps every buffer within wgpu's default 128 MiB binding; the report scales them to a
//! 4096^2 map.

use glam::UVec2;
use terrain_core::detail::DetailLayout;
use terrain_core::{HeightEncoding, TileLayout, WrapMode};
use terrain_gpu::GpuTessellation;
use terrain_gpu::granular::{GpuGranularNormals, GranularScratch};
use terrain_gpu::{
    AtlasConfig, GpuContext, GpuDensityMap, GpuDerivativeMap, GpuDetailTiles, GpuHeightMap,
    GpuTileAtlas,
};
use terrain_lod::{DensityParams, TessConfig, TessHierarchy};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let side: u32 = match std::env::args().nth(1) {
        Some(a) => a
            .parse()
            .map_err(|_| format!("SIDE must be a texel count, not {a:?}"))?,
        None => 1024,
    };
    // Past 2048 the granular normals and tessellation vertices (16 bytes a texel) outgrow
    // wgpu's default 128 MiB storage binding, which the headless context asks for.
    if !(64..=2048).contains(&side) || !side.is_power_of_two() {
        return Err("SIDE must be a power of two from 64 to 2048".into());
    }
    let ctx = GpuContext::new_headless()?;
    let (device, queue) = (&ctx.device, &ctx.queue);
    let size = UVec2::splat(side);
    let texels = f64::from(side) * f64::from(side);
    let enc = HeightEncoding::new(0.01, 0.0)?;
    let coarse =
        terrain_core::CoarseMap::coarse(terrain_core::Grid::new(side, side, 0u16)?, enc, 1.0)?;
    let heights = GpuHeightMap::from_map(device, queue, &coarse)?;
    let normals = GpuDerivativeMap::for_map(device, &heights)?;
    let per_coarse = heights.bytes_per_texel() + normals.bytes_per_texel();

    // A streamed world's atlas: 64 slots of 256^2 tiles.
    let world = TileLayout {
        world_size: size,
        tile_size: 256,
        levels: 1,
        texel_size: 1.0,
        encoding: enc,
        wrap: WrapMode::Clamp,
        fill: 0,
    };
    let atlas_config = AtlasConfig { slots: 64, world };
    let atlas = GpuTileAtlas::new(device, queue, &atlas_config)?;
    let atlas_texels = 64.0 * 256.0 * 256.0;

    // Detail tiles: 128^2 tiles, 32 slots.
    let layout = DetailLayout::new(size, 1.0, 4, 128)?;
    let detail = GpuDetailTiles::new(device, layout, 32)?;

    let density = GpuDensityMap::new(device, size, WrapMode::Clamp, DensityParams::default())?;

    // Granular deformation: u32 fixed-point heights, float normals, the step's scratch.
    let fixed = terrain_core::FixedPointMap::new(
        terrain_core::Grid::new(side, side, 0u32)?,
        HeightEncoding::new(1.0 / 10_000.0, 0.0)?,
        1.0,
        WrapMode::Clamp,
    )?;
    let granular = GpuHeightMap::from_map(device, queue, &fixed)?;
    let granular_normals = GpuGranularNormals::for_map(device, &granular)?;
    let columns = 242_064u64;
    let scratch = GranularScratch::new(device, columns)?;

    // Adaptive tessellation: its vertex grid over the map, and room for 2^16 triangles.
    let hierarchy = TessHierarchy::from_map(&coarse, None, TessConfig::default())?;
    let triangles = 1u32 << 16;
    let tess = GpuTessellation::new(device, queue, &hierarchy, triangles)?;
    let grid = hierarchy.grid_size();
    let vertices = f64::from(grid.x) * f64::from(grid.y);

    let rows: [(&str, f64, &str); 10] = [
        (
            "coarse heights (`GpuHeightMap<u16>`)",
            heights.bytes_per_texel(),
            "2 (Flower 2010, sec. 3.1.1: 16-bit)",
        ),
        (
            "coarse normals (`GpuDerivativeMap`)",
            normals.bytes_per_texel(),
            "2 (Flower 2010, sec. 3.1.2: `GL_RG8`)",
        ),
        (
            "streamed tile slots (`GpuTileAtlas`)",
            atlas.gpu_bytes() as f64 / atlas_texels,
            "2 (the coarse-map's 16 bits, Flower 2010)",
        ),
        (
            "detail tile slots (`GpuDetailTiles`)",
            detail.bytes_per_texel(),
            "1 (Flower 2010, sec. 2.3.1: 8-bit)",
        ),
        (
            "density map and pyramid (`GpuDensityMap`), per coarse texel",
            density.memory_bytes() as f64 / texels,
            "-",
        ),
        (
            "granular heights (`GpuHeightMap<u32>`)",
            granular.bytes_per_texel(),
            "4 (Persson 2019, sec. 4.3: 32-bit integer heights)",
        ),
        (
            "granular normals and height (`GpuGranularNormals`)",
            granular_normals.memory_bytes() as f64 / texels,
            "-",
        ),
        (
            "granular step scratch (`GranularScratch`), per active column",
            scratch.memory_bytes() as f64 / columns as f64,
            "-",
        ),
        (
            "tessellation vertices (`GpuTessellation`), per grid vertex",
            tess.vertex_bytes() as f64 / vertices,
            "-",
        ),
        (
            "tessellation output and level queues, per triangle of capacity",
            tess.triangle_bytes() as f64 / f64::from(triangles),
            "-",
        ),
    ];
    println!(
        "GPU memory on {} ({}), {side}^2 texels:\n",
        ctx.report().name,
        ctx.report().backend
    );
    println!("| resource | bytes per texel | thesis format (bytes) |\n|---|---|---|");
    for (what, bytes, thesis) in rows {
        println!("| {what} | {bytes:.2} | {thesis} |");
    }
    println!(
        "\nHeights + normals of the coarse-map: {per_coarse:.2} bytes per texel, {:.1} MiB for a \
         4096^2 map.",
        per_coarse * 4096.0 * 4096.0 / (1 << 20) as f64
    );
    let materials = terrain_gpu::GpuMaterials::procedural(&ctx.device, &ctx.queue)?;
    println!(
        "The material images (`GpuMaterials::procedural`, four 128^2 albedo and normal layers \
         with mips): {} KiB per renderer, whatever the map's size.",
        materials.bytes() >> 10
    );
    Ok(())
}
