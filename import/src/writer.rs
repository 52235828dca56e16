//! The import itself: choose the topics, time every sample, and write the session.
//!
//! Two passes over the recordings. The first reads the headers of every chosen topic and the
//! small topics whole (trigger, ground truth): it fixes each radar scan's time (trigger by
//! sequence number, else a non-zero header stamp, else the arrival time, each said in the
//! session's `[import]` table), the time origin and the UART rates. The second streams the radar,
//! IMU and pressure messages into the session's wire-format files ([`crate::wire`]), through a
//! short reordering window, so memory stays bounded by one container chunk and the window.

use crate::calib::Calibration;
use crate::cloud::{PointLayout, RadarAxes};
use crate::ros::{
    FluidPressure, Header, Imu, Odometry, PointCloud2, PointField, PoseStamped, Reader, RosMsg,
    TfMessage, TransformStamped,
};
use crate::source::{self, RawMessage, TopicInfo};
use crate::tf::StaticTf;
use crate::wire;
use crate::ImportError;
use milliego_session::{
    ImportMeta, ImportedStream, ImuMeta, Meta, RadarMeta, SessionWriter, StreamKind, TumPose,
};
use std::collections::{BTreeMap, BinaryHeap};
use std::path::{Path, PathBuf};

/// What to import and how.
#[derive(Debug, Clone, Default)]
pub struct ImportOptions {
    /// Radar topic (`sensor_msgs/PointCloud2`); found by type when `None`.
    pub radar_topic: Option<String>,
    /// IMU topic (`sensor_msgs/Imu`).
    pub imu_topic: Option<String>,
    /// Trigger topic (`std_msgs/Header`, scan k <-> trigger k); a Header topic named `*trigger*`
    /// is used when `None`.
    pub trigger_topic: Option<String>,
    /// Barometer topic (`sensor_msgs/FluidPressure`).
    pub baro_topic: Option<String>,
    /// Ground-truth topic (`PoseStamped`, `Odometry`, `TransformStamped` or `TFMessage`).
    pub gt_topic: Option<String>,
    /// For `TFMessage` / `TransformStamped` ground truth: the body's child frame.
    pub gt_child_frame: Option<String>,
    /// The rig's calibration (extrinsics, radar exposure, frame ids).
    pub calib: Option<Calibration>,
    /// The axes of the scans' points (default ROS: x forward).
    pub radar_axes: Option<RadarAxes>,
    /// The Doppler field's name when it is none of [`crate::cloud::DOPPLER_NAMES`].
    pub doppler_field: Option<String>,
    /// Seconds to skip from the start.
    pub start_s: f64,
    /// Seconds to import (all when `None`).
    pub duration_s: Option<f64>,
    /// The chirp configuration the radar ran (`.cfg` text): stored with the session, so the
    /// estimators get its Doppler resolution and frame period; its active frame time is the
    /// exposure when the calibration gives none.
    pub radar_cfg: Option<String>,
    /// The radar's and the IMU's part names for the session (`[radar] device`, `[imu] device`):
    /// a recording names neither, and the IMU's name picks the filter's noise preset and gyro
    /// bias prior (docs/odometry.md, "IMU noise"). `None`: the name in an export's `milliego`
    /// metadata, else "imported from TOPIC".
    pub radar_device: Option<String>,
    /// See `radar_device`.
    pub imu_device: Option<String>,
    /// Session description.
    pub description: String,
}

/// What an import did: per stream, what was read, written and dropped, and how it was timed.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportReport {
    /// The session directory.
    pub session: PathBuf,
    /// Per stream.
    pub streams: Vec<ImportedStream>,
}

/// The topics of every recording, merged by name (counts added, spans joined).
pub fn list(sources: &[PathBuf]) -> Result<Vec<TopicInfo>, ImportError> {
    let mut all: BTreeMap<String, TopicInfo> = BTreeMap::new();
    for p in sources {
        for t in source::open(p)?.topics()? {
            all.entry(t.topic.clone())
                .and_modify(|a| {
                    a.count += t.count;
                    a.span_ns = match (a.span_ns, t.span_ns) {
                        (Some((a0, a1)), Some((b0, b1))) => Some((a0.min(b0), a1.max(b1))),
                        (x, y) => x.or(y),
                    };
                })
                .or_insert(t);
        }
    }
    Ok(all.into_values().collect())
}

/// The streams an import reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Radar,
    Imu,
    Pressure,
    Trigger,
    Truth,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Radar => "radar",
            Kind::Imu => "imu",
            Kind::Pressure => "pressure",
            Kind::Trigger => "trigger",
            Kind::Truth => "groundtruth",
        }
    }
}

const GT_TYPES: &[&str] = &[
    PoseStamped::TYPE,
    Odometry::TYPE,
    TransformStamped::TYPE,
    TfMessage::TYPE,
    "tf/tfMessage",
];

/// Picks the topic of `kind`: the one named, else the only one of its type, else the one whose
/// name says what it is.
fn choose(
    kind: Kind,
    named: Option<&str>,
    topics: &[TopicInfo],
) -> Result<Option<TopicInfo>, ImportError> {
    let types: &[&str] = match kind {
        Kind::Radar => &[PointCloud2::TYPE],
        Kind::Imu => &[Imu::TYPE],
        Kind::Pressure => &[FluidPressure::TYPE],
        Kind::Trigger => &[Header::TYPE],
        Kind::Truth => GT_TYPES,
    };
    let available = || {
        topics
            .iter()
            .map(|t| format!("{} ({})", t.topic, t.msg_type))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(n) = named {
        let t = topics
            .iter()
            .find(|t| t.topic == n)
            .ok_or_else(|| ImportError::Topic {
                stream: kind.name(),
                why: format!(
                    "topic {n} is not in the recording (topics: {})",
                    available()
                ),
            })?;
        if !types.contains(&t.msg_type.as_str()) {
            return Err(ImportError::Topic {
                stream: kind.name(),
                why: format!(
                    "topic {n} is {}, expected {}",
                    t.msg_type,
                    types.join(" or ")
                ),
            });
        }
        return Ok(Some(t.clone()));
    }
    let cands: Vec<&TopicInfo> = topics
        .iter()
        .filter(|t| types.contains(&t.msg_type.as_str()) && t.count > 0)
        .collect();
    let hints: &[&str] = match kind {
        Kind::Radar => &["radar", "mmwave", "ti_"],
        Kind::Imu => &["imu"],
        Kind::Pressure => &["press", "baro"],
        Kind::Trigger => &["trigger"],
        Kind::Truth => &[
            "groundtruth",
            "ground_truth",
            "gt",
            "vicon",
            "mocap",
            "optitrack",
            "truth",
        ],
    };
    let mut hinted: Vec<&&TopicInfo> = cands
        .iter()
        .filter(|t| {
            hints
                .iter()
                .any(|h| t.topic.to_ascii_lowercase().contains(h))
        })
        .collect();
    // Several telling names of different types (`/groundtruth/pose` and `/groundtruth/odom`
    // carry the same poses): the type listed first wins.
    if let Some(best) = hinted
        .iter()
        .filter_map(|t| types.iter().position(|ty| *ty == t.msg_type))
        .min()
    {
        hinted.retain(|t| t.msg_type == types[best]);
    }
    // Header and TF topics are too generic to take without a telling name.
    let generic = matches!(kind, Kind::Trigger | Kind::Truth);
    match (cands.len(), hinted.len()) {
        (0, _) => Ok(None),
        (_, 1) => Ok(Some((*hinted[0]).clone())),
        (1, 0) if !generic => Ok(Some(cands[0].clone())),
        (_, 0) if generic => Ok(None),
        _ => Err(ImportError::Topic {
            stream: kind.name(),
            why: format!(
                "several candidates ({}); name one with --{}-topic",
                cands
                    .iter()
                    .map(|t| t.topic.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                match kind {
                    Kind::Truth => "gt",
                    Kind::Pressure => "baro",
                    k => k.name(),
                }
            ),
        }),
    }
}

/// What the first pass learns of one radar scan.
#[derive(Debug, Clone, Copy)]
struct ScanHead {
    seq: Option<u32>,
    stamp_ns: i64,
    log_ns: i64,
    bytes: usize,
}

/// Per stream, during both passes.
#[derive(Debug, Default)]
struct Tally {
    topic: String,
    msg_type: String,
    timing: String,
    messages: u64,
    written: u64,
    dropped: BTreeMap<String, u64>,
    notes: Vec<String>,
    zero_stamps: u64,
    first_ns: Option<i64>,
    last_ns: Option<i64>,
}

impl Tally {
    fn drop(&mut self, why: &str) {
        self.drop_n(why, 1);
    }
    /// Drops one message for `why`; the first of each reason is named in the notes.
    fn drop_at(&mut self, why: &str, src: &Path, m: &RawMessage<'_>) {
        if !self.dropped.contains_key(why) {
            self.notes
                .push(format!("first dropped ({why}): {}", at(src, m)));
        }
        self.drop(why);
    }
    fn drop_n(&mut self, why: &str, n: u64) {
        if n > 0 {
            *self.dropped.entry(why.into()).or_default() += n;
        }
    }
    fn seen(&mut self, t: i64) {
        self.first_ns = Some(self.first_ns.map_or(t, |f| f.min(t)));
        self.last_ns = Some(self.last_ns.map_or(t, |l| l.max(t)));
    }
    fn into_meta(self, stream: &str) -> ImportedStream {
        ImportedStream {
            stream: stream.into(),
            topic: self.topic,
            msg_type: self.msg_type,
            timing: self.timing,
            messages: self.messages,
            written: self.written,
            dropped: self.dropped,
            notes: self.notes,
        }
    }
}

fn msg_err(src: &Path, m: &RawMessage<'_>, error: crate::ros::MsgError) -> ImportError {
    ImportError::Message {
        at: at(src, m),
        msg_type: m.msg_type.into(),
        error,
    }
}

fn at(src: &Path, m: &RawMessage<'_>) -> Box<crate::At> {
    Box::new(crate::At {
        source: src.into(),
        topic: m.topic.into(),
        index: m.index,
    })
}

/// Reads only the header at the start of a payload (every type this crate imports starts
/// with one).
fn header_of(m: &RawMessage<'_>, src: &Path) -> Result<Header, ImportError> {
    let mut r = Reader::new(m.data, m.encoding).map_err(|e| msg_err(src, m, e))?;
    r.field("header", Header::read)
        .map_err(|e| msg_err(src, m, e))
}

fn decode<M: RosMsg>(m: &RawMessage<'_>, src: &Path) -> Result<M, ImportError> {
    M::decode(m.data, m.encoding).map_err(|e| msg_err(src, m, e))
}

/// A stamp, or the arrival time when the publisher left it at zero.
fn stamp_or_log(h: &Header, m: &RawMessage<'_>) -> i64 {
    if h.stamp_ns != 0 {
        h.stamp_ns
    } else {
        m.log_time_ns as i64
    }
}

/// Checks a message's frame id against the calibration's (when it names one).
fn check_frame(
    want: Option<&String>,
    h: &Header,
    m: &RawMessage<'_>,
    src: &Path,
) -> Result<(), ImportError> {
    match want {
        Some(w) if !h.frame_id.is_empty() && &h.frame_id != w => Err(ImportError::Frame {
            at: at(src, m),
            frame_id: h.frame_id.clone(),
            expected: w.clone(),
        }),
        _ => Ok(()),
    }
}

/// A ground-truth pose: stamp \[ns\], position \[m\], orientation `[x, y, z, w]`.
type TruthPose = (i64, [f64; 3], [f64; 4]);

/// The first pass's findings.
#[derive(Debug, Default)]
struct Survey {
    scans: Vec<ScanHead>,
    triggers: Vec<(Option<u32>, i64)>,
    truth: Vec<TruthPose>,
    tallies: BTreeMap<Kind, Tally>,
    imu_bytes: usize,
    /// `/tf_static` (read only without a calibration file).
    static_tf: StaticTf,
    /// The frame ids of the first radar scan, IMU sample and ground-truth child.
    radar_frame: Option<String>,
    imu_frame: Option<String>,
    truth_child: Option<String>,
}

/// The topic whose static transforms give the extrinsics when no calibration file does.
const TF_STATIC: &str = "/tf_static";

fn survey(
    sources: &[PathBuf],
    chosen: &BTreeMap<Kind, TopicInfo>,
    opts: &ImportOptions,
) -> Result<Survey, ImportError> {
    let mut s = Survey::default();
    for (k, t) in chosen {
        s.tallies.insert(
            *k,
            Tally {
                topic: t.topic.clone(),
                msg_type: t.msg_type.clone(),
                ..Tally::default()
            },
        );
    }
    let by_topic: BTreeMap<&str, Kind> =
        chosen.iter().map(|(k, t)| (t.topic.as_str(), *k)).collect();
    let mut names: Vec<&str> = by_topic.keys().copied().collect();
    if opts.calib.is_none() && !by_topic.contains_key(TF_STATIC) {
        names.push(TF_STATIC);
    }
    let calib = opts.calib.clone().unwrap_or_default();
    for p in sources {
        let mut src = source::open(p)?;
        src.for_each(&names, &mut |m| {
            if m.topic == TF_STATIC && opts.calib.is_none() && m.msg_type == TfMessage::TYPE {
                let tf: TfMessage = decode(&m, p)?;
                tf.transforms.iter().for_each(|x| s.static_tf.add(x));
            }
            let Some(&kind) = by_topic.get(m.topic) else {
                return Ok(());
            };
            let tally = s
                .tallies
                .get_mut(&kind)
                .expect("chosen topics have tallies");
            tally.messages += 1;
            match kind {
                Kind::Radar => {
                    let h = header_of(&m, p)?;
                    check_frame(calib.radar_frame_id.as_ref(), &h, &m, p)?;
                    s.radar_frame.get_or_insert_with(|| h.frame_id.clone());
                    tally.zero_stamps += u64::from(h.stamp_ns == 0);
                    s.scans.push(ScanHead {
                        seq: h.seq,
                        stamp_ns: h.stamp_ns,
                        log_ns: m.log_time_ns as i64,
                        bytes: m.data.len(),
                    });
                }
                Kind::Imu | Kind::Pressure => {
                    let h = header_of(&m, p)?;
                    if kind == Kind::Imu {
                        check_frame(calib.imu_frame_id.as_ref(), &h, &m, p)?;
                        s.imu_frame.get_or_insert_with(|| h.frame_id.clone());
                    }
                    tally.zero_stamps += u64::from(h.stamp_ns == 0);
                    tally.seen(stamp_or_log(&h, &m));
                    s.imu_bytes = s.imu_bytes.max(m.data.len());
                }
                Kind::Trigger => {
                    let h: Header = decode(&m, p)?;
                    let seq = h.seq.or(Some(m.index as u32));
                    s.triggers.push((seq, stamp_or_log(&h, &m)));
                }
                Kind::Truth => {
                    if s.truth_child.is_none() {
                        s.truth_child = truth_child(&m, p, opts.gt_child_frame.as_deref())?;
                    }
                    for (t, pos, q) in truth_poses(&m, p, opts.gt_child_frame.as_deref())? {
                        tally.seen(t);
                        s.truth.push((t, pos, q));
                    }
                }
            }
            Ok(())
        })?;
    }
    Ok(s)
}

/// The frame a ground-truth message gives the pose of (the body), when it says.
fn truth_child(
    m: &RawMessage<'_>,
    src: &Path,
    named: Option<&str>,
) -> Result<Option<String>, ImportError> {
    if let Some(n) = named {
        return Ok(Some(n.into()));
    }
    Ok(match m.msg_type {
        t if t == Odometry::TYPE => Some(decode::<Odometry>(m, src)?.child_frame_id),
        t if t == TransformStamped::TYPE => {
            Some(decode::<TransformStamped>(m, src)?.child_frame_id)
        }
        _ => None,
    }
    .filter(|c| !c.is_empty()))
}

/// The body poses in one ground-truth message: `(stamp ns, position, [x, y, z, w])`.
fn truth_poses(
    m: &RawMessage<'_>,
    src: &Path,
    child: Option<&str>,
) -> Result<Vec<TruthPose>, ImportError> {
    let want = |c: &str| child.is_none_or(|w| w == c);
    Ok(match m.msg_type {
        t if t == PoseStamped::TYPE => {
            let p: PoseStamped = decode(m, src)?;
            vec![(
                stamp_or_log(&p.header, m),
                p.pose.position,
                p.pose.orientation,
            )]
        }
        t if t == Odometry::TYPE => {
            let o: Odometry = decode(m, src)?;
            vec![(
                stamp_or_log(&o.header, m),
                o.pose.position,
                o.pose.orientation,
            )]
        }
        t if t == TransformStamped::TYPE => {
            let x: TransformStamped = decode(m, src)?;
            if want(&x.child_frame_id) {
                vec![(stamp_or_log(&x.header, m), x.translation, x.rotation)]
            } else {
                vec![]
            }
        }
        _ => {
            let tf: TfMessage = decode(m, src)?;
            tf.transforms
                .iter()
                .filter(|x| want(&x.child_frame_id))
                .map(|x| (stamp_or_log(&x.header, m), x.translation, x.rotation))
                .collect()
        }
    })
}

/// Times every scan (recording clock \[ns\]; `None` = cannot be timed) and says how.
fn time_scans(s: &Survey, calib: &Calibration, tally: &mut Tally) -> Vec<Option<i64>> {
    let half = calib.radar_frame_s.map_or(0, |f| (f * 0.5e9) as i64);
    if !s.triggers.is_empty() {
        let by_seq =
            s.scans.iter().all(|h| h.seq.is_some()) && s.triggers.iter().all(|t| t.0.is_some());
        let map: BTreeMap<u32, i64> = s.triggers.iter().map(|t| (t.0.unwrap_or(0), t.1)).collect();
        let times: Vec<Option<i64>> = s
            .scans
            .iter()
            .enumerate()
            .map(|(i, h)| {
                let t = if by_seq {
                    h.seq.and_then(|q| map.get(&q).copied())
                } else {
                    s.triggers.get(i).map(|t| t.1)
                };
                t.map(|t| t + half)
            })
            .collect();
        tally.timing = format!(
            "trigger {}, by {}{}",
            "topic",
            if by_seq {
                "sequence number"
            } else {
                "message order"
            },
            if half > 0 {
                format!(
                    ", + half the {:.1} ms exposure",
                    calib.radar_frame_s.unwrap_or(0.0) * 1e3
                )
            } else {
                String::new()
            }
        );
        return times;
    }
    if tally.zero_stamps == 0 && !s.scans.is_empty() {
        tally.timing = "header stamps".into();
        s.scans.iter().map(|h| Some(h.stamp_ns)).collect()
    } else {
        tally.timing = format!(
            "arrival (bag log time): {} of {} header stamps are zero; ti_mmwave_rospkg publishes a \
             scan when the next one starts, so these times are up to a frame late (give \
             --trigger-topic)",
            tally.zero_stamps,
            s.scans.len()
        );
        s.scans.iter().map(|h| Some(h.log_ns)).collect()
    }
}

/// Items waiting to be written in time order (a min-heap on time, then arrival).
struct Reorder {
    heap: BinaryHeap<std::cmp::Reverse<(i64, u64, Vec<u8>)>>,
    next: u64,
    /// Time of the last item written \[ns\].
    last: Option<i64>,
}

/// Why a message stamped before one already written is dropped.
const BACKWARDS: &str = "stamp more than 2 s before one already written";

/// How long items wait for earlier ones \[ns\].
const REORDER_NS: i64 = 2_000_000_000;

impl Reorder {
    fn new() -> Reorder {
        Reorder {
            heap: BinaryHeap::new(),
            next: 0,
            last: None,
        }
    }

    /// Queues `bytes` at `t`; false (dropped) when something later was already written.
    fn push(&mut self, t: i64, bytes: Vec<u8>) -> bool {
        if self.last.is_some_and(|l| t < l) {
            return false;
        }
        self.heap.push(std::cmp::Reverse((t, self.next, bytes)));
        self.next += 1;
        true
    }

    /// Pops the items older than `now - REORDER_NS` (all with `now = None`).
    fn pop_ready(
        &mut self,
        now: Option<i64>,
        mut out: impl FnMut(i64, Vec<u8>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        while let Some(std::cmp::Reverse((t, _, _))) = self.heap.peek() {
            if now.is_some_and(|n| *t > n - REORDER_NS) {
                break;
            }
            let Some(std::cmp::Reverse((t, _, b))) = self.heap.pop() else {
                break;
            };
            self.last = Some(t);
            out(t, b)?;
        }
        Ok(())
    }
}

/// The topic of every stream the recording has (radar or IMU at least).
fn choose_all(
    opts: &ImportOptions,
    topics: &[TopicInfo],
) -> Result<BTreeMap<Kind, TopicInfo>, ImportError> {
    let mut chosen = BTreeMap::new();
    for (k, n) in [
        (Kind::Radar, &opts.radar_topic),
        (Kind::Imu, &opts.imu_topic),
        (Kind::Trigger, &opts.trigger_topic),
        (Kind::Pressure, &opts.baro_topic),
        (Kind::Truth, &opts.gt_topic),
    ] {
        if let Some(t) = choose(k, n.as_deref(), topics)? {
            chosen.insert(k, t);
        }
    }
    if !chosen.contains_key(&Kind::Radar) && !chosen.contains_key(&Kind::Imu) {
        return Err(ImportError::Topic {
            stream: "radar",
            why: format!(
                "neither a sensor_msgs/PointCloud2 nor a sensor_msgs/Imu topic (topics: {})",
                topics
                    .iter()
                    .map(|t| format!("{} ({})", t.topic, t.msg_type))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    }
    Ok(chosen)
}

/// The points of a scan in the session's axes, as the radar frame carries them (`[x, y, z,
/// velocity]` and the SNR), counting the points dropped in `tally`.
fn scan_points(
    l: &PointLayout,
    c: &PointCloud2,
    axes: RadarAxes,
    tally: &mut Tally,
) -> Result<(Vec<[f32; 4]>, Vec<f64>), crate::cloud::LayoutError> {
    let mut pts = Vec::new();
    let mut snr = Vec::new();
    let mut bad = 0u64;
    l.points(c, |q| {
        let x = axes.to_session(q.xyz);
        if x.iter().chain([&q.doppler]).any(|v| !v.is_finite()) {
            bad += 1;
            return;
        }
        pts.push([x[0] as f32, x[1] as f32, x[2] as f32, q.doppler as f32]);
        snr.push(q.snr.unwrap_or(0.0));
    })?;
    tally.drop_n("point not finite", bad);
    if pts.len() > wire::MAX_POINTS {
        tally.drop_n(
            "point beyond the frame limit",
            (pts.len() - wire::MAX_POINTS) as u64,
        );
        pts.truncate(wire::MAX_POINTS);
        snr.truncate(wire::MAX_POINTS);
    }
    Ok((pts, snr))
}

/// What the import says about a scan layout and the axes.
fn layout_note(l: &PointLayout, axes: RadarAxes) -> String {
    format!(
        "Doppler from field `{}`{}; points {}",
        l.doppler_name,
        l.snr_name
            .as_ref()
            .map_or(String::new(), |n| format!(", SNR from `{n}`")),
        match axes {
            RadarAxes::Ros => "converted from ROS axes (x forward) to TI axes",
            RadarAxes::Session => "kept in TI axes",
        }
    )
}

/// Imports `sources` (read in order, as one recording) into a new session at `out`.
pub fn import(
    sources: &[PathBuf],
    out: &Path,
    opts: &ImportOptions,
) -> Result<ImportReport, ImportError> {
    let topics = list(sources)?;
    let chosen = choose_all(opts, &topics)?;
    let mut calib = opts.calib.clone().unwrap_or_default();
    // The readers take half the active chirping off a frame's ready time when the session has
    // a .cfg, so frames are stamped that much later here.
    let mut half_chirps_s = 0.0;
    // The sources' own `milliego` metadata (our export-mcap writes it): radar axes and .cfg.
    let ours = milliego_metadata(sources)?;
    let radar_cfg = opts
        .radar_cfg
        .clone()
        .or_else(|| ours.get("radar_cfg").cloned());
    if let Some(text) = &radar_cfg {
        let d = radar_driver::cfg::RadarConfig::parse(text)
            .and_then(|c| c.derive(None))
            .map_err(ImportError::RadarCfg)?;
        half_chirps_s = d.active_frame_time_ms / 2e3;
        calib.radar_frame_s = calib.radar_frame_s.or(Some(d.active_frame_time_ms / 1e3));
    }
    let mut s = survey(sources, &chosen, opts)?;
    let axes = match opts.radar_axes {
        Some(a) => a,
        None if ours.get("radar_axes").map(String::as_str) == Some("ti") => RadarAxes::Session,
        None => RadarAxes::Ros,
    };
    let calib_note = if opts.calib.is_some() {
        None
    } else {
        Some(extrinsics_from_tf(&s, axes, &mut calib))
    };
    let mut radar_tally = s.tallies.remove(&Kind::Radar);
    let scan_times = radar_tally
        .as_mut()
        .map(|t| time_scans(&s, &calib, t))
        .unwrap_or_default();
    if let (Some(t), Some(tr)) = (radar_tally.as_mut(), chosen.get(&Kind::Trigger)) {
        t.timing = t.timing.replacen("topic", &tr.topic, 1);
    }
    for (k, t) in s.tallies.iter_mut() {
        if matches!(k, Kind::Imu | Kind::Pressure | Kind::Truth) {
            t.timing = if t.zero_stamps == 0 {
                "header stamps".into()
            } else {
                format!(
                    "header stamps; {} zero stamps timed by arrival",
                    t.zero_stamps
                )
            };
        }
    }
    // The origin: the first time of any sensor stream (ground truth may start earlier).
    let first = scan_times
        .iter()
        .flatten()
        .copied()
        .chain(s.tallies.get(&Kind::Imu).and_then(|t| t.first_ns))
        .chain(s.tallies.get(&Kind::Pressure).and_then(|t| t.first_ns))
        .min()
        .ok_or(ImportError::Empty)?;
    let t0 = first + (opts.start_s.max(0.0) * 1e9) as i64;
    let t_end = opts.duration_s.map(|d| t0 + (d * 1e9) as i64);
    let inside = |t: i64| t >= t0 && t_end.is_none_or(|e| t <= e);
    let secs = |t: i64| (t - t0) as f64 * 1e-9;

    // UART rates that keep up with the data.
    let radar_period = median_period(&scan_times);
    let max_scan = s.scans.iter().map(|h| h.bytes).max().unwrap_or(0);
    let radar_baud = wire::baud_for(
        max_scan + 64,
        radar_period.unwrap_or(0.1),
        wire::RADAR_BAUDS,
    );
    let imu_rate = s
        .tallies
        .get(&Kind::Imu)
        .and_then(|t| Some((t.messages, t.first_ns?, t.last_ns?)))
        .and_then(|(n, a, b)| (n > 1 && b > a).then(|| (n - 1) as f64 / ((b - a) as f64 * 1e-9)));
    let imu_baud = wire::baud_for(
        wire::IMU_MESSAGE_LEN * 2,
        1.0 / imu_rate.unwrap_or(100.0),
        wire::IMU_BAUDS,
    );

    let mut meta = Meta::imported();
    meta.description = opts.description.clone();
    meta.extrinsics.radar = calib.radar;
    meta.extrinsics.imu = calib.imu;
    // The name given, else a device our export named (its `milliego` metadata), else the topic
    // it came from.
    let named = |k: Kind| match k {
        Kind::Radar => opts.radar_device.as_ref().or(ours.get("radar_device")),
        Kind::Imu | Kind::Pressure => opts.imu_device.as_ref().or(ours.get("imu_device")),
        _ => None,
    };
    let device = |k: Kind| {
        chosen.get(&k).map(|t| {
            named(k)
                .cloned()
                .unwrap_or_else(|| format!("imported from {}", t.topic))
        })
    };
    if chosen.contains_key(&Kind::Radar) {
        meta.radar = Some(RadarMeta {
            index: Some("radar.idx".into()),
            baud: radar_baud,
            device: device(Kind::Radar),
            ..RadarMeta::default()
        });
    }
    let imu_stream = chosen.contains_key(&Kind::Imu) || chosen.contains_key(&Kind::Pressure);
    if imu_stream {
        meta.imu = Some(ImuMeta {
            index: Some("imu.idx".into()),
            baud: imu_baud,
            device: device(Kind::Imu).or(device(Kind::Pressure)),
            rate_hz: imu_rate,
            ..ImuMeta::default()
        });
    }
    let mut w = SessionWriter::create(out, meta).map_err(ImportError::Session)?;
    if let Some(text) = &radar_cfg {
        w.radar_cfg(text).map_err(ImportError::Session)?;
    }
    let mut radar_w = match chosen.contains_key(&Kind::Radar) {
        true => Some(w.stream(StreamKind::Radar).map_err(ImportError::Session)?),
        false => None,
    };
    let mut imu_w = match imu_stream {
        true => Some(w.stream(StreamKind::Imu).map_err(ImportError::Session)?),
        false => None,
    };

    // Second pass: the sensor streams.
    let mut layouts: Vec<(Vec<PointField>, PointLayout)> = Vec::new();
    let mut radar_q = Reorder::new();
    let mut imu_q = Reorder::new();
    let mut counter: u16 = 0;
    let by_topic: BTreeMap<&str, Kind> = chosen
        .iter()
        .filter(|(k, _)| matches!(k, Kind::Radar | Kind::Imu | Kind::Pressure))
        .map(|(k, t)| (t.topic.as_str(), *k))
        .collect();
    let names: Vec<&str> = by_topic.keys().copied().collect();
    let mut scan_i = 0usize;
    let mut tallies = std::mem::take(&mut s.tallies);
    let mut radar_written = 0u64;
    let mut radar_notes: Vec<String> = Vec::new();
    let rt = &mut radar_tally;
    for p in sources {
        let mut src = source::open(p)?;
        src.for_each(&names, &mut |m| {
            let Some(&kind) = by_topic.get(m.topic) else {
                return Ok(());
            };
            match kind {
                Kind::Radar => {
                    let i = scan_i;
                    scan_i += 1;
                    let tally = rt.as_mut().expect("radar chosen");
                    let Some(t) = scan_times.get(i).copied().flatten() else {
                        tally.drop("no trigger");
                        return Ok(());
                    };
                    if !inside(t) {
                        tally.drop("outside --start/--duration");
                        return Ok(());
                    }
                    let c: PointCloud2 = decode(&m, p)?;
                    // Scans almost always share one layout: found by comparing fields, no
                    // key built per scan.
                    let known = layouts.iter().position(|(f, _)| *f == c.fields);
                    let li = match known {
                        Some(li) => li,
                        None => {
                            let l = PointLayout::of(&c, opts.doppler_field.as_deref()).map_err(
                                |error| ImportError::Layout {
                                    at: at(p, &m),
                                    error,
                                },
                            )?;
                            radar_notes.push(layout_note(&l, axes));
                            layouts.push((c.fields.clone(), l));
                            layouts.len() - 1
                        }
                    };
                    let l = &layouts[li].1;
                    let (pts, snr) =
                        scan_points(l, &c, axes, tally).map_err(|error| ImportError::Layout {
                            at: at(p, &m),
                            error,
                        })?;
                    let number = s.scans[i].seq.unwrap_or(i as u32);
                    let bytes = wire::radar_frame(
                        number,
                        secs(t) + half_chirps_s,
                        &pts,
                        l.snr_name.as_ref().map(|_| snr.as_slice()),
                    );
                    if !radar_q.push(t, bytes) {
                        tally.drop_at(BACKWARDS, p, &m);
                    }
                    let rw = radar_w.as_mut().expect("radar stream");
                    radar_q.pop_ready(Some(t), |t, b| {
                        radar_written += 1;
                        write_chunk(rw, secs(t) + half_chirps_s, &b, radar_baud)
                    })?;
                }
                Kind::Imu | Kind::Pressure => {
                    let tally = tallies.get_mut(&kind).expect("chosen");
                    let (t, bytes) = if kind == Kind::Imu {
                        let u: Imu = decode(&m, p)?;
                        let t = stamp_or_log(&u.header, &m);
                        if u.angular_velocity
                            .iter()
                            .chain(&u.linear_acceleration)
                            .any(|v| !v.is_finite())
                        {
                            tally.drop_at("not finite", p, &m);
                            return Ok(());
                        }
                        (
                            t,
                            wire::imu_message(
                                counter,
                                secs(t),
                                u.linear_acceleration,
                                u.angular_velocity,
                            ),
                        )
                    } else {
                        let b: FluidPressure = decode(&m, p)?;
                        let t = stamp_or_log(&b.header, &m);
                        if !b.fluid_pressure.is_finite() {
                            tally.drop_at("not finite", p, &m);
                            return Ok(());
                        }
                        (
                            t,
                            wire::pressure_message(counter, secs(t), b.fluid_pressure),
                        )
                    };
                    if !inside(t) {
                        tally.drop("outside --start/--duration");
                        return Ok(());
                    }
                    counter = counter.wrapping_add(1);
                    if !imu_q.push(t, bytes) {
                        tally.drop_at(BACKWARDS, p, &m);
                        return Ok(());
                    }
                    tally.written += 1;
                    let iw = imu_w.as_mut().expect("imu stream");
                    imu_q.pop_ready(Some(t), |t, b| write_chunk(iw, secs(t), &b, imu_baud))?;
                }
                Kind::Trigger | Kind::Truth => {}
            }
            Ok(())
        })?;
    }
    if let Some(rw) = radar_w.as_mut() {
        radar_q.pop_ready(None, |t, b| {
            radar_written += 1;
            write_chunk(rw, secs(t) + half_chirps_s, &b, radar_baud)
        })?;
    }
    if let Some(iw) = imu_w.as_mut() {
        imu_q.pop_ready(None, |t, b| write_chunk(iw, secs(t), &b, imu_baud))?;
    }
    for sw in [radar_w, imu_w].into_iter().flatten() {
        sw.finish().map_err(ImportError::Session)?;
    }
    let poses: Vec<TumPose> = s
        .truth
        .iter()
        .filter(|(t, _, _)| inside(*t))
        .map(|(t, p, q)| TumPose {
            t: secs(*t),
            p: *p,
            q: *q,
        })
        .collect();
    if let Some(gt) = tallies.get_mut(&Kind::Truth) {
        gt.written = poses.len() as u64;
        gt.drop_n(
            "pose outside the sensor streams / --start/--duration",
            (s.truth.len() - poses.len()) as u64,
        );
        if !poses.is_empty() {
            w.groundtruth(&poses).map_err(ImportError::Session)?;
        }
    }
    if let Some(tr) = tallies.get_mut(&Kind::Trigger) {
        tr.written = s.triggers.len() as u64;
        tr.timing = "header stamps (they time the radar scans)".into();
    }
    let mut streams = Vec::new();
    if let Some(mut t) = radar_tally {
        t.written = radar_written;
        t.notes.extend(radar_notes);
        t.notes.extend(calib_note);
        streams.push(t.into_meta("radar"));
    }
    for (k, t) in tallies {
        streams.push(t.into_meta(k.name()));
    }
    w.meta_mut().import = Some(ImportMeta {
        tool: concat!("milliego import ", env!("CARGO_PKG_VERSION")).into(),
        sources: sources.iter().map(|p| p.display().to_string()).collect(),
        time_origin_ns: t0,
        streams: streams.clone(),
    });
    let session = w.finish().map_err(ImportError::Session)?;
    Ok(ImportReport { session, streams })
}

/// The radar axes a recording declares: `milliego export-mcap` records `radar_axes = "ti"` in its
/// `milliego` metadata; anything else is taken to follow ROS (x forward).
/// Without a calibration file: the extrinsics from `/tf_static` when it connects the radar and
/// IMU frames, else identity. Returns what the import says about it.
fn extrinsics_from_tf(s: &Survey, axes: RadarAxes, calib: &mut Calibration) -> String {
    let identity = "radar and IMU at the body origin, radar boresight = body x";
    if s.static_tf.is_empty() {
        return format!("no calibration (--calib) and no {TF_STATIC}: {identity}");
    }
    let (radar, imu) = (s.radar_frame.as_deref(), s.imu_frame.as_deref());
    let Some(rig) = s.static_tf.rig(s.truth_child.as_deref(), radar, imu) else {
        return format!(
            "no calibration (--calib), and {TF_STATIC} does not connect the radar frame `{}` and \
             the IMU frame `{}`: {identity}",
            radar.unwrap_or(""),
            imu.unwrap_or("")
        );
    };
    let mut used = Vec::new();
    if let Some(r) = rig.radar {
        calib.radar = match axes {
            RadarAxes::Ros => crate::calib::radar_from_ros(r.translation_m, r.rotation_wxyz),
            RadarAxes::Session => r,
        };
        used.push(format!("radar `{}`", radar.unwrap_or("")));
    }
    if let Some(i) = rig.imu {
        calib.imu = i;
        used.push(format!("IMU `{}`", imu.unwrap_or("")));
    }
    format!(
        "extrinsics from {TF_STATIC}: {} in body frame `{}`",
        used.join(" and "),
        rig.body
    )
}

/// The first `milliego` metadata record of the sources (empty when none has one).
fn milliego_metadata(sources: &[PathBuf]) -> Result<BTreeMap<String, String>, ImportError> {
    for p in sources {
        if let Some((_, kv)) = source::open(p)?
            .metadata()?
            .into_iter()
            .find(|(name, _)| name == "milliego")
        {
            return Ok(kv.into_iter().collect());
        }
    }
    Ok(BTreeMap::new())
}

/// Writes one chunk whose data was measured at `t_s`: the host stamp is when its last byte would
/// have arrived at `baud` (the readers take the transmission time back off).
fn write_chunk(
    w: &mut milliego_session::StreamWriter,
    t_s: f64,
    bytes: &[u8],
    baud: u32,
) -> Result<(), ImportError> {
    let tx = bytes.len() as f64 * 10.0 / f64::from(baud);
    let host_ns = ((t_s + tx) * 1e9).round().max(0.0) as u64;
    w.write_chunk(host_ns, bytes).map_err(ImportError::Session)
}

/// Median spacing of the timed scans \[s\].
fn median_period(times: &[Option<i64>]) -> Option<f64> {
    let t: Vec<i64> = times.iter().flatten().copied().collect();
    let mut d: Vec<i64> = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0)
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_unstable();
    Some(d[d.len() / 2] as f64 * 1e-9)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn topic(name: &str, ty: &str) -> TopicInfo {
        TopicInfo {
            topic: name.into(),
            msg_type: ty.into(),
            count: 10,
            span_ns: Some((0, 1_000_000_000)),
        }
    }

    #[test]
    fn topics_are_chosen_by_type_then_name() {
        let t = vec![
            topic("/ti_mmwave/radar_scan_pcl", "sensor_msgs/PointCloud2"),
            topic("/velodyne_points", "sensor_msgs/PointCloud2"),
            topic("/imu/data", "sensor_msgs/Imu"),
            topic("/radar/trigger", "std_msgs/Header"),
            topic("/status", "std_msgs/Header"),
            topic("/tf", "tf2_msgs/TFMessage"),
        ];
        let pick = |k, n: Option<&str>| choose(k, n, &t).unwrap().map(|t| t.topic);
        assert_eq!(
            pick(Kind::Radar, None).as_deref(),
            Some("/ti_mmwave/radar_scan_pcl")
        );
        assert_eq!(pick(Kind::Imu, None).as_deref(), Some("/imu/data"));
        assert_eq!(pick(Kind::Trigger, None).as_deref(), Some("/radar/trigger"));
        // /tf is too generic to be ground truth without being named.
        assert_eq!(pick(Kind::Truth, None), None);
        assert_eq!(pick(Kind::Truth, Some("/tf")).as_deref(), Some("/tf"));
        assert_eq!(pick(Kind::Pressure, None), None);
        let e = choose(Kind::Imu, Some("/radar/trigger"), &t)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("is std_msgs/Header, expected sensor_msgs/Imu"),
            "{e}"
        );
        let e = choose(Kind::Imu, Some("/nope"), &t)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/nope is not in the recording") && e.contains("/imu/data"),
            "{e}"
        );
        let two = vec![
            topic("/a", "sensor_msgs/PointCloud2"),
            topic("/b", "sensor_msgs/PointCloud2"),
        ];
        let gt = vec![
            topic("/groundtruth/odom", "nav_msgs/Odometry"),
            topic("/groundtruth/pose", "geometry_msgs/PoseStamped"),
            topic("/tf_static", "tf2_msgs/TFMessage"),
        ];
        let g = choose(Kind::Truth, None, &gt).unwrap().unwrap();
        assert_eq!(g.topic, "/groundtruth/pose");
        let e = choose(Kind::Radar, None, &two).unwrap_err().to_string();
        assert!(
            e.contains("several candidates (/a, /b)") && e.contains("--radar-topic"),
            "{e}"
        );
    }

    #[test]
    fn reorder_releases_in_time_order_and_refuses_the_past() {
        let mut q = Reorder::new();
        let mut out = Vec::new();
        for t in [5, 3, 4] {
            assert!(q.push(t * 1_000_000_000, vec![t as u8]));
        }
        q.pop_ready(Some(6_000_000_000), |t, _| {
            out.push(t / 1_000_000_000);
            Ok(())
        })
        .unwrap();
        assert_eq!(out, vec![3, 4]);
        assert!(
            !q.push(3_500_000_000, vec![]),
            "older than what was written"
        );
        q.pop_ready(None, |t, _| {
            out.push(t / 1_000_000_000);
            Ok(())
        })
        .unwrap();
        assert_eq!(out, vec![3, 4, 5]);
    }

    #[test]
    fn scans_are_timed_by_trigger_sequence_then_stamp_then_arrival() {
        let head = |seq, stamp_ns, log_ns| ScanHead {
            seq: Some(seq),
            stamp_ns,
            log_ns,
            bytes: 100,
        };
        let mut s = Survey {
            scans: vec![head(1, 0, 1_150), head(2, 0, 1_250), head(3, 0, 1_350)],
            triggers: vec![(Some(2), 1_100), (Some(1), 1_000)],
            ..Survey::default()
        };
        let calib = Calibration {
            radar_frame_s: Some(20e-9),
            ..Calibration::default()
        };
        let mut t = Tally::default();
        let times = time_scans(&s, &calib, &mut t);
        assert_eq!(times, vec![Some(1_010), Some(1_110), None]);
        assert!(t.timing.contains("by sequence number"), "{}", t.timing);
        s.triggers.clear();
        let mut t = Tally {
            zero_stamps: 3,
            ..Tally::default()
        };
        assert_eq!(
            time_scans(&s, &Calibration::default(), &mut t),
            vec![Some(1_150), Some(1_250), Some(1_350)]
        );
        assert!(t.timing.starts_with("arrival"), "{}", t.timing);
        s.scans = vec![head(1, 900, 1_150)];
        let mut t = Tally::default();
        assert_eq!(
            time_scans(&s, &Calibration::default(), &mut t),
            vec![Some(900)]
        );
        assert_eq!(t.timing, "header stamps");
    }
}
