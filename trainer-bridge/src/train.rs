//! Runs the PyTorch trainer (`python -m formation_trainer train`) and reports what it produced.
//!
//! The trainer lives in `trainer-bridge/python` (package `formation_trainer`). [`train`] validates
//! the options and the datasets here (typed errors before a Python process starts), runs the
//! trainer with `PYTHONPATH` pointing at the package, forwards each stdout line to a callback and
//! parses the final `FORMATION_TRAIN_REPORT {json}` line. The trainer writes, beside `out`:
//! `<stem>.onnx` (the model, with the metadata contract), `<stem>.pt` (checkpoint for warm starts),
//! `<stem>.loss.csv` and `<stem>.loss.png`.
//!
//! The datasets decide whether the model takes the scan's ranges: data collected with ranges
//! (`formation collect --ranges sectors=K,clip=C`, dataset format version 2) trains a model with
//! the third input `ranges` and `formation.ranges` metadata ([`TrainReport::ranges`]); a warm start
//! from a model without ranges gains a range branch that starts with the old model's outputs.
//!
//! Python is found as: [`TrainOptions::python`], else `$FORMATION_PYTHON`, else
//! `<repo>/.venv/bin/python`, else `python3`.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde::Deserialize;

use crate::dataset::{DatasetError, DatasetReader};

/// The prefix of the trainer's final, machine-readable line.
pub const REPORT_PREFIX: &str = "FORMATION_TRAIN_REPORT ";
/// The exit status the trainer uses when a Python dependency is missing.
const MISSING_DEPENDENCY_EXIT: i32 = 3;
/// The environment variable naming the Python interpreter.
pub const PYTHON_ENV: &str = "FORMATION_PYTHON";
/// How many trailing stderr lines an error carries.
const STDERR_TAIL_LINES: usize = 20;
/// The fix for a Python without the trainer's dependencies.
const SETUP_HINT: &str =
    "install PyTorch and the trainer with `bash .ci/setup-python --train`, or set FORMATION_PYTHON";

/// What to train.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainOptions {
    /// Dataset directories (all must share occupancy, LIDAR and v_train).
    pub data: Vec<PathBuf>,
    /// The ONNX model to write; the checkpoint and loss curve go beside it.
    pub out: PathBuf,
    /// Passes over the training split.
    pub epochs: usize,
    /// Mini-batch size.
    pub batch_size: usize,
    /// Adam learning rate.
    pub lr: f64,
    /// `auto` (CUDA when available), `cpu` or `cuda`.
    pub device: String,
    /// Share of the runs held out for validation, in [0, 1).
    pub val_fraction: f64,
    /// Seeds the split, the shuffling and the initial weights.
    pub seed: u64,
    /// Warm start from this checkpoint (`.pt` written by an earlier training), or from the weights
    /// of a policy `.onnx` written by the trainer.
    pub init_from: Option<PathBuf>,
    /// The Python interpreter; `None` discovers one (see the module docs).
    pub python: Option<PathBuf>,
    /// Also write a few held-out inputs with the torch outputs to this JSON file (for parity tests).
    pub parity_out: Option<PathBuf>,
    /// The d* range \[m\] the model is declared for (its envelope, which must hold every d* of
    /// the data); `None`: the data's own range.
    pub d_star_range: Option<(f64, f64)>,
    /// The network to train; `None`: the warm start's, or the paper's when training from scratch.
    pub architecture: Option<Architecture>,
    /// Whether and how to use the task's exact symmetry under reflection about the robot's
    /// heading axis (rows of the image reversed, Δφ negated, wheels swapped).
    pub mirror: Mirror,
    /// Train each epoch on this many training samples, drawn afresh at random without
    /// replacement; `None`: every training sample. Keeps an epoch's cost fixed as a DAgger
    /// dataset grows, while every sample keeps the same chance of being drawn.
    pub samples_per_epoch: Option<usize>,
    /// Weight each sample's squared error by `(d_ref / d*)²` (`d_ref` makes the mean weight 1),
    /// so a team at small d* is fitted as tightly, relative to d*, as one at large d*: the
    /// success check is relative, a wheel-speed error is in metres (metadata
    /// `formation.train.relative_loss`).
    pub relative_loss: bool,
    /// What the model outputs: the paper's wheel speeds, or the expert's formation velocity in
    /// the robot's frame (computed from the dataset's wheel labels; declared in the model's
    /// `formation.output`).
    pub output: formation_proto::PolicyOutput,
    /// Weight each sample's squared error by `1 / (|f| + eps)` (`f` the expert's formation
    /// velocity, mean weight 1), so that small corrections count; `None`: unweighted
    /// (metadata `formation.train.response_weight`).
    pub response_weight: Option<f64>,
}

/// The policy networks the trainer can build (`formation_trainer.model.ARCHITECTURES`). Each
/// declares its inputs and output in its metadata, so an agent runs any of them without knowing
/// which.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Architecture {
    /// The paper's CNN, with its exact layer sizes (a 32-unit head).
    Paper,
    /// The same convolutions with 64 channels in the last two and a head of two 256-unit layers:
    /// about twice the arithmetic, for teams with many neighbours.
    Wide,
    /// The paper's convolutions with the wide network's head (two 256-unit layers): about 1.2
    /// times the paper's arithmetic, and a head that can hold many neighbours at once.
    WideHead,
    /// A network that sums one learned term per neighbour the robot detects (issue 34), for a
    /// dataset that carries the `neighbours` input; it leaves the image unused. A few thousand
    /// multiply-adds.
    Pair,
    /// The pair network with each term scaled by the expert's pair profile, `(r^4 - 1) / r^3` in
    /// units of d*: the layers learn each neighbour's weight, the profile its shape in distance,
    /// so a neighbour at d* adds nothing and a close one repels as the law does.
    PairPotential,
}

impl Architecture {
    /// Every architecture, in the order `--help` lists them.
    pub const ALL: [Architecture; 5] = [
        Architecture::Paper,
        Architecture::Wide,
        Architecture::WideHead,
        Architecture::Pair,
        Architecture::PairPotential,
    ];

    /// The name the trainer and the command line use.
    pub fn name(self) -> &'static str {
        match self {
            Architecture::Paper => "paper",
            Architecture::Wide => "wide",
            Architecture::WideHead => "wide-head",
            Architecture::Pair => "pair",
            Architecture::PairPotential => "pair-potential",
        }
    }
}

impl std::str::FromStr for Architecture {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Architecture::ALL
            .into_iter()
            .find(|a| a.name() == text.trim())
            .ok_or_else(|| {
                let names: Vec<_> = Architecture::ALL.iter().map(|a| a.name()).collect();
                format!(
                    "unknown network architecture {text:?}: choose one of {}",
                    names.join(", ")
                )
            })
    }
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            data: Vec::new(),
            out: PathBuf::from("policy.onnx"),
            epochs: 10,
            batch_size: 32,
            lr: 1e-4,
            device: "auto".to_owned(),
            val_fraction: 0.1,
            seed: 0,
            init_from: None,
            python: None,
            parity_out: None,
            d_star_range: None,
            architecture: None,
            mirror: Mirror::Off,
            samples_per_epoch: None,
            relative_loss: false,
            output: formation_proto::PolicyOutput::Wheels,
            response_weight: None,
        }
    }
}

/// How training uses the task's exact symmetry under reflection about the robot's heading axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mirror {
    /// Not at all.
    #[default]
    Off,
    /// Train on reflected samples too, and export the network itself: it is as symmetric as it
    /// learned to be, at one evaluation per decision (`formation.train.mirror = true`).
    Augment,
    /// Train on reflected samples too, and export a network whose output is averaged over the
    /// reflection, so the policy is exactly symmetric at twice the arithmetic
    /// (`formation.policy.mirror_averaged = true`).
    Average,
}

impl Mirror {
    /// The mirror use the command line's two flags name (`--mirror` and
    /// `--mirror-augment-only`, which exclude each other).
    pub fn from_flags(average: bool, augment_only: bool) -> Mirror {
        match (average, augment_only) {
            (true, _) => Mirror::Average,
            (false, true) => Mirror::Augment,
            (false, false) => Mirror::Off,
        }
    }
}

/// What the trainer reported.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct TrainReport {
    /// Epochs run.
    pub epochs: usize,
    /// Samples used (training + validation).
    pub samples: usize,
    /// Samples in the training split.
    pub train_samples: usize,
    /// Samples in the validation split.
    pub val_samples: usize,
    /// Training samples drawn per epoch (all of the training split unless capped).
    pub samples_per_epoch: usize,
    /// Mean squared error over the training split in the last epoch.
    pub final_train_loss: f64,
    /// Mean squared error over the validation split after the last epoch (NaN-free; equals the
    /// training loss when there is no validation split).
    pub final_val_loss: f64,
    /// Wall-clock seconds of training (excluding export).
    pub seconds: f64,
    /// The device trained on, e.g. `cpu`.
    pub device: String,
    /// The dataset id(s) recorded in the model, `+`-joined for several datasets.
    pub dataset_id: String,
    /// Largest |torch - onnxruntime| over the parity samples.
    pub parity_max_abs_diff: f64,
    /// The ONNX model.
    pub model: PathBuf,
    /// The checkpoint.
    pub checkpoint: PathBuf,
    /// The loss CSV.
    pub loss_csv: PathBuf,
    /// The loss plot.
    pub loss_png: PathBuf,
    /// The scan's ranges the model takes beside its image (its `formation.ranges`): the
    /// datasets' range input, or `None` for data without ranges.
    #[serde(
        default,
        deserialize_with = "crate::dataset::declared_text::deserialize"
    )]
    pub ranges: Option<formation_proto::RangeInput>,
}

/// Why training did not produce a model.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// An option is out of range.
    #[error("invalid training option {option} = {value}: {reason}")]
    InvalidOption {
        /// The option.
        option: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        reason: &'static str,
    },
    /// A dataset is missing or damaged.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The interpreter could not be started.
    #[error("could not start Python `{python}`: {source}; {SETUP_HINT}")]
    PythonNotFound {
        /// The interpreter tried.
        python: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The interpreter lacks PyTorch (or another trainer dependency).
    #[error("PyTorch not found for {python}: {SETUP_HINT} ({detail})")]
    TorchMissing {
        /// The interpreter.
        python: PathBuf,
        /// The trainer's message, e.g. "No module named 'torch'".
        detail: String,
    },
    /// Reading the trainer's output failed.
    #[error("could not read the trainer's output: {0}")]
    Output(std::io::Error),
    /// The trainer exited with an error.
    #[error("the trainer ({python}) failed with {status}; its last messages:\n{stderr_tail}")]
    Failed {
        /// The interpreter.
        python: PathBuf,
        /// The exit status.
        status: String,
        /// The last lines it wrote to stderr.
        stderr_tail: String,
    },
    /// The trainer exited cleanly without its report line.
    #[error(
        "the trainer exited without a `{REPORT_PREFIX}` line; its last messages:\n{stderr_tail}"
    )]
    MissingReport {
        /// The last lines it wrote to stderr.
        stderr_tail: String,
    },
    /// The report line is not the expected JSON.
    #[error("the trainer's report line is malformed ({source}): {line}")]
    BadReport {
        /// The line.
        line: String,
        /// The parse error.
        source: serde_json::Error,
    },
}

/// Trains a policy: validates `opts` and the datasets, runs the Python trainer, forwards each of
/// its progress lines to `on_line`, and returns its report.
pub fn train(
    opts: &TrainOptions,
    on_line: &mut dyn FnMut(&str),
) -> Result<TrainReport, TrainError> {
    validate(opts)?;
    for dir in &opts.data {
        DatasetReader::open(dir)?;
    }
    let python = find_python(opts.python.as_deref());
    let mut command = Command::new(&python);
    command
        .args(trainer_args(opts))
        .env("PYTHONPATH", python_path())
        .env("PYTHONUNBUFFERED", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = command
        .spawn()
        .map_err(|source| TrainError::PythonNotFound {
            python: python.clone(),
            source,
        })?;
    let stderr = child.stderr.take();
    let stderr_reader = std::thread::spawn(move || stderr.map(tail_lines).unwrap_or_default());
    let mut report_line = None;
    let mut read_error = None;
    if let Some(stdout) = child.stdout.take() {
        for line in BufReader::new(stdout).lines() {
            match line {
                Ok(line) => match line.strip_prefix(REPORT_PREFIX) {
                    Some(json) => report_line = Some(json.to_owned()),
                    None => on_line(&line),
                },
                Err(e) => {
                    read_error = Some(e);
                    break;
                }
            }
        }
    }
    let status = child.wait().map_err(TrainError::Output)?;
    let stderr_tail = stderr_reader.join().unwrap_or_default();
    if let Some(e) = read_error {
        return Err(TrainError::Output(e));
    }
    if status.code() == Some(MISSING_DEPENDENCY_EXIT) {
        return Err(TrainError::TorchMissing {
            python,
            detail: stderr_tail.trim().to_owned(),
        });
    }
    if !status.success() {
        return Err(TrainError::Failed {
            python,
            status: status.to_string(),
            stderr_tail,
        });
    }
    let Some(line) = report_line else {
        return Err(TrainError::MissingReport { stderr_tail });
    };
    serde_json::from_str(&line).map_err(|source| TrainError::BadReport { line, source })
}

fn validate(opts: &TrainOptions) -> Result<(), TrainError> {
    let invalid = |option, value: String, reason| {
        Err(TrainError::InvalidOption {
            option,
            value,
            reason,
        })
    };
    if opts.data.is_empty() {
        return invalid("data", "[]".into(), "give at least one dataset directory");
    }
    if opts.epochs == 0 {
        return invalid("epochs", "0".into(), "must be at least 1");
    }
    if opts.batch_size == 0 {
        return invalid("batch_size", "0".into(), "must be at least 1");
    }
    if opts.samples_per_epoch == Some(0) {
        return invalid(
            "samples_per_epoch",
            "0".into(),
            "must be at least 1 (leave it out to use every sample)",
        );
    }
    if !(opts.lr.is_finite() && opts.lr > 0.0) {
        return invalid("lr", opts.lr.to_string(), "must be finite and > 0");
    }
    if let Some(eps) = opts.response_weight
        && !(eps.is_finite() && eps > 0.0)
    {
        return invalid(
            "response_weight",
            eps.to_string(),
            "must be a speed > 0 m/s (for example 0.05)",
        );
    }
    if !(0.0..1.0).contains(&opts.val_fraction) {
        return invalid(
            "val_fraction",
            opts.val_fraction.to_string(),
            "must be in [0, 1)",
        );
    }
    if !matches!(opts.device.as_str(), "auto" | "cpu" | "cuda") {
        return invalid(
            "device",
            opts.device.clone(),
            "must be `auto`, `cpu` or `cuda`",
        );
    }
    if opts.out.extension().is_none_or(|e| e != "onnx") {
        return invalid(
            "out",
            opts.out.display().to_string(),
            "must be a path ending in .onnx",
        );
    }
    Ok(())
}

/// The command line after the interpreter: `-m formation_trainer train ...`.
fn trainer_args(opts: &TrainOptions) -> Vec<std::ffi::OsString> {
    let mut args: Vec<std::ffi::OsString> =
        vec!["-m".into(), "formation_trainer".into(), "train".into()];
    for dir in &opts.data {
        args.push("--data".into());
        args.push(dir.into());
    }
    let mut push = |flag: &str, value: std::ffi::OsString| {
        args.push(flag.into());
        args.push(value);
    };
    push("--out", opts.out.as_os_str().to_owned());
    push("--epochs", opts.epochs.to_string().into());
    push("--batch-size", opts.batch_size.to_string().into());
    push("--lr", opts.lr.to_string().into());
    push("--device", opts.device.clone().into());
    push("--val-fraction", opts.val_fraction.to_string().into());
    push("--seed", opts.seed.to_string().into());
    if let Some(init) = &opts.init_from {
        push("--init-from", init.as_os_str().to_owned());
    }
    if let Some(parity) = &opts.parity_out {
        push("--parity-out", parity.as_os_str().to_owned());
    }
    if let Some((min, max)) = opts.d_star_range {
        push("--d-star-range", format!("{min},{max}").into());
    }
    if let Some(architecture) = opts.architecture {
        push("--architecture", architecture.name().into());
    }
    if let Some(count) = opts.samples_per_epoch {
        push("--samples-per-epoch", count.to_string().into());
    }
    if opts.output != formation_proto::PolicyOutput::Wheels {
        push("--output", opts.output.name().into());
    }
    if let Some(eps) = opts.response_weight {
        push("--response-weight", eps.to_string().into());
    }
    match opts.mirror {
        Mirror::Off => {}
        Mirror::Augment => args.push("--mirror-augment-only".into()),
        Mirror::Average => args.push("--mirror".into()),
    }
    if opts.relative_loss {
        args.push("--relative-loss".into());
    }
    args
}

/// Reads all of `stream`, keeping its last [`STDERR_TAIL_LINES`] lines.
fn tail_lines(stream: impl Read) -> String {
    let mut tail = VecDeque::with_capacity(STDERR_TAIL_LINES);
    for line in BufReader::new(stream).lines().map_while(Result::ok) {
        if tail.len() == STDERR_TAIL_LINES {
            tail.pop_front();
        }
        tail.push_back(line);
    }
    Vec::from(tail).join("\n")
}

/// The workspace root: the nearest ancestor of the current directory whose `Cargo.toml` declares
/// `[workspace]`, else the one this crate was built in.
pub fn repo_root() -> PathBuf {
    let from_cwd = std::env::current_dir().ok().and_then(|cwd| {
        cwd.ancestors()
            .find(|dir| {
                std::fs::read_to_string(dir.join("Cargo.toml"))
                    .is_ok_and(|text| text.lines().any(|l| l.trim() == "[workspace]"))
            })
            .map(Path::to_path_buf)
    });
    from_cwd.unwrap_or_else(|| {
        let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
        manifest_dir.parent().unwrap_or(manifest_dir).to_path_buf()
    })
}

/// The directory holding the `formation_trainer` package.
pub fn python_package_dir() -> PathBuf {
    let in_repo = repo_root().join("trainer-bridge").join("python");
    if in_repo.join("formation_trainer").is_dir() {
        in_repo
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("python")
    }
}

/// `PYTHONPATH` for the trainer: the package directory, then any inherited entries.
fn python_path() -> std::ffi::OsString {
    let mut paths = vec![python_package_dir()];
    if let Some(existing) = std::env::var_os("PYTHONPATH") {
        paths.extend(std::env::split_paths(&existing));
    }
    std::env::join_paths(paths).unwrap_or_else(|_| python_package_dir().into_os_string())
}

/// The interpreter to run: `explicit`, else `$FORMATION_PYTHON`, else `<repo>/.venv/bin/python`
/// if it exists, else `python3`.
pub fn find_python(explicit: Option<&Path>) -> PathBuf {
    let from_env = std::env::var_os(PYTHON_ENV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from);
    let venv = repo_root().join(".venv").join("bin").join("python");
    choose_python(explicit, from_env, venv.is_file().then_some(venv))
}

/// The discovery order, without I/O.
fn choose_python(
    explicit: Option<&Path>,
    from_env: Option<PathBuf>,
    venv: Option<PathBuf>,
) -> PathBuf {
    explicit
        .map(Path::to_path_buf)
        .or(from_env)
        .or(venv)
        .unwrap_or_else(|| PathBuf::from("python3"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Python trainer turns wheel labels into formation-velocity targets with the expert's
    /// reference cap: its constant is the Rust one.
    #[test]
    fn the_trainers_reference_cap_is_the_experts() {
        let source = include_str!("../python/formation_trainer/train.py");
        let value = source
            .lines()
            .find_map(|line| line.strip_prefix("MAX_REFERENCE_SPEED = "))
            .expect("train.py defines MAX_REFERENCE_SPEED");
        assert_eq!(
            value.trim().parse::<f64>(),
            Ok(formation_proto::MAX_REFERENCE_SPEED)
        );
    }

    fn opts() -> TrainOptions {
        TrainOptions {
            data: vec!["data/expert".into()],
            out: "models/bc.onnx".into(),
            ..TrainOptions::default()
        }
    }

    #[test]
    fn defaults_are_the_papers_settings() {
        let d = TrainOptions::default();
        assert_eq!((d.epochs, d.batch_size, d.lr), (10, 32, 1e-4));
        assert_eq!(
            (d.device.as_str(), d.val_fraction, d.seed),
            ("auto", 0.1, 0)
        );
        assert!(d.init_from.is_none() && d.python.is_none());
    }

    #[test]
    fn python_discovery_prefers_explicit_then_env_then_venv() {
        let env = Some(PathBuf::from("/env/python"));
        let venv = Some(PathBuf::from("/repo/.venv/bin/python"));
        let explicit = Path::new("/explicit/python");
        assert_eq!(
            choose_python(Some(explicit), env.clone(), venv.clone()),
            explicit
        );
        assert_eq!(
            choose_python(None, env.clone(), venv.clone()),
            PathBuf::from("/env/python")
        );
        assert_eq!(
            choose_python(None, None, venv),
            PathBuf::from("/repo/.venv/bin/python")
        );
        assert_eq!(choose_python(None, None, None), PathBuf::from("python3"));
    }

    #[test]
    fn options_are_validated_before_python_starts() {
        let cases: [(TrainOptions, &str); 8] = [
            (
                TrainOptions {
                    data: vec![],
                    ..opts()
                },
                "data",
            ),
            (
                TrainOptions {
                    epochs: 0,
                    ..opts()
                },
                "epochs",
            ),
            (
                TrainOptions {
                    batch_size: 0,
                    ..opts()
                },
                "batch_size",
            ),
            (
                TrainOptions {
                    lr: f64::NAN,
                    ..opts()
                },
                "lr",
            ),
            (
                TrainOptions {
                    val_fraction: 1.0,
                    ..opts()
                },
                "val_fraction",
            ),
            (
                TrainOptions {
                    device: "tpu".into(),
                    ..opts()
                },
                "device",
            ),
            (
                TrainOptions {
                    out: "model.pt".into(),
                    ..opts()
                },
                "out",
            ),
            (
                TrainOptions {
                    samples_per_epoch: Some(0),
                    ..opts()
                },
                "samples_per_epoch",
            ),
        ];
        for (case, field) in cases {
            let err = validate(&case).expect_err(field);
            assert!(
                matches!(err, TrainError::InvalidOption { option, .. } if option == field),
                "{field}"
            );
        }
        assert!(validate(&opts()).is_ok());
    }

    #[test]
    fn trainer_arguments_carry_every_option() {
        let args: Vec<String> = trainer_args(&TrainOptions {
            data: vec!["a".into(), "b".into()],
            init_from: Some("prev.pt".into()),
            seed: 9,
            d_star_range: Some((0.8, 2.5)),
            architecture: Some(Architecture::Wide),
            mirror: Mirror::Average,
            samples_per_epoch: Some(200_000),
            relative_loss: true,
            output: formation_proto::PolicyOutput::FormationVelocity,
            response_weight: Some(0.05),
            ..opts()
        })
        .into_iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
        let joined = args.join(" ");
        assert!(
            joined.starts_with("-m formation_trainer train --data a --data b --out models/bc.onnx"),
            "{joined}"
        );
        for part in [
            "--epochs 10",
            "--batch-size 32",
            "--lr 0.0001",
            "--device auto",
            "--val-fraction 0.1",
            "--seed 9",
            "--d-star-range 0.8,2.5",
            "--init-from prev.pt",
            "--architecture wide",
            "--samples-per-epoch 200000",
            " --mirror",
            " --relative-loss",
            "--output formation_velocity",
            "--response-weight 0.05",
        ] {
            assert!(joined.contains(part), "{part} missing in {joined}");
        }
        assert!(!joined.contains("--parity-out"));
    }

    #[test]
    fn architectures_parse_from_their_names_and_nothing_else() {
        for architecture in Architecture::ALL {
            assert_eq!(architecture.name().parse(), Ok(architecture));
        }
        let err = "wdie".parse::<Architecture>().unwrap_err();
        assert!(
            err.contains("\"wdie\"")
                && err.contains("paper, wide, wide-head, pair, pair-potential"),
            "{err}"
        );
        let plain: Vec<String> = trainer_args(&opts())
            .into_iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        assert!(!plain.contains(&"--architecture".to_owned()), "{plain:?}");
        assert!(!plain.contains(&"--mirror".to_owned()), "{plain:?}");
        assert!(
            !plain.contains(&"--samples-per-epoch".to_owned()),
            "{plain:?}"
        );
    }

    #[test]
    fn a_report_names_the_range_input_or_none() {
        let report = |ranges: &str| {
            format!(
                r#"{{"epochs": 1, "samples": 2, "train_samples": 1, "val_samples": 1,
                "samples_per_epoch": 1, "final_train_loss": 0.5, "final_val_loss": 0.5,
                "seconds": 1.0, "device": "cpu", "dataset_id": "d", "parity_max_abs_diff": 0.0,
                "model": "m.onnx", "checkpoint": "m.pt", "loss_csv": "m.loss.csv",
                "loss_png": "m.loss.png"{ranges}}}"#
            )
        };
        let parse = |text: String| serde_json::from_str::<TrainReport>(&text);
        assert_eq!(parse(report("")).expect("no key").ranges, None);
        assert_eq!(
            parse(report(r#", "ranges": null"#)).expect("null").ranges,
            None
        );
        assert_eq!(
            parse(report(r#", "ranges": "sectors=100,clip=3""#))
                .expect("ranges")
                .ranges,
            Some(formation_proto::RangeInput::new(100, 3.0).expect("ranges"))
        );
        assert!(parse(report(r#", "ranges": "sectors=1,clip=3""#)).is_err());
    }

    #[test]
    fn stderr_tail_keeps_the_last_lines() {
        let text: String = (0..30).map(|i| format!("line {i}\n")).collect();
        let tail = tail_lines(text.as_bytes());
        assert_eq!(tail.lines().count(), STDERR_TAIL_LINES);
        assert!(tail.starts_with("line 10\n") && tail.ends_with("line 29"));
    }

    /// An empty dataset (a header and no shards) in `dir`/d.
    fn empty_dataset(dir: &Path) -> PathBuf {
        let data = dir.join("d");
        let header = crate::dataset::DatasetHeader::new(
            formation_proto::OccupancySpec::PAPER,
            formation_proto::SimulatedLidar::default(),
            0.7,
            0,
            "t",
        );
        crate::dataset::DatasetWriter::create(&data, header)
            .expect("create")
            .finish()
            .expect("finish");
        data
    }

    #[test]
    fn a_missing_interpreter_is_a_typed_error() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let data = empty_dataset(tmp.path());
        let err = train(
            &TrainOptions {
                data: vec![data],
                python: Some(tmp.path().join("no-such-python")),
                ..opts()
            },
            &mut |_| {},
        )
        .expect_err("no interpreter");
        assert!(matches!(err, TrainError::PythonNotFound { .. }), "{err}");
        assert!(err.to_string().contains("setup-python --train"), "{err}");
    }

    /// The demo's `.venv` holds ONNX Runtime only; training from a Python without PyTorch says
    /// how to install it. A fresh virtual environment (no system packages) is such a Python.
    #[test]
    fn a_python_without_pytorch_is_told_how_to_install_it() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let venv = tmp.path().join("venv");
        let made = std::process::Command::new("python3")
            .args(["-m", "venv", "--without-pip"])
            .arg(&venv)
            .status()
            .expect("python3 -m venv (python3 is on every supported machine)");
        assert!(made.success(), "python3 -m venv failed");
        let data = empty_dataset(tmp.path());
        let err = train(
            &TrainOptions {
                data: vec![data],
                python: Some(venv.join("bin/python")),
                ..opts()
            },
            &mut |_| {},
        )
        .expect_err("no PyTorch");
        assert!(matches!(err, TrainError::TorchMissing { .. }), "{err}");
        assert!(err.to_string().contains("setup-python --train"), "{err}");
    }
}
