//! The penetration texture (Persson 2019, sec. 4.1.3, table 4.1): which columns are seeds, obstacles
//! or penetrated, and how deep.

use super::{GranularError, NO_OBJECT, check_area};
use crate::{FixedPointMap, Grid, Rect};

/// Seed coordinate of a column that has no seed (yet). Table 4.1 stores 0 there; a named
/// sentinel keeps column `(0, 0)` usable as a seed.
pub const NO_SEED: u32 = u32::MAX;

/// The kind of a column, with the values of table 4.1's blue channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(i32)]
pub enum ColumnKind {
    /// Not under an object (or far above the terrain): receives displaced material.
    Seed = -3,
    /// Under an object that hovers just above the terrain: receives nothing.
    Obstacle = -2,
    /// The object intersects the terrain here: its material is displaced.
    Penetrating = -1,
}

impl ColumnKind {
    /// The kind for a stored channel value, `None` for anything else.
    pub fn from_i32(v: i32) -> Option<Self> {
        match v {
            -3 => Some(Self::Seed),
            -2 => Some(Self::Obstacle),
            -1 => Some(Self::Penetrating),
            _ => None,
        }
    }
}

/// One texel of the penetration texture (table 4.1), laid out as an `rgba32` texel:
/// `seed_x`, `seed_y` (map coordinates of the seed, the column's own for seeds, [`NO_SEED`]
/// otherwise), `kind` ([`ColumnKind`] as i32) and `penetration` (height units to displace).
#[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Penetration {
    /// Seed column X (map coordinates), or [`NO_SEED`].
    pub seed_x: u32,
    /// Seed column Y (map coordinates), or [`NO_SEED`].
    pub seed_y: u32,
    /// [`ColumnKind`] as its i32 value.
    pub kind: i32,
    /// `height - min(height, depth)` in fixed-point units (listing 4.1).
    pub penetration: u32,
}

impl Penetration {
    /// The column kind (a seed when the stored value is unknown).
    pub fn column_kind(&self) -> ColumnKind {
        ColumnKind::from_i32(self.kind).unwrap_or(ColumnKind::Seed)
    }
}

/// Computes the penetration texture over `area` from the map and the depth texture of that
/// area (see [`super::depth_from_below`]). Per column, with `h` the height and `d` the depth:
/// `penetration = h - min(h, d)`; `Penetrating` if it is > 0, else `Obstacle` if
/// `d != NO_OBJECT` and `d - h <= obstacle_margin` (units), else `Seed` (with its own
/// coordinates).
pub fn penetration_texture(
    map: &FixedPointMap,
    depth: &Grid<u32>,
    area: Rect,
    obstacle_margin: u32,
    out: &mut Grid<Penetration>,
) -> Result<(), GranularError> {
    check_area(area, map.size())?;
    for g in [depth.size(), out.size()] {
        if g != area.size {
            return Err(GranularError::SizeMismatch {
                expected: area.size,
                actual: g,
            });
        }
    }
    let heights = map.grid();
    let (ox, oy) = (area.min.x as u32, area.min.y as u32);
    for j in 0..area.size.y {
        let hrow = &heights.row(oy + j)[ox as usize..(ox + area.size.x) as usize];
        let drow = depth.row(j);
        let orow = out.row_mut(j);
        for i in 0..area.size.x as usize {
            let (h, d) = (hrow[i], drow[i]);
            let pen = h - h.min(d);
            orow[i] = if pen > 0 {
                Penetration {
                    seed_x: NO_SEED,
                    seed_y: NO_SEED,
                    kind: ColumnKind::Penetrating as i32,
                    penetration: pen,
                }
            } else if d != NO_OBJECT && d - h <= obstacle_margin {
                Penetration {
                    seed_x: NO_SEED,
                    seed_y: NO_SEED,
                    kind: ColumnKind::Obstacle as i32,
                    penetration: 0,
                }
            } else {
                Penetration {
                    seed_x: ox + i as u32,
                    seed_y: oy + j,
                    kind: ColumnKind::Seed as i32,
                    penetration: 0,
                }
            };
        }
    }
    Ok(())
}
