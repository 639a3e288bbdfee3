//! [`GpuMaterials`]: the surface materials' images as two texture arrays (albedo as sRGB
//! bytes, tangent-space normals) with their mip chains and one repeating sampler, bound by every
//! terrain renderer at 10, 11 and 12, and [`GpuColorLayer`], an image drawn over a map (an
//! orthophoto), at 13. [`MaterialStyle`] and [`SurfaceShading`] choose, per
//! [`crate::TerrainStyle`], whether a frame is shaded by the height ramp or by the materials,
//! weighted by the autoshader (`terrain_core::material`).
//!
//! Textures rather than storage buffers (unlike the heights): the images are only sampled,
//! and hardware filtering with mips is what keeps a repeated image from shimmering far away.

use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::resources::hole_mask::GpuHoleMask;
use crate::resources::material_layer::GpuMaterialLayer;
use crate::resources::overlay_atlas::{GpuOverlayAtlas, OverlayViews, write_rows};
use crate::resources::window::{WindowOrigin, covered, planned_move, upload_pieces};
use terrain_core::{AutoshadeParams, CoreError, MATERIALS, MaterialImages, MaterialTextures};

/// How the renderers colour the surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum SurfaceShading {
    /// A colour ramp over height, rock on steep slopes: no images, the cheapest.
    #[default]
    Ramp,
    /// The four materials' images ([`GpuMaterials`]), weighted by the autoshader from height,
    /// slope and curvature, projected from three sides on steep ground.
    Materials,
}

/// How the materials are laid on the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields, default))]
pub struct MaterialStyle {
    /// Metres one material image covers before it repeats.
    pub scale_m: f32,
    /// How strongly the images' normals bend the surface's (0: not at all; at most 4).
    pub normal_strength: f32,
    /// Where each material goes.
    pub autoshade: AutoshadeParams,
}

impl Default for MaterialStyle {
    fn default() -> Self {
        Self {
            scale_m: 4.0,
            normal_strength: 0.6,
            autoshade: AutoshadeParams::default(),
        }
    }
}

impl MaterialStyle {
    /// Fails on a repeat outside (0, 1e6] m, a strength outside [0, 4] or bad autoshade edges.
    pub fn validate(&self) -> Result<(), GpuError> {
        if !(self.scale_m > 0.0 && self.scale_m <= 1e6) {
            return Err(CoreError::OutOfRange {
                what: "material scale_m",
                value: f64::from(self.scale_m),
                expected: "metres in (0, 1e6]",
            }
            .into());
        }
        if !(0.0..=4.0).contains(&self.normal_strength) {
            return Err(CoreError::OutOfRange {
                what: "material normal_strength",
                value: f64::from(self.normal_strength),
                expected: "0 to 4",
            }
            .into());
        }
        Ok(self.autoshade.validate()?)
    }
}

/// Side of the procedural images [`GpuMaterials::procedural`] makes.
pub const PROCEDURAL_MATERIAL_SIZE: u32 = 128;

/// The materials on the GPU (see the module docs). Cloning shares the textures.
#[derive(Debug, Clone)]
pub struct GpuMaterials {
    albedo: wgpu::TextureView,
    normal: wgpu::TextureView,
    sampler: wgpu::Sampler,
    bytes: u64,
}

impl GpuMaterials {
    /// Uploads `textures` with their mip chains (albedo averaged in linear light).
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        textures: &MaterialTextures,
    ) -> Result<Self, GpuError> {
        let size = textures.size();
        let max = device.limits().max_texture_dimension_2d;
        if size > max {
            return Err(CoreError::OutOfRange {
                what: "material image side",
                value: f64::from(size),
                expected: "at most the device's max_texture_dimension_2d",
            }
            .into());
        }
        let mips = size.ilog2() + 1;
        // Every layer's mip chain, level by level.
        let chains: Vec<Vec<MaterialImages>> = textures
            .layers()
            .iter()
            .map(|layer| {
                let mut chain = vec![layer.clone()];
                for level in 1..mips {
                    let above = &chain[level as usize - 1];
                    chain.push(above.downsample(size >> (level - 1)));
                }
                chain
            })
            .collect();
        let make = |label, format, pick: fn(&MaterialImages) -> &Vec<[u8; 4]>| {
            let texture = scoped(device, label, || {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: size,
                        height: size,
                        depth_or_array_layers: MATERIALS as u32,
                    },
                    mip_level_count: mips,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                    view_formats: &[],
                })
            })?;
            for (layer, chain) in chains.iter().enumerate() {
                for (level, images) in chain.iter().enumerate() {
                    let side = (size >> level).max(1);
                    queue.write_texture(
                        wgpu::TexelCopyTextureInfo {
                            texture: &texture,
                            mip_level: level as u32,
                            origin: wgpu::Origin3d {
                                x: 0,
                                y: 0,
                                z: layer as u32,
                            },
                            aspect: wgpu::TextureAspect::All,
                        },
                        bytemuck::cast_slice(pick(images)),
                        wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(4 * side),
                            rows_per_image: Some(side),
                        },
                        wgpu::Extent3d {
                            width: side,
                            height: side,
                            depth_or_array_layers: 1,
                        },
                    );
                }
            }
            Ok::<_, GpuError>(texture.create_view(&wgpu::TextureViewDescriptor {
                label: Some(label),
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            }))
        };
        let albedo = make(
            "material albedo",
            // The renderers shade in display-referred values (target_color.wgsl): the sRGB
            // bytes are read as they are, not decoded to linear.
            wgpu::TextureFormat::Rgba8Unorm,
            |i| &i.albedo,
        )?;
        let normal = make("material normals", wgpu::TextureFormat::Rgba8Unorm, |i| {
            &i.normal
        })?;
        // Anisotropic filtering where the adapter has it: the images are seen at grazing
        // angles most of the time.
        let anisotropic = device.adapter_info().device_type.ne(&wgpu::DeviceType::Cpu);
        let sampler = scoped(device, "material sampler", || {
            device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("material sampler"),
                address_mode_u: wgpu::AddressMode::Repeat,
                address_mode_v: wgpu::AddressMode::Repeat,
                address_mode_w: wgpu::AddressMode::Repeat,
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                mipmap_filter: wgpu::MipmapFilterMode::Linear,
                anisotropy_clamp: if anisotropic { 8 } else { 1 },
                ..Default::default()
            })
        })?;
        // Two RGBA8 arrays with mip chains (4/3 of the top level).
        let bytes = 2 * MATERIALS as u64 * 4 * u64::from(size) * u64::from(size) * 4 / 3;
        Ok(Self {
            albedo,
            normal,
            sampler,
            bytes,
        })
    }

    /// The project's procedural materials ([`MaterialTextures::procedural`] at
    /// [`PROCEDURAL_MATERIAL_SIZE`]); what a renderer draws with until given others. The
    /// images are made once per process.
    pub fn procedural(device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Self, GpuError> {
        static IMAGES: std::sync::OnceLock<Result<MaterialTextures, CoreError>> =
            std::sync::OnceLock::new();
        let textures = IMAGES
            .get_or_init(|| MaterialTextures::procedural(PROCEDURAL_MATERIAL_SIZE))
            .as_ref()
            .map_err(|e| GpuError::Core(e.clone()))?;
        Self::new(device, queue, textures)
    }

    /// GPU bytes of the images and their mips.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The bind group entries at 10, 11 and 12 of every terrain pipeline.
    pub(crate) fn entries(&self) -> [wgpu::BindGroupEntry<'_>; 3] {
        [
            wgpu::BindGroupEntry {
                binding: 10,
                resource: wgpu::BindingResource::TextureView(&self.albedo),
            },
            wgpu::BindGroupEntry {
                binding: 11,
                resource: wgpu::BindingResource::TextureView(&self.normal),
            },
            wgpu::BindGroupEntry {
                binding: 12,
                resource: wgpu::BindingResource::Sampler(&self.sampler),
            },
        ]
    }
}

/// What a renderer's shading binds besides its surface: the materials, the colour layer, the
/// material layer and the hole mask.
#[derive(Debug, Clone)]
pub(crate) struct ShadingBindings {
    pub(crate) materials: GpuMaterials,
    /// The colour layer, or a one-texel stand-in.
    pub(crate) color: wgpu::TextureView,
    /// Whether a colour layer is drawn.
    pub(crate) has_color: bool,
    /// The material layer's texture, or the same stand-in.
    pub(crate) paint: wgpu::TextureView,
    /// Whether a material layer is drawn.
    pub(crate) has_paint: bool,
    /// The hole mask's texture, or the same stand-in.
    pub(crate) holes: wgpu::TextureView,
    /// Whether a hole mask is bound.
    pub(crate) has_holes: bool,
    /// The world cells it covers (origin x, z and size), for the frame uniform.
    pub(crate) hole_window: [i32; 4],
    /// The world cells the material layer covers, likewise.
    pub(crate) paint_window: [i32; 4],
    /// The world cells the colour layer covers, likewise.
    pub(crate) color_window: [i32; 4],
    /// A streamed world's paint and colour ([`GpuOverlayAtlas`]): slots and table of each, or
    /// stand-ins (an empty table: nothing resident).
    pub(crate) streamed: [wgpu::TextureView; 4],
    /// Which are streamed: bit 1 paint, bit 2 colour (`color_layer.w` in the shader).
    pub(crate) streamed_bits: u32,
}

impl ShadingBindings {
    /// The bind group entries at 10 to 19 of every terrain pipeline.
    pub(crate) fn entries(&self) -> [wgpu::BindGroupEntry<'_>; 10] {
        let [a, n, s] = self.materials.entries();
        let streamed = |i: usize| wgpu::BindGroupEntry {
            binding: 16 + i as u32,
            resource: wgpu::BindingResource::TextureView(&self.streamed[i]),
        };
        [
            a,
            n,
            s,
            wgpu::BindGroupEntry {
                binding: 13,
                resource: wgpu::BindingResource::TextureView(&self.color),
            },
            wgpu::BindGroupEntry {
                binding: 14,
                resource: wgpu::BindingResource::TextureView(&self.paint),
            },
            wgpu::BindGroupEntry {
                binding: 15,
                resource: wgpu::BindingResource::TextureView(&self.holes),
            },
            streamed(0),
            streamed(1),
            streamed(2),
            streamed(3),
        ]
    }

    /// The frame uniform's flags of the three layers (`color_layer.x`, `.y` and `.z` in the
    /// shader).
    pub(crate) fn layer_flags(&self) -> [f32; 4] {
        let on = |b: bool| f32::from(u8::from(b));
        [
            on(self.has_color || self.streamed_bits & 2 != 0),
            on(self.has_paint || self.streamed_bits & 1 != 0),
            on(self.has_holes),
            self.streamed_bits as f32,
        ]
    }
}

/// The materials a renderer binds: the caller's ([`MaterialSlot::set`]), or the procedural
/// set made on its first frame; and the colour and material layers and the hole mask, if any.
#[derive(Debug, Default)]
pub(crate) struct MaterialSlot {
    materials: Option<GpuMaterials>,
    color: Option<GpuColorLayer>,
    paint: Option<GpuMaterialLayer>,
    holes: Option<GpuHoleMask>,
    /// A streamed world's paint and colour (views of their atlases).
    streamed_paint: Option<OverlayViews>,
    streamed_color: Option<OverlayViews>,
    /// Bound while no colour or material layer or hole mask is.
    no_color: Option<wgpu::TextureView>,
    /// Bound while no streamed layer is: an empty slot array and a table of zeros.
    no_streamed: Option<[wgpu::TextureView; 2]>,
    /// Set since the renderer last bound them.
    changed: bool,
}

impl MaterialSlot {
    /// Binds what `other` binds (materials, colour and material layers, hole mask, streamed
    /// paint and colour) from the next frame on: a renderer that replaces another over the
    /// same surface.
    pub(crate) fn adopt(&mut self, other: &MaterialSlot) {
        self.materials.clone_from(&other.materials);
        self.color.clone_from(&other.color);
        self.paint.clone_from(&other.paint);
        self.holes.clone_from(&other.holes);
        self.streamed_paint.clone_from(&other.streamed_paint);
        self.streamed_color.clone_from(&other.streamed_color);
        self.changed = true;
    }

    /// Binds `materials` from the next frame on.
    pub(crate) fn set(&mut self, materials: &GpuMaterials) {
        self.materials = Some(materials.clone());
        self.changed = true;
    }

    /// Draws `color` (or no colour layer) from the next frame on.
    pub(crate) fn set_color(&mut self, color: Option<&GpuColorLayer>) {
        self.color = color.cloned();
        self.changed = true;
    }

    /// Draws `layer`'s painted weights (or none) from the next frame on.
    pub(crate) fn set_paint(&mut self, layer: Option<&GpuMaterialLayer>) {
        self.paint = layer.cloned();
        self.changed = true;
    }

    /// Leaves out the cells `mask` marks (or none) from the next frame on.
    pub(crate) fn set_holes(&mut self, mask: Option<&GpuHoleMask>) {
        self.holes = mask.cloned();
        self.changed = true;
    }

    /// Draws a streamed world's paint and colour (or none) from the next frame on, instead of
    /// the material and colour layers.
    pub(crate) fn set_streamed(
        &mut self,
        paint: Option<&GpuOverlayAtlas>,
        color: Option<&GpuOverlayAtlas>,
    ) {
        self.streamed_paint = paint.map(GpuOverlayAtlas::views);
        self.streamed_color = color.map(GpuOverlayAtlas::views);
        self.changed = true;
    }

    /// What to bind for a surface of `surface_size` texels (the materials made on first use;
    /// clones share the GPU objects), and whether it changed since the last call (the bind
    /// group must be made again). A colour or material layer of another size is refused.
    pub(crate) fn get(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        surface_size: glam::UVec2,
    ) -> Result<(ShadingBindings, bool), GpuError> {
        let sizes = [
            self.color
                .as_ref()
                .filter(|c| !c.is_window())
                .map(|c| c.size),
            self.paint
                .as_ref()
                .filter(|p| !p.is_window())
                .map(|p| p.size),
            // A window follows the camera over a larger surface; a whole-map mask must match.
            self.holes
                .as_ref()
                .filter(|h| !h.is_window())
                .map(|h| h.size),
        ];
        let streamed_sizes =
            [&self.streamed_paint, &self.streamed_color].map(|a| a.as_ref().map(|a| a.world_size));
        if let Some(actual) = sizes
            .into_iter()
            .chain(streamed_sizes)
            .flatten()
            .find(|s| *s != surface_size)
        {
            return Err(CoreError::SizeMismatch {
                expected: surface_size,
                actual,
            }
            .into());
        }
        let materials = match self.materials.take() {
            Some(m) => m,
            None => GpuMaterials::procedural(device, queue)?,
        };
        let materials = self.materials.insert(materials).clone();
        let stand_in = match &self.no_color {
            Some(stand_in) => stand_in.clone(),
            None => {
                let stand_in =
                    rgba8_texture(device, queue, "no layer", glam::UVec2::ONE, &[[0; 4]])?;
                self.no_color.insert(stand_in).clone()
            }
        };
        let [no_slots, no_table] = match &self.no_streamed {
            Some(views) => views.clone(),
            None => self.no_streamed.insert(no_streamed(device, queue)?).clone(),
        };
        let bindings = ShadingBindings {
            materials,
            color: self
                .color
                .as_ref()
                .map_or(stand_in.clone(), |c| c.view.clone()),
            has_color: self.color.is_some(),
            paint: self
                .paint
                .as_ref()
                .map_or(stand_in.clone(), |p| p.view.clone()),
            has_paint: self.paint.is_some(),
            holes: self.holes.as_ref().map_or(stand_in, |h| h.view.clone()),
            has_holes: self.holes.is_some(),
            hole_window: self.holes.as_ref().map_or([0; 4], |h| h.covered()),
            paint_window: self.paint.as_ref().map_or([0; 4], |p| p.covered()),
            color_window: self.color.as_ref().map_or([0; 4], |c| c.covered()),
            streamed: [
                self.streamed_paint
                    .as_ref()
                    .map_or(no_slots.clone(), |a| a.slots.clone()),
                self.streamed_paint
                    .as_ref()
                    .map_or(no_table.clone(), |a| a.table.clone()),
                self.streamed_color
                    .as_ref()
                    .map_or(no_slots, |a| a.slots.clone()),
                self.streamed_color
                    .as_ref()
                    .map_or(no_table, |a| a.table.clone()),
            ],
            streamed_bits: u32::from(self.streamed_paint.is_some())
                | (u32::from(self.streamed_color.is_some()) << 1),
        };
        Ok((bindings, std::mem::take(&mut self.changed)))
    }
}

/// The layout entries of [`ShadingBindings::entries`] (fragment stage).
pub(crate) fn layout_entries() -> [wgpu::BindGroupLayoutEntry; 10] {
    let texture = |binding, view_dimension| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: true },
            view_dimension,
            multisampled: false,
        },
        count: None,
    };
    let layer = |binding| texture(binding, wgpu::TextureViewDimension::D2);
    let table = |binding| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    };
    [
        texture(10, wgpu::TextureViewDimension::D2Array),
        texture(11, wgpu::TextureViewDimension::D2Array),
        wgpu::BindGroupLayoutEntry {
            binding: 12,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
            count: None,
        },
        layer(13),
        layer(14),
        layer(15),
        texture(16, wgpu::TextureViewDimension::D2Array),
        table(17),
        texture(18, wgpu::TextureViewDimension::D2Array),
        table(19),
    ]
}

/// The stand-ins of a streamed layer (read only where its flag is set, so never): one
/// transparent slot, and a table of one level-0 tile with nothing resident.
fn no_streamed(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
) -> Result<[wgpu::TextureView; 2], GpuError> {
    // Two layers, as GpuOverlayAtlas's (GL reads no array of one); a new texture is zero.
    let slots = scoped(device, "no streamed layer", || {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("no streamed layer"),
            size: wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 2,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
    })?;
    let slots = slots.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    let table = scoped(device, "no streamed table", || {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("no streamed table"),
            size: wgpu::Extent3d {
                width: 3,
                height: 2,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Uint,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        })
    })?;
    let none = terrain_core::INVALID_SLOT;
    write_rows(queue, &table, 0, &[0u32, 1, 1, none, none, none], 3);
    Ok([
        slots,
        table.create_view(&wgpu::TextureViewDescriptor::default()),
    ])
}

/// The frame uniform's material fields: the camera's whole texel's place in the images'
/// repeat and the repeats per metre, the strength; the autoshade edges; the dirt edges,
/// whether materials shade and the curvature's spacing in texels; the colour layer's flag
/// (0 here: see `FrameUniform::set_color_layer`). Computed in f64 so the repeat stays exact far from the origin.
pub(crate) fn frame_fields(
    shading: SurfaceShading,
    style: &MaterialStyle,
    camera_texel: [i32; 2],
    texel_size: f32,
) -> Result<[[f32; 4]; 4], GpuError> {
    style.validate()?;
    let per_m = 1.0 / f64::from(style.scale_m);
    let origin = |t: i32| (f64::from(t) * f64::from(texel_size) * per_m).rem_euclid(1.0) as f32;
    let a = style.autoshade;
    Ok([
        [
            origin(camera_texel[0]),
            origin(camera_texel[1]),
            per_m as f32,
            style.normal_strength,
        ],
        [
            a.rock_slope.0,
            a.rock_slope.1,
            a.snow_height.0,
            a.snow_height.1,
        ],
        [
            a.dirt_curvature.0,
            a.dirt_curvature.1,
            f32::from(u8::from(shading == SurfaceShading::Materials)),
            // Whole texels, from one to the stencil's reach (the spacing is validated finite).
            (a.curvature_spacing_m / texel_size)
                .round()
                .clamp(1.0, crate::render::surface::MAX_CURVATURE_STEP),
        ],
        // Whether a colour layer is drawn: set by the renderer that binds one.
        [0.0; 4],
    ])
}

/// A colour layer over a map (an orthophoto beside a DEM): one RGBA8 texel per map texel, in
/// sRGB as the image holds it, drawn as the surface's albedo in place of the materials' or
/// the ramp's (the materials' normals still bend the light). A texture read texel by texel
/// (bilinear in the shader, wrapped like the heights): storage buffers per shader stage are
/// few on some devices, and the detail surface already uses four.
///
/// A streamed world's colour (its `Layer::Color` tiles) is drawn through a window of cells
/// around the camera ([`GpuColorLayer::window`], placed by [`GpuColorLayer::move_window`], as
/// the material layer's), over the materials by its alpha and faded out towards its edges.
#[derive(Debug, Clone)]
pub struct GpuColorLayer {
    view: wgpu::TextureView,
    texture: wgpu::Texture,
    size: glam::UVec2,
    /// A window's origin, or `None` for the whole map's layer.
    origin: Option<WindowOrigin>,
}

impl GpuColorLayer {
    /// Uploads `colors` (row-major, one `[r, g, b, a]` per map texel). Fails on a side above
    /// the device's `max_texture_dimension_2d`.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        colors: &terrain_core::Grid<[u8; 4]>,
    ) -> Result<Self, GpuError> {
        let size = glam::UVec2::new(colors.width(), colors.height());
        let max = device.limits().max_texture_dimension_2d;
        if size.max_element() > max {
            return Err(CoreError::OutOfRange {
                what: "colour layer side",
                value: f64::from(size.max_element()),
                expected: "at most the device's max_texture_dimension_2d",
            }
            .into());
        }
        let (texture, view) = rgba8_texture_with(
            device,
            queue,
            "colour layer",
            size,
            colors.as_slice(),
            wgpu::TextureUsages::empty(),
        )?;
        Ok(Self {
            view,
            texture,
            size,
            origin: None,
        })
    }

    /// A window of `side` x `side` cells over a larger world: transparent, and covering no
    /// cell until [`GpuColorLayer::move_window`] places it. Fails on a side of 0 or above the
    /// device's `max_texture_dimension_2d`.
    pub fn window(device: &wgpu::Device, queue: &wgpu::Queue, side: u32) -> Result<Self, GpuError> {
        if side == 0 {
            return Err(CoreError::OutOfRange {
                what: "colour window side",
                value: 0.0,
                expected: "at least 1 cell",
            }
            .into());
        }
        // Checked before the cells are allocated.
        if side > device.limits().max_texture_dimension_2d {
            return Err(CoreError::OutOfRange {
                what: "colour window side",
                value: f64::from(side),
                expected: "at most the device's max_texture_dimension_2d",
            }
            .into());
        }
        let clear = terrain_core::Grid::new(side, side, [0u8; 4])?;
        Ok(Self {
            origin: Some(WindowOrigin::unset()),
            ..Self::new(device, queue, &clear)?
        })
    }

    /// Whether this is a window ([`GpuColorLayer::window`]).
    pub fn is_window(&self) -> bool {
        self.origin.is_some()
    }

    /// The world cells it covers: origin (x, z) and size. A window covers none (size 0) until
    /// its first [`GpuColorLayer::move_window`].
    pub fn covered(&self) -> [i32; 4] {
        covered(self.origin.as_ref(), self.size)
    }

    /// Places a window at world cell `origin` with `colors`, the colour layer of the cells
    /// `origin .. origin + side` (as `terrain_cache::read_color` returns it), drawn from the
    /// next submission on. Fails, with nothing changed, on the whole map's layer, on colours
    /// of another size than the window and on an origin whose window would leave `i32`.
    pub fn move_window(
        &self,
        queue: &wgpu::Queue,
        origin: glam::IVec2,
        colors: &terrain_core::Grid<[u8; 4]>,
    ) -> Result<(), GpuError> {
        let (at, pieces) = planned_move(
            self.origin.as_ref(),
            "colour layer to move",
            self.size,
            origin,
            colors.size(),
        )?;
        upload_pieces(
            queue,
            &self.texture,
            colors.as_slice(),
            self.size.x,
            &pieces,
        );
        at.set(origin);
        Ok(())
    }

    /// The layer's size in texels (the map's it is drawn over).
    pub fn size(&self) -> glam::UVec2 {
        self.size
    }

    /// GPU bytes: 4 per texel.
    pub fn bytes(&self) -> u64 {
        4 * u64::from(self.size.x) * u64::from(self.size.y)
    }
}

/// A 2D `Rgba8Unorm` texture of `size` holding `texels`, and its view.
fn rgba8_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &'static str,
    size: glam::UVec2,
    texels: &[[u8; 4]],
) -> Result<wgpu::TextureView, GpuError> {
    rgba8_texture_with(
        device,
        queue,
        label,
        size,
        texels,
        wgpu::TextureUsages::empty(),
    )
    .map(|(_, view)| view)
}

/// [`rgba8_texture`] with `usage` besides sampling and uploads, and the texture itself.
pub(crate) fn rgba8_texture_with(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &'static str,
    size: glam::UVec2,
    texels: &[[u8; 4]],
    usage: wgpu::TextureUsages,
) -> Result<(wgpu::Texture, wgpu::TextureView), GpuError> {
    let extent = wgpu::Extent3d {
        width: size.x,
        height: size.y,
        depth_or_array_layers: 1,
    };
    let texture = scoped(device, label, || {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST | usage,
            view_formats: &[],
        })
    })?;
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        bytemuck::cast_slice(texels),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(4 * size.x),
            rows_per_image: Some(size.y),
        },
        extent,
    );
    let view = texture.create_view(&Default::default());
    Ok((texture, view))
}
