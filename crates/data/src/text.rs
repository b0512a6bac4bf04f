//! A 3x5 pixel bitmap font for the few labels our pictures carry (colour-bar values, plot axes).
//!
//! No font file and no dependency: digits, upper-case letters (lower case is drawn as upper
//! case) and `. - % : /`. Drawing goes through a pixel setter so the same glyphs serve the
//! float images of this crate and the 8-bit images of the training plot.

/// Glyph height in font pixels.
pub const GLYPH_HEIGHT: usize = 5;

/// A 3x5 glyph: five rows of three bits (most significant = left). Unknown characters are blank.
pub fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        '%' => [5, 1, 2, 4, 5],
        ':' => [0, 2, 0, 2, 0],
        '/' => [1, 1, 2, 4, 4],
        '+' => [0, 2, 7, 2, 0],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        '=' => [0, 7, 0, 7, 0],
        ',' => [0, 0, 0, 2, 4],
        '_' => [0, 0, 0, 0, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        _ => [0; 5],
    }
}

/// Width in image pixels of `s` drawn at `scale` (glyphs 3 wide, 1 apart).
pub fn text_width(s: &str, scale: usize) -> usize {
    (s.chars().count() * 4).saturating_sub(1) * scale
}

/// Calls `set(x, y)` for every image pixel of `s` with its top-left corner at `(x0, y0)`, each
/// font pixel `scale` image pixels wide; the caller clips.
pub fn draw_text(s: &str, x0: usize, y0: usize, scale: usize, mut set: impl FnMut(usize, usize)) {
    for (i, c) in s.chars().enumerate() {
        for (gy, row) in glyph(c).iter().enumerate() {
            for gx in 0..3 {
                if row & (4 >> gx) == 0 {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        set(x0 + (i * 4 + gx) * scale + dx, y0 + gy * scale + dy);
                    }
                }
            }
        }
    }
}

/// A short label of a value: no decimals from 100 on, one below, `k`/`M` suffixes from 10^4.
pub fn format_value(v: f64) -> String {
    let a = v.abs();
    if a >= 1e6 {
        format!("{:.1}M", v / 1e6)
    } else if a >= 1e4 {
        format!("{:.0}K", v / 1e3)
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_character_has_a_distinct_glyph() {
        let chars: Vec<char> = "0123456789.-%:/+()=,_ABCDEFGHIJKLMNOPQRSTUVWXYZ".chars().collect();
        for (i, a) in chars.iter().enumerate() {
            assert_ne!(glyph(*a), [0; 5], "{a} is blank");
            for b in &chars[i + 1..] {
                assert_ne!(glyph(*a), glyph(*b), "{a} and {b} look alike");
            }
        }
        assert_eq!(glyph('e'), glyph('E'));
        assert_eq!(glyph('#'), [0; 5]);
    }

    #[test]
    fn drawing_covers_the_measured_box() {
        let (mut max_x, mut max_y, mut n) = (0, 0, 0);
        draw_text("8.8", 10, 20, 2, |x, y| {
            assert!(x >= 10 && y >= 20);
            max_x = max_x.max(x);
            max_y = max_y.max(y);
            n += 1;
        });
        assert_eq!(max_x + 1 - 10, text_width("8.8", 2));
        assert_eq!(max_y + 1 - 20, GLYPH_HEIGHT * 2);
        assert_eq!(n, (13 + 1 + 13) * 4, "two 8s of 13 font pixels and a dot, 4 image pixels each");
    }

    #[test]
    fn values_are_short() {
        assert_eq!(format_value(3.24159), "3.2");
        assert_eq!(format_value(250.4), "250");
        assert_eq!(format_value(15000.0), "15K");
        assert_eq!(format_value(2_500_000.0), "2.5M");
    }
}
