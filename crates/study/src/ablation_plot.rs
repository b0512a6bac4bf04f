//! `ablation.png`: the validation curves of every row of an ablation in one plot.
//!
//! Design decision: the per-run `curves.png` cannot show which row learns faster. This plot
//! draws, per row, the mean validation EPE over its seeds at each validated step as a line, and
//! where a row has several seeds a band from the lowest to the highest seed; the row names are
//! listed under the panel in their colours. Only the validation EPE is drawn: it is the same
//! measure for every row, where training losses of rows with different loss kinds are not
//! comparable.

use std::path::Path;

use dgstereo_core::Result;
use image::{Rgb, RgbImage};

use dgstereo_train::plot::{BOTTOM, GRID, HEIGHT, LEFT, PANEL_W, Series, TEXT, TOP, line, panel, text, write_png};

/// Line colours, one per row, in turn.
const PALETTE: [Rgb<u8>; 8] = [
    Rgb([31, 119, 180]),
    Rgb([255, 127, 14]),
    Rgb([44, 160, 44]),
    Rgb([214, 39, 40]),
    Rgb([148, 103, 189]),
    Rgb([140, 86, 75]),
    Rgb([227, 119, 194]),
    Rgb([23, 190, 207]),
];

/// One row's validation curves: a name and one `(step, EPE)` series per seed.
#[derive(Debug, Clone, Default)]
pub struct RowCurves {
    /// The row's name.
    pub name: String,
    /// One series per seed.
    pub seeds: Vec<Series>,
}

/// The validation EPE of a run's `log.jsonl` (`kind = "validation"` lines), empty when the log
/// is missing.
pub fn validation_series(log: &Path) -> Series {
    let Ok(text) = std::fs::read_to_string(log) else { return Series::new() };
    text.lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["kind"] == "validation")
        .filter_map(|v| Some((v["step"].as_f64()?, v["epe"].as_f64()?)))
        .collect()
}

/// Per step validated by every seed of the row: `(step, mean, lowest, highest)`.
fn summary(row: &RowCurves) -> Vec<(f64, f64, f64, f64)> {
    let Some(first) = row.seeds.first() else { return Vec::new() };
    first
        .iter()
        .filter_map(|&(step, _)| {
            let values: Vec<f64> = row
                .seeds
                .iter()
                .filter_map(|s| s.iter().find(|p| p.0 == step).map(|p| p.1))
                .filter(|v| v.is_finite())
                .collect();
            (values.len() == row.seeds.len()).then(|| {
                let mean = values.iter().sum::<f64>() / values.len() as f64;
                let low = values.iter().copied().fold(f64::INFINITY, f64::min);
                let high = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                (step, mean, low, high)
            })
        })
        .collect()
}

/// A lighter shade of `c` for the seeds' band.
fn light(c: Rgb<u8>) -> Rgb<u8> {
    Rgb(c.0.map(|v| ((u16::from(v) + 2 * 255) / 3) as u8))
}

/// Draws the rows' curves: one panel, the legend below it.
pub fn render(rows: &[RowCurves]) -> RgbImage {
    let legend_line = 22;
    let height = HEIGHT + 8 + legend_line * rows.len() as u32;
    let mut img = RgbImage::from_pixel(PANEL_W, height, Rgb([255, 255, 255]));
    let summaries: Vec<_> = rows.iter().map(summary).collect();
    let max_step = summaries.iter().flatten().map(|p| p.0).fold(1.0f64, f64::max);
    let highs: Vec<Series> = summaries.iter().map(|s| s.iter().map(|p| (p.0, p.3)).collect()).collect();
    // The panel's axes and grid, scaled to the highest seed; the curves are drawn below.
    let series: Vec<(&Series, Rgb<u8>, bool, &str)> =
        highs.iter().map(|h| (h, Rgb([255, 255, 255]), false, "")).collect();
    panel(&mut img, 0, "VALIDATION EPE PX / STEP", &series, max_step);
    let top = highs.iter().flatten().map(|p| p.1).filter(|v| v.is_finite()).fold(0.0f64, f64::max);
    let top = if top > 0.0 { top } else { 1.0 };
    let (x0, x1) = (f64::from(LEFT), f64::from(PANEL_W - 14));
    let (y0, y1) = (f64::from(HEIGHT - BOTTOM), f64::from(TOP));
    let to_px = |s: f64, v: f64| (x0 + (x1 - x0) * s / max_step, y0 + (y1 - y0) * (v / top).clamp(0.0, 1.0));
    // Bands first, each row's beside the others' at a step, then every mean line over them.
    let several = rows.len() as f64;
    for (i, summary) in summaries.iter().enumerate().filter(|(i, _)| rows[*i].seeds.len() > 1) {
        let band = light(PALETTE[i % PALETTE.len()]);
        let offset = (i as f64 - (several - 1.0) / 2.0) * 6.0;
        for &(step, _, low, high) in summary {
            let ((x, ylow), (_, yhigh)) = (to_px(step, low), to_px(step, high));
            for dx in -2..=2 {
                let x = x + offset + f64::from(dx);
                line(&mut img, (x, ylow), (x, yhigh), band);
            }
        }
    }
    for (i, summary) in summaries.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let means: Vec<_> = summary.iter().map(|p| to_px(p.0, p.1)).collect();
        for w in means.windows(2) {
            line(&mut img, w[0], w[1], colour);
        }
        for &(x, y) in &means {
            for dx in -2..=2 {
                line(&mut img, (x + f64::from(dx), y - 2.0), (x + f64::from(dx), y + 2.0), colour);
            }
        }
    }
    line(&mut img, (0.0, f64::from(HEIGHT + 2)), (f64::from(PANEL_W - 1), f64::from(HEIGHT + 2)), GRID);
    for (i, row) in rows.iter().enumerate() {
        let y = f64::from(HEIGHT + 8 + legend_line * i as u32);
        let colour = PALETTE[i % PALETTE.len()];
        for dy in 4..10 {
            line(&mut img, (8.0, y + f64::from(dy)), (28.0, y + f64::from(dy)), colour);
        }
        let seeds =
            if row.seeds.len() > 1 { format!(" ({} SEEDS, BAND: MIN TO MAX)", row.seeds.len()) } else { String::new() };
        text(&mut img, &format!("{}{seeds}", row.name.to_uppercase()), 36.0, y, TEXT);
    }
    img
}

/// Writes the plot of `rows` to `path` (PNG), atomically.
pub fn write_ablation_plot(rows: &[RowCurves], path: &Path) -> Result<()> {
    write_png(&render(rows), path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_drawn_in_their_colours_with_bands_and_a_legend() {
        let curve = |scale: f64| -> Series { (1..=5).map(|s| (f64::from(s) * 10.0, scale / f64::from(s))).collect() };
        let rows = vec![
            RowCurves { name: "baseline".into(), seeds: vec![curve(4.0), curve(6.0), curve(5.0)] },
            RowCurves { name: "+dgia".into(), seeds: vec![curve(3.0)] },
        ];
        let img = render(&rows);
        assert_eq!(img.dimensions(), (PANEL_W, HEIGHT + 8 + 44));
        let count = |c: Rgb<u8>, ys: std::ops::Range<u32>| {
            (0..PANEL_W)
                .flat_map(|x| ys.clone().map(move |y| (x, y)))
                .filter(|&(x, y)| *img.get_pixel(x, y) == c)
                .count()
        };
        assert!(count(PALETTE[0], 0..HEIGHT) > 50, "the first row's mean");
        assert!(count(PALETTE[1], 0..HEIGHT) > 50, "the second row's mean");
        assert!(count(light(PALETTE[0]), 0..HEIGHT) > 20, "the first row's band");
        assert_eq!(count(light(PALETTE[1]), 0..HEIGHT), 0, "a single seed has no band");
        assert!(count(TEXT, HEIGHT..HEIGHT + 52) > 50, "the legend");
    }
}
