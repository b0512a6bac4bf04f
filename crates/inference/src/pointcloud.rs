//! Depth maps and coloured point clouds from disparity and calibration, written as PLY.
//!
//! Depth is `fx · baseline / (d + doffs)` in metres ([`Calibration::depth`]); pixels without a
//! usable disparity (unknown, or `d + doffs <= 0`: a negative disparity places no point in front
//! of the cameras) get `inf` in the depth map, the invalid value of a PFM map. A point cloud keeps the pixels whose depth is
//! finite, positive and at most `max_depth` (far points have a disparity of a pixel or less, so
//! their position is mostly noise), each coloured by the left image.
//!
//! PLY layout (both encodings hold the same data): one `vertex` element with `float x, y, z`
//! (metres, camera frame of the left view: x right, y down, z forward) and `uchar red, green,
//! blue`; `binary_little_endian` (15 bytes per point, the default, compact and what most viewers
//! read fastest) or `ascii` (one `x y z r g b` line per point, for inspection).

use std::io::{BufWriter, Write};
use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_data::{DisparityMap, RgbImage};

use crate::calibration::Calibration;

/// PLY encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum PlyEncoding {
    /// `binary_little_endian 1.0`.
    Binary,
    /// `ascii 1.0`.
    Ascii,
}

/// Points (metres) with their colours.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Positions `[x, y, z]`.
    pub points: Vec<[f32; 3]>,
    /// Colours `[r, g, b]`.
    pub colors: Vec<[u8; 3]>,
}

/// The depth (metres) of every pixel of a disparity map; `inf` where the disparity is unknown or
/// `d + doffs <= 0` (see [`Calibration::depth`]).
pub fn depth_map(disp: &DisparityMap, calib: &Calibration) -> DisparityMap {
    DisparityMap { width: disp.width, height: disp.height, data: disp.data.iter().map(|d| calib.depth(*d)).collect() }
}

/// Whether a depth belongs in the point cloud: finite, positive, at most `max_depth`.
pub fn keeps(z: f32, max_depth: f64) -> bool {
    z.is_finite() && z > 0.0 && (z as f64) <= max_depth
}

/// The coloured points of the pixels kept by [`keeps`].
///
/// # Shapes
/// `depth` and `image` have the same width and height (that of `calib`, see
/// [`Calibration::adjusted`]).
pub fn point_cloud(depth: &DisparityMap, image: &RgbImage, calib: &Calibration, max_depth: f64) -> Result<PointCloud> {
    if (depth.width, depth.height) != (image.width, image.height) {
        return Err(Error::Shape(format!(
            "depth map is {}x{} but the image is {}x{}",
            depth.width, depth.height, image.width, image.height
        )));
    }
    let k_inv =
        calib.intrinsics.try_inverse().ok_or_else(|| Error::format(&calib.source, "intrinsics are not invertible"))?;
    let mut cloud = PointCloud::default();
    for y in 0..depth.height {
        for x in 0..depth.width {
            let z = depth.get(x, y);
            if !keeps(z, max_depth) {
                continue;
            }
            let p = Calibration::backproject(&k_inv, x, y, z as f64);
            cloud.points.push([p.x as f32, p.y as f32, p.z as f32]);
            cloud.colors.push(image.get(x, y).map(|c| c.round().clamp(0.0, 255.0) as u8));
        }
    }
    Ok(cloud)
}

/// Writes a point cloud as PLY (see the module doc for the layout).
pub fn write_ply(path: &Path, cloud: &PointCloud, encoding: PlyEncoding) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut w = BufWriter::new(file);
    let format = match encoding {
        PlyEncoding::Binary => "binary_little_endian",
        PlyEncoding::Ascii => "ascii",
    };
    let write = |w: &mut BufWriter<std::fs::File>| -> std::io::Result<()> {
        write!(
            w,
            "ply\nformat {format} 1.0\ncomment dgstereo: metres, left camera frame (x right, y down, z forward)\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
            cloud.points.len()
        )?;
        for (p, c) in cloud.points.iter().zip(&cloud.colors) {
            match encoding {
                PlyEncoding::Binary => {
                    for v in p {
                        w.write_all(&v.to_le_bytes())?;
                    }
                    w.write_all(c)?;
                }
                PlyEncoding::Ascii => writeln!(w, "{} {} {} {} {} {}", p[0], p[1], p[2], c[0], c[1], c[2])?,
            }
        }
        w.flush()
    };
    write(&mut w).map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    #[test]
    fn cloud_drops_unknown_and_far_points() {
        let calib = Calibration {
            source: "test".into(),
            intrinsics: Matrix3::new(100.0, 0.0, 1.0, 0.0, 100.0, 0.0, 0.0, 0.0, 1.0),
            baseline_m: 0.1,
            doffs: 0.0,
            size: None,
            depth_range: None,
        };
        // Disparities 10 (1 m), 1 (10 m), NaN, 0, -3 → depths 1, 10, inf, inf, inf.
        let disp = DisparityMap::from_vec(5, 1, vec![10.0, 1.0, f32::NAN, 0.0, -3.0]).unwrap();
        let depth = depth_map(&disp, &calib);
        assert_eq!(depth.data[..2], [1.0, 10.0]);
        assert!(depth.data[2..].iter().all(|z| *z == f32::INFINITY), "{:?}", depth.data);
        let image = RgbImage::from_fn(5, 1, |x, _| [x as f32 * 10.0, 0.0, 255.0]);
        let cloud = point_cloud(&depth, &image, &calib, 5.0).unwrap();
        assert_eq!(cloud.points.len(), 1);
        // Pixel (0, 0) at 1 m with cx = 1: x = (0 - 1) / 100.
        assert!((cloud.points[0][0] + 0.01).abs() < 1e-6 && (cloud.points[0][2] - 1.0).abs() < 1e-6);
        assert_eq!(cloud.colors[0], [0, 0, 255]);

        let dir = tempfile::tempdir().unwrap();
        let (b, a) = (dir.path().join("b.ply"), dir.path().join("a.ply"));
        write_ply(&b, &cloud, PlyEncoding::Binary).unwrap();
        write_ply(&a, &cloud, PlyEncoding::Ascii).unwrap();
        let bytes = std::fs::read(&b).unwrap();
        let header_end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        assert_eq!(bytes.len() - header_end, 15);
        let text = std::fs::read_to_string(&a).unwrap();
        assert!(text.contains("element vertex 1\n") && text.ends_with("-0.01 0 1 0 0 255\n"), "{text}");
    }
}
