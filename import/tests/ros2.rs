//! The ROS 2 bag and MCAP readers against recordings written by independent writers
//! (`rosbags` for ROS 2 bags with sqlite3 and mcap storage, plain and zstd-compressed; `mcap` +
//! `mcap_ros2` for plain MCAP files with zstd, lz4 and uncompressed chunks): topics, counts,
//! times and payload bytes equal the writer's manifest, and the payloads decode with this
//! crate's CDR decoders to the values written. Truncated or corrupt files and broken
//! `metadata.yaml` give errors naming the file and the place, never a panic.

mod common;

use milliego_import::ros::{
    normalise_type, Encoding, FluidPressure, Header, Imu, Odometry, PointCloud2, RosMsg, TfMessage,
};
use milliego_import::source::mcap::McapFile;
use milliego_import::source::ros2::{Compression, Ros2Bag, Storage};
use milliego_import::source::{self, Source, SourceError, TopicInfo};
use milliego_import::ImportError;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The recordings and the manifest, written once per test run.
fn fixtures() -> Option<&'static (PathBuf, Value)> {
    static F: OnceLock<Option<(PathBuf, Value)>> = OnceLock::new();
    F.get_or_init(|| {
        let py = common::ros_python()?;
        // One directory per process: nextest runs each test in its own process, and a shared
        // directory was removed and rewritten under the other tests' feet.
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("import-ros2-fixtures-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let out = common::run_py(&py, "write_ros2.py", &[dir.to_str().unwrap()]);
        let manifest: Value = serde_json::from_str(&out).expect("manifest is JSON");
        Some((dir, manifest))
    })
    .as_ref()
}

/// One message as a reader gave it.
#[derive(Debug, Clone, PartialEq)]
struct Got {
    topic: String,
    msg_type: String,
    log_time_ns: u64,
    index: u64,
    data: Vec<u8>,
    encoding: Encoding,
}

fn read_all(src: &mut dyn Source, topics: &[&str]) -> Result<Vec<Got>, ImportError> {
    let mut out = Vec::new();
    read_into(src, topics, &mut out)?;
    Ok(out)
}

fn read_into(src: &mut dyn Source, topics: &[&str], out: &mut Vec<Got>) -> Result<(), ImportError> {
    src.for_each(topics, &mut |m| {
        out.push(Got {
            topic: m.topic.into(),
            msg_type: m.msg_type.into(),
            log_time_ns: m.log_time_ns,
            index: m.index,
            data: m.data.to_vec(),
            encoding: m.encoding,
        });
        Ok(())
    })
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

/// What a file should yield: the manifest's messages with that file's payloads.
fn expected(manifest: &Value, file: &str) -> Vec<Got> {
    let payloads = manifest["files"][file]["payloads"].as_array().unwrap();
    let msgs = manifest["messages"].as_array().unwrap();
    assert_eq!(payloads.len(), msgs.len());
    let mut seen = std::collections::HashMap::<String, u64>::new();
    msgs.iter()
        .zip(payloads)
        .map(|(m, p)| {
            let topic = m["topic"].as_str().unwrap().to_string();
            let i = seen.entry(topic.clone()).or_insert(0);
            let index = *i;
            *i += 1;
            Got {
                topic,
                msg_type: normalise_type(m["type"].as_str().unwrap()),
                log_time_ns: m["log_time_ns"].as_u64().unwrap(),
                index,
                data: unhex(p.as_str().unwrap()),
                encoding: Encoding::Cdr,
            }
        })
        .collect()
}

fn expected_topics(msgs: &[Got]) -> Vec<TopicInfo> {
    let mut out: Vec<TopicInfo> = Vec::new();
    for m in msgs {
        match out.iter_mut().find(|t| t.topic == m.topic) {
            Some(t) => {
                t.count += 1;
                let (a, b) = t.span_ns.unwrap();
                t.span_ns = Some((a.min(m.log_time_ns), b.max(m.log_time_ns)));
            }
            None => out.push(TopicInfo {
                topic: m.topic.clone(),
                msg_type: m.msg_type.clone(),
                count: 1,
                span_ns: Some((m.log_time_ns, m.log_time_ns)),
            }),
        }
    }
    out.sort_by(|a, b| a.topic.cmp(&b.topic));
    out
}

fn sorted(mut t: Vec<TopicInfo>) -> Vec<TopicInfo> {
    t.sort_by(|a, b| a.topic.cmp(&b.topic));
    t
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn check_header(h: &Header, c: &Value) {
    assert_eq!(h.stamp_ns, c["stamp_ns"].as_i64().unwrap());
    assert_eq!(h.frame_id, c["frame_id"].as_str().unwrap());
    assert_eq!(h.seq, None);
}

/// Decodes `m` with this crate's decoders and compares with the values the writer was given.
fn check_values(m: &Got, c: &Value) {
    let e = m.encoding;
    let ctx = format!("{} #{}", m.topic, m.index);
    match m.msg_type.as_str() {
        "sensor_msgs/PointCloud2" => {
            let p = PointCloud2::decode(&m.data, e).expect(&ctx);
            check_header(&p.header, &c["header"]);
            assert_eq!(p.height as u64, c["height"].as_u64().unwrap());
            assert_eq!(p.width as u64, c["width"].as_u64().unwrap());
            assert_eq!(p.point_step as u64, c["point_step"].as_u64().unwrap());
            assert_eq!(p.row_step as u64, c["row_step"].as_u64().unwrap());
            assert_eq!(p.is_bigendian, c["is_bigendian"].as_bool().unwrap());
            assert_eq!(p.is_dense, c["is_dense"].as_bool().unwrap());
            assert_eq!(p.data, unhex(c["data_hex"].as_str().unwrap()));
            let fields = c["fields"].as_array().unwrap();
            assert_eq!(p.fields.len(), fields.len());
            for (f, want) in p.fields.iter().zip(fields) {
                assert_eq!(f.name, want[0].as_str().unwrap());
                assert_eq!(f.offset as u64, want[1].as_u64().unwrap());
                assert_eq!(f.datatype as u64, want[2].as_u64().unwrap());
                assert_eq!(f.count as u64, want[3].as_u64().unwrap());
            }
        }
        "sensor_msgs/Imu" => {
            let i = Imu::decode(&m.data, e).expect(&ctx);
            check_header(&i.header, &c["header"]);
            assert_eq!(i.orientation.to_vec(), f64s(&c["orientation"]));
            assert_eq!(
                i.orientation_covariance.to_vec(),
                f64s(&c["orientation_covariance"])
            );
            assert_eq!(i.angular_velocity.to_vec(), f64s(&c["angular_velocity"]));
            assert_eq!(
                i.angular_velocity_covariance.to_vec(),
                f64s(&c["angular_velocity_covariance"])
            );
            assert_eq!(
                i.linear_acceleration.to_vec(),
                f64s(&c["linear_acceleration"])
            );
            assert_eq!(
                i.linear_acceleration_covariance.to_vec(),
                f64s(&c["linear_acceleration_covariance"])
            );
        }
        "sensor_msgs/FluidPressure" => {
            let p = FluidPressure::decode(&m.data, e).expect(&ctx);
            check_header(&p.header, &c["header"]);
            assert_eq!(p.fluid_pressure, c["fluid_pressure"].as_f64().unwrap());
            assert_eq!(p.variance, c["variance"].as_f64().unwrap());
        }
        "std_msgs/Header" => {
            let h = Header::decode(&m.data, e).expect(&ctx);
            check_header(&h, &c["header"]);
        }
        "nav_msgs/Odometry" => {
            let o = Odometry::decode(&m.data, e).expect(&ctx);
            check_header(&o.header, &c["header"]);
            assert_eq!(o.child_frame_id, c["child_frame_id"].as_str().unwrap());
            assert_eq!(o.pose.position.to_vec(), f64s(&c["position"]));
            assert_eq!(o.pose.orientation.to_vec(), f64s(&c["orientation"]));
            assert_eq!(o.pose_covariance.to_vec(), f64s(&c["pose_covariance"]));
            assert_eq!(o.linear_velocity.to_vec(), f64s(&c["linear_velocity"]));
            assert_eq!(o.angular_velocity.to_vec(), f64s(&c["angular_velocity"]));
            assert_eq!(o.twist_covariance.to_vec(), f64s(&c["twist_covariance"]));
        }
        "tf2_msgs/TFMessage" => {
            let tf = TfMessage::decode(&m.data, e).expect(&ctx);
            let want = c["transforms"].as_array().unwrap();
            assert_eq!(tf.transforms.len(), want.len(), "{ctx}");
            for (t, w) in tf.transforms.iter().zip(want) {
                check_header(&t.header, &w["header"]);
                assert_eq!(t.child_frame_id, w["child_frame_id"].as_str().unwrap());
                assert_eq!(t.translation.to_vec(), f64s(&w["translation"]));
                assert_eq!(t.rotation.to_vec(), f64s(&w["rotation"]));
            }
        }
        other => panic!("unexpected type {other}"),
    }
}

/// Every file of the fixture: topics, messages, payloads and decoded values.
fn check_file(name: &str) {
    let Some((dir, manifest)) = fixtures() else {
        return;
    };
    let path = dir.join(name);
    let want = expected(manifest, name);
    let mut src = source::open(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(src.path(), path);
    let topics = src.topics().unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(sorted(topics), expected_topics(&want), "{name}");
    let got = read_all(src.as_mut(), &[]).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(got.len(), want.len(), "{name}");
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(g, w, "{name}");
    }
    let msgs = manifest["messages"].as_array().unwrap();
    for (g, m) in got.iter().zip(msgs) {
        check_values(g, &m["check"]);
    }
    // One topic: only its messages, indices from 0.
    let imu = read_all(src.as_mut(), &["/imu/data"]).unwrap();
    let want_imu: Vec<_> = want
        .iter()
        .filter(|m| m.topic == "/imu/data")
        .cloned()
        .collect();
    assert_eq!(imu, want_imu, "{name}");
    assert_eq!(imu.len(), 5);
    // Two topics, one absent: fine.
    let two = read_all(src.as_mut(), &["/baro", "/tf", "/nothing"]).unwrap();
    assert_eq!(two.len(), 4, "{name}");
}

#[test]
fn ros2_bag_sqlite3() {
    check_file("sqlite_bag");
    let Some((dir, _)) = fixtures() else { return };
    let bag = Ros2Bag::open(&dir.join("sqlite_bag")).unwrap();
    assert_eq!(bag.metadata().storage, Storage::Sqlite3);
    assert_eq!(bag.metadata().compression, Compression::None);
    assert_eq!(bag.metadata().topics.len(), 6);
    assert_eq!(
        bag.metadata().files,
        vec![dir.join("sqlite_bag/sqlite_bag.db3")]
    );
}

#[test]
fn ros2_bag_mcap_storage() {
    check_file("mcap_bag");
    let Some((dir, _)) = fixtures() else { return };
    let bag = Ros2Bag::open(&dir.join("mcap_bag")).unwrap();
    assert_eq!(bag.metadata().storage, Storage::Mcap);
}

#[test]
fn ros2_bag_zstd_message_and_file_mode() {
    check_file("sqlite_msg_zstd");
    check_file("sqlite_file_zstd");
    let Some((dir, _)) = fixtures() else { return };
    let m = Ros2Bag::open(&dir.join("sqlite_msg_zstd")).unwrap();
    assert_eq!(m.metadata().compression, Compression::Message);
    let f = Ros2Bag::open(&dir.join("sqlite_file_zstd")).unwrap();
    assert_eq!(f.metadata().compression, Compression::File);
}

#[test]
fn plain_mcap_zstd_lz4_and_uncompressed_chunks() {
    check_file("plain_zstd.mcap");
    check_file("plain_lz4.mcap");
    check_file("plain_none.mcap");
}

fn corrupt_of(e: &ImportError) -> (&Path, u64, &str) {
    match e {
        ImportError::Source(SourceError::Corrupt { path, at, why }) => (path, *at, why),
        e => panic!("expected a Corrupt error, got {e:?}"),
    }
}

#[test]
fn truncated_mcap_errors_name_file_and_offset() {
    let Some((dir, manifest)) = fixtures() else {
        return;
    };
    let scratch = tempfile::tempdir().unwrap();
    for name in ["plain_zstd.mcap", "plain_none.mcap"] {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        let want = expected(manifest, name);
        let cut_path = scratch.path().join(name);
        let mut cuts: Vec<usize> = (0..bytes.len()).step_by(61).collect();
        cuts.extend([bytes.len() - 1, bytes.len() - 8, bytes.len() - 9]);
        for cut in cuts {
            std::fs::write(&cut_path, &bytes[..cut]).unwrap();
            let mut f = match McapFile::open(&cut_path) {
                Ok(f) => f,
                Err(SourceError::UnknownFormat { path, .. }) if cut < 8 => {
                    assert_eq!(path, cut_path);
                    continue;
                }
                Err(e) => panic!("{name} cut at {cut}: {e}"),
            };
            let e = f
                .topics()
                .expect_err("a truncated file has no complete topic list");
            let e = ImportError::from(e);
            let (path, at, _) = corrupt_of(&e);
            assert_eq!(path, cut_path);
            assert!(at <= cut as u64, "{name} cut {cut}: {e}");
            let mut got = Vec::new();
            let e = read_into(&mut f, &[], &mut got).expect_err("truncated");
            let (path, at, why) = corrupt_of(&e);
            assert_eq!(path, cut_path);
            assert!(at <= cut as u64, "{name} cut {cut}: {e}");
            assert!(!why.is_empty());
            assert!(e.to_string().contains(name), "{e}");
            // What came before the cut came out right.
            assert!(got.len() <= want.len());
            assert_eq!(got[..], want[..got.len()], "{name} cut {cut}");
        }
    }
}

#[test]
fn corrupt_chunk_is_an_error_but_the_summary_still_lists_topics() {
    let Some((dir, manifest)) = fixtures() else {
        return;
    };
    let name = "plain_none.mcap";
    let mut bytes = std::fs::read(dir.join(name)).unwrap();
    let want = expected(manifest, name);
    // Flip a byte inside the payload of the 6th message (uncompressed chunk: the bytes are there).
    let payload = &want[5].data;
    let at = bytes
        .windows(payload.len())
        .position(|w| w == &payload[..])
        .expect("payload in the file");
    bytes[at + payload.len() / 2] ^= 0x55;
    let scratch = tempfile::tempdir().unwrap();
    let p = scratch.path().join(name);
    std::fs::write(&p, &bytes).unwrap();
    let mut f = McapFile::open(&p).unwrap();
    // The summary (channels, statistics, message indexes) is intact.
    assert_eq!(sorted(f.topics().unwrap()), expected_topics(&want));
    let e = read_all(&mut f, &[]).expect_err("chunk CRC");
    let (path, _, why) = corrupt_of(&e);
    assert_eq!(path, p);
    assert!(why.contains("CRC"), "{e}");
}

#[test]
fn a_chunk_overrunning_itself_stops_reading_there_after_the_messages_before_it() {
    let Some((dir, manifest)) = fixtures() else {
        return;
    };
    let name = "plain_none.mcap";
    let mut bytes = std::fs::read(dir.join(name)).unwrap();
    let want = expected(manifest, name);
    // The last message's record (uncompressed chunks, small: earlier messages lie in earlier
    // chunks) claims 1 MiB, far more than its chunk holds. Its header sits 9 + 22 bytes (channel,
    // sequence, log and publish time) before its payload.
    let k = want.len() - 1;
    let payload = &want[k].data;
    let at = bytes
        .windows(payload.len())
        .position(|w| w == &payload[..])
        .expect("payload in the file")
        - 31;
    assert_eq!(bytes[at], 0x05, "a message record's opcode");
    bytes[at + 1..at + 9].copy_from_slice(&(1u64 << 20).to_le_bytes());
    let scratch = tempfile::tempdir().unwrap();
    let p = scratch.path().join(name);
    std::fs::write(&p, &bytes).unwrap();
    let mut f = McapFile::open(&p).unwrap();
    let mut got = Vec::new();
    let e = read_into(&mut f, &[], &mut got).expect_err("the chunk overruns itself");
    let (path, chunk_at, why) = corrupt_of(&e);
    assert_eq!(path, p);
    assert!(why.contains("claims 1048576 B"), "{e}");
    assert!(chunk_at < at as u64, "{e}");
    // Everything before that chunk came out, and came out right.
    assert!(
        !got.is_empty() && got.len() < want.len(),
        "{} messages",
        got.len()
    );
    assert_eq!(got[..], want[..got.len()]);
}

#[test]
fn flipped_bytes_never_panic() {
    let Some((dir, _)) = fixtures() else {
        return;
    };
    let scratch = tempfile::tempdir().unwrap();
    for name in [
        "plain_zstd.mcap",
        "plain_lz4.mcap",
        "mcap_bag/mcap_bag.mcap",
    ] {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        let p = scratch.path().join("x.mcap");
        for at in (8..bytes.len()).step_by(53) {
            let mut b = bytes.clone();
            b[at] ^= 0xA5;
            std::fs::write(&p, &b).unwrap();
            let mut f = McapFile::open(&p).unwrap();
            let _ = f.topics();
            let _ = read_all(&mut f, &[]);
        }
    }
}

/// A copy of bag `name` in a scratch directory, for breaking.
fn copy_bag(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

#[test]
fn truncated_db3_errors_name_the_file() {
    let Some((dir, manifest)) = fixtures() else {
        return;
    };
    let scratch = tempfile::tempdir().unwrap();
    let bag = scratch.path().join("bag");
    copy_bag(&dir.join("sqlite_bag"), &bag);
    let db = bag.join("sqlite_bag.db3");
    let bytes = std::fs::read(&db).unwrap();
    let want = expected(manifest, "sqlite_bag");
    // sqlite itself reads a cut-off tail as zeros without an error; the reader checks the
    // length against the header, so every cut is an error, and what came before it is right.
    for cut in (0..bytes.len())
        .step_by(1021)
        .chain([4096, bytes.len() - 4096])
    {
        std::fs::write(&db, &bytes[..cut]).unwrap();
        let mut b = Ros2Bag::open(&bag).unwrap();
        let e = b.topics().expect_err("truncated");
        assert_eq!(corrupt_of(&e.into()).0, db, "cut {cut}");
        let mut got = Vec::new();
        let e = read_into(&mut b, &[], &mut got).expect_err("truncated");
        let (path, _, why) = corrupt_of(&e);
        assert_eq!(path, db, "cut {cut}");
        assert!(why.contains("truncated") || why.contains("sqlite"), "{e}");
        assert!(e.to_string().contains("sqlite_bag.db3"), "{e}");
        assert!(got.len() <= want.len());
        assert_eq!(got[..], want[..got.len()], "cut {cut}");
    }
}

#[test]
fn truncated_zstd_file_mode_names_the_compressed_file() {
    let Some((dir, _)) = fixtures() else {
        return;
    };
    let scratch = tempfile::tempdir().unwrap();
    let bag = scratch.path().join("bag");
    copy_bag(&dir.join("sqlite_file_zstd"), &bag);
    let z = bag.join("sqlite_file_zstd.db3.zstd");
    let bytes = std::fs::read(&z).unwrap();
    for cut in (0..bytes.len()).step_by(97) {
        std::fs::write(&z, &bytes[..cut]).unwrap();
        let mut b = Ros2Bag::open(&bag).unwrap();
        let e = read_all(&mut b, &[]).expect_err("truncated");
        let (path, at, _) = corrupt_of(&e);
        assert_eq!(path, z, "cut {cut}: {e}");
        assert!(at <= cut as u64, "cut {cut}: {e}");
    }
}

#[test]
fn broken_metadata_yaml_names_the_file_and_the_key() {
    let Some((dir, _)) = fixtures() else {
        return;
    };
    let scratch = tempfile::tempdir().unwrap();
    let bag = scratch.path().join("bag");
    copy_bag(&dir.join("sqlite_bag"), &bag);
    let yaml = bag.join("metadata.yaml");
    let good = std::fs::read_to_string(&yaml).unwrap();

    let without = |key: &str| -> String {
        good.lines()
            .filter(|l| l.trim_start().split(':').next() != Some(key))
            .collect::<Vec<_>>()
            .join("\n")
    };
    for key in ["storage_identifier", "version"] {
        std::fs::write(&yaml, without(key)).unwrap();
        let e = Ros2Bag::open(&bag).unwrap_err();
        match &e {
            SourceError::Corrupt { path, why, .. } => {
                assert_eq!(path, &yaml);
                assert!(why.contains(key), "{e}");
            }
            e => panic!("{e:?}"),
        }
        assert!(e.to_string().contains("metadata.yaml"), "{e}");
    }

    std::fs::write(
        &yaml,
        good.replace(
            "storage_identifier: sqlite3",
            "storage_identifier: rosbag_v2",
        ),
    )
    .unwrap();
    match Ros2Bag::open(&bag).unwrap_err() {
        SourceError::Unsupported { path, what } => {
            assert_eq!(path, yaml);
            assert!(what.contains("rosbag_v2") && what.contains("storage_identifier"));
        }
        e => panic!("{e:?}"),
    }

    std::fs::write(
        &yaml,
        good.replace("compression_mode: ''", "compression_mode: file")
            .replace("compression_format: ''", "compression_format: lz4"),
    )
    .unwrap();
    match Ros2Bag::open(&bag).unwrap_err() {
        SourceError::Unsupported { path, what } => {
            assert_eq!(path, yaml);
            assert!(what.contains("lz4") && what.contains("file"), "{what}");
        }
        e => panic!("{e:?}"),
    }

    // A YAML syntax error: the offset and line.
    let broken = good.replacen("  version:", "  version: [", 1);
    std::fs::write(&yaml, &broken).unwrap();
    match Ros2Bag::open(&bag).unwrap_err() {
        SourceError::Corrupt { path, at, why } => {
            assert_eq!(path, yaml);
            assert!(at > 0 && why.contains("line"), "{at} {why}");
        }
        e => panic!("{e:?}"),
    }

    // Cut anywhere: an error or (a cut after the last key) a bag, never a panic.
    for cut in (0..good.len()).step_by(37) {
        std::fs::write(&yaml, &good[..cut]).unwrap();
        if let Err(e) = Ros2Bag::open(&bag) {
            assert!(e.to_string().contains("metadata.yaml"), "cut {cut}: {e}");
        }
    }

    // A file the metadata names but the directory lacks.
    std::fs::write(&yaml, good.replace("- sqlite_bag.db3", "- gone.db3")).unwrap();
    let mut b = Ros2Bag::open(&bag).unwrap();
    match b.topics().unwrap_err() {
        SourceError::Io { path, .. } => assert_eq!(path, bag.join("gone.db3")),
        e => panic!("{e:?}"),
    }

    // No metadata.yaml at all.
    std::fs::remove_file(&yaml).unwrap();
    assert!(matches!(
        source::open(&bag),
        Err(SourceError::UnknownFormat { .. })
    ));
}

#[test]
fn open_dispatches_on_directory_and_magic() {
    let Some((dir, _)) = fixtures() else {
        return;
    };
    // A directory is a ROS 2 bag; an MCAP file by its magic, whatever its name.
    let scratch = tempfile::tempdir().unwrap();
    let renamed = scratch.path().join("recording.bin");
    std::fs::copy(dir.join("plain_lz4.mcap"), &renamed).unwrap();
    let mut m = source::open(&renamed).unwrap();
    assert_eq!(m.topics().unwrap().len(), 6);
    let mut d = source::open(&dir.join("mcap_bag")).unwrap();
    assert_eq!(d.topics().unwrap().len(), 6);
    // McapFile refuses a non-MCAP file by its magic.
    let db = dir.join("sqlite_bag/sqlite_bag.db3");
    assert!(matches!(
        McapFile::open(&db),
        Err(SourceError::UnknownFormat { .. })
    ));
    assert!(matches!(
        source::open(&db),
        Err(SourceError::UnknownFormat { .. })
    ));
}

#[test]
fn mcap_ros1_channels() {
    let Some((dir, manifest)) = fixtures() else {
        return;
    };
    let want = manifest["ros1"].as_array().unwrap();
    let mut f = McapFile::open(&dir.join("ros1.mcap")).unwrap();
    let topics = sorted(f.topics().unwrap());
    assert_eq!(
        topics
            .iter()
            .map(|t| (t.topic.as_str(), t.msg_type.as_str(), t.count))
            .collect::<Vec<_>>(),
        [
            ("/hdr1", "std_msgs/Header", 4),
            ("/imu1", "sensor_msgs/Imu", 4)
        ]
    );
    let got = read_all(&mut f, &[]).unwrap();
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g.encoding, Encoding::Ros1);
        assert_eq!(g.topic, w["topic"].as_str().unwrap());
        assert_eq!(g.msg_type, w["type"].as_str().unwrap());
        assert_eq!(g.log_time_ns, w["log_time_ns"].as_u64().unwrap());
        assert_eq!(g.data, unhex(w["payload"].as_str().unwrap()));
        let h = if g.topic == "/imu1" {
            let imu = Imu::decode(&g.data, Encoding::Ros1).unwrap();
            assert_eq!(imu.angular_velocity[0], w["gyro_x"].as_f64().unwrap());
            assert_eq!(imu.linear_acceleration, [0.0, 0.125, 9.8125]);
            imu.header
        } else {
            Header::decode(&g.data, Encoding::Ros1).unwrap()
        };
        assert_eq!(h.seq, Some(w["seq"].as_u64().unwrap() as u32));
        assert_eq!(h.stamp_ns, w["stamp_ns"].as_i64().unwrap());
        assert_eq!(h.frame_id, w["frame_id"].as_str().unwrap());
    }
}

/// A bag of two storage files (the same file twice under two names): the files are read in
/// `relative_file_paths` order, topics merge, and the per-topic index runs on across files.
#[test]
fn multi_file_bags() {
    let Some((dir, manifest)) = fixtures() else {
        return;
    };
    for (bag_name, file, ext) in [
        ("sqlite_bag", "sqlite_bag.db3", "db3"),
        ("mcap_bag", "mcap_bag.mcap", "mcap"),
    ] {
        let scratch = tempfile::tempdir().unwrap();
        let bag = scratch.path().join("bag");
        std::fs::create_dir_all(&bag).unwrap();
        for n in ["a", "b"] {
            std::fs::copy(
                dir.join(bag_name).join(file),
                bag.join(format!("{n}.{ext}")),
            )
            .unwrap();
        }
        let yaml = std::fs::read_to_string(dir.join(bag_name).join("metadata.yaml")).unwrap();
        let yaml = yaml.replace(
            &format!("relative_file_paths:\n  - {file}"),
            &format!("relative_file_paths:\n  - a.{ext}\n  - b.{ext}"),
        );
        assert!(yaml.contains("b.db3") || yaml.contains("b.mcap"), "{yaml}");
        std::fs::write(bag.join("metadata.yaml"), yaml).unwrap();
        let one = expected(manifest, bag_name);
        let mut b = Ros2Bag::open(&bag).unwrap();
        assert_eq!(
            b.metadata().files,
            [bag.join(format!("a.{ext}")), bag.join(format!("b.{ext}"))]
        );
        let topics = sorted(b.topics().unwrap());
        let want_topics: Vec<_> = expected_topics(&one)
            .into_iter()
            .map(|t| TopicInfo {
                count: 2 * t.count,
                ..t
            })
            .collect();
        assert_eq!(topics, want_topics, "{bag_name}");
        let got = read_all(&mut b, &["/imu/data"]).unwrap();
        assert_eq!(got.len(), 10);
        for (i, g) in got.iter().enumerate() {
            assert_eq!(g.index, i as u64, "{bag_name}");
            assert_eq!(
                g.data,
                one.iter()
                    .filter(|m| m.topic == "/imu/data")
                    .nth(i % 5)
                    .unwrap()
                    .data
            );
        }
    }
}
