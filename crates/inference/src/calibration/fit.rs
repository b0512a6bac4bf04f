//! A calibration applied to images of a given size: as it is when the sizes agree, rescaled with
//! a notice when the images are the calibrated ones resized at the same aspect ratio, cropped or
//! scaled as the user says, and an error naming both sizes otherwise.
//!
//! Design decision: a calibration belongs to the image size it was made for. A resize that keeps
//! the aspect ratio is the one change a size alone reveals unambiguously, so it is applied, and
//! said ([`Rescaled`], returned for the front end to print or warn). Any other size could be a
//! crop (the principal point moves, the focal length does not), a resize to another aspect ratio
//! (each axis scales apart) or the wrong file, and guessing gives depth that is silently wrong, so
//! it is an error until the user states what was done ([`Adjustment`]): a crop shifts `cx`, `cy`;
//! a scale multiplies `fx`, `cx` (and `doffs`) by the horizontal factor and `fy`, `cy` by the
//! vertical one. A calibration that does not say its size is applied as it is.

use std::fmt;

use dgstereo_core::{Error, Result};
use nalgebra::Matrix3;

use super::Calibration;

/// How the images were made from the calibrated ones, as the user states it: first a crop whose
/// top-left corner is `crop` (pixels of the calibrated image), then a resize by `scale`
/// (horizontal, vertical).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Adjustment {
    /// Top-left corner `(x, y)` of the crop, in pixels of the calibrated image.
    pub crop: Option<(f64, f64)>,
    /// Resize factors `(sx, sy)` applied after the crop.
    pub scale: Option<(f64, f64)>,
}

impl Adjustment {
    /// Whether nothing was stated.
    pub fn is_none(&self) -> bool {
        self.crop.is_none() && self.scale.is_none()
    }
}

/// The notice of a uniform rescale: the calibration was made for images of `from` and applied to
/// images of `to` (`width, height`), its intrinsics scaled by the size ratio.
#[derive(Clone, Debug, PartialEq)]
pub struct Rescaled {
    /// The calibration's file.
    pub source: std::path::PathBuf,
    /// The calibrated size.
    pub from: (usize, usize),
    /// The images' size.
    pub to: (usize, usize),
}

impl fmt::Display for Rescaled {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ((w0, h0), (w, h)) = (self.from, self.to);
        write!(
            f,
            "calibration {} is for {w0}x{h0} images and these are {w}x{h} (the same aspect ratio): its focal lengths and principal point are scaled by {:.4}",
            self.source.display(),
            w as f64 / w0 as f64
        )
    }
}

/// Sides that agree up to the rounding of a resize.
fn close(a: f64, b: usize) -> bool {
    (a - b as f64).abs() < 1.0
}

impl Calibration {
    /// The calibration for images of `width x height` made from the calibrated ones as
    /// `adjustment` says ([`Calibration::cropped`], then [`Calibration::scaled`]), or, when it
    /// says nothing, [`Calibration::for_size`].
    ///
    /// # Errors
    /// As [`Calibration::for_size`]; with an adjustment, [`Error::Shape`] when the adjusted
    /// calibration's size is not `width x height` or the crop leaves the calibrated image, and
    /// [`Error::config`] for a factor that is not positive.
    pub fn adjusted(
        &self,
        adjustment: &Adjustment,
        width: usize,
        height: usize,
    ) -> Result<(Calibration, Option<Rescaled>)> {
        if adjustment.is_none() {
            return self.for_size(width, height);
        }
        let (sx, sy) = adjustment.scale.unwrap_or((1.0, 1.0));
        let mut c = self.clone();
        if let Some((x, y)) = adjustment.crop {
            c = c.cropped(x, y, width as f64 / sx, height as f64 / sy)?;
        }
        if adjustment.scale.is_some() {
            c = c.scaled(sx, sy)?;
        }
        if let Some((w, h)) = c.size
            && (w, h) != (width, height)
        {
            if !(close(w as f64, width) && close(h as f64, height)) {
                return Err(Error::Shape(format!(
                    "calibration {} is for {}x{} images, {w}x{h} after the stated crop and scale, and these are {width}x{height}",
                    self.source.display(),
                    self.size.map_or(0, |s| s.0),
                    self.size.map_or(0, |s| s.1),
                )));
            }
            c.size = Some((width, height));
        }
        Ok((c, None))
    }

    /// The calibration of the same cameras for images of `width x height`: as it is when the
    /// calibrated size is unknown or the same; scaled by the size ratio, with the notice
    /// [`Rescaled`], when the images are the calibrated ones resized at the same aspect ratio (up
    /// to a pixel of rounding).
    ///
    /// # Errors
    /// [`Error::Shape`] naming both sizes when the images are another size of another aspect
    /// ratio (a crop, a resize to another aspect ratio, or another camera's calibration); say
    /// which with [`Calibration::adjusted`].
    pub fn for_size(&self, width: usize, height: usize) -> Result<(Calibration, Option<Rescaled>)> {
        let Some((w0, h0)) = self.size else { return Ok((self.clone(), None)) };
        if (w0, h0) == (width, height) {
            return Ok((self.clone(), None));
        }
        let (sx, sy) = (width as f64 / w0 as f64, height as f64 / h0 as f64);
        if !(close(w0 as f64 * sy, width) || close(h0 as f64 * sx, height)) {
            return Err(Error::Shape(format!(
                "calibration {} is for {w0}x{h0} images and these are {width}x{height}, not a resize at the same aspect ratio (x{sx:.3} wide, x{sy:.3} high): a calibration applies to the size it was made for; state the crop or the scale that made these images from the calibrated ones",
                self.source.display()
            )));
        }
        let mut c = self.scaled(sx, sy)?;
        c.size = Some((width, height));
        Ok((c, Some(Rescaled { source: self.source.clone(), from: (w0, h0), to: (width, height) })))
    }

    /// The calibration of a crop of the calibrated images whose top-left corner is `(x, y)` and
    /// whose size is `width x height` (pixels of the calibrated image): the principal point
    /// moves by `(-x, -y)`; the focal lengths, baseline and `doffs` stay (both views are cropped
    /// alike).
    ///
    /// # Errors
    /// [`Error::config`]`("crop", ..)` for a negative or non-finite corner; [`Error::Shape`] when
    /// the crop leaves the calibrated image (where its size is known).
    pub fn cropped(&self, x: f64, y: f64, width: f64, height: f64) -> Result<Self> {
        if !(x.is_finite() && y.is_finite() && x >= 0.0 && y >= 0.0) {
            return Err(Error::config("crop", format!("({x}, {y}): the corner must be pixels >= 0")));
        }
        if let Some((w0, h0)) = self.size
            && (x + width > w0 as f64 + 0.5 || y + height > h0 as f64 + 0.5)
        {
            return Err(Error::Shape(format!(
                "a crop of {width:.0}x{height:.0} at ({x}, {y}) does not fit in the {w0}x{h0} images of calibration {}",
                self.source.display()
            )));
        }
        let shift = Matrix3::new(1.0, 0.0, -x, 0.0, 1.0, -y, 0.0, 0.0, 1.0);
        Ok(Self {
            intrinsics: shift * self.intrinsics,
            size: self.size.map(|_| (width.round() as usize, height.round() as usize)),
            ..self.clone()
        })
    }

    /// The calibration of the calibrated images resized by `sx` horizontally and `sy`
    /// vertically: `fx`, `cx` and `doffs` times `sx`, `fy`, `cy` times `sy`, the size (where
    /// known) rounded as a resize rounds.
    ///
    /// # Errors
    /// [`Error::config`]`("scale", ..)` for a factor that is not a positive number.
    pub fn scaled(&self, sx: f64, sy: f64) -> Result<Self> {
        if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
            return Err(Error::config("scale", format!("({sx}, {sy}): the factors must be positive numbers")));
        }
        let scale = Matrix3::new(sx, 0.0, 0.0, 0.0, sy, 0.0, 0.0, 0.0, 1.0);
        let size = self.size.map(|(w, h)| dgstereo_data::resize::scaled_size(w, h, sx, sy));
        Ok(Self { intrinsics: scale * self.intrinsics, doffs: self.doffs * sx, size, ..self.clone() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OAK-D-like: 640x480, fx 400, principal point (320, 240), 7.5 cm baseline.
    fn oakd() -> Calibration {
        Calibration {
            source: "oakd.json".into(),
            intrinsics: Matrix3::new(400.0, 0.0, 320.0, 0.0, 400.0, 240.0, 0.0, 0.0, 1.0),
            baseline_m: 0.075,
            doffs: 2.0,
            size: Some((640, 480)),
            depth_range: None,
        }
    }

    #[test]
    fn the_calibrated_size_and_an_unknown_size_apply_as_they_are() {
        let c = oakd();
        assert_eq!(c.for_size(640, 480).unwrap(), (c.clone(), None));
        let unknown = Calibration { size: None, ..oakd() };
        assert_eq!(unknown.for_size(100, 40).unwrap(), (unknown.clone(), None));
    }

    #[test]
    fn a_resize_at_the_same_aspect_ratio_is_applied_with_a_notice() {
        let (c, notice) = oakd().for_size(320, 240).unwrap();
        assert_eq!((c.fx(), c.intrinsics[(0, 2)], c.intrinsics[(1, 2)], c.doffs), (200.0, 160.0, 120.0, 1.0));
        assert_eq!(c.size, Some((320, 240)));
        let notice = notice.expect("a notice");
        assert_eq!((notice.from, notice.to), ((640, 480), (320, 240)));
        assert!(notice.to_string().contains("640x480") && notice.to_string().contains("0.5000"), "{notice}");
        // The same point at half the size: half the disparity, the same depth.
        assert!((c.depth(20.0) - oakd().depth(40.0)).abs() < 1e-6);
        // A side rounded by the resize still counts as the same aspect ratio.
        let kitti = Calibration { size: Some((1242, 375)), ..oakd() };
        assert!(kitti.for_size(621, 188).unwrap().1.is_some());
    }

    #[test]
    fn another_aspect_ratio_is_an_error_naming_both_sizes() {
        let e = oakd().for_size(100, 40).unwrap_err();
        assert!(matches!(e, Error::Shape(_)), "{e:?}");
        let text = e.to_string();
        assert!(text.contains("640x480") && text.contains("100x40") && text.contains("oakd.json"), "{text}");
    }

    #[test]
    fn a_stated_crop_shifts_the_principal_point_and_a_scale_scales_it() {
        let c = oakd();
        let crop = Adjustment { crop: Some((300.0, 200.0)), scale: None };
        let (cropped, notice) = c.adjusted(&crop, 100, 40).unwrap();
        assert!(notice.is_none());
        assert_eq!((cropped.fx(), cropped.intrinsics[(0, 2)], cropped.intrinsics[(1, 2)]), (400.0, 20.0, 40.0));
        assert_eq!((cropped.doffs, cropped.size), (2.0, Some((100, 40))));
        // The crop's depth is the full image's: the focal length did not change.
        assert_eq!(cropped.depth(10.0), c.depth(10.0));
        // A resize to another aspect ratio, stated.
        let squeeze = Adjustment { crop: None, scale: Some((0.5, 1.0)) };
        let (squeezed, _) = c.adjusted(&squeeze, 320, 480).unwrap();
        assert_eq!((squeezed.fx(), squeezed.intrinsics[(1, 1)], squeezed.intrinsics[(0, 2)]), (200.0, 400.0, 160.0));
        assert_eq!(squeezed.doffs, 1.0);
        // A crop then a half-size resize: the corner in calibrated pixels, the crop 200x80 there.
        let both = Adjustment { crop: Some((300.0, 200.0)), scale: Some((0.5, 0.5)) };
        let (small, _) = c.adjusted(&both, 100, 40).unwrap();
        assert_eq!((small.fx(), small.intrinsics[(0, 2)], small.intrinsics[(1, 2)]), (200.0, 10.0, 20.0));
    }

    #[test]
    fn stated_adjustments_that_do_not_fit_are_errors() {
        let c = oakd();
        // The stated scale gives 320x240, and the images are 300x240.
        let e = c.adjusted(&Adjustment { crop: None, scale: Some((0.5, 0.5)) }, 300, 240).unwrap_err();
        assert!(e.to_string().contains("320x240") && e.to_string().contains("300x240"), "{e}");
        // A crop that leaves the calibrated image.
        let e = c.adjusted(&Adjustment { crop: Some((600.0, 0.0)), scale: None }, 100, 40).unwrap_err();
        assert!(matches!(e, Error::Shape(_)) && e.to_string().contains("does not fit"), "{e}");
        let e = c.adjusted(&Adjustment { crop: Some((-1.0, 0.0)), scale: None }, 100, 40).unwrap_err();
        assert!(matches!(&e, Error::Config(p) if p.key == "crop"), "{e:?}");
        let e = c.adjusted(&Adjustment { crop: None, scale: Some((0.0, 1.0)) }, 100, 40).unwrap_err();
        assert!(matches!(&e, Error::Config(p) if p.key == "scale"), "{e:?}");
    }
}
