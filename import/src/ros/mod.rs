//! ROS messages: the two serialisations ([`ser`]) and the message layouts an import reads
//! ([`msgs`]).

pub mod msgs;
pub mod ser;

pub use msgs::{
    normalise_type, FluidPressure, Header, Imu, Odometry, PointCloud2, PointField, PoseStamped,
    RosMsg, TfMessage, TransformStamped,
};
pub use ser::{Encoding, MsgError, MsgErrorKind, Reader};
