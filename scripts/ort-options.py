"""What ONNX Runtime's graph optimisation and int8 dynamic quantisation do to a policy's single-sample
latency (one intra-op thread, as the agent runs it) and outputs. A measurement, not a test (issue 22).

    .venv/bin/python scripts/ort-options.py onnx/models/policy.onnx
"""

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnxruntime.quantization import QuantType, quantize_dynamic

CALLS = 5000
WARMUP = 300


def session(path: Path, level: ort.GraphOptimizationLevel) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.graph_optimization_level = level
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def percentiles(s: ort.InferenceSession, images: np.ndarray, aux: np.ndarray) -> tuple[float, float]:
    n = len(images)
    feed = lambda i: {"occupancy": images[i % n : i % n + 1], "aux": aux[i % n : i % n + 1]}
    for i in range(WARMUP):
        s.run(None, feed(i))
    times = []
    for i in range(CALLS):
        started = time.perf_counter()
        s.run(None, feed(i))
        times.append(time.perf_counter() - started)
    return float(np.percentile(times, 50) * 1e6), float(np.percentile(times, 99) * 1e6)


def main() -> None:
    if len(sys.argv) != 2:
        sys.exit("usage: ort-options.py MODEL.onnx")
    model = Path(sys.argv[1])
    size = next(int(p.value) for p in onnx.load(str(model)).metadata_props if p.key == "formation.occupancy.size_px")
    rng = np.random.default_rng(0)
    images = (rng.random((64, 1, size, size)) < 0.02).astype(np.float32)
    aux = np.stack([rng.uniform(-3, 3, 64), rng.uniform(0.8, 2.5, 64)], 1).astype(np.float32)
    with tempfile.TemporaryDirectory() as tmp:
        # The exporter's value_info disagrees with ONNX's shape inference on the Gemm weights;
        # the quantiser runs that inference, so it gets the graph without them.
        plain = onnx.load(str(model))
        del plain.graph.value_info[:]
        onnx.save(plain, f"{tmp}/plain.onnx")
        quantize_dynamic(f"{tmp}/plain.onnx", f"{tmp}/int8.onnx", weight_type=QuantType.QInt8)
        reference = session(model, ort.GraphOptimizationLevel.ORT_ENABLE_ALL).run(None, {"occupancy": images, "aux": aux})[0]
        levels = ort.GraphOptimizationLevel
        for name, path, level in [
            ("fp32, no graph optimisation", model, levels.ORT_DISABLE_ALL),
            ("fp32, basic optimisation", model, levels.ORT_ENABLE_BASIC),
            ("fp32, all (the agent's: the default)", model, levels.ORT_ENABLE_ALL),
            ("int8 dynamic quantisation, all", Path(f"{tmp}/int8.onnx"), levels.ORT_ENABLE_ALL),
        ]:
            s = session(path, level)
            diff = np.abs(s.run(None, {"occupancy": images, "aux": aux})[0] - reference).max()
            p50, p99 = percentiles(s, images, aux)
            print(f"{name:38s} p50 {p50:6.1f} us  p99 {p99:6.1f} us  max |output - fp32| {diff:.2e} m/s")


if __name__ == "__main__":
    main()
