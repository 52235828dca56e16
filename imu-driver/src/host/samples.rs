//! MTData2 samples with sensor time, host time and plausibility flags, from any byte source.

use super::reader::{Event, Reader};
use crate::frame::frame_capacity;
use crate::message::Message;
use crate::mtdata2::Sample;
use crate::time::{Checker, Continuity, Flags, MessageKind, TimeWrap};
use std::io::{self, Read};
use std::time::Instant;

/// One MTData2 message as the inertial pipeline consumes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedSample {
    /// The values.
    pub sample: Sample,
    /// Unwrapped SampleTimeFine \[1/10 ms ticks\], if the message has one.
    pub time_ticks: Option<u64>,
    /// Host monotonic time of the message's last byte (when the read that delivered it returned).
    pub host_time: Instant,
    /// Plausibility flags.
    pub flags: Flags,
    /// Packet counter continuity, if the message has a counter.
    pub continuity: Option<Continuity>,
    /// The time track the message was checked on.
    pub kind: MessageKind,
}

/// Reads MTData2 messages as [`TimedSample`]s; other messages and dropped bytes are counted.
#[derive(Debug)]
pub struct Samples<R, const CAP: usize = { frame_capacity(2048) }> {
    reader: Reader<R, CAP>,
    checker: Checker,
    other_messages: u64,
}

impl<R: Read, const CAP: usize> Samples<R, CAP> {
    /// Samples from `reader`, unwrapping SampleTimeFine at the device family's `wrap`.
    pub fn new(reader: Reader<R, CAP>, wrap: TimeWrap) -> Self {
        Self {
            reader,
            checker: Checker::new(wrap),
            other_messages: 0,
        }
    }

    /// The next sample; `Ok(None)` at end of input. Source errors (a port's `TimedOut`) are
    /// returned as they are and the stream stays usable.
    pub fn next_sample(&mut self) -> io::Result<Option<TimedSample>> {
        loop {
            let Some(event) = self.reader.next_event()? else {
                return Ok(None);
            };
            let Event::Frame { frame, at } = event else {
                continue;
            };
            let Ok(Message::MtData2(m)) = Message::decode(&frame) else {
                self.other_messages += 1;
                continue;
            };
            let sample = m.sample();
            let c = self.checker.check(&sample);
            return Ok(Some(TimedSample {
                sample,
                time_ticks: c.time_ticks,
                host_time: at,
                flags: c.flags,
                continuity: c.continuity,
                kind: c.kind,
            }));
        }
    }

    /// The checker (counter statistics, flagged count).
    pub fn checker(&self) -> &Checker {
        &self.checker
    }

    /// The reader (framer counters, the byte source).
    pub fn reader(&mut self) -> &mut Reader<R, CAP> {
        &mut self.reader
    }

    /// Messages that were not MTData2.
    pub fn other_messages(&self) -> u64 {
        self.other_messages
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encode::{encode_frame, MtData2Writer};
    use crate::mtdata2::{DataId, Value};

    fn message(counter: u16, time: u32) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let mut w = MtData2Writer::new(&mut buf);
        w.value(DataId(0x1020), &Value::PacketCounter(counter))
            .unwrap();
        w.value(DataId(0x1060), &Value::SampleTimeFine(time))
            .unwrap();
        w.value(DataId(0x8020), &Value::RateOfTurn([0.1, 0.2, 0.3]))
            .unwrap();
        let n = w.finish(0xFF).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn samples_carry_unwrapped_time_and_flags() {
        let mut bytes = message(65_535, u32::MAX - 49);
        bytes.extend(message(0, 50));
        let mut ack = [0u8; 5];
        let n = encode_frame(&mut ack, 0xFF, 0x31, &[]).unwrap();
        bytes.extend_from_slice(&ack[..n]);
        bytes.extend(message(2, 150));
        let mut s: Samples<_> = Samples::new(Reader::new(&bytes[..]), TimeWrap::Pow32);
        let a = s.next_sample().unwrap().unwrap();
        let b = s.next_sample().unwrap().unwrap();
        let c = s.next_sample().unwrap().unwrap();
        assert_eq!(s.next_sample().unwrap(), None);
        assert_eq!(
            a.sample.rate_of_turn,
            Some([0.1f32 as f64, 0.2f32 as f64, 0.3f32 as f64])
        );
        assert_eq!(b.time_ticks, Some((1 << 32) + 50));
        assert_eq!(b.continuity, Some(Continuity::Next));
        assert!(b.flags.is_clean());
        assert_eq!(c.continuity, Some(Continuity::Gap { missing: 1 }));
        assert_eq!(c.flags, Flags::COUNTER_GAP);
        assert_eq!(s.other_messages(), 1);
    }
}
