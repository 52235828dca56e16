//! The one place where sensor data becomes model input (no train/serve skew): dataset export
//! (`milliego dataset build`) and the runtime both call this crate.
//!
//! Data flow: radar frame points -> [`panorama`] (16 x 64 depth panorama of one frame, then the
//! overlay of the last 3 frames) -> [`window`] (two overlaid panoramas `gap` frames apart plus the
//! IMU samples between them resampled to a fixed length) -> model input tensors
//! ([`panorama::expand`]: x4 nearest upsampling and the dataset's normalisation). Labels: the
//! relative body pose between the two frames ([`pose`]). [`dataset`] writes the shards the Python
//! trainer reads (format: `docs/dataset.md`).
#![forbid(unsafe_code)]

pub mod dataset;
pub mod imu;
pub mod panorama;
pub mod pose;
pub mod window;

use serde::{Deserialize, Serialize};

/// Panorama rows (elevation bins) before upsampling.
pub const PANO_H: usize = 16;
/// Panorama columns (azimuth bins) before upsampling.
pub const PANO_W: usize = 64;
/// Pixels of one panorama.
pub const PANO_LEN: usize = PANO_H * PANO_W;
/// Upsampling factor from panorama to model image.
pub const UPSCALE: usize = 4;
/// Model image height.
pub const IMG_H: usize = PANO_H * UPSCALE;
/// Model image width.
pub const IMG_W: usize = PANO_W * UPSCALE;
/// Channels of the model's radar input: 3 of the previous frame, 3 of the current ([`RadarInput`]).
pub const RADAR_CHANNELS: usize = 6;
/// Radial velocity that maps to 1 in a Doppler image \[m/s\]; faster ones are clamped to +-1.
pub const DOPPLER_SCALE_MPS: f32 = 5.0;

/// What the six channels of a model's radar input carry (model metadata `radar_input`;
/// `docs/model.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RadarInput {
    /// The paper's input: each frame's depth image three times.
    #[default]
    Depth,
    /// Our extension ("milliEgo+D"): each frame's depth image, its Doppler image
    /// (`clamp(v / DOPPLER_SCALE_MPS, -1, 1)`), its depth image again.
    DepthDoppler,
}

/// Floats in the model's radar input (6 x 64 x 256).
pub const RADAR_LEN: usize = RADAR_CHANNELS * IMG_H * IMG_W;
/// IMU samples in a window.
pub const IMU_LEN: usize = 20;

/// Preprocessing settings. The image geometry is fixed by the network (16 x 64 panorama, x4); what
/// may vary is written into the dataset manifest and the model's metadata and checked at load.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Radar frames between the two frames of a window (the paper's frame gap: parallax).
    pub gap: u32,
    /// Consecutive radar frames overlaid into one image (denser images from sparse clouds).
    pub overlay: u32,
    /// Half the azimuth field of view \[deg\]: bin centres from -63 to +63 at 2 deg.
    pub az_half_deg: f64,
    /// Half the elevation field of view \[deg\]: bin centres from +15 (top row) to -15.
    pub el_half_deg: f64,
    /// Angular bin size \[deg/px\].
    pub deg_per_px: f64,
    /// Panorama rows (16).
    pub pano_h: usize,
    /// Panorama columns (64).
    pub pano_w: usize,
    /// Upsampling factor (4).
    pub upscale: usize,
    /// Model image rows (64).
    pub img_h: usize,
    /// Model image columns (256).
    pub img_w: usize,
    /// IMU samples per window (20).
    pub imu_len: usize,
    /// Range mapped to intensity 0 \[m\]: a point at range r has intensity 1 - r / max_range_m;
    /// points beyond are dropped (counted).
    pub max_range_m: f64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            gap: 5,
            overlay: 3,
            az_half_deg: 63.0,
            el_half_deg: 15.0,
            deg_per_px: 2.0,
            pano_h: PANO_H,
            pano_w: PANO_W,
            upscale: UPSCALE,
            img_h: IMG_H,
            img_w: IMG_W,
            imu_len: IMU_LEN,
            max_range_m: 20.0,
        }
    }
}

/// A preprocessing setting that this build cannot use: which one, its value, and what it
/// must be.
#[derive(Debug, Clone, PartialEq)]
pub struct SettingError {
    /// The setting, as named in the model metadata or the run configuration
    /// (e.g. `preprocess.gap`).
    pub setting: &'static str,
    /// Its value, as given.
    pub value: String,
    /// What it must be.
    pub requirement: String,
}

impl SettingError {
    fn new(setting: &'static str, value: impl std::fmt::Display, requirement: String) -> Self {
        SettingError {
            setting,
            value: value.to_string(),
            requirement,
        }
    }
}

impl std::fmt::Display for SettingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} is {}, {}",
            self.setting, self.value, self.requirement
        )
    }
}

impl std::error::Error for SettingError {}

impl Config {
    /// Checks the fields against what the network and this crate support; the error names the
    /// field and the value.
    pub fn validate(&self) -> Result<(), SettingError> {
        let fixed = [
            ("preprocess.pano_h", self.pano_h, PANO_H),
            ("preprocess.pano_w", self.pano_w, PANO_W),
            ("preprocess.upscale", self.upscale, UPSCALE),
            ("preprocess.img_h", self.img_h, IMG_H),
            ("preprocess.img_w", self.img_w, IMG_W),
            ("preprocess.imu_len", self.imu_len, IMU_LEN),
        ];
        for (name, got, want) in fixed {
            if got != want {
                return Err(SettingError::new(
                    name,
                    got,
                    format!("this build supports {want}"),
                ));
            }
        }
        if !(1..=64).contains(&self.gap) {
            return Err(SettingError::new(
                "preprocess.gap",
                self.gap,
                "must be 1..=64".into(),
            ));
        }
        if !(1..=16).contains(&self.overlay) {
            return Err(SettingError::new(
                "preprocess.overlay",
                self.overlay,
                "must be 1..=16".into(),
            ));
        }
        let span_az = 2.0 * self.az_half_deg / self.deg_per_px + 1.0;
        let span_el = 2.0 * self.el_half_deg / self.deg_per_px + 1.0;
        if (span_az - PANO_W as f64).abs() > 1e-9 || (span_el - PANO_H as f64).abs() > 1e-9 {
            return Err(SettingError::new(
                "preprocess field of view",
                format_args!(
                    "+-{} x +-{} deg at {} deg/px",
                    self.el_half_deg, self.az_half_deg, self.deg_per_px
                ),
                format!(
                    "it gives {span_el} x {span_az} bins, the network needs {PANO_H} x {PANO_W}"
                ),
            ));
        }
        if !(self.max_range_m.is_finite() && self.max_range_m > 0.0) {
            return Err(SettingError::new(
                "preprocess.max_range_m",
                self.max_range_m,
                "must be > 0".into(),
            ));
        }
        Ok(())
    }
}

/// Dataset-wide normalisation of panorama intensities: `(x - min) / (max - min) - mean` (the
/// reference's scaling), computed by `milliego dataset build` over every frame's overlaid panorama
/// and stored with the model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Norm {
    /// Smallest intensity.
    pub min: f64,
    /// Largest intensity.
    pub max: f64,
    /// Mean of the min-max scaled intensities.
    pub mean: f64,
}

impl Default for Norm {
    fn default() -> Self {
        Norm {
            min: 0.0,
            max: 1.0,
            mean: 0.0,
        }
    }
}

impl Norm {
    /// Checks the statistics are finite and max > min.
    pub fn validate(&self) -> Result<(), SettingError> {
        if !(self.min.is_finite() && self.max.is_finite() && self.mean.is_finite())
            || self.max <= self.min
        {
            return Err(SettingError::new(
                "normalisation (min, max, mean)",
                format_args!("({}, {}, {})", self.min, self.max, self.mean),
                "needs finite values with max > min".into(),
            ));
        }
        Ok(())
    }
}
