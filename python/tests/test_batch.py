"""The batched environment: B worlds stepped together equal the same worlds stepped one by one,
bit for bit, and bad input raises."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REPO, team_scenario

import formation

SEEDS = [3, 3, 9, 9]
RUNS = [0, 1, 0, 5]


def play(batch: formation.Batch, ticks: int, wobble: np.ndarray) -> dict:
    """Steps `batch` with the expert's actions plus a fixed wobble, recording what it shows."""
    seen = {"scans": [], "occupancy": [], "aux": [], "collided": []}
    for k in range(ticks):
        seen["scans"].append(batch.scans())
        seen["occupancy"].append(batch.occupancy(50, 0.1, "border", None))
        seen["aux"].append(batch.aux())
        actions = batch.expert_actions() + wobble[k % len(wobble)]
        seen["collided"].append(batch.step(np.ascontiguousarray(actions)))
    seen["poses"] = [batch.trajectory(b) for b in range(batch.worlds)]
    seen["metrics"] = [batch.metrics_json(b) for b in range(batch.worlds)]
    return seen


def test_a_batch_equals_its_worlds_stepped_one_by_one(tmp_path):
    scenario = formation.Scenario(str(team_scenario(tmp_path, 8, 2.0)), overrides={"lidar.noise_std": 0.03})
    rng = np.random.default_rng(0)
    wobble = rng.normal(0.0, 0.05, (7, len(SEEDS), 8, 2))
    together = play(formation.Batch(scenario, SEEDS, RUNS), 40, wobble)
    for b, (seed, run) in enumerate(zip(SEEDS, RUNS)):
        alone = play(formation.Batch(scenario, [seed], [run]), 40, wobble[:, b : b + 1])
        for key in ("scans", "occupancy", "aux", "collided"):
            for k, (a, t) in enumerate(zip(alone[key], together[key])):
                assert a.dtype == t.dtype
                assert np.array_equal(a[0].view(np.uint8), t[b].view(np.uint8)), (key, k, b)
        assert np.array_equal(alone["poses"][0].view(np.uint64), together["poses"][b].view(np.uint64))
        assert alone["metrics"][0] == together["metrics"][b]
    # The worlds differ: the batch did not play one world B times.
    assert not np.array_equal(together["poses"][0], together["poses"][1])


def test_bad_batch_input_raises():
    scenario = formation.Scenario(str(REPO / "scenarios" / "table1.toml"), overrides={"duration_s": 0.1})
    batch = formation.Batch(scenario, [1, 2], [0, 0], expert=False)
    with pytest.raises(ValueError, match=r"actions have shape \[2, 3, 1\]; give \(worlds, robots, 2\) = \[2, 3, 2\]"):
        batch.step(np.zeros((2, 3, 1)))
    with pytest.raises(ValueError, match=r"actions have shape \[6\]"):
        batch.step(np.zeros(6))
    bad = np.zeros((2, 3, 2))
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="action of robot 2 in world 1 is NaN"):
        batch.step(bad)
    with pytest.raises(RuntimeError, match="expert=False"):
        batch.expert_actions()
    with pytest.raises(ValueError, match="one seed and one run index per world"):
        batch.reset([1, 2], [0])
    with pytest.raises(ValueError, match="beyond"):
        batch.occupancy(50, 0.1, "clip")
    while not batch.over:
        batch.step(np.zeros((2, 3, 2)))
    with pytest.raises(formation.EpisodeOver, match="world 0: the run is over: all 2 ticks"):
        batch.step(np.zeros((2, 3, 2)))
