//! Calibration of an imported rig: where the radar and the IMU sit on the body, the radar's
//! exposure time, and (optionally) the frame ids the messages must carry.
//!
//! Two file forms:
//! - rio / ekf_rio YAML: `l_b_r_x/y/z` (radar position in the body frame \[m\]), `q_b_r_x/y/z/w`
//!   (rotation radar -> body, Hamilton), `radar_frame_ms` (exposure of one scan \[ms\]); the radar
//!   frame is ROS's (x forward). Other keys are ignored.
//! - TOML (`.toml`): `[radar]` and `[imu]` tables with `translation_m`, `rotation_wxyz`, optional
//!   `frame_id`; `[radar]` also `axes = "ros" | "session"` (default `ros`) and `frame_ms`.
//!
//! Either way the result is in the session's convention: `p_body = R p_sensor + t` with the
//! radar in TI axes (x right, y boresight, z up).

use milliego_session::Extrinsic;
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion};
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};

/// A rig's calibration, in the session's conventions.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Calibration {
    /// Body <- radar (TI axes).
    pub radar: Extrinsic,
    /// Body <- IMU.
    pub imu: Extrinsic,
    /// Exposure of one radar scan \[s\]; a scan's time is its middle.
    pub radar_frame_s: Option<f64>,
    /// The frame id radar messages must carry (when set).
    pub radar_frame_id: Option<String>,
    /// The frame id IMU messages must carry (when set).
    pub imu_frame_id: Option<String>,
}

/// Why a calibration file cannot be used.
#[derive(Debug)]
pub struct CalibError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line, when the problem is on one.
    pub line: Option<usize>,
    /// What is wrong.
    pub why: String,
}

impl fmt::Display for CalibError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "calibration {}:{l}: {}", self.path.display(), self.why),
            None => write!(f, "calibration {}: {}", self.path.display(), self.why),
        }
    }
}

impl std::error::Error for CalibError {}

/// TI axes in ROS radar axes: `p_ti = M p_ros`.
fn ros_to_ti() -> Matrix3<f64> {
    Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
}

/// Body <- radar(ROS axes) as `(t, q_xyzw)` -> body <- radar(TI axes).
pub fn radar_from_ros(t: [f64; 3], q_wxyz: [f64; 4]) -> Extrinsic {
    let q = UnitQuaternion::from_quaternion(Quaternion::new(
        q_wxyz[0], q_wxyz[1], q_wxyz[2], q_wxyz[3],
    ));
    // p_body = R p_ros + t, p_ros = M^T p_ti.
    let r = q.to_rotation_matrix().into_inner() * ros_to_ti().transpose();
    let q_ti = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Extrinsic {
        translation_m: t,
        rotation_wxyz: [q_ti.w, q_ti.i, q_ti.j, q_ti.k],
    }
}

impl Calibration {
    /// Reads a YAML (rio) or TOML calibration, by extension (`.toml` is TOML, anything else YAML).
    pub fn load(path: &Path) -> Result<Calibration, CalibError> {
        let text = std::fs::read_to_string(path).map_err(|e| CalibError {
            path: path.into(),
            line: None,
            why: e.to_string(),
        })?;
        if path.extension().is_some_and(|e| e == "toml") {
            Calibration::from_toml(&text, path)
        } else {
            Calibration::from_rio_yaml(&text, path)
        }
    }

    /// Parses the rio-style YAML (flat `key: value` lines).
    pub fn from_rio_yaml(text: &str, path: &Path) -> Result<Calibration, CalibError> {
        let mut vals = std::collections::BTreeMap::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() || line == "---" {
                continue;
            }
            let Some((k, v)) = line.split_once(':') else {
                return Err(CalibError {
                    path: path.into(),
                    line: Some(i + 1),
                    why: format!("expected `key: value`, got {line:?}"),
                });
            };
            let (k, v) = (k.trim(), v.trim());
            if k.starts_with("l_b_r_") || k.starts_with("q_b_r_") || k == "radar_frame_ms" {
                let x: f64 = v.parse().map_err(|_| CalibError {
                    path: path.into(),
                    line: Some(i + 1),
                    why: format!("{k}: {v:?} is not a number"),
                })?;
                vals.insert(k.to_string(), (x, i + 1));
            }
        }
        let get = |k: &str, default: Option<f64>| -> Result<f64, CalibError> {
            vals.get(k)
                .map(|v| v.0)
                .or(default)
                .ok_or_else(|| CalibError {
                    path: path.into(),
                    line: None,
                    why: format!("missing {k}"),
                })
        };
        let t = [
            get("l_b_r_x", None)?,
            get("l_b_r_y", None)?,
            get("l_b_r_z", None)?,
        ];
        let q = [
            get("q_b_r_w", None)?,
            get("q_b_r_x", None)?,
            get("q_b_r_y", None)?,
            get("q_b_r_z", None)?,
        ];
        check_quat(q, path)?;
        Ok(Calibration {
            radar: radar_from_ros(t, q),
            imu: Extrinsic::default(),
            radar_frame_s: vals.get("radar_frame_ms").map(|v| v.0 * 1e-3),
            radar_frame_id: None,
            imu_frame_id: None,
        })
    }

    /// Parses the TOML form.
    pub fn from_toml(text: &str, path: &Path) -> Result<Calibration, CalibError> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Sensor {
            #[serde(default)]
            translation_m: [f64; 3],
            #[serde(default = "identity")]
            rotation_wxyz: [f64; 4],
            #[serde(default)]
            frame_id: Option<String>,
            #[serde(default)]
            axes: Option<String>,
            #[serde(default)]
            frame_ms: Option<f64>,
        }
        fn identity() -> [f64; 4] {
            [1.0, 0.0, 0.0, 0.0]
        }
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct File {
            radar: Option<Sensor>,
            imu: Option<Sensor>,
        }
        let bad = |why: String| CalibError {
            path: path.into(),
            line: None,
            why,
        };
        let f: File = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
        let mut c = Calibration::default();
        if let Some(r) = f.radar {
            check_quat(r.rotation_wxyz, path)?;
            c.radar = match r.axes.as_deref().unwrap_or("ros") {
                "ros" => radar_from_ros(r.translation_m, r.rotation_wxyz),
                "session" => Extrinsic {
                    translation_m: r.translation_m,
                    rotation_wxyz: r.rotation_wxyz,
                },
                a => {
                    return Err(bad(format!(
                        "radar.axes: {a:?} is neither \"ros\" nor \"session\""
                    )))
                }
            };
            c.radar_frame_s = r.frame_ms.map(|ms| ms * 1e-3);
            c.radar_frame_id = r.frame_id;
        }
        if let Some(i) = f.imu {
            check_quat(i.rotation_wxyz, path)?;
            if i.axes.is_some() || i.frame_ms.is_some() {
                return Err(bad("imu: axes and frame_ms belong to [radar]".into()));
            }
            c.imu = Extrinsic {
                translation_m: i.translation_m,
                rotation_wxyz: i.rotation_wxyz,
            };
            c.imu_frame_id = i.frame_id;
        }
        Ok(c)
    }
}

fn check_quat(q: [f64; 4], path: &Path) -> Result<(), CalibError> {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
        return Err(CalibError {
            path: path.into(),
            line: None,
            why: format!("rotation {q:?} is not a unit quaternion (norm {n})"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn rot(e: &Extrinsic) -> UnitQuaternion<f64> {
        let [w, x, y, z] = e.rotation_wxyz;
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
    }

    #[test]
    fn rio_yaml_identity_mount_maps_boresight_to_body_forward() {
        let text =
            "l_b_r_x: 0.05\nl_b_r_y: 0.0   # left\nl_b_r_z: -0.02\nq_b_r_x: 0.0\nq_b_r_y: 0.0\n\
                    q_b_r_z: 0.0\nq_b_r_w: 1.0\nradar_frame_ms: 18.5\nradar_rate: 10\n";
        let c = Calibration::from_rio_yaml(text, Path::new("rio.yaml")).unwrap();
        assert_eq!(c.radar.translation_m, [0.05, 0.0, -0.02]);
        assert_eq!(c.radar_frame_s, Some(0.0185));
        // TI boresight (y) is ROS x, which the identity mount makes body x.
        let b = rot(&c.radar) * Vector3::new(0.0, 1.0, 0.0);
        assert!((b - Vector3::x()).norm() < 1e-12, "{b}");
        // TI x (right) is ROS -y: body -y.
        let r = rot(&c.radar) * Vector3::new(1.0, 0.0, 0.0);
        assert!((r + Vector3::y()).norm() < 1e-12, "{r}");
    }

    #[test]
    fn errors_name_the_line_or_key() {
        let e = Calibration::from_rio_yaml("l_b_r_x: abc\n", Path::new("c.yaml")).unwrap_err();
        assert_eq!(e.line, Some(1));
        assert!(e.to_string().contains("c.yaml:1"), "{e}");
        let e = Calibration::from_rio_yaml("l_b_r_x: 1\n", Path::new("c.yaml")).unwrap_err();
        assert!(e.to_string().contains("missing l_b_r_y"), "{e}");
        let e = Calibration::from_toml(
            "[radar]\nrotation_wxyz = [2.0, 0.0, 0.0, 0.0]\n",
            Path::new("c.toml"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("unit quaternion"), "{e}");
    }

    #[test]
    fn toml_session_axes_are_kept_and_frame_ids_read() {
        let c = Calibration::from_toml(
            "[radar]\naxes = \"session\"\ntranslation_m = [0.0, 0.1, 0.0]\nframe_id = \"radar_link\"\nframe_ms = 20\n\
             [imu]\nframe_id = \"imu_link\"\n",
            Path::new("c.toml"),
        )
        .unwrap();
        assert_eq!(c.radar.rotation_wxyz, [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(c.radar.translation_m, [0.0, 0.1, 0.0]);
        assert_eq!(c.radar_frame_id.as_deref(), Some("radar_link"));
        assert_eq!(c.imu_frame_id.as_deref(), Some("imu_link"));
        assert_eq!(c.radar_frame_s, Some(0.02));
    }
}
