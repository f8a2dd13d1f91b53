"""What a policy model declares about its input: its ``formation.*`` ONNX metadata.

The environments render each robot's observation exactly as the model was trained on, with the
occupancy settings it declares (``formation.occupancy.*``), and scale its outputs by its training
speed (``formation.v_train``). :meth:`ModelSpec.from_onnx` reads them with ONNX Runtime (or the
``onnx`` package); a spec can also be written by hand.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional

FORMAT = "formation-policy/1"


@dataclass(frozen=True)
class ModelSpec:
    """A policy's input and output contract.

    ``input`` is ``"occupancy"`` (an image of ``size_px`` x ``size_px`` cells of ``resolution_m``
    metres, hits beyond the window dropped or drawn on the border, the window scaled with d* when
    ``d_star_ref_m`` is set) or ``"scan"`` (the raw ranges); both come with the scalars ``aux``
    declares (``formation.aux``: names in order, ``"delta_phi,d_star"`` where the model declares
    none), which the environment makes with the agent's own code, and, where ``ranges`` is set
    (``formation.ranges``, ``"sectors=K,clip=C"``), the scan's ranges pooled into K sectors, and,
    where ``neighbours`` is set (``formation.neighbours``, ``"slots=K,threshold=T,nearest=M"``), the
    neighbours detected in the scan in K slots of ``(x / d*, y / d*, held, present)``, and with
    ``,hidden=1`` also ``(hx, hy)``, the step aside of the slot's hidden pairs. ``output``
    is what the model answers (``formation.output``): ``"wheels"``, wheel speeds at ``v_train``
    m/s scaled by ``v* / v_train``, or ``"formation_velocity"``, the
    correction in the robot's frame to which the reference term ``v* (cos Δφ, sin Δφ)`` is added,
    exactly as the agent does.
    """

    size_px: int = 50
    resolution_m: float = 0.1
    beyond: str = "drop"
    d_star_ref_m: Optional[float] = None
    v_train: float = 0.7
    beams: Optional[int] = None
    max_range: Optional[float] = None
    input: str = "occupancy"
    output: str = "wheels"
    aux: str = "delta_phi,d_star"
    ranges: Optional[str] = None
    neighbours: Optional[str] = None

    def __post_init__(self) -> None:
        if self.output not in ("wheels", "formation_velocity"):
            raise ValueError(
                f"output {self.output!r} is not 'wheels' or 'formation_velocity': use a model with one of "
                "those outputs (formation.output), or a formation build that knows it"
            )
        if self.input not in ("occupancy", "scan"):
            raise ValueError(f"input {self.input!r} is not 'occupancy' or 'scan'")
        if self.beyond not in ("drop", "border"):
            raise ValueError(f"beyond {self.beyond!r} is not 'drop' or 'border'")
        if not (self.v_train > 0 and math.isfinite(self.v_train)):
            raise ValueError(f"v_train {self.v_train} must be a finite speed > 0")

    @staticmethod
    def from_metadata(meta: Mapping[str, str], origin: str = "model") -> "ModelSpec":
        """The spec of a model's ``formation.*`` metadata map."""
        if meta.get("formation.format") != FORMAT:
            raise ValueError(
                f"{origin}: formation.format is {meta.get('formation.format')!r}, not {FORMAT!r}; "
                "export the model with formation_trainer"
            )

        def get(key: str, parse, default=None):
            if key not in meta:
                if default is not None:
                    return default
                raise ValueError(f"{origin}: metadata key {key} is missing")
            try:
                return parse(meta[key])
            except ValueError as e:
                raise ValueError(f"{origin}: metadata {key} = {meta[key]!r}: {e}") from e

        ref = meta.get("formation.occupancy.d_star_ref_m")
        raw_input = meta.get("formation.input", "occupancy")
        return ModelSpec(
            size_px=get("formation.occupancy.size_px", int),
            resolution_m=get("formation.occupancy.resolution_m", float),
            beyond=get("formation.occupancy.beyond", str),
            d_star_ref_m=float(ref) if ref is not None else None,
            v_train=get("formation.v_train", float),
            beams=get("formation.lidar.beams", int),
            max_range=get("formation.lidar.max_range", float),
            input="scan" if raw_input == "scan-ranges" else raw_input,
            output=meta.get("formation.output", "wheels"),
            aux=meta.get("formation.aux", "delta_phi,d_star"),
            ranges=meta.get("formation.ranges"),
            neighbours=meta.get("formation.neighbours"),
        )

    @staticmethod
    def from_onnx(path: str | Path) -> "ModelSpec":
        """Reads the spec from an ONNX file's metadata (with ONNX Runtime, else ``onnx``)."""
        path = Path(path)
        try:
            import onnxruntime

            options = onnxruntime.SessionOptions()
            options.intra_op_num_threads = 1
            session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
            meta = dict(session.get_modelmeta().custom_metadata_map)
        except ImportError:
            import onnx

            meta = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
        return ModelSpec.from_metadata(meta, str(path))
