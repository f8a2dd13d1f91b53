"""ONNX export with the formation model contract, and the torch/onnxruntime parity check.

The exported graph has inputs ``occupancy`` f32 [B, 1, S, S] and ``aux`` f32 [B, 2], and for a model
with ranges a third, ``ranges`` f32 [B, K], declared by ``formation.ranges = "sectors=K,clip=C"``
(the text of ``formation_proto::RangeInput``'s ``Display``); one output f32 [B, 2] named as the
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
from .dataset import RangeInput
from .model import PolicyNet

MODEL_FORMAT = "formation-policy/1"
INPUT_NAMES = ("occupancy", "aux")
#: The inputs of a model with ranges.
RANGE_INPUT_NAMES = ("occupancy", "aux", "ranges")
#: The metadata key declaring the range input.
RANGES_KEY = "formation.ranges"
#: The scalars of the ``aux`` input, in order (``formation.aux``): what the dataset stores.
AUX_LAYOUT = "delta_phi,d_star"
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
) -> dict[str, str]:
    """The ``formation.*`` metadata_props of a model (all values strings); ``ranges``, the data's
    range input, becomes ``formation.ranges``."""
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


def export_onnx(model: PolicyNet, path: str | Path, metadata: dict[str, str], output: str = OUTPUT_NAME) -> None:
    """Exports ``model`` (on CPU, eval mode) to ``path`` atomically, with ``metadata`` as metadata_props
    and its one output named ``output`` (which a model other than ``wheels`` declares in
    ``formation.output``). A model with ranges has the third input ``ranges`` [B, K], which
    ``metadata`` must declare with K sectors."""
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
    input_names = RANGE_INPUT_NAMES if ranges else INPUT_NAMES
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


def torch_outputs(model: PolicyNet, occupancy: np.ndarray, aux: np.ndarray, ranges: np.ndarray | None = None) -> np.ndarray:
    """The model's outputs for float32 inputs, on CPU."""
    model = model.to("cpu").eval()
    with torch.no_grad():
        extra = () if ranges is None else (torch.from_numpy(ranges),)
        return model(torch.from_numpy(occupancy), torch.from_numpy(aux), *extra).numpy()


def _inputs(model: PolicyNet, occupancy, aux, ranges):
    """The inputs as contiguous float32 arrays; ``ranges`` None for a model without them."""
    occupancy = np.ascontiguousarray(occupancy, dtype=np.float32)
    aux = np.ascontiguousarray(aux, dtype=np.float32)
    if model.range_sectors:
        if ranges is None:
            raise ValueError(f"the model takes ranges of {model.range_sectors} sectors: give them")
        ranges = np.ascontiguousarray(ranges, dtype=np.float32)
    else:
        ranges = None
    return occupancy, aux, ranges


def check_parity(
    model: PolicyNet,
    onnx_path: str | Path,
    occupancy: np.ndarray,
    aux: np.ndarray,
    tolerance: float = PARITY_TOLERANCE,
    output: str = OUTPUT_NAME,
    ranges: np.ndarray | None = None,
) -> float:
    """Runs the same inputs through torch and onnxruntime; returns the largest |difference|.

    Raises :class:`ParityError` when it exceeds ``tolerance``.
    """
    import onnxruntime as ort

    occupancy, aux, ranges = _inputs(model, occupancy, aux, ranges)
    expected = torch_outputs(model, occupancy, aux, ranges)
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    session = ort.InferenceSession(str(onnx_path), options, providers=["CPUExecutionProvider"])
    feeds = {"occupancy": occupancy, "aux": aux}
    if ranges is not None:
        feeds["ranges"] = ranges
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
    model: PolicyNet,
    occupancy: np.ndarray,
    aux: np.ndarray,
    tolerance: float = PARITY_TOLERANCE,
    ranges: np.ndarray | None = None,
) -> None:
    """Writes inputs and torch outputs as JSON for Rust-side parity tests.

    ``{"tolerance", "size_px", "cases": [{"occupancy": [S*S floats, row-major], "aux": [2], "wheels": [2]}]}``;
    for a model with ranges each case also holds ``"ranges": [K]``.
    """
    occupancy, aux, ranges = _inputs(model, occupancy, aux, ranges)
    outputs = torch_outputs(model, occupancy, aux, ranges)
    cases = [
        {"occupancy": o.reshape(-1).tolist(), "aux": a.tolist(), "wheels": w.tolist()}
        for o, a, w in zip(occupancy, aux, outputs)
    ]
    if ranges is not None:
        for case, r in zip(cases, ranges):
            case["ranges"] = r.tolist()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    temp.write_text(json.dumps({"tolerance": tolerance, "size_px": model.size_px, "cases": cases}))
    os.replace(temp, path)
