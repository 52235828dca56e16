//! Plays a session's streams into sinks, radar and IMU on one time line.
//!
//! One thread per stream walks its [`StreamSchedule`]: each piece is written in slices of about
//! 2 ms of UART time, slice k due when its last byte would have left a UART at the stream's baud,
//! so the piece's last byte is due at the piece's time. Times are divided by the speed; `--fast`
//! writes without waiting. Faults ([`FaultPlan`]) are applied on the way and counted.

use crate::fault::{FaultCounts, FaultEvent, FaultKind, FaultPlan, Injector};
use crate::schedule::{StreamSchedule, Timing};
use crate::sink::Sink;
use crate::{uart_ns, HilError, StreamKind};
use crossbeam_channel::Sender;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

/// How fast to replay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// The original timing (`--speed 1`).
    Original,
    /// N times faster than recorded (`--speed N`, N > 0; below 1 is slower).
    Speed(f64),
    /// As fast as the sinks take the bytes (`--fast`).
    Fast,
}

impl Pacing {
    /// Wall time per session time, `None` for [`Pacing::Fast`].
    fn scale(self) -> Option<f64> {
        match self {
            Pacing::Original => Some(1.0),
            Pacing::Speed(n) => Some(1.0 / n),
            Pacing::Fast => None,
        }
    }
}

/// Something a running replay tells its caller.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Notice {
    /// A port was closed and reopened; a pty may have a new path.
    Reopened {
        /// Which stream.
        stream: StreamKind,
        /// The device path now.
        path: String,
    },
    /// A sink refused bytes for [`crate::sink::BLOCKED_NOTICE`] (nobody reading a pty?).
    Blocked {
        /// Which stream.
        stream: StreamKind,
        /// The device path.
        path: String,
    },
}

/// Replay options.
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// Pacing.
    pub pacing: Pacing,
    /// Faults to inject.
    pub faults: FaultPlan,
    /// Passes over the session; 0 repeats until stopped (`--loop`).
    pub passes: u32,
    /// Pause between passes \[s of session time\].
    pub pass_gap_s: f64,
    /// How long a reopened port stays closed.
    pub reopen_gap: Duration,
    /// Set to stop the replay early (Ctrl-C).
    pub stop: Arc<AtomicBool>,
    /// Where to send [`Notice`]s (port reopened, sink blocked).
    pub notify: Option<Sender<Notice>>,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        ReplayOptions {
            pacing: Pacing::Original,
            faults: FaultPlan::default(),
            passes: 1,
            pass_gap_s: 0.5,
            reopen_gap: Duration::from_millis(100),
            stop: Arc::new(AtomicBool::new(false)),
            notify: None,
        }
    }
}

/// What a replay did on one stream.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamReport {
    /// Which stream.
    pub stream: StreamKind,
    /// The device path at the end (a reopened pty may have moved).
    pub path: String,
    /// Where the timing came from.
    pub timing: Timing,
    /// UART rate the bytes were paced at \[bit/s\].
    pub baud: u32,
    /// Session bytes of the pieces written completely (before faults) \[B\].
    pub bytes_session: u64,
    /// Bytes written to the sink (after faults) \[B\].
    pub bytes_written: u64,
    /// Passes completed.
    pub passes: u32,
    /// Injected faults.
    pub faults: FaultCounts,
    /// Every injected fault, in order (at most [`crate::fault::MAX_EVENTS`]).
    pub events: Vec<FaultEvent>,
    /// Latest a write finished after it was due \[ns\] (paced replays).
    pub late_max_ns: u64,
    /// Mean of the same over all writes \[ns\].
    pub late_mean_ns: u64,
    /// Writes made.
    pub writes: u64,
    /// Time the sink refused bytes (buffer full) \[ns\].
    pub blocked_ns: u64,
    /// Bytes the system under test sent back (read and discarded) \[B\].
    pub bytes_back: u64,
}

/// What a replay did.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayReport {
    /// Per stream, in the order of the schedules.
    pub streams: Vec<StreamReport>,
    /// Wall time from start to the last byte \[ns\].
    pub wall_ns: u64,
    /// True when stopped before the end.
    pub stopped: bool,
}

impl ReplayReport {
    /// The report of one stream.
    pub fn stream(&self, kind: StreamKind) -> Option<&StreamReport> {
        self.streams.iter().find(|s| s.stream == kind)
    }
}

/// Replays `schedules` into `sinks` (one sink per scheduled stream, matched by stream kind) and
/// gives the sinks back, still open, with the report: closing a pty discards what its reader
/// has not read yet, so the caller decides when to drop them.
pub fn replay(
    schedules: Vec<StreamSchedule>,
    mut sinks: Vec<Sink>,
    opts: &ReplayOptions,
) -> Result<(ReplayReport, Vec<Sink>), HilError> {
    opts.faults.validate()?;
    if let Pacing::Speed(n) = opts.pacing {
        if !(n.is_finite() && n > 0.0) {
            return Err(HilError::Invalid(format!(
                "--speed {n}: must be a positive number"
            )));
        }
    }
    let mut jobs = Vec::new();
    for s in schedules {
        let i = sinks
            .iter()
            .position(|k| k.stream() == s.kind)
            .ok_or_else(|| {
                HilError::Invalid(format!(
                    "no output port given for the {} stream",
                    s.kind.name()
                ))
            })?;
        jobs.push((s, sinks.swap_remove(i)));
    }
    // One pass length for all streams, so --loop keeps radar and IMU aligned pass after pass.
    let pass_len = jobs.iter().map(|(s, _)| s.end_ns()).max().unwrap_or(0)
        + (opts.pass_gap_s.max(0.0) * 1e9) as u64;
    let t0 = Instant::now() + Duration::from_millis(20);
    let failed = Arc::new(AtomicBool::new(false));
    let handles: Vec<_> = jobs
        .into_iter()
        .map(|(s, sink)| {
            let opts = opts.clone();
            let failed = failed.clone();
            thread::Builder::new()
                .name(format!("replay-{}", s.kind.name()))
                .spawn(move || {
                    let r = run_stream(&s, sink, &opts, t0, pass_len, &failed);
                    if r.is_err() {
                        failed.store(true, Ordering::SeqCst);
                    }
                    r
                })
        })
        .collect();
    let mut streams = Vec::new();
    let mut out_sinks = Vec::new();
    let mut first_err = None;
    for h in handles {
        let h = h.map_err(|e| HilError::Invalid(format!("cannot start a replay thread: {e}")))?;
        match h.join() {
            Ok(Ok((r, sink))) => {
                streams.push(r);
                out_sinks.push(sink);
            }
            Ok(Err(e)) => {
                first_err.get_or_insert(e);
            }
            Err(_) => {
                first_err.get_or_insert(HilError::Invalid("a replay thread panicked".into()));
            }
        }
    }
    if let Some(e) = first_err {
        return Err(e);
    }
    out_sinks.extend(sinks);
    let stopped = opts.stop.load(Ordering::SeqCst);
    Ok((
        ReplayReport {
            streams,
            wall_ns: u64::try_from(t0.elapsed().as_nanos()).unwrap_or(u64::MAX),
            stopped,
        },
        out_sinks,
    ))
}

/// Sleeps until `deadline` in steps of at most 50 ms; false when stopped.
fn sleep_until(deadline: Instant, stop: &dyn Fn() -> bool) -> bool {
    loop {
        if stop() {
            return false;
        }
        let now = Instant::now();
        if now >= deadline {
            return true;
        }
        thread::sleep((deadline - now).min(Duration::from_millis(50)));
    }
}

fn run_stream(
    s: &StreamSchedule,
    mut sink: Sink,
    opts: &ReplayOptions,
    t0: Instant,
    pass_len: u64,
    failed: &AtomicBool,
) -> Result<(StreamReport, Sink), HilError> {
    let stop = || opts.stop.load(Ordering::Relaxed) || failed.load(Ordering::Relaxed);
    let scale = opts.pacing.scale();
    let wall = |session_ns: u64| match scale {
        Some(k) => t0 + Duration::from_nanos((session_ns as f64 * k) as u64),
        None => t0,
    };
    let mut inj = Injector::new(&opts.faults, s.kind);
    let mut stalls: VecDeque<(u64, u64)> = fault_times(&opts.faults.stalls, s.kind);
    let mut reopens: VecDeque<(u64, u64)> = fault_times(&opts.faults.reopens, s.kind);
    let slice = usize::try_from(u64::from(s.baud) / 10 / 500)
        .unwrap_or(1)
        .max(16);
    let mut rep = StreamReport {
        stream: s.kind,
        path: sink.path().to_string(),
        timing: s.timing,
        baud: s.baud,
        bytes_session: 0,
        bytes_written: 0,
        passes: 0,
        faults: FaultCounts::default(),
        events: Vec::new(),
        late_max_ns: 0,
        late_mean_ns: 0,
        writes: 0,
        blocked_ns: 0,
        bytes_back: 0,
    };
    let mut late_sum: u128 = 0;
    let mut shift = 0u64; // stall delays so far [ns of session time]
    let mut wire_end = 0u64; // session time the last written byte left [ns]
    let mut last_drain = Instant::now();
    let mut wire = Vec::with_capacity(1 << 16);
    let mut pass = 0u32;
    'passes: while opts.passes == 0 || pass < opts.passes {
        let base = u64::from(pass) * pass_len;
        for p in &s.pieces {
            if stop() {
                break 'passes;
            }
            let t = base + p.t_ns;
            while let Some(&(at, _)) = reopens.front().filter(|(at, _)| *at <= t) {
                reopens.pop_front();
                // Close at the fault's time, not when the piece before it was written.
                if scale.is_some() && !sleep_until(wall(at + shift), &stop) {
                    break 'passes;
                }
                sink.reopen(opts.reopen_gap)?;
                inj.counts.reopens += 1;
                inj.log(pass, p.start, FaultKind::Reopen);
                if let Some(n) = &opts.notify {
                    let _ = n.send(Notice::Reopened {
                        stream: s.kind,
                        path: sink.path().to_string(),
                    });
                }
            }
            while let Some(&(_, dur)) = stalls.front().filter(|(at, _)| *at <= t) {
                stalls.pop_front();
                inj.counts.stalls += 1;
                inj.log(pass, p.start, FaultKind::Stall);
                if scale.is_some() {
                    shift += dur;
                } else if !sleep_until(Instant::now() + Duration::from_nanos(dur), &stop) {
                    break 'passes;
                }
            }
            let Some(bytes) = s.data.get(p.start as usize..p.end as usize) else {
                return Err(HilError::Invalid(format!(
                    "{}: piece {}..{} is outside the {} B stream",
                    s.kind.name(),
                    p.start,
                    p.end,
                    s.data.len()
                )));
            };
            wire.clear();
            inj.apply(
                pass,
                p.start,
                bytes,
                t as f64 * 1e-9,
                &s.frame_starts,
                &mut wire,
            );
            let due_end = t + shift;
            let tx = uart_ns(wire.len() as u64, s.baud);
            let start = due_end.saturating_sub(tx).max(wire_end);
            let mut sent = 0usize;
            for chunk in wire.chunks(if scale.is_some() {
                slice
            } else {
                wire.len().max(1)
            }) {
                sent += chunk.len();
                let due_session = start + uart_ns(sent as u64, s.baud);
                let due = wall(due_session);
                if scale.is_some() && !sleep_until(due, &stop) {
                    break 'passes;
                }
                let mut tell = |path: &str| {
                    if let Some(n) = &opts.notify {
                        let _ = n.send(Notice::Blocked {
                            stream: s.kind,
                            path: path.to_string(),
                        });
                    }
                };
                let blocked = sink.write_all(chunk, &stop, &mut tell)?;
                rep.blocked_ns += u64::try_from(blocked.as_nanos()).unwrap_or(u64::MAX);
                rep.bytes_written += chunk.len() as u64;
                rep.writes += 1;
                if scale.is_some() {
                    let late =
                        u64::try_from(Instant::now().saturating_duration_since(due).as_nanos())
                            .unwrap_or(u64::MAX);
                    rep.late_max_ns = rep.late_max_ns.max(late);
                    late_sum += u128::from(late);
                }
                wire_end = due_session;
                if last_drain.elapsed() > Duration::from_millis(50) {
                    sink.drain_input();
                    last_drain = Instant::now();
                }
            }
            rep.bytes_session += bytes.len() as u64;
        }
        pass += 1;
        rep.passes = pass;
        wire_end = wire_end.max(base + pass_len);
    }
    if rep.writes > 0 {
        rep.late_mean_ns = u64::try_from(late_sum / u128::from(rep.writes)).unwrap_or(u64::MAX);
    }
    sink.drain_input();
    rep.path = sink.path().to_string();
    rep.bytes_back = sink.bytes_back;
    rep.faults = inj.counts;
    rep.events = inj.events;
    Ok((rep, sink))
}

/// The faults of one stream as (time, duration) \[ns\], in time order.
fn fault_times(list: &[crate::PortFault], kind: StreamKind) -> VecDeque<(u64, u64)> {
    let mut v: Vec<(u64, u64)> = list
        .iter()
        .filter(|f| f.stream == kind)
        .map(|f| ((f.at_s * 1e9) as u64, (f.dur_s * 1e9) as u64))
        .collect();
    v.sort_unstable();
    v.into()
}
