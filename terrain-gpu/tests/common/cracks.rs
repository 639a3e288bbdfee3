//! The crack tests' hole count, shared by the render tests.

use terrain_core::Grid;

/// Magenta: a colour the terrain's shading (greens, browns, greys, white, blue-grey fog)
/// cannot produce; the crack tests clear the sky to it.
pub fn is_sky(p: [u8; 4]) -> bool {
    p[0] > 200 && p[1] < 70 && p[2] > 200
}

/// Counts sky pixels below the terrain's silhouette in each column, and terrain pixels. With a
/// level camera (no pitch, no roll) every image column is a vertical plane through the eye,
/// and every ray below one that hits a heightfield hits it too: a sky pixel under terrain is a
/// hole in the mesh.
pub fn holes(image: &Grid<[u8; 4]>) -> (usize, usize) {
    let (mut holes, mut terrain) = (0, 0);
    for x in 0..image.width() {
        let mut seen_terrain = false;
        for y in 0..image.height() {
            if !is_sky(image.get(x, y).unwrap()) {
                seen_terrain = true;
                terrain += 1;
            } else if seen_terrain {
                holes += 1;
            }
        }
    }
    (holes, terrain)
}
