//! A minimal PNG writer (and a reader for the same subset), with no dependency.
//!
//! # What is written
//!
//! * 8-bit RGB (colour type 2), no interlacing, one `IHDR`, one or more `IDAT` chunks (at most
//!   [`IDAT_CHUNK`] bytes each) and `IEND`.
//! * Every row starts with filter byte 0 (`None`).
//! * The image data is a zlib stream (RFC 1950: header `78 01`, Adler-32 trailer) whose deflate
//!   data (RFC 1951) is a sequence of **stored** (uncompressed) blocks of at most 65,535 bytes.
//!
//! Stored blocks make the encoder a few dozen lines with nothing to get subtly wrong, at the cost
//! of files about as large as the raw pixels (800 × 800 RGB ≈ 1.9 MB). That is fine for test
//! pictures and film frames, which are usually re-encoded by a video tool anyway; a real
//! compressor would be the `image` crate's job, which the project does not depend on.
//!
//! # What is read
//!
//! [`decode`] reads back exactly this subset (8-bit RGB, non-interlaced, filter 0 rows, stored
//! deflate blocks), checking the signature, every chunk's CRC-32, the zlib header and the
//! Adler-32 of the data. Anything else (another colour type, compressed deflate blocks, other
//! row filters) is a [`crate::Error::Input`] that says what is unsupported. It exists so that
//! tests can read the encoder's output; it is not a general PNG reader.
//!
//! # Checksums
//!
//! [`crc32`] is the CRC-32 of ISO 3309 / ITU-T V.42 used by PNG (reflected polynomial
//! `0xEDB88320`, initial value and final XOR `0xFFFFFFFF`), table-driven with the table built at
//! compile time; [`adler32`] is zlib's Adler-32 (two sums modulo 65,521, reduced every 5,552
//! bytes so the `u32` sums cannot overflow).

use crate::{Error, Result};

/// The 8 bytes every PNG file starts with.
pub const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

/// Largest payload of one stored deflate block (its length field is 16 bits).
pub const MAX_STORED_BLOCK: usize = 65_535;

/// Largest payload of one `IDAT` chunk written by [`encode`] (1 MiB; the format allows 2³¹ − 1).
pub const IDAT_CHUNK: usize = 1 << 20;

/// The CRC-32 lookup table (one entry per byte value), built at compile time.
const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut n = 0;
    while n < 256 {
        let mut c = n as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        table[n] = c;
        n += 1;
    }
    table
};

/// Continues a CRC-32 over more bytes: `crc` is the raw register (start with `0xFFFFFFFF`, XOR
/// with `0xFFFFFFFF` at the end).
fn crc32_update(mut crc: u32, bytes: &[u8]) -> u32 {
    for &b in bytes {
        crc = CRC_TABLE[((crc ^ b as u32) & 0xFF) as usize] ^ (crc >> 8);
    }
    crc
}

/// The CRC-32 of `bytes` as PNG uses it (check value: `crc32(b"123456789") == 0xCBF43926`).
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32_update(0xFFFF_FFFF, bytes) ^ 0xFFFF_FFFF
}

/// The Adler-32 checksum of `bytes` as zlib uses it (`adler32(b"Wikipedia") == 0x11E60398`).
pub fn adler32(bytes: &[u8]) -> u32 {
    const MOD: u32 = 65_521;
    // 5552 is the largest n for which 255·n·(n+1)/2 + (n+1)·(MOD−1) fits in a u32.
    const NMAX: usize = 5_552;
    let (mut a, mut b) = (1u32, 0u32);
    for chunk in bytes.chunks(NMAX) {
        for &x in chunk {
            a += x as u32;
            b += a;
        }
        a %= MOD;
        b %= MOD;
    }
    (b << 16) | a
}

/// Wraps `data` in a zlib stream made of stored deflate blocks of at most
/// [`MAX_STORED_BLOCK`] bytes (an empty input gives one empty final block).
pub fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let blocks = data.len().div_ceil(MAX_STORED_BLOCK).max(1);
    let mut out = Vec::with_capacity(data.len() + 5 * blocks + 6);
    // CMF = 0x78: deflate with a 32 KiB window; FLG = 0x01: no preset dictionary, "fastest"
    // level, and the check bits that make 0x7801 a multiple of 31.
    out.extend_from_slice(&[0x78, 0x01]);
    let mut chunks = data.chunks(MAX_STORED_BLOCK).peekable();
    if chunks.peek().is_none() {
        out.extend_from_slice(&[0x01, 0x00, 0x00, 0xFF, 0xFF]);
    }
    while let Some(chunk) = chunks.next() {
        // One header byte: BFINAL in bit 0, BTYPE = 00 (stored) in bits 1–2, then padding to
        // the byte boundary; then LEN and its one's complement NLEN, little-endian.
        let last = chunks.peek().is_none();
        out.push(u8::from(last));
        let len = chunk.len() as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(chunk);
    }
    out.extend_from_slice(&adler32(data).to_be_bytes());
    out
}

/// Appends one PNG chunk (length, type, data, CRC-32 of type and data).
fn push_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32_update(crc32_update(0xFFFF_FFFF, kind), data) ^ 0xFFFF_FFFF;
    out.extend_from_slice(&crc.to_be_bytes());
}

/// Encodes an 8-bit RGB image (`rgb` row-major, 3 bytes per pixel, top row first) as PNG.
///
/// Pixels that `rgb` is too short for are written black; extra bytes are ignored. PNG needs
/// both dimensions ≥ 1: with a zero dimension the bytes are still produced, but decoders
/// (including [`decode`]) refuse them.
pub fn encode(width: u32, height: u32, rgb: &[u8]) -> Vec<u8> {
    let row = width as usize * 3;
    let mut raw = Vec::with_capacity((row + 1) * height as usize);
    for y in 0..height as usize {
        raw.push(0); // filter type 0: None
        let start = (y * row).min(rgb.len());
        let end = (start + row).min(rgb.len());
        raw.extend_from_slice(&rgb[start..end]);
        raw.resize(raw.len() + row - (end - start), 0);
    }
    let zlib = zlib_stored(&raw);

    let mut out = Vec::with_capacity(zlib.len() + 64 + 12 * (zlib.len() / IDAT_CHUNK));
    out.extend_from_slice(&SIGNATURE);
    let mut ihdr = [0u8; 13];
    ihdr[0..4].copy_from_slice(&width.to_be_bytes());
    ihdr[4..8].copy_from_slice(&height.to_be_bytes());
    ihdr[8] = 8; // bit depth
    ihdr[9] = 2; // colour type: truecolour (RGB)
    // ihdr[10..13]: compression 0 (deflate), filter method 0, no interlace.
    push_chunk(&mut out, b"IHDR", &ihdr);
    for chunk in zlib.chunks(IDAT_CHUNK) {
        push_chunk(&mut out, b"IDAT", chunk);
    }
    push_chunk(&mut out, b"IEND", &[]);
    out
}

/// A decoded image: width, height and the RGB bytes (row-major, top row first).
pub type Decoded = (u32, u32, Vec<u8>);

fn bad(problem: impl Into<String>) -> Error {
    Error::input(format!("PNG: {}", problem.into()))
}

fn be32(b: &[u8]) -> u32 {
    u32::from_be_bytes([b[0], b[1], b[2], b[3]])
}

/// Decodes the subset of PNG that [`encode`] writes (see the module docs); any other PNG is an
/// [`Error::Input`] naming what is not supported.
pub fn decode(bytes: &[u8]) -> Result<Decoded> {
    if bytes.len() < 8 || bytes[..8] != SIGNATURE {
        return Err(bad("missing PNG signature"));
    }
    let mut pos = 8;
    let mut header: Option<(u32, u32)> = None;
    let mut zlib = Vec::new();
    let mut ended = false;
    while pos < bytes.len() {
        if bytes.len() - pos < 12 {
            return Err(bad(format!("truncated chunk at byte {pos}")));
        }
        let len = be32(&bytes[pos..]) as usize;
        let kind: [u8; 4] = bytes[pos + 4..pos + 8].try_into().expect("4 bytes");
        if len > bytes.len() - pos - 12 {
            return Err(bad(format!("chunk at byte {pos} runs past the end")));
        }
        let data = &bytes[pos + 8..pos + 8 + len];
        let stored = be32(&bytes[pos + 8 + len..]);
        let crc = crc32_update(crc32_update(0xFFFF_FFFF, &kind), data) ^ 0xFFFF_FFFF;
        if crc != stored {
            return Err(bad(format!(
                "CRC mismatch in chunk {} at byte {pos}",
                String::from_utf8_lossy(&kind)
            )));
        }
        match &kind {
            b"IHDR" => {
                if header.is_some() || len != 13 {
                    return Err(bad("bad or repeated IHDR"));
                }
                let (w, h) = (be32(data), be32(&data[4..]));
                if w == 0 || h == 0 {
                    return Err(bad("zero width or height"));
                }
                if data[8..13] != [8, 2, 0, 0, 0] {
                    return Err(bad(format!(
                        "unsupported format (bit depth {}, colour type {}, compression {}, \
                         filter {}, interlace {}); only 8-bit RGB, non-interlaced is supported",
                        data[8], data[9], data[10], data[11], data[12]
                    )));
                }
                header = Some((w, h));
            }
            b"IDAT" => {
                if header.is_none() {
                    return Err(bad("IDAT before IHDR"));
                }
                zlib.extend_from_slice(data);
            }
            b"IEND" => {
                ended = true;
                break;
            }
            _ if kind[0] & 0x20 == 0 => {
                return Err(bad(format!(
                    "unsupported critical chunk {}",
                    String::from_utf8_lossy(&kind)
                )));
            }
            _ => {} // ancillary chunk: skipped
        }
        pos += 12 + len;
    }
    let (width, height) = header.ok_or_else(|| bad("no IHDR chunk"))?;
    if !ended {
        return Err(bad("no IEND chunk"));
    }
    let raw = inflate_stored(&zlib)?;
    let row = width as usize * 3;
    let expected = (row + 1)
        .checked_mul(height as usize)
        .ok_or_else(|| bad("image too large"))?;
    if raw.len() != expected {
        return Err(bad(format!(
            "image data has {} bytes, {width}×{height} RGB needs {expected}",
            raw.len()
        )));
    }
    let mut rgb = Vec::with_capacity(row * height as usize);
    for (y, line) in raw.chunks_exact(row + 1).enumerate() {
        if line[0] != 0 {
            return Err(bad(format!(
                "row {y} uses filter type {}; only filter 0 is supported",
                line[0]
            )));
        }
        rgb.extend_from_slice(&line[1..]);
    }
    Ok((width, height, rgb))
}

/// Unpacks a zlib stream whose deflate data is made of stored blocks only.
pub fn inflate_stored(zlib: &[u8]) -> Result<Vec<u8>> {
    if zlib.len() < 6 {
        return Err(bad("zlib stream too short"));
    }
    let (cmf, flg) = (zlib[0], zlib[1]);
    if cmf & 0x0F != 8 || ((u16::from(cmf) << 8) | u16::from(flg)) % 31 != 0 {
        return Err(bad("bad zlib header"));
    }
    if flg & 0x20 != 0 {
        return Err(bad("zlib preset dictionary is not supported"));
    }
    let mut pos = 2;
    let mut out = Vec::new();
    loop {
        let Some(&head) = zlib.get(pos) else {
            return Err(bad("deflate data ends without a final block"));
        };
        let btype = (head >> 1) & 3;
        if btype != 0 {
            return Err(bad(format!(
                "deflate block type {btype} (compressed) is not supported; only stored blocks"
            )));
        }
        if zlib.len() < pos + 5 {
            return Err(bad("truncated stored block header"));
        }
        let len = u16::from_le_bytes([zlib[pos + 1], zlib[pos + 2]]);
        let nlen = u16::from_le_bytes([zlib[pos + 3], zlib[pos + 4]]);
        if len != !nlen {
            return Err(bad("stored block LEN and NLEN disagree"));
        }
        pos += 5;
        let end = pos + len as usize;
        if end > zlib.len() {
            return Err(bad("stored block runs past the end"));
        }
        out.extend_from_slice(&zlib[pos..end]);
        pos = end;
        if head & 1 != 0 {
            break;
        }
    }
    if zlib.len() < pos + 4 {
        return Err(bad("missing Adler-32"));
    }
    if be32(&zlib[pos..]) != adler32(&out) {
        return Err(bad("Adler-32 mismatch"));
    }
    Ok(out)
}
