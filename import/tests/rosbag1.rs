//! The ROS 1 bag reader against bags written by the independent `rosbags` writer
//! (`tests/py/write_bag1.py`), and against damaged and hand-made bags.

mod common;

use common::{chunk, connection, hand_bag, message, record};

use milliego_import::ros::{Encoding, Header, Imu, PointCloud2, PoseStamped, RosMsg};
use milliego_import::source::rosbag1::{Bag1, MAGIC};
use milliego_import::source::{self, Source, SourceError, TopicInfo};
use milliego_import::ImportError;
use serde_json::Value;
use std::path::{Path, PathBuf};

const COMPRESSIONS: [&str; 3] = ["none", "bz2", "lz4"];

/// The bags the Python writer made, in a temporary directory, and its manifest.
struct Written {
    _dir: tempfile::TempDir,
    manifest: Value,
}

impl Written {
    fn bag(&self, compression: &str) -> PathBuf {
        PathBuf::from(self.manifest["bags"][compression].as_str().unwrap())
    }
}

fn write_bags() -> Option<Written> {
    let py = common::ros_python()?;
    let dir = tempfile::tempdir().unwrap();
    let out = common::run_py(&py, "write_bag1.py", &[dir.path().to_str().unwrap()]);
    let manifest = serde_json::from_str(&out).expect("the manifest is JSON");
    Some(Written {
        _dir: dir,
        manifest,
    })
}

fn expected_topics(m: &Value) -> Vec<TopicInfo> {
    let span = |t: &Value| Some((t["first_ns"].as_u64()?, t["last_ns"].as_u64()?));
    m["topics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| TopicInfo {
            topic: t["topic"].as_str().unwrap().into(),
            msg_type: t["type"].as_str().unwrap().into(),
            count: t["count"].as_u64().unwrap(),
            span_ns: span(t),
        })
        .collect()
}

/// A message as read, owned.
#[derive(Debug, Clone, PartialEq)]
struct Msg {
    topic: String,
    msg_type: String,
    log_time_ns: u64,
    index: u64,
    data: Vec<u8>,
}

fn read_all(src: &mut dyn Source, topics: &[&str]) -> Result<Vec<Msg>, ImportError> {
    let mut out = Vec::new();
    src.for_each(topics, &mut |m| {
        assert_eq!(m.encoding, Encoding::Ros1);
        out.push(Msg {
            topic: m.topic.into(),
            msg_type: m.msg_type.into(),
            log_time_ns: m.log_time_ns,
            index: m.index,
            data: m.data.to_vec(),
        });
        Ok(())
    })?;
    Ok(out)
}

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

/// The manifest's messages, with their per-topic index.
fn expected_messages(m: &Value) -> Vec<Msg> {
    let mut counts = std::collections::HashMap::<String, u64>::new();
    m["messages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            let topic = e["topic"].as_str().unwrap().to_string();
            let n = counts.entry(topic.clone()).or_default();
            *n += 1;
            Msg {
                topic,
                msg_type: e["type"].as_str().unwrap().into(),
                log_time_ns: e["log_time_ns"].as_u64().unwrap(),
                index: *n - 1,
                data: hex(e["hex"].as_str().unwrap()),
            }
        })
        .collect()
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn check_header(h: &Header, v: &Value) {
    assert_eq!(h.seq, Some(v["seq"].as_u64().unwrap() as u32));
    assert_eq!(h.stamp_ns, v["stamp_ns"].as_i64().unwrap());
    assert_eq!(h.frame_id, v["frame_id"].as_str().unwrap());
}

/// Decodes `data` as `msg_type` and checks it against the values the writer set.
fn check_values(msg_type: &str, data: &[u8], v: &Value) {
    match msg_type {
        "std_msgs/Header" => {
            check_header(&Header::decode(data, Encoding::Ros1).unwrap(), &v["header"])
        }
        "sensor_msgs/Imu" => {
            let m = Imu::decode(data, Encoding::Ros1).unwrap();
            check_header(&m.header, &v["header"]);
            assert_eq!(m.orientation.to_vec(), f64s(&v["orientation"]));
            assert_eq!(m.angular_velocity.to_vec(), f64s(&v["angular_velocity"]));
            assert_eq!(
                m.linear_acceleration.to_vec(),
                f64s(&v["linear_acceleration"])
            );
            assert_eq!(m.angular_velocity_covariance, [0.5; 9]);
        }
        "sensor_msgs/PointCloud2" => {
            let m = PointCloud2::decode(data, Encoding::Ros1).unwrap();
            check_header(&m.header, &v["header"]);
            assert_eq!(
                (m.height, u64::from(m.width)),
                (1, v["width"].as_u64().unwrap())
            );
            let names: Vec<&str> = m.fields.iter().map(|f| f.name.as_str()).collect();
            let want: Vec<&str> = v["fields"]
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_str().unwrap())
                .collect();
            assert_eq!(names, want);
            assert!(m
                .fields
                .iter()
                .enumerate()
                .all(|(k, f)| f.offset == 4 * k as u32 && f.datatype == 7));
            assert_eq!(u64::from(m.point_step), v["point_step"].as_u64().unwrap());
            assert_eq!(m.row_step, m.point_step * m.width);
            assert_eq!(m.data, hex(v["data"].as_str().unwrap()));
            assert!(m.is_dense && !m.is_bigendian);
        }
        "geometry_msgs/PoseStamped" => {
            let m = PoseStamped::decode(data, Encoding::Ros1).unwrap();
            check_header(&m.header, &v["header"]);
            assert_eq!(m.pose.position.to_vec(), f64s(&v["position"]));
            assert_eq!(m.pose.orientation.to_vec(), f64s(&v["orientation"]));
        }
        other => panic!("the manifest has a type the test does not check: {other}"),
    }
}

#[test]
fn bags_read_as_the_writer_wrote_them() {
    let Some(w) = write_bags() else { return };
    let topics = expected_topics(&w.manifest);
    let messages = expected_messages(&w.manifest);
    for c in COMPRESSIONS {
        let mut bag = Bag1::open(&w.bag(c)).unwrap();
        assert!(bag.is_indexed());
        assert_eq!(bag.topics().unwrap(), topics, "{c}: topics");
        assert_eq!(read_all(&mut bag, &[]).unwrap(), messages, "{c}: messages");
    }
}

#[test]
fn payloads_decode_to_the_values_written() {
    let Some(w) = write_bags() else { return };
    let entries = w.manifest["messages"].as_array().unwrap();
    for c in COMPRESSIONS {
        let got = read_all(&mut Bag1::open(&w.bag(c)).unwrap(), &[]).unwrap();
        assert_eq!(got.len(), entries.len());
        for (m, e) in got.iter().zip(entries) {
            check_values(&m.msg_type, &m.data, &e["values"]);
        }
    }
}

#[test]
fn for_each_filters_by_topic() {
    let Some(w) = write_bags() else { return };
    let all = expected_messages(&w.manifest);
    let want: Vec<Msg> = all
        .iter()
        .filter(|m| m.topic == "/imu" || m.topic == "/pose")
        .cloned()
        .collect();
    for c in COMPRESSIONS {
        let got = read_all(&mut Bag1::open(&w.bag(c)).unwrap(), &["/pose", "/imu"]).unwrap();
        assert_eq!(got, want, "{c}");
        assert!(read_all(&mut Bag1::open(&w.bag(c)).unwrap(), &["/nothing"])
            .unwrap()
            .is_empty());
    }
}

#[test]
fn for_each_stops_at_the_callbacks_error() {
    let Some(w) = write_bags() else { return };
    let mut bag = Bag1::open(&w.bag("lz4")).unwrap();
    let mut seen = 0;
    let r = bag.for_each(&[], &mut |_| {
        seen += 1;
        if seen == 3 {
            Err(ImportError::Source(SourceError::Unsupported {
                path: "x".into(),
                what: "stop".into(),
            }))
        } else {
            Ok(())
        }
    });
    assert!(matches!(
        r,
        Err(ImportError::Source(SourceError::Unsupported { .. }))
    ));
    assert_eq!(seen, 3);
}

#[test]
fn open_picks_the_bag1_reader() {
    let Some(w) = write_bags() else { return };
    let topics = expected_topics(&w.manifest);
    for c in COMPRESSIONS {
        let mut src = source::open(&w.bag(c)).unwrap();
        assert_eq!(src.path(), w.bag(c));
        assert_eq!(src.topics().unwrap(), topics, "{c}");
    }
}

/// `index_pos` of a bag's header: the first record after the magic, whose fields are
/// `u32 len, name=value`.
fn index_pos_field(bytes: &[u8]) -> usize {
    let key = b"index_pos=";
    let at = bytes[..4096]
        .windows(key.len())
        .position(|w| w == key)
        .unwrap();
    at + key.len()
}

fn index_pos(bytes: &[u8]) -> u64 {
    let at = index_pos_field(bytes);
    u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap())
}

#[test]
fn unindexed_bags_list_topics_by_scanning() {
    let Some(w) = write_bags() else { return };
    let topics = expected_topics(&w.manifest);
    let messages = expected_messages(&w.manifest);
    let dir = tempfile::tempdir().unwrap();
    for c in COMPRESSIONS {
        let full = std::fs::read(w.bag(c)).unwrap();
        let mut cut = full[..index_pos(&full) as usize].to_vec();
        // Cut before the index, header still pointing at it (now the end of the file).
        let p = dir.path().join(format!("{c}-cut.bag"));
        std::fs::write(&p, &cut).unwrap();
        let mut bag = Bag1::open(&p).unwrap();
        assert_eq!(bag.topics().unwrap(), topics, "{c}: cut");
        assert_eq!(read_all(&mut bag, &[]).unwrap(), messages, "{c}: cut");
        // As a recorder that never finished leaves it: index_pos 0.
        let at = index_pos_field(&cut);
        cut[at..at + 8].fill(0);
        let p = dir.path().join(format!("{c}-live.bag"));
        std::fs::write(&p, &cut).unwrap();
        let mut bag = Bag1::open(&p).unwrap();
        assert!(!bag.is_indexed());
        assert_eq!(bag.topics().unwrap(), topics, "{c}: unindexed");
        assert_eq!(read_all(&mut bag, &[]).unwrap(), messages, "{c}: unindexed");
    }
}

/// Opens, lists and reads `path`; every failure must be a typed error (a panic fails the test).
fn read_through(
    path: &Path,
) -> (
    Result<Vec<TopicInfo>, SourceError>,
    Result<Vec<Msg>, ImportError>,
) {
    let topics = Bag1::open(path).and_then(|mut b| b.topics());
    let read = Bag1::open(path)
        .map_err(ImportError::from)
        .and_then(|mut b| read_all(&mut b, &[]));
    (topics, read)
}

/// Offsets to cut or flip at: a stride over the whole bag, and every byte around the start of
/// the first chunk (its record header, the first records inside) and of the index section.
fn offsets(len: usize, index_pos: usize, stride: usize) -> Vec<usize> {
    let first_chunk = MAGIC.len() + 4096;
    let mut v: Vec<usize> = (0..len).step_by(stride).collect();
    v.extend(first_chunk - 8..(first_chunk + 160).min(len));
    v.extend(index_pos - 8..(index_pos + 160).min(len));
    v.extend(len.saturating_sub(16)..len);
    v.sort_unstable();
    v.dedup();
    v
}

#[test]
fn truncated_bags_give_errors_not_panics() {
    let Some(w) = write_bags() else { return };
    let topics = expected_topics(&w.manifest);
    let dir = tempfile::tempdir().unwrap();
    for c in COMPRESSIONS {
        let full = std::fs::read(w.bag(c)).unwrap();
        let index = index_pos(&full) as usize;
        let p = dir.path().join(format!("{c}.bag"));
        for cut in offsets(full.len(), index, 47) {
            std::fs::write(&p, &full[..cut]).unwrap();
            let (listed, read) = read_through(&p);
            if cut < MAGIC.len() {
                assert!(
                    matches!(listed, Err(SourceError::UnknownFormat { .. })),
                    "{c} cut at {cut}"
                );
            } else if cut < index {
                match read {
                    Err(ImportError::Source(SourceError::Corrupt { at, .. })) => {
                        assert!(at as usize <= cut, "{c} cut at {cut}: error at {at}")
                    }
                    other => panic!("{c} cut at {cut} (in the chunks): {other:?}"),
                }
            } else {
                // Only the index is cut: the chunks are whole, so the reader scans them.
                assert_eq!(listed.unwrap(), topics, "{c} cut at {cut} (in the index)");
                assert_eq!(
                    read.unwrap().len(),
                    w.manifest["messages"].as_array().unwrap().len()
                );
            }
        }
    }
}

#[test]
fn flipped_bytes_give_errors_not_panics() {
    let Some(w) = write_bags() else { return };
    let dir = tempfile::tempdir().unwrap();
    for c in COMPRESSIONS {
        let full = std::fs::read(w.bag(c)).unwrap();
        let index = index_pos(&full) as usize;
        let p = dir.path().join(format!("{c}.bag"));
        for (k, at) in offsets(full.len(), index, 59).into_iter().enumerate() {
            let mut bytes = full.clone();
            bytes[at] ^= [0xff, 0x01, 0x80][k % 3];
            std::fs::write(&p, &bytes).unwrap();
            let _ = read_through(&p);
        }
    }
}

#[test]
fn hand_made_live_bag_reads() {
    let dir = tempfile::tempdir().unwrap();
    let header = |seq: u32| {
        let mut h = seq.to_le_bytes().to_vec();
        h.extend([0; 8]);
        h.extend(2u32.to_le_bytes());
        h.extend(b"f0");
        h
    };
    // Two connections on one topic, a type in the `pkg/msg/Type` form, and a second chunk.
    let p = hand_bag(
        dir.path(),
        "live.bag",
        &[
            chunk(
                "none",
                &[
                    connection(4, "/h", "std_msgs/msg/Header"),
                    message(4, 1, 5, &header(0)),
                ],
            ),
            chunk(
                "none",
                &[
                    connection(9, "/h", "std_msgs/Header"),
                    message(9, 2, 0, &header(1)),
                    message(4, 3, 0, &header(2)),
                ],
            ),
        ],
    );
    let mut bag = Bag1::open(&p).unwrap();
    let want = vec![TopicInfo {
        topic: "/h".into(),
        msg_type: "std_msgs/Header".into(),
        count: 3,
        span_ns: Some((1_000_000_005, 3_000_000_000)),
    }];
    assert_eq!(bag.topics().unwrap(), want);
    let got = read_all(&mut bag, &[]).unwrap();
    assert_eq!(got.iter().map(|m| m.index).collect::<Vec<_>>(), [0, 1, 2]);
    let seqs: Vec<_> = got
        .iter()
        .map(|m| Header::decode(&m.data, Encoding::Ros1).unwrap().seq)
        .collect();
    assert_eq!(seqs, [Some(0), Some(1), Some(2)]);
}

#[test]
fn a_message_without_its_connection_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = hand_bag(
        dir.path(),
        "noconn.bag",
        &[chunk("none", &[message(7, 1, 0, b"x")])],
    );
    let e = read_all(&mut Bag1::open(&p).unwrap(), &[]).unwrap_err();
    let text = e.to_string();
    assert!(text.contains("connection 7"), "{text}");
    // The message record starts right after the chunk's header and data length.
    match e {
        ImportError::Source(SourceError::Corrupt { at, .. }) => assert!(at > 4096 + 13, "{at}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_unknown_compression_is_unsupported() {
    let dir = tempfile::tempdir().unwrap();
    let p = hand_bag(
        dir.path(),
        "zstd.bag",
        &[chunk("zstd", &[message(0, 1, 0, b"x")])],
    );
    let e = read_all(&mut Bag1::open(&p).unwrap(), &[]).unwrap_err();
    assert!(
        matches!(e, ImportError::Source(SourceError::Unsupported { .. })),
        "{e:?}"
    );
    assert!(e.to_string().contains("zstd"));
}

#[test]
fn absurd_lengths_are_rejected_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let start = (MAGIC.len() + 4096 + 4) as u64;
    // A header claiming 4 GiB.
    let p = hand_bag(
        dir.path(),
        "huge-header.bag",
        &[vec![0xf0, 0xff, 0xff, 0xff, 1, 2, 3]],
    );
    match read_all(&mut Bag1::open(&p).unwrap(), &[]).unwrap_err() {
        ImportError::Source(SourceError::Corrupt { at, .. }) => assert_eq!(at, start),
        other => panic!("{other:?}"),
    }
    // A chunk whose data claims 4 GiB.
    let mut c = chunk("bz2", &[]);
    let n = c.len();
    c[n - 4..].copy_from_slice(&u32::MAX.to_le_bytes());
    let p = hand_bag(dir.path(), "huge-chunk.bag", &[c]);
    let e = read_all(&mut Bag1::open(&p).unwrap(), &[]).unwrap_err();
    assert!(e.to_string().contains("left in the file"), "{e}");
    // A chunk claiming to decompress to 4 GiB from a few bytes.
    let mut c = record(
        &[
            ("op", &[0x05]),
            ("compression", b"lz4"),
            ("size", &u32::MAX.to_le_bytes()),
        ],
        &[4, 0x22, 0x4d, 0x18],
    );
    c.extend(message(0, 0, 0, b""));
    let p = hand_bag(dir.path(), "bomb.bag", &[c]);
    assert!(read_all(&mut Bag1::open(&p).unwrap(), &[]).is_err());
}

#[test]
fn not_a_bag_is_an_unknown_format() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.bag");
    std::fs::write(&p, b"#ROSBAG V1.2\n").unwrap();
    assert!(matches!(
        Bag1::open(&p),
        Err(SourceError::UnknownFormat { .. })
    ));
    assert!(matches!(
        source::open(&p),
        Err(SourceError::UnknownFormat { .. })
    ));
}

#[test]
fn topics_come_from_the_index_without_reading_chunks() {
    let Some(w) = write_bags() else { return };
    let topics = expected_topics(&w.manifest);
    let dir = tempfile::tempdir().unwrap();
    for c in ["none", "bz2"] {
        let mut bytes = std::fs::read(w.bag(c)).unwrap();
        // Damage the first chunk's data (not its record header): in `none` the length of the
        // first record inside, in `bz2` a byte of the stream (its CRC then fails).
        let chunk = MAGIC.len() + 4096;
        let header_len = u32::from_le_bytes(bytes[chunk..chunk + 4].try_into().unwrap()) as usize;
        let data = chunk + 4 + header_len + 4;
        let at = if c == "none" { data } else { data + 40 };
        bytes[at..at + 4].copy_from_slice(&[0xff; 4]);
        let p = dir.path().join(format!("{c}.bag"));
        std::fs::write(&p, &bytes).unwrap();
        let mut bag = Bag1::open(&p).unwrap();
        assert_eq!(bag.topics().unwrap(), topics, "{c}: from the index");
        match read_all(&mut bag, &[]) {
            Err(ImportError::Source(SourceError::Corrupt { at: e, .. })) => {
                assert!(
                    e as usize == chunk || e as usize == data,
                    "{c}: error at {e}"
                )
            }
            other => panic!("{c}: {other:?}"),
        }
    }
}

/// The top-level chunk records of an uncompressed bag: (offset of the record, its data range).
fn chunk_records(bytes: &[u8]) -> Vec<(usize, std::ops::Range<usize>)> {
    let end = index_pos(bytes) as usize;
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let mut out = Vec::new();
    let mut at = MAGIC.len() + 4096;
    while at < end {
        let header_len = u32_at(at);
        let header = &bytes[at + 4..at + 4 + header_len];
        let data_at = at + 4 + header_len + 4;
        let data_len = u32_at(at + 4 + header_len);
        if header.windows(4).any(|w| w == b"op=\x05") {
            out.push((at, data_at..data_at + data_len));
        }
        at = data_at + data_len;
    }
    out
}

#[test]
fn chunks_without_the_wanted_topics_are_not_read() {
    let Some(w) = write_bags() else { return };
    let want: Vec<Msg> = expected_messages(&w.manifest)
        .into_iter()
        .filter(|m| m.topic == "/pose")
        .collect();
    let mut bytes = std::fs::read(w.bag("none")).unwrap();
    let chunks = chunk_records(&bytes);
    // Break every chunk that holds no /pose payload: the first record inside claims 4 GiB.
    let mut broken = 0;
    for (_, data) in &chunks {
        let holds_pose = want.iter().any(|m| {
            bytes[data.clone()]
                .windows(m.data.len())
                .any(|w| w == m.data)
        });
        if !holds_pose {
            bytes[data.start..data.start + 4].copy_from_slice(&[0xff; 4]);
            broken += 1;
        }
    }
    assert!(
        broken > 0 && broken < chunks.len(),
        "{broken} of {}",
        chunks.len()
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("skip.bag");
    std::fs::write(&p, &bytes).unwrap();
    let got = read_all(&mut Bag1::open(&p).unwrap(), &["/pose"]).unwrap();
    assert_eq!(got, want, "only the chunks with /pose are read");
    assert!(matches!(
        read_all(&mut Bag1::open(&p).unwrap(), &["/imu"]),
        Err(ImportError::Source(SourceError::Corrupt { .. }))
    ));
}
