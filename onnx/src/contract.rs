//! The formation-policy/1 model contract, as pure checks over plain data.
//!
//! The Python exporter writes it and [`crate::OnnxPolicy::load`] enforces it:
//!
//! - inputs exactly `occupancy` f32 `[B, 1, S, S]` and `aux` f32 `[B, A]`: the scalars that
//!   `formation.aux` declares, in order (`A` of them; absent: the paper's `delta_phi,d_star`, see
//!   [`AuxLayout`]); and `ranges` f32 `[B, K]` where `formation.ranges = "sectors=K,clip=C"`
//!   declares the scan's ranges beside the image ([`RangeInput`]); and `neighbours` f32
//!   `[B, K, 4]` where `formation.neighbours = "slots=K,threshold=T,nearest=M"` declares the
//!   neighbours detected in the scan ([`NeighbourInput`]), `[B, K, 6]` where it adds `hidden=1`;
//! - one output, by default `wheels` f32 `[B, 2]` (left, right) m/s at `v_train`; or, where the
//!   metadata declares `formation.output = formation_velocity`, `formation_velocity` f32 `[B, 2]`:
//!   the correction of the formation in the robot's frame ([`PolicyOutput`]); `B` dynamic;
//! - string metadata (`formation.*` keys, see [`keys`]) with the occupancy rendering, the LIDAR
//!   and `v_train`, where `S` equals `formation.occupancy.size_px`.
//!
//! Nothing here touches ONNX Runtime: the session's inputs and outputs are first described as
//! [`TensorSignature`]s, so every rule is unit-tested without a model file.

use std::collections::BTreeMap;
use std::fmt;

use formation_proto::{
    AuxLayout, BeyondWindow, LidarSpec, NeighbourInput, OccupancySpec, PolicyIo, RangeInput,
};

/// The value of [`keys::FORMAT`] this crate understands.
pub const MODEL_FORMAT: &str = "formation-policy/1";
/// Name of the image input.
pub const OCCUPANCY_INPUT: &str = "occupancy";
/// Name of the input of scalars beside the image ([`AuxLayout`]).
pub const AUX_INPUT: &str = "aux";
/// Name of the input of the scan's ranges ([`RangeInput`]), where the metadata declares one.
pub const RANGES_INPUT: &str = "ranges";
/// Name of the input of the detected neighbours ([`NeighbourInput`]), where the metadata declares
/// one.
pub const NEIGHBOURS_INPUT: &str = "neighbours";
/// Name of the wheel-speed output.
pub const WHEELS_OUTPUT: &str = "wheels";
/// Name of the formation-velocity output.
pub const FORMATION_VELOCITY_OUTPUT: &str = "formation_velocity";

pub use formation_proto::PolicyOutput;

/// The one input kind agents feed today: the occupancy image rendered from the robot's own scan
/// (the value of [`keys::INPUT`]).
pub const INPUT_OCCUPANCY: &str = "occupancy";

/// Largest image side `S` a model may declare \[cells\] (the paper's network takes 50). It bounds
/// the input buffers an agent allocates from the model's metadata.
pub const MAX_SIZE_PX: usize = 1024;

/// ONNX `metadata_props` keys of the contract (all values are strings).
pub mod keys {
    /// Contract version, [`super::MODEL_FORMAT`].
    pub const FORMAT: &str = "formation.format";
    /// Image side in cells (`S`).
    pub const SIZE_PX: &str = "formation.occupancy.size_px";
    /// Cell edge length \[m\].
    pub const RESOLUTION_M: &str = "formation.occupancy.resolution_m";
    /// `drop` or `border`.
    pub const BEYOND: &str = "formation.occupancy.beyond";
    /// The d* \[m\] at which cells are `resolution_m` wide, for a window that scales with d*
    /// (optional; absent: a fixed window).
    pub const D_STAR_REF_M: &str = "formation.occupancy.d_star_ref_m";
    /// The kind of sensor input the model takes (optional; absent means [`super::INPUT_OCCUPANCY`]).
    pub const INPUT: &str = "formation.input";
    /// What the model's one output means (optional; absent means `wheels`): see
    /// [`super::PolicyOutput`].
    pub const OUTPUT: &str = "formation.output";
    /// The scalars beside the image, by name and in order, comma-separated (optional; absent
    /// means `delta_phi,d_star`): see [`formation_proto::AuxLayout`].
    pub const AUX: &str = "formation.aux";
    /// The scan's ranges beside the image, `sectors=K,clip=C` (optional; absent: none): see
    /// [`formation_proto::RangeInput`].
    pub const RANGES: &str = "formation.ranges";
    /// The neighbours detected in the scan beside the image, `slots=K,threshold=T,nearest=M`,
    /// optionally `,hidden=1` (optional; absent: none): see [`formation_proto::NeighbourInput`].
    pub const NEIGHBOURS: &str = "formation.neighbours";
    /// LIDAR beams the model was trained with.
    pub const BEAMS: &str = "formation.lidar.beams";
    /// LIDAR maximum range \[m\].
    pub const MAX_RANGE: &str = "formation.lidar.max_range";
    /// Training speed \[m/s\]: outputs are wheel speeds at this speed.
    pub const V_TRAIN: &str = "formation.v_train";
    /// Id of the dataset the model was trained on.
    pub const DATASET_ID: &str = "formation.dataset_id";
    /// Smallest d* \[m\] of the training data (optional, with [`D_STAR_MAX`]).
    pub const D_STAR_MIN: &str = "formation.envelope.d_star_min";
    /// Largest d* \[m\] of the training data (optional, with [`D_STAR_MIN`]).
    pub const D_STAR_MAX: &str = "formation.envelope.d_star_max";
    /// Team sizes of the training data, comma-separated (optional).
    pub const TEAM_SIZES: &str = "formation.envelope.team_sizes";
    /// LIDAR range noise \[m\] of the training data (optional).
    pub const NOISE_STD: &str = "formation.lidar.noise_std";
}

/// What a model was trained on beyond its sensor contract: the range of d*, the team sizes and
/// the LIDAR noise, when its metadata records them (models exported before the envelope existed
/// record none, and nothing is refused for them).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ModelEnvelope {
    /// Smallest and largest d* \[m\] of the training data.
    pub d_star: Option<(f64, f64)>,
    /// Team sizes of the training data, ascending.
    pub team_sizes: Vec<usize>,
    /// LIDAR range noise \[m\] of the training data.
    pub noise_std: Option<f64>,
}

impl ModelEnvelope {
    /// Relative slack on the d* range: the range is recorded from `f32` samples, so a scenario's
    /// `0.8` must match a recorded `0.800000011920929`.
    pub const D_STAR_SLACK: f64 = 1e-6;

    /// Whether `d_star` lies in the recorded d* range (true when none is recorded).
    pub fn admits_d_star(&self, d_star: f64) -> bool {
        self.d_star.is_none_or(|(lo, hi)| {
            d_star >= lo * (1.0 - Self::D_STAR_SLACK) && d_star <= hi * (1.0 + Self::D_STAR_SLACK)
        })
    }
}

impl ModelMetadata {
    /// What the model takes and answers: its image, its scalars, its output and `v_train`.
    pub fn io(&self) -> PolicyIo {
        PolicyIo {
            image: self.occupancy,
            aux: self.aux,
            ranges: self.ranges,
            neighbours: self.neighbours,
            output: self.output,
            v_train: self.v_train,
        }
    }

    /// The envelope the metadata records ([`parse_metadata`] has checked it parses).
    pub fn envelope(&self) -> ModelEnvelope {
        parse_envelope(&self.extra).unwrap_or_default()
    }
}

/// The optional envelope keys, checked.
fn parse_envelope(entries: &BTreeMap<String, String>) -> Result<ModelEnvelope, ContractViolation> {
    let optional_real = |key: &'static str| -> Result<Option<f64>, ContractViolation> {
        entries
            .get(key)
            .map_or(Ok(None), |_| parse_positive_real(entries, key).map(Some))
    };
    let d_star = match (
        optional_real(keys::D_STAR_MIN)?,
        optional_real(keys::D_STAR_MAX)?,
    ) {
        (None, None) => None,
        (Some(lo), Some(hi)) if lo <= hi => Some((lo, hi)),
        (Some(_), Some(_)) => {
            return Err(ContractViolation::BadMetadata {
                key: keys::D_STAR_MAX,
                value: entries[keys::D_STAR_MAX].clone(),
                expected: "at least formation.envelope.d_star_min",
            });
        }
        (None, Some(_)) => {
            return Err(ContractViolation::MissingMetadata {
                key: keys::D_STAR_MIN,
            });
        }
        (Some(_), None) => {
            return Err(ContractViolation::MissingMetadata {
                key: keys::D_STAR_MAX,
            });
        }
    };
    let team_sizes = match entries.get(keys::TEAM_SIZES) {
        None => Vec::new(),
        Some(text) => {
            let mut sizes = text
                .split(',')
                .map(|n| n.trim().parse::<usize>().ok().filter(|&n| n > 0))
                .collect::<Option<Vec<usize>>>()
                .ok_or_else(|| ContractViolation::BadMetadata {
                    key: keys::TEAM_SIZES,
                    value: text.clone(),
                    expected: "a comma-separated list of positive team sizes",
                })?;
            sizes.sort_unstable();
            sizes.dedup();
            sizes
        }
    };
    let noise_std = match entries.get(keys::NOISE_STD) {
        None => None,
        Some(text) => match text.trim().parse::<f64>() {
            Ok(x) if x.is_finite() && x >= 0.0 => Some(x),
            _ => {
                return Err(ContractViolation::BadMetadata {
                    key: keys::NOISE_STD,
                    value: text.clone(),
                    expected: "a finite number >= 0",
                });
            }
        },
    };
    Ok(ModelEnvelope {
        d_star,
        team_sizes,
        noise_std,
    })
}

/// What a model's metadata says about how it was trained, parsed and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelMetadata {
    /// The occupancy rendering the model was trained on.
    pub occupancy: OccupancySpec,
    /// LIDAR beams of the training sensor.
    pub beams: usize,
    /// LIDAR maximum range of the training sensor \[m\].
    pub max_range: f64,
    /// Training speed \[m/s\]; deployed commands are scaled by `v* / v_train`.
    pub v_train: f64,
    /// Id of the training dataset.
    pub dataset_id: String,
    /// What its one output means.
    pub output: PolicyOutput,
    /// The scalars it takes beside its image.
    pub aux: AuxLayout,
    /// The scan's ranges it takes beside its image, if any.
    pub ranges: Option<RangeInput>,
    /// The neighbours detected in its scan it takes beside its image, if any.
    pub neighbours: Option<NeighbourInput>,
    /// Every other metadata entry (training figures, DAgger iteration, creator, ...), by full key.
    pub extra: BTreeMap<String, String>,
}

/// Element type of a model input or output, as far as the contract cares.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ElementKind {
    /// A 32-bit float tensor, the only kind the contract accepts.
    F32,
    /// A tensor of another element type (its name, for the message).
    OtherTensor(String),
    /// Not a tensor at all (sequence, map, optional).
    NotTensor(String),
}

/// One model input or output: name, element kind and dimensions (`-1` = dynamic).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TensorSignature {
    /// Input or output name.
    pub name: String,
    /// Element type.
    pub element: ElementKind,
    /// Dimensions; `-1` for a dynamic (symbolic) one.
    pub dims: Vec<i64>,
}

/// How a model breaks the contract: expected versus found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ContractViolation {
    /// The model declares a sensor input this agent cannot feed.
    #[error(
        "the model declares the input \"{input}\" ({key}), which this agent cannot feed: it \
         renders only \"{INPUT_OCCUPANCY}\" (the occupancy image of its own scan); use a model \
         trained on occupancy images, or a formation build that feeds \"{input}\"",
        key = keys::INPUT
    )]
    UnsupportedInput {
        /// The declared input kind.
        input: String,
    },
    /// The model's inputs are not exactly `occupancy` and `aux` (and `ranges`, where its
    /// metadata declares `formation.ranges`, and `neighbours`, where it declares
    /// `formation.neighbours`).
    #[error(
        "inputs are [{}], expected exactly [occupancy, aux{}{}] (the metadata declares {}`{}` and \
         declares {}`{}`)",
        .found.join(", "),
        if *.ranges { ", ranges" } else { "" },
        if *.neighbours { ", neighbours" } else { "" },
        if *.ranges { "" } else { "no " },
        keys::RANGES,
        if *.neighbours { "" } else { "no " },
        keys::NEIGHBOURS
    )]
    InputNames {
        /// Input names found.
        found: Vec<String>,
        /// Whether the metadata declares a range input.
        ranges: bool,
        /// Whether the metadata declares a neighbour input.
        neighbours: bool,
    },
    /// The model declares a range input this agent cannot feed.
    #[error("metadata `{}` = {value:?} cannot be fed: {reason}", keys::RANGES)]
    BadRanges {
        /// The declared value.
        value: String,
        /// What is wrong with it.
        #[source]
        reason: formation_proto::RangeInputError,
    },
    /// The model declares a neighbour input this agent cannot feed.
    #[error("metadata `{}` = {value:?} cannot be fed: {reason}", keys::NEIGHBOURS)]
    BadNeighbours {
        /// The declared value.
        value: String,
        /// What is wrong with it.
        #[source]
        reason: formation_proto::NeighbourInputError,
    },
    /// The model's outputs are not exactly the one its metadata declares.
    #[error(
        "outputs are [{}], expected exactly [{expected}] (the output `{}` declares, or \
         `wheels` where it is absent)",
        .found.join(", "),
        keys::OUTPUT
    )]
    OutputNames {
        /// Output names found.
        found: Vec<String>,
        /// The output the metadata declares.
        expected: PolicyOutput,
    },
    /// The model declares an output this agent cannot use.
    #[error(
        "the model declares the output \"{output}\" ({}), which this agent cannot use: it \
         uses \"wheels\" or \"formation_velocity\"; use a model with one of those outputs, or a \
         formation build that knows \"{output}\"",
        keys::OUTPUT
    )]
    UnsupportedOutput {
        /// The declared output.
        output: String,
    },
    /// An input or output is not an f32 tensor.
    #[error("`{name}` is {found}, expected a float32 tensor")]
    ElementType {
        /// Input or output name.
        name: String,
        /// What it is.
        found: String,
    },
    /// An input or output has the wrong shape.
    #[error("`{name}` has shape {}, expected {expected}", DimsDisplay(.found))]
    Shape {
        /// Input or output name.
        name: String,
        /// The expected shape, e.g. `[batch, 1, 50, 50]`.
        expected: String,
        /// Dimensions found (`-1` = dynamic).
        found: Vec<i64>,
    },
    /// The model declares scalar inputs this agent cannot feed.
    #[error("metadata `{}` = {value:?} cannot be fed: {reason}", keys::AUX)]
    BadAux {
        /// The declared value.
        value: String,
        /// What is wrong with it.
        #[source]
        reason: formation_proto::policy_io::AuxLayoutError,
    },
    /// A required metadata key is absent.
    #[error("metadata key `{key}` is missing")]
    MissingMetadata {
        /// The key.
        key: &'static str,
    },
    /// A metadata value does not parse or is out of range.
    #[error("metadata `{key}` = {value:?} is not {expected}")]
    BadMetadata {
        /// The key.
        key: &'static str,
        /// Its value.
        value: String,
        /// What it should be.
        expected: &'static str,
    },
}

/// Formats dimensions with `batch` for a dynamic first one and `dynamic` for any other:
/// `[batch, 1, 40, 40]`, `[batch, dynamic]`.
struct DimsDisplay<'a>(&'a [i64]);

impl fmt::Display for DimsDisplay<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[")?;
        for (i, d) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            if *d < 0 && i == 0 {
                f.write_str("batch")?
            } else if *d < 0 {
                f.write_str("dynamic")?
            } else {
                write!(f, "{d}")?
            }
        }
        f.write_str("]")
    }
}

/// Parses and checks the `formation.*` metadata. Keys other than the required ones go to
/// [`ModelMetadata::extra`].
pub fn parse_metadata(
    entries: &BTreeMap<String, String>,
) -> Result<ModelMetadata, ContractViolation> {
    let format = required(entries, keys::FORMAT)?;
    if format != MODEL_FORMAT {
        return Err(ContractViolation::BadMetadata {
            key: keys::FORMAT,
            value: format.to_owned(),
            expected: "\"formation-policy/1\"",
        });
    }
    if let Some(input) = entries.get(keys::INPUT)
        && input != INPUT_OCCUPANCY
    {
        return Err(ContractViolation::UnsupportedInput {
            input: input.clone(),
        });
    }
    let output = match entries.get(keys::OUTPUT) {
        None => PolicyOutput::Wheels,
        Some(text) => {
            PolicyOutput::parse(text).ok_or_else(|| ContractViolation::UnsupportedOutput {
                output: text.clone(),
            })?
        }
    };
    let aux = match entries.get(keys::AUX) {
        None => AuxLayout::PAPER,
        Some(text) => AuxLayout::parse(text).map_err(|reason| ContractViolation::BadAux {
            value: text.clone(),
            reason,
        })?,
    };
    let size_px: usize = parse_positive_int(entries, keys::SIZE_PX)?;
    if size_px > MAX_SIZE_PX {
        return Err(ContractViolation::BadMetadata {
            key: keys::SIZE_PX,
            value: size_px.to_string(),
            expected: "an image side of at most 1024 cells",
        });
    }
    let resolution_m = parse_positive_real(entries, keys::RESOLUTION_M)?;
    let beyond_text = required(entries, keys::BEYOND)?;
    let beyond =
        BeyondWindow::parse(beyond_text).ok_or_else(|| ContractViolation::BadMetadata {
            key: keys::BEYOND,
            value: beyond_text.to_owned(),
            expected: "\"drop\" or \"border\"",
        })?;
    let d_star_ref_m = entries.get(keys::D_STAR_REF_M).map_or(Ok(None), |_| {
        parse_positive_real(entries, keys::D_STAR_REF_M).map(Some)
    })?;
    let beams = parse_positive_int(entries, keys::BEAMS)?;
    let max_range = parse_positive_real(entries, keys::MAX_RANGE)?;
    let ranges = parse_ranges(entries, beams)?;
    let neighbours = parse_neighbours(entries)?;
    let v_train = parse_positive_real(entries, keys::V_TRAIN)?;
    let dataset_id = required(entries, keys::DATASET_ID)?.to_owned();

    const PARSED: [&str; 14] = [
        keys::FORMAT,
        keys::OUTPUT,
        keys::AUX,
        keys::RANGES,
        keys::NEIGHBOURS,
        keys::SIZE_PX,
        keys::RESOLUTION_M,
        keys::BEYOND,
        keys::D_STAR_REF_M,
        keys::INPUT,
        keys::BEAMS,
        keys::MAX_RANGE,
        keys::V_TRAIN,
        keys::DATASET_ID,
    ];
    parse_envelope(entries)?;
    let extra = entries
        .iter()
        .filter(|(key, _)| !PARSED.contains(&key.as_str()))
        .map(|(key, value)| (key.clone(), value.clone()))
        .collect();
    Ok(ModelMetadata {
        occupancy: OccupancySpec {
            size_px,
            resolution_m,
            beyond,
            d_star_ref_m,
        },
        beams,
        max_range,
        v_train,
        dataset_id,
        output,
        aux,
        ranges,
        neighbours,
        extra,
    })
}

/// The optional range input, checked against the model's LIDAR beams.
fn parse_ranges(
    entries: &BTreeMap<String, String>,
    beams: usize,
) -> Result<Option<RangeInput>, ContractViolation> {
    let Some(text) = entries.get(keys::RANGES) else {
        return Ok(None);
    };
    let bad = |reason| ContractViolation::BadRanges {
        value: text.clone(),
        reason,
    };
    let ranges = RangeInput::parse(text).map_err(bad)?;
    ranges.check_beams(beams).map_err(bad)?;
    Ok(Some(ranges))
}

/// The optional neighbour input.
fn parse_neighbours(
    entries: &BTreeMap<String, String>,
) -> Result<Option<NeighbourInput>, ContractViolation> {
    let Some(text) = entries.get(keys::NEIGHBOURS) else {
        return Ok(None);
    };
    NeighbourInput::parse(text)
        .map(Some)
        .map_err(|reason| ContractViolation::BadNeighbours {
            value: text.clone(),
            reason,
        })
}

fn required<'a>(
    entries: &'a BTreeMap<String, String>,
    key: &'static str,
) -> Result<&'a str, ContractViolation> {
    entries
        .get(key)
        .map(String::as_str)
        .ok_or(ContractViolation::MissingMetadata { key })
}

/// The required `key`'s value parsed as a `T` that `valid` accepts; else
/// [`ContractViolation::BadMetadata`] with the value and `expected`, what it must be.
fn parse_valid<T: std::str::FromStr>(
    entries: &BTreeMap<String, String>,
    key: &'static str,
    valid: impl Fn(&T) -> bool,
    expected: &'static str,
) -> Result<T, ContractViolation> {
    let text = required(entries, key)?;
    match text.trim().parse::<T>() {
        Ok(value) if valid(&value) => Ok(value),
        _ => Err(ContractViolation::BadMetadata {
            key,
            value: text.to_owned(),
            expected,
        }),
    }
}

fn parse_positive_int(
    entries: &BTreeMap<String, String>,
    key: &'static str,
) -> Result<usize, ContractViolation> {
    parse_valid(entries, key, |&n: &usize| n > 0, "a positive integer")
}

fn parse_positive_real(
    entries: &BTreeMap<String, String>,
    key: &'static str,
) -> Result<f64, ContractViolation> {
    parse_valid(
        entries,
        key,
        |&x: &f64| x.is_finite() && x > 0.0,
        "a finite number > 0",
    )
}

/// The sensor side of the contract: what a policy was trained for, as far as it records it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorContract {
    /// LIDAR beams of the training sensor, if recorded.
    pub beams: Option<usize>,
    /// LIDAR maximum range of the training sensor \[m\], if recorded.
    pub max_range: Option<f64>,
    /// The occupancy image the policy takes (its window is `size_px * resolution_m` on a side).
    pub occupancy: OccupancySpec,
}

impl From<&ModelMetadata> for SensorContract {
    fn from(meta: &ModelMetadata) -> SensorContract {
        SensorContract {
            beams: Some(meta.beams),
            max_range: Some(meta.max_range),
            occupancy: meta.occupancy,
        }
    }
}

/// How a robot's LIDAR differs from the one a policy was trained for: the model's value and the
/// sensor's. Each message reads after "model `id` ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SensorViolation {
    /// Another beam count: the image is drawn from a different ray pattern.
    #[error("was trained with {trained} LIDAR beams, but this robot's LIDAR has {actual}")]
    Beams {
        /// The model's beams.
        trained: usize,
        /// The sensor's beams.
        actual: usize,
    },
    /// Another maximum range: obstacles appear where the model never saw any, or vanish.
    #[error(
        "was trained with a LIDAR max_range of {trained} m, but this robot's LIDAR has max_range \
         {actual} m"
    )]
    MaxRange {
        /// The model's range \[m\].
        trained: f64,
        /// The sensor's range \[m\].
        actual: f64,
    },
    /// The model takes the scan's ranges in more sectors than the LIDAR has beams.
    #[error(
        "takes the scan's ranges in {sectors} sectors, but this robot's LIDAR has only {beams} \
         beams"
    )]
    RangeSectors {
        /// Sectors the model declares.
        sectors: usize,
        /// The sensor's beams.
        beams: usize,
    },
    /// The sensor cannot see as far as the edge of the model's image window.
    #[error(
        "takes a {window_m} m wide image window (its edge {reach_m} m away), but this robot's \
         LIDAR reaches only {actual} m"
    )]
    Window {
        /// Side of the image window \[m\].
        window_m: f64,
        /// Distance from the robot to the window's edge \[m\].
        reach_m: f64,
        /// The sensor's range \[m\].
        actual: f64,
    },
}

/// Relative tolerance of the range comparison: metadata stores the range as decimal text.
const RANGE_TOLERANCE: f64 = 1e-9;

/// Checks a robot's LIDAR against the sensor a policy was trained for, in this order:
///
/// 1. beams: equal to the recorded count;
/// 2. range: equal to the recorded maximum range (to a relative 1e-9);
/// 3. window: the sensor reaches the edge of the image window (half its side). A recorded range
///    is checked on the range itself in step 2, which also fixes what the window showed in
///    training (a model trained with a range short of its window saw that band empty, and still
///    does); this step therefore constrains policies that do not record their range.
pub fn check_sensor(trained: &SensorContract, lidar: &LidarSpec) -> Result<(), SensorViolation> {
    if let Some(beams) = trained.beams
        && beams != lidar.beams
    {
        return Err(SensorViolation::Beams {
            trained: beams,
            actual: lidar.beams,
        });
    }
    if let Some(range) = trained.max_range {
        let close = (lidar.max_range - range).abs() <= RANGE_TOLERANCE * range;
        // A NaN range is not close to anything.
        if !close {
            return Err(SensorViolation::MaxRange {
                trained: range,
                actual: lidar.max_range,
            });
        }
    } else {
        let window_m = trained.occupancy.window_m();
        let reach_m = window_m / 2.0;
        let reaches = lidar.max_range >= reach_m * (1.0 - RANGE_TOLERANCE);
        if !reaches {
            return Err(SensorViolation::Window {
                window_m,
                reach_m,
                actual: lidar.max_range,
            });
        }
    }
    Ok(())
}

/// One dimension of an expected shape.
#[derive(Debug, Clone, Copy)]
enum Dim {
    /// The batch dimension: must be dynamic.
    Batch,
    /// A fixed size.
    Exact(i64),
}

/// Checks the model's inputs and outputs against the contract for `size_px x size_px` images,
/// the scalars `aux`, the output, the ranges and the neighbours its metadata declares.
///
/// Input order does not matter (inputs are bound by name); names, element types and shapes do.
pub fn check_signature(
    inputs: &[TensorSignature],
    outputs: &[TensorSignature],
    size_px: usize,
    aux_layout: AuxLayout,
    output: PolicyOutput,
    ranges: Option<RangeInput>,
    neighbours: Option<NeighbourInput>,
) -> Result<(), ContractViolation> {
    let names = |list: &[TensorSignature]| list.iter().map(|t| t.name.clone()).collect::<Vec<_>>();
    let find = |name: &str| inputs.iter().find(|t| t.name == name);
    let wrong_inputs = || ContractViolation::InputNames {
        found: names(inputs),
        ranges: ranges.is_some(),
        neighbours: neighbours.is_some(),
    };
    let (Some(occupancy), Some(aux)) = (find(OCCUPANCY_INPUT), find(AUX_INPUT)) else {
        return Err(wrong_inputs());
    };
    let ranges_tensor = find(RANGES_INPUT);
    let neighbours_tensor = find(NEIGHBOURS_INPUT);
    if inputs.len() != 2 + usize::from(ranges.is_some()) + usize::from(neighbours.is_some())
        || ranges_tensor.is_some() != ranges.is_some()
        || neighbours_tensor.is_some() != neighbours.is_some()
    {
        return Err(wrong_inputs());
    }
    let [wheels] = outputs else {
        return Err(ContractViolation::OutputNames {
            found: names(outputs),
            expected: output,
        });
    };
    if wheels.name != output.name() {
        return Err(ContractViolation::OutputNames {
            found: names(outputs),
            expected: output,
        });
    }
    let side = i64::try_from(size_px).unwrap_or(i64::MAX);
    check_tensor(
        occupancy,
        &[
            Dim::Batch,
            Dim::Exact(1),
            Dim::Exact(side),
            Dim::Exact(side),
        ],
    )?;
    let width = i64::try_from(aux_layout.len()).unwrap_or(i64::MAX);
    check_tensor(aux, &[Dim::Batch, Dim::Exact(width)])?;
    if let (Some(tensor), Some(ranges)) = (ranges_tensor, ranges) {
        let sectors = i64::try_from(ranges.sectors).unwrap_or(i64::MAX);
        check_tensor(tensor, &[Dim::Batch, Dim::Exact(sectors)])?;
    }
    if let (Some(tensor), Some(neighbours)) = (neighbours_tensor, neighbours) {
        let slots = i64::try_from(neighbours.slots).unwrap_or(i64::MAX);
        let features = i64::try_from(neighbours.features()).unwrap_or(i64::MAX);
        check_tensor(
            tensor,
            &[Dim::Batch, Dim::Exact(slots), Dim::Exact(features)],
        )?;
    }
    check_tensor(wheels, &[Dim::Batch, Dim::Exact(2)])
}

fn check_tensor(tensor: &TensorSignature, expected: &[Dim]) -> Result<(), ContractViolation> {
    match &tensor.element {
        ElementKind::F32 => {}
        ElementKind::OtherTensor(ty) => {
            return Err(ContractViolation::ElementType {
                name: tensor.name.clone(),
                found: format!("a {ty} tensor"),
            });
        }
        ElementKind::NotTensor(kind) => {
            return Err(ContractViolation::ElementType {
                name: tensor.name.clone(),
                found: kind.clone(),
            });
        }
    }
    let matches = tensor.dims.len() == expected.len()
        && tensor
            .dims
            .iter()
            .zip(expected)
            .all(|(&found, want)| match want {
                Dim::Batch => found < 0,
                Dim::Exact(n) => found == *n,
            });
    if matches {
        return Ok(());
    }
    let expected_text = expected
        .iter()
        .map(|d| match d {
            Dim::Batch => "batch (dynamic)".to_owned(),
            Dim::Exact(n) => n.to_string(),
        })
        .collect::<Vec<_>>()
        .join(", ");
    Err(ContractViolation::Shape {
        name: tensor.name.clone(),
        expected: format!("[{expected_text}]"),
        found: tensor.dims.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 39: only the first dynamic dimension is the batch; any other unknown one is said to
    /// be dynamic, not "batch".
    #[test]
    fn a_shape_names_only_its_first_dynamic_dimension_batch() {
        let err = ContractViolation::Shape {
            name: "wheel_cmd".into(),
            expected: "[batch, 2]".into(),
            found: vec![-1, -1],
        };
        let message = err.to_string();
        assert!(
            message.contains("has shape [batch, dynamic], expected [batch, 2]"),
            "{message}"
        );
        assert_eq!(
            DimsDisplay(&[-1, 1, 50, 50]).to_string(),
            "[batch, 1, 50, 50]"
        );
    }

    fn paper_metadata() -> BTreeMap<String, String> {
        [
            (keys::FORMAT, "formation-policy/1"),
            (keys::SIZE_PX, "50"),
            (keys::RESOLUTION_M, "0.1"),
            (keys::BEYOND, "border"),
            (keys::BEAMS, "900"),
            (keys::MAX_RANGE, "10"),
            (keys::V_TRAIN, "0.7"),
            (keys::DATASET_ID, "ds-1234"),
            ("formation.train.epochs", "40"),
            ("formation.dagger.iteration", "2"),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect()
    }

    fn tensor(name: &str, dims: &[i64]) -> TensorSignature {
        TensorSignature {
            name: name.to_owned(),
            element: ElementKind::F32,
            dims: dims.to_vec(),
        }
    }

    fn paper_inputs() -> Vec<TensorSignature> {
        vec![
            tensor("occupancy", &[-1, 1, 50, 50]),
            tensor("aux", &[-1, 2]),
        ]
    }

    fn paper_outputs() -> Vec<TensorSignature> {
        vec![tensor("wheels", &[-1, 2])]
    }

    /// What a model's metadata declares of its signature beside its 50 px images.
    #[derive(Clone, Copy)]
    struct Declared {
        aux: AuxLayout,
        output: PolicyOutput,
        ranges: Option<RangeInput>,
        neighbours: Option<NeighbourInput>,
    }

    impl Declared {
        /// What a model that declares nothing takes and gives: the paper's.
        const NOTHING: Declared = Declared {
            aux: AuxLayout::PAPER,
            output: PolicyOutput::Wheels,
            ranges: None,
            neighbours: None,
        };
    }

    /// [`check_signature`] of `inputs` and `outputs` for 50 px images and `declared`.
    fn check_declared(
        inputs: &[TensorSignature],
        outputs: &[TensorSignature],
        declared: Declared,
    ) -> Result<(), ContractViolation> {
        check_signature(
            inputs,
            outputs,
            50,
            declared.aux,
            declared.output,
            declared.ranges,
            declared.neighbours,
        )
    }

    /// [`check_declared`] for a model that declares nothing.
    fn check_paper(
        inputs: &[TensorSignature],
        outputs: &[TensorSignature],
    ) -> Result<(), ContractViolation> {
        check_declared(inputs, outputs, Declared::NOTHING)
    }

    /// Asserts that `entries` with `key` (an input declaration) set to `value` are refused, the
    /// message naming `key` and saying `fault`.
    fn assert_declaration_refused(
        mut entries: BTreeMap<String, String>,
        key: &str,
        value: &str,
        fault: &str,
    ) {
        entries.insert(key.into(), value.into());
        let message = parse_metadata(&entries).unwrap_err().to_string();
        assert!(
            message.contains(key) && message.contains(fault),
            "{value}: {message}"
        );
    }

    #[test]
    fn a_declared_range_input_is_parsed_checked_and_needs_its_tensor() {
        let mut entries = paper_metadata();
        assert_eq!(parse_metadata(&entries).unwrap().ranges, None);
        entries.insert(keys::RANGES.into(), "sectors=100,clip=3".into());
        let meta = parse_metadata(&entries).expect("valid");
        let ranges = meta.ranges.expect("declared");
        assert_eq!((ranges.sectors, ranges.clip), (100, 3.0));
        assert_eq!(meta.io().ranges, Some(ranges));
        assert!(!meta.extra.contains_key(keys::RANGES));
        let mut inputs = paper_inputs();
        let declared = Declared {
            ranges: Some(ranges),
            ..Declared::NOTHING
        };
        let check = |inputs: &[TensorSignature]| check_declared(inputs, &paper_outputs(), declared);
        assert!(matches!(
            check(&inputs),
            Err(ContractViolation::InputNames { ranges: true, .. })
        ));
        inputs.push(tensor("ranges", &[-1, 90]));
        assert!(matches!(
            check(&inputs),
            Err(ContractViolation::Shape { ref name, .. }) if name == "ranges"
        ));
        inputs[2] = tensor("ranges", &[-1, 100]);
        check(&inputs).expect("the declared input");

        for (value, fault) in [
            ("sectors=100", "is not a range input"),
            ("sectors=1000,clip=3", "out of range"),
            ("sectors=360,clip=3", "at least as many LIDAR beams"),
        ] {
            let mut entries = paper_metadata();
            if value.starts_with("sectors=360") {
                entries.insert(keys::BEAMS.into(), "180".into());
            }
            assert_declaration_refused(entries, keys::RANGES, value, fault);
        }
    }

    #[test]
    fn a_declared_neighbour_input_is_parsed_checked_and_needs_its_tensor() {
        let mut entries = paper_metadata();
        assert_eq!(parse_metadata(&entries).unwrap().neighbours, None);
        entries.insert(
            keys::NEIGHBOURS.into(),
            "slots=8,threshold=1.3,nearest=2".into(),
        );
        let meta = parse_metadata(&entries).expect("valid");
        let neighbours = meta.neighbours.expect("declared");
        assert_eq!(
            (neighbours.slots, neighbours.threshold, neighbours.nearest),
            (8, 1.3, 2)
        );
        assert_eq!(meta.io().neighbours, Some(neighbours));
        assert_eq!(meta.io().ranges, None);
        assert!(!meta.extra.contains_key(keys::NEIGHBOURS));
        let mut inputs = paper_inputs();
        let declared = Declared {
            neighbours: Some(neighbours),
            ..Declared::NOTHING
        };
        let check = |inputs: &[TensorSignature]| check_declared(inputs, &paper_outputs(), declared);
        let missing = check(&inputs).unwrap_err();
        assert!(matches!(
            missing,
            ContractViolation::InputNames {
                neighbours: true,
                ranges: false,
                ..
            }
        ));
        assert!(
            missing
                .to_string()
                .contains("expected exactly [occupancy, aux, neighbours]"),
            "{missing}"
        );
        inputs.push(tensor("neighbours", &[-1, 8]));
        assert!(matches!(
            check(&inputs),
            Err(ContractViolation::Shape { ref name, .. }) if name == "neighbours"
        ));
        inputs[2] = tensor("neighbours", &[-1, 6, 4]);
        assert!(matches!(
            check(&inputs),
            Err(ContractViolation::Shape { ref name, .. }) if name == "neighbours"
        ));
        inputs[2] = tensor("neighbours", &[-1, 8, 4]);
        check(&inputs).expect("the declared input");
        // With the hidden pairs' step aside (`hidden=1`) a slot holds six numbers, not four.
        let hidden = Declared {
            neighbours: Some(neighbours.with_hidden(true)),
            ..Declared::NOTHING
        };
        let shape = check_declared(&inputs, &paper_outputs(), hidden).unwrap_err();
        assert!(shape.to_string().contains("neighbours"), "{shape}");
        let mut six = inputs.clone();
        six[2] = tensor("neighbours", &[-1, 8, 6]);
        check_declared(&six, &paper_outputs(), hidden).expect("six numbers a slot");
        assert!(check(&six).is_err());

        // An undeclared `neighbours` tensor is refused, saying the metadata declares none.
        let undeclared = check_paper(&inputs, &paper_outputs()).unwrap_err();
        assert!(
            undeclared
                .to_string()
                .contains("declares no `formation.neighbours`"),
            "{undeclared}"
        );

        // Both tensor inputs at once, in any order.
        let mut both = vec![tensor("ranges", &[-1, 100])];
        both.extend(inputs.iter().cloned());
        let ranges = Some(RangeInput::new(100, 3.0).unwrap());
        check_declared(
            &both,
            &paper_outputs(),
            Declared {
                ranges,
                neighbours: Some(neighbours),
                ..Declared::NOTHING
            },
        )
        .expect("ranges and neighbours");

        for (value, fault) in [
            ("slots=8", "is not a neighbour input"),
            ("slots=80,threshold=1.3,nearest=2", "out of range"),
            ("slots=8,threshold=0.5,nearest=2", "out of range"),
        ] {
            assert_declaration_refused(paper_metadata(), keys::NEIGHBOURS, value, fault);
        }
    }

    #[test]
    fn paper_metadata_parses_with_extras_kept() {
        let meta = parse_metadata(&paper_metadata()).expect("valid metadata");
        assert_eq!(
            meta.occupancy,
            OccupancySpec {
                size_px: 50,
                resolution_m: 0.1,
                beyond: BeyondWindow::Border,
                d_star_ref_m: None,
            }
        );
        assert_eq!((meta.beams, meta.max_range, meta.v_train), (900, 10.0, 0.7));
        assert_eq!(meta.dataset_id, "ds-1234");
        let extra: Vec<&str> = meta.extra.keys().map(String::as_str).collect();
        assert_eq!(
            extra,
            ["formation.dagger.iteration", "formation.train.epochs"]
        );
    }

    #[test]
    fn the_scalars_beside_the_image_are_declared_and_set_the_aux_width() {
        let meta = parse_metadata(&paper_metadata()).unwrap();
        assert_eq!(meta.aux, AuxLayout::PAPER);
        assert_eq!(meta.io().aux.len(), 2);
        let mut entries = paper_metadata();
        entries.insert(keys::AUX.into(), "d_star".into());
        let meta = parse_metadata(&entries).unwrap();
        assert_eq!(meta.aux.len(), 1);
        assert!(!meta.extra.contains_key(keys::AUX));
        let one_wide = vec![
            tensor("occupancy", &[-1, 1, 50, 50]),
            tensor("aux", &[-1, 1]),
        ];
        check_declared(
            &one_wide,
            &paper_outputs(),
            Declared {
                aux: meta.aux,
                ..Declared::NOTHING
            },
        )
        .expect("a one-wide aux for one declared scalar");
        assert!(matches!(
            check_declared(
                &paper_inputs(),
                &paper_outputs(),
                Declared {
                    aux: meta.aux,
                    ..Declared::NOTHING
                }
            ),
            Err(ContractViolation::Shape { .. })
        ));
        entries.insert(keys::AUX.into(), "delta_phi,wind".into());
        let message = parse_metadata(&entries).unwrap_err().to_string();
        assert!(
            message.contains("formation.aux") && message.contains("\"wind\""),
            "{message}"
        );
    }

    #[test]
    fn the_output_is_declared_in_the_metadata_and_an_unknown_one_is_refused_by_name() {
        // Absent: today's wheels.
        let meta = parse_metadata(&paper_metadata()).unwrap();
        assert_eq!(meta.output, PolicyOutput::Wheels);
        let mut entries = paper_metadata();
        entries.insert(keys::OUTPUT.into(), "formation_velocity".into());
        let meta = parse_metadata(&entries).unwrap();
        assert_eq!(meta.output, PolicyOutput::FormationVelocity);
        assert!(!meta.extra.contains_key(keys::OUTPUT));
        // The declared output's tensor must be the model's one output.
        let outputs = [tensor("formation_velocity", &[-1, 2])];
        check_declared(
            &paper_inputs(),
            &outputs,
            Declared {
                output: PolicyOutput::FormationVelocity,
                ..Declared::NOTHING
            },
        )
        .expect("declared and present");
        let err = check_declared(
            &paper_inputs(),
            &paper_outputs(),
            Declared {
                output: PolicyOutput::FormationVelocity,
                ..Declared::NOTHING
            },
        )
        .unwrap_err();
        let message = err.to_string();
        assert!(
            message.contains("outputs are [wheels], expected exactly [formation_velocity]")
                && message.contains("formation.output"),
            "{message}"
        );
        assert!(check_paper(&paper_inputs(), &outputs).is_err());
        entries.insert(keys::OUTPUT.into(), "torques".into());
        let message = parse_metadata(&entries).unwrap_err().to_string();
        assert!(
            message.contains("declares the output \"torques\" (formation.output)")
                && message.contains("cannot use"),
            "{message}"
        );
    }

    #[test]
    fn each_missing_required_key_is_named() {
        for key in [
            keys::FORMAT,
            keys::SIZE_PX,
            keys::RESOLUTION_M,
            keys::BEYOND,
            keys::BEAMS,
            keys::MAX_RANGE,
            keys::V_TRAIN,
            keys::DATASET_ID,
        ] {
            let mut entries = paper_metadata();
            entries.remove(key);
            assert_eq!(
                parse_metadata(&entries),
                Err(ContractViolation::MissingMetadata { key })
            );
        }
    }

    #[test]
    fn bad_metadata_values_are_refused_with_the_value() {
        for (key, value) in [
            (keys::FORMAT, "formation-policy/2"),
            (keys::SIZE_PX, "0"),
            (keys::SIZE_PX, "fifty"),
            (keys::RESOLUTION_M, "-0.1"),
            (keys::BEYOND, "clip"),
            (keys::BEAMS, "9.5"),
            (keys::MAX_RANGE, "inf"),
            (keys::V_TRAIN, "NaN"),
            (keys::D_STAR_REF_M, "0"),
            (keys::D_STAR_REF_M, "one"),
        ] {
            let mut entries = paper_metadata();
            entries.insert(key.to_owned(), value.to_owned());
            match parse_metadata(&entries) {
                Err(ContractViolation::BadMetadata {
                    key: k, value: v, ..
                }) => {
                    assert_eq!((k, v.as_str()), (key, value));
                }
                other => panic!("{key} = {value}: expected BadMetadata, got {other:?}"),
            }
        }
    }

    #[test]
    fn a_window_scaled_with_d_star_is_declared_in_the_metadata() {
        let mut entries = paper_metadata();
        entries.insert(keys::D_STAR_REF_M.to_owned(), "1.25".to_owned());
        entries.insert(keys::INPUT.to_owned(), INPUT_OCCUPANCY.to_owned());
        let meta = parse_metadata(&entries).expect("valid metadata");
        assert_eq!(meta.occupancy.d_star_ref_m, Some(1.25));
        assert!(meta.extra.is_empty() || !meta.extra.contains_key(keys::D_STAR_REF_M));
    }

    #[test]
    fn an_input_the_agent_cannot_feed_is_refused_by_name() {
        let mut entries = paper_metadata();
        entries.insert(keys::INPUT.to_owned(), "scan-ranges".to_owned());
        let err = parse_metadata(&entries).expect_err("an agent renders only occupancy images");
        assert_eq!(
            err,
            ContractViolation::UnsupportedInput {
                input: "scan-ranges".into()
            }
        );
        let text = err.to_string();
        assert!(
            text.contains("\"scan-ranges\"") && text.contains(keys::INPUT),
            "{text}"
        );
    }

    #[test]
    fn an_oversized_image_side_is_refused() {
        let mut entries = paper_metadata();
        entries.insert(keys::SIZE_PX.to_owned(), "1025".to_owned());
        assert!(matches!(
            parse_metadata(&entries),
            Err(ContractViolation::BadMetadata {
                key: keys::SIZE_PX,
                ..
            })
        ));
        entries.insert(keys::SIZE_PX.to_owned(), "1024".to_owned());
        parse_metadata(&entries).expect("1024 is the largest allowed side");
    }

    #[test]
    fn the_sensor_check_covers_beams_range_and_window() {
        let meta = parse_metadata(&paper_metadata()).expect("valid");
        let trained = SensorContract::from(&meta);
        let paper = LidarSpec::default();
        check_sensor(&trained, &paper).expect("the paper's sensor (noise is no part of it)");
        assert_eq!(
            check_sensor(
                &trained,
                &LidarSpec {
                    beams: 360,
                    ..paper
                }
            ),
            Err(SensorViolation::Beams {
                trained: 900,
                actual: 360
            })
        );
        for range in [5.0, 1e-9, 10.5, f64::NAN] {
            let err = check_sensor(
                &trained,
                &LidarSpec {
                    max_range: range,
                    ..paper
                },
            )
            .expect_err("another range");
            assert!(
                matches!(err, SensorViolation::MaxRange { trained, .. } if trained == 10.0),
                "{err:?}"
            );
        }
        let message = check_sensor(
            &trained,
            &LidarSpec {
                max_range: 5.0,
                ..paper
            },
        )
        .expect_err("another range")
        .to_string();
        assert!(
            message.contains("max_range of 10 m") && message.contains("max_range 5 m"),
            "{message}"
        );

        // Without a recorded range, the sensor must reach the 5 m window's edge, 2.5 m away.
        let unrecorded = SensorContract {
            max_range: None,
            ..trained
        };
        check_sensor(
            &unrecorded,
            &LidarSpec {
                max_range: 2.5,
                ..paper
            },
        )
        .expect("reaches the edge");
        let short = LidarSpec {
            max_range: 1.0,
            ..paper
        };
        let err = check_sensor(&unrecorded, &short).expect_err("short of the window");
        assert_eq!(
            err,
            SensorViolation::Window {
                window_m: 5.0,
                reach_m: 2.5,
                actual: 1.0
            }
        );
        assert!(err.to_string().contains("5 m wide"), "{err}");
    }

    #[test]
    fn paper_signature_passes_in_any_input_order() {
        check_paper(&paper_inputs(), &paper_outputs()).expect("paper contract");
        let mut swapped = paper_inputs();
        swapped.reverse();
        check_paper(&swapped, &paper_outputs()).expect("order does not matter");
    }

    #[test]
    fn wrong_or_extra_names_are_refused() {
        let renamed = vec![tensor("image", &[-1, 1, 50, 50]), tensor("aux", &[-1, 2])];
        assert_eq!(
            check_paper(&renamed, &paper_outputs()),
            Err(ContractViolation::InputNames {
                found: vec!["image".into(), "aux".into()],
                ranges: false,
                neighbours: false,
            })
        );
        let mut extra = paper_inputs();
        extra.push(tensor("speed", &[-1, 1]));
        assert!(matches!(
            check_paper(&extra, &paper_outputs()),
            Err(ContractViolation::InputNames { .. })
        ));
        let outputs = vec![tensor("wheels", &[-1, 2]), tensor("value", &[-1, 1])];
        assert!(matches!(
            check_paper(&paper_inputs(), &outputs),
            Err(ContractViolation::OutputNames { .. })
        ));
        assert!(matches!(
            check_paper(&paper_inputs(), &[tensor("cmd", &[-1, 2])]),
            Err(ContractViolation::OutputNames { .. })
        ));
    }

    #[test]
    fn image_side_must_match_size_px_and_batch_must_be_dynamic() {
        let small = vec![
            tensor("occupancy", &[-1, 1, 40, 40]),
            tensor("aux", &[-1, 2]),
        ];
        let err = check_paper(&small, &paper_outputs()).expect_err("40 px image for size_px 50");
        assert_eq!(
            err.to_string(),
            "`occupancy` has shape [batch, 1, 40, 40], expected [batch (dynamic), 1, 50, 50]"
        );
        let fixed_batch = vec![tensor("occupancy", &[1, 1, 50, 50]), tensor("aux", &[1, 2])];
        assert!(matches!(
            check_paper(&fixed_batch, &paper_outputs()),
            Err(ContractViolation::Shape { .. })
        ));
        let flat_aux = vec![
            tensor("occupancy", &[-1, 1, 50, 50]),
            tensor("aux", &[-1, 3]),
        ];
        assert!(matches!(
            check_paper(&flat_aux, &paper_outputs()),
            Err(ContractViolation::Shape { name, .. }) if name == "aux"
        ));
    }

    #[test]
    fn non_f32_tensors_are_refused() {
        let mut inputs = paper_inputs();
        inputs[0].element = ElementKind::OtherTensor("Float64".into());
        assert_eq!(
            check_paper(&inputs, &paper_outputs()),
            Err(ContractViolation::ElementType {
                name: "occupancy".into(),
                found: "a Float64 tensor".into()
            })
        );
        let mut outputs = paper_outputs();
        outputs[0].element = ElementKind::NotTensor("a sequence".into());
        assert!(matches!(
            check_paper(&paper_inputs(), &outputs),
            Err(ContractViolation::ElementType { .. })
        ));
    }

    #[test]
    fn the_envelope_is_read_when_recorded_and_refused_when_malformed() {
        let mut entries = paper_metadata();
        assert_eq!(
            parse_metadata(&entries).unwrap().envelope(),
            ModelEnvelope::default()
        );
        entries.insert(keys::D_STAR_MIN.into(), "0.800000011920929".into());
        entries.insert(keys::D_STAR_MAX.into(), "2.5".into());
        entries.insert(keys::TEAM_SIZES.into(), "5, 3,7".into());
        entries.insert(keys::NOISE_STD.into(), "0.03".into());
        let envelope = parse_metadata(&entries).unwrap().envelope();
        assert_eq!(envelope.d_star, Some((0.800000011920929, 2.5)));
        assert_eq!(envelope.team_sizes, [3, 5, 7]);
        assert_eq!(envelope.noise_std, Some(0.03));
        assert!(envelope.admits_d_star(0.8) && envelope.admits_d_star(2.5));
        assert!(!envelope.admits_d_star(3.0) && !envelope.admits_d_star(0.7));
        assert!(ModelEnvelope::default().admits_d_star(50.0));

        for (key, value) in [
            (keys::D_STAR_MAX, "0.5"),
            (keys::D_STAR_MIN, "-1"),
            (keys::TEAM_SIZES, "3,x"),
            (keys::NOISE_STD, "nan"),
        ] {
            let mut bad = entries.clone();
            bad.insert(key.into(), value.into());
            assert!(
                matches!(
                    parse_metadata(&bad),
                    Err(ContractViolation::BadMetadata { .. })
                ),
                "{key} = {value}"
            );
        }
        let mut half = entries.clone();
        half.remove(keys::D_STAR_MAX);
        assert!(matches!(
            parse_metadata(&half),
            Err(ContractViolation::MissingMetadata { key }) if key == keys::D_STAR_MAX
        ));
    }
}
