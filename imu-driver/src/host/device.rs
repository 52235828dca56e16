//! Device control over a serial port (or any `Read + Write`, e.g. a pseudo-terminal).

use super::reader::{Event, Reader};
use crate::encode::{EncodeError, HostMessage, BID_MASTER};
use crate::message::{
    mid, Baudrate, ErrorCode, FirmwareRev, Message, MessageError, OutputConfiguration,
    OutputSetting,
};
use crate::mtdata2::DataId;
use std::fmt;
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

/// The control steps, named in errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControlStep {
    /// Waiting for the device's WakeUp after power-up or reset.
    WakeUp,
    /// GoToConfig / its ack.
    GoToConfig,
    /// ReqDID / DeviceID.
    ReqDeviceId,
    /// ReqProductCode / ProductCode.
    ReqProductCode,
    /// ReqFWRev / FirmwareRev.
    ReqFirmwareRev,
    /// SetOutputConfiguration / its ack.
    SetOutputConfiguration,
    /// SetBaudrate / its ack.
    SetBaudrate,
    /// Reset / ResetAck.
    Reset,
    /// GoToMeasurement / its ack.
    GoToMeasurement,
}

impl fmt::Display for ControlStep {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            Self::WakeUp => "WakeUp",
            Self::GoToConfig => "GoToConfig",
            Self::ReqDeviceId => "ReqDID",
            Self::ReqProductCode => "ReqProductCode",
            Self::ReqFirmwareRev => "ReqFWRev",
            Self::SetOutputConfiguration => "SetOutputConfiguration",
            Self::SetBaudrate => "SetBaudrate",
            Self::Reset => "Reset",
            Self::GoToMeasurement => "GoToMeasurement",
        };
        f.write_str(s)
    }
}

/// A failed control step.
#[derive(Debug)]
pub enum DeviceError {
    /// Opening or configuring the serial port failed.
    Port(serialport::Error),
    /// Reading or writing failed (end of input included).
    Io {
        /// The step.
        step: ControlStep,
        /// The I/O error.
        source: io::Error,
    },
    /// No reply within the step's timeout.
    Timeout {
        /// The step.
        step: ControlStep,
        /// How long it waited.
        waited: Duration,
        /// Other frames seen meanwhile (e.g. MTData2 still streaming).
        other_frames: u64,
    },
    /// The device answered with an Error message.
    Rejected {
        /// The step.
        step: ControlStep,
        /// The error code.
        code: ErrorCode,
        /// Detail bytes.
        detail: Vec<u8>,
    },
    /// The reply did not decode.
    BadReply {
        /// The step.
        step: ControlStep,
        /// Why.
        error: MessageError,
    },
    /// The request could not be encoded (e.g. more than 32 outputs).
    Encode {
        /// The step.
        step: ControlStep,
        /// Why.
        error: EncodeError,
    },
}

impl fmt::Display for DeviceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Port(e) => write!(f, "serial port: {e}"),
            Self::Io { step, source } => write!(f, "{step}: I/O error: {source}"),
            Self::Timeout {
                step,
                waited,
                other_frames,
            } => write!(
                f,
                "{step}: no reply within {} ms ({other_frames} other frames seen)",
                waited.as_millis()
            ),
            Self::Rejected { step, code, detail } => {
                write!(f, "{step}: device replied Error {code}")?;
                if !detail.is_empty() {
                    write!(f, " detail {detail:02X?}")?;
                }
                Ok(())
            }
            Self::BadReply { step, error } => write!(f, "{step}: bad reply: {error}"),
            Self::Encode { step, error } => write!(f, "{step}: {error}"),
        }
    }
}

impl std::error::Error for DeviceError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Port(e) => Some(e),
            Self::Io { source, .. } => Some(source),
            Self::BadReply { error, .. } => Some(error),
            Self::Encode { error, .. } => Some(error),
            _ => None,
        }
    }
}

impl From<serialport::Error> for DeviceError {
    fn from(e: serialport::Error) -> Self {
        Self::Port(e)
    }
}

/// A reply frame, owned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    /// Message id.
    pub mid: u8,
    /// Payload.
    pub payload: Vec<u8>,
    /// Host time of its last byte.
    pub at: Instant,
}

/// A requested rate that the device did not grant as asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RateDifference {
    /// The output.
    pub id: DataId,
    /// Requested rate \[Hz\] (`None`: not requested, yet configured).
    pub requested: Option<u16>,
    /// Rate in force \[Hz\] (`None`: requested but absent from the ack).
    pub actual: Option<u16>,
}

impl fmt::Display for RateDifference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let show = |r: Option<u16>| match r {
            None => "absent".to_string(),
            Some(0 | 0xFFFF) => "max".to_string(),
            Some(hz) => format!("{hz} Hz"),
        };
        write!(
            f,
            "{}: requested {}, device uses {}",
            self.id,
            show(self.requested),
            show(self.actual)
        )
    }
}

/// The outcome of SetOutputConfiguration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutputReport {
    /// What was asked.
    pub requested: Vec<OutputSetting>,
    /// What the ack says is in force.
    pub actual: Vec<OutputSetting>,
    /// Every difference between the two.
    pub differences: Vec<RateDifference>,
}

/// Compares requested output rates with an ack's (0 and 0xFFFF both mean "max").
pub fn compare_rates(requested: &[OutputSetting], actual: &[OutputSetting]) -> Vec<RateDifference> {
    let same = |a: &OutputSetting, b: &OutputSetting| {
        a.rate_hz == b.rate_hz || (a.is_max_rate() && b.is_max_rate())
    };
    let mut out = Vec::new();
    for r in requested {
        match actual.iter().find(|a| a.id == r.id) {
            Some(a) if same(r, a) => {}
            Some(a) => out.push(RateDifference {
                id: r.id,
                requested: Some(r.rate_hz),
                actual: Some(a.rate_hz),
            }),
            None => out.push(RateDifference {
                id: r.id,
                requested: Some(r.rate_hz),
                actual: None,
            }),
        }
    }
    for a in actual {
        if !requested.iter().any(|r| r.id == a.id) {
            out.push(RateDifference {
                id: a.id,
                requested: None,
                actual: Some(a.rate_hz),
            });
        }
    }
    out
}

/// Changing the host side's baud rate (serial ports; a pty accepts it and ignores it).
pub trait HostBaud {
    /// Sets the host port's baud rate.
    fn set_host_baud(&mut self, bps: u32) -> io::Result<()>;
}

impl HostBaud for Box<dyn serialport::SerialPort> {
    fn set_host_baud(&mut self, bps: u32) -> io::Result<()> {
        self.set_baud_rate(bps).map_err(io::Error::from)
    }
}

#[cfg(unix)]
impl HostBaud for serialport::TTYPort {
    fn set_host_baud(&mut self, bps: u32) -> io::Result<()> {
        serialport::SerialPort::set_baud_rate(self, bps).map_err(io::Error::from)
    }
}

/// What [`Device::configure`] does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    /// Outputs to configure (at most 32); empty leaves the configuration as it is.
    pub outputs: Vec<OutputSetting>,
    /// A new baud rate (SetBaudrate, Reset, then the host follows).
    pub baudrate: Option<Baudrate>,
    /// Enter measurement mode at the end.
    pub measure: bool,
}

/// What [`Device::configure`] found and did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigReport {
    /// Device id.
    pub device_id: u64,
    /// Product code.
    pub product_code: String,
    /// Firmware revision.
    pub firmware: FirmwareRev,
    /// The output configuration outcome (`None` when the plan had no outputs).
    pub outputs: Option<OutputReport>,
    /// The baud rate switched to.
    pub baudrate: Option<Baudrate>,
    /// Frames that were not the awaited reply (MTData2 still streaming, ...).
    pub other_frames: u64,
}

/// Control of one device: each step sends a request and waits for its specific reply, skipping
/// anything else (MTData2 keeps streaming until GoToConfig takes effect), with a timeout.
///
/// The port's own read timeout should be short (10-50 ms): it bounds how late a step notices its
/// deadline.
#[derive(Debug)]
pub struct Device<P> {
    reader: Reader<P>,
    bid: u8,
    timeout: Duration,
    other_frames: u64,
}

impl Device<Box<dyn serialport::SerialPort>> {
    /// Opens a serial port (8N1, no flow control, 20 ms read timeout).
    pub fn open(path: &str, baud: u32) -> Result<Self, DeviceError> {
        let port = serialport::new(path, baud)
            .timeout(Duration::from_millis(20))
            .open()?;
        Ok(Self::new(port))
    }
}

impl<P: Read + Write> Device<P> {
    /// Controls the device on `port` (bus id 0xFF, 1 s per step).
    pub fn new(port: P) -> Self {
        Self {
            reader: Reader::new(port),
            bid: BID_MASTER,
            timeout: Duration::from_secs(1),
            other_frames: 0,
        }
    }

    /// Sets the timeout of each step.
    pub fn with_timeout(mut self, timeout: Duration) -> Self {
        self.timeout = timeout;
        self
    }

    /// Sets the bus id requests are addressed to (replies echo it).
    pub fn with_bus_id(mut self, bid: u8) -> Self {
        self.bid = bid;
        self
    }

    /// The underlying reader (to stream measurements after configuration).
    pub fn reader(&mut self) -> &mut Reader<P> {
        &mut self.reader
    }

    /// Gives the reader back.
    pub fn into_reader(self) -> Reader<P> {
        self.reader
    }

    /// Frames seen that were not an awaited reply.
    pub fn other_frames(&self) -> u64 {
        self.other_frames
    }

    /// Sends one message.
    pub fn send(&mut self, step: ControlStep, msg: &HostMessage<'_>) -> Result<(), DeviceError> {
        let mut buf = [0u8; 8 + 4 * crate::encode::MAX_OUTPUT_SETTINGS];
        let n = msg
            .encode(self.bid, &mut buf)
            .map_err(|error| DeviceError::Encode { step, error })?;
        let port = self.reader.get_mut();
        port.write_all(buf.get(..n).unwrap_or_default())
            .and_then(|()| port.flush())
            .map_err(|source| DeviceError::Io { step, source })
    }

    /// Waits for a frame with MID `want` until `deadline`; an Error message fails the step.
    pub fn await_mid(
        &mut self,
        step: ControlStep,
        want: u8,
        deadline: Instant,
    ) -> Result<Reply, DeviceError> {
        let started = Instant::now();
        let seen_before = self.other_frames;
        loop {
            if Instant::now() >= deadline {
                return Err(DeviceError::Timeout {
                    step,
                    waited: started.elapsed(),
                    other_frames: self.other_frames - seen_before,
                });
            }
            match self.reader.next_event() {
                Ok(Some(Event::Frame { frame, at })) => {
                    if frame.mid() == want {
                        return Ok(Reply {
                            mid: want,
                            payload: frame.payload().to_vec(),
                            at,
                        });
                    }
                    if let Ok(Message::Error { code, detail }) = Message::decode(&frame) {
                        return Err(DeviceError::Rejected {
                            step,
                            code,
                            detail: detail.to_vec(),
                        });
                    }
                    self.other_frames += 1;
                }
                Ok(Some(Event::Dropped { .. })) => {}
                Ok(None) => {
                    return Err(DeviceError::Io {
                        step,
                        source: io::ErrorKind::UnexpectedEof.into(),
                    })
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                    ) => {}
                Err(source) => return Err(DeviceError::Io { step, source }),
            }
        }
    }

    /// Sends a request and waits for its reply (MID + 1).
    pub fn request(
        &mut self,
        step: ControlStep,
        msg: &HostMessage<'_>,
    ) -> Result<Reply, DeviceError> {
        self.send(step, msg)?;
        let want = msg.reply_mid().unwrap_or(mid::MTDATA2);
        self.await_mid(step, want, Instant::now() + self.timeout)
    }

    /// Waits for the device's WakeUp (after power-up or reset) and answers WakeUpAck so it stays
    /// in config mode.
    pub fn wake_up(&mut self) -> Result<(), DeviceError> {
        let step = ControlStep::WakeUp;
        self.await_mid(step, mid::WAKE_UP, Instant::now() + self.timeout)?;
        self.send(step, &HostMessage::WakeUpAck)
    }

    /// Enters config mode, resending GoToConfig three times within the timeout while the
    /// device may still be streaming.
    pub fn go_to_config(&mut self) -> Result<(), DeviceError> {
        let step = ControlStep::GoToConfig;
        let deadline = Instant::now() + self.timeout;
        let slice = self.timeout / 3;
        let started = Instant::now();
        let seen_before = self.other_frames;
        for attempt in 1..=3u32 {
            self.send(step, &HostMessage::GoToConfig)?;
            let until = if attempt == 3 {
                deadline
            } else {
                (Instant::now() + slice).min(deadline)
            };
            match self.await_mid(step, mid::GO_TO_CONFIG_ACK, until) {
                Ok(_) => return Ok(()),
                Err(DeviceError::Timeout { .. }) if attempt < 3 => {}
                Err(DeviceError::Timeout { .. }) => break,
                Err(e) => return Err(e),
            }
        }
        Err(DeviceError::Timeout {
            step,
            waited: started.elapsed(),
            other_frames: self.other_frames - seen_before,
        })
    }

    /// Enters measurement mode.
    pub fn go_to_measurement(&mut self) -> Result<(), DeviceError> {
        self.request(ControlStep::GoToMeasurement, &HostMessage::GoToMeasurement)
            .map(drop)
    }

    fn decode<T>(
        &mut self,
        step: ControlStep,
        msg: HostMessage<'_>,
        pick: impl FnOnce(Message<'_>) -> Option<T>,
    ) -> Result<T, DeviceError> {
        let reply = self.request(step, &msg)?;
        let m = Message::decode_payload(reply.mid, &reply.payload)
            .map_err(|error| DeviceError::BadReply { step, error })?;
        pick(m).ok_or(DeviceError::BadReply {
            step,
            error: MessageError::BadLength {
                mid: reply.mid,
                len: reply.payload.len(),
                expected: "the reply's layout",
            },
        })
    }

    /// The device id.
    pub fn device_id(&mut self) -> Result<u64, DeviceError> {
        self.decode(
            ControlStep::ReqDeviceId,
            HostMessage::ReqDeviceId,
            |m| match m {
                Message::DeviceId(id) => Some(id),
                _ => None,
            },
        )
    }

    /// The product code.
    pub fn product_code(&mut self) -> Result<String, DeviceError> {
        self.decode(
            ControlStep::ReqProductCode,
            HostMessage::ReqProductCode,
            |m| match m {
                Message::ProductCode(p) => Some(String::from_utf8_lossy(p).into_owned()),
                _ => None,
            },
        )
    }

    /// The firmware revision.
    pub fn firmware_rev(&mut self) -> Result<FirmwareRev, DeviceError> {
        self.decode(
            ControlStep::ReqFirmwareRev,
            HostMessage::ReqFirmwareRev,
            |m| match m {
                Message::FirmwareRev(f) => Some(f),
                _ => None,
            },
        )
    }

    /// Sets the outputs and compares the rates in the ack with the request.
    pub fn set_output_configuration(
        &mut self,
        outputs: &[OutputSetting],
    ) -> Result<OutputReport, DeviceError> {
        let step = ControlStep::SetOutputConfiguration;
        let reply = self.request(step, &HostMessage::SetOutputConfiguration(outputs))?;
        let config = OutputConfiguration::new_checked(&reply.payload)
            .map_err(|error| DeviceError::BadReply { step, error })?;
        let actual: Vec<OutputSetting> = config.settings().collect();
        Ok(OutputReport {
            differences: compare_rates(outputs, &actual),
            requested: outputs.to_vec(),
            actual,
        })
    }

    /// Sets the device's baud rate (effective after a reset).
    pub fn set_baudrate(&mut self, baud: Baudrate) -> Result<(), DeviceError> {
        self.request(ControlStep::SetBaudrate, &HostMessage::SetBaudrate(baud))
            .map(drop)
    }

    /// Resets the device.
    pub fn reset(&mut self) -> Result<(), DeviceError> {
        self.request(ControlStep::Reset, &HostMessage::Reset)
            .map(drop)
    }
}

impl<P: Read + Write + HostBaud> Device<P> {
    /// Switches device and host to `baud`: SetBaudrate, Reset, host follows, then WakeUp (or
    /// GoToConfig when no WakeUp is seen) to stay in config mode.
    pub fn change_baudrate(&mut self, baud: Baudrate) -> Result<(), DeviceError> {
        self.set_baudrate(baud)?;
        self.reset()?;
        self.reader
            .get_mut()
            .set_host_baud(baud.bps())
            .map_err(|source| DeviceError::Io {
                step: ControlStep::SetBaudrate,
                source,
            })?;
        self.reader.discard();
        match self.wake_up() {
            Ok(()) => Ok(()),
            Err(DeviceError::Timeout { .. }) => self.go_to_config(),
            Err(e) => Err(e),
        }
    }

    /// Runs the whole sequence: GoToConfig, identity, outputs, optional baud change, optional
    /// GoToMeasurement.
    pub fn configure(&mut self, plan: &Plan) -> Result<ConfigReport, DeviceError> {
        let before = self.other_frames;
        self.go_to_config()?;
        let device_id = self.device_id()?;
        let product_code = self.product_code()?;
        let firmware = self.firmware_rev()?;
        let outputs = if plan.outputs.is_empty() {
            None
        } else {
            Some(self.set_output_configuration(&plan.outputs)?)
        };
        if let Some(b) = plan.baudrate {
            self.change_baudrate(b)?;
        }
        if plan.measure {
            self.go_to_measurement()?;
        }
        Ok(ConfigReport {
            device_id,
            product_code,
            firmware,
            outputs,
            baudrate: plan.baudrate,
            other_frames: self.other_frames - before,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_differences_are_reported_both_ways() {
        let s = |id, rate_hz| OutputSetting {
            id: DataId(id),
            rate_hz,
        };
        let requested = [
            s(0x1020, 0),
            s(0x4020, 400),
            s(0x8020, 400),
            s(0x1060, 0xFFFF),
        ];
        let actual = [
            s(0x1020, 0xFFFF),
            s(0x4020, 100),
            s(0x1060, 0xFFFF),
            s(0xE020, 0xFFFF),
        ];
        let d = compare_rates(&requested, &actual);
        assert_eq!(
            d,
            vec![
                RateDifference {
                    id: DataId(0x4020),
                    requested: Some(400),
                    actual: Some(100)
                },
                RateDifference {
                    id: DataId(0x8020),
                    requested: Some(400),
                    actual: None
                },
                RateDifference {
                    id: DataId(0xE020),
                    requested: None,
                    actual: Some(0xFFFF)
                },
            ]
        );
        assert_eq!(
            d[0].to_string(),
            "Acceleration(Float32): requested 400 Hz, device uses 100 Hz"
        );
    }
}
