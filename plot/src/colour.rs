//! Colour maps: viridis (sequential, for errors) and a blue-white-red diverging map (for Doppler),
//! both piecewise linear through matplotlib's samples, so the same colours appear in every figure.

use plotters::style::RGBColor;

/// Ground truth line colour.
pub const GROUND_TRUTH: RGBColor = RGBColor(128, 128, 128);

/// Line colours for series (matplotlib's tab10 order).
pub const SERIES: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

const VIRIDIS: [u32; 11] = [
    0x440154, 0x482475, 0x414487, 0x355F8D, 0x2A788E, 0x21918C, 0x22A884, 0x44BF70, 0x7AD151,
    0xBDDF26, 0xFDE725,
];

/// ColorBrewer RdBu, reversed: blue for approaching (negative), red for receding.
const BLUE_WHITE_RED: [u32; 11] = [
    0x053061, 0x2166AC, 0x4393C3, 0x92C5DE, 0xD1E5F0, 0xF7F7F7, 0xFDDBC7, 0xF4A582, 0xD6604D,
    0xB2182B, 0x67001F,
];

fn lerp(map: &[u32; 11], t: f64) -> RGBColor {
    let t = if t.is_nan() { 0.5 } else { t.clamp(0.0, 1.0) };
    let x = t * 10.0;
    let i = (x.floor() as usize).min(9);
    let f = x - i as f64;
    let ch = |c: u32, s: u32| f64::from((c >> s) & 0xFF);
    let mix = |s| (ch(map[i], s) * (1.0 - f) + ch(map[i + 1], s) * f).round() as u8;
    RGBColor(mix(16), mix(8), mix(0))
}

/// Viridis at `t` in 0..=1 (clamped; NaN gives the middle).
pub fn error_colour(t: f64) -> RGBColor {
    lerp(&VIRIDIS, t)
}

/// Blue (0, approaching) through white (0.5, still) to red (1, receding).
pub fn doppler_colour(t: f64) -> RGBColor {
    lerp(&BLUE_WHITE_RED, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_and_middle() {
        assert_eq!(error_colour(0.0), RGBColor(0x44, 0x01, 0x54));
        assert_eq!(error_colour(1.0), RGBColor(0xFD, 0xE7, 0x25));
        assert_eq!(error_colour(2.0), error_colour(1.0));
        assert_eq!(doppler_colour(0.5), RGBColor(0xF7, 0xF7, 0xF7));
        assert_eq!(doppler_colour(f64::NAN), doppler_colour(0.5));
    }
}
