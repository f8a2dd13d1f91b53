"""Sweeps on a real two-node Ray cluster on this machine (`ray start --head`, and a second node
with `--address`): the merged JSON equals `formation eval --json`, byte for byte, also when a
worker is SIGKILLed mid-sweep (Ray retries its share; nothing is lost or counted twice)."""

from __future__ import annotations

import pytest

from conftest import MODEL, REPO, WorkerKiller, cli, local_eval_json
from formation.sweep import Cell, SweepError, eval_sweep, grid


def test_a_table1_policy_sweep_on_two_nodes_survives_a_killed_worker_byte_for_byte(cluster, tmp_path):
    scenario = str(REPO / "scenarios" / "table1.toml")
    killer = WorkerKiller(b"--shard")
    cell = Cell(scenario, controller="policy", model=str(MODEL))
    results = eval_sweep([cell], out_dir=str(tmp_path / "sweep"), runs_per_share=10,
                         address=cluster, formation_bin=str(cli()))
    killer.assert_killed_one()
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
