#!/usr/bin/env python3
"""Independent readers of a formation recording, for tests/tests/record.rs.

Only third-party readers are used here, none of formation's code: the `mcap` package with
`mcap-ros2-support` (decoding from the schemas the file carries), `rosbags` (reading the file as
a rosbag2, deserialising with its own ROS 2 Jazzy types) and Rerun (`rerun mcap convert`, then
the .rrd read back with Rerun's Python API). Every subcommand prints one JSON object on stdout
and exits 0; a check that fails exits 1 saying what failed; a missing package exits 3 with the
fix.

    mcap_readers.py check
    mcap_readers.py decode FILE RUN_LOG ROBOTS      every ROS 2 message, /tf against the run log
    mcap_readers.py rosbags FILE ROBOTS             LaserScan, Odometry and Twist through rosbags
    mcap_readers.py rerun FILE RRD ROBOTS           rerun mcap convert, then the .rrd's entities
    mcap_readers.py stream FILE                     the streaming reader on a pipe (a crashed file)
    mcap_readers.py compare FILE_A FILE_B           the decoded ROS 2 messages of two recordings
    mcap_readers.py metadata FILE                   the run's metadata record (formation.run)
    mcap_readers.py attachments FILE                every attachment (name, media type, size,
                                                    SHA-256) and formation.swapped_model record
"""

import collections
import json
import math
import os
import shutil
import subprocess
import sys

MISSING_PACKAGE = 3
ROS2_TOPICS = ("scan", "odom", "cmd_vel", "replay")


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


def need(condition, message):
    if not condition:
        fail(message)


def imports():
    try:
        import mcap  # noqa: F401
        import mcap_ros2  # noqa: F401
        import rerun  # noqa: F401
        import rosbags  # noqa: F401
    except ImportError as e:
        print(
            f"missing Python package ({e}); install the test requirements with "
            "`bash .ci/setup-python --test` (tests/python/requirements-record.txt)",
            file=sys.stderr,
        )
        sys.exit(MISSING_PACKAGE)


def yaw(q):
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def decoded_messages(path):
    """(topic, log_time, decoded) of every CDR message, in log-time order, with mcap-ros2."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            need(schema.encoding == "ros2msg", f"{channel.topic}: schema encoding {schema.encoding}")
            need(channel.message_encoding == "cdr", f"{channel.topic}: {channel.message_encoding}")
            yield channel.topic, message.log_time, decoded, message.data


def decode(path, run_log, robots):
    with open(run_log) as f:
        trajectory = json.load(f)["trajectory"]
    times, poses = trajectory["times"], trajectory["poses"]
    counts = collections.Counter()
    worst = 0.0
    tf_samples = 0
    for topic, log_time, msg, _ in decoded_messages(path):
        counts[topic] += 1
        if topic != "/tf":
            continue
        for t in msg.transforms:
            need(t.header.frame_id == "world", f"/tf parent {t.header.frame_id}")
            robot = int(t.child_frame_id.split("/")[0][len("robot_"):])
            stamp = t.header.stamp.sec + 1e-9 * t.header.stamp.nanosec
            k = round(stamp / trajectory["dt"])
            need(abs(times[k] - stamp) < 1e-6, f"/tf stamp {stamp} is not sample {k}'s {times[k]}")
            pose = poses[k][robot]
            tr = t.transform.translation
            err = max(abs(tr.x - pose["x"]), abs(tr.y - pose["y"]))
            dtheta = math.remainder(yaw(t.transform.rotation) - pose["theta"], 2 * math.pi)
            need(abs(dtheta) < 1e-6, f"robot {robot} sample {k}: yaw off by {dtheta}")
            worst = max(worst, err)
            tf_samples += 1
    for robot in range(robots):
        for name in ROS2_TOPICS:
            need(counts[f"/robot_{robot}/{name}"] > 0, f"no /robot_{robot}/{name} message")
    need(tf_samples == robots * len(poses), f"{tf_samples} /tf poses for {len(poses)} samples")
    need(worst <= 1e-6, f"/tf differs from the run log by {worst} m")
    print(json.dumps({"messages": sum(counts.values()), "topics": dict(counts),
                      "tf_samples": tf_samples, "max_tf_error_m": worst}))


def read_rosbags(path, robots):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    wanted = {"sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "geometry_msgs/msg/Twist"}
    counts = collections.Counter()
    with Reader(path) as reader:
        connections = [c for c in reader.connections if c.msgtype in wanted]
        for connection, _, raw in reader.messages(connections=connections):
            msg = store.deserialize_cdr(raw, connection.msgtype)
            if connection.msgtype == "sensor_msgs/msg/LaserScan":
                need(len(msg.ranges) > 0, f"{connection.topic}: an empty scan")
            counts[connection.topic] += 1
        duration_s = reader.duration / 1e9
    for robot in range(robots):
        for name in ("scan", "odom", "cmd_vel"):
            need(counts[f"/robot_{robot}/{name}"] > 0, f"rosbags read no /robot_{robot}/{name}")
    print(json.dumps({"messages": sum(counts.values()), "duration_s": duration_s}))


def rerun_cli():
    beside = os.path.join(os.path.dirname(sys.executable), "rerun")
    return beside if os.path.exists(beside) else shutil.which("rerun")


def read_rerun(path, rrd, robots):
    from rerun.chunk import RrdReader

    cli = rerun_cli()
    need(cli is not None, "no `rerun` executable beside this Python (the rerun-sdk wheel has one)")
    done = subprocess.run([cli, "mcap", "convert", path, "-o", rrd], capture_output=True, text=True)
    need(done.returncode == 0, f"rerun mcap convert failed:\n{done.stderr}")
    for line in done.stderr.splitlines():
        need(" ERROR " not in line and "failed" not in line.lower(), f"rerun said: {line}")
    entities = collections.Counter()
    child_frames = set()
    for chunk in RrdReader(rrd).stream():
        entities[chunk.entity_path] += chunk.num_rows
        if chunk.entity_path == "/tf":
            batch = chunk.to_record_batch()
            if "Transform3D:child_frame" in batch.schema.names:
                for frames in batch.column("Transform3D:child_frame").to_pylist():
                    child_frames.update(frames or [])
    for robot in range(robots):
        for name in ROS2_TOPICS:
            need(entities[f"/robot_{robot}/{name}"] > 0, f"the .rrd has no /robot_{robot}/{name}")
        need(f"robot_{robot}/base_link" in child_frames, f"the .rrd's /tf never places robot {robot}")
    print(json.dumps({"entities": len(entities), "rows": sum(entities.values()),
                      "tf_frames": len(child_frames)}))


def stream(path):
    """The streaming reader over a pipe (nothing can be sought) that the file is copied into,
    up to the first record it cannot read, as after a crash."""
    import threading

    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    read_end, write_end = os.pipe()

    def feed():
        with open(path, "rb") as src, os.fdopen(write_end, "wb") as pipe:
            try:
                shutil.copyfileobj(src, pipe)
            except BrokenPipeError:
                pass

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    messages, latest, error = 0, None, None
    with os.fdopen(read_end, "rb") as pipe:
        need(not pipe.seekable(), "the stream must not be seekable")
        try:
            for record in StreamReader(pipe, skip_magic=False).records:
                if isinstance(record, Message):
                    messages += 1
                    latest = record.log_time if latest is None else max(latest, record.log_time)
        except Exception as e:  # a file cut short ends in a record that cannot be read
            error = f"{type(e).__name__}: {e}"
    print(json.dumps({"messages": messages, "latest_s": None if latest is None else latest / 1e9,
                      "stopped_by": error}))


def compare(path_a, path_b):
    def load(path):
        return [(topic, t, repr(msg), bytes(raw)) for topic, t, msg, raw in decoded_messages(path)]

    a, b = load(path_a), load(path_b)
    need(len(a) == len(b), f"{len(a)} ROS 2 messages against {len(b)}")
    differing = [(x[0], x[1]) for x, y in zip(a, b) if x != y]
    need(not differing, f"{len(differing)} messages differ, the first: {differing[:3]}")
    print(json.dumps({"messages": len(a), "differing": 0}))


def metadata(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    need("formation.run" in records, f"no formation.run metadata record, only {list(records)}")
    print(json.dumps(records["formation.run"]))


def attachments(path):
    import hashlib

    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        found = [{"name": a.name, "media_type": a.media_type, "size": len(a.data),
                  "sha256": hashlib.sha256(a.data).hexdigest()} for a in reader.iter_attachments()]
        f.seek(0)
        swaps = [m.metadata for m in make_reader(f).iter_metadata()
                 if m.name == "formation.swapped_model"]
    print(json.dumps({"attachments": found, "swapped_models": swaps}))


def main():
    imports()
    command, args = sys.argv[1], sys.argv[2:]
    if command == "check":
        print(json.dumps({"ok": True}))
    elif command == "decode":
        decode(args[0], args[1], int(args[2]))
    elif command == "rosbags":
        read_rosbags(args[0], int(args[1]))
    elif command == "rerun":
        read_rerun(args[0], args[1], int(args[2]))
    elif command == "stream":
        stream(args[0])
    elif command == "compare":
        compare(args[0], args[1])
    elif command == "metadata":
        metadata(args[0])
    elif command == "attachments":
        attachments(args[0])
    else:
        fail(f"unknown command {command}")


if __name__ == "__main__":
    main()
