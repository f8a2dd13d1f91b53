"""Reads datasets written by the Rust ``trainer_bridge::dataset`` module, with numpy and safetensors only.

A dataset is a directory with ``manifest.json`` and ``shard-NNNNNN.safetensors`` files (see
``trainer-bridge/src/dataset.rs`` for the format). Every problem found (missing or truncated shard,
unknown version, shapes that disagree with the manifest, datasets that cannot be mixed) raises
:class:`DatasetError` naming the file and the fix.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from safetensors.numpy import load_file

FORMAT = "formation-dataset"
VERSION = 1
MANIFEST = "manifest.json"
RECOLLECT = "delete the dataset and re-run `formation collect`"

#: (dtype, shape after the sample axis, given size_px) of every shard tensor.
_TENSORS = {
    "occupancy": (np.uint8, lambda s: (s, s)),
    "aux": (np.float32, lambda s: (2,)),
    "wheels": (np.float32, lambda s: (2,)),
    "iteration": (np.uint32, lambda s: ()),
    "run": (np.uint32, lambda s: ()),
    "robot": (np.uint8, lambda s: ()),
}
_SAFETENSORS_DTYPES = {"U8": np.uint8, "F32": np.float32, "U32": np.uint32}
_BYTES_PER_ELEMENT = {"U8": 1, "F32": 4, "U32": 4}


class DatasetError(Exception):
    """A dataset is missing, damaged, of another version, or cannot be combined with another."""


@dataclass(frozen=True)
class Manifest:
    """A validated ``manifest.json``."""

    directory: Path
    dataset_id: str
    occupancy: dict
    lidar: dict
    v_train: float
    seed: int
    scenario: str
    shards: list = field(default_factory=list)
    samples: int = 0

    @property
    def size_px(self) -> int:
        return int(self.occupancy["size_px"])

    def iterations(self) -> list[int]:
        return sorted({int(s["iteration"]) for s in self.shards})


def _check_format_and_version(path: Path, fmt, version) -> None:
    if fmt != FORMAT:
        raise DatasetError(
            f"{path} has format {fmt!r}, expected {FORMAT!r}: point at a dataset written by `formation collect`"
        )
    if str(version) != str(VERSION):
        raise DatasetError(
            f"{path} has dataset format version {version}, but this trainer reads version {VERSION}: "
            "re-run `formation collect` with this build (or use the formation build that wrote it)"
        )


def read_manifest(directory: str | Path) -> Manifest:
    """Reads and validates ``<directory>/manifest.json`` (format, version, totals, file names)."""
    directory = Path(directory)
    path = directory / MANIFEST
    if not path.is_file():
        raise DatasetError(
            f"{directory} is not a formation dataset (no {MANIFEST}): create one with `formation collect`"
        )
    try:
        raw = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path} is not a valid dataset manifest ({e}): {RECOLLECT}") from e
    if not isinstance(raw, dict):
        raise DatasetError(f"{path} is not a valid dataset manifest (not a JSON object): {RECOLLECT}")
    _check_format_and_version(path, raw.get("format"), raw.get("version"))
    try:
        manifest = Manifest(
            directory=directory,
            dataset_id=str(raw["dataset_id"]),
            occupancy=_occupancy(raw["occupancy"]),
            lidar={k: raw["lidar"][k] for k in ("beams", "max_range", "noise_std")},
            v_train=float(raw["v_train"]),
            seed=int(raw["seed"]),
            scenario=str(raw["scenario"]),
            shards=[
                {"file": str(s["file"]), "samples": int(s["samples"]), "iteration": int(s["iteration"])}
                for s in raw["shards"]
            ],
            samples=int(raw["samples"]),
        )
    except (KeyError, TypeError, ValueError) as e:
        raise DatasetError(f"{path} is not a valid dataset manifest (bad or missing field {e}): {RECOLLECT}") from e
    total = sum(s["samples"] for s in manifest.shards)
    if total != manifest.samples:
        raise DatasetError(f"{path}: `samples` is {manifest.samples} but the shards hold {total}: {RECOLLECT}")
    for s in manifest.shards:
        name = s["file"]
        digits = name.removeprefix("shard-").removesuffix(".safetensors")
        if not (name.startswith("shard-") and name.endswith(".safetensors") and digits.isdigit()):
            raise DatasetError(f"{path}: shard file name {name!r} is not shard-NNNNNN.safetensors: {RECOLLECT}")
    return manifest


def _read_shard_header(path: Path) -> tuple[dict, int]:
    """The safetensors header of ``path`` and the byte count it describes; checks truncation."""
    if not path.is_file():
        raise DatasetError(f"{path} is listed in the manifest but missing: {RECOLLECT}")
    size = path.stat().st_size
    with path.open("rb") as f:
        prefix = f.read(8)
        if len(prefix) < 8:
            raise DatasetError(f"{path} is truncated ({size} bytes, its header needs 8): {RECOLLECT}")
        (header_len,) = struct.unpack("<Q", prefix)
        if header_len > 100_000_000:
            raise DatasetError(f"{path} is corrupt (header length {header_len} is implausible): {RECOLLECT}")
        if size < 8 + header_len:
            raise DatasetError(f"{path} is truncated ({size} bytes, its header needs {8 + header_len}): {RECOLLECT}")
        try:
            header = json.loads(f.read(header_len))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise DatasetError(f"{path} is corrupt (unreadable safetensors header: {e}): {RECOLLECT}") from e
    data_end = max((t["data_offsets"][1] for k, t in header.items() if k != "__metadata__"), default=0)
    expected = 8 + header_len + data_end
    if size < expected:
        raise DatasetError(f"{path} is truncated ({size} bytes, its header needs {expected}): {RECOLLECT}")
    if size > expected:
        raise DatasetError(f"{path} is corrupt ({size} bytes, but its header describes {expected}): {RECOLLECT}")
    return header, expected


def check_shard(path: Path, entry: dict, size_px: int) -> None:
    """Validates one shard's header against its manifest entry without reading the samples."""
    header, _ = _read_shard_header(path)
    meta = header.get("__metadata__") or {}
    _check_format_and_version(path, meta.get("format"), meta.get("version"))
    n = entry["samples"]
    for name, (dtype, tail) in _TENSORS.items():
        info = header.get(name)
        if info is None:
            raise DatasetError(f"{path} is corrupt (no `{name}` tensor): {RECOLLECT}")
        shape = (n, *tail(size_px))
        if _SAFETENSORS_DTYPES.get(info["dtype"]) is not dtype or tuple(info["shape"]) != shape:
            raise DatasetError(
                f"{path} is corrupt (`{name}` is {info['dtype']} {info['shape']}, "
                f"the manifest needs {np.dtype(dtype).name} {list(shape)}): {RECOLLECT}"
            )
    if str(meta.get("iteration")) != str(entry["iteration"]):
        raise DatasetError(
            f"{path} is corrupt (its iteration {meta.get('iteration')} differs from the manifest's "
            f"{entry['iteration']}): {RECOLLECT}"
        )


def load_shard(path: Path, entry: dict, size_px: int) -> dict[str, np.ndarray]:
    """Validates and loads one shard's tensors."""
    check_shard(path, entry, size_px)
    try:
        return load_file(str(path))
    except Exception as e:  # safetensors raises its own error types
        raise DatasetError(f"{path} is corrupt ({e}): {RECOLLECT}") from e


@dataclass
class Samples:
    """All samples of one or more compatible datasets, as numpy arrays."""

    occupancy: np.ndarray  # uint8 [N, S, S]
    aux: np.ndarray  # float32 [N, 2]: delta_phi, d*
    wheels: np.ndarray  # float32 [N, 2]: left, right
    iteration: np.ndarray  # uint32 [N]
    run: np.ndarray  # uint32 [N]
    robot: np.ndarray  # uint8 [N]
    source: np.ndarray  # int32 [N]: index into `manifests`
    manifests: list

    def __len__(self) -> int:
        return int(self.robot.shape[0])

    @property
    def size_px(self) -> int:
        return self.manifests[0].size_px

    @property
    def lidar(self) -> dict:
        """The LIDAR of the data: beams and range (shared by every dataset) and the largest range
        noise of any dataset (a model trained on several noise levels is trained up to it)."""
        lidar = dict(self.manifests[0].lidar)
        lidar["noise_std"] = max(float(m.lidar["noise_std"]) for m in self.manifests)
        return lidar

    @property
    def dataset_id(self) -> str:
        return "+".join(m.dataset_id for m in self.manifests)

    @property
    def max_iteration(self) -> int:
        return int(self.iteration.max()) if len(self) else 0

    def episode_keys(self) -> np.ndarray:
        """One int64 per sample identifying its (dataset, iteration, run): correlated samples share it."""
        return (
            self.source.astype(np.int64) << 48
            | self.iteration.astype(np.int64) << 32
            | self.run.astype(np.int64)
        )


def _occupancy(raw: dict) -> dict:
    """The occupancy settings of a manifest: the window, and ``d_star_ref_m`` only for a window
    that scales with d* (cells ``resolution_m * d* / d_star_ref_m`` wide)."""
    occupancy = {k: raw[k] for k in ("size_px", "resolution_m", "beyond")}
    if raw.get("d_star_ref_m") is not None:
        occupancy["d_star_ref_m"] = float(raw["d_star_ref_m"])
    return occupancy


def _sensor(lidar: dict) -> dict:
    """What a model's sensor contract holds of a LIDAR: its beams and range, not its noise
    (data of several noise levels train one model)."""
    return {k: v for k, v in lidar.items() if k != "noise_std"}


def _check_compatible(first: Manifest, other: Manifest) -> None:
    for name, a, b in (
        ("occupancy", first.occupancy, other.occupancy),
        ("lidar", _sensor(first.lidar), _sensor(other.lidar)),
        ("v_train", first.v_train, other.v_train),
    ):
        if a != b:
            raise DatasetError(
                f"datasets {first.directory} and {other.directory} cannot be trained together: "
                f"their {name} differ ({a} vs {b}); train on datasets collected with the same settings"
            )


def load(directories) -> Samples:
    """Loads every shard of every dataset in ``directories`` (which must share their settings)."""
    directories = [Path(d) for d in directories]
    if not directories:
        raise DatasetError("no dataset given: pass at least one --data directory")
    manifests = [read_manifest(d) for d in directories]
    for m in manifests[1:]:
        _check_compatible(manifests[0], m)
    total = sum(m.samples for m in manifests)
    if total == 0:
        names = ", ".join(str(d) for d in directories)
        raise DatasetError(f"{names} holds no samples: collect some with `formation collect`")
    # Every shard is checked before anything is allocated, and each one is copied into arrays
    # sized once for all of them: memory peaks at the samples plus one shard, not twice the
    # samples, so a dataset of more than half the machine's memory still loads.
    for m in manifests:
        for entry in m.shards:
            check_shard(m.directory / entry["file"], entry, m.size_px)
    size_px = manifests[0].size_px
    arrays = {name: np.empty((total, *tail(size_px)), dtype) for name, (dtype, tail) in _TENSORS.items()}
    source = np.empty(total, dtype=np.int32)
    start = 0
    for index, m in enumerate(manifests):
        for entry in m.shards:
            tensors = load_shard(m.directory / entry["file"], entry, m.size_px)
            end = start + entry["samples"]
            for name in _TENSORS:
                arrays[name][start:end] = tensors[name]
            source[start:end] = index
            del tensors
            start = end
    return Samples(source=source, manifests=manifests, **arrays)
