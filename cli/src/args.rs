//! Command-line arguments of every `formation` subcommand (clap derive).

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use formation_expert::ExpertGains;
use formation_runtime::transport::{Transport, TransportParser};
use formation_trainer_bridge::train::Architecture;

use formation_runtime::{ClockMode, RuntimeSettings};

/// Learned decentralized multi-robot formation control.
#[derive(Debug, Parser)]
#[command(name = "formation", version, about, propagate_version = true)]
pub struct Cli {
    /// More log output on stderr (-v info, -vv debug); FORMATION_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Evaluate a controller over a scenario's runs and print Table I figures.
    #[command(after_help = EVAL_EXAMPLES)]
    Eval(EvalArgs),
    /// Gauge how strongly a controller corrects formation errors: its own runs relabelled by the
    /// expert, the slope and RMS error of its formation velocity binned by the label's size.
    #[command(after_help = GAUGE_EXAMPLES)]
    Gauge(GaugeArgs),
    /// Merge the shards of an evaluation spread over workers (`eval --shard`) into its summary.
    #[command(after_help = MERGE_EXAMPLES)]
    Merge(MergeArgs),
    /// Record expert demonstrations into a dataset.
    #[command(after_help = COLLECT_EXAMPLES)]
    Collect(CollectArgs),
    /// Train the paper's CNN on a dataset (PyTorch) and export it to ONNX.
    #[command(after_help = TRAIN_EXAMPLES)]
    Train(TrainArgs),
    /// DAgger: the policy drives, the expert labels, the dataset grows, the policy is retrained.
    #[command(after_help = DAGGER_EXAMPLES)]
    Dagger(DaggerArgs),
    /// Label one share of a DAgger iteration's runs into a part file (a sweep worker's task);
    /// `formation dagger-append` appends the iteration's parts to the dataset.
    #[command(after_help = DAGGER_LABEL_EXAMPLES)]
    DaggerLabel(DaggerLabelArgs),
    /// Append the parts of one DAgger iteration (`formation dagger-label --part`) to the
    /// dataset in run order, after checking they are that iteration's, complete and disjoint.
    #[command(after_help = DAGGER_APPEND_EXAMPLES)]
    DaggerAppend(DaggerAppendArgs),
    /// Launch the world and one agent process per robot (iceoryx2, or Zenoh for agents on other
    /// hosts).
    #[command(after_help = RUN_EXAMPLES)]
    Run(RunArgs),
    /// Per-stage latency profile of the multi-process runtime.
    #[command(after_help = PROFILE_EXAMPLES)]
    Profile(ProfileArgs),
    /// Swap the ONNX model of one running agent.
    #[command(after_help = SWAP_EXAMPLES)]
    Swap(SwapArgs),
    /// Create Zenoh credentials for a team: one login per robot (plus the launch secret), one
    /// for `formation swap` and a read-only one for `formation record --connect`, for agents on
    /// other hosts.
    #[command(after_help = CREDENTIALS_EXAMPLES)]
    Credentials(CredentialsArgs),
    /// Record a live Zenoh team from outside to MCAP: the same file `--record` writes.
    #[command(after_help = RECORD_EXAMPLES)]
    Record(RecordArgs),
    /// Build the HTML report (Table I, Figs. 6-9) from eval/run output directories.
    #[command(after_help = REPORT_EXAMPLES)]
    Report(ReportArgs),
    /// The main job: the paper's three cases and Table I with the shipped model over real
    /// processes, ending in a report.
    #[command(after_help = DEMO_EXAMPLES)]
    Demo(DemoArgs),
    /// Replay a recording (`--record`): each robot's recorded inputs through the agent's
    /// decision, compared with the recorded commands. Exit 0: every command bit for bit the
    /// same; 1: some differ (the table and the JSON say where); 2: an error.
    #[command(after_help = REPLAY_EXAMPLES)]
    Replay(ReplayArgs),
}

// The examples that end each subcommand's help (`after_help`): one or two each, and every one
// parses (`tests::every_subcommand_ends_its_help_with_examples_that_parse`).
const EVAL_EXAMPLES: &str = "Examples:
  formation eval --scenario scenarios/table1.toml --runs 100 --json out/table1.json
  formation eval --controller expert --scenario scenarios/teams.toml --robots 3,8,16 --runs 20";
const MERGE_EXAMPLES: &str = "Examples:
  formation eval --scenario scenarios/table1.toml --first-run 0 --runs 40 --shard a.json
  formation merge a.json b.json --json table1.json";
const COLLECT_EXAMPLES: &str = "Examples:
  formation collect --scenario scenarios/collect.toml --out data/expert --beyond border
  formation collect --scenario scenarios/teams-generalist.toml --out data/own-scan \\
      --neighbours 16 --own-scan-labels --unshaped-labels";
const TRAIN_EXAMPLES: &str = "Examples:
  formation train --data data/expert --out models/policy.onnx --epochs 10 --device cpu";
const DAGGER_EXAMPLES: &str = "Examples:
  formation dagger --data data/expert --iterations 2 --out models/policy.onnx
  formation dagger --data data/expert --init-model m0.onnx --iterations 3 --d-star-range \\
      0.8,2.5 --out m.onnx";
const DAGGER_LABEL_EXAMPLES: &str = "Examples:
  formation dagger-label --data data --model m0.onnx --iteration 1 --first-run 0 --runs 80 \\
      --part a.part";
const DAGGER_APPEND_EXAMPLES: &str = "Examples:
  formation dagger-append --data data --iteration 1 --runs 153 a.part b.part";
const RUN_EXAMPLES: &str = "Examples:
  formation run --scenario scenarios/case1.toml --out runs/case1
  formation run --scenario scenarios/case1.toml --clock realtime --run-id demo --record \\
      case1.mcap";
const PROFILE_EXAMPLES: &str = "Examples:
  formation profile --scenario scenarios/case1.toml --out runs/prof3
  formation profile --scenario scenarios/swarm32.toml --clock realtime --out runs/prof32";
const SWAP_EXAMPLES: &str = "Examples:
  formation swap --run demo --robot 1 --model onnx/models/paper/policy.onnx
  formation swap --run demo --robot 1 --model other.onnx --at-tick 400";
const CREDENTIALS_EXAMPLES: &str = "Examples:
  formation credentials --robots 3 --out creds";
const RECORD_EXAMPLES: &str = "Examples:
  formation record --connect tcp/WORLD_HOST:7447 --run-id demo --credentials \\
      creds/recorder.json --out demo.mcap
  formation record --connect tcp/WORLD_HOST:7447 --transport ros2 --run-id demo --out demo.mcap";
const REPORT_EXAMPLES: &str = "Examples:
  formation report runs/ --out report.html";
const DEMO_EXAMPLES: &str = "Examples:
  formation demo --out reports/demo
  formation demo --runs 10 --record case1.mcap --out reports/quick";
const REPLAY_EXAMPLES: &str = "Examples:
  formation replay case1.mcap
  formation replay case1.mcap --model onnx/models/paper/policy.onnx --json r.json";

/// Which controller drives the robots.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ControllerKind {
    /// The model-based expert (sees every robot's pose).
    Expert,
    /// The learned policy, one independent agent per robot (own scan and heading only).
    Policy,
    /// The expert's law on each robot's own scan: one independent pilot per robot, holding the
    /// neighbours it detects in its own scan (own scan and heading only; no model). With
    /// `--robots`, beside the expert on the same runs.
    ExpertOwnScan,
}

/// `formation eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Scenario TOML file.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Controller to evaluate.
    #[arg(long, value_enum, default_value_t = ControllerKind::Policy)]
    pub controller: ControllerKind,
    /// ONNX model for `--controller policy` (default: the scenario's `model`, else the shipped
    /// model).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Number of runs (default: the scenario's `runs`; at most 10000).
    #[arg(long, value_parser = run_count)]
    pub runs: Option<usize>,
    /// Base seed (default: the scenario's `seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Write the summary JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write report data (summary, per-run metrics, trajectories) into this directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Save the trajectories of at most this many runs under `--out` (default: all when there
    /// are at most 5 runs, else none).
    #[arg(long)]
    pub save_trajectories: Option<usize>,
    /// Run every robot's policy in its own OS process (policy controller only), over
    /// `--transport`.
    #[arg(long)]
    pub processes: bool,
    /// With `--processes`: how the agents reach the world, iceoryx2 shared memory, Zenoh over
    /// TCP (needs --listen; every agent runs on this host, with fresh credentials), ROS 2
    /// (needs --listen; the world as a ROS 2 team, ROS 2 agents), or a registered transport.
    #[arg(long, value_parser = TransportParser::new(crate::TRANSPORT_PLUGINS), default_value_t = Transport::Iceoryx2)]
    pub transport: Transport,
    /// Zenoh and ROS 2: where the world listens, tcp/ADDR:PORT.
    #[arg(long, value_name = "tcp/ADDR:PORT")]
    pub listen: Option<String>,
    /// Worker threads for in-process evaluation (default: available cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Record the runs to MCAP in this folder, which must exist: `run-NNNN.mcap` per run, each
    /// robot's scan, odometry, command and TF, the goal and the formation's edges, for Foxglove,
    /// Rerun and ROS 2 tools, plus what each agent received and sent, for replay.
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// With --record: record at most this many runs, the first ones (default: all when there
    /// are at most 5 runs, else the first 5).
    #[arg(long, requires = "record", value_name = "N")]
    pub record_runs: Option<usize>,
    /// Record run 0 into this file instead (`formation demo --record`).
    #[arg(skip)]
    pub record_file: Option<PathBuf>,
    /// Serve the runs live to Foxglove on this address, checked (`formation demo --foxglove`;
    /// with --processes).
    #[arg(skip)]
    pub foxglove: Option<std::net::SocketAddr>,
    /// Evaluate over these team sizes (e.g. `3,5,8,13,16,32`): the scenario resized to each, the
    /// expert always and the policy when `--model` is given; prints the scaling table and writes
    /// it with `--json`. With `--shard`, one size: the scenario resized to it.
    #[arg(long, value_delimiter = ',', value_parser = team_size)]
    pub robots: Option<Vec<usize>>,
    /// Play only runs `A .. A + --runs` of the evaluation (a share of a sweep over workers);
    /// needs --shard.
    #[arg(long, value_name = "A", requires = "shard")]
    pub first_run: Option<usize>,
    /// Write the runs' metrics as a shard for `formation merge`, which builds the summary one
    /// evaluation of all the runs writes, byte for byte (in-process only).
    #[arg(long, value_name = "FILE")]
    pub shard: Option<PathBuf>,
    /// With `--controller expert-own-scan`: the law's gains as JSON, fields of `ExpertGains` (for
    /// example `{"unblock_hidden_pairs": true}`); the scored expert keeps its own.
    #[arg(long, value_name = "JSON", value_parser = expert_gains)]
    pub gains: Option<ExpertGains>,
    /// Walk a robot profile's reality ladder (`pioneer-p3dx`, `turtlebot3-burger`): the
    /// scenario with the profile's effects added one at a time, the expert and (unless
    /// `--controller expert`) the policy, or with `--controller expert-own-scan` the expert's
    /// law on each robot's own scan, on each rung; prints the table and writes it with `--json`. Team sizes from `--robots` (default: the scenario's).
    #[arg(long, value_name = "PROFILE")]
    pub ladder: Option<String>,
}

/// `formation gauge`'s examples.
const GAUGE_EXAMPLES: &str = "Examples:
  formation gauge --scenario scenarios/teams-generalist.toml --robots 16,32 --runs 20 --own-scan
  formation gauge --scenario scenarios/teams-generalist.toml --robots 16 --model M.onnx \\
      --duration-s 240 --json response.json";

/// `formation gauge`.
#[derive(Debug, Args)]
#[command(group(
    clap::ArgGroup::new("other_controllers")
        .args(["expert", "own_scan"])
        .multiple(true)
))]
pub struct GaugeArgs {
    /// Scenario TOML file.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Team sizes to gauge (e.g. `16,32`; default: the scenario's).
    #[arg(long, value_delimiter = ',', value_parser = team_size)]
    pub robots: Option<Vec<usize>>,
    /// ONNX model to gauge (default: the scenario's `model`, else the shipped model).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Also gauge the expert with these gains as JSON (for example `{"shaping_wheel_accel": 1.0}`,
    /// a teacher), against the scored expert's labels; `{}` gauges the scored expert itself.
    #[arg(long, value_name = "JSON", value_parser = expert_gains)]
    pub expert: Option<ExpertGains>,
    /// Also gauge the expert's law on each robot's own scan (`eval --controller
    /// expert-own-scan`, the teacher that sees what a policy sees), with `--expert`'s gains when
    /// given, against the scored expert's labels.
    #[arg(long)]
    pub own_scan: bool,
    /// Gauge only the controllers given by `--expert` and `--own-scan`, not the policy.
    #[arg(long, requires = "other_controllers")]
    pub no_policy: bool,
    /// Runs per team size (default: the scenario's `runs`; at most 10000).
    #[arg(long, value_parser = run_count)]
    pub runs: Option<usize>,
    /// Base seed (default: the scenario's `seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Run length in seconds (default: the scenario's).
    #[arg(long, value_parser = gauge_duration)]
    pub duration_s: Option<f64>,
    /// Gauge every this many ticks.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..=10_000))]
    pub stride: u64,
    /// Write the response curve JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Worker threads (default: available cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Parses the expert's gains from JSON (fields of `ExpertGains`, the others at their defaults)
/// and checks them.
pub fn expert_gains(json: &str) -> Result<ExpertGains, String> {
    let gains: ExpertGains = serde_json::from_str(json).map_err(|e| {
        format!(
            "{json:?} is not the expert's gains as JSON ({e}): give for example \
             '{{\"shaping_wheel_accel\": 1.0}}' (fields of ExpertGains), or '{{}}' for the \
             scored expert's"
        )
    })?;
    gains.validate().map_err(|e| e.to_string())?;
    Ok(gains)
}

/// Parses a gauge run length: seconds from 1 to 3600.
pub fn gauge_duration(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if (1.0..=3600.0).contains(&s) => Ok(s),
        _ => Err(format!(
            "expected a run length from 1 to 3600 s, got {text:?}"
        )),
    }
}

/// `formation merge`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The shards (`formation eval --shard`) of one evaluation, in any order.
    #[arg(required = true, value_name = "SHARD")]
    pub shards: Vec<PathBuf>,
    /// The evaluation's number of runs (default: up to the last run a shard holds); a run that
    /// no shard holds is an error.
    #[arg(long, value_parser = run_count)]
    pub runs: Option<usize>,
    /// Write the merged summary here (the JSON `formation eval --json` writes).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// How the expert shapes its labels: `--label-wheel-accel`, `--unshaped-labels` and
/// `--label-pair-band`, which `formation collect` and `formation dagger` share. The help texts are
/// collect's; `formation dagger` says its own with clap's `mut_arg`.
#[derive(Debug, Clone, Args)]
pub struct LabelShapingArgs {
    /// Label with the expert's formation velocity shaped for this wheel acceleration limit
    /// \[m/s²\], whatever the scenario's own (see `formation dagger --label-wheel-accel`).
    #[arg(long, value_name = "A", value_parser = wheel_accel)]
    pub label_wheel_accel: Option<f64>,
    /// Label with the unlimited law, shaped for no limit whatever the scenario's own: for a
    /// policy that answers a formation velocity, which each agent shapes for its own wheels.
    #[arg(long, conflicts_with = "label_wheel_accel")]
    pub unshaped_labels: bool,
    /// Label with smooth pair weights: a pair's weight rises from 0 to 1 over witness ratios
    /// LOW..HIGH instead of the neighbour rule's step at its threshold, so that the labels are
    /// one continuous function of what a robot senses (issue 34 item 3; default: the rule's
    /// pairs exactly, as the scored expert holds them).
    #[arg(long, value_name = "LOW,HIGH", value_parser = pair_weight_band)]
    pub label_pair_band: Option<[f64; 2]>,
}

impl LabelShapingArgs {
    /// `gains` with the labels shaped as the flags say.
    pub fn shape(&self, gains: ExpertGains) -> ExpertGains {
        ExpertGains {
            shaping_wheel_accel: self.label_wheel_accel,
            unshaped: self.unshaped_labels,
            pair_weight_band: self.label_pair_band,
            ..gains
        }
    }
}

/// `formation collect`.
#[derive(Debug, Args)]
pub struct CollectArgs {
    /// Scenario TOML describing the demonstration runs.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Output dataset directory (must not exist, or be empty).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of runs (default: the scenario's `runs`; at most 10000).
    #[arg(long, value_parser = run_count)]
    pub runs: Option<usize>,
    /// Base seed (default: the scenario's `seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Occupancy window side in cells.
    #[arg(long, default_value_t = 50)]
    pub size_px: usize,
    /// Occupancy cell size \[m\].
    #[arg(long, default_value_t = 0.1)]
    pub resolution: f64,
    /// What to draw for hits beyond the window: `drop` (the paper) or `border`.
    #[arg(long, default_value = "drop")]
    pub beyond: String,
    /// Scale the window with each run's d*: cells are `--resolution` wide at this d* \[m\] and
    /// `resolution * d* / scale_d_star` at any other, so a neighbour at d* lies the same number
    /// of cells away at every spacing (default: a fixed window, as in the paper).
    #[arg(long, value_name = "D_STAR_REF_M")]
    pub scale_d_star: Option<f64>,
    /// How the expert's labels are shaped.
    #[command(flatten)]
    pub labels: LabelShapingArgs,
    /// Also record each robot's scan ranges beside its image, `sectors=K,clip=C`: K sectors
    /// (centred on bearings 2 pi s / K), each the mean range of its returning beams over d*, at
    /// most C. A network trained on the dataset takes them as its `ranges` input (for example
    /// `sectors=100,clip=3` for 900 beams, 9 a sector).
    #[arg(long, value_name = "sectors=K,clip=C", value_parser = range_input)]
    pub ranges: Option<formation_proto::RangeInput>,
    /// Also record the neighbours each robot detects in its own scan beside its image, in K
    /// slots (1 to 64) of (x/d*, y/d*, held, present), held by the scenarios' default rule
    /// (`slots=K,threshold=1.3,nearest=2`); or give the whole declaration, where `,hidden=1`
    /// adds each slot's share of the step aside of the pairs the robot hides (hx, hy). A
    /// network trained on the dataset takes them as its `neighbours` input.
    #[arg(long, value_name = "K", value_parser = neighbour_slots)]
    pub neighbours: Option<formation_proto::NeighbourInput>,
    /// Label each robot with the expert's law on the neighbours it detects in its own scan (what
    /// `formation eval --controller expert-own-scan` drives with) instead of the expert's
    /// command from every pose; combines with the shaping and pair-weight flags. The expert
    /// still drives the runs.
    #[arg(long)]
    pub own_scan_labels: bool,
    /// With --own-scan-labels: a robot that hides two detections from each other, which would
    /// hold each other, steps aside (the law's `unblock_hidden_pairs`: table1 93 -> 100 % for
    /// the law itself).
    #[arg(long, requires = "own_scan_labels")]
    pub unblock_hidden_pairs: bool,
}

/// `formation train`.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Dataset directory (repeat to train on several).
    #[arg(long, required = true)]
    pub data: Vec<PathBuf>,
    /// Output ONNX file (a `.pt` checkpoint, loss CSV/PNG are written beside it).
    #[arg(long)]
    pub out: PathBuf,
    /// Epochs.
    #[arg(long, default_value_t = 10)]
    pub epochs: usize,
    /// Mini-batch size (the paper: 32).
    #[arg(long, default_value_t = 32)]
    pub batch_size: usize,
    /// Adam learning rate (the paper: 1e-4).
    #[arg(long, default_value_t = 1e-4)]
    pub lr: f64,
    /// `auto`, `cpu` or `cuda`.
    #[arg(long, default_value = "auto")]
    pub device: String,
    /// Warm start from this checkpoint (`.pt`), or from the weights of a policy `.onnx` written by
    /// formation's trainer (a shipped model, for instance).
    #[arg(long)]
    pub init_from: Option<PathBuf>,
    /// Training seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The d* range the model is declared for, `MIN,MAX` in metres (its envelope: `eval`, `run`
    /// and the agents refuse goals outside it); it must hold every d* of the data. Default: the
    /// data's own range.
    #[arg(long, value_name = "MIN,MAX", value_parser = d_star_range)]
    pub d_star_range: Option<(f64, f64)>,
    /// Which network, whether to mirror the data, how many samples an epoch draws.
    #[command(flatten)]
    pub network: NetworkArgs,
}

/// The network `formation train` and `formation dagger` train, its data augmentation, and how
/// much of the data each epoch draws.
#[derive(Debug, Args)]
pub struct NetworkArgs {
    /// The network: `paper` (the paper's CNN), `wide` or `wide-head` (CNNs for teams), `pair`
    /// (one learned term per detected neighbour; data collected with `--neighbours K`) or
    /// `pair-potential` (the same, each term shaped by the law's pair profile). Default: the warm
    /// start's (`--init-from`, or `--init-model`'s checkpoint), else `pair` for data with
    /// neighbours, else `paper`.
    #[arg(long, value_parser = architecture)]
    pub architecture: Option<Architecture>,
    /// Use the task's exact symmetry under reflection about the robot's heading axis (the
    /// image's rows reversed, Δφ negated, the wheels swapped): train on reflected samples too,
    /// and export a policy whose output is averaged over the reflection, so it is exactly
    /// symmetric.
    #[arg(long)]
    pub mirror: bool,
    /// Train on reflected samples as `--mirror` does, but export the network itself rather than
    /// its average over the reflection: the symmetry lives in the weights, as far as it was
    /// learned, and a decision costs one evaluation instead of two.
    #[arg(long, conflicts_with = "mirror")]
    pub mirror_augment_only: bool,
    /// Train each epoch on this many training samples drawn at random, not all of them: an
    /// epoch then costs the same however large the data (a DAgger dataset) grows.
    #[arg(long)]
    pub samples_per_epoch: Option<std::num::NonZeroUsize>,
    /// Weight each sample's squared error by `(d_ref / d*)²` (mean weight 1): the success check
    /// judges distances relative to d*, so this fits small-d* teams as tightly as large ones.
    #[arg(long)]
    pub relative_loss: bool,
    /// What the model outputs: `wheels` (the paper's wheel speeds at v_train, scaled by
    /// v*/v_train) or `formation_velocity` (the expert's correction in the robot's frame, to
    /// which the agent adds the reference term at the goal's own speed).
    #[arg(long, default_value = "wheels", value_parser = policy_output)]
    pub output: formation_proto::PolicyOutput,
    /// Weight each sample's squared error by 1 / (|f| + EPS), `f` the expert's formation
    /// velocity \[m/s\] (mean weight 1), so that small corrections count (for example 0.05).
    #[arg(long, value_name = "EPS")]
    pub response_weight: Option<f64>,
}

/// Parses a policy output kind: `wheels` or `formation_velocity`.
pub fn policy_output(text: &str) -> Result<formation_proto::PolicyOutput, String> {
    formation_proto::PolicyOutput::parse(text.trim())
        .ok_or_else(|| format!("expected `wheels` or `formation_velocity`, got {text:?}"))
}

/// What DAgger rolls out, shared by `formation dagger` and `formation dagger-label`.
#[derive(Debug, Args)]
pub struct DaggerRolloutArgs {
    /// The expert dataset to start from; DAgger samples are appended to it.
    #[arg(long)]
    pub data: PathBuf,
    /// Scenario the policy drives in to visit states (default: scenarios/collect.toml).
    #[arg(long, default_value = "scenarios/collect.toml")]
    pub scenario: PathBuf,
    /// Probability that the expert drives a run in iteration 1; it decays as beta^k.
    #[arg(long, default_value_t = 0.0)]
    pub beta: f64,
    /// Base seed of the DAgger rollouts.
    #[arg(long, default_value_t = 1000)]
    pub seed: u64,
    /// Team sizes of the rollouts, used in turn (e.g. `3,5,7`; default: the scenario's).
    #[arg(long, value_delimiter = ',', value_parser = team_size)]
    pub team_sizes: Vec<usize>,
    /// Run lengths of some team sizes instead of the scenario's, `SIZE=SECONDS` (e.g.
    /// `24=100,32=100`: long rollouts where large teams stall).
    #[arg(long, value_delimiter = ',', value_name = "SIZE=SECONDS", value_parser = team_duration)]
    pub rollout_durations: Vec<(usize, f64)>,
}

/// A team size and a run length, `SIZE=SECONDS` (`formation dagger --rollout-durations`); the
/// length's bounds are the scenario's `duration_s`'s, checked with the team.
pub fn team_duration(text: &str) -> Result<(usize, f64), String> {
    let (size, seconds) = text
        .split_once('=')
        .ok_or_else(|| format!("`{text}` is not SIZE=SECONDS (e.g. 32=100)"))?;
    let size = team_size(size.trim())?;
    let seconds: f64 = seconds
        .trim()
        .parse()
        .map_err(|_| format!("`{seconds}` in `{text}` is not a number of seconds"))?;
    if !(seconds.is_finite() && seconds > 0.0) {
        return Err(format!("`{text}`: the run length must be > 0 seconds"));
    }
    Ok((size, seconds))
}

/// `formation dagger`.
#[derive(Debug, Args)]
#[command(
    mut_arg("label_wheel_accel", |a| a.help(
        "Label with the expert's formation velocity shaped for this wheel acceleration limit \
         \\[m/s²\\] in every run, whatever the run's own limit, so that the labels are one \
         function of what a robot senses (default: each run's own limit)"
    )),
    mut_arg("unshaped_labels", |a| a.help(
        "Label with the unlimited law in every run, whatever the run's own limit: for a policy \
         that answers a formation velocity (`formation train --output formation_velocity`), \
         which each agent shapes for its own wheels"
    ))
)]
pub struct DaggerArgs {
    /// The dataset, the rollout scenario, beta, seed and team sizes.
    #[command(flatten)]
    pub rollouts: DaggerRolloutArgs,
    /// DAgger iterations.
    #[arg(long, default_value_t = 2)]
    pub iterations: usize,
    /// Output ONNX file of the final policy; each iteration's model is kept beside it.
    #[arg(long)]
    pub out: PathBuf,
    /// Start from this model (default: train one on the dataset first).
    #[arg(long)]
    pub init_model: Option<PathBuf>,
    /// Closed-loop runs per iteration (default: the scenario's `runs`; at most 10000).
    #[arg(long, value_parser = run_count)]
    pub runs: Option<usize>,
    /// Training epochs per iteration.
    #[arg(long, default_value_t = 8)]
    pub epochs: usize,
    /// Mini-batch size.
    #[arg(long, default_value_t = 64)]
    pub batch_size: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// `auto`, `cpu` or `cuda`.
    #[arg(long, default_value = "auto")]
    pub device: String,
    /// Scenario for each iteration's closed-loop Table I figures.
    #[arg(long, default_value = "scenarios/table1.toml")]
    pub eval_scenario: PathBuf,
    /// Runs of that evaluation (at most 10000).
    #[arg(long, default_value_t = 100, value_parser = run_count)]
    pub eval_runs: usize,
    /// The d* range the models are declared for, `MIN,MAX` in metres (default: the rollout
    /// scenario's `goal.d_star_range` when it has one, else the data's own range).
    #[arg(long, value_name = "MIN,MAX", value_parser = d_star_range)]
    pub d_star_range: Option<(f64, f64)>,
    /// Wheel acceleration limits \[m/s²\] of the rollouts, each run with every team size in
    /// turn (e.g. `none,1.0,2.0`; `none`: no limit; default: the scenario's own).
    #[arg(long, value_delimiter = ',', value_parser = wheel_accel_or_none)]
    pub wheel_accels: Vec<Option<f64>>,
    /// How the expert's labels are shaped, in every run whatever the run's own limit.
    #[command(flatten)]
    pub labels: LabelShapingArgs,
    /// Label each robot with the expert's law on the neighbours it detects in its own scan
    /// instead of from every pose: give it when the dataset was collected with
    /// `formation collect --own-scan-labels` (DAgger refuses to mix two laws in one dataset).
    #[arg(long)]
    pub own_scan_labels: bool,
    /// With --own-scan-labels: the law steps aside for the pairs a robot hides; give it when the
    /// dataset was collected with `formation collect --unblock-hidden-pairs`.
    #[arg(long, requires = "own_scan_labels")]
    pub unblock_hidden_pairs: bool,
    /// Which network, whether to mirror the data, how many samples an epoch draws.
    #[command(flatten)]
    pub network: NetworkArgs,
}

/// `formation dagger-label`.
#[derive(Debug, Args)]
pub struct DaggerLabelArgs {
    /// The dataset (only its manifest is read), the rollout scenario, beta, seed and team sizes:
    /// the same as the DAgger session's.
    #[command(flatten)]
    pub rollouts: DaggerRolloutArgs,
    /// The policy that drives in this iteration: iteration K-1's model (`formation dagger`
    /// keeps iteration k's as `<stem>-dagger<k>.onnx`).
    #[arg(long)]
    pub model: PathBuf,
    /// The DAgger iteration K (at least 1); the expert drives a run with probability beta^K.
    #[arg(long, value_name = "K")]
    pub iteration: usize,
    /// The first run of the iteration this share labels.
    #[arg(long, value_name = "A", default_value_t = 0)]
    pub first_run: usize,
    /// Runs in this share, `A .. A + R` (default: the scenario's runs after A; at most 10000).
    #[arg(long, value_name = "R", value_parser = run_count)]
    pub runs: Option<usize>,
    /// Write the share's labelled samples here (a DAgger part), atomically.
    #[arg(long, value_name = "FILE")]
    pub part: PathBuf,
    /// Worker threads (default: available cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// `formation dagger-append`.
#[derive(Debug, Args)]
pub struct DaggerAppendArgs {
    /// The dataset the parts were labelled for.
    #[arg(long)]
    pub data: PathBuf,
    /// The DAgger iteration the parts hold.
    #[arg(long, value_name = "K")]
    pub iteration: u32,
    /// The iteration's runs: the parts must hold runs 0 .. N, each once (at most 10000).
    #[arg(long, value_name = "N", value_parser = run_count)]
    pub runs: usize,
    /// The parts (`formation dagger-label --part`) of the iteration, in any order.
    #[arg(required = true, value_name = "PART")]
    pub parts: Vec<PathBuf>,
}

/// `formation report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Directory holding eval/run outputs (searched recursively for `summary.json` and run logs).
    pub dir: PathBuf,
    /// Output HTML file.
    #[arg(long, default_value = "report.html")]
    pub out: PathBuf,
}

/// `formation demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// ONNX model (default: the shipped model).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Output directory for run data and the report.
    #[arg(long, default_value = "reports/demo")]
    pub out: PathBuf,
    /// Table I runs (at most 10000).
    #[arg(long, default_value_t = 100, value_parser = run_count)]
    pub runs: usize,
    /// Run in-process instead of one OS process per robot.
    #[arg(long)]
    pub in_process: bool,
    /// Record case 1 to this MCAP file, whose folder must exist (for Foxglove, Rerun and ROS 2
    /// tools, and replay).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Watch the three cases live in Foxglove: serve them on HOST:PORT over Foxglove's
    /// WebSocket protocol (e.g. 127.0.0.1:8765; another address than loopback is readable by
    /// anyone who reaches it). Builds with the feature `foxglove` only; not with --in-process.
    #[arg(long, value_name = "HOST:PORT", conflicts_with = "in_process")]
    pub foxglove: Option<String>,
}

/// `formation replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The recording (an MCAP file written by `--record`).
    #[arg(value_name = "FILE.mcap")]
    pub file: PathBuf,
    /// Decide with this ONNX model instead of the recording's own (to see how far another model
    /// would have driven otherwise).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Replay only this robot.
    #[arg(long, value_name = "I")]
    pub robot: Option<u32>,
    /// A model swapped in during the run (`formation swap`; repeat for several) that the
    /// recording does not hold (the world's own --record stores it; a recording made from
    /// outside, or one whose file changed before it was stored, names it by its id only): it
    /// decides the steps whose model id is its own.
    #[arg(long, value_name = "FILE.onnx")]
    pub swap_model: Vec<PathBuf>,
    /// Write the report's JSON here (default: next to the recording, `FILE.replay.json`).
    #[arg(long, value_name = "FILE.json")]
    pub json: Option<PathBuf>,
}

/// Parses a `--runs` count: a whole number from 1 to the scenario limit
/// ([`formation_world::scenario::limits::MAX_RUNS`]), so a typo cannot ask for a billion runs.
pub fn run_count(text: &str) -> Result<usize, String> {
    let max = formation_world::scenario::limits::MAX_RUNS;
    match text.trim().parse::<usize>() {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(format!(
            "expected a number of runs from 1 to {max}, got {text:?}"
        )),
    }
}

/// Parses a team size: a whole number from 2 to the scenario limit
/// ([`formation_world::scenario::limits::MAX_ROBOTS`]).
pub fn team_size(text: &str) -> Result<usize, String> {
    let (min, max) = (
        formation_world::scenario::limits::MIN_ROBOTS,
        formation_world::scenario::limits::MAX_ROBOTS,
    );
    match text.trim().parse::<usize>() {
        Ok(n) if (min..=max).contains(&n) => Ok(n),
        _ => Err(format!(
            "expected a team size from {min} to {max}, got {text:?}"
        )),
    }
}

/// A network architecture by its name ([`Architecture::ALL`]).
fn architecture(text: &str) -> Result<Architecture, String> {
    text.parse()
}

/// A wheel acceleration limit in m/s², within the scenario's bounds for `robot.max_wheel_accel`.
fn wheel_accel(text: &str) -> Result<f64, String> {
    let bounds = formation_world::scenario::limits::MAX_WHEEL_ACCEL;
    match text.trim().parse::<f64>() {
        Ok(a) if a.is_finite() && bounds.min <= a && a <= bounds.max => Ok(a),
        _ => Err(format!(
            "expected a wheel acceleration limit from {} to {} m/s², got {text:?}",
            bounds.min, bounds.max
        )),
    }
}

/// A wheel acceleration limit in m/s², or `none` for no limit.
fn wheel_accel_or_none(text: &str) -> Result<Option<f64>, String> {
    if text.trim() == "none" {
        return Ok(None);
    }
    wheel_accel(text)
        .map(Some)
        .map_err(|e| format!("{e}, or none for no limit"))
}

/// `MIN,MAX` in metres, with `0 < MIN < MAX`, both finite.
/// `A,B` with `0 < A < B`, both finite; `expected` says what was asked for in the error.
fn increasing_positive_pair(text: &str, expected: &str) -> Result<(f64, f64), String> {
    let parsed = text
        .split_once(',')
        .and_then(|(a, b)| Some((a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?)));
    match parsed {
        Some((min, max)) if min.is_finite() && max.is_finite() && 0.0 < min && min < max => {
            Ok((min, max))
        }
        _ => Err(format!("expected {expected}, got {text:?}")),
    }
}

fn d_star_range(text: &str) -> Result<(f64, f64), String> {
    increasing_positive_pair(text, "MIN,MAX in metres with 0 < MIN < MAX (e.g. 0.8,2.5)")
}

fn pair_weight_band(text: &str) -> Result<[f64; 2], String> {
    increasing_positive_pair(
        text,
        "LOW,HIGH witness ratios with 0 < LOW < HIGH (e.g. 1.1,1.5)",
    )
    .map(|(low, high)| [low, high])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_d_star_range_is_two_increasing_positive_distances() {
        assert_eq!(d_star_range("0.8,2.5"), Ok((0.8, 2.5)));
        assert_eq!(d_star_range(" 1 , 2 "), Ok((1.0, 2.0)));
        for bad in ["2.5,0.8", "0,1", "1", "1,nan", "a,b", "1,1"] {
            let e = d_star_range(bad).unwrap_err();
            assert!(e.contains("MIN,MAX") && e.contains(bad), "{bad}: {e}");
        }
        assert_eq!(pair_weight_band("1.1,1.5"), Ok([1.1, 1.5]));
        for bad in ["1.5,1.1", "0,1", "1.2", "1,inf"] {
            let e = pair_weight_band(bad).unwrap_err();
            assert!(e.contains("LOW,HIGH") && e.contains(bad), "{bad}: {e}");
        }
    }

    #[test]
    fn gauge_without_the_policy_needs_another_controller() {
        let base = ["formation", "gauge", "--scenario", "s.toml", "--no-policy"];
        let error = Cli::try_parse_from(base).unwrap_err();
        assert!(error.to_string().contains("--no-policy"), "{error}");
        for extra in [&["--own-scan"][..], &["--expert", "{}"][..]] {
            let cli = Cli::try_parse_from(base.iter().chain(extra)).unwrap();
            let Command::Gauge(args) = cli.command else {
                panic!("not gauge")
            };
            assert!(args.no_policy);
            assert_eq!(args.own_scan, extra[0] == "--own-scan");
        }
    }

    #[test]
    fn wheel_acceleration_limits_are_bounded_and_none_means_no_limit() {
        assert_eq!(wheel_accel("1.5"), Ok(1.5));
        assert_eq!(wheel_accel_or_none("none"), Ok(None));
        assert_eq!(wheel_accel_or_none("2"), Ok(Some(2.0)));
        for bad in ["0", "-1", "nan", "inf", "1e9", "fast"] {
            let e = wheel_accel(bad).unwrap_err();
            assert!(
                e.contains("0.01 to 1000 m/s²") && e.contains(bad),
                "{bad}: {e}"
            );
            let e = wheel_accel_or_none(bad).unwrap_err();
            assert!(e.contains("or none for no limit"), "{bad}: {e}");
        }
        let cli = Cli::try_parse_from([
            "formation",
            "dagger",
            "--data",
            "d",
            "--out",
            "p.onnx",
            "--wheel-accels",
            "none,1.0",
            "--label-wheel-accel",
            "1",
        ])
        .unwrap();
        let Command::Dagger(args) = cli.command else {
            panic!("not dagger")
        };
        assert_eq!(args.wheel_accels, [None, Some(1.0)]);
        assert_eq!(args.labels.label_wheel_accel, Some(1.0));
        assert!(!args.labels.unshaped_labels);
        // Unshaped labels, for a formation-velocity policy; never beside a fixed limit.
        let base = ["formation", "collect", "--scenario", "s.toml", "--out", "D"];
        let cli = Cli::try_parse_from(base.iter().chain(&["--unshaped-labels"])).unwrap();
        let Command::Collect(args) = cli.command else {
            panic!("not collect")
        };
        assert!(args.labels.unshaped_labels && args.labels.label_wheel_accel.is_none());
        let both = ["--unshaped-labels", "--label-wheel-accel", "1"];
        let error = Cli::try_parse_from(base.iter().chain(&both)).unwrap_err();
        assert!(error.to_string().contains("cannot be used with"), "{error}");
    }

    #[test]
    fn neighbours_take_k_slots_of_the_default_rule_and_own_scan_labels_parse() {
        let base = ["formation", "collect", "--scenario", "s.toml", "--out", "D"];
        let cli = Cli::try_parse_from(base.iter().chain(&[
            "--neighbours",
            "16",
            "--own-scan-labels",
            "--unshaped-labels",
        ]))
        .unwrap();
        let Command::Collect(args) = cli.command else {
            panic!("not collect")
        };
        assert_eq!(
            args.neighbours,
            Some(formation_proto::NeighbourInput::with_default_rule(16).unwrap())
        );
        assert_eq!(
            args.neighbours.unwrap().to_string(),
            "slots=16,threshold=1.3,nearest=2"
        );
        assert!(args.own_scan_labels && args.labels.unshaped_labels && !args.unblock_hidden_pairs);
        let cli = Cli::try_parse_from(
            base.iter()
                .chain(&["--own-scan-labels", "--unblock-hidden-pairs"]),
        )
        .unwrap();
        let Command::Collect(args) = cli.command else {
            panic!("not collect")
        };
        assert!(args.unblock_hidden_pairs);
        // Stepping aside is the own-scan law's: without --own-scan-labels it is refused.
        let error =
            Cli::try_parse_from(base.iter().chain(&["--unblock-hidden-pairs"])).unwrap_err();
        assert!(error.to_string().contains("--own-scan-labels"), "{error}");
        let cli = Cli::try_parse_from(base).unwrap();
        let Command::Collect(args) = cli.command else {
            panic!("not collect")
        };
        assert!(args.neighbours.is_none() && !args.own_scan_labels);
        // A whole declaration, with the hidden pairs' step aside.
        let declared = "slots=8,threshold=1.3,nearest=2,hidden=1";
        let flag = format!("--neighbours={declared}");
        let cli = Cli::try_parse_from(base.iter().copied().chain([flag.as_str()])).unwrap();
        let Command::Collect(args) = cli.command else {
            panic!("not collect")
        };
        let neighbours = args.neighbours.unwrap();
        assert!(neighbours.hidden && neighbours.slots == 8);
        assert_eq!(neighbours.to_string(), declared);
        for (bad, says) in [
            ("0", "slots = 0 is out of range"),
            ("65", "slots = 65 is out of range"),
            ("1.5", "from 1 to 64"),
            ("many", "from 1 to 64"),
            ("slots=8,hidden=1", "is not a neighbour input"),
        ] {
            let flag = format!("--neighbours={bad}");
            let error = Cli::try_parse_from(base.iter().copied().chain([flag.as_str()]))
                .unwrap_err()
                .to_string();
            assert!(
                error.contains("--neighbours <K>") && error.contains(says),
                "{bad}: {error}"
            );
        }
        let dagger = ["formation", "dagger", "--data", "d", "--out", "p.onnx"];
        let cli = Cli::try_parse_from(dagger.iter().chain(&["--own-scan-labels"])).unwrap();
        let Command::Dagger(args) = cli.command else {
            panic!("not dagger")
        };
        assert!(args.own_scan_labels);
        let cli = Cli::try_parse_from(dagger).unwrap();
        let Command::Dagger(args) = cli.command else {
            panic!("not dagger")
        };
        assert!(!args.own_scan_labels);
    }

    #[test]
    fn rollout_durations_are_size_equals_seconds() {
        assert_eq!(team_duration("32=100"), Ok((32, 100.0)));
        assert_eq!(team_duration(" 24 = 80.5"), Ok((24, 80.5)));
        for (bad, says) in [
            ("32", "SIZE=SECONDS"),
            ("1=10", "2 to 1024"),
            ("8=fast", "not a number"),
            ("8=-1", "> 0"),
            ("8=nan", "> 0"),
        ] {
            let error = team_duration(bad).unwrap_err();
            assert!(error.contains(says), "{bad}: {error}");
        }
    }

    #[test]
    fn expert_gains_parse_from_json_and_bad_ones_name_the_field() {
        let gains = expert_gains(r#"{"unblock_hidden_pairs": true}"#).expect("parses");
        assert!(gains.unblock_hidden_pairs);
        assert_eq!(
            gains.k_formation_graph,
            ExpertGains::default().k_formation_graph
        );
        assert_eq!(expert_gains("{}"), Ok(ExpertGains::default()));
        let typo = expert_gains(r#"{"unblock_hiden_pairs": true}"#).unwrap_err();
        assert!(
            typo.contains("unblock_hiden_pairs") && typo.contains("fields of ExpertGains"),
            "{typo}"
        );
        let negative = expert_gains(r#"{"k_formation_graph": -1}"#).unwrap_err();
        assert!(negative.contains("k_formation_graph"), "{negative}");
        let cli = Cli::try_parse_from([
            "formation",
            "eval",
            "--scenario",
            "s.toml",
            "--controller",
            "expert-own-scan",
            "--gains",
            r#"{"unblock_hidden_pairs": true}"#,
        ])
        .expect("parses");
        let Command::Eval(eval) = cli.command else {
            panic!("an eval")
        };
        assert!(eval.gains.is_some_and(|g| g.unblock_hidden_pairs));
        assert!(crate::eval::refuse_gains_without_own_scan(&eval).is_ok());
        let policy = EvalArgs {
            controller: ControllerKind::Policy,
            ..eval
        };
        let refused = crate::eval::refuse_gains_without_own_scan(&policy).unwrap_err();
        assert!(
            refused.to_string().contains("--controller expert-own-scan"),
            "{refused}"
        );
    }

    #[test]
    fn team_sizes_are_bounded_and_lists_parse() {
        assert_eq!(team_size("16"), Ok(16));
        for bad in ["1", "0", "1025", "x"] {
            assert!(team_size(bad).unwrap_err().contains("2 to 1024"), "{bad}");
        }
        let cli = Cli::try_parse_from([
            "formation",
            "eval",
            "--scenario",
            "s.toml",
            "--robots",
            "3,5,8",
        ])
        .unwrap();
        let Command::Eval(args) = cli.command else {
            panic!()
        };
        assert_eq!(args.robots, Some(vec![3, 5, 8]));
        assert!(
            Cli::try_parse_from(["formation", "eval", "--scenario", "s", "--robots", "3,1"])
                .is_err()
        );
    }

    #[test]
    fn dagger_label_takes_dagger_s_rollout_flags_and_a_share_of_runs() {
        let cli = Cli::try_parse_from([
            "formation",
            "dagger-label",
            "--data",
            "d",
            "--model",
            "m.onnx",
            "--iteration",
            "2",
            "--beta",
            "0.5",
            "--team-sizes",
            "3,5",
            "--first-run",
            "10",
            "--runs",
            "5",
            "--part",
            "p",
        ])
        .expect("parses");
        let Command::DaggerLabel(args) = cli.command else {
            panic!("not dagger-label: {:?}", cli.command);
        };
        assert_eq!(args.rollouts.team_sizes, [3, 5]);
        assert!(args.rollouts.rollout_durations.is_empty());
        assert_eq!(args.rollouts.seed, 1000, "formation dagger's default seed");
        assert_eq!(
            (args.iteration, args.first_run, args.runs),
            (2, 10, Some(5))
        );
        let missing_runs = Cli::try_parse_from([
            "formation",
            "dagger-append",
            "--data",
            "d",
            "--iteration",
            "1",
            "p",
        ]);
        assert!(
            missing_runs.is_err(),
            "dagger-append needs the iteration's --runs"
        );
    }

    #[test]
    fn run_counts_are_bounded() {
        assert_eq!(run_count("1"), Ok(1));
        assert_eq!(run_count("10000"), Ok(10_000));
        for bad in ["0", "10001", "1e12", "-1", "many", "18446744073709551616"] {
            let err = run_count(bad).expect_err(bad);
            assert!(err.contains("1 to 10000"), "{err}");
        }
    }

    /// Every subcommand's help ends with examples (`after_help`), each a whole `formation`
    /// command line that parses with today's flags, and one of them runs the subcommand itself.
    #[test]
    fn every_subcommand_ends_its_help_with_examples_that_parse() {
        use clap::CommandFactory;
        let cli = Cli::command();
        let mut checked = 0;
        for sub in cli.get_subcommands() {
            let name = sub.get_name();
            let help = sub
                .get_after_help()
                .map(|h| h.to_string())
                .unwrap_or_else(|| panic!("`formation {name} --help` ends with no examples"));
            let body = help.strip_prefix("Examples:\n").unwrap_or_else(|| {
                panic!("{name}: its after_help starts with Examples:, got {help:?}")
            });
            let examples: Vec<String> = body
                .replace("\\\n", " ")
                .lines()
                .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
                .collect();
            assert!(
                (1..=2).contains(&examples.len()),
                "{name}: {} examples",
                examples.len()
            );
            for example in &examples {
                let words: Vec<&str> = example.split_whitespace().collect();
                assert_eq!(words.first(), Some(&"formation"), "{name}: {example}");
                if let Err(e) = Cli::try_parse_from(&words) {
                    panic!("{name}: the example `{example}` does not parse:\n{e}");
                }
            }
            assert!(
                examples
                    .iter()
                    .any(|e| e.starts_with(&format!("formation {name} "))),
                "{name}: no example runs `formation {name}`: {examples:?}"
            );
            checked += 1;
        }
        assert!(checked >= 15, "only {checked} subcommands");
    }
}

/// `formation run`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Scenario TOML file.
    #[arg(long)]
    pub scenario: PathBuf,
    /// ONNX model for every robot the scenario does not assign one to (default: the scenario's
    /// `model`, else the shipped model).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Clock mode of the world.
    #[arg(long, value_enum, default_value_t = RuntimeSettings::DEFAULT.clock)]
    pub clock: ClockMode,
    /// Output directory for the run logs (`runs/`, `timing/`) and the latency profile `profile.json`.
    #[arg(long, default_value = "out/run")]
    pub out: PathBuf,
    /// Number of runs (default: 1; at most 10000).
    #[arg(long, default_value_t = 1, value_parser = run_count)]
    pub runs: usize,
    /// Index of the first run.
    #[arg(long, default_value_t = 0)]
    pub first_run: usize,
    /// Base seed (default: the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Lockstep: how long the world waits for a robot's command before braking it \[ms\].
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.command_timeout_ms)]
    pub timeout_ms: u64,
    /// Realtime: a command older than this brakes its robot \[ms\].
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.stale_ms)]
    pub stale_ms: u64,
    /// Run id (namespaces the iceoryx2 services, e.g. for `formation swap`; default: generated).
    #[arg(long)]
    pub run_id: Option<String>,
    /// Restart budget: at most this many agent restarts (all robots together) within any
    /// `--restart-window-s`; past it the launch fails. Restarts back off exponentially per robot.
    #[arg(long, default_value_t = 5)]
    pub restarts: u32,
    /// The restart budget's sliding window \[s\].
    #[arg(long, default_value_t = 60.0)]
    pub restart_window_s: f64,
    /// Delay before restarting a dead agent \[ms\]; doubles with each further restart of the same
    /// robot within the window (at most 5 s).
    #[arg(long, default_value_t = 50)]
    pub restart_delay_ms: u64,
    /// Lockstep: each tick takes at least this long \[ms\] (0: as fast as the agents answer),
    /// e.g. 50 to watch a deterministic run at the speed of the real clock.
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.pace_ms)]
    pub pace_ms: u64,
    /// Lockstep: the world polls for the agents' commands this long after publishing a tick's
    /// scans before it blocks \[µs\] (0: block at once). Each empty poll yields the core, so
    /// agents ready to run go first. Lowers the round trip by about one wake-up.
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.spin_us)]
    pub spin_us: u64,
    /// Testing only: make an agent misbehave, `ROBOT:MODE` with MODE one of crash-after=N,
    /// hang-after=N, late-ms=X, nan-after=N (repeatable). Applies to the agent's first start; a
    /// restarted agent behaves.
    #[arg(long = "fault", value_name = "ROBOT:MODE")]
    pub faults: Vec<String>,
    /// How the agents reach the world: iceoryx2 shared memory (this host), Zenoh over TCP
    /// (agents on this host or others; needs --listen), ROS 2 over rmw_zenoh (the world as a
    /// team of ROS 2 robots that ROS 2 agents drive; needs --listen), or a registered transport
    /// (--listen: its endpoint, if it takes one).
    #[arg(long, value_parser = TransportParser::new(crate::TRANSPORT_PLUGINS), default_value_t = Transport::Iceoryx2)]
    pub transport: Transport,
    /// Zenoh and ROS 2: where the world listens, tcp/ADDR:PORT (tcp/0.0.0.0:7447 for every
    /// interface).
    #[arg(long, value_name = "tcp/ADDR:PORT")]
    pub listen: Option<String>,
    /// Zenoh: robots whose agents are started by hand, on other hosts (comma separated, e.g.
    /// 1,2); the launcher starts the others and waits for these.
    #[arg(long, value_delimiter = ',', value_name = "ROBOTS")]
    pub remote: Vec<usize>,
    /// Zenoh: the credentials folder (`formation credentials`); default: fresh credentials in
    /// `<out>/credentials/<run id>/`. ROS 2 on a tls/ endpoint: the folder of `formation
    /// credentials --tls` (default: fresh ones there too), whose `ros2/` gets each node's
    /// session configuration.
    #[arg(long, value_name = "DIR")]
    pub credentials: Option<PathBuf>,
    /// Zenoh: how long the world waits for the remote agents to connect \[s\].
    #[arg(long, default_value_t = 300.0)]
    pub remote_timeout_s: f64,
    /// ROS 2: the ROS domain id of the team's topics (default 0).
    #[arg(long, value_name = "ID", value_parser = clap::value_parser!(u32).range(0..=232))]
    pub ros_domain_id: Option<u32>,
    /// Record the run to this MCAP file, whose folder must exist (with several --runs, run N to
    /// `<stem>-run-NNNN.mcap` beside it): each robot's scan, odometry, command and TF, the goal
    /// and the formation's edges, for Foxglove, Rerun and ROS 2 tools, plus what each agent
    /// received and sent, for replay. The world process writes it.
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Watch the run live in Foxglove: the world serves it on HOST:PORT over Foxglove's
    /// WebSocket protocol, with the topics of --record (e.g. 127.0.0.1:8765, or port 0 for any
    /// free port; another address than loopback is readable by anyone who reaches it). Builds
    /// with the feature `foxglove` only.
    #[arg(long, value_name = "HOST:PORT")]
    pub foxglove: Option<String>,
}

/// `formation profile`: a run whose per-stage latency histograms are written as JSON.
#[derive(Debug, Clone, Args)]
pub struct ProfileArgs {
    /// The run to profile.
    #[command(flatten)]
    pub run: RunArgs,
}

/// `formation swap`: change one running robot's model.
#[derive(Debug, Clone, Args)]
#[command(
    mut_arg("transport", |a| a.help(
        "How to reach the run: iceoryx2 (this host) or Zenoh (sends the model's bytes)"
    )),
    mut_arg("connect", |a| a.help("Zenoh: the world's endpoint, tcp/ADDR:PORT")),
    mut_arg("credentials", |a| a.help(
        "Zenoh: the operator's login file (operator.json from `formation credentials`)"
    ))
)]
pub struct SwapArgs {
    /// Run id of the running launch (`formation run` prints it; set it with `--run-id`).
    #[arg(long)]
    pub run: String,
    /// Robot whose model to swap.
    #[arg(long)]
    pub robot: usize,
    /// The new ONNX model.
    #[arg(long)]
    pub model: PathBuf,
    /// First tick the new model may drive (default: as soon as the agent has loaded it).
    #[arg(long, default_value_t = 0)]
    pub at_tick: u64,
    /// How long to wait for the agent's answer \[s\].
    #[arg(long, default_value_t = 30.0)]
    pub timeout_s: f64,
    /// `--transport`, `--connect` and `--credentials`, the agent's flags with the help above.
    #[command(flatten)]
    pub reach: formation_agent_node::reach::ReachArgs,
}

/// `formation record --connect`: record a live Zenoh team from outside.
#[derive(Debug, Clone, Args)]
pub struct RecordArgs {
    /// The team's endpoint, tcp/HOST:PORT (its `formation run --listen`).
    #[arg(long, value_name = "tcp/HOST:PORT")]
    pub connect: String,
    /// Run id of the running launch (`formation run` prints it; set it with `--run-id`).
    #[arg(long)]
    pub run_id: String,
    /// The team's transport: zenoh (a formation team over Zenoh) or ros2 (a ROS 2 team,
    /// `formation run --transport ros2`).
    #[arg(long, value_parser = TransportParser::new(crate::TRANSPORT_PLUGINS), default_value_t = Transport::Zenoh)]
    pub transport: Transport,
    /// The recorder's login file (recorder.json from `formation credentials`): read-only, and
    /// required for a Zenoh team; a ROS 2 team on tcp/ has no logins and takes none; a ROS 2
    /// team on tls/ takes the recorder's certificate beside it (`formation credentials --tls`).
    #[arg(long, value_name = "FILE")]
    pub credentials: Option<PathBuf>,
    /// The MCAP file to write, whose folder must exist (with several runs, run N to
    /// `<stem>-run-NNNN.mcap` beside it, as `--record` names them).
    #[arg(long, value_name = "FILE.mcap")]
    pub out: PathBuf,
    /// How long to wait for the team's world to be there \[s\].
    #[arg(long, default_value_t = 30.0)]
    pub timeout_s: f64,
}

/// `formation credentials`: Zenoh logins for a team, and with `--tls` its certificates.
#[derive(Debug, Clone, Args)]
pub struct CredentialsArgs {
    /// Robots of the team (logins robot-0 .. robot-(N-1)).
    #[arg(long, required_unless_present = "renew")]
    pub robots: Option<usize>,
    /// Folder to create (owner-only); it must not hold credentials yet (with --renew: the
    /// team's folder).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write a certificate authority (ca.pem) and, per principal (world, robot-I,
    /// operator, recorder), a key and a certificate named by its login, for `tls/` endpoints.
    #[arg(long)]
    pub tls: bool,
    /// How many days the certificates are valid.
    #[arg(long, default_value_t = 365, requires = "tls")]
    pub valid_days: u32,
    /// Renew one principal's key and certificate (world, operator, recorder or robot-I) with
    /// the folder's authority; the others stay valid.
    #[arg(
        long,
        value_name = "PRINCIPAL",
        requires = "tls",
        conflicts_with = "robots"
    )]
    pub renew: Option<String>,
}

/// `--ranges`: a range input, checked as a model's metadata is.
fn range_input(text: &str) -> Result<formation_proto::RangeInput, String> {
    formation_proto::RangeInput::parse(text).map_err(|e| e.to_string())
}

/// `--neighbours K`: a neighbour input of K slots under the scenarios' default rule
/// ([`formation_proto::NeighbourInput::with_default_rule`]), or a whole declaration
/// (`slots=K,threshold=T,nearest=M[,hidden=1]`), checked as a model's metadata is.
fn neighbour_slots(text: &str) -> Result<formation_proto::NeighbourInput, String> {
    use formation_proto::NeighbourInput;
    if text.contains('=') {
        return NeighbourInput::parse(text).map_err(|e| e.to_string());
    }
    let slots: usize = text.trim().parse().map_err(|_| {
        format!(
            "expected a number of neighbour slots from {} to {} (or a declaration \
             slots=K,threshold=T,nearest=M[,hidden=1]), got {text:?}",
            NeighbourInput::MIN_SLOTS,
            NeighbourInput::MAX_SLOTS
        )
    })?;
    NeighbourInput::with_default_rule(slots).map_err(|e| e.to_string())
}
