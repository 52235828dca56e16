//! Encoder: frames for every host-to-device message, and MTData2 (for tests and simulators).
//!
//! Everything writes into a caller's `&mut [u8]` and returns the frame length, or an error when
//! the buffer is too small; nothing allocates.

use crate::frame::{
    checksum_sum, EXTENDED_LEN, MAX_EXTENDED_PAYLOAD, MAX_STANDARD_PAYLOAD, PREAMBLE,
};
use crate::message::{mid, Baudrate, OutputSetting};
use crate::mtdata2::{DataId, DataKind, GnssPvt, Layout, Value};
use core::fmt;

/// Bus id of the master device (replies echo the id they were addressed with).
pub const BID_MASTER: u8 = 0xFF;

/// The most settings SetOutputConfiguration accepts.
pub const MAX_OUTPUT_SETTINGS: usize = 32;

/// Why a message could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The output buffer is too small.
    BufferTooSmall {
        /// Bytes the frame needs (so far).
        need: usize,
        /// Bytes available.
        have: usize,
    },
    /// The payload exceeds 65535 bytes.
    PayloadTooLarge {
        /// Payload length.
        len: usize,
    },
    /// An MTData2 item exceeds 255 bytes.
    ItemTooLarge {
        /// The item's data id.
        id: u16,
        /// Its length.
        len: usize,
    },
    /// More than 32 output settings.
    TooManySettings {
        /// Settings given.
        count: usize,
    },
    /// The value does not match the data id's kind.
    ValueMismatch {
        /// The data id.
        id: u16,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BufferTooSmall { need, have } => {
                write!(f, "output buffer too small: need {need} bytes, have {have}")
            }
            Self::PayloadTooLarge { len } => {
                write!(f, "payload of {len} bytes exceeds {MAX_EXTENDED_PAYLOAD}")
            }
            Self::ItemTooLarge { id, len } => {
                write!(f, "MTData2 item 0x{id:04X} of {len} bytes exceeds 255")
            }
            Self::TooManySettings { count } => write!(
                f,
                "{count} output settings exceed the device's {MAX_OUTPUT_SETTINGS}"
            ),
            Self::ValueMismatch { id } => {
                write!(f, "value does not match data id 0x{id:04X}")
            }
        }
    }
}

impl core::error::Error for EncodeError {}

fn too_small(need: usize, have: usize) -> EncodeError {
    EncodeError::BufferTooSmall { need, have }
}

/// The header for a `len`-byte payload and its length (4, or 6 for the extended form).
fn header_bytes(bid: u8, mid: u8, len: usize) -> Result<([u8; 6], usize), EncodeError> {
    if len > MAX_EXTENDED_PAYLOAD {
        return Err(EncodeError::PayloadTooLarge { len });
    }
    Ok(if len <= MAX_STANDARD_PAYLOAD {
        ([PREAMBLE, bid, mid, len as u8, 0, 0], 4)
    } else {
        let [hi, lo] = (len as u16).to_be_bytes();
        ([PREAMBLE, bid, mid, EXTENDED_LEN, hi, lo], 6)
    })
}

/// Writes the header for a `len`-byte payload at the start of `out`; returns its length.
fn write_header(out: &mut [u8], bid: u8, mid: u8, len: usize) -> Result<usize, EncodeError> {
    let (header, h) = header_bytes(bid, mid, len)?;
    let need = h + len + 1;
    if out.len() < need {
        return Err(too_small(need, out.len()));
    }
    let have = out.len();
    out.get_mut(..h)
        .ok_or(too_small(need, have))?
        .copy_from_slice(header.get(..h).unwrap_or_default());
    Ok(h)
}

/// Appends the checksum of `out[1..end]` at `out[end]`; returns the frame length.
fn seal(out: &mut [u8], end: usize) -> Result<usize, EncodeError> {
    let have = out.len();
    let cs = checksum_sum(out.get(1..end).ok_or(too_small(end + 1, have))?).wrapping_neg();
    *out.get_mut(end).ok_or(too_small(end + 1, have))? = cs;
    Ok(end + 1)
}

/// Encodes one frame (standard or extended length as the payload requires).
///
/// ```
/// let mut buf = [0u8; 8];
/// let n = imu_driver::encode_frame(&mut buf, 0xFF, 0x30, &[]).unwrap();
/// assert_eq!(&buf[..n], &[0xFA, 0xFF, 0x30, 0x00, 0xD1]);
/// ```
pub fn encode_frame(
    out: &mut [u8],
    bid: u8,
    mid: u8,
    payload: &[u8],
) -> Result<usize, EncodeError> {
    let h = write_header(out, bid, mid, payload.len())?;
    let end = h + payload.len();
    let have = out.len();
    out.get_mut(h..end)
        .ok_or(too_small(end + 1, have))?
        .copy_from_slice(payload);
    seal(out, end)
}

/// Encodes a list of output settings as `u16 id, u16 rate` pairs with the given MID
/// (0xC0 to set them; a fake device answers with 0xC1).
pub fn encode_output_settings(
    out: &mut [u8],
    bid: u8,
    mid: u8,
    settings: &[OutputSetting],
) -> Result<usize, EncodeError> {
    if settings.len() > MAX_OUTPUT_SETTINGS {
        return Err(EncodeError::TooManySettings {
            count: settings.len(),
        });
    }
    let h = write_header(out, bid, mid, settings.len() * 4)?;
    let mut at = h;
    for s in settings {
        let [a, b] = s.id.0.to_be_bytes();
        let [r0, r1] = s.rate_hz.to_be_bytes();
        let have = out.len();
        out.get_mut(at..at + 4)
            .ok_or(too_small(at + 5, have))?
            .copy_from_slice(&[a, b, r0, r1]);
        at += 4;
    }
    seal(out, at)
}

/// A message the host sends to a device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HostMessage<'a> {
    /// Answer to the device's WakeUp: stay in config mode.
    WakeUpAck,
    /// Enter config mode.
    GoToConfig,
    /// Enter measurement mode.
    GoToMeasurement,
    /// Request the device id.
    ReqDeviceId,
    /// Request the product code.
    ReqProductCode,
    /// Request the firmware revision.
    ReqFirmwareRev,
    /// Request the baud rate code.
    ReqBaudrate,
    /// Set the baud rate (takes effect after a reset).
    SetBaudrate(Baudrate),
    /// Reset the device.
    Reset,
    /// Request the legacy configuration block.
    ReqConfiguration,
    /// Request the output configuration.
    ReqOutputConfiguration,
    /// Set the output configuration (at most 32 settings).
    SetOutputConfiguration(&'a [OutputSetting]),
    /// Request one MTData2 message.
    ReqData,
    /// Set the legacy output mode.
    SetOutputMode(u16),
    /// Set the legacy output settings.
    SetOutputSettings(u32),
}

impl HostMessage<'_> {
    /// The message id.
    pub const fn mid(&self) -> u8 {
        match self {
            Self::WakeUpAck => mid::WAKE_UP_ACK,
            Self::GoToConfig => mid::GO_TO_CONFIG,
            Self::GoToMeasurement => mid::GO_TO_MEASUREMENT,
            Self::ReqDeviceId => mid::REQ_DID,
            Self::ReqProductCode => mid::REQ_PRODUCT_CODE,
            Self::ReqFirmwareRev => mid::REQ_FW_REV,
            Self::ReqBaudrate | Self::SetBaudrate(_) => mid::SET_BAUDRATE,
            Self::Reset => mid::RESET,
            Self::ReqConfiguration => mid::REQ_CONFIGURATION,
            Self::ReqOutputConfiguration | Self::SetOutputConfiguration(_) => {
                mid::SET_OUTPUT_CONFIGURATION
            }
            Self::ReqData => mid::REQ_DATA,
            Self::SetOutputMode(_) => mid::SET_OUTPUT_MODE,
            Self::SetOutputSettings(_) => mid::SET_OUTPUT_SETTINGS,
        }
    }

    /// The MID of the device's reply (`mid + 1`), `None` for WakeUpAck and ReqData (answered
    /// by MTData2).
    pub const fn reply_mid(&self) -> Option<u8> {
        match self {
            Self::WakeUpAck => None,
            Self::ReqData => Some(mid::MTDATA2),
            other => Some(other.mid() + 1),
        }
    }

    /// Encodes the frame into `out`; returns its length.
    pub fn encode(&self, bid: u8, out: &mut [u8]) -> Result<usize, EncodeError> {
        let m = self.mid();
        match *self {
            Self::SetBaudrate(b) => encode_frame(out, bid, m, &[b.code()]),
            Self::SetOutputConfiguration(s) => encode_output_settings(out, bid, m, s),
            Self::SetOutputMode(v) => encode_frame(out, bid, m, &v.to_be_bytes()),
            Self::SetOutputSettings(v) => encode_frame(out, bid, m, &v.to_be_bytes()),
            _ => encode_frame(out, bid, m, &[]),
        }
    }
}

/// Builds an MTData2 frame item by item, in place.
///
/// ```
/// use imu_driver::{DataId, MtData2Writer, Value};
/// let mut buf = [0u8; 64];
/// let mut w = MtData2Writer::new(&mut buf);
/// w.value(DataId(0x1020), &Value::PacketCounter(7)).unwrap();
/// w.value(DataId(0x4020), &Value::Acceleration([0.0, 0.0, 9.81])).unwrap();
/// let n = w.finish(0xFF).unwrap();
/// assert_eq!(n, 4 + 5 + 15 + 1);
/// ```
#[derive(Debug)]
pub struct MtData2Writer<'a> {
    out: &'a mut [u8],
    /// End of the items written so far (items start at offset 6, room for an extended header).
    end: usize,
}

const ITEMS_START: usize = 6;

impl<'a> MtData2Writer<'a> {
    /// A writer into `out`.
    pub fn new(out: &'a mut [u8]) -> Self {
        Self {
            out,
            end: ITEMS_START,
        }
    }

    /// Appends one raw item.
    pub fn item(&mut self, id: DataId, data: &[u8]) -> Result<(), EncodeError> {
        if data.len() > 255 {
            return Err(EncodeError::ItemTooLarge {
                id: id.0,
                len: data.len(),
            });
        }
        let start = self.end;
        let stop = start + 3 + data.len();
        let have = self.out.len();
        let dst = self
            .out
            .get_mut(start..stop)
            .ok_or(too_small(stop + 1, have))?;
        let [hi, lo] = id.0.to_be_bytes();
        dst[..3].copy_from_slice(&[hi, lo, data.len() as u8]);
        dst[3..].copy_from_slice(data);
        self.end = stop;
        Ok(())
    }

    /// Appends an item holding `values` encoded in the id's precision.
    pub fn floats(&mut self, id: DataId, values: &[f64]) -> Result<(), EncodeError> {
        let p = id.precision();
        let mut buf = [0u8; 9 * 8];
        let len = values.len() * p.size();
        if len > buf.len() {
            return Err(EncodeError::ItemTooLarge { id: id.0, len });
        }
        for (v, chunk) in values.iter().zip(buf.chunks_exact_mut(p.size())) {
            p.encode(*v, chunk)
                .ok_or(EncodeError::ValueMismatch { id: id.0 })?;
        }
        self.item(id, buf.get(..len).unwrap_or_default())
    }

    /// Appends a typed value under `id` (floats in the id's precision).
    pub fn value(&mut self, id: DataId, v: &Value<'_>) -> Result<(), EncodeError> {
        let mismatch = EncodeError::ValueMismatch { id: id.0 };
        let kind = id.kind();
        if let Layout::Floats(n) = kind.layout() {
            let f = v.floats();
            if f.len() != n || !same_kind(kind, v) {
                return Err(mismatch);
            }
            return self.floats(id, f);
        }
        match (kind, v) {
            (DataKind::UtcTime, Value::UtcTime(t)) => self.item(id, &t.to_bytes()),
            (DataKind::PacketCounter, Value::PacketCounter(c)) => self.item(id, &c.to_be_bytes()),
            (DataKind::SampleTimeFine, Value::SampleTimeFine(t))
            | (DataKind::SampleTimeCoarse, Value::SampleTimeCoarse(t))
            | (DataKind::BaroPressure, Value::BaroPressure(t))
            | (DataKind::StatusWord, Value::StatusWord(t)) => self.item(id, &t.to_be_bytes()),
            (DataKind::StatusByte, Value::StatusByte(s)) => self.item(id, &[*s]),
            (DataKind::Rssi, Value::Rssi(r)) => self.item(id, &r.to_be_bytes()),
            (DataKind::GnssPvtData, Value::GnssPvtData(p)) => self.item(id, &pvt_bytes(p)),
            (DataKind::GnssSatInfo, Value::GnssSatInfo(s)) => {
                let mut buf = [0u8; 255];
                let sats = s.raw_satellites();
                let len = 8 + sats.len();
                let dst = buf
                    .get_mut(..len)
                    .ok_or(EncodeError::ItemTooLarge { id: id.0, len })?;
                dst[..4].copy_from_slice(&s.itow.to_be_bytes());
                dst[4] = s.num_svs;
                dst[5..8].copy_from_slice(&s.reserved);
                dst[8..].copy_from_slice(sats);
                self.item(id, dst)
            }
            (DataKind::Unknown, Value::Unknown(d)) => self.item(id, d),
            _ => Err(mismatch),
        }
    }

    /// Payload bytes written so far.
    pub fn payload_len(&self) -> usize {
        self.end - ITEMS_START
    }

    /// Writes header and checksum; the frame then starts at `out[0]`. Returns its length.
    pub fn finish(self, bid: u8) -> Result<usize, EncodeError> {
        let len = self.payload_len();
        let (header, h) = header_bytes(bid, mid::MTDATA2, len)?;
        let have = self.out.len();
        if have < h + len + 1 {
            return Err(too_small(h + len + 1, have));
        }
        self.out.copy_within(ITEMS_START..self.end, h);
        self.out
            .get_mut(..h)
            .ok_or(too_small(h + len + 1, have))?
            .copy_from_slice(header.get(..h).unwrap_or_default());
        seal(self.out, h + len)
    }
}

fn same_kind(kind: DataKind, v: &Value<'_>) -> bool {
    matches!(
        (kind, v),
        (DataKind::Temperature, Value::Temperature(_))
            | (DataKind::Quaternion, Value::Quaternion(_))
            | (DataKind::RotationMatrix, Value::RotationMatrix(_))
            | (DataKind::EulerAngles, Value::EulerAngles(_))
            | (DataKind::DeltaV, Value::DeltaV(_))
            | (DataKind::Acceleration, Value::Acceleration(_))
            | (DataKind::FreeAcceleration, Value::FreeAcceleration(_))
            | (DataKind::AccelerationHr, Value::AccelerationHr(_))
            | (DataKind::AltitudeEllipsoid, Value::AltitudeEllipsoid(_))
            | (DataKind::PositionEcef, Value::PositionEcef(_))
            | (DataKind::LatLon, Value::LatLon(_))
            | (DataKind::RateOfTurn, Value::RateOfTurn(_))
            | (DataKind::DeltaQ, Value::DeltaQ(_))
            | (DataKind::RateOfTurnHr, Value::RateOfTurnHr(_))
            | (DataKind::MagneticField, Value::MagneticField(_))
            | (DataKind::VelocityXyz, Value::VelocityXyz(_))
    )
}

/// The 94 wire bytes of a GNSS PVT record.
pub fn pvt_bytes(p: &GnssPvt) -> [u8; 94] {
    let mut out = [0u8; 94];
    let mut at = 0;
    let mut put = |b: &[u8]| {
        if let Some(dst) = out.get_mut(at..at + b.len()) {
            dst.copy_from_slice(b);
        }
        at += b.len();
    };
    put(&p.itow.to_be_bytes());
    put(&p.year.to_be_bytes());
    put(&[p.month, p.day, p.hour, p.min, p.sec, p.valid]);
    put(&p.t_acc.to_be_bytes());
    put(&p.nano.to_be_bytes());
    put(&[p.fix_type, p.flags, p.num_sv, p.reserved1]);
    for v in [p.lon, p.lat, p.height, p.hmsl] {
        put(&v.to_be_bytes());
    }
    put(&p.h_acc.to_be_bytes());
    put(&p.v_acc.to_be_bytes());
    for v in [p.vel_n, p.vel_e, p.vel_d, p.g_speed, p.head_mot] {
        put(&v.to_be_bytes());
    }
    put(&p.s_acc.to_be_bytes());
    put(&p.head_acc.to_be_bytes());
    put(&p.head_veh.to_be_bytes());
    for v in [p.gdop, p.pdop, p.tdop, p.vdop, p.hdop, p.ndop, p.edop] {
        put(&v.to_be_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::XbusFrame;
    use crate::message::Message;
    use crate::mtdata2::{MtData2, Precision};

    #[test]
    fn host_messages_have_known_bytes() {
        let mut buf = [0u8; 64];
        let cases: [(HostMessage<'_>, &[u8]); 4] = [
            (HostMessage::GoToConfig, &[0xFA, 0xFF, 0x30, 0x00, 0xD1]),
            (
                HostMessage::GoToMeasurement,
                &[0xFA, 0xFF, 0x10, 0x00, 0xF1],
            ),
            (HostMessage::WakeUpAck, &[0xFA, 0xFF, 0x3F, 0x00, 0xC2]),
            (
                HostMessage::SetBaudrate(Baudrate::B921600),
                &[0xFA, 0xFF, 0x18, 0x01, 0x80, 0x68],
            ),
        ];
        for (m, bytes) in cases {
            let n = m.encode(BID_MASTER, &mut buf).unwrap();
            assert_eq!(&buf[..n], bytes, "{m:?}");
        }
    }

    #[test]
    fn every_host_message_is_a_valid_frame_with_its_mid() {
        let settings = [OutputSetting {
            id: DataId(0x4020),
            rate_hz: 100,
        }; 3];
        let all = [
            HostMessage::WakeUpAck,
            HostMessage::GoToConfig,
            HostMessage::GoToMeasurement,
            HostMessage::ReqDeviceId,
            HostMessage::ReqProductCode,
            HostMessage::ReqFirmwareRev,
            HostMessage::ReqBaudrate,
            HostMessage::SetBaudrate(Baudrate::B115200),
            HostMessage::Reset,
            HostMessage::ReqConfiguration,
            HostMessage::ReqOutputConfiguration,
            HostMessage::SetOutputConfiguration(&settings),
            HostMessage::ReqData,
            HostMessage::SetOutputMode(2),
            HostMessage::SetOutputSettings(1),
        ];
        let mut buf = [0u8; 64];
        for m in all {
            let n = m.encode(0x01, &mut buf).unwrap();
            let f = XbusFrame::new_checked(&buf[..n]).unwrap();
            assert_eq!((f.bid(), f.mid()), (0x01, m.mid()));
        }
        let n = HostMessage::SetOutputConfiguration(&settings)
            .encode(0xFF, &mut buf)
            .unwrap();
        assert_eq!(&buf[4..8], &[0x40, 0x20, 0x00, 0x64]);
        assert_eq!(n, 4 + 12 + 1);
        let many = [settings[0]; 33];
        assert_eq!(
            HostMessage::SetOutputConfiguration(&many).encode(0xFF, &mut [0u8; 200]),
            Err(EncodeError::TooManySettings { count: 33 })
        );
    }

    #[test]
    fn small_buffers_are_reported() {
        assert_eq!(
            HostMessage::GoToConfig.encode(0xFF, &mut [0u8; 4]),
            Err(EncodeError::BufferTooSmall { need: 5, have: 4 })
        );
        let mut buf = [0u8; 12];
        let mut w = MtData2Writer::new(&mut buf);
        assert!(w.item(DataId(0x1020), &[0, 1]).is_ok());
        assert!(matches!(
            w.item(DataId(0x1060), &[0; 4]),
            Err(EncodeError::BufferTooSmall { .. })
        ));
    }

    #[test]
    fn mtdata2_writer_switches_to_extended_length() {
        let mut buf = [0u8; 400];
        let mut w = MtData2Writer::new(&mut buf);
        for _ in 0..20 {
            w.floats(
                DataId::of(DataKind::Acceleration, Precision::Float32).unwrap(),
                &[1.0, 2.0, 3.0],
            )
            .unwrap();
        }
        assert_eq!(w.payload_len(), 300);
        let n = w.finish(0xFF).unwrap();
        let f = XbusFrame::new_checked(&buf[..n]).unwrap();
        assert!(f.is_extended());
        let Ok(Message::MtData2(m)) = Message::decode(&f) else {
            panic!()
        };
        assert_eq!(m.items().count(), 20);
        assert_eq!(
            MtData2::new(f.payload()).sample().acceleration,
            Some([1.0, 2.0, 3.0])
        );
    }

    #[test]
    fn value_must_match_the_id() {
        let mut buf = [0u8; 64];
        let mut w = MtData2Writer::new(&mut buf);
        assert_eq!(
            w.value(DataId(0x4020), &Value::RateOfTurn([0.0; 3])),
            Err(EncodeError::ValueMismatch { id: 0x4020 })
        );
    }
}
