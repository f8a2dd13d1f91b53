//! ONNX Runtime policies through ort: model loading, contract validation, inference.
