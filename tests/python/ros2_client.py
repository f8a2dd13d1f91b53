#!/usr/bin/env python3
"""An independent ROS 2 client of `formation-agent --transport ros2`, for tests/tests/ros2_clients.rs.

Nothing here is formation code, and nothing here reads formation's sources: the client speaks
rmw_zenoh's wire format with third-party libraries only, so that the Rust test checks the agent
against the outside world rather than against itself.

- `eclipse-zenoh`: it is the Zenoh router the agent connects to (the role of the robot's
  `rmw_zenohd`), listening on `--listen`; it publishes samples on rmw_zenoh's data keys
  (`<domain>/<topic>/<pkg>::msg::dds_::<Name>_/RIHS01_<hash>`) with rmw_zenoh's attachment
  (sequence number, source timestamp, GID, written by `zenoh.ext.z_serialize`, the serializer
  behind rmw_zenoh's `AttachmentData`), receives the agent's Twists with their attachments, and
  reads the liveliness tokens under `@ros2_lv`.
- `rosbags` (`Stores.ROS2_JAZZY`): CDR serialisation of `sensor_msgs/LaserScan`,
  `sensor_msgs/Imu` and `std_msgs/Float64`, decoding of `geometry_msgs/Twist`, and the RIHS01
  type hashes that the keys must carry.
- `zenoh-ros2-sdk`: discovery (`ros2 topic list -t` / `ros2 topic info -v` through liveliness),
  and a publisher of its own for the goal topics. Its message definitions are given explicitly;
  fetching them from the network is made to fail loudly.

Usage:
    ros2_client.py check                                  # exit 0, or 3 naming a missing package
    ros2_client.py run PLAN.json --listen tcp/127.0.0.1:PORT

The plan (written by the Rust test, so both sides use the same numbers) says which topics to use,
which scans, orientations and goals to publish, and what to wait for; see `run`. Floats that must
compare exactly travel as IEEE-754 bit patterns: u32 for float32, u64 for float64.

Output: one JSON object per line on stdout, `{"event": ...}`. After the plan the client prints
`{"event": "done"}`, keeps routing until its standard input closes (the test stops the agent
first), then prints `{"event": "summary", ...}` with every Twist it received.
Exit status: 0 when the plan ran; 1 when a check failed (an `{"event": "error"}` line says which);
3 when a package is missing.
"""

import json
import struct
import sys
import threading
import time

MISSING_PACKAGE = 3

try:
    import numpy as np
    import zenoh
    from rosbags.typesys import Stores, get_typestore
    from zenoh.ext import Int64, UInt8, z_deserialize, z_serialize
    import zenoh_ros2_sdk
    import zenoh_ros2_sdk._cache
    import zenoh_ros2_sdk.message_registry
except ImportError as e:  # pragma: no cover - exercised by the Rust test's skip path
    print(f"MISSING: {e.name}: {e}", file=sys.stderr)
    sys.exit(MISSING_PACKAGE)

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types

LASER_SCAN = "sensor_msgs/msg/LaserScan"
IMU = "sensor_msgs/msg/Imu"
FLOAT64 = "std_msgs/msg/Float64"
TWIST = "geometry_msgs/msg/Twist"
# A type of another definition: its hash, put on a LaserScan key, is "a LaserScan whose
# definition differs" to a subscriber.
OTHER_TYPE = "sensor_msgs/msg/MultiEchoLaserScan"

# How long any single wait of the client may take before it reports an error.
WAIT_S = 60.0


class CheckFailed(Exception):
    """A check of the client failed."""


class TimedOut(CheckFailed):
    """What the client waited for did not come in time."""


def wait_on(condition, limit_s, found, timed_out):
    """What `found()` returns once it is not None, waiting on `condition` (held by the caller)
    up to `limit_s`; raises `timed_out()` after."""
    deadline = time.monotonic() + limit_s
    while True:
        result = found()
        if result is not None:
            return result
        left = deadline - time.monotonic()
        if left <= 0:
            raise timed_out()
        condition.wait(min(left, 0.5))


def emit(event, **fields):
    print(json.dumps({"event": event, **fields}), flush=True)


def no_network(*args, **kwargs):
    raise RuntimeError(
        "zenoh-ros2-sdk tried to fetch message definitions from the network; the test gives them "
        f"explicitly (args {args!r})"
    )


# The SDK clones message repositories when a definition is missing: forbid it.
zenoh_ros2_sdk._cache.clone_to_cache = no_network
zenoh_ros2_sdk.message_registry.clone_to_cache = no_network


def dds_type_name(ros_type):
    """`pkg/msg/Name` -> `pkg::msg::dds_::Name_` (rmw_zenoh's DDS type name)."""
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def data_key(domain_id, topic, ros_type, type_hash=None):
    return "/".join(
        [
            str(domain_id),
            topic.strip("/"),
            dds_type_name(ros_type),
            type_hash or TS.hash_rihs01(ros_type),
        ]
    )


def f32(bits):
    return float(np.array([bits], dtype=np.uint32).view(np.float32)[0])


def f64(bits):
    return struct.unpack("<d", struct.pack("<Q", bits))[0]


def f64_bits(value):
    return struct.unpack("<Q", struct.pack("<d", float(value)))[0]


def stamp(ns):
    return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(ns, frame_id):
    return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame_id)


def laser_scan(spec):
    ranges = np.array(spec["ranges_bits"], dtype=np.uint32).view(np.float32)
    return T[LASER_SCAN](
        header=header(spec["stamp_ns"], "laser"),
        angle_min=f32(spec["angle_min_bits"]),
        angle_max=f32(spec["angle_max_bits"]),
        angle_increment=f32(spec["angle_increment_bits"]),
        time_increment=0.0,
        scan_time=0.0,
        range_min=f32(spec["range_min_bits"]),
        range_max=f32(spec["range_max_bits"]),
        ranges=ranges,
        intensities=np.array([], dtype=np.float32),
    )


def imu(spec):
    vector3 = T["geometry_msgs/msg/Vector3"]
    x, y, z, w = (f64(b) for b in spec["quaternion_bits"])
    return T[IMU](
        header=header(spec["stamp_ns"], "imu_link"),
        orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
        orientation_covariance=np.zeros(9, dtype=np.float64),
        angular_velocity=vector3(x=0.0, y=0.0, z=0.0),
        angular_velocity_covariance=np.zeros(9, dtype=np.float64),
        linear_acceleration=vector3(x=0.0, y=0.0, z=9.81),
        linear_acceleration_covariance=np.zeros(9, dtype=np.float64),
    )


def cdr(message, ros_type):
    return bytes(TS.serialize_cdr(message, ros_type, little_endian=True))


class Publisher:
    """An rmw_zenoh-style publisher on one data key: CDR payload and the attachment."""

    def __init__(self, session, key, gid):
        self.key = key
        self.publisher = session.declare_publisher(key)
        self.gid = gid
        self.sequence = 0

    def put(self, payload, source_timestamp_ns):
        self.sequence += 1
        attachment = z_serialize(
            (Int64(self.sequence), Int64(source_timestamp_ns), [UInt8(b) for b in self.gid])
        )
        self.publisher.put(payload, attachment=attachment)


class Twists:
    """Every sample on the agent's cmd_vel, decoded with rosbags and checked on the wire."""

    def __init__(self, session, domain_id, topic):
        self.expected_key = data_key(domain_id, topic, TWIST)
        self.lock = threading.Condition()
        self.received = []
        self.problems = []
        self.subscriber = session.declare_subscriber(
            f"{domain_id}/{topic.strip('/')}/**", self.on_sample
        )

    def on_sample(self, sample):
        try:
            entry = self.decode(sample)
        except Exception as e:  # noqa: BLE001 - any decoding failure is a finding
            with self.lock:
                self.problems.append(f"a sample on {sample.key_expr}: {e!r}")
                self.lock.notify_all()
            return
        with self.lock:
            self.received.append(entry)
            self.lock.notify_all()

    def decode(self, sample):
        key = str(sample.key_expr)
        if key != self.expected_key:
            raise CheckFailed(f"key {key}, expected {self.expected_key} (rosbags' RIHS01 hash)")
        if sample.attachment is None:
            raise CheckFailed("no attachment")
        raw = sample.attachment.to_bytes()
        sequence, timestamp, gid = z_deserialize(tuple[Int64, Int64, list[UInt8]], sample.attachment)
        if len(gid) != 16 or len(raw) != 33:
            raise CheckFailed(f"attachment of {len(raw)} bytes with a GID of {len(gid)}: {raw.hex()}")
        payload = sample.payload.to_bytes()
        if payload[:4] != b"\x00\x01\x00\x00":
            raise CheckFailed(f"CDR encapsulation header {payload[:4].hex()}, expected 00010000")
        twist = TS.deserialize_cdr(payload, TWIST)
        # The six components: linear x, y, z, then angular x, y, z.
        values = [getattr(vector, axis) for vector in (twist.linear, twist.angular) for axis in "xyz"]
        return {
            "stamp_ns": timestamp,
            "sequence": sequence,
            "gid": bytes(gid).hex(),
            "twist": values,
            "twist_bits": [f64_bits(v) for v in values],
            "zero": all(v == 0.0 for v in values),
            "received_at": time.time(),
        }

    def check(self):
        with self.lock:
            if self.problems:
                raise CheckFailed("; ".join(self.problems))

    def count(self):
        with self.lock:
            return len(self.received)

    def wait_for(self, matches, since=0, limit_s=WAIT_S, what="a Twist"):
        """The first Twist from index `since` on that `matches`, waiting up to `limit_s`."""
        index = since

        def found():
            nonlocal index
            if self.problems:
                raise CheckFailed("; ".join(self.problems))
            while index < len(self.received):
                entry = self.received[index]
                index += 1
                if matches(entry):
                    return entry
            return None

        with self.lock:
            return wait_on(self.lock, limit_s, found, lambda: TimedOut(f"no {what} within {limit_s} s"))

    def summary(self):
        with self.lock:
            sequences = [t["sequence"] for t in self.received]
            gids = sorted({t["gid"] for t in self.received})
            return {
                "twists": self.received,
                "sequences_increase": all(b > a for a, b in zip(sequences, sequences[1:])),
                "gids": gids,
                "problems": self.problems,
            }


class Graph:
    """The liveliness tokens of the graph, as a raw eclipse-zenoh liveliness subscriber sees them."""

    def __init__(self, session, domain_id):
        self.lock = threading.Condition()
        self.tokens = set()
        self.subscriber = session.liveliness().declare_subscriber(
            f"@ros2_lv/{domain_id}/**", self.on_token, history=True
        )

    def on_token(self, sample):
        with self.lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.tokens.add(str(sample.key_expr))
            else:
                self.tokens.discard(str(sample.key_expr))
            self.lock.notify_all()

    def wait_for_publisher(self, topic, limit_s=WAIT_S):
        """Waits for an `MP` token on `topic` (the agent declares its publisher last)."""
        mangled = topic.replace("/", "%")

        def found():
            for token in self.tokens:
                parts = token.split("/")
                if len(parts) >= 13 and parts[5] == "MP" and parts[9] == mangled:
                    return token
            return None

        with self.lock:
            return wait_on(
                self.lock, limit_s, found, lambda: CheckFailed(f"no publisher token on {topic} within {limit_s} s")
            )


def open_router(listen):
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([listen]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def node_tokens(session, domain_id):
    """`ros2 node list` through a raw liveliness query: the `NN` tokens of the domain."""
    nodes = []
    for reply in session.liveliness().get(f"@ros2_lv/{domain_id}/*/*/*/NN/**", timeout=5.0):
        if reply.ok is None:
            continue
        parts = str(reply.ok.key_expr).split("/")
        nodes.append(
            {
                "zid": parts[2],
                "node_id": parts[3],
                "enclave": parts[6].replace("%", "/"),
                "namespace": parts[7].replace("%", "/"),
                "name": parts[8],
                "token": str(reply.ok.key_expr),
            }
        )
    return nodes


def endpoint_info(info):
    return {
        "node_name": info.node_name,
        "node_namespace": info.node_namespace,
        "topic_type": info.topic_type,
        "type_hash": info.type_hash,
        "qos": info.qos,
    }


def discover(session, plan, port):
    """What zenoh-ros2-sdk finds of the graph, and the node list from the raw tokens."""
    domain_id = plan["domain_id"]
    topics = zenoh_ros2_sdk.get_topic_names_and_types(
        domain_id=domain_id, router_ip="127.0.0.1", router_port=port, timeout=3.0
    )
    infos = {}
    topics_of_interest = [plan["scan_topic"], plan["orientation_topic"], plan["cmd_vel_topic"]]
    for topic in topics_of_interest + list(plan.get("goal_topics") or []):
        info = zenoh_ros2_sdk.get_topic_info(
            topic, domain_id=domain_id, router_ip="127.0.0.1", router_port=port, timeout=3.0,
            verbose=True,
        )
        infos[topic] = None if info is None else {
            "types": info.topic_types,
            "publishers": [endpoint_info(p) for p in info.publishers],
            "subscribers": [endpoint_info(s) for s in info.subscribers],
        }
    emit(
        "discovery",
        topics=[[name, types] for name, types in topics],
        info=infos,
        nodes=node_tokens(session, domain_id),
        rosbags_hashes={t: TS.hash_rihs01(t) for t in [LASER_SCAN, IMU, FLOAT64, TWIST]},
    )


class SdkGoals:
    """The goal topics published by zenoh-ros2-sdk's own publisher (explicit definitions)."""

    def __init__(self, plan, port):
        self.publishers = [
            zenoh_ros2_sdk.ROS2Publisher(
                topic=topic,
                msg_type=FLOAT64,
                msg_definition="float64 data\n",
                node_name="goal_publisher",
                domain_id=plan["domain_id"],
                router_ip="127.0.0.1",
                router_port=port,
            )
            for topic in plan["goal_topics"]
        ]
        self.values = [f64(b) for b in plan["goal_bits"]]
        self.hashes = [p.type_hash for p in self.publishers]

    def publish(self):
        for publisher, value in zip(self.publishers, self.values):
            publisher.publish(data=value)


def run(plan, listen):
    session = open_router(listen)
    try:
        run_plan(session, plan, listen)
    finally:
        session.close()


def run_plan(session, plan, listen):
    port = int(listen.rsplit(":", 1)[1])
    domain_id = plan["domain_id"]
    graph = Graph(session, domain_id)
    twists = Twists(session, domain_id, plan["cmd_vel_topic"])
    gid = bytes(range(0x10, 0x20))
    scans = Publisher(session, data_key(domain_id, plan["scan_topic"], LASER_SCAN), gid)
    emit("listening", endpoint=listen, zid=str(session.zid()))

    token = graph.wait_for_publisher(plan["cmd_vel_topic"])
    emit("agent", token=token)

    orientation = Publisher(session, data_key(domain_id, plan["orientation_topic"], IMU), gid)
    sdk_goals = None
    if plan.get("goal_topics") and plan.get("goal_via_sdk"):
        sdk_goals = SdkGoals(plan, port)
        emit("sdk_goal_publishers", type_hashes=sdk_goals.hashes)
    elif plan.get("goal_topics"):
        for topic, bits in zip(plan["goal_topics"], plan["goal_bits"]):
            goal = Publisher(session, data_key(domain_id, topic, FLOAT64), gid)
            goal.put(cdr(T[FLOAT64](data=f64(bits)), FLOAT64), time.time_ns())

    def publish_step(step):
        if step.get("imu"):
            orientation.put(cdr(imu(step["imu"]), IMU), step["imu"]["stamp_ns"])
        scan = step["scan"]
        scans.put(cdr(laser_scan(scan), LASER_SCAN), scan["stamp_ns"])

    def answer(step, limit_s=WAIT_S):
        since = twists.count()
        publish_step(step)
        wanted = step["scan"]["stamp_ns"]
        return twists.wait_for(
            lambda t: t["stamp_ns"] == wanted, since, limit_s, f"Twist answering the scan stamped {wanted}"
        )

    if sdk_goals is not None:
        # A fresh peer session of the SDK may put before the router has told it of the agent's
        # subscriptions: publish the goals, and a first scan, until the agent drives.
        first = plan["steps"][0]
        deadline = time.monotonic() + WAIT_S
        while True:
            sdk_goals.publish()
            time.sleep(0.1)
            reply = answer(first)
            if not reply["zero"]:
                break
            if time.monotonic() > deadline:
                raise CheckFailed("the agent never drove on the goals of zenoh-ros2-sdk's publisher")
            first = dict(first, scan=dict(first["scan"], stamp_ns=first["scan"]["stamp_ns"] + 1))
        emit("answer", index=0, **reply)
        steps = plan["steps"][1:]
        offset = 1
    else:
        steps = plan["steps"]
        offset = 0

    for index, step in enumerate(steps, start=offset):
        emit("answer", index=index, **answer(step))

    stream = plan.get("stream")
    if stream:
        run_stream(session, plan, stream, scans, twists, gid)

    if plan.get("discover"):
        discover(session, plan, port)

    if plan.get("hold"):
        since = twists.count()
        emit("driving", twists_so_far=since)
        brake = twists.wait_for(lambda t: t["zero"], since, WAIT_S, "zero Twist")
        emit("brake", **brake)

    twists.check()
    emit("done")
    sys.stdin.read()
    # The agent has stopped: everything it sent has arrived.
    emit("summary", **twists.summary())


def run_stream(session, plan, stream, scans, twists, gid):
    """Publishes bad input every `period_ms` until the agent publishes a zero Twist.

    `wrong_hash`: a valid LaserScan on a key with another type's RIHS01 hash; `truncated`: the
    CDR of a LaserScan cut in half on the right key; `no_orientation`: valid LaserScans while the
    orientation topic stays silent.
    """
    domain_id = plan["domain_id"]
    bad = stream["bad"]
    period = stream["period_ms"] / 1000.0
    other_hash = TS.hash_rihs01(OTHER_TYPE)
    if bad == "wrong_hash":
        publisher = Publisher(
            session, data_key(domain_id, plan["scan_topic"], LASER_SCAN, other_hash), gid
        )
    else:
        publisher = scans
    since = twists.count()
    stamps = []
    deadline = time.monotonic() + stream["limit_s"]
    emit("stream", bad=bad, other_hash=other_hash)
    while True:
        spec = dict(stream["scan"], stamp_ns=stream["scan"]["stamp_ns"] + len(stamps))
        payload = cdr(laser_scan(spec), LASER_SCAN)
        if bad == "truncated":
            payload = payload[: len(payload) // 2]
        publisher.put(payload, spec["stamp_ns"])
        stamps.append(spec["stamp_ns"])
        try:
            brake = twists.wait_for(lambda t: t["zero"], since, period, "zero Twist")
            break
        except TimedOut:
            if time.monotonic() > deadline:
                raise CheckFailed(f"no zero Twist within {stream['limit_s']} s of {bad} input")
    answered = [t for t in twists.summary()["twists"][since:] if t["stamp_ns"] in stamps]
    emit(
        "brake",
        **brake,
        answers_a_streamed_scan=brake["stamp_ns"] in stamps,
        streamed=len(stamps),
        streamed_answered=len(answered),
        streamed_answered_nonzero=sum(1 for t in answered if not t["zero"]),
    )


def main():
    if len(sys.argv) >= 2 and sys.argv[1] == "check":
        import importlib.metadata as md

        emit(
            "versions",
            **{p: md.version(p) for p in ["eclipse-zenoh", "rosbags", "zenoh-ros2-sdk"]},
        )
        return 0
    if len(sys.argv) != 5 or sys.argv[1] != "run" or sys.argv[3] != "--listen":
        print(__doc__, file=sys.stderr)
        return 2
    with open(sys.argv[2]) as f:
        plan = json.load(f)
    try:
        run(plan, sys.argv[4])
    except CheckFailed as e:
        emit("error", message=str(e))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
