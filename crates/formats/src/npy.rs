//! NumPy `.npy` arrays (read any rank in C order, write `float32`/`float64`).
//!
//! # Layout on disk
//! `\x93NUMPY`, version `major minor`, a little-endian header length (`u16` for 1.0, `u32` for
//! 2.0/3.0), a Python-literal dict `{'descr': '<f4', 'fortran_order': False, 'shape': (H, W), }`
//! padded with spaces and a newline to a multiple of 64 bytes, then the raw samples.
//! Reading accepts floats (`f4`, `f8`) and integers (`u1`, `i1`, `u2`, `i2`, `u4`, `i4`) in either
//! byte order, every sample converted to `f32`; Fortran order is refused.

use std::path::Path;

use dgstereo_core::{Error, Result};

/// A decoded array: `shape` and its samples in C (row-major) order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Dimensions, outermost first.
    pub shape: Vec<usize>,
    /// Samples, row-major.
    pub data: Vec<f32>,
}

/// Sample type of a written `.npy`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NpyDtype {
    /// `<f4`
    F32,
    /// `<f8`
    F64,
}

const MAGIC: &[u8] = b"\x93NUMPY";

/// What a sample of a read `.npy` is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleKind {
    /// IEEE float (`f`).
    Float,
    /// Unsigned integer (`u`).
    Unsigned,
    /// Signed integer (`i`).
    Signed,
}

/// What a `.npy` header says: the shape, the sample type and where the samples start.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NpyHeader {
    /// Dimensions, outermost first.
    pub shape: Vec<usize>,
    /// What a sample is.
    pub kind: SampleKind,
    /// Bytes per sample (1, 2, 4 or 8).
    pub sample_bytes: usize,
    /// Whether the samples are little-endian.
    pub little_endian: bool,
    /// The offset of the first sample.
    pub data_start: usize,
}

impl NpyHeader {
    /// The number of sample bytes the header promises.
    pub fn data_bytes(&self) -> usize {
        self.shape.iter().product::<usize>() * self.sample_bytes
    }
}

/// The offset just past the header of the `.npy` bytes starting `bytes` (the magic, the version
/// and the header's length are read; 10 or 12 bytes suffice).
fn header_end(bytes: &[u8], path: &Path) -> Result<usize> {
    let err = |m: &str| Error::format(path, format!("npy: {m}"));
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(err("not a .npy file (bad magic)"));
    }
    match bytes[6] {
        1 => Ok(10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize),
        2 | 3 if bytes.len() < 12 => Err(err("truncated header")),
        2 | 3 => Ok(12 + u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize),
        v => Err(Error::format(path, format!("npy: unsupported version {v}"))),
    }
}

/// Parses the header at the start of `bytes` (the samples need not follow); `path` only names
/// the file in errors.
pub fn decode_npy_header(bytes: &[u8], path: &Path) -> Result<NpyHeader> {
    let err = |m: String| Error::format(path, format!("npy: {m}"));
    let end = header_end(bytes, path)?;
    let start = if bytes[6] == 1 { 10 } else { 12 };
    if bytes.len() < end {
        return Err(err("truncated header".into()));
    }
    let header = std::str::from_utf8(&bytes[start..end]).map_err(|_| err("header is not text".into()))?;
    let descr = dict_value(header, "descr").ok_or_else(|| err("header lacks 'descr'".into()))?;
    let descr = descr.trim().trim_matches(|c| c == '\'' || c == '"');
    let fortran = dict_value(header, "fortran_order").ok_or_else(|| err("header lacks 'fortran_order'".into()))?;
    if fortran.trim().starts_with("True") {
        return Err(err("Fortran-order arrays are not supported".into()));
    }
    let shape_s = dict_value(header, "shape").ok_or_else(|| err("header lacks 'shape'".into()))?;
    let shape_s = shape_s.trim();
    let inner = shape_s
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| err(format!("bad shape {shape_s:?}")))?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse::<usize>())
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|_| err(format!("bad shape {shape_s:?}")))?;
    let (sample_bytes, little_endian, kind) = dtype(descr).ok_or_else(|| {
        err(format!("unsupported dtype {descr:?} (need a float: f4, f8, or an integer: u1, i1, u2, i2, u4, i4)"))
    })?;
    shape
        .iter()
        .try_fold(sample_bytes, |n: usize, d| n.checked_mul(*d))
        .ok_or_else(|| err(format!("shape {shape:?} overflows")))?;
    Ok(NpyHeader { shape, kind, sample_bytes, little_endian, data_start: end })
}

/// `(bytes per sample, little-endian, kind)` of a `descr` such as `<f4`, `|u1` or `>i2`.
fn dtype(descr: &str) -> Option<(usize, bool, SampleKind)> {
    let (order, code) = descr.split_at_checked(1)?;
    let little = match order {
        "<" | "|" | "=" => true,
        ">" => false,
        _ => return None,
    };
    let (kind, bytes) = match code {
        "f4" => (SampleKind::Float, 4),
        "f8" => (SampleKind::Float, 8),
        "u1" => (SampleKind::Unsigned, 1),
        "i1" => (SampleKind::Signed, 1),
        "u2" => (SampleKind::Unsigned, 2),
        "i2" => (SampleKind::Signed, 2),
        "u4" => (SampleKind::Unsigned, 4),
        "i4" => (SampleKind::Signed, 4),
        _ => return None,
    };
    Some((bytes, little, kind))
}

/// One sample of `header`'s type from its `bytes` (as many as the type's size), as `f32`.
fn sample(header: &NpyHeader, bytes: &[u8]) -> f32 {
    let mut b = [0u8; 8];
    let n = header.sample_bytes;
    b[..n].copy_from_slice(bytes);
    if !header.little_endian {
        b[..n].reverse();
    }
    match (header.kind, n) {
        (SampleKind::Float, 4) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        (SampleKind::Float, _) => f64::from_le_bytes(b) as f32,
        (SampleKind::Unsigned, _) => u64::from_le_bytes(b) as f32,
        (SampleKind::Signed, _) => {
            // Sign-extend the n-byte value.
            let shift = 64 - 8 * n as u32;
            ((u64::from_le_bytes(b) << shift) as i64 >> shift) as f32
        }
    }
}

/// The error of a `.npy` whose samples are fewer than its header promises.
fn truncated(header: &NpyHeader, found: usize, path: &Path) -> Error {
    Error::format(
        path,
        format!("npy: truncated: shape {:?} needs {} data bytes, found {found}", header.shape, header.data_bytes()),
    )
}

/// Reads a `.npy` file's header and checks, by the file's length, that every sample is there,
/// without reading the samples.
pub fn read_npy_header(path: impl AsRef<Path>) -> Result<NpyHeader> {
    let path = path.as_ref();
    let (mut prefix, length) = crate::file_start::read_prefix(path, 4096)?;
    let end = header_end(&prefix, path)?;
    if end > prefix.len() && (end as u64) <= length {
        prefix = crate::file_start::read_prefix(path, end)?.0;
    }
    let header = decode_npy_header(&prefix, path)?;
    let found = length.saturating_sub(header.data_start as u64);
    if found < header.data_bytes() as u64 {
        return Err(truncated(&header, found as usize, path));
    }
    Ok(header)
}

/// Parses `.npy` bytes; `path` only names the file in errors.
pub fn decode_npy(bytes: &[u8], path: &Path) -> Result<NpyArray> {
    let header = decode_npy_header(bytes, path)?;
    let size = header.sample_bytes;
    let n: usize = header.shape.iter().product();
    let body = &bytes[header.data_start..];
    if body.len() < n * size {
        return Err(truncated(&header, body.len(), path));
    }
    let data = body[..n * size].chunks_exact(size).map(|c| sample(&header, c)).collect();
    Ok(NpyArray { shape: header.shape, data })
}

/// The text after `'key':` in a header dict, up to the next top-level comma.
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let pat_sq = format!("'{key}'");
    let pat_dq = format!("\"{key}\"");
    let at =
        header.find(&pat_sq).map(|i| i + pat_sq.len()).or_else(|| header.find(&pat_dq).map(|i| i + pat_dq.len()))?;
    let rest = header[at..].trim_start().strip_prefix(':')?;
    let mut depth = 0i32;
    for (i, c) in rest.char_indices() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' | '}' if depth == 0 => return Some(&rest[..i]),
            _ => {}
        }
    }
    Some(rest)
}

/// Encodes an array as `.npy` version 1.0.
pub fn encode_npy(arr: &NpyArray, dtype: NpyDtype) -> Result<Vec<u8>> {
    let n: usize = arr.shape.iter().product();
    if n != arr.data.len() {
        return Err(Error::Shape(format!("npy shape {:?} needs {n} samples, got {}", arr.shape, arr.data.len())));
    }
    let shape = match arr.shape.len() {
        1 => format!("({},)", arr.shape[0]),
        _ => format!("({})", arr.shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let descr = if dtype == NpyDtype::F32 { "<f4" } else { "<f8" };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + n * 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in &arr.data {
        match dtype {
            NpyDtype::F32 => out.extend_from_slice(&v.to_le_bytes()),
            NpyDtype::F64 => out.extend_from_slice(&f64::from(*v).to_le_bytes()),
        }
    }
    Ok(out)
}

/// Reads a `.npy` file.
pub fn read_npy(path: impl AsRef<Path>) -> Result<NpyArray> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode_npy(&bytes, path)
}

/// Writes a `.npy` file.
pub fn write_npy(path: impl AsRef<Path>, arr: &NpyArray, dtype: NpyDtype) -> Result<()> {
    let path = path.as_ref();
    let bytes = encode_npy(arr, dtype).map_err(|e| Error::format(path, e.to_string()))?;
    std::fs::write(path, bytes).map_err(|e| Error::io(path, e))
}
