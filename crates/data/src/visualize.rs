//! Pictures of disparity maps: the turbo colour map with a legend of its range, the error
//! against ground truth, and panels side by side (what `dgstereo infer --save color`, the demo
//! and `experiment samples` write).
//!
//! Design decision: a picture is an [`RgbImage`] like any image of this crate, so it is written
//! with [`crate::save_rgb`] and its legend is drawn with the crate's own bitmap font
//! ([`crate::text`]); nothing here reads or writes files.

use crate::image::{DisparityMap, RgbImage};
use crate::text::{GLYPH_HEIGHT, format_value, text_width};

/// Google's Turbo colour map (polynomial fit by its authors), `t` in 0..1, RGB 0..255.
pub fn turbo(t: f32) -> [f32; 3] {
    let x = t.clamp(0.0, 1.0) as f64;
    let r =
        0.13572138 + x * (4.61539260 + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))));
    let g = 0.09140261 + x * (2.19418839 + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))));
    let b =
        0.10667330 + x * (12.64194608 + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))));
    [r, g, b].map(|c| (c.clamp(0.0, 1.0) * 255.0) as f32)
}

/// The range used to colour a map: `[lo, hi]` of its finite values (robust to a few outliers).
pub fn display_range(d: &DisparityMap) -> (f32, f32) {
    let mut v: Vec<f32> = d.data.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (0.0, 1.0);
    }
    v.sort_by(f32::total_cmp);
    let lo = v[(v.len() as f64 * 0.001) as usize];
    let hi = v[((v.len() as f64 * 0.999) as usize).min(v.len() - 1)];
    if hi > lo { (lo, hi) } else { (lo, lo + 1.0) }
}

/// Colours a disparity map (near = red, far = blue); non-finite pixels are black.
///
/// With `legend`, a band below the map shows the colour bar spanning `range` from left (low) to
/// right (high), with ticks at 0, 25, 50, 75 and 100 % and the low, middle and high values
/// written under it (in the map's unit, pixels of disparity). The bar and its labels keep a
/// margin from the image's sides ([`legend_bar`], [`legend_labels`]), so the end labels are
/// whole however the picture is framed.
pub fn colorize(d: &DisparityMap, range: (f32, f32), legend: bool) -> RgbImage {
    let (lo, hi) = range;
    let bar = if legend { (d.height / 16).clamp(6, 24) } else { 0 };
    let scale = (bar / 6).max(1);
    let text = if legend { GLYPH_HEIGHT * scale + 2 * scale } else { 0 };
    let mut img = RgbImage::new(d.width, d.height + bar + text);
    for y in 0..d.height {
        for x in 0..d.width {
            let v = d.data[y * d.width + x];
            let rgb = if v.is_finite() { turbo((v - lo) / (hi - lo)) } else { [0.0; 3] };
            img.set(x, y, rgb);
        }
    }
    if !legend || d.width == 0 {
        return img;
    }
    let (x0, x1) = legend_bar(d.width, scale);
    let span = (x1 - x0).max(1);
    let tick_x = |k: usize| x0 + k * (x1 - x0) / 4;
    for y in d.height..d.height + bar {
        for x in x0..=x1 {
            let t = (x - x0) as f32 / span as f32;
            let tick = (0..=4).any(|k| x == tick_x(k));
            let rgb = if tick && y >= d.height + 2 * bar / 3 { [255.0; 3] } else { turbo(t) };
            img.set(x, y, rgb);
        }
    }
    let y0 = d.height + bar + scale;
    for (label, x) in legend_labels(d.width, scale, range) {
        draw_text(&mut img, &label, x, y0, scale);
    }
    img
}

/// The first and last column (inclusive) of the legend's colour bar for a map `width` pixels
/// wide, with glyphs `scale` pixels per font pixel: a margin of two font pixels from each side,
/// less on maps too narrow to spare it.
pub fn legend_bar(width: usize, scale: usize) -> (usize, usize) {
    let margin = (2 * scale).min(width.saturating_sub(1) / 8);
    (margin, width.saturating_sub(1 + margin))
}

/// The legend's labels and the column of their left edge: the low value starting under the
/// bar's left end, the high value ending under its right end, the middle one centred under the
/// middle tick. A label that would overlap another (a font pixel apart at least) or reach past
/// the bar is left out, the middle one first.
pub fn legend_labels(width: usize, scale: usize, (lo, hi): (f32, f32)) -> Vec<(String, usize)> {
    let (x0, x1) = legend_bar(width, scale);
    let text = |v: f32| format_value(f64::from(v));
    let (low, middle, high) = (text(lo), text((lo + hi) / 2.0), text(hi));
    let (wl, wm, wh) = (text_width(&low, scale), text_width(&middle, scale), text_width(&high, scale));
    let bar = x1 + 1 - x0;
    let mut labels = Vec::new();
    if wl <= bar {
        labels.push((low, x0, wl));
    }
    if wh <= bar && (labels.is_empty() || wl + scale + wh <= bar) {
        labels.push((high, x1 + 1 - wh, wh));
    }
    let centre = x0 + (x1 - x0) / 2;
    let xm = centre.saturating_sub(wm / 2).max(x0);
    let clear = labels.iter().all(|(_, x, w)| xm + wm + scale <= *x || x + w + scale <= xm);
    if xm + wm <= x1 + 1 && clear {
        labels.push((middle, xm, wm));
    }
    labels.sort_by_key(|(_, x, _)| *x);
    labels.into_iter().map(|(label, x, _)| (label, x)).collect()
}

/// Draws `s` in white with its top-left corner at `(x0, y0)` (see [`crate::text`]);
/// what falls outside the image is clipped.
fn draw_text(img: &mut RgbImage, s: &str, x0: usize, y0: usize, scale: usize) {
    crate::text::draw_text(s, x0, y0, scale, |x, y| {
        if x < img.width && y < img.height {
            img.set(x, y, [255.0; 3]);
        }
    });
}

/// Absolute error against ground truth as a picture (0 = black, `max` px or more = white);
/// pixels without ground truth are dark blue.
pub fn error_image(pred: &DisparityMap, gt: &DisparityMap, max: f32) -> RgbImage {
    let mut img = RgbImage::new(gt.width, gt.height);
    for i in 0..gt.data.len() {
        let (x, y) = (i % gt.width, i / gt.width);
        let g = gt.data[i];
        let rgb = if g.is_finite() && g > 0.0 {
            let e = ((pred.data[i] - g).abs() / max).min(1.0) * 255.0;
            [e, e, e]
        } else {
            [0.0, 0.0, 60.0]
        };
        img.set(x, y, rgb);
    }
    img
}

/// Panels of equal height side by side (shorter ones are padded with black at the bottom).
pub fn side_by_side(panels: &[&RgbImage]) -> RgbImage {
    let h = panels.iter().map(|p| p.height).max().unwrap_or(0);
    let w: usize = panels.iter().map(|p| p.width).sum();
    let mut out = RgbImage::new(w, h);
    let mut x0 = 0;
    for p in panels {
        for y in 0..p.height {
            for x in 0..p.width {
                out.set(x0 + x, y, p.get(x, y));
            }
        }
        x0 += p.width;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legend_adds_a_bar_and_written_values() {
        let d = DisparityMap { width: 64, height: 48, data: (0..64 * 48).map(|i| (i % 64) as f32).collect() };
        let plain = colorize(&d, (0.0, 63.0), false);
        let with = colorize(&d, (0.0, 63.0), true);
        assert_eq!(plain.height, 48);
        assert!(with.height > 48 + 6);
        // The colour of the map's left column (its low end) equals the bar's left end.
        let (x0, _) = legend_bar(64, 1);
        assert_eq!(with.get(0, 0), with.get(x0, 48));
        // The text band holds white glyph pixels and black background.
        let text_rows = 48 + 6..with.height;
        let white = text_rows
            .clone()
            .flat_map(|y| (0..64).map(move |x| (x, y)))
            .filter(|&(x, y)| with.get(x, y) == [255.0; 3])
            .count();
        assert!(white > 10 && white < 64 * text_rows.len() / 2, "{white}");
    }

    #[test]
    fn legend_labels_stay_whole_inside_the_picture() {
        for width in [20, 40, 64, 450, 1242] {
            for range in [(0.0, 63.0), (18.1, 57.9), (-12.5, 1234.0), (-123456.0, 9.0)] {
                for scale in [1, 2, 4] {
                    let (x0, x1) = legend_bar(width, scale);
                    assert!(x0 >= 1 && x1 <= width - 2, "{width}: bar {x0}..={x1}");
                    let labels = legend_labels(width, scale, range);
                    let spans: Vec<(usize, usize)> =
                        labels.iter().map(|(l, x)| (*x, x + text_width(l, scale))).collect();
                    for (a, b) in spans.iter().zip(spans.iter().skip(1)) {
                        assert!(a.1 + scale <= b.0, "{width} {range:?} x{scale}: {labels:?} overlap");
                    }
                    for (start, end) in &spans {
                        assert!(*start >= x0 && *end <= x1 + 1, "{width} {range:?} x{scale}: {labels:?}");
                    }
                    if width >= 450 {
                        assert_eq!(labels.len(), 3, "{width} {range:?} x{scale}: {labels:?}");
                    }
                }
            }
        }
        // Drawn: no white glyph pixel in the two outer columns of the text band.
        let d = DisparityMap { width: 450, height: 375, data: (0..450 * 375).map(|i| (i % 450) as f32).collect() };
        let img = colorize(&d, (18.1, 57.9), true);
        let band = 375 + 23..img.height;
        for x in [0, 1, 448, 449] {
            assert!(band.clone().all(|y| img.get(x, y) != [255.0; 3]), "column {x} holds text");
        }
        assert!(band.clone().any(|y| img.get(6, y) == [255.0; 3]), "the low label starts after the margin");
    }
}
