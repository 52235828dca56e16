//! The ROS 2 messages the export writes: plain structs, their CDR encoding and their `ros2msg`
//! schema text as ROS 2 bags store it (the type's own definition, then every type it depends on,
//! each once, depth first, after a line of 80 `=` and a `MSG: pkg/Type` line).

use crate::cdr::{CdrError, CdrWriter};

/// A ROS 2 message type this crate can write.
pub trait RosMessage {
    /// Full type name, e.g. `sensor_msgs/msg/Imu`.
    const NAME: &'static str;
    /// The type's definition (one `.msg` file).
    fn definition() -> &'static Def;
    /// Appends the fields to `w`.
    fn encode(&self, w: &mut CdrWriter) -> Result<(), CdrError>;

    /// The CDR payload (encapsulation header included).
    fn to_cdr(&self) -> Result<Vec<u8>, CdrError> {
        let mut w = CdrWriter::new();
        self.encode(&mut w)?;
        Ok(w.into_bytes())
    }

    /// The `ros2msg` schema text.
    fn schema_text() -> String {
        schema_text(Self::definition())
    }
}

/// One `.msg` definition and the types it references.
#[derive(Debug)]
pub struct Def {
    /// `pkg/Type` (the form `MSG:` lines use).
    pub name: &'static str,
    /// The `.msg` text.
    pub text: &'static str,
    /// Referenced types, in field order.
    pub deps: &'static [&'static Def],
}

/// The separator line between definitions in a ROS 2 schema.
pub const SEPARATOR: &str =
    "================================================================================";

/// Concatenates `def` and its dependencies (depth first, each once).
pub fn schema_text(def: &Def) -> String {
    fn walk(d: &Def, seen: &mut Vec<&'static str>, out: &mut String) {
        for dep in d.deps {
            if seen.contains(&dep.name) {
                continue;
            }
            seen.push(dep.name);
            out.push_str(SEPARATOR);
            out.push_str("\nMSG: ");
            out.push_str(dep.name);
            out.push('\n');
            out.push_str(dep.text);
            walk(dep, seen, out);
        }
    }
    let mut out = String::from(def.text);
    let mut seen = vec![def.name];
    walk(def, &mut seen, &mut out);
    out
}

macro_rules! def {
    ($id:ident, $name:literal, [$($dep:ident),*], $text:literal) => {
        #[doc = concat!("Definition of `", $name, "`.")]
        pub static $id: Def = Def { name: $name, text: $text, deps: &[$(&$dep),*] };
    };
}

def!(
    TIME,
    "builtin_interfaces/Time",
    [],
    "int32 sec\nuint32 nanosec\n"
);
def!(
    HEADER,
    "std_msgs/Header",
    [TIME],
    "builtin_interfaces/Time stamp\nstring frame_id\n"
);
def!(
    POINT_FIELD,
    "sensor_msgs/PointField",
    [],
    "uint8 INT8 = 1\nuint8 UINT8 = 2\nuint8 INT16 = 3\nuint8 UINT16 = 4\nuint8 INT32 = 5\nuint8 UINT32 = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n"
);
def!(
    POINT_CLOUD2,
    "sensor_msgs/PointCloud2",
    [HEADER, POINT_FIELD],
    "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n"
);
def!(
    QUATERNION,
    "geometry_msgs/Quaternion",
    [],
    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
);
def!(
    VECTOR3,
    "geometry_msgs/Vector3",
    [],
    "float64 x\nfloat64 y\nfloat64 z\n"
);
def!(
    POINT,
    "geometry_msgs/Point",
    [],
    "float64 x\nfloat64 y\nfloat64 z\n"
);
def!(
    IMU,
    "sensor_msgs/Imu",
    [HEADER, QUATERNION, VECTOR3],
    "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n"
);
def!(
    POSE,
    "geometry_msgs/Pose",
    [POINT, QUATERNION],
    "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"
);
def!(
    POSE_STAMPED,
    "geometry_msgs/PoseStamped",
    [HEADER, POSE],
    "std_msgs/Header header\ngeometry_msgs/Pose pose\n"
);
def!(
    POSE_WITH_COVARIANCE,
    "geometry_msgs/PoseWithCovariance",
    [POSE],
    "geometry_msgs/Pose pose\nfloat64[36] covariance\n"
);
def!(
    TWIST,
    "geometry_msgs/Twist",
    [VECTOR3],
    "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n"
);
def!(
    TWIST_WITH_COVARIANCE,
    "geometry_msgs/TwistWithCovariance",
    [TWIST],
    "geometry_msgs/Twist twist\nfloat64[36] covariance\n"
);
def!(
    ODOMETRY,
    "nav_msgs/Odometry",
    [HEADER, POSE_WITH_COVARIANCE, TWIST_WITH_COVARIANCE],
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n"
);
def!(
    TRANSFORM,
    "geometry_msgs/Transform",
    [VECTOR3, QUATERNION],
    "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
);
def!(
    TRANSFORM_STAMPED,
    "geometry_msgs/TransformStamped",
    [HEADER, TRANSFORM],
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n"
);
def!(
    TF_MESSAGE,
    "tf2_msgs/TFMessage",
    [TRANSFORM_STAMPED],
    "geometry_msgs/TransformStamped[] transforms\n"
);

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// Stamp \[ns\] (written as `sec`, `nanosec`).
    pub stamp_ns: u64,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

impl Header {
    fn encode(&self, w: &mut CdrWriter) -> Result<(), CdrError> {
        let sec = self.stamp_ns / 1_000_000_000;
        // ROS time is int32 seconds: beyond 2038 it saturates rather than wrapping.
        w.i32(i32::try_from(sec).unwrap_or(i32::MAX));
        w.u32((self.stamp_ns % 1_000_000_000) as u32);
        w.string(&self.frame_id)
    }
}

/// A pose or transform: translation \[m\] and unit quaternion (x, y, z, w).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position \[m\].
    pub p: [f64; 3],
    /// Orientation (x, y, z, w).
    pub q: [f64; 4],
}

impl Pose {
    fn encode(&self, w: &mut CdrWriter) {
        w.f64_array(&self.p);
        w.f64_array(&self.q);
    }
}

/// `sensor_msgs/msg/PointField` datatype `FLOAT32`.
pub const FLOAT32: u8 = 7;

/// `sensor_msgs/msg/PointCloud2` of FLOAT32 fields, one row.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2 {
    /// Stamp and frame.
    pub header: Header,
    /// Field names; each point is `names.len()` little-endian f32 values in this order.
    pub fields: &'static [&'static str],
    /// Points, row-major, `fields.len()` values each.
    pub values: Vec<f32>,
}

impl PointCloud2 {
    /// Points in the cloud.
    pub fn width(&self) -> usize {
        self.values.len() / self.fields.len().max(1)
    }
}

impl RosMessage for PointCloud2 {
    const NAME: &'static str = "sensor_msgs/msg/PointCloud2";
    fn definition() -> &'static Def {
        &POINT_CLOUD2
    }
    fn encode(&self, w: &mut CdrWriter) -> Result<(), CdrError> {
        self.header.encode(w)?;
        let step = 4 * self.fields.len();
        let width = self.width();
        let too_long = |_| CdrError::TooLong {
            what: "point cloud",
            len: self.values.len(),
        };
        w.u32(1);
        w.u32(u32::try_from(width).map_err(too_long)?);
        w.seq_len("fields", self.fields.len())?;
        for (i, name) in self.fields.iter().enumerate() {
            w.string(name)?;
            w.u32(4 * i as u32);
            w.u8(FLOAT32);
            w.u32(1);
        }
        w.bool(false);
        w.u32(step as u32);
        w.u32(u32::try_from(step * width).map_err(too_long)?);
        let data: Vec<u8> = self.values[..width * self.fields.len()]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        w.bytes(&data)?;
        w.bool(self.values.iter().all(|v| v.is_finite()));
        Ok(())
    }
}

/// `sensor_msgs/msg/Imu` without an orientation (its covariance\[0\] is -1: unknown).
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    /// Stamp and frame.
    pub header: Header,
    /// Rate of turn \[rad/s\].
    pub angular_velocity: [f64; 3],
    /// Specific force \[m/s^2\].
    pub linear_acceleration: [f64; 3],
}

impl RosMessage for Imu {
    const NAME: &'static str = "sensor_msgs/msg/Imu";
    fn definition() -> &'static Def {
        &IMU
    }
    fn encode(&self, w: &mut CdrWriter) -> Result<(), CdrError> {
        self.header.encode(w)?;
        w.f64_array(&[0.0, 0.0, 0.0, 1.0]);
        let mut unknown = [0.0; 9];
        unknown[0] = -1.0;
        w.f64_array(&unknown);
        // Zero covariance: not known (REP 145).
        w.f64_array(&self.angular_velocity);
        w.f64_array(&[0.0; 9]);
        w.f64_array(&self.linear_acceleration);
        w.f64_array(&[0.0; 9]);
        Ok(())
    }
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

impl RosMessage for PoseStamped {
    const NAME: &'static str = "geometry_msgs/msg/PoseStamped";
    fn definition() -> &'static Def {
        &POSE_STAMPED
    }
    fn encode(&self, w: &mut CdrWriter) -> Result<(), CdrError> {
        self.header.encode(w)?;
        self.pose.encode(w);
        Ok(())
    }
}

/// `nav_msgs/msg/Odometry` with zero (unknown) covariances.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Stamp and the pose's frame.
    pub header: Header,
    /// Frame of the twist (the moving body).
    pub child_frame_id: String,
    /// Pose of the child frame in the header frame.
    pub pose: Pose,
    /// Linear velocity in the child frame \[m/s\].
    pub linear: [f64; 3],
    /// Angular velocity in the child frame \[rad/s\].
    pub angular: [f64; 3],
}

impl RosMessage for Odometry {
    const NAME: &'static str = "nav_msgs/msg/Odometry";
    fn definition() -> &'static Def {
        &ODOMETRY
    }
    fn encode(&self, w: &mut CdrWriter) -> Result<(), CdrError> {
        self.header.encode(w)?;
        w.string(&self.child_frame_id)?;
        self.pose.encode(w);
        w.f64_array(&[0.0; 36]);
        w.f64_array(&self.linear);
        w.f64_array(&self.angular);
        w.f64_array(&[0.0; 36]);
        Ok(())
    }
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// Child frame.
    pub child_frame_id: String,
    /// Child frame in the parent frame: p_parent = R * p_child + t.
    pub transform: Pose,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

impl RosMessage for TfMessage {
    const NAME: &'static str = "tf2_msgs/msg/TFMessage";
    fn definition() -> &'static Def {
        &TF_MESSAGE
    }
    fn encode(&self, w: &mut CdrWriter) -> Result<(), CdrError> {
        w.seq_len("transforms", self.transforms.len())?;
        for t in &self.transforms {
            t.header.encode(w)?;
            w.string(&t.child_frame_id)?;
            t.transform.encode(w);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hdr(stamp_ns: u64, frame: &str) -> Header {
        Header {
            stamp_ns,
            frame_id: frame.into(),
        }
    }

    #[test]
    fn pose_stamped_bytes() {
        // Header: sec 1, nanosec 500, frame "w" (len 2): body bytes 0..14; the float64s start at
        // 16 after two bytes of padding.
        let m = PoseStamped {
            header: hdr(1_000_000_500, "w"),
            pose: Pose {
                p: [1.0, 2.0, 3.0],
                q: [0.0, 0.0, 0.0, 1.0],
            },
        };
        let mut want: Vec<u8> = vec![0, 1, 0, 0, 1, 0, 0, 0, 0xf4, 1, 0, 0, 2, 0, 0, 0, b'w', 0];
        want.extend([0, 0]);
        for v in [1.0f64, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
            want.extend(v.to_le_bytes());
        }
        assert_eq!(m.to_cdr().unwrap(), want);
    }

    #[test]
    fn point_cloud_bytes() {
        let m = PointCloud2 {
            header: hdr(0, "radar"),
            fields: &["x", "v"],
            values: vec![1.0, -2.0],
        };
        let mut want: Vec<u8> = vec![0, 1, 0, 0];
        want.extend([0, 0, 0, 0, 0, 0, 0, 0]); // stamp
        want.extend([6, 0, 0, 0]);
        want.extend(b"radar\0"); // body 12..18
        want.extend([0, 0]); // pad to 20
        want.extend([1, 0, 0, 0, 1, 0, 0, 0]); // height, width
        want.extend([2, 0, 0, 0]); // two fields
        want.extend([2, 0, 0, 0, b'x', 0, 0, 0]); // name 32..38, pad to 40
        want.extend([0, 0, 0, 0, FLOAT32, 0, 0, 0, 1, 0, 0, 0]); // offset, datatype, pad, count
        want.extend([2, 0, 0, 0, b'v', 0, 0, 0]);
        want.extend([4, 0, 0, 0, FLOAT32, 0, 0, 0, 1, 0, 0, 0]);
        want.extend([0, 0, 0, 0]); // is_bigendian + pad
        want.extend([8, 0, 0, 0, 8, 0, 0, 0]); // point_step, row_step
        want.extend([8, 0, 0, 0]);
        want.extend(1.0f32.to_le_bytes());
        want.extend((-2.0f32).to_le_bytes());
        want.push(1); // is_dense
        assert_eq!(m.to_cdr().unwrap(), want);
    }

    #[test]
    fn odometry_nests_pose_and_twist_without_padding_of_their_own() {
        let m = Odometry {
            header: hdr(0, ""),
            child_frame_id: "b".into(),
            pose: Pose {
                p: [0.0; 3],
                q: [0.0, 0.0, 0.0, 1.0],
            },
            linear: [1.0, 0.0, 0.0],
            angular: [0.0, 0.0, 2.0],
        };
        let b = m.to_cdr().unwrap();
        // header 0..13 ("" = len 1 + NUL), child "b": pad to 16, len 16..20, "b\0" 20..22,
        // pad to 24, then 7 + 36 + 6 + 36 float64s.
        assert_eq!(b.len(), 4 + 24 + 8 * (7 + 36 + 6 + 36));
        assert_eq!(&b[4 + 16..4 + 22], &[2, 0, 0, 0, b'b', 0]);
        let twist = 4 + 24 + 8 * (7 + 36);
        assert_eq!(&b[twist..twist + 8], &1.0f64.to_le_bytes());
        assert_eq!(&b[twist + 40..twist + 48], &2.0f64.to_le_bytes());
    }

    #[test]
    fn imu_marks_orientation_unknown() {
        let m = Imu {
            header: hdr(0, "imu"),
            angular_velocity: [0.1, 0.2, 0.3],
            linear_acceleration: [0.0, 0.0, 9.81],
        };
        let b = m.to_cdr().unwrap();
        // header: 8 + 4 + "imu\0" = body 16; orientation 16..48; covariance 48..120; gyro.
        assert_eq!(b.len(), 4 + 16 + 8 * (4 + 9 + 3 + 9 + 3 + 9));
        assert_eq!(&b[4 + 48..4 + 56], &(-1.0f64).to_le_bytes());
        assert_eq!(&b[4 + 120..4 + 128], &0.1f64.to_le_bytes());
    }

    #[test]
    fn tf_message_is_a_sequence_of_transforms() {
        let t = |c: &str| TransformStamped {
            header: hdr(0, "body"),
            child_frame_id: c.into(),
            transform: Pose {
                p: [0.0; 3],
                q: [0.0, 0.0, 0.0, 1.0],
            },
        };
        let b = TfMessage {
            transforms: vec![t("radar"), t("imu")],
        }
        .to_cdr()
        .unwrap();
        assert_eq!(&b[4..8], &[2, 0, 0, 0]);
        // count 0..4, stamp 4..12, "body" 12..21, pad to 24, "radar" 24..34, pad to 40, 7 f64.
        assert_eq!(&b[4 + 24..4 + 34], b"\x06\0\0\0radar\0");
        assert_eq!(&b[4 + 40 + 48..4 + 40 + 56], &1.0f64.to_le_bytes());
    }

    #[test]
    fn schema_texts_list_each_dependency_once_depth_first() {
        let s = PoseStamped::schema_text();
        let want = format!(
            "std_msgs/Header header\ngeometry_msgs/Pose pose\n\
             {SEPARATOR}\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
             {SEPARATOR}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n\
             {SEPARATOR}\nMSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n\
             {SEPARATOR}\nMSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n\
             {SEPARATOR}\nMSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
        );
        assert_eq!(s, want);
        assert_eq!(SEPARATOR.len(), 80);
        let odom = Odometry::schema_text();
        for name in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
            "geometry_msgs/TwistWithCovariance",
            "geometry_msgs/Twist",
            "geometry_msgs/Vector3",
        ] {
            assert_eq!(
                odom.matches(&format!("\nMSG: {name}\n")).count(),
                1,
                "{name} once in the Odometry schema"
            );
        }
        assert!(
            PointCloud2::schema_text().contains("MSG: sensor_msgs/PointField\nuint8 INT8 = 1\n")
        );
        assert!(
            TfMessage::schema_text().starts_with("geometry_msgs/TransformStamped[] transforms\n")
        );
        assert!(Imu::schema_text().contains("float64[9] orientation_covariance\n"));
    }
}
