//! C ABI for the milliEgo pose link (`pose-link`, spec: `docs/pose-link.md`), for headset,
//! game-engine and host code in C, C++ or C#.
//!
//! * [`pose_link_decode`] checks one UDP datagram (or one COBS-decoded serial frame) and fills a
//!   [`PoseLinkPose`]; [`pose_link_encode`] and [`pose_link_encode_serial`] write one.
//! * [`PoseLinkDeframer`] is the serial deframer in caller-allocated storage
//!   ([`POSE_LINK_DEFRAMER_SIZE`] bytes, aligned to [`POSE_LINK_DEFRAMER_ALIGN`]), set up by
//!   [`pose_link_deframer_init`]; bytes go in with [`pose_link_deframer_poll`] (one result per
//!   call) or [`pose_link_deframer_push`] (callbacks), and [`pose_link_deframer_counters`] reads
//!   its counters: every dropped byte and frame is counted.
//! * Every function returns a [`PoseLinkStatus`]; null pointers, short buffers and bad input give
//!   a status, never undefined behaviour or a panic. Nothing allocates.
//!
//! The header `include/pose_link.h` is generated from this file by cbindgen (`gen-header`).
//!
//! ```
//! use pose_link_c::*;
//! let pose = PoseLinkPose { seq: 7, position: [1.0, 2.0, 0.5], ..PoseLinkPose::default() };
//! let mut buf = [0u8; POSE_LINK_MESSAGE_LEN];
//! let mut n = 0usize;
//! // SAFETY: every pointer is valid for the length given.
//! unsafe {
//!     assert_eq!(pose_link_encode(&pose, buf.as_mut_ptr(), buf.len(), &mut n), PoseLinkStatus::Ok);
//!     let mut back = PoseLinkPose::default();
//!     assert_eq!(pose_link_decode(buf.as_ptr(), n, &mut back), PoseLinkStatus::Ok);
//!     assert_eq!(back, pose);
//! }
//! ```
#![no_std]
// The workspace denies `unsafe_code`. A C ABI cannot be written without it: C hands over raw
// pointers, and turning them into slices and references is unsafe by definition. Every unsafe
// block below states the contract that makes it sound, and unsafe operations inside unsafe
// functions still need their own block.
#![allow(unsafe_code)]
#![deny(unsafe_op_in_unsafe_fn)]
#![warn(missing_docs)]

// The ABI itself uses only `core` (the same code would serve a firmware build). `std` is linked
// for the host static and dynamic libraries only: it gives them the panic runtime a `staticlib`
// or `cdylib` must have. Nothing here is meant to panic, and a panic would abort at the
// `extern "C"` boundary (Rust 1.81+), never unwind into C.
extern crate std;

use core::ffi::{c_char, c_void};
use core::mem::{align_of, size_of};
use core::ptr;
use pose_link::{
    encode_serial, DecodeError, Deframer, Estimator, Event, FrameError, Health, PoseMessage,
};

/// Bytes of a version-1 pose message (one UDP datagram).
pub const POSE_LINK_MESSAGE_LEN: usize = 104;
/// Wire version this library writes and reads.
pub const POSE_LINK_VERSION: u8 = 1;
/// Largest serial frame of a version-1 message: COBS-encoded message plus the 0x00 delimiter.
pub const POSE_LINK_SERIAL_FRAME_MAX: usize = 106;
/// Bytes of a `PoseLinkDeframer`.
pub const POSE_LINK_DEFRAMER_SIZE: usize = 256;
/// Alignment of a `PoseLinkDeframer` (bytes).
pub const POSE_LINK_DEFRAMER_ALIGN: usize = 8;

/// Health flag: no radar frame for longer than a few frame periods.
pub const POSE_LINK_HEALTH_RADAR_MISSING: u16 = 1 << 0;
/// Health flag: no IMU sample for longer than a few sample periods.
pub const POSE_LINK_HEALTH_IMU_MISSING: u16 = 1 << 1;
/// Health flag: a fallback estimator produced the pose (the learned model was unavailable).
pub const POSE_LINK_HEALTH_MODEL_FALLBACK: u16 = 1 << 2;
/// Health flag: sensor and host clocks are not synchronised yet.
pub const POSE_LINK_HEALTH_CLOCK_UNSYNCED: u16 = 1 << 3;
/// Health flag: frames or samples were dropped since the previous message.
pub const POSE_LINK_HEALTH_FRAMES_DROPPED: u16 = 1 << 4;
/// Health flag: IMU-propagated between radar-rate poses.
pub const POSE_LINK_HEALTH_PREDICTED: u16 = 1 << 5;
/// Health flag: the trajectory origin was reset.
pub const POSE_LINK_HEALTH_RESET: u16 = 1 << 6;
/// Health flag: the estimator changed at this pose (same world frame, no new origin).
pub const POSE_LINK_HEALTH_HANDOVER: u16 = 1 << 7;
/// Health flag: the pose rests on the IMU alone (no radar velocity, rest or learned measurement
/// applied for over a second); its position error grows until the flag clears.
pub const POSE_LINK_HEALTH_DEAD_RECKONING: u16 = 1 << 8;

/// Estimator code: the learned milliEgo model.
pub const POSE_LINK_ESTIMATOR_MODEL: u8 = 0;
/// Estimator code: Doppler radar-inertial odometry.
pub const POSE_LINK_ESTIMATOR_DOPPLER: u8 = 1;
/// Estimator code: IMU dead reckoning.
pub const POSE_LINK_ESTIMATOR_IMU: u8 = 2;
/// Estimator code: Doppler radar-inertial odometry with the learned model's motion as a
/// measurement.
pub const POSE_LINK_ESTIMATOR_FUSED: u8 = 3;

// The literals above are what cbindgen can put in the header; they must equal the Rust crate's.
const _: () = {
    assert!(POSE_LINK_MESSAGE_LEN == pose_link::MESSAGE_LEN);
    assert!(POSE_LINK_VERSION == pose_link::VERSION);
    assert!(POSE_LINK_SERIAL_FRAME_MAX == pose_link::SERIAL_FRAME_MAX);
    assert!(POSE_LINK_HEALTH_RADAR_MISSING == Health::RADAR_MISSING.0);
    assert!(POSE_LINK_HEALTH_IMU_MISSING == Health::IMU_MISSING.0);
    assert!(POSE_LINK_HEALTH_MODEL_FALLBACK == Health::MODEL_FALLBACK.0);
    assert!(POSE_LINK_HEALTH_CLOCK_UNSYNCED == Health::CLOCK_UNSYNCED.0);
    assert!(POSE_LINK_HEALTH_FRAMES_DROPPED == Health::FRAMES_DROPPED.0);
    assert!(POSE_LINK_HEALTH_PREDICTED == Health::PREDICTED.0);
    assert!(POSE_LINK_HEALTH_RESET == Health::RESET.0);
    assert!(POSE_LINK_HEALTH_HANDOVER == Health::HANDOVER.0);
    assert!(POSE_LINK_HEALTH_DEAD_RECKONING == Health::DEAD_RECKONING.0);
};

/// What a call did. Zero is success; the names of the message errors are those of
/// `pose_link::DecodeError` (see `pose_link_status_name`).
#[repr(i32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PoseLinkStatus {
    /// Success (a pose was decoded / encoded, the deframer initialised or fed).
    Ok = 0,
    /// A required pointer argument was null.
    NullPointer = 1,
    /// An argument is unusable: a length above `PTRDIFF_MAX`, a misaligned deframer.
    InvalidArgument = 2,
    /// The deframer was not set up with `pose_link_deframer_init`.
    NotInitialised = 3,
    /// Fewer bytes than a header, or than the header's body length says.
    TooShort = 4,
    /// More bytes than the header's body length says (one message per datagram or frame).
    TooLong = 5,
    /// Not a pose message (type byte).
    UnknownType = 6,
    /// A major version this decoder does not speak.
    UnsupportedVersion = 7,
    /// The body is shorter than version 1's.
    BodyTooShort = 8,
    /// The CRC-32C does not match.
    BadCrc = 9,
    /// The output buffer is too small.
    BufferTooSmall = 10,
    /// Serial: a frame did not COBS-decode (dropped and counted).
    BadCobs = 11,
    /// Serial: a frame grew beyond the deframer's buffer before its delimiter (dropped, counted).
    Overflow = 12,
    /// Serial: the input is used up without completing a frame.
    NeedMore = 13,
}

/// Every status, in code order.
const STATUSES: [PoseLinkStatus; 14] = [
    PoseLinkStatus::Ok,
    PoseLinkStatus::NullPointer,
    PoseLinkStatus::InvalidArgument,
    PoseLinkStatus::NotInitialised,
    PoseLinkStatus::TooShort,
    PoseLinkStatus::TooLong,
    PoseLinkStatus::UnknownType,
    PoseLinkStatus::UnsupportedVersion,
    PoseLinkStatus::BodyTooShort,
    PoseLinkStatus::BadCrc,
    PoseLinkStatus::BufferTooSmall,
    PoseLinkStatus::BadCobs,
    PoseLinkStatus::Overflow,
    PoseLinkStatus::NeedMore,
];

impl PoseLinkStatus {
    /// Stable snake_case name; the message errors' equal `DecodeError::kind_name`, the serial
    /// ones `FrameError::kind_name`.
    pub const fn name(self) -> &'static core::ffi::CStr {
        match self {
            Self::Ok => c"ok",
            Self::NullPointer => c"null_pointer",
            Self::InvalidArgument => c"invalid_argument",
            Self::NotInitialised => c"not_initialised",
            Self::TooShort => c"too_short",
            Self::TooLong => c"too_long",
            Self::UnknownType => c"unknown_type",
            Self::UnsupportedVersion => c"unsupported_version",
            Self::BodyTooShort => c"body_too_short",
            Self::BadCrc => c"bad_crc",
            Self::BufferTooSmall => c"buffer_too_small",
            Self::BadCobs => c"bad_cobs",
            Self::Overflow => c"overflow",
            Self::NeedMore => c"need_more",
        }
    }
}

impl From<DecodeError> for PoseLinkStatus {
    fn from(e: DecodeError) -> Self {
        match e {
            DecodeError::TooShort { .. } => Self::TooShort,
            DecodeError::TooLong { .. } => Self::TooLong,
            DecodeError::UnknownType { .. } => Self::UnknownType,
            DecodeError::UnsupportedVersion { .. } => Self::UnsupportedVersion,
            DecodeError::BodyTooShort { .. } => Self::BodyTooShort,
            DecodeError::BadCrc { .. } => Self::BadCrc,
            DecodeError::BufferTooSmall { .. } => Self::BufferTooSmall,
        }
    }
}

impl From<FrameError> for PoseLinkStatus {
    fn from(e: FrameError) -> Self {
        match e {
            FrameError::Cobs(_) => Self::BadCobs,
            FrameError::Message(e) => e.into(),
            FrameError::Overflow { .. } => Self::Overflow,
        }
    }
}

/// One pose, every field of the version-1 message (96 bytes, no padding).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseLinkPose {
    /// Sequence number, +1 per message (wraps at 2^32); a gap means lost messages.
    pub seq: u32,
    /// Health flags (`POSE_LINK_HEALTH_*`; ignore unknown bits).
    pub health: u16,
    /// Estimator code (`POSE_LINK_ESTIMATOR_*`; others may come from newer senders).
    pub estimator: u8,
    /// Zero (the wire's reserved byte; ignored by the encoder).
    pub reserved: u8,
    /// When the measurement the pose belongs to was taken, on the run's common clock (ns).
    pub measurement_time_ns: u64,
    /// Host monotonic time when the message was built (ns).
    pub host_time_ns: u64,
    /// Position x, y, z of the body in the world frame (m).
    pub position: [f64; 3],
    /// Orientation body to world, unit quaternion w, x, y, z.
    pub orientation: [f32; 4],
    /// Translation since the previous radar-rate pose, in the previous body frame (m).
    pub rel_translation: [f32; 3],
    /// Rotation since the previous radar-rate pose, unit quaternion w, x, y, z.
    pub rel_rotation: [f32; 4],
    /// Frames and samples the pipeline dropped since it started.
    pub dropped_total: u32,
}

const _: () = assert!(size_of::<PoseLinkPose>() == 96 && align_of::<PoseLinkPose>() == 8);

impl Default for PoseLinkPose {
    fn default() -> Self {
        PoseMessage::default().into()
    }
}

impl From<PoseMessage> for PoseLinkPose {
    fn from(m: PoseMessage) -> Self {
        PoseLinkPose {
            seq: m.seq,
            health: m.health.0,
            estimator: m.estimator.code(),
            reserved: 0,
            measurement_time_ns: m.measurement_time_ns,
            host_time_ns: m.host_time_ns,
            position: m.position,
            orientation: m.orientation,
            rel_translation: m.rel_translation,
            rel_rotation: m.rel_rotation,
            dropped_total: m.dropped_total,
        }
    }
}

impl From<PoseLinkPose> for PoseMessage {
    fn from(p: PoseLinkPose) -> Self {
        PoseMessage {
            health: Health(p.health),
            estimator: Estimator::from_code(p.estimator),
            seq: p.seq,
            measurement_time_ns: p.measurement_time_ns,
            host_time_ns: p.host_time_ns,
            position: p.position,
            orientation: p.orientation,
            rel_translation: p.rel_translation,
            rel_rotation: p.rel_rotation,
            dropped_total: p.dropped_total,
        }
    }
}

/// The deframer's counters since `pose_link_deframer_init` (as `pose_link::DeframerCounters`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PoseLinkDeframerCounters {
    /// Bytes consumed (bytes).
    pub bytes_in: u64,
    /// Messages decoded.
    pub messages_ok: u64,
    /// Frames that failed COBS decoding.
    pub frames_bad_cobs: u64,
    /// Frames whose message failed to decode (CRC, type, version, length).
    pub frames_bad_message: u64,
    /// Frames longer than the buffer.
    pub frames_overflow: u64,
    /// Bytes of dropped frames, delimiters included (bytes).
    pub bytes_dropped: u64,
    /// Empty frames (consecutive delimiters), ignored.
    pub empty_frames: u64,
}

type Inner = Deframer<{ pose_link::SERIAL_FRAME_MAX }>;
const DEFRAMER_MAGIC: u64 = 0x706f_7365_6c6e_6b31; // "poselnk1"
                                                   // Words after the magic (a literal, so that cbindgen writes it into the header).
const STATE_WORDS: usize = 31;

/// Serial deframer in caller-allocated storage: declare one (static, on the stack or inside
/// another struct; or `POSE_LINK_DEFRAMER_SIZE` bytes aligned to `POSE_LINK_DEFRAMER_ALIGN`)
/// and call `pose_link_deframer_init` before anything else. The fields are private; copying an
/// initialised deframer copies its state. Not thread-safe: one thread at a time.
#[repr(C)]
#[derive(Debug)]
pub struct PoseLinkDeframer {
    magic: u64,
    state: [u64; 31],
}

const _: () = {
    assert!(size_of::<PoseLinkDeframer>() == POSE_LINK_DEFRAMER_SIZE);
    assert!(STATE_WORDS == POSE_LINK_DEFRAMER_SIZE / 8 - 1);
    assert!(align_of::<PoseLinkDeframer>() == POSE_LINK_DEFRAMER_ALIGN);
    // The Rust deframer lives in `state`: it must fit and need no stricter alignment.
    assert!(size_of::<Inner>() <= STATE_WORDS * 8);
    assert!(align_of::<Inner>() <= align_of::<u64>());
};

/// Called with each decoded pose by `pose_link_deframer_push`; `pose` is valid during the call.
pub type PoseLinkPoseCallback =
    Option<unsafe extern "C" fn(user: *mut c_void, pose: *const PoseLinkPose)>;
/// Called with each dropped frame's status by `pose_link_deframer_push`.
pub type PoseLinkErrorCallback =
    Option<unsafe extern "C" fn(user: *mut c_void, status: PoseLinkStatus)>;

/// `len` bytes at `data` as a slice: `NullPointer` for null, `InvalidArgument` above
/// `isize::MAX`.
///
/// # Safety
/// A non-null `data` must be valid for reads of `len` bytes that nothing writes to for `'a`.
unsafe fn input<'a>(data: *const u8, len: usize) -> Result<&'a [u8], PoseLinkStatus> {
    if data.is_null() {
        return Err(PoseLinkStatus::NullPointer);
    }
    if len > isize::MAX as usize {
        return Err(PoseLinkStatus::InvalidArgument);
    }
    // SAFETY: non-null, at most isize::MAX bytes (checked above), readable and unaliased by
    // writes for 'a (the caller's contract). u8 has alignment 1.
    Ok(unsafe { core::slice::from_raw_parts(data, len) })
}

/// `len` writable bytes at `data` as a slice (errors as `input`).
///
/// # Safety
/// A non-null `data` must be valid for writes of `len` bytes, accessed by nothing else for `'a`.
unsafe fn output<'a>(data: *mut u8, len: usize) -> Result<&'a mut [u8], PoseLinkStatus> {
    if data.is_null() {
        return Err(PoseLinkStatus::NullPointer);
    }
    if len > isize::MAX as usize {
        return Err(PoseLinkStatus::InvalidArgument);
    }
    // SAFETY: as in `input`, plus exclusive access for 'a (the caller's contract).
    Ok(unsafe { core::slice::from_raw_parts_mut(data, len) })
}

/// The Rust deframer inside `d`, after checking `d` is non-null, aligned and initialised.
///
/// # Safety
/// A non-null `d` must point to a `PoseLinkDeframer` (initialised or not) valid for reads.
unsafe fn deframer(d: *const PoseLinkDeframer) -> Result<*const Inner, PoseLinkStatus> {
    if d.is_null() {
        return Err(PoseLinkStatus::NullPointer);
    }
    if !d.addr().is_multiple_of(POSE_LINK_DEFRAMER_ALIGN) {
        return Err(PoseLinkStatus::InvalidArgument);
    }
    // SAFETY: non-null and aligned (checked), valid for reads (contract). The magic is a plain
    // u64: any bit pattern is a value.
    if unsafe { ptr::addr_of!((*d).magic).read() } != DEFRAMER_MAGIC {
        return Err(PoseLinkStatus::NotInitialised);
    }
    // SAFETY: a field address of the valid `*d` (no read). `state` holds an `Inner` written by
    // `pose_link_deframer_init` (the magic says so), which fits and is aligned (const asserts).
    Ok(unsafe { ptr::addr_of!((*d).state) }.cast::<Inner>())
}

/// As `deframer`, mutable.
///
/// # Safety
/// A non-null `d` must point to a `PoseLinkDeframer` (initialised or not) valid for reads and
/// writes, accessed by nothing else for `'a`.
unsafe fn deframer_mut<'a>(d: *mut PoseLinkDeframer) -> Result<&'a mut Inner, PoseLinkStatus> {
    // SAFETY: the caller's contract covers `deframer`'s.
    let inner = unsafe { deframer(d) }?;
    // SAFETY: an initialised `Inner` (checked by `deframer`) derived from the mutable `d`,
    // writable and exclusive for 'a (contract).
    Ok(unsafe { &mut *inner.cast_mut() })
}

/// Writes `value` through `out` when it is non-null.
///
/// # Safety
/// A non-null `out` must be valid for writes of one `T` (any alignment).
unsafe fn put<T>(out: *mut T, value: T) {
    if !out.is_null() {
        // SAFETY: non-null and writable (contract); unaligned writes are allowed.
        unsafe { out.write_unaligned(value) }
    }
}

/// The wire version this library speaks (`POSE_LINK_VERSION`), for languages without the
/// header's macros.
#[no_mangle]
pub extern "C" fn pose_link_version() -> u8 {
    POSE_LINK_VERSION
}

/// Bytes of a version-1 message (`POSE_LINK_MESSAGE_LEN`).
#[no_mangle]
pub extern "C" fn pose_link_message_len() -> usize {
    POSE_LINK_MESSAGE_LEN
}

/// Bytes a `PoseLinkDeframer` needs (`POSE_LINK_DEFRAMER_SIZE`; alignment
/// `POSE_LINK_DEFRAMER_ALIGN`).
#[no_mangle]
pub extern "C" fn pose_link_deframer_size() -> usize {
    POSE_LINK_DEFRAMER_SIZE
}

/// Stable snake_case name of a status code (`"bad_crc"`, ...; `"unknown"` for other values), a
/// static NUL-terminated string.
#[no_mangle]
pub extern "C" fn pose_link_status_name(status: i32) -> *const c_char {
    STATUSES
        .iter()
        .find(|s| **s as i32 == status)
        .map_or(c"unknown", |s| s.name())
        .as_ptr()
}

/// Decodes exactly one message: `len` bytes at `data` (a whole UDP datagram). On `Ok` the pose
/// is written to `*out`; on an error `*out` is left as it was.
///
/// # Safety
/// `data` must be null or valid for reads of `len` bytes; `out` null or valid for writes of one
/// `PoseLinkPose`. Null pointers give `NullPointer`.
#[no_mangle]
pub unsafe extern "C" fn pose_link_decode(
    data: *const u8,
    len: usize,
    out: *mut PoseLinkPose,
) -> PoseLinkStatus {
    if out.is_null() {
        return PoseLinkStatus::NullPointer;
    }
    // SAFETY: the caller's contract on `data`/`len`; the slice lives only in this call.
    let bytes = match unsafe { input(data, len) } {
        Ok(b) => b,
        Err(e) => return e,
    };
    match PoseMessage::decode(bytes) {
        Ok(m) => {
            // SAFETY: `out` is non-null and writable (contract).
            unsafe { put(out, m.into()) };
            PoseLinkStatus::Ok
        }
        Err(e) => e.into(),
    }
}

/// Encodes `*pose` as a version-1 message into `out` (`cap` bytes, at least
/// `POSE_LINK_MESSAGE_LEN`); the length is written to `*written` unless it is null.
///
/// # Safety
/// `pose` must be null or valid for reads of one `PoseLinkPose`; `out` null or valid for writes
/// of `cap` bytes; `written` null or valid for writes of one `size_t`.
#[no_mangle]
pub unsafe extern "C" fn pose_link_encode(
    pose: *const PoseLinkPose,
    out: *mut u8,
    cap: usize,
    written: *mut usize,
) -> PoseLinkStatus {
    // SAFETY: the caller's contract, passed on.
    unsafe {
        encode_with(pose, out, cap, written, |m, buf| {
            m.encode(buf).map_err(Into::into)
        })
    }
}

/// The encoders' common part: reads `*pose`, encodes it with `encode` into `out` (`cap` bytes)
/// and writes the length to `*written` unless it is null.
///
/// # Safety
/// As `pose_link_encode`.
unsafe fn encode_with(
    pose: *const PoseLinkPose,
    out: *mut u8,
    cap: usize,
    written: *mut usize,
    encode: impl FnOnce(&PoseMessage, &mut [u8]) -> Result<usize, PoseLinkStatus>,
) -> PoseLinkStatus {
    if pose.is_null() {
        return PoseLinkStatus::NullPointer;
    }
    // SAFETY: non-null and readable (contract); every bit pattern is a valid PoseLinkPose
    // (integers and floats only); unaligned reads are allowed.
    let m: PoseMessage = unsafe { pose.read_unaligned() }.into();
    // SAFETY: the caller's contract on `out`/`cap`.
    let buf = match unsafe { output(out, cap) } {
        Ok(b) => b,
        Err(e) => return e,
    };
    match encode(&m, buf) {
        Ok(n) => {
            // SAFETY: `written` is null or writable (contract).
            unsafe { put(written, n) };
            PoseLinkStatus::Ok
        }
        Err(e) => e,
    }
}

/// Encodes `*pose` for the serial link: COBS plus the 0x00 delimiter, into `out` (`cap` bytes; at
/// most `POSE_LINK_SERIAL_FRAME_MAX` are needed); the length is written to `*written` unless
/// it is null.
///
/// # Safety
/// As `pose_link_encode`.
#[no_mangle]
pub unsafe extern "C" fn pose_link_encode_serial(
    pose: *const PoseLinkPose,
    out: *mut u8,
    cap: usize,
    written: *mut usize,
) -> PoseLinkStatus {
    // SAFETY: the caller's contract, passed on.
    unsafe {
        encode_with(pose, out, cap, written, |m, buf| {
            encode_serial(m, buf).map_err(|_| PoseLinkStatus::BufferTooSmall)
        })
    }
}

/// Sets up (or resets) a deframer: empty buffer, counters zero.
///
/// # Safety
/// `d` must be null or valid for writes of one `PoseLinkDeframer` (its contents may be
/// uninitialised); nothing else may access it during the call.
#[no_mangle]
pub unsafe extern "C" fn pose_link_deframer_init(d: *mut PoseLinkDeframer) -> PoseLinkStatus {
    if d.is_null() {
        return PoseLinkStatus::NullPointer;
    }
    if !d.addr().is_multiple_of(POSE_LINK_DEFRAMER_ALIGN) {
        return PoseLinkStatus::InvalidArgument;
    }
    // SAFETY: non-null, aligned (checked) and writable (contract); `state` can hold an `Inner`
    // (const asserts); writing without reading the old contents is right for uninitialised
    // memory, and `Inner` has no destructor to skip.
    unsafe {
        ptr::addr_of_mut!((*d).state)
            .cast::<Inner>()
            .write(Inner::default());
        ptr::addr_of_mut!((*d).magic).write(DEFRAMER_MAGIC);
    }
    PoseLinkStatus::Ok
}

/// Feeds bytes up to the next complete frame. `*consumed` gets the bytes used (the call stops
/// right after a frame's delimiter, so call again with the rest). Returns `Ok` with the pose in
/// `*out`, the error of a dropped frame (`BadCobs`, `Overflow`, `BadCrc`, `TooShort`, ...;
/// counted), or `NeedMore` when every byte was used without completing a frame.
///
/// # Safety
/// `d` null or an initialised deframer used by nothing else during the call; `data` null or
/// valid for reads of `len` bytes (not inside `*d`); `consumed` null or valid for writes of one
/// `size_t`; `out` null or valid for writes of one `PoseLinkPose`. All four must be non-null
/// (else `NullPointer`, nothing consumed).
#[no_mangle]
pub unsafe extern "C" fn pose_link_deframer_poll(
    d: *mut PoseLinkDeframer,
    data: *const u8,
    len: usize,
    consumed: *mut usize,
    out: *mut PoseLinkPose,
) -> PoseLinkStatus {
    if consumed.is_null() || out.is_null() {
        return PoseLinkStatus::NullPointer;
    }
    // SAFETY: the caller's contract on `d`; the borrow ends with this call.
    let inner = match unsafe { deframer_mut(d) } {
        Ok(i) => i,
        Err(e) => return e,
    };
    // SAFETY: the caller's contract on `data`/`len` (not overlapping `*d`).
    let all = match unsafe { input(data, len) } {
        Ok(b) => b,
        Err(e) => return e,
    };
    let mut rest = all;
    let ev = inner.poll(&mut rest);
    // SAFETY: `consumed` and `out` are non-null and writable (contract).
    unsafe { put(consumed, all.len() - rest.len()) };
    match ev {
        Event::Message(m) => {
            // SAFETY: as above.
            unsafe { put(out, m.into()) };
            PoseLinkStatus::Ok
        }
        Event::BadFrame(e) => e.into(),
        Event::NeedMore => PoseLinkStatus::NeedMore,
    }
}

/// Feeds all `len` bytes: `on_pose(user, pose)` for each decoded pose, `on_error(user, status)`
/// for each dropped frame (either may be null; the counters count everything). Returns `Ok` once
/// every byte is consumed. The callbacks may call this deframer's functions.
///
/// # Safety
/// As `pose_link_deframer_poll` for `d` and `data`; the callbacks, when non-null, must be safe
/// to call with `user` and must return normally.
#[no_mangle]
pub unsafe extern "C" fn pose_link_deframer_push(
    d: *mut PoseLinkDeframer,
    data: *const u8,
    len: usize,
    on_pose: PoseLinkPoseCallback,
    on_error: PoseLinkErrorCallback,
    user: *mut c_void,
) -> PoseLinkStatus {
    // SAFETY: the caller's contract on `d`; checked once here (each poll below re-borrows).
    if let Err(e) = unsafe { deframer(d) } {
        return e;
    }
    // SAFETY: the caller's contract on `data`/`len`.
    let mut rest = match unsafe { input(data, len) } {
        Ok(b) => b,
        Err(e) => return e,
    };
    while !rest.is_empty() {
        // SAFETY: checked above; the borrow ends before a callback runs, so a callback that
        // calls back into `d` does not alias it.
        let ev = match unsafe { deframer_mut(d) } {
            Ok(inner) => inner.poll(&mut rest),
            Err(e) => return e,
        };
        match ev {
            Event::Message(m) => {
                let pose = PoseLinkPose::from(m);
                if let Some(f) = on_pose {
                    // SAFETY: a valid callback for `user` (contract); `pose` outlives the call.
                    unsafe { f(user, &pose) };
                }
            }
            Event::BadFrame(e) => {
                if let Some(f) = on_error {
                    // SAFETY: a valid callback for `user` (contract).
                    unsafe { f(user, e.into()) };
                }
            }
            Event::NeedMore => break,
        }
    }
    PoseLinkStatus::Ok
}

/// Copies the deframer's counters to `*out`.
///
/// # Safety
/// `d` null or an initialised deframer nothing writes to during the call; `out` null or valid
/// for writes of one `PoseLinkDeframerCounters`.
#[no_mangle]
pub unsafe extern "C" fn pose_link_deframer_counters(
    d: *const PoseLinkDeframer,
    out: *mut PoseLinkDeframerCounters,
) -> PoseLinkStatus {
    if out.is_null() {
        return PoseLinkStatus::NullPointer;
    }
    // SAFETY: the caller's contract on `d`; an initialised `Inner` (checked by `deframer`)
    // that nothing writes to during this read.
    let c = match unsafe { deframer(d) } {
        Ok(inner) => *unsafe { &*inner }.counters(),
        Err(e) => return e,
    };
    let counters = PoseLinkDeframerCounters {
        bytes_in: c.bytes_in,
        messages_ok: c.messages_ok,
        frames_bad_cobs: c.frames_bad_cobs,
        frames_bad_message: c.frames_bad_message,
        frames_overflow: c.frames_overflow,
        bytes_dropped: c.bytes_dropped,
        empty_frames: c.empty_frames,
    };
    // SAFETY: non-null and writable (contract).
    unsafe { put(out, counters) };
    PoseLinkStatus::Ok
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_names_match_the_rust_error_kinds() {
        let errors = [
            DecodeError::TooShort { need: 8, have: 0 },
            DecodeError::TooLong {
                expected: 104,
                have: 105,
            },
            DecodeError::UnknownType { ty: 2 },
            DecodeError::UnsupportedVersion { version: 2 },
            DecodeError::BodyTooShort { len: 3 },
            DecodeError::BadCrc {
                computed: 1,
                carried: 2,
            },
            DecodeError::BufferTooSmall { need: 104 },
        ];
        for e in errors {
            let s = PoseLinkStatus::from(e);
            assert_eq!(s.name().to_str().unwrap(), e.kind_name());
        }
        let f = FrameError::Overflow { dropped: 3 };
        assert_eq!(
            PoseLinkStatus::from(f).name().to_str().unwrap(),
            f.kind_name()
        );
        let f = FrameError::Cobs(pose_link::cobs::CobsError::ZeroByte { at: 0 });
        assert_eq!(
            PoseLinkStatus::from(f).name().to_str().unwrap(),
            f.kind_name()
        );
        for (i, s) in STATUSES.iter().enumerate() {
            assert_eq!(*s as i32, i as i32);
        }
    }
}
