"""Shared test helpers: synthetic datasets written in the documented on-disk format.

The writer here is deliberately independent of the Rust one: it writes what the format
description in ``trainer-bridge/src/dataset.rs`` says, so the reader is tested against the spec.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from safetensors.numpy import save_file

#: The expert's team gain, ``ExpertGains::default().k_formation_graph`` in expert/src/controller.rs:
#: the gain of the law on each robot's own detections (expert/src/own_scan.rs).
K_FORMATION_GRAPH = 1.0


def pair_law(neighbours: np.ndarray, gain: float = K_FORMATION_GRAPH) -> np.ndarray:
    """The teacher's formation velocity in units of d* from neighbour slots ``[N, K, 4]``:
    ``f / d* = -k * sum over held j of 2 (|u|^4 - 1) / |u|^3 * (-u / |u|)`` with ``u = x_j / d*``
    (``add_pair_term`` on ``p_ij = -x_j``, then ``-k`` times the gradient), written here from the
    formula, not from the trainer."""
    u = np.asarray(neighbours, dtype=np.float64)[..., :2]
    held = np.asarray(neighbours, dtype=np.float64)[..., 2] * np.asarray(neighbours, dtype=np.float64)[..., 3]
    r = np.linalg.norm(u, axis=-1)
    safe = np.where(r > 0, r, 1.0)
    magnitude = 2.0 * (safe**4 - 1.0) / safe**3
    gradient = magnitude[..., None] * (-u / safe[..., None])
    return (-gain * (held[..., None] * gradient).sum(axis=1)).astype(np.float32)


def neighbour_sets(rng: np.random.Generator, samples: int, slots: int) -> np.ndarray:
    """Random neighbour inputs ``[samples, slots, 4]`` laid out as collection lays them out: 1-6
    held neighbours near a hexagonal formation at d* (each sample its own jitter, 0.3 % to 15 % of
    d*, so that small and large corrections both occur), up to 4 others held by nobody at 1.5-3 d*;
    held slots first, each group nearest first, empty slots all zero."""
    held_count = rng.integers(1, min(6, slots) + 1, samples)
    other_count = np.minimum(rng.integers(0, 5, samples), slots - held_count)
    slot = np.arange(slots)[None, :]
    held = slot < held_count[:, None]
    present = slot < (held_count + other_count)[:, None]
    jitter = np.exp(rng.uniform(np.log(0.003), np.log(0.15), samples))[:, None]
    hexagon = np.argsort(rng.random((samples, 6)), axis=1)[:, np.minimum(slot[0], 5)] * (np.pi / 3)
    rotation = rng.uniform(-np.pi, np.pi, samples)[:, None]
    bearing = np.where(
        held,
        rotation + hexagon + rng.normal(0.0, 1.0, (samples, slots)) * jitter,
        rng.uniform(-np.pi, np.pi, (samples, slots)),
    )
    distance = np.where(held, 1.0 + rng.normal(0.0, 1.0, (samples, slots)) * jitter, rng.uniform(1.5, 3.0, (samples, slots)))
    key = np.where(present, np.where(held, 0.0, 100.0) + distance, 1e9)
    order = np.argsort(key, axis=1)
    take = lambda a: np.take_along_axis(a, order, axis=1)
    out = np.zeros((samples, slots, 4), dtype=np.float32)
    out[..., 0] = take(np.where(present, distance * np.cos(bearing), 0.0))
    out[..., 1] = take(np.where(present, distance * np.sin(bearing), 0.0))
    out[..., 2] = take(held.astype(np.float64))
    out[..., 3] = take(present.astype(np.float64))
    return out


def hidden_steps(rng: np.random.Generator, neighbours: np.ndarray) -> np.ndarray:
    """``neighbours`` [N, K, 4] with the two numbers of ``hidden=1`` added a slot: in a fifth of
    the samples the first two slots are the ends of a pair the robot hides, each carrying half of
    a step aside of 0.5-4 d* in a random direction; elsewhere zeros."""
    samples, slots, _ = neighbours.shape
    out = np.zeros((samples, slots, 6), dtype=np.float32)
    out[..., :4] = neighbours
    hides = (rng.random(samples) < 0.2) & (neighbours[:, : min(2, slots), 3].sum(axis=1) == min(2, slots))
    angle = rng.uniform(-np.pi, np.pi, samples)
    half = 0.5 * rng.uniform(0.5, 4.0, samples) * hides
    out[:, :2, 4] = (half * np.cos(angle))[:, None]
    out[:, :2, 5] = (half * np.sin(angle))[:, None]
    return out


def wheels_from_formation_velocity(f: np.ndarray, aux: np.ndarray, v_train: float) -> np.ndarray:
    """The wheel labels at ``v_train`` whose point velocity is ``v_train (cos dphi, sin dphi) + f``
    (the inverse of ``train.formation_velocity_targets``: ``u = ((L + R) / 2, (R - L) / 2)``)."""
    delta_phi = aux[:, 0].astype(np.float64)
    u_x = v_train * np.cos(delta_phi) + f[:, 0]
    u_y = v_train * np.sin(delta_phi) + f[:, 1]
    return np.stack([u_x - u_y, u_x + u_y], axis=1).astype(np.float32)


def synthetic_arrays(
    samples: int,
    size_px: int = 50,
    seed: int = 0,
    runs: int = 8,
    iteration: int = 0,
    sectors: int = 0,
    clip: float = 3.0,
    slots: int = 0,
    v_train: float = 0.7,
    hidden: bool = False,
):
    """Random sparse images and labels that depend on them (so a model can learn something); with
    ``sectors``, also ranges in [0, clip] that the labels depend on; with ``slots``, neighbours
    (:func:`neighbour_sets`) and wheel labels that are the teacher's law on them
    (:func:`pair_law`) at ``v_train``; with ``hidden``, each slot also carries a step aside
    (:func:`hidden_steps`), which the labels add at the team gain."""
    rng = np.random.default_rng(seed)
    occupancy = (rng.random((samples, size_px, size_px)) < 0.02).astype(np.uint8)
    aux = np.stack([rng.uniform(-np.pi, np.pi, samples), rng.uniform(0.5, 3.0, samples)], 1).astype(np.float32)
    left_mass = occupancy[:, :, : size_px // 2].mean(axis=(1, 2))
    wheels = np.stack([0.3 * np.sin(aux[:, 0]) + 5 * left_mass, 0.3 * np.cos(aux[:, 0]) - 0.1 * aux[:, 1]], 1)
    extra = {}
    if sectors:
        ranges = np.random.default_rng(seed + 1000).uniform(0.0, clip, (samples, sectors)).astype(np.float32)
        wheels = wheels + 0.05 * np.stack([ranges[:, 1] - ranges[:, -1], ranges[:, 0] - clip / 2], 1)
        extra["ranges"] = ranges
    if slots:
        neighbours = neighbour_sets(np.random.default_rng(seed + 2000), samples, slots)
        if hidden:
            neighbours = hidden_steps(np.random.default_rng(seed + 3000), neighbours)
        f = pair_law(neighbours) * aux[:, 1:2]
        if hidden:
            f = f + K_FORMATION_GRAPH * neighbours[..., 4:6].sum(axis=1) * aux[:, 1:2]
        wheels = wheels_from_formation_velocity(f, aux, v_train)
        extra["neighbours"] = neighbours
    return extra | {
        "occupancy": occupancy,
        "aux": aux,
        "wheels": wheels.astype(np.float32),
        "iteration": np.full(samples, iteration, dtype=np.uint32),
        "run": (np.arange(samples) * runs // max(samples, 1)).astype(np.uint32),
        "robot": (np.arange(samples) % 3).astype(np.uint8),
    }


def write_dataset(
    directory: Path,
    samples: int = 96,
    size_px: int = 50,
    shard_size: int = 40,
    seed: int = 0,
    v_train: float = 0.7,
    iteration: int = 0,
    noise_std: float = 0.0,
    d_star_ref_m: float | None = None,
    ranges: str | None = None,
    neighbours: str | None = None,
    labels: dict | None = None,
) -> Path:
    """Writes a dataset of ``samples`` synthetic samples in shards of ``shard_size``; ``ranges``
    (``"sectors=K,clip=C"``) makes it a version 2 dataset whose shards hold ``ranges`` [N, K];
    ``neighbours`` (``"slots=K,threshold=T,nearest=M"``) a version 3 dataset (with or without
    ranges) whose shards hold ``neighbours`` [N, K, 4] and whose wheel labels follow the teacher's
    law on them; ``labels`` is the manifest's label law."""
    directory.mkdir(parents=True)
    sectors, clip = 0, 3.0
    if ranges is not None:
        fields = dict(part.split("=") for part in ranges.split(","))
        sectors, clip = int(fields["sectors"]), float(fields["clip"])
    slots, hidden = 0, False
    if neighbours is not None:
        fields = {k.strip(): v for k, v in (part.split("=") for part in neighbours.split(","))}
        slots, hidden = int(fields["slots"]), fields.get("hidden") == "1"
    version = 3 if neighbours is not None else 2 if ranges is not None else 1
    arrays = synthetic_arrays(
        samples, size_px, seed, iteration=iteration, sectors=sectors, clip=clip, slots=slots, v_train=v_train,
        hidden=hidden,
    )
    shards = []
    for index, start in enumerate(range(0, samples, shard_size)):
        part = {k: np.ascontiguousarray(v[start : start + shard_size]) for k, v in arrays.items()}
        n = len(part["robot"])
        name = f"shard-{index:06d}.safetensors"
        meta = {"format": "formation-dataset", "version": str(version), "iteration": str(iteration), "samples": str(n)}
        save_file(part, str(directory / name), metadata=meta)
        shards.append({"file": name, "samples": n, "iteration": iteration, "checksum": "0" * 16})
    manifest = {
        "format": "formation-dataset",
        "version": version,
        "dataset_id": f"synthetic{seed:07d}",
        "occupancy": {"size_px": size_px, "resolution_m": 0.1, "beyond": "drop"}
        | ({} if d_star_ref_m is None else {"d_star_ref_m": d_star_ref_m}),
        "lidar": {"beams": 900, "max_range": 10.0, "noise_std": noise_std},
        "v_train": v_train,
        "seed": seed,
        "scenario": "synthetic",
        "shards": shards,
        "samples": samples,
    } | ({} if ranges is None else {"ranges": ranges}) | ({} if neighbours is None else {"neighbours": neighbours}) | (
        {} if labels is None else {"labels": labels}
    )
    (directory / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return directory


@pytest.fixture
def make_dataset(tmp_path):
    """``make_dataset(name, **kwargs)`` writes a synthetic dataset under the test's temp dir."""
    return lambda name="data", **kwargs: write_dataset(tmp_path / name, **kwargs)
