"""Trains the formation policy CNN on datasets written by `formation collect` and exports it to ONNX.

Modules:
    dataset: reads the Rust-written dataset format (numpy + safetensors) with clear errors.
    model:   the paper's CNN (exact layer sizes).
    train:   the training loop (MSE, Adam), loss curve, checkpoint, then ONNX export.
    export:  ONNX export with the metadata contract, and the torch/onnxruntime parity check.

Run as ``python -m formation_trainer {train,export} --help``.
"""

__version__ = "0.1.0"

#: Written into every model's ``formation.created_by``.
CREATED_BY = f"formation_trainer {__version__}"
