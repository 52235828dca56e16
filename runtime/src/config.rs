//! The run configuration file (TOML). Every field is optional; command-line flags override it.
//! Unknown fields are errors, and values are checked with messages that name the field.

use crate::estimator::EstimatorKind;
use crate::output::OutputSpec;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The whole file.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileConfig {
    /// Estimator: model, doppler, imu or auto.
    pub estimator: Option<EstimatorKind>,
    /// Learned-model file.
    pub model: Option<PathBuf>,
    /// Threads for the learned model's matrix products (default 1).
    pub model_threads: Option<usize>,
    /// Outputs: `udp://HOST:PORT`, `serial:DEV[@BAUD]`, `tum:FILE`.
    #[serde(default)]
    pub out: Vec<String>,
    /// Publish IMU-propagated poses between radar-rate poses.
    pub imu_rate_output: Option<bool>,
    /// TUM outputs include the predicted poses.
    pub tum_predicted: Option<bool>,
    /// Summary JSON file.
    pub summary_json: Option<PathBuf>,
    /// Radar.
    #[serde(default)]
    pub radar: RadarSection,
    /// IMU.
    #[serde(default)]
    pub imu: ImuSection,
    /// Sensor placement in the body frame.
    #[serde(default)]
    pub extrinsics: ExtrinsicsSection,
    /// Synchroniser.
    #[serde(default)]
    pub sync: SyncSection,
    /// Queue capacities.
    #[serde(default)]
    pub queues: QueueSection,
}

/// `[radar]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadarSection {
    /// CLI port.
    pub cli: Option<String>,
    /// Data port.
    pub data: Option<String>,
    /// `.cfg` file.
    pub cfg: Option<PathBuf>,
    /// Data-port baud rate \[bit/s\].
    pub baud: Option<u32>,
}

/// `[imu]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuSection {
    /// Port.
    pub port: Option<String>,
    /// Baud rate \[bit/s\].
    pub baud: Option<u32>,
    /// SampleTimeFine wrap: `pow32` (MTi-1/600) or `day` (MTi-10/100).
    pub wrap: Option<String>,
    /// The part's name (e.g. `MTi-1`, `MTi-630`, `BMI088`): picks the filter's IMU noise preset
    /// and gyro bias prior as a session's device name does (docs/odometry.md, "IMU noise").
    pub device: Option<String>,
}

/// One sensor's placement.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// Rotation sensor to body, unit quaternion (w, x, y, z).
    pub rotation_wxyz: [f64; 4],
    /// Sensor origin in the body frame \[m\].
    pub translation_m: [f64; 3],
}

/// `[extrinsics]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtrinsicsSection {
    /// Radar in the body frame.
    pub radar: Option<Placement>,
    /// IMU in the body frame.
    pub imu: Option<Placement>,
}

/// `[sync]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyncSection {
    /// A stream is missing after this many of its periods without data.
    pub stall_periods: Option<f64>,
    /// Longest an IMU sample waits for a radar frame due before it \[s\].
    pub max_hold_s: Option<f64>,
    /// Clock-fit window \[pairs\].
    pub clock_window: Option<usize>,
    /// Stamps later than the clock envelope by more than this are rejected \[s\].
    pub late_s: Option<f64>,
}

/// `[queues]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QueueSection {
    /// Radar frames between the reader and the synchroniser.
    pub radar: Option<usize>,
    /// IMU samples between the reader and the synchroniser.
    pub imu: Option<usize>,
    /// Synchronised events before the estimator.
    pub events: Option<usize>,
    /// Poses before the output.
    pub poses: Option<usize>,
}

/// A configuration file that cannot be used.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError(pub String);

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ConfigError {}

impl FileConfig {
    /// Parses and validates `text` (`name` is used in messages).
    pub fn parse(text: &str, name: &str) -> Result<FileConfig, ConfigError> {
        let c: FileConfig =
            toml::from_str(text).map_err(|e| ConfigError(format!("{name}: {e}")))?;
        c.validate()
            .map_err(|e| ConfigError(format!("{name}: {e}")))?;
        Ok(c)
    }

    /// Reads, parses and validates a file.
    pub fn load(path: &Path) -> Result<FileConfig, ConfigError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ConfigError(format!("{}: {e}", path.display())))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// The outputs, parsed.
    pub fn outputs(&self) -> Result<Vec<OutputSpec>, ConfigError> {
        self.out
            .iter()
            .map(|o| o.parse().map_err(ConfigError))
            .collect()
    }

    fn validate(&self) -> Result<(), String> {
        self.outputs().map_err(|e| format!("out: {e}"))?;
        if let Some(w) = &self.imu.wrap {
            if w != "pow32" && w != "day" {
                return Err(format!("imu.wrap: {w:?} is neither \"pow32\" nor \"day\""));
            }
        }
        for (name, b) in [("radar.baud", self.radar.baud), ("imu.baud", self.imu.baud)] {
            if b == Some(0) {
                return Err(format!("{name}: must be positive"));
            }
        }
        for (name, p) in [
            ("extrinsics.radar", &self.extrinsics.radar),
            ("extrinsics.imu", &self.extrinsics.imu),
        ] {
            if let Some(p) = p {
                let n = p.rotation_wxyz.iter().map(|v| v * v).sum::<f64>().sqrt();
                if (n - 1.0).abs().is_nan() || (n - 1.0).abs() >= 1e-3 {
                    return Err(format!(
                        "{name}.rotation_wxyz: not a unit quaternion (norm {n})"
                    ));
                }
                if !p.translation_m.iter().all(|v| v.is_finite()) {
                    return Err(format!("{name}.translation_m: not finite"));
                }
            }
        }
        if let Some(n) = self.model_threads {
            if !(1..=64).contains(&n) {
                return Err(format!("model_threads: {n} (1 to 64)"));
            }
        }
        if let Some(s) = self.sync.stall_periods {
            if !(s >= 1.0 && s.is_finite()) {
                return Err(format!("sync.stall_periods: {s} (at least 1)"));
            }
        }
        if let Some(s) = self.sync.max_hold_s {
            if !(s > 0.0 && s <= 5.0) {
                return Err(format!("sync.max_hold_s: {s} (0 to 5 s)"));
            }
        }
        if let Some(s) = self.sync.late_s {
            if !(s > 0.0 && s.is_finite()) {
                return Err(format!("sync.late_s: {s} (positive)"));
            }
        }
        if self
            .sync
            .clock_window
            .is_some_and(|w| !(16..=65536).contains(&w))
        {
            return Err("sync.clock_window: 16 to 65536 pairs".into());
        }
        for (name, q) in [
            ("queues.radar", self.queues.radar),
            ("queues.imu", self.queues.imu),
            ("queues.events", self.queues.events),
            ("queues.poses", self.queues.poses),
        ] {
            if q.is_some_and(|q| !(1..=1_000_000).contains(&q)) {
                return Err(format!("{name}: 1 to 1000000"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_file_parses() {
        let text = include_str!("../example.toml");
        let c = FileConfig::parse(text, "example.toml").unwrap();
        assert_eq!(c.estimator, Some(EstimatorKind::Auto));
        assert_eq!(c.outputs().unwrap().len(), 2);
        assert!(c.extrinsics.radar.is_some());
        assert_eq!(c.queues.radar, Some(8));
        assert_eq!(c.model_threads, Some(1));
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        let e = FileConfig::parse("estimatr = \"doppler\"", "x.toml").unwrap_err();
        assert!(
            e.0.contains("unknown field") && e.0.contains("estimatr"),
            "{e}"
        );
        let e = FileConfig::parse("estimator = \"kalman\"", "x.toml").unwrap_err();
        assert!(e.0.contains("unknown variant"), "{e}");
        let e = FileConfig::parse("out = [\"udp://nohost\"]", "x.toml").unwrap_err();
        assert!(e.0.contains("udp://HOST:PORT"), "{e}");
        let e = FileConfig::parse("model_threads = 0", "x.toml").unwrap_err();
        assert!(e.0.contains("model_threads: 0"), "{e}");
        let e = FileConfig::parse("[sync]\nstall_periods = 0.5", "x.toml").unwrap_err();
        assert!(e.0.contains("sync.stall_periods"), "{e}");
        let e = FileConfig::parse(
            "[extrinsics.radar]\nrotation_wxyz = [1, 1, 0, 0]\ntranslation_m = [0, 0, 0]",
            "x.toml",
        )
        .unwrap_err();
        assert!(e.0.contains("unit quaternion"), "{e}");
    }
}
