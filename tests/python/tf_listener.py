#!/usr/bin/env python3
"""An independent `/tf` listener of a live ROS 2 team, for tests/tests/ros2_team.rs.

Nothing here is formation code: `eclipse-zenoh` connects to the team's Zenoh router as a client
and subscribes to rmw_zenoh's data keys of `/tf` and `/tf_static`
(`<domain>/<topic>/tf2_msgs::msg::dds_::TFMessage_/RIHS01_<hash>`, the hash from `rosbags`), and
`rosbags` (`Stores.ROS2_JAZZY`) decodes every sample as a `tf2_msgs/msg/TFMessage`.

Usage:
    tf_listener.py --connect tcp/127.0.0.1:PORT [--domain 0] [--quiet-s 3] [--limit-s 120]

It prints one JSON object per transform received, `{"topic", "sec", "nanosec", "parent",
"child", "x", "y", "z", "qx", "qy", "qz", "qw"}`, and ends when `/tf` has been quiet for
`--quiet-s` after its first sample (the run ended), or after `--limit-s` (exit 1: nothing came).
"""

import argparse
import json
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
TF = "tf2_msgs/msg/TFMessage"
DDS_NAME = "tf2_msgs::msg::dds_::TFMessage_"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--connect", required=True)
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--quiet-s", type=float, default=3.0)
    parser.add_argument("--limit-s", type=float, default=120.0)
    args = parser.parse_args()

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("scouting/multicast/enabled", "false")
    started = time.monotonic()
    session = None
    while session is None:
        try:
            session = zenoh.open(config)
        except Exception:  # the router is not up yet
            if time.monotonic() - started > args.limit_s:
                print(f"could not connect to {args.connect}", file=sys.stderr)
                return 1
            time.sleep(0.2)

    lock = threading.Lock()
    last = [None]
    type_hash = TS.hash_rihs01(TF)

    def on_sample(sample):
        topic = "/" + str(sample.key_expr).split("/")[1]
        message = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), TF)
        lines = []
        for edge in message.transforms:
            t, r = edge.transform.translation, edge.transform.rotation
            lines.append(json.dumps({
                "topic": topic,
                "sec": edge.header.stamp.sec,
                "nanosec": edge.header.stamp.nanosec,
                "parent": edge.header.frame_id,
                "child": edge.child_frame_id,
                "x": t.x, "y": t.y, "z": t.z,
                "qx": r.x, "qy": r.y, "qz": r.z, "qw": r.w,
            }))
        with lock:
            for line in lines:
                print(line)
            sys.stdout.flush()
            if topic == "/tf":
                last[0] = time.monotonic()

    subscribers = [
        session.declare_subscriber(f"{args.domain}/{topic}/{DDS_NAME}/{type_hash}", on_sample)
        for topic in ("tf", "tf_static")
    ]
    while True:
        time.sleep(0.1)
        with lock:
            seen = last[0]
        now = time.monotonic()
        if seen is not None and now - seen > args.quiet_s:
            break
        if seen is None and now - started > args.limit_s:
            print("no /tf sample came", file=sys.stderr)
            return 1
    for subscriber in subscribers:
        subscriber.undeclare()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
