//! PFM (portable float map): `PF` colour or `Pf` grayscale, `f32`, either endianness.
//!
//! # Layout on disk
//! A text header `PF|Pf <ws> width <ws> height <ws> scale`, one whitespace byte, then
//! `width * height * channels` `f32` samples, interleaved, rows **bottom to top**. A negative
//! scale means little-endian samples, a positive one big-endian. Reading flips the rows so
//! memory is top to bottom; writing flips them back.

use std::path::Path;

use dgstereo_core::{Error, Result};

/// A decoded PFM: `channels` is 1 (`Pf`) or 3 (`PF`), samples interleaved, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Pfm {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// 1 or 3.
    pub channels: usize,
    /// Samples, `HWC`, top row first.
    pub data: Vec<f32>,
}

/// Byte order of the samples of a written PFM.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Endian {
    /// Little-endian (negative scale in the header), what most tools write.
    Little,
    /// Big-endian (positive scale).
    Big,
}

/// What a PFM's header says: the size, the channels, the byte order and where the samples start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PfmHeader {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// 1 (`Pf`) or 3 (`PF`).
    pub channels: usize,
    /// Whether the samples are little-endian (a negative scale).
    pub little_endian: bool,
    /// The offset of the first sample.
    pub data_start: usize,
}

impl PfmHeader {
    /// The number of sample bytes the header promises.
    pub fn data_bytes(&self) -> usize {
        self.width * self.height * self.channels * 4
    }
}

/// Parses the header at the start of `bytes` (the samples need not follow); `path` only names
/// the file in errors.
pub fn decode_pfm_header(bytes: &[u8], path: &Path) -> Result<PfmHeader> {
    let err = |m: String| Error::format(path, format!("PFM: {m}"));
    let mut pos = 0usize;
    let mut token = |what: &str| -> Result<String> {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err(err(format!("header ends before the {what}")));
        }
        if pos - start > 32 {
            return Err(err(format!("the {what} is not a header token")));
        }
        Ok(String::from_utf8_lossy(&bytes[start..pos]).into_owned())
    };
    let magic = token("magic")?;
    let channels = match magic.as_str() {
        "PF" => 3,
        "Pf" => 1,
        m => return Err(err(format!("bad magic {m:?}, expected \"PF\" or \"Pf\""))),
    };
    let width: usize = token("width")?.parse().map_err(|_| err("bad width".into()))?;
    let height: usize = token("height")?.parse().map_err(|_| err("bad height".into()))?;
    let scale: f32 = token("scale")?.parse().map_err(|_| err("bad scale".into()))?;
    if scale == 0.0 || !scale.is_finite() {
        return Err(err(format!("scale {scale} must be finite and non-zero")));
    }
    // Exactly one whitespace byte separates the header from the samples.
    if pos >= bytes.len() || !bytes[pos].is_ascii_whitespace() {
        return Err(err("missing whitespace after the header".into()));
    }
    width
        .checked_mul(height)
        .and_then(|v| v.checked_mul(channels * 4))
        .ok_or_else(|| err(format!("size {width}x{height} overflows")))?;
    Ok(PfmHeader { width, height, channels, little_endian: scale < 0.0, data_start: pos + 1 })
}

/// The error of a PFM whose samples are fewer than its header promises.
fn truncated(header: &PfmHeader, found: usize, path: &Path) -> Error {
    let PfmHeader { width, height, channels, .. } = *header;
    Error::format(
        path,
        format!("PFM: truncated: {width}x{height}x{channels} needs {} data bytes, found {found}", header.data_bytes()),
    )
}

/// Reads a PFM file's header and checks, by the file's length, that every sample is there,
/// without reading the samples.
pub fn read_pfm_header(path: impl AsRef<Path>) -> Result<PfmHeader> {
    let path = path.as_ref();
    let (prefix, length) = crate::file_start::read_prefix(path, 4096)?;
    let header = decode_pfm_header(&prefix, path)?;
    let found = length.saturating_sub(header.data_start as u64);
    if found < header.data_bytes() as u64 {
        return Err(truncated(&header, found as usize, path));
    }
    Ok(header)
}

/// Parses PFM bytes; `path` only names the file in errors.
pub fn decode_pfm(bytes: &[u8], path: &Path) -> Result<Pfm> {
    let header = decode_pfm_header(bytes, path)?;
    let PfmHeader { width, height, channels, little_endian: little, data_start } = header;
    let n = width * height * channels;
    let body = &bytes[data_start..];
    if body.len() < n * 4 {
        return Err(truncated(&header, body.len(), path));
    }
    let row = width * channels;
    let mut data = vec![0f32; n];
    for (i, chunk) in body[..n * 4].chunks_exact(4).enumerate() {
        let b = [chunk[0], chunk[1], chunk[2], chunk[3]];
        let v = if little { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) };
        // File row r (bottom first) goes to memory row height-1-r.
        let (r, c) = (i / row, i % row);
        data[(height - 1 - r) * row + c] = v;
    }
    Ok(Pfm { width, height, channels, data })
}

/// Encodes a PFM with the given byte order.
pub fn encode_pfm(pfm: &Pfm, endian: Endian) -> Result<Vec<u8>> {
    if pfm.channels != 1 && pfm.channels != 3 {
        return Err(Error::Shape(format!("PFM needs 1 or 3 channels, got {}", pfm.channels)));
    }
    let row = pfm.width * pfm.channels;
    if pfm.data.len() != row * pfm.height {
        return Err(Error::Shape(format!(
            "PFM {}x{}x{} needs {} samples, got {}",
            pfm.width,
            pfm.height,
            pfm.channels,
            row * pfm.height,
            pfm.data.len()
        )));
    }
    let magic = if pfm.channels == 3 { "PF" } else { "Pf" };
    let scale = if endian == Endian::Little { "-1.0" } else { "1.0" };
    let mut out = format!("{magic}\n{} {}\n{scale}\n", pfm.width, pfm.height).into_bytes();
    out.reserve(pfm.data.len() * 4);
    for r in (0..pfm.height).rev() {
        for v in &pfm.data[r * row..(r + 1) * row] {
            let b = if endian == Endian::Little { v.to_le_bytes() } else { v.to_be_bytes() };
            out.extend_from_slice(&b);
        }
    }
    Ok(out)
}

/// Reads a PFM file.
pub fn read_pfm(path: impl AsRef<Path>) -> Result<Pfm> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode_pfm(&bytes, path)
}

/// Writes a PFM file.
pub fn write_pfm(path: impl AsRef<Path>, pfm: &Pfm, endian: Endian) -> Result<()> {
    let path = path.as_ref();
    let bytes = encode_pfm(pfm, endian).map_err(|e| Error::format(path, e.to_string()))?;
    std::fs::write(path, bytes).map_err(|e| Error::io(path, e))
}
