"""Sweeps on a real two-node Ray cluster on this machine (`ray start --head`, and a second node
with `--address`): the merged JSON equals `formation eval --json`, byte for byte, also when a
worker is SIGKILLed mid-sweep (Ray retries its share; nothing is lost or counted twice)."""

from __future__ import annotations

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

from conftest import MODEL, REPO, cli
from formation.sweep import Cell, SweepError, eval_sweep, grid

RAY = Path(sys.executable).parent / "ray"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster():
    """A head node and a worker node, one CPU each, in a temp dir of their own; stopped after."""
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


def local_eval_json(tmp_path: Path, *args: str) -> bytes:
    out = tmp_path / "local.json"
    done = subprocess.run([str(cli()), "eval", *args, "--json", str(out)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out.read_bytes()


def share_processes() -> list[tuple[int, int]]:
    """(pid, parent pid) of every running `formation eval ... --shard` process."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            args = (entry / "cmdline").read_bytes().split(b"\0")
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        if args and args[0].endswith(b"formation") and b"--shard" in args:
            found.append((int(entry.name), int(stat.rsplit(")", 1)[1].split()[1])))
    return found


def test_a_table1_policy_sweep_on_two_nodes_survives_a_killed_worker_byte_for_byte(cluster, tmp_path):
    scenario = str(REPO / "scenarios" / "table1.toml")
    killed = []

    def kill_one_worker():
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and not killed:
            shares = share_processes()
            if shares:
                pid, worker = shares[0]
                os.kill(worker, signal.SIGKILL)  # the Ray worker running the share
                os.kill(pid, signal.SIGKILL)
                killed.append(worker)
            time.sleep(0.05)

    killer = threading.Thread(target=kill_one_worker)
    killer.start()
    cell = Cell(scenario, controller="policy", model=str(MODEL))
    results = eval_sweep([cell], out_dir=str(tmp_path / "sweep"), runs_per_share=10,
                         address=cluster, formation_bin=str(cli()))
    killer.join()
    assert killed, "no share was seen running, so none was killed"
    merged = (tmp_path / "sweep" / f"{cell.name()}.json").read_bytes()
    local = local_eval_json(tmp_path, "--scenario", scenario, "--controller", "policy",
                            "--model", str(MODEL))
    assert merged == local
    assert len(results[cell.name()]["per_run"]) == 100
    shards = sorted((tmp_path / "sweep" / cell.name()).iterdir())
    assert len(shards) == 10, "one shard per share: the killed one's retry replaced it"


def test_a_grid_of_seeds_and_team_sizes_matches_each_cells_own_eval(cluster, tmp_path):
    scenario = str(REPO / "scenarios" / "teams.toml")
    cells = grid([scenario], team_sizes=[None], seeds=[3, 4], controller="expert", runs=12)
    results = eval_sweep(cells, out_dir=str(tmp_path / "grid"), runs_per_share=5,
                         address=cluster, formation_bin=str(cli()))
    assert set(results) == {c.name() for c in cells}
    for cell in cells:
        local = local_eval_json(tmp_path, "--scenario", scenario, "--controller", "expert",
                                "--seed", str(cell.seed), "--runs", "12")
        assert (tmp_path / "grid" / f"{cell.name()}.json").read_bytes() == local
    resized = Cell(scenario, controller="expert", robots=5, runs=4)
    merged = eval_sweep([resized], out_dir=str(tmp_path / "resized"), runs_per_share=2,
                        address=cluster, formation_bin=str(cli()))[resized.name()]
    assert len(merged["per_run"]) == 4
    assert all(run["team"] is not None for run in merged["per_run"])


def test_a_share_that_fails_names_the_runs_and_the_cause(cluster, tmp_path):
    missing = Cell(str(tmp_path / "nope.toml"), controller="expert", runs=2)
    with pytest.raises(SweepError, match="nope.toml"):
        eval_sweep([missing], out_dir=str(tmp_path / "bad"), address=cluster,
                   formation_bin=str(cli()), max_retries=0)
    with pytest.raises(SweepError, match="no `formation` binary"):
        eval_sweep([missing], out_dir=str(tmp_path / "bad"), formation_bin=str(tmp_path / "x"))
