//! Plain-Rust operations on single-channel `H x W` maps used by the simulated prior.

/// Whether a disparity sample is valid ground truth (finite and positive).
pub fn is_valid(d: f32) -> bool {
    d.is_finite() && d > 0.0
}

/// Fills invalid samples (see [`is_valid`]) the way a monocular network's dense output
/// continues the surface behind an occluder: each invalid run of a row takes the smaller (farther,
/// background) of the valid values bordering it, or the one that exists at an image edge. Rows
/// with no valid sample copy the filled row nearest to them (the farther of two at equal
/// distance). A map with no valid sample becomes zeros.
///
/// # Shapes
/// - `values`: `height · width`, row-major
pub fn fill_holes_background(values: &mut [f32], height: usize, width: usize) {
    let mut row_filled = vec![false; height];
    for (y, filled) in row_filled.iter_mut().enumerate() {
        let row = &mut values[y * width..(y + 1) * width];
        if !row.iter().any(|&v| is_valid(v)) {
            continue;
        }
        *filled = true;
        let mut x = 0;
        while x < width {
            if is_valid(row[x]) {
                x += 1;
                continue;
            }
            let start = x;
            while x < width && !is_valid(row[x]) {
                x += 1;
            }
            let before = (start > 0).then(|| row[start - 1]);
            let after = (x < width).then(|| row[x]);
            let fill = match (before, after) {
                (Some(a), Some(b)) => a.min(b),
                (Some(a), None) | (None, Some(a)) => a,
                (None, None) => unreachable!("the row has a valid sample"),
            };
            row[start..x].fill(fill);
        }
    }
    let filled_rows: Vec<usize> = (0..height).filter(|&y| row_filled[y]).collect();
    for y in (0..height).filter(|&y| !row_filled[y]) {
        let nearest = filled_rows.iter().map(|&r| r.abs_diff(y)).min();
        match nearest {
            None => values[y * width..(y + 1) * width].fill(0.0),
            Some(dist) => {
                let candidates: Vec<usize> = filled_rows.iter().copied().filter(|r| r.abs_diff(y) == dist).collect();
                for x in 0..width {
                    let v = candidates.iter().map(|&r| values[r * width + x]).fold(f32::INFINITY, f32::min);
                    values[y * width + x] = v;
                }
            }
        }
    }
}

/// Forward-warps the left view's disparity to the right view: left pixel `x` lands on
/// `round(x - d)`; where several land on one pixel the largest disparity (the nearest surface)
/// wins; pixels nothing lands on (disocclusions, the right image's left border... and invalid
/// input) are NaN.
///
/// # Shapes
/// - `disparity`, output: `height · width`, row-major
pub fn warp_left_to_right(disparity: &[f32], height: usize, width: usize) -> Vec<f32> {
    let mut out = vec![f32::NAN; height * width];
    for y in 0..height {
        for x in 0..width {
            let d = disparity[y * width + x];
            if !is_valid(d) {
                continue;
            }
            let target = (x as f32 - d).round();
            if target < 0.0 || target >= width as f32 {
                continue;
            }
            let slot = &mut out[y * width + target as usize];
            if slot.is_nan() || *slot < d {
                *slot = d;
            }
        }
    }
    out
}

/// Separable Gaussian blur with standard deviation `sigma` pixels (radius `ceil(3σ)`), edges
/// replicated. `sigma <= 0` leaves the map unchanged.
///
/// # Shapes
/// - `values`, output: `height · width`, row-major
pub fn gaussian_blur(values: &[f32], height: usize, width: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 {
        return values.to_vec();
    }
    let radius = (3.0 * sigma).ceil() as i64;
    let kernel: Vec<f32> = (-radius..=radius).map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp()).collect();
    let total: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / total).collect();
    let pass = |src: &[f32], along_rows: bool| -> Vec<f32> {
        let mut dst = vec![0f32; src.len()];
        let (n, stride_len) = if along_rows { (width, 1) } else { (height, width) };
        for y in 0..height {
            for x in 0..width {
                let pos = if along_rows { x } else { y } as i64;
                let base = y * width + x - (pos as usize) * stride_len;
                dst[y * width + x] = kernel
                    .iter()
                    .enumerate()
                    .map(|(k, w)| {
                        let p = (pos + k as i64 - radius).clamp(0, n as i64 - 1) as usize;
                        w * src[base + p * stride_len]
                    })
                    .sum();
            }
        }
        dst
    };
    pass(&pass(values, true), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holes_take_the_background_side() {
        // Row: foreground 20, a hole, then background 5.
        let mut row = vec![20.0, 20.0, f32::NAN, 0.0, -1.0, 5.0, 5.0];
        fill_holes_background(&mut row, 1, 7);
        assert_eq!(row, vec![20.0, 20.0, 5.0, 5.0, 5.0, 5.0, 5.0]);
        // Edge holes copy the only neighbour; empty rows copy the nearest filled row.
        let mut map = vec![f32::NAN, 3.0, 4.0, f32::NAN, f32::NAN, f32::NAN];
        fill_holes_background(&mut map, 2, 3);
        assert_eq!(map, vec![3.0, 3.0, 4.0, 3.0, 3.0, 4.0]);
        let mut empty = vec![f32::NAN; 4];
        fill_holes_background(&mut empty, 2, 2);
        assert_eq!(empty, vec![0.0; 4]);
    }

    #[test]
    fn warp_moves_by_disparity_and_nearest_wins() {
        let w = 10;
        let mut d = vec![2.0f32; w];
        d[6] = 4.0; // a near pixel lands on 2, where left pixel 4 (d = 2) also lands
        let r = warp_left_to_right(&d, 1, w);
        assert_eq!(r[2], 4.0);
        assert_eq!(r[0], 2.0);
        assert!(r[8].is_nan() && r[9].is_nan(), "nothing lands on the right border: {r:?}");
    }

    #[test]
    fn blur_keeps_constants_and_mass() {
        let (h, w) = (6, 9);
        let flat = vec![3.5f32; h * w];
        assert!(gaussian_blur(&flat, h, w, 1.3).iter().all(|v| (v - 3.5).abs() < 1e-5));
        // Away from the border (radius ceil(3 · 0.8) = 3) the blur conserves mass and spreads.
        let (h, w) = (12, 12);
        let mut spike = vec![0f32; h * w];
        spike[6 * w + 6] = 1.0;
        let b = gaussian_blur(&spike, h, w, 0.8);
        assert!((b.iter().sum::<f32>() - 1.0).abs() < 1e-4);
        assert!(b[6 * w + 6] < 1.0 && b[6 * w + 7] > 0.0 && b[5 * w + 6] > 0.0);
        assert_eq!(b[6 * w + 10], 0.0);
    }
}
