//! The one streaming bytes -> IMU samples decoder: Xbus framer, MTData2 decoding and the
//! SampleTimeFine checker, fed in chunks as they arrive. Sessions run it in batch over a recorded
//! stream, the runtime's reader live over a port; the same bytes give the same samples however
//! they are chunked.
//!
//! A sample is an MTData2 message with acceleration, rate of turn and SampleTimeFine; a message
//! with BaroPressure and SampleTimeFine alone is a barometer reading
//! ([`Decoder::feed_with_pressure`]). Nothing is dropped silently: [`ImuDecodeReport`] counts
//! rejected frames (framer), barometer readings and messages that are neither
//! (acknowledgements, GNSS-only or orientation-only messages).
//!
//! ```
//! use imu_driver::host::decoder::Decoder;
//! use imu_driver::{DataId, MtData2Writer, TimeWrap, Value};
//! let mut bytes = Vec::new();
//! for i in 0..3u32 {
//!     let mut buf = [0u8; 64];
//!     let mut w = MtData2Writer::new(&mut buf);
//!     w.value(DataId(0x1060), &Value::SampleTimeFine(100 * i)).unwrap();
//!     w.value(DataId(0x4020), &Value::Acceleration([0.0, 0.0, 9.81])).unwrap();
//!     w.value(DataId(0x8020), &Value::RateOfTurn([0.0; 3])).unwrap();
//!     let n = w.finish(0xFF).unwrap();
//!     bytes.extend_from_slice(&buf[..n]);
//! }
//! let mut dec = Decoder::new(TimeWrap::Pow32);
//! let mut t = Vec::new();
//! for chunk in bytes.chunks(5) {
//!     dec.feed(chunk, (), |s| t.push(s.sensor_s));
//! }
//! dec.finish();
//! assert_eq!(t, [0.0, 0.01, 0.02]);
//! assert_eq!(dec.report().samples, 3);
//! ```

use crate::framer::{Counters, Poll};
use crate::message::Message;
use crate::time::{Checker, Flags, TimeWrap};
use crate::LogFramer;
use alloc::boxed::Box;

/// One IMU sample. `stamp` is what the caller passed with the chunk that completed the message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample<S> {
    /// The caller's stamp of the chunk that held the message's last byte.
    pub stamp: S,
    /// Unwrapped SampleTimeFine \[s\].
    pub sensor_s: f64,
    /// Specific force, sensor frame \[m/s^2\].
    pub accel: [f64; 3],
    /// Rate of turn, sensor frame \[rad/s\].
    pub gyro: [f64; 3],
    /// PacketCounter, if sent.
    pub packet_counter: Option<u16>,
    /// Plausibility flags from the time checker.
    pub flags: Flags,
    /// Message length on the wire \[B\].
    pub bytes: usize,
}

/// One barometer reading (an MTData2 message with BaroPressure and SampleTimeFine, as MTi-100
/// class devices send it beside the inertial messages).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureSample<S> {
    /// The caller's stamp of the chunk that held the message's last byte.
    pub stamp: S,
    /// Unwrapped SampleTimeFine \[s\].
    pub sensor_s: f64,
    /// Pressure \[Pa\].
    pub pa: f64,
}

/// What decoding found so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ImuDecodeReport {
    /// Framer counters (bytes in, skipped, frames rejected by reason).
    pub framer: Counters,
    /// Samples published.
    pub samples: u64,
    /// Barometer readings (messages with BaroPressure and SampleTimeFine but no inertial sample),
    /// published to [`Decoder::feed_with_pressure`]'s callback or, with [`Decoder::feed`], only
    /// counted here.
    pub pressure: u64,
    /// Good frames that were neither samples nor barometer readings (other messages, MTData2
    /// without acceleration, rate of turn and SampleTimeFine).
    pub not_samples: u64,
}

/// The streaming IMU decoder (see the [module docs](self)); allocation-free after creation.
pub struct Decoder {
    framer: Box<LogFramer>,
    checker: Checker,
    samples: u64,
    pressure: u64,
    not_samples: u64,
}

impl core::fmt::Debug for Decoder {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Decoder")
            .field("samples", &self.samples)
            .field("not_samples", &self.not_samples)
            .finish()
    }
}

impl Decoder {
    /// A decoder for a device whose SampleTimeFine wraps as `wrap`.
    pub fn new(wrap: TimeWrap) -> Self {
        Decoder {
            framer: Box::new(LogFramer::new()),
            checker: Checker::new(wrap),
            samples: 0,
            pressure: 0,
            not_samples: 0,
        }
    }

    /// Counters so far.
    pub fn report(&self) -> ImuDecodeReport {
        ImuDecodeReport {
            framer: *self.framer.counters(),
            samples: self.samples,
            pressure: self.pressure,
            not_samples: self.not_samples,
        }
    }

    /// Feeds the next chunk of the stream, received at `stamp`; `publish` gets each sample
    /// (barometer readings are counted in [`ImuDecodeReport::pressure`]).
    pub fn feed<S: Copy>(&mut self, input: &[u8], stamp: S, publish: impl FnMut(ImuSample<S>)) {
        self.feed_with_pressure(input, stamp, publish, |_| {});
    }

    /// [`Decoder::feed`], with `pressure` getting each barometer reading.
    pub fn feed_with_pressure<S: Copy>(
        &mut self,
        mut input: &[u8],
        stamp: S,
        mut publish: impl FnMut(ImuSample<S>),
        mut pressure: impl FnMut(PressureSample<S>),
    ) {
        loop {
            match self.framer.poll(&mut input) {
                Poll::Frame(f) => {
                    let Ok(Message::MtData2(d)) = Message::decode(&f) else {
                        self.not_samples += 1;
                        continue;
                    };
                    let s = d.sample();
                    let checked = self.checker.check(&s);
                    match (s.acceleration, s.rate_of_turn, checked.time_ticks) {
                        (Some(accel), Some(gyro), Some(ticks)) => {
                            self.samples += 1;
                            publish(ImuSample {
                                stamp,
                                sensor_s: ticks as f64 * 1e-4,
                                accel,
                                gyro,
                                packet_counter: s.packet_counter,
                                flags: checked.flags,
                                bytes: f.as_bytes().len(),
                            });
                        }
                        (None, None, Some(ticks)) if s.pressure_pa.is_some() => {
                            self.pressure += 1;
                            pressure(PressureSample {
                                stamp,
                                sensor_s: ticks as f64 * 1e-4,
                                pa: s.pressure_pa.unwrap_or(f64::NAN),
                            });
                        }
                        _ => self.not_samples += 1,
                    }
                }
                Poll::Dropped { .. } => {}
                Poll::NeedMore => break,
            }
        }
    }

    /// Ends the stream (or a stretch of it, before a port is reopened): a partial message is
    /// counted as truncated.
    pub fn finish(&mut self) {
        self.framer.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DataId, MtData2Writer, Value};

    fn message(ticks: u32, counter: u16, motion: bool) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let mut w = MtData2Writer::new(&mut buf);
        w.value(DataId(0x1020), &Value::PacketCounter(counter))
            .unwrap();
        w.value(DataId(0x1060), &Value::SampleTimeFine(ticks))
            .unwrap();
        if motion {
            w.value(DataId(0x4020), &Value::Acceleration([0.1, 0.0, 9.81]))
                .unwrap();
            w.value(DataId(0x8020), &Value::RateOfTurn([0.0, 0.0, 0.01]))
                .unwrap();
        }
        let n = w.finish(0xFF).unwrap();
        buf[..n].to_vec()
    }

    fn pressure(ticks: u32, counter: u16, pa: u32) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let mut w = MtData2Writer::new(&mut buf);
        w.value(DataId(0x1020), &Value::PacketCounter(counter))
            .unwrap();
        w.value(DataId(0x1060), &Value::SampleTimeFine(ticks))
            .unwrap();
        w.value(DataId(0x3010), &Value::BaroPressure(pa)).unwrap();
        let n = w.finish(0xFF).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn barometer_readings_come_out_beside_the_samples_and_are_counted() {
        let mut bytes = message(100, 1, true);
        bytes.extend(pressure(150, 2, 101_300));
        bytes.extend(message(200, 3, true));
        bytes.extend(message(250, 4, false)); // neither: time alone
        let mut dec = Decoder::new(TimeWrap::Pow32);
        let (mut samples, mut baro) = (Vec::new(), Vec::new());
        for chunk in bytes.chunks(7) {
            dec.feed_with_pressure(
                chunk,
                (),
                |s| samples.push(s.sensor_s),
                |p| baro.push((p.sensor_s, p.pa)),
            );
        }
        assert_eq!(samples, [0.01, 0.02]);
        assert_eq!(baro, [(150.0 * 1e-4, 101_300.0)]);
        let r = dec.report();
        assert_eq!((r.samples, r.pressure, r.not_samples), (2, 1, 1));
        // `feed` leaves them out, counted.
        let mut dec = Decoder::new(TimeWrap::Pow32);
        let mut n = 0;
        dec.feed(&bytes, (), |_| n += 1);
        assert_eq!((n, dec.report().pressure), (2, 1));
    }

    #[test]
    fn chunking_does_not_change_samples_and_other_messages_are_counted() {
        let mut bytes = Vec::new();
        for i in 0..20u32 {
            bytes.extend(message(100 * i, i as u16, i != 7));
            if i == 3 {
                bytes.extend([0x55u8; 9]); // line noise
            }
        }
        let mut all = Vec::new();
        for chunk in [1usize, 3, 64, 10_000] {
            let mut dec = Decoder::new(TimeWrap::Pow32);
            let mut got = Vec::new();
            for c in bytes.chunks(chunk) {
                dec.feed(c, (), |s| got.push((s.sensor_s, s.packet_counter)));
            }
            dec.finish();
            let r = dec.report();
            assert_eq!((r.samples, r.not_samples), (19, 1), "chunks of {chunk}");
            assert_eq!(r.framer.bytes_skipped, 9);
            all.push(got);
        }
        assert!(all.windows(2).all(|w| w[0] == w[1]));
        assert_eq!(all[0][7], (0.08, Some(8)));
    }
}
