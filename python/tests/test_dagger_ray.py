"""One DAgger iteration's rollouts as Ray tasks on a real two-node Ray cluster on this machine
(`ray start --head`, and a second node with `--address`): the dataset is byte for byte the one the
local CLI writes for that iteration, also when a worker is SIGKILLed mid-iteration (Ray retries
its share; nothing is lost or counted twice); a whole iteration then trains on the driver and
evaluates on Ray."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from conftest import IMAGE_MODEL, WorkerKiller, cli, local_eval_json, team_scenario
from formation.dagger import dagger_iteration, label_iteration
from formation.sweep import SweepError, run_cli

SETTINGS = dict(team_sizes=(3, 4), beta=0.5, seed=11)
RUNS = 8
TICKS = 40  # 2 s at 20 Hz


def expert_dataset(tmp_path: Path, scenario: Path) -> Path:
    """A dataset of one expert demonstration run (iteration 0), as DAgger starts from."""
    out = tmp_path / "expert"
    done = subprocess.run([str(cli()), "collect", "--scenario", str(scenario), "--out", str(out),
                           "--runs", "1"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out


def files_of(dataset: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(dataset.iterdir())}


def label_locally(data: Path, scenario: Path, part: Path) -> None:
    """The iteration labelled in one share on this machine and appended, with the CLI."""
    binary = str(cli())
    run_cli(binary, "dagger-label", "--data", str(data), "--scenario", str(scenario),
            "--model", str(IMAGE_MODEL), "--iteration", "1", "--beta", "0.5", "--seed", "11",
            "--team-sizes", "3,4", "--runs", str(RUNS), "--part", str(part))
    run_cli(binary, "dagger-append", "--data", str(data), "--iteration", "1",
            "--runs", str(RUNS), str(part))


def test_a_dagger_iteration_on_two_nodes_survives_a_killed_worker_byte_for_byte(cluster, tmp_path):
    scenario = team_scenario(tmp_path, robots=3, duration_s=2.0)
    expert = expert_dataset(tmp_path, scenario)
    on_ray = shutil.copytree(expert, tmp_path / "on-ray")
    local = shutil.copytree(expert, tmp_path / "local")

    killer = WorkerKiller(b"--part")
    parts = label_iteration(str(on_ray), str(IMAGE_MODEL), 1, RUNS, scenario=str(scenario),
                            runs_per_share=2, parts_dir=str(tmp_path / "parts"), address=cluster,
                            formation_bin=str(cli()), **SETTINGS)
    killer.assert_killed_one()
    assert [p.name for p in parts] == [f"part-{first:06d}.safetensors" for first in (0, 2, 4, 6)]
    assert sorted(p.name for p in (tmp_path / "parts").iterdir()) == [p.name for p in parts], \
        "one whole part per share: the killed one's retry wrote it once, no temporary file left"

    label_locally(local, scenario, tmp_path / "whole.part")
    assert files_of(on_ray) == files_of(local)
    manifest = json.loads((on_ray / "manifest.json").read_text())
    dagger = [s for s in manifest["shards"] if s["iteration"] == 1]
    # Runs 0..8 alternate teams of 3 and 4 robots: every robot's view at every tick, once.
    assert sum(s["samples"] for s in dagger) == TICKS * (3 + 4) * RUNS // 2

    with pytest.raises(SweepError, match="already holds samples of DAgger iteration 1"):
        run_cli(str(cli()), "dagger-append", "--data", str(on_ray), "--iteration", "1",
                "--runs", str(RUNS), *map(str, parts))


def test_a_dagger_share_that_fails_names_its_runs_and_the_cause(cluster, tmp_path):
    scenario = team_scenario(tmp_path, robots=3, duration_s=1.0)
    expert = expert_dataset(tmp_path, scenario)
    with pytest.raises(SweepError, match=r"iteration 1, runs 0\.\.2: .*nope\.onnx"):
        label_iteration(str(expert), str(tmp_path / "nope.onnx"), 1, 2, scenario=str(scenario),
                        address=cluster, formation_bin=str(cli()), max_retries=0)
    manifest = json.loads((expert / "manifest.json").read_text())
    assert {s["iteration"] for s in manifest["shards"]} == {0}, "nothing was appended"


def test_a_whole_dagger_iteration_labels_on_ray_trains_on_the_driver_and_evaluates(cluster, tmp_path):
    scenario = team_scenario(tmp_path, robots=3, duration_s=1.0)
    expert = expert_dataset(tmp_path, scenario)
    out = tmp_path / "models" / "m1.onnx"
    point = dagger_iteration(str(expert), str(IMAGE_MODEL), 1, str(out), runs=4, scenario=str(scenario),
                             train_args=("--epochs", "1", "--device", "cpu"),
                             eval_scenario=str(scenario), eval_runs=2, runs_per_share=2,
                             address=cluster, formation_bin=str(cli()))
    manifest = json.loads((expert / "manifest.json").read_text())
    assert {s["iteration"] for s in manifest["shards"]} == {0, 1}
    assert out.is_file() and out.with_suffix(".pt").is_file()
    local = local_eval_json(tmp_path, "--scenario", str(scenario), "--controller", "policy",
                            "--model", str(out), "--runs", "2")
    merged = out.parent / "m1-eval" / f"{scenario.stem}-policy-m1.json"
    assert merged.read_bytes() == local, "the evaluation on Ray is the local one, byte for byte"
    assert point == json.loads(local)
    assert len(point["per_run"]) == 2
