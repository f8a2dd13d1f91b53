//! Figures and messages that stay true under faults: a run cut short by a signal is never a
//! success and Table I says how many runs were incomplete; a full disk is named as the cause,
//! first, and a partial `eval --out` is marked so and the report says what it lacks; an output
//! path under a file names that file.

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use formation_tests::{
    LiveProcess, ProcessTest, Tmpfs, await_connected, binaries, expert_eval_once, files_under,
    formation_run, formation_run_args, read_json, repo_root, report_command, run, shipped_model,
    signal_world,
};
use formation_world::metrics::{MetricsConfig, run_metrics};

/// The watchdog limit of each test: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

/// SIGHUP ends the world by its default action, 30-odd simulated seconds into a 60 s run of
/// the shipped policy: the last 20 s it played are well formed, which used to count as a success
/// at both tolerances. The run is kept, marked incomplete, and counts as a run that did not
/// succeed; the terminal and `summary.json` say how many runs were incomplete.
///
/// The launch runs under `env --default-signal=HUP`: a harness started with `nohup` ignores
/// SIGHUP, every child inherits that, and the world would rightly live through the signal.
#[test]
fn a_run_cut_by_sighup_to_the_world_is_incomplete_and_no_success() {
    let t = ProcessTest::start("sighup_incomplete", LIMIT);
    let out = t.out();
    let scenario = repo_root().join("scenarios/case1.toml");
    let model = shipped_model();
    let mut hangup_by_default = Command::new("env");
    hangup_by_default
        .arg("--default-signal=HUP")
        .arg(&binaries().cli);
    formation_run_args(
        &mut hangup_by_default,
        &t.run,
        (&scenario, &model, &out),
        &["--clock", "lockstep", "--pace-ms", "10"],
    );
    let mut launch = LiveProcess::spawn(hangup_by_default);
    await_connected(&mut launch);
    // Wait until the journal holds more than the 20 s window (400 ticks), well short of 1200.
    let journal = out.join("runs/run-0000.journal");
    let started = Instant::now();
    loop {
        let ticks = formation_world::runlog::read_journal(&journal)
            .map_or(0, |(_, trajectory)| trajectory.commands.len());
        if ticks >= 600 {
            break;
        }
        launch.assert_holds(
            started.elapsed() < Duration::from_secs(120),
            &format!("the run did not reach 600 ticks ({ticks})"),
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let finished = signal_world(&t.run, launch, "-HUP", LIMIT);
    finished.assert_failed("a run cut short fails the launch");
    t.assert_clean();

    let log = formation_world::RunLog::read(&out.join("runs/run-0000.json"))
        .unwrap_or_else(|e| panic!("{e}\n{}", finished.describe()));
    let played = log.ticks() as u64;
    finished.assert_holds((600..1200).contains(&played), &format!("{played} ticks"));
    assert!(!log.complete);
    // What the run log's figures were before a run knew it was incomplete: its last 20 s pass.
    let as_if_whole = run_metrics(&log.trajectory, played, &MetricsConfig::default());
    assert!(
        as_if_whole.success_5 && as_if_whole.success_10,
        "the played part must pass on its own for this test to mean anything: {as_if_whole:?}"
    );
    assert!(!log.metrics.success_5 && !log.metrics.success_10);
    assert_eq!(
        log.metrics.incomplete.map(|p| (p.ticks, p.planned_ticks)),
        Some((played, 1200))
    );

    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["runs"], 1, "{summary}");
    assert_eq!(summary["runs_incomplete"], 1, "{summary}");
    assert_eq!(summary["success_rate_5"], 0.0, "{summary}");
    assert_eq!(summary["success_rate_10"], 0.0, "{summary}");
    assert_eq!(summary["per_run"][0]["incomplete"]["ticks"], played);
    assert_eq!(summary["per_run"][0]["incomplete"]["planned_ticks"], 1200);
    assert_eq!(summary["median_convergence_s"], serde_json::Value::Null);
    assert!(
        finished
            .stdout()
            .contains("incomplete runs: 1 of 1, counted as failures"),
        "Table I on the terminal says so\n{}",
        finished.describe()
    );
}

/// A full disk under `formation run`: the world's failed write is the first thing said, and no
/// agent is reported as exited and restarting (the world asked them to exit).
#[test]
fn a_full_disk_under_run_is_named_first_without_restart_lines() {
    let t = ProcessTest::start("full_disk_first", LIMIT);
    let disk = Tmpfs::mount(&t.path().join("disk"), "256k");
    let out = disk.dir().join("out");
    let scenario = t.case1(120.0);
    let finished = LiveProcess::spawn(formation_run(
        &t.run,
        &scenario,
        &out,
        &["--clock", "lockstep"],
    ))
    .finish(LIMIT);
    finished.assert_failed("a run that cannot be written fails");
    t.assert_clean();
    let stderr = finished.stderr();
    finished.assert_holds(
        !stderr.contains("restarting"),
        "no agent restart is announced: the world asked the agents to exit",
    );
    let first = stderr
        .lines()
        .find(|line| line.contains("error") || line.contains("exited"))
        .unwrap_or_default();
    assert!(
        first.starts_with("formation-world: error:")
            && first.contains("run-0000.journal")
            && first.contains("the disk is full"),
        "the world's failed write comes first: {first:?}\n{}",
        finished.describe()
    );
    drop(disk);
}

/// `--json` or `--out` under a file: the message names the file in the way, before anything runs,
/// and speaks of neither "File exists" nor a full disk.
#[test]
fn an_output_path_under_a_file_names_that_file() {
    let t = ProcessTest::start("path_under_file", LIMIT);
    let blocker = t.path().join("passwd");
    std::fs::write(&blocker, b"root:x:0:0\n").expect("blocker");
    let scenario = repo_root().join("scenarios/case1.toml");
    let json = blocker.join("x.json");
    let out = blocker.join("x");
    for extra in [
        ["--json", json.to_str().expect("utf-8")],
        ["--out", out.to_str().expect("utf-8")],
    ] {
        let finished = run(expert_eval_once(&scenario, &extra), LIMIT);
        finished.assert_failed("expected failure");
        finished.assert_no_panic();
        let stderr = finished.stderr();
        assert!(
            stderr.contains(&format!("{} is a file, not a directory", blocker.display())),
            "{}",
            finished.describe()
        );
        for misleading in ["File exists", "disk", "Not a directory (os error"] {
            finished.assert_holds(
                !stderr.contains(misleading),
                &format!("{misleading:?} is not the cause"),
            );
        }
        finished.assert_holds(
            !finished.stdout().contains("Table I"),
            "refused before evaluating",
        );
    }
}

/// A full disk while `eval --out` writes its run log: the eval fails naming the full disk and
/// the partial output; `summary.json` is written after the run logs, marked `complete: false`
/// with the run logs it should have; `formation report` builds but warns, naming the missing
/// run log, on the terminal and on the page.
#[test]
fn a_full_disk_under_eval_out_leaves_an_output_marked_partial_that_report_names() {
    let t = ProcessTest::start("eval_out_full", LIMIT);
    let disk = Tmpfs::mount(&t.path().join("disk"), "64k");
    let out = disk.dir().join("out");
    let scenario = repo_root().join("scenarios/case1.toml");
    let finished = run(
        expert_eval_once(&scenario, &["--out", out.to_str().expect("utf-8")]),
        LIMIT,
    );
    finished.assert_failed("expected failure");
    finished.assert_no_panic().assert_stderr_has_all(
        &["run-0000.json", "the disk is full", "partial"],
        "the error names the run log, the full disk and the partial output",
    );
    let temporary: Vec<PathBuf> = files_under(disk.dir())
        .into_iter()
        .filter(|p| p.to_string_lossy().contains(".tmp"))
        .collect();
    assert!(temporary.is_empty(), "temporary files left: {temporary:?}");
    assert!(!out.join("runs/run-0000.json").exists());
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["complete"], false, "{summary}");
    assert_eq!(summary["run_logs"], serde_json::json!([0]), "{summary}");
    assert_eq!(
        summary["medians_over"]["convergence_s"]["of"],
        summary["medians_over"]["rel_formation_error"]["of"],
        "each median states its runs: {summary}"
    );

    let html = t.path().join("report.html");
    let reported = run(report_command(&out, &html), LIMIT);
    reported.assert_success().assert_stderr_has_all(
        &["warning", "partial output", "runs/run-0000.json"],
        "the report says what is missing",
    );
    let page = std::fs::read_to_string(&html).expect("report.html");
    assert!(page.contains("partial output"), "the page says it too");
    drop(disk);
}
