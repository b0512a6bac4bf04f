//! A PNG of the training and validation curves, drawn with the `image` crate.
//!
//! Two panels side by side, step on the x axis: the loss (left) and the EPE (right). Training
//! values are blue, validation values orange (drawn as a line with dots). The y axes start at 0
//! and end at the largest value drawn; light grey lines mark quarters of both axes, labelled with
//! their values in the data crate's bitmap font (no font dependency), and each panel has a title
//! and a legend. The exact numbers are in `log.jsonl` beside the plot. The drawing primitives
//! are public: the study's `ablation.png` draws with them.

use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_data::text::{GLYPH_HEIGHT, draw_text, format_value, text_width};
use image::{Rgb, RgbImage};

/// The width of one panel, in pixels.
pub const PANEL_W: u32 = 480;
/// The height of a plot, in pixels.
pub const HEIGHT: u32 = 320;
/// Left margin (y tick labels), bottom (x tick labels), top (title and legend), right.
pub const LEFT: u32 = 44;
/// The bottom margin (x tick labels).
pub const BOTTOM: u32 = 22;
/// The top margin (title and legend).
pub const TOP: u32 = 22;
const RIGHT: u32 = 14;
const SCALE: usize = 2;
const TRAIN: Rgb<u8> = Rgb([31, 119, 180]);
const VALID: Rgb<u8> = Rgb([255, 127, 14]);
const AXIS: Rgb<u8> = Rgb([60, 60, 60]);
/// The grid lines' colour.
pub const GRID: Rgb<u8> = Rgb([225, 225, 225]);
/// The text's colour.
pub const TEXT: Rgb<u8> = Rgb([40, 40, 40]);

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

/// Draws a line from `(x0, y0)` to `(x1, y1)` (clipped to the image).
pub fn line(img: &mut RgbImage, (x0, y0): (f64, f64), (x1, y1): (f64, f64), colour: Rgb<u8>) {
    let n = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (x, y) = (x0 + (x1 - x0) * t, y0 + (y1 - y0) * t);
        if x >= 0.0 && y >= 0.0 && (x as u32) < img.width() && (y as u32) < img.height() {
            img.put_pixel(x as u32, y as u32, colour);
        }
    }
}

/// Writes `s` with its top-left corner at `(x, y)` (clipped to the image).
pub fn text(img: &mut RgbImage, s: &str, x: f64, y: f64, colour: Rgb<u8>) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    draw_text(s, x.max(0.0) as usize, y.max(0.0) as usize, SCALE, |x, y| {
        if x < w && y < h {
            img.put_pixel(x as u32, y as u32, colour);
        }
    });
}

/// One panel: `title` at the top left, one legend entry per named series at the top right.
pub fn panel(img: &mut RgbImage, left: u32, title: &str, series: &[(&Series, Rgb<u8>, bool, &str)], max_step: f64) {
    let (x0, x1) = (f64::from(left + LEFT), f64::from(left + PANEL_W - RIGHT));
    let (y0, y1) = (f64::from(HEIGHT - BOTTOM), f64::from(TOP));
    let finite = |s: &Series| s.iter().filter(|(_, v)| v.is_finite()).map(|p| p.1).collect::<Vec<_>>();
    let top = series.iter().flat_map(|(s, _, _, _)| finite(s)).fold(0.0f64, f64::max);
    let top = if top > 0.0 { top } else { 1.0 };
    let glyph_h = (GLYPH_HEIGHT * SCALE) as f64;
    for q in 0..=4 {
        let f = f64::from(q) / 4.0;
        if q > 0 {
            line(img, (x0, y0 + (y1 - y0) * f), (x1, y0 + (y1 - y0) * f), GRID);
            line(img, (x0 + (x1 - x0) * f, y0), (x0 + (x1 - x0) * f, y1), GRID);
        }
        let y_label = format_value(top * f);
        let y = y0 + (y1 - y0) * f - glyph_h / 2.0;
        text(img, &y_label, x0 - 4.0 - text_width(&y_label, SCALE) as f64, y, TEXT);
        let step = max_step.max(1.0) * f;
        let x_label = if step >= 1e4 { format_value(step) } else { format!("{step:.0}") };
        let w = text_width(&x_label, SCALE) as f64;
        let x = (x0 + (x1 - x0) * f - w / 2.0).min(x1 + f64::from(RIGHT) - w - 1.0);
        text(img, &x_label, x, y0 + 5.0, TEXT);
    }
    line(img, (x0, y0), (x1, y0), AXIS);
    line(img, (x0, y0), (x0, y1), AXIS);
    text(img, title, x0, 4.0, TEXT);
    let mut right = x1;
    for (_, colour, _, name) in series.iter().rev().filter(|s| !s.3.is_empty()) {
        let w = text_width(name, SCALE) as f64;
        right -= w;
        text(img, name, right, 4.0, *colour);
        right -= 14.0;
    }
    let to_px =
        |(s, v): (f64, f64)| (x0 + (x1 - x0) * s / max_step.max(1.0), y0 + (y1 - y0) * (v / top).clamp(0.0, 1.0));
    for (s, colour, dots, _) in series {
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
    panel(&mut img, 0, "LOSS / STEP", &[(&curves.train_loss, TRAIN, false, "TRAIN")], max_step);
    let epe = [(&curves.train_epe, TRAIN, false, "TRAIN"), (&curves.valid_epe, VALID, true, "VALIDATION")];
    panel(&mut img, PANEL_W, "EPE PX / STEP", &epe, max_step);
    img
}

/// Writes the plot of `curves` to `path` (PNG), atomically.
pub fn write_plot(curves: &Curves, path: &Path) -> Result<()> {
    write_png(&render(curves), path)
}

/// Writes `img` to `path` (PNG), atomically.
pub fn write_png(img: &RgbImage, path: &Path) -> Result<()> {
    let mut bytes = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
        .map_err(|e| Error::encode(format!("the plot {}", path.display()), e))?;
    crate::checkpoint::write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(img: &RgbImage, colour: Rgb<u8>, x: std::ops::Range<u32>, y: std::ops::Range<u32>) -> usize {
        x.flat_map(|x| y.clone().map(move |y| (x, y))).filter(|&(x, y)| *img.get_pixel(x, y) == colour).count()
    }

    #[test]
    fn curves_titles_legends_and_tick_labels_are_drawn() {
        let curves = Curves {
            train_loss: (1..=100).map(|s| (f64::from(s), 50.0 / f64::from(s))).collect(),
            train_epe: (1..=100).map(|s| (f64::from(s), 10.0 / f64::from(s).sqrt())).collect(),
            valid_epe: vec![(50.0, 2.0), (100.0, 1.5)],
        };
        let img = render(&curves);
        if let Some(dir) = std::env::var_os("DGSTEREO_PLOT_DIR") {
            img.save(std::path::Path::new(&dir).join("curves-test.png")).unwrap();
        }
        assert_eq!(img.dimensions(), (2 * PANEL_W, HEIGHT));
        // Titles in the top band of both panels; the validation legend in its colour.
        assert!(count(&img, TEXT, 0..PANEL_W / 2, 0..TOP) > 20);
        assert!(count(&img, TEXT, PANEL_W..PANEL_W + PANEL_W / 2, 0..TOP) > 20);
        assert!(count(&img, VALID, PANEL_W + PANEL_W / 2..2 * PANEL_W, 0..TOP) > 20);
        // Tick labels left of the y axes and under the x axes.
        assert!(count(&img, TEXT, 0..LEFT - 2, TOP..HEIGHT - BOTTOM) > 20);
        assert!(count(&img, TEXT, LEFT..PANEL_W, HEIGHT - BOTTOM + 2..HEIGHT) > 20);
        // The curves themselves.
        assert!(count(&img, TRAIN, LEFT..PANEL_W, TOP..HEIGHT - BOTTOM) > 100);
        assert!(count(&img, VALID, PANEL_W + LEFT..2 * PANEL_W, TOP..HEIGHT - BOTTOM) > 10);
    }
}
