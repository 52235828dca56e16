"""The peer of the import throughput benchmark: the `rosbags` reader (what Python users of ROS
recordings read bags with) reading every message of PATH (a ROS 1 bag or a ROS 2 bag directory)
and deserialising it, point clouds viewed as float32 arrays.

Usage: peer_read.py PATH
Prints {"seconds": wall time of the read (interpreter start-up excluded), "messages": N}.
"""
import json
import sys
import time
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader


def main():
    path = Path(sys.argv[1])
    t0 = time.perf_counter()
    n = 0
    points = 0
    with AnyReader([path]) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype == 'sensor_msgs/msg/PointCloud2':
                points += np.frombuffer(msg.data, dtype='<f4').size
            n += 1
    dt = time.perf_counter() - t0
    json.dump({'seconds': dt, 'messages': n, 'floats': points}, sys.stdout)


if __name__ == '__main__':
    main()
