//! The host side of `scripts/firmware-hil`: reads what the hub sent on its link (a capture of
//! the link UART) and checks it against the session that was replayed into the hub's sensor
//! UARTs and the faults the replay injected. Prints one `PASS name: detail` or `FAIL name:
//! detail` line per check and a JSON summary on the last line; exits 1 when a check failed.
//!
//! ```text
//! cargo run -p hub-link --example hub_check -- --session DIR --link FILE \
//!     [--radar-garbage B] [--radar-dropped N] [--imu-garbage B] [--imu-dropped N] [--tolerance-ms T] [--max-ms M]
//! ```

use hub_link::{Deframer, Event, Health, Message, FRAME_MAX};
use milliego_hil::schedule::{self, StreamSchedule};
use milliego_hil::StreamKind;
use std::collections::BTreeMap;
use std::process::ExitCode;

/// What the hub forwarded for one sensor.
#[derive(Default)]
struct Forwarded {
    frames: Vec<(u64, Vec<u8>)>,
}

/// A frame of the original stream: its bytes' range.
struct Orig {
    start: usize,
    end: usize,
}

fn radar_frames(data: &[u8]) -> Vec<Orig> {
    let mut f: Box<radar_driver::Framer<4096>> =
        Box::new(radar_driver::Framer::new(radar_driver::LayoutHint::Auto));
    let mut out = Vec::new();
    let mut input = data;
    loop {
        let p = f.poll(&mut input);
        let len = match p {
            radar_driver::Poll::Frame(fr) => Some(fr.as_bytes().len()),
            radar_driver::Poll::Dropped { .. } => None,
            radar_driver::Poll::NeedMore => break,
        };
        if let Some(len) = len {
            let end = (f.counters().bytes_in - f.buffered() as u64) as usize;
            out.push(Orig {
                start: end - len,
                end,
            });
        }
    }
    out
}

fn imu_frames(data: &[u8]) -> Vec<Orig> {
    let mut f: Box<imu_driver::DeviceFramer> = Box::new(imu_driver::Framer::new());
    let mut out = Vec::new();
    let mut input = data;
    loop {
        let len = match f.poll(&mut input) {
            imu_driver::Poll::Frame(fr) => Some(fr.as_bytes().len()),
            imu_driver::Poll::Dropped { .. } => None,
            imu_driver::Poll::NeedMore => break,
        };
        if let Some(len) = len {
            let end = (f.counters().bytes_in - f.buffered() as u64) as usize;
            out.push(Orig {
                start: end - len,
                end,
            });
        }
    }
    out
}

/// When the byte before `end` was due on the wire \[ns since replay start\]: its piece's due
/// time less the UART time of the bytes after it in the piece.
fn due_ns(s: &StreamSchedule, end: u64) -> f64 {
    let i = s.pieces.partition_point(|p| p.end < end);
    let p = &s.pieces[i.min(s.pieces.len() - 1)];
    p.t_ns as f64 - (p.end.saturating_sub(end)) as f64 * 10e9 / f64::from(s.baud)
}

/// How the emulated UART receives a stream. QEMU's PL011 model takes one byte per pass of its
/// event loop (its receive FIFO reports room for one byte at a time), so it drains a pty more
/// slowly than the replay writes a frame at the UART's rate: a byte is received at
/// `D[i] = max(A[i], D[i-1] + 1/rate)`, `A[i]` the byte's due time on the wire. The rate is fitted
/// (one number per stream, the same for every frame), and the hub's stamps are compared with the
/// modelled receive time of the stamped byte, after one clock offset per stream.
struct Delivery {
    /// Fitted delivery rate \[B/s\] (the largest tried, 1 MB/s, means no lag).
    rate: f64,
    /// Hub time minus modelled receive time, median \[ns\].
    offset_ns: f64,
    /// Per-frame deviation from the offset \[ms\].
    dev_ms: Vec<f64>,
    max_ms: f64,
    p95_ms: f64,
    mean_ms: f64,
    /// Least-squares slope of hub time against modelled receive time (1 when the hub's timer runs
    /// at the rate it reports).
    slope: f64,
}

impl Delivery {
    /// `stamps`: (offset just past the stamped byte in the stream, hub time \[ns\]), in order.
    fn fit(s: &StreamSchedule, stamps: &[(usize, f64)]) -> Delivery {
        let due: Vec<f64> = (1..=s.data.len() as u64).map(|e| due_ns(s, e)).collect();
        let mut best: Option<Delivery> = None;
        // 8 kB/s to 1 MB/s, 5% apart.
        let mut rate = 8e3;
        while rate <= 1.0e6 {
            let step = 1e9 / rate;
            let mut d = f64::NEG_INFINITY;
            let recv: Vec<f64> = due
                .iter()
                .map(|&a| {
                    d = a.max(d + step);
                    d
                })
                .collect();
            let res: Vec<f64> = stamps
                .iter()
                .map(|&(end, t)| t - recv[end.clamp(1, recv.len()) - 1])
                .collect();
            let recv_at: Vec<f64> = stamps
                .iter()
                .map(|&(end, _)| recv[end.clamp(1, recv.len()) - 1])
                .collect();
            let mut fit = Delivery::from_residuals(rate, &res);
            fit.slope = slope(&recv_at, &res) + 1.0;
            if best.as_ref().is_none_or(|b| fit.p95_ms < b.p95_ms) {
                best = Some(fit);
            }
            rate *= 1.05;
        }
        best.unwrap_or_else(|| Delivery::from_residuals(0.0, &[]))
    }

    fn from_residuals(rate: f64, res: &[f64]) -> Delivery {
        let mut sorted = res.to_vec();
        sorted.sort_by(f64::total_cmp);
        let offset_ns = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        let dev_ms: Vec<f64> = res.iter().map(|r| (r - offset_ns) * 1e-6).collect();
        let mut abs: Vec<f64> = dev_ms.iter().map(|d| d.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let q =
            |f: f64| abs.get(((abs.len() as f64 * f) as usize).min(abs.len().saturating_sub(1)));
        Delivery {
            rate,
            offset_ns,
            max_ms: abs.last().copied().unwrap_or(0.0),
            p95_ms: q(0.95).copied().unwrap_or(0.0),
            mean_ms: dev_ms.iter().sum::<f64>() / dev_ms.len().max(1) as f64,
            dev_ms,
            slope: 1.0,
        }
    }
}

/// Least-squares slope of `y` against `x` (0 for fewer than two points or no spread).
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    if sxx > 0.0 {
        sxy / sxx
    } else {
        0.0
    }
}

struct Checks {
    passed: u32,
    failed: u32,
}

impl Checks {
    fn check(&mut self, name: &str, ok: bool, detail: String) {
        if ok {
            self.passed += 1;
            println!("PASS {name}: {detail}");
        } else {
            self.failed += 1;
            println!("FAIL {name}: {detail}");
        }
    }
}

fn arg(args: &BTreeMap<String, String>, k: &str) -> u64 {
    args.get(k).and_then(|v| v.parse().ok()).unwrap_or(0)
}

fn main() -> ExitCode {
    let mut args = BTreeMap::new();
    let mut it = std::env::args().skip(1);
    while let (Some(k), Some(v)) = (it.next(), it.next()) {
        args.insert(k.trim_start_matches("--").to_string(), v);
    }
    let (Some(session), Some(link)) = (args.get("session"), args.get("link")) else {
        eprintln!("usage: hub_check --session DIR --link FILE [--radar-garbage B] [--radar-dropped N] [--imu-garbage B] [--imu-dropped N] [--tolerance-ms T] [--max-ms M]");
        return ExitCode::from(2);
    };
    let tol_ms: f64 = args
        .get("tolerance-ms")
        .and_then(|v| v.parse().ok())
        .unwrap_or(40.0);
    let max_ms: f64 = args
        .get("max-ms")
        .and_then(|v| v.parse().ok())
        .unwrap_or(250.0);
    let session = milliego_session::Session::open(session).expect("session");
    let schedules = schedule::build(&session, None, None).expect("schedule");
    let wire = std::fs::read(link).expect("link capture");

    // Everything the hub said.
    let mut d: Box<Deframer<FRAME_MAX>> = Box::default();
    let mut input = &wire[..];
    let (mut radar, mut imu) = (Forwarded::default(), Forwarded::default());
    let mut healths: Vec<(u64, Health)> = Vec::new();
    let mut seqs = Vec::new();
    let mut bad = 0u64;
    loop {
        match d.poll(&mut input) {
            Event::Message(m) => {
                seqs.push(m.header().seq);
                match m {
                    Message::Radar { header, bytes } => {
                        radar.frames.push((header.t_ns, bytes.to_vec()))
                    }
                    Message::Imu { header, bytes } => {
                        imu.frames.push((header.t_ns, bytes.to_vec()))
                    }
                    Message::Health { header, health } => healths.push((header.t_ns, health)),
                }
            }
            Event::BadFrame(e) => {
                bad += 1;
                eprintln!("bad link frame: {e}");
            }
            Event::NeedMore => break,
        }
    }
    let mut c = Checks {
        passed: 0,
        failed: 0,
    };
    let dc = *d.counters();
    c.check(
        "link frames intact",
        bad == 0 && dc.messages_ok > 0,
        format!(
            "{} messages, {} bad frames, {} B",
            dc.messages_ok,
            bad,
            wire.len()
        ),
    );
    let gaps = seqs
        .windows(2)
        .filter(|w| w[1] != w[0].wrapping_add(1))
        .count();
    c.check(
        "link sequence contiguous from 0",
        gaps == 0 && seqs.first() == Some(&0),
        format!("{} messages, {gaps} gaps", seqs.len()),
    );
    let Some(&(health_t, h)) = healths.last() else {
        c.check("health received", false, "no health message".into());
        println!("{} passed, {} failed", c.passed, c.failed);
        return ExitCode::FAILURE;
    };
    c.check(
        "health clock",
        h.timer_hz > 0 && healths.windows(2).all(|w| w[1].0 > w[0].0),
        format!(
            "{} health messages, timer {} Hz, last at {:.3} s hub time",
            healths.len(),
            h.timer_hz,
            health_t as f64 * 1e-9
        ),
    );
    c.check(
        "link never dropped a message (backpressure)",
        h.link_dropped == 0,
        format!(
            "sent {}, dropped {} ({} B), transmit ring high water {} of {} B",
            h.link_sent, h.link_dropped, h.link_dropped_bytes, h.link_high_water, h.capacities[2]
        ),
    );

    let mut summary = serde_json::Map::new();
    let mut offsets = Vec::new();
    for s in &schedules {
        let (name, fwd, ph, garbage, dropped, origs) = match s.kind {
            StreamKind::Radar => (
                "radar",
                &radar,
                h.radar,
                arg(&args, "radar-garbage"),
                arg(&args, "radar-dropped"),
                radar_frames(&s.data),
            ),
            StreamKind::Imu => (
                "imu",
                &imu,
                h.imu,
                arg(&args, "imu-garbage"),
                arg(&args, "imu-dropped"),
                imu_frames(&s.data),
            ),
        };
        let orig_frame_bytes: usize = origs.iter().map(|o| o.end - o.start).sum();
        let orig_junk = s.data.len() - orig_frame_bytes;
        // 1. Every byte the UART received is the session's, less the dropped, plus the garbage.
        let want_rx = s.data.len() as u64 - dropped + garbage;
        c.check(
            &format!("{name}: bytes received = session - dropped + garbage"),
            u64::from(ph.rx_bytes) == want_rx,
            format!(
                "hub {} B, session {} B - {dropped} dropped + {garbage} garbage = {want_rx} B",
                ph.rx_bytes,
                s.data.len()
            ),
        );
        c.check(
            &format!("{name}: nothing lost in the hub"),
            ph.ring_overflow == 0 && ph.uart_errors == 0,
            format!(
                "ring overflow {} B, UART errors {}, ring high water {} B",
                ph.ring_overflow, ph.uart_errors, ph.ring_high_water
            ),
        );
        // 2. Every forwarded frame is an original frame, byte for byte, in order; or, only where
        // bytes were dropped, the session's bytes at that place less one dropped byte that the
        // sensor's own checksum did not catch (Xbus: 1 in 256), forwarded as the framer took it.
        let mut k = 0usize;
        let mut matched = Vec::new();
        let mut false_accepts = 0u64;
        let mut exact = true;
        for (t, bytes) in &fwd.frames {
            let found = (k..origs.len()).find(|&j| &s.data[origs[j].start..origs[j].end] == bytes);
            match found {
                Some(j) => {
                    matched.push((j, *t));
                    k = j + 1;
                }
                None if dropped > 0 => {
                    let one_dropped = |at: usize| {
                        let src = s.data.get(at..at + bytes.len() + 1).unwrap_or_default();
                        src.len() == bytes.len() + 1
                            && (0..src.len())
                                .any(|x| src[..x] == bytes[..x] && src[x + 1..] == bytes[x..])
                    };
                    match (k..origs.len()).find(|&j| one_dropped(origs[j].start)) {
                        Some(j) => {
                            false_accepts += 1;
                            k = j + 1;
                        }
                        None => {
                            exact = false;
                            break;
                        }
                    }
                }
                None => {
                    exact = false;
                    break;
                }
            }
        }
        let lost = origs.len() - matched.len();
        c.check(
            &format!("{name}: every forwarded frame byte-exact and in order"),
            exact && !fwd.frames.is_empty(),
            format!(
                "{} forwarded of {} in the session; {false_accepts} of them the session's bytes less a dropped byte that passed the sensor's checksum",
                fwd.frames.len(),
                origs.len()
            ),
        );
        c.check(
            &format!("{name}: hub forwarded-frame counter"),
            u64::from(ph.frames_forwarded) == fwd.frames.len() as u64,
            format!(
                "hub says {}, link carried {}",
                ph.frames_forwarded,
                fwd.frames.len()
            ),
        );
        // 3. Counters equal the injected faults.
        let fwd_bytes: usize = fwd.frames.iter().map(|f| f.1.len()).sum();
        let lost_bytes = orig_frame_bytes - fwd_bytes;
        let want_skipped = (orig_junk + lost_bytes) as u64 + garbage - dropped;
        c.check(
            &format!("{name}: skipped bytes = garbage + lost frames - dropped"),
            u64::from(ph.bytes_skipped) == want_skipped,
            format!(
                "hub {} B; {garbage} garbage + {lost_bytes} B of frames not forwarded as sent - {dropped} dropped + {orig_junk} junk in the session = {want_skipped} B",
                ph.bytes_skipped
            ),
        );
        // A dropped byte loses its frame; one that slips past the checksum also takes the next
        // frame's first byte.
        let lost_ok = if dropped == 0 {
            lost == 0 && ph.frames_bad == 0 && false_accepts == 0
        } else {
            lost >= 1 && lost as u64 <= dropped + false_accepts && ph.frames_bad >= 1
        };
        c.check(
            &format!("{name}: frames lost only to dropped bytes"),
            lost_ok,
            format!(
                "{lost} lost, {dropped} bytes dropped, hub framer rejects {}, retracted {}",
                ph.frames_bad, ph.frames_retracted
            ),
        );
        // 4. Hub times monotonic and within the tolerance of the replay schedule, once the
        // emulator's delivery is modelled (see `Delivery`).
        let mono = matched.windows(2).all(|w| w[1].1 >= w[0].1)
            && fwd.frames.windows(2).all(|w| w[1].0 >= w[0].0);
        c.check(
            &format!("{name}: hub times monotonic"),
            mono,
            format!("{} frames", matched.len()),
        );
        let stamps: Vec<(usize, f64)> = matched
            .iter()
            .map(|&(j, t)| (origs[j].end, t as f64))
            .collect();
        let last = Delivery::fit(s, &stamps);
        let beyond = last.dev_ms.iter().filter(|d| d.abs() > tol_ms).count();
        c.check(
            &format!(
                "{name}: hub times within {tol_ms} ms of the replay schedule (95% of frames), all within {max_ms} ms"
            ),
            last.p95_ms <= tol_ms && last.max_ms <= max_ms,
            format!(
                "after the offset {:.3} s and the emulator's delivery at {:.1} kB/s: 95% within {:.2} ms, max |dev| {:.2} ms, mean {:.2} ms; {beyond} of {} beyond {tol_ms} ms",
                last.offset_ns * 1e-9,
                last.rate * 1e-3,
                last.p95_ms,
                last.max_ms,
                last.mean_ms,
                stamps.len()
            ),
        );
        c.check(
            &format!("{name}: hub clock rate = the replay's"),
            (last.slope - 1.0).abs() <= 0.01,
            format!(
                "hub time against the modelled receive time: slope {:.5} (1 +- 0.01)",
                last.slope
            ),
        );
        let (median, max, mean, dev) = (last.offset_ns, last.max_ms, last.mean_ms, &last.dev_ms);
        offsets.push(median);
        if let Some(dir) = args.get("residuals") {
            let rows: String = matched
                .iter()
                .zip(dev)
                .map(|(&(j, t), d)| {
                    let len = origs[j].end - origs[j].start;
                    let due = due_ns(s, origs[j].end as u64) * 1e-9;
                    format!("{j},{len},{:.6},{due:.6},{d:.3}\n", t as f64 * 1e-9)
                })
                .collect();
            let _ = std::fs::write(
                format!("{dir}/{name}-residuals.csv"),
                format!("frame,bytes,hub_s,due_s,dev_ms\n{rows}"),
            );
        }
        summary.insert(
            name.into(),
            serde_json::json!({
                "session_frames": origs.len(), "forwarded": fwd.frames.len(), "lost": lost,
                "rx_bytes": ph.rx_bytes, "bytes_skipped": ph.bytes_skipped,
                "frames_bad": ph.frames_bad, "frames_retracted": ph.frames_retracted,
                "ring_high_water": ph.ring_high_water, "offset_s": median * 1e-9,
                "dev_max_ms": max, "dev_mean_ms": mean, "dev_p95_ms": last.p95_ms,
                "delivery_bytes_per_s": last.rate, "clock_slope": last.slope, "beyond_tolerance": beyond,
            }),
        );
    }
    summary.insert(
        "health".into(),
        serde_json::json!({
            "timer_hz": h.timer_hz, "link_sent": h.link_sent, "link_high_water": h.link_high_water,
            "stamps_merged": h.stamps_merged, "isr_max_per_byte": h.isr_max_per_byte,
            "isr_clock": h.isr_clock,
        }),
    );
    println!("{}", serde_json::Value::Object(summary));
    if c.failed > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
