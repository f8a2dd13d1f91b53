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


def synthetic_arrays(
    samples: int, size_px: int = 50, seed: int = 0, runs: int = 8, iteration: int = 0, sectors: int = 0, clip: float = 3.0
):
    """Random sparse images and labels that depend on them (so a model can learn something); with
    ``sectors``, also ranges in [0, clip] that the labels depend on."""
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
) -> Path:
    """Writes a dataset of ``samples`` synthetic samples in shards of ``shard_size``; ``ranges``
    (``"sectors=K,clip=C"``) makes it a version 2 dataset whose shards hold ``ranges`` [N, K]."""
    directory.mkdir(parents=True)
    sectors, clip = 0, 3.0
    if ranges is not None:
        fields = dict(part.split("=") for part in ranges.split(","))
        sectors, clip = int(fields["sectors"]), float(fields["clip"])
    version = 2 if ranges is not None else 1
    arrays = synthetic_arrays(samples, size_px, seed, iteration=iteration, sectors=sectors, clip=clip)
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
    } | ({} if ranges is None else {"ranges": ranges})
    (directory / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return directory


@pytest.fixture
def make_dataset(tmp_path):
    """``make_dataset(name, **kwargs)`` writes a synthetic dataset under the test's temp dir."""
    return lambda name="data", **kwargs: write_dataset(tmp_path / name, **kwargs)
