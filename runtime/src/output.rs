//! Pose outputs: UDP (one pose-link message per datagram), serial (COBS-framed with
//! `pose_link::encode_serial`), TUM files (radar-rate poses unless asked for the predicted ones).

use pose_link::{encode_serial, Health, PoseMessage, MESSAGE_LEN, SERIAL_FRAME_MAX};
use std::io::{self, Write};
use std::net::UdpSocket;

/// Where poses go, as given on the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutputSpec {
    /// `udp://HOST:PORT`.
    Udp(String),
    /// `serial:DEV[@BAUD]`.
    Serial(String, u32),
    /// `tum:FILE`.
    Tum(std::path::PathBuf),
}

impl std::str::FromStr for OutputSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if let Some(a) = s.strip_prefix("udp://") {
            if a.rsplit_once(':')
                .is_none_or(|(_, p)| p.parse::<u16>().is_err())
            {
                return Err(format!("output {s:?}: expected udp://HOST:PORT"));
            }
            Ok(OutputSpec::Udp(a.to_string()))
        } else if let Some(d) = s.strip_prefix("serial:") {
            match d.rsplit_once('@') {
                Some((dev, b)) => b
                    .parse()
                    .map(|b| OutputSpec::Serial(dev.to_string(), b))
                    .map_err(|_| format!("output {s:?}: bad baud rate {b:?}")),
                None if !d.is_empty() => Ok(OutputSpec::Serial(d.to_string(), 921_600)),
                None => Err(format!("output {s:?}: expected serial:DEV[@BAUD]")),
            }
        } else if let Some(f) = s.strip_prefix("tum:") {
            if f.is_empty() {
                return Err(format!("output {s:?}: expected tum:FILE"));
            }
            Ok(OutputSpec::Tum(f.into()))
        } else {
            Err(format!(
                "output {s:?}: expected udp://HOST:PORT, serial:DEV[@BAUD] or tum:FILE"
            ))
        }
    }
}

/// An open output.
pub enum Sink {
    /// UDP socket, connected to the destination.
    Udp(UdpSocket),
    /// Serial port.
    Serial(Box<dyn serialport::SerialPort>),
    /// TUM file; `predicted` also writes IMU-rate poses.
    Tum(io::BufWriter<std::fs::File>, bool),
    /// Anything else (tests).
    Writer(Box<dyn Write + Send>),
}

impl std::fmt::Debug for Sink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Sink::Udp(_) => "Sink::Udp",
            Sink::Serial(_) => "Sink::Serial",
            Sink::Tum(..) => "Sink::Tum",
            Sink::Writer(_) => "Sink::Writer",
        })
    }
}

/// An output that could not be opened: which one, and the operating system's error.
#[derive(Debug)]
pub struct SinkError {
    /// The output as given (`udp://HOST:PORT`, `serial:DEV[@BAUD]`, `tum:PATH`).
    pub spec: OutputSpec,
    /// Why it could not be opened.
    pub error: io::Error,
}

impl std::fmt::Display for SinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.spec {
            OutputSpec::Udp(a) => write!(f, "udp://{a}: {}", self.error),
            OutputSpec::Serial(d, _) => write!(f, "serial:{d}: {}", self.error),
            OutputSpec::Tum(p) => write!(f, "tum:{}: {}", p.display(), self.error),
        }
    }
}

impl std::error::Error for SinkError {}

impl Sink {
    /// Opens `spec`; `tum_predicted` makes TUM files include predicted poses.
    pub fn open(spec: &OutputSpec, tum_predicted: bool) -> Result<Sink, SinkError> {
        let fail = |error: io::Error| SinkError {
            spec: spec.clone(),
            error,
        };
        match spec {
            OutputSpec::Udp(a) => {
                let s = UdpSocket::bind(("0.0.0.0", 0)).map_err(fail)?;
                s.connect(a.as_str()).map_err(fail)?;
                Ok(Sink::Udp(s))
            }
            OutputSpec::Serial(d, b) => serialport::new(d, *b)
                .timeout(std::time::Duration::from_millis(100))
                .open()
                .map(Sink::Serial)
                .map_err(|e| fail(e.into())),
            OutputSpec::Tum(p) => std::fs::File::create(p)
                .map(|f| Sink::Tum(io::BufWriter::new(f), tum_predicted))
                .map_err(fail),
        }
    }

    /// Sends one pose at time `t` \[s\] (`bytes`: its encoding; `serial`: its COBS frame).
    pub fn send(&mut self, m: &PoseMessage, t: f64, bytes: &[u8], serial: &[u8]) -> io::Result<()> {
        match self {
            Sink::Udp(s) => match s.send(bytes) {
                // Nobody listening yet: the datagram is lost, as UDP allows.
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => Ok(()),
                r => r.map(|_| ()),
            },
            Sink::Serial(p) => p.write_all(serial),
            Sink::Writer(w) => w.write_all(serial),
            Sink::Tum(w, predicted) => {
                if m.health.contains(Health::PREDICTED) && !*predicted {
                    return Ok(());
                }
                let [qw, qx, qy, qz] = m.orientation;
                writeln!(
                    w,
                    "{:.9} {:.6} {:.6} {:.6} {:.9} {:.9} {:.9} {:.9}",
                    t, m.position[0], m.position[1], m.position[2], qx, qy, qz, qw
                )
            }
        }
    }

    /// Flushes buffered output.
    pub fn flush(&mut self) -> io::Result<()> {
        match self {
            Sink::Tum(w, _) => w.flush(),
            Sink::Serial(p) => p.flush(),
            Sink::Writer(w) => w.flush(),
            Sink::Udp(_) => Ok(()),
        }
    }
}

/// Encodes a message for every transport, into fixed buffers.
#[derive(Debug)]
pub struct Encoded {
    /// The 104-byte message.
    pub bytes: [u8; MESSAGE_LEN],
    /// COBS frame with its delimiter.
    pub serial: [u8; SERIAL_FRAME_MAX],
    /// Length of `serial` in use.
    pub serial_len: usize,
}

impl Default for Encoded {
    fn default() -> Self {
        Encoded {
            bytes: [0; MESSAGE_LEN],
            serial: [0; SERIAL_FRAME_MAX],
            serial_len: 0,
        }
    }
}

impl Encoded {
    /// Encodes `m` (never fails for buffers of these sizes).
    pub fn encode(&mut self, m: &PoseMessage) {
        let _ = m.encode(&mut self.bytes);
        self.serial_len = encode_serial(m, &mut self.serial).unwrap_or(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pose_link::{Deframer, Event};
    use std::sync::{Arc, Mutex};

    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);
    impl Write for Shared {
        fn write(&mut self, b: &[u8]) -> io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn output_specs_parse() {
        assert_eq!(
            "udp://127.0.0.1:9870".parse(),
            Ok(OutputSpec::Udp("127.0.0.1:9870".into()))
        );
        assert_eq!(
            "serial:/dev/ttyUSB2@460800".parse(),
            Ok(OutputSpec::Serial("/dev/ttyUSB2".into(), 460_800))
        );
        assert_eq!(
            "serial:/dev/ttyUSB2".parse(),
            Ok(OutputSpec::Serial("/dev/ttyUSB2".into(), 921_600))
        );
        assert_eq!("tum:a.tum".parse(), Ok(OutputSpec::Tum("a.tum".into())));
        assert!("udp://host".parse::<OutputSpec>().is_err());
        assert!("file:x".parse::<OutputSpec>().is_err());
    }

    #[test]
    fn serial_frames_decode_with_the_pose_link_deframer() {
        let buf = Shared::default();
        let mut sink = Sink::Writer(Box::new(buf.clone()));
        let mut enc = Encoded::default();
        let msgs: Vec<PoseMessage> = (0..3u32)
            .map(|k| PoseMessage {
                seq: k,
                position: [f64::from(k), 0.0, 0.0],
                health: Health::PREDICTED,
                ..PoseMessage::default()
            })
            .collect();
        for m in &msgs {
            enc.encode(m);
            sink.send(m, 0.0, &enc.bytes, &enc.serial[..enc.serial_len])
                .unwrap();
        }
        let bytes = buf.0.lock().unwrap().clone();
        let mut d: Deframer<256> = Deframer::default();
        let mut input = &bytes[..];
        let mut got = Vec::new();
        loop {
            match d.poll(&mut input) {
                Event::Message(m) => got.push(m),
                Event::NeedMore => break,
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(got, msgs);
    }
}
