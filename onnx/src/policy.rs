//! [`OnnxPolicy`]: one validated ONNX Runtime session running the policy network, one sample at a
//! time, with its input tensors allocated once.

use std::collections::BTreeMap;
use std::path::Path;

use formation_proto::{LidarSpec, NeighbourInput, PolicyInput};
use ort::environment::Environment;
use ort::session::Session;
use ort::value::{Tensor, TensorElementType, ValueType};

use crate::contract::{
    AUX_INPUT, ElementKind, ModelMetadata, NEIGHBOURS_INPUT, OCCUPANCY_INPUT, RANGES_INPUT,
    SensorContract, TensorSignature, check_sensor, check_signature, parse_metadata,
};
use crate::error::PolicyError;
use crate::model_file::read_model_file;
use crate::runtime::environment;

/// A policy network loaded from an ONNX file that follows the formation-policy/1 contract.
///
/// Each instance owns its own single-threaded session (intra- and inter-op threads 1), so one
/// instance per robot runs independently; the instance is `Send` but inference takes `&mut self`.
#[derive(Debug)]
pub struct OnnxPolicy {
    session: Session,
    metadata: ModelMetadata,
    model_id: String,
    /// `occupancy` `[1, 1, S, S]`, `aux` `[1, A]` and, where declared, `ranges` `[1, K]` and
    /// `neighbours` `[1, K, 4]`, in the session's input order.
    inputs: Vec<Tensor<f32>>,
    /// Which of `inputs` is the image, the scalars, the ranges and the neighbours.
    slots: InputSlots,
    cells: usize,
    /// Whether any node of the graph reads the occupancy image ([`OnnxPolicy::reads_image`]).
    reads_image: bool,
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
        check_signature(
            &inputs,
            &outputs,
            size_px,
            metadata.aux,
            metadata.output,
            metadata.ranges,
            metadata.neighbours,
        )
        .map_err(contract)?;

        // The contract holds exactly these names, so each is found once.
        let slot = |name: &str| inputs.iter().position(|t| t.name == name);
        let slots = InputSlots {
            image: slot(OCCUPANCY_INPUT).unwrap_or(0),
            aux: slot(AUX_INPUT).unwrap_or(1),
            ranges: slot(RANGES_INPUT),
            neighbours: slot(NEIGHBOURS_INPUT),
        };
        let cells = size_px * size_px;
        let tensors = inputs
            .iter()
            .map(|t| match t.name.as_str() {
                OCCUPANCY_INPUT => zeros(vec![1, 1, size_px, size_px]),
                AUX_INPUT => zeros(vec![1, metadata.aux.len()]),
                NEIGHBOURS_INPUT => zeros(vec![
                    1,
                    metadata.neighbours.map_or(0, |n| n.slots),
                    metadata
                        .neighbours
                        .map_or(NeighbourInput::BASE_FEATURES, |n| n.features()),
                ]),
                _ => zeros(vec![1, metadata.ranges.map_or(0, |r| r.sectors)]),
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(session_error)?;
        Ok(OnnxPolicy {
            session,
            metadata,
            model_id: formation_proto::model_id::model_id(path, &bytes),
            inputs: tensors,
            slots,
            cells,
            reads_image: crate::graph::reads_input(&bytes, OCCUPANCY_INPUT),
        })
    }

    /// What the model's metadata says about its training.
    pub fn metadata(&self) -> &ModelMetadata {
        &self.metadata
    }

    /// Whether the network reads the occupancy image it declares. One that does not (the
    /// pair-potential network reads only its neighbours and scalars) still takes an image of the
    /// declared shape, but its output is the same whatever the image holds, so a caller may skip
    /// rendering it; [`OnnxPolicy::infer`] then leaves the image tensor as it is.
    pub fn reads_image(&self) -> bool {
        self.reads_image
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

    /// One forward pass: `input.image` has `size_px * size_px` cells, row-major; `input.aux`
    /// holds the scalars the model declares, in order ([`ModelMetadata::aux`]; the paper's
    /// `(delta_phi, d*)` for a model that declares none); `input.ranges` one value a sector of
    /// the range input it declares ([`ModelMetadata::ranges`]), or nothing where it declares
    /// none; `input.neighbours` [`NeighbourInput::features`] values a slot of the neighbour input
    /// it declares ([`ModelMetadata::neighbours`]), or nothing where it declares none. Returns the model's two output values: `(left, right)` wheel speeds at `v_train`,
    /// or the formation velocity `(f_x, f_y)` in the robot's frame, as its metadata declares
    /// ([`crate::contract::PolicyOutput`]).
    pub fn infer(&mut self, input: &PolicyInput<'_>) -> Result<[f32; 2], PolicyError> {
        let PolicyInput {
            image: occupancy,
            aux,
            ranges,
            neighbours,
        } = *input;
        if occupancy.len() != self.cells {
            return Err(PolicyError::InputLength {
                model: self.model_id.clone(),
                expected: self.cells,
                actual: occupancy.len(),
            });
        }
        let sectors = self.metadata.ranges.map_or(0, |r| r.sectors);
        if ranges.len() != sectors {
            return Err(PolicyError::RangesLength {
                model: self.model_id.clone(),
                declared: self.metadata.ranges,
                actual: ranges.len(),
            });
        }
        let neighbour_values = self.metadata.neighbours.map_or(0, |n| n.len());
        if neighbours.len() != neighbour_values {
            return Err(PolicyError::NeighboursLength {
                model: self.model_id.clone(),
                declared: self.metadata.neighbours,
                actual: neighbours.len(),
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
        let mut fill = |slot: usize, values: &[f32]| -> Result<(), PolicyError> {
            let (_, cells) = self.inputs[slot]
                .try_extract_tensor_mut()
                .map_err(|e| failed(e.to_string()))?;
            cells.copy_from_slice(values);
            Ok(())
        };
        if self.reads_image {
            fill(self.slots.image, occupancy)?;
        }
        fill(self.slots.aux, aux)?;
        if let Some(slot) = self.slots.ranges {
            fill(slot, ranges)?;
        }
        if let Some(slot) = self.slots.neighbours {
            fill(slot, neighbours)?;
        }

        let inputs = &self.inputs;
        let outputs = match inputs.as_slice() {
            [a, b] => self.session.run(ort::inputs![a, b]),
            [a, b, c] => self.session.run(ort::inputs![a, b, c]),
            [a, b, c, d] => self.session.run(ort::inputs![a, b, c, d]),
            other => {
                return Err(failed(format!(
                    "{} inputs held, where the contract admits two to four",
                    other.len()
                )));
            }
        }
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

/// Where each input sits in the session's input order.
#[derive(Debug, Clone, Copy)]
struct InputSlots {
    image: usize,
    aux: usize,
    ranges: Option<usize>,
    neighbours: Option<usize>,
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
