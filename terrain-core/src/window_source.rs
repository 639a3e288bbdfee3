//! [`WindowSource`]: where a window of level-0 heights that follows the camera over a world
//! larger than memory gets its texels (terrain-physics' `CollisionWindow` is such a window,
//! terrain-cache's RAM pool such a source). A source may fill a texel whose tile is not in
//! memory yet from coarser data (Fikkan 2013, sec. 4.3: a coarser level stands in for a tile on
//! its way); it then remembers it, says so, and hands the texels back to be filled again once
//! the tile has arrived, so the window never keeps a stand-in.

use crate::{Grid, Rect};
use glam::UVec2;

/// Fills a moving window's texels (see the module docs).
///
/// Contract for implementers:
/// - `fill` writes the level-0 heights of `rect` (world texels, inside the world) into `out`,
///   of `rect`'s size, the best data it has, and remembers the texels it filled with
///   stand-ins. Failures are the implementation's own [`WindowSource::Error`], never a panic.
/// - `improved` returns the rects (world texels) filled with stand-ins whose real data has
///   arrived since, forgetting them as it returns them (filling them again remembers what is
///   still a stand-in then); stand-ins outside `window` (the window's rect now, if any) are
///   forgotten.
/// - `is_stand_in` says whether `texel` was filled with a stand-in the source still
///   remembers: once `improved` has returned its rect it answers `false`, so the window keeps
///   the rects `improved` returned as stand-ins itself until it has filled them again
///   (`CollisionWindow::follow` does).
pub trait WindowSource {
    /// Why a fill failed (a tile that could not be read, say).
    type Error;

    /// Fills `out` with the heights of `rect` (see the trait docs).
    fn fill(&mut self, rect: Rect, out: &mut Grid<u16>) -> Result<(), Self::Error>;

    /// Rects to fill again now that their data has arrived (see the trait docs).
    fn improved(&mut self, window: Option<Rect>) -> Vec<Rect>;

    /// Whether `texel` (world texels) holds a stand-in.
    fn is_stand_in(&self, texel: UVec2) -> bool;
}
