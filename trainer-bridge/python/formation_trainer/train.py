"""Behaviour cloning of the expert: MSE on the model's output, Adam, seeded.

The output (``output``) is either the paper's ``wheels``, the (left, right) wheel speeds at
``v_train``, or ``formation_velocity``: the expert's formation velocity in the robot's frame, the
velocity of the point half a wheel track ahead of the axle minus the reference term
``v_train (cos Δφ, sin Δφ)``, which the agent adds back at the goal's own speed. It is computed from
the dataset's wheel labels (:func:`formation_velocity_targets`), so no data is collected again.
With ``response_weight`` each sample's squared error is weighted by ``1 / (|f| + eps)`` (mean
weight 1), so the small corrections that decide the strict check (labels of 0.05-0.2 m/s, edges
1-5 % off d*) are not averaged away by a loss dominated by large ones.

With ``relative_loss`` each sample's squared error is weighted by ``(d_ref / d*)**2``, where
``d_ref`` makes the training samples' mean weight 1 (see :func:`relative_weights`). The success
check judges distances relative to d*, and a wheel-speed error moves a robot by the same metres
whatever d* is, so without the weight a team at d* = 0.8 m is fitted 10 times less tightly, in the
check's terms, than one at 2.5 m. Train and validation losses are then both weighted.

**Ranges.** A dataset whose samples carry their scan's ranges (``formation collect --ranges
sectors=K,clip=C``) trains a model that takes them (``PolicyNet(range_sectors=K)``, the third
input ``ranges`` and ``formation.ranges`` in the export); the dataset decides, no option does.
Mirroring reflects the ranges with the image. A model with ranges needs a dataset with them.
Warm-starting a model *without* ranges on a dataset *with* them (:func:`add_range_branch`) adds
the range branch, copies every other weight, and gives the head's first layer zero weights on
the 64 new features, so the new network starts with exactly the old one's outputs and learns to
use the ranges from there.

**Neighbours: the pair network.** A dataset whose samples carry the neighbours each robot detects
in its own scan (``formation collect --neighbours K``, format version 3) trains the pair network
(:class:`~formation_trainer.model.PairNet`, ``--architecture pair``, which the trainer picks for
such a dataset when no architecture is named): one learned term per neighbour, summed, times d*.
It answers a formation velocity (``--output formation_velocity``, which it needs) and is exported
with the third input ``neighbours`` and ``formation.neighbours``, the dataset's declaration. Its
training leaves out the samples whose expert wheels saturated (:func:`unsaturated`): their
formation velocity is the saturated point's, not the law's, and the network fits the law. A
CNN (``--architecture paper|wide|wide-head``) may still be trained on such a dataset from its
images; it leaves the neighbours out. A warm start from a pair network needs data with the same
number of slots. Mirroring negates the neighbours' ``y``.

Validation holds out whole runs (every sample of a run is in the same split: consecutive ticks are
nearly identical, so a per-sample split would measure memorisation). Images stay uint8 in memory
and become float per batch. After training, beside ``out`` (``<stem>.onnx``) it writes:

- ``<stem>.pt``: checkpoint (weights, optimiser state, metadata) for warm starts (``--init-from``)
  and for ``python -m formation_trainer export``;
- ``<stem>.loss.csv`` (epoch, train_loss, val_loss, seconds) and ``<stem>.loss.png``;
- ``<stem>.onnx``: the model with its metadata, checked against onnxruntime on held-out samples.

The last stdout line is ``FORMATION_TRAIN_REPORT {json}``, parsed by the Rust bridge.
"""

from __future__ import annotations

import csv
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import nn

from . import dataset as ds
from . import export
from .model import PAIR_ARCHITECTURES, PAIR_HIDDEN, PAIR_POTENTIAL_ARCHITECTURE, RANGE_FEATURES, PairNet, PolicyNet, mirror_inputs, mirror_output

CHECKPOINT_FORMAT = "formation-checkpoint/1"
REPORT_PREFIX = "FORMATION_TRAIN_REPORT "
#: Held-out samples run through torch and onnxruntime after export.
PARITY_SAMPLES = 64
#: Samples written to ``--parity-out``.
PARITY_FILE_SAMPLES = 8
#: Batch size for evaluation passes (no gradients).
EVAL_BATCH = 1024
#: A wheel label within this much [m/s] of the data's largest |wheel label| counts as saturated.
SATURATION_MARGIN = 1e-3
#: The fastest reference term the expert adds [m/s]: ``formation_proto::MAX_REFERENCE_SPEED``, which
#: a test of formation-trainer-bridge holds this line to. Labels collected above it carry this speed.
MAX_REFERENCE_SPEED = 0.7


class TrainError(Exception):
    """Training cannot run with these options."""


@dataclass
class TrainConfig:
    data: list
    out: Path
    epochs: int = 10
    batch_size: int = 32
    lr: float = 1e-4
    device: str = "auto"
    val_fraction: float = 0.1
    seed: int = 0
    init_from: Path | None = None
    parity_out: Path | None = None
    # The d* range the model is declared for (its envelope); None: the data's own range.
    d_star_range: tuple[float, float] | None = None
    # The network (one of model.ARCHITECTURE_NAMES); None: the warm start's, else the pair
    # network for data with neighbours and the paper's for the rest.
    architecture: str | None = None
    # Use the task's mirror symmetry: mirror half of every batch about the robot's heading axis
    # (see mirror_batch), and make the model average its output over the reflection
    # (PolicyNet.mirror_averaged), so the exported policy is exactly symmetric.
    mirror: bool = False
    # With mirror: export the mirror average (exactly symmetric, two evaluations per decision);
    # False exports the fitted network itself (symmetric as far as it learned, one evaluation).
    mirror_average: bool = True
    # Train each epoch on this many training samples drawn afresh at random (without
    # replacement); None: every training sample. Keeps an epoch's cost fixed as a DAgger
    # dataset grows, while every sample keeps the same chance of being drawn.
    samples_per_epoch: int | None = None
    # Weight each sample's squared error by (d_ref / d*)^2 (see relative_weights).
    relative_loss: bool = False
    # What the model outputs: "wheels" (the paper's) or "formation_velocity" (see the module).
    output: str = "wheels"
    # Weight each sample's squared error by 1 / (|f| + response_weight) [m/s] (see
    # response_weights); None: unweighted.
    response_weight: float | None = None


def artifact_paths(out: Path) -> dict[str, Path]:
    """The files written for model ``out`` (``<dir>/<stem>.onnx``)."""
    out = Path(out)
    return {
        "model": out,
        "checkpoint": out.with_suffix(".pt"),
        "loss_csv": out.with_name(out.stem + ".loss.csv"),
        "loss_png": out.with_name(out.stem + ".loss.png"),
    }


def resolve_device(name: str) -> torch.device:
    """``auto`` picks CUDA when available; ``cuda`` without a GPU is an error, not a silent fallback."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name == "cuda":
        if not torch.cuda.is_available():
            raise TrainError("--device cuda was asked for but PyTorch sees no CUDA device: use --device cpu or auto")
        return torch.device("cuda")
    raise TrainError(f"--device must be auto, cpu or cuda, got {name!r}")


def split_by_episode(keys: np.ndarray, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices of the (train, validation) splits, holding out ``val_fraction`` of the episodes.

    With a single episode the split falls back to samples. Both splits are sorted.
    """
    n = len(keys)
    if not 0.0 <= val_fraction < 1.0:
        raise TrainError(f"--val-fraction must be in [0, 1), got {val_fraction}")
    rng = np.random.default_rng(seed)
    if val_fraction == 0.0 or n < 2:
        return np.arange(n), np.arange(0)
    groups, inverse = np.unique(keys, return_inverse=True)
    if len(groups) >= 2:
        n_val = min(max(1, round(val_fraction * len(groups))), len(groups) - 1)
        val_groups = np.zeros(len(groups), dtype=bool)
        val_groups[rng.permutation(len(groups))[:n_val]] = True
        is_val = val_groups[inverse]
    else:
        n_val = min(max(1, round(val_fraction * n)), n - 1)
        is_val = np.zeros(n, dtype=bool)
        is_val[rng.permutation(n)[:n_val]] = True
    return np.flatnonzero(~is_val), np.flatnonzero(is_val)


def load_checkpoint(path: Path) -> dict:
    """Reads a checkpoint written by :func:`save_checkpoint`, with a clear error if it is not one.

    A ``.onnx`` policy written by this trainer is accepted too (see :func:`checkpoint_from_onnx`),
    so a shipped model can be fine-tuned without the ``.pt`` it was trained beside.
    """
    path = Path(path)
    if not path.is_file():
        raise TrainError(f"checkpoint {path} does not exist: train a model first (it is written beside the .onnx)")
    if path.suffix == ".onnx":
        return checkpoint_from_onnx(path)
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:
        raise TrainError(f"{path} is not a readable checkpoint ({e}): retrain, or pass the .pt written beside a model") from e
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != CHECKPOINT_FORMAT:
        raise TrainError(f"{path} is not a formation checkpoint ({CHECKPOINT_FORMAT}): pass the .pt written beside a model")
    return checkpoint


def checkpoint_from_onnx(path: Path) -> dict:
    """The weights of a formation policy ``.onnx`` as a checkpoint without optimizer state.

    The exporter keeps the PyTorch parameter names as the graph's initializers, and the metadata
    names the architecture and the image size; every parameter must be there with its shape.
    """
    import onnx
    from onnx import numpy_helper

    def foreign(why: str) -> TrainError:
        return TrainError(
            f"{path} cannot seed training: {why}; warm-start from a policy written by formation's trainer, or its .pt"
        )

    try:
        graph = onnx.load(str(path))
    except Exception as e:
        raise foreign(f"it is not a readable ONNX file ({e})") from e
    meta = {p.key: p.value for p in graph.metadata_props}
    if meta.get("formation.format") != export.MODEL_FORMAT:
        raise foreign(f"its formation.format is {meta.get('formation.format')!r}, not {export.MODEL_FORMAT!r}")
    architecture = meta.get("formation.train.architecture", "paper")
    mirror_averaged = meta.get("formation.policy.mirror_averaged") == "true"
    output = meta.get("formation.output", export.OUTPUT_NAME)
    neighbour_slots = None
    try:
        size_px = int(meta["formation.occupancy.size_px"])
        ranges = export.declared_ranges(meta)
        range_sectors = ranges.sectors if ranges else None
        if architecture in PAIR_ARCHITECTURES:
            neighbours = export.declared_neighbours(meta)
            if neighbours is None:
                raise ValueError(f"a pair network without {export.NEIGHBOURS_KEY}")
            neighbour_slots = neighbours.slots
            potential = architecture == PAIR_POTENTIAL_ARCHITECTURE
            model = PairNet(
                neighbour_slots, size_px, mirror_averaged, output, potential=potential, hidden_pairs=neighbours.hidden
            )
        else:
            model = PolicyNet(size_px, architecture, mirror_averaged, output, range_sectors)
    except (KeyError, ValueError) as e:
        raise foreign(f"its metadata does not describe a network this trainer builds ({e})") from e
    weights = {init.name: numpy_helper.to_array(init) for init in graph.graph.initializer}
    state = {}
    for name, param in model.state_dict().items():
        if name not in weights:
            raise foreign(f"it has no weights named {name!r}")
        if tuple(weights[name].shape) != tuple(param.shape):
            raise foreign(f"{name!r} has shape {tuple(weights[name].shape)}, the {architecture!r} network needs {tuple(param.shape)}")
        state[name] = torch.from_numpy(weights[name].copy())
    return {
        "format": CHECKPOINT_FORMAT,
        "size_px": size_px,
        "architecture": architecture,
        "mirror_averaged": mirror_averaged,
        "output": output,
        "range_sectors": range_sectors,
        "neighbour_slots": neighbour_slots,
        "pair_hidden": list(PAIR_HIDDEN) if neighbour_slots else None,
        "hidden_pairs": bool(neighbour_slots) and model.hidden_pairs,
        "model_state": state,
        "metadata": meta,
    }


def save_checkpoint(path: Path, model: PolicyNet | PairNet, optimizer, metadata: dict[str, str]) -> None:
    temp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    torch.save(
        {
            "format": CHECKPOINT_FORMAT,
            "size_px": model.size_px,
            "architecture": model.architecture,
            "mirror_averaged": model.mirror_averaged,
            "output": model.output,
            "range_sectors": model.range_sectors,
            "neighbour_slots": model.neighbour_slots,
            "pair_hidden": list(model.hidden) if isinstance(model, PairNet) else None,
            "hidden_pairs": isinstance(model, PairNet) and model.hidden_pairs,
            "model_state": model.state_dict(),
            "optimizer_state": optimizer.state_dict(),
            "metadata": metadata,
        },
        temp,
    )
    os.replace(temp, path)


def model_from_checkpoint(checkpoint: dict, size_px: int | None = None) -> PolicyNet | PairNet:
    """A model with the checkpoint's weights; ``size_px`` (if given) must match the checkpoint's."""
    if size_px is not None and checkpoint["size_px"] != size_px:
        raise TrainError(
            f"the checkpoint was trained on {checkpoint['size_px']} px images but the data has {size_px} px: "
            "warm-start only from a model trained on the same occupancy settings"
        )
    # Checkpoints from before the architecture choice hold the paper's network, and those from
    # before the mirror average a network without it.
    if checkpoint.get("architecture") in PAIR_ARCHITECTURES:
        model = PairNet(
            checkpoint["neighbour_slots"],
            checkpoint["size_px"],
            checkpoint.get("mirror_averaged", False),
            checkpoint.get("output", "formation_velocity"),
            tuple(checkpoint.get("pair_hidden") or PAIR_HIDDEN),
            potential=checkpoint["architecture"] == PAIR_POTENTIAL_ARCHITECTURE,
            hidden_pairs=checkpoint.get("hidden_pairs", False),
        )
        model.load_state_dict(checkpoint["model_state"])
        return model
    model = PolicyNet(
        checkpoint["size_px"],
        checkpoint.get("architecture", "paper"),
        checkpoint.get("mirror_averaged", False),
        checkpoint.get("output", "wheels"),
        checkpoint.get("range_sectors"),
    )
    model.load_state_dict(checkpoint["model_state"])
    return model


def add_range_branch(model: PolicyNet, sectors: int) -> PolicyNet:
    """``model`` (without ranges) with a range branch of ``sectors`` sectors, computing exactly
    what ``model`` computes: every weight is copied, the head's first layer keeps its columns for
    the image features and aux and gets zero columns for the 64 range features, and the range
    branch is initialised as a fresh one is (its gradients reach it through those columns)."""
    if model.range_sectors is not None:
        raise TrainError(f"the network already takes ranges of {model.range_sectors} sectors")
    widened = PolicyNet(model.size_px, model.architecture, model.mirror_averaged, model.output, sectors)
    old, new = model.state_dict(), widened.state_dict()
    first = next(m for m in model.head if isinstance(m, nn.Linear))
    first_name = next(name for name, m in model.head.named_children() if m is first)
    weight_key = f"head.{first_name}.weight"
    state = {}
    for name, param in new.items():
        if name == weight_key:
            columns = old[name].shape[1]
            if param.shape[1] != columns + RANGE_FEATURES:
                raise TrainError(f"the head's first layer takes {param.shape[1]} inputs, expected {columns} + {RANGE_FEATURES}")
            param = torch.zeros_like(param)
            param[:, :columns] = old[name]
        elif name in old:
            param = old[name].clone()
        state[name] = param
    widened.load_state_dict(state)
    return widened


def _apply(
    model, occupancy: torch.Tensor, aux: torch.Tensor, ranges: torch.Tensor | None, neighbours: torch.Tensor | None = None
) -> torch.Tensor:
    """``model`` on a batch, given its third input (ranges or neighbours) only where it takes one."""
    if neighbours is not None:
        return model(occupancy, aux, neighbours)
    return model(occupancy, aux) if ranges is None else model(occupancy, aux, ranges)


def _batch(tensors: dict, index: torch.Tensor):
    """The batch ``index``: occupancy [B, 1, S, S] float, aux, ranges and neighbours (None where
    the model takes none), targets."""
    occupancy = tensors["occupancy"].index_select(0, index).unsqueeze(1).float()
    ranges = tensors["ranges"].index_select(0, index) if "ranges" in tensors else None
    neighbours = tensors["neighbours"].index_select(0, index) if "neighbours" in tensors else None
    return occupancy, tensors["aux"].index_select(0, index), ranges, neighbours, tensors["targets"].index_select(0, index)


def unsaturated(wheels: np.ndarray, margin: float = SATURATION_MARGIN) -> np.ndarray:
    """Which samples' expert wheel labels did not saturate: a sample whose larger |wheel label|
    lies within ``margin`` m/s of the largest in the data was scaled into the wheel limit, so its
    formation velocity is the saturated point's, not the law's (the manifest does not record the
    robot's wheel limit; the data's own largest label stands for it, as in the offline probes of
    docs/measurements/response-ceiling)."""
    speed = np.abs(np.asarray(wheels, dtype=np.float64)).max(axis=1) if len(wheels) else np.zeros(0)
    if len(speed) == 0:
        return np.zeros(0, dtype=bool)
    return speed < speed.max() - margin


def formation_velocity_targets(wheels: np.ndarray, aux: np.ndarray, v_train: float) -> np.ndarray:
    """The expert's formation velocity in the robot's frame from its wheel labels at ``v_train``.

    With the controlled point half a track ahead of the axle (``c = l/2``), wheels ``(L, R)`` move it
    at ``u = ((L + R) / 2, (R - L) / 2)`` in the robot's frame, whatever the track; the reference term
    seen from the robot is ``v (cos Δφ, sin Δφ)``, at ``v = v_train`` capped to the expert's
    ``MAX_REFERENCE_SPEED`` as it caps it. Where the expert's wheels saturated, ``u`` is the
    saturated point velocity, which is what the robot could do."""
    wheels = np.asarray(wheels, dtype=np.float64)
    delta_phi = np.asarray(aux, dtype=np.float64)[:, 0]
    u_x = (wheels[:, 0] + wheels[:, 1]) / 2
    u_y = (wheels[:, 1] - wheels[:, 0]) / 2
    reference = min(max(v_train, -MAX_REFERENCE_SPEED), MAX_REFERENCE_SPEED)
    f = np.stack([u_x - reference * np.cos(delta_phi), u_y - reference * np.sin(delta_phi)], axis=1)
    return f.astype(np.float32)


def response_weights(targets: np.ndarray, eps: float, train_idx: np.ndarray) -> np.ndarray:
    """Per-sample weights ``1 / (|f| + eps)``, scaled so that the training samples' mean weight is 1."""
    if not (math.isfinite(eps) and eps > 0):
        raise TrainError(f"--response-weight must be a speed > 0 m/s (for example 0.05), got {eps}")
    inverse = 1.0 / (np.linalg.norm(np.asarray(targets, dtype=np.float64), axis=1) + eps)
    scale = inverse[train_idx].mean() if len(train_idx) else inverse.mean()
    return (inverse / scale).astype(np.float32)


def training_threads() -> int:
    """CPU threads for training: ``FORMATION_TRAIN_THREADS`` when set, else every core. On a host
    whose cores are busy with other work (a build, another training), one thread is often several
    times faster than two: PyTorch's threads wait for each other at every operation, and a
    descheduled one stalls them all."""
    text = os.environ.get("FORMATION_TRAIN_THREADS", "").strip()
    if not text:
        return os.cpu_count() or 1
    try:
        threads = int(text)
    except ValueError:
        threads = 0
    if threads < 1:
        raise TrainError(f"FORMATION_TRAIN_THREADS must be a positive number of threads, got {text!r}")
    return threads


def mirror_batch(
    occupancy: torch.Tensor,
    aux: torch.Tensor,
    wheels: torch.Tensor,
    flip: torch.Tensor,
    output: str = "wheels",
    ranges: torch.Tensor | None = None,
    neighbours: torch.Tensor | None = None,
):
    """Reflects the samples where ``flip`` is true about the robot's heading axis (y -> -y).

    The task is symmetric under that reflection, exactly: the image's rows reverse (row ``r`` holds
    ``y`` in ``[W/2 - (r+1) res, W/2 - r res)``, so ``-y`` falls in row ``size - 1 - r``, and a scan
    of beams at ``2 pi k / n`` reflects onto itself), the heading error ``delta_phi`` changes sign,
    d* stays, and the expert's turn reverses, which swaps the left and right wheel speeds (for a
    ``formation_velocity`` output: negates its sideways component). The ranges' sector ``s``
    becomes sector ``(K - s) % K``; the neighbours' ``y / d*`` changes sign (their flags and
    order stay). Training on both halves doubles the distinct views and builds the symmetry into
    the policy.

    Returns ``(occupancy, aux, wheels)``, followed by the ranges and then the neighbours where they
    are given.
    """
    mirrored_occupancy, mirrored_aux, *mirrored_extra = mirror_inputs(occupancy, aux, ranges, neighbours)
    occupancy = torch.where(flip[:, None, None, None], mirrored_occupancy, occupancy)
    aux = torch.where(flip[:, None], mirrored_aux, aux)
    wheels = torch.where(flip[:, None], mirror_output(wheels, output), wheels)
    batch = (occupancy, aux, wheels)
    for original, mirrored in zip((x for x in (ranges, neighbours) if x is not None), mirrored_extra):
        where = flip.reshape(-1, *([1] * (original.dim() - 1)))
        batch = (*batch, torch.where(where, mirrored, original))
    return batch


def relative_weights(d_star: np.ndarray, train_idx: np.ndarray) -> np.ndarray:
    """Per-sample loss weights ``(d_ref / d*)**2``, ``d_ref`` chosen so that the training samples'
    mean weight is 1 (the loss keeps its scale, and so does the learning rate's effect)."""
    d_star = np.asarray(d_star, dtype=np.float64)
    if len(d_star) == 0 or not np.all(np.isfinite(d_star)) or np.any(d_star <= 0):
        raise TrainError("--relative-loss needs every sample's d* to be finite and > 0; the dataset has others")
    inverse_square = 1.0 / d_star**2
    scale = inverse_square[train_idx].mean() if len(train_idx) else inverse_square.mean()
    return (inverse_square / scale).astype(np.float32)


def squared_error(prediction: torch.Tensor, wheels: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """Per-sample sum of squared wheel errors, times the sample's weight if there is one."""
    error = (prediction - wheels).pow(2).sum(dim=1)
    return error if weights is None else error * weights


def mean_loss(model: PolicyNet | PairNet, tensors: dict, indices: torch.Tensor) -> float:
    """Mean squared error over ``indices`` (no gradients), weighted if ``tensors`` has weights."""
    if len(indices) == 0:
        return math.nan
    model.eval()
    total = 0.0
    with torch.no_grad():
        for start in range(0, len(indices), EVAL_BATCH):
            index = indices[start : start + EVAL_BATCH]
            occupancy, aux, ranges, neighbours, wheels = _batch(tensors, index)
            weights = tensors["weights"].index_select(0, index) if "weights" in tensors else None
            total += squared_error(_apply(model, occupancy, aux, ranges, neighbours), wheels, weights).sum().item()
    return total / (2 * len(indices))


def write_loss_curve(paths: dict[str, Path], history: list[dict]) -> None:
    """Writes the loss CSV and PNG."""
    with paths["loss_csv"].open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["epoch", "train_loss", "val_loss", "seconds"])
        for row in history:
            val = "" if math.isnan(row["val_loss"]) else f"{row['val_loss']:.8g}"
            writer.writerow([row["epoch"], f"{row['train_loss']:.8g}", val, f"{row['seconds']:.3f}"])
    try:
        import matplotlib
    except ImportError:  # the PNG is a convenience; the CSV holds the data
        print("matplotlib is not installed: skipping the loss PNG (the CSV has the curve)", flush=True)
        return
    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    epochs = [r["epoch"] for r in history]
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    ax.plot(epochs, [r["train_loss"] for r in history], marker="o", label="train")
    if not all(math.isnan(r["val_loss"]) for r in history):
        ax.plot(epochs, [r["val_loss"] for r in history], marker="s", label="validation")
    ax.set_xlabel("epoch")
    ax.set_ylabel("MSE [(m/s)^2]")
    if all(r["train_loss"] > 0 for r in history):
        ax.set_yscale("log")
    ax.set_title(paths["model"].stem)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(paths["loss_png"])
    plt.close(fig)


def envelope_metadata(samples, declared: tuple[float, float] | None = None) -> dict[str, str]:
    """The model's envelope (``formation.envelope.*``): the d* range (``declared``, which must hold
    every d* of the data, else the data's own range) and the team sizes of the training data (the
    robots of each (dataset, iteration, run)). ``formation eval/run`` and the agents refuse a goal
    whose d* lies outside the range."""
    if len(samples) == 0:
        return {}
    d_star = samples.aux[:, 1].astype(np.float64)
    lo, hi = float(d_star.min()), float(d_star.max())
    if declared is not None:
        d_lo, d_hi = (float(x) for x in declared)
        if not (math.isfinite(d_lo) and math.isfinite(d_hi) and 0 < d_lo < d_hi):
            raise TrainError(f"--d-star-range must be two distances MIN,MAX with 0 < MIN < MAX (got {d_lo},{d_hi})")
        slack = 1e-6
        if lo < d_lo * (1 - slack) or hi > d_hi * (1 + slack):
            raise TrainError(
                f"--d-star-range {d_lo},{d_hi} does not hold the training data's d* range "
                f"[{lo:.6g}, {hi:.6g}]: declare a range that covers the data"
            )
        lo, hi = d_lo, d_hi
    _, episode = np.unique(samples.episode_keys(), return_inverse=True)
    robots = np.zeros(int(episode.max()) + 1, dtype=np.int64)
    np.maximum.at(robots, episode, samples.robot.astype(np.int64) + 1)
    return {
        "envelope.d_star_min": export.number_text(lo),
        "envelope.d_star_max": export.number_text(hi),
        "envelope.team_sizes": ",".join(str(int(n)) for n in sorted(set(robots.tolist()))),
    }


def run(cfg: TrainConfig, log: Callable[[str], None] = print) -> dict:
    """Trains, writes every artefact and returns the report (also printed by the CLI)."""
    if cfg.epochs < 1 or cfg.batch_size < 1 or not (cfg.lr > 0 and math.isfinite(cfg.lr)):
        raise TrainError(f"epochs and batch size must be >= 1 and lr > 0 (got {cfg.epochs}, {cfg.batch_size}, {cfg.lr})")
    if cfg.samples_per_epoch is not None and cfg.samples_per_epoch < 1:
        raise TrainError(f"--samples-per-epoch must be >= 1 (got {cfg.samples_per_epoch}); leave it out to use every sample")
    if cfg.output not in export.OUTPUT_NAMES:
        raise TrainError(f"--output must be one of {', '.join(export.OUTPUT_NAMES)}, got {cfg.output!r}")
    out = Path(cfg.out)
    if out.suffix != ".onnx":
        raise TrainError(f"--out must end in .onnx, got {out}")
    paths = artifact_paths(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    device = resolve_device(cfg.device)
    torch.set_num_threads(training_threads())
    torch.manual_seed(cfg.seed)

    samples = ds.load(cfg.data)
    data_ranges = samples.range_input
    sectors = data_ranges.sectors if data_ranges else None
    data_neighbours = samples.neighbour_input
    data_names = ", ".join(str(d) for d in cfg.data)
    train_idx, val_idx = split_by_episode(samples.episode_keys(), cfg.val_fraction, cfg.seed)
    if cfg.init_from is not None:
        model = model_from_checkpoint(load_checkpoint(cfg.init_from), samples.size_px)
        if cfg.architecture is not None and cfg.architecture != model.architecture:
            raise TrainError(
                f"{cfg.init_from} holds the {model.architecture!r} network, not {cfg.architecture!r}: "
                f"warm-start from a checkpoint of the same architecture, or train {cfg.architecture!r} from scratch"
            )
        if isinstance(model, PairNet):
            _check_pair_data(data_neighbours, data_names, cfg.output)
            if (model.neighbour_slots, model.hidden_pairs) != (data_neighbours.slots, data_neighbours.hidden):
                raise TrainError(
                    f"{cfg.init_from} takes neighbours in {model.neighbour_slots} slots of "
                    f"{model.neighbour_features} values but the data's are "
                    f"{data_neighbours}: warm-start from a pair network of the same slots, or collect the data with its"
                )
            log(f"warm start from {cfg.init_from}")
        elif model.range_sectors == sectors:
            log(f"warm start from {cfg.init_from}")
        elif model.range_sectors is None:
            model = add_range_branch(model, sectors)
            log(
                f"warm start from {cfg.init_from}, a network without ranges: added a range branch for the data's "
                f"{data_ranges} with zero weights into the head, so the network starts with the old model's outputs"
            )
        elif sectors is None:
            raise TrainError(
                f"{cfg.init_from} takes the scan's ranges ({model.range_sectors} sectors) but "
                f"{', '.join(str(d) for d in cfg.data)} holds none: a model with ranges needs a dataset with ranges; "
                "collect one with `formation collect --ranges sectors=K,clip=C`, or warm-start from a model without ranges"
            )
        else:
            raise TrainError(
                f"{cfg.init_from} takes ranges of {model.range_sectors} sectors but the data's are {data_ranges}: "
                "warm-start from a model of the same range input, or collect the data with its"
            )
    elif cfg.architecture in PAIR_ARCHITECTURES or (cfg.architecture is None and data_neighbours is not None):
        _check_pair_data(data_neighbours, data_names, cfg.output, chosen=cfg.architecture is None)
        potential = cfg.architecture == PAIR_POTENTIAL_ARCHITECTURE
        model = PairNet(
            data_neighbours.slots, samples.size_px, potential=potential, hidden_pairs=data_neighbours.hidden
        )
    else:
        try:
            model = PolicyNet(samples.size_px, cfg.architecture or "paper", range_sectors=sectors)
        except ValueError as e:
            raise TrainError(str(e)) from e
    pair = isinstance(model, PairNet)
    if pair:
        # The pair network fits the law: samples whose wheels saturated are left out.
        keep = unsaturated(samples.wheels)
        dropped = int(len(keep) - keep.sum())
        train_idx, val_idx = train_idx[keep[train_idx]], val_idx[keep[val_idx]]
        if len(train_idx) == 0:
            raise TrainError(
                f"every training sample of {data_names} has saturated expert wheels: collect data whose labels "
                "the wheel limit does not cut (--unshaped-labels on a team near its formation)"
            )
        log(f"left out {dropped} of {len(keep)} samples whose expert wheels saturated (the pair network fits the law)")
    if cfg.mirror:
        model.mirror_averaged = cfg.mirror_average
    # A warm start from a model of the other output keeps its weights and learns the new meaning.
    model.output = cfg.output
    # With mirrored batches the network itself is fitted to both halves of the reflection. Its
    # expected loss bounds that of its mirror average from above (the square of a mean error is
    # at most the mean of the squares), at half the arithmetic of fitting the average.
    fitted = model.raw if cfg.mirror else model
    model.to(device)
    v_train = samples.manifests[0].v_train
    if cfg.output == "formation_velocity":
        targets = formation_velocity_targets(samples.wheels, samples.aux, v_train)
    else:
        targets = samples.wheels
    tensors = {
        "occupancy": torch.from_numpy(samples.occupancy).to(device),
        "aux": torch.from_numpy(samples.aux).to(device),
        "targets": torch.from_numpy(targets).to(device),
    }
    # The model's third input, where it takes one: a CNN the data's ranges, the pair network the
    # data's neighbours (and not the ranges).
    if model.range_sectors:
        tensors["ranges"] = torch.from_numpy(samples.ranges).to(device)
    if pair:
        tensors["neighbours"] = torch.from_numpy(samples.neighbours).to(device)
    weights = None
    if cfg.relative_loss:
        weights = relative_weights(samples.aux[:, 1], train_idx)
    if cfg.response_weight is not None:
        respond = response_weights(formation_velocity_targets(samples.wheels, samples.aux, v_train), cfg.response_weight, train_idx)
        weights = respond if weights is None else weights * respond
    if weights is not None:
        tensors["weights"] = torch.from_numpy(weights).to(device)
    train_t = torch.from_numpy(train_idx).to(device)
    val_t = torch.from_numpy(val_idx).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    shuffle = torch.Generator().manual_seed(cfg.seed)
    per_epoch = len(train_t) if cfg.samples_per_epoch is None else min(cfg.samples_per_epoch, len(train_t))
    drawn = "" if per_epoch == len(train_t) else f" of {per_epoch} samples drawn at random"
    log(
        f"training on {len(samples)} samples ({len(train_idx)} train / {len(val_idx)} validation) "
        f"from {', '.join(str(d) for d in cfg.data)} on {device} ({torch.get_num_threads()} threads); "
        f"{model.architecture} network{f', ranges {data_ranges}' if model.range_sectors else ''}"
        f"{f', neighbours {data_neighbours}' if pair else ''}{', mirrored' if cfg.mirror else ''}{', mirror-averaged' if model.mirror_averaged else ''}"
        f"{', loss relative to d*' if cfg.relative_loss else ''}"
        f"{f', loss weighted 1/(|f| + {cfg.response_weight:g})' if cfg.response_weight is not None else ''}"
        f", output {cfg.output}, batch {cfg.batch_size}, lr {cfg.lr:g}, "
        f"{cfg.epochs} epochs{drawn}"
    )

    history = []
    started = time.perf_counter()
    for epoch in range(1, cfg.epochs + 1):
        epoch_start = time.perf_counter()
        model.train()
        order = train_t[torch.randperm(len(train_t), generator=shuffle)[:per_epoch].to(device)]
        total = 0.0
        for start in range(0, len(order), cfg.batch_size):
            index = order[start : start + cfg.batch_size]
            occupancy, aux, ranges, neighbours, wheels = _batch(tensors, index)
            if cfg.mirror:
                flip = torch.rand(len(aux), generator=shuffle) < 0.5
                occupancy, aux, wheels, *mirrored = mirror_batch(
                    occupancy, aux, wheels, flip.to(device), cfg.output, ranges, neighbours
                )
                if ranges is not None:
                    ranges = mirrored.pop(0)
                if neighbours is not None:
                    neighbours = mirrored.pop(0)
            weights = tensors["weights"].index_select(0, index) if "weights" in tensors else None
            # The mean over samples and both wheels, as nn.functional.mse_loss computes it.
            loss = squared_error(_apply(fitted, occupancy, aux, ranges, neighbours), wheels, weights).mean() / 2
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += loss.item() * len(aux)
        train_loss = total / max(1, len(order))
        val_loss = mean_loss(model, tensors, val_t)
        seconds = time.perf_counter() - epoch_start
        history.append({"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss, "seconds": seconds})
        val_text = "-" if math.isnan(val_loss) else f"{val_loss:.6f}"
        log(
            f"epoch {epoch}/{cfg.epochs}  train_loss {train_loss:.6f}  val_loss {val_text}  "
            f"{seconds:.1f} s ({len(order) / max(seconds, 1e-9):.0f} samples/s)"
        )
    train_seconds = time.perf_counter() - started
    final_train = history[-1]["train_loss"]
    final_val = history[-1]["val_loss"]
    reported_val = final_train if math.isnan(final_val) else final_val

    model.to("cpu").eval()
    manifest = samples.manifests[0]
    metadata = export.model_metadata(
        occupancy=manifest.occupancy,
        lidar=samples.lidar,
        v_train=manifest.v_train,
        dataset_id=samples.dataset_id,
        epochs=cfg.epochs,
        final_train_loss=final_train,
        final_val_loss=reported_val,
        samples=len(samples),
        dagger_iteration=samples.max_iteration,
        ranges=data_ranges if model.range_sectors else None,
        neighbours=data_neighbours if pair else None,
        extra={
            "train.batch_size": cfg.batch_size,
            "train.lr": repr(float(cfg.lr)),
            "train.seed": cfg.seed,
            "train.val_samples": len(val_idx),
            "train.init_from": cfg.init_from.name if cfg.init_from else "",
            "train.architecture": model.architecture,
            "train.mirror": "true" if cfg.mirror else "false",
            "policy.mirror_averaged": "true" if model.mirror_averaged else "false",
            "train.samples_per_epoch": per_epoch,
            "train.relative_loss": "true" if cfg.relative_loss else "false",
            "train.response_weight": "" if cfg.response_weight is None else repr(float(cfg.response_weight)),
            "output": cfg.output,
            **envelope_metadata(samples, cfg.d_star_range),
        },
    )
    save_checkpoint(paths["checkpoint"], model, optimizer, metadata)
    write_loss_curve(paths, history)
    export.export_onnx(model, out, metadata, output=cfg.output)

    held_out = val_idx if len(val_idx) else train_idx
    pick = np.random.default_rng(cfg.seed).permutation(held_out)[:PARITY_SAMPLES]
    occupancy = samples.occupancy[pick][:, None].astype(np.float32)
    aux = samples.aux[pick]
    ranges = samples.ranges[pick] if model.range_sectors else None
    neighbours = samples.neighbours[pick] if pair else None
    parity = export.check_parity(model, out, occupancy, aux, output=cfg.output, ranges=ranges, neighbours=neighbours)
    if cfg.parity_out is not None:
        n = PARITY_FILE_SAMPLES
        export.write_parity_file(
            cfg.parity_out, model, occupancy[:n], aux[:n], ranges=None if ranges is None else ranges[:n],
            neighbours=None if neighbours is None else neighbours[:n],
        )
    log(f"wrote {out} (onnxruntime parity {parity:.2e} on {len(pick)} held-out samples), {paths['checkpoint'].name}, "
        f"{paths['loss_csv'].name}, {paths['loss_png'].name}")
    return {
        "epochs": cfg.epochs,
        "samples": len(samples),
        "train_samples": int(len(train_idx)),
        "samples_per_epoch": int(per_epoch),
        "val_samples": int(len(val_idx)),
        "final_train_loss": final_train,
        "final_val_loss": reported_val,
        "seconds": train_seconds,
        "device": str(device),
        "dataset_id": samples.dataset_id,
        "parity_max_abs_diff": parity,
        # The range input the model takes (formation.ranges), or None.
        "ranges": data_ranges.text() if model.range_sectors else None,
        # The neighbour input the model takes (formation.neighbours), or None.
        "neighbours": data_neighbours.text() if pair else None,
        **{name: str(path) for name, path in paths.items()},
    }


def _check_pair_data(neighbours, data_names: str, output: str, chosen: bool = False) -> None:
    """Refuses to train the pair network on data without neighbours, or for a wheels output."""
    if neighbours is None:
        raise TrainError(
            f"the pair network takes the neighbours each robot detects in its own scan, but {data_names} holds none: "
            "collect the data with `formation collect --neighbours K`, or train a CNN (--architecture paper|wide|wide-head)"
        )
    if output != "formation_velocity":
        why = f"{data_names} declares neighbours ({neighbours}), so the trainer builds the pair network, which" if chosen else "the pair network"
        raise TrainError(
            f"{why} answers a formation velocity, not {output!r}: add --output formation_velocity "
            "(or name a CNN, --architecture wide-head, to train on the images alone)"
        )


def report_line(report: dict) -> str:
    return REPORT_PREFIX + json.dumps(report, sort_keys=True)
