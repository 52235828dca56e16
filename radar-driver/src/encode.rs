//! Frame encoder: builds byte-exact frames of every layout, for tests, fuzz seeds and the
//! sensor simulator. No allocation: TLV payloads are serialised straight into the output buffer.

use crate::frame::{ones_complement_fold, Layout, MAGIC};
use crate::tlv::{types, CompressedUnits, Target};
use core::fmt;

/// Maximum TLVs one builder holds.
pub const MAX_TLVS: usize = 16;

/// The output buffer is too small.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BufferTooSmall {
    /// Bytes the frame needs \[B\].
    pub need: usize,
    /// Bytes the buffer has \[B\].
    pub have: usize,
}

impl fmt::Display for BufferTooSmall {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "frame needs {} B, buffer has {} B", self.need, self.have)
    }
}

impl core::error::Error for BufferTooSmall {}

/// A raw SDK 1/2 point: {u16 rangeIdx, i16 dopplerIdx, u16 peakVal, i16 x, y, z} (x, y, z in Q format).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct QPointRaw {
    /// Range bin.
    pub range_idx: u16,
    /// Doppler bin (signed).
    pub doppler_idx: i16,
    /// Peak value.
    pub peak: u16,
    /// x, y, z in Q format.
    pub xyz: [i16; 3],
}

/// A raw compressed point: {i8 elevation, i8 azimuth, i16 doppler, u16 range, u16 snr}.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CompressedRaw {
    /// Elevation in units.
    pub elevation: i8,
    /// Azimuth in units.
    pub azimuth: i8,
    /// Doppler in units.
    pub doppler: i16,
    /// Range in units.
    pub range: u16,
    /// SNR in units.
    pub snr: u16,
}

/// One TLV to emit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TlvOut<'a> {
    /// Any type with a raw payload.
    Raw(u32, &'a [u8]),
    /// Type 1, SDK 3: \[x, y, z, velocity\].
    Points(&'a [[f32; 4]]),
    /// Type 1, SDK 1/2: Q format and points.
    PointsQ(u16, &'a [QPointRaw]),
    /// Type 7: (snr, noise) in 0.1 dB.
    SideInfo(&'a [(i16, i16)]),
    /// A u16 array (range profile 2, noise profile 3, range-Doppler 5) of the given type.
    U16s(u32, &'a [u16]),
    /// Type 6 stats: six u32.
    Stats([u32; 6]),
    /// Type 9 temperature: valid flag, time \[ms\], 10 sensors \[deg C\].
    Temperature(i32, u32, [i16; 10]),
    /// Compressed points of the given type (6 in the people-counting labs, 1020 in the toolbox).
    Compressed(u32, CompressedUnits, &'a [CompressedRaw]),
    /// Targets of the given type (7 or 1010).
    Targets(u32, &'a [Target]),
    /// Target index of the given type (8 or 1011).
    TargetIndex(u32, &'a [u8]),
    /// Type 1012 heights: (tid, maxZ, minZ).
    Heights(&'a [(u32, f32, f32)]),
    /// Presence of the given type (11 or 1021).
    Presence(u32, u32),
}

impl TlvOut<'_> {
    fn ty(&self) -> u32 {
        match *self {
            TlvOut::Raw(t, _) | TlvOut::U16s(t, _) | TlvOut::Compressed(t, _, _) => t,
            TlvOut::Targets(t, _) | TlvOut::TargetIndex(t, _) | TlvOut::Presence(t, _) => t,
            TlvOut::Points(_) | TlvOut::PointsQ(..) => types::POINTS,
            TlvOut::SideInfo(_) => types::SIDE_INFO,
            TlvOut::Stats(_) => types::STATS,
            TlvOut::Temperature(..) => types::TEMPERATURE,
            TlvOut::Heights(_) => types::TARGET_HEIGHT,
        }
    }

    fn payload_len(&self) -> usize {
        match *self {
            TlvOut::Raw(_, p) | TlvOut::TargetIndex(_, p) => p.len(),
            TlvOut::Points(p) => p.len() * 16,
            TlvOut::PointsQ(_, p) => 4 + p.len() * 12,
            TlvOut::SideInfo(p) => p.len() * 4,
            TlvOut::U16s(_, p) => p.len() * 2,
            TlvOut::Stats(_) => 24,
            TlvOut::Temperature(..) => 28,
            TlvOut::Compressed(_, _, p) => 20 + p.len() * 8,
            TlvOut::Targets(_, p) => p.len() * Target::SIZE,
            TlvOut::Heights(p) => p.len() * 12,
            TlvOut::Presence(..) => 4,
        }
    }

    fn point_count(&self) -> Option<u32> {
        match *self {
            TlvOut::Points(p) => Some(p.len() as u32),
            TlvOut::PointsQ(_, p) => Some(p.len() as u32),
            _ => None,
        }
    }

    fn write(&self, out: &mut Writer<'_>) {
        match *self {
            TlvOut::Raw(_, p) | TlvOut::TargetIndex(_, p) => out.bytes(p),
            TlvOut::Points(p) => p.iter().flatten().for_each(|v| out.f32(*v)),
            TlvOut::PointsQ(q, p) => {
                out.u16(p.len() as u16);
                out.u16(q);
                for pt in p {
                    out.u16(pt.range_idx);
                    out.u16(pt.doppler_idx as u16);
                    out.u16(pt.peak);
                    pt.xyz.iter().for_each(|v| out.u16(*v as u16));
                }
            }
            TlvOut::SideInfo(p) => p.iter().for_each(|(s, n)| {
                out.u16(*s as u16);
                out.u16(*n as u16);
            }),
            TlvOut::U16s(_, p) => p.iter().for_each(|v| out.u16(*v)),
            TlvOut::Stats(s) => s.iter().for_each(|v| out.u32(*v)),
            TlvOut::Temperature(valid, time, s) => {
                out.u32(valid as u32);
                out.u32(time);
                s.iter().for_each(|v| out.u16(*v as u16));
            }
            TlvOut::Compressed(_, u, p) => {
                [u.elevation, u.azimuth, u.doppler, u.range, u.snr]
                    .iter()
                    .for_each(|v| out.f32(*v));
                for c in p {
                    out.bytes(&[c.elevation as u8, c.azimuth as u8]);
                    out.u16(c.doppler as u16);
                    out.u16(c.range);
                    out.u16(c.snr);
                }
            }
            TlvOut::Targets(_, p) => {
                for t in p {
                    out.u32(t.tid);
                    t.position
                        .iter()
                        .chain(&t.velocity)
                        .chain(&t.acceleration)
                        .for_each(|v| out.f32(*v));
                    t.error_covariance.iter().for_each(|v| out.f32(*v));
                    out.f32(t.gain);
                    out.f32(t.confidence);
                }
            }
            TlvOut::Heights(p) => p.iter().for_each(|(tid, hi, lo)| {
                out.u32(*tid);
                out.f32(*hi);
                out.f32(*lo);
            }),
            TlvOut::Presence(_, v) => out.u32(v),
        }
    }
}

struct Writer<'b> {
    buf: &'b mut [u8],
    pos: usize,
}

impl Writer<'_> {
    fn bytes(&mut self, b: &[u8]) {
        if let Some(dst) = self.buf.get_mut(self.pos..self.pos + b.len()) {
            dst.copy_from_slice(b);
        }
        self.pos += b.len();
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
}

/// Builds one frame.
#[derive(Debug, Clone)]
pub struct FrameBuilder<'a> {
    /// Header layout.
    pub layout: Layout,
    /// Version word.
    pub version: u32,
    /// Platform word.
    pub platform: u32,
    /// Frame number.
    pub frame_number: u32,
    /// timeCpuCycles (OOB) or timestamp (52-byte header).
    pub time_cpu_cycles: u32,
    /// Sub-frame number.
    pub subframe: u32,
    /// numDetectedObj; `None` = the point count of the points TLV.
    pub num_detected_obj: Option<u32>,
    /// People-counting processing-time fields: chirp margin, frame processing, tracking, UART
    /// sending (written in each header's own field order).
    pub lab_timing: [u32; 4],
    /// Byte used for the padding of out-of-box frames (SDK 2 sends 0x0F; SDK 3 garbage).
    pub pad_byte: u8,
    /// Extra bytes of totalPacketLen beyond the content (to build truncated or padded oddities).
    pub extra_len: u32,
    tlvs: heapless::Vec<TlvOut<'a>, MAX_TLVS>,
}

impl<'a> FrameBuilder<'a> {
    /// An out-of-box frame; the layout (36 or 40 B) follows version and platform.
    pub fn oob(version: u32, platform: u32, frame_number: u32) -> Self {
        Self::new(
            Layout::oob_for(version, platform),
            version,
            platform,
            frame_number,
        )
    }

    /// A frame of any layout.
    pub fn new(layout: Layout, version: u32, platform: u32, frame_number: u32) -> Self {
        FrameBuilder {
            layout,
            version,
            platform,
            frame_number,
            time_cpu_cycles: 0,
            subframe: 0,
            num_detected_obj: None,
            lab_timing: [0; 4],
            pad_byte: 0x0F,
            extra_len: 0,
            tlvs: heapless::Vec::new(),
        }
    }

    /// Adds a TLV (ignored beyond [`MAX_TLVS`]).
    pub fn tlv(mut self, t: TlvOut<'a>) -> Self {
        let _ = self.tlvs.push(t);
        self
    }

    /// Adds SDK 3 points (\[x, y, z, velocity\] in m and m/s).
    pub fn points(self, p: &'a [[f32; 4]]) -> Self {
        self.tlv(TlvOut::Points(p))
    }

    /// Sets timeCpuCycles.
    pub fn cycles(mut self, c: u32) -> Self {
        self.time_cpu_cycles = c;
        self
    }

    /// Total length this frame will have \[B\].
    pub fn len(&self) -> usize {
        let body: usize = self.tlvs.iter().map(|t| 8 + t.payload_len()).sum();
        let mut n = self.layout.header_len() + body;
        if self.layout.is_padded() {
            n = n.div_ceil(32) * 32;
        }
        n + self.extra_len as usize
    }

    /// True when the frame would be a bare header (never: a header is at least 36 B).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Writes the frame into `buf`; returns its length.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, BufferTooSmall> {
        let total = self.len();
        if buf.len() < total {
            return Err(BufferTooSmall {
                need: total,
                have: buf.len(),
            });
        }
        let mut w = Writer { buf, pos: 0 };
        let num_tlvs = self.tlvs.len() as u32;
        let num_obj = self
            .num_detected_obj
            .or_else(|| self.tlvs.iter().find_map(TlvOut::point_count))
            .unwrap_or(0);
        w.bytes(&MAGIC);
        w.u32(self.version);
        match self.layout {
            Layout::Oob40 | Layout::Oob36 => {
                for v in [
                    total as u32,
                    self.platform,
                    self.frame_number,
                    self.time_cpu_cycles,
                    num_obj,
                    num_tlvs,
                ] {
                    w.u32(v);
                }
                if self.layout == Layout::Oob40 {
                    w.u32(self.subframe);
                }
            }
            Layout::PeopleCounting48 => {
                for v in [
                    total as u32,
                    self.platform,
                    self.frame_number,
                    self.subframe,
                ] {
                    w.u32(v);
                }
                self.lab_timing.iter().for_each(|v| w.u32(*v));
                w.u16(num_tlvs as u16);
                w.u16(0);
            }
            Layout::PeopleCounting52 => {
                for v in [
                    self.platform,
                    self.time_cpu_cycles,
                    total as u32,
                    self.frame_number,
                    self.subframe,
                ] {
                    w.u32(v);
                }
                let [chirp, frame, tracking, uart] = self.lab_timing;
                [chirp, frame, uart, tracking]
                    .iter()
                    .for_each(|v| w.u32(*v));
                w.u16(num_tlvs as u16);
                w.u16(0);
            }
        }
        let hlen = self.layout.header_len();
        if self.layout.tlv_len_includes_header() {
            let folded = ones_complement_fold(&w.buf[..hlen]);
            let ck = !folded;
            w.buf[hlen - 2..hlen].copy_from_slice(&ck.to_le_bytes());
        }
        for t in &self.tlvs {
            w.u32(t.ty());
            let len = t.payload_len()
                + if self.layout.tlv_len_includes_header() {
                    8
                } else {
                    0
                };
            w.u32(len as u32);
            t.write(&mut w);
        }
        while w.pos < total {
            w.bytes(&[self.pad_byte]);
        }
        Ok(total)
    }

    /// The frame as a new vector.
    #[cfg(feature = "alloc")]
    pub fn to_vec(&self) -> alloc::vec::Vec<u8> {
        let mut v = alloc::vec![0u8; self.len()];
        let n = self.write(&mut v).unwrap_or(0);
        v.truncate(n);
        v
    }
}
