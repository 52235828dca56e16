//! The ROS messages an import reads, each layout written once for both serialisations
//! ([`super::ser`]). Units are the messages' own: metres, radians, seconds, pascals.
//!
//! Type names are normalised to `pkg/Type` ([`normalise_type`]): ROS 2 writes
//! `sensor_msgs/msg/Imu`, ROS 1 `sensor_msgs/Imu`.

use super::ser::{Encoding, MsgError, Reader};

/// `pkg/msg/Type` -> `pkg/Type`; other names unchanged.
pub fn normalise_type(name: &str) -> String {
    match name.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, "msg", ty] => format!("{pkg}/{ty}"),
        _ => name.to_string(),
    }
}

/// A message type this crate decodes.
pub trait RosMsg: Sized {
    /// `pkg/Type`.
    const TYPE: &'static str;
    /// Reads the fields.
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError>;

    /// Decodes a whole payload (trailing bytes beyond padding are an error).
    fn decode(buf: &[u8], enc: Encoding) -> Result<Self, MsgError> {
        let mut r = Reader::new(buf, enc)?;
        let m = Self::read(&mut r)?;
        r.finish()?;
        Ok(m)
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Header {
    /// Sequence number (ROS 1 only).
    pub seq: Option<u32>,
    /// Stamp \[ns since the epoch of the recording's clock\]; 0 when the publisher left it unset.
    pub stamp_ns: i64,
    /// Frame the data is in.
    pub frame_id: String,
}

impl RosMsg for Header {
    const TYPE: &'static str = "std_msgs/Header";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        let seq = match r.encoding() {
            Encoding::Ros1 => Some(r.field("seq", |r| r.u32())?),
            Encoding::Cdr => None,
        };
        Ok(Header {
            seq,
            stamp_ns: r.field("stamp", |r| r.time_ns())?,
            frame_id: r.field("frame_id", |r| r.string())?,
        })
    }
}

fn header(r: &mut Reader<'_>) -> Result<Header, MsgError> {
    r.field("header", Header::read)
}

fn vec3(r: &mut Reader<'_>, name: &str) -> Result<[f64; 3], MsgError> {
    r.field(name, |r| r.f64_array::<3>())
}

/// A quaternion, `[x, y, z, w]` (the message's order).
fn quat(r: &mut Reader<'_>, name: &str) -> Result<[f64; 4], MsgError> {
    r.field(name, |r| r.f64_array::<4>())
}

/// `sensor_msgs/PointField` datatypes.
pub mod datatype {
    /// `INT8`.
    pub const INT8: u8 = 1;
    /// `UINT8`.
    pub const UINT8: u8 = 2;
    /// `INT16`.
    pub const INT16: u8 = 3;
    /// `UINT16`.
    pub const UINT16: u8 = 4;
    /// `INT32`.
    pub const INT32: u8 = 5;
    /// `UINT32`.
    pub const UINT32: u8 = 6;
    /// `FLOAT32`.
    pub const FLOAT32: u8 = 7;
    /// `FLOAT64`.
    pub const FLOAT64: u8 = 8;

    /// Size of one value \[B\], or `None` for an unknown datatype.
    pub fn size(d: u8) -> Option<usize> {
        match d {
            INT8 | UINT8 => Some(1),
            INT16 | UINT16 => Some(2),
            INT32 | UINT32 | FLOAT32 => Some(4),
            FLOAT64 => Some(8),
            _ => None,
        }
    }
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointField {
    /// Field name (`x`, `velocity`, ...).
    pub name: String,
    /// Byte offset in a point.
    pub offset: u32,
    /// One of [`datatype`].
    pub datatype: u8,
    /// Values in the field.
    pub count: u32,
}

/// `sensor_msgs/PointCloud2`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointCloud2 {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The point layout.
    pub fields: Vec<PointField>,
    /// Values are big-endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    pub data: Vec<u8>,
    /// No invalid points.
    pub is_dense: bool,
}

impl RosMsg for PointCloud2 {
    const TYPE: &'static str = "sensor_msgs/PointCloud2";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        let header = header(r)?;
        let height = r.field("height", |r| r.u32())?;
        let width = r.field("width", |r| r.u32())?;
        let n = r.field("fields", |r| r.seq_len(9))?;
        let mut fields = Vec::with_capacity(n);
        for i in 0..n {
            fields.push(r.field(&format!("fields[{i}]"), |r| {
                Ok(PointField {
                    name: r.field("name", |r| r.string())?,
                    offset: r.field("offset", |r| r.u32())?,
                    datatype: r.field("datatype", |r| r.u8())?,
                    count: r.field("count", |r| r.u32())?,
                })
            })?);
        }
        Ok(PointCloud2 {
            header,
            height,
            width,
            fields,
            is_bigendian: r.field("is_bigendian", |r| r.bool())?,
            point_step: r.field("point_step", |r| r.u32())?,
            row_step: r.field("row_step", |r| r.u32())?,
            data: r.field("data", |r| r.bytes())?.to_vec(),
            is_dense: r.field("is_dense", |r| r.bool())?,
        })
    }
}

/// `sensor_msgs/Imu`.
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    /// Header.
    pub header: Header,
    /// Orientation `[x, y, z, w]`.
    pub orientation: [f64; 4],
    /// Its covariance; `[0] == -1` means no orientation.
    pub orientation_covariance: [f64; 9],
    /// Angular velocity \[rad/s\].
    pub angular_velocity: [f64; 3],
    /// Its covariance.
    pub angular_velocity_covariance: [f64; 9],
    /// Linear acceleration \[m/s^2\] (specific force, gravity included).
    pub linear_acceleration: [f64; 3],
    /// Its covariance.
    pub linear_acceleration_covariance: [f64; 9],
}

impl RosMsg for Imu {
    const TYPE: &'static str = "sensor_msgs/Imu";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        Ok(Imu {
            header: header(r)?,
            orientation: quat(r, "orientation")?,
            orientation_covariance: r.field("orientation_covariance", |r| r.f64_array())?,
            angular_velocity: vec3(r, "angular_velocity")?,
            angular_velocity_covariance: r
                .field("angular_velocity_covariance", |r| r.f64_array())?,
            linear_acceleration: vec3(r, "linear_acceleration")?,
            linear_acceleration_covariance: r
                .field("linear_acceleration_covariance", |r| r.f64_array())?,
        })
    }
}

/// `sensor_msgs/FluidPressure`.
#[derive(Debug, Clone, PartialEq)]
pub struct FluidPressure {
    /// Header.
    pub header: Header,
    /// Pressure \[Pa\].
    pub fluid_pressure: f64,
    /// Its variance \[Pa^2\] (0 = unknown).
    pub variance: f64,
}

impl RosMsg for FluidPressure {
    const TYPE: &'static str = "sensor_msgs/FluidPressure";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        Ok(FluidPressure {
            header: header(r)?,
            fluid_pressure: r.field("fluid_pressure", |r| r.f64())?,
            variance: r.field("variance", |r| r.f64())?,
        })
    }
}

/// A pose: position \[m\] and orientation `[x, y, z, w]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position \[m\].
    pub position: [f64; 3],
    /// Orientation `[x, y, z, w]`.
    pub orientation: [f64; 4],
}

fn pose(r: &mut Reader<'_>, name: &str) -> Result<Pose, MsgError> {
    r.field(name, |r| {
        Ok(Pose {
            position: vec3(r, "position")?,
            orientation: quat(r, "orientation")?,
        })
    })
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseStamped {
    /// Header.
    pub header: Header,
    /// The pose of the body in `header.frame_id`.
    pub pose: Pose,
}

impl RosMsg for PoseStamped {
    const TYPE: &'static str = "geometry_msgs/PoseStamped";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        Ok(PoseStamped {
            header: header(r)?,
            pose: pose(r, "pose")?,
        })
    }
}

/// `nav_msgs/Odometry` (the covariances and twist are read and kept).
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Header (`frame_id`: the world frame).
    pub header: Header,
    /// The body frame.
    pub child_frame_id: String,
    /// The pose of `child_frame_id` in `header.frame_id`.
    pub pose: Pose,
    /// Pose covariance (row-major 6x6).
    pub pose_covariance: [f64; 36],
    /// Linear velocity \[m/s\] in `child_frame_id`.
    pub linear_velocity: [f64; 3],
    /// Angular velocity \[rad/s\] in `child_frame_id`.
    pub angular_velocity: [f64; 3],
    /// Twist covariance (row-major 6x6).
    pub twist_covariance: [f64; 36],
}

impl RosMsg for Odometry {
    const TYPE: &'static str = "nav_msgs/Odometry";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        let header = header(r)?;
        let child_frame_id = r.field("child_frame_id", |r| r.string())?;
        let (pose, pose_covariance) = r.field("pose", |r| {
            Ok((pose(r, "pose")?, r.field("covariance", |r| r.f64_array())?))
        })?;
        let (linear_velocity, angular_velocity, twist_covariance) = r.field("twist", |r| {
            let (l, a) = r.field("twist", |r| Ok((vec3(r, "linear")?, vec3(r, "angular")?)))?;
            Ok((l, a, r.field("covariance", |r| r.f64_array())?))
        })?;
        Ok(Odometry {
            header,
            child_frame_id,
            pose,
            pose_covariance,
            linear_velocity,
            angular_velocity,
            twist_covariance,
        })
    }
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Header (`frame_id`: the parent frame).
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// Translation of the child in the parent \[m\].
    pub translation: [f64; 3],
    /// Rotation child -> parent `[x, y, z, w]`.
    pub rotation: [f64; 4],
}

impl RosMsg for TransformStamped {
    const TYPE: &'static str = "geometry_msgs/TransformStamped";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        let header = header(r)?;
        let child_frame_id = r.field("child_frame_id", |r| r.string())?;
        let (translation, rotation) = r.field("transform", |r| {
            Ok((vec3(r, "translation")?, quat(r, "rotation")?))
        })?;
        Ok(TransformStamped {
            header,
            child_frame_id,
            translation,
            rotation,
        })
    }
}

/// `tf2_msgs/TFMessage` (ROS 1 `tf/tfMessage` has the same layout).
#[derive(Debug, Clone, PartialEq)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

impl RosMsg for TfMessage {
    const TYPE: &'static str = "tf2_msgs/TFMessage";
    fn read(r: &mut Reader<'_>) -> Result<Self, MsgError> {
        // A transform is at least 4 (stamp) + 4 + 4 (two empty strings) + 56 bytes.
        let n = r.field("transforms", |r| r.seq_len(68))?;
        let mut transforms = Vec::with_capacity(n);
        for i in 0..n {
            transforms.push(r.field(&format!("transforms[{i}]"), TransformStamped::read)?);
        }
        Ok(TfMessage { transforms })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little writer for both serialisations, so layouts are checked field by field against
    /// bytes laid out by hand rules (not by the reader).
    struct W {
        b: Vec<u8>,
        cdr: bool,
    }
    impl W {
        fn new(cdr: bool) -> W {
            W {
                b: if cdr { vec![0, 1, 0, 0] } else { vec![] },
                cdr,
            }
        }
        fn al(&mut self, n: usize) {
            if self.cdr {
                while !(self.b.len() - 4).is_multiple_of(n) {
                    self.b.push(0);
                }
            }
        }
        fn u8(&mut self, v: u8) {
            self.b.push(v);
        }
        fn u32(&mut self, v: u32) {
            self.al(4);
            self.b.extend(v.to_le_bytes());
        }
        fn f64(&mut self, v: f64) {
            self.al(8);
            self.b.extend(v.to_le_bytes());
        }
        fn s(&mut self, v: &str) {
            if self.cdr {
                self.u32(v.len() as u32 + 1);
                self.b.extend(v.as_bytes());
                self.b.push(0);
            } else {
                self.u32(v.len() as u32);
                self.b.extend(v.as_bytes());
            }
        }
        fn header(&mut self, seq: u32, sec: u32, nsec: u32, frame: &str) {
            if !self.cdr {
                self.u32(seq);
            }
            self.u32(sec);
            self.u32(nsec);
            self.s(frame);
        }
    }

    #[test]
    fn point_cloud_both_encodings() {
        for cdr in [false, true] {
            let mut w = W::new(cdr);
            w.header(5, 10, 20, "radar");
            w.u32(1);
            w.u32(2);
            w.u32(2);
            for (i, name) in ["x", "velocity"].iter().enumerate() {
                w.s(name);
                w.u32(4 * i as u32);
                w.u8(datatype::FLOAT32);
                w.u32(1);
            }
            w.u8(0);
            w.u32(8);
            w.u32(16);
            w.u32(16);
            w.b.extend([0xAB; 16]);
            w.u8(1);
            let enc = if cdr { Encoding::Cdr } else { Encoding::Ros1 };
            let m = PointCloud2::decode(&w.b, enc).unwrap();
            assert_eq!(m.header.seq, (!cdr).then_some(5));
            assert_eq!(m.header.stamp_ns, 10_000_000_020);
            assert_eq!(m.header.frame_id, "radar");
            assert_eq!((m.height, m.width, m.point_step, m.row_step), (1, 2, 8, 16));
            assert_eq!(m.fields[1].name, "velocity");
            assert_eq!(m.fields[1].offset, 4);
            assert_eq!(m.data, vec![0xAB; 16]);
            assert!(m.is_dense && !m.is_bigendian);
            // Cut anywhere: an error naming a field, never a panic.
            for cut in 0..w.b.len() {
                assert!(PointCloud2::decode(&w.b[..cut], enc).is_err());
            }
        }
    }

    #[test]
    fn imu_and_pressure_both_encodings() {
        for cdr in [false, true] {
            let mut w = W::new(cdr);
            w.header(1, 2, 3, "imu");
            for v in 0..(4 + 9 + 3 + 9 + 3 + 9) {
                w.f64(f64::from(v));
            }
            let enc = if cdr { Encoding::Cdr } else { Encoding::Ros1 };
            let m = Imu::decode(&w.b, enc).unwrap();
            assert_eq!(m.orientation, [0.0, 1.0, 2.0, 3.0]);
            assert_eq!(m.angular_velocity, [13.0, 14.0, 15.0]);
            assert_eq!(m.linear_acceleration, [25.0, 26.0, 27.0]);
            let mut w = W::new(cdr);
            w.header(1, 2, 3, "baro");
            w.f64(101_325.0);
            w.f64(4.0);
            let p = FluidPressure::decode(&w.b, enc).unwrap();
            assert_eq!((p.fluid_pressure, p.variance), (101_325.0, 4.0));
            // A pressure payload is not an IMU payload.
            assert!(Imu::decode(&w.b, enc).is_err());
        }
    }

    #[test]
    fn ground_truth_messages() {
        for cdr in [false, true] {
            let enc = if cdr { Encoding::Cdr } else { Encoding::Ros1 };
            let mut w = W::new(cdr);
            w.u32(1);
            w.header(0, 7, 0, "world");
            w.s("body");
            for v in [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
                w.f64(v);
            }
            let tf = TfMessage::decode(&w.b, enc).unwrap();
            assert_eq!(tf.transforms.len(), 1);
            assert_eq!(tf.transforms[0].child_frame_id, "body");
            assert_eq!(tf.transforms[0].translation, [1.0, 2.0, 3.0]);
            assert_eq!(tf.transforms[0].rotation[3], 1.0);

            let mut w = W::new(cdr);
            w.header(0, 7, 0, "world");
            w.s("body");
            for v in 0..(7 + 36 + 6 + 36) {
                w.f64(f64::from(v));
            }
            let o = Odometry::decode(&w.b, enc).unwrap();
            assert_eq!(o.pose.position, [0.0, 1.0, 2.0]);
            assert_eq!(o.pose_covariance[0], 7.0);
            assert_eq!(o.linear_velocity, [43.0, 44.0, 45.0]);
            assert_eq!(o.twist_covariance[35], 84.0);

            let mut w = W::new(cdr);
            w.header(0, 7, 0, "world");
            for v in [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
                w.f64(v);
            }
            let p = PoseStamped::decode(&w.b, enc).unwrap();
            assert_eq!(p.pose.position, [1.0, 2.0, 3.0]);
        }
    }

    #[test]
    fn type_names() {
        assert_eq!(normalise_type("sensor_msgs/msg/Imu"), "sensor_msgs/Imu");
        assert_eq!(normalise_type("sensor_msgs/Imu"), "sensor_msgs/Imu");
        assert_eq!(normalise_type("tf/tfMessage"), "tf/tfMessage");
    }
}
