//! Training datasets: sessions -> shards the Python trainer reads (format: `docs/dataset.md`).
//!
//! Each session's streams go through the same [`WindowBuilder`] the runtime uses, in time order
//! on the session clock ([`SessionClock`]), and each window gets its ground-truth label
//! ([`crate::pose`]). One safetensors file per session; `manifest.json` holds the preprocessing
//! settings, the dataset-wide normalisation and what was skipped, with the reason.

use crate::pose::{interpolate, relative, to_label};
use crate::window::{BuilderConfig, Counters, Window, WindowBuilder};
use crate::{Config, Norm, SettingError, IMU_LEN, PANO_H, PANO_W};
use milliego_session::streams::{imu_samples, radar_frames, SessionClock, StreamReport};
use milliego_session::{Session, SessionError};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use safetensors::tensor::{Dtype, TensorView};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Format name in the manifest.
pub const FORMAT: &str = "milliego-dataset";
/// Format version written by this crate.
pub const VERSION: u32 = 1;
/// Largest ground-truth spacing a label may be interpolated across \[s\].
const GT_MAX_GAP_S: f64 = 0.1;

/// Why a dataset could not be built.
#[derive(Debug)]
pub enum DatasetError {
    /// Reading a session failed.
    Session(SessionError),
    /// A session cannot give training windows; names the session and why.
    Unusable {
        /// Session directory.
        session: PathBuf,
        /// What is missing.
        why: String,
    },
    /// Writing the output failed.
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        error: String,
    },
    /// A preprocessing setting this build cannot use.
    Config(SettingError),
    /// No session was given.
    NoSessions,
    /// Every panorama pixel of the dataset has the same value, so it cannot be normalised.
    Flat,
}

impl std::fmt::Display for DatasetError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DatasetError::Session(e) => write!(f, "{e}"),
            DatasetError::Unusable { session, why } => write!(f, "{}: {why}", session.display()),
            DatasetError::Io { path, error } => write!(f, "{}: {error}", path.display()),
            DatasetError::Config(e) => write!(f, "{e}"),
            DatasetError::NoSessions => f.write_str("no sessions given"),
            DatasetError::Flat => f.write_str(
                "every panorama pixel has the same value (no radar returns?): cannot normalise",
            ),
        }
    }
}

impl std::error::Error for DatasetError {}

impl From<SessionError> for DatasetError {
    fn from(e: SessionError) -> Self {
        DatasetError::Session(e)
    }
}

/// One session's training data.
#[derive(Debug, Clone, Default)]
pub struct Shard {
    /// Session name (its directory name).
    pub session: String,
    /// Overlaid panorama per accepted radar frame, F x 16 x 64.
    pub panorama: Vec<f32>,
    /// Radial velocity of each overlaid panorama pixel's point \[m/s\], F x 16 x 64.
    pub doppler: Vec<f32>,
    /// Frame time on the session clock \[s\], F.
    pub frame_time: Vec<f64>,
    /// Ground-truth body pose at each frame, F x 7 (x y z \[m\], qx qy qz qw; NaN where the
    /// ground truth does not reach).
    pub gt_pose: Vec<f64>,
    /// (prev, cur) frame indices per window, W x 2.
    pub pair: Vec<i64>,
    /// IMU window per window, W x 20 x 6.
    pub imu: Vec<f32>,
    /// Label per window, W x 6 (tx ty tz \[m\], roll pitch yaw \[deg\]).
    pub label: Vec<f32>,
    /// What the window builder counted.
    pub counters: Counters,
    /// Radar stream decoding.
    pub radar: StreamReport,
    /// IMU stream decoding.
    pub imu_stream: StreamReport,
    /// Radar frames without a measurement time (no host stamp and no sensor time).
    pub frames_without_time: u64,
    /// Windows dropped because the ground truth did not cover both frames.
    pub no_ground_truth: u64,
}

impl Shard {
    /// Frames.
    pub fn frames(&self) -> usize {
        self.frame_time.len()
    }
    /// Windows.
    pub fn windows(&self) -> usize {
        self.pair.len() / 2
    }
}

/// What [`feed_session`] hands its callback, in time order.
#[derive(Debug)]
pub enum Event<'a> {
    /// A radar frame was accepted: its push sequence number, time \[s\] and overlaid panoramas.
    Frame {
        /// Push sequence number (index among accepted frames).
        seq: u64,
        /// Measurement time on the session clock \[s\].
        t: f64,
        /// Overlaid panorama.
        panorama: &'a [f32; crate::PANO_LEN],
        /// Radial velocity of each of its pixels' point \[m/s\].
        doppler: &'a [f32; crate::PANO_LEN],
    },
    /// A window is ready.
    Window(Window<'a>),
}

/// What feeding a session saw.
#[derive(Debug, Clone, Copy, Default)]
pub struct Fed {
    /// Radar stream decoding.
    pub radar: StreamReport,
    /// IMU stream decoding.
    pub imu: StreamReport,
    /// IMU samples decoded.
    pub imu_samples: usize,
    /// Radar frames without a measurement time.
    pub frames_without_time: u64,
    /// The window builder's counters.
    pub counters: Counters,
}

/// Feeds a session's radar frames and IMU samples through a [`WindowBuilder`] in time order on
/// the session clock (exactly as the runtime receives them, minus the latency), IMU samples
/// rotated into the body frame with the session's extrinsic.
pub fn feed_session(
    session: &Session,
    pre: &Config,
    on: &mut dyn FnMut(Event<'_>),
) -> Result<Fed, DatasetError> {
    pre.validate().map_err(DatasetError::Config)?;
    let unusable = |why: &str| DatasetError::Unusable {
        session: session.dir.clone(),
        why: why.to_string(),
    };
    let (frames, radar) = radar_frames(session)?;
    let (imu, imu_stream) = imu_samples(session)?;
    if frames.is_empty() || imu.is_empty() {
        return Err(unusable("needs both radar frames and IMU samples"));
    }
    let clock = SessionClock::fit(session, &frames, &imu)?;
    let [w, x, y, z] = session.meta.extrinsics.imu.rotation_wxyz;
    let mut builder = WindowBuilder::new(BuilderConfig {
        pre: *pre,
        imu_to_body: UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        ..BuilderConfig::default()
    })
    .map_err(DatasetError::Config)?;
    let mut fed = Fed {
        radar,
        imu: imu_stream,
        imu_samples: imu.len(),
        ..Fed::default()
    };
    let mut timed: Vec<(f64, usize)> = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        match clock.radar_s(f) {
            Some(t) => timed.push((t, i)),
            None => fed.frames_without_time += 1,
        }
    }
    timed.sort_by(|a, b| a.0.total_cmp(&b.0));
    let drain = |b: &mut WindowBuilder, on: &mut dyn FnMut(Event<'_>)| {
        while let Some(win) = b.poll() {
            on(Event::Window(win));
        }
    };
    let mut next_imu = 0;
    let mut seq = 0u64;
    for &(t, i) in &timed {
        while next_imu < imu.len() && clock.imu_s(imu[next_imu].sensor_s) <= t {
            let s = &imu[next_imu];
            builder.push_imu(clock.imu_s(s.sensor_s), s.accel, s.gyro);
            next_imu += 1;
            drain(&mut builder, on);
        }
        let f = &frames[i];
        if let Some((panorama, doppler)) = builder.push_radar(f.frame_number, t, &f.cloud.points) {
            on(Event::Frame {
                seq,
                t,
                panorama,
                doppler,
            });
            seq += 1;
        }
        drain(&mut builder, on);
    }
    for s in &imu[next_imu..] {
        builder.push_imu(clock.imu_s(s.sensor_s), s.accel, s.gyro);
        drain(&mut builder, on);
    }
    builder.finish();
    fed.counters = *builder.counters();
    Ok(fed)
}

/// Builds one session's shard.
pub fn shard_from_session(session: &Session, pre: &Config) -> Result<Shard, DatasetError> {
    let gt = session
        .groundtruth()?
        .ok_or_else(|| DatasetError::Unusable {
            session: session.dir.clone(),
            why: "no ground truth: a training dataset needs labels".into(),
        })?;
    let mut shard = Shard {
        session: session.dir.file_name().map_or_else(
            || session.dir.display().to_string(),
            |n| n.to_string_lossy().into(),
        ),
        ..Shard::default()
    };
    let fed = feed_session(session, pre, &mut |ev| match ev {
        Event::Frame {
            t,
            panorama,
            doppler,
            ..
        } => {
            shard.panorama.extend_from_slice(panorama);
            shard.doppler.extend_from_slice(doppler);
            shard.frame_time.push(t);
            match interpolate(&gt, t, GT_MAX_GAP_S) {
                Some(p) => {
                    let q = p.rotation.quaternion();
                    let v = p.translation.vector;
                    shard.gt_pose.extend([v.x, v.y, v.z, q.i, q.j, q.k, q.w]);
                }
                None => shard.gt_pose.extend([f64::NAN; 7]),
            }
        }
        Event::Window(win) => {
            let gi = |seq: u64| &shard.gt_pose[seq as usize * 7..seq as usize * 7 + 7];
            let (a, c) = (gi(win.prev_seq), gi(win.cur_seq));
            if a[0].is_nan() || c[0].is_nan() {
                shard.no_ground_truth += 1;
                return;
            }
            let iso = |p: &[f64]| {
                Isometry3::from_parts(
                    Translation3::new(p[0], p[1], p[2]),
                    UnitQuaternion::from_quaternion(Quaternion::new(p[6], p[3], p[4], p[5])),
                )
            };
            let label = to_label(&relative(&iso(a), &iso(c)));
            shard.pair.extend([win.prev_seq as i64, win.cur_seq as i64]);
            shard.imu.extend(win.imu.iter().flatten());
            shard.label.extend(label.map(|v| v as f32));
        }
    })?;
    shard.radar = fed.radar;
    shard.imu_stream = fed.imu;
    shard.frames_without_time = fed.frames_without_time;
    shard.counters = fed.counters;
    if shard.windows() == 0 {
        return Err(DatasetError::Unusable {
            session: session.dir.clone(),
            why: format!(
                "no training windows ({} frames, {} IMU samples, counters {:?})",
                shard.frames(),
                fed.imu_samples,
                shard.counters
            ),
        });
    }
    Ok(shard)
}

fn le_bytes<T: Copy, const N: usize>(v: &[T], f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    v.iter().flat_map(|x| f(*x)).collect()
}

/// Writes a shard as safetensors.
pub fn write_shard(path: &Path, s: &Shard) -> Result<(), DatasetError> {
    let (f, w) = (s.frames(), s.windows());
    let bufs = [
        (
            "panorama",
            Dtype::F32,
            vec![f, PANO_H, PANO_W],
            le_bytes(&s.panorama, f32::to_le_bytes),
        ),
        (
            "doppler",
            Dtype::F32,
            vec![f, PANO_H, PANO_W],
            le_bytes(&s.doppler, f32::to_le_bytes),
        ),
        (
            "frame_time",
            Dtype::F64,
            vec![f],
            le_bytes(&s.frame_time, f64::to_le_bytes),
        ),
        (
            "gt_pose",
            Dtype::F64,
            vec![f, 7],
            le_bytes(&s.gt_pose, f64::to_le_bytes),
        ),
        (
            "pair",
            Dtype::I64,
            vec![w, 2],
            le_bytes(&s.pair, i64::to_le_bytes),
        ),
        (
            "imu",
            Dtype::F32,
            vec![w, IMU_LEN, 6],
            le_bytes(&s.imu, f32::to_le_bytes),
        ),
        (
            "label",
            Dtype::F32,
            vec![w, 6],
            le_bytes(&s.label, f32::to_le_bytes),
        ),
    ];
    let io = |e: String| DatasetError::Io {
        path: path.to_path_buf(),
        error: e,
    };
    let mut views = Vec::with_capacity(bufs.len());
    for (name, dt, shape, bytes) in &bufs {
        views.push((
            *name,
            TensorView::new(*dt, shape.clone(), bytes).map_err(|e| io(e.to_string()))?,
        ));
    }
    let info = [("session".to_string(), s.session.clone())]
        .into_iter()
        .collect();
    safetensors::serialize_to_file(views, Some(info), path).map_err(|e| io(e.to_string()))
}

/// Running panorama statistics for [`Norm`].
#[derive(Debug, Clone, Copy)]
pub struct NormAccumulator {
    min: f64,
    max: f64,
    sum: f64,
    n: u64,
}

impl Default for NormAccumulator {
    fn default() -> Self {
        NormAccumulator {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            sum: 0.0,
            n: 0,
        }
    }
}

impl NormAccumulator {
    /// Adds panoramas (any number of 16 x 64 blocks).
    pub fn add(&mut self, panoramas: &[f32]) {
        for &v in panoramas {
            let v = f64::from(v);
            self.min = self.min.min(v);
            self.max = self.max.max(v);
            self.sum += v;
        }
        self.n += panoramas.len() as u64;
    }

    /// The normalisation: min, max, and the mean after min-max scaling (x4 nearest upsampling
    /// leaves all three unchanged, so they are computed on the panoramas). None without data or
    /// when every pixel is equal.
    pub fn norm(&self) -> Option<Norm> {
        let n = Norm {
            min: self.min,
            max: self.max,
            mean: (self.sum / self.n as f64 - self.min) / (self.max - self.min),
        };
        (self.n > 0 && n.validate().is_ok()).then_some(n)
    }
}

/// One shard in the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardEntry {
    /// File name inside the dataset directory.
    pub file: String,
    /// Session name.
    pub session: String,
    /// Session directory as given.
    pub source: String,
    /// Frames.
    pub frames: usize,
    /// Windows.
    pub windows: usize,
    /// Skipped, with the reason (the builder's counters and the label check).
    pub skipped: Skipped,
}

/// Why frames, windows or points are not in a shard.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Skipped {
    /// Radar frames the framer rejected.
    pub radar_frames_bad: u64,
    /// IMU messages the framer rejected.
    pub imu_messages_bad: u64,
    /// Radar frames without a time.
    pub frames_without_time: u64,
    /// Radar frames out of order or duplicated.
    pub frames_out_of_order: u64,
    /// Frames without a window: frame n - gap missing.
    pub no_prev_frame: u64,
    /// Frames without a window: IMU did not cover the interval.
    pub imu_not_covered: u64,
    /// Frames without a window: IMU gap inside the interval.
    pub imu_gap: u64,
    /// Windows without ground truth at both frames.
    pub no_ground_truth: u64,
    /// Points outside the field of view.
    pub points_out_of_view: u64,
    /// Points beyond the maximum range.
    pub points_out_of_range: u64,
    /// Points with non-finite coordinates.
    pub points_non_finite: u64,
}

impl Skipped {
    fn of(s: &Shard) -> Skipped {
        let c = &s.counters;
        Skipped {
            radar_frames_bad: s.radar.bad,
            imu_messages_bad: s.imu_stream.bad,
            frames_without_time: s.frames_without_time,
            frames_out_of_order: c.frames_out_of_order,
            no_prev_frame: c.no_prev_frame,
            imu_not_covered: c.imu_not_covered,
            imu_gap: c.imu_gap,
            no_ground_truth: s.no_ground_truth,
            points_out_of_view: c.points.out_of_view,
            points_out_of_range: c.points.out_of_range,
            points_non_finite: c.points.non_finite,
        }
    }
}

/// `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// Format version.
    pub version: u32,
    /// Preprocessing settings.
    pub preprocess: Config,
    /// Dataset-wide normalisation.
    pub norm: Norm,
    /// Label conventions, in words.
    pub label: String,
    /// Shards.
    pub shards: Vec<ShardEntry>,
    /// Total frames.
    pub frames: usize,
    /// Total windows.
    pub windows: usize,
}

/// Label conventions written into manifests and model metadata.
pub const LABEL_CONVENTION: &str = "relative body pose prev->cur in the prev body frame: \
    tx ty tz [m], roll pitch yaw [deg], R = Rz(yaw) Ry(pitch) Rx(roll)";

/// Progress of [`build`].
#[derive(Debug, Clone, Copy)]
pub enum Progress<'a> {
    /// Starting a session (index, total, directory).
    Start(usize, usize, &'a Path),
    /// A session's shard written.
    Done(usize, &'a ShardEntry),
}

/// Builds a dataset from `sessions` into `out` (created; existing shard files are overwritten).
pub fn build(
    sessions: &[PathBuf],
    out: &Path,
    pre: &Config,
    progress: &mut dyn FnMut(Progress<'_>),
) -> Result<Manifest, DatasetError> {
    pre.validate().map_err(DatasetError::Config)?;
    if sessions.is_empty() {
        return Err(DatasetError::NoSessions);
    }
    std::fs::create_dir_all(out).map_err(|e| DatasetError::Io {
        path: out.to_path_buf(),
        error: e.to_string(),
    })?;
    let mut acc = NormAccumulator::default();
    let mut shards = Vec::new();
    for (i, dir) in sessions.iter().enumerate() {
        progress(Progress::Start(i, sessions.len(), dir));
        let session = Session::open(dir)?;
        let shard = shard_from_session(&session, pre)?;
        acc.add(&shard.panorama);
        let file = format!("shard-{i:04}.safetensors");
        write_shard(&out.join(&file), &shard)?;
        let entry = ShardEntry {
            file,
            session: shard.session.clone(),
            source: dir.display().to_string(),
            frames: shard.frames(),
            windows: shard.windows(),
            skipped: Skipped::of(&shard),
        };
        progress(Progress::Done(i, &entry));
        shards.push(entry);
    }
    let norm = acc.norm().ok_or(DatasetError::Flat)?;
    let manifest = Manifest {
        format: FORMAT.into(),
        version: VERSION,
        preprocess: *pre,
        norm,
        label: LABEL_CONVENTION.into(),
        frames: shards.iter().map(|s| s.frames).sum(),
        windows: shards.iter().map(|s| s.windows).sum(),
        shards,
    };
    let path = out.join("manifest.json");
    let text = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
    std::fs::write(&path, text + "\n").map_err(|e| DatasetError::Io {
        path,
        error: e.to_string(),
    })?;
    Ok(manifest)
}

/// Reads a dataset manifest, checking format and version.
pub fn read_manifest(dir: &Path) -> Result<Manifest, DatasetError> {
    let path = dir.join("manifest.json");
    let io = |e: String| DatasetError::Io {
        path: path.clone(),
        error: e,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| io(e.to_string()))?;
    let m: Manifest = serde_json::from_str(&text).map_err(|e| io(e.to_string()))?;
    if m.format != FORMAT || m.version != VERSION {
        return Err(io(format!(
            "format {} version {}, this build reads {FORMAT} version {VERSION}",
            m.format, m.version
        )));
    }
    Ok(m)
}
