//! The on-disk dataset of (occupancy image, delta_phi, d*) -> wheel command samples.
//!
//! A dataset is a directory holding `manifest.json` and shards `shard-NNNNNN.safetensors`:
//!
//! - The manifest carries [`DATASET_FORMAT`], the format version [`DATASET_VERSION`], the
//!   [`DatasetHeader`] (`dataset_id` and the [`CollectionSettings`]: occupancy settings, LIDAR,
//!   `v_train`, seed, scenario, and the ranges, neighbours and label law if any), one
//!   [`ShardEntry`] per shard (file, samples, DAgger iteration, byte size, FNV-1a checksum) and the
//!   total sample count.
//! - A shard holds `occupancy` U8 `[N, S, S]`, `aux` F32 `[N, 2]` (delta_phi, d*), `wheels` F32
//!   `[N, 2]` (left, right), `iteration` U32 `[N]`, `run` U32 `[N]` and `robot` U8 `[N]`; its
//!   safetensors `__metadata__` repeats the format, version, dataset id and iteration.
//! - A dataset whose samples carry their scan's ranges ([`RangeInput`], issue 34) declares them in
//!   the manifest as `"ranges": "sectors=K,clip=C"` and is format version 2
//!   ([`DATASET_VERSION`]); each of its shards also holds `ranges` F32 `[N, K]`. A dataset without
//!   them is version 1 ([`DATASET_VERSION_WITHOUT_RANGES`]), byte for byte what builds before
//!   ranges wrote, with the same `dataset_id`. The reader takes both, and refuses a version 2
//!   manifest without `ranges` or a version 1 manifest with them.
//! - A dataset whose samples carry the neighbours each robot detects in its own scan
//!   ([`NeighbourInput`], issue 34) declares them in the manifest as
//!   `"neighbours": "slots=K,threshold=T,nearest=M"` and is format version 3 ([`DATASET_VERSION`]),
//!   with or without ranges; each of its shards also holds `neighbours` F32 `[N, K, 4]` (per slot
//!   `x/d*, y/d*, held, present`; `[N, K, 6]` with `,hidden=1`, then also `hx, hy`). A dataset without neighbours keeps version 1 or 2, its bytes and
//!   its `dataset_id`. The reader refuses a version 3 manifest without `neighbours` or a version 1
//!   or 2 manifest with them.
//! - A dataset labelled by a law other than the expert's default records it as `"labels"`
//!   ([`LabelLaw`]), folded into `dataset_id`; one labelled by the default has no such key and
//!   keeps the id and bytes of before.
//!
//! Every file is written under a temporary name in the same directory, synced and renamed, and the
//! manifest is rewritten after each shard, so an interrupted collection leaves a valid dataset of
//! the shards it finished. DAgger appends shards with a new iteration number to an existing dataset
//! ([`DatasetWriter::append`]). The Python trainer reads the same files with numpy and safetensors.
//!
//! [`DatasetReader::open`] checks the manifest and every shard's size cheaply; reading a shard also
//! checks its checksum, tensor names, dtypes and shapes. Every failure names the file and the fix.

use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};

use formation_proto::{NeighbourInput, OccupancySpec, RangeInput, RangeInputError, SimulatedLidar};
use safetensors::tensor::{Dtype, SafeTensorError, SafeTensors, TensorView};
use serde::{Deserialize, Serialize};

use crate::difference::{Difference, FirstDifference};
use crate::digest::Fnv1a64;
use crate::label_law::LabelLaw;

/// The `format` string of every dataset manifest.
pub const DATASET_FORMAT: &str = "formation-dataset";
/// The newest manifest/shard layout version, which this build writes for a dataset whose samples
/// carry the neighbours detected in their scan (a manifest with `neighbours`, shards with a
/// `neighbours` tensor), with or without ranges.
pub const DATASET_VERSION: u32 = 3;
/// The layout version of a dataset with ranges and without neighbours (a manifest with `ranges`,
/// shards with a `ranges` tensor).
pub const DATASET_VERSION_WITH_RANGES: u32 = 2;
/// The layout version of a dataset without ranges or neighbours: what this build writes for one,
/// and what every build before ranges wrote. The reader takes all three versions.
pub const DATASET_VERSION_WITHOUT_RANGES: u32 = 1;
/// Samples per shard unless [`DatasetWriter::with_shard_size`] says otherwise (~41 MB of images).
pub const DEFAULT_SHARD_SIZE: usize = 16384;
/// The manifest's file name inside a dataset directory.
pub const MANIFEST_FILE: &str = "manifest.json";

/// The layout version of a dataset with or without ranges and neighbours: 3 with neighbours,
/// else 2 with ranges, else 1.
pub fn dataset_version(ranges: Option<RangeInput>, neighbours: Option<NeighbourInput>) -> u32 {
    match (ranges, neighbours) {
        (_, Some(_)) => DATASET_VERSION,
        (Some(_), None) => DATASET_VERSION_WITH_RANGES,
        (None, None) => DATASET_VERSION_WITHOUT_RANGES,
    }
}

/// What produced a dataset: the settings every sample shares. Appending checks it matches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetHeader {
    /// Layout version ([`dataset_version`] of `ranges` and `neighbours`); `version` in the
    /// manifest.
    pub format_version: u32,
    /// The collection settings, written in place as the header's own keys.
    #[serde(flatten)]
    pub settings: CollectionSettings,
    /// Deterministic id of the settings above (16 hex digits); see [`DatasetHeader::new`].
    pub dataset_id: String,
}

/// How a dataset's samples were collected: the settings its [`DatasetHeader`] and its
/// [`Manifest`] both hold, serialized flat (`#[serde(flatten)]`) as keys of theirs, in this
/// order, so `manifest.json` and a part's header keep the keys and bytes they had before these
/// fields were gathered here. Every one of them is folded into `dataset_id`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CollectionSettings {
    /// How the occupancy images were rendered.
    pub occupancy: OccupancySpec,
    /// The LIDAR the scans came from.
    pub lidar: SimulatedLidar,
    /// The speed v* \[m/s\] the wheel labels were produced at (deployment scales by v*/v_train).
    pub v_train: f64,
    /// Base seed of the collection.
    pub seed: u64,
    /// Name of the scenario the samples came from.
    pub scenario: String,
    /// The scan's ranges each sample carries beside its image, if any
    /// ([`DatasetHeader::with_ranges`]); serialized as `"sectors=K,clip=C"`, absent when none.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "declared_text"
    )]
    pub ranges: Option<RangeInput>,
    /// The neighbours detected in its scan each sample carries beside its image, if any
    /// ([`DatasetHeader::with_neighbours`]); serialized as `"slots=K,threshold=T,nearest=M"`,
    /// absent when none.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "declared_text"
    )]
    pub neighbours: Option<NeighbourInput>,
    /// The law that labelled the samples ([`DatasetHeader::with_labels`]): `"labels": {...}`,
    /// absent for the expert's default.
    #[serde(default, skip_serializing_if = "LabelLaw::is_default")]
    pub labels: LabelLaw,
}

/// An optional model input declaration (`Option<RangeInput>`, `Option<NeighbourInput>`) as its
/// metadata text (the type's `Display` and `FromStr`, the one definition of it), or nothing.
pub(crate) mod declared_text {
    use std::fmt::Display;
    use std::str::FromStr;

    use serde::{Deserialize, Deserializer, Serializer};

    pub(crate) fn serialize<T: Display, S: Serializer>(
        declared: &Option<T>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        match declared {
            Some(declared) => serializer.collect_str(declared),
            None => serializer.serialize_none(),
        }
    }

    pub(crate) fn deserialize<'de, T, D>(deserializer: D) -> Result<Option<T>, D::Error>
    where
        T: FromStr,
        T::Err: Display,
        D: Deserializer<'de>,
    {
        Option::<String>::deserialize(deserializer)?
            .map(|text| text.parse::<T>().map_err(serde::de::Error::custom))
            .transpose()
    }
}

impl DatasetHeader {
    /// A header of samples without ranges (format version [`DATASET_VERSION_WITHOUT_RANGES`])
    /// whose `dataset_id` is a stable hash of every other field, so the same collection settings
    /// always give the same id. [`DatasetHeader::with_ranges`] adds ranges,
    /// [`DatasetHeader::with_neighbours`] neighbours.
    pub fn new(
        occupancy: OccupancySpec,
        lidar: SimulatedLidar,
        v_train: f64,
        seed: u64,
        scenario: impl Into<String>,
    ) -> DatasetHeader {
        let mut header = DatasetHeader {
            format_version: DATASET_VERSION_WITHOUT_RANGES,
            settings: CollectionSettings {
                occupancy,
                lidar,
                v_train,
                seed,
                scenario: scenario.into(),
                ranges: None,
                neighbours: None,
                labels: LabelLaw::default(),
            },
            dataset_id: String::new(),
        };
        header.dataset_id = header.settings_hash();
        header
    }

    /// The same settings with samples labelled by `labels`; recomputes `dataset_id`.
    /// `with_labels(LabelLaw::default())` changes nothing.
    pub fn with_labels(mut self, labels: LabelLaw) -> DatasetHeader {
        self.settings.labels = labels;
        self.dataset_id = self.settings_hash();
        self
    }

    /// The same settings with samples that carry (`Some`) or do not carry (`None`) their scan's
    /// ranges: sets the format version to match ([`dataset_version`]) and recomputes
    /// `dataset_id`. `with_ranges(None)` gives back exactly [`DatasetHeader::new`]'s header.
    pub fn with_ranges(mut self, ranges: Option<RangeInput>) -> DatasetHeader {
        self.settings.ranges = ranges;
        self.format_version = dataset_version(ranges, self.settings.neighbours);
        self.dataset_id = self.settings_hash();
        self
    }

    /// The same settings with samples that carry (`Some`) or do not carry (`None`) the
    /// neighbours detected in their scan: sets the format version to match
    /// ([`dataset_version`]: 3 with neighbours) and recomputes `dataset_id`.
    /// `with_neighbours(None)` on a header without neighbours changes nothing.
    pub fn with_neighbours(mut self, neighbours: Option<NeighbourInput>) -> DatasetHeader {
        self.settings.neighbours = neighbours;
        self.format_version = dataset_version(self.settings.ranges, neighbours);
        self.dataset_id = self.settings_hash();
        self
    }

    /// Checks that the format version is the one of the header's ranges and neighbours
    /// ([`dataset_version`]).
    pub fn check(&self) -> Result<(), DatasetError> {
        if self.format_version != dataset_version(self.settings.ranges, self.settings.neighbours) {
            return Err(DatasetError::InconsistentHeader {
                version: self.format_version,
                ranges: self.settings.ranges,
                neighbours: self.settings.neighbours,
            });
        }
        Ok(())
    }

    /// Sectors of each sample's ranges: `K`, or 0 for a dataset without ranges.
    pub fn range_sectors(&self) -> usize {
        self.settings.ranges.map_or(0, |r| r.sectors)
    }

    /// Slots of each sample's neighbours: `K`, or 0 for a dataset without neighbours.
    pub fn neighbour_slots(&self) -> usize {
        self.settings.neighbours.map_or(0, |n| n.slots)
    }

    /// Values of each sample's neighbours: `K * features`, or 0 for a dataset without neighbours.
    pub fn neighbour_values(&self) -> usize {
        self.settings.neighbours.map_or(0, |n| n.len())
    }

    /// Cells in one occupancy image (`size_px^2`).
    pub fn cells(&self) -> usize {
        self.settings.occupancy.size_px * self.settings.occupancy.size_px
    }

    fn settings_hash(&self) -> String {
        let settings = &self.settings;
        let mut hash = Fnv1a64::new();
        hash.update_field(DATASET_FORMAT.as_bytes());
        hash.update_field(&self.format_version.to_le_bytes());
        hash.update_field(&(settings.occupancy.size_px as u64).to_le_bytes());
        hash.update_field(&settings.occupancy.resolution_m.to_le_bytes());
        hash.update_field(settings.occupancy.beyond.as_str().as_bytes());
        // Only a scaled window adds a field, so a fixed window's dataset id is unchanged.
        if let Some(reference) = settings.occupancy.d_star_ref_m {
            hash.update_field(&reference.to_le_bytes());
        }
        hash.update_field(&(settings.lidar.spec.beams as u64).to_le_bytes());
        hash.update_field(&settings.lidar.spec.max_range.to_le_bytes());
        settings
            .lidar
            .noise
            .hash_fields(&mut |bytes| hash.update_field(bytes));
        hash.update_field(&settings.v_train.to_le_bytes());
        hash.update_field(&settings.seed.to_le_bytes());
        hash.update_field(settings.scenario.as_bytes());
        // Only a dataset with ranges adds a field, so one without keeps its id.
        if let Some(ranges) = settings.ranges {
            hash.update_field(ranges.to_string().as_bytes());
        }
        // Only a dataset with neighbours adds a field, so one without keeps its id.
        if let Some(neighbours) = settings.neighbours {
            hash.update_field(neighbours.to_string().as_bytes());
        }
        // Only a law other than the default adds fields, so a default-labelled id is unchanged.
        settings
            .labels
            .hash_fields(&mut |bytes| hash.update_field(bytes));
        hash.hex()
    }

    /// The first field in which `self` and `other` differ, with both values, if any.
    pub(crate) fn first_difference(&self, other: &DatasetHeader) -> Option<Difference> {
        let ranges = |h: &DatasetHeader| {
            h.settings
                .ranges
                .map_or_else(|| "none".to_owned(), |r| r.to_string())
        };
        let neighbours = |h: &DatasetHeader| {
            h.settings
                .neighbours
                .map_or_else(|| "none".to_owned(), |n| n.to_string())
        };
        FirstDifference::of(self, other)
            .display("range input", ranges)
            .display("neighbour input", neighbours)
            .display("label law", |h| h.settings.labels)
            .display("format version", |h| h.format_version)
            .debug("occupancy settings", |h| h.settings.occupancy)
            .debug("LIDAR", |h| h.settings.lidar)
            .display("v_train", |h| h.settings.v_train)
            .display("seed", |h| h.settings.seed)
            .display("scenario", |h| &h.settings.scenario)
            .display("dataset_id", |h| &h.dataset_id)
            .found()
    }
}

/// One training sample: what one robot saw at one tick and the command the expert gave it.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// `size_px * size_px` occupancy cells, row-major (1 = occupied).
    pub occupancy: Vec<u8>,
    /// `wrap(phi* - theta)` \[rad\], in (-pi, pi].
    pub delta_phi: f32,
    /// Desired pairwise distance d* \[m\].
    pub d_star: f32,
    /// Label: (left, right) wheel speeds \[m/s\] at `v_train`.
    pub wheels: [f32; 2],
    /// The scan's ranges, one value a sector ([`RangeInput`]): `K` values for a dataset that
    /// declares ranges, none for one that does not.
    pub ranges: Vec<f32>,
    /// The neighbours detected in the scan ([`NeighbourInput`]), `K` slots of
    /// [`NeighbourInput::features`] values each (`x/d*, y/d*, held, present`, then
    /// `hx, hy` with `hidden=1`), slot after slot: `K * features` values for a dataset that declares neighbours, none for one that does not.
    pub neighbours: Vec<f32>,
    /// DAgger iteration (0 = expert demonstrations).
    pub iteration: u32,
    /// Run index within its iteration.
    pub run: u32,
    /// Robot index within its run.
    pub robot: u8,
}

/// One shard as listed in the manifest.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardEntry {
    /// File name inside the dataset directory.
    pub file: String,
    /// Samples it holds.
    pub samples: usize,
    /// DAgger iteration of all its samples.
    pub iteration: u32,
    /// Exact file size in bytes.
    pub bytes: u64,
    /// FNV-1a 64 of the whole file, 16 hex digits.
    pub fnv1a64: String,
}

/// The content of `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`DATASET_FORMAT`].
    pub format: String,
    /// Layout version ([`dataset_version`]: 1, 2 or 3).
    pub version: u32,
    /// See [`DatasetHeader::dataset_id`].
    pub dataset_id: String,
    /// See [`DatasetHeader::settings`]: written in place as the manifest's own keys.
    #[serde(flatten)]
    pub settings: CollectionSettings,
    /// Shards in the order they were written.
    pub shards: Vec<ShardEntry>,
    /// Total samples over all shards.
    pub samples: usize,
}

impl Manifest {
    fn empty(header: &DatasetHeader) -> Manifest {
        Manifest {
            format: DATASET_FORMAT.to_owned(),
            version: header.format_version,
            dataset_id: header.dataset_id.clone(),
            settings: header.settings.clone(),
            shards: Vec::new(),
            samples: 0,
        }
    }

    /// Reads and checks `dir/manifest.json` alone (format, version, shape), not the shards: what
    /// a worker labelling samples for the dataset needs of it.
    pub fn read(dir: &Path) -> Result<Manifest, DatasetError> {
        read_manifest(dir)
    }

    /// The settings every sample shares.
    pub fn header(&self) -> DatasetHeader {
        DatasetHeader {
            format_version: self.version,
            settings: self.settings.clone(),
            dataset_id: self.dataset_id.clone(),
        }
    }

    /// The largest DAgger iteration present (0 for an empty dataset).
    pub fn last_iteration(&self) -> u32 {
        self.shards.iter().map(|s| s.iteration).max().unwrap_or(0)
    }
}

/// Why a dataset could not be written or read. Every message names the file and the fix.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file-system operation failed.
    #[error("{action} {path}: {source}")]
    Io {
        /// What was being done, e.g. "reading".
        action: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The directory has no manifest.
    #[error(
        "{dir} is not a dataset (no {MANIFEST_FILE}); collect one with `formation collect --out {dir}`"
    )]
    NotADataset {
        /// The directory.
        dir: PathBuf,
    },
    /// `create` was pointed at an existing dataset.
    #[error(
        "{dir} already holds a dataset; choose another output directory or delete it (DAgger appends to it instead)"
    )]
    AlreadyExists {
        /// The directory.
        dir: PathBuf,
    },
    /// `create` was pointed at a directory with other files in it.
    #[error("{dir} exists and is not empty; choose a new or empty directory for the dataset")]
    DirectoryNotEmpty {
        /// The directory.
        dir: PathBuf,
    },
    /// The manifest is not valid JSON of the expected shape.
    #[error(
        "{path} is not a valid dataset manifest ({reason}); restore it or re-run `formation collect`"
    )]
    BadManifest {
        /// The manifest file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The manifest's `format` is not [`DATASET_FORMAT`].
    #[error("{path} has format `{found}`, not `{DATASET_FORMAT}`: this is not a formation dataset")]
    WrongFormat {
        /// The manifest file.
        path: PathBuf,
        /// The format it declares.
        found: String,
    },
    /// The manifest's version is not one this build reads.
    #[error(
        "{path} is dataset format version {found}, but this build reads versions {DATASET_VERSION_WITHOUT_RANGES}, {DATASET_VERSION_WITH_RANGES} and {DATASET_VERSION}; re-collect it with `formation collect` (or use the formation release that wrote it)"
    )]
    UnsupportedVersion {
        /// The manifest file.
        path: PathBuf,
        /// The version it declares.
        found: u64,
    },
    /// The manifest's version disagrees with its `ranges`: version 2 declares ranges, version 1
    /// does not.
    #[error(
        "{path} is dataset format version {version} but {}: version {DATASET_VERSION_WITHOUT_RANGES} holds no ranges and version {DATASET_VERSION_WITH_RANGES} declares them; the manifest was edited or damaged: restore it, or re-run `formation collect`",
        match ranges {
            Some(ranges) => format!("declares ranges \"{ranges}\""),
            None => "declares no `ranges`".to_owned(),
        }
    )]
    RangesVersion {
        /// The manifest file.
        path: PathBuf,
        /// The version it declares.
        version: u32,
        /// The ranges it declares.
        ranges: Option<RangeInput>,
    },
    /// The manifest's version disagrees with its `neighbours`: version 3 declares neighbours,
    /// versions 1 and 2 do not.
    #[error(
        "{path} is dataset format version {version} but {}: only version {DATASET_VERSION} declares the neighbours detected in each scan, and versions {DATASET_VERSION_WITHOUT_RANGES} and {DATASET_VERSION_WITH_RANGES} hold none; the manifest was edited or damaged: restore it, or re-run `formation collect`",
        match neighbours {
            Some(neighbours) => format!("declares neighbours \"{neighbours}\""),
            None => "declares no `neighbours`".to_owned(),
        }
    )]
    NeighboursVersion {
        /// The manifest file.
        path: PathBuf,
        /// The version it declares.
        version: u32,
        /// The neighbours it declares.
        neighbours: Option<NeighbourInput>,
    },
    /// A header whose format version does not match its ranges and neighbours (built field by
    /// field).
    #[error(
        "a dataset header of format version {version} with ranges {} and neighbours {} is inconsistent; build it with `DatasetHeader::new(..).with_ranges(..).with_neighbours(..)`",
        ranges.map_or_else(|| "none".to_owned(), |r| r.to_string()),
        neighbours.map_or_else(|| "none".to_owned(), |n| n.to_string())
    )]
    InconsistentHeader {
        /// The version it holds.
        version: u32,
        /// The ranges it holds.
        ranges: Option<RangeInput>,
        /// The neighbours it holds.
        neighbours: Option<NeighbourInput>,
    },
    /// The ranges declared need more beams than the dataset's LIDAR has.
    #[error(
        "a dataset of {ranges} ranges cannot come from its LIDAR: {source}; declare fewer sectors"
    )]
    RangeBeams {
        /// The ranges declared.
        ranges: RangeInput,
        /// What is wrong.
        source: RangeInputError,
    },
    /// A shard listed in the manifest does not exist.
    #[error(
        "{path} is listed in the manifest but missing; restore it, or delete its manifest entry, or re-run `formation collect`"
    )]
    MissingShard {
        /// The shard file.
        path: PathBuf,
    },
    /// A shard's size on disk differs from the manifest.
    #[error(
        "{path} is {} (expected {samples} samples in {expected_bytes} bytes, found {actual_bytes} bytes); delete it and its manifest entry or re-run `formation collect`",
        size_verdict(*.actual_bytes, *.expected_bytes)
    )]
    ShardSize {
        /// The shard file.
        path: PathBuf,
        /// Samples the manifest says it holds.
        samples: usize,
        /// Size the manifest records.
        expected_bytes: u64,
        /// Size on disk.
        actual_bytes: u64,
    },
    /// A shard's content does not match the manifest or the layout.
    #[error(
        "{path} is corrupt ({reason}); delete it and its manifest entry or re-run `formation collect`"
    )]
    CorruptShard {
        /// The shard file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Appending with settings that differ from the dataset's.
    #[error(
        "cannot append to {dir}: its {field} is {existing} but the new samples' is {requested}; collect into a new dataset directory instead"
    )]
    HeaderMismatch {
        /// The dataset directory.
        dir: PathBuf,
        /// The first differing field.
        field: &'static str,
        /// The dataset's value.
        existing: String,
        /// The value asked for.
        requested: String,
    },
    /// A sample's image has the wrong number of cells.
    #[error(
        "a sample's occupancy image has {actual} cells but the dataset's {size_px}x{size_px} images have {expected}; render with the dataset's occupancy settings"
    )]
    SampleImageSize {
        /// Cells on a side.
        size_px: usize,
        /// `size_px^2`.
        expected: usize,
        /// Cells in the sample.
        actual: usize,
    },
    /// A sample's ranges do not have the dataset's sector count.
    #[error(
        "a sample has {actual} range values but the dataset {}; compute the ranges with the dataset's range input",
        match declared {
            Some(ranges) => format!("declares {} sectors ({ranges})", ranges.sectors),
            None => "declares no ranges (give an empty `ranges`, or collect into a dataset with ranges)".to_owned(),
        }
    )]
    SampleRanges {
        /// The dataset's range input, if any.
        declared: Option<RangeInput>,
        /// Values in the sample.
        actual: usize,
    },
    /// A sample's neighbours do not have the dataset's slot count.
    #[error(
        "a sample has {actual} neighbour values but the dataset {}; fill them with `NeighbourInputBuilder` for the dataset's neighbour input",
        match declared {
            Some(neighbours) => format!(
                "declares {} slots of {} values ({neighbours}), {} in all",
                neighbours.slots,
                neighbours.features(),
                neighbours.len()
            ),
            None => "declares no neighbours (give an empty `neighbours`, or collect into a dataset with neighbours)".to_owned(),
        }
    )]
    SampleNeighbours {
        /// The dataset's neighbour input, if any.
        declared: Option<NeighbourInput>,
        /// Values in the sample.
        actual: usize,
    },
    /// A sample's iteration differs from the iteration being written.
    #[error(
        "a sample is labelled DAgger iteration {actual} but this writer writes iteration {expected}; open the writer with the sample's iteration"
    )]
    SampleIteration {
        /// The writer's iteration.
        expected: u32,
        /// The sample's iteration.
        actual: u32,
    },
    /// A sample holds NaN or infinity.
    #[error(
        "a sample's {field} is not finite (run {run}, robot {robot}); the labeller produced an invalid value"
    )]
    NonFiniteSample {
        /// Which field.
        field: &'static str,
        /// Its run.
        run: u32,
        /// Its robot.
        robot: u8,
    },
    /// `with_shard_size(0)`.
    #[error("the shard size must be at least 1 sample")]
    ZeroShardSize,
    /// The safetensors encoder refused the tensors (a bug: the shapes are built here).
    #[error("encoding shard {path}: {source}")]
    Encode {
        /// The shard file.
        path: PathBuf,
        /// The encoder's error.
        source: SafeTensorError,
    },
}

fn size_verdict(actual: u64, expected: u64) -> &'static str {
    if actual < expected {
        "truncated"
    } else {
        "larger than recorded"
    }
}

/// What turns an OS error while doing `action` (e.g. "reading") to `path` into a
/// [`DatasetError::Io`]; the DAgger parts' file operations fail the same way.
pub(crate) fn io_error<'a>(
    action: &'static str,
    path: &'a Path,
) -> impl FnOnce(std::io::Error) -> DatasetError + 'a {
    move |source| DatasetError::Io {
        action,
        path: path.to_path_buf(),
        source,
    }
}

/// `shard-NNNNNN.safetensors`.
fn shard_file_name(index: usize) -> String {
    format!("shard-{index:06}.safetensors")
}

/// The index in a `shard-NNNNNN.safetensors` name, if it is one.
fn shard_index(file: &str) -> Option<usize> {
    file.strip_prefix("shard-")?
        .strip_suffix(".safetensors")?
        .parse()
        .ok()
}

/// Writes `bytes` to `path` atomically ([`formation_proto::files::write_atomic`]).
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), DatasetError> {
    formation_proto::files::write_atomic(path, bytes).map_err(io_error("writing", path))
}

fn write_manifest(dir: &Path, manifest: &Manifest) -> Result<(), DatasetError> {
    let path = dir.join(MANIFEST_FILE);
    let mut text = serde_json::to_vec_pretty(manifest).map_err(|e| DatasetError::BadManifest {
        path: path.clone(),
        reason: e.to_string(),
    })?;
    text.push(b'\n');
    write_atomic(&path, &text)
}

/// Reads and validates `dir/manifest.json`: format, then version, then the full shape.
fn read_manifest(dir: &Path) -> Result<Manifest, DatasetError> {
    let path = dir.join(MANIFEST_FILE);
    let text = match fs::read(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(DatasetError::NotADataset {
                dir: dir.to_path_buf(),
            });
        }
        Err(e) => return Err(io_error("reading", &path)(e)),
    };
    let bad = |reason: String| DatasetError::BadManifest {
        path: path.clone(),
        reason,
    };
    let value: serde_json::Value = serde_json::from_slice(&text).map_err(|e| bad(e.to_string()))?;
    let format = value.get("format").and_then(serde_json::Value::as_str);
    if format != Some(DATASET_FORMAT) {
        return Err(DatasetError::WrongFormat {
            path,
            found: format.unwrap_or("<missing>").to_owned(),
        });
    }
    let version = value
        .get("version")
        .and_then(serde_json::Value::as_u64)
        .ok_or_else(|| bad("no numeric `version`".into()))?;
    if ![
        DATASET_VERSION_WITHOUT_RANGES,
        DATASET_VERSION_WITH_RANGES,
        DATASET_VERSION,
    ]
    .map(u64::from)
    .contains(&version)
    {
        return Err(DatasetError::UnsupportedVersion {
            path,
            found: version,
        });
    }
    let manifest: Manifest = serde_json::from_value(value).map_err(|e| bad(e.to_string()))?;
    if manifest.settings.neighbours.is_some() != (manifest.version == DATASET_VERSION) {
        return Err(DatasetError::NeighboursVersion {
            path,
            version: manifest.version,
            neighbours: manifest.settings.neighbours,
        });
    }
    if manifest.version != dataset_version(manifest.settings.ranges, manifest.settings.neighbours) {
        return Err(DatasetError::RangesVersion {
            path,
            version: manifest.version,
            ranges: manifest.settings.ranges,
        });
    }
    if let Some(ranges) = manifest.settings.ranges {
        ranges
            .check_beams(manifest.settings.lidar.spec.beams)
            .map_err(|e| bad(e.to_string()))?;
    }
    let listed: usize = manifest.shards.iter().map(|s| s.samples).sum();
    if listed != manifest.samples {
        return Err(bad(format!(
            "`samples` is {} but the shards hold {listed}",
            manifest.samples
        )));
    }
    if let Some(entry) = manifest
        .shards
        .iter()
        .find(|s| shard_index(&s.file).is_none())
    {
        return Err(bad(format!(
            "shard file name `{}` is not shard-NNNNNN.safetensors",
            entry.file
        )));
    }
    Ok(manifest)
}

/// Column buffers of the shard being filled (also the body of a DAgger part,
/// [`crate::dagger_part`]).
#[derive(Debug)]
pub(crate) struct PendingShard {
    occupancy: Vec<u8>,
    aux: Vec<u8>,
    wheels: Vec<u8>,
    iteration: Vec<u8>,
    run: Vec<u8>,
    robot: Vec<u8>,
    /// The `ranges` column, `Some` iff the dataset declares ranges of this many sectors.
    ranges: Option<(usize, Vec<u8>)>,
    /// The `neighbours` column, `Some` iff the dataset declares neighbours: `[slots, features]`.
    neighbours: Option<([usize; 2], Vec<u8>)>,
    samples: usize,
}

impl PendingShard {
    /// Empty columns for samples of a dataset with `header`.
    pub(crate) fn new(header: &DatasetHeader) -> PendingShard {
        PendingShard {
            occupancy: Vec::new(),
            aux: Vec::new(),
            wheels: Vec::new(),
            iteration: Vec::new(),
            run: Vec::new(),
            robot: Vec::new(),
            ranges: header.settings.ranges.map(|r| (r.sectors, Vec::new())),
            neighbours: header
                .settings
                .neighbours
                .map(|n| ([n.slots, n.features()], Vec::new())),
            samples: 0,
        }
    }

    /// Adds a sample checked with [`check_sample`] against the same header.
    pub(crate) fn push(&mut self, sample: &Sample) {
        self.occupancy.extend_from_slice(&sample.occupancy);
        for value in [sample.delta_phi, sample.d_star] {
            self.aux.extend_from_slice(&value.to_le_bytes());
        }
        for value in sample.wheels {
            self.wheels.extend_from_slice(&value.to_le_bytes());
        }
        self.iteration
            .extend_from_slice(&sample.iteration.to_le_bytes());
        self.run.extend_from_slice(&sample.run.to_le_bytes());
        self.robot.push(sample.robot);
        if let Some((_, ranges)) = &mut self.ranges {
            for value in &sample.ranges {
                ranges.extend_from_slice(&value.to_le_bytes());
            }
        }
        if let Some((_, neighbours)) = &mut self.neighbours {
            for value in &sample.neighbours {
                neighbours.extend_from_slice(&value.to_le_bytes());
            }
        }
        self.samples += 1;
    }

    /// Samples buffered.
    pub(crate) fn samples(&self) -> usize {
        self.samples
    }

    /// FNV-1a 64 over the six columns, then `ranges` and `neighbours` where the dataset declares
    /// them, each length-prefixed, in file order.
    pub(crate) fn columns_fnv1a64(&self) -> String {
        let mut hash = Fnv1a64::new();
        for column in [
            &self.occupancy,
            &self.aux,
            &self.wheels,
            &self.iteration,
            &self.run,
            &self.robot,
        ] {
            hash.update_field(column);
        }
        if let Some((_, ranges)) = &self.ranges {
            hash.update_field(ranges);
        }
        if let Some((_, neighbours)) = &self.neighbours {
            hash.update_field(neighbours);
        }
        hash.hex()
    }

    /// The safetensors file of a dataset shard for these samples.
    fn encode(
        &self,
        header: &DatasetHeader,
        iteration: u32,
        path: &Path,
    ) -> Result<Vec<u8>, DatasetError> {
        let metadata = HashMap::from([
            ("format".to_owned(), DATASET_FORMAT.to_owned()),
            ("version".to_owned(), header.format_version.to_string()),
            ("dataset_id".to_owned(), header.dataset_id.clone()),
            ("iteration".to_owned(), iteration.to_string()),
        ]);
        self.encode_with(header.settings.occupancy.size_px, metadata, path)
    }

    /// The safetensors file holding these samples' columns, with `metadata` as its
    /// `__metadata__`.
    pub(crate) fn encode_with(
        &self,
        size: usize,
        metadata: HashMap<String, String>,
        path: &Path,
    ) -> Result<Vec<u8>, DatasetError> {
        let n = self.samples;
        let encode_error = |source| DatasetError::Encode {
            path: path.to_path_buf(),
            source,
        };
        let mut tensors = vec![
            (
                "occupancy",
                TensorView::new(Dtype::U8, vec![n, size, size], &self.occupancy),
            ),
            ("aux", TensorView::new(Dtype::F32, vec![n, 2], &self.aux)),
            (
                "wheels",
                TensorView::new(Dtype::F32, vec![n, 2], &self.wheels),
            ),
            (
                "iteration",
                TensorView::new(Dtype::U32, vec![n], &self.iteration),
            ),
            ("run", TensorView::new(Dtype::U32, vec![n], &self.run)),
            ("robot", TensorView::new(Dtype::U8, vec![n], &self.robot)),
        ];
        if let Some((sectors, ranges)) = &self.ranges {
            tensors.push((
                "ranges",
                TensorView::new(Dtype::F32, vec![n, *sectors], ranges),
            ));
        }
        if let Some(([slots, features], neighbours)) = &self.neighbours {
            tensors.push((
                "neighbours",
                TensorView::new(Dtype::F32, vec![n, *slots, *features], neighbours),
            ));
        }
        let mut views = Vec::with_capacity(tensors.len());
        for (name, view) in tensors {
            views.push((name, view.map_err(encode_error)?));
        }
        let mut file =
            safetensors::serialize(views, Some(metadata.clone())).map_err(encode_error)?;
        sort_metadata(&mut file, &metadata).map_err(|reason| DatasetError::CorruptShard {
            path: path.to_path_buf(),
            reason,
        })?;
        Ok(file)
    }
}

/// safetensors writes `__metadata__` (a `HashMap`) in the map's random iteration order, but the
/// same samples must give the same bytes: this rewrites the object with its keys sorted. Its
/// length does not depend on the order, so nothing else in the file moves.
fn sort_metadata(file: &mut [u8], metadata: &HashMap<String, String>) -> Result<(), String> {
    const PREFIX: &[u8] = b"{\"__metadata__\":";
    let sorted: std::collections::BTreeMap<&String, &String> = metadata.iter().collect();
    let sorted = serde_json::to_vec(&sorted).map_err(|e| e.to_string())?;
    let start = 8 + PREFIX.len();
    let end = start + sorted.len();
    if file.get(8..start) != Some(PREFIX) || file.len() < end {
        return Err("the encoder did not write `__metadata__` first".into());
    }
    let written: HashMap<String, String> =
        serde_json::from_slice(&file[start..end]).map_err(|e| e.to_string())?;
    if written != *metadata {
        return Err("the encoder wrote other `__metadata__` than given".into());
    }
    file[start..end].copy_from_slice(&sorted);
    Ok(())
}

/// Refuses a sample that does not fit a dataset with `header` being written as `iteration`:
/// another image size, another iteration, ranges or neighbours of another length, a non-finite
/// value.
pub(crate) fn check_sample(
    header: &DatasetHeader,
    iteration: u32,
    sample: &Sample,
) -> Result<(), DatasetError> {
    let expected = header.cells();
    if sample.occupancy.len() != expected {
        return Err(DatasetError::SampleImageSize {
            size_px: header.settings.occupancy.size_px,
            expected,
            actual: sample.occupancy.len(),
        });
    }
    if sample.iteration != iteration {
        return Err(DatasetError::SampleIteration {
            expected: iteration,
            actual: sample.iteration,
        });
    }
    let non_finite = |field| DatasetError::NonFiniteSample {
        field,
        run: sample.run,
        robot: sample.robot,
    };
    if !(sample.delta_phi.is_finite() && sample.d_star.is_finite()) {
        return Err(non_finite("delta_phi or d_star"));
    }
    if !sample.wheels.iter().all(|w| w.is_finite()) {
        return Err(non_finite("wheels label"));
    }
    let wrong_ranges = |actual| DatasetError::SampleRanges {
        declared: header.settings.ranges,
        actual,
    };
    let wrong_neighbours = |actual| DatasetError::SampleNeighbours {
        declared: header.settings.neighbours,
        actual,
    };
    check_optional_input(&sample.ranges, header.range_sectors(), wrong_ranges, || {
        non_finite("ranges")
    })?;
    check_optional_input(
        &sample.neighbours,
        header.neighbour_values(),
        wrong_neighbours,
        || non_finite("neighbours"),
    )
}

/// Refuses the `values` of a sample's optional input (its ranges or its neighbours) unless there
/// are `expected` of them, all finite: `wrong_count` is the error for the count found, and
/// `non_finite` the error for a NaN or an infinity.
fn check_optional_input(
    values: &[f32],
    expected: usize,
    wrong_count: impl FnOnce(usize) -> DatasetError,
    non_finite: impl FnOnce() -> DatasetError,
) -> Result<(), DatasetError> {
    if values.len() != expected {
        return Err(wrong_count(values.len()));
    }
    if !values.iter().all(|v| v.is_finite()) {
        return Err(non_finite());
    }
    Ok(())
}

/// Writes samples into a new dataset, or appends a new DAgger iteration to an existing one.
///
/// Samples are buffered and written as a shard every `shard_size` samples; the manifest is
/// rewritten after each shard. Call [`DatasetWriter::finish`] to write the last, partial shard.
#[derive(Debug)]
pub struct DatasetWriter {
    dir: PathBuf,
    header: DatasetHeader,
    manifest: Manifest,
    iteration: u32,
    shard_size: usize,
    next_shard: usize,
    pending: PendingShard,
}

impl DatasetWriter {
    /// Creates the dataset directory `dir` (which must not exist or be empty) with an empty
    /// manifest, and a writer of iteration 0.
    pub fn create(dir: &Path, header: DatasetHeader) -> Result<DatasetWriter, DatasetError> {
        header.check()?;
        if let Some(ranges) = header.settings.ranges {
            ranges
                .check_beams(header.settings.lidar.spec.beams)
                .map_err(|source| DatasetError::RangeBeams { ranges, source })?;
        }
        if dir.join(MANIFEST_FILE).exists() {
            return Err(DatasetError::AlreadyExists {
                dir: dir.to_path_buf(),
            });
        }
        if dir.exists() {
            let mut entries = fs::read_dir(dir).map_err(io_error("listing", dir))?;
            if entries.next().is_some() {
                return Err(DatasetError::DirectoryNotEmpty {
                    dir: dir.to_path_buf(),
                });
            }
        }
        fs::create_dir_all(dir).map_err(io_error("creating", dir))?;
        let manifest = Manifest::empty(&header);
        write_manifest(dir, &manifest)?;
        let pending = PendingShard::new(&header);
        Ok(DatasetWriter {
            dir: dir.to_path_buf(),
            header,
            manifest,
            iteration: 0,
            shard_size: DEFAULT_SHARD_SIZE,
            next_shard: 0,
            pending,
        })
    }

    /// Opens the existing dataset `dir` to add shards of DAgger iteration `iteration`, with the
    /// dataset's own settings.
    pub fn append(dir: &Path, iteration: u32) -> Result<DatasetWriter, DatasetError> {
        let manifest = read_manifest(dir)?;
        let next_shard = manifest
            .shards
            .iter()
            .filter_map(|s| shard_index(&s.file))
            .max()
            .map_or(0, |last| last + 1);
        let header = manifest.header();
        Ok(DatasetWriter {
            dir: dir.to_path_buf(),
            pending: PendingShard::new(&header),
            header,
            manifest,
            iteration,
            shard_size: DEFAULT_SHARD_SIZE,
            next_shard,
        })
    }

    /// Like [`DatasetWriter::append`], but refuses unless the dataset was written with `expected`
    /// settings (the error names the first differing field).
    pub fn append_matching(
        dir: &Path,
        expected: &DatasetHeader,
        iteration: u32,
    ) -> Result<DatasetWriter, DatasetError> {
        let writer = DatasetWriter::append(dir, iteration)?;
        if let Some((field, existing, requested)) = writer.header().first_difference(expected) {
            return Err(DatasetError::HeaderMismatch {
                dir: dir.to_path_buf(),
                field,
                existing,
                requested,
            });
        }
        Ok(writer)
    }

    /// Writes a shard every `samples` samples instead of [`DEFAULT_SHARD_SIZE`].
    pub fn with_shard_size(mut self, samples: usize) -> Result<DatasetWriter, DatasetError> {
        if samples == 0 {
            return Err(DatasetError::ZeroShardSize);
        }
        self.shard_size = samples;
        Ok(self)
    }

    /// The dataset's settings.
    pub fn header(&self) -> &DatasetHeader {
        &self.header
    }

    /// The manifest as written so far (buffered samples are not in it yet).
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The DAgger iteration this writer writes.
    pub fn iteration(&self) -> u32 {
        self.iteration
    }

    /// Samples in the dataset so far, including buffered ones not yet in a shard.
    pub fn samples(&self) -> usize {
        self.manifest.samples + self.pending.samples
    }

    /// Adds one sample; writes a shard when `shard_size` samples are buffered.
    pub fn push(&mut self, sample: Sample) -> Result<(), DatasetError> {
        check_sample(&self.header, self.iteration, &sample)?;
        self.pending.push(&sample);
        if self.pending.samples >= self.shard_size {
            self.flush_shard()?;
        }
        Ok(())
    }

    /// Writes the buffered samples (if any) as one shard and rewrites the manifest.
    fn flush_shard(&mut self) -> Result<(), DatasetError> {
        if self.pending.samples == 0 {
            return Ok(());
        }
        let file = shard_file_name(self.next_shard);
        let path = self.dir.join(&file);
        let bytes = self.pending.encode(&self.header, self.iteration, &path)?;
        write_atomic(&path, &bytes)?;
        let mut checksum = Fnv1a64::new();
        checksum.update(&bytes);
        self.manifest.shards.push(ShardEntry {
            file,
            samples: self.pending.samples,
            iteration: self.iteration,
            bytes: bytes.len() as u64,
            fnv1a64: checksum.hex(),
        });
        self.manifest.samples += self.pending.samples;
        self.next_shard += 1;
        self.pending = PendingShard::new(&self.header);
        write_manifest(&self.dir, &self.manifest)
    }

    /// Writes the last shard and returns the final manifest.
    pub fn finish(mut self) -> Result<Manifest, DatasetError> {
        self.flush_shard()?;
        Ok(self.manifest)
    }
}

/// Reads a dataset written by [`DatasetWriter`].
#[derive(Debug, Clone)]
pub struct DatasetReader {
    dir: PathBuf,
    header: DatasetHeader,
    manifest: Manifest,
}

impl DatasetReader {
    /// Opens `dir`: checks the manifest's format, version and shape, and that every listed shard
    /// exists with the recorded size. Shard contents are checked when read.
    pub fn open(dir: &Path) -> Result<DatasetReader, DatasetError> {
        let manifest = read_manifest(dir)?;
        for entry in &manifest.shards {
            let path = dir.join(&entry.file);
            let actual_bytes = match fs::metadata(&path) {
                Ok(meta) => meta.len(),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return Err(DatasetError::MissingShard { path });
                }
                Err(e) => return Err(io_error("inspecting", &path)(e)),
            };
            if actual_bytes != entry.bytes {
                return Err(DatasetError::ShardSize {
                    path,
                    samples: entry.samples,
                    expected_bytes: entry.bytes,
                    actual_bytes,
                });
            }
        }
        Ok(DatasetReader {
            dir: dir.to_path_buf(),
            header: manifest.header(),
            manifest,
        })
    }

    /// The dataset directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The shared settings.
    pub fn header(&self) -> &DatasetHeader {
        &self.header
    }

    /// Total samples.
    pub fn samples(&self) -> usize {
        self.manifest.samples
    }

    /// Reads and validates shard `index` (manifest order) into samples.
    pub fn read_shard(&self, index: usize) -> Result<Vec<Sample>, DatasetError> {
        let Some(entry) = self.manifest.shards.get(index) else {
            return Ok(Vec::new());
        };
        let path = self.dir.join(&entry.file);
        let bytes = fs::read(&path).map_err(io_error("reading", &path))?;
        decode_shard(&bytes, entry, &self.header, &path)
    }

    /// Every sample, shard by shard, in write order; stops at the first bad shard.
    pub fn iter(&self) -> impl Iterator<Item = Result<Sample, DatasetError>> + '_ {
        (0..self.manifest.shards.len()).flat_map(move |index| match self.read_shard(index) {
            Ok(samples) => samples.into_iter().map(Ok).collect::<Vec<_>>(),
            Err(e) => vec![Err(e)],
        })
    }

    /// Every sample in memory.
    pub fn load_all(&self) -> Result<Vec<Sample>, DatasetError> {
        let mut all = Vec::with_capacity(self.manifest.samples);
        for index in 0..self.manifest.shards.len() {
            all.extend(self.read_shard(index)?);
        }
        Ok(all)
    }
}

/// Checks a shard file's bytes against its manifest entry and the layout, and decodes it.
fn decode_shard(
    bytes: &[u8],
    entry: &ShardEntry,
    header: &DatasetHeader,
    path: &Path,
) -> Result<Vec<Sample>, DatasetError> {
    let corrupt = |reason: String| DatasetError::CorruptShard {
        path: path.to_path_buf(),
        reason,
    };
    if bytes.len() as u64 != entry.bytes {
        return Err(DatasetError::ShardSize {
            path: path.to_path_buf(),
            samples: entry.samples,
            expected_bytes: entry.bytes,
            actual_bytes: bytes.len() as u64,
        });
    }
    let mut checksum = Fnv1a64::new();
    checksum.update(bytes);
    if checksum.hex() != entry.fnv1a64 {
        return Err(corrupt(format!(
            "checksum {} differs from the manifest's {}",
            checksum.hex(),
            entry.fnv1a64
        )));
    }
    let tensors = SafeTensors::deserialize(bytes).map_err(|e| corrupt(e.to_string()))?;
    decode_columns(&tensors, entry.samples, header).map_err(corrupt)
}

/// The `n` samples of a dataset with `header` held in the columns of `tensors` (six, `ranges` iff
/// the header declares ranges, `neighbours` iff it declares neighbours); the error says which
/// column is missing, unexpected or of another type or shape.
pub(crate) fn decode_columns(
    tensors: &SafeTensors<'_>,
    n: usize,
    header: &DatasetHeader,
) -> Result<Vec<Sample>, String> {
    let size = header.settings.occupancy.size_px;
    let column = |name: &str, dtype: Dtype, shape: &[usize]| -> Result<&[u8], String> {
        let view = tensors
            .tensor(name)
            .map_err(|_| format!("no `{name}` tensor"))?;
        if view.dtype() != dtype || view.shape() != shape {
            return Err(format!(
                "`{name}` is {:?} {:?}, expected {dtype:?} {shape:?}",
                view.dtype(),
                view.shape()
            ));
        }
        Ok(view.data())
    };
    let occupancy = column("occupancy", Dtype::U8, &[n, size, size])?;
    let aux = column("aux", Dtype::F32, &[n, 2])?;
    let wheels = column("wheels", Dtype::F32, &[n, 2])?;
    let iteration = column("iteration", Dtype::U32, &[n])?;
    let run = column("run", Dtype::U32, &[n])?;
    let robot = column("robot", Dtype::U8, &[n])?;
    let sectors = header.range_sectors();
    let ranges = match header.settings.ranges {
        Some(_) => column("ranges", Dtype::F32, &[n, sectors])?,
        None if tensors.tensor("ranges").is_ok() => {
            return Err("a `ranges` tensor, but the manifest declares no ranges".to_owned());
        }
        None => &[],
    };
    let slots = header.neighbour_slots();
    let neighbour_values = header.neighbour_values();
    let neighbours = match header.settings.neighbours {
        Some(_) => column(
            "neighbours",
            Dtype::F32,
            &[
                n,
                slots,
                header.settings.neighbours.map_or(0, |n| n.features()),
            ],
        )?,
        None if tensors.tensor("neighbours").is_ok() => {
            return Err(
                "a `neighbours` tensor, but the manifest declares no neighbours".to_owned(),
            );
        }
        None => &[],
    };

    // The `i`th little-endian 4-byte word of a column.
    let word_at =
        |data: &[u8], i: usize| -> [u8; 4] { data[4 * i..4 * i + 4].try_into().expect("4 bytes") };
    let f32_at = |data: &[u8], i: usize| f32::from_le_bytes(word_at(data, i));
    let u32_at = |data: &[u8], i: usize| u32::from_le_bytes(word_at(data, i));
    let cells = size * size;
    Ok((0..n)
        .map(|i| Sample {
            occupancy: occupancy[i * cells..(i + 1) * cells].to_vec(),
            delta_phi: f32_at(aux, 2 * i),
            d_star: f32_at(aux, 2 * i + 1),
            wheels: [f32_at(wheels, 2 * i), f32_at(wheels, 2 * i + 1)],
            iteration: u32_at(iteration, i),
            run: u32_at(run, i),
            ranges: (0..sectors)
                .map(|k| f32_at(ranges, i * sectors + k))
                .collect(),
            neighbours: (0..neighbour_values)
                .map(|k| f32_at(neighbours, i * neighbour_values + k))
                .collect(),
            robot: robot[i],
        })
        .collect())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use formation_proto::BeyondWindow;

    const SIZE: usize = 6;

    /// The settings of the test datasets, with `seed`.
    pub(crate) fn header(seed: u64) -> DatasetHeader {
        DatasetHeader::new(
            OccupancySpec {
                size_px: SIZE,
                resolution_m: 0.1,
                beyond: BeyondWindow::Drop,
                d_star_ref_m: None,
            },
            SimulatedLidar::default(),
            0.7,
            seed,
            "unit".to_owned(),
        )
    }

    /// A sample whose every field depends on `k`, so mix-ups show.
    pub(crate) fn sample(k: u32, iteration: u32) -> Sample {
        let mut occupancy = vec![0u8; SIZE * SIZE];
        occupancy[k as usize % (SIZE * SIZE)] = 1;
        Sample {
            occupancy,
            delta_phi: -1.5 + 0.01 * k as f32,
            d_star: 1.0 + 0.5 * (k % 3) as f32,
            wheels: [0.1 * k as f32, -0.2 * k as f32],
            ranges: Vec::new(),
            neighbours: Vec::new(),
            iteration,
            run: k / 4,
            robot: (k % 4) as u8,
        }
    }

    /// The test datasets' range input: 6 sectors, clip 3.
    pub(crate) fn ranges() -> RangeInput {
        RangeInput::new(6, 3.0).expect("ranges")
    }

    /// The settings of the test datasets with ranges, with `seed`.
    pub(crate) fn header_with_ranges(seed: u64) -> DatasetHeader {
        header(seed).with_ranges(Some(ranges()))
    }

    /// [`sample`] with 6 range values that depend on `k`.
    pub(crate) fn sample_with_ranges(k: u32, iteration: u32) -> Sample {
        Sample {
            ranges: (0..6).map(|s| 0.25 * s as f32 + 0.001 * k as f32).collect(),
            ..sample(k, iteration)
        }
    }

    /// The test datasets' neighbour input: 3 slots, threshold 1.3, the 2 nearest held.
    pub(crate) fn neighbours() -> NeighbourInput {
        NeighbourInput::with_default_rule(3).expect("neighbours")
    }

    /// The settings of the test datasets with neighbours (and no ranges), with `seed`.
    pub(crate) fn header_with_neighbours(seed: u64) -> DatasetHeader {
        header(seed).with_neighbours(Some(neighbours()))
    }

    /// [`sample`] with 3 slots of neighbours (12 values) that depend on `k`: two detections, the
    /// first held, and an empty slot.
    pub(crate) fn sample_with_neighbours(k: u32, iteration: u32) -> Sample {
        let x = 0.01 * k as f32;
        let slots: [[f32; 4]; 3] = [
            [1.0 + x, -0.5, 1.0, 1.0],
            [-1.2, 0.8 + x, 0.0, 1.0],
            [0.0; 4],
        ];
        Sample {
            neighbours: slots.concat(),
            ..sample(k, iteration)
        }
    }

    /// A new dataset of `header` in `dir`, `shard_size` samples a shard, holding `samples`.
    fn write_samples(
        dir: &Path,
        header: DatasetHeader,
        shard_size: usize,
        samples: impl IntoIterator<Item = Sample>,
    ) -> Manifest {
        let mut writer = DatasetWriter::create(dir, header)
            .expect("create")
            .with_shard_size(shard_size)
            .expect("shard size");
        for sample in samples {
            writer.push(sample).expect("push");
        }
        writer.finish().expect("finish")
    }

    fn write(dir: &Path, count: u32, shard_size: usize) -> Manifest {
        write_samples(dir, header(7), shard_size, (0..count).map(|k| sample(k, 0)))
    }

    /// Appends `sample` as DAgger iteration 1 to the dataset of `header` in `dir`, then reads back
    /// all its samples.
    fn append_and_load(dir: &Path, header: &DatasetHeader, sample: Sample) -> Vec<Sample> {
        let mut writer = DatasetWriter::append_matching(dir, header, 1).expect("append");
        writer.push(sample).expect("push");
        writer.finish().expect("finish");
        DatasetReader::open(dir)
            .expect("open")
            .load_all()
            .expect("load")
    }

    /// The tensors of shard `file` in `dir` (dtype and shape by name) and the format version in
    /// its metadata.
    fn shard_tensors(dir: &Path, file: &str) -> (HashMap<String, (Dtype, Vec<usize>)>, String) {
        let shard = fs::read(dir.join(file)).expect("shard");
        let tensors = SafeTensors::deserialize(&shard).expect("safetensors");
        let shapes = tensors
            .tensors()
            .into_iter()
            .map(|(name, view)| (name, (view.dtype(), view.shape().to_vec())))
            .collect();
        let (_, meta) = SafeTensors::read_metadata(&shard).expect("metadata");
        let version = meta.metadata().as_ref().expect("meta")["version"].clone();
        (shapes, version)
    }

    /// Rewrites the manifest of `dir` with `edit` applied to its JSON.
    fn edit_manifest(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
        let mut value = manifest_json(dir);
        edit(&mut value);
        fs::write(dir.join(MANIFEST_FILE), value.to_string()).expect("write");
    }

    /// Rewrites the manifest of `dir` to format `version` declaring `key` as `value`, and checks
    /// that opening the dataset then fails as a bad manifest whose message contains `says`.
    fn assert_bad_declaration(dir: &Path, version: u32, key: &str, value: &str, says: &str) {
        edit_manifest(dir, |manifest| {
            manifest["version"] = version.into();
            manifest[key] = value.into();
        });
        let err = DatasetReader::open(dir).expect_err("a bad declaration");
        assert!(matches!(err, DatasetError::BadManifest { .. }), "{err:?}");
        assert!(err.to_string().contains(says), "{err}");
    }

    /// Lists the first shard of `dir` under `manifest` (as holding `samples`, its size and
    /// checksum those of the file) and returns why loading the dataset then fails.
    fn load_error_under(dir: &Path, manifest: &serde_json::Value, samples: usize) -> DatasetError {
        let bytes = fs::read(dir.join("shard-000000.safetensors")).expect("shard");
        let mut manifest = manifest.clone();
        manifest["shards"][0]["bytes"] = bytes.len().into();
        manifest["shards"][0]["samples"] = samples.into();
        manifest["samples"] = samples.into();
        let mut checksum = Fnv1a64::new();
        checksum.update(&bytes);
        manifest["shards"][0]["fnv1a64"] = checksum.hex().into();
        fs::write(dir.join(MANIFEST_FILE), manifest.to_string()).expect("write");
        DatasetReader::open(dir)
            .expect("open")
            .load_all()
            .expect_err("corrupt")
    }

    #[test]
    fn dataset_id_is_deterministic_and_depends_on_the_settings() {
        assert_eq!(header(7).dataset_id, header(7).dataset_id);
        assert_eq!(header(7).dataset_id.len(), 16);
        assert_ne!(header(7).dataset_id, header(8).dataset_id);
        let mut border = header(7);
        border.settings.occupancy.beyond = BeyondWindow::Border;
        let border = DatasetHeader::new(
            border.settings.occupancy,
            border.settings.lidar,
            0.7,
            7,
            "unit",
        );
        assert_ne!(header(7).dataset_id, border.dataset_id);
    }

    #[test]
    fn samples_round_trip_through_shards_in_order() {
        let dir = tempfile::tempdir().expect("tempdir");
        let manifest = write(dir.path(), 10, 4);
        assert_eq!(manifest.samples, 10);
        let sizes: Vec<usize> = manifest.shards.iter().map(|s| s.samples).collect();
        assert_eq!(sizes, [4, 4, 2]);
        assert_eq!(manifest.shards[2].file, "shard-000002.safetensors");

        let reader = DatasetReader::open(dir.path()).expect("open");
        assert_eq!(reader.header(), &header(7));
        assert_eq!(reader.manifest(), &manifest);
        let expected: Vec<Sample> = (0..10).map(|k| sample(k, 0)).collect();
        assert_eq!(reader.load_all().expect("load"), expected);
        let iterated: Vec<Sample> = reader.iter().collect::<Result<_, _>>().expect("iter");
        assert_eq!(iterated, expected);
        let leftovers: Vec<_> = fs::read_dir(dir.path())
            .expect("list")
            .filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    }

    #[test]
    fn the_same_samples_write_the_same_bytes() {
        let dirs: Vec<_> = (0..4)
            .map(|_| tempfile::tempdir().expect("tempdir"))
            .collect();
        for dir in &dirs {
            write(dir.path(), 6, 4);
        }
        for file in [
            MANIFEST_FILE,
            "shard-000000.safetensors",
            "shard-000001.safetensors",
        ] {
            let first = fs::read(dirs[0].path().join(file)).expect("read");
            for dir in &dirs[1..] {
                assert_eq!(
                    fs::read(dir.path().join(file)).expect("read"),
                    first,
                    "{file}"
                );
            }
        }
    }

    #[test]
    fn the_manifest_uses_the_documented_keys() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 3, 8);
        let value = manifest_json(dir.path());
        assert_eq!(value["format"], "formation-dataset");
        assert_eq!(value["version"], 1);
        assert_eq!(value["occupancy"]["size_px"], SIZE);
        assert_eq!(value["occupancy"]["beyond"], "drop");
        assert_eq!(value["lidar"]["beams"], 900);
        assert_eq!(value["samples"], 3);
        assert_eq!(value["shards"][0]["file"], "shard-000000.safetensors");
        assert_eq!(value["shards"][0]["iteration"], 0);
    }

    #[test]
    fn the_settings_keys_stand_where_they_stood_before_they_were_gathered() {
        // `CollectionSettings` is flattened in place: the header's and the manifest's keys keep
        // the order (and so the bytes) of when each struct held the settings itself.
        let labels = crate::label_law::LabelLaw {
            unshaped: true,
            ..Default::default()
        };
        let header = header_with_ranges(7)
            .with_neighbours(Some(neighbours()))
            .with_labels(labels);
        let settings = [
            "occupancy",
            "lidar",
            "v_train",
            "seed",
            "scenario",
            "ranges",
            "neighbours",
            "labels",
        ];
        let in_order = |text: &str, keys: &[&str]| {
            let at = |key: &str| text.find(&format!("\"{key}\":"));
            keys.windows(2).all(|pair| at(pair[0]) < at(pair[1])) && at(keys[0]).is_some()
        };
        let header_text = serde_json::to_string(&header).expect("json");
        let header_keys = [&["format_version"], &settings[..], &["dataset_id"]].concat();
        assert!(in_order(&header_text, &header_keys), "{header_text}");
        let manifest_text = serde_json::to_string(&Manifest::empty(&header)).expect("json");
        let manifest_keys = [
            &["format", "version", "dataset_id"],
            &settings[..],
            &["shards", "samples"],
        ]
        .concat();
        assert!(in_order(&manifest_text, &manifest_keys), "{manifest_text}");
    }

    #[test]
    fn appending_adds_shards_of_a_new_iteration() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 5, 4);
        let mut writer = DatasetWriter::append_matching(dir.path(), &header(7), 1)
            .expect("append")
            .with_shard_size(4)
            .expect("shard size");
        assert_eq!(writer.samples(), 5);
        for k in 100..103 {
            writer.push(sample(k, 1)).expect("push");
        }
        let manifest = writer.finish().expect("finish");
        assert_eq!(manifest.samples, 8);
        assert_eq!(manifest.last_iteration(), 1);
        let files: Vec<(&str, u32)> = manifest
            .shards
            .iter()
            .map(|s| (s.file.as_str(), s.iteration))
            .collect();
        assert_eq!(
            files,
            [
                ("shard-000000.safetensors", 0),
                ("shard-000001.safetensors", 0),
                ("shard-000002.safetensors", 1)
            ]
        );
        let all = DatasetReader::open(dir.path())
            .expect("open")
            .load_all()
            .expect("load");
        assert_eq!(all.len(), 8);
        assert_eq!(all[4], sample(4, 0));
        assert_eq!(all[5], sample(100, 1));
    }

    #[test]
    fn appending_with_different_settings_is_refused_naming_the_field() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 2, 4);
        let err = DatasetWriter::append_matching(dir.path(), &header(99), 1).expect_err("mismatch");
        assert!(
            matches!(&err, DatasetError::HeaderMismatch { field: "seed", existing, requested, .. }
                if existing == "7" && requested == "99"),
            "{err:?}"
        );
        assert!(err.to_string().contains("new dataset directory"), "{err}");
    }

    #[test]
    fn a_sample_from_another_iteration_or_image_size_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut writer = DatasetWriter::create(dir.path(), header(7)).expect("create");
        assert!(matches!(
            writer.push(sample(0, 2)),
            Err(DatasetError::SampleIteration {
                expected: 0,
                actual: 2
            })
        ));
        let small = Sample {
            occupancy: vec![0; 5],
            ..sample(0, 0)
        };
        assert!(matches!(
            writer.push(small),
            Err(DatasetError::SampleImageSize {
                expected: 36,
                actual: 5,
                ..
            })
        ));
        let nan = Sample {
            wheels: [f32::NAN, 0.0],
            ..sample(0, 0)
        };
        assert!(matches!(
            writer.push(nan),
            Err(DatasetError::NonFiniteSample { .. })
        ));
        assert_eq!(writer.finish().expect("finish").samples, 0);
    }

    #[test]
    fn creating_over_an_existing_dataset_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 1, 4);
        assert!(matches!(
            DatasetWriter::create(dir.path(), header(7)),
            Err(DatasetError::AlreadyExists { .. })
        ));
        let other = tempfile::tempdir().expect("tempdir");
        fs::write(other.path().join("notes.txt"), "x").expect("write");
        assert!(matches!(
            DatasetWriter::create(other.path(), header(7)),
            Err(DatasetError::DirectoryNotEmpty { .. })
        ));
    }

    #[test]
    fn a_truncated_shard_is_named_with_its_sample_count_and_the_fix() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 6, 4);
        let shard = dir.path().join("shard-000001.safetensors");
        let bytes = fs::read(&shard).expect("read");
        fs::write(&shard, &bytes[..bytes.len() - 10]).expect("truncate");
        let err = DatasetReader::open(dir.path()).expect_err("truncated");
        let message = err.to_string();
        assert!(
            matches!(err, DatasetError::ShardSize { samples: 2, .. }),
            "{err:?}"
        );
        assert!(
            message.contains("shard-000001.safetensors is truncated (expected 2 samples"),
            "{message}"
        );
        assert!(
            message.contains("delete it and its manifest entry or re-run `formation collect`"),
            "{message}"
        );
    }

    #[test]
    fn a_corrupted_shard_fails_its_checksum_when_read() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 3, 4);
        let shard = dir.path().join("shard-000000.safetensors");
        let mut bytes = fs::read(&shard).expect("read");
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        fs::write(&shard, &bytes).expect("write");
        let reader = DatasetReader::open(dir.path()).expect("sizes still match");
        let err = reader.load_all().expect_err("corrupt");
        assert!(matches!(err, DatasetError::CorruptShard { .. }), "{err:?}");
        assert!(err.to_string().contains("checksum"), "{err}");
    }

    #[test]
    fn a_missing_shard_is_reported() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 3, 4);
        let missing = dir.path().join("shard-000000.safetensors");
        fs::remove_file(&missing).expect("remove");
        let err = DatasetReader::open(dir.path()).expect_err("a missing shard");
        assert!(
            matches!(&err, DatasetError::MissingShard { path } if *path == missing),
            "{err:?}"
        );
    }

    #[test]
    fn an_unknown_version_or_format_is_refused_before_anything_else() {
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 1, 4);
        edit_manifest(dir.path(), |value| value["version"] = 4.into());
        let err = DatasetReader::open(dir.path()).expect_err("version");
        assert!(
            matches!(err, DatasetError::UnsupportedVersion { found: 4, .. }),
            "{err:?}"
        );
        assert!(
            err.to_string().contains("reads versions 1, 2 and 3"),
            "{err}"
        );

        let path = dir.path().join(MANIFEST_FILE);
        fs::write(&path, r#"{"format": "something-else", "version": 1}"#).expect("write");
        assert!(matches!(
            DatasetReader::open(dir.path()),
            Err(DatasetError::WrongFormat { found, .. }) if found == "something-else"
        ));
        fs::write(&path, "{ not json").expect("write");
        assert!(matches!(
            DatasetReader::open(dir.path()),
            Err(DatasetError::BadManifest { .. })
        ));
    }

    #[test]
    fn a_directory_without_a_manifest_is_not_a_dataset() {
        let dir = tempfile::tempdir().expect("tempdir");
        let err = DatasetReader::open(dir.path()).expect_err("no manifest");
        assert!(matches!(err, DatasetError::NotADataset { .. }));
        assert!(err.to_string().contains("formation collect --out"), "{err}");
    }

    #[test]
    fn a_zero_shard_size_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let writer = DatasetWriter::create(dir.path(), header(1)).expect("create");
        assert!(matches!(
            writer.with_shard_size(0),
            Err(DatasetError::ZeroShardSize)
        ));
    }

    fn write_with_ranges(dir: &Path, count: u32, shard_size: usize) -> Manifest {
        let samples = (0..count).map(|k| sample_with_ranges(k, 0));
        write_samples(dir, header_with_ranges(7), shard_size, samples)
    }

    /// The manifest of `dir` as JSON.
    fn manifest_json(dir: &Path) -> serde_json::Value {
        let text = fs::read_to_string(dir.join(MANIFEST_FILE)).expect("manifest");
        serde_json::from_str(&text).expect("json")
    }

    #[test]
    fn a_header_without_ranges_is_todays_byte_for_byte() {
        // The id of `header(7)` as builds before ranges computed it (FNV-1a 64 over its
        // length-prefixed fields, computed apart from this code): a dataset without ranges keeps
        // its id, its version and its bytes.
        assert_eq!(header(7).dataset_id, "6e5ecb97c951d8be");
        assert_eq!(header(7).with_ranges(None), header(7));
        assert_eq!(header(7).format_version, 1);
        assert!(header(7).settings.ranges.is_none());
        let json = serde_json::to_value(header(7)).expect("json");
        assert!(json.get("ranges").is_none(), "{json}");
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), 3, 8);
        let value = manifest_json(dir.path());
        assert_eq!(value["version"], 1);
        assert!(value.get("ranges").is_none(), "{value}");
        let (tensors, version) = shard_tensors(dir.path(), "shard-000000.safetensors");
        assert!(!tensors.contains_key("ranges"));
        assert_eq!(version, "1");
    }

    #[test]
    fn ranges_change_the_id_and_the_version_and_round_trip() {
        let with = header_with_ranges(7);
        assert_eq!(with.format_version, DATASET_VERSION_WITH_RANGES);
        assert_eq!(with.format_version, 2);
        assert_ne!(with.dataset_id, header(7).dataset_id);
        assert_ne!(
            with.dataset_id,
            header(7)
                .with_ranges(Some(RangeInput::new(6, 2.0).expect("ranges")))
                .dataset_id
        );
        assert_eq!(with.clone().with_ranges(None), header(7));
        assert_eq!(with.range_sectors(), 6);

        let dir = tempfile::tempdir().expect("tempdir");
        let manifest = write_with_ranges(dir.path(), 10, 4);
        let value = manifest_json(dir.path());
        assert_eq!(value["version"], 2);
        assert_eq!(value["ranges"], "sectors=6,clip=3");
        let reader = DatasetReader::open(dir.path()).expect("open");
        assert_eq!(reader.header(), &with);
        assert_eq!(reader.manifest(), &manifest);
        let expected: Vec<Sample> = (0..10).map(|k| sample_with_ranges(k, 0)).collect();
        assert_eq!(reader.load_all().expect("load"), expected);

        let (tensors, version) = shard_tensors(dir.path(), "shard-000002.safetensors");
        assert_eq!(tensors["ranges"], (Dtype::F32, vec![2, 6]));
        assert_eq!(version, "2");

        let all = append_and_load(dir.path(), &with, sample_with_ranges(50, 1));
        assert_eq!(all[10], sample_with_ranges(50, 1));
    }

    #[test]
    fn appending_with_other_ranges_or_neighbours_is_refused_naming_them() {
        let other_ranges = header(7).with_ranges(Some(RangeInput::new(6, 2.5).expect("ranges")));
        for (ranged, appended, field, existing_text, requested_text) in [
            (
                false,
                header_with_ranges(7),
                "range input",
                "none",
                "sectors=6,clip=3",
            ),
            (
                true,
                other_ranges,
                "range input",
                "sectors=6,clip=3",
                "sectors=6,clip=2.5",
            ),
            (
                false,
                header_with_neighbours(7),
                "neighbour input",
                "none",
                "slots=3,threshold=1.3,nearest=2",
            ),
        ] {
            let dir = tempfile::tempdir().expect("tempdir");
            if ranged {
                write_with_ranges(dir.path(), 2, 4);
            } else {
                write(dir.path(), 2, 4);
            }
            let err =
                DatasetWriter::append_matching(dir.path(), &appended, 1).expect_err("mismatch");
            assert!(
                matches!(&err, DatasetError::HeaderMismatch { field: f, existing, requested, .. }
                    if *f == field && existing == existing_text && requested == requested_text),
                "{err:?}"
            );
        }
    }

    #[test]
    fn a_label_law_changes_the_id_round_trips_and_refuses_appends_of_another() {
        let unshaped = crate::label_law::LabelLaw {
            unshaped: true,
            ..Default::default()
        };
        // The default law stores nothing and keeps the id and bytes of before.
        assert_eq!(header(7).with_labels(Default::default()), header(7));
        assert!(
            serde_json::to_value(header(7))
                .expect("json")
                .get("labels")
                .is_none()
        );
        let labelled = header(7).with_labels(unshaped);
        assert_ne!(labelled.dataset_id, header(7).dataset_id);

        let dir = tempfile::tempdir().expect("tempdir");
        let mut writer = DatasetWriter::create(dir.path(), labelled.clone()).expect("create");
        writer.push(sample(0, 0)).expect("push");
        writer.finish().expect("finish");
        let value = manifest_json(dir.path());
        assert_eq!(
            value["labels"],
            serde_json::json!({"unshaped": true}),
            "{value}"
        );
        let reader = DatasetReader::open(dir.path()).expect("open");
        assert_eq!(reader.header(), &labelled);

        // DAgger samples labelled by the default law may not join an unshaped dataset.
        let err = DatasetWriter::append_matching(dir.path(), &header(7), 1).expect_err("mismatch");
        assert!(
            matches!(&err, DatasetError::HeaderMismatch { field: "label law", existing, .. }
                if existing.contains("--unshaped-labels")),
            "{err:?}"
        );
    }

    fn write_with_neighbours(dir: &Path, header: DatasetHeader, samples: &[Sample]) -> Manifest {
        write_samples(dir, header, 4, samples.iter().cloned())
    }

    #[test]
    fn a_header_without_neighbours_keeps_its_version_id_and_bytes() {
        // The ids of before neighbours (the first is pinned above, apart from this code).
        assert_eq!(header(7).with_neighbours(None), header(7));
        assert_eq!(header(7).dataset_id, "6e5ecb97c951d8be");
        let ranged = header_with_ranges(7);
        assert_eq!(ranged.clone().with_neighbours(None), ranged);
        assert_eq!(ranged.format_version, 2);
        for header in [header(7), ranged] {
            let json = serde_json::to_value(&header).expect("json");
            assert!(json.get("neighbours").is_none(), "{json}");
            assert_eq!(header.neighbour_values(), 0);
        }
    }

    #[test]
    fn neighbours_make_version_3_change_the_id_and_round_trip() {
        let with = header_with_neighbours(7);
        assert_eq!(with.format_version, 3);
        assert_eq!(with.format_version, DATASET_VERSION);
        assert_ne!(with.dataset_id, header(7).dataset_id);
        let other_rule =
            header(7).with_neighbours(Some(NeighbourInput::new(3, 1.5, 2).expect("neighbours")));
        assert_ne!(with.dataset_id, other_rule.dataset_id);
        assert_eq!(with.clone().with_neighbours(None), header(7));
        assert_eq!((with.neighbour_slots(), with.neighbour_values()), (3, 12));

        let dir = tempfile::tempdir().expect("tempdir");
        let samples: Vec<Sample> = (0..10).map(|k| sample_with_neighbours(k, 0)).collect();
        let manifest = write_with_neighbours(dir.path(), with.clone(), &samples);
        let value = manifest_json(dir.path());
        assert_eq!(value["version"], 3);
        assert_eq!(value["neighbours"], "slots=3,threshold=1.3,nearest=2");
        assert!(value.get("ranges").is_none(), "{value}");
        let reader = DatasetReader::open(dir.path()).expect("open");
        assert_eq!(reader.header(), &with);
        assert_eq!(reader.manifest(), &manifest);
        assert_eq!(reader.load_all().expect("load"), samples);

        let (tensors, version) = shard_tensors(dir.path(), "shard-000002.safetensors");
        assert_eq!(tensors["neighbours"], (Dtype::F32, vec![2, 3, 4]));
        assert!(!tensors.contains_key("ranges"));
        assert_eq!(version, "3");

        let all = append_and_load(dir.path(), &with, sample_with_neighbours(50, 1));
        assert_eq!(all[10], sample_with_neighbours(50, 1));
    }

    #[test]
    fn ranges_and_neighbours_together_are_version_3_and_round_trip() {
        let both = header_with_ranges(7).with_neighbours(Some(neighbours()));
        assert_eq!(both.format_version, 3);
        assert_eq!(
            header_with_neighbours(7).with_ranges(Some(ranges())),
            both,
            "the order of the two does not matter"
        );
        assert_ne!(both.dataset_id, header_with_neighbours(7).dataset_id);
        assert_ne!(both.dataset_id, header_with_ranges(7).dataset_id);
        let samples: Vec<Sample> = (0..5)
            .map(|k| Sample {
                ranges: sample_with_ranges(k, 0).ranges,
                ..sample_with_neighbours(k, 0)
            })
            .collect();
        let dir = tempfile::tempdir().expect("tempdir");
        write_with_neighbours(dir.path(), both.clone(), &samples);
        let value = manifest_json(dir.path());
        assert_eq!(
            (&value["version"], &value["ranges"], &value["neighbours"]),
            (
                &serde_json::json!(3),
                &serde_json::json!("sectors=6,clip=3"),
                &serde_json::json!("slots=3,threshold=1.3,nearest=2")
            )
        );
        let reader = DatasetReader::open(dir.path()).expect("open");
        assert_eq!(reader.header(), &both);
        assert_eq!(reader.load_all().expect("load"), samples);
    }

    /// One of the two optional per-sample inputs, ranges or neighbours, as the tests that hold
    /// for both drive it: how to build settings and samples with it, and what its errors say.
    struct OptionalInput {
        /// Its name in the manifest, the shards and the errors: `ranges` or `neighbours`.
        name: &'static str,
        /// The test datasets' declaration of it, as the manifest writes it.
        declared: &'static str,
        /// The format version of a dataset that declares this input alone.
        version: u32,
        /// The test settings with this input alone, with `seed`.
        header: fn(u64) -> DatasetHeader,
        /// A test sample holding this input (`k`, `iteration`).
        sample: fn(u32, u32) -> Sample,
        /// How many values of this input a test sample holds.
        count: usize,
        /// This input's values in a sample.
        values: fn(&mut Sample) -> &mut Vec<f32>,
        /// What the error for a sample without this input's values says under the test settings.
        missing_values: &'static str,
        /// `(declared, values)` if the error is this input's wrong count: whether the dataset
        /// declares the input, and how many values the sample holds.
        wrong_count: fn(&DatasetError) -> Option<(bool, usize)>,
        /// `(version, declared)` if the error is a manifest whose version disagrees with this
        /// input.
        version_mismatch: fn(&DatasetError) -> Option<(u32, bool)>,
        /// A declaration out of this input's bounds, and a word of the error it gets.
        out_of_bounds: (&'static str, &'static str),
        /// The test settings with another size of this input, and how many values a sample of
        /// them holds.
        resized: fn() -> (DatasetHeader, usize),
        /// Why a shard of `resized` is corrupt under the test settings.
        resized_reason: &'static str,
    }

    /// The range input of [`header_with_ranges`].
    const RANGES: OptionalInput = OptionalInput {
        name: "ranges",
        declared: "sectors=6,clip=3",
        version: DATASET_VERSION_WITH_RANGES,
        header: header_with_ranges,
        sample: sample_with_ranges,
        count: 6,
        values: |sample| &mut sample.ranges,
        missing_values: "has 0 range values but the dataset declares 6 sectors (sectors=6,clip=3)",
        wrong_count: |err| match err {
            DatasetError::SampleRanges { declared, actual } => Some((declared.is_some(), *actual)),
            _ => None,
        },
        version_mismatch: |err| match err {
            DatasetError::RangesVersion {
                version, ranges, ..
            } => Some((*version, ranges.is_some())),
            _ => None,
        },
        out_of_bounds: ("sectors=2,clip=3", "sectors"),
        resized: || {
            let four = RangeInput::new(4, 3.0).expect("4 sectors");
            (header(7).with_ranges(Some(four)), 4)
        },
        resized_reason: "`ranges` is F32 [2, 4], expected F32 [2, 6]",
    };

    /// The neighbour input of [`header_with_neighbours`].
    const NEIGHBOURS: OptionalInput = OptionalInput {
        name: "neighbours",
        declared: "slots=3,threshold=1.3,nearest=2",
        version: DATASET_VERSION,
        header: header_with_neighbours,
        sample: sample_with_neighbours,
        count: 12,
        values: |sample| &mut sample.neighbours,
        missing_values: "has 0 neighbour values but the dataset declares 3 slots of 4 values \
                         (slots=3,threshold=1.3,nearest=2), 12 in all",
        wrong_count: |err| match err {
            DatasetError::SampleNeighbours { declared, actual } => {
                Some((declared.is_some(), *actual))
            }
            _ => None,
        },
        version_mismatch: |err| match err {
            DatasetError::NeighboursVersion {
                version,
                neighbours,
                ..
            } => Some((*version, neighbours.is_some())),
            _ => None,
        },
        out_of_bounds: ("slots=65,threshold=1.3,nearest=2", "slots"),
        resized: || {
            let four = NeighbourInput::with_default_rule(4).expect("4 slots");
            (header(7).with_neighbours(Some(four)), 16)
        },
        resized_reason: "`neighbours` is F32 [2, 4, 4], expected F32 [2, 3, 4]",
    };

    /// A new dataset of `input`'s test settings in `dir`, in one shard, holding `count` of its
    /// test samples.
    fn write_with(dir: &Path, input: &OptionalInput, count: u32) -> Manifest {
        let samples = (0..count).map(|k| (input.sample)(k, 0));
        write_samples(dir, (input.header)(7), 8, samples)
    }

    #[test]
    fn ranges_or_neighbours_of_the_wrong_length_or_not_finite_are_refused() {
        for input in [RANGES, NEIGHBOURS] {
            let name = input.name;
            let dir = tempfile::tempdir().expect("tempdir");
            let mut writer = DatasetWriter::create(dir.path(), (input.header)(7)).expect("create");
            let err = writer.push(sample(0, 0)).expect_err("no values");
            assert_eq!((input.wrong_count)(&err), Some((true, 0)), "{err:?}");
            assert!(err.to_string().contains(input.missing_values), "{err}");
            let mut short = (input.sample)(0, 0);
            assert_eq!((input.values)(&mut short).len(), input.count);
            (input.values)(&mut short).pop();
            let err = writer.push(short).expect_err("one value short");
            let one_short = Some((true, input.count - 1));
            assert_eq!((input.wrong_count)(&err), one_short, "{err:?}");
            for (index, bad) in [(3, f32::NAN), (3, f32::INFINITY), (5, f32::NAN)] {
                let mut not_finite = (input.sample)(0, 0);
                (input.values)(&mut not_finite)[index] = bad;
                let err = writer.push(not_finite).expect_err("not finite");
                assert!(
                    matches!(err, DatasetError::NonFiniteSample { field, .. } if field == name),
                    "{err:?}"
                );
            }
            assert_eq!(writer.finish().expect("finish").samples, 0);

            let other = tempfile::tempdir().expect("tempdir");
            let mut writer = DatasetWriter::create(other.path(), header(7)).expect("create");
            let err = writer.push((input.sample)(0, 0)).expect_err("undeclared");
            assert_eq!(
                (input.wrong_count)(&err),
                Some((false, input.count)),
                "{err:?}"
            );
            let undeclared = format!("declares no {name}");
            assert!(err.to_string().contains(&undeclared), "{err}");
        }
    }

    #[test]
    fn a_version_that_disagrees_with_the_ranges_or_neighbours_is_refused_naming_the_file() {
        // The input, whether the dataset holds it, the version its manifest is then edited to,
        // and another declaration the edit adds.
        for (input, held, version, also) in [
            (RANGES, true, 1, None),
            (RANGES, false, 2, None),
            (NEIGHBOURS, false, 3, None),
            (NEIGHBOURS, true, 1, None),
            (NEIGHBOURS, true, 2, Some(("ranges", RANGES.declared))),
        ] {
            let dir = tempfile::tempdir().expect("tempdir");
            if held {
                write_with(dir.path(), &input, 2);
            } else {
                write(dir.path(), 2, 4);
            }
            edit_manifest(dir.path(), |value| {
                value["version"] = version.into();
                if let Some((key, declared)) = also {
                    value[key] = declared.into();
                }
            });
            let err = DatasetReader::open(dir.path()).expect_err("a version that disagrees");
            let found = (input.version_mismatch)(&err);
            assert_eq!(found, Some((version, held)), "{err:?}");
            let declares = match held {
                true => format!("declares {} \"{}\"", input.name, input.declared),
                false => format!("declares no `{}`", input.name),
            };
            let message = err.to_string();
            let says = format!("manifest.json is dataset format version {version} but {declares}");
            assert!(message.contains(&says), "{message}");
            assert!(message.contains("re-run `formation collect`"), "{message}");
        }

        // A declaration out of its bounds.
        for input in [RANGES, NEIGHBOURS] {
            let dir = tempfile::tempdir().expect("tempdir");
            write_with(dir.path(), &input, 1);
            let (value, says) = input.out_of_bounds;
            assert_bad_declaration(dir.path(), input.version, input.name, value, says);
        }
    }

    #[test]
    fn a_shard_whose_ranges_or_neighbours_disagree_with_the_manifest_is_corrupt() {
        // A shard of a dataset with the input, listed in a manifest without it: the shard has a
        // tensor the manifest does not declare. The other way round: no tensor. And a shard of
        // another size of the input: a tensor of another shape.
        for input in [RANGES, NEIGHBOURS] {
            let with = tempfile::tempdir().expect("tempdir");
            write_with(with.path(), &input, 2);
            let without = tempfile::tempdir().expect("tempdir");
            write(without.path(), 2, 8);
            let resized = tempfile::tempdir().expect("tempdir");
            let (resized_header, count) = (input.resized)();
            let resized_samples = (0..2).map(|k| {
                let mut sample = sample(k, 0);
                *(input.values)(&mut sample) = vec![0.5; count];
                sample
            });
            write_samples(resized.path(), resized_header, 8, resized_samples);
            let with_manifest = manifest_json(with.path());
            let without_manifest = manifest_json(without.path());
            let name = input.name;
            for (dir, manifest, reason) in [
                (
                    with.path(),
                    &without_manifest,
                    format!("a `{name}` tensor, but the manifest declares no {name}"),
                ),
                (
                    without.path(),
                    &with_manifest,
                    format!("no `{name}` tensor"),
                ),
                (resized.path(), &with_manifest, input.resized_reason.into()),
            ] {
                let err = load_error_under(dir, manifest, 2);
                assert!(
                    matches!(&err, DatasetError::CorruptShard { reason: r, .. } if *r == reason),
                    "{err:?}"
                );
            }
        }
    }

    #[test]
    fn a_header_built_field_by_field_with_the_wrong_version_is_refused() {
        for (input, version) in [(RANGES, 1), (RANGES, 3), (NEIGHBOURS, 1), (NEIGHBOURS, 2)] {
            let mut header = (input.header)(7);
            header.format_version = version;
            let dir = tempfile::tempdir().expect("tempdir");
            let err = DatasetWriter::create(dir.path(), header).expect_err("inconsistent");
            assert!(
                matches!(err, DatasetError::InconsistentHeader { version: v, .. } if v == version),
                "{err:?}"
            );
            let message = err.to_string();
            let holds = format!("{} {}", input.name, input.declared);
            assert!(message.contains(&holds), "{message}");
            assert!(
                message.contains(&format!("with_{}", input.name)),
                "{message}"
            );
        }

        let dir = tempfile::tempdir().expect("tempdir");
        let too_many =
            header_with_ranges(7).with_ranges(Some(RangeInput::new(360, 3.0).expect("ranges")));
        let mut few_beams = too_many.clone();
        few_beams.settings.lidar.spec.beams = 100;
        let ranges = few_beams.settings.ranges;
        let few_beams = few_beams.with_ranges(ranges);
        assert!(matches!(
            DatasetWriter::create(dir.path(), few_beams),
            Err(DatasetError::RangeBeams { .. })
        ));
        DatasetWriter::create(dir.path(), too_many).expect("900 beams fill 360 sectors");
    }

    #[test]
    fn shard_names_parse_back_to_their_index() {
        assert_eq!(shard_index(&shard_file_name(42)), Some(42));
        assert_eq!(shard_index("manifest.json"), None);
        assert_eq!(shard_index("shard-x.safetensors"), None);
    }
}
