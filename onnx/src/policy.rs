//! [`OnnxPolicy`]: one validated ONNX Runtime session running the policy network, one sample at a
//! time, with its input tensors allocated once.

use std::collections::BTreeMap;
use std::path::Path;

use formation_proto::LidarSpec;
use ort::environment::Environment;
use ort::session::Session;
use ort::value::{Tensor, TensorElementType, ValueType};

use crate::contract::{
    ElementKind, ModelMetadata, OCCUPANCY_INPUT, SensorContract, TensorSignature, check_sensor,
    check_signature, parse_metadata,
};
use crate::error::PolicyError;
use crate::model_file::read_model_file;
use crate::runtime::environment;

/// A policy network loaded from an ONNX file that follows the formation-policy/1 contract.
///
/// Each instance owns its own single-threaded session (intra- and inter-op threads 1), so one
/// instance per robot runs independently; the instance is `Send` but inference takes `&mut self`.
pub struct OnnxPolicy {
    session: Session,
    metadata: ModelMetadata,
    model_id: String,
    /// `occupancy` `[1, 1, S, S]` and `aux` `[1, 2]`, in the session's input order.
    inputs: [Tensor<f32>; 2],
    /// Which of `inputs` is the image.
    occupancy_slot: usize,
    cells: usize,
}

impl std::fmt::Debug for OnnxPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxPolicy")
            .field("model_id", &self.model_id)
            .field("metadata", &self.metadata)
            .finish()
    }
}

impl OnnxPolicy {
    /// Loads a model, starting ONNX Runtime on first use (see [`crate::ort_library_path`]), and
    /// checks its inputs, output and metadata against the contract.
    ///
    /// The file must be a regular file of at most [`crate::MAX_MODEL_BYTES`]; a missing path, a
    /// directory, a FIFO, a device or an oversized file is refused before it is read (see
    /// [`crate::check_model_file`]).
    pub fn load(path: &Path) -> Result<OnnxPolicy, PolicyError> {
        let bytes = read_model_file(path)?;
        let env = environment()?;
        let session_error = |reason: String| PolicyError::Session {
            path: path.to_path_buf(),
            reason,
        };
        let session = single_threaded_session(env, &bytes).map_err(session_error)?;

        let contract = |reason| PolicyError::Contract {
            path: path.to_path_buf(),
            reason,
        };
        let metadata = parse_metadata(&metadata_entries(&session).map_err(session_error)?)
            .map_err(contract)?;
        let inputs: Vec<TensorSignature> = session
            .inputs()
            .iter()
            .map(|o| signature(o.name(), o.dtype()))
            .collect();
        let outputs: Vec<TensorSignature> = session
            .outputs()
            .iter()
            .map(|o| signature(o.name(), o.dtype()))
            .collect();
        let size_px = metadata.occupancy.size_px;
        check_signature(&inputs, &outputs, size_px, metadata.aux, metadata.output)
            .map_err(contract)?;

        let occupancy_slot = usize::from(inputs[0].name != OCCUPANCY_INPUT);
        let cells = size_px * size_px;
        let occupancy = zeros(vec![1, 1, size_px, size_px]).map_err(session_error)?;
        let aux = zeros(vec![1, metadata.aux.len()]).map_err(session_error)?;
        let inputs = if occupancy_slot == 0 {
            [occupancy, aux]
        } else {
            [aux, occupancy]
        };
        Ok(OnnxPolicy {
            session,
            metadata,
            model_id: formation_proto::model_id::model_id(path, &bytes),
            inputs,
            occupancy_slot,
            cells,
        })
    }

    /// What the model's metadata says about its training.
    pub fn metadata(&self) -> &ModelMetadata {
        &self.metadata
    }

    /// A short id for logs: the file stem and 8 hex digits of a hash of the file's bytes.
    pub fn model_id(&self) -> &str {
        &self.model_id
    }

    /// Checks that the model was trained for this LIDAR: beam count, maximum range and image
    /// window (see [`crate::contract::check_sensor`]).
    pub fn check_sensor(&self, lidar: &LidarSpec) -> Result<(), PolicyError> {
        check_sensor(&SensorContract::from(&self.metadata), lidar).map_err(|reason| {
            PolicyError::SensorMismatch {
                model: self.model_id.clone(),
                reason,
            }
        })
    }

    /// One forward pass: `occupancy` has `size_px * size_px` cells, row-major; `aux` holds the
    /// scalars the model declares, in order ([`ModelMetadata::aux`]; the paper's
    /// `(delta_phi, d*)` for a model that declares none). Returns the model's two output values: `(left, right)` wheel speeds at
    /// `v_train`, or the formation velocity `(f_x, f_y)` in the robot's frame, as its metadata
    /// declares ([`crate::contract::PolicyOutput`]).
    pub fn infer(&mut self, occupancy: &[f32], aux: &[f32]) -> Result<[f32; 2], PolicyError> {
        if occupancy.len() != self.cells {
            return Err(PolicyError::InputLength {
                model: self.model_id.clone(),
                expected: self.cells,
                actual: occupancy.len(),
            });
        }
        if aux.len() != self.metadata.aux.len() {
            return Err(PolicyError::AuxLength {
                model: self.model_id.clone(),
                declared: self.metadata.aux,
                actual: aux.len(),
            });
        }
        let model = &self.model_id;
        let failed = |reason: String| PolicyError::Inference {
            model: model.clone(),
            reason,
        };
        let aux_slot = 1 - self.occupancy_slot;
        let (_, image) = self.inputs[self.occupancy_slot]
            .try_extract_tensor_mut()
            .map_err(|e| failed(e.to_string()))?;
        image.copy_from_slice(occupancy);
        let (_, aux_cells) = self.inputs[aux_slot]
            .try_extract_tensor_mut()
            .map_err(|e| failed(e.to_string()))?;
        aux_cells.copy_from_slice(aux);

        let outputs = self
            .session
            .run(ort::inputs![&self.inputs[0], &self.inputs[1]])
            .map_err(|e| failed(e.to_string()))?;
        let name = self.metadata.output.name();
        let wheels = outputs
            .get(name)
            .ok_or_else(|| failed(format!("no `{name}` output")))?;
        let (_, values) = wheels
            .try_extract_tensor::<f32>()
            .map_err(|e| failed(e.to_string()))?;
        let &[left, right] = values else {
            return Err(failed(format!(
                "`{name}` has {} values, expected 2",
                values.len()
            )));
        };
        if !(left.is_finite() && right.is_finite()) {
            return Err(PolicyError::NonFiniteOutput {
                model: model.clone(),
                left,
                right,
            });
        }
        Ok([left, right])
    }
}

/// A session for the model bytes with one intra-op and one inter-op thread.
fn single_threaded_session(env: &Environment, bytes: &[u8]) -> Result<Session, String> {
    let builder = Session::builder(env).map_err(|e| e.to_string())?;
    let builder = builder.with_intra_threads(1).map_err(|e| e.to_string())?;
    let mut builder = builder.with_inter_threads(1).map_err(|e| e.to_string())?;
    builder.commit_from_memory(bytes).map_err(|e| e.to_string())
}

/// The model's custom metadata (`metadata_props`) as a map.
fn metadata_entries(session: &Session) -> Result<BTreeMap<String, String>, String> {
    let metadata = session.metadata().map_err(|e| e.to_string())?;
    let keys = metadata.custom_keys().map_err(|e| e.to_string())?;
    Ok(keys
        .into_iter()
        .filter_map(|key| metadata.custom(&key).map(|value| (key, value)))
        .collect())
}

/// Describes an ort input/output for the contract checks.
fn signature(name: &str, dtype: &ValueType) -> TensorSignature {
    let (element, dims) = match dtype {
        ValueType::Tensor {
            ty: TensorElementType::Float32,
            shape,
            ..
        } => (ElementKind::F32, shape.to_vec()),
        ValueType::Tensor { ty, shape, .. } => {
            (ElementKind::OtherTensor(ty.to_string()), shape.to_vec())
        }
        other => (ElementKind::NotTensor(other.to_string()), Vec::new()),
    };
    TensorSignature {
        name: name.to_owned(),
        element,
        dims,
    }
}

fn zeros(shape: Vec<usize>) -> Result<Tensor<f32>, String> {
    let len = shape.iter().product();
    Tensor::from_array((shape, vec![0.0_f32; len])).map_err(|e| e.to_string())
}

/// Keeps [`OnnxPolicy`] movable to an agent thread: a compile error if it stops being `Send`.
const _: fn() = || {
    fn assert_send<T: Send>() {}
    assert_send::<OnnxPolicy>();
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_model_is_reported_before_touching_the_runtime() {
        let path = Path::new("/nonexistent/policy.onnx");
        match OnnxPolicy::load(path) {
            Err(err @ PolicyError::ModelNotFound { .. }) => {
                assert!(
                    err.to_string().contains("/nonexistent/policy.onnx"),
                    "{err}"
                );
                assert!(err.to_string().contains("formation train"), "{err}");
            }
            other => panic!("expected ModelNotFound, got {other:?}"),
        }
    }
}
