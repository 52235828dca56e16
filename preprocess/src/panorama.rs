//! Radar point cloud -> panoramic depth image (the paper's projection), overlay of consecutive
//! frames, and expansion to the model's input tensor.
//!
//! Radar frame: x right, y boresight, z up \[m\]. Azimuth `atan2(x, y)` (positive to the right),
//! elevation `atan2(z, hypot(x, y))`. Column `round((az + az_half) / deg_per_px)` (column 0 =
//! leftmost, -63 deg), row `round((el_half - el) / deg_per_px)` (row 0 = top, +15 deg): bin
//! centres every 2 deg, 16 x 64 bins. Intensity `1 - r / max_range` (nearer points brighter; 0 =
//! no return); several points in one bin keep the brightest (nearest). Beside each depth panorama
//! the Doppler panorama holds that winning point's radial velocity \[m/s\] (as the radar reports it:
//! negative approaching; 0 where the bin is empty), for the models that read Doppler
//! ([`RadarInput::DepthDoppler`], "milliEgo+D").

use crate::{
    Config, Norm, RadarInput, DOPPLER_SCALE_MPS, IMG_H, IMG_W, PANO_H, PANO_LEN, PANO_W, RADAR_LEN,
    UPSCALE,
};
use radar_driver::tlv::Point;

/// What happened to the points of one projection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProjectStats {
    /// Points written into a bin.
    pub in_view: u32,
    /// Points outside the azimuth/elevation field of view.
    pub out_of_view: u32,
    /// Points beyond `max_range_m`.
    pub out_of_range: u32,
    /// Points with a NaN or infinite coordinate.
    pub non_finite: u32,
}

impl core::ops::AddAssign for ProjectStats {
    fn add_assign(&mut self, o: ProjectStats) {
        self.in_view += o.in_view;
        self.out_of_view += o.out_of_view;
        self.out_of_range += o.out_of_range;
        self.non_finite += o.non_finite;
    }
}

/// The bin (row, column) and intensity of a point, or why it has none.
pub fn bin(cfg: &Config, p: &Point) -> Result<(usize, usize, f32), Dropped> {
    let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
    if !(x.is_finite() && y.is_finite() && z.is_finite()) {
        return Err(Dropped::NonFinite);
    }
    let r = (x * x + y * y + z * z).sqrt();
    if r > cfg.max_range_m {
        return Err(Dropped::OutOfRange);
    }
    let az = x.atan2(y).to_degrees();
    let el = z.atan2(x.hypot(y)).to_degrees();
    let col = ((az + cfg.az_half_deg) / cfg.deg_per_px).round();
    let row = ((cfg.el_half_deg - el) / cfg.deg_per_px).round();
    if !(0.0..PANO_W as f64).contains(&col) || !(0.0..PANO_H as f64).contains(&row) {
        return Err(Dropped::OutOfView);
    }
    Ok((
        row as usize,
        col as usize,
        (1.0 - r / cfg.max_range_m) as f32,
    ))
}

/// Why a point is not in the panorama.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dropped {
    /// NaN or infinite coordinate.
    NonFinite,
    /// Beyond the maximum range.
    OutOfRange,
    /// Outside the field of view.
    OutOfView,
}

/// Projects one frame's points into `out` (16 x 64, row-major) and the winning points' radial
/// velocities \[m/s\] into `doppler`; both are cleared first. Of several points in one bin the
/// nearest wins (the first of equals).
pub fn project(
    cfg: &Config,
    points: &[Point],
    out: &mut [f32; PANO_LEN],
    doppler: &mut [f32; PANO_LEN],
) -> ProjectStats {
    out.fill(0.0);
    doppler.fill(0.0);
    let mut s = ProjectStats::default();
    for p in points {
        match bin(cfg, p) {
            Ok((r, c, v)) => {
                let i = r * PANO_W + c;
                if v > out[i] {
                    out[i] = v;
                    doppler[i] = if p.velocity.is_finite() {
                        p.velocity
                    } else {
                        0.0
                    };
                }
                s.in_view += 1;
            }
            Err(Dropped::NonFinite) => s.non_finite += 1,
            Err(Dropped::OutOfRange) => s.out_of_range += 1,
            Err(Dropped::OutOfView) => s.out_of_view += 1,
        }
    }
    s
}

/// Overlays single-frame panoramas, each a (depth, Doppler) pair: the brightest (nearest) return
/// of each bin and its Doppler (the earlier frame's of equals).
pub fn overlay<'a>(
    frames: impl IntoIterator<Item = (&'a [f32; PANO_LEN], &'a [f32; PANO_LEN])>,
    out: &mut [f32; PANO_LEN],
    doppler: &mut [f32; PANO_LEN],
) {
    out.fill(0.0);
    doppler.fill(0.0);
    for (f, d) in frames {
        for i in 0..PANO_LEN {
            if f[i] > out[i] {
                out[i] = f[i];
                doppler[i] = d[i];
            }
        }
    }
}

/// One panorama -> one 64 x 256 model image: nearest-neighbour x4 (each bin becomes a 4 x 4
/// block), then `(x - min) / (max - min) - mean`, in f32 in that order (the Python trainer's
/// `expand_panorama` does the same arithmetic; a test checks them against each other).
pub fn expand(pano: &[f32; PANO_LEN], norm: &Norm, out: &mut [f32]) {
    let (min, span, mean) = (
        norm.min as f32,
        (norm.max - norm.min) as f32,
        norm.mean as f32,
    );
    upsample(pano, out, |x| (x - min) / span - mean);
}

/// One Doppler panorama -> one 64 x 256 model image: nearest-neighbour x4, each value
/// `clamp(v / DOPPLER_SCALE_MPS, -1, 1)` (no dataset statistics: the scale is fixed).
pub fn expand_doppler(doppler: &[f32; PANO_LEN], out: &mut [f32]) {
    upsample(doppler, out, |v| (v / DOPPLER_SCALE_MPS).clamp(-1.0, 1.0));
}

/// Each bin of `pano`, mapped by `f`, as a 4 x 4 block of the 64 x 256 image `out`.
fn upsample(pano: &[f32; PANO_LEN], out: &mut [f32], f: impl Fn(f32) -> f32) {
    debug_assert_eq!(out.len(), IMG_H * IMG_W);
    for r in 0..PANO_H {
        for c in 0..PANO_W {
            let v = f(pano[r * PANO_W + c]);
            for i in 0..UPSCALE {
                let row = (r * UPSCALE + i) * IMG_W + c * UPSCALE;
                out[row..row + UPSCALE].fill(v);
            }
        }
    }
}

/// The model's radar input (6 x 64 x 256, channels first), laid out as `input` says:
/// [`RadarInput::Depth`], three copies of the previous frame's depth image then three of the
/// current's (the reference repeats its one depth channel so FlowNet-shaped first layers fit);
/// [`RadarInput::DepthDoppler`], per frame its depth image, its Doppler image, its depth image
/// again (previous frame in channels 0-2, current in 3-5). `*_doppler` are read only for the
/// latter.
pub fn radar_tensor(
    input: RadarInput,
    (prev, prev_doppler): (&[f32; PANO_LEN], &[f32; PANO_LEN]),
    (cur, cur_doppler): (&[f32; PANO_LEN], &[f32; PANO_LEN]),
    norm: &Norm,
    out: &mut [f32; RADAR_LEN],
) {
    let plane = IMG_H * IMG_W;
    expand(prev, norm, &mut out[..plane]);
    expand(cur, norm, &mut out[3 * plane..4 * plane]);
    match input {
        RadarInput::Depth => {
            out.copy_within(0..plane, plane);
            out.copy_within(3 * plane..4 * plane, 4 * plane);
        }
        RadarInput::DepthDoppler => {
            expand_doppler(prev_doppler, &mut out[plane..2 * plane]);
            expand_doppler(cur_doppler, &mut out[4 * plane..5 * plane]);
        }
    }
    out.copy_within(0..plane, 2 * plane);
    out.copy_within(3 * plane..4 * plane, 5 * plane);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pt(x: f32, y: f32, z: f32) -> Point {
        Point {
            x,
            y,
            z,
            velocity: 0.0,
        }
    }

    /// A point at range r, azimuth az, elevation el (degrees).
    fn polar(r: f64, az: f64, el: f64) -> Point {
        let (az, el) = (az.to_radians(), el.to_radians());
        pt(
            (r * el.cos() * az.sin()) as f32,
            (r * el.cos() * az.cos()) as f32,
            (r * el.sin()) as f32,
        )
    }

    #[test]
    fn known_points_land_in_the_expected_bins() {
        let cfg = Config::default();
        // Boresight, level: azimuth 0 -> column 63/2 = 31.5 rounds to 32; elevation 0 -> row 7.5
        // rounds to 8 (round half away from zero).
        assert_eq!(bin(&cfg, &polar(5.0, 0.0, 0.0)).unwrap().0, 8);
        assert_eq!(bin(&cfg, &polar(5.0, 0.0, 0.0)).unwrap().1, 32);
        // Bin centres: az -63 -> col 0, +63 -> col 63; el +15 -> row 0, -15 -> row 15.
        let (r, c, _) = bin(&cfg, &polar(5.0, -63.0, 15.0)).unwrap();
        assert_eq!((r, c), (0, 0));
        let (r, c, _) = bin(&cfg, &polar(5.0, 63.0, -15.0)).unwrap();
        assert_eq!((r, c), (15, 63));
        // Right of boresight is a higher column; up is a lower row.
        let (r, c, _) = bin(&cfg, &polar(5.0, 21.0, 7.0)).unwrap();
        assert_eq!((r, c), (4, 42));
        let (r, c, _) = bin(&cfg, &polar(5.0, -31.0, -9.0)).unwrap();
        assert_eq!((r, c), (12, 16));
        // Just outside the field of view.
        assert_eq!(bin(&cfg, &polar(5.0, 64.5, 0.0)), Err(Dropped::OutOfView));
        assert_eq!(bin(&cfg, &polar(5.0, 0.0, -16.5)), Err(Dropped::OutOfView));
        // Behind the sensor.
        assert_eq!(bin(&cfg, &pt(0.0, -3.0, 0.0)), Err(Dropped::OutOfView));
        assert_eq!(bin(&cfg, &polar(25.0, 0.0, 0.0)), Err(Dropped::OutOfRange));
        assert_eq!(bin(&cfg, &pt(f32::NAN, 1.0, 0.0)), Err(Dropped::NonFinite));
    }

    #[test]
    fn nearer_points_are_brighter_and_win_their_bin() {
        let cfg = Config::default();
        let mut pano = [0.0; PANO_LEN];
        let mut dop = [0.0; PANO_LEN];
        let s = project(
            &cfg,
            &[
                polar(10.0, 0.0, 0.0),
                polar(5.0, 0.0, 0.0),
                polar(30.0, 0.0, 0.0),
            ],
            &mut pano,
            &mut dop,
        );
        assert_eq!((s.in_view, s.out_of_range), (2, 1));
        let v = pano[8 * PANO_W + 32];
        assert!((v - 0.75).abs() < 1e-6, "{v}");
        assert_eq!(pano.iter().filter(|v| **v > 0.0).count(), 1);
    }

    #[test]
    fn overlay_keeps_the_brightest_return() {
        let mut a = [0.0; PANO_LEN];
        let mut b = [0.0; PANO_LEN];
        a[3] = 0.5;
        b[3] = 0.7;
        b[9] = 0.2;
        let (mut da, mut db) = ([0.0; PANO_LEN], [0.0; PANO_LEN]);
        (da[3], db[3], db[9]) = (-1.0, 2.0, 3.0);
        let mut o = [1.0; PANO_LEN];
        let mut od = [1.0; PANO_LEN];
        overlay([(&a, &da), (&b, &db)], &mut o, &mut od);
        assert_eq!((o[3], o[9], o[0]), (0.7, 0.2, 0.0));
        assert_eq!(
            (od[3], od[9], od[0]),
            (2.0, 3.0, 0.0),
            "the winner's Doppler"
        );
    }

    #[test]
    fn the_nearest_point_gives_its_bin_its_doppler() {
        let cfg = Config::default();
        let (mut pano, mut dop) = ([0.0; PANO_LEN], [0.0; PANO_LEN]);
        let at = |r: f64, v: f32| Point {
            velocity: v,
            ..polar(r, 0.0, 0.0)
        };
        project(
            &cfg,
            &[at(10.0, -1.5), at(5.0, 0.75), at(8.0, 2.0)],
            &mut pano,
            &mut dop,
        );
        assert_eq!(dop[8 * PANO_W + 32], 0.75, "the 5 m point's");
        assert_eq!(dop.iter().filter(|v| **v != 0.0).count(), 1);
    }

    #[test]
    fn doppler_input_holds_each_frames_doppler_between_its_depth_copies() {
        let (mut prev, mut cur) = ([0.0; PANO_LEN], [0.0; PANO_LEN]);
        let (mut prev_d, mut cur_d) = ([0.0; PANO_LEN], [0.0; PANO_LEN]);
        (prev[0], prev_d[0]) = (0.5, -2.5);
        (cur[PANO_W + 2], cur_d[PANO_W + 2]) = (0.25, 7.0);
        cur_d[5] = -30.0;
        let norm = Norm::default();
        let mut t = Box::new([0.0f32; RADAR_LEN]);
        radar_tensor(
            RadarInput::DepthDoppler,
            (&prev, &prev_d),
            (&cur, &cur_d),
            &norm,
            &mut t,
        );
        let plane = IMG_H * IMG_W;
        let px = |ch: usize, r: usize, c: usize| t[ch * plane + r * IMG_W + c];
        for ch in [0, 2] {
            assert_eq!(
                (px(ch, 3, 3), px(ch, 4, 4)),
                (0.5, 0.0),
                "prev depth in {ch}"
            );
        }
        for ch in [3, 5] {
            assert_eq!(
                (px(ch, 4, 8), px(ch, 7, 11)),
                (0.25, 0.25),
                "cur depth in {ch}"
            );
        }
        // Doppler / 5 m/s, clamped to +-1, in blocks of 4 x 4.
        assert_eq!((px(1, 0, 0), px(1, 3, 3), px(1, 4, 4)), (-0.5, -0.5, 0.0));
        assert_eq!((px(4, 4, 8), px(4, 0, 20), px(4, 0, 0)), (1.0, -1.0, 0.0));
        // The paper's layout ignores the Doppler panoramas.
        let mut d = Box::new([0.0f32; RADAR_LEN]);
        radar_tensor(
            RadarInput::Depth,
            (&prev, &prev_d),
            (&cur, &cur_d),
            &norm,
            &mut d,
        );
        assert_eq!(d[plane + 3 * IMG_W + 3], 0.5);
        assert_eq!(d[4 * plane + 4 * IMG_W + 8], 0.25);
    }

    #[test]
    fn expansion_repeats_bins_and_normalises() {
        let mut prev = [0.0; PANO_LEN];
        let mut cur = [0.0; PANO_LEN];
        prev[PANO_W + 2] = 0.5; // row 1, col 2
        cur[0] = 1.0;
        let norm = Norm {
            min: 0.0,
            max: 2.0,
            mean: 0.1,
        };
        let mut t = Box::new([0.0f32; RADAR_LEN]);
        let dop = [0.0; PANO_LEN];
        radar_tensor(
            RadarInput::Depth,
            (&prev, &dop),
            (&cur, &dop),
            &norm,
            &mut t,
        );
        let plane = IMG_H * IMG_W;
        for ch in 0..3 {
            let img = &t[ch * plane..(ch + 1) * plane];
            assert_eq!(img[4 * IMG_W + 8], 0.25 - 0.1);
            assert_eq!(img[7 * IMG_W + 11], 0.25 - 0.1);
            assert_eq!(img[8 * IMG_W + 8], -0.1);
            assert_eq!(img[3 * IMG_W + 8], -0.1);
        }
        for ch in 3..6 {
            let img = &t[ch * plane..(ch + 1) * plane];
            assert_eq!(img[3 * IMG_W + 3], 0.5 - 0.1);
            assert_eq!(img[4 * IMG_W + 4], -0.1);
        }
    }
}
