//! The report reads what `formation eval --out` writes: run data built and serialised with
//! `formation-world`'s own types (`Trajectory`, `RunMetrics`, `summarize`), laid out as the CLI's
//! `EvalOutput` (summary keys flattened) and `RunLog`, is drawn with the writer's numbers.

use std::fs;
use std::path::Path;

use formation_proto::{Pose, WheelCmd};
use formation_world::Trajectory;
use formation_world::metrics::{MetricsConfig, RunMetrics, run_metrics, summarize};
use serde_json::{Value, json};

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
                Pose {
                    x: x + side,
                    y: 0.0,
                    theta: 0.0,
                },
                Pose {
                    x: x + 0.5 * side,
                    y: 0.866 * side,
                    theta: 0.0,
                },
            ]
        })
        .collect();
    Trajectory {
        dt,
        d_star,
        v_star: 0.7,
        edges: vec![(0, 1), (0, 2), (1, 2)],
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

/// Writes an eval output directory the way `formation eval --out` does.
fn write_eval_dir(dir: &Path, scenario: &str, runs: &[(Trajectory, bool)]) -> Vec<RunMetrics> {
    let cfg = MetricsConfig::default();
    let metrics: Vec<RunMetrics> = runs.iter().map(|(t, _)| run_metrics(t, &cfg)).collect();
    let mut summary = serde_json::to_value(summarize(&metrics)).expect("summary");
    let fields = summary.as_object_mut().expect("object");
    fields.insert("controller".into(), json!("expert"));
    fields.insert("models".into(), json!([]));
    fields.insert("scenario".into(), json!(scenario));
    fields.insert("seed".into(), json!(7));
    fields.insert(
        "per_run".into(),
        serde_json::to_value(&metrics).expect("metrics"),
    );
    fs::create_dir_all(dir.join("runs")).expect("mkdir");
    fs::write(
        dir.join("summary.json"),
        serde_json::to_vec_pretty(&summary).expect("json"),
    )
    .expect("write");
    for (index, ((trajectory, keep), m)) in runs.iter().zip(&metrics).enumerate() {
        if *keep {
            let log = json!({"index": index, "metrics": m, "trajectory": trajectory});
            fs::write(
                dir.join(format!("runs/run-{index:04}.json")),
                serde_json::to_vec(&log).expect("json"),
            )
            .expect("write");
        }
    }
    metrics
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
        run_metrics(&trajectory(25.0, 1.0, 1.0), &MetricsConfig::default()),
        run_metrics(&trajectory(25.0, 1.0, 1.0), &MetricsConfig::default()),
    ];
    metrics[1].rel_formation_error = f64::NAN;
    metrics[1].orientation_error_rad = f64::NAN;
    let mut summary = serde_json::to_value(summarize(&metrics)).expect("summary");
    summary["per_run"] = serde_json::to_value(&metrics).expect("metrics");
    assert_eq!(
        summary["per_run"][1]["rel_formation_error"],
        Value::Null,
        "serde_json writes NaN as null"
    );
    fs::write(dir.path().join("summary.json"), summary.to_string()).expect("write");
    let report =
        formation_report::build_report(dir.path(), &dir.path().join("r.html")).expect("report");
    assert_eq!(report.evaluations, 1);
}

/// A run the runtime stopped early: its log, written with the world's own `RunLog` type
/// (`complete: false`), and a summary listing it, appear in the report marked incomplete.
#[test]
fn an_incomplete_run_written_by_the_world_is_marked_in_the_report() {
    use formation_world::runlog::RunLog;
    let dir = tempfile::tempdir().expect("tempdir");
    let run_dir = dir.path().join("run");
    let trajectory = trajectory(4.2, 2.0, 0.5);
    let metrics = run_metrics(&trajectory, &MetricsConfig::default());
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
    fs::create_dir_all(run_dir.join("runs")).expect("mkdir");
    fs::write(
        run_dir.join("runs/run-0000.json"),
        serde_json::to_vec(&log).expect("json"),
    )
    .expect("write");
    // An older summary without `incomplete_runs`: the run log alone marks the run.
    let mut summary = serde_json::to_value(summarize(&[metrics])).expect("summary");
    summary["per_run"] = json!([log.metrics]);
    summary["scenario"] = json!("case1");
    fs::write(run_dir.join("summary.json"), summary.to_string()).expect("write");

    let out = dir.path().join("report.html");
    formation_report::build_report(dir.path(), &out).expect("report");
    let html = fs::read_to_string(&out).expect("html");
    assert!(
        html.contains("1 of 1 run incomplete (stopped early: interrupted by Ctrl-C)"),
        "Table I marks it"
    );
    assert!(html.contains("<span class=\"badge\">incomplete</span>"));
    assert!(html.contains("no, stopped early after 4.2 s of 60.0 s: interrupted by Ctrl-C"));
}
