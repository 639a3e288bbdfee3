//! PNG byte helpers for tests that build or damage PNG files by hand (terrain-core's I/O tests
//! and decoder fuzz targets, terrain-cache's tile fuzz target): the signature, CRC-32,
//! Adler-32, chunk framing and chunk walking, written independently of the decoders under
//! test.

/// The PNG signature.
pub const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

/// CRC-32 (PNG's polynomial) over the concatenation of `parts`.
pub fn crc32(parts: &[&[u8]]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for part in parts {
        for &b in *part {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
    }
    !crc
}

/// Adler-32, the checksum that ends a zlib stream.
pub fn adler32(data: &[u8]) -> u32 {
    let (mut a, mut b) = (1u32, 0u32);
    for &d in data {
        a = (a + u32::from(d)) % 65521;
        b = (b + a) % 65521;
    }
    (b << 16) | a
}

/// One chunk: length, type, data and CRC.
pub fn chunk(ty: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(data.len() + 12);
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    out.extend_from_slice(ty);
    out.extend_from_slice(data);
    out.extend_from_slice(&crc32(&[ty, data]).to_be_bytes());
    out
}

/// The whole chunks of a PNG after its signature: (offset of the length field, data length),
/// up to the first that does not fit in `png`.
pub fn chunks_of(png: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 12 <= png.len() {
        let len = u32::from_be_bytes([png[at], png[at + 1], png[at + 2], png[at + 3]]) as usize;
        if len > png.len() || at + 12 + len > png.len() {
            break;
        }
        out.push((at, len));
        at += 12 + len;
    }
    out
}

/// Recomputes every whole chunk's CRC, so that a mutation reaches the parser behind the CRC
/// check.
pub fn fix_crcs(png: &mut [u8]) {
    for (at, len) in chunks_of(png) {
        let crc = crc32(&[&png[at + 4..at + 8 + len]]);
        png[at + 8 + len..at + 12 + len].copy_from_slice(&crc.to_be_bytes());
    }
}
