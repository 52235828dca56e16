//! The C ABI called from Rust exactly as C calls it (raw pointers): encode/decode round trips
//! against the Rust crate's bytes, a status for every null pointer, short, long and corrupt
//! input, and the deframer's poll and callback APIs with exact counters.
#![allow(unsafe_code)]

use pose_link::{cobs, Deframer, Estimator, Health, PoseMessage, MESSAGE_LEN, SERIAL_FRAME_MAX};
use pose_link_c::*;
use std::ffi::{c_void, CStr};
use std::ptr;

fn sample(seq: u32) -> PoseLinkPose {
    PoseLinkPose {
        seq,
        health: POSE_LINK_HEALTH_PREDICTED | POSE_LINK_HEALTH_HANDOVER | 0x8000,
        estimator: POSE_LINK_ESTIMATOR_DOPPLER,
        reserved: 0,
        measurement_time_ns: 1_234_567_890_123 + u64::from(seq),
        host_time_ns: 9_876_543_210,
        position: [1.5, -2.25, f64::from(seq) * 0.125],
        orientation: [0.5, -0.5, 0.5, 0.5],
        rel_translation: [0.01, 0.02, -0.03],
        rel_rotation: [0.999, 0.01, 0.02, 0.03],
        dropped_total: 42,
    }
}

fn encode(p: &PoseLinkPose) -> [u8; MESSAGE_LEN] {
    let mut b = [0u8; MESSAGE_LEN];
    let mut n = 0;
    // SAFETY: valid pointers, `b` has its length.
    let s = unsafe { pose_link_encode(p, b.as_mut_ptr(), b.len(), &mut n) };
    assert_eq!(s, PoseLinkStatus::Ok);
    assert_eq!(n, MESSAGE_LEN);
    b
}

fn decode(b: &[u8]) -> Result<PoseLinkPose, PoseLinkStatus> {
    let mut out = PoseLinkPose::default();
    // SAFETY: `b` is valid for its length, `out` for one pose.
    match unsafe { pose_link_decode(b.as_ptr(), b.len(), &mut out) } {
        PoseLinkStatus::Ok => Ok(out),
        e => Err(e),
    }
}

fn name(code: i32) -> &'static str {
    // SAFETY: pose_link_status_name returns a static NUL-terminated string.
    unsafe { CStr::from_ptr(pose_link_status_name(code)) }
        .to_str()
        .unwrap()
}

#[test]
fn encode_decode_round_trip_matches_the_rust_crate() {
    for seq in [0, 1, 77, u32::MAX] {
        let p = sample(seq);
        let bytes = encode(&p);
        // The bytes are the Rust crate's, field for field.
        let m = PoseMessage::from(p);
        let mut rust = [0u8; MESSAGE_LEN];
        m.encode(&mut rust).unwrap();
        assert_eq!(bytes, rust);
        assert_eq!(m.estimator, Estimator::Doppler);
        assert!(m.health.contains(Health::PREDICTED | Health::HANDOVER));
        assert_eq!(decode(&bytes), Ok(p));
        assert_eq!(PoseMessage::decode(&bytes).unwrap(), m);
    }
    // An unknown estimator code travels as is.
    let p = PoseLinkPose {
        estimator: 9,
        ..sample(3)
    };
    assert_eq!(decode(&encode(&p)).unwrap().estimator, 9);
    // The reserved byte is not data: it is written as zero and read back as zero.
    let p = PoseLinkPose {
        reserved: 0xAB,
        ..sample(4)
    };
    assert_eq!(encode(&p)[5], 0);
    assert_eq!(decode(&encode(&p)).unwrap().reserved, 0);
    assert_eq!(pose_link_version(), 1);
    assert_eq!(pose_link_message_len(), 104);
    assert_eq!(pose_link_deframer_size(), POSE_LINK_DEFRAMER_SIZE);
    assert_eq!(POSE_LINK_SERIAL_FRAME_MAX, SERIAL_FRAME_MAX);
}

#[test]
fn every_bad_input_gets_its_status_and_leaves_the_output_alone() {
    let good = encode(&sample(5));
    let sentinel = PoseLinkPose {
        seq: 0xDEAD,
        ..PoseLinkPose::default()
    };
    let status = |b: &[u8]| {
        let mut out = sentinel;
        // SAFETY: valid pointers.
        let s = unsafe { pose_link_decode(b.as_ptr(), b.len(), &mut out) };
        assert_eq!(out, sentinel, "output written on {s:?}");
        s
    };
    assert_eq!(status(&good[..0]), PoseLinkStatus::TooShort);
    assert_eq!(status(&good[..7]), PoseLinkStatus::TooShort);
    assert_eq!(status(&good[..103]), PoseLinkStatus::TooShort);
    let mut long = [0u8; MESSAGE_LEN + 1];
    long[..MESSAGE_LEN].copy_from_slice(&good);
    assert_eq!(status(&long), PoseLinkStatus::TooLong);
    let with = |at: usize, v: u8| {
        let mut b = good;
        b[at] = v;
        b
    };
    assert_eq!(status(&with(0, 2)), PoseLinkStatus::UnknownType);
    assert_eq!(status(&with(1, 2)), PoseLinkStatus::UnsupportedVersion);
    assert_eq!(status(&with(6, 91)), PoseLinkStatus::BodyTooShort);
    for at in [2, 8, 40, 99, 100, 103] {
        assert_eq!(
            status(&with(at, good[at] ^ 0x10)),
            PoseLinkStatus::BadCrc,
            "{at}"
        );
    }

    // Null pointers, every argument of every function.
    let mut out = sentinel;
    let mut n = 7usize;
    let mut buf = [0u8; 200];
    let p = sample(1);
    // SAFETY: every non-null pointer is valid; the nulls are what is tested.
    unsafe {
        assert_eq!(
            pose_link_decode(ptr::null(), 104, &mut out),
            PoseLinkStatus::NullPointer
        );
        assert_eq!(
            pose_link_decode(good.as_ptr(), good.len(), ptr::null_mut()),
            PoseLinkStatus::NullPointer
        );
        assert_eq!(
            pose_link_encode(ptr::null(), buf.as_mut_ptr(), buf.len(), &mut n),
            PoseLinkStatus::NullPointer
        );
        assert_eq!(
            pose_link_encode(&p, ptr::null_mut(), 200, &mut n),
            PoseLinkStatus::NullPointer
        );
        assert_eq!(
            pose_link_encode_serial(ptr::null(), buf.as_mut_ptr(), buf.len(), &mut n),
            PoseLinkStatus::NullPointer
        );
        assert_eq!(
            pose_link_encode_serial(&p, ptr::null_mut(), 200, &mut n),
            PoseLinkStatus::NullPointer
        );
        // Lengths no object can have.
        assert_eq!(
            pose_link_decode(good.as_ptr(), usize::MAX, &mut out),
            PoseLinkStatus::InvalidArgument
        );
        assert_eq!(
            pose_link_encode(&p, buf.as_mut_ptr(), usize::MAX, &mut n),
            PoseLinkStatus::InvalidArgument
        );
        // Short output buffers.
        assert_eq!(
            pose_link_encode(&p, buf.as_mut_ptr(), 103, &mut n),
            PoseLinkStatus::BufferTooSmall
        );
        assert_eq!(
            pose_link_encode_serial(&p, buf.as_mut_ptr(), 20, &mut n),
            PoseLinkStatus::BufferTooSmall
        );
        assert_eq!(n, 7, "written is only set on success");
        // `written` is optional.
        assert_eq!(
            pose_link_encode(&p, buf.as_mut_ptr(), 104, ptr::null_mut()),
            PoseLinkStatus::Ok
        );
        assert_eq!(
            pose_link_deframer_init(ptr::null_mut()),
            PoseLinkStatus::NullPointer
        );
        let mut c = PoseLinkDeframerCounters::default();
        assert_eq!(
            pose_link_deframer_counters(ptr::null(), &mut c),
            PoseLinkStatus::NullPointer
        );
    }
    assert_eq!(out, sentinel);

    // Names: the Rust crate's kind names, and "unknown" past the end.
    assert_eq!(name(0), "ok");
    assert_eq!(name(PoseLinkStatus::BadCrc as i32), "bad_crc");
    assert_eq!(name(PoseLinkStatus::TooShort as i32), "too_short");
    assert_eq!(name(PoseLinkStatus::Overflow as i32), "overflow");
    assert_eq!(name(PoseLinkStatus::NeedMore as i32), "need_more");
    assert_eq!(name(-1), "unknown");
    assert_eq!(name(14), "unknown");
}

/// One serial frame of `raw` (already encoded, perhaps corrupted).
fn frame(raw: &[u8]) -> Vec<u8> {
    let mut out = [0u8; 512];
    let n = cobs::encode(raw, &mut out).unwrap();
    let mut v = out[..n].to_vec();
    v.push(0);
    v
}

fn serial(p: &PoseLinkPose) -> Vec<u8> {
    let mut b = [0u8; POSE_LINK_SERIAL_FRAME_MAX];
    let mut n = 0;
    // SAFETY: valid pointers, `b` has its length.
    let s = unsafe { pose_link_encode_serial(p, b.as_mut_ptr(), b.len(), &mut n) };
    assert_eq!(s, PoseLinkStatus::Ok);
    b[..n].to_vec()
}

/// A stream with every kind of damage, and what each frame should give.
fn damaged_stream() -> (Vec<u8>, Vec<Result<u32, PoseLinkStatus>>) {
    let mut s = Vec::new();
    let mut expect = Vec::new();
    // Mid-frame start: the tail of a frame whose start was missed (does not COBS-decode).
    s.extend_from_slice(&[0x09, 0x33, 0x44, 0x00]);
    expect.push(Err(PoseLinkStatus::BadCobs));
    s.extend(serial(&sample(0)));
    expect.push(Ok(0));
    s.extend_from_slice(&[0, 0]); // empty frames, ignored
    let mut bad = encode(&sample(1));
    bad[44] ^= 0x01;
    s.extend(frame(&bad));
    expect.push(Err(PoseLinkStatus::BadCrc));
    s.extend(serial(&sample(2)));
    expect.push(Ok(2));
    s.extend(frame(&encode(&sample(3))[..60]));
    expect.push(Err(PoseLinkStatus::TooShort));
    s.extend(std::iter::repeat_n(0x55u8, 300));
    s.push(0);
    expect.push(Err(PoseLinkStatus::Overflow));
    let mut v2 = encode(&sample(4));
    v2[1] = 2;
    s.extend(frame(&v2));
    expect.push(Err(PoseLinkStatus::UnsupportedVersion));
    for seq in 5..9 {
        s.extend(serial(&sample(seq)));
        expect.push(Ok(seq));
    }
    // An unfinished frame at the end: buffered, not counted as anything yet.
    s.extend_from_slice(&serial(&sample(9))[..50]);
    (s, expect)
}

fn rust_counters(stream: &[u8]) -> PoseLinkDeframerCounters {
    let mut d = Deframer::<SERIAL_FRAME_MAX>::default();
    let mut input = stream;
    while d.poll(&mut input) != pose_link::Event::NeedMore {}
    let c = d.counters();
    PoseLinkDeframerCounters {
        bytes_in: c.bytes_in,
        messages_ok: c.messages_ok,
        frames_bad_cobs: c.frames_bad_cobs,
        frames_bad_message: c.frames_bad_message,
        frames_overflow: c.frames_overflow,
        bytes_dropped: c.bytes_dropped,
        empty_frames: c.empty_frames,
    }
}

fn counters(d: &PoseLinkDeframer) -> PoseLinkDeframerCounters {
    let mut c = PoseLinkDeframerCounters::default();
    // SAFETY: an initialised deframer, a valid output.
    assert_eq!(
        unsafe { pose_link_deframer_counters(d, &mut c) },
        PoseLinkStatus::Ok
    );
    c
}

#[test]
fn deframer_poll_reports_each_frame_and_counts_every_byte() {
    let (stream, expect) = damaged_stream();
    // Uninitialised storage: zeroed here (garbage in C); either way the magic is missing.
    // SAFETY: PoseLinkDeframer is plain integers; all-zero is a value.
    let mut d: PoseLinkDeframer = unsafe { std::mem::zeroed() };
    let mut used = 0usize;
    let mut out = PoseLinkPose::default();
    // SAFETY: valid pointers throughout.
    unsafe {
        assert_eq!(
            pose_link_deframer_poll(&mut d, stream.as_ptr(), stream.len(), &mut used, &mut out),
            PoseLinkStatus::NotInitialised
        );
        let mut c = PoseLinkDeframerCounters::default();
        assert_eq!(
            pose_link_deframer_counters(&d, &mut c),
            PoseLinkStatus::NotInitialised
        );
        assert_eq!(pose_link_deframer_init(&mut d), PoseLinkStatus::Ok);
        for (a, b) in [
            (ptr::null_mut(), &mut out as *mut _),
            (&mut used as *mut _, ptr::null_mut()),
        ] {
            assert_eq!(
                pose_link_deframer_poll(&mut d, stream.as_ptr(), stream.len(), a, b),
                PoseLinkStatus::NullPointer
            );
        }
        assert_eq!(
            pose_link_deframer_poll(&mut d, ptr::null(), 3, &mut used, &mut out),
            PoseLinkStatus::NullPointer
        );
        assert_eq!(
            pose_link_deframer_poll(ptr::null_mut(), stream.as_ptr(), 3, &mut used, &mut out),
            PoseLinkStatus::NullPointer
        );
    }
    assert_eq!(counters(&d), PoseLinkDeframerCounters::default());

    // Fed in uneven chunks, so frames straddle calls.
    let mut got = Vec::new();
    for chunk in stream.chunks(37) {
        let mut rest = chunk;
        loop {
            let mut used = usize::MAX;
            // SAFETY: valid pointers; `rest` is valid for its length.
            let s = unsafe {
                pose_link_deframer_poll(&mut d, rest.as_ptr(), rest.len(), &mut used, &mut out)
            };
            assert!(used <= rest.len());
            rest = &rest[used..];
            match s {
                PoseLinkStatus::NeedMore => {
                    assert!(rest.is_empty());
                    break;
                }
                PoseLinkStatus::Ok => got.push(Ok(out.seq)),
                e => got.push(Err(e)),
            }
        }
    }
    assert_eq!(got, expect);
    for seq in [0u32, 2, 5, 8] {
        // Every field came through.
        assert!(expect.contains(&Ok(seq)));
    }
    assert_eq!(out, sample(8));
    let c = counters(&d);
    assert_eq!(c, rust_counters(&stream));
    assert_eq!(c.bytes_in, stream.len() as u64);
    assert_eq!(c.messages_ok, 6);
    assert_eq!(c.frames_bad_cobs, 1);
    assert_eq!(c.frames_bad_message, 3);
    assert_eq!(c.frames_overflow, 1);
    assert_eq!(c.empty_frames, 2);
    // Every byte is a good frame's, a dropped frame's, an empty delimiter or still buffered.
    let good: u64 = (0..9)
        .filter(|s| expect.contains(&Ok(*s)))
        .map(|s| serial(&sample(s)).len() as u64)
        .sum();
    assert_eq!(c.bytes_in, good + c.bytes_dropped + c.empty_frames + 50);

    // Init resets.
    // SAFETY: a valid deframer.
    assert_eq!(
        unsafe { pose_link_deframer_init(&mut d) },
        PoseLinkStatus::Ok
    );
    assert_eq!(counters(&d), PoseLinkDeframerCounters::default());
}

#[derive(Default)]
struct Seen {
    poses: Vec<PoseLinkPose>,
    errors: Vec<PoseLinkStatus>,
    /// The deframer, read back from inside the callback (re-entry is allowed).
    deframer: *const PoseLinkDeframer,
    messages_ok_in_callback: Vec<u64>,
}

unsafe extern "C" fn on_pose(user: *mut c_void, pose: *const PoseLinkPose) {
    // SAFETY: `user` is the `Seen` passed to push, `pose` valid during the call.
    let seen = unsafe { &mut *user.cast::<Seen>() };
    seen.poses.push(unsafe { *pose });
    let mut c = PoseLinkDeframerCounters::default();
    // SAFETY: the deframer being pushed to; push holds no borrow during the callback.
    let s = unsafe { pose_link_deframer_counters(seen.deframer, &mut c) };
    assert_eq!(s, PoseLinkStatus::Ok);
    seen.messages_ok_in_callback.push(c.messages_ok);
}

unsafe extern "C" fn on_error(user: *mut c_void, status: PoseLinkStatus) {
    // SAFETY: `user` is the `Seen` passed to push.
    unsafe { &mut *user.cast::<Seen>() }.errors.push(status);
}

#[test]
fn deframer_push_calls_back_per_pose_and_per_dropped_frame() {
    let (stream, expect) = damaged_stream();
    // Caller-allocated storage as C would have it: bytes with the documented size and alignment.
    #[repr(C, align(8))]
    struct Storage([u8; POSE_LINK_DEFRAMER_SIZE]);
    let mut storage = Storage([0xA5; POSE_LINK_DEFRAMER_SIZE]);
    let d = storage.0.as_mut_ptr().cast::<PoseLinkDeframer>();
    let mut seen = Seen {
        deframer: d,
        ..Seen::default()
    };
    let user = (&mut seen as *mut Seen).cast::<c_void>();
    // SAFETY: `storage` is valid, aligned and only used through `d`; callbacks match `user`.
    unsafe {
        assert_eq!(
            pose_link_deframer_push(d, stream.as_ptr(), 4, Some(on_pose), None, user),
            PoseLinkStatus::NotInitialised
        );
        assert_eq!(pose_link_deframer_init(d), PoseLinkStatus::Ok);
        assert_eq!(
            pose_link_deframer_push(d, ptr::null(), 4, Some(on_pose), None, user),
            PoseLinkStatus::NullPointer
        );
        for chunk in stream.chunks(61) {
            let s = pose_link_deframer_push(
                d,
                chunk.as_ptr(),
                chunk.len(),
                Some(on_pose),
                Some(on_error),
                user,
            );
            assert_eq!(s, PoseLinkStatus::Ok);
        }
        // Null callbacks: counted, not reported.
        let more = serial(&sample(20));
        assert_eq!(
            pose_link_deframer_push(d, more.as_ptr(), more.len(), None, None, user),
            PoseLinkStatus::Ok
        );
    }
    let poses: Vec<Result<u32, PoseLinkStatus>> = seen.poses.iter().map(|p| Ok(p.seq)).collect();
    let oks: Vec<_> = expect.iter().filter(|e| e.is_ok()).cloned().collect();
    assert_eq!(poses, oks);
    let errs: Vec<_> = expect.iter().filter_map(|e| e.err()).collect();
    assert_eq!(seen.errors, errs);
    assert_eq!(seen.poses[1], sample(2));
    assert_eq!(seen.messages_ok_in_callback, vec![1, 2, 3, 4, 5, 6]);
    // SAFETY: initialised above.
    let c = counters(unsafe { &*d });
    // The last frame completed the unfinished one's bytes into garbage: it started mid-frame,
    // so both are dropped together as one bad frame, and nothing is lost from the count.
    let mut all = stream.clone();
    all.extend(serial(&sample(20)));
    assert_eq!(c, rust_counters(&all));
    assert_eq!(c.bytes_in, all.len() as u64);

    // A misaligned deframer is refused, not used.
    // SAFETY: the pointer is in bounds of `storage`; the functions check alignment first.
    let off = unsafe { storage.0.as_mut_ptr().add(1) }.cast::<PoseLinkDeframer>();
    assert_eq!(
        unsafe { pose_link_deframer_init(off) },
        PoseLinkStatus::InvalidArgument
    );
}
