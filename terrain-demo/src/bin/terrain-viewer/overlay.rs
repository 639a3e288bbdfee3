//! On-screen text (frame timings, modes): lines rasterised on the CPU with the public-domain
//! 8x8 glyphs of `font8x8` into an RGBA texture, uploaded when the text changes, and drawn as
//! one alpha-blended quad in the top-left corner by a tiny pipeline of its own.

use anyhow::Result;
use glam::Vec2;

/// Text the texture holds at most: columns and lines.
const COLS: u32 = 48;
const LINES: u32 = 6;
/// Pixels of a glyph cell (8 x 8 glyphs, 2 rows between lines) and of the margin.
const CELL: (u32, u32) = (8, 10);
const MARGIN: u32 = 4;
const TEX_W: u32 = COLS * CELL.0 + 2 * MARGIN;
const TEX_H: u32 = LINES * CELL.1 + 2 * MARGIN;
/// Background and text colours (straight alpha).
const BACKGROUND: [u8; 4] = [0, 0, 0, 150];
const INK: [u8; 4] = [255, 255, 255, 255];

const SHADER: &str = r"
struct Quad {
    // Top-left corner and size in clip space; the part of the texture that holds text.
    origin: vec2<f32>,
    size: vec2<f32>,
    uv_max: vec2<f32>,
    _pad: vec2<f32>,
};
@group(0) @binding(0) var<uniform> quad: Quad;
@group(0) @binding(1) var text: texture_2d<f32>;
@group(0) @binding(2) var nearest: sampler;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VsOut {
    let corner = vec2<f32>(f32(i & 1u), f32(i >> 1u));
    var out: VsOut;
    out.position = vec4<f32>(quad.origin + corner * quad.size, 0.0, 1.0);
    out.uv = corner * quad.uv_max;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    return textureSample(text, nearest, in.uv);
}
";

/// The quad's uniform block, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct QuadUniform {
    origin: [f32; 2],
    size: [f32; 2],
    uv_max: [f32; 2],
    _pad: [f32; 2],
}

/// Rasterises `lines` into a `TEX_W x TEX_H` RGBA image; returns it and the pixels used
/// (width, height). Characters past [`COLS`] and lines past [`LINES`] are cut; characters
/// outside ASCII show as `?`.
pub fn rasterise(lines: &[String]) -> (Vec<u8>, (u32, u32)) {
    let mut pixels = vec![0u8; (TEX_W * TEX_H * 4) as usize];
    let cols = lines
        .iter()
        .take(LINES as usize)
        .map(|l| l.chars().count().min(COLS as usize) as u32)
        .max()
        .unwrap_or(0);
    let rows = lines.len().min(LINES as usize) as u32;
    let used = (cols * CELL.0 + 2 * MARGIN, rows * CELL.1 + 2 * MARGIN - 2);
    for y in 0..used.1 {
        for x in 0..used.0 {
            let i = ((y * TEX_W + x) * 4) as usize;
            pixels[i..i + 4].copy_from_slice(&BACKGROUND);
        }
    }
    for (row, line) in lines.iter().take(LINES as usize).enumerate() {
        for (col, ch) in line.chars().take(COLS as usize).enumerate() {
            let code = if ch.is_ascii() {
                ch as usize
            } else {
                '?' as usize
            };
            let glyph = font8x8::legacy::BASIC_LEGACY[code];
            let (x0, y0) = (MARGIN + col as u32 * CELL.0, MARGIN + row as u32 * CELL.1);
            for (gy, bits) in glyph.iter().enumerate() {
                for gx in 0..8u32 {
                    // Bit 0 is the glyph's leftmost pixel.
                    if bits & (1 << gx) != 0 {
                        let i = (((y0 + gy as u32) * TEX_W + x0 + gx) * 4) as usize;
                        pixels[i..i + 4].copy_from_slice(&INK);
                    }
                }
            }
        }
    }
    (pixels, used)
}

/// The overlay: its texture, pipeline and the text last uploaded.
#[derive(Debug)]
pub struct Overlay {
    pipeline: wgpu::RenderPipeline,
    texture: wgpu::Texture,
    uniform: wgpu::Buffer,
    group: wgpu::BindGroup,
    lines: Vec<String>,
    used: (u32, u32),
}

impl Overlay {
    /// Builds the pipeline for passes of `color` format (no depth, one sample).
    pub fn new(device: &wgpu::Device, color: wgpu::TextureFormat) -> Result<Self> {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("viewer overlay"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("viewer overlay text"),
            size: wgpu::Extent3d {
                width: TEX_W,
                height: TEX_H,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("viewer overlay quad"),
            size: std::mem::size_of::<QuadUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("viewer overlay"),
            ..Default::default()
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("viewer overlay"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleStrip,
                ..Default::default()
            },
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: color,
                    blend: Some(wgpu::BlendState::ALPHA_BLENDING),
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let view = texture.create_view(&Default::default());
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("viewer overlay"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&sampler),
                },
            ],
        });
        Ok(Self {
            pipeline,
            texture,
            uniform,
            group,
            lines: Vec::new(),
            used: (0, 0),
        })
    }

    /// Uploads `lines` when they differ from the text shown.
    pub fn set_text(&mut self, queue: &wgpu::Queue, lines: Vec<String>) {
        if lines == self.lines {
            return;
        }
        let (pixels, used) = rasterise(&lines);
        queue.write_texture(
            self.texture.as_image_copy(),
            &pixels,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(TEX_W * 4),
                rows_per_image: Some(TEX_H),
            },
            wgpu::Extent3d {
                width: TEX_W,
                height: TEX_H,
                depth_or_array_layers: 1,
            },
        );
        self.lines = lines;
        self.used = used;
    }

    /// Writes the quad for a target of `size` pixels: text pixels at 1:1, or 2:1 on targets
    /// at least 1200 pixels wide.
    pub fn prepare(&self, queue: &wgpu::Queue, size: Vec2) {
        let scale = if size.x >= 1200.0 { 2.0 } else { 1.0 };
        let used = Vec2::new(self.used.0 as f32, self.used.1 as f32);
        let quad = QuadUniform {
            origin: [-1.0, 1.0],
            size: [
                2.0 * used.x * scale / size.x,
                -2.0 * used.y * scale / size.y,
            ],
            uv_max: [used.x / TEX_W as f32, used.y / TEX_H as f32],
            _pad: [0.0; 2],
        };
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&quad));
    }

    /// Records the quad into `pass` (nothing before the first text).
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        if self.lines.is_empty() {
            return;
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.group, &[]);
        pass.draw(0..4, 0..1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_ink_on_a_box_that_fits_it() {
        let (pixels, used) = rasterise(&["Hi".to_string(), "fps 60".to_string()]);
        assert_eq!(used, (6 * 8 + 8, 2 * 10 + 6));
        let at = |x: u32, y: u32| {
            let i = ((y * TEX_W + x) * 4) as usize;
            [pixels[i], pixels[i + 1], pixels[i + 2], pixels[i + 3]]
        };
        let ink = (0..used.1)
            .flat_map(|y| (0..used.0).map(move |x| (x, y)))
            .filter(|&(x, y)| at(x, y) == INK)
            .count();
        assert!(ink > 40, "{ink} ink pixels");
        assert_eq!(at(0, 0), BACKGROUND);
        assert_eq!(at(used.0 + 1, 0), [0; 4]);
    }
}
