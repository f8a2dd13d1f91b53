//! What the `formation-fuzz` commands do: list the targets, write the corpora, run one campaign,
//! run the CI lane (every target for a few seconds), run one saved case; and the report they print.

use std::path::Path;
use std::time::Duration;

use crate::FuzzError;
use crate::campaign::{self, Report, Settings};
use crate::corpus;
use crate::targets::{self, Target};

/// Address space a campaign may take: an allocation past it fails (and aborts the process, with
/// the size in the message) instead of swapping the machine; the resident-memory limit the
/// watchdog enforces is far below it.
pub const ADDRESS_SPACE_LIMIT: u64 = 4 << 30;

/// Caps this process's address space at [`ADDRESS_SPACE_LIMIT`] (or the hard limit, if lower).
pub fn limit_address_space() -> std::io::Result<()> {
    let (_, hard) = rlimit::Resource::AS.get()?;
    rlimit::Resource::AS.set(ADDRESS_SPACE_LIMIT.min(hard), hard)
}

/// Prints `report`: its line and its most frequent refusals.
pub fn print(report: &Report) {
    println!("{}", report.line());
    let shown: Vec<String> = report
        .refusals
        .iter()
        .take(6)
        .map(|(kind, n)| {
            format!(
                "{kind} {:.1} %",
                100.0 * *n as f64 / report.cases.max(1) as f64
            )
        })
        .collect();
    if !shown.is_empty() {
        println!("{:<15} refused: {}", "", shown.join(", "));
    }
    for finding in &report.findings {
        println!(
            "{:<15} FINDING case {} (from seed {}): {}\n{:<15}   saved as {}",
            "",
            finding.index,
            finding.seed,
            finding.what.lines().next().unwrap_or_default(),
            "",
            finding.saved.display()
        );
    }
}

/// Runs one campaign of `target` with the seeds under `root`.
pub fn run(target: &'static Target, root: &Path, settings: &Settings) -> Result<Report, FuzzError> {
    let seeds = corpus::load(root, target)?;
    campaign::run(target, &seeds, settings)
}

/// The CI lane: every target for `each`, reports printed as they finish.
pub fn ci(root: &Path, each: Duration, settings: &Settings) -> Result<Vec<Report>, FuzzError> {
    let settings = Settings {
        cases: None,
        time: Some(each),
        ..settings.clone()
    };
    let mut reports = Vec::new();
    for target in targets::ALL {
        let report = run(target, root, &settings)?;
        print(&report);
        reports.push(report);
    }
    Ok(reports)
}

/// Writes the corpora of `names` (every target when empty) under `root`.
pub fn seed(root: &Path, names: &[String]) -> Result<(), FuzzError> {
    let chosen: Vec<&'static Target> = if names.is_empty() {
        targets::ALL.iter().collect()
    } else {
        names
            .iter()
            .map(|n| targets::find(n))
            .collect::<Result<_, _>>()?
    };
    for target in chosen {
        let written = corpus::write(root, target)?;
        let bytes: u64 = written
            .iter()
            .filter_map(|p| std::fs::metadata(p).ok())
            .map(|m| m.len())
            .sum();
        println!(
            "{:<15} {} seeds, {bytes} bytes, in {}",
            target.name,
            written.len(),
            corpus::dir(root, target).display()
        );
    }
    Ok(())
}

/// Lists the targets.
pub fn list() {
    for target in targets::ALL {
        println!("{:<15} {}", target.name, target.about);
    }
}
