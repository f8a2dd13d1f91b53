"""Shared helpers of the `formation` package's tests: the repository, the CLI, scenarios, and a
two-node Ray cluster with a worker killer for the sweep tests."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MODEL = REPO / "onnx" / "models" / "policy.onnx"
#: An image network that answers wheel speeds (the default until issue 34): what DAgger on an
#: image-only expert dataset warm-starts from.
IMAGE_MODEL = REPO / "onnx" / "models" / "wide-head" / "policy.onnx"
RAY = Path(sys.executable).parent / "ray"


def cli() -> Path:
    """The `formation` binary: FORMATION_BIN, else `$CARGO_TARGET_DIR` (or the workspace's
    target/) /debug/formation."""
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    path = Path(os.environ.get("FORMATION_BIN", target / "debug" / "formation"))
    if not path.is_file():
        pytest.fail(
            f"no formation binary at {path}: build it with `cargo build` "
            "(scripts/test-all does) or point FORMATION_BIN at one"
        )
    return path


def team_scenario(tmp_path: Path, robots: int, duration_s: float, base: str = "teams.toml") -> Path:
    """scenarios/`base` (teams.toml by default) for `robots` robots and `duration_s` seconds, as a
    file both the CLI and the package read."""
    text = (REPO / "scenarios" / base).read_text()
    text = text.replace("robots = 8", f"robots = {robots}").replace("duration_s = 60.0", f"duration_s = {duration_s}")
    path = tmp_path / f"{Path(base).stem}-{robots}.toml"
    path.write_text(text)
    return path


def cli_run_poses(scenario: Path, out: Path, seed: int, run: int, controller: str, model: Path = MODEL) -> list:
    """Every robot's pose at every tick of run `run` of `formation eval --seed seed`, from the
    run log it writes (`--out ... --save-trajectories`)."""
    args = [
        str(cli()), "eval", "--scenario", str(scenario), "--controller", controller,
        "--seed", str(seed), "--runs", str(run + 1), "--out", str(out),
        "--save-trajectories", str(run + 1), "--threads", "1",
    ]
    if controller == "policy":
        args += ["--model", str(model)]
    done = subprocess.run(args, capture_output=True, text=True, env={**os.environ, "ORT_DISABLE_TELEMETRY": "1"})
    assert done.returncode == 0, done.stderr
    log = json.loads((out / "runs" / f"run-{run:04d}.json").read_text())
    return log["trajectory"]["poses"]


def pose_rows(rows: list) -> list:
    """Run-log pose rows as (x, y, theta) tuples."""
    return [[(p["x"], p["y"], p["theta"]) for p in row] for row in rows]


def local_eval_json(tmp_path: Path, *args: str) -> bytes:
    """What `formation eval ARGS --json` writes, run here."""
    out = tmp_path / "local.json"
    done = subprocess.run([str(cli()), "eval", *args, "--json", str(out)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out.read_bytes()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster():
    """A real two-node Ray cluster on this machine (`ray start --head`, and a second node with
    `--address`), one CPU each, in a temp dir of its own; stopped after the module."""
    if not RAY.is_file():
        pytest.fail(f"no `ray` at {RAY}: bash .ci/setup-python --test installs it")
    port = free_port()
    # Ray's socket paths must stay short: a short temp dir under /tmp.
    temp = tempfile.mkdtemp(prefix="fr", dir="/tmp")
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    head = [str(RAY), "start", "--head", f"--port={port}", "--num-cpus=1",
            "--include-dashboard=false", f"--temp-dir={temp}", "--disable-usage-stats"]
    subprocess.run(head, check=True, capture_output=True, env=env)
    address = f"127.0.0.1:{port}"
    try:
        worker = [str(RAY), "start", f"--address={address}", "--num-cpus=1"]
        subprocess.run(worker, check=True, capture_output=True, env=env)
        yield address
    finally:
        subprocess.run([str(RAY), "stop", "--force"], capture_output=True, env=env)
        subprocess.run(["rm", "-rf", temp])


def share_processes(marker: bytes) -> list[tuple[int, int]]:
    """(pid, parent pid) of every running `formation` process with `marker` in its arguments
    (`--shard`: an eval share; `--part`: a DAgger share)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            args = (entry / "cmdline").read_bytes().split(b"\0")
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        if args and args[0].endswith(b"formation") and marker in args:
            found.append((int(entry.name), int(stat.rsplit(")", 1)[1].split()[1])))
    return found


class WorkerKiller:
    """A thread that SIGKILLs the first running share it sees (`formation ... MARKER`) and the
    Ray worker running it, mid-share; Ray must retry that task."""

    def __init__(self, marker: bytes, timeout_s: float = 300):
        self.killed: list[int] = []
        self._marker = marker
        self._deadline = time.monotonic() + timeout_s
        self._thread = threading.Thread(target=self._hunt, daemon=True)
        self._thread.start()

    def _hunt(self) -> None:
        while time.monotonic() < self._deadline and not self.killed:
            shares = share_processes(self._marker)
            if shares:
                pid, worker = shares[0]
                try:
                    os.kill(worker, signal.SIGKILL)  # the Ray worker running the share
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    continue  # it finished first: wait for the next one
                self.killed.append(worker)
            time.sleep(0.01)

    def assert_killed_one(self) -> None:
        """Stops hunting and checks that a share was killed mid-run."""
        self._deadline = 0
        self._thread.join()
        assert self.killed, "no share was seen running, so none was killed"
