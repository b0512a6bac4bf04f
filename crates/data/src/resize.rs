//! Resizing of planes, images, disparity and masks with OpenCV's conventions.
//!
//! [`resize_plane_linear`] is `cv2.resize(src, None, fx, fy, INTER_LINEAR)` on `f32` data: the
//! output size is `round(w · fx) x round(h · fy)` and output pixel `dx` samples the source at
//! `(dx + 0.5) / fx - 0.5` (half-pixel centres), clamped to the border. [`resize_plane_nearest`]
//! takes the source pixel `floor((dx + 0.5) / fx)` (`INTER_NEAREST_EXACT`), so it never mixes
//! values: it is how sparse or discontinuous maps (valid masks, the disparity for the edge-aware
//! loss) are resized. Interpolation skips zero weights, so a NaN only spreads to output pixels
//! that really mix it in.

use crate::image::{DisparityMap, Mask, RgbImage};

/// The output size of `cv2.resize(None, fx, fy)`: `(round(w · fx), round(h · fy))`, at least 1.
pub fn scaled_size(width: usize, height: usize, fx: f64, fy: f64) -> (usize, usize) {
    let r = |v: f64| (v.round_ties_even() as usize).max(1);
    (r(width as f64 * fx), r(height as f64 * fy))
}

/// Source index and weight of the next sample for each output index (OpenCV's `INTER_LINEAR`).
fn linear_taps(n_in: usize, n_out: usize, scale: f64) -> Vec<(usize, f32)> {
    let inv = 1.0 / scale;
    (0..n_out)
        .map(|d| {
            let f = (d as f64 + 0.5) * inv - 0.5;
            let mut s = f.floor();
            let mut t = f - s;
            if s < 0.0 {
                s = 0.0;
                t = 0.0;
            }
            if s as usize >= n_in - 1 {
                s = (n_in - 1) as f64;
                t = 0.0;
            }
            (s as usize, t as f32)
        })
        .collect()
}

fn nearest_taps(n_in: usize, n_out: usize, scale: f64) -> Vec<usize> {
    (0..n_out).map(|d| (((d as f64 + 0.5) / scale).floor() as usize).min(n_in - 1)).collect()
}

#[inline]
fn mix(a: f32, b: f32, t: f32) -> f32 {
    if t == 0.0 {
        a
    } else if t == 1.0 {
        b
    } else {
        a * (1.0 - t) + b * t
    }
}

/// Resizes a row-major plane by factors `fx`, `fy` with `INTER_LINEAR`; returns `(plane, w, h)`.
pub fn resize_plane_linear(src: &[f32], width: usize, height: usize, fx: f64, fy: f64) -> (Vec<f32>, usize, usize) {
    let (ow, oh) = scaled_size(width, height, fx, fy);
    let xs = linear_taps(width, ow, fx);
    let ys = linear_taps(height, oh, fy);
    let mut out = Vec::with_capacity(ow * oh);
    for &(sy, ty) in &ys {
        let r0 = &src[sy * width..(sy + 1) * width];
        let r1 = &src[(sy + 1).min(height - 1) * width..((sy + 1).min(height - 1) + 1) * width];
        for &(sx, tx) in &xs {
            let sx1 = (sx + 1).min(width - 1);
            let top = mix(r0[sx], r0[sx1], tx);
            let bot = if ty == 0.0 { 0.0 } else { mix(r1[sx], r1[sx1], tx) };
            out.push(mix(top, bot, ty));
        }
    }
    (out, ow, oh)
}

/// Resizes a row-major plane by factors `fx`, `fy` with half-pixel nearest neighbour.
pub fn resize_plane_nearest<T: Copy>(
    src: &[T],
    width: usize,
    height: usize,
    fx: f64,
    fy: f64,
) -> (Vec<T>, usize, usize) {
    let (ow, oh) = scaled_size(width, height, fx, fy);
    let xs = nearest_taps(width, ow, fx);
    let ys = nearest_taps(height, oh, fy);
    let mut out = Vec::with_capacity(ow * oh);
    for &sy in &ys {
        for &sx in &xs {
            out.push(src[sy * width + sx]);
        }
    }
    (out, ow, oh)
}

/// Resizes an image bilinearly (`INTER_LINEAR`), channel by channel.
pub fn resize_rgb(img: &RgbImage, fx: f64, fy: f64) -> RgbImage {
    let (ow, oh) = scaled_size(img.width, img.height, fx, fy);
    let mut data = Vec::with_capacity(3 * ow * oh);
    for c in 0..3 {
        data.extend(resize_plane_linear(img.plane(c), img.width, img.height, fx, fy).0);
    }
    RgbImage { width: ow, height: oh, data }
}

/// Resizes a disparity map both bilinearly and by nearest neighbour, each multiplied by `fx`
/// (disparity is a horizontal distance); returns `(linear, nearest)`.
pub fn resize_disparity(d: &DisparityMap, fx: f64, fy: f64) -> (DisparityMap, DisparityMap) {
    let s = fx as f32;
    let (lin, w, h) = resize_plane_linear(&d.data, d.width, d.height, fx, fy);
    let (near, _, _) = resize_plane_nearest(&d.data, d.width, d.height, fx, fy);
    (
        DisparityMap { width: w, height: h, data: lin.into_iter().map(|v| v * s).collect() },
        DisparityMap { width: w, height: h, data: near.into_iter().map(|v| v * s).collect() },
    )
}

/// Resizes a mask by nearest neighbour.
pub fn resize_mask(m: &Mask, fx: f64, fy: f64) -> Mask {
    let (data, width, height) = resize_plane_nearest(&m.data, m.width, m.height, fx, fy);
    Mask { width, height, data }
}

/// The factor that brings the longer side of `width x height` down to `max_size` pixels (1 when
/// it fits or there is no limit).
pub fn fit_scale(width: usize, height: usize, max_size: Option<usize>) -> f64 {
    match max_size {
        Some(m) if width.max(height) > m => m as f64 / width.max(height) as f64,
        _ => 1.0,
    }
}

/// A disparity map computed on a downscaled pair, brought back to `width x height`: resized
/// bilinearly and multiplied by the width ratio (disparity is a horizontal distance).
pub fn disparity_to_size(small: &DisparityMap, width: usize, height: usize) -> dgstereo_core::Result<DisparityMap> {
    if (small.width, small.height) == (width, height) {
        return Ok(small.clone());
    }
    let (fx, fy) = (width as f64 / small.width as f64, height as f64 / small.height as f64);
    let (data, ow, oh) = resize_plane_linear(&small.data, small.width, small.height, fx, fy);
    if (ow, oh) != (width, height) {
        return Err(dgstereo_core::Error::Shape(format!(
            "disparity of {}x{} resized to {ow}x{oh} instead of {width}x{height}",
            small.width, small.height
        )));
    }
    let sx = fx as f32;
    Ok(DisparityMap { width, height, data: data.into_iter().map(|d| d * sx).collect() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downscaled_disparity_comes_back_at_size_and_scale() {
        assert_eq!(fit_scale(450, 375, Some(150)), 150.0 / 450.0);
        assert_eq!(fit_scale(450, 375, Some(500)), 1.0);
        assert_eq!(fit_scale(450, 375, None), 1.0);
        let s = fit_scale(450, 375, Some(150));
        let (w, h) = scaled_size(450, 375, s, s);
        let small = DisparityMap { width: w, height: h, data: vec![10.0; w * h] };
        let back = disparity_to_size(&small, 450, 375).unwrap();
        assert_eq!((back.width, back.height), (450, 375));
        assert!(back.data.iter().all(|d| (d - 30.0).abs() < 1e-4), "10 px at a third of the width is 30 px");
    }

    #[test]
    fn linear_matches_opencv_half_pixel_formula() {
        // cv2.resize(np.float32([[0, 10, 20, 30]]), None, fx=2, fy=1) =
        // [0, 2.5, 7.5, 12.5, 17.5, 22.5, 27.5, 30].
        let (out, w, h) = resize_plane_linear(&[0.0, 10.0, 20.0, 30.0], 4, 1, 2.0, 1.0);
        assert_eq!((w, h), (8, 1));
        assert_eq!(out, vec![0.0, 2.5, 7.5, 12.5, 17.5, 22.5, 27.5, 30.0]);
        // Halving averages pairs: [5, 25].
        let (out, _, _) = resize_plane_linear(&[0.0, 10.0, 20.0, 30.0], 4, 1, 0.5, 1.0);
        assert_eq!(out, vec![5.0, 25.0]);
    }

    #[test]
    fn nearest_never_mixes_and_disparity_scales_with_fx() {
        let d = DisparityMap::from_vec(4, 2, vec![1.0, 1.0, 9.0, 9.0, 1.0, 1.0, 9.0, 9.0]).unwrap();
        let (lin, near) = resize_disparity(&d, 1.5, 1.0);
        assert_eq!((lin.width, lin.height), (6, 2));
        assert!(near.data.iter().all(|v| *v == 1.5 || *v == 13.5));
        assert!(lin.data.iter().any(|v| *v > 1.5 && *v < 13.5));
        assert_eq!(lin.get(0, 0), 1.5);
        assert_eq!(lin.get(5, 1), 13.5);
    }

    #[test]
    fn nan_spreads_only_to_pixels_mixing_it() {
        let src = [1.0, 1.0, f32::NAN, 1.0, 1.0, 1.0, 1.0, 1.0];
        let (out, _, _) = resize_plane_linear(&src, 8, 1, 1.0, 1.0);
        assert!(out[2].is_nan() && out.iter().filter(|v| v.is_nan()).count() == 1);
        let (out, _, _) = resize_plane_linear(&src, 8, 1, 2.0, 1.0);
        assert!(out[0].is_finite() && out[15].is_finite());
    }

    #[test]
    fn size_rounds_like_opencv() {
        assert_eq!(scaled_size(100, 50, 1.256, 0.5), (126, 25));
        assert_eq!(scaled_size(3, 3, 0.1, 0.1), (1, 1));
    }
}
