//! Sensor time: SampleTimeFine unwrapping, PacketCounter continuity, and plausibility checks that
//! flag frames the 8-bit checksum let through.

use crate::mtdata2::Sample;

/// SampleTimeFine ticks per second (10 kHz).
pub const TICKS_PER_SECOND: u64 = 10_000;

/// Where SampleTimeFine wraps, which depends on the device family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeWrap {
    /// 2^32 ticks (MTi-1 and MTi-600 series). Note: adding 0xFFFF_FFFF per wrap, as one official
    /// driver does, is off by one tick per wrap.
    Pow32,
    /// 864,000,000 ticks, one day (MTi-10/100 series).
    Day,
}

impl TimeWrap {
    /// The modulus in ticks.
    pub const fn modulus(self) -> u64 {
        match self {
            Self::Pow32 => 1 << 32,
            Self::Day => 864_000_000,
        }
    }
}

/// Unwraps SampleTimeFine into a monotonic tick count.
///
/// Each raw value is placed in the wrap period (previous, current or next) that puts it closest to
/// the last unwrapped value, so a message whose time is a little earlier (GNSS PVT messages run
/// 40-60 ms behind the inertial ones) is not mistaken for a wrap.
#[derive(Debug, Clone, Copy)]
pub struct SampleTimeUnwrapper {
    wrap: TimeWrap,
    last: Option<u64>,
}

impl SampleTimeUnwrapper {
    /// An unwrapper for the given device family.
    pub const fn new(wrap: TimeWrap) -> Self {
        Self { wrap, last: None }
    }

    /// Unwrapped ticks for a raw SampleTimeFine (raw values at or above a day modulus are
    /// reduced modulo it).
    pub fn unwrap(&mut self, raw: u32) -> u64 {
        let m = self.wrap.modulus();
        let raw = u64::from(raw) % m;
        let t = match self.last {
            None => raw,
            Some(last) => {
                let base = last - last % m;
                let candidates = [
                    base.checked_sub(m).map(|b| b + raw),
                    Some(base + raw),
                    Some(base + m + raw),
                ];
                candidates
                    .into_iter()
                    .flatten()
                    .min_by_key(|c| c.abs_diff(last))
                    .unwrap_or(base + raw)
            }
        };
        self.last = Some(t);
        t
    }

    /// The last unwrapped value.
    pub fn last(&self) -> Option<u64> {
        self.last
    }
}

/// How a packet counter relates to the previous one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Continuity {
    /// The first counter seen.
    First,
    /// Exactly one more than the previous (mod 2^16).
    Next,
    /// Counters were skipped.
    Gap {
        /// Number of missing counter values.
        missing: u16,
    },
    /// The same counter again.
    Repeat,
    /// A counter from the recent past (less than 2^15 behind).
    Backward {
        /// How far behind.
        by: u16,
    },
}

/// PacketCounter continuity tracking (u16, wraps).
#[derive(Debug, Clone, Copy, Default)]
pub struct CounterTracker {
    last: Option<u16>,
    /// Counters that followed their predecessor.
    pub in_sequence: u64,
    /// Gaps seen.
    pub gaps: u64,
    /// Counter values missing in total.
    pub missing: u64,
    /// Repeated or backward counters.
    pub out_of_order: u64,
}

impl CounterTracker {
    /// A tracker that has seen nothing.
    pub const fn new() -> Self {
        Self {
            last: None,
            in_sequence: 0,
            gaps: 0,
            missing: 0,
            out_of_order: 0,
        }
    }

    /// Accounts for a counter and classifies it. A backward counter does not move the reference.
    pub fn update(&mut self, counter: u16) -> Continuity {
        let Some(last) = self.last else {
            self.last = Some(counter);
            return Continuity::First;
        };
        let step = counter.wrapping_sub(last);
        let c = match step {
            1 => Continuity::Next,
            0 => Continuity::Repeat,
            s if s < 0x8000 => Continuity::Gap { missing: s - 1 },
            s => Continuity::Backward {
                by: s.wrapping_neg(),
            },
        };
        match c {
            Continuity::Next => self.in_sequence += 1,
            Continuity::Gap { missing } => {
                self.gaps += 1;
                self.missing += u64::from(missing);
            }
            Continuity::Repeat | Continuity::Backward { .. } => self.out_of_order += 1,
            Continuity::First => {}
        }
        if matches!(c, Continuity::Next | Continuity::Gap { .. }) {
            self.last = Some(counter);
        }
        c
    }
}

/// Plausibility flags of one message (a bit set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Flags(pub u16);

impl Flags {
    /// No flag.
    pub const NONE: Flags = Flags(0);
    /// Packet counters were skipped before this message.
    pub const COUNTER_GAP: Flags = Flags(1 << 0);
    /// The packet counter repeats or runs backward.
    pub const COUNTER_BACKWARD: Flags = Flags(1 << 1);
    /// SampleTimeFine is not after the previous message of the same kind.
    pub const TIME_BACKWARD: Flags = Flags(1 << 2);
    /// SampleTimeFine jumped further ahead than [`Limits::max_time_step_ticks`].
    pub const TIME_JUMP: Flags = Flags(1 << 3);
    /// A value is NaN, infinite or outside its range (see [`Limits`]).
    pub const VALUE_RANGE: Flags = Flags(1 << 4);
    /// An item failed to decode.
    pub const ITEM_ERROR: Flags = Flags(1 << 5);

    /// True when no flag is set.
    pub const fn is_clean(self) -> bool {
        self.0 == 0
    }

    /// True when every flag of `other` is set.
    pub const fn contains(self, other: Flags) -> bool {
        self.0 & other.0 == other.0
    }

    /// Names of the set flags.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        const NAMES: [&str; 6] = [
            "counter_gap",
            "counter_backward",
            "time_backward",
            "time_jump",
            "value_range",
            "item_error",
        ];
        NAMES
            .into_iter()
            .enumerate()
            .filter(move |(i, _)| self.0 & (1 << i) != 0)
            .map(|(_, n)| n)
    }
}

impl core::ops::BitOr for Flags {
    type Output = Flags;
    fn bitor(self, rhs: Flags) -> Flags {
        Flags(self.0 | rhs.0)
    }
}

impl core::ops::BitOrAssign for Flags {
    fn bitor_assign(&mut self, rhs: Flags) {
        self.0 |= rhs.0;
    }
}

/// Value ranges for the plausibility checks (generous: above any MTi's full scale).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest acceleration component \[m/s^2\] (MTi full scale is 16 g; default 50 g).
    pub max_acceleration: f64,
    /// Largest rate-of-turn component \[rad/s\] (full scale 2000 deg/s; default 50 rad/s).
    pub max_rate_of_turn: f64,
    /// Largest magnetic field component \[a.u.\].
    pub max_magnetic_field: f64,
    /// Allowed deviation of a quaternion's norm from 1.
    pub quaternion_norm_tolerance: f64,
    /// Temperature range \[°C\].
    pub temperature: (f64, f64),
    /// Largest forward SampleTimeFine step between messages of one kind \[ticks\] (default 10 s).
    pub max_time_step_ticks: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_acceleration: 50.0 * 9.80665,
            max_rate_of_turn: 50.0,
            max_magnetic_field: 100.0,
            quaternion_norm_tolerance: 0.01,
            temperature: (-60.0, 150.0),
            max_time_step_ticks: 10 * TICKS_PER_SECOND,
        }
    }
}

/// Message kinds whose SampleTimeFine runs on its own track.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageKind {
    /// Regular inertial/orientation messages.
    Inertial,
    /// Messages with a GNSS PVT record (their time is 40-60 ms earlier than the preceding
    /// inertial one).
    GnssPvt,
    /// Messages with GNSS satellite info (they share the PVT message's time).
    GnssSatInfo,
    /// Messages with high-rate (HR) outputs, sent separately at ~1 kHz.
    HighRate,
}

impl MessageKind {
    /// The kind of a message by its content.
    pub fn of(sample: &Sample) -> Self {
        if sample.has_gnss_pvt {
            Self::GnssPvt
        } else if sample.has_gnss_sat_info {
            Self::GnssSatInfo
        } else if sample.has_high_rate {
            Self::HighRate
        } else {
            Self::Inertial
        }
    }

    const fn index(self) -> usize {
        match self {
            Self::Inertial => 0,
            Self::GnssPvt => 1,
            Self::GnssSatInfo => 2,
            Self::HighRate => 3,
        }
    }
}

/// The verdict on one message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Checked {
    /// Plausibility flags.
    pub flags: Flags,
    /// Packet counter continuity, if the message has a counter.
    pub continuity: Option<Continuity>,
    /// Unwrapped SampleTimeFine \[ticks\], if the message has one.
    pub time_ticks: Option<u64>,
    /// The message kind the time was checked against.
    pub kind: MessageKind,
}

/// Plausibility checker over a stream of MTData2 messages: counter continuity, time monotonic per
/// [`MessageKind`], value ranges.
#[derive(Debug, Clone)]
pub struct Checker {
    limits: Limits,
    unwrapper: SampleTimeUnwrapper,
    counters: CounterTracker,
    last_time: [Option<u64>; 4],
    /// Messages with at least one flag.
    pub flagged: u64,
}

impl Checker {
    /// A checker for a device family's time wrap, with default limits.
    pub fn new(wrap: TimeWrap) -> Self {
        Self::with_limits(wrap, Limits::default())
    }

    /// A checker with explicit limits.
    pub fn with_limits(wrap: TimeWrap, limits: Limits) -> Self {
        Self {
            limits,
            unwrapper: SampleTimeUnwrapper::new(wrap),
            counters: CounterTracker::new(),
            last_time: [None; 4],
            flagged: 0,
        }
    }

    /// Counter statistics so far.
    pub fn counters(&self) -> &CounterTracker {
        &self.counters
    }

    /// Checks one message (its [`Sample`]).
    pub fn check(&mut self, s: &Sample) -> Checked {
        let mut flags = Flags::NONE;
        let kind = MessageKind::of(s);
        let continuity = s.packet_counter.map(|c| self.counters.update(c));
        match continuity {
            Some(Continuity::Gap { .. }) => flags |= Flags::COUNTER_GAP,
            Some(Continuity::Repeat | Continuity::Backward { .. }) => {
                flags |= Flags::COUNTER_BACKWARD
            }
            _ => {}
        }
        let time_ticks = s.sample_time_fine.map(|raw| self.unwrapper.unwrap(raw));
        if let Some(t) = time_ticks {
            let slot = &mut self.last_time[kind.index()];
            if let Some(prev) = *slot {
                if t <= prev {
                    flags |= Flags::TIME_BACKWARD;
                } else if t - prev > self.limits.max_time_step_ticks {
                    flags |= Flags::TIME_JUMP;
                }
            }
            if slot.is_none_or(|p| t > p) {
                *slot = Some(t);
            }
        }
        if !self.values_plausible(s) {
            flags |= Flags::VALUE_RANGE;
        }
        if s.errors > 0 {
            flags |= Flags::ITEM_ERROR;
        }
        if !flags.is_clean() {
            self.flagged += 1;
        }
        Checked {
            flags,
            continuity,
            time_ticks,
            kind,
        }
    }

    fn values_plausible(&self, s: &Sample) -> bool {
        let l = &self.limits;
        let within = |v: &[f64], max: f64| v.iter().all(|x| x.is_finite() && x.abs() <= max);
        let vectors = [
            (s.acceleration.as_ref().map(|v| &v[..]), l.max_acceleration),
            (
                s.free_acceleration.as_ref().map(|v| &v[..]),
                l.max_acceleration,
            ),
            (s.rate_of_turn.as_ref().map(|v| &v[..]), l.max_rate_of_turn),
            (
                s.magnetic_field.as_ref().map(|v| &v[..]),
                l.max_magnetic_field,
            ),
            (s.euler_angles.as_ref().map(|v| &v[..]), 180.0 + 1e-3),
            (s.delta_v.as_ref().map(|v| &v[..]), l.max_acceleration),
        ];
        let vectors_ok = vectors
            .iter()
            .all(|(v, max)| v.is_none_or(|v| within(v, *max)));
        let quat_ok = [s.quaternion, s.delta_q].iter().flatten().all(|q| {
            let n = libm::sqrt(q.iter().map(|x| x * x).sum::<f64>());
            n.is_finite() && (n - 1.0).abs() <= l.quaternion_norm_tolerance
        });
        let temp_ok = s
            .temperature
            .is_none_or(|t| t.is_finite() && t >= l.temperature.0 && t <= l.temperature.1);
        vectors_ok && quat_ok && temp_ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unwraps_at_pow32_without_the_off_by_one() {
        let mut u = SampleTimeUnwrapper::new(TimeWrap::Pow32);
        assert_eq!(u.unwrap(u32::MAX - 99), (1 << 32) - 100);
        assert_eq!(u.unwrap(0), 1 << 32);
        assert_eq!(u.unwrap(100), (1 << 32) + 100);
    }

    #[test]
    fn unwraps_at_one_day_and_keeps_small_backward_steps() {
        let day = 864_000_000u64;
        let mut u = SampleTimeUnwrapper::new(TimeWrap::Day);
        assert_eq!(u.unwrap(863_999_900), day - 100);
        assert_eq!(u.unwrap(50), day + 50);
        // A GNSS message 500 ticks (50 ms) earlier, from before the wrap.
        assert_eq!(u.unwrap(863_999_650), day - 350);
        assert_eq!(u.unwrap(150), day + 150);
        // Several days in steps of a third of a day.
        let mut expect = day + 150;
        for _ in 0..12 {
            expect += day / 3;
            assert_eq!(u.unwrap((expect % day) as u32), expect);
        }
    }

    #[test]
    fn counter_continuity_with_wrap_and_gaps() {
        let mut c = CounterTracker::new();
        assert_eq!(c.update(65534), Continuity::First);
        assert_eq!(c.update(65535), Continuity::Next);
        assert_eq!(c.update(0), Continuity::Next);
        assert_eq!(c.update(3), Continuity::Gap { missing: 2 });
        assert_eq!(c.update(3), Continuity::Repeat);
        assert_eq!(c.update(1), Continuity::Backward { by: 2 });
        assert_eq!(c.update(4), Continuity::Next);
        assert_eq!(
            (c.in_sequence, c.gaps, c.missing, c.out_of_order),
            (3, 1, 2, 2)
        );
    }

    fn sample(pc: u16, t: u32) -> Sample {
        Sample {
            packet_counter: Some(pc),
            sample_time_fine: Some(t),
            acceleration: Some([0.0, 0.0, 9.81]),
            ..Sample::default()
        }
    }

    #[test]
    fn time_is_monotonic_per_message_kind() {
        let mut ch = Checker::new(TimeWrap::Pow32);
        assert!(ch.check(&sample(1, 1000)).flags.is_clean());
        let gnss = Sample {
            has_gnss_pvt: true,
            ..sample(2, 500)
        };
        assert!(
            ch.check(&gnss).flags.is_clean(),
            "GNSS runs on its own track"
        );
        assert!(ch.check(&sample(3, 1100)).flags.is_clean());
        let back = ch.check(&sample(4, 1050));
        assert_eq!(back.flags, Flags::TIME_BACKWARD);
        let jump = ch.check(&sample(5, 1100 + 200_000));
        assert_eq!(jump.flags, Flags::TIME_JUMP);
    }

    #[test]
    fn corrupted_values_and_counters_are_flagged() {
        let mut ch = Checker::new(TimeWrap::Pow32);
        ch.check(&sample(10, 100));
        let gap = ch.check(&sample(12, 200));
        assert_eq!(gap.flags, Flags::COUNTER_GAP);
        assert_eq!(gap.continuity, Some(Continuity::Gap { missing: 1 }));
        let mut s = sample(13, 300);
        s.acceleration = Some([f64::NAN, 0.0, 0.0]);
        assert!(ch.check(&s).flags.contains(Flags::VALUE_RANGE));
        let mut s = sample(14, 400);
        s.quaternion = Some([0.9, 0.0, 0.0, 0.0]);
        assert!(ch.check(&s).flags.contains(Flags::VALUE_RANGE));
        let mut s = sample(15, 500);
        s.rate_of_turn = Some([0.0, 1e6, 0.0]);
        assert!(ch.check(&s).flags.contains(Flags::VALUE_RANGE));
        assert_eq!(ch.flagged, 4);
        let names: std::vec::Vec<_> = (Flags::COUNTER_GAP | Flags::VALUE_RANGE).names().collect();
        assert_eq!(names, ["counter_gap", "value_range"]);
    }
}
