//! A session (radar, IMU, ground truth, extrinsics) and any number of estimated trajectories
//! written as one MCAP file with ROS 2 channels: `ros2msg` schemas, CDR messages, the `ros2`
//! profile and `offered_qos_profiles` channel metadata, so Foxglove opens it and the rosbag2 MCAP
//! storage plugin plays it. Messages are written in log-time order into chunks (zstd or none),
//! followed by a summary section with chunk and message indexes.

use crate::msg::{
    Header, Imu, Odometry, PointCloud2, Pose, PoseStamped, RosMessage, TfMessage, TransformStamped,
};
use crate::CdrError;
use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions};
use milliego_session::streams::{imu_samples, radar_frames, SessionClock, StreamReport};
use milliego_session::{Extrinsic, Session, SessionError, TumPose};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Topic of the radar point clouds.
pub const RADAR_TOPIC: &str = "/radar/points";
/// The `radar_axes` value of the `milliego` metadata record: `/radar/points` are in the
/// session's (TI's) radar axes, x right, y boresight, z up.
pub const RADAR_AXES: &str = "ti";
/// Topic of the IMU samples.
pub const IMU_TOPIC: &str = "/imu/data";
/// Topic of the sensor extrinsics.
pub const TF_STATIC_TOPIC: &str = "/tf_static";
/// Name of the ground-truth trajectory (`/groundtruth/pose`, `/groundtruth/odom`).
pub const GROUNDTRUTH: &str = "groundtruth";
/// Point fields of `/radar/points`, FLOAT32 each: position \[m\], radial velocity \[m/s\], SNR
/// \[dB\] (NaN when the frame has no side info).
pub const POINT_FIELDS: &[&str] = &["x", "y", "z", "velocity", "snr"];

/// Export settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExportOptions {
    /// zstd-compress the chunks (else store them uncompressed).
    pub compress: bool,
    /// Target uncompressed chunk size \[B\].
    pub chunk_size: u64,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            compress: true,
            chunk_size: 1 << 20,
        }
    }
}

/// An estimated trajectory to export: body poses in its own world frame, time on the session host
/// clock \[s\] (what `milliego odometry` writes).
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Topic prefix: `/<name>/pose`, `/<name>/odom`; letters, digits and `_`, not starting with a
    /// digit (see [`topic_name`]).
    pub name: String,
    /// The poses.
    pub poses: Vec<TumPose>,
}

/// Messages and payload bytes written on one topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicSummary {
    /// Topic.
    pub topic: String,
    /// ROS 2 type, e.g. `sensor_msgs/msg/Imu`.
    pub ros_type: &'static str,
    /// Messages written.
    pub messages: u64,
    /// CDR payload bytes written (uncompressed) \[B\].
    pub bytes: u64,
}

/// What an export wrote and what it could not place in time.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportSummary {
    /// Output file.
    pub path: PathBuf,
    /// File size \[B\].
    pub file_bytes: u64,
    /// Per topic, in channel order.
    pub topics: Vec<TopicSummary>,
    /// Radar stream decoding.
    pub radar: StreamReport,
    /// IMU stream decoding.
    pub imu: StreamReport,
    /// Radar frames with neither a host stamp nor a sensor time: not exported.
    pub radar_untimed: u64,
    /// True when the session had no timing index for a stream: its sensor clock was then taken
    /// to start at host time 0.
    pub clock_unsynced: bool,
    /// Added to every session time so that no log time is negative \[ns\] (0 unless some frame
    /// was measured before the session started).
    pub time_offset_ns: u64,
    /// First and last log time \[ns\], if anything was written.
    pub log_time_range_ns: Option<(u64, u64)>,
}

impl ExportSummary {
    /// Messages written on all topics.
    pub fn messages(&self) -> u64 {
        self.topics.iter().map(|t| t.messages).sum()
    }
}

/// Why an export failed.
#[derive(Debug)]
pub enum ExportError {
    /// Reading the session failed.
    Session(SessionError),
    /// A trajectory name that cannot be a topic, or one used twice.
    BadName {
        /// The name.
        name: String,
        /// What is wrong.
        what: &'static str,
    },
    /// A trajectory pose without a finite time.
    BadPose {
        /// Trajectory name.
        name: String,
        /// Index of the pose.
        index: usize,
    },
    /// Encoding a message failed.
    Cdr {
        /// Topic.
        topic: String,
        /// Why.
        error: CdrError,
    },
    /// Creating the output file failed.
    Io {
        /// Output file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// Writing the MCAP container failed.
    Mcap {
        /// Output file.
        path: PathBuf,
        /// Why.
        error: mcap::McapError,
    },
}

impl std::fmt::Display for ExportError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ExportError::Session(e) => write!(f, "{e}"),
            ExportError::BadName { name, what } => {
                write!(f, "trajectory name {name:?}: {what}")
            }
            ExportError::BadPose { name, index } => {
                write!(f, "trajectory {name:?}: pose {index} has no finite time")
            }
            ExportError::Cdr { topic, error } => write!(f, "{topic}: {error}"),
            ExportError::Io { path, error } => write!(f, "{}: {error}", path.display()),
            ExportError::Mcap { path, error } => {
                write!(f, "{}: writing MCAP: {error}", path.display())
            }
        }
    }
}

impl std::error::Error for ExportError {}

impl From<SessionError> for ExportError {
    fn from(e: SessionError) -> Self {
        ExportError::Session(e)
    }
}

/// A topic-safe name from a file stem: characters other than ASCII letters, digits and `_`
/// become `_`; a leading digit (or an empty name) gets an `est_` prefix.
pub fn topic_name(stem: &str) -> String {
    let s: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.chars().next().is_none_or(|c| c.is_ascii_digit()) {
        format!("est_{s}")
    } else {
        s
    }
}

/// QoS the recording is offered with, as rosbag2 writes `offered_qos_profiles` (history KEEP_LAST,
/// reliability RELIABLE, durability TRANSIENT_LOCAL for `/tf_static` else VOLATILE, liveliness
/// AUTOMATIC, infinite deadline, lifespan and lease).
fn qos_yaml(latched: bool) -> String {
    let inf = "\n    sec: 2147483647\n    nsec: 4294967295";
    format!(
        "- history: 1\n  depth: {}\n  reliability: 1\n  durability: {}\n  deadline:{inf}\n  lifespan:{inf}\n  liveliness: 1\n  liveliness_lease_duration:{inf}\n  avoid_ros_namespace_conventions: false",
        if latched { 1 } else { 10 },
        if latched { 1 } else { 2 }
    )
}

/// One message waiting to be written: log time \[ns\], channel slot, payload.
struct Pending {
    log_time: u64,
    slot: usize,
    data: Vec<u8>,
}

struct Topics {
    list: Vec<(TopicSummary, String, bool)>,
    pending: Vec<Pending>,
    /// Added to session times so that none is negative \[s\].
    shift_s: f64,
}

impl Topics {
    fn add<M: RosMessage>(&mut self, topic: &str, latched: bool) -> usize {
        self.list.push((
            TopicSummary {
                topic: topic.into(),
                ros_type: M::NAME,
                messages: 0,
                bytes: 0,
            },
            M::schema_text(),
            latched,
        ));
        self.list.len() - 1
    }

    /// Log time of a session time \[ns\].
    fn ns(&self, t_s: f64) -> u64 {
        ns(t_s + self.shift_s)
    }

    /// A header stamped with the log time of session time `t_s` \[s\].
    fn header(&self, t_s: f64, frame_id: &str) -> Header {
        Header {
            stamp_ns: self.ns(t_s),
            frame_id: frame_id.into(),
        }
    }

    fn push<M: RosMessage>(&mut self, slot: usize, t_s: f64, m: &M) -> Result<(), ExportError> {
        let data = m.to_cdr().map_err(|error| ExportError::Cdr {
            topic: self.list[slot].0.topic.clone(),
            error,
        })?;
        self.pending.push(Pending {
            log_time: self.ns(t_s),
            slot,
            data,
        });
        Ok(())
    }
}

fn ns(t_s: f64) -> u64 {
    // Callers shift times to >= 0 first; `as` saturates anything else.
    (t_s * 1e9).round() as u64
}

fn transform(header: Header, e: &Extrinsic, child: &str) -> TransformStamped {
    let [w, x, y, z] = e.rotation_wxyz;
    TransformStamped {
        header,
        child_frame_id: child.into(),
        transform: Pose {
            p: e.translation_m,
            q: [x, y, z, w],
        },
    }
}

type Quat = [f64; 4];

fn q_mul(a: Quat, b: Quat) -> Quat {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]
}

fn q_conj(q: Quat) -> Quat {
    [-q[0], -q[1], -q[2], q[3]]
}

/// `q^-1 * v` for a unit quaternion (world vector into the body frame).
fn rotate_inv(q: Quat, v: [f64; 3]) -> [f64; 3] {
    let r = q_mul(q_mul(q_conj(q), [v[0], v[1], v[2], 0.0]), q);
    [r[0], r[1], r[2]]
}

/// Body-frame twist at pose `i` by differences of its neighbours: (linear \[m/s\], angular
/// \[rad/s\]); zero where the neighbours share a time.
fn twist(poses: &[TumPose], i: usize) -> ([f64; 3], [f64; 3]) {
    let (a, b) = (i.saturating_sub(1), (i + 1).min(poses.len() - 1));
    let (pa, pb) = (&poses[a], &poses[b]);
    let dt = pb.t - pa.t;
    // Also catches a NaN difference.
    if dt.is_nan() || dt <= 0.0 {
        return ([0.0; 3], [0.0; 3]);
    }
    let v = [
        (pb.p[0] - pa.p[0]) / dt,
        (pb.p[1] - pa.p[1]) / dt,
        (pb.p[2] - pa.p[2]) / dt,
    ];
    // Relative rotation in the body frame, shortest way, as a rotation vector.
    let mut d = q_mul(q_conj(pa.q), pb.q);
    if d[3] < 0.0 {
        d = d.map(|x| -x);
    }
    let s = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let angle = 2.0 * s.atan2(d[3]);
    let w = if s > 1e-12 {
        [d[0], d[1], d[2]].map(|x| x / s * angle / dt)
    } else {
        [d[0], d[1], d[2]].map(|x| 2.0 * x / dt)
    };
    (rotate_inv(poses[i].q, v), w)
}

fn push_trajectory(
    topics: &mut Topics,
    name: &str,
    child: &str,
    poses: &[TumPose],
) -> Result<(), ExportError> {
    let pose_slot = topics.add::<PoseStamped>(&format!("/{name}/pose"), false);
    let odom_slot = topics.add::<Odometry>(&format!("/{name}/odom"), false);
    for (i, p) in poses.iter().enumerate() {
        let header = topics.header(p.t, "world");
        let pose = Pose { p: p.p, q: p.q };
        topics.push(
            pose_slot,
            p.t,
            &PoseStamped {
                header: header.clone(),
                pose,
            },
        )?;
        let (linear, angular) = twist(poses, i);
        topics.push(
            odom_slot,
            p.t,
            &Odometry {
                header,
                child_frame_id: child.into(),
                pose,
                linear,
                angular,
            },
        )?;
    }
    Ok(())
}

/// Exports `session` and `estimates` to `out` (created or truncated).
pub fn export(
    session: &Session,
    estimates: &[Trajectory],
    out: &Path,
    opts: &ExportOptions,
) -> Result<ExportSummary, ExportError> {
    for (i, e) in estimates.iter().enumerate() {
        if topic_name(&e.name) != e.name {
            return Err(ExportError::BadName {
                name: e.name.clone(),
                what: "use letters, digits and _ only, not starting with a digit",
            });
        }
        if let Some(k) = e.poses.iter().position(|p| !p.t.is_finite()) {
            return Err(ExportError::BadPose {
                name: e.name.clone(),
                index: k,
            });
        }
        // `/imu/pose` (the demo's imu.tum) does not collide with `/imu/data`; only these do.
        if e.name == GROUNDTRUTH || estimates[..i].iter().any(|o| o.name == e.name) {
            return Err(ExportError::BadName {
                name: e.name.clone(),
                what: "already taken by another topic",
            });
        }
    }
    let (frames, radar_rep) = radar_frames(session)?;
    let (imu, imu_rep) = imu_samples(session)?;
    let clock = SessionClock::fit(session, &frames, &imu)?;
    let groundtruth = session.groundtruth()?;

    // One time base: session host seconds, shifted only if something precedes the session start.
    let radar_times: Vec<Option<f64>> = frames
        .iter()
        .map(|f| clock.radar_s(f).filter(|t| t.is_finite()))
        .collect();
    let t_min = radar_times
        .iter()
        .flatten()
        .copied()
        .chain(imu.iter().map(|s| clock.imu_s(s.sensor_s)))
        .chain(groundtruth.iter().flatten().map(|p| p.t))
        .chain(estimates.iter().flat_map(|e| e.poses.iter().map(|p| p.t)))
        .filter(|t| t.is_finite())
        .fold(f64::INFINITY, f64::min);
    let shift_s = if t_min.is_finite() && t_min < 0.0 {
        -t_min
    } else {
        0.0
    };
    let mut topics = Topics {
        list: Vec::new(),
        pending: Vec::new(),
        shift_s,
    };
    let tf_slot = topics.add::<TfMessage>(TF_STATIC_TOPIC, true);
    // The extrinsics, stamped at the first message.
    let t_first = if t_min.is_finite() { t_min } else { 0.0 };
    let e = &session.meta.extrinsics;
    let tf = TfMessage {
        transforms: vec![
            transform(topics.header(t_first, "body"), &e.radar, "radar"),
            transform(topics.header(t_first, "body"), &e.imu, "imu"),
        ],
    };
    topics.push(tf_slot, t_first, &tf)?;
    let mut radar_untimed = 0;
    if session.radar.is_some() {
        let slot = topics.add::<PointCloud2>(RADAR_TOPIC, false);
        for (f, t) in frames.iter().zip(&radar_times) {
            let Some(t) = *t else {
                radar_untimed += 1;
                continue;
            };
            let snr = f.cloud.snr_db.as_deref();
            let values = f
                .cloud
                .points
                .iter()
                .enumerate()
                .flat_map(|(i, p)| {
                    let s = snr.and_then(|s| s.get(i)).copied().unwrap_or(f32::NAN);
                    [p.x, p.y, p.z, p.velocity, s]
                })
                .collect();
            topics.push(
                slot,
                t,
                &PointCloud2 {
                    header: topics.header(t, "radar"),
                    fields: POINT_FIELDS,
                    values,
                },
            )?;
        }
    }
    if session.imu.is_some() {
        let slot = topics.add::<Imu>(IMU_TOPIC, false);
        for s in &imu {
            let t = clock.imu_s(s.sensor_s);
            topics.push(
                slot,
                t,
                &Imu {
                    header: topics.header(t, "imu"),
                    angular_velocity: s.gyro,
                    linear_acceleration: s.accel,
                },
            )?;
        }
    }
    if let Some(gt) = &groundtruth {
        push_trajectory(&mut topics, GROUNDTRUTH, "body", gt)?;
    }
    for e in estimates {
        push_trajectory(&mut topics, &e.name, &format!("{}/body", e.name), &e.poses)?;
    }

    let mut pending = std::mem::take(&mut topics.pending);
    // Stable: equal times keep the order pushed (the extrinsics first).
    pending.sort_by_key(|p| p.log_time);

    let mcap_err = |error| ExportError::Mcap {
        path: out.to_path_buf(),
        error,
    };
    let file = File::create(out).map_err(|error| ExportError::Io {
        path: out.to_path_buf(),
        error,
    })?;
    let mut w = WriteOptions::new()
        .profile("ros2")
        .library(concat!("milliego-mcap ", env!("CARGO_PKG_VERSION")))
        .compression(opts.compress.then_some(Compression::Zstd))
        .chunk_size(Some(opts.chunk_size))
        .create(BufWriter::new(file))
        .map_err(mcap_err)?;
    let mut ids = Vec::new();
    for (t, schema, latched) in &topics.list {
        let schema_id = w
            .add_schema(t.ros_type, "ros2msg", schema.as_bytes())
            .map_err(mcap_err)?;
        let meta = BTreeMap::from([("offered_qos_profiles".to_string(), qos_yaml(*latched))]);
        ids.push(
            w.add_channel(schema_id, &t.topic, "cdr", &meta)
                .map_err(mcap_err)?,
        );
    }
    let mut range = None;
    for p in pending {
        let stamp = p.log_time;
        let (summary, _, _) = &mut topics.list[p.slot];
        summary.messages += 1;
        summary.bytes += p.data.len() as u64;
        let header = MessageHeader {
            channel_id: ids[p.slot],
            sequence: u32::try_from(summary.messages).unwrap_or(u32::MAX),
            log_time: stamp,
            publish_time: stamp,
        };
        w.write_to_known_channel(&header, &p.data)
            .map_err(mcap_err)?;
        range = Some(range.map_or((stamp, stamp), |(a, _): (u64, u64)| (a, stamp)));
    }
    let offset_s = format!("{shift_s}");
    let mut ours = BTreeMap::from([
        ("session".into(), session.dir.display().to_string()),
        (
            "time_base".into(),
            "session host clock [s] * 1e9 + time_offset_ns".into(),
        ),
        ("time_offset_ns".into(), ns(shift_s).to_string()),
        ("time_offset_s".into(), offset_s),
        ("clock_unsynced".into(), clock.unsynced().to_string()),
        // /radar/points are in the session's radar axes, not ROS's (milliego import reads this).
        ("radar_axes".into(), RADAR_AXES.into()),
    ]);
    // The parts by name: the filter's IMU noise preset follows the IMU device's.
    let devices = [
        (
            "radar_device",
            session.meta.radar.as_ref().and_then(|r| r.device.clone()),
        ),
        (
            "imu_device",
            session.meta.imu.as_ref().and_then(|i| i.device.clone()),
        ),
    ];
    for (key, device) in devices {
        if let Some(d) = device {
            ours.insert(key.into(), d);
        }
    }
    // The chirp configuration the radar ran: Doppler resolution and exposure for the estimators.
    if let Some(cfg) = session.radar_cfg()? {
        ours.insert("radar_cfg".into(), cfg);
    }
    w.write_metadata(&Metadata {
        name: "milliego".into(),
        metadata: ours,
    })
    .map_err(mcap_err)?;
    w.finish().map_err(mcap_err)?;
    w.into_inner().flush().map_err(|error| ExportError::Io {
        path: out.to_path_buf(),
        error,
    })?;
    let file_bytes = std::fs::metadata(out)
        .map_err(|error| ExportError::Io {
            path: out.to_path_buf(),
            error,
        })?
        .len();
    Ok(ExportSummary {
        path: out.to_path_buf(),
        file_bytes,
        topics: topics.list.into_iter().map(|(t, _, _)| t).collect(),
        radar: radar_rep,
        imu: imu_rep,
        radar_untimed,
        clock_unsynced: clock.unsynced(),
        time_offset_ns: ns(shift_s),
        log_time_range_ns: range,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topic_names_from_file_stems() {
        assert_eq!(topic_name("doppler"), "doppler");
        assert_eq!(topic_name("run-2.final"), "run_2_final");
        assert_eq!(topic_name("2024"), "est_2024");
        assert_eq!(topic_name(""), "est_");
    }

    #[test]
    fn twist_is_in_the_body_frame() {
        // Moving along world +y at 2 m/s while yawed +90 deg: body +x; turning at 0.5 rad/s.
        let pose = |t: f64| {
            let yaw = std::f64::consts::FRAC_PI_2 + 0.5 * t;
            TumPose {
                t,
                p: [0.0, 2.0 * t, 0.0],
                q: [0.0, 0.0, (yaw / 2.0).sin(), (yaw / 2.0).cos()],
            }
        };
        let poses: Vec<TumPose> = (0..3).map(|i| pose(f64::from(i) * 0.01)).collect();
        let (v, w) = twist(&poses, 1);
        // The body turns 0.005 rad from the path by the middle pose: x within 1e-4, y within 2e-2.
        assert!(
            (v[0] - 2.0).abs() < 1e-4 && v[1].abs() < 2e-2 && v[2].abs() < 1e-12,
            "{v:?}"
        );
        assert!(
            w[0].abs() < 1e-12 && w[1].abs() < 1e-12 && (w[2] - 0.5).abs() < 1e-9,
            "{w:?}"
        );
        // Ends use one-sided differences; a lone pose or equal times give zero.
        assert_eq!(twist(&poses[..1], 0), ([0.0; 3], [0.0; 3]));
    }

    #[test]
    fn qos_of_tf_static_is_transient_local() {
        assert!(qos_yaml(true).contains("durability: 1\n"));
        assert!(qos_yaml(false).contains("durability: 2\n"));
        assert!(qos_yaml(false).starts_with("- history: 1\n  depth: 10\n"));
    }
}
