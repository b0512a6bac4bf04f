//! Pictures of disparity maps: the turbo colour map with a legend, and side-by-side panels.

use dgstereo_data::{DisparityMap, RgbImage};

/// Google's Turbo colour map (polynomial fit by its authors), `t` in 0..1, RGB 0..255.
pub fn turbo(t: f32) -> [f32; 3] {
    let x = t.clamp(0.0, 1.0) as f64;
    let r = 0.13572138 + x * (4.61539260 + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))));
    let g = 0.09140261 + x * (2.19418839 + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))));
    let b = 0.10667330 + x * (12.64194608 + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))));
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

/// Colours a disparity map (near = red, far = blue); non-finite pixels are black. A legend bar
/// with tick marks at the bottom spans `range` from left (low) to right (high).
pub fn colorize(d: &DisparityMap, range: (f32, f32), legend: bool) -> RgbImage {
    let (lo, hi) = range;
    let bar = if legend { (d.height / 16).clamp(6, 24) } else { 0 };
    let mut img = RgbImage::new(d.width, d.height + bar);
    for y in 0..d.height {
        for x in 0..d.width {
            let v = d.data[y * d.width + x];
            let rgb = if v.is_finite() { turbo((v - lo) / (hi - lo)) } else { [0.0; 3] };
            img.set(x, y, rgb);
        }
    }
    for y in d.height..d.height + bar {
        for x in 0..d.width {
            let t = x as f32 / (d.width.max(2) - 1) as f32;
            // Ticks at 0, 25, 50, 75, 100 % of the range, in the bottom third of the bar.
            let tick = (0..=4).any(|k| (x as i64 - (k * (d.width - 1) / 4) as i64).abs() <= 0);
            let rgb = if tick && y >= d.height + 2 * bar / 3 { [255.0; 3] } else { turbo(t) };
            img.set(x, y, rgb);
        }
    }
    img
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
