"""Shared helpers of the `formation` package's tests: the repository, the CLI and scenarios."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MODEL = REPO / "onnx" / "models" / "policy.onnx"


def cli() -> Path:
    """The `formation` binary: FORMATION_BIN, else `$CARGO_TARGET_DIR` (or the workspace's
    target/) /debug/formation."""
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    path = Path(os.environ.get("FORMATION_BIN", target / "debug" / "formation"))
    if not path.is_file():
        pytest.fail(
            f"no formation binary at {path}: build it with `cargo build -p formation-cli` "
            "(scripts/test-all does) or point FORMATION_BIN at one"
        )
    return path


def team_scenario(tmp_path: Path, robots: int, duration_s: float) -> Path:
    """scenarios/teams.toml for `robots` robots and `duration_s` seconds, as a file both the CLI
    and the package read."""
    text = (REPO / "scenarios" / "teams.toml").read_text()
    text = text.replace("robots = 8", f"robots = {robots}").replace("duration_s = 60.0", f"duration_s = {duration_s}")
    path = tmp_path / f"teams-{robots}.toml"
    path.write_text(text)
    return path


def cli_run_poses(scenario: Path, out: Path, seed: int, run: int, controller: str) -> list:
    """Every robot's pose at every tick of run `run` of `formation eval --seed seed`, from the
    run log it writes (`--out ... --save-trajectories`)."""
    args = [
        str(cli()), "eval", "--scenario", str(scenario), "--controller", controller,
        "--seed", str(seed), "--runs", str(run + 1), "--out", str(out),
        "--save-trajectories", str(run + 1), "--threads", "1",
    ]
    if controller == "policy":
        args += ["--model", str(MODEL)]
    done = subprocess.run(args, capture_output=True, text=True, env={**os.environ, "ORT_DISABLE_TELEMETRY": "1"})
    assert done.returncode == 0, done.stderr
    log = json.loads((out / "runs" / f"run-{run:04d}.json").read_text())
    return log["trajectory"]["poses"]


def pose_rows(rows: list) -> list:
    """Run-log pose rows as (x, y, theta) tuples."""
    return [[(p["x"], p["y"], p["theta"]) for p in row] for row in rows]
