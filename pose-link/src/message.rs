//! The pose message, version 1.

use crate::crc::crc32c;
use core::fmt;

/// Message type of a pose.
pub const MSG_POSE: u8 = 0x01;
/// Wire version written by this crate. Decoders accept this major version with any body at least
/// as long as version 1's (later minor revisions only append fields before the CRC).
pub const VERSION: u8 = 1;
/// Bytes of a version-1 pose message (header, body, CRC).
pub const MESSAGE_LEN: usize = 104;
const HEADER_LEN: usize = 8;
const BODY_V1: usize = MESSAGE_LEN - HEADER_LEN - 4;

/// Health flags: what the consumer should know about this pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct Health(pub u16);

impl Health {
    /// No radar frame arrived for longer than a few frame periods.
    pub const RADAR_MISSING: Health = Health(1 << 0);
    /// No IMU sample arrived for longer than a few sample periods.
    pub const IMU_MISSING: Health = Health(1 << 1);
    /// The learned model is missing, unhealthy or too slow; a fallback estimator produced the pose.
    pub const MODEL_FALLBACK: Health = Health(1 << 2);
    /// Sensor and host clocks are not (yet) synchronised; times may be off.
    pub const CLOCK_UNSYNCED: Health = Health(1 << 3);
    /// Frames or samples were dropped since the previous message.
    pub const FRAMES_DROPPED: Health = Health(1 << 4);
    /// The pose was propagated with the IMU between radar-rate updates (high-rate output).
    pub const PREDICTED: Health = Health(1 << 5);
    /// The pipeline (re)started: the trajectory origin was reset.
    pub const RESET: Health = Health(1 << 6);
    /// The estimator changed at this pose (for example the learned model handed over to the
    /// Doppler filter): the trajectory goes on in the same world frame, no new origin.
    pub const HANDOVER: Health = Health(1 << 7);
    /// The pose rests on the IMU alone: the estimator applied no radar velocity, rest or learned
    /// measurement for longer than a second (a scene the radar cannot see, a radar gone quiet).
    /// Its position error grows with time until the flag clears.
    pub const DEAD_RECKONING: Health = Health(1 << 8);

    /// True when every flag of `other` is set.
    pub fn contains(self, other: Health) -> bool {
        self.0 & other.0 == other.0
    }
    /// True when no flag is set.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// Names of the set flags (unknown bits as `bitN`), for logs and dumps.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        const NAMES: [&str; 16] = [
            "radar_missing",
            "imu_missing",
            "model_fallback",
            "clock_unsynced",
            "frames_dropped",
            "predicted",
            "reset",
            "handover",
            "dead_reckoning",
            "bit9",
            "bit10",
            "bit11",
            "bit12",
            "bit13",
            "bit14",
            "bit15",
        ];
        (0..16)
            .filter(move |i| self.0 & (1 << i) != 0)
            .map(|i| NAMES[i])
    }
}

impl core::ops::BitOr for Health {
    type Output = Health;
    fn bitor(self, rhs: Health) -> Health {
        Health(self.0 | rhs.0)
    }
}

impl core::ops::BitOrAssign for Health {
    fn bitor_assign(&mut self, rhs: Health) {
        self.0 |= rhs.0;
    }
}

/// Which estimator produced the pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub enum Estimator {
    /// The milliEgo network.
    #[default]
    Model,
    /// Doppler radar-inertial odometry (classical fallback).
    Doppler,
    /// IMU-only dead reckoning.
    Imu,
    /// Doppler radar-inertial odometry with the network's relative motion as a measurement.
    Fused,
    /// A value this decoder does not know (sent by a newer encoder).
    Unknown(u8),
}

impl Estimator {
    /// Wire code.
    pub fn code(self) -> u8 {
        match self {
            Estimator::Model => 0,
            Estimator::Doppler => 1,
            Estimator::Imu => 2,
            Estimator::Fused => 3,
            Estimator::Unknown(c) => c,
        }
    }
    /// From a wire code.
    pub fn from_code(c: u8) -> Estimator {
        match c {
            0 => Estimator::Model,
            1 => Estimator::Doppler,
            2 => Estimator::Imu,
            3 => Estimator::Fused,
            c => Estimator::Unknown(c),
        }
    }
    /// Lowercase name.
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Model => "model",
            Estimator::Doppler => "doppler",
            Estimator::Imu => "imu",
            Estimator::Fused => "fused",
            Estimator::Unknown(_) => "unknown",
        }
    }
}

/// One pose, as sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseMessage {
    /// Health flags.
    pub health: Health,
    /// Estimator that produced the pose.
    pub estimator: Estimator,
    /// Sequence number, +1 per message (wraps at 2^32); a gap means lost messages.
    pub seq: u32,
    /// When the measurement the pose belongs to was taken (the middle of the radar frame's chirps,
    /// or the IMU sample), on the run's common clock \[ns\]: live, the host monotonic clock from
    /// the pipeline's start, onto which the synchroniser maps both sensors' clocks; offline, the
    /// session clock. Wire offset 12 (named "sensor time" before; same field, same meaning on
    /// the wire).
    pub measurement_time_ns: u64,
    /// Host monotonic time when the message was built \[ns\].
    pub host_time_ns: u64,
    /// Position of the body in the world (trajectory origin) frame \[m\].
    pub position: [f64; 3],
    /// Orientation of the body in the world frame, unit quaternion (w, x, y, z).
    pub orientation: [f32; 4],
    /// Translation since the previous radar-rate pose, in the previous body frame \[m\].
    pub rel_translation: [f32; 3],
    /// Rotation since the previous radar-rate pose, unit quaternion (w, x, y, z).
    pub rel_rotation: [f32; 4],
    /// Frames and samples dropped by the pipeline since it started.
    pub dropped_total: u32,
}

impl Default for PoseMessage {
    fn default() -> Self {
        PoseMessage {
            health: Health::default(),
            estimator: Estimator::Model,
            seq: 0,
            measurement_time_ns: 0,
            host_time_ns: 0,
            position: [0.0; 3],
            orientation: [1.0, 0.0, 0.0, 0.0],
            rel_translation: [0.0; 3],
            rel_rotation: [1.0, 0.0, 0.0, 0.0],
            dropped_total: 0,
        }
    }
}

/// Why bytes are not a pose message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// Fewer bytes than a header, or than the header's body length says.
    TooShort {
        /// Bytes needed \[B\].
        need: usize,
        /// Bytes present \[B\].
        have: usize,
    },
    /// More bytes than the header's body length says (one message per datagram/frame).
    TooLong {
        /// Bytes the header implies \[B\].
        expected: usize,
        /// Bytes present \[B\].
        have: usize,
    },
    /// Not a pose message.
    UnknownType {
        /// The type byte.
        ty: u8,
    },
    /// A major version this decoder does not speak.
    UnsupportedVersion {
        /// The version byte.
        version: u8,
    },
    /// The body is shorter than version 1's.
    BodyTooShort {
        /// Body length in the header \[B\].
        len: u16,
    },
    /// The CRC does not match.
    BadCrc {
        /// CRC computed over the message \[u32\].
        computed: u32,
        /// CRC carried by the message.
        carried: u32,
    },
    /// The output buffer is too small for [`PoseMessage::encode`].
    BufferTooSmall {
        /// Bytes needed \[B\].
        need: usize,
    },
}

impl DecodeError {
    /// Stable snake_case name of the error kind (for counters and summaries).
    pub fn kind_name(&self) -> &'static str {
        match self {
            Self::TooShort { .. } => "too_short",
            Self::TooLong { .. } => "too_long",
            Self::UnknownType { .. } => "unknown_type",
            Self::UnsupportedVersion { .. } => "unsupported_version",
            Self::BodyTooShort { .. } => "body_too_short",
            Self::BadCrc { .. } => "bad_crc",
            Self::BufferTooSmall { .. } => "buffer_too_small",
        }
    }
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooShort { need, have } => {
                write!(f, "pose message too short: need {need} B, have {have} B")
            }
            Self::TooLong { expected, have } => {
                write!(
                    f,
                    "pose message too long: header says {expected} B, have {have} B"
                )
            }
            Self::UnknownType { ty } => write!(f, "not a pose message: type {ty:#04x}"),
            Self::UnsupportedVersion { version } => {
                write!(
                    f,
                    "pose link version {version} is not supported (this decoder speaks {VERSION})"
                )
            }
            Self::BodyTooShort { len } => write!(
                f,
                "pose body of {len} B is shorter than version 1's {BODY_V1} B"
            ),
            Self::BadCrc { computed, carried } => {
                write!(
                    f,
                    "pose message CRC mismatch: computed {computed:#010x}, carried {carried:#010x}"
                )
            }
            Self::BufferTooSmall { need } => write!(f, "output buffer too small: need {need} B"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}

struct W<'a> {
    b: &'a mut [u8],
    at: usize,
}

impl W<'_> {
    fn put(&mut self, bytes: &[u8]) {
        self.b[self.at..self.at + bytes.len()].copy_from_slice(bytes);
        self.at += bytes.len();
    }
}

struct R<'a> {
    b: &'a [u8],
    at: usize,
}

impl R<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        if let Some(s) = self.b.get(self.at..self.at + N) {
            out.copy_from_slice(s);
        }
        self.at += N;
        out
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
}

impl PoseMessage {
    /// Writes the version-1 message into `out` (at least [`MESSAGE_LEN`] bytes); returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, DecodeError> {
        let Some(b) = out.get_mut(..MESSAGE_LEN) else {
            return Err(DecodeError::BufferTooSmall { need: MESSAGE_LEN });
        };
        let mut w = W { b, at: 0 };
        w.put(&[MSG_POSE, VERSION]);
        w.put(&self.health.0.to_le_bytes());
        w.put(&[self.estimator.code(), 0]);
        w.put(&(BODY_V1 as u16).to_le_bytes());
        w.put(&self.seq.to_le_bytes());
        w.put(&self.measurement_time_ns.to_le_bytes());
        w.put(&self.host_time_ns.to_le_bytes());
        self.position.iter().for_each(|v| w.put(&v.to_le_bytes()));
        self.orientation
            .iter()
            .for_each(|v| w.put(&v.to_le_bytes()));
        self.rel_translation
            .iter()
            .for_each(|v| w.put(&v.to_le_bytes()));
        self.rel_rotation
            .iter()
            .for_each(|v| w.put(&v.to_le_bytes()));
        w.put(&self.dropped_total.to_le_bytes());
        let crc = crc32c(&w.b[..MESSAGE_LEN - 4]);
        w.put(&crc.to_le_bytes());
        Ok(MESSAGE_LEN)
    }

    /// Decodes exactly one message (a whole UDP datagram, or one COBS-decoded serial frame).
    pub fn decode(bytes: &[u8]) -> Result<PoseMessage, DecodeError> {
        if bytes.len() < HEADER_LEN {
            return Err(DecodeError::TooShort {
                need: HEADER_LEN,
                have: bytes.len(),
            });
        }
        if bytes[0] != MSG_POSE {
            return Err(DecodeError::UnknownType { ty: bytes[0] });
        }
        if bytes[1] != VERSION {
            return Err(DecodeError::UnsupportedVersion { version: bytes[1] });
        }
        let body_len = u16::from_le_bytes([bytes[6], bytes[7]]);
        if usize::from(body_len) < BODY_V1 {
            return Err(DecodeError::BodyTooShort { len: body_len });
        }
        let total = HEADER_LEN + usize::from(body_len) + 4;
        if bytes.len() < total {
            return Err(DecodeError::TooShort {
                need: total,
                have: bytes.len(),
            });
        }
        if bytes.len() > total {
            return Err(DecodeError::TooLong {
                expected: total,
                have: bytes.len(),
            });
        }
        let computed = crc32c(&bytes[..total - 4]);
        let carried = u32::from_le_bytes([
            bytes[total - 4],
            bytes[total - 3],
            bytes[total - 2],
            bytes[total - 1],
        ]);
        if computed != carried {
            return Err(DecodeError::BadCrc { computed, carried });
        }
        let mut r = R { b: bytes, at: 2 };
        let health = Health(u16::from_le_bytes(r.take()));
        let [est, _reserved] = r.take::<2>();
        let _body_len: [u8; 2] = r.take();
        let seq = u32::from_le_bytes(r.take());
        let measurement_time_ns = u64::from_le_bytes(r.take());
        let host_time_ns = u64::from_le_bytes(r.take());
        let position = [r.f64(), r.f64(), r.f64()];
        let orientation = [r.f32(), r.f32(), r.f32(), r.f32()];
        let rel_translation = [r.f32(), r.f32(), r.f32()];
        let rel_rotation = [r.f32(), r.f32(), r.f32(), r.f32()];
        let dropped_total = u32::from_le_bytes(r.take());
        Ok(PoseMessage {
            health,
            estimator: Estimator::from_code(est),
            seq,
            measurement_time_ns,
            host_time_ns,
            position,
            orientation,
            rel_translation,
            rel_rotation,
            dropped_total,
        })
    }
}
