//! One campaign: cases made from a target's seeds ([`crate::mutate::make_case`]) run against the
//! target until a case count or a time is reached, with a counter, a rate, the share decoded, the
//! refusals by kind and the process's peak memory.
//!
//! A panic is caught, saved to the findings folder with its message, and counted; the campaign
//! stops after a few. A watchdog thread watches the case in flight: one that runs longer than
//! [`Settings::hang_after`] (a hang) or a resident memory above [`Settings::memory_limit`] (an
//! unbounded allocation) is saved and ends the process with [`EXIT_WATCHDOG`], as nothing else
//! stops a hung decoder. Every finding file names the campaign seed and the case index, so
//! `formation-fuzz run NAME --seed S --skip I --cases 1` makes the same case again.

use std::collections::BTreeMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::FuzzError;
use crate::mutate::make_case;
use crate::targets::{Scratch, Seed, Target};

/// The exit status when the watchdog ends a campaign (a hang or memory past the limit).
pub const EXIT_WATCHDOG: i32 = 3;

/// Findings after which a campaign stops.
const MAX_FINDINGS: usize = 5;

/// How a campaign runs.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Stop after this many cases.
    pub cases: Option<u64>,
    /// Stop after this long.
    pub time: Option<Duration>,
    /// The campaign seed (the same seed makes the same cases).
    pub seed: u64,
    /// The first case index (to make one case of a campaign again).
    pub skip: u64,
    /// Where findings are saved.
    pub findings: PathBuf,
    /// A case running longer than this is a hang.
    pub hang_after: Duration,
    /// Resident memory above this many bytes is a finding.
    pub memory_limit: u64,
    /// Write each case here before running it (to catch a case that aborts the process).
    pub trace: Option<PathBuf>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            cases: None,
            time: Some(Duration::from_secs(10)),
            seed: 1,
            skip: 0,
            findings: PathBuf::from("target/fuzz-findings"),
            hang_after: Duration::from_secs(10),
            memory_limit: 256 << 20,
            trace: None,
        }
    }
}

/// A case that broke the property.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    /// Its index in the campaign.
    pub index: u64,
    /// The seed it was made from.
    pub seed: String,
    /// What happened (the panic's message and place).
    pub what: String,
    /// Where the case was saved.
    pub saved: PathBuf,
}

/// What a campaign did.
#[derive(Debug, Clone)]
pub struct Report {
    /// The target.
    pub target: &'static str,
    /// Seeds in its corpus.
    pub seeds: usize,
    /// Cases run.
    pub cases: u64,
    /// Cases that decoded.
    pub decoded: u64,
    /// Wall time.
    pub elapsed: Duration,
    /// Refusals by kind, most frequent first.
    pub refusals: Vec<(String, u64)>,
    /// Panics.
    pub findings: Vec<Finding>,
    /// The process's peak resident memory so far \[bytes\] (`VmHWM`), when the OS says.
    pub peak_rss: Option<u64>,
}

impl Report {
    /// Cases per second.
    pub fn rate(&self) -> f64 {
        self.cases as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }

    /// The share of cases that decoded, in percent.
    pub fn decoded_percent(&self) -> f64 {
        100.0 * self.decoded as f64 / (self.cases.max(1)) as f64
    }

    /// One line: count, time, rate, share decoded, memory, findings.
    pub fn line(&self) -> String {
        let rss = self
            .peak_rss
            .map_or("?".to_owned(), |b| format!("{:.0} MB", b as f64 / 1e6));
        format!(
            "{:<15} {:>9} cases in {:>6.1} s ({:>7.0}/s), {:>5.1} % decoded, {} seeds, peak RSS {rss}, {} findings",
            self.target,
            self.cases,
            self.elapsed.as_secs_f64(),
            self.rate(),
            self.decoded_percent(),
            self.seeds,
            self.findings.len()
        )
    }
}

/// The process's resident memory now and its peak \[bytes\], from `/proc/self/status`.
pub fn memory() -> Option<(u64, u64)> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map(|kb| kb * 1024)
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

/// What the watchdog sees of the case in flight.
struct InFlight {
    index: AtomicU64,
    /// Milliseconds since the campaign began when the case in flight began.
    started_ms: AtomicU64,
    done: AtomicBool,
}

/// The message of the last panic, taken by the panic hook instead of printed.
static LAST_PANIC: Mutex<Option<String>> = Mutex::new(None);

/// Saves case `index` (`bytes`) of `target` with a note of what it broke.
fn save(
    settings: &Settings,
    target: &str,
    index: u64,
    bytes: &[u8],
    what: &str,
) -> Result<PathBuf, FuzzError> {
    let path = settings
        .findings
        .join(format!("{target}-seed{}-case{index}.bin", settings.seed));
    let saving = |source| FuzzError::SaveFinding {
        path: path.clone(),
        source,
    };
    std::fs::create_dir_all(&settings.findings).map_err(saving)?;
    std::fs::write(&path, bytes).map_err(saving)?;
    std::fs::write(path.with_extension("txt"), what).map_err(saving)?;
    Ok(path)
}

/// Starts the watchdog over `flight`; it ends the process on a hang or memory past the limit.
fn watchdog(
    target: &'static Target,
    seeds: Arc<Vec<Vec<u8>>>,
    settings: Settings,
    flight: Arc<InFlight>,
    begun: Instant,
    scratch: PathBuf,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        while !flight.done.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(50));
            let index = flight.index.load(Ordering::Relaxed);
            let started = flight.started_ms.load(Ordering::Relaxed);
            let running = (begun.elapsed().as_millis() as u64).saturating_sub(started);
            let rss = memory().map_or(0, |(rss, _)| rss);
            let what = if running > settings.hang_after.as_millis() as u64 {
                format!("case {index} has run for {running} ms: a hang")
            } else if rss > settings.memory_limit {
                format!(
                    "resident memory {} MB during case {index}, over the limit of {} MB",
                    rss >> 20,
                    settings.memory_limit >> 20
                )
            } else {
                continue;
            };
            let (_, _, bytes) =
                make_case(&seeds, target.tokens, target.shape, settings.seed, index);
            let saved = save(&settings, target.name, index, &bytes, &what)
                .map_or_else(|e| e.to_string(), |p| p.display().to_string());
            eprintln!(
                "formation-fuzz: {}: {what}; the case is saved as {saved}",
                target.name
            );
            let _ = std::fs::remove_dir_all(&scratch);
            std::process::exit(EXIT_WATCHDOG);
        }
    })
}

/// Runs `target` over `seeds` as `settings` say.
pub fn run(
    target: &'static Target,
    seeds: &[Seed],
    settings: &Settings,
) -> Result<Report, FuzzError> {
    let scratch = Scratch::new()?;
    let seed_bytes: Arc<Vec<Vec<u8>>> = Arc::new(seeds.iter().map(|(_, b)| b.clone()).collect());
    let begun = Instant::now();
    let flight = Arc::new(InFlight {
        index: AtomicU64::new(settings.skip),
        started_ms: AtomicU64::new(0),
        done: AtomicBool::new(false),
    });
    let dog = watchdog(
        target,
        Arc::clone(&seed_bytes),
        settings.clone(),
        Arc::clone(&flight),
        begun,
        scratch.dir().to_path_buf(),
    );
    let previous_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|info| {
        if let Ok(mut last) = LAST_PANIC.lock() {
            *last = Some(info.to_string());
        }
    }));
    let result = cases(
        target,
        seeds,
        &seed_bytes,
        settings,
        &scratch,
        &flight,
        begun,
    );
    std::panic::set_hook(previous_hook);
    flight.done.store(true, Ordering::Relaxed);
    let _ = dog.join();
    result
}

/// The campaign's loop.
fn cases(
    target: &'static Target,
    seeds: &[Seed],
    seed_bytes: &[Vec<u8>],
    settings: &Settings,
    scratch: &Scratch,
    flight: &InFlight,
    begun: Instant,
) -> Result<Report, FuzzError> {
    let mut report = Report {
        target: target.name,
        seeds: seeds.len(),
        cases: 0,
        decoded: 0,
        elapsed: Duration::ZERO,
        refusals: Vec::new(),
        findings: Vec::new(),
        peak_rss: None,
    };
    let mut refusals: BTreeMap<String, u64> = BTreeMap::new();
    let mut index = settings.skip;
    loop {
        if settings.cases.is_some_and(|n| report.cases >= n)
            || (report.cases.is_multiple_of(64)
                && settings.time.is_some_and(|t| begun.elapsed() >= t))
            || report.findings.len() >= MAX_FINDINGS
        {
            break;
        }
        let (seed, _, case) = make_case(
            seed_bytes,
            target.tokens,
            target.shape,
            settings.seed,
            index,
        );
        if let Some(trace) = &settings.trace {
            std::fs::write(trace, &case).map_err(|source| FuzzError::SaveFinding {
                path: trace.clone(),
                source,
            })?;
        }
        flight.index.store(index, Ordering::Relaxed);
        flight
            .started_ms
            .store(begun.elapsed().as_millis() as u64, Ordering::Relaxed);
        match catch_unwind(AssertUnwindSafe(|| (target.run)(scratch, &case))) {
            Ok(Ok(())) => report.decoded += 1,
            Ok(Err(refusal)) => *refusals.entry(refusal.0).or_default() += 1,
            Err(_) => {
                let what = LAST_PANIC
                    .lock()
                    .ok()
                    .and_then(|mut p| p.take())
                    .unwrap_or_else(|| "a panic".to_owned());
                let saved = save(settings, target.name, index, &case, &what)?;
                report.findings.push(Finding {
                    index,
                    seed: seeds[seed].0.clone(),
                    what,
                    saved,
                });
            }
        }
        report.cases += 1;
        index += 1;
    }
    report.elapsed = begun.elapsed();
    let mut refusals: Vec<(String, u64)> = refusals.into_iter().collect();
    refusals.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    report.refusals = refusals;
    report.peak_rss = memory().map(|(_, peak)| peak);
    Ok(report)
}

/// Runs one saved case (a finding) through `target`: `Ok(Ok)` decoded, `Ok(Err)` refused.
pub fn run_file(target: &Target, path: &Path) -> Result<Result<(), String>, FuzzError> {
    let bytes = std::fs::read(path).map_err(|source| FuzzError::Corpus {
        action: "reading the case",
        path: path.to_path_buf(),
        source,
    })?;
    let scratch = Scratch::new()?;
    Ok((target.run)(&scratch, &bytes).map_err(|r| r.0))
}
