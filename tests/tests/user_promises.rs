//! Issue 39's command-line promises, through the real `formation` binary: an output never
//! overwrites one of the command's own inputs (refused, exit 2, the input kept byte for byte, and
//! nothing else written); `--controller policy` with `--robots` evaluates the policy without
//! `--model` (the shipped default); `eval --robots N` with `--out` and `--save-trajectories`
//! evaluates that one team size as any evaluation.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_tests::{Finished, ProcessTest, binaries, expert_eval_once, read_json, run};

const LIMIT: Duration = Duration::from_secs(300);

/// `formation ARGS`.
fn formation(args: &[&str]) -> Finished {
    let mut command = Command::new(&binaries().cli);
    command.args(args);
    run(command, LIMIT)
}

fn text(path: &Path) -> &str {
    path.to_str().expect("a UTF-8 path")
}

#[test]
fn outputs_never_overwrite_their_own_inputs() {
    let t = ProcessTest::start("promises_inputs", LIMIT);
    let scenario = t.case1(2.0);
    let before = std::fs::read(&scenario).expect("scenario");
    let out = t.path().join("eval");
    let evaluated = run(expert_eval_once(&scenario, &["--out", text(&out)]), LIMIT);
    evaluated.assert_success();
    let summary = out.join("summary.json");
    let run_log = out.join("runs/run-0000.json");
    let kept = |path: &Path| std::fs::read(path).expect("an input");
    let (summary_bytes, log_bytes) = (kept(&summary), kept(&run_log));

    // `report D --out D/summary.json` and `--out D/runs/run-0000.json`: refused, kept.
    for (target, what) in [(&summary, "an eval summary"), (&run_log, "a run log")] {
        let refused = formation(&["report", text(&out), "--out", text(target)]);
        refused.assert_exit(2);
        refused.assert_failure_mentioning(what);
        refused.assert_failure_mentioning("report.html");
        assert!(
            !formation_report_figures(target).exists(),
            "{}",
            refused.describe()
        );
    }
    assert_eq!(kept(&summary), summary_bytes);
    assert_eq!(kept(&run_log), log_bytes);
    // A folder given as `--out` is told to name an .html file.
    let refused = formation(&["report", text(&out), "--out", text(&out)]);
    refused.assert_exit(2);
    refused.assert_failure_mentioning(&out.join("report.html").display().to_string());
    // The report still builds from the same folder.
    let html = t.path().join("report.html");
    formation(&["report", text(&out), "--out", text(&html)]).assert_success();

    // `eval --json <the scenario>`: refused before any run, the scenario kept.
    let refused = run(
        expert_eval_once(&scenario, &["--json", text(&scenario)]),
        LIMIT,
    );
    refused.assert_exit(2);
    refused.assert_failure_mentioning("is the file --scenario reads");
    assert!(
        !refused.stdout().contains("Table I"),
        "{}",
        refused.describe()
    );
    assert_eq!(std::fs::read(&scenario).expect("scenario"), before);
}

/// `formation record --out` and `formation gauge --json` never go over the credentials or the
/// scenario they read: refused before connecting or playing, exit 2, the input kept.
#[test]
fn record_and_gauge_never_overwrite_their_own_inputs() {
    let t = ProcessTest::start("promises_record_gauge", LIMIT);
    let creds = t.path().join("creds");
    formation(&["credentials", "--robots", "2", "--out", text(&creds)]).assert_success();
    let credentials = creds.join("recorder.json");
    let before = std::fs::read(&credentials).unwrap();
    let refused = formation(&[
        "record",
        "--connect",
        "tcp/127.0.0.1:9",
        "--run-id",
        "promises",
        "--credentials",
        text(&credentials),
        "--out",
        text(&credentials),
    ]);
    refused.assert_exit(2);
    if !refused.stderr().contains("not built") {
        refused.assert_failure_mentioning("is the file --credentials reads");
    }
    assert_eq!(std::fs::read(&credentials).unwrap(), before);

    let scenario = t.case1(2.0);
    let scenario_bytes = std::fs::read(&scenario).unwrap();
    let refused = formation(&[
        "gauge",
        "--scenario",
        text(&scenario),
        "--runs",
        "1",
        "--json",
        text(&scenario),
    ]);
    refused.assert_exit(2);
    refused.assert_failure_mentioning("is the file --scenario reads");
    refused.assert_failure_mentioning("response.json");
    assert_eq!(std::fs::read(&scenario).unwrap(), scenario_bytes);
}

/// The figures folder a report at `out` would get.
fn formation_report_figures(out: &Path) -> std::path::PathBuf {
    let stem = out
        .file_stem()
        .expect("stem")
        .to_string_lossy()
        .into_owned();
    out.with_file_name(format!("{stem}-figures"))
}

#[test]
fn one_team_size_evaluates_with_its_outputs_and_the_policy_is_always_evaluated() {
    let t = ProcessTest::start("promises_sizes", LIMIT);
    let scenario = t.case1(2.0);

    // `eval --robots 16 --runs 2 --save-trajectories 2 --out D`: the 16-robot team, evaluated
    // and written as any evaluation.
    let out = t.path().join("sixteen");
    let evaluated = formation(&[
        "eval",
        "--controller",
        "expert",
        "--scenario",
        text(&scenario),
        "--robots",
        "16",
        "--runs",
        "2",
        "--save-trajectories",
        "2",
        "--out",
        text(&out),
    ]);
    evaluated.assert_success();
    assert_eq!(read_json(&out.join("summary.json"))["runs"], 2);
    for index in 0..2 {
        let log = read_json(&out.join(format!("runs/run-{index:04}.json")));
        let poses = &log["trajectory"]["poses"][0];
        assert_eq!(poses.as_array().map(Vec::len), Some(16), "run {index}");
    }
    // Several sizes with --out still say how to get one.
    let refused = formation(&[
        "eval",
        "--scenario",
        text(&scenario),
        "--robots",
        "3,4",
        "--out",
        text(&t.path().join("two")),
    ]);
    refused.assert_exit(2);
    refused.assert_failure_mentioning("one team size at a time (--robots N)");
    assert!(!t.path().join("two").exists());

    // `--robots` without `--model`: the default controller is the policy, and the shipped one
    // is evaluated beside the expert.
    let table = t.path().join("scaling.json");
    let four_robots = |controller: &str| {
        let finished = formation(&[
            "eval",
            "--controller",
            controller,
            "--scenario",
            text(&scenario),
            "--robots",
            "4",
            "--runs",
            "1",
            "--json",
            text(&table),
        ]);
        finished.assert_success();
        let rows = read_json(&table)["rows"].as_array().cloned().expect("rows");
        (finished, rows)
    };
    let (scaled, rows) = four_robots("policy");
    let controllers: Vec<&str> = rows
        .iter()
        .filter_map(|r| r["controller"].as_str())
        .collect();
    assert_eq!(controllers, ["expert", "policy"], "{}", scaled.describe());
    // `--controller expert` asks for the expert alone.
    let (_, rows) = four_robots("expert");
    assert!(rows.iter().all(|r| r["controller"] == "expert"), "{rows:?}");
}

/// `formation run --record FILE` says which file it wrote, as `eval --record` does (issue 39).
#[test]
fn run_record_prints_the_file_it_wrote() {
    let t = ProcessTest::start("promises_run_record", LIMIT);
    let scenario = t.case1(1.0);
    let file = t.path().join("run.mcap");
    let mut command = t.formation_run(&scenario, &["--clock", "lockstep"]);
    command.arg("--record").arg(&file);
    let finished = run(command, LIMIT);
    finished.assert_success();
    t.assert_clean();
    assert!(file.is_file(), "{}", finished.describe());
    finished.assert_stdout_has(&format!("recorded {}", file.display()));
}
