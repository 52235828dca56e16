//! Plausibility of released frames: what the framer cannot check because the out-of-box format
//! has no checksum.
//!
//! A [`Frame`] the framer releases holds together (magic, lengths, TLV walk), but a corrupted byte
//! inside it goes unseen: a frame number, a coordinate, a velocity, a count. [`Checker`] is fed
//! every released frame in order and answers [`Verdict::Accept`] (or [`Verdict::Reanchored`]) or
//! [`Verdict::Reject`] with the [`Implausible`] reason and its evidence. It uses only what is
//! known:
//!
//! * **Frame-number continuity**: a frame must continue the last accepted one: its number in
//!   `(last, last + max_gap]` (or, with sub-frames, the same number and a later sub-frame), the
//!   same header version, platform and layout, the same compressed-point units, and, when the
//!   frame period is known and the header has a cycle counter, a cycle delta within a quarter
//!   period of `frames x period`. A frame that does not is rejected and held as a *suspect*; if
//!   the next frame continues the suspect instead, the suspect was a genuine restart or jump and
//!   the checker re-anchors on the new frame ([`Verdict::Reanchored`]). A single corrupted number
//!   is therefore rejected, a real restart costs one frame, and good frames are judged the moment
//!   they arrive (no lookahead).
//! * **The .cfg's limits** ([`Limits::from_derived`]): point range within the maximum range
//!   (+5 %), radial velocity within the maximum velocity plus one Doppler bin (twice the maximum
//!   with extendedMaxVelocity), points per frame within twice what the UART carries per frame
//!   period, sub-frame number below the number of sub-frames (0 without advanced frame config).
//! * **Always**: finite coordinates, velocities, point units and target states; numDetectedObj
//!   equal to the points TLV's count and side info (SDK 3) one entry per point; out-of-box
//!   packets padded to a multiple of 32 B with less than 32 B of padding; a sane absolute cap on
//!   points; sub-frame below the SDK's maximum of 4.
//!
//! Every verdict is counted ([`CheckCounters`], one counter per reason); nothing is dropped
//! silently. The checker is `no_std`, allocation-free, and keeps a one-frame undo so that a frame
//! the framer retracts ([`crate::FrameError::OverlapsNextFrame`]) can be taken back with
//! [`Checker::retract`] without moving the continuity anchor.

use crate::cfg::Derived;
use crate::clock::cpu_clock_hz;
use crate::frame::{Frame, Layout};
use crate::tlv::{types, Dialect, Tlv};
use core::fmt;

/// Largest frame-number step accepted without confirmation (frames lost in between).
pub const DEFAULT_MAX_GAP: u32 = 16;
/// Points per frame accepted without a .cfg (no TI demo or lab sends more).
pub const DEFAULT_MAX_POINTS: u32 = 2048;
/// Sub-frames of the SDK's advanced frame configuration at most (mmWaveLink's limit).
pub const SDK_MAX_SUBFRAMES: u32 = 4;
/// Margin on the .cfg's maximum range (fraction).
pub const RANGE_MARGIN: f64 = 0.05;
/// Tolerance of the cycle-counter check, as a fraction of one frame period (processing-time
/// jitter is well below it; one frame too many or too few is four times over it).
pub const CLOCK_TOLERANCE: f64 = 0.25;
/// Out-of-box packets are padded to a multiple of this \[B\].
pub const OOB_SEGMENT: u32 = 32;

/// What the checker holds frames to. [`Limits::default`] is what holds without a .cfg.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest point range, margin included \[m\].
    pub max_range_m: Option<f32>,
    /// Largest radial speed, margin included \[m/s\].
    pub max_velocity_mps: Option<f32>,
    /// Doppler bin size, to check SDK 1/2 Doppler indices \[m/s\].
    pub velocity_resolution_mps: Option<f32>,
    /// Most points per frame (all point TLVs together).
    pub max_points: u32,
    /// Sub-frames per frame: the sub-frame number must be below it.
    pub num_subframes: u32,
    /// Largest frame-number step accepted at once (see [`DEFAULT_MAX_GAP`]).
    pub max_gap: u32,
    /// Frame period, for the cycle-counter check \[s\].
    pub frame_period_s: Option<f64>,
    /// Out-of-box packets must be padded to 32 B (less than 32 B of padding).
    pub oob_padding: bool,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_range_m: None,
            max_velocity_mps: None,
            velocity_resolution_mps: None,
            max_points: DEFAULT_MAX_POINTS,
            num_subframes: SDK_MAX_SUBFRAMES,
            max_gap: DEFAULT_MAX_GAP,
            frame_period_s: None,
            oob_padding: true,
        }
    }
}

impl Limits {
    /// The limits a .cfg implies: range up to `max_range_m` x 1.05, radial speed up to
    /// `max_velocity_mps` (x 2 with extendedMaxVelocity) plus one Doppler bin, at most twice the
    /// points the UART carries per frame period, sub-frame below `num_subframes`, and the frame
    /// period for the cycle-counter check.
    pub fn from_derived(d: &Derived) -> Limits {
        let vmax = d.max_velocity_mps * if d.extended_max_velocity { 2.0 } else { 1.0 };
        let finite_pos = |v: f64| (v.is_finite() && v > 0.0).then_some(v);
        Limits {
            max_range_m: finite_pos(d.max_range_m).map(|r| (r * (1.0 + RANGE_MARGIN)) as f32),
            max_velocity_mps: finite_pos(vmax)
                .map(|v| (v + d.velocity_resolution_mps.max(0.0)) as f32),
            velocity_resolution_mps: finite_pos(d.velocity_resolution_mps).map(|v| v as f32),
            max_points: d.max_points_per_frame.saturating_mul(2).max(1),
            num_subframes: d.num_subframes.max(1),
            max_gap: DEFAULT_MAX_GAP,
            // frameCfg's period; advanced frame configs time their sub-frames otherwise.
            frame_period_s: finite_pos(d.frame_period_ms / 1e3).filter(|_| d.num_subframes <= 1),
            oob_padding: true,
        }
    }
}

impl From<&Derived> for Limits {
    fn from(d: &Derived) -> Self {
        Limits::from_derived(d)
    }
}

/// Which stream-identity field changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdentityField {
    /// Header layout (values: 0 oob40, 1 oob36, 2 pc48, 3 pc52).
    Layout,
    /// Header version word.
    Version,
    /// Header platform word.
    Platform,
    /// A compressed-point unit (values: its f32 bits).
    PointUnits,
}

impl IdentityField {
    /// Stable lowercase name.
    pub const fn name(self) -> &'static str {
        match self {
            IdentityField::Layout => "layout",
            IdentityField::Version => "version",
            IdentityField::Platform => "platform",
            IdentityField::PointUnits => "point_units",
        }
    }
}

/// Which two counts disagree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CountField {
    /// The header's numDetectedObj against the points TLV.
    NumDetectedObj,
    /// Side-info entries (TLV 7) against the points TLV.
    SideInfo,
}

impl CountField {
    /// Stable lowercase name.
    pub const fn name(self) -> &'static str {
        match self {
            CountField::NumDetectedObj => "num_detected_obj",
            CountField::SideInfo => "side_info",
        }
    }
}

/// Why a frame that the framer released is not plausible. Each variant carries its evidence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Implausible {
    /// The frame number does not continue the last accepted frame (nor the held suspect).
    FrameNumber {
        /// Frame number seen.
        seen: u32,
        /// Last accepted frame number; expected `last + 1 ..= last + max_gap`.
        last: u32,
        /// The largest step accepted at once.
        max_gap: u32,
    },
    /// The cycle counter does not match the frame-number step at the .cfg's frame period.
    SensorClock {
        /// Frame number seen.
        frame_number: u32,
        /// Frames since the last accepted one.
        frames: u32,
        /// Cycles since the last accepted frame (mod 2^32) \[cycles\].
        cycles: u32,
        /// Cycles expected: frames x period x clock rate \[cycles\].
        expected: u64,
        /// Tolerance either side \[cycles\].
        tolerance: u64,
    },
    /// Version, platform, layout or compressed-point units differ from the stream's.
    StreamIdentity {
        /// Field.
        field: IdentityField,
        /// Value seen.
        seen: u32,
        /// Value of the stream so far.
        expected: u32,
    },
    /// Sub-frame number out of range.
    Subframe {
        /// Sub-frame number seen.
        seen: u32,
        /// Number of sub-frames (the number must be below it).
        limit: u32,
    },
    /// More points than the limit.
    TooManyPoints {
        /// Points in the frame.
        count: u32,
        /// The limit.
        max: u32,
    },
    /// Two counts that must agree do not.
    CountMismatch {
        /// Which count.
        field: CountField,
        /// Its value.
        seen: u32,
        /// Points in the points TLV.
        points: u32,
    },
    /// A points TLV whose payload does not fit its layout.
    MalformedPoints {
        /// TLV type.
        ty: u32,
        /// Payload length \[B\].
        len: u32,
    },
    /// A NaN or infinite coordinate, velocity, unit or target value.
    NonFinite {
        /// TLV type.
        ty: u32,
        /// Point or target index (`u32::MAX`: the TLV's units).
        index: u32,
    },
    /// A point beyond the maximum range.
    Range {
        /// Point index.
        index: u32,
        /// Its range \[m\].
        range_m: f32,
        /// The limit \[m\].
        max_m: f32,
    },
    /// A radial velocity beyond the maximum.
    Velocity {
        /// Point index.
        index: u32,
        /// Its radial velocity \[m/s\].
        velocity_mps: f32,
        /// The limit on its magnitude \[m/s\].
        max_mps: f32,
    },
    /// An out-of-box packet not padded as the demo pads (numTLVs or a TLV length changed).
    Padding {
        /// totalPacketLen \[B\].
        total_len: u32,
        /// Bytes after the last TLV \[B\].
        padding: u32,
    },
}

/// Number of [`Implausible`] kinds, for per-reason counters.
pub const IMPLAUSIBLE_KINDS: usize = 11;

/// Names of the kinds, indexed by [`Implausible::kind_index`].
pub const IMPLAUSIBLE_NAMES: [&str; IMPLAUSIBLE_KINDS] = [
    "frame_number",
    "sensor_clock",
    "stream_identity",
    "subframe",
    "too_many_points",
    "count_mismatch",
    "malformed_points",
    "non_finite",
    "range",
    "velocity",
    "padding",
];

impl Implausible {
    /// Stable index of the kind (0..[`IMPLAUSIBLE_KINDS`]).
    pub const fn kind_index(&self) -> usize {
        match self {
            Self::FrameNumber { .. } => 0,
            Self::SensorClock { .. } => 1,
            Self::StreamIdentity { .. } => 2,
            Self::Subframe { .. } => 3,
            Self::TooManyPoints { .. } => 4,
            Self::CountMismatch { .. } => 5,
            Self::MalformedPoints { .. } => 6,
            Self::NonFinite { .. } => 7,
            Self::Range { .. } => 8,
            Self::Velocity { .. } => 9,
            Self::Padding { .. } => 10,
        }
    }

    /// Stable snake_case name of the kind.
    pub const fn kind_name(&self) -> &'static str {
        IMPLAUSIBLE_NAMES[self.kind_index()]
    }

    /// True for the reasons that concern the frame's place in the stream (number, clock,
    /// identity) rather than its content.
    pub const fn is_continuity(&self) -> bool {
        matches!(
            self,
            Self::FrameNumber { .. } | Self::SensorClock { .. } | Self::StreamIdentity { .. }
        )
    }
}

impl fmt::Display for Implausible {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::FrameNumber { seen, last, max_gap } => write!(
                f,
                "frame number {seen} does not follow {last} (expected {}..={})",
                last.wrapping_add(1),
                last.wrapping_add(max_gap)
            ),
            Self::SensorClock {
                frame_number,
                frames,
                cycles,
                expected,
                tolerance,
            } => write!(
                f,
                "frame {frame_number}: {cycles} cycles since the last frame, {frames} frame(s) at the .cfg's period need {expected} +- {tolerance}"
            ),
            Self::StreamIdentity {
                field,
                seen,
                expected,
            } => write!(
                f,
                "{} {seen:#x} differs from the stream's {expected:#x}",
                field.name()
            ),
            Self::Subframe { seen, limit } => {
                write!(f, "sub-frame {seen} with {limit} sub-frame(s) configured")
            }
            Self::TooManyPoints { count, max } => {
                write!(f, "{count} points in one frame, at most {max} plausible")
            }
            Self::CountMismatch {
                field,
                seen,
                points,
            } => write!(
                f,
                "{} says {seen}, the points TLV holds {points}",
                field.name()
            ),
            Self::MalformedPoints { ty, len } => {
                write!(f, "points TLV type {ty} of {len} B does not fit its layout")
            }
            Self::NonFinite { ty, index } if index == u32::MAX => {
                write!(f, "TLV type {ty}: a unit is NaN or infinite")
            }
            Self::NonFinite { ty, index } => {
                write!(f, "TLV type {ty}, entry {index}: NaN or infinite value")
            }
            Self::Range {
                index,
                range_m,
                max_m,
            } => write!(f, "point {index} at {range_m} m, beyond {max_m} m"),
            Self::Velocity {
                index,
                velocity_mps,
                max_mps,
            } => write!(
                f,
                "point {index} moves at {velocity_mps} m/s, beyond +-{max_mps} m/s"
            ),
            Self::Padding { total_len, padding } => write!(
                f,
                "out-of-box packet of {total_len} B with {padding} B of padding (padded to 32 B: less than 32)"
            ),
        }
    }
}

impl core::error::Error for Implausible {}

/// What to do with a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Plausible: pass it on.
    Accept,
    /// Plausible, and it confirmed the previously rejected frame as a genuine restart or jump:
    /// the stream continues from here (pass it on).
    Reanchored,
    /// Not plausible: drop it (counted).
    Reject(Implausible),
}

impl Verdict {
    /// True for [`Verdict::Accept`] and [`Verdict::Reanchored`].
    pub const fn is_accept(&self) -> bool {
        !matches!(self, Verdict::Reject(_))
    }
}

/// Counters since the checker was created (or since the frames they count were retracted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CheckCounters {
    /// Frames accepted (re-anchors included).
    pub accepted: u64,
    /// Frames rejected, indexed by [`Implausible::kind_index`].
    pub rejected: [u64; IMPLAUSIBLE_KINDS],
    /// Accepted frames that confirmed a restart or jump.
    pub reanchored: u64,
    /// Frames taken back with [`Checker::retract`] (no longer in `accepted` or `rejected`).
    pub retracted: u64,
}

impl CheckCounters {
    /// Total rejected frames.
    pub fn rejected_total(&self) -> u64 {
        self.rejected.iter().sum()
    }

    /// `(name, count)` per reason, in [`IMPLAUSIBLE_NAMES`] order.
    pub fn by_reason(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        IMPLAUSIBLE_NAMES
            .iter()
            .copied()
            .zip(self.rejected.iter().copied())
    }
}

/// Where a frame sits in the stream: what the next frame must continue.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Anchor {
    number: u32,
    subframe: u32,
    /// Cycle counter and its rate \[Hz\].
    cycles: Option<(u32, u32)>,
    layout: Layout,
    version: u32,
    platform: u32,
    /// Compressed-point units (f32 bits), once a frame carried them.
    units: Option<[u32; 5]>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct State {
    anchor: Option<Anchor>,
    suspect: Option<Anchor>,
    counters: CheckCounters,
}

/// The plausibility checker (see the [module docs](self)).
///
/// ```
/// use radar_driver::{Frame, Layout, encode::FrameBuilder};
/// use radar_driver::plausible::{Checker, Limits};
/// let mut checker = Checker::new(Limits { max_range_m: Some(10.0), ..Limits::default() });
/// let mut buf = [0u8; 128];
/// for (n, y, ok) in [(7, 2.0, true), (8, 2.5, true), (9, 99.0, false), (200, 2.0, false), (10, 2.0, true)] {
///     let pts = [[0.0, y, 0.0, 0.0]];
///     let len = FrameBuilder::oob(0x0303_0002, 0xA6843, n).points(&pts).write(&mut buf).unwrap();
///     let frame = Frame::new_checked(&buf[..len], Layout::Oob40).unwrap();
///     assert_eq!(checker.check(&frame).is_accept(), ok, "frame {n}");
/// }
/// assert_eq!(checker.counters().rejected_total(), 2);
/// ```
#[derive(Debug, Clone)]
pub struct Checker {
    limits: Limits,
    state: State,
    undo: Option<State>,
}

impl Default for Checker {
    fn default() -> Self {
        Checker::new(Limits::default())
    }
}

impl Checker {
    /// A checker holding frames to `limits`.
    pub fn new(limits: Limits) -> Self {
        Checker {
            limits,
            state: State {
                anchor: None,
                suspect: None,
                counters: CheckCounters::default(),
            },
            undo: None,
        }
    }

    /// The limits in force.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Counters so far.
    pub fn counters(&self) -> &CheckCounters {
        &self.state.counters
    }

    /// Number of the last accepted frame (the continuity anchor).
    pub fn last_frame_number(&self) -> Option<u32> {
        self.state.anchor.map(|a| a.number)
    }

    /// Judges the next frame of the stream (in order) and counts the verdict.
    pub fn check(&mut self, frame: &Frame<'_>) -> Verdict {
        self.undo = Some(self.state);
        let v = self.judge(frame);
        let c = &mut self.state.counters;
        match v {
            Verdict::Accept => c.accepted += 1,
            Verdict::Reanchored => {
                c.accepted += 1;
                c.reanchored += 1;
            }
            Verdict::Reject(r) => c.rejected[r.kind_index()] += 1,
        }
        v
    }

    /// Takes back the last frame checked (the framer retracted it: it lost bytes on the wire):
    /// the continuity anchor, the suspect and the counters return to what they were before it,
    /// and `retracted` counts it. Only the last frame can be retracted; a second call does
    /// nothing.
    pub fn retract(&mut self) {
        if let Some(s) = self.undo.take() {
            self.state = s;
            self.state.counters.retracted += 1;
        }
    }

    fn judge(&mut self, frame: &Frame<'_>) -> Verdict {
        let units = match self.content(frame) {
            Ok(u) => u,
            Err(r) => return Verdict::Reject(r),
        };
        let h = frame.header();
        let mut cur = Anchor {
            number: h.frame_number,
            subframe: h.subframe.unwrap_or(0),
            cycles: h.time_cpu_cycles.map(|c| (c, cpu_clock_hz(h))),
            layout: h.layout,
            version: h.version.0,
            platform: h.platform,
            units,
        };
        let st = &mut self.state;
        let Some(anchor) = st.anchor else {
            st.anchor = Some(cur);
            st.suspect = None;
            return Verdict::Accept;
        };
        match continues(&self.limits, &anchor, &cur) {
            Ok(()) => {
                cur.units = cur.units.or(anchor.units);
                st.anchor = Some(cur);
                st.suspect = None;
                Verdict::Accept
            }
            Err(r) => {
                if let Some(s) = st.suspect {
                    if continues(&self.limits, &s, &cur).is_ok() {
                        cur.units = cur.units.or(s.units);
                        st.anchor = Some(cur);
                        st.suspect = None;
                        return Verdict::Reanchored;
                    }
                }
                st.suspect = Some(cur);
                Verdict::Reject(r)
            }
        }
    }

    /// The checks that need only the frame itself; returns the compressed-point units if any.
    fn content(&self, frame: &Frame<'_>) -> Result<Option<[u32; 5]>, Implausible> {
        let l = &self.limits;
        let h = frame.header();
        if let Some(sf) = h.subframe {
            let limit = l.num_subframes.clamp(1, SDK_MAX_SUBFRAMES);
            if sf >= limit {
                return Err(Implausible::Subframe { seen: sf, limit });
            }
        }
        if l.oob_padding && frame.layout().is_padded() {
            let padding = frame.padding_len() as u32;
            if !h.total_len.is_multiple_of(OOB_SEGMENT) || padding >= OOB_SEGMENT {
                return Err(Implausible::Padding {
                    total_len: h.total_len,
                    padding,
                });
            }
        }
        let dialect = Dialect::of(frame);
        let oob_sdk = match dialect {
            Dialect::Oob { sdk_major } => Some(sdk_major),
            Dialect::PeopleCounting => None,
        };
        let max_r2 = l.max_range_m.map(|r| r * r);
        let range = |index: usize, x: f32, y: f32, z: f32| -> Result<(), Implausible> {
            if let Some(m2) = max_r2 {
                let r2 = x * x + y * y + z * z;
                if r2 > m2 {
                    return Err(Implausible::Range {
                        index: index as u32,
                        range_m: libm::sqrtf(r2),
                        max_m: l.max_range_m.unwrap_or(0.0),
                    });
                }
            }
            Ok(())
        };
        let velocity = |index: usize, v: f32| -> Result<(), Implausible> {
            match l.max_velocity_mps {
                Some(m) if libm::fabsf(v) > m => Err(Implausible::Velocity {
                    index: index as u32,
                    velocity_mps: v,
                    max_mps: m,
                }),
                _ => Ok(()),
            }
        };
        let mut points: u32 = 0;
        let mut tlv1_points: Option<u32> = None;
        let mut side_info: Option<u32> = None;
        let mut units = None;
        for raw in frame.tlvs() {
            let is_points_type = match dialect {
                Dialect::Oob { .. } => {
                    raw.ty == types::POINTS || raw.ty == types::COMPRESSED_POINTS
                }
                Dialect::PeopleCounting => raw.ty == types::PC_COMPRESSED_POINTS,
            };
            let tlv = match raw.decode(dialect) {
                Ok(t) => t,
                Err(_) if is_points_type => {
                    return Err(Implausible::MalformedPoints {
                        ty: raw.ty,
                        len: raw.payload.len() as u32,
                    })
                }
                // Labs reuse other known types for payloads of their own: not a defect.
                Err(_) => continue,
            };
            let ty = raw.ty;
            match tlv {
                Tlv::Points(p) => {
                    for (i, q) in p.iter().enumerate() {
                        if !(q.x.is_finite()
                            && q.y.is_finite()
                            && q.z.is_finite()
                            && q.velocity.is_finite())
                        {
                            return Err(Implausible::NonFinite {
                                ty,
                                index: i as u32,
                            });
                        }
                        range(i, q.x, q.y, q.z)?;
                        velocity(i, q.velocity)?;
                    }
                    let n = p.len() as u32;
                    points = points.saturating_add(n);
                    tlv1_points = Some(tlv1_points.unwrap_or(0).saturating_add(n));
                }
                Tlv::PointsQ(p) => {
                    for (i, q) in p.iter().enumerate() {
                        range(i, q.x, q.y, q.z)?;
                        if let Some(vres) = l.velocity_resolution_mps {
                            velocity(i, f32::from(q.doppler_idx) * vres)?;
                        }
                    }
                    let n = p.len() as u32;
                    points = points.saturating_add(n);
                    tlv1_points = Some(tlv1_points.unwrap_or(0).saturating_add(n));
                }
                Tlv::CompressedPoints(c) => {
                    let u = c.units();
                    let all = [u.elevation, u.azimuth, u.doppler, u.range, u.snr];
                    if !all.iter().all(|v| v.is_finite()) {
                        return Err(Implausible::NonFinite {
                            ty,
                            index: u32::MAX,
                        });
                    }
                    units.get_or_insert(all.map(f32::to_bits));
                    for (i, s) in c.iter().enumerate() {
                        // Ranges are non-negative (u16 x unit); only the unit's sign matters.
                        let r = libm::fabsf(s.range);
                        range(i, r, 0.0, 0.0)?;
                        velocity(i, s.doppler)?;
                    }
                    points = points.saturating_add(c.len() as u32);
                }
                Tlv::Targets(t) => {
                    for (i, tg) in t.iter().enumerate() {
                        let finite = tg
                            .position
                            .iter()
                            .chain(&tg.velocity)
                            .chain(&tg.acceleration)
                            .chain(&tg.error_covariance)
                            .chain([&tg.gain, &tg.confidence])
                            .all(|v| v.is_finite());
                        if !finite {
                            return Err(Implausible::NonFinite {
                                ty,
                                index: i as u32,
                            });
                        }
                    }
                }
                Tlv::SideInfo(s) if oob_sdk.is_some_and(|m| m >= 3) => {
                    side_info = Some(side_info.unwrap_or(0).saturating_add(s.len() as u32));
                }
                _ => {}
            }
        }
        if points > l.max_points {
            return Err(Implausible::TooManyPoints {
                count: points,
                max: l.max_points,
            });
        }
        if let Some(n) = tlv1_points {
            if let Some(obj) = h.num_detected_obj {
                if obj != n {
                    return Err(Implausible::CountMismatch {
                        field: CountField::NumDetectedObj,
                        seen: obj,
                        points: n,
                    });
                }
            }
            if let Some(s) = side_info {
                if s != n {
                    return Err(Implausible::CountMismatch {
                        field: CountField::SideInfo,
                        seen: s,
                        points: n,
                    });
                }
            }
        }
        Ok(units)
    }
}

const fn layout_code(l: Layout) -> u32 {
    match l {
        Layout::Oob40 => 0,
        Layout::Oob36 => 1,
        Layout::PeopleCounting48 => 2,
        Layout::PeopleCounting52 => 3,
    }
}

/// Whether `cur` continues the stream at `a`.
fn continues(l: &Limits, a: &Anchor, cur: &Anchor) -> Result<(), Implausible> {
    let identity = |field, seen: u32, expected: u32| {
        if seen == expected {
            Ok(())
        } else {
            Err(Implausible::StreamIdentity {
                field,
                seen,
                expected,
            })
        }
    };
    identity(
        IdentityField::Layout,
        layout_code(cur.layout),
        layout_code(a.layout),
    )?;
    identity(IdentityField::Version, cur.version, a.version)?;
    identity(IdentityField::Platform, cur.platform, a.platform)?;
    if let (Some(u), Some(e)) = (cur.units, a.units) {
        for (s, e) in u.iter().zip(e.iter()) {
            identity(IdentityField::PointUnits, *s, *e)?;
        }
    }
    let d = cur.number.wrapping_sub(a.number);
    let next_subframe = l.num_subframes > 1 && d == 0 && cur.subframe > a.subframe;
    // Sub-frames of an advanced frame config follow their own timing: no clock check across them.
    let subframes = cur.subframe > 0 || a.subframe > 0;
    if !(next_subframe || (1..=l.max_gap.max(1)).contains(&d)) {
        return Err(Implausible::FrameNumber {
            seen: cur.number,
            last: a.number,
            max_gap: l.max_gap.max(1),
        });
    }
    if let (Some((c, hz)), Some((ca, hza)), Some(p), false) =
        (cur.cycles, a.cycles, l.frame_period_s, subframes)
    {
        let per_frame = p * f64::from(hz);
        let expected = f64::from(d) * per_frame;
        // Only where the 32-bit counter cannot have wrapped ambiguously.
        if hz == hza && expected < 2_147_483_648.0 {
            let delta = c.wrapping_sub(ca);
            let tolerance = CLOCK_TOLERANCE * per_frame;
            if libm::fabs(f64::from(delta) - expected) > tolerance {
                return Err(Implausible::SensorClock {
                    frame_number: cur.number,
                    frames: d,
                    cycles: delta,
                    expected: expected as u64,
                    tolerance: tolerance as u64,
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfg::RadarConfig;
    use crate::encode::{CompressedRaw, FrameBuilder, QPointRaw, TlvOut};
    use crate::tlv::{CompressedUnits, Target};

    const V3: u32 = 0x0303_0002;
    const P68: u32 = 0xA6843;
    /// 100 ms at 200 MHz.
    const CYC: u32 = 20_000_000;

    fn cfg_limits() -> Limits {
        // ad_ISK.cfg's chirp: 60.5 GHz, 50 MHz/us, 256 samples at 6 Msps, 3 TX x 32 loops, 100 ms.
        let text =
            "channelCfg 15 7 0\nadcCfg 2 1\nprofileCfg 0 60.5 100 25 69 0 0 50 1 256 6000 0 0 30\n\
            chirpCfg 0 0 0 0 0 0 0 1\nchirpCfg 1 1 0 0 0 0 0 2\nchirpCfg 2 2 0 0 0 0 0 4\n\
            frameCfg 0 2 32 0 100 1 0\nguiMonitor -1 1 0 0 0 0 0\n";
        Limits::from_derived(&RadarConfig::parse(text).unwrap().derive(None).unwrap())
    }

    /// An SDK 3 frame with these points and the cycle counter of a 100 ms stream.
    fn oob(n: u32, pts: &[[f32; 4]]) -> Vec<u8> {
        FrameBuilder::oob(V3, P68, n)
            .cycles(n.wrapping_mul(CYC))
            .points(pts)
            .to_vec()
    }

    fn check(c: &mut Checker, bytes: &[u8]) -> Verdict {
        let layout = crate::frame::Layout::oob_for(V3, P68);
        let layout =
            if bytes.len() >= 48 && crate::frame::ones_complement_fold(&bytes[..48]) == 0xFFFF {
                Layout::PeopleCounting48
            } else {
                layout
            };
        c.check(&Frame::new_checked(bytes, layout).unwrap())
    }

    fn kind(v: Verdict) -> &'static str {
        match v {
            Verdict::Accept => "accept",
            Verdict::Reanchored => "reanchored",
            Verdict::Reject(r) => r.kind_name(),
        }
    }

    const PT: [[f32; 4]; 1] = [[0.5, 2.0, 0.1, -0.3]];

    #[test]
    fn limits_follow_the_cfg() {
        let l = cfg_limits();
        // c fs / 2S = 3e8 x 6e6 / (2 x 50e12) = 18 m (complex ADC), + 5 %.
        let r = l.max_range_m.unwrap();
        assert!((r - 18.0 * 1.05).abs() < 0.1, "{r}");
        let v = l.max_velocity_mps.unwrap();
        let vres = l.velocity_resolution_mps.unwrap();
        assert!(
            (v - 17.0 * vres).abs() < 1e-4,
            "16 bins of {vres} + one: {v}"
        );
        assert_eq!(l.num_subframes, 1);
        assert!((l.frame_period_s.unwrap() - 0.1).abs() < 1e-9);
        assert!(l.max_points >= 400, "{}", l.max_points);
    }

    #[test]
    fn consecutive_frames_and_small_gaps_are_accepted_at_once() {
        let mut c = Checker::new(cfg_limits());
        for n in [100, 101, 102, 110, 111, 111 + DEFAULT_MAX_GAP] {
            assert_eq!(kind(check(&mut c, &oob(n, &PT))), "accept", "frame {n}");
        }
        assert_eq!(c.counters().accepted, 6);
        assert_eq!(c.counters().rejected_total(), 0);
    }

    #[test]
    fn a_single_corrupted_frame_number_is_rejected() {
        let mut c = Checker::default();
        check(&mut c, &oob(100, &PT));
        // High byte, low byte behind, the same number again, one gap too many.
        for (bad, good) in [
            (100 + (1 << 24), 101),
            (90, 102),
            (102, 103),
            (104 + DEFAULT_MAX_GAP, 104),
        ] {
            let mut f = oob(good, &PT);
            f[20..24].copy_from_slice(&bad.to_le_bytes());
            match check(&mut c, &f) {
                Verdict::Reject(Implausible::FrameNumber {
                    seen,
                    last,
                    max_gap,
                }) => {
                    assert_eq!((seen, last + 1, max_gap), (bad, good, DEFAULT_MAX_GAP));
                }
                v => panic!("{bad}: {v:?}"),
            }
            // The stream goes on from the good frames; nothing is lost.
            assert_eq!(kind(check(&mut c, &oob(good, &PT))), "accept");
        }
        assert_eq!(c.counters().rejected[0], 4);
        assert_eq!(c.counters().reanchored, 0);
    }

    #[test]
    fn a_restart_or_a_long_jump_is_accepted_once_confirmed() {
        let mut c = Checker::new(cfg_limits());
        for n in 500..505 {
            check(&mut c, &oob(n, &PT));
        }
        // sensorStop / sensorStart: numbers (and cycles) start again at 1.
        let seq = [(1, "frame_number"), (2, "reanchored"), (3, "accept")];
        for (n, want) in seq {
            assert_eq!(kind(check(&mut c, &oob(n, &PT))), want, "frame {n}");
        }
        // A real jump (the host lost a second of data): confirmed by the next frame.
        for (n, want) in [(60, "frame_number"), (61, "reanchored"), (62, "accept")] {
            assert_eq!(kind(check(&mut c, &oob(n, &PT))), want, "frame {n}");
        }
        assert_eq!(c.counters().reanchored, 2);
        assert_eq!(c.last_frame_number(), Some(62));
    }

    #[test]
    fn cycle_counter_must_match_the_frame_step() {
        let mut c = Checker::new(cfg_limits());
        check(&mut c, &oob(10, &PT));
        // Number 11 -> 12 (in the window) but the clock says one frame: corrupted number.
        let mut f = oob(11, &PT);
        f[20..24].copy_from_slice(&12u32.to_le_bytes());
        match check(&mut c, &f) {
            Verdict::Reject(Implausible::SensorClock {
                frame_number,
                frames,
                cycles,
                expected,
                tolerance,
            }) => {
                assert_eq!((frame_number, frames, cycles), (12, 2, CYC));
                assert!(expected.abs_diff(2 * u64::from(CYC)) <= 1, "{expected}");
                assert!(tolerance.abs_diff(u64::from(CYC) / 4) <= 1, "{tolerance}");
            }
            v => panic!("{v:?}"),
        }
        // Jitter well inside a quarter period passes; the counter wrapping passes.
        let mut f = oob(11, &PT);
        f[24..28].copy_from_slice(&(11 * CYC + 3_000_000).to_le_bytes());
        assert_eq!(kind(check(&mut c, &f)), "accept");
        let mut c = Checker::new(cfg_limits());
        let wrap = u32::MAX - CYC / 2;
        let f = FrameBuilder::oob(V3, P68, 1)
            .cycles(wrap)
            .points(&PT)
            .to_vec();
        check(&mut c, &f);
        let f = FrameBuilder::oob(V3, P68, 2)
            .cycles(wrap.wrapping_add(CYC))
            .points(&PT)
            .to_vec();
        assert_eq!(kind(check(&mut c, &f)), "accept");
        // Without a frame period there is no clock check.
        let mut c = Checker::default();
        check(&mut c, &oob(10, &PT));
        let mut f = oob(11, &PT);
        f[20..24].copy_from_slice(&12u32.to_le_bytes());
        assert_eq!(kind(check(&mut c, &f)), "accept");
    }

    #[test]
    fn stream_identity_changes_are_suspect() {
        let mut c = Checker::default();
        check(&mut c, &oob(1, &PT));
        let f = FrameBuilder::oob(0x0303_0102, P68, 2).points(&PT).to_vec();
        assert_eq!(
            check(&mut c, &f),
            Verdict::Reject(Implausible::StreamIdentity {
                field: IdentityField::Version,
                seen: 0x0303_0102,
                expected: V3
            })
        );
        let f = FrameBuilder::oob(V3, 0xA1843, 3).points(&PT).to_vec();
        assert_eq!(kind(check(&mut c, &f)), "stream_identity");
        // A new device (reflashed, swapped) confirmed by its next frame.
        let f = FrameBuilder::oob(V3, 0xA1843, 4).points(&PT).to_vec();
        assert_eq!(kind(check(&mut c, &f)), "reanchored");
    }

    #[test]
    fn range_velocity_and_finite_values_follow_the_cfg() {
        let l = cfg_limits();
        let (rmax, vmax) = (l.max_range_m.unwrap(), l.max_velocity_mps.unwrap());
        let mut c = Checker::new(l);
        let cases: [([f32; 4], &str); 7] = [
            ([0.0, 18.5, 0.0, 0.0], "accept"),
            ([0.0, rmax + 0.1, 0.0, 0.0], "range"),
            ([0.0, 3.0, 0.0, vmax - 0.01], "accept"),
            ([0.0, 3.0, 0.0, -vmax - 0.01], "velocity"),
            ([f32::NAN, 3.0, 0.0, 0.0], "non_finite"),
            ([0.0, 3.0, 0.0, f32::INFINITY], "non_finite"),
            ([0.0, 3.0, f32::NEG_INFINITY, 0.0], "non_finite"),
        ];
        for (k, (p, want)) in cases.iter().enumerate() {
            let pts = [PT[0], *p];
            let v = check(&mut c, &oob(k as u32 + 1, &pts));
            assert_eq!(kind(v), *want, "{p:?}: {v:?}");
            if let Verdict::Reject(Implausible::Range {
                index,
                range_m,
                max_m,
            }) = v
            {
                assert_eq!(index, 1);
                assert!((range_m - rmax - 0.1).abs() < 1e-3 && max_m == rmax);
            }
        }
        // Without a .cfg only finiteness is checked.
        let mut c = Checker::default();
        assert_eq!(
            kind(check(&mut c, &oob(1, &[[0.0, 500.0, 0.0, 90.0]]))),
            "accept"
        );
        assert_eq!(
            kind(check(&mut c, &oob(2, &[[0.0, f32::NAN, 0.0, 0.0]]))),
            "non_finite"
        );
    }

    #[test]
    fn rejected_content_does_not_move_the_anchor() {
        let mut c = Checker::default();
        check(&mut c, &oob(5, &PT));
        assert_eq!(kind(check(&mut c, &oob(6, &[[f32::NAN; 4]]))), "non_finite");
        assert_eq!(c.last_frame_number(), Some(5));
        assert_eq!(kind(check(&mut c, &oob(7, &PT))), "accept");
    }

    #[test]
    fn sdk2_doppler_indices_use_the_velocity_resolution() {
        let l = Limits {
            velocity_resolution_mps: Some(0.1),
            max_velocity_mps: Some(1.7),
            ..Limits::default()
        };
        let mut c = Checker::new(l);
        let q = |d: i16| QPointRaw {
            range_idx: 10,
            doppler_idx: d,
            peak: 100,
            xyz: [0, 1024, 0],
        };
        let v2 = 0x0200_0004;
        for (n, d, want) in [(1, 16, "accept"), (2, -18, "velocity")] {
            let pts = [q(d)];
            let f = FrameBuilder::oob(v2, 0xA1642, n)
                .tlv(TlvOut::PointsQ(9, &pts))
                .to_vec();
            assert_eq!(kind(check(&mut c, &f)), want, "doppler {d}");
        }
    }

    #[test]
    fn counts_must_agree_and_stay_bounded() {
        let mut c = Checker::new(Limits {
            max_points: 3,
            ..Limits::default()
        });
        let pts = [PT[0]; 2];
        let mut b = FrameBuilder::oob(V3, P68, 1).points(&pts);
        b.num_detected_obj = Some(3);
        assert_eq!(
            check(&mut c, &b.to_vec()),
            Verdict::Reject(Implausible::CountMismatch {
                field: CountField::NumDetectedObj,
                seen: 3,
                points: 2
            })
        );
        let side = [(100i16, 50i16)];
        let f = FrameBuilder::oob(V3, P68, 2)
            .points(&pts)
            .tlv(TlvOut::SideInfo(&side))
            .to_vec();
        assert_eq!(kind(check(&mut c, &f)), "count_mismatch");
        let four = [PT[0]; 4];
        assert_eq!(
            check(&mut c, &oob(3, &four)),
            Verdict::Reject(Implausible::TooManyPoints { count: 4, max: 3 })
        );
        // The zero-point quirk (empty TLV 1, numDetectedObj 0, no side info) is fine.
        assert_eq!(kind(check(&mut c, &oob(4, &[]))), "accept");
        // Frames without a points TLV (lab payloads) say nothing about numDetectedObj.
        let mut b = FrameBuilder::oob(V3, P68, 5).tlv(TlvOut::Raw(0x2000, &[1, 2, 3, 4]));
        b.num_detected_obj = Some(99);
        assert_eq!(kind(check(&mut c, &b.to_vec())), "accept");
    }

    #[test]
    fn points_tlv_that_does_not_decode_is_rejected() {
        let mut c = Checker::default();
        let f = FrameBuilder::oob(V3, P68, 1)
            .tlv(TlvOut::Raw(types::POINTS, &[0; 20]))
            .to_vec();
        assert_eq!(
            check(&mut c, &f),
            Verdict::Reject(Implausible::MalformedPoints { ty: 1, len: 20 })
        );
        // Another known type with a lab's own payload passes (the vital-signs lab does this).
        let f = FrameBuilder::oob(V3, P68, 2)
            .tlv(TlvOut::Raw(types::STATS, &[0; 128]))
            .to_vec();
        assert_eq!(kind(check(&mut c, &f)), "accept");
    }

    #[test]
    fn subframe_must_be_configured() {
        let mut c = Checker::new(cfg_limits());
        let mut b = FrameBuilder::oob(V3, P68, 1).cycles(CYC).points(&PT);
        b.subframe = 1;
        assert_eq!(
            check(&mut c, &b.to_vec()),
            Verdict::Reject(Implausible::Subframe { seen: 1, limit: 1 })
        );
        // Advanced frame config with 2 sub-frames: 0 and 1 under one number, then the next.
        let mut c = Checker::new(Limits {
            num_subframes: 2,
            ..cfg_limits()
        });
        for (n, sf, want) in [
            (1, 0, "accept"),
            (1, 1, "accept"),
            (2, 0, "accept"),
            (2, 2, "subframe"),
            (2, 0, "frame_number"),
        ] {
            let mut b = FrameBuilder::oob(V3, P68, n).points(&PT);
            b.subframe = sf;
            assert_eq!(kind(check(&mut c, &b.to_vec())), want, "{n}/{sf}");
        }
        // Without a .cfg: below the SDK's 4.
        let mut c = Checker::default();
        let mut b = FrameBuilder::oob(V3, P68, 1).points(&PT);
        b.subframe = 4;
        assert_eq!(kind(check(&mut c, &b.to_vec())), "subframe");
    }

    #[test]
    fn padding_of_out_of_box_packets() {
        let mut c = Checker::default();
        let mut b = FrameBuilder::oob(V3, P68, 1).points(&PT);
        b.extra_len = 32;
        assert_eq!(
            check(&mut c, &b.to_vec()),
            Verdict::Reject(Implausible::Padding {
                total_len: 96,
                padding: 32
            })
        );
        let mut b = FrameBuilder::oob(V3, P68, 1).points(&PT);
        b.extra_len = 4;
        assert_eq!(kind(check(&mut c, &b.to_vec())), "padding");
        let mut c = Checker::new(Limits {
            oob_padding: false,
            ..Limits::default()
        });
        assert_eq!(kind(check(&mut c, &b.to_vec())), "accept");
    }

    #[test]
    fn people_counting_points_targets_and_units() {
        let units = CompressedUnits {
            elevation: 0.01,
            azimuth: 0.01,
            doppler: 0.00028,
            range: 0.00025,
            snr: 0.04,
        };
        let p = |range: u16, doppler: i16| CompressedRaw {
            elevation: 3,
            azimuth: -20,
            doppler,
            range,
            snr: 300,
        };
        let pc = |n: u32, u: CompressedUnits, pts: &[CompressedRaw], tg: &[Target]| {
            FrameBuilder::new(Layout::PeopleCounting48, 0x0305_0004, P68, n)
                .tlv(TlvOut::Compressed(types::PC_COMPRESSED_POINTS, u, pts))
                .tlv(TlvOut::Targets(types::PC_TARGETS, tg))
                .to_vec()
        };
        let mut c = Checker::new(Limits {
            max_range_m: Some(8.0),
            max_velocity_mps: Some(5.0),
            ..Limits::default()
        });
        let t = Target {
            tid: 1,
            position: [0.5, 3.0, 1.0],
            ..Target::default()
        };
        let mut bad_t = t;
        bad_t.error_covariance[5] = f32::NAN;
        let cases = [
            (1, units, p(12_000, 1000), t, "accept"),
            (2, units, p(40_000, 1000), t, "range"),
            (3, units, p(12_000, -20_000), t, "velocity"),
            (4, units, p(12_000, 1000), bad_t, "non_finite"),
            (
                5,
                CompressedUnits {
                    range: f32::NAN,
                    ..units
                },
                p(1, 1),
                t,
                "non_finite",
            ),
            (
                6,
                CompressedUnits {
                    range: 0.0005,
                    ..units
                },
                p(1, 1),
                t,
                "stream_identity",
            ),
            (7, units, p(12_000, 1000), t, "accept"),
        ];
        for (n, u, pt, tg, want) in cases {
            let v = check(&mut c, &pc(n, u, &[pt], &[tg]));
            assert_eq!(kind(v), want, "frame {n}: {v:?}");
        }
    }

    #[test]
    fn retract_restores_the_anchor_and_the_counters() {
        let mut c = Checker::new(cfg_limits());
        check(&mut c, &oob(10, &PT));
        // Frame 11 is accepted, then the framer retracts it (it lost bytes).
        assert_eq!(kind(check(&mut c, &oob(11, &PT))), "accept");
        let before = c.counters().accepted;
        c.retract();
        assert_eq!(c.last_frame_number(), Some(10), "the anchor is back at 10");
        assert_eq!(c.counters().accepted, before - 1);
        assert_eq!(c.counters().retracted, 1);
        c.retract();
        assert_eq!(
            c.counters().retracted,
            1,
            "only the last frame can be retracted"
        );
        // The retracted frame's bytes were shifted: its number may have read high. Had the
        // anchor moved there, frame 12 would now be rejected.
        let mut f = oob(11, &PT);
        f[20..24].copy_from_slice(&20u32.to_le_bytes());
        f[24..28].copy_from_slice(&(20 * CYC).to_le_bytes());
        assert_eq!(kind(check(&mut c, &f)), "accept");
        c.retract();
        assert_eq!(kind(check(&mut c, &oob(12, &PT))), "accept");
        // A rejected frame that is retracted is no longer a suspect nor counted as rejected.
        let mut f = oob(13, &PT);
        f[20..24].copy_from_slice(&900u32.to_le_bytes());
        assert_eq!(kind(check(&mut c, &f)), "frame_number");
        c.retract();
        assert_eq!(c.counters().rejected_total(), 0);
        assert_eq!(
            kind(check(&mut c, &oob(901, &PT))),
            "frame_number",
            "900 was forgotten"
        );
        assert_eq!(c.counters().reanchored, 0);
    }
}
