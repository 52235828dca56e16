//! Property tests: random MTData2 packets through encoder -> framer (random chunking, noise in
//! front) -> decoder, compared field by field; arbitrary bytes through the framer and the item
//! iterator without panics and with exact byte accounting.

use imu_driver::mtdata2::{Layout, UtcTime};
use imu_driver::{
    CoordinateFrame, DataId, DataKind, Framer, Message, MtData2, MtData2Writer, Poll, Precision,
    Value,
};
use proptest::prelude::*;

fn quantize(v: f64, p: Precision) -> f64 {
    match p {
        Precision::Float32 => f64::from(v as f32),
        Precision::Fp1220 => (v * 1_048_576.0).round() / 1_048_576.0,
        Precision::Fp1632 => (v * 4_294_967_296.0).round() / 4_294_967_296.0,
        Precision::Float64 => v,
    }
}

/// A float-valued value of `kind` holding `f` (length already right).
fn float_value(kind: DataKind, f: &[f64]) -> Value<'static> {
    let a3 = || [f[0], f[1], f[2]];
    let a4 = || [f[0], f[1], f[2], f[3]];
    match kind {
        DataKind::Temperature => Value::Temperature(f[0]),
        DataKind::AltitudeEllipsoid => Value::AltitudeEllipsoid(f[0]),
        DataKind::LatLon => Value::LatLon([f[0], f[1]]),
        DataKind::Quaternion => Value::Quaternion(a4()),
        DataKind::DeltaQ => Value::DeltaQ(a4()),
        DataKind::RotationMatrix => {
            let mut m = [0.0; 9];
            m.copy_from_slice(&f[..9]);
            Value::RotationMatrix(m)
        }
        DataKind::EulerAngles => Value::EulerAngles(a3()),
        DataKind::DeltaV => Value::DeltaV(a3()),
        DataKind::Acceleration => Value::Acceleration(a3()),
        DataKind::FreeAcceleration => Value::FreeAcceleration(a3()),
        DataKind::AccelerationHr => Value::AccelerationHr(a3()),
        DataKind::PositionEcef => Value::PositionEcef(a3()),
        DataKind::RateOfTurn => Value::RateOfTurn(a3()),
        DataKind::RateOfTurnHr => Value::RateOfTurnHr(a3()),
        DataKind::MagneticField => Value::MagneticField(a3()),
        DataKind::VelocityXyz => Value::VelocityXyz(a3()),
        other => panic!("{other:?} is not float-valued"),
    }
}

/// One random item: its id and value.
#[derive(Debug, Clone)]
enum Spec {
    Floats {
        kind: usize,
        precision: usize,
        frame: usize,
        values: Vec<f64>,
    },
    Counter(u16),
    Time(u32),
    Status(u32),
    Utc {
        nanos: u32,
        year: u16,
        second: u8,
    },
    Unknown {
        id: u16,
        data: Vec<u8>,
    },
}

fn float_kinds() -> Vec<DataKind> {
    DataKind::ALL
        .iter()
        .copied()
        .filter(|k| matches!(k.layout(), Layout::Floats(_)))
        .collect()
}

fn spec() -> impl Strategy<Value = Spec> {
    prop_oneof![
        (
            0usize..16,
            0usize..4,
            0usize..3,
            prop::collection::vec(-1000.0f64..1000.0, 9)
        )
            .prop_map(|(kind, precision, frame, values)| Spec::Floats {
                kind,
                precision,
                frame,
                values
            }),
        any::<u16>().prop_map(Spec::Counter),
        any::<u32>().prop_map(Spec::Time),
        any::<u32>().prop_map(Spec::Status),
        (0u32..1_000_000_000, 2000u16..2100, 0u8..60).prop_map(|(nanos, year, second)| Spec::Utc {
            nanos,
            year,
            second
        }),
        // Ids in groups no MTi defines (0x9xxx, 0xFxxx) are unknown to us.
        (
            prop_oneof![0x9000u16..0x9FFF, 0xF000u16..0xFFFF],
            prop::collection::vec(any::<u8>(), 0..40)
        )
            .prop_map(|(id, data)| Spec::Unknown { id, data }),
    ]
}

/// The id, the value to encode and the value expected back.
fn build(s: &Spec) -> (DataId, Value<'_>, Value<'_>) {
    match s {
        Spec::Floats {
            kind,
            precision,
            frame,
            values,
        } => {
            let kinds = float_kinds();
            let kind = kinds[kind % kinds.len()];
            let p = Precision::ALL[*precision];
            let frame = [
                CoordinateFrame::Enu,
                CoordinateFrame::Ned,
                CoordinateFrame::Nwu,
            ][*frame];
            let id = DataId::of(kind, p).unwrap().in_frame(frame);
            let Layout::Floats(n) = kind.layout() else {
                unreachable!()
            };
            let sent = &values[..n];
            let back: Vec<f64> = sent.iter().map(|v| quantize(*v, p)).collect();
            (id, float_value(kind, sent), float_value(kind, &back))
        }
        Spec::Counter(c) => (
            DataId(0x1020),
            Value::PacketCounter(*c),
            Value::PacketCounter(*c),
        ),
        Spec::Time(t) => (
            DataId(0x1060),
            Value::SampleTimeFine(*t),
            Value::SampleTimeFine(*t),
        ),
        Spec::Status(w) => (DataId(0xE020), Value::StatusWord(*w), Value::StatusWord(*w)),
        Spec::Utc {
            nanos,
            year,
            second,
        } => {
            let t = UtcTime {
                nanos: *nanos,
                year: *year,
                month: 1,
                day: 20,
                hour: 13,
                minute: 47,
                second: *second,
                flags: 7,
            };
            (DataId(0x1010), Value::UtcTime(t), Value::UtcTime(t))
        }
        Spec::Unknown { id, data } => (DataId(*id), Value::Unknown(data), Value::Unknown(data)),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn encoder_framer_decoder_round_trip(
        specs in prop::collection::vec(spec(), 0..40),
        noise in prop::collection::vec(any::<u8>().prop_filter("no preamble", |b| *b != 0xFA), 0..20),
        cuts in prop::collection::vec(1usize..64, 1..40),
    ) {
        let built: Vec<_> = specs.iter().map(build).collect();
        let mut buf = vec![0u8; 8192];
        let mut w = MtData2Writer::new(&mut buf);
        for (id, sent, _) in &built {
            w.value(*id, sent).unwrap();
        }
        let n = w.finish(0xFF).unwrap();
        let stream: Vec<u8> = [&noise[..], &buf[..n]].concat();

        let mut framer = Framer::<{ imu_driver::frame_capacity(4096) }>::new();
        let mut payloads = Vec::new();
        let mut rest = &stream[..];
        let mut i = 0;
        while !rest.is_empty() {
            let take = cuts[i % cuts.len()].min(rest.len());
            let mut chunk = &rest[..take];
            rest = &rest[take..];
            i += 1;
            loop {
                match framer.poll(&mut chunk) {
                    Poll::Frame(f) => payloads.push((f.mid(), f.payload().to_vec())),
                    Poll::Dropped { .. } => {}
                    Poll::NeedMore => break,
                }
            }
        }
        prop_assert_eq!(framer.finish(), None);
        prop_assert_eq!(payloads.len(), 1);
        prop_assert_eq!(framer.counters().bytes_skipped, noise.len() as u64);
        let (mid, payload) = &payloads[0];
        let Ok(Message::MtData2(m)) = Message::decode_payload(*mid, payload) else {
            return Err(TestCaseError::fail("not MTData2"));
        };
        let items: Vec<_> = m.items().collect();
        prop_assert_eq!(items.len(), built.len());
        for (item, (id, _, expected)) in items.iter().zip(&built) {
            let item = item.as_ref().unwrap();
            prop_assert_eq!(item.id, *id);
            prop_assert_eq!(item.id.coordinate_frame(), id.coordinate_frame());
            prop_assert_eq!(item.value().unwrap(), *expected);
        }
    }

    #[test]
    fn framer_survives_any_bytes_and_accounts_for_each(
        data in prop::collection::vec(prop_oneof![Just(0xFAu8), Just(0xFF), Just(0x00), any::<u8>()], 0..2000),
        cuts in prop::collection::vec(1usize..300, 1..20),
    ) {
        let mut framer = Framer::<64>::new();
        let mut rest = &data[..];
        let mut i = 0;
        let mut frame_bytes = 0u64;
        while !rest.is_empty() {
            let take = cuts[i % cuts.len()].min(rest.len());
            let mut chunk = &rest[..take];
            rest = &rest[take..];
            i += 1;
            loop {
                match framer.poll(&mut chunk) {
                    Poll::Frame(f) => {
                        prop_assert!(f.payload().len() <= framer_max());
                        prop_assert_eq!(imu_driver::XbusFrame::new_checked(f.as_bytes()), Ok(f));
                        frame_bytes += f.as_bytes().len() as u64;
                    }
                    Poll::Dropped { bytes, .. } => prop_assert!(bytes > 0),
                    Poll::NeedMore => break,
                }
            }
        }
        framer.finish();
        let c = *framer.counters();
        prop_assert_eq!(c.bytes_in, data.len() as u64);
        prop_assert_eq!(c.frame_bytes, frame_bytes);
        prop_assert_eq!(c.frame_bytes + c.bytes_skipped, c.bytes_in);
    }

    #[test]
    fn item_iterator_survives_any_payload(payload in prop::collection::vec(any::<u8>(), 0..600)) {
        let mut consumed = 0usize;
        let mut stopped = false;
        for item in MtData2::new(&payload).items() {
            prop_assert!(!stopped, "nothing after an error that ends iteration");
            match item {
                Ok(i) => {
                    consumed += 3 + i.data.len();
                    let _ = i.value();
                }
                Err(_) => stopped = true,
            }
        }
        prop_assert!(consumed <= payload.len());
        if !stopped {
            prop_assert_eq!(consumed, payload.len());
        }
        let _ = MtData2::new(&payload).sample();
    }
}

fn framer_max() -> usize {
    64 - imu_driver::FRAME_OVERHEAD
}
