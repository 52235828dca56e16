//! The ROS message decoders (ROS 1 and CDR) and the point-cloud layout over arbitrary payloads:
//! the first byte picks the type and the encoding, the rest is the payload.
#![no_main]

use libfuzzer_sys::fuzz_target;
use milliego_import::ros::Encoding;

mod import_common;

const TYPES: [&str; 8] = [
    "sensor_msgs/PointCloud2",
    "sensor_msgs/Imu",
    "sensor_msgs/FluidPressure",
    "std_msgs/Header",
    "geometry_msgs/PoseStamped",
    "nav_msgs/Odometry",
    "geometry_msgs/TransformStamped",
    "tf2_msgs/TFMessage",
];

fuzz_target!(|data: &[u8]| {
    let Some((&pick, payload)) = data.split_first() else {
        return;
    };
    let ty = TYPES[usize::from(pick) % TYPES.len()];
    let enc = if pick & 0x80 == 0 { Encoding::Ros1 } else { Encoding::Cdr };
    import_common::decode(ty, payload, enc);
});
