//! Colour images drawn over a heightmap (an orthophoto beside a DEM): 8-bit RGB or RGBA, as
//! PNG or (Geo)TIFF, read with the heightmaps' limits and checks (special files, sizes,
//! truncation, corruption) into RGBA pixels.

use crate::geotiff::{Origin, check_first_ifd, map_tiff_error};
use crate::grid::Grid;
use crate::io::png::decode_png_color;
use crate::io::{MapIoError, ReadLimits, check_size, open_regular, try_zeroed};
use std::io::{Cursor, Read};
use std::path::Path;
use tiff::ColorType;
use tiff::decoder::{Decoder, DecodingResult, Limits};

/// Reads a colour image file (PNG or TIFF, told apart by their first bytes) into RGBA pixels,
/// alpha 255 where the file has none. Grayscale, 16-bit and other colour types are refused
/// with a clear error, as are files larger than `limits` allow.
pub fn read_color_image(
    path: impl AsRef<Path>,
    limits: &ReadLimits,
) -> Result<Grid<[u8; 4]>, MapIoError> {
    let path = path.as_ref();
    let file = open_regular(path)?;
    let io_err = |source| MapIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let len = file.metadata().map_err(io_err)?.len();
    // A compressed image is never much larger than its pixels; an uncompressed one is them.
    let most = limits.max_samples.saturating_mul(4).saturating_add(1 << 20);
    if len > most {
        return Err(MapIoError::Corrupt {
            reason: format!("{len} bytes is more than a colour image within the limits holds"),
        });
    }
    let mut bytes = try_zeroed::<u8>(0, 0, 0)?;
    bytes
        .try_reserve_exact(len as usize)
        .map_err(|_| MapIoError::Corrupt {
            reason: format!("no memory for a {len}-byte file"),
        })?;
    (&file).take(most).read_to_end(&mut bytes).map_err(io_err)?;
    decode(&bytes, limits, Origin::File(path))
}

/// Decodes a colour image held in memory. See [`read_color_image`].
pub fn decode_color_image(bytes: &[u8], limits: &ReadLimits) -> Result<Grid<[u8; 4]>, MapIoError> {
    decode(bytes, limits, Origin::Memory)
}

fn decode(
    bytes: &[u8],
    limits: &ReadLimits,
    origin: Origin<'_>,
) -> Result<Grid<[u8; 4]>, MapIoError> {
    if bytes.starts_with(b"\x89PNG") {
        return decode_png_color(bytes, limits);
    }
    if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        return decode_tiff(bytes, limits, origin);
    }
    Err(MapIoError::Corrupt {
        reason: "a colour image must be a PNG or a TIFF (neither signature found)".to_owned(),
    })
}

fn decode_tiff(
    bytes: &[u8],
    limits: &ReadLimits,
    origin: Origin<'_>,
) -> Result<Grid<[u8; 4]>, MapIoError> {
    let len = bytes.len() as u64;
    check_first_ifd(&mut Cursor::new(bytes), len, limits, origin)?;
    let err = |e| map_tiff_error(e, origin);
    let mut decoder = Decoder::new(Cursor::new(bytes)).map_err(err)?;
    let (width, height) = decoder.dimensions().map_err(err)?;
    check_size(width, height, limits)?;
    let channels = match decoder.colortype().map_err(err)? {
        ColorType::RGB(8) => 3,
        ColorType::RGBA(8) => 4,
        other => {
            return Err(MapIoError::NotRgba {
                color_type: format!("TIFF {other:?}"),
            });
        }
    };
    let texels = width as usize * height as usize;
    let buffer = texels.saturating_mul(channels);
    // The decoder allocates its buffer itself, infallibly: make sure it can exist first.
    drop(try_zeroed::<u8>(buffer, width, height)?);
    let mut tiff_limits = Limits::default();
    tiff_limits.decoding_buffer_size = buffer;
    tiff_limits.intermediate_buffer_size = bytes.len();
    let mut decoder = decoder.with_limits(tiff_limits);
    let DecodingResult::U8(data) = decoder.read_image().map_err(err)? else {
        return Err(MapIoError::Corrupt {
            reason: "the TIFF decoder returned other than 8-bit samples".to_owned(),
        });
    };
    if data.len() != buffer {
        return Err(MapIoError::Corrupt {
            reason: format!(
                "the TIFF decoder returned {} samples for a {width}x{height} image",
                data.len()
            ),
        });
    }
    let pixels = data
        .chunks_exact(channels)
        .map(|p| [p[0], p[1], p[2], if channels == 4 { p[3] } else { 255 }])
        .collect();
    Ok(Grid::from_vec(width, height, pixels)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiff_rgb(width: u32, height: u32, data: &[u8]) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        let mut enc = tiff::encoder::TiffEncoder::new(&mut out).expect("encoder");
        enc.write_image::<tiff::encoder::colortype::RGB8>(width, height, data)
            .expect("write");
        out.into_inner()
    }

    #[test]
    fn rgb_and_rgba_png_and_tiff_read_as_rgba() {
        let limits = ReadLimits::default();
        let grid = Grid::from_fn(3, 2, |x, y| [x as u8 * 50, y as u8 * 90, 7, 200]).expect("grid");
        let png = crate::io::encode_png_rgba8(&grid).expect("png");
        assert_eq!(decode_color_image(&png, &limits).expect("rgba png"), grid);
        let rgb: Vec<u8> = grid
            .as_slice()
            .iter()
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let tiff = tiff_rgb(3, 2, &rgb);
        let read = decode_color_image(&tiff, &limits).expect("rgb tiff");
        assert!(
            read.as_slice()
                .iter()
                .zip(grid.as_slice())
                .all(|(a, b)| a[..3] == b[..3] && a[3] == 255)
        );
    }

    #[test]
    fn grayscale_truncated_oversized_and_unknown_files_are_refused() {
        let limits = ReadLimits::default();
        let gray = crate::io::encode_png8(&Grid::new(4, 4, 9u8).expect("grid")).expect("png");
        assert!(matches!(
            decode_color_image(&gray, &limits),
            Err(MapIoError::NotRgba { .. })
        ));
        let tiff = tiff_rgb(4, 4, &[1; 48]);
        for cut in [8, tiff.len() / 2, tiff.len() - 1] {
            assert!(decode_color_image(&tiff[..cut], &limits).is_err(), "{cut}");
        }
        let small = ReadLimits {
            max_side: 2,
            ..limits
        };
        assert!(decode_color_image(&tiff, &small).is_err());
        assert!(decode_color_image(b"GIF89a", &limits).is_err());
        assert!(read_color_image("/dev/null", &limits).is_err());
    }
}
