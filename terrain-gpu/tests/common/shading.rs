//! The render tests' shading scene: a cliff between a lowland and a highland, solid-colour
//! materials, one top-down frame per LOD mode, and the colour of the pixels over a map point.

#![allow(dead_code)] // Each test binary uses its own share.

use glam::{UVec2, Vec3};
use terrain_core::{
    CoarseMap, Grid, HeightEncoding, MATERIALS, MaterialImages, MaterialTextures, WrapMode,
};
use terrain_gpu::{
    ClipmapSurface, GpuContext, GpuDerivativeMap, GpuHeightMap, MaterialStyle, NormalPass,
    OffscreenTarget, SurfaceShading, TargetFormat, TerrainRenderer, TerrainStyle, TerrainView,
    ViewMatrices,
};
use terrain_lod::{CdlodConfig, ClipmapLayout, LodMetric, TessConfig};

pub const SIZE: UVec2 = UVec2::new(320, 180);
pub const MAP: u32 = 256;
/// The lowland's and the highland's heights; the ramp spans 0..40 m.
pub const LOW: f32 = 6.0;
pub const HIGH: f32 = 38.0;
/// The cliff between them rises over these columns (slope 32 / 16 = 2: all rock).
pub const CLIFF: (u32, u32) = (120, 136);

/// Lowland west of the cliff, highland east of it; the same along z.
pub fn cliff_map() -> CoarseMap {
    let enc = HeightEncoding::spanning::<u16>(0.0, 40.0).expect("range");
    let grid = Grid::from_fn(MAP, MAP, |x, _| {
        let f = ((x as f32 - CLIFF.0 as f32) / (CLIFF.1 - CLIFF.0) as f32).clamp(0.0, 1.0);
        enc.to_raw(LOW + (HIGH - LOW) * f).round() as u16
    })
    .expect("grid");
    CoarseMap::new(grid, enc, 1.0, WrapMode::Clamp).expect("map")
}

/// Solid-colour materials (flat normals), one distinct colour each.
pub const SOLID: [[u8; 4]; MATERIALS] = [
    [200, 40, 40, 255],
    [40, 200, 40, 255],
    [40, 40, 200, 255],
    [220, 220, 60, 255],
];

pub fn solid_materials() -> MaterialTextures {
    let layers = SOLID
        .iter()
        .map(|&c| MaterialImages {
            albedo: vec![c; 16 * 16],
            normal: vec![[128, 128, 255, 255]; 16 * 16],
        })
        .collect();
    MaterialTextures::new(16, layers).expect("valid images")
}

/// The mean and the mean absolute deviation (sRGB bytes) of the pixels over map columns
/// `columns` (rows 30 to 30 from the bottom), in the top-down view of [`draw`].
pub fn region(image: &Grid<[u8; 4]>, columns: (u32, u32)) -> (Vec3, f32) {
    // The orthographic view spans map x 0..256 across the 320 pixels (0.8 m a pixel).
    let px = |x: u32| (x as f32 * SIZE.x as f32 / MAP as f32) as u32;
    let mut pixels = Vec::new();
    for y in 30..SIZE.y - 30 {
        for x in px(columns.0)..px(columns.1) {
            let p = image.get(x, y).expect("inside");
            pixels.push(Vec3::new(p[0].into(), p[1].into(), p[2].into()));
        }
    }
    let mean = pixels.iter().sum::<Vec3>() / pixels.len() as f32;
    let spread = pixels
        .iter()
        .map(|p| (*p - mean).abs().element_sum() / 3.0)
        .sum::<f32>()
        / pixels.len() as f32;
    (mean, spread)
}

/// One top-down frame of `renderer` over `map` with `shading`.
pub fn draw(
    ctx: &GpuContext,
    renderer: &mut TerrainRenderer,
    gpu: &(GpuHeightMap<u16>, GpuDerivativeMap),
    shading: SurfaceShading,
) -> Grid<[u8; 4]> {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let target = OffscreenTarget::new(device, SIZE).expect("target");
    // Straight down on the map's middle, 256 m x 144 m.
    let view = ViewMatrices {
        view: glam::camera::rh::view::look_to_mat4(
            Vec3::new(128.0, 300.0, 128.0),
            Vec3::NEG_Y,
            // Screen right is world +X.
            Vec3::NEG_Z,
        ),
        projection: glam::camera::rh::proj::directx::orthographic(
            -128.0, 128.0, -72.0, 72.0, 1.0, 1000.0,
        ),
    };
    let style = TerrainStyle {
        ramp: (0.0, 40.0),
        // From the west: the cliff (facing west) and the flats are both lit, and the flats'
        // specular reflection points away from the camera.
        light_dir: Vec3::new(-0.8, 0.6, 0.0),
        shading,
        materials: MaterialStyle {
            scale_m: 8.0,
            ..MaterialStyle::default()
        },
        ..TerrainStyle::default()
    };
    let terrain_view = TerrainView {
        surface: ClipmapSurface::Coarse {
            map: &gpu.0,
            normals: &gpu.1,
        },
        camera: &view,
        style: &style,
        target_size: SIZE,
    };
    let mut encoder = device.create_command_encoder(&Default::default());
    renderer
        .prepare(device, queue, &mut encoder, &terrain_view)
        .expect("prepare");
    {
        let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
        renderer.draw(&mut pass);
    }
    queue.submit([encoder.finish()]);
    renderer.recall();
    let image = target.read_rgba8(device, queue).expect("read back");
    ctx.check().expect("no GPU validation errors");
    image
}

/// The prepare of a default view of `renderer` over `map`: what a layer it cannot draw fails.
pub fn try_prepare(
    ctx: &GpuContext,
    renderer: &mut TerrainRenderer,
    gpu: &(GpuHeightMap<u16>, GpuDerivativeMap),
) -> Result<(), terrain_gpu::GpuError> {
    let view = ViewMatrices {
        view: glam::camera::rh::view::look_to_mat4(
            Vec3::new(128.0, 300.0, 128.0),
            Vec3::NEG_Y,
            Vec3::NEG_Z,
        ),
        projection: glam::camera::rh::proj::directx::perspective(1.0, 16.0 / 9.0, 1.0, 1000.0),
    };
    let style = TerrainStyle::default();
    let view = TerrainView {
        surface: ClipmapSurface::Coarse {
            map: &gpu.0,
            normals: &gpu.1,
        },
        camera: &view,
        style: &style,
        target_size: SIZE,
    };
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    renderer.prepare(&ctx.device, &ctx.queue, &mut encoder, &view)
}

pub fn renderers(ctx: &GpuContext, map: &CoarseMap) -> Vec<TerrainRenderer> {
    let (device, queue, format) = (&ctx.device, &ctx.queue, &TargetFormat::CAPTURE);
    let cdlod = CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 4,
        metric: LodMetric::Distance,
        ..CdlodConfig::default()
    };
    let layout = ClipmapLayout::new(63, 4).expect("layout");
    vec![
        TerrainRenderer::clipmap(device, format, layout, (0.0, 40.0)).expect("clipmap"),
        TerrainRenderer::cdlod(device, format, map, cdlod).expect("cdlod"),
        TerrainRenderer::tessellated(device, queue, format, map, TessConfig::default(), true)
            .expect("tessellated"),
    ]
}

pub fn upload(ctx: &GpuContext, map: &CoarseMap) -> (GpuHeightMap<u16>, GpuDerivativeMap) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let heights = GpuHeightMap::from_map(device, queue, map).expect("heights");
    let normals = GpuDerivativeMap::for_map(device, &heights).expect("normals");
    let mut pass = NormalPass::new(device).expect("normal pass");
    let mut encoder = device.create_command_encoder(&Default::default());
    pass.encode_full(device, queue, &mut encoder, &heights, &normals)
        .expect("normals");
    queue.submit([encoder.finish()]);
    (heights, normals)
}

/// A solid material's colour lit by diffuse `diffuse` (the shader's 0.28 ambient + 0.8
/// diffuse), in bytes: the renderers shade the images' sRGB values as they are.
pub fn lit(material: usize, diffuse: f32) -> Vec3 {
    let c = SOLID[material];
    Vec3::new(c[0].into(), c[1].into(), c[2].into()) * (0.28 + 0.8 * diffuse)
}

/// Texture filtering of a constant image returns the constant within the filter's weight
/// precision, and the 8-bit output rounds once: a few sRGB steps cover any conforming device.
pub const COLOUR_TOLERANCE: f32 = 4.0;

/// The mean colour of the pixels whose centres lie within `radius` pixels of map point
/// `(x, z)` in [`draw`]'s view (0.8 m a pixel; the view's top edge is z = 56).
pub fn around(image: &Grid<[u8; 4]>, x: f32, z: f32, radius: f32) -> Vec3 {
    let (cx, cy) = (x / 0.8, (z - 56.0) / 0.8);
    let mut sum = Vec3::ZERO;
    let mut n = 0.0;
    for y in 0..SIZE.y {
        for px in 0..SIZE.x {
            if (px as f32 + 0.5 - cx).hypot(y as f32 + 0.5 - cy) <= radius {
                let p = image.get(px, y).expect("inside");
                sum += Vec3::new(p[0].into(), p[1].into(), p[2].into());
                n += 1.0;
            }
        }
    }
    assert!(n > 0.0, "no pixel centre within {radius} px of ({x}, {z})");
    sum / n
}
