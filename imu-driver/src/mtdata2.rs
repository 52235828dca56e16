//! MTData2 (MID 0x36): data identifiers, the item iterator and typed values.
//!
//! A payload is a sequence of items `u16 data id, u8 size, size bytes`. Identifiers we do not
//! know are yielded as [`Value::Unknown`] and skipped by their size; a wrong size for a known id
//! is an error for that item only; the iterator stops only when an item claims more bytes than
//! remain.

use core::fmt;

/// Float encoding of an item, from bits 1..0 of the data id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Precision {
    /// IEEE 754 single precision, 4 bytes.
    Float32,
    /// Fixed point 12.20: an `i32` divided by 2^20, 4 bytes.
    Fp1220,
    /// Fixed point 16.32: the `u32` fraction, then the `i16` integer part, 6 bytes.
    Fp1632,
    /// IEEE 754 double precision, 8 bytes.
    Float64,
}

impl Precision {
    /// All four, in format-bit order.
    pub const ALL: [Precision; 4] = [
        Precision::Float32,
        Precision::Fp1220,
        Precision::Fp1632,
        Precision::Float64,
    ];

    /// Bytes per value.
    pub const fn size(self) -> usize {
        match self {
            Self::Float32 | Self::Fp1220 => 4,
            Self::Fp1632 => 6,
            Self::Float64 => 8,
        }
    }

    /// The format bits (1..0) of a data id.
    pub const fn bits(self) -> u16 {
        match self {
            Self::Float32 => 0,
            Self::Fp1220 => 1,
            Self::Fp1632 => 2,
            Self::Float64 => 3,
        }
    }

    /// Decodes one value from the first [`size`](Self::size) bytes of `b`, or `None` if too short.
    #[inline]
    pub fn decode(self, b: &[u8]) -> Option<f64> {
        Some(match self {
            Self::Float32 => f64::from(f32::from_be_bytes(take(b)?)),
            Self::Fp1220 => f64::from(i32::from_be_bytes(take(b)?)) / (1u32 << 20) as f64,
            Self::Fp1632 => {
                let frac = u32::from_be_bytes(take(b)?);
                let int = i16::from_be_bytes(take(b.get(4..)?)?);
                // 48 significant bits: exact in an f64.
                ((i64::from(int) << 32) | i64::from(frac)) as f64 / 4_294_967_296.0
            }
            Self::Float64 => f64::from_be_bytes(take(b)?),
        })
    }

    /// Encodes `v` into the first [`size`](Self::size) bytes of `out` (fixed point rounds to
    /// nearest and saturates); returns `None` if `out` is too short.
    pub fn encode(self, v: f64, out: &mut [u8]) -> Option<()> {
        let out = out.get_mut(..self.size())?;
        match self {
            Self::Float32 => out.copy_from_slice(&(v as f32).to_be_bytes()),
            Self::Fp1220 => {
                out.copy_from_slice(&(libm::round(v * f64::from(1u32 << 20)) as i32).to_be_bytes())
            }
            Self::Fp1632 => {
                let fixed = libm::round(v * 4_294_967_296.0) as i64;
                let fixed = fixed.clamp(
                    i64::from(i16::MIN) << 32,
                    (i64::from(i16::MAX) << 32) | 0xFFFF_FFFF,
                );
                out.get_mut(..4)?
                    .copy_from_slice(&((fixed & 0xFFFF_FFFF) as u32).to_be_bytes());
                out.get_mut(4..)?
                    .copy_from_slice(&((fixed >> 32) as i16).to_be_bytes());
            }
            Self::Float64 => out.copy_from_slice(&v.to_be_bytes()),
        }
        Some(())
    }
}

#[inline]
fn take<const N: usize>(b: &[u8]) -> Option<[u8; N]> {
    b.get(..N)?.try_into().ok()
}

/// Coordinate frame of orientation and velocity items, from bits 3..2 of the data id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CoordinateFrame {
    /// East-North-Up (the default).
    Enu,
    /// North-East-Down.
    Ned,
    /// North-West-Up.
    Nwu,
    /// Bits 3..2 = 0b11, not defined by the protocol.
    Reserved,
}

impl CoordinateFrame {
    /// The format bits (3..2) of a data id.
    pub const fn bits(self) -> u16 {
        match self {
            Self::Enu => 0x0,
            Self::Ned => 0x4,
            Self::Nwu => 0x8,
            Self::Reserved => 0xC,
        }
    }

    /// Xsens' name ("EastNorthUp", ...).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Enu => "EastNorthUp",
            Self::Ned => "NorthEastDown",
            Self::Nwu => "NorthWestUp",
            Self::Reserved => "Reserved",
        }
    }
}

macro_rules! data_kinds {
    ($( $(#[$doc:meta])* $kind:ident = $id:literal, $name:literal, $snake:literal, $layout:expr; )*) => {
        /// What a data id carries (its `id & 0xFFF0`).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum DataKind {
            $( $(#[$doc])* $kind, )*
            /// An identifier this decoder does not know (skipped by size).
            Unknown,
        }

        impl DataKind {
            /// Every known kind.
            pub const ALL: &'static [DataKind] = &[$(DataKind::$kind),*];

            /// The kind of a data id.
            pub const fn from_id(id: u16) -> Self {
                match id & 0xFFF0 {
                    $( $id => Self::$kind, )*
                    _ => Self::Unknown,
                }
            }

            /// The id with format bits zero, `None` for [`DataKind::Unknown`].
            pub const fn base_id(self) -> Option<u16> {
                match self {
                    $( Self::$kind => Some($id), )*
                    Self::Unknown => None,
                }
            }

            /// Xsens' name of the output ("Acceleration", "GNSSPVTData", ...).
            pub const fn name(self) -> &'static str {
                match self {
                    $( Self::$kind => $name, )*
                    Self::Unknown => "Unknown",
                }
            }

            /// A snake_case name for JSON keys ("acceleration", "gnss_pvt_data", ...).
            pub const fn snake_name(self) -> &'static str {
                match self {
                    $( Self::$kind => $snake, )*
                    Self::Unknown => "unknown",
                }
            }

            /// The item layout.
            pub const fn layout(self) -> Layout {
                match self {
                    $( Self::$kind => $layout, )*
                    Self::Unknown => Layout::Opaque,
                }
            }
        }
    };
}

/// How an item's payload is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// `n` values in the precision of the id's format bits.
    Floats(usize),
    /// A fixed number of bytes whatever the format bits.
    Fixed(usize),
    /// GNSS satellite info: an 8-byte header and 4 bytes per satellite.
    SatInfo,
    /// Unknown: any size.
    Opaque,
}

data_kinds! {
    /// Temperature \[°C\].
    Temperature = 0x0810, "Temperature", "temperature", Layout::Floats(1);
    /// UTC time (12 bytes).
    UtcTime = 0x1010, "UTCTime", "utc_time", Layout::Fixed(12);
    /// Packet counter (u16, wraps).
    PacketCounter = 0x1020, "PacketCounter", "packet_counter", Layout::Fixed(2);
    /// Sample time \[1/10 ms ticks\] (u32).
    SampleTimeFine = 0x1060, "SampleTimeFine", "sample_time_fine", Layout::Fixed(4);
    /// Sample time \[s\] (u32).
    SampleTimeCoarse = 0x1070, "SampleTimeCoarse", "sample_time_coarse", Layout::Fixed(4);
    /// Orientation quaternion q0 (scalar), q1, q2, q3.
    Quaternion = 0x2010, "Quaternion", "quaternion", Layout::Floats(4);
    /// Rotation matrix, 9 values in wire order.
    RotationMatrix = 0x2020, "RotationMatrix", "rotation_matrix", Layout::Floats(9);
    /// Euler angles roll, pitch, yaw \[deg\] (Z-Y'-X'').
    EulerAngles = 0x2030, "EulerAngles", "euler_angles", Layout::Floats(3);
    /// Barometric pressure \[Pa\] (u32).
    BaroPressure = 0x3010, "BaroPressure", "baro_pressure", Layout::Fixed(4);
    /// Velocity increment \[m/s\], sensor frame.
    DeltaV = 0x4010, "DeltaV", "delta_v", Layout::Floats(3);
    /// Calibrated acceleration \[m/s^2\], sensor frame.
    Acceleration = 0x4020, "Acceleration", "acceleration", Layout::Floats(3);
    /// Free acceleration (gravity removed) \[m/s^2\], earth frame.
    FreeAcceleration = 0x4030, "FreeAcceleration", "free_acceleration", Layout::Floats(3);
    /// High-rate acceleration \[m/s^2\], sensor frame.
    AccelerationHr = 0x4040, "AccelerationHR", "acceleration_hr", Layout::Floats(3);
    /// Altitude above the WGS84 ellipsoid \[m\].
    AltitudeEllipsoid = 0x5020, "AltitudeEllipsoid", "altitude_ellipsoid", Layout::Floats(1);
    /// Position in ECEF \[m\].
    PositionEcef = 0x5030, "PositionECEF", "position_ecef", Layout::Floats(3);
    /// Latitude, longitude \[deg\].
    LatLon = 0x5040, "LatLon", "lat_lon", Layout::Floats(2);
    /// GNSS position-velocity-time (94 bytes, u-blox NAV-PVT fields).
    GnssPvtData = 0x7010, "GNSSPVTData", "gnss_pvt_data", Layout::Fixed(94);
    /// GNSS satellite information.
    GnssSatInfo = 0x7020, "GNSSSatInfo", "gnss_sat_info", Layout::SatInfo;
    /// Calibrated rate of turn \[rad/s\], sensor frame.
    RateOfTurn = 0x8020, "RateOfTurn", "rate_of_turn", Layout::Floats(3);
    /// Orientation increment quaternion.
    DeltaQ = 0x8030, "DeltaQ", "delta_q", Layout::Floats(4);
    /// High-rate rate of turn \[rad/s\], sensor frame.
    RateOfTurnHr = 0x8040, "RateOfTurnHR", "rate_of_turn_hr", Layout::Floats(3);
    /// Magnetic field \[a.u., normalised to the calibration field\], sensor frame.
    MagneticField = 0xC020, "MagneticField", "magnetic_field", Layout::Floats(3);
    /// Velocity \[m/s\], earth frame.
    VelocityXyz = 0xD010, "VelocityXYZ", "velocity_xyz", Layout::Floats(3);
    /// Status byte (the low 8 bits of the status word).
    StatusByte = 0xE010, "StatusByte", "status_byte", Layout::Fixed(1);
    /// Status word (u32 bit field).
    StatusWord = 0xE020, "StatusWord", "status_word", Layout::Fixed(4);
    /// Received signal strength \[dBm\] (wireless devices).
    Rssi = 0xE040, "Rssi", "rssi", Layout::Fixed(1);
}

impl DataKind {
    /// True for the orientation and velocity groups, whose format bits 3..2 carry a coordinate frame.
    pub const fn has_frame(self) -> bool {
        matches!(
            self,
            Self::Quaternion | Self::RotationMatrix | Self::EulerAngles | Self::VelocityXyz
        )
    }
}

/// An MTData2 data identifier: group (bits 15..11), type (7..4), format (3..0).
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct DataId(pub u16);

impl DataId {
    /// The id of `kind` in `precision` (and ENU), `None` for [`DataKind::Unknown`].
    pub const fn of(kind: DataKind, precision: Precision) -> Option<Self> {
        match kind.base_id() {
            Some(base) => {
                let fmt = match kind.layout() {
                    Layout::Floats(_) => precision.bits(),
                    _ => 0,
                };
                Some(Self(base | fmt))
            }
            None => None,
        }
    }

    /// The same id with its coordinate-frame bits set (orientation and velocity kinds only).
    pub const fn in_frame(self, frame: CoordinateFrame) -> Self {
        if self.kind().has_frame() {
            Self((self.0 & !0x000C) | frame.bits())
        } else {
            self
        }
    }

    /// What the id carries.
    #[inline]
    pub const fn kind(self) -> DataKind {
        DataKind::from_id(self.0)
    }

    /// Float encoding (meaningful for [`Layout::Floats`] kinds).
    #[inline]
    pub const fn precision(self) -> Precision {
        match self.0 & 0x3 {
            0 => Precision::Float32,
            1 => Precision::Fp1220,
            2 => Precision::Fp1632,
            _ => Precision::Float64,
        }
    }

    /// Coordinate frame (meaningful for orientation and velocity kinds).
    #[inline]
    pub const fn coordinate_frame(self) -> CoordinateFrame {
        match self.0 & 0xC {
            0x0 => CoordinateFrame::Enu,
            0x4 => CoordinateFrame::Ned,
            0x8 => CoordinateFrame::Nwu,
            _ => CoordinateFrame::Reserved,
        }
    }

    /// The payload size this id requires, `None` when any size is possible (unknown ids,
    /// satellite info).
    pub const fn expected_size(self) -> Option<usize> {
        match self.kind().layout() {
            Layout::Floats(n) => Some(n * self.precision().size()),
            Layout::Fixed(n) => Some(n),
            Layout::SatInfo | Layout::Opaque => None,
        }
    }
}

impl fmt::Debug for DataId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "DataId(0x{:04X} {:?})", self.0, self.kind())
    }
}

impl fmt::Display for DataId {
    /// Xsens-style name: `Acceleration(Float32)`, `EulerAngles(EastNorthUp,FP1220)`, `PacketCounter`,
    /// `0xABCD` for unknown ids.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = self.kind();
        if kind == DataKind::Unknown {
            return write!(f, "0x{:04X}", self.0);
        }
        f.write_str(kind.name())?;
        if let Layout::Floats(_) = kind.layout() {
            let p = match self.precision() {
                Precision::Float32 => "Float32",
                Precision::Fp1220 => "FP1220",
                Precision::Fp1632 => "FP1632",
                Precision::Float64 => "Float64",
            };
            if kind.has_frame() {
                write!(f, "({},{p})", self.coordinate_frame().name())
            } else {
                write!(f, "({p})")
            }
        } else {
            Ok(())
        }
    }
}

/// Why an MTData2 payload or item could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mtdata2Error {
    /// Fewer than the 3 header bytes of an item remain.
    HeaderTruncated {
        /// Bytes left in the payload.
        room: usize,
    },
    /// An item claims more bytes than remain in the payload (iteration stops).
    ItemOverrun {
        /// The item's data id.
        id: u16,
        /// Its announced size.
        size: usize,
        /// Bytes left after its header.
        room: usize,
    },
    /// A known id arrived with a size its format does not allow (this item only).
    BadItemSize {
        /// The item's data id.
        id: u16,
        /// Its announced size.
        size: usize,
        /// The size the id requires (for satellite info: the size its count implies).
        expected: usize,
    },
}

impl fmt::Display for Mtdata2Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::HeaderTruncated { room } => {
                write!(f, "MTData2 item header truncated: {room} bytes left")
            }
            Self::ItemOverrun { id, size, room } => write!(
                f,
                "MTData2 item 0x{id:04X} claims {size} bytes but {room} remain"
            ),
            Self::BadItemSize { id, size, expected } => write!(
                f,
                "MTData2 item 0x{id:04X} has {size} bytes, its format needs {expected}"
            ),
        }
    }
}

impl core::error::Error for Mtdata2Error {}

/// A view of an MTData2 payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MtData2<'a> {
    payload: &'a [u8],
}

impl<'a> MtData2<'a> {
    /// Wraps an MTData2 payload; every check happens while iterating.
    pub const fn new(payload: &'a [u8]) -> Self {
        Self { payload }
    }

    /// The payload bytes.
    pub const fn payload(&self) -> &'a [u8] {
        self.payload
    }

    /// The items in wire order.
    pub fn items(&self) -> Items<'a> {
        Items { rest: self.payload }
    }

    /// Collects the values most consumers need; items in error and unknown ids are skipped
    /// (their count is returned in [`Sample::errors`]).
    pub fn sample(&self) -> Sample {
        let mut s = Sample::default();
        for item in self.items() {
            match item.and_then(|i| i.value()) {
                Ok(v) => s.absorb(&v),
                Err(_) => s.errors += 1,
            }
        }
        s
    }
}

/// Iterator over the items of an MTData2 payload.
#[derive(Debug, Clone)]
pub struct Items<'a> {
    rest: &'a [u8],
}

impl<'a> Iterator for Items<'a> {
    type Item = Result<Item<'a>, Mtdata2Error>;

    fn next(&mut self) -> Option<Self::Item> {
        match *self.rest {
            [] => None,
            [hi, lo, size, ref tail @ ..] => {
                let id = u16::from_be_bytes([hi, lo]);
                let size = usize::from(size);
                match tail.split_at_checked(size) {
                    Some((data, rest)) => {
                        self.rest = rest;
                        Some(Ok(Item {
                            id: DataId(id),
                            data,
                        }))
                    }
                    None => {
                        let room = tail.len();
                        self.rest = &[];
                        Some(Err(Mtdata2Error::ItemOverrun { id, size, room }))
                    }
                }
            }
            _ => {
                let room = self.rest.len();
                self.rest = &[];
                Some(Err(Mtdata2Error::HeaderTruncated { room }))
            }
        }
    }
}

/// One MTData2 item: its id and payload bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Item<'a> {
    /// The data identifier.
    pub id: DataId,
    /// The item's payload bytes.
    pub data: &'a [u8],
}

impl<'a> Item<'a> {
    /// Decodes the item; unknown ids give [`Value::Unknown`].
    pub fn value(&self) -> Result<Value<'a>, Mtdata2Error> {
        let kind = self.id.kind();
        let d = self.data;
        let bad = |expected| Mtdata2Error::BadItemSize {
            id: self.id.0,
            size: d.len(),
            expected,
        };
        if let Some(expected) = self.id.expected_size() {
            if d.len() != expected {
                return Err(bad(expected));
            }
        }
        let p = self.id.precision();
        Ok(match kind {
            DataKind::Temperature => Value::Temperature(floats::<1>(d, p)[0]),
            DataKind::UtcTime => Value::UtcTime(UtcTime::parse(d).ok_or(bad(12))?),
            DataKind::PacketCounter => Value::PacketCounter(u16::from_be_bytes(arr(d))),
            DataKind::SampleTimeFine => Value::SampleTimeFine(u32::from_be_bytes(arr(d))),
            DataKind::SampleTimeCoarse => Value::SampleTimeCoarse(u32::from_be_bytes(arr(d))),
            DataKind::Quaternion => Value::Quaternion(floats(d, p)),
            DataKind::RotationMatrix => Value::RotationMatrix(floats(d, p)),
            DataKind::EulerAngles => Value::EulerAngles(floats(d, p)),
            DataKind::BaroPressure => Value::BaroPressure(u32::from_be_bytes(arr(d))),
            DataKind::DeltaV => Value::DeltaV(floats(d, p)),
            DataKind::Acceleration => Value::Acceleration(floats(d, p)),
            DataKind::FreeAcceleration => Value::FreeAcceleration(floats(d, p)),
            DataKind::AccelerationHr => Value::AccelerationHr(floats(d, p)),
            DataKind::AltitudeEllipsoid => Value::AltitudeEllipsoid(floats::<1>(d, p)[0]),
            DataKind::PositionEcef => Value::PositionEcef(floats(d, p)),
            DataKind::LatLon => Value::LatLon(floats(d, p)),
            DataKind::GnssPvtData => Value::GnssPvtData(GnssPvt::parse(d).ok_or(bad(94))?),
            DataKind::GnssSatInfo => Value::GnssSatInfo(GnssSatInfo::parse(self.id, d)?),
            DataKind::RateOfTurn => Value::RateOfTurn(floats(d, p)),
            DataKind::DeltaQ => Value::DeltaQ(floats(d, p)),
            DataKind::RateOfTurnHr => Value::RateOfTurnHr(floats(d, p)),
            DataKind::MagneticField => Value::MagneticField(floats(d, p)),
            DataKind::VelocityXyz => Value::VelocityXyz(floats(d, p)),
            DataKind::StatusByte => Value::StatusByte(u8::from_be_bytes(arr(d))),
            DataKind::StatusWord => Value::StatusWord(u32::from_be_bytes(arr(d))),
            DataKind::Rssi => Value::Rssi(i8::from_be_bytes(arr(d))),
            DataKind::Unknown => Value::Unknown(d),
        })
    }
}

/// The first `N` bytes (zero-padded when short; sizes are checked before this is used).
#[inline]
fn arr<const N: usize>(d: &[u8]) -> [u8; N] {
    let mut out = [0u8; N];
    for (o, b) in out.iter_mut().zip(d) {
        *o = *b;
    }
    out
}

/// `N` values in precision `p` (0.0 for missing bytes; sizes are checked before this is used).
#[inline]
fn floats<const N: usize>(d: &[u8], p: Precision) -> [f64; N] {
    let mut out = [0.0; N];
    for (o, chunk) in out.iter_mut().zip(d.chunks_exact(p.size())) {
        *o = p.decode(chunk).unwrap_or(0.0);
    }
    out
}

/// A decoded MTData2 item. Vectors are `[x, y, z]`; quaternions `[q0 (scalar), q1, q2, q3]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value<'a> {
    /// Temperature \[°C\].
    Temperature(f64),
    /// UTC time.
    UtcTime(UtcTime),
    /// Packet counter (wraps at 2^16).
    PacketCounter(u16),
    /// Sample time \[1/10 ms ticks\], wraps (see [`time`](crate::time)).
    SampleTimeFine(u32),
    /// Sample time \[s\].
    SampleTimeCoarse(u32),
    /// Orientation quaternion, earth frame to sensor frame.
    Quaternion([f64; 4]),
    /// Rotation matrix in wire order (column-major: a=R11, b=R21, c=R31, d=R12, ...).
    RotationMatrix([f64; 9]),
    /// Roll, pitch, yaw \[deg\].
    EulerAngles([f64; 3]),
    /// Barometric pressure \[Pa\].
    BaroPressure(u32),
    /// Velocity increment \[m/s\].
    DeltaV([f64; 3]),
    /// Acceleration \[m/s^2\], sensor frame.
    Acceleration([f64; 3]),
    /// Free acceleration \[m/s^2\], earth frame.
    FreeAcceleration([f64; 3]),
    /// High-rate acceleration \[m/s^2\], sensor frame.
    AccelerationHr([f64; 3]),
    /// Altitude above the ellipsoid \[m\].
    AltitudeEllipsoid(f64),
    /// ECEF position \[m\].
    PositionEcef([f64; 3]),
    /// Latitude, longitude \[deg\].
    LatLon([f64; 2]),
    /// GNSS PVT record.
    GnssPvtData(GnssPvt),
    /// GNSS satellite information.
    GnssSatInfo(GnssSatInfo<'a>),
    /// Rate of turn \[rad/s\], sensor frame.
    RateOfTurn([f64; 3]),
    /// Orientation increment quaternion.
    DeltaQ([f64; 4]),
    /// High-rate rate of turn \[rad/s\], sensor frame.
    RateOfTurnHr([f64; 3]),
    /// Magnetic field \[a.u.\], sensor frame.
    MagneticField([f64; 3]),
    /// Velocity \[m/s\], earth frame.
    VelocityXyz([f64; 3]),
    /// Status byte.
    StatusByte(u8),
    /// Status word.
    StatusWord(u32),
    /// Received signal strength \[dBm\].
    Rssi(i8),
    /// An unknown id's raw bytes.
    Unknown(&'a [u8]),
}

impl Value<'_> {
    /// The float components of float-valued items (empty for the others).
    pub fn floats(&self) -> &[f64] {
        match self {
            Self::Temperature(v) | Self::AltitudeEllipsoid(v) => core::slice::from_ref(v),
            Self::Quaternion(v) | Self::DeltaQ(v) => v,
            Self::RotationMatrix(v) => v,
            Self::EulerAngles(v)
            | Self::DeltaV(v)
            | Self::Acceleration(v)
            | Self::FreeAcceleration(v)
            | Self::AccelerationHr(v)
            | Self::PositionEcef(v)
            | Self::RateOfTurn(v)
            | Self::RateOfTurnHr(v)
            | Self::MagneticField(v)
            | Self::VelocityXyz(v) => v,
            Self::LatLon(v) => v,
            _ => &[],
        }
    }
}

/// UTC time item (0x1010).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UtcTime {
    /// Nanoseconds of the second.
    pub nanos: u32,
    /// Year.
    pub year: u16,
    /// Month 1..12.
    pub month: u8,
    /// Day 1..31.
    pub day: u8,
    /// Hour 0..23.
    pub hour: u8,
    /// Minute 0..59.
    pub minute: u8,
    /// Second 0..60.
    pub second: u8,
    /// Validity flags (bit 0: date valid, bit 1: time of day valid, bit 2: fully resolved).
    pub flags: u8,
}

impl UtcTime {
    fn parse(d: &[u8]) -> Option<Self> {
        let [n0, n1, n2, n3, y0, y1, month, day, hour, minute, second, flags] = take(d)?;
        Some(Self {
            nanos: u32::from_be_bytes([n0, n1, n2, n3]),
            year: u16::from_be_bytes([y0, y1]),
            month,
            day,
            hour,
            minute,
            second,
            flags,
        })
    }

    /// The 12 wire bytes.
    pub fn to_bytes(&self) -> [u8; 12] {
        let mut out = [0u8; 12];
        out[..4].copy_from_slice(&self.nanos.to_be_bytes());
        out[4..6].copy_from_slice(&self.year.to_be_bytes());
        out[6..].copy_from_slice(&[
            self.month,
            self.day,
            self.hour,
            self.minute,
            self.second,
            self.flags,
        ]);
        out
    }
}

impl fmt::Display for UtcTime {
    /// RFC 3339 with trailing zeros of the fraction removed: `2019-01-20T13:47:24.1219Z`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}",
            self.year, self.month, self.day, self.hour, self.minute, self.second
        )?;
        if self.nanos != 0 {
            let mut n = self.nanos;
            let mut digits = 9;
            while n.is_multiple_of(10) {
                n /= 10;
                digits -= 1;
            }
            write!(f, ".{n:0digits$}")?;
        }
        f.write_str("Z")
    }
}

/// GNSS PVT record (0x7010, 94 bytes; the fields of u-blox NAV-PVT).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(missing_docs)]
pub struct GnssPvt {
    /// GPS time of week \[ms\].
    pub itow: u32,
    pub year: u16,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub min: u8,
    pub sec: u8,
    /// Validity flags.
    pub valid: u8,
    /// Time accuracy \[ns\].
    pub t_acc: u32,
    /// Fraction of second \[ns\], may be negative.
    pub nano: i32,
    /// 0 none, 2 2D, 3 3D, ...
    pub fix_type: u8,
    pub flags: u8,
    /// Satellites used.
    pub num_sv: u8,
    pub reserved1: u8,
    /// Longitude \[1e-7 deg\].
    pub lon: i32,
    /// Latitude \[1e-7 deg\].
    pub lat: i32,
    /// Height above ellipsoid \[mm\].
    pub height: i32,
    /// Height above mean sea level \[mm\].
    pub hmsl: i32,
    /// Horizontal accuracy \[mm\].
    pub h_acc: u32,
    /// Vertical accuracy \[mm\].
    pub v_acc: u32,
    /// North velocity \[mm/s\].
    pub vel_n: i32,
    /// East velocity \[mm/s\].
    pub vel_e: i32,
    /// Down velocity \[mm/s\].
    pub vel_d: i32,
    /// Ground speed \[mm/s\].
    pub g_speed: i32,
    /// Heading of motion \[1e-5 deg\].
    pub head_mot: i32,
    /// Speed accuracy \[mm/s\].
    pub s_acc: u32,
    /// Heading accuracy \[1e-5 deg\].
    pub head_acc: u32,
    /// Heading of vehicle \[1e-5 deg\].
    pub head_veh: i32,
    /// Dilutions of precision \[0.01\].
    pub gdop: u16,
    pub pdop: u16,
    pub tdop: u16,
    pub vdop: u16,
    pub hdop: u16,
    pub ndop: u16,
    pub edop: u16,
}

/// Big-endian cursor over a checked slice.
struct Cursor<'a>(&'a [u8]);

impl Cursor<'_> {
    fn bytes<const N: usize>(&mut self) -> [u8; N] {
        let out = arr::<N>(self.0);
        self.0 = self.0.get(N..).unwrap_or_default();
        out
    }
    fn u8(&mut self) -> u8 {
        self.bytes::<1>()[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_be_bytes(self.bytes())
    }
    fn u32(&mut self) -> u32 {
        u32::from_be_bytes(self.bytes())
    }
    fn i32(&mut self) -> i32 {
        i32::from_be_bytes(self.bytes())
    }
}

impl GnssPvt {
    fn parse(d: &[u8]) -> Option<Self> {
        if d.len() != 94 {
            return None;
        }
        let mut c = Cursor(d);
        Some(Self {
            itow: c.u32(),
            year: c.u16(),
            month: c.u8(),
            day: c.u8(),
            hour: c.u8(),
            min: c.u8(),
            sec: c.u8(),
            valid: c.u8(),
            t_acc: c.u32(),
            nano: c.i32(),
            fix_type: c.u8(),
            flags: c.u8(),
            num_sv: c.u8(),
            reserved1: c.u8(),
            lon: c.i32(),
            lat: c.i32(),
            height: c.i32(),
            hmsl: c.i32(),
            h_acc: c.u32(),
            v_acc: c.u32(),
            vel_n: c.i32(),
            vel_e: c.i32(),
            vel_d: c.i32(),
            g_speed: c.i32(),
            head_mot: c.i32(),
            s_acc: c.u32(),
            head_acc: c.u32(),
            head_veh: c.i32(),
            gdop: c.u16(),
            pdop: c.u16(),
            tdop: c.u16(),
            vdop: c.u16(),
            hdop: c.u16(),
            ndop: c.u16(),
            edop: c.u16(),
        })
    }
}

/// GNSS satellite information (0x7020): a header and 4 bytes per satellite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GnssSatInfo<'a> {
    /// GPS time of week \[ms\].
    pub itow: u32,
    /// Number of satellites that follow.
    pub num_svs: u8,
    /// Reserved bytes.
    pub reserved: [u8; 3],
    sats: &'a [u8],
}

/// One satellite of [`GnssSatInfo`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Satellite {
    /// GNSS system (0 GPS, 1 SBAS, 2 Galileo, 3 BeiDou, 5 QZSS, 6 GLONASS).
    pub gnss_id: u8,
    /// Satellite id within the system.
    pub sv_id: u8,
    /// Carrier to noise ratio \[dBHz\].
    pub cno: u8,
    /// Flags (quality, used for navigation, health, differential).
    pub flags: u8,
}

impl<'a> GnssSatInfo<'a> {
    fn parse(id: DataId, d: &'a [u8]) -> Result<Self, Mtdata2Error> {
        let [i0, i1, i2, i3, num_svs, r0, r1, r2] = take(d).ok_or(Mtdata2Error::BadItemSize {
            id: id.0,
            size: d.len(),
            expected: 8,
        })?;
        let expected = 8 + 4 * usize::from(num_svs);
        let sats = d.get(8..).unwrap_or_default();
        if d.len() != expected {
            return Err(Mtdata2Error::BadItemSize {
                id: id.0,
                size: d.len(),
                expected,
            });
        }
        Ok(Self {
            itow: u32::from_be_bytes([i0, i1, i2, i3]),
            num_svs,
            reserved: [r0, r1, r2],
            sats,
        })
    }

    /// The satellite records as sent (4 bytes each).
    pub fn raw_satellites(&self) -> &'a [u8] {
        self.sats
    }

    /// The satellites.
    pub fn satellites(&self) -> impl Iterator<Item = Satellite> + 'a {
        self.sats.chunks_exact(4).map(|c| Satellite {
            gnss_id: c.first().copied().unwrap_or(0),
            sv_id: c.get(1).copied().unwrap_or(0),
            cno: c.get(2).copied().unwrap_or(0),
            flags: c.get(3).copied().unwrap_or(0),
        })
    }
}

/// The values of one MTData2 message that an inertial pipeline uses.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// Packet counter.
    pub packet_counter: Option<u16>,
    /// Sample time \[1/10 ms ticks\], raw (wrapping).
    pub sample_time_fine: Option<u32>,
    /// Acceleration \[m/s^2\], sensor frame.
    pub acceleration: Option<[f64; 3]>,
    /// Rate of turn \[rad/s\], sensor frame.
    pub rate_of_turn: Option<[f64; 3]>,
    /// Magnetic field \[a.u.\], sensor frame.
    pub magnetic_field: Option<[f64; 3]>,
    /// Velocity increment \[m/s\].
    pub delta_v: Option<[f64; 3]>,
    /// Orientation increment.
    pub delta_q: Option<[f64; 4]>,
    /// Orientation quaternion.
    pub quaternion: Option<[f64; 4]>,
    /// Roll, pitch, yaw \[deg\].
    pub euler_angles: Option<[f64; 3]>,
    /// Free acceleration \[m/s^2\].
    pub free_acceleration: Option<[f64; 3]>,
    /// Temperature \[°C\].
    pub temperature: Option<f64>,
    /// Barometric pressure \[Pa\].
    pub pressure_pa: Option<f64>,
    /// Status word (a status byte is widened).
    pub status: Option<u32>,
    /// True when the message carries a GNSS PVT record (its time runs behind the inertial
    /// messages).
    pub has_gnss_pvt: bool,
    /// True when the message carries GNSS satellite info (sent separately, with the PVT's time).
    pub has_gnss_sat_info: bool,
    /// True when it carries high-rate (HR) outputs.
    pub has_high_rate: bool,
    /// Items that failed to decode.
    pub errors: u16,
}

impl Sample {
    fn absorb(&mut self, v: &Value<'_>) {
        match *v {
            Value::PacketCounter(c) => self.packet_counter = Some(c),
            Value::SampleTimeFine(t) => self.sample_time_fine = Some(t),
            Value::Acceleration(a) => self.acceleration = Some(a),
            Value::RateOfTurn(w) => self.rate_of_turn = Some(w),
            Value::MagneticField(m) => self.magnetic_field = Some(m),
            Value::DeltaV(d) => self.delta_v = Some(d),
            Value::DeltaQ(q) => self.delta_q = Some(q),
            Value::Quaternion(q) => self.quaternion = Some(q),
            Value::EulerAngles(e) => self.euler_angles = Some(e),
            Value::FreeAcceleration(a) => self.free_acceleration = Some(a),
            Value::Temperature(t) => self.temperature = Some(t),
            Value::BaroPressure(p) => self.pressure_pa = Some(f64::from(p)),
            Value::StatusWord(s) => self.status = Some(s),
            Value::StatusByte(s) => self.status = Some(u32::from(s)),
            Value::GnssPvtData(_) => self.has_gnss_pvt = true,
            Value::GnssSatInfo(_) => self.has_gnss_sat_info = true,
            Value::AccelerationHr(a) => {
                self.has_high_rate = true;
                self.acceleration.get_or_insert(a);
            }
            Value::RateOfTurnHr(w) => {
                self.has_high_rate = true;
                self.rate_of_turn.get_or_insert(w);
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precisions_decode_known_vectors() {
        assert_eq!(Precision::Float32.decode(&1.5f32.to_be_bytes()), Some(1.5));
        // -1.5 in 12.20 = -0x0018_0000
        assert_eq!(
            Precision::Fp1220.decode(&(-0x0018_0000i32).to_be_bytes()),
            Some(-1.5)
        );
        // 16.32: fraction 0x8000_0000 (0.5) then integer -2 -> -1.5
        assert_eq!(
            Precision::Fp1632.decode(&[0x80, 0, 0, 0, 0xFF, 0xFE]),
            Some(-1.5)
        );
        assert_eq!(
            Precision::Fp1632.decode(&[0, 0, 0, 1, 0, 0]),
            Some(1.0 / 4_294_967_296.0)
        );
        assert_eq!(
            Precision::Float64.decode(&(-2.25f64).to_be_bytes()),
            Some(-2.25)
        );
        assert_eq!(Precision::Fp1632.decode(&[0; 5]), None);
    }

    #[test]
    fn precisions_round_trip() {
        for p in Precision::ALL {
            let mut buf = [0u8; 8];
            for v in [0.0, 1.0, -9.80665, 123.456, -0.001] {
                p.encode(v, &mut buf).unwrap();
                let back = p.decode(&buf).unwrap();
                let tol = match p {
                    Precision::Float32 => 1e-5 * v.abs().max(1.0),
                    Precision::Fp1220 => 0.5 / f64::from(1u32 << 20),
                    Precision::Fp1632 => 0.5 / 4_294_967_296.0,
                    Precision::Float64 => 0.0,
                };
                assert!((back - v).abs() <= tol, "{p:?} {v} -> {back}");
            }
        }
    }

    #[test]
    fn data_id_fields() {
        let id = DataId(0x2035);
        assert_eq!(id.kind(), DataKind::EulerAngles);
        assert_eq!(id.precision(), Precision::Fp1220);
        assert_eq!(id.coordinate_frame(), CoordinateFrame::Ned);
        assert_eq!(id.expected_size(), Some(12));
        assert_eq!(std::format!("{id}"), "EulerAngles(NorthEastDown,FP1220)");
        assert_eq!(std::format!("{}", DataId(0x4023)), "Acceleration(Float64)");
        assert_eq!(std::format!("{}", DataId(0x1020)), "PacketCounter");
        assert_eq!(std::format!("{}", DataId(0x9990)), "0x9990");
        assert_eq!(
            DataId::of(DataKind::Quaternion, Precision::Fp1632)
                .map(|i| i.in_frame(CoordinateFrame::Nwu)),
            Some(DataId(0x201A))
        );
        for kind in DataKind::ALL {
            let id = DataId::of(*kind, Precision::Float64).unwrap();
            assert_eq!(id.kind(), *kind);
        }
    }

    #[test]
    fn unknown_ids_are_skipped_by_size_and_bad_sizes_do_not_abort() {
        let payload = [
            0x10, 0x20, 0x02, 0x01, 0x02, // PacketCounter 258
            0x99, 0x90, 0x03, 0xAA, 0xBB, 0xCC, // unknown
            0x40, 0x20, 0x02, 0x00, 0x00, // Acceleration with 2 bytes: bad size
            0x10, 0x60, 0x04, 0x00, 0x00, 0x00, 0x2A, // SampleTimeFine 42
        ];
        let values: std::vec::Vec<_> = MtData2::new(&payload)
            .items()
            .map(|i| i.and_then(|i| i.value()))
            .collect();
        assert_eq!(values.len(), 4);
        assert_eq!(values[0], Ok(Value::PacketCounter(258)));
        assert_eq!(values[1], Ok(Value::Unknown(&[0xAA, 0xBB, 0xCC])));
        assert_eq!(
            values[2],
            Err(Mtdata2Error::BadItemSize {
                id: 0x4020,
                size: 2,
                expected: 12
            })
        );
        assert_eq!(values[3], Ok(Value::SampleTimeFine(42)));
    }

    #[test]
    fn overrun_and_truncated_header_stop_iteration_with_evidence() {
        let overrun = [0x10, 0x20, 0x05, 0x01];
        let v: std::vec::Vec<_> = MtData2::new(&overrun).items().collect();
        assert_eq!(
            v,
            vec![Err(Mtdata2Error::ItemOverrun {
                id: 0x1020,
                size: 5,
                room: 1
            })]
        );
        let short = [0x10, 0x20, 0x01, 0x07, 0x10];
        let v: std::vec::Vec<_> = MtData2::new(&short).items().collect();
        assert_eq!(v.len(), 2);
        assert_eq!(v[1], Err(Mtdata2Error::HeaderTruncated { room: 1 }));
    }

    #[test]
    fn utc_time_formats_like_rfc3339_nano() {
        let mut t = UtcTime {
            nanos: 121_900_000,
            year: 2019,
            month: 1,
            day: 20,
            hour: 13,
            minute: 47,
            second: 24,
            flags: 7,
        };
        assert_eq!(std::format!("{t}"), "2019-01-20T13:47:24.1219Z");
        t.nanos = 0;
        assert_eq!(std::format!("{t}"), "2019-01-20T13:47:24Z");
        t.nanos = 5;
        assert_eq!(std::format!("{t}"), "2019-01-20T13:47:24.000000005Z");
        assert_eq!(UtcTime::parse(&t.to_bytes()), Some(t));
    }

    #[test]
    fn sat_info_size_follows_its_count() {
        let mut d = [0u8; 16];
        d[4] = 2;
        d[8..12].copy_from_slice(&[0, 5, 40, 0x0F]);
        let item = Item {
            id: DataId(0x7020),
            data: &d,
        };
        let Ok(Value::GnssSatInfo(s)) = item.value() else {
            panic!()
        };
        let sats: std::vec::Vec<_> = s.satellites().collect();
        assert_eq!(sats.len(), 2);
        assert_eq!(
            sats[0],
            Satellite {
                gnss_id: 0,
                sv_id: 5,
                cno: 40,
                flags: 0x0F
            }
        );
        let item = Item {
            id: DataId(0x7020),
            data: &d[..12],
        };
        assert_eq!(
            item.value(),
            Err(Mtdata2Error::BadItemSize {
                id: 0x7020,
                size: 12,
                expected: 16
            })
        );
    }
}
