"""ONNX export with the formation model contract, and the torch/onnxruntime parity check.

The exported graph has inputs ``occupancy`` f32 [B, 1, S, S] and ``aux`` f32 [B, 2], and for a model
with ranges a third, ``ranges`` f32 [B, K], declared by ``formation.ranges = "sectors=K,clip=C"``
(the text of ``formation_proto::RangeInput``'s ``Display``); a pair network
(:class:`~formation_trainer.model.PairNet`) has, beside the first two, ``neighbours`` f32
[B, K, 4] ([B, K, 6] with ``,hidden=1``), declared by ``formation.neighbours =
"slots=K,threshold=T,nearest=M"`` (the text of
``formation_proto::NeighbourInput``'s ``Display``, as the dataset declared it) and answers a
``formation_velocity``; one output f32 [B, 2] named as the
model's ``formation.output`` metadata declares it (``wheels``, the default, or
``formation_velocity``), with a dynamic batch B; and it carries ``formation.*`` metadata_props
(all strings) that the Rust ``formation_onnx`` crate validates against the agent's sensor. After
export the same held-out inputs are run through torch and onnxruntime; a difference above
:data:`PARITY_TOLERANCE` fails the export.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import sys
import warnings
from pathlib import Path

import numpy as np
import torch

from . import CREATED_BY
from .dataset import NeighbourInput, RangeInput
from .model import AUX_NAMES, PairNet, PolicyNet

MODEL_FORMAT = "formation-policy/1"
INPUT_NAMES = ("occupancy", "aux")
#: The inputs of a model with ranges.
RANGE_INPUT_NAMES = ("occupancy", "aux", "ranges")
#: The metadata key declaring the range input.
RANGES_KEY = "formation.ranges"
#: The inputs of a model that takes the detected neighbours.
NEIGHBOUR_INPUT_NAMES = ("occupancy", "aux", "neighbours")
#: The metadata key declaring the neighbour input.
NEIGHBOURS_KEY = "formation.neighbours"
#: The scalars of the ``aux`` input, in order (``formation.aux``): what the dataset stores.
AUX_LAYOUT = ",".join(AUX_NAMES)
OUTPUT_NAME = "wheels"
#: The outputs a model may declare (``formation.output``), each also its tensor's name.
OUTPUT_NAMES = ("wheels", "formation_velocity")
OPSET = 20
PARITY_TOLERANCE = 1e-4


class ParityError(Exception):
    """onnxruntime and torch disagree on the exported model."""


def number_text(value: float) -> str:
    """A metadata number: integral values without a fraction ("50", "10"), others as Python repr ("0.1")."""
    value = float(value)
    if not math.isfinite(value):
        return repr(value)
    return str(int(value)) if value.is_integer() else repr(value)


def model_metadata(
    *,
    occupancy: dict,
    lidar: dict,
    v_train: float,
    dataset_id: str,
    epochs: int,
    final_train_loss: float,
    final_val_loss: float,
    samples: int,
    dagger_iteration: int,
    extra: dict | None = None,
    ranges: RangeInput | None = None,
    neighbours: NeighbourInput | None = None,
) -> dict[str, str]:
    """The ``formation.*`` metadata_props of a model (all values strings); ``ranges``, the data's
    range input, becomes ``formation.ranges``, and ``neighbours``, the data's neighbour input,
    ``formation.neighbours``."""
    meta = {
        "formation.format": MODEL_FORMAT,
        "formation.occupancy.size_px": str(int(occupancy["size_px"])),
        "formation.occupancy.resolution_m": number_text(occupancy["resolution_m"]),
        "formation.occupancy.beyond": str(occupancy["beyond"]),
        "formation.input": "occupancy",
        # The scalars beside the image, by name and in order (formation_proto::AuxLayout).
        "formation.aux": AUX_LAYOUT,
        "formation.lidar.beams": str(int(lidar["beams"])),
        "formation.lidar.max_range": number_text(lidar["max_range"]),
        "formation.lidar.noise_std": number_text(lidar["noise_std"]),
        "formation.v_train": number_text(v_train),
        "formation.dataset_id": dataset_id,
        "formation.train.epochs": str(int(epochs)),
        "formation.train.final_train_loss": repr(float(final_train_loss)),
        "formation.train.final_val_loss": repr(float(final_val_loss)),
        "formation.train.samples": str(int(samples)),
        "formation.dagger.iteration": str(int(dagger_iteration)),
        "formation.created_by": CREATED_BY,
    }
    if occupancy.get("d_star_ref_m") is not None:
        meta["formation.occupancy.d_star_ref_m"] = number_text(occupancy["d_star_ref_m"])
    if ranges is not None:
        meta[RANGES_KEY] = ranges.text()
    if neighbours is not None:
        meta[NEIGHBOURS_KEY] = neighbours.text()
    for key, value in (extra or {}).items():
        meta.setdefault(f"formation.{key}", str(value))
    return meta


@contextlib.contextmanager
def _quiet_exporter():
    """Keeps the exporter's chatter off stdout (which carries the trainer's progress lines)."""
    with contextlib.redirect_stdout(sys.stderr), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        previous = logging.getLogger("torch").level
        logging.getLogger("torch").setLevel(logging.ERROR)
        try:
            yield
        finally:
            logging.getLogger("torch").setLevel(previous)


def declared_ranges(metadata: dict[str, str]) -> RangeInput | None:
    """The range input ``formation.ranges`` declares, or None."""
    text = metadata.get(RANGES_KEY)
    return None if text is None else RangeInput.parse(text)


def declared_neighbours(metadata: dict[str, str]) -> NeighbourInput | None:
    """The neighbour input ``formation.neighbours`` declares, or None."""
    text = metadata.get(NEIGHBOURS_KEY)
    return None if text is None else NeighbourInput.parse(text)


def export_onnx(model: PolicyNet | PairNet, path: str | Path, metadata: dict[str, str], output: str = OUTPUT_NAME) -> None:
    """Exports ``model`` (on CPU, eval mode) to ``path`` atomically, with ``metadata`` as metadata_props
    and its one output named ``output`` (which a model other than ``wheels`` declares in
    ``formation.output``). A model with ranges has the third input ``ranges`` [B, K], which
    ``metadata`` must declare with K sectors; a pair network the third input ``neighbours``
    [B, K, 4] ([B, K, 6] with ``hidden=1``), which ``metadata`` must declare alike. The image stays an input of a pair
    network, which does not use it (the graph keeps it)."""
    if output not in OUTPUT_NAMES:
        raise ValueError(f"output must be one of {OUTPUT_NAMES}, got {output!r}")
    if metadata.get("formation.output", OUTPUT_NAME) != output:
        raise ValueError(f"metadata declares formation.output = {metadata.get('formation.output')!r}, the graph {output!r}")
    ranges = declared_ranges(metadata)
    if (ranges.sectors if ranges else None) != model.range_sectors:
        raise ValueError(
            f"metadata declares {RANGES_KEY} = {metadata.get(RANGES_KEY)!r}, "
            f"the network takes {model.range_sectors or 'no'} range sectors"
        )
    neighbours = declared_neighbours(metadata)
    declared = (neighbours.slots, neighbours.features) if neighbours else None
    taken = (model.neighbour_slots, model.neighbour_features) if model.neighbour_slots else None
    if declared != taken:
        raise ValueError(
            f"metadata declares {NEIGHBOURS_KEY} = {metadata.get(NEIGHBOURS_KEY)!r}, "
            f"the network takes {f'{taken[0]} neighbour slots of {taken[1]} values' if taken else 'no neighbours'}"
        )
    if ranges and neighbours:
        raise ValueError("no network of this trainer takes both ranges and neighbours")
    input_names = NEIGHBOUR_INPUT_NAMES if neighbours else RANGE_INPUT_NAMES if ranges else INPUT_NAMES
    import onnx

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    model = model.to("cpu").eval()
    size = model.size_px
    example = (torch.zeros(2, 1, size, size), torch.zeros(2, 2))
    batch = torch.export.Dim("batch")
    dynamic = {"occupancy": {0: batch}, "aux": {0: batch}}
    if ranges:
        example = (*example, torch.zeros(2, ranges.sectors))
        dynamic["ranges"] = {0: batch}
    if neighbours:
        example = (*example, torch.zeros(2, neighbours.slots, neighbours.features))
        dynamic["neighbours"] = {0: batch}
    try:
        with _quiet_exporter():
            torch.onnx.export(
                model,
                example,
                str(temp),
                input_names=list(input_names),
                output_names=[output],
                dynamic_shapes=dynamic,
                opset_version=OPSET,
                dynamo=True,
                external_data=False,
            )
        proto = onnx.load(str(temp))
        names = ([i.name for i in proto.graph.input], [o.name for o in proto.graph.output])
        if names != (list(input_names), [output]):
            raise RuntimeError(f"the exporter produced inputs/outputs {names}, expected {input_names} -> {output}")
        del proto.metadata_props[:]
        for key, value in sorted(metadata.items()):
            entry = proto.metadata_props.add()
            entry.key, entry.value = key, value
        onnx.checker.check_model(proto)
        onnx.save(proto, str(temp))
        os.replace(temp, path)
    finally:
        temp.unlink(missing_ok=True)


def torch_outputs(
    model: PolicyNet | PairNet,
    occupancy: np.ndarray,
    aux: np.ndarray,
    ranges: np.ndarray | None = None,
    neighbours: np.ndarray | None = None,
) -> np.ndarray:
    """The model's outputs for float32 inputs, on CPU (its third input, ranges or neighbours,
    where it takes one)."""
    model = model.to("cpu").eval()
    with torch.no_grad():
        third = neighbours if neighbours is not None else ranges
        extra = () if third is None else (torch.from_numpy(third),)
        return model(torch.from_numpy(occupancy), torch.from_numpy(aux), *extra).numpy()


def _inputs(model: PolicyNet | PairNet, occupancy, aux, ranges, neighbours=None):
    """The inputs as contiguous float32 arrays; ``ranges`` and ``neighbours`` None for a model
    without them."""
    occupancy = np.ascontiguousarray(occupancy, dtype=np.float32)
    aux = np.ascontiguousarray(aux, dtype=np.float32)
    ranges = _optional_input(
        ranges, model.range_sectors, f"the model takes ranges of {model.range_sectors} sectors: give them"
    )
    neighbours = _optional_input(
        neighbours, model.neighbour_slots, f"the model takes neighbours in {model.neighbour_slots} slots: give them"
    )
    return occupancy, aux, ranges, neighbours


def _optional_input(value, taken: int, missing: str):
    """An input the model takes only where ``taken`` (its sectors or slots) is not 0: ``value`` as a
    contiguous float32 array there (a ValueError saying ``missing`` if it is None), else None."""
    if not taken:
        return None
    if value is None:
        raise ValueError(missing)
    return np.ascontiguousarray(value, dtype=np.float32)


def check_parity(
    model: PolicyNet | PairNet,
    onnx_path: str | Path,
    occupancy: np.ndarray,
    aux: np.ndarray,
    tolerance: float = PARITY_TOLERANCE,
    output: str = OUTPUT_NAME,
    ranges: np.ndarray | None = None,
    neighbours: np.ndarray | None = None,
) -> float:
    """Runs the same inputs through torch and onnxruntime; returns the largest |difference|.

    Raises :class:`ParityError` when it exceeds ``tolerance``.
    """
    import onnxruntime as ort

    occupancy, aux, ranges, neighbours = _inputs(model, occupancy, aux, ranges, neighbours)
    expected = torch_outputs(model, occupancy, aux, ranges, neighbours)
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    session = ort.InferenceSession(str(onnx_path), options, providers=["CPUExecutionProvider"])
    feeds = {"occupancy": occupancy, "aux": aux}
    if ranges is not None:
        feeds["ranges"] = ranges
    if neighbours is not None:
        feeds["neighbours"] = neighbours
    (actual,) = session.run([output], feeds)
    diff = float(np.max(np.abs(actual - expected))) if expected.size else 0.0
    if not diff <= tolerance:
        raise ParityError(
            f"{onnx_path}: onnxruntime and torch differ by {diff:.3g} (> {tolerance:g}) on {len(aux)} samples; "
            "the export is wrong: do not deploy this model"
        )
    return diff


def write_parity_file(
    path: str | Path,
    model: PolicyNet | PairNet,
    occupancy: np.ndarray,
    aux: np.ndarray,
    tolerance: float = PARITY_TOLERANCE,
    ranges: np.ndarray | None = None,
    neighbours: np.ndarray | None = None,
) -> None:
    """Writes inputs and torch outputs as JSON for Rust-side parity tests.

    ``{"tolerance", "size_px", "cases": [{"occupancy": [S*S floats, row-major], "aux": [2], "wheels": [2]}]}``;
    for a model with ranges each case also holds ``"ranges": [K]``, and for a pair network
    ``"neighbours": [K*4 floats, row-major]`` (``"wheels"`` then holds its formation velocity).
    """
    occupancy, aux, ranges, neighbours = _inputs(model, occupancy, aux, ranges, neighbours)
    outputs = torch_outputs(model, occupancy, aux, ranges, neighbours)
    cases = [
        {"occupancy": o.reshape(-1).tolist(), "aux": a.tolist(), "wheels": w.tolist()}
        for o, a, w in zip(occupancy, aux, outputs)
    ]
    if ranges is not None:
        for case, r in zip(cases, ranges):
            case["ranges"] = r.tolist()
    if neighbours is not None:
        for case, n in zip(cases, neighbours):
            case["neighbours"] = n.reshape(-1).tolist()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    temp.write_text(json.dumps({"tolerance": tolerance, "size_px": model.size_px, "cases": cases}))
    os.replace(temp, path)
