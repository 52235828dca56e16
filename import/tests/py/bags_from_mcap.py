"""Rewrites a session exported by `milliego export-mcap` as the recordings users have, with the
independent `rosbags` writer:

  ti.bag     ROS 1, ti_mmwave_rospkg style: /ti_mmwave/radar_scan_pcl PointCloud2 (x y z intensity
             velocity, float32, point_step 32, ROS axes x forward), header.stamp ZERO and bag
             time 100-130 ms late (the driver's behaviour), a hardware trigger /radar/trigger
             (std_msgs/Header, seq k = scan k, stamped at the scan's start), /imu/data,
             /groundtruth/pose; plus ti.yaml, a rio-style calibration.
  ros2_db3/  ROS 2 bag, sqlite3 storage: the same streams with correct header stamps, no trigger.
  rig.toml, rig_session.toml   the rig's calibration as TOML (radar in ROS / session axes).
  csv/       the same streams in the CSV layout of docs/import.md (ROS radar axes, header times).

usage: bags_from_mcap.py EXPORT.mcap OUTDIR [--compression none|bz2|lz4]
Prints a JSON summary (messages per file and topic).
"""
import json
import math
import sys
from pathlib import Path

import numpy as np
from mcap_ros2.reader import read_ros2_messages
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

FRAME_MS = 20.0  # exposure written to the calibration; triggers mark the scan's start


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


# p_ti = M p_ros with M = [[0,-1,0],[1,0,0],[0,0,1]]: a +90 deg rotation about z, as (x y z w).
Q_TI_FROM_ROS = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))


def read_export(path):
    radar, imu, gt, tf = [], [], [], {}
    for m in read_ros2_messages(str(path)):
        t = m.channel.topic
        msg = m.ros_msg
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec if hasattr(msg, "header") else None
        if t == "/radar/points":
            names = [f.name for f in msg.fields]
            data = np.frombuffer(bytes(msg.data), dtype="<f4").reshape(-1, len(names))
            radar.append((stamp, data[:, names.index("x")], data[:, names.index("y")],
                          data[:, names.index("z")], data[:, names.index("velocity")],
                          data[:, names.index("snr")]))
        elif t == "/imu/data":
            imu.append((stamp, msg.angular_velocity, msg.linear_acceleration))
        elif t == "/groundtruth/pose":
            gt.append((stamp, msg.pose))
        elif t == "/tf_static":
            for x in msg.transforms:
                tf[x.child_frame_id] = x.transform
    return radar, imu, gt, tf


def ros_cloud(ts, header, x, y, z, v, snr):
    pf = ts.types["sensor_msgs/msg/PointField"]
    fields = [pf(name=n, offset=o, datatype=7, count=1)
              for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 16), ("velocity", 20))]
    n = len(x)
    buf = np.zeros((n, 8), dtype="<f4")
    # ROS axes: x forward = TI y, y left = -TI x.
    buf[:, 0], buf[:, 1], buf[:, 2] = y, -x, z
    buf[:, 4] = np.nan_to_num(snr, nan=0.0)
    buf[:, 5] = v
    return ts.types["sensor_msgs/msg/PointCloud2"](
        header=header, height=1, width=n, fields=fields, is_bigendian=False, point_step=32,
        row_step=32 * n, data=np.frombuffer(buf.tobytes(), dtype=np.uint8), is_dense=True)


def time_of(ts, ns):
    return ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(ts, ros1, seq, ns, frame):
    h = ts.types["std_msgs/msg/Header"]
    if ros1:
        return h(seq=seq, stamp=time_of(ts, ns), frame_id=frame)
    return h(stamp=time_of(ts, ns), frame_id=frame)


def imu_msg(ts, hdr, w, a):
    v3 = ts.types["geometry_msgs/msg/Vector3"]
    q = ts.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    cov = np.zeros(9)
    ocov = cov.copy()
    ocov[0] = -1.0
    return ts.types["sensor_msgs/msg/Imu"](
        header=hdr, orientation=q, orientation_covariance=ocov,
        angular_velocity=v3(x=w.x, y=w.y, z=w.z), angular_velocity_covariance=cov,
        linear_acceleration=v3(x=a.x, y=a.y, z=a.z), linear_acceleration_covariance=cov)


def pose_msg(ts, hdr, pose):
    return ts.types["geometry_msgs/msg/PoseStamped"](header=hdr, pose=pose)


def write(path_out, ros1, radar, imu, gt, compression):
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ser = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    msgs = []  # (bag time, topic, type, bytes)
    for k, (t, x, y, z, v, snr) in enumerate(radar):
        if ros1:
            late = 100_000_000 + int(30_000_000 * min(len(x), 200) / 200)
            hdr = header(ts, True, k, 0, "ti_mmwave")
            msgs.append((t + late, "/ti_mmwave/radar_scan_pcl", "sensor_msgs/msg/PointCloud2",
                         ser(ros_cloud(ts, hdr, x, y, z, v, snr), "sensor_msgs/msg/PointCloud2")))
            trig = t - int(FRAME_MS * 0.5e6)
            msgs.append((trig + 1_000_000, "/radar/trigger", "std_msgs/msg/Header",
                         ser(header(ts, True, k, trig, "imu"), "std_msgs/msg/Header")))
        else:
            hdr = header(ts, False, k, t, "radar")
            msgs.append((t + 5_000_000, "/radar/points", "sensor_msgs/msg/PointCloud2",
                         ser(ros_cloud(ts, hdr, x, y, z, v, snr), "sensor_msgs/msg/PointCloud2")))
    for k, (t, w, a) in enumerate(imu):
        msgs.append((t + 2_000_000, "/imu/data", "sensor_msgs/msg/Imu",
                     ser(imu_msg(ts, header(ts, ros1, k, t, "imu"), w, a), "sensor_msgs/msg/Imu")))
    for k, (t, pose) in enumerate(gt):
        msgs.append((t, "/groundtruth/pose", "geometry_msgs/msg/PoseStamped",
                     ser(pose_msg(ts, header(ts, ros1, k, t, "world"), pose), "geometry_msgs/msg/PoseStamped")))
    msgs.sort(key=lambda m: m[0])
    counts = {}
    if ros1:
        w = Writer1(path_out)
        if compression != "none":
            w.set_compression(getattr(Writer1.CompressionFormat, compression.upper()))
        w.chunk_threshold = 256 * 1024
    else:
        w = Writer2(path_out, version=8)
    with w:
        conns = {}
        for t, topic, ty, data in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, ty, typestore=ts)
            w.write(conns[topic], t, data)
            counts[topic] = counts.get(topic, 0) + 1
    return counts


def write_csv(d, radar, imu, gt):
    """The CSV layout of docs/import.md: ROS radar axes, times in seconds (repr: exact)."""
    d.mkdir(parents=True, exist_ok=True)
    s = lambda ns: repr(ns / 1e9)
    with open(d / "radar.csv", "w") as f:
        f.write("t,frame,x,y,z,doppler,snr\n")
        for k, (t, x, y, z, v, snr) in enumerate(radar):
            for i in range(len(x)):
                f.write(f"{s(t)},{k},{float(y[i])!r},{float(-x[i])!r},{float(z[i])!r},{float(v[i])!r},{float(snr[i])!r}\n")
    with open(d / "imu.csv", "w") as f:
        f.write("t,gx,gy,gz,ax,ay,az\n")
        for t, w, a in imu:
            f.write(f"{s(t)},{w.x!r},{w.y!r},{w.z!r},{a.x!r},{a.y!r},{a.z!r}\n")
    with open(d / "groundtruth.csv", "w") as f:
        f.write("# t x y z qx qy qz qw\nt,x,y,z,qx,qy,qz,qw\n")
        for t, p in gt:
            q, o = p.position, p.orientation
            f.write(f"{s(t)},{q.x!r},{q.y!r},{q.z!r},{o.x!r},{o.y!r},{o.z!r},{o.w!r}\n")
    return {"radar.csv": len(radar), "imu.csv": len(imu), "groundtruth.csv": len(gt)}


def main():
    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    compression = "none"
    if "--compression" in sys.argv:
        compression = sys.argv[sys.argv.index("--compression") + 1]
    out.mkdir(parents=True, exist_ok=True)
    radar, imu, gt, tf = read_export(src)
    summary = {"ti.bag": write(out / "ti.bag", True, radar, imu, gt, compression),
               "ros2_db3": write(out / "ros2_db3", False, radar, imu, gt, "none")}
    # The calibration: body <- radar in ROS axes = (body <- radar_ti) * (ti <- ros).
    r = tf.get("radar")
    q = (r.rotation.x, r.rotation.y, r.rotation.z, r.rotation.w) if r else (0.0, 0.0, 0.0, 1.0)
    qb = tuple(float(v) for v in quat_mul(q, Q_TI_FROM_ROS))
    t = (r.translation.x, r.translation.y, r.translation.z) if r else (0.0, 0.0, 0.0)
    (out / "ti.yaml").write_text(
        "".join(f"l_b_r_{a}: {v!r}\n" for a, v in zip("xyz", t))
        + "".join(f"q_b_r_{a}: {v!r}\n" for a, v in zip("xyzw", qb))
        + f"radar_frame_ms: {FRAME_MS}\nradar_rate: 10\n")
    # The same rig as TOML (both sensors; the radar in ROS axes, and in the session's for the MCAP).
    i = tf.get("imu")
    qi = (i.rotation.w, i.rotation.x, i.rotation.y, i.rotation.z) if i else (1.0, 0.0, 0.0, 0.0)
    ti = (i.translation.x, i.translation.y, i.translation.z) if i else (0.0, 0.0, 0.0)
    imu_toml = f"[imu]\ntranslation_m = {list(ti)!r}\nrotation_wxyz = {list(qi)!r}\n"
    (out / "rig.toml").write_text(
        f"[radar]\naxes = \"ros\"\nframe_ms = {FRAME_MS}\ntranslation_m = {list(t)!r}\n"
        f"rotation_wxyz = {[qb[3], qb[0], qb[1], qb[2]]!r}\n" + imu_toml)
    (out / "rig_session.toml").write_text(
        f"[radar]\naxes = \"session\"\ntranslation_m = {list(t)!r}\n"
        f"rotation_wxyz = {[q[3], q[0], q[1], q[2]]!r}\n" + imu_toml)
    summary["csv"] = write_csv(out / "csv", radar, imu, gt)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
