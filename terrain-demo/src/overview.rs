//! The top-down hillshade overview (terrain-core's `HillshadeOverview`, redrawn only where the
//! map changed): the whole frame without a GPU, an inset with one. With materials shading it is
//! coloured by the autoshader's materials (their colours from afar), as the frames are.

use anyhow::Result;
use glam::UVec2;
use terrain_core::{
    AutoshadeParams, CoarseMap, Grid, HillshadeMaterials, HillshadeOverview, HillshadeParams,
    MaterialTextures,
};

/// The overview of `map` at `size` pixels, coloured by the height ramp or, with `materials`,
/// by the autoshader's placement of the project's procedural materials. Cells `holes` cuts
/// are dark.
pub fn overview(
    map: &CoarseMap,
    size: UVec2,
    materials: bool,
    holes: Option<&Grid<u8>>,
) -> Result<HillshadeOverview> {
    let materials = match materials {
        // A small set: only the images' mean colours are used.
        true => Some(HillshadeMaterials::new(
            &MaterialTextures::procedural(16)?,
            AutoshadeParams::default(),
        )?),
        false => None,
    };
    let params = HillshadeParams {
        materials,
        ..HillshadeParams::with_size(size)
    };
    Ok(HillshadeOverview::new(map, params, holes)?)
}
