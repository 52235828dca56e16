//! MCAP export of milliEgo sessions for Foxglove and `ros2 bag`: radar point clouds
//! (`sensor_msgs/msg/PointCloud2`), IMU samples (`sensor_msgs/msg/Imu`), ground-truth and estimated
//! trajectories (`geometry_msgs/msg/PoseStamped`, `nav_msgs/msg/Odometry`) and the sensor
//! extrinsics (`/tf_static`, `tf2_msgs/msg/TFMessage`), all on the session host clock.
//!
//! Layers: [`cdr`] writes CDR payloads (XCDR1, little-endian), [`msg`] holds the message structs
//! and their `ros2msg` schema texts, [`mod@export`] decodes a session, puts every stream on one time
//! base and writes the MCAP file with the `mcap` crate. `docs/mcap.md` lists topics, frames and
//! limits.

#![forbid(unsafe_code)]

pub mod cdr;
pub mod export;
pub mod msg;

pub use cdr::{CdrError, CdrWriter};
pub use export::{
    export, topic_name, ExportError, ExportOptions, ExportSummary, TopicSummary, Trajectory,
};
