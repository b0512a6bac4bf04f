//! Readers (and writers, for tests and exports) of single-channel maps: `.npy`, `.pfm`, `.png`.
//!
//! Small and self-contained on purpose (the data crate is another stage's): NumPy arrays of any
//! float or integer dtype in C order whose shape is `(H, W)` up to leading/trailing 1s; PFM in
//! either byte order (`Pf` grey, or `PF` colour, first channel), stored bottom row first; PNG
//! grey at 16 or 8 bits, the stored integer taken as the value (the scale of a relative prior
//! does not matter).

use std::path::Path;

use dgstereo_core::{Error, Result};

/// A single-channel map, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// `height · width` values, row-major, top row first.
    pub values: Vec<f32>,
}

/// The extensions [`read_depth_map`] understands, in the order the file provider probes them.
pub const EXTENSIONS: [&str; 3] = ["npy", "pfm", "png"];

/// Reads a map, choosing the reader by the file's extension.
pub fn read_depth_map(path: &Path) -> Result<DepthMap> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("npy") => read_npy(path),
        Some("pfm") => read_pfm(path),
        Some("png") => read_png(path),
        _ => Err(Error::format(path, "unknown prior file type (expected .npy, .pfm or .png)")),
    }
}

fn header_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let start = header.find(&format!("'{key}'"))? + key.len() + 2;
    let rest = header[start..].trim_start().strip_prefix(':')?.trim_start();
    Some(rest)
}

/// Reads a `.npy` file holding a 2-D array (extra axes of length 1 allowed).
pub fn read_npy(path: &Path) -> Result<DepthMap> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |m: &str| Error::format(path, format!("npy: {m}"));
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("missing magic string"));
    }
    let (header_len, offset) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(bad(&format!("unsupported version {v}"))),
    };
    let header = std::str::from_utf8(bytes.get(offset..offset + header_len).ok_or_else(|| bad("truncated header"))?)
        .map_err(|_| bad("header is not text"))?;
    let descr = header_value(header, "descr").ok_or_else(|| bad("no 'descr'"))?;
    let descr = descr.trim_start_matches(['\'', '"']).split(['\'', '"']).next().unwrap_or("");
    if header_value(header, "fortran_order").is_some_and(|v| v.starts_with("True")) {
        return Err(bad("Fortran-ordered arrays are not supported"));
    }
    let shape_text = header_value(header, "shape").ok_or_else(|| bad("no 'shape'"))?;
    let shape_text = shape_text.trim_start_matches('(').split(')').next().unwrap_or("");
    let shape: Vec<usize> = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(|_| bad(&format!("bad shape '{shape_text}'"))))
        .collect::<Result<_>>()?;
    let mut dims = shape.as_slice();
    while dims.len() > 2 && dims[0] == 1 {
        dims = &dims[1..];
    }
    while dims.len() > 2 && dims[dims.len() - 1] == 1 {
        dims = &dims[..dims.len() - 1];
    }
    let &[height, width] = dims else {
        return Err(bad(&format!("shape {shape:?} is not a single 2-D map")));
    };
    if descr.len() < 3 {
        return Err(bad(&format!("bad dtype '{descr}'")));
    }
    let (order, kind) = descr.split_at(1);
    let big_endian = order == ">";
    let data = &bytes[offset + header_len..];
    let count = height * width;
    let size: usize = kind[1..].parse().map_err(|_| bad(&format!("bad dtype '{descr}'")))?;
    if data.len() < count * size {
        return Err(bad("truncated data"));
    }
    let word = |i: usize| -> Vec<u8> {
        let mut w = data[i * size..(i + 1) * size].to_vec();
        if big_endian {
            w.reverse();
        }
        w
    };
    let convert: Box<dyn Fn(Vec<u8>) -> f32> = match kind {
        "f4" => Box::new(|w| f32::from_le_bytes(w.try_into().unwrap())),
        "f8" => Box::new(|w| f64::from_le_bytes(w.try_into().unwrap()) as f32),
        "u1" => Box::new(|w| w[0] as f32),
        "u2" => Box::new(|w| u16::from_le_bytes(w.try_into().unwrap()) as f32),
        "i2" => Box::new(|w| i16::from_le_bytes(w.try_into().unwrap()) as f32),
        "i4" => Box::new(|w| i32::from_le_bytes(w.try_into().unwrap()) as f32),
        "u4" => Box::new(|w| u32::from_le_bytes(w.try_into().unwrap()) as f32),
        _ => return Err(bad(&format!("unsupported dtype '{descr}'"))),
    };
    Ok(DepthMap { height, width, values: (0..count).map(|i| convert(word(i))).collect() })
}

/// Writes a map as a little-endian float32 `.npy` of shape `(H, W)`.
pub fn write_npy(path: &Path, map: &DepthMap) -> Result<()> {
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}), }}", map.height, map.width);
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    out.extend(map.values.iter().flat_map(|v| v.to_le_bytes()));
    std::fs::write(path, out).map_err(|e| Error::io(path, e))
}

/// Reads a `.pfm` file (first channel of colour files).
pub fn read_pfm(path: &Path) -> Result<DepthMap> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |m: &str| Error::format(path, format!("pfm: {m}"));
    // Three whitespace-separated header tokens after the magic, then one whitespace byte.
    let mut tokens = Vec::new();
    let mut pos = 0;
    while tokens.len() < 4 {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err(bad("truncated header"));
        }
        tokens.push(std::str::from_utf8(&bytes[start..pos]).map_err(|_| bad("header is not text"))?.to_string());
    }
    let data = &bytes[pos + 1..];
    let channels = match tokens[0].as_str() {
        "Pf" => 1,
        "PF" => 3,
        m => return Err(bad(&format!("bad magic '{m}'"))),
    };
    let width: usize = tokens[1].parse().map_err(|_| bad("bad width"))?;
    let height: usize = tokens[2].parse().map_err(|_| bad("bad height"))?;
    let scale: f32 = tokens[3].parse().map_err(|_| bad("bad scale"))?;
    if data.len() < width * height * channels * 4 {
        return Err(bad("truncated data"));
    }
    let mut values = vec![0f32; width * height];
    for row in 0..height {
        for col in 0..width {
            let i = ((height - 1 - row) * width + col) * channels * 4;
            let b = [data[i], data[i + 1], data[i + 2], data[i + 3]];
            values[row * width + col] = if scale < 0.0 { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) };
        }
    }
    Ok(DepthMap { height, width, values })
}

/// Writes a map as a little-endian grey `.pfm`.
pub fn write_pfm(path: &Path, map: &DepthMap) -> Result<()> {
    let mut out = format!("Pf\n{} {}\n-1.0\n", map.width, map.height).into_bytes();
    for row in (0..map.height).rev() {
        out.extend(map.values[row * map.width..(row + 1) * map.width].iter().flat_map(|v| v.to_le_bytes()));
    }
    std::fs::write(path, out).map_err(|e| Error::io(path, e))
}

/// Reads a grey `.png` (16 or 8 bits); the values are the stored integers.
pub fn read_png(path: &Path) -> Result<DepthMap> {
    let image = image::open(path).map_err(|e| Error::format(path, format!("png: {e}")))?;
    let (width, height) = (image.width() as usize, image.height() as usize);
    let values = match image {
        image::DynamicImage::ImageLuma16(g) => g.into_raw().into_iter().map(f32::from).collect(),
        image::DynamicImage::ImageLuma8(g) => g.into_raw().into_iter().map(f32::from).collect(),
        other => {
            return Err(Error::format(
                path,
                format!("png: a prior must be one grey channel, found {:?}", other.color()),
            ));
        }
    };
    Ok(DepthMap { height, width, values })
}

/// Writes a map as a 16-bit grey `.png`, values rounded and clamped to `0..=65535`.
pub fn write_png16(path: &Path, map: &DepthMap) -> Result<()> {
    let raw: Vec<u16> = map.values.iter().map(|v| v.round().clamp(0.0, 65535.0) as u16).collect();
    let buffer = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(map.width as u32, map.height as u32, raw)
        .ok_or_else(|| Error::format(path, "png: size does not match the values"))?;
    buffer.save(path).map_err(|e| Error::format(path, format!("png: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> DepthMap {
        let (height, width) = (5, 7);
        DepthMap { height, width, values: (0..35).map(|i| (i * 37 % 101) as f32 * 3.0 + 1.0).collect() }
    }

    #[test]
    fn formats_round_trip_and_keep_row_order() {
        let dir = std::env::temp_dir().join(format!("dgstereo-prior-formats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let map = sample();
        for (ext, write) in
            [("npy", write_npy as fn(&Path, &DepthMap) -> Result<()>), ("pfm", write_pfm), ("png", write_png16)]
        {
            let path = dir.join(format!("m.{ext}"));
            write(&path, &map).unwrap();
            let back = read_depth_map(&path).unwrap();
            assert_eq!(back, map, "{ext}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn npy_reads_other_dtypes_and_rejects_3d() {
        let dir = std::env::temp_dir().join(format!("dgstereo-prior-npy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, descr: &str, shape: &str, data: Vec<u8>| {
            let header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}\n");
            let mut out = b"\x93NUMPY\x01\x00".to_vec();
            out.extend((header.len() as u16).to_le_bytes());
            out.extend(header.as_bytes());
            out.extend(data);
            let p = dir.join(name);
            std::fs::write(&p, out).unwrap();
            p
        };
        let f8 = write(
            "a.npy",
            "<f8",
            "(1, 2, 3)",
            [1.5f64, 2.0, 3.0, 4.0, 5.0, 6.25].iter().flat_map(|v| v.to_le_bytes()).collect(),
        );
        let m = read_npy(&f8).unwrap();
        assert_eq!((m.height, m.width), (2, 3));
        assert_eq!(m.values, vec![1.5, 2.0, 3.0, 4.0, 5.0, 6.25]);
        let be = write("b.npy", ">f4", "(2, 1)", [7.0f32, -1.0].iter().flat_map(|v| v.to_be_bytes()).collect());
        assert_eq!(read_npy(&be).unwrap().values, vec![7.0, -1.0]);
        let u2 = write("c.npy", "<u2", "(1, 2)", [300u16, 65535].iter().flat_map(|v| v.to_le_bytes()).collect());
        assert_eq!(read_npy(&u2).unwrap().values, vec![300.0, 65535.0]);
        let cube = write("d.npy", "<f4", "(2, 2, 2)", vec![0; 32]);
        let err = read_npy(&cube).unwrap_err().to_string();
        assert!(err.contains("d.npy"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
