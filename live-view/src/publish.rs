//! The channels and what goes on them.

use crate::gt::GroundTruth;
use crate::ViewCounters;
use foxglove::bytes::Bytes;
use foxglove::schemas::packed_element_field::NumericType;
use foxglove::schemas::{
    FrameTransform, FrameTransforms, PackedElementField, PointCloud, Pose, PoseInFrame,
    PosesInFrame, Quaternion, Timestamp, Vector3,
};
use foxglove::{Channel, ChannelBuilder, Context, RawChannel, Schema};
use milliego_runtime::estimator::Mounting;
use milliego_runtime::view::{ViewEvent, ViewStatus};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use pose_link::{Estimator, Health, PoseMessage};
use serde_json::json;
use std::sync::Arc;

/// JSON schema of `/imu` (`milliego.Imu`): one IMU sample in the IMU frame.
pub const IMU_SCHEMA: &str = r#"{
  "title": "milliego.Imu",
  "description": "One IMU sample in time order, in the IMU's sensor frame (frame_id imu).",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "description": "Time on the run's common clock (session host clock for sessions)",
                  "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "frame_id": {"type": "string"},
    "accel": {"type": "object", "description": "Specific force [m/s^2]",
              "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
    "gyro": {"type": "object", "description": "Rate of turn [rad/s]",
             "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}}
  }
}"#;

/// JSON schema of `/velocity` (`milliego.Velocity`): the body's velocity in the world frame
/// from consecutive radar-rate poses.
pub const VELOCITY_SCHEMA: &str = r#"{
  "title": "milliego.Velocity",
  "description": "Body velocity in the world frame from consecutive radar-rate poses (finite difference).",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "frame_id": {"type": "string"},
    "velocity": {"type": "object", "description": "[m/s]",
                 "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
    "speed": {"type": "number", "description": "|velocity| [m/s]"}
  }
}"#;

/// JSON schema of `/health` (`milliego.Health`): what the run is doing, about every 100 ms.
pub const HEALTH_SCHEMA: &str = r#"{
  "title": "milliego.Health",
  "description": "The run's state: estimator, the latest pose's flags, drop counters, clock state.",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "description": "Time of the latest pose",
                  "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "estimator": {"type": "string", "description": "The estimator asked for: auto, model, doppler, imu"},
    "active_estimator": {"type": "string", "description": "The latest pose's estimator code: model, doppler, imu"},
    "input": {"type": "string", "description": "session or devices"},
    "flags": {"type": "array", "items": {"type": "string"},
              "description": "The latest pose's health flags: radar_missing, imu_missing, model_fallback, clock_unsynced, frames_dropped, predicted, reset, handover, dead_reckoning"},
    "health_bits": {"type": "integer"},
    "clock": {"type": "object", "properties": {"mode": {"type": "string", "description": "session fit or online"},
                                               "synced": {"type": "boolean"}}},
    "seq": {"type": "integer", "description": "The latest pose's sequence number"},
    "poses": {"type": "integer", "description": "Poses the view received"},
    "radar_in": {"type": "integer"}, "imu_in": {"type": "integer"},
    "dropped_total": {"type": "integer", "description": "The pose path's drops as the latest pose reports them"},
    "drops": {"type": "object", "properties": {"radar_queue": {"type": "integer"}, "imu_queue": {"type": "integer"},
                                               "event_queue": {"type": "integer"}, "pose_queue": {"type": "integer"},
                                               "sync_buffers": {"type": "integer"}}},
    "view_dropped": {"type": "integer", "description": "Items the view's hand-off lost"}
  }
}"#;

/// Radar-rate poses the trajectory keeps; past it, every second one is dropped (the path
/// keeps its shape at half the density).
const TRAJECTORY_MAX: usize = 20_000;
/// Least data time between trajectory messages \[s\] (the last one is always sent).
const TRAJECTORY_PERIOD_S: f64 = 0.2;
/// Bytes per point: x, y, z, doppler, snr as f32.
const POINT_STRIDE: usize = 20;

fn stamp(t: f64) -> Timestamp {
    Timestamp::try_from_epoch_secs_f64(t.max(0.0)).unwrap_or(Timestamp::MIN)
}

fn nanos(t: f64) -> u64 {
    (t.max(0.0) * 1e9).round() as u64
}

fn pose_of(iso: &Isometry3<f64>) -> Pose {
    let v = iso.translation.vector;
    let q = iso.rotation;
    Pose {
        position: Some(Vector3 {
            x: v.x,
            y: v.y,
            z: v.z,
        }),
        orientation: Some(Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}

fn iso_of(m: &PoseMessage) -> Isometry3<f64> {
    let [w, x, y, z] = m.orientation.map(f64::from);
    Isometry3::from_parts(
        Translation3::from(nalgebra::Vector3::from(m.position)),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
    )
}

fn transform(t: f64, parent: &str, child: &str, iso: &Isometry3<f64>) -> FrameTransform {
    let p = pose_of(iso);
    FrameTransform {
        timestamp: Some(stamp(t)),
        parent_frame_id: parent.into(),
        child_frame_id: child.into(),
        translation: p.position,
        rotation: p.orientation,
    }
}

fn flag_names(h: Health) -> Vec<&'static str> {
    [
        (Health::RADAR_MISSING, "radar_missing"),
        (Health::IMU_MISSING, "imu_missing"),
        (Health::MODEL_FALLBACK, "model_fallback"),
        (Health::CLOCK_UNSYNCED, "clock_unsynced"),
        (Health::FRAMES_DROPPED, "frames_dropped"),
        (Health::PREDICTED, "predicted"),
        (Health::RESET, "reset"),
        (Health::HANDOVER, "handover"),
        (Health::DEAD_RECKONING, "dead_reckoning"),
    ]
    .into_iter()
    .filter(|(f, _)| h.contains(*f))
    .map(|(_, n)| n)
    .collect()
}

fn estimator_name(e: Estimator) -> String {
    match e {
        Estimator::Model => "model".into(),
        Estimator::Doppler => "doppler".into(),
        Estimator::Imu => "imu".into(),
        Estimator::Fused => "fused".into(),
        Estimator::Unknown(n) => format!("unknown({n})"),
    }
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
    name: &str,
    schema: &'static str,
) -> Arc<RawChannel> {
    ChannelBuilder::new(topic)
        .context(ctx)
        .message_encoding("json")
        .schema(Schema::new(name, "jsonschema", schema.as_bytes()))
        .build_raw()
        // Only fails without a message encoding, which is set above.
        .unwrap_or_else(|e| panic!("live view: channel {topic}: {e}"))
}

/// A channel of a well-known schema (protobuf), also kept raw in `all`.
fn typed_channel<T: foxglove::Encode>(
    ctx: &Arc<Context>,
    topic: &str,
    all: &mut Vec<Arc<RawChannel>>,
) -> Channel<T> {
    let raw = ChannelBuilder::new(topic)
        .context(ctx)
        .build::<T>()
        .into_inner();
    all.push(Arc::clone(&raw));
    Channel::from_raw_channel(raw)
}

/// The view's channels and state.
pub struct Publisher {
    points: Channel<PointCloud>,
    pose: Channel<PoseInFrame>,
    trajectory: Channel<PosesInFrame>,
    tf: Channel<FrameTransforms>,
    imu: Arc<RawChannel>,
    velocity: Arc<RawChannel>,
    health: Arc<RawChannel>,
    gt_pose: Option<Channel<PoseInFrame>>,
    gt_trajectory: Option<Channel<PosesInFrame>>,
    gt: Option<GroundTruth>,
    mounting: Mounting,
    estimator: String,
    input: String,
    clock: String,
    path: Vec<Pose>,
    gt_path: Vec<Pose>,
    path_t: f64,
    last_path_sent_t: f64,
    path_dirty: bool,
    last_radar_pose: Option<(f64, nalgebra::Vector3<f64>)>,
    last_pose: Option<(f64, PoseMessage)>,
    status: ViewStatus,
    buf: Vec<u8>,
    all: Vec<Arc<RawChannel>>,
    /// What was published.
    pub counters: ViewCounters,
}

impl Publisher {
    /// Advertises the channels on `ctx` (the ground-truth ones only when there is ground truth).
    pub fn new(ctx: &Arc<Context>, gt: Option<GroundTruth>) -> Publisher {
        let mut all = Vec::new();
        let points = typed_channel(ctx, "/radar/points", &mut all);
        let pose = typed_channel(ctx, "/pose", &mut all);
        let trajectory = typed_channel(ctx, "/trajectory", &mut all);
        let tf = typed_channel(ctx, "/tf", &mut all);
        let (gt_pose, gt_trajectory) = match gt {
            Some(_) => (
                Some(typed_channel(ctx, "/ground_truth/pose", &mut all)),
                Some(typed_channel(ctx, "/ground_truth/trajectory", &mut all)),
            ),
            None => (None, None),
        };
        let imu = json_channel(ctx, "/imu", "milliego.Imu", IMU_SCHEMA);
        let velocity = json_channel(ctx, "/velocity", "milliego.Velocity", VELOCITY_SCHEMA);
        let health = json_channel(ctx, "/health", "milliego.Health", HEALTH_SCHEMA);
        all.extend([&imu, &velocity, &health].map(Arc::clone));
        Publisher {
            points,
            pose,
            trajectory,
            tf,
            imu,
            velocity,
            health,
            gt_pose,
            gt_trajectory,
            gt,
            all,
            mounting: Mounting::default(),
            estimator: String::new(),
            input: String::new(),
            clock: String::new(),
            path: Vec::new(),
            gt_path: Vec::new(),
            path_t: 0.0,
            last_path_sent_t: f64::NEG_INFINITY,
            path_dirty: false,
            last_radar_pose: None,
            last_pose: None,
            status: ViewStatus::default(),
            buf: Vec::new(),
            counters: ViewCounters::default(),
        }
    }

    /// Every channel (to see whether a client subscribed).
    pub fn channels(&self) -> Vec<Arc<RawChannel>> {
        self.all.clone()
    }

    /// Publishes one event.
    pub fn handle(&mut self, ev: ViewEvent) {
        match ev {
            ViewEvent::Start {
                mounting,
                estimator,
                input,
                clock,
            } => {
                self.mounting = mounting;
                self.estimator = estimator;
                self.input = input;
                self.clock = clock;
            }
            ViewEvent::Radar {
                t, points, snr_db, ..
            } => self.radar(t, &points, &snr_db),
            ViewEvent::Imu { t, accel, gyro } => {
                self.counters.imu += 1;
                let v = json!({
                    "timestamp": ts_json(t),
                    "frame_id": "imu",
                    "accel": {"x": accel[0], "y": accel[1], "z": accel[2]},
                    "gyro": {"x": gyro[0], "y": gyro[1], "z": gyro[2]},
                });
                self.log_json(JsonTopic::Imu, t, &v);
            }
            ViewEvent::Pose { t, msg } => self.pose(t, msg),
            ViewEvent::Status(s) => {
                self.status = s;
                self.health();
            }
        }
    }

    fn radar(&mut self, t: f64, points: &[radar_driver::host::Point], snr: &[f32]) {
        self.counters.radar += 1;
        let mut data = Vec::with_capacity(points.len() * POINT_STRIDE);
        for (i, p) in points.iter().enumerate() {
            let s = snr.get(i).copied().unwrap_or(f32::NAN);
            for v in [p.x, p.y, p.z, p.velocity, s] {
                data.extend_from_slice(&v.to_le_bytes());
            }
        }
        let field = |name: &str, offset: u32| PackedElementField {
            name: name.into(),
            offset,
            r#type: NumericType::Float32 as i32,
        };
        let msg = PointCloud {
            timestamp: Some(stamp(t)),
            frame_id: "radar".into(),
            pose: Some(pose_of(&Isometry3::identity())),
            point_stride: POINT_STRIDE as u32,
            fields: vec![
                field("x", 0),
                field("y", 4),
                field("z", 8),
                field("doppler", 12),
                field("snr", 16),
            ],
            data: Bytes::from(data),
        };
        self.points.log_with_time(&msg, nanos(t));
    }

    fn pose(&mut self, t: f64, msg: PoseMessage) {
        self.counters.poses += 1;
        let iso = iso_of(&msg);
        let pose = pose_of(&iso);
        self.pose.log_with_time(
            &PoseInFrame {
                timestamp: Some(stamp(t)),
                frame_id: "world".into(),
                pose: Some(pose),
            },
            nanos(t),
        );
        let tfs = FrameTransforms {
            transforms: vec![
                transform(t, "world", "body", &iso),
                transform(t, "body", "radar", &self.mounting.radar),
                transform(t, "body", "imu", &self.mounting.imu),
            ],
        };
        self.tf.log_with_time(&tfs, nanos(t));
        self.last_pose = Some((t, msg));
        if msg.health.contains(Health::PREDICTED) {
            return;
        }
        // Radar-rate poses: the trajectory, the velocity, the ground truth.
        let p = iso.translation.vector;
        if let Some((t0, p0)) = self.last_radar_pose {
            if t > t0 {
                let v = (p - p0) / (t - t0);
                let j = json!({
                    "timestamp": ts_json(t),
                    "frame_id": "world",
                    "velocity": {"x": v.x, "y": v.y, "z": v.z},
                    "speed": v.norm(),
                });
                self.log_json(JsonTopic::Velocity, t, &j);
            }
        }
        self.last_radar_pose = Some((t, p));
        self.path.push(pose);
        if let Some(g) = self.gt.as_mut().and_then(|g| g.aligned(t, &iso)) {
            let gp = pose_of(&g);
            if let Some(c) = &self.gt_pose {
                c.log_with_time(
                    &PoseInFrame {
                        timestamp: Some(stamp(t)),
                        frame_id: "world".into(),
                        pose: Some(gp),
                    },
                    nanos(t),
                );
            }
            self.gt_path.push(gp);
        }
        for path in [&mut self.path, &mut self.gt_path] {
            if path.len() > TRAJECTORY_MAX {
                let mut i = 0;
                path.retain(|_| {
                    i += 1;
                    i % 2 == 1
                });
            }
        }
        self.path_t = t;
        self.path_dirty = true;
        if t - self.last_path_sent_t >= TRAJECTORY_PERIOD_S {
            self.send_paths();
        }
    }

    fn send_paths(&mut self) {
        let t = self.path_t;
        self.last_path_sent_t = t;
        self.path_dirty = false;
        let msg = |poses: &Vec<Pose>| PosesInFrame {
            timestamp: Some(stamp(t)),
            frame_id: "world".into(),
            poses: poses.clone(),
        };
        self.trajectory.log_with_time(&msg(&self.path), nanos(t));
        if let Some(c) = &self.gt_trajectory {
            c.log_with_time(&msg(&self.gt_path), nanos(t));
        }
    }

    fn health(&mut self) {
        self.counters.health += 1;
        let s = self.status;
        let (t, msg) = self.last_pose.unwrap_or_default();
        let v = json!({
            "timestamp": ts_json(t),
            "estimator": self.estimator,
            "active_estimator": if self.last_pose.is_some() { estimator_name(msg.estimator) } else { String::new() },
            "input": self.input,
            "flags": flag_names(msg.health),
            "health_bits": msg.health.0,
            "clock": {"mode": self.clock, "synced": self.last_pose.is_some() && !msg.health.contains(Health::CLOCK_UNSYNCED)},
            "seq": msg.seq,
            "poses": self.counters.poses,
            "radar_in": s.radar_in,
            "imu_in": s.imu_in,
            "dropped_total": msg.dropped_total,
            "drops": {
                "radar_queue": s.queue_drops[0],
                "imu_queue": s.queue_drops[1],
                "event_queue": s.queue_drops[2],
                "pose_queue": s.queue_drops[3],
                "sync_buffers": s.queue_drops[4],
            },
            "view_dropped": s.view_dropped,
        });
        self.log_json(JsonTopic::Health, t, &v);
    }

    fn log_json(&mut self, topic: JsonTopic, t: f64, v: &serde_json::Value) {
        self.buf.clear();
        if serde_json::to_writer(&mut self.buf, v).is_ok() {
            let c = match topic {
                JsonTopic::Imu => &self.imu,
                JsonTopic::Velocity => &self.velocity,
                JsonTopic::Health => &self.health,
            };
            c.log_with_meta(
                &self.buf,
                foxglove::PartialMetadata {
                    log_time: Some(nanos(t)),
                },
            );
        }
    }

    /// The end of the run: the last trajectory and health.
    pub fn finish(&mut self) {
        if self.path_dirty {
            self.send_paths();
        }
        self.health();
    }
}

#[derive(Clone, Copy)]
enum JsonTopic {
    Imu,
    Velocity,
    Health,
}

fn ts_json(t: f64) -> serde_json::Value {
    let s = stamp(t);
    json!({"sec": s.sec(), "nsec": s.nsec()})
}
