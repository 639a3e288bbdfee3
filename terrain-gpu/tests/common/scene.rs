//! A small closed test scene shared by the render tests and the golden-image example.

use glam::{UVec2, Vec2, Vec3};
use terrain_core::{CoarseMap, Grid, HeightEncoding, TerrainParams, generate_coarse_map};
use terrain_gpu::{
    Camera, ClipmapRenderer, ClipmapSurface, ClipmapView, DetailShading, GpuContext,
    GpuDerivativeMap, GpuDetailTiles, GpuHeightMap, NormalPass, OffscreenTarget, SkyColors,
    SkyPass, TargetFormat, TerrainStyle,
};
use terrain_lod::{ClipmapLayout, Frustum};

/// Heights of the scene span 0..HEIGHT metres.
pub const HEIGHT: f32 = 40.0;

/// The scene: a 256 x 256 procedural coarse-map at 1 m per texel on the GPU, a small clipmap
/// (N = 31, so many level boundaries are on screen) and the passes.
pub struct Scene {
    pub ctx: GpuContext,
    pub map: CoarseMap,
    pub gpu_map: GpuHeightMap<u16>,
    pub normals: GpuDerivativeMap,
    pub layout: ClipmapLayout,
    pub sky: SkyPass,
    pub renderer: ClipmapRenderer,
    /// `TerrainStyle::hide_outside_map` of the views rendered.
    pub hide_outside: bool,
    /// A detail layer to draw the map with (`ClipmapSurface::Detail`), if any.
    pub detail: Option<(GpuDetailTiles, DetailShading)>,
}

impl Scene {
    pub fn new(ctx: GpuContext, n: u32, levels: u32) -> Scene {
        let params = TerrainParams {
            size: UVec2::splat(256),
            seed: 11,
            octaves: 5,
            ..TerrainParams::default()
        };
        let enc = HeightEncoding::spanning::<u16>(0.0, HEIGHT).unwrap();
        let map = generate_coarse_map(&params, enc, 1.0).unwrap();
        let (device, queue) = (&ctx.device, &ctx.queue);
        let gpu_map = GpuHeightMap::from_map(device, queue, &map).unwrap();
        let normals = GpuDerivativeMap::for_map(device, &gpu_map).unwrap();
        let mut pass = NormalPass::new(device).unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        pass.encode_full(device, queue, &mut encoder, &gpu_map, &normals)
            .unwrap();
        queue.submit([encoder.finish()]);
        let layout = ClipmapLayout::new(n, levels).unwrap();
        let sky = SkyPass::new(device, &TargetFormat::CAPTURE).unwrap();
        let renderer = ClipmapRenderer::new(device, &TargetFormat::CAPTURE, &layout).unwrap();
        Scene {
            ctx,
            map,
            gpu_map,
            normals,
            layout,
            sky,
            renderer,
            hide_outside: false,
            detail: None,
        }
    }

    /// Ground height (m) under a world position.
    pub fn ground(&self, xz: Vec2) -> f32 {
        terrain_core::bilinear(&self.map, xz).unwrap()
    }

    /// Writes the uniforms of one view of `camera` on a target of `size` with `sky` colours
    /// (for [`Scene::draw`]); returns the triangle count of the placed frame.
    pub fn prepare(&mut self, camera: &Camera, size: UVec2, sky: &SkyColors) -> u64 {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let aspect = size.x as f32 / size.y as f32;
        let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
        let frame = self
            .layout
            .place(
                Vec2::new(camera.position.x, camera.position.z),
                1.0,
                (0.0, HEIGHT),
                Some(&frustum),
            )
            .unwrap();
        let style = TerrainStyle {
            ramp: (0.0, HEIGHT),
            hide_outside_map: self.hide_outside,
            ..TerrainStyle::default()
        };
        self.sky
            .prepare(queue, camera.view_proj_relative(aspect), sky)
            .unwrap();
        let surface = match &self.detail {
            Some((detail, shading)) => ClipmapSurface::Detail {
                map: &self.gpu_map,
                normals: &self.normals,
                detail,
                shading,
            },
            None => ClipmapSurface::Coarse {
                map: &self.gpu_map,
                normals: &self.normals,
            },
        };
        let view = ClipmapView {
            surface,
            frame: &frame,
            camera,
            style: &style,
            target_size: size,
        };
        self.renderer.prepare(device, queue, &view).unwrap();
        frame.triangle_count(self.layout.mesh())
    }

    /// Renders `camera` at `size` with `sky` colours through an [`OffscreenTarget`]; returns
    /// the image and the triangle count.
    pub fn render(
        &mut self,
        camera: &Camera,
        size: UVec2,
        sky: &SkyColors,
    ) -> (Grid<[u8; 4]>, u64) {
        let triangles = self.prepare(camera, size, sky);
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let target = OffscreenTarget::new(device, size).unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
            self.sky.draw(&mut pass);
            self.renderer.draw(&mut pass);
        }
        queue.submit([encoder.finish()]);
        let image = target.read_rgba8(device, queue).unwrap();
        self.ctx.check().expect("no GPU validation errors");
        (image, triangles)
    }
}

/// The fixed view of the golden image.
pub fn golden_camera(scene: &Scene) -> Camera {
    let xz = Vec2::new(100.3, 140.7);
    let eye = Vec3::new(xz.x, scene.ground(xz) + 25.0, xz.y);
    Camera::looking(eye, Vec3::new(1.0, -0.45, 0.6))
}

/// Size of the golden image.
pub const GOLDEN_SIZE: UVec2 = UVec2::new(192, 128);
