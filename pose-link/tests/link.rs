//! Pose-link codec: committed test vectors, property round trips over both transports, corruption
//! detection, and a real UDP loopback exchange.

use pose_link::{
    cobs, encode_serial, DecodeError, Deframer, Estimator, Event, FrameError, Health, PoseMessage,
    MESSAGE_LEN, SERIAL_FRAME_MAX,
};
use proptest::prelude::*;
use serde_json::{json, Value};

const VECTORS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../docs/pose-link-vectors.json"
);

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn vector_messages() -> Vec<PoseMessage> {
    let a = PoseMessage {
        seq: 1,
        measurement_time_ns: 1_000_000_000,
        host_time_ns: 1_000_250_000,
        ..PoseMessage::default()
    };
    let mut b = a;
    b.seq = 2;
    b.health = Health::PREDICTED | Health::MODEL_FALLBACK;
    b.estimator = Estimator::Doppler;
    b.position = [1.5, -0.25, 1e3];
    b.orientation = [0.70710677, 0.0, 0.0, 0.70710677];
    b.rel_translation = [0.05, 0.0, -0.001];
    b.rel_rotation = [0.99999, 0.0, 0.0044721, 0.0];
    b.dropped_total = 3;
    let mut c = b;
    c.seq = u32::MAX;
    c.health = Health(0xFFFF);
    c.estimator = Estimator::Imu;
    c.measurement_time_ns = u64::MAX;
    vec![a, b, c]
}

/// f32 values as their shortest decimal, so the JSON text round-trips exactly.
fn f32s<const N: usize>(v: [f32; N]) -> Vec<f64> {
    v.iter()
        .map(|x| x.to_string().parse::<f64>().unwrap_or(f64::NAN))
        .collect()
}

fn fields(m: &PoseMessage) -> Value {
    json!({
        "seq": m.seq, "health": m.health.0, "estimator": m.estimator.code(),
        "measurement_time_ns": m.measurement_time_ns, "host_time_ns": m.host_time_ns,
        "position": m.position, "orientation": f32s(m.orientation),
        "rel_translation": f32s(m.rel_translation), "rel_rotation": f32s(m.rel_rotation),
        "dropped_total": m.dropped_total,
    })
}

/// The committed vectors pin the wire format: encoding must reproduce them byte for byte, and
/// decoding must give their fields. Regenerate only for a new format version:
/// `POSE_LINK_WRITE_VECTORS=1 cargo test -p pose-link --test link vectors`.
#[test]
fn vectors() {
    let msgs = vector_messages();
    let make = |m: &PoseMessage| {
        let mut udp = [0u8; MESSAGE_LEN];
        m.encode(&mut udp).unwrap();
        let mut ser = [0u8; SERIAL_FRAME_MAX];
        let n = encode_serial(m, &mut ser).unwrap();
        json!({"fields": fields(m), "udp_hex": hex(&udp), "serial_hex": hex(&ser[..n])})
    };
    let generated = json!({"version": 1, "vectors": msgs.iter().map(make).collect::<Vec<_>>()});
    if std::env::var_os("POSE_LINK_WRITE_VECTORS").is_some() {
        std::fs::write(
            VECTORS,
            serde_json::to_string_pretty(&generated).unwrap() + "\n",
        )
        .unwrap();
    }
    let committed: Value =
        serde_json::from_str(&std::fs::read_to_string(VECTORS).unwrap()).unwrap();
    assert_eq!(
        committed, generated,
        "the encoder no longer produces the committed version-1 bytes"
    );
    for v in committed["vectors"].as_array().unwrap() {
        let bytes: Vec<u8> = (0..v["udp_hex"].as_str().unwrap().len() / 2)
            .map(|i| {
                u8::from_str_radix(&v["udp_hex"].as_str().unwrap()[2 * i..2 * i + 2], 16).unwrap()
            })
            .collect();
        let m = PoseMessage::decode(&bytes).unwrap();
        assert_eq!(fields(&m), v["fields"]);
    }
}

fn message() -> impl Strategy<Value = PoseMessage> {
    (
        any::<u16>(),
        0u8..5,
        any::<u32>(),
        any::<(u64, u64)>(),
        prop::array::uniform3(-1e6f64..1e6),
        prop::array::uniform4(-1f32..1.0),
        prop::array::uniform3(-10f32..10.0),
        prop::array::uniform4(-1f32..1.0),
        any::<u32>(),
    )
        .prop_map(
            |(
                h,
                e,
                seq,
                (st, ht),
                position,
                orientation,
                rel_translation,
                rel_rotation,
                dropped_total,
            )| {
                PoseMessage {
                    health: Health(h),
                    estimator: Estimator::from_code(e),
                    seq,
                    measurement_time_ns: st,
                    host_time_ns: ht,
                    position,
                    orientation,
                    rel_translation,
                    rel_rotation,
                    dropped_total,
                }
            },
        )
}

proptest! {
    #[test]
    fn udp_round_trip(m in message()) {
        let mut b = [0u8; MESSAGE_LEN];
        prop_assert_eq!(m.encode(&mut b), Ok(MESSAGE_LEN));
        prop_assert_eq!(PoseMessage::decode(&b), Ok(m));
    }

    #[test]
    fn any_single_bit_flip_is_detected(m in message(), bit in 0usize..MESSAGE_LEN * 8) {
        let mut b = [0u8; MESSAGE_LEN];
        m.encode(&mut b).unwrap();
        b[bit / 8] ^= 1 << (bit % 8);
        prop_assert!(PoseMessage::decode(&b).is_err());
    }

    #[test]
    fn serial_stream_with_noise_and_random_chunking(
        msgs in prop::collection::vec(message(), 1..20),
        noise_after in prop::collection::vec(prop::option::of(prop::collection::vec(1u8..=255, 1..40)), 20),
        chunk in 1usize..64,
    ) {
        let mut wire = Vec::new();
        let mut noise_frames = 0;
        for (i, m) in msgs.iter().enumerate() {
            let mut f = [0u8; SERIAL_FRAME_MAX];
            let n = encode_serial(m, &mut f).unwrap();
            wire.extend_from_slice(&f[..n]);
            if let Some(junk) = &noise_after[i] {
                wire.extend_from_slice(junk);
                wire.push(0);
                noise_frames += 1;
            }
        }
        let mut d: Deframer<SERIAL_FRAME_MAX> = Deframer::default();
        let mut got = Vec::new();
        let mut bad = 0;
        for c in wire.chunks(chunk) {
            let mut input = c;
            loop {
                match d.poll(&mut input) {
                    Event::Message(m) => got.push(m),
                    Event::BadFrame(_) => bad += 1,
                    Event::NeedMore => break,
                }
            }
        }
        prop_assert_eq!(got, msgs);
        prop_assert_eq!(bad, noise_frames);
        let c = d.counters();
        prop_assert_eq!(c.bytes_in, wire.len() as u64);
        prop_assert_eq!(c.frames_bad_cobs + c.frames_bad_message + c.frames_overflow, noise_frames as u64);
    }
}

#[test]
fn decode_errors_carry_evidence() {
    let mut b = [0u8; MESSAGE_LEN];
    PoseMessage::default().encode(&mut b).unwrap();
    assert_eq!(
        PoseMessage::decode(&b[..5]),
        Err(DecodeError::TooShort { need: 8, have: 5 })
    );
    assert_eq!(
        PoseMessage::decode(&b[..50]),
        Err(DecodeError::TooShort {
            need: MESSAGE_LEN,
            have: 50
        })
    );
    let mut long = b.to_vec();
    long.push(0);
    assert_eq!(
        PoseMessage::decode(&long),
        Err(DecodeError::TooLong {
            expected: MESSAGE_LEN,
            have: MESSAGE_LEN + 1
        })
    );
    let mut t = b;
    t[0] = 9;
    assert_eq!(
        PoseMessage::decode(&t),
        Err(DecodeError::UnknownType { ty: 9 })
    );
    t = b;
    t[1] = 2;
    assert_eq!(
        PoseMessage::decode(&t),
        Err(DecodeError::UnsupportedVersion { version: 2 })
    );
    t = b;
    t[20] ^= 0x10;
    assert!(matches!(
        PoseMessage::decode(&t),
        Err(DecodeError::BadCrc { .. })
    ));
    assert!(PoseMessage::default().encode(&mut [0u8; 10]).is_err());
}

#[test]
fn a_newer_minor_revision_with_appended_fields_still_decodes() {
    // Version-1 promise: fields never move; a later revision may append fields before the CRC
    // and raise the body length. An old decoder reads what it knows.
    let m = vector_messages()[1];
    let mut b = [0u8; MESSAGE_LEN];
    m.encode(&mut b).unwrap();
    let mut ext = b[..MESSAGE_LEN - 4].to_vec();
    ext.extend_from_slice(&[0xAB; 12]);
    let body = (ext.len() - 8) as u16;
    ext[6..8].copy_from_slice(&body.to_le_bytes());
    let crc = pose_link::crc32c(&ext);
    ext.extend_from_slice(&crc.to_le_bytes());
    assert_eq!(PoseMessage::decode(&ext), Ok(m));
}

#[test]
fn overlong_serial_frames_are_dropped_and_counted() {
    let mut d: Deframer<SERIAL_FRAME_MAX> = Deframer::default();
    let mut wire = vec![0x55u8; 500];
    wire.push(0);
    let mut f = [0u8; SERIAL_FRAME_MAX];
    let n = encode_serial(&PoseMessage::default(), &mut f).unwrap();
    wire.extend_from_slice(&f[..n]);
    let mut input = &wire[..];
    assert_eq!(
        d.poll(&mut input),
        Event::BadFrame(FrameError::Overflow { dropped: 501 })
    );
    assert_eq!(d.poll(&mut input), Event::Message(PoseMessage::default()));
    assert_eq!(d.counters().bytes_dropped, 501);
    assert_eq!(cobs::max_encoded_len(MESSAGE_LEN) + 1, SERIAL_FRAME_MAX);
}

#[test]
fn udp_loopback_one_message_per_datagram() {
    let rx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(std::time::Duration::from_secs(5)))
        .unwrap();
    let tx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for m in vector_messages() {
        let mut b = [0u8; MESSAGE_LEN];
        m.encode(&mut b).unwrap();
        tx.send_to(&b, rx.local_addr().unwrap()).unwrap();
    }
    let mut buf = [0u8; 1500];
    for want in vector_messages() {
        let n = rx.recv(&mut buf).unwrap();
        assert_eq!(PoseMessage::decode(&buf[..n]), Ok(want));
    }
}

#[test]
fn health_flags_are_named_and_unknown_bits_kept_by_number() {
    let h = Health::RADAR_MISSING | Health::DEAD_RECKONING | Health(1 << 9);
    assert_eq!(
        h.names().collect::<Vec<_>>(),
        ["radar_missing", "dead_reckoning", "bit9"]
    );
    assert!(h.contains(Health::DEAD_RECKONING));
    assert!(!Health::HANDOVER.contains(Health::DEAD_RECKONING));
}
