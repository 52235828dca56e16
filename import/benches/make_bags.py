"""Writes the recordings the import throughput benchmark reads, with the independent `rosbags`
writer: a ti_mmwave_rospkg-like rig of SECONDS seconds.

Usage: make_bags.py OUTDIR SECONDS

- OUTDIR/none.bag, OUTDIR/lz4.bag   ROS 1 (uncompressed / lz4 chunks, rosbags' default 768 KiB
                                    chunk threshold)
- OUTDIR/ros2/                      ROS 2 bag, sqlite3 storage
Topics: /ti_mmwave/radar_scan_pcl PointCloud2 at 20 Hz (256 points of x y z intensity velocity,
float32, point_step 32 as ti_mmwave_rospkg writes), /imu/data Imu at 400 Hz, /radar/trigger Header
at 20 Hz, /groundtruth/pose PoseStamped at 100 Hz. Values are deterministic (seeded).
Prints a JSON summary (file sizes in bytes, messages per topic).
"""
import json
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

T0 = 1_700_000_000_000_000_000  # [ns]
POINTS = 256
RADAR_HZ, IMU_HZ, GT_HZ = 20, 400, 100


def build(ts, seconds):
    """(topic, type, time ns, message) in time order."""
    T = ts.types
    rng = np.random.default_rng(7)

    def stamp(ns):
        return T['builtin_interfaces/msg/Time'](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(seq, ns, frame):
        kw = dict(stamp=stamp(ns), frame_id=frame)
        if 'seq' in T['std_msgs/msg/Header'].__dataclass_fields__:
            kw['seq'] = seq
        return T['std_msgs/msg/Header'](**kw)

    def vec3(x, y, z):
        return T['geometry_msgs/msg/Vector3'](x=x, y=y, z=z)

    fields = [T['sensor_msgs/msg/PointField'](name=n, offset=4 * k, datatype=7, count=1)
              for k, n in enumerate(['x', 'y', 'z', 'intensity', 'velocity'])]
    q = T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)
    out = []
    for i in range(seconds * IMU_HZ):
        ns = T0 + i * 1_000_000_000 // IMU_HZ
        a = rng.normal(0.0, 0.05, 3)
        out.append(('/imu/data', 'sensor_msgs/msg/Imu', ns, T['sensor_msgs/msg/Imu'](
            header=header(i, ns, 'imu'), orientation=q, orientation_covariance=np.zeros(9),
            angular_velocity=vec3(*rng.normal(0.0, 0.01, 3)),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec3(a[0], a[1], 9.81 + a[2]),
            linear_acceleration_covariance=np.zeros(9))))
    for i in range(seconds * RADAR_HZ):
        ns = T0 + i * 1_000_000_000 // RADAR_HZ
        pts = np.zeros((POINTS, 8), dtype='<f4')
        pts[:, 0] = rng.uniform(0.5, 8.0, POINTS)
        pts[:, 1] = rng.uniform(-4.0, 4.0, POINTS)
        pts[:, 2] = rng.uniform(-1.0, 1.0, POINTS)
        pts[:, 3] = rng.uniform(5.0, 40.0, POINTS)
        pts[:, 4] = rng.normal(0.0, 0.2, POINTS)
        out.append(('/radar/trigger', 'std_msgs/msg/Header', ns, header(i, ns, 'radar')))
        # Published late, like ti_mmwave_rospkg; the trigger times the scan.
        late = ns + 110_000_000
        out.append(('/ti_mmwave/radar_scan_pcl', 'sensor_msgs/msg/PointCloud2', late,
                    T['sensor_msgs/msg/PointCloud2'](
                        header=header(i, late, 'radar'), height=1, width=POINTS, fields=fields,
                        is_bigendian=False, point_step=32, row_step=32 * POINTS,
                        data=pts.view(np.uint8).ravel(), is_dense=True)))
    for i in range(seconds * GT_HZ):
        ns = T0 + i * 1_000_000_000 // GT_HZ
        out.append(('/groundtruth/pose', 'geometry_msgs/msg/PoseStamped', ns,
                    T['geometry_msgs/msg/PoseStamped'](
                        header=header(i, ns, 'map'),
                        pose=T['geometry_msgs/msg/Pose'](
                            position=T['geometry_msgs/msg/Point'](x=0.01 * i, y=0.0, z=0.0),
                            orientation=q))))
    out.sort(key=lambda m: m[2])
    return out


def main():
    outdir, seconds = Path(sys.argv[1]), int(sys.argv[2])
    outdir.mkdir(parents=True, exist_ok=True)
    summary = {'files': {}, 'messages': {}}
    ts1 = get_typestore(Stores.ROS1_NOETIC)
    msgs = build(ts1, seconds)
    for m in msgs:
        summary['messages'][m[0]] = summary['messages'].get(m[0], 0) + 1
    for comp in ['none', 'lz4']:
        path = outdir / f'{comp}.bag'
        path.unlink(missing_ok=True)
        w = Writer1(path)
        if comp != 'none':
            w.set_compression(Writer1.CompressionFormat.LZ4)
        with w:
            conns = {}
            for topic, ty, ns, msg in msgs:
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, ty, typestore=ts1)
                w.write(conns[topic], ns, ts1.serialize_ros1(msg, ty))
        summary['files'][f'ros1-{comp}'] = path.stat().st_size
    ts2 = get_typestore(Stores.ROS2_HUMBLE)
    msgs = build(ts2, seconds)
    path = outdir / 'ros2'
    if path.exists():
        for f in path.iterdir():
            f.unlink()
        path.rmdir()
    with Writer2(path, version=8) as w:
        conns = {}
        for topic, ty, ns, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, ty, typestore=ts2)
            w.write(conns[topic], ns, ts2.serialize_cdr(msg, ty))
    summary['files']['ros2-sqlite3'] = sum(f.stat().st_size for f in path.iterdir())
    json.dump(summary, sys.stdout)


if __name__ == '__main__':
    main()
