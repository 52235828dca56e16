//! Typed TLV decoding: zero-copy views over TLV payloads.
//!
//! [`RawTlv::decode`] maps a TLV to a [`Tlv`] according to the frame's [`Dialect`]: the
//! out-of-box demo (SDK 1-3 and the radar toolbox) or the people-counting labs, which reuse the
//! type numbers 6-8 for other payloads. A type this crate does not know becomes
//! [`Tlv::Unknown`]; a known type whose payload does not fit its layout is a [`TlvError`] (the
//! raw payload stays available), so lab-specific payloads never produce garbage values.

use crate::error::{Expected, TlvError};
use crate::frame::{Frame, Layout, RawTlv};

/// Which type dictionary a frame's TLVs follow.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// Out-of-box demo and radar toolbox. `sdk_major` decides the point format of type 1
    /// (Q-format with a descriptor before SDK 3, f32 from SDK 3 on).
    Oob {
        /// SDK major version from the header.
        sdk_major: u8,
    },
    /// Industrial Toolbox people-counting labs (48/52-byte headers).
    PeopleCounting,
}

impl Dialect {
    /// The dialect of a checked frame.
    pub fn of(frame: &Frame<'_>) -> Dialect {
        match frame.layout() {
            Layout::PeopleCounting48 | Layout::PeopleCounting52 => Dialect::PeopleCounting,
            Layout::Oob36 | Layout::Oob40 => Dialect::Oob {
                sdk_major: frame.header().version.major(),
            },
        }
    }
}

/// TLV type numbers.
pub mod types {
    /// Detected points (OOB).
    pub const POINTS: u32 = 1;
    /// Range profile (OOB).
    pub const RANGE_PROFILE: u32 = 2;
    /// Noise profile (OOB).
    pub const NOISE_PROFILE: u32 = 3;
    /// Azimuth static heatmap (OOB).
    pub const AZIMUTH_HEATMAP: u32 = 4;
    /// Range-Doppler heatmap (OOB).
    pub const RANGE_DOPPLER_HEATMAP: u32 = 5;
    /// Statistics (OOB).
    pub const STATS: u32 = 6;
    /// Side info per point (OOB).
    pub const SIDE_INFO: u32 = 7;
    /// Azimuth/elevation static heatmap (OOB, AOP/ODS builds).
    pub const AZ_EL_HEATMAP: u32 = 8;
    /// Temperature (OOB).
    pub const TEMPERATURE: u32 = 9;
    /// Compressed spherical points (people-counting labs).
    pub const PC_COMPRESSED_POINTS: u32 = 6;
    /// Tracked targets (people-counting labs).
    pub const PC_TARGETS: u32 = 7;
    /// Target index per point of the previous frame (people-counting labs).
    pub const PC_TARGET_INDEX: u32 = 8;
    /// Presence indication (people-counting labs).
    pub const PC_PRESENCE: u32 = 11;
    /// Tracked targets (radar toolbox).
    pub const TARGETS: u32 = 1010;
    /// Target index (radar toolbox).
    pub const TARGET_INDEX: u32 = 1011;
    /// Target height (radar toolbox).
    pub const TARGET_HEIGHT: u32 = 1012;
    /// Compressed spherical points (radar toolbox).
    pub const COMPRESSED_POINTS: u32 = 1020;
    /// Presence indication (radar toolbox).
    pub const PRESENCE: u32 = 1021;
}

/// A decoded TLV.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tlv<'a> {
    /// SDK 3 detected points.
    Points(Points<'a>),
    /// SDK 1/2 detected points in Q format.
    PointsQ(PointsQ<'a>),
    /// Range profile: one u16 per range bin (log2 magnitude, Q9).
    RangeProfile(U16s<'a>),
    /// Noise profile: one u16 per range bin (log2 magnitude, Q9).
    NoiseProfile(U16s<'a>),
    /// Azimuth static heatmap: complex16 (imag first) per range bin x virtual antenna.
    AzimuthHeatmap(Complex16s<'a>),
    /// Range-Doppler heatmap: u16, range-major.
    RangeDopplerHeatmap(U16s<'a>),
    /// Processing statistics.
    Stats(Stats),
    /// SNR and noise per point.
    SideInfo(SideInfo<'a>),
    /// Azimuth/elevation static heatmap: complex16 (imag first).
    AzElHeatmap(Complex16s<'a>),
    /// Chip temperatures.
    Temperature(Temperature),
    /// Compressed spherical points (people counting type 6, radar toolbox 1020).
    CompressedPoints(CompressedPoints<'a>),
    /// Tracked targets (people counting type 7, radar toolbox 1010).
    Targets(Targets<'a>),
    /// Target id per point of the previous frame; 253/254/255 mean not associated.
    TargetIndex(&'a [u8]),
    /// Target heights (radar toolbox 1012).
    TargetHeights(TargetHeights<'a>),
    /// Presence indication (people counting 11, radar toolbox 1021).
    Presence(u32),
    /// A type this decoder does not know: passed through untouched.
    Unknown {
        /// TLV type.
        ty: u32,
        /// Raw payload.
        payload: &'a [u8],
    },
}

impl<'a> RawTlv<'a> {
    /// Decodes this TLV under `dialect`.
    pub fn decode(&self, dialect: Dialect) -> Result<Tlv<'a>, TlvError> {
        let p = self.payload;
        let ty = self.ty;
        match dialect {
            Dialect::Oob { sdk_major } => match ty {
                types::POINTS if sdk_major >= 3 => Ok(Tlv::Points(Points(multiple(ty, p, 16)?))),
                types::POINTS => PointsQ::new(p).map(Tlv::PointsQ),
                types::RANGE_PROFILE => Ok(Tlv::RangeProfile(U16s(pow2_u16s(ty, p)?))),
                types::NOISE_PROFILE => Ok(Tlv::NoiseProfile(U16s(pow2_u16s(ty, p)?))),
                types::AZIMUTH_HEATMAP => Ok(Tlv::AzimuthHeatmap(Complex16s(multiple(ty, p, 4)?))),
                types::RANGE_DOPPLER_HEATMAP => {
                    Ok(Tlv::RangeDopplerHeatmap(U16s(pow2_u16s(ty, p)?)))
                }
                types::STATS => Stats::new(ty, p).map(Tlv::Stats),
                types::SIDE_INFO => Ok(Tlv::SideInfo(SideInfo(multiple(ty, p, 4)?))),
                types::AZ_EL_HEATMAP => Ok(Tlv::AzElHeatmap(Complex16s(multiple(ty, p, 4)?))),
                types::TEMPERATURE => Temperature::new(ty, p).map(Tlv::Temperature),
                types::COMPRESSED_POINTS => CompressedPoints::new(ty, p).map(Tlv::CompressedPoints),
                types::TARGETS => Ok(Tlv::Targets(Targets(multiple(ty, p, Target::SIZE as u32)?))),
                types::TARGET_INDEX => Ok(Tlv::TargetIndex(p)),
                types::TARGET_HEIGHT => Ok(Tlv::TargetHeights(TargetHeights(multiple(ty, p, 12)?))),
                types::PRESENCE => presence(ty, p),
                _ => Ok(Tlv::Unknown { ty, payload: p }),
            },
            Dialect::PeopleCounting => match ty {
                types::PC_COMPRESSED_POINTS => {
                    CompressedPoints::new(ty, p).map(Tlv::CompressedPoints)
                }
                types::PC_TARGETS => {
                    Ok(Tlv::Targets(Targets(multiple(ty, p, Target::SIZE as u32)?)))
                }
                types::PC_TARGET_INDEX => Ok(Tlv::TargetIndex(p)),
                types::PC_PRESENCE => presence(ty, p),
                _ => Ok(Tlv::Unknown { ty, payload: p }),
            },
        }
    }
}

fn bad(ty: u32, p: &[u8], expected: Expected) -> TlvError {
    TlvError::BadLength {
        ty,
        len: p.len() as u32,
        expected,
    }
}

fn multiple(ty: u32, p: &[u8], n: u32) -> Result<&[u8], TlvError> {
    if p.len().is_multiple_of(n as usize) {
        Ok(p)
    } else {
        Err(bad(ty, p, Expected::MultipleOf(n)))
    }
}

fn pow2_u16s(ty: u32, p: &[u8]) -> Result<&[u8], TlvError> {
    if p.len().is_multiple_of(2) && (p.len() / 2).is_power_of_two() {
        Ok(p)
    } else {
        Err(bad(ty, p, Expected::PowerOfTwoU16s))
    }
}

fn exactly(ty: u32, p: &[u8], n: u32) -> Result<&[u8], TlvError> {
    if p.len() == n as usize {
        Ok(p)
    } else {
        Err(bad(ty, p, Expected::Exactly(n)))
    }
}

fn presence(ty: u32, p: &[u8]) -> Result<Tlv<'_>, TlvError> {
    exactly(ty, p, 4).map(|p| Tlv::Presence(u32_at(p, 0)))
}

fn u32_at(p: &[u8], i: usize) -> u32 {
    p.get(i..i + 4)
        .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}
fn f32_at(p: &[u8], i: usize) -> f32 {
    f32::from_bits(u32_at(p, i))
}
fn u16_at(p: &[u8], i: usize) -> u16 {
    p.get(i..i + 2)
        .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]))
}
fn i16_at(p: &[u8], i: usize) -> i16 {
    u16_at(p, i) as i16
}

/// A detected point in Cartesian sensor coordinates: x right, y boresight, z up.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// x \[m\].
    pub x: f32,
    /// y \[m\] (boresight).
    pub y: f32,
    /// z \[m\].
    pub z: f32,
    /// Radial (Doppler) velocity \[m/s\]; negative when approaching.
    pub velocity: f32,
}

/// SDK 3 points: N x {f32 x, y, z \[m\], f32 velocity \[m/s\]}.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Points<'a>(&'a [u8]);

impl<'a> Points<'a> {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.0.len() / 16
    }
    /// True when the TLV carries no point (the zero-length TLV 1 firmware quirk).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Point `i`, if present.
    pub fn get(&self, i: usize) -> Option<Point> {
        let b = self.0.get(i * 16..i * 16 + 16)?;
        Some(Point {
            x: f32_at(b, 0),
            y: f32_at(b, 4),
            z: f32_at(b, 8),
            velocity: f32_at(b, 12),
        })
    }
    /// All points in order.
    pub fn iter(&self) -> impl Iterator<Item = Point> + 'a {
        let s = *self;
        (0..s.len()).filter_map(move |i| s.get(i))
    }
}

/// SDK 1/2 point in Q format, converted to metres; the Doppler stays a bin index because its
/// scale comes from the chirp configuration (see [`crate::cfg::Derived::velocity_resolution_mps`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct QPoint {
    /// Range bin index.
    pub range_idx: u16,
    /// Signed Doppler bin index (multiply by the velocity resolution for m/s).
    pub doppler_idx: i16,
    /// Peak value (linear magnitude, unitless).
    pub peak: u16,
    /// x \[m\].
    pub x: f32,
    /// y \[m\].
    pub y: f32,
    /// z \[m\].
    pub z: f32,
}

/// SDK 1/2 points: {u16 numObj, u16 xyzQFormat} then N x {u16 rangeIdx, i16 dopplerIdx,
/// u16 peakVal, i16 x, i16 y, i16 z}; metres = value / 2^Q.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointsQ<'a> {
    q: u16,
    body: &'a [u8],
}

impl<'a> PointsQ<'a> {
    fn new(p: &'a [u8]) -> Result<Self, TlvError> {
        const TY: u32 = types::POINTS;
        if p.len() < 4 {
            return Err(bad(
                TY,
                p,
                Expected::PrefixThenMultipleOf {
                    prefix: 4,
                    elem: 12,
                },
            ));
        }
        let count = u32::from(u16_at(p, 0));
        let q = u16_at(p, 2);
        let implied = 4 + 12 * count;
        if p.len() != implied as usize {
            return Err(bad(TY, p, Expected::FromCount { count, implied }));
        }
        if q > 15 {
            return Err(TlvError::BadQFormat { q });
        }
        Ok(PointsQ { q, body: &p[4..] })
    }
    /// The Q format (fractional bits of x, y, z).
    pub fn q_format(&self) -> u16 {
        self.q
    }
    /// Number of points.
    pub fn len(&self) -> usize {
        self.body.len() / 12
    }
    /// True when there is no point.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Point `i`, if present.
    pub fn get(&self, i: usize) -> Option<QPoint> {
        let b = self.body.get(i * 12..i * 12 + 12)?;
        let scale = 1.0 / (1u32 << self.q) as f32;
        Some(QPoint {
            range_idx: u16_at(b, 0),
            doppler_idx: i16_at(b, 2),
            peak: u16_at(b, 4),
            x: f32::from(i16_at(b, 6)) * scale,
            y: f32::from(i16_at(b, 8)) * scale,
            z: f32::from(i16_at(b, 10)) * scale,
        })
    }
    /// All points in order.
    pub fn iter(&self) -> impl Iterator<Item = QPoint> + 'a {
        let s = *self;
        (0..s.len()).filter_map(move |i| s.get(i))
    }
}

/// A slice of little-endian u16 values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct U16s<'a>(&'a [u8]);

impl<'a> U16s<'a> {
    /// Number of values.
    pub fn len(&self) -> usize {
        self.0.len() / 2
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// Value `i`, if present.
    pub fn get(&self, i: usize) -> Option<u16> {
        self.0
            .get(i * 2..i * 2 + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
    }
    /// All values in order.
    pub fn iter(&self) -> impl Iterator<Item = u16> + 'a {
        self.0
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
    }
}

/// A slice of complex16 values sent imaginary part first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Complex16s<'a>(&'a [u8]);

impl<'a> Complex16s<'a> {
    /// Number of complex values.
    pub fn len(&self) -> usize {
        self.0.len() / 4
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// Value `i` as (real, imag), if present.
    pub fn get(&self, i: usize) -> Option<(i16, i16)> {
        let b = self.0.get(i * 4..i * 4 + 4)?;
        Some((i16_at(b, 2), i16_at(b, 0)))
    }
}

/// Processing statistics (OOB type 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stats {
    /// Inter-frame processing time \[us\].
    pub inter_frame_processing_time_us: u32,
    /// Transmit output time \[us\].
    pub transmit_output_time_us: u32,
    /// Inter-frame processing margin \[us\].
    pub inter_frame_processing_margin_us: u32,
    /// Inter-chirp processing margin \[us\].
    pub inter_chirp_processing_margin_us: u32,
    /// Active frame CPU load \[%\].
    pub active_frame_cpu_load_pct: u32,
    /// Inter-frame CPU load \[%\].
    pub inter_frame_cpu_load_pct: u32,
}

impl Stats {
    fn new(ty: u32, p: &[u8]) -> Result<Self, TlvError> {
        let p = exactly(ty, p, 24)?;
        Ok(Stats {
            inter_frame_processing_time_us: u32_at(p, 0),
            transmit_output_time_us: u32_at(p, 4),
            inter_frame_processing_margin_us: u32_at(p, 8),
            inter_chirp_processing_margin_us: u32_at(p, 12),
            active_frame_cpu_load_pct: u32_at(p, 16),
            inter_frame_cpu_load_pct: u32_at(p, 20),
        })
    }
}

/// Side info of one point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SideInfoEntry {
    /// SNR \[0.1 dB\].
    pub snr_raw: i16,
    /// Noise \[0.1 dB\].
    pub noise_raw: i16,
}

impl SideInfoEntry {
    /// SNR \[dB\].
    pub fn snr_db(&self) -> f32 {
        f32::from(self.snr_raw) * 0.1
    }
    /// Noise \[dB\].
    pub fn noise_db(&self) -> f32 {
        f32::from(self.noise_raw) * 0.1
    }
}

/// Side info per point (OOB type 7): i16 snr, i16 noise, in 0.1 dB.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SideInfo<'a>(&'a [u8]);

impl<'a> SideInfo<'a> {
    /// Number of entries (one per point of TLV 1).
    pub fn len(&self) -> usize {
        self.0.len() / 4
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// Entry `i`, if present.
    pub fn get(&self, i: usize) -> Option<SideInfoEntry> {
        let b = self.0.get(i * 4..i * 4 + 4)?;
        Some(SideInfoEntry {
            snr_raw: i16_at(b, 0),
            noise_raw: i16_at(b, 2),
        })
    }
    /// All entries in order.
    pub fn iter(&self) -> impl Iterator<Item = SideInfoEntry> + 'a {
        let s = *self;
        (0..s.len()).filter_map(move |i| s.get(i))
    }
}

/// Chip temperatures (OOB type 9).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Temperature {
    /// Non-zero when the report is valid (tempReportValid == 0 means valid in the SDK; kept raw).
    pub report_valid: i32,
    /// Time of the report \[ms\].
    pub time_ms: u32,
    /// Rx0-3, Tx0-2, PM, Dig0, Dig1 \[deg C\].
    pub sensors_c: [i16; 10],
}

impl Temperature {
    fn new(ty: u32, p: &[u8]) -> Result<Self, TlvError> {
        let p = exactly(ty, p, 28)?;
        let mut sensors_c = [0i16; 10];
        for (i, s) in sensors_c.iter_mut().enumerate() {
            *s = i16_at(p, 8 + 2 * i);
        }
        Ok(Temperature {
            report_valid: u32_at(p, 0) as i32,
            time_ms: u32_at(p, 4),
            sensors_c,
        })
    }
}

/// Units of the compressed point cloud: raw value x unit = physical value.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CompressedUnits {
    /// Elevation unit \[rad\].
    pub elevation: f32,
    /// Azimuth unit \[rad\].
    pub azimuth: f32,
    /// Doppler unit \[m/s\].
    pub doppler: f32,
    /// Range unit \[m\].
    pub range: f32,
    /// SNR unit (linear ratio as the lab reports it).
    pub snr: f32,
}

/// A point of the compressed cloud, in spherical coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SphericalPoint {
    /// Range \[m\].
    pub range: f32,
    /// Azimuth \[rad\], positive to the right of boresight.
    pub azimuth: f32,
    /// Elevation \[rad\], positive up.
    pub elevation: f32,
    /// Radial velocity \[m/s\].
    pub doppler: f32,
    /// SNR (the lab's linear unit).
    pub snr: f32,
}

impl SphericalPoint {
    /// Cartesian point (x right, y boresight, z up), as TI's tools convert it.
    pub fn to_cartesian(&self) -> Point {
        let (se, ce) = (libm::sinf(self.elevation), libm::cosf(self.elevation));
        let (sa, ca) = (libm::sinf(self.azimuth), libm::cosf(self.azimuth));
        Point {
            x: self.range * ce * sa,
            y: self.range * ce * ca,
            z: self.range * se,
            velocity: self.doppler,
        }
    }
}

/// Compressed spherical points: 5 f32 units (elevation, azimuth, doppler, range, snr) then
/// N x {i8 elevation, i8 azimuth, i16 doppler, u16 range, u16 snr}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressedPoints<'a> {
    units: CompressedUnits,
    body: &'a [u8],
}

impl<'a> CompressedPoints<'a> {
    fn new(ty: u32, p: &'a [u8]) -> Result<Self, TlvError> {
        if p.len() < 20 || !(p.len() - 20).is_multiple_of(8) {
            return Err(bad(
                ty,
                p,
                Expected::PrefixThenMultipleOf {
                    prefix: 20,
                    elem: 8,
                },
            ));
        }
        let units = CompressedUnits {
            elevation: f32_at(p, 0),
            azimuth: f32_at(p, 4),
            doppler: f32_at(p, 8),
            range: f32_at(p, 12),
            snr: f32_at(p, 16),
        };
        Ok(CompressedPoints {
            units,
            body: &p[20..],
        })
    }
    /// The units the raw values are multiplied by.
    pub fn units(&self) -> CompressedUnits {
        self.units
    }
    /// Number of points.
    pub fn len(&self) -> usize {
        self.body.len() / 8
    }
    /// True when there is no point.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Point `i` in spherical coordinates, if present.
    pub fn get(&self, i: usize) -> Option<SphericalPoint> {
        let b = self.body.get(i * 8..i * 8 + 8)?;
        let u = self.units;
        Some(SphericalPoint {
            elevation: f32::from(b[0] as i8) * u.elevation,
            azimuth: f32::from(b[1] as i8) * u.azimuth,
            doppler: f32::from(i16_at(b, 2)) * u.doppler,
            range: f32::from(u16_at(b, 4)) * u.range,
            snr: f32::from(u16_at(b, 6)) * u.snr,
        })
    }
    /// All points in order.
    pub fn iter(&self) -> impl Iterator<Item = SphericalPoint> + 'a {
        let s = *self;
        (0..s.len()).filter_map(move |i| s.get(i))
    }
}

/// One tracked target (112 B: u32 tid + 27 f32).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Target {
    /// Track id.
    pub tid: u32,
    /// Position x, y, z \[m\].
    pub position: [f32; 3],
    /// Velocity x, y, z \[m/s\].
    pub velocity: [f32; 3],
    /// Acceleration x, y, z \[m/s^2\].
    pub acceleration: [f32; 3],
    /// Error covariance, 4x4 row-major.
    pub error_covariance: [f32; 16],
    /// Gating function gain.
    pub gain: f32,
    /// Confidence level (0..1).
    pub confidence: f32,
}

impl Target {
    /// Size of one target record \[B\].
    pub const SIZE: usize = 112;
}

/// Tracked targets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Targets<'a>(&'a [u8]);

impl<'a> Targets<'a> {
    /// Number of targets.
    pub fn len(&self) -> usize {
        self.0.len() / Target::SIZE
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// Target `i`, if present.
    pub fn get(&self, i: usize) -> Option<Target> {
        let b = self.0.get(i * Target::SIZE..(i + 1) * Target::SIZE)?;
        let f = |k: usize| f32_at(b, 4 + 4 * k);
        let mut t = Target {
            tid: u32_at(b, 0),
            ..Target::default()
        };
        t.position = [f(0), f(1), f(2)];
        t.velocity = [f(3), f(4), f(5)];
        t.acceleration = [f(6), f(7), f(8)];
        for (k, e) in t.error_covariance.iter_mut().enumerate() {
            *e = f(9 + k);
        }
        t.gain = f(25);
        t.confidence = f(26);
        Some(t)
    }
    /// All targets in order.
    pub fn iter(&self) -> impl Iterator<Item = Target> + 'a {
        let s = *self;
        (0..s.len()).filter_map(move |i| s.get(i))
    }
}

/// Height of one target (radar toolbox 1012).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TargetHeight {
    /// Track id.
    pub tid: u32,
    /// Highest point \[m\].
    pub max_z: f32,
    /// Lowest point \[m\].
    pub min_z: f32,
}

/// Target heights: N x {u32 tid, f32 maxZ, f32 minZ}.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TargetHeights<'a>(&'a [u8]);

impl<'a> TargetHeights<'a> {
    /// Number of entries.
    pub fn len(&self) -> usize {
        self.0.len() / 12
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// Entry `i`, if present.
    pub fn get(&self, i: usize) -> Option<TargetHeight> {
        let b = self.0.get(i * 12..i * 12 + 12)?;
        Some(TargetHeight {
            tid: u32_at(b, 0),
            max_z: f32_at(b, 4),
            min_z: f32_at(b, 8),
        })
    }
}
