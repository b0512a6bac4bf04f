//! The size at which the network sees a pair: `max_size` shrinks large pairs, `min_size`
//! enlarges small ones; the disparity always comes back at the input size, multiplied by the
//! inverse factor.
//!
//! Design decision: a model whose finest grid is 1/8 of the input (the bundled default) loses
//! fine structure on small pairs. On Cones (450x375, 32 iterations) the stage-6 default scores
//! EPE 3.54 px / bad-2 36.6 % at the given size and 2.02 px / 23.7 % with the pair upscaled 2x;
//! on the 640x480 OAK-D desk the textureless wall, wrongly nearer than the desk top in front of
//! it, comes closer to the truth (mean disparity 26.5 against the desk's 17.8 px at 640x480,
//! 23.6 against 18.1 at 900x675). So `min_size auto` (the default) upscales pairs whose longer
//! side is under [`AUTO_MIN_SIZE`] pixels for models at 1/8 resolution, and leaves 1/4-resolution
//! models (the official RAFT-Stereo layout) at the size the reference code uses. An explicit
//! `max_size` turns the automatic enlargement off: asking for a cap means asking for speed.
//!
//! A pair with a side under [`MIN_WORKING_SIZE`] pixels, as given or after `max_size`, is
//! refused ([`network_size`]): the network pads its input to a multiple of 32 (64 for
//! 1/8-resolution models), so such a pair would be mostly padding, and enlarging it
//! (`min_size`) invents the detail the network would match.

use std::str::FromStr;

use dgstereo_core::{Error, Result};
use dgstereo_data::resize::{fit_scale, scaled_size};

/// The smallest side, in pixels, of a pair the network is given, and the smallest that
/// `max_size` and `min_size` may ask for.
pub const MIN_WORKING_SIZE: usize = 32;

/// The longer side that `min_size auto` brings small pairs up to for 1/8-resolution models
/// (Cones: 2x, a 640x480 pair: 1.4x).
pub const AUTO_MIN_SIZE: usize = 900;

/// `min_size`: `auto`, `off` (or `0`), or a number of pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MinSize {
    /// [`AUTO_MIN_SIZE`] for models at 1/8 resolution without `max_size`, else none.
    Auto,
    /// Never enlarge.
    Off,
    /// Enlarge pairs whose longer side is under this many pixels.
    Pixels(usize),
}

impl FromStr for MinSize {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(Self::Auto),
            "off" | "none" | "0" => Ok(Self::Off),
            t => t
                .parse::<usize>()
                .map(Self::Pixels)
                .map_err(|_| format!("'{s}': expected `auto`, `off` or a number of pixels")),
        }
    }
}

impl MinSize {
    /// The smallest longer side for a model at 1/`factor` resolution, given `max_size`.
    pub fn resolve(self, factor: usize, max_size: Option<usize>) -> Option<usize> {
        match self {
            Self::Auto if factor >= 8 && max_size.is_none() => Some(AUTO_MIN_SIZE),
            Self::Auto | Self::Off => None,
            Self::Pixels(n) => Some(n),
        }
    }
}

/// The factor applied to both sides of a `width x height` pair: down to `max_size` when the
/// longer side exceeds it ([`fit_scale`]), else up to `min_size` when the longer side is under
/// it, else 1.
pub fn working_scale(width: usize, height: usize, min_size: Option<usize>, max_size: Option<usize>) -> f64 {
    let down = fit_scale(width, height, max_size);
    let longer = width.max(height);
    match min_size {
        Some(m) if down == 1.0 && longer < m => m as f64 / longer as f64,
        _ => down,
    }
}

/// The factor and the size (`width, height`) at which the network sees a `width x height` pair
/// ([`working_scale`], then rounded as the resize rounds).
///
/// # Errors
/// [`Error::Shape`] when a side of the pair is under [`MIN_WORKING_SIZE`];
/// [`Error::config`]`("max_size", ..)` when `max_size` brings a side under it.
pub fn network_size(
    width: usize,
    height: usize,
    min_size: Option<usize>,
    max_size: Option<usize>,
) -> Result<(f64, (usize, usize))> {
    if width < MIN_WORKING_SIZE || height < MIN_WORKING_SIZE {
        return Err(Error::Shape(format!(
            "the pair is {width}x{height} pixels: the network needs at least {MIN_WORKING_SIZE} pixels on each side"
        )));
    }
    let scale = working_scale(width, height, min_size, max_size);
    let size = if scale == 1.0 { (width, height) } else { scaled_size(width, height, scale, scale) };
    if size.0 < MIN_WORKING_SIZE || size.1 < MIN_WORKING_SIZE {
        let cap = max_size.map_or_else(|| "the working size".to_string(), |m| m.to_string());
        return Err(Error::config(
            "max_size",
            format!(
                "{cap} brings the {width}x{height} pair to {}x{}, under the network's {MIN_WORKING_SIZE} pixels a side: raise it or leave it out",
                size.0, size.1
            ),
        ));
    }
    Ok((scale, size))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_size_parses_and_names_bad_values() {
        assert_eq!("auto".parse(), Ok(MinSize::Auto));
        assert_eq!("OFF".parse(), Ok(MinSize::Off));
        assert_eq!("0".parse(), Ok(MinSize::Off));
        assert_eq!("720".parse(), Ok(MinSize::Pixels(720)));
        let e = "big".parse::<MinSize>().unwrap_err();
        assert!(e.contains("'big'") && e.contains("auto"), "{e}");
    }

    #[test]
    fn auto_enlarges_only_eighth_resolution_models_without_a_cap() {
        assert_eq!(MinSize::Auto.resolve(8, None), Some(AUTO_MIN_SIZE));
        assert_eq!(MinSize::Auto.resolve(4, None), None);
        assert_eq!(MinSize::Auto.resolve(8, Some(640)), None);
        assert_eq!(MinSize::Off.resolve(8, None), None);
        assert_eq!(MinSize::Pixels(500).resolve(4, None), Some(500));
    }

    #[test]
    fn working_scale_enlarges_small_pairs_and_shrinks_large_ones() {
        // Cones 450x375 with the automatic size: 2x.
        assert_eq!(working_scale(450, 375, Some(900), None), 2.0);
        assert_eq!(working_scale(375, 450, Some(900), None), 2.0);
        // Large enough already, or no lower bound: unchanged.
        assert_eq!(working_scale(1242, 375, Some(900), None), 1.0);
        assert_eq!(working_scale(450, 375, None, None), 1.0);
        // The cap wins over the lower bound.
        assert_eq!(working_scale(1242, 375, Some(900), Some(621)), 0.5);
        assert_eq!(working_scale(450, 375, None, Some(150)), 150.0 / 450.0);
    }

    #[test]
    fn pairs_under_the_minimum_are_refused_with_their_size() {
        assert_eq!(network_size(450, 375, Some(900), None).unwrap(), (2.0, (900, 750)));
        assert_eq!(network_size(32, 32, None, None).unwrap(), (1.0, (32, 32)));
        for (w, h) in [(1, 1), (31, 100), (100, 31)] {
            let e = network_size(w, h, Some(900), None).unwrap_err();
            assert!(matches!(e, Error::Shape(_)), "{e:?}");
            assert!(e.to_string().contains(&format!("{w}x{h}")) && e.to_string().contains("32"), "{e}");
        }
        // A cap that brings the shorter side under the minimum names the cap and both sizes.
        let e = network_size(1000, 40, None, Some(100)).unwrap_err();
        assert!(matches!(&e, Error::Config(p) if p.key == "max_size"), "{e:?}");
        assert!(e.to_string().contains("1000x40") && e.to_string().contains("100x4,"), "{e}");
    }
}
