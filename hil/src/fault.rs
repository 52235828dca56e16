//! Seeded fault injection: every injected fault is counted, and its byte offset logged, so a test
//! can predict what a driver must report.
//!
//! Faults per stream, each stream with its own ChaCha8 generator seeded from the plan's seed and
//! the stream (so one stream's faults do not depend on the other's pacing):
//!
//! * corrupt: each byte, with probability `corrupt`, is XORed with a random non-zero value;
//! * drop: each byte, with probability `drop`, is not sent;
//! * garbage: bursts of `len` random bytes arrive as a Poisson process of `rate` bursts per
//!   second of session time; a due burst is inserted at the next frame start (never inside a
//!   frame), and its bytes never include a sync byte (0x02, the first byte of the TI magic, or
//!   0xFA, the Xbus preamble), so a framer skips exactly the garbage bytes;
//! * stall: the stream stops at session time t for d seconds (later bytes are delayed, none lost);
//! * reopen: at session time t the port is closed and opened again (a pseudo-terminal gets a new
//!   pair).

use crate::{parse_stream, HilError, StreamKind};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Garbage bursts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Garbage {
    /// Mean bursts per second of session time \[1/s\].
    pub rate_hz: f64,
    /// Bytes per burst \[B\].
    pub len: usize,
}

/// A fault at a moment of one stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PortFault {
    /// Which stream.
    pub stream: StreamKind,
    /// Session time of the fault \[s\].
    pub at_s: f64,
    /// Duration (stalls) \[s\]; 0 for reopens.
    pub dur_s: f64,
}

/// What to inject.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FaultPlan {
    /// Probability that a byte is corrupted.
    pub corrupt: f64,
    /// Probability that a byte is dropped.
    pub drop: f64,
    /// Garbage bursts.
    pub garbage: Option<Garbage>,
    /// Stalls.
    pub stalls: Vec<PortFault>,
    /// Port close/reopen events.
    pub reopens: Vec<PortFault>,
    /// Seed of the generators.
    pub seed: u64,
}

impl FaultPlan {
    /// Checks the probabilities and rates.
    pub fn validate(&self) -> Result<(), HilError> {
        for (name, p) in [("--corrupt", self.corrupt), ("--drop", self.drop)] {
            if !(0.0..=1.0).contains(&p) {
                return Err(HilError::Invalid(format!(
                    "{name} {p}: a fraction of bytes must be within 0..=1"
                )));
            }
        }
        if let Some(g) = self.garbage {
            if !(g.rate_hz.is_finite() && g.rate_hz >= 0.0) || g.len == 0 {
                return Err(HilError::Invalid(format!(
                    "--garbage {}:{}: the rate must be >= 0 bursts/s and the length >= 1 B",
                    g.rate_hz, g.len
                )));
            }
        }
        for f in self.stalls.iter().chain(&self.reopens) {
            if !(f.at_s.is_finite() && f.at_s >= 0.0 && f.dur_s.is_finite() && f.dur_s >= 0.0) {
                return Err(HilError::Invalid(format!(
                    "{} fault at {} s for {} s: times must be finite and >= 0",
                    f.stream.name(),
                    f.at_s,
                    f.dur_s
                )));
            }
        }
        Ok(())
    }

    /// True when the plan injects nothing.
    pub fn is_empty(&self) -> bool {
        self.corrupt == 0.0
            && self.drop == 0.0
            && self.garbage.is_none()
            && self.stalls.is_empty()
            && self.reopens.is_empty()
    }
}

/// Parses `RATE:LEN` (bursts per second, bytes per burst).
pub fn parse_garbage(s: &str) -> Result<Garbage, HilError> {
    let bad = || HilError::Invalid(format!("--garbage {s:?}: expected RATE:LEN, e.g. 0.5:32"));
    let (r, l) = s.split_once(':').ok_or_else(bad)?;
    Ok(Garbage {
        rate_hz: r.trim().parse().map_err(|_| bad())?,
        len: l.trim().parse().map_err(|_| bad())?,
    })
}

/// Parses `STREAM@T+D` (a stall of D seconds at T seconds).
pub fn parse_stall(s: &str) -> Result<PortFault, HilError> {
    let bad = || {
        HilError::Invalid(format!(
            "--stall {s:?}: expected STREAM@T+D, e.g. imu@2.5+0.4"
        ))
    };
    let (stream, rest) = s.split_once('@').ok_or_else(bad)?;
    let (t, d) = rest.split_once('+').ok_or_else(bad)?;
    Ok(PortFault {
        stream: parse_stream(stream.trim())?,
        at_s: t.trim().parse().map_err(|_| bad())?,
        dur_s: d.trim().parse().map_err(|_| bad())?,
    })
}

/// Parses `STREAM@T` (close and reopen the port at T seconds).
pub fn parse_reopen(s: &str) -> Result<PortFault, HilError> {
    let bad = || HilError::Invalid(format!("--reopen {s:?}: expected STREAM@T, e.g. radar@3"));
    let (stream, t) = s.split_once('@').ok_or_else(bad)?;
    Ok(PortFault {
        stream: parse_stream(stream.trim())?,
        at_s: t.trim().parse().map_err(|_| bad())?,
        dur_s: 0.0,
    })
}

/// What an injected fault was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// The byte at `offset` was XORed with a non-zero value.
    Corrupt,
    /// The byte at `offset` was not sent.
    Drop,
    /// `len` garbage bytes were sent before the byte at `offset`.
    Garbage {
        /// Burst length \[B\].
        len: usize,
    },
    /// The stream stopped before the byte at `offset`.
    Stall,
    /// The port was closed and reopened before the byte at `offset`.
    Reopen,
}

/// One injected fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultEvent {
    /// Which pass over the session (0 unless `--loop`).
    pub pass: u32,
    /// Offset in the stream's data file of the byte concerned.
    pub offset: u64,
    /// What was done.
    pub kind: FaultKind,
}

/// Injected fault totals of one stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultCounts {
    /// Bytes corrupted.
    pub corrupted: u64,
    /// Bytes dropped.
    pub dropped: u64,
    /// Garbage bursts inserted.
    pub garbage_bursts: u64,
    /// Garbage bytes inserted \[B\].
    pub garbage_bytes: u64,
    /// Stalls.
    pub stalls: u64,
    /// Port reopens.
    pub reopens: u64,
}

/// The most fault events kept per stream (the counts are always complete).
pub const MAX_EVENTS: usize = 1 << 20;

/// The byte-level injector of one stream.
#[derive(Debug)]
pub(crate) struct Injector {
    rng: ChaCha8Rng,
    corrupt: f64,
    drop: f64,
    garbage: Option<Garbage>,
    next_burst_s: f64,
    pub(crate) counts: FaultCounts,
    pub(crate) events: Vec<FaultEvent>,
}

impl Injector {
    pub(crate) fn new(plan: &FaultPlan, stream: StreamKind) -> Self {
        let salt = match stream {
            StreamKind::Radar => 0x5241_4441_5200_0000,
            StreamKind::Imu => 0x494D_5500_0000_0000,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(plan.seed ^ salt);
        let garbage = plan.garbage.filter(|g| g.rate_hz > 0.0);
        let next_burst_s = garbage.map_or(f64::INFINITY, |g| exp_draw(&mut rng, g.rate_hz));
        Injector {
            rng,
            corrupt: plan.corrupt,
            drop: plan.drop,
            garbage,
            next_burst_s,
            counts: FaultCounts::default(),
            events: Vec::new(),
        }
    }

    pub(crate) fn log(&mut self, pass: u32, offset: u64, kind: FaultKind) {
        if self.events.len() < MAX_EVENTS {
            self.events.push(FaultEvent { pass, offset, kind });
        }
    }

    /// Applies the byte faults to `bytes` (offset `start` in the stream file, due at session time
    /// `t_s`), appending what goes on the wire to `out`. `frame_starts` are the stream's frame
    /// start offsets (ascending).
    pub(crate) fn apply(
        &mut self,
        pass: u32,
        start: u64,
        bytes: &[u8],
        t_s: f64,
        frame_starts: &[u64],
        out: &mut Vec<u8>,
    ) {
        let mut burst_at = None;
        if let Some(g) = self.garbage {
            if self.next_burst_s <= t_s {
                let end = start + bytes.len() as u64;
                let i = frame_starts.partition_point(|&s| s < start);
                if let Some(&at) = frame_starts.get(i).filter(|&&s| s < end) {
                    burst_at = Some((at, g.len));
                    self.next_burst_s = t_s + exp_draw(&mut self.rng, g.rate_hz);
                }
            }
        }
        let plain = self.corrupt == 0.0 && self.drop == 0.0;
        if plain && burst_at.is_none() {
            out.extend_from_slice(bytes);
            return;
        }
        for (i, &b) in bytes.iter().enumerate() {
            let offset = start + i as u64;
            if let Some((at, len)) = burst_at.filter(|(at, _)| *at == offset) {
                for _ in 0..len {
                    out.push(self.garbage_byte());
                }
                self.counts.garbage_bursts += 1;
                self.counts.garbage_bytes += len as u64;
                self.log(pass, at, FaultKind::Garbage { len });
            }
            if plain {
                out.push(b);
                continue;
            }
            if self.drop > 0.0 && self.rng.gen_bool(self.drop) {
                self.counts.dropped += 1;
                self.log(pass, offset, FaultKind::Drop);
                continue;
            }
            if self.corrupt > 0.0 && self.rng.gen_bool(self.corrupt) {
                let x: u8 = self.rng.gen_range(1..=255);
                out.push(b ^ x);
                self.counts.corrupted += 1;
                self.log(pass, offset, FaultKind::Corrupt);
                continue;
            }
            out.push(b);
        }
    }

    fn garbage_byte(&mut self) -> u8 {
        loop {
            let b: u8 = self.rng.gen();
            if b != 0x02 && b != 0xFA {
                return b;
            }
        }
    }
}

/// An exponential inter-arrival time for `rate` events per second \[s\].
fn exp_draw(rng: &mut ChaCha8Rng, rate: f64) -> f64 {
    let u: f64 = rng.gen_range(f64::MIN_POSITIVE..1.0);
    -u.ln() / rate
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_cli_forms() {
        assert_eq!(
            parse_garbage("0.5:32").unwrap(),
            Garbage {
                rate_hz: 0.5,
                len: 32
            }
        );
        assert!(parse_garbage("0.5").is_err());
        let s = parse_stall("imu@2.5+0.4").unwrap();
        assert_eq!((s.stream, s.at_s, s.dur_s), (StreamKind::Imu, 2.5, 0.4));
        assert!(parse_stall("gps@1+1").is_err());
        assert_eq!(parse_reopen("radar@3").unwrap().at_s, 3.0);
        assert!(FaultPlan {
            drop: 1.5,
            ..FaultPlan::default()
        }
        .validate()
        .is_err());
    }

    #[test]
    fn same_seed_same_faults_and_every_byte_counted() {
        let plan = FaultPlan {
            corrupt: 0.01,
            drop: 0.01,
            garbage: Some(Garbage {
                rate_hz: 50.0,
                len: 7,
            }),
            seed: 42,
            ..FaultPlan::default()
        };
        let data: Vec<u8> = (0..20_000u32).map(|i| (i % 251) as u8).collect();
        let starts: Vec<u64> = (0..20_000).step_by(100).collect();
        let run = || {
            let mut inj = Injector::new(&plan, StreamKind::Radar);
            let mut out = Vec::new();
            for (k, c) in data.chunks(100).enumerate() {
                inj.apply(0, k as u64 * 100, c, k as f64 * 0.01, &starts, &mut out);
            }
            (out, inj.counts, inj.events)
        };
        let (a, ca, ea) = run();
        let (b, cb, eb) = run();
        assert_eq!((&a, ca, &ea), (&b, cb, &eb));
        assert!(ca.corrupted > 0 && ca.dropped > 0 && ca.garbage_bursts > 0);
        assert_eq!(
            a.len() as u64,
            data.len() as u64 - ca.dropped + ca.garbage_bytes
        );
        assert_eq!(ca.garbage_bytes, 7 * ca.garbage_bursts);
        for e in &ea {
            if let FaultKind::Garbage { .. } = e.kind {
                assert_eq!(e.offset % 100, 0, "burst inside a frame");
            }
        }
    }
}
