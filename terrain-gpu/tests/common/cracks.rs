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

/// Fails when the terrain fills less than a quarter of `image` or sky shows inside it (see
/// [`holes`]), writing the image to the temp directory as `{name}.png` for a look.
#[allow(dead_code)] // not every test binary that shares the file checks whole frames
pub fn assert_no_holes(image: &Grid<[u8; 4]>, name: &str) {
    let (holes, terrain) = holes(image);
    let quarter = (image.width() * image.height() / 4) as usize;
    assert!(
        terrain > quarter,
        "{name}: the terrain fills {terrain} pixels only"
    );
    if holes > 0 {
        let path = std::env::temp_dir().join(format!("{name}.png"));
        let _ = terrain_core::io::write_png_rgba8(&path, image);
        panic!(
            "{name}: {holes} sky pixels inside the terrain (image: {})",
            path.display()
        );
    }
}
