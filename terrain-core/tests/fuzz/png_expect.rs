//! What each PNG decoder must return: the decoder a target drives (16-bit, 8-bit or the RGBA8
//! capture decoder), the pixels a valid file decodes to, and the checks on any other input.

use glam::UVec2;
use terrain_core::Grid;
use terrain_core::io::{
    GrayImage, MapIoError, ReadLimits, decode_png, decode_png_rgba8, decode_png8, decode_png16,
    read_png8, read_png16,
};
use terrain_test_support::png_encoder::Image;

/// Which decoder a target drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Gray8,
    Gray16,
    Rgba8,
}

pub(crate) const GRAY8: u8 = 0;
pub(crate) const GRAY16: u8 = 1;
pub(crate) const RGBA8: u8 = 2;

pub(crate) fn kind(k: u8) -> Kind {
    match k {
        GRAY8 => Kind::Gray8,
        GRAY16 => Kind::Gray16,
        _ => Kind::Rgba8,
    }
}

impl Kind {
    /// The (colour type, bit depth) this decoder accepts.
    pub(crate) fn format(self) -> (u8, u8) {
        match self {
            Kind::Gray8 => (0, 8),
            Kind::Gray16 => (0, 16),
            Kind::Rgba8 => (6, 8),
        }
    }
}

/// A decoder's output as one comparable value.
#[derive(Debug, PartialEq)]
pub(crate) enum Pixels {
    Gray8(Grid<u8>),
    Gray16(Grid<u16>),
    Rgba8(Grid<[u8; 4]>),
}

impl Pixels {
    pub(crate) fn size(&self) -> UVec2 {
        match self {
            Pixels::Gray8(g) => g.size(),
            Pixels::Gray16(g) => g.size(),
            Pixels::Rgba8(g) => g.size(),
        }
    }
}

pub(crate) fn decode(k: Kind, bytes: &[u8], limits: &ReadLimits) -> Result<Pixels, MapIoError> {
    match k {
        Kind::Gray8 => decode_png8(bytes, limits).map(Pixels::Gray8),
        Kind::Gray16 => decode_png16(bytes, limits).map(Pixels::Gray16),
        Kind::Rgba8 => decode_png_rgba8(bytes, limits).map(Pixels::Rgba8),
    }
}

pub(crate) fn read_file(
    k: Kind,
    path: &std::path::Path,
    limits: &ReadLimits,
) -> Result<Pixels, MapIoError> {
    match k {
        Kind::Gray8 => read_png8(path, limits).map(Pixels::Gray8),
        Kind::Gray16 => read_png16(path, limits).map(Pixels::Gray16),
        Kind::Rgba8 => terrain_core::io::read_png_rgba8(path, limits).map(Pixels::Rgba8),
    }
}

/// The pixels a decoder of kind `k` must return for `img`.
pub(crate) fn expected_pixels(k: Kind, img: &Image) -> Pixels {
    let (w, h) = (img.width, img.height);
    match k {
        Kind::Gray8 => Pixels::Gray8(
            Grid::from_vec(w, h, img.samples.iter().map(|&v| v as u8).collect()).unwrap(),
        ),
        Kind::Gray16 => Pixels::Gray16(Grid::from_vec(w, h, img.samples.clone()).unwrap()),
        Kind::Rgba8 => Pixels::Rgba8(
            Grid::from_vec(
                w,
                h,
                img.samples
                    .chunks_exact(4)
                    .map(|p| [p[0] as u8, p[1] as u8, p[2] as u8, p[3] as u8])
                    .collect(),
            )
            .unwrap(),
        ),
    }
}

/// Checks a decode of a valid file of `img`: the exact pixels when the decoder takes the
/// image's format and size, else the error the header calls for.
pub(crate) fn check_valid(
    k: Kind,
    img: &Image,
    limits: &ReadLimits,
    got: Result<Pixels, MapIoError>,
) -> Result<(), String> {
    let (w, h) = (img.width, img.height);
    let fmt = (img.color_type, img.bit_depth);
    let describe = || format!("{w}x{h} colour type {} depth {}", fmt.0, fmt.1);
    if w > limits.max_side || h > limits.max_side {
        return match got {
            Err(MapIoError::TooLarge { width, height, .. }) if width == w && height == h => Ok(()),
            other => Err(format!(
                "{}: over max_side {}, expected TooLarge, got {other:?}",
                describe(),
                limits.max_side
            )),
        };
    }
    let ok = match (k, got) {
        (_, Ok(p)) if fmt == k.format() => {
            let want = expected_pixels(k, img);
            if p == want {
                return Ok(());
            }
            return Err(format!(
                "{}: decoded pixels differ from the encoded ones",
                describe()
            ));
        }
        (Kind::Gray8 | Kind::Gray16, Err(MapIoError::NotGrayscale { .. })) => fmt.0 != 0,
        (Kind::Gray8 | Kind::Gray16, Err(MapIoError::UnsupportedBitDepth { bits })) => {
            fmt.0 == 0 && bits == fmt.1 && bits < 8
        }
        (Kind::Gray8, Err(MapIoError::WrongBitDepth { expected: 8, found })) => {
            fmt == (0, 16) && found == 16
        }
        (
            Kind::Gray16,
            Err(MapIoError::WrongBitDepth {
                expected: 16,
                found,
            }),
        ) => fmt == (0, 8) && found == 8,
        (Kind::Rgba8, Err(MapIoError::NotRgba { .. })) => fmt.0 != 6,
        (Kind::Rgba8, Err(MapIoError::WrongBitDepth { expected: 8, found })) => {
            fmt == (6, 16) && found == 16
        }
        (_, other) => {
            return Err(format!("{}: unexpected result {other:?}", describe()));
        }
    };
    if ok {
        Ok(())
    } else {
        Err(format!("{}: wrong error for this header", describe()))
    }
}

/// Checks what any input may decode to: an error, or pixels within the limits. For the gray
/// decoders, also that the generic `decode_png` agrees with the depth-specific one.
pub(crate) fn check_any(
    k: Kind,
    bytes: &[u8],
    limits: &ReadLimits,
) -> Result<Option<Pixels>, String> {
    let got = decode(k, bytes, limits);
    if let Ok(p) = &got {
        let s = p.size();
        if s.x == 0 || s.y == 0 || s.x > limits.max_side || s.y > limits.max_side {
            return Err(format!(
                "decoded a {}x{} image, limits {limits:?}",
                s.x, s.y
            ));
        }
    }
    if k != Kind::Rgba8 {
        let generic = decode_png(bytes, limits);
        let agree = match (&got, &generic) {
            (Ok(Pixels::Gray8(a)), Ok(GrayImage::Gray8(b))) => a == b,
            (Ok(Pixels::Gray16(a)), Ok(GrayImage::Gray16(b))) => a == b,
            (Ok(_), _) => false,
            (Err(_), Ok(GrayImage::Gray8(_))) => k == Kind::Gray16,
            (Err(_), Ok(GrayImage::Gray16(_))) => k == Kind::Gray8,
            (Err(_), Err(_)) => true,
        };
        if !agree {
            return Err(format!(
                "decode_png and the {k:?} decoder disagree: {:?} vs {:?}",
                got.as_ref().map(Pixels::size),
                generic.as_ref().map(GrayImage::size)
            ));
        }
    }
    Ok(got.ok())
}
