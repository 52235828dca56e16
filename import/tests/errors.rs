//! `import()` on bad recordings: every error names the file, the topic, the message index and
//! the field; what is dropped instead of refused is counted, with the first one named. The bags
//! are written by hand (ROS 1, format 2.0) so each fault is exactly the one under test.

mod common;

use common::{chunk, connection, hand_bag, message};
use milliego_import::calib::Calibration;
use milliego_import::source::SourceError;
use milliego_import::{import, ImportError, ImportOptions};
use std::path::{Path, PathBuf};

/// ROS 1 serialisation of the fields these tests need.
#[derive(Default)]
struct Ser(Vec<u8>);

impl Ser {
    fn u8(mut self, v: u8) -> Self {
        self.0.push(v);
        self
    }
    fn u32(mut self, v: u32) -> Self {
        self.0.extend(v.to_le_bytes());
        self
    }
    fn f64s(mut self, v: &[f64]) -> Self {
        v.iter().for_each(|x| self.0.extend(x.to_le_bytes()));
        self
    }
    fn string(self, s: &str) -> Self {
        let mut me = self.u32(s.len() as u32);
        me.0.extend(s.as_bytes());
        me
    }
    fn header(self, seq: u32, t_ns: u64, frame: &str) -> Self {
        self.u32(seq)
            .u32((t_ns / 1_000_000_000) as u32)
            .u32((t_ns % 1_000_000_000) as u32)
            .string(frame)
    }
}

const T0: u64 = 1_700_000_000_000_000_000;

fn imu(seq: u32, t_ns: u64, frame: &str) -> Vec<u8> {
    let cov = [0.0; 9];
    Ser::default()
        .header(seq, t_ns, frame)
        .f64s(&[0.0, 0.0, 0.0, 1.0])
        .f64s(&cov)
        .f64s(&[0.01, -0.02, 0.03])
        .f64s(&cov)
        .f64s(&[0.1, 0.2, 9.81])
        .f64s(&cov)
        .0
}

/// A PointCloud2 of one point with float32 fields `names` (datatype 7, or `types` when given).
fn cloud(seq: u32, t_ns: u64, names: &[&str], types: &[u8]) -> Vec<u8> {
    let mut s = Ser::default()
        .header(seq, t_ns, "radar")
        .u32(1)
        .u32(1)
        .u32(names.len() as u32);
    for (k, n) in names.iter().enumerate() {
        s = s
            .string(n)
            .u32(4 * k as u32)
            .u8(types.get(k).copied().unwrap_or(7))
            .u32(1);
    }
    let step = 4 * names.len() as u32;
    let mut s = s.u8(0).u32(step).u32(step).u32(step);
    for k in 0..names.len() {
        s.0.extend((1.0f32 + k as f32).to_le_bytes());
    }
    s.u8(1).0
}

/// A bag with a radar topic (`scans`) and an IMU topic (`imus`), one message per entry.
fn bag(dir: &Path, name: &str, scans: &[Vec<u8>], imus: &[(u64, Vec<u8>)]) -> PathBuf {
    let mut recs = vec![
        connection(0, "/radar", "sensor_msgs/PointCloud2"),
        connection(1, "/imu", "sensor_msgs/Imu"),
    ];
    for (i, s) in scans.iter().enumerate() {
        let t = T0 + i as u64 * 100_000_000;
        recs.push(message(
            0,
            (t / 1_000_000_000) as u32,
            (t % 1_000_000_000) as u32,
            s,
        ));
    }
    for (t, m) in imus {
        recs.push(message(
            1,
            (t / 1_000_000_000) as u32,
            (t % 1_000_000_000) as u32,
            m,
        ));
    }
    hand_bag(dir, name, &[chunk("none", &recs)])
}

fn imus(n: u32, frame: &str) -> Vec<(u64, Vec<u8>)> {
    (0..n)
        .map(|i| {
            let t = T0 + u64::from(i) * 10_000_000;
            (t, imu(i, t, frame))
        })
        .collect()
}

fn good_scans(n: u32) -> Vec<Vec<u8>> {
    (0..n)
        .map(|i| {
            cloud(
                i,
                T0 + u64::from(i) * 100_000_000,
                &["x", "y", "z", "velocity"],
                &[],
            )
        })
        .collect()
}

fn run(p: &Path, opts: &ImportOptions) -> Result<milliego_import::ImportReport, ImportError> {
    let out = p.with_extension("session");
    import(&[p.to_path_buf()], &out, opts)
}

#[test]
fn a_good_hand_made_bag_imports() {
    let d = tempfile::tempdir().unwrap();
    let p = bag(d.path(), "good.bag", &good_scans(5), &imus(50, "imu"));
    let r = run(&p, &ImportOptions::default()).unwrap();
    let written: Vec<(String, u64)> = r
        .streams
        .iter()
        .map(|s| (s.stream.clone(), s.written))
        .collect();
    assert_eq!(written, [("radar".to_string(), 5), ("imu".to_string(), 50)]);
}

#[test]
fn a_scan_without_z_names_file_topic_message_and_fields() {
    let d = tempfile::tempdir().unwrap();
    let mut scans = good_scans(3);
    scans[2] = cloud(2, T0 + 200_000_000, &["x", "y", "velocity"], &[]);
    let p = bag(d.path(), "noz.bag", &scans, &imus(30, "imu"));
    let e = run(&p, &ImportOptions::default()).unwrap_err();
    assert!(matches!(e, ImportError::Layout { .. }), "{e:?}");
    let text = e.to_string();
    for want in [
        "noz.bag",
        "/radar message 2",
        "no field z",
        "fields: x, y, velocity",
    ] {
        assert!(text.contains(want), "`{want}` not in: {text}");
    }
}

#[test]
fn an_unknown_field_type_is_named() {
    let d = tempfile::tempdir().unwrap();
    let scans = vec![cloud(0, T0, &["x", "y", "z", "velocity"], &[7, 7, 7, 42])];
    let p = bag(d.path(), "type.bag", &scans, &imus(10, "imu"));
    let text = run(&p, &ImportOptions::default()).unwrap_err().to_string();
    for want in [
        "type.bag",
        "/radar message 0",
        "field velocity: datatype 42",
    ] {
        assert!(text.contains(want), "`{want}` not in: {text}");
    }
}

#[test]
fn a_cut_imu_message_names_the_field_and_offset() {
    let d = tempfile::tempdir().unwrap();
    let mut i = imus(20, "imu");
    let cut = i[7].1.len() - 30;
    i[7].1.truncate(cut);
    let p = bag(d.path(), "cut.bag", &good_scans(2), &i);
    let e = run(&p, &ImportOptions::default()).unwrap_err();
    assert!(matches!(e, ImportError::Message { .. }), "{e:?}");
    let text = e.to_string();
    for want in [
        "cut.bag",
        "/imu message 7",
        "linear_acceleration_covariance",
    ] {
        assert!(text.contains(want), "`{want}` not in: {text}");
    }
}

#[test]
fn an_imu_in_a_frame_the_calibration_does_not_describe_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let mut i = imus(20, "imu_link");
    i[4].1 = imu(4, i[4].0, "camera_link");
    let p = bag(d.path(), "frame.bag", &good_scans(2), &i);
    let calib_path = d.path().join("rig.toml");
    let calib = Calibration::from_toml("[imu]\nframe_id = \"imu_link\"\n", &calib_path).unwrap();
    let opts = ImportOptions {
        calib: Some(calib),
        ..ImportOptions::default()
    };
    let e = run(&p, &opts).unwrap_err();
    assert!(matches!(e, ImportError::Frame { .. }), "{e:?}");
    let text = e.to_string();
    for want in ["frame.bag", "/imu message 4", "camera_link", "imu_link"] {
        assert!(text.contains(want), "`{want}` not in: {text}");
    }
}

#[test]
fn missing_and_mistyped_topics_list_what_the_recording_has() {
    let d = tempfile::tempdir().unwrap();
    let p = bag(d.path(), "t.bag", &good_scans(2), &imus(10, "imu"));
    let opts = ImportOptions {
        imu_topic: Some("/nope".into()),
        ..ImportOptions::default()
    };
    let text = run(&p, &opts).unwrap_err().to_string();
    for want in [
        "imu topic",
        "/nope is not in the recording",
        "/radar (sensor_msgs/PointCloud2)",
    ] {
        assert!(text.contains(want), "`{want}` not in: {text}");
    }
    let opts = ImportOptions {
        imu_topic: Some("/radar".into()),
        ..ImportOptions::default()
    };
    let text = run(&p, &opts).unwrap_err().to_string();
    assert!(
        text.contains("/radar is sensor_msgs/PointCloud2, expected sensor_msgs/Imu"),
        "{text}"
    );
}

#[test]
fn stamps_going_back_are_dropped_counted_and_the_first_named() {
    let d = tempfile::tempdir().unwrap();
    let mut i = imus(400, "imu");
    // Message 300 is stamped 3 s before its predecessors: beyond the 2 s reordering window.
    i[300].1 = imu(300, i[300].0 - 3_000_000_000, "imu");
    let p = bag(d.path(), "back.bag", &good_scans(2), &i);
    let r = run(&p, &ImportOptions::default()).unwrap();
    let s = r.streams.iter().find(|s| s.stream == "imu").unwrap();
    assert_eq!(s.written, 399);
    assert_eq!(s.dropped.values().sum::<u64>(), 1, "{:?}", s.dropped);
    assert!(
        s.notes
            .iter()
            .any(|n| n.contains("back.bag: /imu message 300")),
        "{:?}",
        s.notes
    );
}

#[test]
fn a_truncated_bag_names_the_file_and_offset() {
    let d = tempfile::tempdir().unwrap();
    let p = bag(d.path(), "whole.bag", &good_scans(3), &imus(30, "imu"));
    let bytes = std::fs::read(&p).unwrap();
    let cut = d.path().join("cut.bag");
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    let e = run(&cut, &ImportOptions::default()).unwrap_err();
    let text = e.to_string();
    assert!(text.contains("cut.bag"), "{text}");
    match e {
        ImportError::Source(SourceError::Corrupt { path, at, .. }) => {
            assert_eq!(path, cut);
            assert!(at > 4096 && at < bytes.len() as u64, "offset {at}");
            assert!(text.contains(&at.to_string()), "{text}");
        }
        other => panic!("{other:?}"),
    }
}
