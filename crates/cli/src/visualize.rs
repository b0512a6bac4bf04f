//! Pictures of disparity maps: the turbo colour map with a legend, and side-by-side panels.

use dgstereo_data::text::{GLYPH_HEIGHT, format_value, text_width};
use dgstereo_data::{DisparityMap, RgbImage};

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
/// written under it (in the map's unit, pixels of disparity).
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
    if !legend {
        return img;
    }
    let tick_x = |k: usize| k * (d.width.max(1) - 1) / 4;
    for y in d.height..d.height + bar {
        for x in 0..d.width {
            let t = x as f32 / (d.width.max(2) - 1) as f32;
            let tick = (0..=4).any(|k| x == tick_x(k));
            let rgb = if tick && y >= d.height + 2 * bar / 3 { [255.0; 3] } else { turbo(t) };
            img.set(x, y, rgb);
        }
    }
    let y0 = d.height + bar + scale;
    let labels = [(lo, 0usize), ((lo + hi) / 2.0, 1), (hi, 2)];
    for (value, align) in labels {
        let label = format_value(f64::from(value));
        let w = text_width(&label, scale);
        let anchor = tick_x(2 * align);
        let x0 = match align {
            0 => 0,
            1 => anchor.saturating_sub(w / 2),
            _ => d.width.saturating_sub(w),
        };
        draw_text(&mut img, &label, x0, y0, scale);
    }
    img
}

/// Draws `s` in white with its top-left corner at `(x0, y0)` (see [`dgstereo_data::text`]);
/// what falls outside the image is clipped.
fn draw_text(img: &mut RgbImage, s: &str, x0: usize, y0: usize, scale: usize) {
    dgstereo_data::text::draw_text(s, x0, y0, scale, |x, y| {
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
        // The colour of the map's left column equals the bar's left end (same range).
        assert_eq!(with.get(1, 0), with.get(1, 48));
        // The text band holds white glyph pixels and black background.
        let text_rows = 48 + 6..with.height;
        let white = text_rows
            .clone()
            .flat_map(|y| (0..64).map(move |x| (x, y)))
            .filter(|&(x, y)| with.get(x, y) == [255.0; 3])
            .count();
        assert!(white > 10 && white < 64 * text_rows.len() / 2, "{white}");
    }
}
