//! The frame layer: header layouts, the zero-copy checked frame view and its TLV walk.
//!
//! A [`Frame`] is built only through [`Frame::new_checked`], which validates the magic word, the
//! length, the header checksum (where the layout has one) and that every TLV fits inside the
//! frame. Once checked, no accessor panics.

use crate::error::FrameError;

/// The 8-byte sync word that starts every frame (u16 words 0x0102, 0x0304, 0x0506, 0x0708, LE).
pub const MAGIC: [u8; 8] = [0x02, 0x01, 0x04, 0x03, 0x06, 0x05, 0x08, 0x07];

/// Size of a TLV header (u32 type, u32 length) \[B\].
pub const TLV_HEADER_LEN: usize = 8;

/// Header layouts found on the data UART of TI's demos and labs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Layout {
    /// Out-of-box demo, SDK 1.x-3.x and the radar toolbox: 40-byte header with subFrameNumber.
    /// TLV length counts the payload only; the packet is padded to a multiple of 32 B.
    Oob40,
    /// Out-of-box demo on xWR14xx with SDK 1.x/2.x: 36-byte header without subFrameNumber.
    Oob36,
    /// Industrial Toolbox 4.x 3D people counting: 48-byte header ending in a checksum; TLV length
    /// includes the TLV header; no padding.
    PeopleCounting48,
    /// Older people-counting labs: 52-byte header (timestamp, packetLength at offset 20) ending in
    /// a checksum; TLV length includes the TLV header; no padding.
    PeopleCounting52,
}

/// Which header layout a framer expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LayoutHint {
    /// Detect per frame: a people-counting header is recognised by its checksum (and a frame that
    /// then does not hold together is read as out-of-box), anything else is read as the
    /// out-of-box header (36 or 40 B by platform and SDK version).
    #[default]
    Auto,
    /// Always this layout.
    Fixed(Layout),
}

mod field {
    pub type Field = core::ops::Range<usize>;
    pub const MAGIC: Field = 0..8;
    pub const VERSION: Field = 8..12;
    pub const TOTAL_LEN: Field = 12..16;
    pub const PLATFORM: Field = 16..20;
    pub const FRAME_NUMBER: Field = 20..24;
    // Out-of-box demo.
    pub const OOB_TIME_CPU_CYCLES: Field = 24..28;
    pub const OOB_NUM_DETECTED_OBJ: Field = 28..32;
    pub const OOB_NUM_TLVS: Field = 32..36;
    pub const OOB_SUBFRAME: Field = 36..40;
    // 48-byte people counting.
    pub const PC48_SUBFRAME: Field = 24..28;
    pub const PC48_CHIRP_MARGIN: Field = 28..32;
    pub const PC48_FRAME_PROC_TIME: Field = 32..36;
    pub const PC48_TRACKING_TIME: Field = 36..40;
    pub const PC48_UART_SENDING_TIME: Field = 40..44;
    pub const PC48_NUM_TLVS: Field = 44..46;
    pub const PC48_CHECKSUM: Field = 46..48;
    // 52-byte people counting.
    pub const PC52_PLATFORM: Field = 12..16;
    pub const PC52_TIMESTAMP: Field = 16..20;
    pub const PC52_TOTAL_LEN: Field = 20..24;
    pub const PC52_FRAME_NUMBER: Field = 24..28;
    pub const PC52_SUBFRAME: Field = 28..32;
    pub const PC52_CHIRP_MARGIN: Field = 32..36;
    pub const PC52_FRAME_MARGIN: Field = 36..40;
    pub const PC52_UART_SENT_TIME: Field = 40..44;
    pub const PC52_TRACK_PROC_TIME: Field = 44..48;
    pub const PC52_NUM_TLVS: Field = 48..50;
    pub const PC52_CHECKSUM: Field = 50..52;
}

impl Layout {
    /// Header length of this layout, magic included \[B\].
    pub const fn header_len(self) -> usize {
        match self {
            Layout::Oob36 => 36,
            Layout::Oob40 => 40,
            Layout::PeopleCounting48 => 48,
            Layout::PeopleCounting52 => 52,
        }
    }

    /// Where totalPacketLen lives in this layout's header.
    const fn total_len_field(self) -> core::ops::Range<usize> {
        match self {
            Layout::PeopleCounting52 => field::PC52_TOTAL_LEN,
            _ => field::TOTAL_LEN,
        }
    }

    /// True when a TLV's length field counts its own 8-byte header (people-counting labs).
    pub const fn tlv_len_includes_header(self) -> bool {
        matches!(self, Layout::PeopleCounting48 | Layout::PeopleCounting52)
    }

    /// True when the layout pads the packet after the last TLV (the out-of-box demo, to 32 B).
    pub const fn is_padded(self) -> bool {
        matches!(self, Layout::Oob36 | Layout::Oob40)
    }

    /// Stable lowercase name (`oob40`, `oob36`, `pc48`, `pc52`).
    pub const fn name(self) -> &'static str {
        match self {
            Layout::Oob40 => "oob40",
            Layout::Oob36 => "oob36",
            Layout::PeopleCounting48 => "pc48",
            Layout::PeopleCounting52 => "pc52",
        }
    }

    /// The out-of-box layout a header with this version and platform uses: 36 B on xWR14xx
    /// before SDK 3, 40 B everywhere else.
    pub const fn oob_for(version: u32, platform: u32) -> Layout {
        if platform & 0xFFFF == 0x1443 && (version >> 24) < 3 {
            Layout::Oob36
        } else {
            Layout::Oob40
        }
    }

    /// The claimed total length of a frame starting at `buf\[0\]` in this layout, once the field is in.
    pub fn claimed_len(self, buf: &[u8]) -> Option<u32> {
        read_u32(buf, self.total_len_field())
    }
}

pub(crate) fn read_u32(buf: &[u8], f: core::ops::Range<usize>) -> Option<u32> {
    let b = buf.get(f)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

pub(crate) fn read_u16(buf: &[u8], f: core::ops::Range<usize>) -> Option<u16> {
    let b = buf.get(f)?;
    Some(u16::from_le_bytes([b[0], b[1]]))
}

fn le_u32(buf: &[u8], f: core::ops::Range<usize>) -> u32 {
    read_u32(buf, f).unwrap_or(0)
}

fn le_u16(buf: &[u8], f: core::ops::Range<usize>) -> u16 {
    read_u16(buf, f).unwrap_or(0)
}

/// One's-complement 16-bit sum of little-endian words, folded (0xFFFF over a valid
/// people-counting header, checksum included).
pub fn ones_complement_fold(bytes: &[u8]) -> u16 {
    fold(word_sum(bytes))
}

/// Plain sum of the little-endian 16-bit words of `bytes` (a last odd byte as its own word);
/// [`fold`] turns it into the one's-complement sum. Folding once at the end gives the same
/// result as folding after every word (end-around carries commute), without a dependency
/// between the additions.
fn word_sum(bytes: &[u8]) -> u64 {
    let mut words = bytes.chunks_exact(2);
    let mut sum: u64 = words
        .by_ref()
        .map(|w| u64::from(u16::from_le_bytes([w[0], w[1]])))
        .sum();
    if let [lo] = *words.remainder() {
        sum += u64::from(lo);
    }
    sum
}

/// One's-complement fold of a word sum to 16 bits.
fn fold(mut sum: u64) -> u16 {
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    sum as u16
}

/// SDK version as sent: major.minor.bugfix.build, one byte each.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Version(pub u32);

impl Version {
    /// Major version (the SDK generation: 1, 2 or 3).
    pub const fn major(self) -> u8 {
        (self.0 >> 24) as u8
    }
    /// Minor version.
    pub const fn minor(self) -> u8 {
        (self.0 >> 16) as u8
    }
    /// Bug-fix version.
    pub const fn bugfix(self) -> u8 {
        (self.0 >> 8) as u8
    }
    /// Build number.
    pub const fn build(self) -> u8 {
        self.0 as u8
    }
}

impl core::fmt::Display for Version {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{}.{}.{}.{}",
            self.major(),
            self.minor(),
            self.bugfix(),
            self.build()
        )
    }
}

/// Processing-time fields of the people-counting headers (units as the lab defines them,
/// CPU cycles or microseconds depending on the lab version).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LabTiming {
    /// chirpProcessingMargin / chirpMargin.
    pub chirp_margin: u32,
    /// frameProcessingTime (48-byte header) or frameMargin (52-byte header).
    pub frame_processing: u32,
    /// trackingTime / trackProcessTime.
    pub tracking: u32,
    /// uartSendingTime / uartSentTime.
    pub uart_sending: u32,
}

/// The header fields of a checked frame, decoded into one value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Header layout.
    pub layout: Layout,
    /// SDK / lab version.
    pub version: Version,
    /// Whole packet length, header and padding included \[B\].
    pub total_len: u32,
    /// Platform: 0xA1843, 0xA6843, 0xA1642, 0xA1443 (0xA in the top nibble, part number below).
    pub platform: u32,
    /// Frame counter (the sensor's; starts at 1 after sensorStart).
    pub frame_number: u32,
    /// Sub-frame index (advanced frame config); absent in the 36-byte header.
    pub subframe: Option<u32>,
    /// CPU cycle counter at frame start (out-of-box demo) or the 52-byte header's timestamp; see
    /// [`crate::clock`] for the rate. Absent in the 48-byte people-counting header.
    pub time_cpu_cycles: Option<u32>,
    /// numDetectedObj (out-of-box demo only).
    pub num_detected_obj: Option<u32>,
    /// Number of TLVs that follow the header.
    pub num_tlvs: u32,
    /// Header checksum as sent (people-counting layouts).
    pub checksum: Option<u16>,
    /// Processing-time fields (people-counting layouts).
    pub lab_timing: Option<LabTiming>,
}

impl Header {
    /// Decodes the header fields of `buf` (which must hold at least `layout.header_len()` bytes;
    /// missing bytes read as 0, so call this on checked data).
    fn read(buf: &[u8], layout: Layout) -> Header {
        use field::*;
        match layout {
            Layout::Oob40 | Layout::Oob36 => Header {
                layout,
                version: Version(le_u32(buf, VERSION)),
                total_len: le_u32(buf, TOTAL_LEN),
                platform: le_u32(buf, PLATFORM),
                frame_number: le_u32(buf, FRAME_NUMBER),
                subframe: (layout == Layout::Oob40).then(|| le_u32(buf, OOB_SUBFRAME)),
                time_cpu_cycles: Some(le_u32(buf, OOB_TIME_CPU_CYCLES)),
                num_detected_obj: Some(le_u32(buf, OOB_NUM_DETECTED_OBJ)),
                num_tlvs: le_u32(buf, OOB_NUM_TLVS),
                checksum: None,
                lab_timing: None,
            },
            Layout::PeopleCounting48 => Header {
                layout,
                version: Version(le_u32(buf, VERSION)),
                total_len: le_u32(buf, TOTAL_LEN),
                platform: le_u32(buf, PLATFORM),
                frame_number: le_u32(buf, FRAME_NUMBER),
                subframe: Some(le_u32(buf, PC48_SUBFRAME)),
                time_cpu_cycles: None,
                num_detected_obj: None,
                num_tlvs: u32::from(le_u16(buf, PC48_NUM_TLVS)),
                checksum: Some(le_u16(buf, PC48_CHECKSUM)),
                lab_timing: Some(LabTiming {
                    chirp_margin: le_u32(buf, PC48_CHIRP_MARGIN),
                    frame_processing: le_u32(buf, PC48_FRAME_PROC_TIME),
                    tracking: le_u32(buf, PC48_TRACKING_TIME),
                    uart_sending: le_u32(buf, PC48_UART_SENDING_TIME),
                }),
            },
            Layout::PeopleCounting52 => Header {
                layout,
                version: Version(le_u32(buf, VERSION)),
                total_len: le_u32(buf, PC52_TOTAL_LEN),
                platform: le_u32(buf, PC52_PLATFORM),
                frame_number: le_u32(buf, PC52_FRAME_NUMBER),
                subframe: Some(le_u32(buf, PC52_SUBFRAME)),
                time_cpu_cycles: Some(le_u32(buf, PC52_TIMESTAMP)),
                num_detected_obj: None,
                num_tlvs: u32::from(le_u16(buf, PC52_NUM_TLVS)),
                checksum: Some(le_u16(buf, PC52_CHECKSUM)),
                lab_timing: Some(LabTiming {
                    chirp_margin: le_u32(buf, PC52_CHIRP_MARGIN),
                    frame_processing: le_u32(buf, PC52_FRAME_MARGIN),
                    tracking: le_u32(buf, PC52_TRACK_PROC_TIME),
                    uart_sending: le_u32(buf, PC52_UART_SENT_TIME),
                }),
            },
        }
    }
}

/// Outcome of looking at the start of a candidate frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Detect {
    /// At least this many bytes are needed before the layout can be decided.
    NeedMore(usize),
    /// The layout, and the claimed total length.
    Found(Layout, u32),
    /// The header is already known bad.
    Bad(FrameError),
}

/// Decides the layout of a candidate that starts with the magic word.
pub(crate) fn detect(buf: &[u8], hint: LayoutHint) -> Detect {
    let layout = match hint {
        LayoutHint::Fixed(l) => {
            if buf.len() < l.header_len() {
                return Detect::NeedMore(l.header_len());
            }
            l
        }
        LayoutHint::Auto => {
            // The 52-byte header's sum continues the 48-byte one.
            let s48 = buf.get(..48).map(word_sum);
            let s52 = s48.zip(buf.get(48..52)).map(|(s, rest)| s + word_sum(rest));
            if s48.is_some_and(|s| fold(s) == 0xFFFF) {
                Layout::PeopleCounting48
            } else if s52.is_some_and(|s| fold(s) == 0xFFFF) {
                Layout::PeopleCounting52
            } else if buf.len() >= 52 {
                oob_layout(buf)
            } else {
                // Fewer than 52 bytes: only a short out-of-box frame can already be complete.
                match read_u32(buf, field::TOTAL_LEN) {
                    Some(len) if (36..52).contains(&len) && buf.len() >= len as usize => {
                        let l = oob_layout(buf);
                        if buf.len() < l.header_len() {
                            return Detect::NeedMore(l.header_len());
                        }
                        l
                    }
                    _ => return Detect::NeedMore(52),
                }
            }
        }
    };
    let len = layout.claimed_len(buf).unwrap_or(0);
    if (len as usize) < layout.header_len() {
        return Detect::Bad(FrameError::LengthTooSmall {
            len,
            min: layout.header_len() as u32,
        });
    }
    if let Some(folded) = header_checksum_error(buf, layout) {
        return Detect::Bad(FrameError::BadChecksum { folded });
    }
    Detect::Found(layout, len)
}

fn oob_layout(buf: &[u8]) -> Layout {
    Layout::oob_for(le_u32(buf, field::VERSION), le_u32(buf, field::PLATFORM))
}

/// The folded sum when `layout` has a header checksum and it is wrong.
fn header_checksum_error(buf: &[u8], layout: Layout) -> Option<u16> {
    if !layout.tlv_len_includes_header() {
        return None;
    }
    let folded = ones_complement_fold(buf.get(..layout.header_len())?);
    (folded != 0xFFFF).then_some(folded)
}

/// A checked, zero-copy view of one whole frame.
///
/// ```
/// use radar_driver::{Frame, Layout, encode::FrameBuilder};
/// let mut buf = [0u8; 128];
/// let n = FrameBuilder::oob(0x0303_0002, 0xA6843, 7).points(&[[0.5, 1.0, 0.0, -0.25]]).write(&mut buf).unwrap();
/// let frame = Frame::new_checked(&buf[..n], Layout::Oob40).unwrap();
/// assert_eq!(frame.header().frame_number, 7);
/// assert_eq!(frame.tlvs().count(), 1);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    bytes: &'a [u8],
    header: Header,
}

impl<'a> Frame<'a> {
    /// Validates `buf` as a frame of `layout`: magic, length, header checksum, and a TLV walk that
    /// honours numTLVs and stays inside totalPacketLen. `buf` may be longer than the frame; the
    /// view covers exactly totalPacketLen bytes.
    pub fn new_checked(buf: &'a [u8], layout: Layout) -> Result<Self, FrameError> {
        let hlen = layout.header_len();
        if buf.len() < hlen {
            return Err(FrameError::BufferTooShort {
                need: hlen,
                have: buf.len(),
            });
        }
        if buf[field::MAGIC] != MAGIC {
            return Err(FrameError::BadMagic);
        }
        let header = Header::read(buf, layout);
        let total = header.total_len as usize;
        if total < hlen {
            return Err(FrameError::LengthTooSmall {
                len: header.total_len,
                min: hlen as u32,
            });
        }
        if buf.len() < total {
            return Err(FrameError::BufferTooShort {
                need: total,
                have: buf.len(),
            });
        }
        if let Some(folded) = header_checksum_error(buf, layout) {
            return Err(FrameError::BadChecksum { folded });
        }
        let bytes = &buf[..total];
        let end = walk_tlvs(bytes, layout, header.num_tlvs)?;
        if !layout.is_padded() && end != total {
            return Err(FrameError::TrailingBytes {
                len: (total - end) as u32,
            });
        }
        Ok(Frame { bytes, header })
    }

    /// A view of bytes that [`Frame::new_checked`] has already accepted with this layout.
    pub(crate) fn trusted(bytes: &'a [u8], layout: Layout) -> Self {
        Frame {
            bytes,
            header: Header::read(bytes, layout),
        }
    }

    /// The decoded header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The header layout.
    pub fn layout(&self) -> Layout {
        self.header.layout
    }

    /// The whole frame as sent (header, TLVs, padding) \[B\].
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Padding after the last TLV \[B\] (content undefined, never validated).
    pub fn padding_len(&self) -> usize {
        let end = walk_tlvs(self.bytes, self.header.layout, self.header.num_tlvs)
            .unwrap_or(self.bytes.len());
        self.bytes.len() - end
    }

    /// The TLVs, in order. Each carries its type and raw payload; see [`crate::tlv`] to decode.
    pub fn tlvs(&self) -> TlvIter<'a> {
        TlvIter {
            bytes: self.bytes,
            offset: self.header.layout.header_len(),
            remaining: self.header.num_tlvs,
            index: 0,
            includes_header: self.header.layout.tlv_len_includes_header(),
        }
    }
}

/// Walks `num_tlvs` TLVs from the end of the header; returns the offset after the last one.
fn walk_tlvs(bytes: &[u8], layout: Layout, num_tlvs: u32) -> Result<usize, FrameError> {
    let total = bytes.len();
    let mut off = layout.header_len();
    for index in 0..num_tlvs {
        let room = total - off;
        if room < TLV_HEADER_LEN {
            return Err(FrameError::TlvHeaderOverrun {
                index,
                offset: off as u32,
                room: room as u32,
            });
        }
        let ty = le_u32(bytes, off..off + 4);
        let len = le_u32(bytes, off + 4..off + 8);
        let room_after = (room - TLV_HEADER_LEN) as u32;
        let payload = if layout.tlv_len_includes_header() {
            len.checked_sub(TLV_HEADER_LEN as u32)
        } else {
            Some(len)
        };
        match payload {
            Some(p) if p <= room_after => off += TLV_HEADER_LEN + p as usize,
            _ => {
                return Err(FrameError::BadTlvLength {
                    index,
                    ty,
                    len,
                    room: room_after,
                })
            }
        }
    }
    Ok(off)
}

/// One TLV of a checked frame: its type and raw payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawTlv<'a> {
    /// Position within the frame (0-based).
    pub index: u32,
    /// TLV type as sent.
    pub ty: u32,
    /// Payload (without the 8-byte TLV header).
    pub payload: &'a [u8],
}

/// Iterator over the TLVs of a checked frame (see [`Frame::tlvs`]).
#[derive(Debug, Clone)]
pub struct TlvIter<'a> {
    bytes: &'a [u8],
    offset: usize,
    remaining: u32,
    index: u32,
    includes_header: bool,
}

impl<'a> Iterator for TlvIter<'a> {
    type Item = RawTlv<'a>;
    fn next(&mut self) -> Option<RawTlv<'a>> {
        if self.remaining == 0 {
            return None;
        }
        let off = self.offset;
        let ty = read_u32(self.bytes, off..off + 4)?;
        let len = read_u32(self.bytes, off + 4..off + 8)? as usize;
        let plen = if self.includes_header {
            len.checked_sub(TLV_HEADER_LEN)?
        } else {
            len
        };
        let payload = self
            .bytes
            .get(off + TLV_HEADER_LEN..off + TLV_HEADER_LEN + plen)?;
        self.offset = off + TLV_HEADER_LEN + plen;
        self.remaining -= 1;
        let index = self.index;
        self.index += 1;
        Some(RawTlv { index, ty, payload })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (0, Some(self.remaining as usize))
    }
}

/// Position of the first full magic word in `hay`.
pub fn find_magic(hay: &[u8]) -> Option<usize> {
    // memchr for the first byte, then the whole word: `memmem::find` builds a searcher per call,
    // which costs more than the search on the short windows the framer looks at.
    let mut start = 0;
    while let Some(p) = memchr::memchr(MAGIC[0], hay.get(start..)?) {
        let i = start + p;
        match hay.get(i..i + MAGIC.len()) {
            Some(w) if w == MAGIC => return Some(i),
            Some(_) => start = i + 1,
            None => return None,
        }
    }
    None
}

/// Position of the first place where a magic word starts, either whole or as a prefix that runs
/// into the end of `hay` (so it may complete with the next chunk).
pub(crate) fn find_magic_or_prefix(
    hay: &[u8],
    find: impl FnOnce(&[u8]) -> Option<usize>,
) -> Option<usize> {
    if let Some(i) = find(hay) {
        return Some(i);
    }
    // No whole magic: only a prefix in the last 7 bytes can still become one.
    let tail_start = hay.len().saturating_sub(MAGIC.len() - 1);
    let mut start = tail_start;
    while let Some(p) = memchr::memchr(MAGIC[0], &hay[start..]) {
        let i = start + p;
        if hay[i..] == MAGIC[..hay.len() - i] {
            return Some(i);
        }
        start = i + 1;
    }
    None
}
