#!/usr/bin/env python3
"""An independent Foxglove WebSocket client (foxglove.websocket.v1) for the live view's tests.

Connects with the protocol's subprotocol, reads the advertised channels, subscribes to every one
(also those advertised later) and decodes each message: protobuf channels with the
foxglove-schemas-protobuf classes (picked by schema name), JSON channels with json. Runs until
the server closes the connection (or --seconds), then writes what it saw as JSON:

  {"channels": {topic: {"schemaName", "encoding", "schemaEncoding"}},
   "counts": {topic: n},
   "radar": [{"t", "n", "first": [x, y, z, doppler, snr] or null, "fields": [...]}],
   "pose": [{"t", "p": [x, y, z], "q": [x, y, z, w], "frame"}],
   "trajectory_last": {"frame", "poses": [[x, y, z, qx, qy, qz, qw], ...]},
   "gt_pose": [...], "gt_trajectory_last": ...,
   "tf_last": [{"parent", "child", "t": [x, y, z], "q": [x, y, z, w]}],
   "imu": {"n", "first", "last"}, "velocity_n", "health_last": {...}, "errors": [...]}

--stall: subscribe, then stop reading (the socket's receive buffer is made small) until
--seconds passed; writes only the channel list.

Needs: websockets, foxglove-schemas-protobuf (protobuf).
"""

import argparse
import importlib
import json
import socket
import struct
import sys
import time
import urllib.parse

from websockets.sync.client import connect
from websockets.exceptions import ConnectionClosed

SUBPROTOCOL = "foxglove.websocket.v1"


def pb_class(schema_name):
    # "foxglove.PointCloud" -> foxglove_schemas_protobuf.PointCloud_pb2.PointCloud
    name = schema_name.split(".")[-1]
    mod = importlib.import_module(f"foxglove_schemas_protobuf.{name}_pb2")
    return getattr(mod, name)


def stamp(ts):
    return ts.seconds + ts.nanos * 1e-9


def pose_list(p):
    return [p.position.x, p.position.y, p.position.z,
            p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--seconds", type=float, default=120.0)
    ap.add_argument("--stall", action="store_true")
    a = ap.parse_args()

    sock = None
    if a.stall:
        u = urllib.parse.urlparse(a.url)
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect((u.hostname, u.port))
    out = {"channels": {}, "counts": {}, "radar": [], "pose": [], "gt_pose": [],
           "trajectory_last": None, "gt_trajectory_last": None, "tf_last": None,
           "imu": {"n": 0, "first": None, "last": None}, "velocity_n": 0,
           "health_last": None, "health_n": 0, "server_info": None, "errors": []}
    try:
        with connect(a.url, subprotocols=[SUBPROTOCOL], sock=sock, max_size=None,
                     open_timeout=10, close_timeout=2) as ws:
            serve(ws, a, out)
    except ConnectionClosed:
        pass
    with open(a.out, "w") as f:
        json.dump(out, f)


def serve(ws, a, out):
    if ws.subprotocol != SUBPROTOCOL:
        sys.exit(f"server chose subprotocol {ws.subprotocol!r}")

    channels = {}   # channel id -> advertisement
    subs = {}       # subscription id -> (topic, decoder)
    next_sub = [1]
    def subscribe(chs):
        s = []
        for ch in chs:
            sid = next_sub[0]
            next_sub[0] += 1
            if ch["encoding"] == "protobuf":
                cls = pb_class(ch["schemaName"])
                dec = (lambda cls: lambda b: cls.FromString(b))(cls)
            elif ch["encoding"] == "json":
                dec = lambda b: json.loads(b)
            else:
                out["errors"].append(f"{ch['topic']}: unknown encoding {ch['encoding']}")
                continue
            subs[sid] = (ch["topic"], dec)
            s.append({"id": sid, "channelId": ch["id"]})
        if s:
            ws.send(json.dumps({"op": "subscribe", "subscriptions": s}))

    def on_message(topic, m):
        out["counts"][topic] = out["counts"].get(topic, 0) + 1
        if topic == "/radar/points":
            fields = [(f.name, f.offset, f.type) for f in m.fields]
            n = len(m.data) // m.point_stride if m.point_stride else 0
            first = list(struct.unpack_from("<5f", m.data, 0)) if n else None
            out["radar"].append({"t": stamp(m.timestamp), "n": n, "first": first,
                                 "frame": m.frame_id, "fields": [f[0] for f in fields]})
        elif topic in ("/pose", "/ground_truth/pose"):
            pl = pose_list(m.pose)
            key = "pose" if topic == "/pose" else "gt_pose"
            out[key].append({"t": stamp(m.timestamp), "p": pl[:3], "q": pl[3:], "frame": m.frame_id})
        elif topic in ("/trajectory", "/ground_truth/trajectory"):
            key = "trajectory_last" if topic == "/trajectory" else "gt_trajectory_last"
            out[key] = {"frame": m.frame_id, "t": stamp(m.timestamp),
                        "poses": [pose_list(p) for p in m.poses]}
        elif topic == "/tf":
            out["tf_last"] = [{"parent": t.parent_frame_id, "child": t.child_frame_id,
                               "t": [t.translation.x, t.translation.y, t.translation.z],
                               "q": [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w]}
                              for t in m.transforms]
        elif topic == "/imu":
            out["imu"]["n"] += 1
            if out["imu"]["first"] is None:
                out["imu"]["first"] = m
            out["imu"]["last"] = m
        elif topic == "/velocity":
            out["velocity_n"] += 1
        elif topic == "/health":
            out["health_n"] += 1
            out["health_last"] = m

    deadline = time.monotonic() + a.seconds
    try:
        while time.monotonic() < deadline:
            if a.stall and subs:
                # Subscribed: stop reading; the server's queue for us fills.
                time.sleep(max(0.0, deadline - time.monotonic()))
                break
            try:
                msg = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
            except TimeoutError:
                break
            if isinstance(msg, str):
                j = json.loads(msg)
                op = j.get("op")
                if op == "serverInfo":
                    out["server_info"] = j
                elif op == "advertise":
                    for ch in j["channels"]:
                        channels[ch["id"]] = ch
                        out["channels"][ch["topic"]] = {k: ch.get(k) for k in
                                                        ("schemaName", "encoding", "schemaEncoding")}
                    subscribe(j["channels"])
                elif op == "status" and j.get("level", 0) >= 2:
                    out["errors"].append(j.get("message"))
                continue
            op = msg[0]
            if op != 0x01:  # 0x02: time
                continue
            sid, _log_time = struct.unpack_from("<IQ", msg, 1)
            if sid not in subs:
                continue
            topic, dec = subs[sid]
            try:
                on_message(topic, dec(msg[13:]))
            except Exception as e:  # noqa: BLE001 - every decoding failure is reported
                out["errors"].append(f"{topic}: {e}")
    except ConnectionClosed:
        pass


if __name__ == "__main__":
    main()
