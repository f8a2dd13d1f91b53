//! Why a policy could not be loaded, validated or run: one error type for the whole crate, each
//! variant naming the cause and how to fix it.

use std::path::PathBuf;

use crate::contract::{ContractViolation, SensorViolation};

/// How to obtain the ONNX Runtime library; appended to every "library not found" message.
pub const LIBRARY_FIX: &str = "install it with `bash .ci/setup-python` (pip onnxruntime==1.31.1 into .venv) \
                               or set ORT_DYLIB_PATH=/path/to/libonnxruntime.so.1.31.1";

/// Everything that can go wrong between a model file on disk and a pair of wheel speeds.
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    /// `ORT_DYLIB_PATH` is set but names no file.
    #[error(
        "ORT_DYLIB_PATH is set to {path:?}, which does not exist; point it at libonnxruntime.so.1.31.1 \
         or unset it to use the one in .venv"
    )]
    LibraryPathMissing {
        /// The value of `ORT_DYLIB_PATH`.
        path: PathBuf,
    },
    /// No ONNX Runtime shared library was found anywhere it is looked for.
    #[error("ONNX Runtime library not found (looked in {}); {LIBRARY_FIX}", .searched.join(", "))]
    LibraryNotFound {
        /// The places searched, in order, for the message.
        searched: Vec<String>,
    },
    /// The library file exists but ONNX Runtime could not be started from it.
    #[error(
        "could not start ONNX Runtime from {path:?}: {reason}; it must be the onnxruntime 1.31 shared \
         library: {LIBRARY_FIX}"
    )]
    RuntimeLoad {
        /// The library that was tried.
        path: PathBuf,
        /// What ort or the dynamic loader reported.
        reason: String,
    },
    /// The model file does not exist.
    #[error(
        "model {path:?} not found; train one with `formation train` (or `formation learn`), or pass the \
         path of an existing .onnx file"
    )]
    ModelNotFound {
        /// The path given.
        path: PathBuf,
    },
    /// The model path names something other than a regular file (a directory, a FIFO, a device).
    #[error(
        "model {path:?} is {kind}, not a regular file; pass the path of an .onnx file exported by \
         `formation train`"
    )]
    ModelNotAFile {
        /// The path given.
        path: PathBuf,
        /// What it is instead, e.g. `a directory`.
        kind: &'static str,
    },
    /// The model file is larger than any policy this project loads.
    #[error(
        "model {path:?} is {size} bytes, over the {limit}-byte ({mib} MiB) limit of a model file; \
         the formation policies are well under 1 MiB, so check that the path names the right file",
        size = SizeText { size: *.size, limit: *.limit },
        mib = .limit >> 20
    )]
    ModelTooLarge {
        /// The path given.
        path: PathBuf,
        /// Its size in bytes, or `None` when it grew past the limit while being read.
        size: Option<u64>,
        /// The largest model file loaded, in bytes (`model_file::MAX_MODEL_BYTES`).
        limit: u64,
    },
    /// The model file exists but could not be read.
    #[error("could not read model {path:?}: {source}")]
    ModelRead {
        /// The path given.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// ONNX Runtime refused to build a session from the file (not an ONNX model, or a broken one).
    #[error(
        "ONNX Runtime could not open model {path:?}: {reason}; re-export it with `formation train`"
    )]
    Session {
        /// The model file.
        path: PathBuf,
        /// ONNX Runtime's message.
        reason: String,
    },
    /// The model opens but does not follow the formation-policy/1 contract.
    #[error(
        "model {path:?} breaks the formation-policy/1 contract: {reason}; re-export it with `formation train`"
    )]
    Contract {
        /// The model file.
        path: PathBuf,
        /// What is wrong, expected versus found.
        reason: ContractViolation,
    },
    /// The model was trained for a different sensor than the one it is asked to drive.
    #[error(
        "model {model} {reason}; use a model trained with the scenario's sensor settings \
         (formation collect/train) or set the scenario's [lidar] to the model's"
    )]
    SensorMismatch {
        /// Model id.
        model: String,
        /// Which setting differs, with the model's value and the sensor's.
        reason: SensorViolation,
    },
    /// An input buffer of the wrong size was passed to [`crate::OnnxPolicy::infer`].
    #[error(
        "model {model}: the occupancy image has {actual} cells, the model takes {expected} (size_px^2)"
    )]
    InputLength {
        /// Model id.
        model: String,
        /// `size_px * size_px`.
        expected: usize,
        /// Cells given.
        actual: usize,
    },
    /// The scalars beside the image are not as many as the model declares.
    #[error(
        "model {model}: {actual} scalars given beside the image, the model declares {} ({declared})",
        declared.len()
    )]
    AuxLength {
        /// Model id.
        model: String,
        /// What the model declares.
        declared: formation_proto::AuxLayout,
        /// Scalars given.
        actual: usize,
    },
    /// The scan's ranges given do not match the range input the model declares.
    #[error(
        "model {model}: {actual} range values given, but the model declares {} \
         (`formation.ranges`); feed one value a sector, as \
         `formation_perception::ranges::pool` computes them",
        match declared {
            Some(ranges) => format!("{} sectors ({ranges})", ranges.sectors),
            None => "no range input".to_owned(),
        }
    )]
    RangesLength {
        /// Model id.
        model: String,
        /// What the model declares.
        declared: Option<formation_proto::RangeInput>,
        /// Values given.
        actual: usize,
    },
    /// The detected neighbours given do not match the neighbour input the model declares.
    #[error(
        "model {model}: {actual} neighbour values given, but the model declares {} \
         (`formation.neighbours`); feed {} values a slot, as \
         `formation_perception::neighbour_input::NeighbourInputBuilder::fill` computes them",
        match declared {
            Some(neighbours) => format!("{} ({neighbours})", neighbours.len()),
            None => "no neighbour input".to_owned(),
        },
        declared.map_or(formation_proto::NeighbourInput::BASE_FEATURES, |n| n.features())
    )]
    NeighboursLength {
        /// Model id.
        model: String,
        /// What the model declares.
        declared: Option<formation_proto::NeighbourInput>,
        /// Values given.
        actual: usize,
    },
    /// ONNX Runtime failed while running the model.
    #[error("model {model}: inference failed: {reason}")]
    Inference {
        /// Model id.
        model: String,
        /// ONNX Runtime's message.
        reason: String,
    },
    /// The model produced NaN or infinity.
    #[error(
        "model {model} returned a non-finite command ({left}, {right}); the model is broken, retrain it"
    )]
    NonFiniteOutput {
        /// Model id.
        model: String,
        /// Left wheel output.
        left: f32,
        /// Right wheel output.
        right: f32,
    },
}

/// A model file's size for [`PolicyError::ModelTooLarge`]: the bytes, or "more than" the limit
/// when the file grew past it while being read.
struct SizeText {
    size: Option<u64>,
    limit: u64,
}

impl std::fmt::Display for SizeText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.size {
            Some(size) => write!(f, "{size}"),
            None => write!(f, "more than {}", self.limit),
        }
    }
}
