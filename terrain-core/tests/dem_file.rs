//! `DemFile`: a DEM opened once is read through the handle it was measured by, so a file
//! swapped in at its path between the measure and the read is not the one read.

use glam::UVec2;
use std::path::PathBuf;
use terrain_core::Grid;
use terrain_core::dem::{DemFile, DemFormat, DemOptions};
use terrain_core::io::{ByteOrder, encode_png16, encode_raw16};

/// A fresh folder for one test, removed at the end.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("terrain_dem_file_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch folder");
        Self(dir)
    }

    fn file(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.0.join(name);
        std::fs::write(&p, bytes).expect("write");
        p
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn grid(w: u32, h: u32, base: u16) -> Grid<u16> {
    Grid::from_fn(w, h, |x, y| base + (x * 7 + y * 3) as u16).unwrap()
}

fn heights(g: &Grid<u16>) -> Vec<f32> {
    g.as_slice().iter().map(|&v| f32::from(v)).collect()
}

#[test]
fn a_png_replaced_after_open_is_read_as_opened() {
    let s = Scratch::new("png");
    let first = grid(5, 3, 100);
    let path = s.file("dem.png", &encode_png16(&first).unwrap());
    let dem = DemFile::open(&path, &DemOptions::default()).unwrap();
    assert_eq!(
        (dem.format(), dem.size()),
        (DemFormat::Png, UVec2::new(5, 3))
    );
    // Another valid DEM, of another size, renamed over the path.
    let other = s.file("other.png", &encode_png16(&grid(9, 4, 5000)).unwrap());
    std::fs::rename(&other, &path).unwrap();
    assert_eq!(
        terrain_core::dem::dem_size(&path, &DemOptions::default()).unwrap(),
        (DemFormat::Png, UVec2::new(9, 4))
    );
    let read = dem.read().unwrap();
    assert_eq!(read.size(), UVec2::new(5, 3));
    assert_eq!(read.heights.as_slice(), heights(&first));
}

#[test]
fn a_raw16_replaced_after_open_is_read_as_opened() {
    let s = Scratch::new("raw");
    let first = grid(4, 4, 7);
    let path = s.file("dem.r16", &encode_raw16(&first));
    let options = DemOptions {
        raw_size: Some(UVec2::new(4, 4)),
        byte_order: ByteOrder::Little,
        ..DemOptions::default()
    };
    let dem = DemFile::open(&path, &options).unwrap();
    assert_eq!(
        (dem.format(), dem.size()),
        (DemFormat::Raw16, UVec2::new(4, 4))
    );
    let other = s.file("other.r16", &encode_raw16(&grid(8, 2, 900)));
    std::fs::rename(&other, &path).unwrap();
    let read = dem.read().unwrap();
    assert_eq!(read.heights.as_slice(), heights(&first));
}

#[test]
fn a_format_sniffed_from_the_first_bytes_still_reads_from_the_start() {
    let s = Scratch::new("sniff");
    let first = grid(3, 2, 40);
    // No extension: the format comes from the signature, read through the same handle.
    let path = s.file("dem", &encode_png16(&first).unwrap());
    let dem = DemFile::open(&path, &DemOptions::default()).unwrap();
    assert_eq!(dem.format(), DemFormat::Png);
    assert_eq!(dem.read().unwrap().heights.as_slice(), heights(&first));
}
