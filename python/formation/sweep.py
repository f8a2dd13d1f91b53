"""Evaluation sweeps as Ray tasks: scenarios x team sizes x seeds x models, on this machine or a cluster.

Each cell of the grid is one ``formation eval``, cut into shares of its runs. Every share is a Ray
task that runs ``formation eval --first-run A --runs K --shard FILE`` and hands the shard's bytes
back; the driver keeps exactly one shard per share and merges each cell with ``formation merge``,
which writes the JSON one ``formation eval --json`` of all the runs writes, byte for byte (every
run is a pure function of scenario, seed, run index and model).

A worker that dies mid-share (a killed process, a lost node) is retried by Ray (``max_retries``);
its share's result arrives once, so no run is lost or counted twice, and the merge refuses a run
held twice or by none anyway.

    from formation.sweep import Cell, eval_sweep
    results = eval_sweep([Cell("scenarios/table1.toml", controller="expert")], out_dir="sweep")

By default it calls ``ray.init()`` here; ``address="HOST:PORT"`` (or ``"auto"``) joins a running
cluster. Every node needs the ``formation`` binary at the same path (``formation_bin``, else
``FORMATION_BIN``, else ``formation`` on ``PATH``) and the scenario and model files.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Iterable, Optional, Sequence


class SweepError(RuntimeError):
    """A sweep that could not run: a missing binary, a failed share, or shards that do not merge."""


@dataclasses.dataclass(frozen=True)
class Cell:
    """One evaluation of the grid: ``formation eval`` with these settings."""

    scenario: str
    controller: str = "policy"
    model: Optional[str] = None
    seed: Optional[int] = None
    robots: Optional[int] = None
    runs: Optional[int] = None

    def name(self) -> str:
        """A file name for the cell's merged JSON."""
        parts = [Path(self.scenario).stem, self.controller]
        if self.model:
            parts.append(Path(self.model).stem)
        if self.robots is not None:
            parts.append(f"n{self.robots}")
        if self.seed is not None:
            parts.append(f"s{self.seed}")
        return "-".join(parts)

    def eval_args(self) -> list[str]:
        """The flags every share of this cell passes to ``formation eval``."""
        args = ["--scenario", self.scenario, "--controller", self.controller]
        if self.model:
            args += ["--model", self.model]
        if self.seed is not None:
            args += ["--seed", str(self.seed)]
        if self.robots is not None:
            args += ["--robots", str(self.robots)]
        return args


def grid(
    scenarios: Sequence[str],
    team_sizes: Sequence[Optional[int]] = (None,),
    seeds: Sequence[Optional[int]] = (None,),
    models: Sequence[Optional[str]] = (None,),
    controller: str = "policy",
    runs: Optional[int] = None,
) -> list[Cell]:
    """Every combination of scenarios x team sizes x seeds x models, as cells."""
    return [
        Cell(s, controller=controller, model=m, seed=seed, robots=n, runs=runs)
        for s in scenarios
        for n in team_sizes
        for seed in seeds
        for m in models
    ]


def formation_binary(formation_bin: Optional[str] = None) -> str:
    """The ``formation`` executable: the argument, else ``FORMATION_BIN``, else ``PATH``."""
    candidate = formation_bin or os.environ.get("FORMATION_BIN") or shutil.which("formation")
    if not candidate or not Path(candidate).is_file():
        raise SweepError(
            "no `formation` binary: build it (`cargo build --release`) and pass "
            "formation_bin=..., set FORMATION_BIN, or put it on PATH"
        )
    return str(Path(candidate).resolve())


def _scenario_runs(cell: Cell) -> int:
    """How many runs the cell plays: its own ``runs``, else its scenario file's ``runs`` key."""
    if cell.runs is not None:
        return cell.runs
    try:
        import tomllib
    except ImportError as e:  # Python < 3.11
        raise SweepError(f"{cell.scenario}: give Cell(runs=N) (no tomllib here)") from e
    with open(cell.scenario, "rb") as f:
        runs = tomllib.load(f).get("runs")
    if not isinstance(runs, int) or runs < 1:
        raise SweepError(f"{cell.scenario}: no `runs` count; give Cell(runs=N)")
    return runs


@dataclasses.dataclass(frozen=True)
class Share:
    """One Ray task of a sweep: ``formation ARGS OUT_FLAG FILE`` on some node, whose output file
    the driver keeps at ``path`` (``what`` names the share in errors)."""

    args: tuple[str, ...]
    out_flag: str
    path: Path
    what: str


def _run_share(binary: str, args: Sequence[str], out_flag: str, what: str) -> bytes:
    """One share, on a worker: runs ``formation ARGS OUT_FLAG F`` into a temp dir of its own and
    returns F's bytes (so nodes need no shared folder)."""
    with tempfile.TemporaryDirectory(prefix="formation-share-") as tmp:
        out = Path(tmp) / "share.out"
        cmd = [binary, *args, out_flag, str(out)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise SweepError(
                f"{what}: `{' '.join(cmd)}` exited {done.returncode}: {done.stderr.strip()}"
            )
        return out.read_bytes()


def write_atomic(path: Path, data: bytes) -> None:
    """Writes ``data`` to ``path`` under a temporary name, synced, then renamed: a reader (or a
    driver killed mid-write) sees the old file or the new one, never half of one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def run_shares(
    shares: Sequence[Share],
    binary: str,
    address: Optional[str] = None,
    max_retries: int = 3,
) -> None:
    """Runs every share as a Ray task of one CPU and writes its output file to ``share.path``.

    A task whose worker dies (a killed process, a lost node) is retried by Ray up to
    ``max_retries`` times; the driver keeps exactly one result per share, written atomically, so
    a share's file is written once, whole. Joins the cluster at ``address`` (``None``: a local
    ``ray.init()``) unless Ray is already initialised here.
    """
    import ray

    started_here = not ray.is_initialized()
    if started_here:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        task = ray.remote(num_cpus=1, max_retries=max_retries)(_run_share)
        pending = [(s, task.remote(binary, list(s.args), s.out_flag, s.what)) for s in shares]
        for share, ref in pending:
            try:
                data = ray.get(ref)
            except ray.exceptions.RayError as e:
                raise SweepError(f"{share.what}: {e}") from e
            write_atomic(share.path, data)
    finally:
        if started_here:
            ray.shutdown()


def run_cli(binary: str, *args: str) -> str:
    """Runs ``formation ARGS`` here (a merge, an append, a training); returns its stdout."""
    done = subprocess.run([binary, *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SweepError(f"`formation {' '.join(args)}` exited {done.returncode}: {done.stderr.strip()}")
    return done.stdout


def eval_sweep(
    cells: Iterable[Cell],
    out_dir: str,
    runs_per_share: int = 10,
    address: Optional[str] = None,
    formation_bin: Optional[str] = None,
    max_retries: int = 3,
) -> dict[str, dict]:
    """Evaluates every cell as Ray tasks of ``runs_per_share`` runs and merges each cell.

    Writes ``OUT_DIR/<cell>/shard-NNNNNN.json`` and ``OUT_DIR/<cell>.json`` (what ``formation eval
    --json`` writes); returns the merged JSON per cell name.
    """
    if runs_per_share < 1:
        raise SweepError(f"runs_per_share must be at least 1 (got {runs_per_share})")
    binary = formation_binary(formation_bin)
    cells = list(cells)
    names = [c.name() for c in cells]
    if len(set(names)) != len(names):
        raise SweepError(f"two cells have the same name: {names}")
    out = Path(out_dir)
    shares: list[Share] = []
    for cell in cells:
        total = _scenario_runs(cell)
        for first in range(0, total, runs_per_share):
            count = min(runs_per_share, total - first)
            args = ("eval", *cell.eval_args(), "--first-run", str(first), "--runs", str(count),
                    "--threads", "1")
            path = out / cell.name() / f"shard-{first:06d}.json"
            what = f"cell {cell.name()}, runs {first}..{first + count}"
            shares.append(Share(args, "--shard", path, what))
    run_shares(shares, binary, address=address, max_retries=max_retries)
    results = {}
    for cell in cells:
        merged = out / f"{cell.name()}.json"
        paths = [str(s.path) for s in shares if s.path.parent.name == cell.name()]
        try:
            run_cli(binary, "merge", *paths, "--runs", str(_scenario_runs(cell)), "--json", str(merged))
        except SweepError as e:
            raise SweepError(f"merging {cell.name()}: {e}") from e
        results[cell.name()] = json.loads(merged.read_text())
    return results
