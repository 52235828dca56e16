//! Shared by the import fuzz targets: every message a reader hands out is decoded as its type
//! says, and scans are read point by point, so the decoders see what the container readers pass.

use milliego_import::cloud::PointLayout;
use milliego_import::ros::{
    Encoding, FluidPressure, Header, Imu, Odometry, PointCloud2, PoseStamped, RosMsg, TfMessage,
    TransformStamped,
};
use milliego_import::source::{RawMessage, Source};
use std::path::PathBuf;

/// Decodes `data` as `msg_type` (any outcome but a panic is fine).
pub fn decode(msg_type: &str, data: &[u8], enc: Encoding) {
    match msg_type {
        "sensor_msgs/PointCloud2" => {
            if let Ok(c) = PointCloud2::decode(data, enc) {
                if let Ok(l) = PointLayout::of(&c, None) {
                    let mut n = 0usize;
                    if l.points(&c, |p| n += usize::from(p.doppler.is_finite())).is_ok() {
                        assert!(n <= c.data.len());
                    }
                }
            }
        }
        "sensor_msgs/Imu" => drop(Imu::decode(data, enc)),
        "sensor_msgs/FluidPressure" => drop(FluidPressure::decode(data, enc)),
        "std_msgs/Header" => drop(Header::decode(data, enc)),
        "geometry_msgs/PoseStamped" => drop(PoseStamped::decode(data, enc)),
        "nav_msgs/Odometry" => drop(Odometry::decode(data, enc)),
        "geometry_msgs/TransformStamped" => drop(TransformStamped::decode(data, enc)),
        "tf2_msgs/TFMessage" => drop(TfMessage::decode(data, enc)),
        _ => {}
    }
}

/// Lists the topics, then reads every message (decoding each) and, when that worked, reads
/// the first topic alone and checks it got the same messages of it: all of them when `exact`,
/// else (a reader that trusts an index to skip data) a subsequence, never a message that
/// reading everything did not give.
pub fn read_all(src: &mut dyn Source, exact: bool) {
    let topics = src.topics();
    let mut all: Vec<(String, u64, u64)> = Vec::new();
    let mut on_msg = |m: RawMessage<'_>| {
        decode(m.msg_type, m.data, m.encoding);
        all.push((m.topic.to_string(), m.log_time_ns, m.index));
        Ok(())
    };
    if src.for_each(&[], &mut on_msg).is_err() {
        return;
    }
    let Some(first) = all.first().map(|m| m.0.clone()) else {
        return;
    };
    let mut one = Vec::new();
    let r = src.for_each(&[first.as_str()], &mut |m| {
        one.push((m.topic.to_string(), m.log_time_ns, m.index));
        Ok(())
    });
    if r.is_ok() {
        let want: Vec<_> = all.into_iter().filter(|m| m.0 == first).collect();
        if exact {
            assert_eq!(one, want, "reading one topic gives what reading all gave of it");
        } else {
            let mut rest = want.iter().map(|m| (&m.0, m.1));
            for m in &one {
                assert!(
                    rest.any(|w| w == (&m.0, m.1)),
                    "reading one topic gave a message that reading all did not: {m:?}"
                );
            }
        }
    }
    drop(topics);
}

/// A file of this process for the container readers, which read files.
pub fn scratch(name: &str, bytes: &[u8]) -> PathBuf {
    let p = std::env::temp_dir().join(format!("milliego-fuzz-{}-{name}", std::process::id()));
    std::fs::write(&p, bytes).expect("the fuzz scratch file is writable");
    p
}
