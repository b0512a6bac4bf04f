//! Middlebury's `calib.txt`: `key=value` lines, the camera matrices as `[f 0 cx; 0 f cy; 0 0 1]`,
//! the baseline in millimetres.

use std::path::Path;

use dgstereo_core::{Error, Result};

/// The contents of a Middlebury `calib.txt`.
#[derive(Clone, Debug, PartialEq)]
pub struct MiddleburyCalib {
    /// Left camera matrix, row-major 3x3.
    pub cam0: [[f64; 3]; 3],
    /// Right camera matrix.
    pub cam1: [[f64; 3]; 3],
    /// x-difference of the principal points (`disparity + doffs` is the true disparity).
    pub doffs: f64,
    /// Baseline (mm).
    pub baseline: f64,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Conservative bound on the disparity range.
    pub ndisp: usize,
}

impl MiddleburyCalib {
    /// Depth (in the baseline's unit) of a disparity `d`: `baseline · f / (d + doffs)`.
    pub fn depth(&self, d: f64) -> f64 {
        self.baseline * self.cam0[0][0] / (d + self.doffs)
    }
}

fn parse_matrix(s: &str) -> Option<[[f64; 3]; 3]> {
    let inner = s.trim().strip_prefix('[')?.strip_suffix(']')?;
    let rows: Vec<&str> = inner.split(';').collect();
    if rows.len() != 3 {
        return None;
    }
    let mut m = [[0.0; 3]; 3];
    for (r, row) in rows.iter().enumerate() {
        let vals: Vec<f64> = row.split_whitespace().map(str::parse).collect::<std::result::Result<_, _>>().ok()?;
        if vals.len() != 3 {
            return None;
        }
        m[r].copy_from_slice(&vals);
    }
    Some(m)
}

/// Parses a Middlebury `calib.txt` (`key=value` lines; `cam0=[f 0 cx; 0 f cy; 0 0 1]`).
/// Unknown keys (`isint`, `vmin`, `vmax`, `dyavg`, `dymax`) are ignored; the keys of
/// [`MiddleburyCalib`] are required.
pub fn read_middlebury_calib(path: impl AsRef<Path>) -> Result<MiddleburyCalib> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut kv = std::collections::HashMap::new();
    for line in text.lines() {
        if let Some((k, v)) = line.split_once('=') {
            kv.insert(k.trim().to_string(), v.trim().to_string());
        }
    }
    let get = |k: &str| kv.get(k).ok_or_else(|| Error::format(path, format!("calib: missing key {k:?}")));
    let num = |k: &str| -> Result<f64> {
        get(k)?.parse::<f64>().map_err(|_| Error::format(path, format!("calib: {k} is not a number")))
    };
    let mat = |k: &str| -> Result<[[f64; 3]; 3]> {
        parse_matrix(get(k)?)
            .ok_or_else(|| Error::format(path, format!("calib: {k} is not a 3x3 matrix [a b c; d e f; g h i]")))
    };
    Ok(MiddleburyCalib {
        cam0: mat("cam0")?,
        cam1: mat("cam1")?,
        doffs: num("doffs")?,
        baseline: num("baseline")?,
        width: num("width")? as usize,
        height: num("height")? as usize,
        ndisp: num("ndisp")? as usize,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_calib_txt_is_read_and_a_broken_one_names_the_file_and_key() {
        let dir = tempfile::tempdir().unwrap();
        let calib = dir.path().join("calib.txt");
        std::fs::write(
            &calib,
            "cam0=[4161.221 0 1445.577; 0 4161.221 984.686; 0 0 1]\ncam1=[4161.221 0 1654.636; 0 4161.221 984.686; 0 0 1]\n\
             doffs=209.059\nbaseline=176.252\nwidth=2880\nheight=1988\nndisp=280\nisint=0\nvmin=33\nvmax=218\n",
        )
        .unwrap();
        let c = read_middlebury_calib(&calib).unwrap();
        assert_eq!((c.width, c.height, c.ndisp), (2880, 1988, 280));
        assert_eq!(c.cam0[0][2], 1445.577);
        assert_eq!(c.cam1[0][2], 1654.636);
        assert_eq!((c.doffs, c.baseline), (209.059, 176.252));
        assert!((c.depth(100.0) - 176.252 * 4161.221 / 309.059).abs() < 1e-9);
        std::fs::write(&calib, "cam0=[1 0 0; 0 1 0]\ndoffs=1\n").unwrap();
        let e = read_middlebury_calib(&calib).unwrap_err().to_string();
        assert!(e.contains("calib.txt") && e.contains("cam0"), "{e}");
    }
}
