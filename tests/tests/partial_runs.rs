//! A run that ends abnormally keeps what it played: Ctrl-C on the launcher, a SIGKILLed world
//! and a full disk each leave an incomplete run log (or, on the full disk, the journal cut back
//! to whole lines and no temporary file), a non-zero exit, and a report that says "incomplete".

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use formation_proto::wire::RunId;
use formation_tests::{
    LiveProcess, ProcessTest, Tmpfs, await_connected, binaries, compared_steps, files_under,
    formation_run, read_json, repo_root, report_command, run, send_signal, signal_world,
};

/// The watchdog limit of each test: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

/// `formation run` of `scenario` into `out`, with `extra` flags.
fn launch(run_id: &RunId, scenario: &Path, out: &Path, extra: &[&str]) -> LiveProcess {
    LiveProcess::spawn(formation_run(run_id, scenario, out, extra))
}

/// Checks the incomplete run 0 in `out`: its log, the summary that lists it, no journal left,
/// and a report that says so. Returns the run log.
fn assert_kept_incomplete(out: &Path, min_ticks: usize, describe: &str) -> serde_json::Value {
    let log = read_json(&out.join("runs/run-0000.json"));
    assert_eq!(log["complete"], false, "{describe}");
    let ticks = log["trajectory"]["commands"].as_array().map_or(0, Vec::len);
    assert!(
        ticks >= min_ticks,
        "{ticks} ticks kept, expected at least {min_ticks}\n{describe}"
    );
    assert!(ticks < 1200, "the run stopped early: {ticks} ticks");
    assert_eq!(
        log["trajectory"]["poses"].as_array().map(Vec::len),
        Some(ticks + 1)
    );
    assert!(
        !out.join("runs/run-0000.journal").exists(),
        "the journal became the run log"
    );
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["runs"], 1, "{summary}");
    let incomplete = summary["incomplete_runs"]
        .as_array()
        .unwrap_or_else(|| panic!("summary.json lists the incomplete run: {summary}"));
    assert_eq!(incomplete.len(), 1);
    assert_eq!(incomplete[0]["index"], 0);
    assert_eq!(incomplete[0]["ticks"], ticks);

    let html_path = out.with_file_name("report.html");
    run(report_command(out, &html_path), LIMIT).assert_success();
    let html = std::fs::read_to_string(&html_path).expect("report.html");
    assert!(
        html.contains("1 of 1 run incomplete (stopped early"),
        "Table I marks the run incomplete"
    );
    assert!(html.contains("<span class=\"badge\">incomplete</span>"));
    log
}

/// Ctrl-C (SIGINT to the launcher) four seconds into a 60 s realtime run: the launcher exits
/// non-zero, and the run played so far is kept, marked incomplete, in the run log, the summary
/// and the report.
#[test]
fn ctrl_c_keeps_the_partial_run_marked_incomplete() {
    let t = ProcessTest::start("ctrl_c_partial", LIMIT);
    let out = t.out();
    let scenario = repo_root().join("scenarios/case1.toml");
    let recording = t.path().join("ctrlc.mcap");
    let record = recording.display().to_string();
    let mut command = t.formation_run(&scenario, &["--clock", "realtime", "--record", &record]);
    // The world's info lines (its recording's) go to a pipe here: no colour codes (issue 39).
    command.env("FORMATION_LOG", "info");
    let mut launch = LiveProcess::spawn(command);
    await_connected(&mut launch);
    std::thread::sleep(Duration::from_secs(4));
    send_signal(launch.id(), "-INT");
    let finished = launch.finish(LIMIT);
    finished.assert_failed("an interrupted run fails");
    finished.assert_stderr_has("interrupted by Ctrl-C");
    t.assert_clean();
    finished.assert_holds(
        finished.stderr().contains("recorded") && !finished.stderr().contains('\u{1b}'),
        "log lines to a pipe are plain text",
    );
    // 4 s at 20 Hz is 80 ticks; allow for a slow start on a loaded machine.
    let log = assert_kept_incomplete(&out, 40, &finished.describe());
    assert_eq!(log["stop_reason"], "interrupted by Ctrl-C");
    assert_eq!(log["planned_ticks"], 1200);
    assert!(
        out.join("timing/run-0000.json").is_file(),
        "the world keeps its timing log too"
    );
    // The recording says the run stopped early, and so does its replay (issue 39): every tick
    // recorded is replayed, the report is marked incomplete with the reason.
    let json = t.path().join("ctrlc.replay.json");
    let mut replay = Command::new(&binaries().cli);
    replay
        .arg("replay")
        .arg(&recording)
        .arg("--json")
        .arg(&json);
    let replayed = run(replay, LIMIT);
    let report = read_json(&json);
    assert_eq!(
        report["complete"],
        false,
        "{report}\n{}",
        replayed.describe()
    );
    assert!(
        report["stop_reason"]
            .as_str()
            .is_some_and(|r| !r.is_empty()),
        "{report}"
    );
    replayed.assert_stdout_has("the run is incomplete: it stopped before its last tick");
    let compared = compared_steps(&report);
    assert!(compared >= 3 * 40, "{report}");
}

/// A world SIGKILLed mid-run cannot save anything itself: the launcher turns the journal it
/// left into an incomplete run log once the world is gone.
#[test]
fn a_sigkilled_world_leaves_a_journal_the_launcher_recovers() {
    let t = ProcessTest::start("killed_world", LIMIT);
    let out = t.out();
    let scenario = repo_root().join("scenarios/case1.toml");
    let mut launch = launch(&t.run, &scenario, &out, &["--clock", "realtime"]);
    await_connected(&mut launch);
    // Past the journal's one-second flush period, twice over.
    std::thread::sleep(Duration::from_secs(3));
    let journal = out.join("runs/run-0000.journal");
    assert!(journal.is_file(), "the world journals the run as it goes");
    let finished = signal_world(&t.run, launch, "-KILL", LIMIT);
    finished.assert_failed("a killed world fails the launch");
    finished.assert_stderr_has("recovered run 0");
    t.assert_clean();
    let log = assert_kept_incomplete(&out, 20, &finished.describe());
    let reason = log["stop_reason"].as_str().unwrap_or_default();
    assert!(
        reason.contains("the world process exited (killed by signal 9)"),
        "{reason}"
    );
}

/// An agent that crashes with no restart left: the launcher stops the world, which keeps the
/// run played so far; the run log says why it stopped.
#[test]
fn a_spent_restart_budget_keeps_the_partial_run() {
    let t = ProcessTest::start("budget_partial", LIMIT);
    let out = t.out();
    let scenario = repo_root().join("scenarios/case1.toml");
    let finished = launch(
        &t.run,
        &scenario,
        &out,
        &[
            "--clock",
            "lockstep",
            "--pace-ms",
            "5",
            "--restarts",
            "0",
            "--fault",
            "1:crash-after=60",
        ],
    )
    .finish(LIMIT);
    finished.assert_failure_mentioning("restart budget");
    t.assert_clean();
    let log = assert_kept_incomplete(&out, 60, &finished.describe());
    let reason = log["stop_reason"].as_str().unwrap_or_default();
    assert!(
        reason.starts_with("the agent of robot 1 exited") && reason.contains("restart budget"),
        "{reason}"
    );
}

/// `--out` on a 256 KiB disk and a run whose journal needs about 1 MB: the world fails as soon
/// as the disk is full, with an error that names the file and the full disk, leaves the journal
/// cut back to whole lines (far short of the scenario's ticks) and no temporary file, and the
/// launcher exits non-zero.
#[test]
fn a_full_disk_fails_the_run_promptly_and_leaves_no_temporary_file() {
    let t = ProcessTest::start("full_disk", LIMIT);
    let disk = Tmpfs::mount(&t.path().join("disk"), "256k");
    let out = disk.dir().join("out");
    let ticks = 2400;
    let scenario = t.case1(120.0);
    let finished = launch(&t.run, &scenario, &out, &["--clock", "lockstep"]).finish(LIMIT);
    finished.assert_failed("a run that cannot be written fails");
    let stderr = finished.stderr();
    finished.assert_holds(
        stderr.contains("run-0000.journal") && stderr.contains("the disk is full"),
        "the error names the file and the full disk",
    );
    t.assert_clean();

    let files = files_under(disk.dir());
    let temporary: Vec<&PathBuf> = files
        .iter()
        .filter(|p| p.to_string_lossy().contains(".tmp"))
        .collect();
    finished.assert_holds(
        temporary.is_empty(),
        &format!("temporary files left: {temporary:?}"),
    );
    // The run stopped when the disk filled: the journal holds whole lines, far fewer than the
    // scenario's ticks (it does not play on and fail only at the end).
    let journal = out.join("runs/run-0000.journal");
    let (header, trajectory) = formation_world::runlog::read_journal(&journal)
        .unwrap_or_else(|e| panic!("{e}\n{}", finished.describe()));
    assert_eq!(header.ticks, ticks);
    let journaled = trajectory.commands.len() as u64;
    assert!(
        journaled > 0 && journaled < ticks,
        "{journaled} of {ticks} ticks journaled"
    );
    let text = std::fs::read(&journal).expect("journal");
    assert_eq!(text.last(), Some(&b'\n'), "cut back to whole lines");
    drop(disk);
}
