//! Left-right consistency: which pixels of the left view's disparity the right view confirms.
//!
//! A pixel that only the left camera sees (the band along the left border, the strip left of
//! each foreground object) has no match, and a network extrapolates there. Running the same
//! network on the mirrored and swapped pair gives the right view's disparity (mirroring turns
//! the right view into a left one); a left pixel `x` with disparity `d` is *confirmed* when the
//! right view's disparity at `x - d` agrees within a threshold. Rejected pixels are filled from
//! the nearest confirmed pixels on their row, the smaller (farther) of the two: an occluded pixel
//! belongs to the surface behind the occluder. This is the classical post-processing of stereo
//! matchers (the left-right check and background fill of Hirschmüller's semi-global matching),
//! applied to the network's two outputs.

use dgstereo_core::{Error, Result};
use dgstereo_data::{DisparityMap, Mask, RgbImage};

/// The usual threshold of the check, in pixels: the two views' disparities may differ by this
/// much before a pixel is rejected.
pub const DEFAULT_THRESHOLD: f32 = 2.0;

/// The image mirrored left to right.
pub fn mirror_rgb(image: &RgbImage) -> RgbImage {
    let (w, h) = (image.width, image.height);
    let mut out = RgbImage::new(w, h);
    if w == 0 {
        return out;
    }
    for (src, dst) in image.data.chunks_exact(w).zip(out.data.chunks_exact_mut(w)) {
        for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
            *d = *s;
        }
    }
    out
}

/// The disparity map mirrored left to right.
pub fn mirror_disparity(map: &DisparityMap) -> DisparityMap {
    let mut out = map.clone();
    if map.width == 0 {
        return out;
    }
    for row in out.data.chunks_exact_mut(map.width) {
        row.reverse();
    }
    out
}

/// Which pixels of `left` (the left view's disparity) the right view's disparity `right` does not
/// confirm: `true` where `|left(x) - right(x - left(x))|` exceeds `threshold` pixels (the right
/// map read with linear interpolation along the row), where `x - left(x)` falls outside the
/// image, and where either value is not finite.
///
/// # Shapes
/// Both maps and the mask `width x height`.
///
/// # Errors
/// [`Error::Shape`] when a map's values do not fill its size or the two maps differ in size.
pub fn rejected_pixels(left: &DisparityMap, right: &DisparityMap, threshold: f32) -> Result<Mask> {
    check_filled("the left view's disparity", left.width, left.height, left.data.len())?;
    check_filled("the right view's disparity", right.width, right.height, right.data.len())?;
    if (left.width, left.height) != (right.width, right.height) {
        return Err(Error::Shape(format!(
            "left-right check: the left view's disparity is {}x{} and the right view's {}x{}",
            left.width, left.height, right.width, right.height
        )));
    }
    let w = left.width;
    if w == 0 {
        return Ok(Mask { width: 0, height: left.height, data: Vec::new() });
    }
    let mut rejected = vec![true; left.data.len()];
    for ((l_row, r_row), out) in
        left.data.chunks_exact(w).zip(right.data.chunks_exact(w)).zip(rejected.chunks_exact_mut(w))
    {
        for (x, (&d, flag)) in l_row.iter().zip(out.iter_mut()).enumerate() {
            let xr = x as f32 - d;
            if !d.is_finite() || xr < 0.0 || xr > (w - 1) as f32 {
                continue;
            }
            let i = xr.floor() as usize;
            let a = xr - i as f32;
            let dr = if i + 1 < w { r_row[i] * (1.0 - a) + r_row[i + 1] * a } else { r_row[i] };
            *flag = !(dr.is_finite() && (d - dr).abs() <= threshold);
        }
    }
    Ok(Mask { width: w, height: left.height, data: rejected })
}

/// `disparity` with each rejected pixel replaced by the smaller of the nearest accepted values to
/// its left and to its right on the same row (the one that exists, at a row's ends); rows without
/// an accepted pixel are left as they are.
///
/// # Shapes
/// `disparity` and `rejected` are `width x height`.
///
/// # Errors
/// [`Error::Shape`] when the map's or the mask's values do not fill their size or the two
/// differ in size.
pub fn fill_rejected(disparity: &DisparityMap, rejected: &Mask) -> Result<DisparityMap> {
    check_filled("the disparity", disparity.width, disparity.height, disparity.data.len())?;
    check_filled("the mask of rejected pixels", rejected.width, rejected.height, rejected.data.len())?;
    if (disparity.width, disparity.height) != (rejected.width, rejected.height) {
        return Err(Error::Shape(format!(
            "left-right check: the disparity is {}x{} and the mask of rejected pixels {}x{}",
            disparity.width, disparity.height, rejected.width, rejected.height
        )));
    }
    let w = disparity.width;
    let mut out = disparity.clone();
    if w == 0 {
        return Ok(out);
    }
    let mut from_left = vec![None; w];
    for (row, flags) in out.data.chunks_exact_mut(w).zip(rejected.data.chunks_exact(w)) {
        let mut last = None;
        for x in 0..w {
            if !flags[x] {
                last = Some(row[x]);
            }
            from_left[x] = last;
        }
        let mut next: Option<f32> = None;
        for x in (0..w).rev() {
            if !flags[x] {
                next = Some(row[x]);
                continue;
            }
            let fill = match (from_left[x], next) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
            if let Some(v) = fill {
                row[x] = v;
            }
        }
    }
    Ok(out)
}

/// Checks that `len` values fill a `width x height` map (`what` names it in the error).
fn check_filled(what: &str, width: usize, height: usize, len: usize) -> Result<()> {
    if width.checked_mul(height) != Some(len) {
        return Err(Error::Shape(format!("left-right check: {what} is {width}x{height} but holds {len} values")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene of a background plane at disparity `bg` with a box at disparity `fg` covering
    /// columns `x0..x1` (left view) on every row: the two views' exact disparity maps.
    fn box_scene(w: usize, h: usize, bg: f32, fg: f32, x0: usize, x1: usize) -> (DisparityMap, DisparityMap) {
        let mut left = DisparityMap::filled(w, h, bg);
        let mut right = DisparityMap::filled(w, h, bg);
        for y in 0..h {
            for x in x0..x1 {
                left.data[y * w + x] = fg;
                // The box is seen in the right view `fg` pixels further left.
                right.data[y * w + x - fg as usize] = fg;
            }
        }
        (left, right)
    }

    #[test]
    fn occluded_pixels_are_rejected_and_visible_ones_kept() {
        let (w, h, bg, fg) = (64, 3, 4.0, 12.0);
        let (left, right) = box_scene(w, h, bg, fg, 30, 40);
        let rejected = rejected_pixels(&left, &right, 1.0).unwrap();
        for x in 0..w {
            // Out of the right view: the left band; hidden by the box in the right view: the
            // background just left of the box, columns 30 - (fg - bg) .. 30.
            let occluded = x < bg as usize || (22..30).contains(&x);
            assert_eq!(rejected.data[x], occluded, "column {x}");
            assert_eq!(rejected.data[2 * w + x], occluded, "row 2, column {x}");
        }
    }

    #[test]
    fn rejected_pixels_take_the_background_and_the_band_its_right_neighbour() {
        let (w, h, bg, fg) = (64, 2, 4.0, 12.0);
        let (mut left, right) = box_scene(w, h, bg, fg, 30, 40);
        // A network extrapolates in the occluded strip and the band: spoil both.
        for y in 0..h {
            for x in (0..4).chain(22..30) {
                left.data[y * w + x] = 20.0;
            }
        }
        let rejected = rejected_pixels(&left, &right, 1.0).unwrap();
        let filled = fill_rejected(&left, &rejected).unwrap();
        let (exact, _) = box_scene(w, h, bg, fg, 30, 40);
        assert_eq!(filled.data, exact.data);
    }

    #[test]
    fn a_threshold_accepts_small_disagreement_and_rejects_large() {
        let (w, h) = (32, 1);
        let left = DisparityMap::filled(w, h, 3.0);
        let right = DisparityMap::filled(w, h, 4.5);
        assert!(rejected_pixels(&left, &right, 2.0).unwrap().data[3..].iter().all(|&r| !r));
        assert!(rejected_pixels(&left, &right, 1.0).unwrap().data.iter().all(|&r| r));
        let mut nan = left.clone();
        nan.data[10] = f32::NAN;
        assert!(rejected_pixels(&nan, &right, 2.0).unwrap().data[10]);
    }

    #[test]
    fn fractional_disparities_read_the_right_view_between_pixels() {
        // A slanted plane: left disparity 2 + x/8, so the right view's disparity at x' = x - d is
        // exact, and every pixel inside the image must be confirmed at a tight threshold.
        let (w, h) = (48, 1);
        let left = DisparityMap { width: w, height: h, data: (0..w).map(|x| 2.0 + x as f32 / 8.0).collect() };
        // x' = x - 2 - x/8 = 7x/8 - 2, so x = (x' + 2) * 8 / 7 and d = 2 + x/8.
        let right =
            DisparityMap { width: w, height: h, data: (0..w).map(|xp| 2.0 + (xp as f32 + 2.0) / 7.0).collect() };
        let rejected = rejected_pixels(&left, &right, 0.01).unwrap();
        for x in 0..w {
            assert_eq!(rejected.data[x], (x as f32) < 2.0 + x as f32 / 8.0, "column {x}");
        }
    }

    #[test]
    fn rows_without_accepted_pixels_stay_as_they_are_and_mirroring_round_trips() {
        let map = DisparityMap { width: 3, height: 2, data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0] };
        assert_eq!(fill_rejected(&map, &Mask { width: 3, height: 2, data: vec![true; 6] }).unwrap().data, map.data);
        let m = mirror_disparity(&map);
        assert_eq!(m.data, vec![3.0, 2.0, 1.0, 6.0, 5.0, 4.0]);
        assert_eq!(mirror_disparity(&m).data, map.data);
        let image = RgbImage { width: 2, height: 1, data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0] };
        assert_eq!(mirror_rgb(&image).data, vec![2.0, 1.0, 4.0, 3.0, 6.0, 5.0]);
    }

    #[test]
    fn maps_of_different_sizes_are_errors_naming_both_sizes() {
        let (a, b) = (DisparityMap::filled(8, 4, 1.0), DisparityMap::filled(8, 5, 1.0));
        let e = rejected_pixels(&a, &b, 1.0).unwrap_err();
        assert!(matches!(e, Error::Shape(_)) && e.to_string().contains("8x4") && e.to_string().contains("8x5"), "{e}");
        let mask = Mask { width: 7, height: 4, data: vec![false; 28] };
        let e = fill_rejected(&a, &mask).unwrap_err();
        assert!(matches!(e, Error::Shape(_)) && e.to_string().contains("7x4"), "{e}");
        // Values that do not fill the stated size, and empty maps, are not panics either.
        let short = DisparityMap { width: 8, height: 4, data: vec![1.0; 31] };
        let e = rejected_pixels(&short, &a, 1.0).unwrap_err();
        assert!(e.to_string().contains("holds 31 values"), "{e}");
        let empty = DisparityMap { width: 0, height: 3, data: Vec::new() };
        assert_eq!(rejected_pixels(&empty, &empty, 1.0).unwrap().data.len(), 0);
        assert_eq!(mirror_disparity(&empty), empty);
    }
}
