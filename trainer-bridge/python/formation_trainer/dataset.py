"""Reads datasets written by the Rust ``trainer_bridge::dataset`` module, with numpy and safetensors only.

A dataset is a directory with ``manifest.json`` and ``shard-NNNNNN.safetensors`` files (see
``trainer-bridge/src/dataset.rs`` for the format). Every problem found (missing or truncated shard,
unknown version, shapes that disagree with the manifest, datasets that cannot be mixed) raises
:class:`DatasetError` naming the file and the fix.

Format version 1 holds no ranges; version 2 declares the scan's ranges in the manifest
(``"ranges": "sectors=K,clip=C"``, :class:`RangeInput`) and each shard holds ``ranges`` f32
``[N, K]`` beside the image. Version 3 declares the neighbours each robot detects in its own scan
(``"neighbours": "slots=K,threshold=T,nearest=M"``, :class:`NeighbourInput`), with or without
ranges, and each shard holds ``neighbours`` f32 ``[N, K, 4]``: per slot ``(x / d*, y / d*, held,
present)``, held slots first, nearest first, empty slots all zero. Every version is read;
:attr:`Samples.ranges` is ``[N, 0]`` without ranges and :attr:`Samples.neighbours` ``[N, 0, 4]``
without neighbours.
"""

from __future__ import annotations

import json
import struct
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from safetensors.numpy import load_file

FORMAT = "formation-dataset"
#: The layout version of a dataset whose samples carry their scan's ranges (and no neighbours).
VERSION = 2
#: The layout of a dataset without ranges (every dataset written before ranges).
VERSION_WITHOUT_RANGES = 1
#: The newest layout version: a dataset whose samples carry the neighbours each robot detects in
#: its own scan (with or without ranges).
VERSION_WITH_NEIGHBOURS = 3
VERSIONS = (VERSION_WITHOUT_RANGES, VERSION, VERSION_WITH_NEIGHBOURS)
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


#: The bounds of ``formation_proto::RangeInput``.
MIN_SECTORS, MAX_SECTORS, MAX_CLIP = 4, 360, 100.0


def f32_text(value: float) -> str:
    """``value`` as an ``f32`` and written as Rust's ``Display`` writes one: the shortest decimal
    that reads back to the same ``f32``, no exponent, no ``.0`` (``3``, ``2.5``, ``0.1``)."""
    return np.format_float_positional(np.float32(value), unique=True, trim="-")


@dataclass(frozen=True)
class RangeInput:
    """The scan's ranges a model takes beside its image (``formation_proto::RangeInput``): ``sectors``
    values, each the mean of ``range / d*`` over its sector's returning beams, at most ``clip``."""

    sectors: int
    clip: float

    def __post_init__(self):
        if not MIN_SECTORS <= self.sectors <= MAX_SECTORS:
            raise ValueError(f"range input sectors = {self.sectors} is out of range: {MIN_SECTORS} to {MAX_SECTORS}")
        if not 0.0 < float(np.float32(self.clip)) <= MAX_CLIP:
            raise ValueError(f"range input clip = {self.clip} is out of range: above 0 and at most {MAX_CLIP:g}")
        object.__setattr__(self, "clip", float(np.float32(self.clip)))

    @staticmethod
    def parse(text: str) -> "RangeInput":
        """Reads ``sectors=K,clip=C`` (either order, spaces allowed), as ``RangeInput::parse``."""
        values = {}
        for part in str(text).split(","):
            key, sep, value = part.partition("=")
            key, value = key.strip(), value.strip()
            if not sep or key not in ("sectors", "clip") or key in values:
                raise ValueError(f"{text!r} is not a range input: write \"sectors=K,clip=C\"")
            values[key] = value
        if set(values) != {"sectors", "clip"} or not re.fullmatch(r"\+?[0-9]+", values["sectors"]):
            raise ValueError(f"{text!r} is not a range input: write \"sectors=K,clip=C\"")
        try:
            clip = float(values["clip"])
        except ValueError:
            raise ValueError(f"{text!r} is not a range input: write \"sectors=K,clip=C\"") from None
        return RangeInput(int(values["sectors"]), clip)

    def text(self) -> str:
        """``sectors=K,clip=C``, exactly as ``RangeInput``'s ``Display`` writes it."""
        return f"sectors={self.sectors},clip={f32_text(self.clip)}"

    def __str__(self) -> str:
        return self.text()

    def mirrored(self) -> list[int]:
        """The sector each sector maps to under reflection about the heading axis: ``(K - s) % K``."""
        return [(self.sectors - s) % self.sectors for s in range(self.sectors)]


#: The bounds of ``formation_proto::NeighbourInput``.
MIN_SLOTS, MAX_SLOTS, MAX_THRESHOLD, MAX_NEAREST = 1, 64, 4.0, 8
#: Numbers per neighbour slot: ``x / d*``, ``y / d*``, ``held``, ``present``.
NEIGHBOUR_FEATURES = 4
#: Numbers per neighbour slot with ``hidden=1``: then also ``hx``, ``hy``, the step aside of the
#: hidden pairs the slot is an end of.
HIDDEN_NEIGHBOUR_FEATURES = 6
_NEIGHBOUR_SYNTAX = 'write "slots=K,threshold=T,nearest=M", and ",hidden=1" for the step aside of hidden pairs'


def f64_text(value: float) -> str:
    """``value`` written as Rust's ``Display`` writes an ``f64``: the shortest decimal that reads
    back to the same number, no exponent, no ``.0`` (``1``, ``1.3``)."""
    return np.format_float_positional(np.float64(value), unique=True, trim="-")


@dataclass(frozen=True)
class NeighbourInput:
    """The neighbours a robot detects in its own scan, as a model takes them beside its image
    (``formation_proto::NeighbourInput``): ``slots`` slots of ``(x / d*, y / d*, held, present)``,
    ``held`` by the Gabriel rule at witness ratio ``threshold`` plus the ``nearest`` nearest; with
    ``hidden`` two more a slot, ``(hx, hy)``, the step aside of the pairs the robot hides."""

    slots: int
    threshold: float
    nearest: int
    hidden: bool = False

    @property
    def features(self) -> int:
        """Numbers per slot: 6 with ``hidden``, else 4."""
        return HIDDEN_NEIGHBOUR_FEATURES if self.hidden else NEIGHBOUR_FEATURES

    def __post_init__(self):
        if not MIN_SLOTS <= self.slots <= MAX_SLOTS:
            raise ValueError(f"neighbour input slots = {self.slots} is out of range: {MIN_SLOTS} to {MAX_SLOTS}")
        if not 1.0 <= float(self.threshold) <= MAX_THRESHOLD:
            raise ValueError(f"neighbour input threshold = {self.threshold} is out of range: 1 to {MAX_THRESHOLD:g}")
        if not 0 <= self.nearest <= MAX_NEAREST:
            raise ValueError(f"neighbour input nearest = {self.nearest} is out of range: 0 to {MAX_NEAREST}")
        object.__setattr__(self, "threshold", float(self.threshold))

    @staticmethod
    def parse(text: str) -> "NeighbourInput":
        """Reads ``slots=K,threshold=T,nearest=M``, optionally ``,hidden=0|1`` (any order, spaces
        around the keys and values allowed), as ``NeighbourInput::parse``."""
        values = {}
        for part in str(text).split(","):
            key, sep, value = part.partition("=")
            key, value = key.strip(), value.strip()
            if not sep or key not in ("slots", "threshold", "nearest", "hidden") or key in values:
                raise ValueError(f"{text!r} is not a neighbour input: {_NEIGHBOUR_SYNTAX}")
            values[key] = value
        integer = re.compile(r"\+?[0-9]+")
        hidden = values.pop("hidden", "0")
        if (
            hidden not in ("0", "1")
            or set(values) != {"slots", "threshold", "nearest"}
            or not integer.fullmatch(values["slots"])
            or not integer.fullmatch(values["nearest"])
        ):
            raise ValueError(f"{text!r} is not a neighbour input: {_NEIGHBOUR_SYNTAX}")
        try:
            threshold = float(values["threshold"])
        except ValueError:
            raise ValueError(f"{text!r} is not a neighbour input: {_NEIGHBOUR_SYNTAX}") from None
        return NeighbourInput(int(values["slots"]), threshold, int(values["nearest"]), hidden == "1")

    def text(self) -> str:
        """``slots=K,threshold=T,nearest=M[,hidden=1]``, exactly as ``NeighbourInput``'s
        ``Display`` writes it."""
        text = f"slots={self.slots},threshold={f64_text(self.threshold)},nearest={self.nearest}"
        return text + ",hidden=1" if self.hidden else text

    def __str__(self) -> str:
        return self.text()


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
    version: int = VERSION_WITHOUT_RANGES
    ranges: RangeInput | None = None
    #: The neighbours each sample carries (version 3), or None.
    neighbours: NeighbourInput | None = None
    #: The law that labelled the samples (``--label-wheel-accel``, ``--unshaped-labels``,
    #: ``--label-pair-band``, ``--own-scan-labels``: ``"own_scan": true``), ``{}`` for the
    #: expert's default (no ``labels`` key). Read as it is: any key is kept and compared.
    labels: dict = field(default_factory=dict)

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
    if str(version) not in {str(v) for v in VERSIONS}:
        raise DatasetError(
            f"{path} has dataset format version {version}, but this trainer reads versions "
            f"{', '.join(str(v) for v in VERSIONS[:-1])} and {VERSIONS[-1]}: "
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
    version = int(raw["version"])
    ranges = _declared_input(path, raw, "ranges", RangeInput.parse)
    neighbours = _declared_input(path, raw, "neighbours", NeighbourInput.parse)
    if (neighbours is not None) != (version == VERSION_WITH_NEIGHBOURS):
        declared = f'declares neighbours "{neighbours}"' if neighbours is not None else "declares no `neighbours`"
        raise DatasetError(
            f"{path} is dataset format version {version} but {declared}: versions {VERSION_WITHOUT_RANGES} and "
            f"{VERSION} hold no neighbours and version {VERSION_WITH_NEIGHBOURS} declares them; the manifest was "
            "edited or damaged: restore it, or re-run `formation collect`"
        )
    if neighbours is None and (ranges is not None) != (version == VERSION):
        declared = f'declares ranges "{ranges}"' if ranges is not None else "declares no `ranges`"
        raise DatasetError(
            f"{path} is dataset format version {version} but {declared}: version {VERSION_WITHOUT_RANGES} "
            f"holds no ranges and version {VERSION} declares them; the manifest was edited or damaged: "
            "restore it, or re-run `formation collect`"
        )
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
            version=version,
            ranges=ranges,
            neighbours=neighbours,
            labels=dict(raw.get("labels") or {}),
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


def _declared_input(path: Path, raw: dict, key: str, parse):
    """The model input the manifest at ``path`` declares under ``key`` (``ranges``,
    ``neighbours``), read by ``parse``, or None where it declares none."""
    if raw.get(key) is None:
        return None
    try:
        return parse(raw[key])
    except ValueError as e:
        raise DatasetError(f"{path} is not a valid dataset manifest (its `{key}`: {e}): {RECOLLECT}") from e


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


def _tensors(sectors: int, neighbours: "NeighbourInput | None" = None) -> dict:
    """The shard tensors of a dataset whose ranges have ``sectors`` sectors (0: none) and which
    declares ``neighbours`` (None: none)."""
    tensors = dict(_TENSORS)
    if sectors:
        tensors["ranges"] = (np.float32, lambda s: (sectors,))
    if neighbours is not None:
        tensors["neighbours"] = (np.float32, lambda s: (neighbours.slots, neighbours.features))
    return tensors


def check_shard(manifest: Manifest, entry: dict) -> Path:
    """Validates the header of the shard of ``entry`` in ``manifest`` against the two without
    reading the samples: its version (the manifest's) and its tensors, ``ranges`` iff the manifest
    declares them and ``neighbours`` iff it declares them. Returns the shard's path."""
    path = manifest.directory / entry["file"]
    size_px, ranges, version, neighbours = manifest.size_px, manifest.ranges, manifest.version, manifest.neighbours
    header, _ = _read_shard_header(path)
    meta = header.get("__metadata__") or {}
    _check_format_and_version(path, meta.get("format"), meta.get("version"))
    if str(meta.get("version")) != str(version):
        raise DatasetError(
            f"{path} is corrupt (its version {meta.get('version')} differs from the manifest's {version}): {RECOLLECT}"
        )
    if ranges is None and "ranges" in header:
        raise DatasetError(f"{path} is corrupt (a `ranges` tensor, but the manifest declares no ranges): {RECOLLECT}")
    if neighbours is None and "neighbours" in header:
        raise DatasetError(
            f"{path} is corrupt (a `neighbours` tensor, but the manifest declares no neighbours): {RECOLLECT}"
        )
    n = entry["samples"]
    for name, (dtype, tail) in _tensors(ranges.sectors if ranges else 0, neighbours).items():
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
    return path


def load_shard(manifest: Manifest, entry: dict) -> dict[str, np.ndarray]:
    """Validates (``check_shard``) and loads the tensors of the shard of ``entry`` in ``manifest``."""
    path = check_shard(manifest, entry)
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
    ranges: np.ndarray | None = None  # float32 [N, K]; [N, 0] without ranges
    neighbours: np.ndarray | None = None  # float32 [N, K, 4 or 6]; [N, 0, 4] without neighbours

    def __post_init__(self):
        if self.ranges is None:
            self.ranges = np.zeros((len(self), 0), dtype=np.float32)
        if self.neighbours is None:
            self.neighbours = np.zeros((len(self), 0, NEIGHBOUR_FEATURES), dtype=np.float32)

    def __len__(self) -> int:
        return int(self.robot.shape[0])

    @property
    def size_px(self) -> int:
        return self.manifests[0].size_px

    @property
    def range_input(self) -> RangeInput | None:
        """The ranges every sample carries (shared by every dataset), or None."""
        return self.manifests[0].ranges

    @property
    def neighbour_input(self) -> NeighbourInput | None:
        """The neighbours every sample carries (shared by every dataset), or None."""
        return self.manifests[0].neighbours

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
        ("range input", first.ranges, other.ranges),
        ("neighbour input", first.neighbours, other.neighbours),
        ("label law", first.labels or "the expert's default", other.labels or "the expert's default"),
    ):
        if a != b:
            raise DatasetError(
                f"datasets {first.directory} and {other.directory} cannot be trained together: "
                f"their {name} differ ({a} vs {b}); train on datasets collected with the same settings"
                + (" (the same `formation collect` range input)" if name == "range input" else "")
                + (" (the same `formation collect --neighbours` input)" if name == "neighbour input" else "")
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
            check_shard(m, entry)
    size_px = manifests[0].size_px
    first = manifests[0]
    tensors_of = _tensors(first.ranges.sectors if first.ranges else 0, first.neighbours)
    arrays = {name: np.empty((total, *tail(size_px)), dtype) for name, (dtype, tail) in tensors_of.items()}
    source = np.empty(total, dtype=np.int32)
    start = 0
    for index, m in enumerate(manifests):
        for entry in m.shards:
            tensors = load_shard(m, entry)
            end = start + entry["samples"]
            for name in tensors_of:
                arrays[name][start:end] = tensors[name]
            source[start:end] = index
            del tensors
            start = end
    return Samples(source=source, manifests=manifests, **arrays)
