#!/usr/bin/env python3
"""An independent client of formation's live view (`--foxglove`), for tests/tests/live_view.rs.

None of formation's code is used here: the `websockets` package speaks Foxglove's WebSocket
protocol (subprotocol `foxglove.sdk.v1`, as the Foxglove app does: JSON `serverInfo` and
`advertise`, a `subscribe` to every channel, binary `MessageData` frames), and
`mcap-ros2-support` decodes each message's CDR with the `ros2msg` schema its channel advertised.
Every subcommand prints one JSON object on stdout and exits 0; a check that fails exits 1 saying
what failed; a missing package exits 3 with the fix.

    foxglove_client.py watch URL SECONDS    subscribe to every channel; decode until a LaserScan
                                            and a /tf message came (at most SECONDS)
    foxglove_client.py stall URL SECONDS    subscribe to every channel, read a little, then stop
                                            reading for SECONDS (the socket fills) and leave
    foxglove_client.py follow URL SECONDS   subscribe to every channel and read every message
                                            until the server closes (at most SECONDS); counts
                                            (`scripts/measure live-view`)
"""

import json
import struct
import sys
import time

MISSING_PACKAGE = 3
SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


def imports():
    try:
        from mcap_ros2._dynamic import generate_dynamic
        from websockets.sync.client import connect
    except ImportError as e:
        print(
            f"{e}: run `bash .ci/setup-python --test` (tests/python/requirements-record.txt)",
            file=sys.stderr,
        )
        sys.exit(MISSING_PACKAGE)
    return connect, generate_dynamic


def connect_view(url):
    """The connection (a context manager), retried for a minute while nothing listens yet (the
    world starts its server once its specs are read)."""
    connect, _ = imports()
    deadline = time.monotonic() + 60
    while True:
        try:
            return connect(url, subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=30)
        except ConnectionRefusedError:
            if time.monotonic() > deadline:
                fail(f"nothing listened on {url} for a minute")
            time.sleep(0.1)


def open_view(ws):
    """Reads the server's info and channels, subscribes to every channel."""
    _, generate_dynamic = imports()
    if ws.subprotocol != SUBPROTOCOL:
        fail(f"the server chose the subprotocol {ws.subprotocol!r}, not {SUBPROTOCOL}")
    info = None
    channels = {}
    deadline = time.monotonic() + 30
    # The server sends its info, then advertises its channels (in batches).
    while time.monotonic() < deadline:
        try:
            frame = ws.recv(timeout=1 if channels else 30)
        except TimeoutError:
            if channels:
                break
            fail("no channels advertised within 30 s")
        if isinstance(frame, bytes):
            continue
        op = json.loads(frame)
        if op["op"] == "serverInfo":
            info = op
        elif op["op"] == "advertise":
            for ch in op["channels"]:
                channels[ch["id"]] = ch
    if info is None:
        fail("no serverInfo")
    subscriptions = []
    decoders = {}
    for sub_id, (channel_id, ch) in enumerate(sorted(channels.items())):
        subscriptions.append({"id": sub_id, "channelId": channel_id})
        if ch["encoding"] != "cdr" or ch.get("schemaEncoding") != "ros2msg":
            fail(f"{ch['topic']}: encoding {ch['encoding']}, schema {ch.get('schemaEncoding')}")
        decode = generate_dynamic(ch["schemaName"], ch["schema"])[ch["schemaName"]]
        decoders[sub_id] = (ch["topic"], ch["schemaName"], decode)
    ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
    return info, channels, decoders


def message(frame):
    """A binary MessageData frame: (subscription id, log time [ns], payload); None otherwise."""
    if not isinstance(frame, bytes) or len(frame) < 13 or frame[0] != MESSAGE_DATA:
        return None
    sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
    return sub_id, log_time, frame[13:]


def watch(url, seconds):
    with connect_view(url) as ws:
        info, channels, decoders, counts, scan, tf, first_time = receive(ws, seconds)
    if scan is None or tf is None:
        fail(f"within {seconds} s no LaserScan ({scan}) or no /tf ({tf}); received {counts}")
    print(
        json.dumps(
            {
                "subprotocol": SUBPROTOCOL,
                "server": info.get("name"),
                "topics": sorted(ch["topic"] for ch in channels.values()),
                "types": {ch["topic"]: ch["schemaName"] for ch in channels.values()},
                "received": counts,
                "first_log_time_ns": first_time,
                "scan": scan,
                "tf": tf,
            }
        )
    )


def receive(ws, seconds):
    """Subscribes to everything and decodes until a LaserScan and a /tf came."""
    info, channels, decoders = open_view(ws)
    counts = {}
    scan = tf = None
    first_time = None
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and (scan is None or tf is None):
        try:
            got = message(ws.recv(timeout=max(0.1, deadline - time.monotonic())))
        except TimeoutError:
            break
        if got is None:
            continue
        sub_id, log_time, payload = got
        topic, type_name, decode = decoders[sub_id]
        counts[topic] = counts.get(topic, 0) + 1
        first_time = log_time if first_time is None else first_time
        msg = decode(payload)
        if type_name == "sensor_msgs/msg/LaserScan" and scan is None:
            scan = {
                "topic": topic,
                "frame_id": msg.header.frame_id,
                "beams": len(msg.ranges),
                "range_max": msg.range_max,
                "stamp_ns": msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec,
                "log_time_ns": log_time,
            }
        if topic == "/tf" and tf is None:
            t = msg.transforms[0]
            tf = {
                "parent": t.header.frame_id,
                "child": t.child_frame_id,
                "x": t.transform.translation.x,
                "y": t.transform.translation.y,
            }
    return info, channels, decoders, counts, scan, tf, first_time


def stall(url, seconds):
    with connect_view(url) as ws:
        _, channels, _ = open_view(ws)
        received = 0
        deadline = time.monotonic() + 2
        while time.monotonic() < deadline and received < 50:
            try:
                if message(ws.recv(timeout=1)) is not None:
                    received += 1
            except TimeoutError:
                break
        # From here on nothing is read: websockets stops reading the socket once its small
        # queue of frames is full, the kernel's buffers fill, and the server can no longer send.
        time.sleep(seconds)
    print(json.dumps({"channels": len(channels), "received_before_stall": received}))


def follow(url, seconds):
    from websockets.exceptions import ConnectionClosed

    messages = size = 0
    with connect_view(url) as ws:
        open_view(ws)
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                got = message(ws.recv(timeout=max(0.1, deadline - time.monotonic())))
            except (TimeoutError, ConnectionClosed):
                break
            if got is not None:
                messages += 1
                size += len(got[2])
    print(json.dumps({"messages": messages, "bytes": size}))


def main(argv):
    if len(argv) == 3 and argv[0] == "watch":
        watch(argv[1], float(argv[2]))
    elif len(argv) == 3 and argv[0] == "stall":
        stall(argv[1], float(argv[2]))
    elif len(argv) == 3 and argv[0] == "follow":
        follow(argv[1], float(argv[2]))
    else:
        fail(__doc__)


if __name__ == "__main__":
    main(sys.argv[1:])
