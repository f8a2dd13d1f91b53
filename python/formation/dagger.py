"""One DAgger iteration with its rollouts as Ray tasks, on this machine or a cluster.

Iteration ``k``'s runs are cut into shares. Every share is a Ray task that runs ``formation
dagger-label --iteration K --first-run A --runs R --part FILE`` (the policy drives, or the expert
with probability ``beta^k``; the expert labels every robot's view at every tick) and hands the
part's bytes back; the driver keeps exactly one part per share, written atomically, and appends
them with ``formation dagger-append``, which checks that the parts are that iteration's, of one
labelling, and cover its runs once each, then appends them in run order. Run ``i`` of iteration
``k`` is a pure function of the settings and ``i``, so the dataset is byte for byte the one
``formation dagger`` writes for that iteration.

A worker that dies mid-share is retried by Ray (``max_retries``); its part arrives once, so no
run is lost or counted twice, and the append refuses a run held twice or by none anyway (and an
iteration the dataset already holds).

    from formation.dagger import dagger_iteration
    curve_point = dagger_iteration("data", "policy-dagger0.onnx", 1, "policy-dagger1.onnx",
                                   runs=153, beta=0.5, train_args=["--epochs", "8"])

By default it calls ``ray.init()`` here; ``address="HOST:PORT"`` (or ``"auto"``) joins a running
cluster. Every node needs the ``formation`` binary, the scenario, the model and the dataset's
``manifest.json`` at the same paths (a worker reads only the manifest).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence

from formation.sweep import Cell, Share, SweepError, eval_sweep, formation_binary, run_cli, run_shares

__all__ = ["DAGGER_TRAINING", "SweepError", "dagger_iteration", "label_iteration", "warm_start_of"]

#: ``formation dagger``'s training defaults, as ``formation train`` flags (its own differ).
DAGGER_TRAINING = ("--epochs", "8", "--batch-size", "64", "--lr", "0.001")


def _label_args(
    data: str,
    model: str,
    iteration: int,
    scenario: str,
    team_sizes: Sequence[int],
    beta: float,
    seed: int,
) -> tuple[str, ...]:
    """The flags every share of the iteration passes to ``formation dagger-label``."""
    args = ["dagger-label", "--data", str(data), "--scenario", str(scenario), "--model", str(model),
            "--iteration", str(iteration), "--beta", repr(float(beta)), "--seed", str(seed)]
    if team_sizes:
        args += ["--team-sizes", ",".join(str(n) for n in team_sizes)]
    return tuple(args)


def label_iteration(
    data: str,
    model: str,
    iteration: int,
    runs: int,
    scenario: str = "scenarios/collect.toml",
    team_sizes: Sequence[int] = (),
    beta: float = 0.0,
    seed: int = 1000,
    runs_per_share: int = 10,
    parts_dir: Optional[str] = None,
    address: Optional[str] = None,
    formation_bin: Optional[str] = None,
    max_retries: int = 3,
) -> list[Path]:
    """Labels iteration ``iteration``'s ``runs`` rollouts as Ray tasks of ``runs_per_share`` runs
    and appends them to the dataset ``data``, in run order.

    ``model`` drives (iteration ``k - 1``'s policy); ``scenario``, ``team_sizes``, ``beta`` and
    ``seed`` are ``formation dagger``'s flags of the same names. The parts are kept in
    ``parts_dir`` (default: ``<data>.dagger<k>.parts`` beside the dataset) as
    ``part-NNNNNN.safetensors``; returns their paths in run order.
    """
    if runs < 1 or runs_per_share < 1:
        raise SweepError(f"runs and runs_per_share must be at least 1 (got {runs}, {runs_per_share})")
    binary = formation_binary(formation_bin)
    folder = Path(parts_dir) if parts_dir else Path(f"{data}.dagger{iteration}.parts")
    common = _label_args(data, model, iteration, scenario, team_sizes, beta, seed)
    shares = []
    for first in range(0, runs, runs_per_share):
        count = min(runs_per_share, runs - first)
        args = (*common, "--first-run", str(first), "--runs", str(count), "--threads", "1")
        path = folder / f"part-{first:06d}.safetensors"
        shares.append(Share(args, "--part", path, f"iteration {iteration}, runs {first}..{first + count}"))
    run_shares(shares, binary, address=address, max_retries=max_retries)
    parts = [s.path for s in shares]
    run_cli(binary, "dagger-append", "--data", str(data), "--iteration", str(iteration),
            "--runs", str(runs), *map(str, parts))
    return parts


def warm_start_of(model: str) -> str:
    """What the next iteration trains from, as ``formation dagger`` does: the ``.pt`` checkpoint
    beside ``model`` when there is one (it was trained here), else the ``.onnx`` itself."""
    checkpoint = Path(model).with_suffix(".pt")
    return str(checkpoint) if checkpoint.is_file() else str(model)


def dagger_iteration(
    data: str,
    model: str,
    iteration: int,
    out: str,
    runs: int,
    scenario: str = "scenarios/collect.toml",
    team_sizes: Sequence[int] = (),
    beta: float = 0.0,
    seed: int = 1000,
    train_args: Sequence[str] = DAGGER_TRAINING,
    eval_scenario: str = "scenarios/table1.toml",
    eval_runs: int = 100,
    runs_per_share: int = 10,
    address: Optional[str] = None,
    formation_bin: Optional[str] = None,
    max_retries: int = 3,
) -> dict:
    """One DAgger iteration: labels its rollouts on Ray (:func:`label_iteration`), retrains
    ``model`` on the grown dataset into ``out``, and evaluates ``out`` in closed loop.

    Training runs on the driver, with ``formation train --data DATA --out OUT --init-from
    <model's checkpoint, else model> TRAIN_ARGS`` (default: ``formation dagger``'s epochs, batch
    size and learning rate, :data:`DAGGER_TRAINING`; add its other training flags there, e.g.
    ``--d-star-range 1,2``). The evaluation is an
    :func:`formation.sweep.eval_sweep` of ``eval_runs`` runs of ``eval_scenario`` on Ray, written
    beside ``out`` as ``<stem>-eval/``; returns its summary (what ``formation eval --json``
    writes), the iteration's point of the DAgger curve.
    """
    binary = formation_binary(formation_bin)
    label_iteration(data, model, iteration, runs, scenario=scenario, team_sizes=team_sizes,
                    beta=beta, seed=seed, runs_per_share=runs_per_share, address=address,
                    formation_bin=binary, max_retries=max_retries)
    run_cli(binary, "train", "--data", str(data), "--out", str(out), "--init-from",
            warm_start_of(model), *train_args)
    cell = Cell(str(eval_scenario), controller="policy", model=str(out), runs=eval_runs)
    out_dir = Path(out).with_name(f"{Path(out).stem}-eval")
    return eval_sweep([cell], out_dir=str(out_dir), runs_per_share=runs_per_share,
                      address=address, formation_bin=binary, max_retries=max_retries)[cell.name()]
