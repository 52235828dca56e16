//! Message identifiers and the decoded messages a device sends.

use crate::frame::XbusFrame;
use crate::mtdata2::{DataId, MtData2, Precision};
use core::fmt;

/// Message identifiers (a reply's MID is its request's MID + 1).
pub mod mid {
    /// Requests the device id.
    pub const REQ_DID: u8 = 0x00;
    /// Device id (4 bytes; 8 on the 600 series).
    pub const DEVICE_ID: u8 = 0x01;
    /// Requests configuration mode.
    pub const GO_TO_CONFIG: u8 = 0x30;
    /// Acknowledges [`GO_TO_CONFIG`].
    pub const GO_TO_CONFIG_ACK: u8 = 0x31;
    /// Requests measurement mode.
    pub const GO_TO_MEASUREMENT: u8 = 0x10;
    /// Acknowledges [`GO_TO_MEASUREMENT`].
    pub const GO_TO_MEASUREMENT_ACK: u8 = 0x11;
    /// Requests the firmware revision.
    pub const REQ_FW_REV: u8 = 0x12;
    /// Firmware revision.
    pub const FIRMWARE_REV: u8 = 0x13;
    /// Requests (empty payload) or sets (1 byte) the baud rate.
    pub const SET_BAUDRATE: u8 = 0x18;
    /// Acknowledges or reports the baud rate.
    pub const SET_BAUDRATE_ACK: u8 = 0x19;
    /// Requests the product code.
    pub const REQ_PRODUCT_CODE: u8 = 0x1C;
    /// Product code (ASCII).
    pub const PRODUCT_CODE: u8 = 0x1D;
    /// Requests the legacy configuration block.
    pub const REQ_CONFIGURATION: u8 = 0x0C;
    /// Legacy configuration block (118 bytes).
    pub const CONFIGURATION: u8 = 0x0D;
    /// Legacy measurement data.
    pub const MTDATA: u8 = 0x32;
    /// Requests one MTData2 message (polled mode).
    pub const REQ_DATA: u8 = 0x34;
    /// Measurement data.
    pub const MTDATA2: u8 = 0x36;
    /// Sent by the device at power-up; answer with [`WAKE_UP_ACK`] within 500 ms to stay in config.
    pub const WAKE_UP: u8 = 0x3E;
    /// Acknowledges [`WAKE_UP`] (sent by the host).
    pub const WAKE_UP_ACK: u8 = 0x3F;
    /// Resets the device.
    pub const RESET: u8 = 0x40;
    /// Acknowledges [`RESET`].
    pub const RESET_ACK: u8 = 0x41;
    /// Error reply.
    pub const ERROR: u8 = 0x42;
    /// Warning.
    pub const WARNING: u8 = 0x43;
    /// Requests (empty) or sets (pairs) the output configuration.
    pub const SET_OUTPUT_CONFIGURATION: u8 = 0xC0;
    /// Output configuration actually in use.
    pub const OUTPUT_CONFIGURATION: u8 = 0xC1;
    /// Legacy output mode (bit field, 2 bytes).
    pub const SET_OUTPUT_MODE: u8 = 0xD0;
    /// Legacy output settings (bit field, 4 bytes).
    pub const SET_OUTPUT_SETTINGS: u8 = 0xD2;

    /// A human name of a MID, `None` if unknown.
    pub const fn name(mid: u8) -> Option<&'static str> {
        Some(match mid {
            REQ_DID => "ReqDID",
            DEVICE_ID => "DeviceID",
            GO_TO_CONFIG => "GoToConfig",
            GO_TO_CONFIG_ACK => "GoToConfigAck",
            GO_TO_MEASUREMENT => "GoToMeasurement",
            GO_TO_MEASUREMENT_ACK => "GoToMeasurementAck",
            REQ_FW_REV => "ReqFWRev",
            FIRMWARE_REV => "FirmwareRev",
            SET_BAUDRATE => "SetBaudrate",
            SET_BAUDRATE_ACK => "SetBaudrateAck",
            REQ_PRODUCT_CODE => "ReqProductCode",
            PRODUCT_CODE => "ProductCode",
            REQ_CONFIGURATION => "ReqConfiguration",
            CONFIGURATION => "Configuration",
            MTDATA => "MTData",
            REQ_DATA => "ReqData",
            MTDATA2 => "MTData2",
            WAKE_UP => "WakeUp",
            WAKE_UP_ACK => "WakeUpAck",
            RESET => "Reset",
            RESET_ACK => "ResetAck",
            ERROR => "Error",
            WARNING => "Warning",
            SET_OUTPUT_CONFIGURATION => "SetOutputConfiguration",
            OUTPUT_CONFIGURATION => "OutputConfiguration",
            SET_OUTPUT_MODE => "SetOutputMode",
            0xD1 => "OutputModeAck",
            SET_OUTPUT_SETTINGS => "SetOutputSettings",
            0xD3 => "OutputSettingsAck",
            _ => return None,
        })
    }
}

/// Error codes of the Error message (0x42); unknown codes are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorCode {
    /// 0x03: period sent is not within the valid range.
    PeriodOutOfRange,
    /// 0x04: message sent is invalid.
    InvalidMessage,
    /// 0x1E: timer overflow (sample rate too high for the outputs or baud rate).
    TimerOverflow,
    /// 0x20: requested baud rate is invalid.
    InvalidBaudrate,
    /// 0x21: a parameter is invalid or out of range.
    InvalidParameter,
    /// 0x28: device error; 5 bytes of detail follow.
    DeviceError,
    /// A code not listed above.
    Unknown(u8),
}

impl ErrorCode {
    /// Decodes a code byte.
    pub const fn from_u8(code: u8) -> Self {
        match code {
            0x03 => Self::PeriodOutOfRange,
            0x04 => Self::InvalidMessage,
            0x1E => Self::TimerOverflow,
            0x20 => Self::InvalidBaudrate,
            0x21 => Self::InvalidParameter,
            0x28 => Self::DeviceError,
            other => Self::Unknown(other),
        }
    }

    /// The code byte.
    pub const fn as_u8(self) -> u8 {
        match self {
            Self::PeriodOutOfRange => 0x03,
            Self::InvalidMessage => 0x04,
            Self::TimerOverflow => 0x1E,
            Self::InvalidBaudrate => 0x20,
            Self::InvalidParameter => 0x21,
            Self::DeviceError => 0x28,
            Self::Unknown(c) => c,
        }
    }

    /// What the code means.
    pub const fn text(self) -> &'static str {
        match self {
            Self::PeriodOutOfRange => "period out of range",
            Self::InvalidMessage => "invalid message",
            Self::TimerOverflow => "timer overflow",
            Self::InvalidBaudrate => "invalid baud rate",
            Self::InvalidParameter => "invalid parameter",
            Self::DeviceError => "device error",
            Self::Unknown(_) => "unknown error",
        }
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:02X} ({})", self.as_u8(), self.text())
    }
}

/// Baud rate codes of SetBaudrate (0x18).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Baudrate {
    /// 4,000,000 bd (0x0D).
    B4000000,
    /// 2,000,000 bd (0x0C).
    B2000000,
    /// 921,600 bd (0x80; 0x0A is accepted on input).
    B921600,
    /// 460,800 bd (0x00).
    B460800,
    /// 230,400 bd (0x01).
    B230400,
    /// 115,200 bd (0x02, the default).
    B115200,
    /// 57,600 bd (0x04).
    B57600,
    /// 38,400 bd (0x05).
    B38400,
    /// 19,200 bd (0x07).
    B19200,
    /// 9,600 bd (0x09).
    B9600,
}

impl Baudrate {
    /// The code sent in SetBaudrate.
    pub const fn code(self) -> u8 {
        match self {
            Self::B4000000 => 0x0D,
            Self::B2000000 => 0x0C,
            Self::B921600 => 0x80,
            Self::B460800 => 0x00,
            Self::B230400 => 0x01,
            Self::B115200 => 0x02,
            Self::B57600 => 0x04,
            Self::B38400 => 0x05,
            Self::B19200 => 0x07,
            Self::B9600 => 0x09,
        }
    }

    /// Decodes a code, `None` if unknown.
    pub const fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0x0D => Self::B4000000,
            0x0C => Self::B2000000,
            0x80 | 0x0A => Self::B921600,
            0x00 => Self::B460800,
            0x01 => Self::B230400,
            0x02 => Self::B115200,
            0x04 => Self::B57600,
            0x05 => Self::B38400,
            0x07 => Self::B19200,
            0x09 => Self::B9600,
            _ => return None,
        })
    }

    /// Bits per second.
    pub const fn bps(self) -> u32 {
        match self {
            Self::B4000000 => 4_000_000,
            Self::B2000000 => 2_000_000,
            Self::B921600 => 921_600,
            Self::B460800 => 460_800,
            Self::B230400 => 230_400,
            Self::B115200 => 115_200,
            Self::B57600 => 57_600,
            Self::B38400 => 38_400,
            Self::B19200 => 19_200,
            Self::B9600 => 9_600,
        }
    }

    /// The code for a bit rate, `None` if the device has none.
    pub const fn from_bps(bps: u32) -> Option<Self> {
        Some(match bps {
            4_000_000 => Self::B4000000,
            2_000_000 => Self::B2000000,
            921_600 => Self::B921600,
            460_800 => Self::B460800,
            230_400 => Self::B230400,
            115_200 => Self::B115200,
            57_600 => Self::B57600,
            38_400 => Self::B38400,
            19_200 => Self::B19200,
            9_600 => Self::B9600,
            _ => return None,
        })
    }
}

/// One entry of an output configuration: a data id and its rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputSetting {
    /// The output.
    pub id: DataId,
    /// Rate \[Hz\]; 0 and 0xFFFF mean "as fast as possible" ([`OutputSetting::MAX_RATE`]).
    pub rate_hz: u16,
}

impl OutputSetting {
    /// The "maximum rate" value.
    pub const MAX_RATE: u16 = 0xFFFF;

    /// True when the rate means "as fast as possible" (0 or 0xFFFF).
    pub const fn is_max_rate(&self) -> bool {
        self.rate_hz == 0 || self.rate_hz == Self::MAX_RATE
    }
}

/// An OutputConfiguration payload (the ack of SetOutputConfiguration): `N x (u16 id, u16 rate)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputConfiguration<'a> {
    payload: &'a [u8],
}

impl<'a> OutputConfiguration<'a> {
    /// Checks that the payload is whole pairs.
    pub fn new_checked(payload: &'a [u8]) -> Result<Self, MessageError> {
        if !payload.len().is_multiple_of(4) {
            return Err(MessageError::BadLength {
                mid: mid::OUTPUT_CONFIGURATION,
                len: payload.len(),
                expected: "a multiple of 4",
            });
        }
        Ok(Self { payload })
    }

    /// The settings in order.
    pub fn settings(&self) -> impl Iterator<Item = OutputSetting> + 'a {
        self.payload.chunks_exact(4).map(|c| {
            let [a, b, r0, r1] = [
                c.first().copied().unwrap_or(0),
                c.get(1).copied().unwrap_or(0),
                c.get(2).copied().unwrap_or(0),
                c.get(3).copied().unwrap_or(0),
            ];
            OutputSetting {
                id: DataId(u16::from_be_bytes([a, b])),
                rate_hz: u16::from_be_bytes([r0, r1]),
            }
        })
    }

    /// Number of settings.
    pub fn len(&self) -> usize {
        self.payload.len() / 4
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.payload.is_empty()
    }
}

/// Firmware revision (0x13).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FirmwareRev {
    /// Major version.
    pub major: u8,
    /// Minor version.
    pub minor: u8,
    /// Revision.
    pub revision: u8,
    /// Build number (newer firmware).
    pub build: Option<u32>,
    /// Source control revision (newer firmware).
    pub scm: Option<u32>,
}

impl fmt::Display for FirmwareRev {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.revision)?;
        if let Some(b) = self.build {
            write!(f, " build {b}")?;
        }
        if let Some(s) = self.scm {
            write!(f, " rev {s}")?;
        }
        Ok(())
    }
}

/// The main fields of the legacy Configuration block (0x0D, 118 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Configuration {
    /// Device id of the master.
    pub master_device_id: u32,
    /// Sampling period \[1/115200 s\].
    pub sampling_period: u16,
    /// Output skip factor.
    pub output_skip_factor: u16,
    /// Sync-in mode.
    pub sync_in_mode: u16,
    /// Sync-in skip factor.
    pub sync_in_skip_factor: u16,
    /// Sync-in offset.
    pub sync_in_offset: u32,
    /// Number of devices.
    pub num_devices: u16,
    /// Device id of the first device.
    pub device_id: u32,
    /// Length of its legacy MTData payload \[bytes\].
    pub data_length: u16,
    /// Legacy output mode.
    pub output_mode: u16,
    /// Legacy output settings.
    pub output_settings: u32,
}

/// Why a frame's payload does not decode as its MID says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageError {
    /// The payload length does not fit the message.
    BadLength {
        /// The message id.
        mid: u8,
        /// Payload length received.
        len: usize,
        /// What the message requires.
        expected: &'static str,
    },
    /// Legacy MTData cannot be decoded for this output mode (only temperature, calibrated,
    /// orientation, status and sample counter are supported).
    UnsupportedOutputMode {
        /// The output mode bits.
        mode: u16,
    },
}

impl fmt::Display for MessageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BadLength { mid, len, expected } => write!(
                f,
                "message 0x{mid:02X} has a {len}-byte payload, expected {expected}"
            ),
            Self::UnsupportedOutputMode { mode } => {
                write!(
                    f,
                    "legacy MTData with output mode 0x{mode:04X} is not supported"
                )
            }
        }
    }
}

impl core::error::Error for MessageError {}

/// A message from a device, decoded from a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message<'a> {
    /// Measurement data (items decoded lazily).
    MtData2(MtData2<'a>),
    /// Legacy measurement data; decode with [`LegacyMtData::decode`] knowing the output mode.
    MtData(&'a [u8]),
    /// Error reply.
    Error {
        /// The code.
        code: ErrorCode,
        /// Detail bytes (5 for [`ErrorCode::DeviceError`]).
        detail: &'a [u8],
    },
    /// Warning.
    Warning {
        /// The warning code (the first 4 bytes; 0 when shorter).
        code: u32,
        /// The bytes after the code (often text).
        detail: &'a [u8],
    },
    /// Device id (4 or 8 bytes).
    DeviceId(u64),
    /// Product code, ASCII with trailing spaces/NULs removed.
    ProductCode(&'a [u8]),
    /// Firmware revision.
    FirmwareRev(FirmwareRev),
    /// Legacy configuration block.
    Configuration(Configuration),
    /// Output configuration in use (ack of SetOutputConfiguration).
    OutputConfiguration(OutputConfiguration<'a>),
    /// Baud rate ack (empty) or report (the code).
    Baudrate(Option<u8>),
    /// The device woke up (answer with WakeUpAck).
    WakeUp,
    /// Config mode entered.
    GoToConfigAck,
    /// Measurement mode entered.
    GoToMeasurementAck,
    /// Reset acknowledged.
    ResetAck,
    /// Any other message (acks of other setters, requests echoed on a bus, ...).
    Other {
        /// The message id.
        mid: u8,
        /// Its payload.
        payload: &'a [u8],
    },
}

impl<'a> Message<'a> {
    /// Decodes a frame by its MID.
    pub fn decode(frame: &XbusFrame<'a>) -> Result<Self, MessageError> {
        Self::decode_payload(frame.mid(), frame.payload())
    }

    /// Decodes a payload by MID.
    pub fn decode_payload(mid: u8, p: &'a [u8]) -> Result<Self, MessageError> {
        let bad = |expected| MessageError::BadLength {
            mid,
            len: p.len(),
            expected,
        };
        Ok(match mid {
            mid::MTDATA2 => Self::MtData2(MtData2::new(p)),
            mid::MTDATA => Self::MtData(p),
            mid::ERROR => {
                let (&code, detail) = p.split_first().ok_or(bad("at least 1 byte"))?;
                Self::Error {
                    code: ErrorCode::from_u8(code),
                    detail,
                }
            }
            mid::WARNING => match p.split_first_chunk::<4>() {
                Some((code, detail)) => Self::Warning {
                    code: u32::from_be_bytes(*code),
                    detail,
                },
                None => Self::Warning { code: 0, detail: p },
            },
            mid::DEVICE_ID => Self::DeviceId(match p.len() {
                4 | 8 => p.iter().fold(0u64, |acc, b| (acc << 8) | u64::from(*b)),
                _ => return Err(bad("4 or 8 bytes")),
            }),
            mid::PRODUCT_CODE => {
                let end = p
                    .iter()
                    .rposition(|b| *b != b' ' && *b != 0)
                    .map_or(0, |i| i + 1);
                Self::ProductCode(p.get(..end).unwrap_or_default())
            }
            mid::FIRMWARE_REV => match *p {
                [major, minor, revision] => Self::FirmwareRev(FirmwareRev {
                    major,
                    minor,
                    revision,
                    build: None,
                    scm: None,
                }),
                [major, minor, revision, b0, b1, b2, b3, s0, s1, s2, s3] => {
                    Self::FirmwareRev(FirmwareRev {
                        major,
                        minor,
                        revision,
                        build: Some(u32::from_be_bytes([b0, b1, b2, b3])),
                        scm: Some(u32::from_be_bytes([s0, s1, s2, s3])),
                    })
                }
                _ => return Err(bad("3 or 11 bytes")),
            },
            mid::CONFIGURATION => {
                if p.len() != 118 {
                    return Err(bad("118 bytes"));
                }
                let be16 = |o: usize| {
                    u16::from_be_bytes([
                        p.get(o).copied().unwrap_or(0),
                        p.get(o + 1).copied().unwrap_or(0),
                    ])
                };
                let be32 = |o: usize| (u32::from(be16(o)) << 16) | u32::from(be16(o + 2));
                Self::Configuration(Configuration {
                    master_device_id: be32(0),
                    sampling_period: be16(4),
                    output_skip_factor: be16(6),
                    sync_in_mode: be16(8),
                    sync_in_skip_factor: be16(10),
                    sync_in_offset: be32(12),
                    num_devices: be16(96),
                    device_id: be32(98),
                    data_length: be16(102),
                    output_mode: be16(104),
                    output_settings: be32(106),
                })
            }
            mid::OUTPUT_CONFIGURATION => {
                Self::OutputConfiguration(OutputConfiguration::new_checked(p)?)
            }
            mid::SET_BAUDRATE_ACK => Self::Baudrate(p.first().copied()),
            mid::WAKE_UP => Self::WakeUp,
            mid::GO_TO_CONFIG_ACK => Self::GoToConfigAck,
            mid::GO_TO_MEASUREMENT_ACK => Self::GoToMeasurementAck,
            mid::RESET_ACK => Self::ResetAck,
            _ => Self::Other { mid, payload: p },
        })
    }
}

/// Legacy output mode bits (SetOutputMode, 0xD0) that [`LegacyMtData`] understands.
pub mod output_mode {
    /// Temperature.
    pub const TEMPERATURE: u16 = 0x0001;
    /// Calibrated inertial data (acceleration, rate of turn, magnetic field).
    pub const CALIBRATED: u16 = 0x0002;
    /// Orientation.
    pub const ORIENTATION: u16 = 0x0004;
    /// Status byte.
    pub const STATUS: u16 = 0x0800;
}

/// Legacy output settings bits (SetOutputSettings, 0xD2) that [`LegacyMtData`] understands.
pub mod output_settings {
    /// A u16 sample counter ends the message.
    pub const SAMPLE_COUNTER: u32 = 0x0001;
    /// Orientation as Euler angles (else quaternion unless [`MATRIX`]).
    pub const EULER: u32 = 0x0004;
    /// Orientation as a rotation matrix.
    pub const MATRIX: u32 = 0x0008;
    /// No acceleration in the calibrated block.
    pub const NO_ACCELERATION: u32 = 0x0010;
    /// No rate of turn in the calibrated block.
    pub const NO_RATE_OF_TURN: u32 = 0x0020;
    /// No magnetic field in the calibrated block.
    pub const NO_MAGNETIC_FIELD: u32 = 0x0040;
    /// Data format bits 9..8: 0 Float32, 1 Fp12.20, 2 Fp16.32, 3 Float64.
    pub const FORMAT_SHIFT: u32 = 8;
}

/// Legacy MTData (0x32), whose layout is fixed by the output mode and settings in force.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegacyMtData {
    /// Temperature \[°C\].
    pub temperature: Option<f64>,
    /// Acceleration \[m/s^2\].
    pub acceleration: Option<[f64; 3]>,
    /// Rate of turn \[rad/s\].
    pub rate_of_turn: Option<[f64; 3]>,
    /// Magnetic field \[a.u.\].
    pub magnetic_field: Option<[f64; 3]>,
    /// Quaternion (q0 scalar).
    pub quaternion: Option<[f64; 4]>,
    /// Roll, pitch, yaw \[deg\].
    pub euler_angles: Option<[f64; 3]>,
    /// Rotation matrix, wire order.
    pub rotation_matrix: Option<[f64; 9]>,
    /// Status byte.
    pub status: Option<u8>,
    /// Sample counter.
    pub sample_counter: Option<u16>,
}

impl LegacyMtData {
    /// Decodes a legacy MTData payload for the given output mode (0xD0) and settings (0xD2).
    pub fn decode(payload: &[u8], mode: u16, settings: u32) -> Result<Self, MessageError> {
        let known = output_mode::TEMPERATURE
            | output_mode::CALIBRATED
            | output_mode::ORIENTATION
            | output_mode::STATUS;
        if mode & !known != 0 {
            return Err(MessageError::UnsupportedOutputMode { mode });
        }
        let p = match (settings >> output_settings::FORMAT_SHIFT) & 0x3 {
            0 => Precision::Float32,
            1 => Precision::Fp1220,
            2 => Precision::Fp1632,
            _ => Precision::Float64,
        };
        let mut out = Self::default();
        let mut rest = payload;
        let mut floats = |n: usize, dst: &mut [f64]| -> Option<()> {
            for d in dst.iter_mut().take(n) {
                *d = p.decode(rest)?;
                rest = rest.get(p.size()..)?;
            }
            Some(())
        };
        let mut ok = true;
        if mode & output_mode::TEMPERATURE != 0 {
            let mut t = [0.0];
            ok &= floats(1, &mut t).is_some();
            out.temperature = Some(t[0]);
        }
        if mode & output_mode::CALIBRATED != 0 {
            for (flag, slot) in [
                (output_settings::NO_ACCELERATION, &mut out.acceleration),
                (output_settings::NO_RATE_OF_TURN, &mut out.rate_of_turn),
                (output_settings::NO_MAGNETIC_FIELD, &mut out.magnetic_field),
            ] {
                if settings & flag == 0 {
                    let mut v = [0.0; 3];
                    ok &= floats(3, &mut v).is_some();
                    *slot = Some(v);
                }
            }
        }
        if mode & output_mode::ORIENTATION != 0 {
            if settings & output_settings::MATRIX != 0 {
                let mut v = [0.0; 9];
                ok &= floats(9, &mut v).is_some();
                out.rotation_matrix = Some(v);
            } else if settings & output_settings::EULER != 0 {
                let mut v = [0.0; 3];
                ok &= floats(3, &mut v).is_some();
                out.euler_angles = Some(v);
            } else {
                let mut v = [0.0; 4];
                ok &= floats(4, &mut v).is_some();
                out.quaternion = Some(v);
            }
        }
        let expected_tail = usize::from(mode & output_mode::STATUS != 0)
            + 2 * usize::from(settings & output_settings::SAMPLE_COUNTER != 0);
        if !ok || rest.len() != expected_tail {
            return Err(MessageError::BadLength {
                mid: mid::MTDATA,
                len: payload.len(),
                expected: "the length implied by the output mode and settings",
            });
        }
        if mode & output_mode::STATUS != 0 {
            out.status = rest.first().copied();
            rest = rest.get(1..).unwrap_or_default();
        }
        if settings & output_settings::SAMPLE_COUNTER != 0 {
            out.sample_counter = match *rest {
                [a, b] => Some(u16::from_be_bytes([a, b])),
                _ => None,
            };
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_reply_carries_code_and_detail() {
        let m = Message::decode_payload(mid::ERROR, &[0x28, 1, 2, 3, 4, 5]).unwrap();
        assert_eq!(
            m,
            Message::Error {
                code: ErrorCode::DeviceError,
                detail: &[1, 2, 3, 4, 5]
            }
        );
        assert_eq!(ErrorCode::from_u8(0x99), ErrorCode::Unknown(0x99));
        assert!(Message::decode_payload(mid::ERROR, &[]).is_err());
    }

    #[test]
    fn identity_messages() {
        assert_eq!(
            Message::decode_payload(mid::DEVICE_ID, &[0x03, 0x70, 0x12, 0x34]),
            Ok(Message::DeviceId(0x0370_1234))
        );
        assert!(Message::decode_payload(mid::DEVICE_ID, &[1, 2, 3]).is_err());
        assert_eq!(
            Message::decode_payload(mid::PRODUCT_CODE, b"MTi-G-710-2A8G4   \0"),
            Ok(Message::ProductCode(b"MTi-G-710-2A8G4"))
        );
        let fw = [1, 2, 3, 0, 0, 0, 9, 0, 0, 1, 0];
        assert_eq!(
            Message::decode_payload(mid::FIRMWARE_REV, &fw),
            Ok(Message::FirmwareRev(FirmwareRev {
                major: 1,
                minor: 2,
                revision: 3,
                build: Some(9),
                scm: Some(256)
            }))
        );
    }

    #[test]
    fn output_configuration_pairs() {
        let p = [0x10, 0x20, 0xFF, 0xFF, 0x40, 0x20, 0x00, 0x64];
        let Ok(Message::OutputConfiguration(c)) =
            Message::decode_payload(mid::OUTPUT_CONFIGURATION, &p)
        else {
            panic!()
        };
        let v: std::vec::Vec<_> = c.settings().collect();
        assert_eq!(v[0].id, DataId(0x1020));
        assert!(v[0].is_max_rate());
        assert_eq!(
            v[1],
            OutputSetting {
                id: DataId(0x4020),
                rate_hz: 100
            }
        );
        assert!(Message::decode_payload(mid::OUTPUT_CONFIGURATION, &p[..7]).is_err());
    }

    #[test]
    fn legacy_calibrated_data_with_counter() {
        let mut p = std::vec::Vec::new();
        for v in [0.1f32, 0.2, 9.8, 0.01, 0.02, 0.03, 1.0, 0.0, 0.5] {
            p.extend_from_slice(&v.to_be_bytes());
        }
        p.extend_from_slice(&[0x12, 0x34]);
        let d = LegacyMtData::decode(&p, output_mode::CALIBRATED, output_settings::SAMPLE_COUNTER)
            .unwrap();
        assert_eq!(
            d.acceleration,
            Some([0.1f32 as f64, 0.2f32 as f64, 9.8f32 as f64])
        );
        assert_eq!(d.magnetic_field.map(|m| m[2]), Some(0.5));
        assert_eq!(d.sample_counter, Some(0x1234));
        assert!(LegacyMtData::decode(&p[..37], output_mode::CALIBRATED, 1).is_err());
        assert_eq!(
            LegacyMtData::decode(&p, 0x0010, 0),
            Err(MessageError::UnsupportedOutputMode { mode: 0x0010 })
        );
        // Without magnetic field, fixed point 12.20: 6 x 4 bytes.
        let mut q = std::vec::Vec::new();
        for v in [1i32 << 20, -(1 << 19), 0, 0, 0, 3 << 20] {
            q.extend_from_slice(&v.to_be_bytes());
        }
        let d = LegacyMtData::decode(
            &q,
            output_mode::CALIBRATED,
            output_settings::NO_MAGNETIC_FIELD | (1 << output_settings::FORMAT_SHIFT),
        )
        .unwrap();
        assert_eq!(d.acceleration, Some([1.0, -0.5, 0.0]));
        assert_eq!(d.rate_of_turn, Some([0.0, 0.0, 3.0]));
        assert_eq!(d.magnetic_field, None);
    }

    #[test]
    fn baud_codes_round_trip() {
        for code in 0..=255u8 {
            if let Some(b) = Baudrate::from_code(code) {
                assert_eq!(Baudrate::from_bps(b.bps()), Some(b));
                assert_eq!(Baudrate::from_code(b.code()), Some(b));
            }
        }
        assert_eq!(Baudrate::from_code(0x0A), Some(Baudrate::B921600));
    }
}
