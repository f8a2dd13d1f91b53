//! `formation-fuzz`: the fuzzing driver (formation_fuzz::driver does the work). Exit status 0
//! when every case kept the property, 1 on a finding or an error, 3 when the watchdog ended a
//! campaign (a hang or memory past the limit).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use formation_fuzz::campaign::Settings;
use formation_fuzz::{campaign, corpus, driver, targets};

#[derive(Parser)]
#[command(about = "Fuzzing every decoder of bytes from outside, on stable Rust")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// The corpus root (one folder per target).
    #[arg(long, global = true)]
    corpus: Option<PathBuf>,
    /// Where findings are saved.
    #[arg(long, global = true, default_value = "target/fuzz-findings")]
    findings: PathBuf,
    /// The campaign seed: the same seed makes the same cases.
    #[arg(long, global = true, default_value_t = 1)]
    seed: u64,
    /// Resident memory [MB] above which the watchdog stops a campaign (a finding).
    #[arg(long, global = true, default_value_t = 256)]
    memory_mb: u64,
}

#[derive(Subcommand)]
enum Command {
    /// Lists the targets.
    List,
    /// Writes the seed corpora from the real encoders.
    Seed {
        /// Targets (all when none).
        names: Vec<String>,
    },
    /// Runs one campaign.
    Run {
        /// The target.
        name: String,
        /// Stop after this many seconds.
        #[arg(long, conflicts_with = "minutes")]
        seconds: Option<f64>,
        /// Stop after this many minutes.
        #[arg(long)]
        minutes: Option<f64>,
        /// Stop after this many cases.
        #[arg(long)]
        cases: Option<u64>,
        /// Start at this case index (with --cases 1, makes one case of the campaign again).
        #[arg(long, default_value_t = 0)]
        skip: u64,
        /// Write each case to this file before running it (finds a case that aborts).
        #[arg(long)]
        trace: Option<PathBuf>,
    },
    /// The CI lane: every target for a few seconds.
    Ci {
        /// Seconds per target.
        #[arg(long, default_value_t = 10.0)]
        seconds_each: f64,
    },
    /// Runs one saved case.
    Case {
        /// The target.
        name: String,
        /// The case file.
        file: PathBuf,
    },
}

fn seconds(s: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(s).map_err(|_| anyhow::anyhow!("{s} is not a number of seconds"))
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("formation-fuzz: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Runs the command; `Ok(false)` when a campaign had findings.
fn run(cli: Cli) -> anyhow::Result<bool> {
    let root = cli.corpus.unwrap_or_else(corpus::default_root);
    let base = Settings {
        seed: cli.seed,
        findings: cli.findings,
        memory_limit: cli.memory_mb << 20,
        ..Settings::default()
    };
    match cli.command {
        Command::List => driver::list(),
        Command::Seed { names } => driver::seed(&root, &names)?,
        Command::Run {
            name,
            seconds: secs,
            minutes,
            cases,
            skip,
            trace,
        } => {
            driver::limit_address_space()?;
            let time = match (secs, minutes, cases) {
                (Some(s), _, _) => Some(seconds(s)?),
                (_, Some(m), _) => Some(seconds(m * 60.0)?),
                (None, None, Some(_)) => None,
                (None, None, None) => Some(Duration::from_secs(10)),
            };
            let settings = Settings {
                cases,
                time,
                skip,
                trace,
                ..base
            };
            let report = driver::run(targets::find(&name)?, &root, &settings)?;
            driver::print(&report);
            return Ok(report.findings.is_empty());
        }
        Command::Ci { seconds_each } => {
            driver::limit_address_space()?;
            let reports = driver::ci(&root, seconds(seconds_each)?, &base)?;
            return Ok(reports.iter().all(|r| r.findings.is_empty()));
        }
        Command::Case { name, file } => match campaign::run_file(targets::find(&name)?, &file)? {
            Ok(()) => println!("decoded"),
            Err(refusal) => println!("refused: {refusal}"),
        },
    }
    Ok(true)
}
