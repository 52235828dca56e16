//! `milliego pose listen`: decode a pose stream from UDP or serial, print it, optionally save it
//! as a TUM trajectory.

use crate::output;
use clap::{Args, Subcommand};
use pose_link::{Deframer, Event, PoseMessage, SERIAL_FRAME_MAX};
use serde_json::json;
use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::UdpSocket;
use std::time::{Duration, Instant};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Subcommand)]
pub enum PoseCmd {
    /// Listen on `udp://ADDR:PORT` or `serial:DEV[@BAUD]`; one JSON object per pose on stdout.
    Listen(ListenArgs),
}

#[derive(Debug, Args)]
pub struct ListenArgs {
    /// `udp://ADDR:PORT` (e.g. udp://0.0.0.0:9870) or `serial:DEV[@BAUD]` (default 921600 baud).
    endpoint: String,
    /// Also write the trajectory as TUM (t tx ty tz qx qy qz qw; t = sensor time in s).
    #[arg(long)]
    tum: Option<std::path::PathBuf>,
    /// Stop after this many good messages.
    #[arg(long)]
    count: Option<u64>,
    /// Stop after this many seconds.
    #[arg(long)]
    seconds: Option<f64>,
    /// Print only the closing summary.
    #[arg(long)]
    quiet: bool,
}

enum Source {
    Udp(UdpSocket),
    Serial(
        Box<dyn serialport::SerialPort>,
        Box<Deframer<SERIAL_FRAME_MAX>>,
    ),
}

#[derive(Default)]
struct Stats {
    messages: u64,
    seq_gaps: u64,
    seq_missing: u64,
    last_seq: Option<u32>,
    bad: BTreeMap<String, u64>,
}

impl Stats {
    fn note(&mut self, m: &PoseMessage) {
        self.messages += 1;
        if let Some(last) = self.last_seq {
            let step = m.seq.wrapping_sub(last);
            if step != 1 {
                self.seq_gaps += 1;
                if step < u32::MAX / 2 {
                    self.seq_missing += u64::from(step.saturating_sub(1));
                }
            }
        }
        self.last_seq = Some(m.seq);
    }
    fn bad(&mut self, what: &str) {
        *self.bad.entry(what.to_string()).or_default() += 1;
    }
}

pub fn run(cmd: PoseCmd) -> Result<()> {
    match cmd {
        PoseCmd::Listen(a) => listen(a),
    }
}

fn open(endpoint: &str) -> Result<Source> {
    if let Some(addr) = endpoint.strip_prefix("udp://") {
        let sock = UdpSocket::bind(addr).map_err(|e| format!("{endpoint}: cannot bind: {e}"))?;
        sock.set_read_timeout(Some(Duration::from_millis(100)))?;
        eprintln!("milliego: listening on udp://{}", sock.local_addr()?);
        return Ok(Source::Udp(sock));
    }
    if let Some(spec) = endpoint.strip_prefix("serial:") {
        let (dev, baud) = match spec.rsplit_once('@') {
            Some((d, b)) => (
                d,
                b.parse::<u32>()
                    .map_err(|_| format!("{endpoint}: baud {b:?} is not a number"))?,
            ),
            None => (spec, 921_600),
        };
        let port = serialport::new(dev, baud)
            .timeout(Duration::from_millis(100))
            .open()
            .map_err(|e| format!("{dev}: {e}"))?;
        eprintln!("milliego: listening on serial:{dev}@{baud}");
        return Ok(Source::Serial(port, Box::default()));
    }
    Err(format!("{endpoint}: expected udp://ADDR:PORT or serial:DEV[@BAUD]").into())
}

fn listen(a: ListenArgs) -> Result<()> {
    let mut src = open(&a.endpoint)?;
    let mut tum = match &a.tum {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?,
        )),
        None => None,
    };
    let mut out = output::stdout();
    let mut stats = Stats::default();
    let start = Instant::now();
    let mut buf = vec![0u8; 65_536];
    let mut open_out = true;
    'outer: loop {
        if a.count.is_some_and(|n| stats.messages >= n)
            || a.seconds
                .is_some_and(|s| start.elapsed().as_secs_f64() >= s)
        {
            break;
        }
        let mut got: Vec<PoseMessage> = Vec::new();
        match &mut src {
            Source::Udp(sock) => match sock.recv(&mut buf) {
                Ok(n) => match PoseMessage::decode(&buf[..n]) {
                    Ok(m) => got.push(m),
                    Err(e) => {
                        eprintln!("milliego: dropped datagram of {n} B: {e}");
                        stats.bad(e.kind_name());
                    }
                },
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => return Err(e.into()),
            },
            Source::Serial(port, deframer) => match port.read(&mut buf) {
                Ok(n) => {
                    let mut input = &buf[..n];
                    loop {
                        match deframer.poll(&mut input) {
                            Event::Message(m) => got.push(m),
                            Event::BadFrame(e) => {
                                eprintln!("milliego: dropped serial frame: {e}");
                                stats.bad(e.kind_name());
                            }
                            Event::NeedMore => break,
                        }
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => return Err(format!("{}: {e}", a.endpoint).into()),
            },
        }
        for m in got {
            stats.note(&m);
            if let Some(t) = tum.as_mut() {
                let q = m.orientation;
                writeln!(
                    t,
                    "{:.9} {} {} {} {} {} {} {}",
                    m.measurement_time_ns as f64 / 1e9,
                    m.position[0],
                    m.position[1],
                    m.position[2],
                    q[1],
                    q[2],
                    q[3],
                    q[0]
                )?;
            }
            if !a.quiet && open_out {
                let v = json!({
                    "seq": m.seq,
                    "estimator": m.estimator.name(),
                    "health": m.health.names().collect::<Vec<_>>(),
                    "measurement_time_s": m.measurement_time_ns as f64 / 1e9,
                    "host_time_s": m.host_time_ns as f64 / 1e9,
                    "position": m.position,
                    "orientation_wxyz": m.orientation,
                    "rel_translation": m.rel_translation,
                    "rel_rotation_wxyz": m.rel_rotation,
                    "dropped_total": m.dropped_total,
                });
                open_out = output::line(&mut out, &v.to_string())?;
                out.flush().ok();
            }
            if a.count.is_some_and(|n| stats.messages >= n) {
                break 'outer;
            }
        }
    }
    if let Some(mut t) = tum {
        t.flush()?;
    }
    let summary = json!({
        "endpoint": a.endpoint,
        "messages": stats.messages,
        "seq_gaps": stats.seq_gaps,
        "seq_missing": stats.seq_missing,
        "dropped_by_reason": stats.bad,
    });
    eprintln!("milliego: {summary}");
    out.flush().ok();
    Ok(())
}
