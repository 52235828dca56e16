//! `session.toml`: what the session holds and how the sensors sit on the body.

use crate::{err, io_err, ErrorKind, SessionError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Value of the `format` key.
pub const FORMAT: &str = "milliego-session";
/// Current format version. Readers accept this version and older ones. Writers write the
/// oldest version that holds what the session uses ([`Meta::required_version`]): 2 only for the
/// `[import]` table, so sessions without it stay readable by version 1 readers.
pub const VERSION: u32 = 2;

/// Where the data came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// Recorded from devices by `milliego record`.
    Recorded,
    /// Written by `milliego sim`.
    Simulated,
    /// Bare captures opened without metadata.
    #[default]
    Imported,
}

/// The radar stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadarMeta {
    /// Data file (raw data-port bytes).
    pub data: String,
    /// Timing index file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<String>,
    /// The .cfg the radar ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cfg: Option<String>,
    /// Data port baud rate \[bit/s\].
    #[serde(default = "default_radar_baud")]
    pub baud: u32,
    /// Device (free text, e.g. "IWR6843ISK").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// Port it was recorded from (informational).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub port: Option<String>,
}

fn default_radar_baud() -> u32 {
    921_600
}

impl Default for RadarMeta {
    fn default() -> Self {
        RadarMeta {
            data: "radar.bin".into(),
            index: None,
            cfg: None,
            baud: 921_600,
            device: None,
            port: None,
        }
    }
}

/// The IMU stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuMeta {
    /// Data file (raw Xbus bytes).
    pub data: String,
    /// Timing index file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<String>,
    /// Port baud rate \[bit/s\].
    #[serde(default = "default_imu_baud")]
    pub baud: u32,
    /// Device (free text, e.g. "MTi-3").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// SampleTimeFine wrap: "u32" (MTi-1/600 series, 2^32 ticks) or "day" (10/100 series).
    #[serde(default = "default_wrap")]
    pub sample_time_wrap: String,
    /// Configured inertial output rate \[Hz\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    /// Port it was recorded from (informational).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub port: Option<String>,
}

fn default_imu_baud() -> u32 {
    115_200
}
fn default_wrap() -> String {
    "u32".into()
}

impl ImuMeta {
    /// The SampleTimeFine wrap `sample_time_wrap` names ("day": one day, else 2^32 ticks).
    pub fn time_wrap(&self) -> imu_driver::TimeWrap {
        match self.sample_time_wrap.as_str() {
            "day" => imu_driver::TimeWrap::Day,
            _ => imu_driver::TimeWrap::Pow32,
        }
    }
}

impl Default for ImuMeta {
    fn default() -> Self {
        ImuMeta {
            data: "imu.bin".into(),
            index: None,
            baud: 115_200,
            device: None,
            sample_time_wrap: default_wrap(),
            rate_hz: None,
            port: None,
        }
    }
}

/// Pose of a sensor in the body frame: p_body = R * p_sensor + t.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Extrinsic {
    /// Translation t \[m\].
    pub translation_m: [f64; 3],
    /// Rotation R as a unit quaternion (w, x, y, z).
    pub rotation_wxyz: [f64; 4],
}

impl Default for Extrinsic {
    fn default() -> Self {
        Extrinsic {
            translation_m: [0.0; 3],
            rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

/// Sensor poses in the body frame (the body frame is the one ground truth describes).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Extrinsics {
    /// Radar (x right, y boresight, z up) in the body frame.
    #[serde(default)]
    pub radar: Extrinsic,
    /// IMU sensor frame in the body frame.
    #[serde(default)]
    pub imu: Extrinsic,
}

/// Ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct GroundTruthMeta {
    /// TUM file: body pose in the world frame, time on the session host clock \[s\].
    pub file: String,
}

/// The truth about the sensor clocks (simulated sessions): sensor time = (1 + drift) * host time
/// + offset.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ClockTruth {
    /// Radar clock offset \[s\].
    pub radar_offset_s: f64,
    /// Radar clock drift \[ppm\].
    pub radar_drift_ppm: f64,
    /// IMU clock offset \[s\].
    pub imu_offset_s: f64,
    /// IMU clock drift \[ppm\].
    pub imu_drift_ppm: f64,
}

/// The whole `session.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Meta {
    /// Always [`FORMAT`].
    pub format: String,
    /// Format version ([`VERSION`]).
    pub version: u32,
    /// Where the data came from.
    #[serde(default)]
    pub source: Source,
    /// Free-text description (scenario, seed, operator notes).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// Radar stream.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radar: Option<RadarMeta>,
    /// IMU stream.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imu: Option<ImuMeta>,
    /// Sensor poses on the body.
    #[serde(default)]
    pub extrinsics: Extrinsics,
    /// Ground truth.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub groundtruth: Option<GroundTruthMeta>,
    /// Clock truth (simulated sessions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clock: Option<ClockTruth>,
    /// Where an imported session's data came from and how it was timed (version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub import: Option<ImportMeta>,
}

/// The provenance of an imported session (`[import]`, version 2): the recordings, and per
/// stream the topic, how its samples were timed and what was dropped. Readers need none of it to
/// decode the session; it is there so a user can see what the import decided.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ImportMeta {
    /// The tool and its version (`milliego import 0.1.0`).
    pub tool: String,
    /// The recordings read, as given.
    pub sources: Vec<String>,
    /// Recording time of the session's host-clock zero \[ns, the recording's clock\].
    pub time_origin_ns: i64,
    /// Per stream (`radar`, `imu`, `pressure`, `groundtruth`, `trigger`).
    #[serde(default)]
    pub streams: Vec<ImportedStream>,
}

/// One imported stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ImportedStream {
    /// `radar`, `imu`, `pressure`, `groundtruth` or `trigger`.
    pub stream: String,
    /// Topic (or CSV file).
    pub topic: String,
    /// Message type.
    pub msg_type: String,
    /// How the samples were timed, in words (e.g. `trigger /radar/trigger, by sequence number`).
    pub timing: String,
    /// Messages read.
    pub messages: u64,
    /// Samples written to the session.
    pub written: u64,
    /// Messages or points dropped, by reason.
    #[serde(default)]
    pub dropped: std::collections::BTreeMap<String, u64>,
    /// Anything else the import decided (field names used, axis conversion).
    #[serde(default)]
    pub notes: Vec<String>,
}

impl Meta {
    /// Metadata of a new session from `source`.
    pub fn new(source: Source) -> Meta {
        Meta {
            format: FORMAT.into(),
            version: VERSION,
            source,
            description: String::new(),
            radar: None,
            imu: None,
            extrinsics: Extrinsics::default(),
            groundtruth: None,
            clock: None,
            import: None,
        }
    }

    /// Defaults for bare captures.
    pub fn imported() -> Meta {
        Meta::new(Source::Imported)
    }

    /// Reads and checks `session.toml`.
    pub fn read(path: &Path) -> Result<Meta, SessionError> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        let meta: Meta =
            toml::from_str(&text).map_err(|e| err(path, ErrorKind::Meta(e.to_string())))?;
        if meta.format != FORMAT {
            return Err(err(
                path,
                ErrorKind::Meta(format!("format is {:?}, expected {FORMAT:?}", meta.format)),
            ));
        }
        if meta.version > VERSION {
            return Err(err(
                path,
                ErrorKind::Meta(format!(
                    "format version {} is newer than this reader ({VERSION})",
                    meta.version
                )),
            ));
        }
        Ok(meta)
    }

    /// The oldest format version that holds this metadata: 2 with an `[import]` table, else 1.
    pub fn required_version(&self) -> u32 {
        if self.import.is_some() {
            2
        } else {
            1
        }
    }

    /// Writes `session.toml`, as the oldest version that holds it ([`Meta::required_version`]).
    pub fn write(&self, path: &Path) -> Result<(), SessionError> {
        let mut m = self.clone();
        m.version = self.required_version();
        let text =
            toml::to_string_pretty(&m).map_err(|e| err(path, ErrorKind::Meta(e.to_string())))?;
        std::fs::write(path, text).map_err(io_err(path))
    }
}
