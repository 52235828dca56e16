"""Writes ROS 1 bags with the independent `rosbags` writer and prints a JSON manifest.

Usage: write_bag1.py OUTDIR

Writes OUTDIR/none.bag, OUTDIR/bz2.bag and OUTDIR/lz4.bag: the same messages, chunks compressed
(or not) as named, with a small chunk threshold so each bag has several chunks. Topics:

- /radar/points  sensor_msgs/PointCloud2  (x, y, z, intensity as float32)
- /imu           sensor_msgs/Imu          (two connections: callerids /imu_a and /imu_b)
- /header        std_msgs/Header
- /pose          geometry_msgs/PoseStamped
- /empty         std_msgs/Header          (a connection with no messages)

The manifest (stdout): {"bags": {compression: path}, "topics": [{topic, type, count,
first_ns, last_ns}], "messages": [{topic, type, log_time_ns, hex, values}]} in write order, where
`values` are the fields the writer set (header seq / stamp_ns / frame_id, and per type the
vectors), for the reader's decoders to be checked against.
"""

import json
import struct
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS1_NOETIC)
T = TS.types
T0 = 1_700_000_000_123_456_789  # first log time [ns]


def stamp(ns):
    return T['builtin_interfaces/msg/Time'](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(seq, ns, frame):
    return T['std_msgs/msg/Header'](seq=seq, stamp=stamp(ns), frame_id=frame)


def header_values(seq, ns, frame):
    return {'seq': seq, 'stamp_ns': ns, 'frame_id': frame}


def vec3(v):
    return T['geometry_msgs/msg/Vector3'](x=v[0], y=v[1], z=v[2])


def quat(q):
    return T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3])


def cloud(i, ns):
    n = 3 + i % 5
    names = ['x', 'y', 'z', 'intensity']
    fields = [
        T['sensor_msgs/msg/PointField'](name=name, offset=4 * k, datatype=7, count=1)
        for k, name in enumerate(names)
    ]
    pts = [(0.5 * p + i, -0.25 * p, 0.125 * i, 10.0 + p) for p in range(n)]
    data = b''.join(struct.pack('<4f', *p) for p in pts)
    msg = T['sensor_msgs/msg/PointCloud2'](
        header=header(i, ns, 'radar'), height=1, width=n, fields=fields, is_bigendian=False,
        point_step=16, row_step=16 * n, data=np.frombuffer(data, dtype=np.uint8), is_dense=True)
    values = {'header': header_values(i, ns, 'radar'), 'width': n, 'fields': names,
              'point_step': 16, 'data': data.hex()}
    return msg, values


def imu(i, ns):
    q = [0.0, 0.0, 0.6, 0.8]
    # Binary fractions, so the JSON round trip is exact.
    w = [0.015625 * i, -0.03125 * i, 0.5]
    a = [0.125, 0.25 * i, 9.8125]
    msg = T['sensor_msgs/msg/Imu'](
        header=header(i, ns, 'imu'), orientation=quat(q), orientation_covariance=np.zeros(9),
        angular_velocity=vec3(w), angular_velocity_covariance=np.full(9, 0.5),
        linear_acceleration=vec3(a), linear_acceleration_covariance=np.eye(3).ravel())
    values = {'header': header_values(i, ns, 'imu'), 'orientation': q, 'angular_velocity': w,
              'linear_acceleration': a}
    return msg, values


def plain_header(i, ns):
    frame = f'frame{i}'
    return header(i, ns, frame), {'header': header_values(i, ns, frame)}


def pose(i, ns):
    p = [1.0 * i, 2.0 * i, -3.5]
    q = [0.0, 0.0, 0.0, 1.0]
    msg = T['geometry_msgs/msg/PoseStamped'](
        header=header(i, ns, 'map'),
        pose=T['geometry_msgs/msg/Pose'](
            position=T['geometry_msgs/msg/Point'](x=p[0], y=p[1], z=p[2]), orientation=quat(q)))
    return msg, {'header': header_values(i, ns, 'map'), 'position': p, 'orientation': q}


def messages():
    """(topic, connection key, ros type, log time ns, message, values) in write order."""
    out = []
    for i in range(40):
        t = T0 + i * 10_000_000
        out.append(('/imu', 'imu_a' if i % 2 == 0 else 'imu_b', 'sensor_msgs/msg/Imu', t + 1,
                    *imu(i, t - 5)))
        if i % 4 == 0:
            out.append(('/radar/points', 'radar', 'sensor_msgs/msg/PointCloud2', t + 2,
                        *cloud(i // 4, t - 7)))
        if i % 5 == 0:
            out.append(('/header', 'header', 'std_msgs/msg/Header', t + 3,
                        *plain_header(i // 5, t)))
        if i % 8 == 3:
            out.append(('/pose', 'pose', 'geometry_msgs/msg/PoseStamped', t + 4, *pose(i // 8, t)))
    return out


CONNECTIONS = {
    'imu_a': ('/imu', 'sensor_msgs/msg/Imu', '/imu_a'),
    'imu_b': ('/imu', 'sensor_msgs/msg/Imu', '/imu_b'),
    'radar': ('/radar/points', 'sensor_msgs/msg/PointCloud2', None),
    'header': ('/header', 'std_msgs/msg/Header', None),
    'pose': ('/pose', 'geometry_msgs/msg/PoseStamped', None),
    'empty': ('/empty', 'std_msgs/msg/Header', None),
}


def write(path, compression, msgs):
    w = Writer(path)
    if compression != 'none':
        w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    w.chunk_threshold = 1500  # [B]: several chunks
    with w:
        conns = {key: w.add_connection(topic, ty, typestore=TS, callerid=caller)
                 for key, (topic, ty, caller) in CONNECTIONS.items()}
        for topic, key, ty, t, msg, _ in msgs:
            w.write(conns[key], t, TS.serialize_ros1(msg, ty))


def topics(msgs):
    out = {}
    for topic, _, ty, t, _, _ in msgs:
        e = out.setdefault(topic, {'topic': topic, 'type': ty.replace('/msg/', '/'), 'count': 0,
                                   'first_ns': t, 'last_ns': t})
        e['count'] += 1
        e['first_ns'] = min(e['first_ns'], t)
        e['last_ns'] = max(e['last_ns'], t)
    out['/empty'] = {'topic': '/empty', 'type': 'std_msgs/Header', 'count': 0,
                     'first_ns': None, 'last_ns': None}
    return sorted(out.values(), key=lambda e: e['topic'])


def main():
    outdir = Path(sys.argv[1])
    msgs = messages()
    bags = {}
    for compression in ['none', 'bz2', 'lz4']:
        path = outdir / f'{compression}.bag'
        write(path, compression, msgs)
        bags[compression] = str(path)
    manifest = {
        'bags': bags,
        'topics': topics(msgs),
        'messages': [{'topic': topic, 'type': ty.replace('/msg/', '/'), 'log_time_ns': t,
                      'hex': TS.serialize_ros1(msg, ty).hex(), 'values': values}
                     for topic, _, ty, t, msg, values in msgs],
    }
    json.dump(manifest, sys.stdout)


if __name__ == '__main__':
    main()
