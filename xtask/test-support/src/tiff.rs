//! A small baseline TIFF writer of the tests' own, so the GeoTIFF reader (the `tiff` crate
//! underneath) is checked against files it did not write: one band of any sample type,
//! uncompressed, in strips or tiles, little- or big-endian, classic TIFF or BigTIFF, with the
//! GeoTIFF tags a DEM carries (pixel scale, tie point, GeoKey directory, GDAL nodata) and any
//! extra entry a test wants (to make bad files). terrain-core's DEM tests and GeoTIFF fuzz
//! classes and the [`decoders`](crate::decoders) corpora write their files with it.

/// Sample types as TIFF states them: bits per sample and SampleFormat (1 uint, 2 int, 3 float).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sample {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    F32,
    F64,
}

impl Sample {
    pub const ALL: [Sample; 8] = [
        Sample::U8,
        Sample::I8,
        Sample::U16,
        Sample::I16,
        Sample::U32,
        Sample::I32,
        Sample::F32,
        Sample::F64,
    ];

    pub fn bytes(self) -> usize {
        match self {
            Sample::U8 | Sample::I8 => 1,
            Sample::U16 | Sample::I16 => 2,
            Sample::U32 | Sample::I32 | Sample::F32 => 4,
            Sample::F64 => 8,
        }
    }

    fn format(self) -> u16 {
        match self {
            Sample::U8 | Sample::U16 | Sample::U32 => 1,
            Sample::I8 | Sample::I16 | Sample::I32 => 2,
            Sample::F32 | Sample::F64 => 3,
        }
    }

    /// `v` in this type's bytes, in the file's byte order (integers saturate).
    fn encode(self, v: f64, big: bool) -> Vec<u8> {
        macro_rules! bytes {
            ($x:expr) => {
                if big {
                    $x.to_be_bytes().to_vec()
                } else {
                    $x.to_le_bytes().to_vec()
                }
            };
        }
        match self {
            Sample::U8 => bytes!(v as u8),
            Sample::I8 => bytes!(v as i8),
            Sample::U16 => bytes!(v as u16),
            Sample::I16 => bytes!(v as i16),
            Sample::U32 => bytes!(v as u32),
            Sample::I32 => bytes!(v as i32),
            Sample::F32 => bytes!(v as f32),
            Sample::F64 => bytes!(v),
        }
    }
}

/// How the samples are cut into chunks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Strips of this many rows.
    Strips(u32),
    /// Tiles of this width and height.
    Tiles(u32, u32),
}

/// TIFF field types used here.
pub const SHORT: u16 = 3;
pub const LONG: u16 = 4;
pub const ASCII: u16 = 2;
pub const DOUBLE: u16 = 12;
pub const LONG8: u16 = 16;

/// A file to write.
#[derive(Debug, Clone)]
pub struct TiffSpec {
    pub width: u32,
    pub height: u32,
    pub sample: Sample,
    /// Row-major values, converted to `sample`.
    pub values: Vec<f64>,
    pub big_endian: bool,
    pub bigtiff: bool,
    pub layout: Layout,
    /// Samples per pixel (1 for a DEM; more makes a multi-band file, each band the same).
    pub bands: u16,
    pub pixel_scale: Option<[f64; 3]>,
    pub tiepoint: Option<[f64; 6]>,
    /// GeoKeys as (id, value), stored inline.
    pub geokeys: Vec<(u16, u16)>,
    pub nodata: Option<String>,
    /// Extra entries: (tag, type, count, value bytes in the file's order); one of a tag the
    /// writer writes itself replaces the writer's.
    pub extra: Vec<(u16, u16, u64, Vec<u8>)>,
}

impl TiffSpec {
    /// A little-endian, classic, one-strip-per-row file of `values`.
    pub fn new(width: u32, height: u32, sample: Sample, values: Vec<f64>) -> Self {
        Self {
            width,
            height,
            sample,
            values,
            big_endian: false,
            bigtiff: false,
            layout: Layout::Strips(1),
            bands: 1,
            pixel_scale: None,
            tiepoint: None,
            geokeys: Vec::new(),
            nodata: None,
            extra: Vec::new(),
        }
    }

    /// A value's bytes in the file's byte order.
    fn ordered<const N: usize>(&self, big: [u8; N], little: [u8; N]) -> [u8; N] {
        if self.big_endian { big } else { little }
    }

    fn u16s(&self, v: &[u16]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| self.ordered(x.to_be_bytes(), x.to_le_bytes()))
            .collect()
    }

    fn u32s(&self, v: &[u32]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| self.ordered(x.to_be_bytes(), x.to_le_bytes()))
            .collect()
    }

    fn u64s(&self, v: &[u64]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| self.ordered(x.to_be_bytes(), x.to_le_bytes()))
            .collect()
    }

    fn f64s(&self, v: &[f64]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| self.ordered(x.to_be_bytes(), x.to_le_bytes()))
            .collect()
    }

    /// The value at `(x, y)` (0 outside the image: tile padding).
    fn at(&self, x: u32, y: u32) -> f64 {
        if x < self.width && y < self.height {
            self.values[(y * self.width + x) as usize]
        } else {
            0.0
        }
    }

    /// The chunks' bytes, in order.
    fn chunks(&self) -> Vec<Vec<u8>> {
        let px = |x, y| {
            let one = self.sample.encode(self.at(x, y), self.big_endian);
            one.repeat(usize::from(self.bands))
        };
        match self.layout {
            Layout::Strips(rows) => (0..self.height.div_ceil(rows))
                .map(|s| {
                    let y0 = s * rows;
                    let y1 = (y0 + rows).min(self.height);
                    (y0..y1)
                        .flat_map(|y| (0..self.width).flat_map(move |x| px(x, y)))
                        .collect()
                })
                .collect(),
            Layout::Tiles(tw, th) => {
                let mut out = Vec::new();
                for ty in 0..self.height.div_ceil(th) {
                    for tx in 0..self.width.div_ceil(tw) {
                        let mut tile = Vec::new();
                        for y in 0..th {
                            for x in 0..tw {
                                tile.extend(px(tx * tw + x, ty * th + y));
                            }
                        }
                        out.push(tile);
                    }
                }
                out
            }
        }
    }

    /// The file's bytes.
    pub fn write(&self) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend(if self.big_endian { b"MM" } else { b"II" });
        if self.bigtiff {
            out.extend(self.u16s(&[43, 8, 0]));
            out.extend(self.u64s(&[0])); // IFD offset, patched below
        } else {
            out.extend(self.u16s(&[42]));
            out.extend(self.u32s(&[0]));
        }
        let mut offsets = Vec::new();
        let mut counts = Vec::new();
        for chunk in self.chunks() {
            offsets.push(out.len() as u64);
            counts.push(chunk.len() as u64);
            out.extend(chunk);
        }
        if out.len() % 2 == 1 {
            out.push(0);
        }

        let n = self.bands;
        let mut entries: Vec<(u16, u16, u64, Vec<u8>)> = vec![
            (256, LONG, 1, self.u32s(&[self.width])),
            (257, LONG, 1, self.u32s(&[self.height])),
            (
                258,
                SHORT,
                u64::from(n),
                self.u16s(&vec![(self.sample.bytes() * 8) as u16; usize::from(n)]),
            ),
            (259, SHORT, 1, self.u16s(&[1])),
            (262, SHORT, 1, self.u16s(&[if n >= 3 { 2 } else { 1 }])),
            (277, SHORT, 1, self.u16s(&[n])),
            (284, SHORT, 1, self.u16s(&[1])),
            (
                339,
                SHORT,
                u64::from(n),
                self.u16s(&vec![self.sample.format(); usize::from(n)]),
            ),
        ];
        let (off_ty, off_bytes, cnt_bytes) = if self.bigtiff {
            (LONG8, self.u64s(&offsets), self.u64s(&counts))
        } else {
            let o: Vec<u32> = offsets.iter().map(|&v| v as u32).collect();
            let c: Vec<u32> = counts.iter().map(|&v| v as u32).collect();
            (LONG, self.u32s(&o), self.u32s(&c))
        };
        let k = offsets.len() as u64;
        match self.layout {
            Layout::Strips(rows) => {
                entries.push((273, off_ty, k, off_bytes));
                entries.push((278, LONG, 1, self.u32s(&[rows])));
                entries.push((279, off_ty, k, cnt_bytes));
            }
            Layout::Tiles(tw, th) => {
                entries.push((322, LONG, 1, self.u32s(&[tw])));
                entries.push((323, LONG, 1, self.u32s(&[th])));
                entries.push((324, off_ty, k, off_bytes));
                entries.push((325, off_ty, k, cnt_bytes));
            }
        }
        if let Some(s) = self.pixel_scale {
            entries.push((33550, DOUBLE, 3, self.f64s(&s)));
        }
        if let Some(t) = self.tiepoint {
            entries.push((33922, DOUBLE, 6, self.f64s(&t)));
        }
        if !self.geokeys.is_empty() {
            let mut dir = vec![1u16, 1, 0, self.geokeys.len() as u16];
            for &(id, v) in &self.geokeys {
                dir.extend([id, 0, 1, v]);
            }
            entries.push((34735, SHORT, dir.len() as u64, self.u16s(&dir)));
        }
        if let Some(text) = &self.nodata {
            let mut b = text.as_bytes().to_vec();
            b.push(0);
            entries.push((42113, ASCII, b.len() as u64, b));
        }
        entries.retain(|e| self.extra.iter().all(|x| x.0 != e.0));
        entries.extend(self.extra.iter().cloned());
        entries.sort_by_key(|e| e.0);

        // The directory, then the values that do not fit inline.
        let ifd = out.len() as u64;
        let (count_len, entry_len, inline) = if self.bigtiff { (8, 20, 8) } else { (2, 12, 4) };
        let mut external = ifd + count_len + entries.len() as u64 * entry_len + inline as u64;
        let mut tail = Vec::new();
        if self.bigtiff {
            out.extend(self.u64s(&[entries.len() as u64]));
        } else {
            out.extend(self.u16s(&[entries.len() as u16]));
        }
        for (tag, ty, count, value) in &entries {
            out.extend(self.u16s(&[*tag, *ty]));
            if self.bigtiff {
                out.extend(self.u64s(&[*count]));
            } else {
                out.extend(self.u32s(&[*count as u32]));
            }
            if value.len() <= inline {
                let mut v = value.clone();
                v.resize(inline, 0);
                out.extend(v);
            } else {
                if self.bigtiff {
                    out.extend(self.u64s(&[external]));
                } else {
                    out.extend(self.u32s(&[external as u32]));
                }
                tail.extend(value);
                if tail.len() % 2 == 1 {
                    tail.push(0);
                }
                external = ifd
                    + count_len
                    + entries.len() as u64 * entry_len
                    + inline as u64
                    + tail.len() as u64;
            }
        }
        out.extend(vec![0u8; inline]); // no next directory
        out.extend(tail);
        // Patch the first directory's offset into the header.
        if self.bigtiff {
            let b = self.u64s(&[ifd]);
            out[8..16].copy_from_slice(&b);
        } else {
            let b = self.u32s(&[ifd as u32]);
            out[4..8].copy_from_slice(&b);
        }
        out
    }
}
