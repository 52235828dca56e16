"""Writes ROS 2 recordings with independent writers, for import/tests/ros2.rs.

    python write_ros2.py OUTDIR

writes into OUTDIR:
  sqlite_bag/       ROS 2 bag, sqlite3 storage       (rosbags.rosbag2.Writer)
  mcap_bag/         ROS 2 bag, mcap storage          (rosbags.rosbag2.Writer)
  sqlite_msg_zstd/  sqlite3, message-mode zstd       (rosbags.rosbag2.Writer)
  sqlite_file_zstd/ sqlite3, file-mode zstd          (rosbags.rosbag2.Writer)
  plain_zstd.mcap, plain_lz4.mcap, plain_none.mcap
                    plain MCAP, ros2 profile, chunks of that compression, small chunks so
                    there are several (mcap + mcap_ros2 writers)
  ros1.mcap         plain MCAP, ros1 profile: `ros1` channels (mcap writer, rosbags
                    ROS1_NOETIC serialize_ros1), its own messages under "ros1"

and prints a JSON manifest on stdout:
  {"messages": [{"topic", "type", "log_time_ns", "check": {...known values...}}, ...],
   "files": {NAME: {"kind": "ros2" | "mcap", "payloads": [hex, ...]}}}

Messages are listed in log-time order (all log times distinct); payloads[i] is the i-th
message's serialised bytes as that file stores them (for the rosbags files the
rosbags serialize_cdr bytes; for the plain MCAP files, read back with mcap's reader).
Values are dyadic fractions so they survive JSON exactly.
"""

import json
import sys
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap_ros2.writer import Writer as McapRos2Writer
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
Time = T["builtin_interfaces/msg/Time"]
Header = T["std_msgs/msg/Header"]
PointField = T["sensor_msgs/msg/PointField"]
PointCloud2 = T["sensor_msgs/msg/PointCloud2"]
Imu = T["sensor_msgs/msg/Imu"]
FluidPressure = T["sensor_msgs/msg/FluidPressure"]
Odometry = T["nav_msgs/msg/Odometry"]
TFMessage = T["tf2_msgs/msg/TFMessage"]
TransformStamped = T["geometry_msgs/msg/TransformStamped"]
Transform = T["geometry_msgs/msg/Transform"]
Vector3 = T["geometry_msgs/msg/Vector3"]
Quaternion = T["geometry_msgs/msg/Quaternion"]
Point = T["geometry_msgs/msg/Point"]
Pose = T["geometry_msgs/msg/Pose"]
PoseWithCovariance = T["geometry_msgs/msg/PoseWithCovariance"]
Twist = T["geometry_msgs/msg/Twist"]
TwistWithCovariance = T["geometry_msgs/msg/TwistWithCovariance"]

T0 = 1_700_000_000_000_000_000  # log time of the first message [ns]


def header(stamp_ns, frame):
    return Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)


def hcheck(stamp_ns, frame):
    return {"stamp_ns": stamp_ns, "frame_id": frame}


def f64s(n, a, step=0.25):
    return [a + step * k for k in range(n)]


def cloud(i, stamp):
    names = ["x", "y", "z", "velocity", "intensity"]
    fields = [PointField(name=n, offset=4 * k, datatype=7, count=1) for k, n in enumerate(names)]
    width = 3 + i
    pts = np.array(f64s(width * 5, 0.5 * i, 0.125), dtype="<f4")
    data = np.frombuffer(pts.tobytes(), dtype=np.uint8)
    msg = PointCloud2(
        header=header(stamp, "radar"),
        height=1,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=20,
        row_step=20 * width,
        data=data,
        is_dense=i % 2 == 0,
    )
    check = {
        "header": hcheck(stamp, "radar"),
        "height": 1,
        "width": width,
        "fields": [[n, 4 * k, 7, 1] for k, n in enumerate(names)],
        "is_bigendian": False,
        "point_step": 20,
        "row_step": 20 * width,
        "data_hex": data.tobytes().hex(),
        "is_dense": i % 2 == 0,
    }
    return msg, check


def imu(i, stamp):
    q = [0.0, 0.0, 0.5 * (i % 2), 1.0]
    w = f64s(3, 0.25 * i - 1.0)
    a = [0.5, -0.25, 9.8125 + 0.125 * i]
    oc, wc, ac = f64s(9, 1.0), f64s(9, 2.0), f64s(9, 3.0)
    msg = Imu(
        header=header(stamp, "imu_link"),
        orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
        orientation_covariance=np.array(oc),
        angular_velocity=Vector3(x=w[0], y=w[1], z=w[2]),
        angular_velocity_covariance=np.array(wc),
        linear_acceleration=Vector3(x=a[0], y=a[1], z=a[2]),
        linear_acceleration_covariance=np.array(ac),
    )
    check = {
        "header": hcheck(stamp, "imu_link"),
        "orientation": q,
        "orientation_covariance": oc,
        "angular_velocity": w,
        "angular_velocity_covariance": wc,
        "linear_acceleration": a,
        "linear_acceleration_covariance": ac,
    }
    return msg, check


def baro(i, stamp):
    p, v = 101325.0 - 0.5 * i, 4.0 + i
    msg = FluidPressure(header=header(stamp, "baro"), fluid_pressure=p, variance=v)
    return msg, {"header": hcheck(stamp, "baro"), "fluid_pressure": p, "variance": v}


def plain_header(i, stamp):
    frame = "" if i == 0 else f"frame_{i}"  # the empty string too
    return header(stamp, frame), {"header": hcheck(stamp, frame)}


def odom(i, stamp):
    pos = [1.0 + i, 2.0 - 0.5 * i, 0.25]
    q = [0.0, 0.0, 0.0, 1.0]
    pc, tc = f64s(36, 10.0 + i), f64s(36, -5.0)
    lin, ang = [0.5 * i, 0.0, -0.125], [0.0, 0.0625, 0.25 * i]
    msg = Odometry(
        header=header(stamp, "odom"),
        child_frame_id="base_link",
        pose=PoseWithCovariance(
            pose=Pose(
                position=Point(x=pos[0], y=pos[1], z=pos[2]),
                orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
            ),
            covariance=np.array(pc),
        ),
        twist=TwistWithCovariance(
            twist=Twist(
                linear=Vector3(x=lin[0], y=lin[1], z=lin[2]),
                angular=Vector3(x=ang[0], y=ang[1], z=ang[2]),
            ),
            covariance=np.array(tc),
        ),
    )
    check = {
        "header": hcheck(stamp, "odom"),
        "child_frame_id": "base_link",
        "position": pos,
        "orientation": q,
        "pose_covariance": pc,
        "linear_velocity": lin,
        "angular_velocity": ang,
        "twist_covariance": tc,
    }
    return msg, check


def tf(i, stamp):
    transforms, checks = [], []
    for k in range(i + 1):  # 1, 2, ... transforms
        child = f"link_{k}"
        tr, rot = [0.5 * k, -1.0, 2.0 + i], [0.0, 0.5 * (k % 2), 0.0, 1.0]
        transforms.append(
            TransformStamped(
                header=header(stamp + k, "world"),
                child_frame_id=child,
                transform=Transform(
                    translation=Vector3(x=tr[0], y=tr[1], z=tr[2]),
                    rotation=Quaternion(x=rot[0], y=rot[1], z=rot[2], w=rot[3]),
                ),
            )
        )
        checks.append(
            {
                "header": hcheck(stamp + k, "world"),
                "child_frame_id": child,
                "translation": tr,
                "rotation": rot,
            }
        )
    return TFMessage(transforms=transforms), {"transforms": checks}


TOPICS = [
    ("/radar/points", "sensor_msgs/msg/PointCloud2", cloud, 3),
    ("/imu/data", "sensor_msgs/msg/Imu", imu, 5),
    ("/baro", "sensor_msgs/msg/FluidPressure", baro, 2),
    ("/header", "std_msgs/msg/Header", plain_header, 2),
    ("/odom", "nav_msgs/msg/Odometry", odom, 2),
    ("/tf", "tf2_msgs/msg/TFMessage", tf, 2),
]


def messages():
    """(topic, type, log_time_ns, msg, check), in log-time order, all times distinct."""
    out = []
    for t, (topic, ty, make, n) in enumerate(TOPICS):
        for i in range(n):
            log_time = T0 + i * 10_000_000 + t * 1_000_000 + 17
            stamp = log_time - 2_500_000 + i  # the header stamp is not the log time
            msg, check = make(i, stamp)
            out.append((topic, ty, log_time, msg, check))
    out.sort(key=lambda m: m[2])
    return out


def to_dict(msg):
    """A rosbags message as the plain dicts / lists mcap_ros2's serialiser takes."""
    if isinstance(msg, np.ndarray):
        return msg.tobytes() if msg.dtype == np.uint8 else msg.tolist()
    if isinstance(msg, list):
        return [to_dict(m) for m in msg]
    if hasattr(msg, "__dataclass_fields__"):
        return {k: to_dict(getattr(msg, k)) for k in msg.__dataclass_fields__ if k != "__msgtype__"}
    return msg


def write_rosbags(path, msgs, storage, compression=None):
    w = Writer(path, version=8, storage_plugin=storage)
    if compression is not None:
        w.set_compression(compression, CompressionFormat.ZSTD)
    w.open()
    conns = {}
    for topic, ty, _, _ in TOPICS:
        conns[topic] = w.add_connection(topic, ty, typestore=TS)
    payloads = []
    for topic, ty, log_time, msg, _ in msgs:
        data = TS.serialize_cdr(msg, ty)
        w.write(conns[topic], log_time, data)
        payloads.append(bytes(data).hex())
    w.close()
    return payloads


def write_plain_mcap(path, msgs, compression):
    with open(path, "wb") as f:
        w = McapRos2Writer(f, chunk_size=700, compression=compression)
        schemas = {}
        for _, ty, _, _ in TOPICS:
            schemas[ty] = w.register_msgdef(ty, TS.generate_msgdef(ty, ros_version=2)[0])
        for k, (topic, ty, log_time, msg, _) in enumerate(msgs):
            w.write_message(
                topic, schemas[ty], to_dict(msg), log_time=log_time, publish_time=log_time + 1,
                sequence=k,
            )
        w.finish()
    payloads = []
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            payloads.append(message.data.hex())
    assert len(payloads) == len(msgs)
    return payloads


def write_ros1_mcap(path):
    """Imu and Header with ros1 encoding; returns [{topic, type, log_time_ns, seq, payload}]."""
    from mcap.writer import Writer as McapWriter

    ts1 = get_typestore(Stores.ROS1_NOETIC)
    t1 = ts1.types
    out = []
    with open(path, "wb") as f:
        w = McapWriter(f, chunk_size=400, compression=CompressionType.ZSTD)
        w.start(profile="ros1", library="write_ros2.py")
        chans = {}
        for topic, ty in [("/imu1", "sensor_msgs/msg/Imu"), ("/hdr1", "std_msgs/msg/Header")]:
            name = ty.replace("/msg/", "/")
            sid = w.register_schema(name, "ros1msg", ts1.generate_msgdef(ty)[0].encode())
            chans[topic] = (w.register_channel(topic, "ros1", sid), ty, name)
        for i in range(4):
            for k, topic in enumerate(["/imu1", "/hdr1"]):
                cid, ty, name = chans[topic]
                log_time = T0 + i * 5_000_000 + k * 1_000_000
                stamp = log_time - 1000
                hdr = t1["std_msgs/msg/Header"](
                    seq=100 + i,
                    stamp=t1["builtin_interfaces/msg/Time"](
                        sec=stamp // 10**9, nanosec=stamp % 10**9
                    ),
                    frame_id=f"f{i}",
                )
                if topic == "/hdr1":
                    msg = hdr
                else:
                    V3, Q = t1["geometry_msgs/msg/Vector3"], t1["geometry_msgs/msg/Quaternion"]
                    msg = t1["sensor_msgs/msg/Imu"](
                        header=hdr,
                        orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                        orientation_covariance=np.zeros(9),
                        angular_velocity=V3(x=0.25 * i, y=0.0, z=-0.5),
                        angular_velocity_covariance=np.zeros(9),
                        linear_acceleration=V3(x=0.0, y=0.125, z=9.8125),
                        linear_acceleration_covariance=np.zeros(9),
                    )
                data = ts1.serialize_ros1(msg, ty)
                w.add_message(cid, log_time, bytes(data), log_time)
                out.append(
                    {
                        "topic": topic,
                        "type": name,
                        "log_time_ns": log_time,
                        "seq": 100 + i,
                        "stamp_ns": stamp,
                        "frame_id": f"f{i}",
                        "gyro_x": 0.25 * i,
                        "payload": bytes(data).hex(),
                    }
                )
        w.finish()
    return out


def main():
    out = Path(sys.argv[1])
    msgs = messages()
    files = {}
    files["sqlite_bag"] = write_rosbags(out / "sqlite_bag", msgs, StoragePlugin.SQLITE3)
    files["mcap_bag"] = write_rosbags(out / "mcap_bag", msgs, StoragePlugin.MCAP)
    files["sqlite_msg_zstd"] = write_rosbags(
        out / "sqlite_msg_zstd", msgs, StoragePlugin.SQLITE3, CompressionMode.MESSAGE
    )
    files["sqlite_file_zstd"] = write_rosbags(
        out / "sqlite_file_zstd", msgs, StoragePlugin.SQLITE3, CompressionMode.FILE
    )
    files = {k: {"kind": "ros2", "payloads": v} for k, v in files.items()}
    for name, comp in [
        ("plain_zstd.mcap", CompressionType.ZSTD),
        ("plain_lz4.mcap", CompressionType.LZ4),
        ("plain_none.mcap", CompressionType.NONE),
    ]:
        files[name] = {"kind": "mcap", "payloads": write_plain_mcap(out / name, msgs, comp)}
    manifest = {
        "messages": [
            {"topic": t, "type": ty, "log_time_ns": lt, "check": c} for t, ty, lt, _, c in msgs
        ],
        "files": files,
        "ros1": write_ros1_mcap(out / "ros1.mcap"),
    }
    json.dump(manifest, sys.stdout)


if __name__ == "__main__":
    main()
