//! What every terrain renderer (clipmap, CDLOD, tessellation) does the same way for its
//! surface: the surfaces themselves ([`ClipmapSurface`]: what is checked of each and which
//! buffers it binds where), the detail surfaces' uniform, written each frame and bound at 3
//! beside the detail tiles' 4 and 5, and how far beyond the drawn mesh a fragment may read
//! (the parallax march's reach). One place, so the three renderers shade a detail layer
//! identically.

use crate::error::GpuError;
use crate::resources::atlas::GpuTileAtlas;
use crate::resources::detail::{DetailInfo, DetailShading, GpuDetailTiles};
use crate::resources::maps::{GpuDerivativeMap, GpuHeightMap};
use glam::{IVec2, UVec2};
use terrain_core::WrapMode;

/// The detail surface's per-frame uniform of one renderer.
#[derive(Debug)]
pub(crate) struct DetailUniform {
    buffer: wgpu::Buffer,
}

impl DetailUniform {
    /// The (empty) uniform buffer; written by [`DetailUniform::surface_buffers`].
    pub(crate) fn new(device: &wgpu::Device, label: &'static str) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: std::mem::size_of::<DetailInfo>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }

    /// The buffers `surface` binds, with their bindings: for a surface with detail tiles this
    /// uniform, written for a camera at coarse texel `camera_texel`, goes at 3 beside the
    /// tiles' 4 and 5; other surfaces bind their own buffers only. Fails on shading out of
    /// range.
    pub(crate) fn surface_buffers(
        &self,
        queue: &wgpu::Queue,
        surface: &ClipmapSurface<'_>,
        texel_size: f32,
        camera_texel: IVec2,
    ) -> Result<BoundBuffers, GpuError> {
        let mut buffers = surface.buffers();
        if let Some((detail, shading)) = surface.detail() {
            let reach = shading.check(texel_size)?;
            let info = detail.info(camera_texel, shading, reach)?;
            queue.write_buffer(&self.buffer, 0, bytemuck::bytes_of(&info));
            buffers.push((3, self.buffer.clone()));
        }
        Ok(buffers)
    }
}

/// Whole coarse texels a fragment of `surface` may read beyond the drawn mesh's own texels:
/// the material shading's curvature stencil ([`MATERIAL_REACH`]), plus for a detail surface
/// the parallax march's reach and one for the bilinear neighbour.
pub(crate) fn fragment_reach(surface: &ClipmapSurface<'_>) -> i32 {
    MATERIAL_REACH
        + match surface {
            ClipmapSurface::Detail { shading, .. }
            | ClipmapSurface::AtlasDetail { shading, .. } => {
                shading.max_reach_texels.ceil() as i32 + 1
            }
            _ => 0,
        }
}

/// Texels the material shading reads around a fragment: its nearest texel (one past the
/// cell) and the curvature's neighbours at most [`MAX_CURVATURE_STEP`] beyond.
pub(crate) const MATERIAL_REACH: i32 = MAX_CURVATURE_STEP as i32 + 2;

/// The most texels between the heights the curvature is measured from.
pub(crate) const MAX_CURVATURE_STEP: f32 = 6.0;

/// `source` with an engine's `surface_weights` function (see
/// [`crate::TerrainRenderer::set_surface_shader`]) between its user markers, or `source` as it
/// is without one.
pub(crate) fn with_surface_weights(
    source: &'static str,
    user: Option<&str>,
) -> std::borrow::Cow<'static, str> {
    let Some(user) = user else {
        return source.into();
    };
    let (begin, end) = terrain_shaders::USER_SURFACE_MARKERS;
    // terrain-shaders' tests check every renderer's shader carries the markers once, in order;
    // a source without them is drawn as it is.
    match (source.find(begin), source.find(end)) {
        (Some(a), Some(b)) if a < b => {
            format!("{}{begin}\n{user}\n{}", &source[..a], &source[b..]).into()
        }
        _ => source.into(),
    }
}

/// The storage buffers a surface binds, with their bindings ([`ClipmapSurface::buffers`]).
pub(crate) type BoundBuffers = Vec<(u32, wgpu::Buffer)>;

/// Which pipeline a surface is drawn with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SurfaceKind {
    Coarse,
    Granular,
    Atlas,
    Detail,
    AtlasDetail,
}

/// The surface a clipmap displaces and lights. A repeating map wraps (toroidal coarse-map); a
/// clamped map extends its edge texels outwards.
#[derive(Debug, Clone, Copy)]
pub enum ClipmapSurface<'a> {
    /// A coarse-map and its partial-derivative normals ([`crate::NormalPass`]).
    Coarse {
        /// The heights.
        map: &'a GpuHeightMap<u16>,
        /// Their derivative normals (same size).
        normals: &'a GpuDerivativeMap,
    },
    /// A granular map drawn straight from [`crate::granular::GranularNormalsPass`]'s output
    /// (unit normal and float height in metres per texel, 16 bytes): nothing is uploaded.
    Granular {
        /// The fixed-point heights (their size, encoding, spacing and wrap; not read).
        map: &'a GpuHeightMap<u32>,
        /// The normal-and-height buffer of the map.
        surface: &'a wgpu::Buffer,
    },
    /// The resident tiles of a streamed world (Fikkan 2013, sec. 5.6): each texel from the finest
    /// level resident in the atlas (a missing tile shows as its coarser ancestor, never as a
    /// hole), the world clamped at its edges (or wrapped, as its layout says), normals by
    /// central differences of those heights.
    Atlas {
        /// The tile slots and indirection table.
        atlas: &'a GpuTileAtlas,
    },
    /// A coarse-map with a detail layer (Flower 2010, sec. 2.3): the coarse grid displaced by the
    /// coarse heights, each fragment shaded at the point a parallax march through the detail
    /// heights finds, with the composite normal of eq. 3.4 (coarse and detail gradients
    /// added) and the detail's height in the colour ramp, the detail faded out with distance.
    Detail {
        /// The heights.
        map: &'a GpuHeightMap<u16>,
        /// Their derivative normals (same size).
        normals: &'a GpuDerivativeMap,
        /// The detail tiles over `map` (their layout's coarse size and spacing are the map's).
        detail: &'a GpuDetailTiles,
        /// Fade distances and parallax march.
        shading: &'a DetailShading,
    },
    /// A streamed world's atlas (as [`ClipmapSurface::Atlas`]) with a detail layer over its
    /// level 0 (as [`ClipmapSurface::Detail`]): footprints in detail tiles drawn on a world
    /// larger than memory (Flower 2010, sec. 2.3 over Fikkan 2013's cache).
    AtlasDetail {
        /// The tile slots and indirection table.
        atlas: &'a GpuTileAtlas,
        /// The detail tiles over the world's level 0 (their layout's coarse size and spacing
        /// are the world's).
        detail: &'a GpuDetailTiles,
        /// Fade distances and parallax march.
        shading: &'a DetailShading,
    },
}

/// What the renderer needs to know of a surface.
pub(crate) struct SurfaceInfo {
    pub(crate) size: UVec2,
    pub(crate) encoding: terrain_core::HeightEncoding,
    pub(crate) texel_size: f32,
    pub(crate) wrap: WrapMode,
}

impl ClipmapSurface<'_> {
    /// Checks the parts agree and returns the map's description.
    pub(crate) fn check(&self) -> Result<SurfaceInfo, GpuError> {
        let (size, encoding, texel_size, wrap) = match *self {
            ClipmapSurface::Coarse { map, normals } => {
                if normals.size() != map.size() {
                    return Err(GpuError::SizeMismatch {
                        expected: map.size(),
                        actual: normals.size(),
                    });
                }
                (map.size(), map.encoding(), map.texel_size(), map.wrap())
            }
            ClipmapSurface::Detail {
                map,
                normals,
                detail,
                shading,
            } => {
                ClipmapSurface::Coarse { map, normals }.check()?;
                check_detail_over(detail, shading, map.size(), map.texel_size())?;
                (map.size(), map.encoding(), map.texel_size(), map.wrap())
            }
            ClipmapSurface::Granular { map, surface } => {
                let need = u64::from(map.size().x) * u64::from(map.size().y) * 16;
                if surface.size() < need {
                    return Err(GpuError::Unsupported {
                        what: "ClipmapRenderer",
                        reason: "the granular surface buffer holds fewer than 16 bytes per texel",
                    });
                }
                (map.size(), map.encoding(), map.texel_size(), map.wrap())
            }
            ClipmapSurface::Atlas { atlas } => {
                let w = &atlas.config().world;
                (w.world_size, w.encoding, w.texel_size, w.wrap)
            }
            ClipmapSurface::AtlasDetail {
                atlas,
                detail,
                shading,
            } => {
                let w = &atlas.config().world;
                check_detail_over(detail, shading, w.world_size, w.texel_size)?;
                (w.world_size, w.encoding, w.texel_size, w.wrap)
            }
        };
        Ok(SurfaceInfo {
            size,
            encoding,
            texel_size,
            wrap,
        })
    }

    /// The storage buffers the surface binds, with their bindings: a coarse-map's at 1 and 2,
    /// an atlas's at 1 to 3 (20 to 22 beside detail tiles), detail tiles at 4 and 5 (the
    /// renderer's detail uniform goes at 3).
    pub(crate) fn buffers(&self) -> BoundBuffers {
        let atlas_at = |first: u32, atlas: &GpuTileAtlas| {
            [
                (first, atlas.info_buffer().clone()),
                (first + 1, atlas.heights_buffer().clone()),
                (first + 2, atlas.table_buffer().clone()),
            ]
        };
        let detail_at = |detail: &GpuDetailTiles| {
            [
                (4, detail.table_buffer().clone()),
                (5, detail.heights_buffer().clone()),
            ]
        };
        match *self {
            ClipmapSurface::Coarse { map, normals } => {
                vec![(1, map.buffer().clone()), (2, normals.buffer().clone())]
            }
            ClipmapSurface::Detail {
                map,
                normals,
                detail,
                ..
            } => {
                let mut b = vec![(1, map.buffer().clone()), (2, normals.buffer().clone())];
                b.extend(detail_at(detail));
                b
            }
            ClipmapSurface::Granular { surface, .. } => vec![(1, surface.clone())],
            ClipmapSurface::Atlas { atlas } => atlas_at(1, atlas).to_vec(),
            ClipmapSurface::AtlasDetail { atlas, detail, .. } => {
                let mut b = atlas_at(ATLAS_BESIDE_DETAIL, atlas).to_vec();
                b.extend(detail_at(detail));
                b
            }
        }
    }

    /// The detail tiles and their shading, for the surfaces that have them.
    pub(crate) fn detail(&self) -> Option<(&GpuDetailTiles, &DetailShading)> {
        match *self {
            ClipmapSurface::Detail {
                detail, shading, ..
            }
            | ClipmapSurface::AtlasDetail {
                detail, shading, ..
            } => Some((detail, shading)),
            _ => None,
        }
    }

    pub(crate) fn kind(&self) -> SurfaceKind {
        match self {
            ClipmapSurface::Coarse { .. } => SurfaceKind::Coarse,
            ClipmapSurface::Granular { .. } => SurfaceKind::Granular,
            ClipmapSurface::Atlas { .. } => SurfaceKind::Atlas,
            ClipmapSurface::Detail { .. } => SurfaceKind::Detail,
            ClipmapSurface::AtlasDetail { .. } => SurfaceKind::AtlasDetail,
        }
    }
}

/// The first binding of an atlas drawn beside detail tiles (`tile_atlas_bind_high.wgsl`).
pub(crate) const ATLAS_BESIDE_DETAIL: u32 = 20;

/// Checks detail tiles lie over a surface of `size` texels of `texel_m` metres, and their
/// shading.
fn check_detail_over(
    detail: &GpuDetailTiles,
    shading: &DetailShading,
    size: UVec2,
    texel_m: f32,
) -> Result<(), GpuError> {
    let layout = detail.layout();
    if layout.coarse_size() != size {
        return Err(GpuError::SizeMismatch {
            expected: size,
            actual: layout.coarse_size(),
        });
    }
    if layout.coarse_texel_m() != texel_m {
        return Err(GpuError::Unsupported {
            what: "ClipmapRenderer",
            reason: "the detail layout's coarse texel spacing is not the surface's",
        });
    }
    shading.check(texel_m).map(|_| ())
}
