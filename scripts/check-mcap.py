#!/usr/bin/env python3
"""Decode every message of a milliEgo MCAP export with the `mcap` and `mcap-ros2-support` PyPI
packages (the reader Foxglove's tooling and ros2 bag users rely on) and check it.

Usage: check-mcap.py FILE.mcap [EXPECT.json]

Always checked: the ros2 profile, ros2msg schemas and cdr channels, a summary with chunk indexes
(seekable), every message decodes with its ROS 2 schema, log times never decrease, each header
stamp equals its log time, PointCloud2 data is width * point_step bytes with fields
x, y, z, velocity, snr.
EXPECT.json (optional) holds {"counts": {topic: n}, "first_cloud_points": n,
"first_imu_angular_velocity": [x, y, z], "first_pose": {"topic": t, "position": [x, y, z],
"orientation": [x, y, z, w]}, "tol": 1e-9}.
Prints one line per topic and "ok"; exits 1 with the reasons otherwise.
"""
import json
import struct
import sys
from collections import Counter

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main():
    if len(sys.argv) not in (2, 3):
        print(__doc__, file=sys.stderr)
        return 2
    path = sys.argv[1]
    expect = {}
    if len(sys.argv) == 3:
        with open(sys.argv[2]) as f:
            expect = json.load(f)
    tol = expect.get("tol", 1e-9)
    errors = []
    counts = Counter()
    first = {}
    last_log = None
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        if header.profile != "ros2":
            errors.append(f"profile {header.profile!r}, expected 'ros2'")
        summary = reader.get_summary()
        if summary is None:
            errors.append("no summary section")
        else:
            if not summary.chunk_indexes:
                errors.append("no chunk indexes")
            for ch in summary.channels.values():
                sc = summary.schemas.get(ch.schema_id)
                if ch.message_encoding != "cdr" or sc is None or sc.encoding != "ros2msg":
                    errors.append(f"{ch.topic}: not a ros2msg/cdr channel")
                if "offered_qos_profiles" not in ch.metadata:
                    errors.append(f"{ch.topic}: no offered_qos_profiles")
        for schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
            topic = channel.topic
            counts[topic] += 1
            if last_log is not None and message.log_time < last_log:
                errors.append(f"{topic}: log time {message.log_time} before {last_log}")
            last_log = message.log_time
            if message.publish_time != message.log_time:
                errors.append(f"{topic}: publish time differs from log time")
            stamps = [t.header.stamp for t in msg.transforms] if schema.name == "tf2_msgs/msg/TFMessage" else [msg.header.stamp]
            for st in stamps:
                if st.sec * 1_000_000_000 + st.nanosec != message.log_time:
                    errors.append(f"{topic}: header stamp {st.sec}.{st.nanosec:09d} != log time {message.log_time}")
            if schema.name == "sensor_msgs/msg/PointCloud2":
                names = [fl.name for fl in msg.fields]
                if names != ["x", "y", "z", "velocity", "snr"] or msg.point_step != 20:
                    errors.append(f"{topic}: fields {names}, point_step {msg.point_step}")
                if len(msg.data) != msg.width * msg.point_step or msg.height != 1:
                    errors.append(f"{topic}: {len(msg.data)} data bytes for {msg.height}x{msg.width} points")
            if topic not in first:
                first[topic] = msg
    for topic, n in sorted(counts.items()):
        print(f"{topic:<28} {n:>8}")

    def close(a, b):
        return len(a) == len(b) and all(abs(x - y) <= tol for x, y in zip(a, b))

    for topic, n in expect.get("counts", {}).items():
        if counts.get(topic, 0) != n:
            errors.append(f"{topic}: {counts.get(topic, 0)} messages, expected {n}")
    if "first_cloud_points" in expect:
        cloud = first.get("/radar/points")
        got = cloud.width if cloud is not None else None
        if got != expect["first_cloud_points"]:
            errors.append(f"first cloud: {got} points, expected {expect['first_cloud_points']}")
        elif got:
            x = struct.unpack_from("<f", cloud.data, 0)[0]
            if "first_cloud_x" in expect and abs(x - expect["first_cloud_x"]) > 1e-6:
                errors.append(f"first cloud: x {x}, expected {expect['first_cloud_x']}")
    if "first_imu_angular_velocity" in expect:
        imu = first.get("/imu/data")
        got = [imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z] if imu else []
        if not close(got, expect["first_imu_angular_velocity"]):
            errors.append(f"first IMU angular velocity {got}, expected {expect['first_imu_angular_velocity']}")
        if imu and imu.orientation_covariance[0] != -1.0:
            errors.append("IMU orientation not marked unknown")
    if "first_pose" in expect:
        want = expect["first_pose"]
        m = first.get(want["topic"])
        got = []
        if m is not None:
            p, q = m.pose.position, m.pose.orientation
            got = [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
        if not close(got, want["position"] + want["orientation"]):
            errors.append(f"{want['topic']}: first pose {got}, expected {want['position'] + want['orientation']}")
    if errors:
        for e in errors[:20]:
            print(f"{path}: {e}", file=sys.stderr)
        return 1
    print(f"ok: {sum(counts.values())} messages decoded from {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
