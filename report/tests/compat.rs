//! The report reads what the writers write: run data computed by `formation-world`
//! (`run_metrics`, `summarize`) and written as the writers do, with the one definition of each
//! file in `formation-schema` (`EvalOutput` for `summary.json`, `RunLog` through the world's
//! `write_json_atomic`, `LatencyProfile` for `profile.json`), is drawn with the writer's numbers.
//! No JSON is built by hand, so a field renamed on the writer's side breaks this test.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use formation_proto::{Pose, WheelCmd};
use formation_schema::{EvalOutput, IncompleteRun, LatencyProfile, RunLog, StageStats};
use formation_world::Trajectory;
use formation_world::metrics::{MetricsConfig, RunMetrics, run_metrics, summarize};
use formation_world::runlog::{log_paths, write_json_atomic};

/// Three robots settling into a triangle of side `d_star` while driving along +x.
fn trajectory(seconds: f64, d_star: f64, spread: f64) -> Trajectory {
    let dt = 0.05;
    let ticks = (seconds / dt).round() as usize;
    let times: Vec<f64> = (0..=ticks).map(|k| k as f64 * dt).collect();
    let poses = times
        .iter()
        .map(|&t| {
            let side = d_star * (1.0 + spread * (-t / 4.0).exp());
            let x = 0.7 * t;
            vec![
                Pose {
                    x,
                    y: 0.0,
                    theta: 0.0,
                },
                Pose::new(x + side, 0.0, 0.0),
                Pose::new(x + 0.5 * side, 0.866 * side, 0.0),
            ]
        })
        .collect();
    Trajectory {
        dt,
        d_star,
        v_star: 0.7,
        edges: vec![(0, 1), (0, 2), (1, 2)],
        neighbours: formation_proto::NeighbourRule::AllPairs,
        phi_star: vec![0.0; times.len()],
        commands: vec![
            vec![
                WheelCmd {
                    left: 0.7,
                    right: 0.7
                };
                3
            ];
            ticks
        ],
        times,
        poses,
        collisions: vec![(3, 0, 1)],
    }
}

/// Writes an eval output directory the way `formation eval --out` does: the summary through
/// `formation_schema`, the run logs through the world's writer, both of the writers' own types.
fn write_eval_dir(dir: &Path, scenario: &str, runs: &[(Trajectory, bool)]) -> Vec<RunMetrics> {
    let cfg = MetricsConfig::default();
    let metrics: Vec<RunMetrics> = runs
        .iter()
        .map(|(t, _)| run_metrics(t, t.commands.len() as u64, &cfg))
        .collect();
    write_summary(dir, &eval_output(scenario, &metrics));
    for (index, ((trajectory, keep), m)) in runs.iter().zip(&metrics).enumerate() {
        if *keep {
            let log = RunLog {
                index,
                metrics: m.clone(),
                trajectory: trajectory.clone(),
                clock: "in-process".into(),
                models: Vec::new(),
                complete: true,
                stop_reason: None,
                planned_ticks: Some(trajectory.commands.len() as u64),
            };
            write_json_atomic(&log_paths(dir, index).0, &log).expect("run log");
        }
    }
    metrics
}

/// The summary `formation eval` writes over these runs.
fn eval_output(scenario: &str, per_run: &[RunMetrics]) -> EvalOutput {
    EvalOutput::of_runs(
        "expert",
        Vec::new(),
        scenario,
        Some(7),
        summarize(per_run),
        per_run.to_vec(),
    )
}

fn write_summary(dir: &Path, summary: &EvalOutput) {
    fs::create_dir_all(dir).expect("mkdir");
    fs::write(
        dir.join("summary.json"),
        formation_schema::to_json_pretty(summary).expect("json"),
    )
    .expect("write");
}

#[test]
fn report_reads_what_the_writer_types_serialise() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("out");
    let runs: Vec<(Trajectory, bool)> = (0..6)
        .map(|k| {
            (
                trajectory(30.0, 1.0 + 0.1 * k as f64, if k == 5 { 0.0 } else { 2.0 }),
                k == 0,
            )
        })
        .collect();
    let metrics = write_eval_dir(&data.join("table"), "table1", &runs);
    write_eval_dir(
        &data.join("case1"),
        "case1",
        &[(trajectory(12.0, 2.0, 0.5), true)],
    );

    let out = dir.path().join("report.html");
    let summary = formation_report::build_report(&data, &out).expect("report");
    assert_eq!((summary.evaluations, summary.runs_drawn), (2, 2));
    let html = fs::read_to_string(&out).expect("html");

    let expected = summarize(&metrics);
    assert!(html.contains(&format!(
        "<td>{:.1} %</td>",
        100.0 * expected.success_rate_10
    )));
    let median = expected.median_convergence_s.expect("some run converges");
    assert!(
        html.contains(&format!("<td>{median:.2} s</td>")),
        "median convergence {median:.2}"
    );
    assert_eq!(expected.collisions, 6, "every table run has a collision");
    assert!(
        html.contains("<td>6</td></tr>"),
        "runs with collisions, the row's last cell"
    );

    // One point per sample on each edge's error line (601 samples over 30 s).
    let errors =
        fs::read_to_string(summary.figures_dir.join("table-run0-errors.svg")).expect("svg");
    let counts: Vec<usize> = errors
        .split("<polyline")
        .skip(1)
        .filter_map(|tag| {
            let start = tag.find("points=\"")? + 8;
            Some(
                tag[start..start + tag[start..].find('"')?]
                    .split_whitespace()
                    .count(),
            )
        })
        .collect();
    assert_eq!(
        counts.iter().filter(|&&n| n == 601).count(),
        6,
        "3 edges and 3 robots: {counts:?}"
    );
    // The collision recorded at sample 3 is marked on the trajectory.
    let paths =
        fs::read_to_string(summary.figures_dir.join("table-run0-trajectory.svg")).expect("svg");
    assert!(paths.contains("collision"));
}

#[test]
fn non_finite_metrics_written_as_null_are_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut metrics = vec![
        run_metrics(&trajectory(25.0, 1.0, 1.0), 500, &MetricsConfig::default()),
        run_metrics(&trajectory(25.0, 1.0, 1.0), 500, &MetricsConfig::default()),
    ];
    metrics[1].rel_formation_error = f64::NAN;
    metrics[1].orientation_error_rad = f64::NAN;
    let summary = eval_output("table1", &metrics);
    let json: serde_json::Value =
        serde_json::from_slice(&formation_schema::to_json(&summary).expect("json")).expect("json");
    assert_eq!(
        json["per_run"][1]["rel_formation_error"],
        serde_json::Value::Null,
        "serde_json writes NaN as null"
    );
    write_summary(dir.path(), &summary);
    let report =
        formation_report::build_report(dir.path(), &dir.path().join("r.html")).expect("report");
    assert_eq!(report.evaluations, 1);
}

/// A run the runtime stopped early: its log, written by the world's writer (`complete: false`),
/// appears in the report marked incomplete, whether or not the summary lists it.
#[test]
fn an_incomplete_run_written_by_the_world_is_marked_in_the_report() {
    for listed in [false, true] {
        let dir = tempfile::tempdir().expect("tempdir");
        let run_dir = dir.path().join("run");
        let trajectory = trajectory(4.2, 2.0, 0.5);
        let metrics = run_metrics(&trajectory, 1200, &MetricsConfig::default());
        let log = RunLog {
            index: 0,
            metrics: metrics.clone(),
            trajectory,
            clock: "realtime".into(),
            models: vec!["m-1".into(); 3],
            complete: false,
            stop_reason: Some("interrupted by Ctrl-C".into()),
            planned_ticks: Some(1200),
        };
        write_json_atomic(&log_paths(&run_dir, 0).0, &log).expect("run log");
        let mut summary = eval_output("case1", &[metrics]);
        if listed {
            summary.incomplete_runs = vec![IncompleteRun {
                index: 0,
                ticks: log.ticks(),
                planned_ticks: log.planned_ticks,
                stop_reason: log.stop_reason.clone(),
            }];
        }
        write_summary(&run_dir, &summary);

        let out = dir.path().join("report.html");
        formation_report::build_report(dir.path(), &out).expect("report");
        let html = fs::read_to_string(&out).expect("html");
        assert!(
            html.contains("1 of 1 run incomplete (stopped early: interrupted by Ctrl-C)"),
            "Table I marks it (listed in the summary: {listed})"
        );
        assert!(html.contains("<span class=\"badge\">incomplete</span>"));
        assert!(html.contains("no, stopped early after 4.2 s of 60.0 s: interrupted by Ctrl-C"));
    }
}

/// A latency profile of the writer's type is drawn with its numbers.
#[test]
fn a_profile_written_by_the_runtime_is_drawn() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("out");
    write_eval_dir(&data, "case1", &[(trajectory(6.0, 2.0, 0.5), false)]);
    let stage = |p50_us: f64| StageStats {
        count: 1200,
        p50_us,
        p90_us: 1.5 * p50_us,
        p99_us: 2.0 * p50_us,
        max_us: 9.0 * p50_us,
        histogram: vec![(1024.0, 1200)],
    };
    let stages = BTreeMap::from([
        ("round_trip".to_owned(), stage(900.0)),
        ("inference".to_owned(), stage(700.0)),
        ("tick".to_owned(), stage(50_000.0)),
    ]);
    let profile = LatencyProfile {
        runs: 2,
        clock: "lockstep".into(),
        used_commands: 1200,
        braked: BTreeMap::from([("missing".to_owned(), 3)]),
        braked_per_robot: vec![BTreeMap::from([("missing".to_owned(), 3)])],
        stages: stages.clone(),
        per_agent: vec![stages],
        inference_paper_ms: 2.1,
    };
    fs::write(
        data.join("profile.json"),
        formation_schema::to_json_pretty(&profile).expect("json"),
    )
    .expect("write");
    let out = dir.path().join("report.html");
    let summary = formation_report::build_report(&data, &out).expect("report");
    assert_eq!(summary.latency_profiles, 1);
    let html = fs::read_to_string(&out).expect("html");
    assert!(
        html.contains("2 runs, 1200 commands used, braked by the watchdog: missing 3"),
        "the caption shows the profile's counts"
    );
}
