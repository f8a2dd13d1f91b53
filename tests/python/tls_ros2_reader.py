#!/usr/bin/env python3
"""Independent clients of a live ROS 2 team on a `tls/` router, for tests/tests/ros2_tls.rs.

Nothing here is formation code: `eclipse-zenoh` opens client sessions to the team's Zenoh router
with a TLS configuration written here from the credentials folder's PEM files (the team's
`ca.pem`, a principal's `NAME.pem` and `NAME.key.pem`), and `rosbags` (`Stores.ROS2_JAZZY`)
decodes what arrives on rmw_zenoh's data keys (`<domain>/<topic>/<type>/<hash>`).

Usage:
    tls_ros2_reader.py --connect tls/127.0.0.1:PORT --credentials DIR --robot I [--other DIR]
                       [--seconds 8] [--limit-s 60]

Up to four sessions, kept for `--seconds`; the robot's is opened first, retried for `--limit-s`
while the router starts:
  * `robot`: robot I's certificate; subscribes to `/tf`, its own `/robot_I/scan`, another robot's
    `/robot_J/scan` (J != I), and puts 20 forged Twists on robot J's `cmd_vel`;
  * `recorder`: the recorder's certificate; subscribes to robot J's `cmd_vel` (to see whether a
    forged Twist got through) and to `/tf`;
  * `bare`: no certificate (the team's CA only); subscribes to everything of the domain;
  * `stranger`: a certificate of another authority (`--other DIR`), when given.

It prints one JSON object: per session whether it opened (`opened`, `error`) and its counts:
`tf` (decoded /tf messages), `scan` (decoded LaserScans of robot I, with `beams` of the last),
`other_scan` (robot J's scans), `cmd_vel_seen` (every Twist the recorder saw on robot J's
`cmd_vel`, its agent's included), `forged_seen` (those that came from the robot session), `any` (every sample, for the bare and stranger sessions).
"""

import argparse
import json
import os
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)


def config_for(connect: str, ca: str, cert: str | None, key: str | None) -> zenoh.Config:
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([connect]))
    config.insert_json5("connect/timeout_ms", "2000")
    config.insert_json5("connect/exit_on_failure", "true")
    config.insert_json5("scouting/multicast/enabled", "false")
    tls = {"root_ca_certificate": ca, "verify_name_on_connect": False}
    if cert is not None:
        tls.update({
            "connect_certificate": cert,
            "connect_private_key": key,
            "enable_mtls": True,
        })
    config.insert_json5("transport/link/tls", json.dumps(tls))
    return config


class Counts:
    def __init__(self):
        self.lock = threading.Lock()
        self.values = {}

    def add(self, name: str, value: int = 1):
        with self.lock:
            self.values[name] = self.values.get(name, 0) + value

    def set(self, name: str, value):
        with self.lock:
            self.values[name] = value


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--connect", required=True)
    parser.add_argument("--credentials", required=True)
    parser.add_argument("--other")
    parser.add_argument("--robot", type=int, required=True)
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--limit-s", type=float, default=60.0)
    args = parser.parse_args()
    creds = args.credentials
    me, other = args.robot, (args.robot + 1) % args.robots
    d = args.domain
    ca = os.path.join(creds, "ca.pem")

    def own(name, folder=creds):
        return (os.path.join(folder, f"{name}.pem"), os.path.join(folder, f"{name}.key.pem"))

    sessions = {}
    report = {}
    plans = {
        "robot": (ca, *own(f"robot-{me}")),
        "recorder": (ca, *own("recorder")),
        "bare": (ca, None, None),
    }
    if args.other:
        plans["stranger"] = (os.path.join(args.other, "ca.pem"), *own(f"robot-{me}", args.other))
    # The robot's session first, retried while the router starts, then the recorder's; their
    # subscriptions are declared at once, before the refused sessions take their time.
    started = time.monotonic()
    while "robot" not in sessions:
        try:
            sessions["robot"] = zenoh.open(config_for(args.connect, *plans["robot"]))
            report["robot"] = {"opened": True}
        except Exception as e:  # the router is not up yet
            if time.monotonic() - started > args.limit_s:
                report["robot"] = {"opened": False, "error": str(e)}
                break
            time.sleep(0.2)

    def try_open(name):
        try:
            sessions[name] = zenoh.open(config_for(args.connect, *plans[name]))
            report[name] = {"opened": True}
        except Exception as e:  # refused: no session at all
            report[name] = {"opened": False, "error": str(e)}

    try_open("recorder")
    counts = {name: Counts() for name in plans}
    keep = []

    def tf_counter(c):
        def on(sample):
            TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "tf2_msgs/msg/TFMessage")
            c.add("tf")
        return on

    if "robot" in sessions:
        s, c = sessions["robot"], counts["robot"]
        keep.append(s.declare_subscriber(f"{d}/tf/**", tf_counter(c)))

        def on_scan(sample, c=c):
            scan = TS.deserialize_cdr(bytes(sample.payload.to_bytes()), "sensor_msgs/msg/LaserScan")
            c.add("scan")
            c.set("beams", len(scan.ranges))
        keep.append(s.declare_subscriber(f"{d}/robot_{me}/scan/**", on_scan))
        keep.append(s.declare_subscriber(
            f"{d}/robot_{other}/scan/**", lambda _s, c=c: c.add("other_scan")))
    if "recorder" in sessions:
        s, c = sessions["recorder"], counts["recorder"]
        keep.append(s.declare_subscriber(f"{d}/tf/**", tf_counter(c)))

        def on_forged(sample, c=c):
            c.add("cmd_vel_seen")
            if str(sample.key_expr).endswith("/forged/by-robot"):
                c.add("forged_seen")
        keep.append(s.declare_subscriber(f"{d}/robot_{other}/cmd_vel/**", on_forged))
    for name in ("bare", "stranger"):
        if name not in plans:
            continue
        try_open(name)
        if name in sessions:
            c = counts[name]
            keep.append(sessions[name].declare_subscriber(f"{d}/**", lambda _s, c=c: c.add("any")))

    started = time.monotonic()
    forged = 0
    while time.monotonic() - started < args.seconds:
        if "robot" in sessions and forged < 20:
            sessions["robot"].put(f"{d}/robot_{other}/cmd_vel/forged/by-robot", b"\0" * 48)
            forged += 1
        time.sleep(0.1)
    for name, c in counts.items():
        with c.lock:
            report[name].update(c.values)
    report["forged_sent"] = forged
    print(json.dumps(report), flush=True)
    del keep
    for s in sessions.values():
        s.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
