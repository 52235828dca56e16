//! The replay schedule: when each byte range of a stream is due on the wire.
//!
//! Each stream becomes a list of [`Piece`]s, byte ranges with the time their last byte is due
//! \[ns since replay start, at speed 1\]. With a timing index, a piece is a read chunk and its time
//! is the host time its read returned. Without one (bare TI `.dat` / Xsens logs), a piece is one
//! frame (with any junk before it), timed by the sensor clock:
//!
//! * radar: frame number x frame period when the session has a `radar.cfg` with `frameCfg`, else
//!   the unwrapped timeCpuCycles, else back to back at the UART rate;
//! * IMU: SampleTimeFine (10 kHz, unwrapped per the session's `sample_time_wrap`), else back to
//!   back.
//!
//! In both cases a piece never arrives faster than its baud allows: a piece of n bytes is due no
//! earlier than n x 10 bits / baud after the previous one. Radar and IMU share the time line, so
//! they keep their relative timing (exactly for recorded sessions; from their first frames for
//! bare captures, whose clocks are unrelated).

use crate::{uart_ns, HilError};
use imu_driver::time::SampleTimeUnwrapper;
use imu_driver::{LogFramer, Message, TimeWrap, Value};
use milliego_session::{Session, Stream, StreamKind};
use radar_driver::cfg::RadarConfig;
use radar_driver::clock::{cpu_clock_hz, CycleUnwrapper};
use radar_driver::{Framer, Poll, DEFAULT_MAX_FRAME};

/// A byte range of a stream and when its last byte is due.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Piece {
    /// When the last byte of the range is due \[ns since replay start, at speed 1\].
    pub t_ns: u64,
    /// First byte (offset in the stream's data file).
    pub start: u64,
    /// End of the range (exclusive).
    pub end: u64,
}

/// Where a stream's timing came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Timing {
    /// The session's timing index (host time per read chunk).
    Index,
    /// Radar frame number x frame period from `radar.cfg`.
    RadarFrameNumber {
        /// Frame period \[s\].
        period_s: f64,
    },
    /// Radar timeCpuCycles, unwrapped.
    RadarCycles,
    /// IMU SampleTimeFine.
    ImuSampleTime,
    /// No clock: back to back at the UART rate.
    Baud,
}

/// One stream's data and schedule.
#[derive(Debug, Clone)]
pub struct StreamSchedule {
    /// Which stream.
    pub kind: StreamKind,
    /// UART rate the pieces are paced at \[bit/s\].
    pub baud: u32,
    /// Where the times came from.
    pub timing: Timing,
    /// The pieces, in stream order, with non-decreasing times.
    pub pieces: Vec<Piece>,
    /// Offsets where a frame starts (the sensor's framer on the whole stream), ascending. Garbage
    /// bursts are inserted only there, so they never cut a frame.
    pub frame_starts: Vec<u64>,
    /// The stream's bytes.
    pub data: Vec<u8>,
}

impl StreamSchedule {
    /// Time the last piece is due \[ns\] (0 when empty).
    pub fn end_ns(&self) -> u64 {
        self.pieces.last().map_or(0, |p| p.t_ns)
    }
}

/// Builds the schedules of all streams of a session (radar first), with the session's baud rates
/// unless overridden.
pub fn build(
    session: &Session,
    baud_radar: Option<u32>,
    baud_imu: Option<u32>,
) -> Result<Vec<StreamSchedule>, HilError> {
    let mut out = Vec::new();
    if let Some(s) = &session.radar {
        let baud = baud_radar
            .or(session.meta.radar.as_ref().map(|r| r.baud))
            .unwrap_or(921_600);
        let period = session
            .radar_cfg()?
            .and_then(|text| RadarConfig::parse(&text).ok())
            .and_then(|c| c.frame)
            .map(|f| f.frame_periodicity_ms / 1000.0)
            .filter(|p| p.is_finite() && *p > 0.0);
        out.push(build_stream(s, baud, |data| radar_frames(data, period))?);
    }
    if let Some(s) = &session.imu {
        let baud = baud_imu
            .or(session.meta.imu.as_ref().map(|m| m.baud))
            .unwrap_or(115_200);
        let wrap = session
            .meta
            .imu
            .as_ref()
            .map_or(TimeWrap::Pow32, |m| m.time_wrap());
        out.push(build_stream(s, baud, |data| imu_frames(data, wrap))?);
    }
    Ok(out)
}

/// Frames of a stream: (end offset, sensor time \[s\] since the first frame if known), and the
/// clock used.
type Frames = (Vec<(u64, u64, Option<f64>)>, Timing);

fn build_stream(
    s: &Stream,
    baud: u32,
    frames: impl FnOnce(&[u8]) -> Frames,
) -> Result<StreamSchedule, HilError> {
    if baud == 0 {
        return Err(HilError::Invalid(format!("{}: baud rate 0", s.kind.name())));
    }
    let data = s.read_all()?;
    let (frames, clock) = frames(&data);
    let frame_starts = frames.iter().map(|f| f.0).collect();
    let (pieces, timing) = if s.index.is_some() {
        let mut pieces = Vec::new();
        let mut last = 0u64;
        for c in s.chunks() {
            let min = last + uart_ns(c.end - c.start, baud);
            let t = c.host_ns.map_or(min, |t| t.max(last));
            pieces.push(Piece {
                t_ns: t,
                start: c.start,
                end: c.end,
            });
            last = t;
        }
        (pieces, Timing::Index)
    } else {
        (sensor_pieces(&frames, data.len() as u64, baud), clock)
    };
    Ok(StreamSchedule {
        kind: s.kind,
        baud,
        timing,
        pieces,
        frame_starts,
        data,
    })
}

/// Pieces from frames timed by the sensor clock: frame i (with the junk before it) is due at its
/// sensor time plus its own transmission time, and never before the previous piece plus its
/// transmission time.
fn sensor_pieces(frames: &[(u64, u64, Option<f64>)], len: u64, baud: u32) -> Vec<Piece> {
    let mut pieces = Vec::with_capacity(frames.len() + 1);
    let mut start = 0u64;
    let mut last = 0u64;
    for &(_, end, t) in frames {
        let tx = uart_ns(end - start, baud);
        let clock = t.map_or(0, |s| (s.max(0.0) * 1e9) as u64 + tx);
        let due = clock.max(last + tx);
        pieces.push(Piece {
            t_ns: due,
            start,
            end,
        });
        start = end;
        last = due;
    }
    if start < len {
        pieces.push(Piece {
            t_ns: last + uart_ns(len - start, baud),
            start,
            end: len,
        });
    }
    pieces
}

/// Radar frames (start, end, sensor time) of a whole stream.
fn radar_frames(data: &[u8], period_s: Option<f64>) -> Frames {
    let mut framer: Box<Framer<DEFAULT_MAX_FRAME>> = Box::default();
    let mut input = data;
    let mut out = Vec::new();
    let mut first_number: Option<u32> = None;
    let mut unwrapper: Option<CycleUnwrapper> = None;
    let mut used_cycles = false;
    loop {
        let header = match framer.poll(&mut input) {
            Poll::Frame(f) => *f.header(),
            Poll::Dropped { .. } => continue,
            Poll::NeedMore => break,
        };
        let end = (data.len() - input.len()) as u64;
        let start = end - u64::from(header.total_len);
        let t = if let Some(p) = period_s {
            let first = *first_number.get_or_insert(header.frame_number);
            Some(f64::from(header.frame_number.wrapping_sub(first)) * p)
        } else if let Some(c) = header.time_cpu_cycles {
            used_cycles = true;
            let u =
                unwrapper.get_or_insert_with(|| CycleUnwrapper::new(cpu_clock_hz(&header), None));
            u.push(header.frame_number, c).seconds
        } else {
            None
        };
        out.push((start, end, t));
    }
    let timing = match period_s {
        Some(period_s) => Timing::RadarFrameNumber { period_s },
        None if used_cycles => Timing::RadarCycles,
        None => Timing::Baud,
    };
    (out, timing)
}

/// IMU frames (start, end, sensor time) of a whole stream.
fn imu_frames(data: &[u8], wrap: TimeWrap) -> Frames {
    let mut framer: Box<LogFramer> = Box::default();
    let mut input = data;
    let mut out = Vec::new();
    let mut unwrapper = SampleTimeUnwrapper::new(wrap);
    let mut first: Option<u64> = None;
    let mut any = false;
    loop {
        let (len, stf) = match framer.poll(&mut input) {
            imu_driver::Poll::Frame(f) => (f.as_bytes().len() as u64, sample_time(&f)),
            imu_driver::Poll::Dropped { .. } => continue,
            imu_driver::Poll::NeedMore => break,
        };
        let end = (data.len() - input.len()) as u64;
        let t = stf.map(|raw| {
            any = true;
            let ticks = unwrapper.unwrap(raw);
            let f = *first.get_or_insert(ticks);
            ticks.saturating_sub(f) as f64 / imu_driver::time::TICKS_PER_SECOND as f64
        });
        out.push((end - len, end, t));
    }
    // Messages without SampleTimeFine go right after the previous one.
    let timing = if any {
        Timing::ImuSampleTime
    } else {
        Timing::Baud
    };
    (out, timing)
}

fn sample_time(f: &imu_driver::XbusFrame<'_>) -> Option<u32> {
    let Ok(Message::MtData2(m)) = Message::decode(f) else {
        return None;
    };
    m.items().flatten().find_map(|i| match i.value() {
        Ok(Value::SampleTimeFine(t)) => Some(t),
        _ => None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use imu_driver::MtData2Writer;
    use radar_driver::encode::FrameBuilder;

    fn radar(n: u32, cycles: u32) -> Vec<u8> {
        FrameBuilder::oob(0x0303_0002, 0xA6843, n)
            .cycles(cycles)
            .to_vec()
    }

    fn imu(stf: Option<u32>) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let mut w = MtData2Writer::new(&mut buf);
        w.value(imu_driver::DataId(0x1020), &Value::PacketCounter(1))
            .unwrap();
        if let Some(t) = stf {
            w.value(imu_driver::DataId(0x1060), &Value::SampleTimeFine(t))
                .unwrap();
        }
        let n = w.finish(0xFF).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn radar_frames_are_timed_by_frame_number_or_cycles() {
        // Frames 10, 11, 13 (one missing) at 200 MHz, 50 ms apart; junk before the first.
        let mut data = vec![0xAA; 5];
        for (n, c) in [(10u32, 1_000u32), (11, 10_001_000), (13, 30_001_000)] {
            data.extend(radar(n, c));
        }
        let (frames, timing) = radar_frames(&data, Some(0.05));
        assert_eq!(timing, Timing::RadarFrameNumber { period_s: 0.05 });
        let t: Vec<f64> = frames.iter().map(|f| f.2.unwrap()).collect();
        assert!(t[0] == 0.0 && (t[1] - 0.05).abs() < 1e-12 && (t[2] - 0.15).abs() < 1e-12);
        assert_eq!(frames[0].0, 5, "the frame starts after the junk");
        let (frames, timing) = radar_frames(&data, None);
        assert_eq!(timing, Timing::RadarCycles);
        let t: Vec<f64> = frames.iter().map(|f| f.2.unwrap()).collect();
        assert!(
            (t[1] - 0.05).abs() < 1e-9 && (t[2] - 0.15).abs() < 1e-9,
            "{t:?}"
        );
    }

    #[test]
    fn pieces_follow_the_clock_but_never_beat_the_uart() {
        // Two 1000-byte frames 1 ms apart on the sensor clock at 115200 bit/s (86.8 ms each).
        let frames = [(0, 1000, Some(0.0)), (1000, 2000, Some(0.001))];
        let p = sensor_pieces(&frames, 2010, 115_200);
        let tx = uart_ns(1000, 115_200);
        assert_eq!(p[0].t_ns, tx);
        assert_eq!(
            p[1].t_ns,
            2 * tx,
            "the second frame waits for the first on the wire"
        );
        assert_eq!(
            (p[2].start, p[2].end),
            (2000, 2010),
            "the tail is a piece too"
        );
        assert_eq!(p[2].t_ns, 2 * tx + uart_ns(10, 115_200));
        // Far apart: the clock rules.
        let frames = [(0, 100, Some(0.0)), (100, 200, Some(1.0))];
        let p = sensor_pieces(&frames, 200, 921_600);
        assert_eq!(p[1].t_ns, 1_000_000_000 + uart_ns(100, 921_600));
    }

    #[test]
    fn imu_messages_are_timed_by_sample_time_fine() {
        let mut data = Vec::new();
        data.extend(imu(Some(u32::MAX - 50))); // wraps after 51 ticks
        data.extend(imu(Some(50)));
        data.extend(imu(None));
        let (frames, timing) = imu_frames(&data, TimeWrap::Pow32);
        assert_eq!(timing, Timing::ImuSampleTime);
        assert_eq!(frames[0].2, Some(0.0));
        assert!((frames[1].2.unwrap() - 0.0101).abs() < 1e-12);
        assert_eq!(frames[2].2, None);
        let p = sensor_pieces(&frames, data.len() as u64, 115_200);
        assert!(
            p[2].t_ns > p[1].t_ns,
            "a message without time follows the previous one"
        );
        let (_, timing) = imu_frames(&imu(None), TimeWrap::Pow32);
        assert_eq!(timing, Timing::Baud);
    }
}
