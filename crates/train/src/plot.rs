//! A PNG of the training and validation curves, drawn with the `image` crate.
//!
//! Two panels side by side, step on the x axis: the loss (left) and the EPE (right). Training
//! values are blue, validation values orange (drawn as a line with dots). The y axes start at 0
//! and end at the largest value drawn; light grey lines mark quarters of both axes. There is no
//! text (no font dependency): the numbers are in `log.jsonl` beside the plot.

use std::path::Path;

use dgstereo_core::{Error, Result};
use image::{Rgb, RgbImage};

const PANEL_W: u32 = 480;
const HEIGHT: u32 = 320;
const MARGIN: u32 = 24;
const TRAIN: Rgb<u8> = Rgb([31, 119, 180]);
const VALID: Rgb<u8> = Rgb([255, 127, 14]);
const AXIS: Rgb<u8> = Rgb([60, 60, 60]);
const GRID: Rgb<u8> = Rgb([225, 225, 225]);

/// A series of `(step, value)` points.
pub type Series = Vec<(f64, f64)>;

/// The curves to draw.
#[derive(Debug, Clone, Default)]
pub struct Curves {
    /// Training loss per logged step.
    pub train_loss: Series,
    /// Training EPE per logged step.
    pub train_epe: Series,
    /// Validation EPE per validation.
    pub valid_epe: Series,
}

fn line(img: &mut RgbImage, (x0, y0): (f64, f64), (x1, y1): (f64, f64), colour: Rgb<u8>) {
    let n = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (x, y) = (x0 + (x1 - x0) * t, y0 + (y1 - y0) * t);
        if x >= 0.0 && y >= 0.0 && (x as u32) < img.width() && (y as u32) < img.height() {
            img.put_pixel(x as u32, y as u32, colour);
        }
    }
}

fn panel(img: &mut RgbImage, left: u32, series: &[(&Series, Rgb<u8>, bool)], max_step: f64) {
    let (x0, x1) = (f64::from(left + MARGIN), f64::from(left + PANEL_W - MARGIN / 2));
    let (y0, y1) = (f64::from(HEIGHT - MARGIN), f64::from(MARGIN / 2));
    let finite = |s: &Series| s.iter().filter(|(_, v)| v.is_finite()).map(|p| p.1).collect::<Vec<_>>();
    let top = series.iter().flat_map(|(s, _, _)| finite(s)).fold(0.0f64, f64::max);
    let top = if top > 0.0 { top } else { 1.0 };
    for q in 1..=4 {
        let f = f64::from(q) / 4.0;
        line(img, (x0, y0 + (y1 - y0) * f), (x1, y0 + (y1 - y0) * f), GRID);
        line(img, (x0 + (x1 - x0) * f, y0), (x0 + (x1 - x0) * f, y1), GRID);
    }
    line(img, (x0, y0), (x1, y0), AXIS);
    line(img, (x0, y0), (x0, y1), AXIS);
    let to_px =
        |(s, v): (f64, f64)| (x0 + (x1 - x0) * s / max_step.max(1.0), y0 + (y1 - y0) * (v / top).clamp(0.0, 1.0));
    for (s, colour, dots) in series {
        let pts: Vec<_> = s.iter().copied().filter(|(_, v)| v.is_finite()).map(to_px).collect();
        for w in pts.windows(2) {
            line(img, w[0], w[1], *colour);
        }
        if *dots || pts.len() == 1 {
            for &(x, y) in &pts {
                for dx in -2..=2 {
                    line(img, (x + f64::from(dx), y - 2.0), (x + f64::from(dx), y + 2.0), *colour);
                }
            }
        }
    }
}

/// Draws `curves` into an image.
pub fn render(curves: &Curves) -> RgbImage {
    let mut img = RgbImage::from_pixel(2 * PANEL_W, HEIGHT, Rgb([255, 255, 255]));
    let max_step = [&curves.train_loss, &curves.train_epe, &curves.valid_epe]
        .iter()
        .flat_map(|s| s.iter().map(|p| p.0))
        .fold(1.0f64, f64::max);
    panel(&mut img, 0, &[(&curves.train_loss, TRAIN, false)], max_step);
    panel(&mut img, PANEL_W, &[(&curves.train_epe, TRAIN, false), (&curves.valid_epe, VALID, true)], max_step);
    img
}

/// Writes the plot of `curves` to `path` (PNG), atomically.
pub fn write_plot(curves: &Curves, path: &Path) -> Result<()> {
    let img = render(curves);
    let mut bytes = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
        .map_err(|e| Error::Other(format!("{}: cannot encode the plot: {e}", path.display())))?;
    crate::checkpoint::write_atomic(path, &bytes)
}
