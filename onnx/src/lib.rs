//! ONNX Runtime policies through ort: finding the runtime library, loading a model (a regular file
//! of at most [`MAX_MODEL_BYTES`], checked before it is read), checking it against the
//! formation-policy/1 contract and a robot's sensor, and single-sample inference.
//!
//! ```no_run
//! # fn main() -> Result<(), formation_onnx::PolicyError> {
//! let mut policy = formation_onnx::OnnxPolicy::load(std::path::Path::new("onnx/models/policy.onnx"))?;
//! let cells = policy.metadata().occupancy.size_px.pow(2);
//! let image = vec![0.0; cells];
//! let input = formation_proto::PolicyInput::image_and_aux(&image, &[0.3, 1.5]);
//! let [left, right] = policy.infer(&input)?;
//! # let _ = (left, right);
//! # Ok(())
//! # }
//! ```

pub mod contract;
mod error;
mod graph;
mod model_file;
mod policy;
mod runtime;

pub use contract::{
    ContractViolation, ModelEnvelope, ModelMetadata, PolicyOutput, SensorContract, SensorViolation,
};
pub use error::{LIBRARY_FIX, PolicyError};
pub use model_file::{MAX_MODEL_BYTES, check_model_file};
pub use policy::OnnxPolicy;
pub use runtime::{
    ORT_DISABLE_TELEMETRY, ORT_DYLIB_PATH, disable_telemetry_before_threads, init_runtime,
    ort_library_path,
};
