//! `build_report` end to end on synthetic eval output: what it writes, that the page shows the
//! data it read, and its errors on bad input.

mod common;

use std::fs;
use std::path::Path;

use formation_report::{ReportError, ReportSummary, build_report};
use formation_schema::{Quantiles, ScalingRow, SchemaError, SchemaFile};

fn polyline_point_counts(svg: &str) -> Vec<usize> {
    svg.split("<polyline")
        .skip(1)
        .filter_map(|tag| {
            let start = tag.find("points=\"")? + 8;
            let end = start + tag[start..].find('"')?;
            Some(tag[start..end].split_whitespace().count())
        })
        .collect()
}

/// Quantiles of ten values that all equal `median`.
fn same_quantiles(median: f64) -> Quantiles {
    Quantiles {
        min: median,
        q1: median,
        median,
        q3: median,
        max: median,
        count: 10,
    }
}

/// A row of the scaling and ladder tables below: `controller` (a policy is model
/// `policy-1234`) on `robots` (all pairs for 3, else the Gabriel graph) over 10 runs, successful
/// at 10 % in the share `success` and at 5 % in 0.1 less, converging in `robots` seconds.
fn scaling_row(controller: &str, robots: usize, success: f64) -> ScalingRow {
    ScalingRow {
        controller: controller.into(),
        model: (controller == "policy").then(|| "policy-1234".to_owned()),
        robots,
        neighbours: if robots == 3 { "all_pairs" } else { "gabriel" }.into(),
        runs: 10,
        success_rate_5: success - 0.1,
        success_rate_10: success,
        anchor_success_rate: 1.0,
        convergence_s: Some(same_quantiles(robots as f64)),
        rel_formation_error: Some(same_quantiles(0.01)),
        max_edge_window_error: Some(same_quantiles(0.02)),
        collisions: 0,
        team_size: None,
        goal_speed: None,
        model_input: None,
    }
}

/// Writes `table` as `data/file`, the only input there, and builds the report of `data` beside
/// it (`report.html`): a report of no evaluation and the table's one figure. Returns the summary
/// and the page.
fn report_of_one_table<F: SchemaFile>(
    data: &Path,
    file: &str,
    table: &F,
) -> (ReportSummary, String) {
    common::write_file(&data.join(file), table);
    let out = data.parent().expect("parent").join("report.html");
    let summary =
        build_report(data, &out).unwrap_or_else(|e| panic!("{file} alone makes a report: {e}"));
    assert_eq!(summary.evaluations, 0);
    assert_eq!(summary.figures.len(), 1);
    let html = fs::read_to_string(&out).expect("html");
    (summary, html)
}

#[test]
fn writes_html_and_every_figure() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("demo");
    common::write_demo_dir(&data, 30.0);
    let out = dir.path().join("site/report.html");
    let summary = build_report(&data, &out).expect("report");

    assert_eq!(summary.html, out);
    assert_eq!(summary.evaluations, 4);
    assert_eq!(summary.runs_drawn, 3);
    assert_eq!((summary.loss_curves, summary.latency_profiles), (1, 1));
    // Fig. 9, three panels per case, the loss curve and the latency profile.
    assert_eq!(summary.figures.len(), 1 + 3 * 3 + 1 + 1);
    assert_eq!(summary.figures_dir, dir.path().join("site/report-figures"));
    let html = fs::read_to_string(&out).expect("html");
    for figure in &summary.figures {
        let svg = fs::read_to_string(figure).expect("svg file");
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
            "{}",
            figure.display()
        );
        let stem = figure
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .into_owned();
        assert!(
            html.contains(&format!("data-figure=\"{stem}\"")),
            "{stem} is inline in the page"
        );
    }

    // Table I: 19 of 20 runs succeed at 10 %; the paper's numbers beside ours.
    assert!(html.contains("<td>95.0 %</td>"), "success at 10 %");
    assert!(
        html.contains("<td>90.0 %</td>") && html.contains("<td>96.0 %</td>"),
        "paper row"
    );
    let summary_json: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(data.join("table1/summary.json")).expect("read"))
            .expect("json");
    let median_conv = summary_json["median_convergence_s"]
        .as_f64()
        .expect("median");
    assert!(
        html.contains(&format!("<td>{median_conv:.2} s</td>")),
        "median convergence {median_conv:.2}"
    );
    let rate5 = summary_json["success_rate_5"].as_f64().expect("rate");
    assert!(html.contains(&format!("<td>{:.1} %</td>", 100.0 * rate5)));

    // Each case's error panel: one line per edge with one point per sample (30 s at 20 Hz).
    let errors =
        fs::read_to_string(summary.figures_dir.join("case1-run0-errors.svg")).expect("svg");
    let long_lines = polyline_point_counts(&errors)
        .into_iter()
        .filter(|&n| n == 601)
        .count();
    assert_eq!(long_lines, 3 + 3, "3 edges and 3 robots");
    assert!(html.contains("constant desired orientation φ* = 3.76 rad"));
    assert!(html.contains("(cf. paper Fig. 7)"));
    assert!(html.contains("time-varying desired orientation"));

    // Self-contained: nothing is loaded from elsewhere.
    for forbidden in [" src=", "href=\"http", "url(", "@import", "@font-face"] {
        assert!(!html.contains(forbidden), "{forbidden}");
    }
}

#[test]
fn the_figures_follow_the_data() {
    let dir = tempfile::tempdir().expect("tempdir");
    common::write_demo_dir(dir.path(), 12.0);
    let first = build_report(dir.path(), &dir.path().join("a.html")).expect("report");
    let log_path = dir.path().join("case2/runs/run-0000.json");
    let mut log: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&log_path).expect("read")).expect("json");
    log["trajectory"]["poses"][100][1]["x"] = serde_json::json!(25.0);
    common::write_json(&log_path, &log);
    let second = build_report(dir.path(), &dir.path().join("b.html")).expect("report");
    let read = |s: &formation_report::ReportSummary, name: &str| {
        fs::read_to_string(s.figures_dir.join(name)).expect("svg")
    };
    // The figures that draw the changed pose change; the others stay as they were.
    for (figure, changes) in [
        ("case2-run0-trajectory.svg", true),
        ("case2-run0-errors.svg", true),
        ("case1-run0-trajectory.svg", false),
        ("case2-run0-wheels.svg", false),
    ] {
        assert_eq!(
            read(&first, figure) != read(&second, figure),
            changes,
            "{figure}"
        );
    }
}

#[test]
fn stale_figures_are_removed() {
    let dir = tempfile::tempdir().expect("tempdir");
    common::write_demo_dir(dir.path(), 6.0);
    let out = dir.path().join("r.html");
    build_report(dir.path(), &out).expect("report");
    fs::remove_dir_all(dir.path().join("case3")).expect("rm");
    let summary = build_report(dir.path(), &out).expect("report");
    let on_disk = fs::read_dir(&summary.figures_dir).expect("dir").count();
    assert_eq!(on_disk, summary.figures.len());
    assert!(!summary.figures_dir.join("case3-run0-errors.svg").exists());
}

#[test]
fn missing_and_empty_directories_are_explained() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("nowhere");
    let err = build_report(&missing, &dir.path().join("r.html")).expect_err("missing dir");
    assert!(matches!(err, ReportError::MissingInputDir { .. }), "{err}");
    assert!(err.to_string().contains("nowhere"), "{err}");

    fs::write(dir.path().join("notes.txt"), "hello").expect("write");
    let err = build_report(dir.path(), &dir.path().join("r.html")).expect_err("no summary");
    let message = err.to_string();
    assert!(
        message.starts_with("no eval or run output under"),
        "{message}"
    );
    assert!(
        message.contains("formation eval --out") && message.contains("formation demo"),
        "{message}"
    );
    assert!(
        !dir.path().join("r.html").exists(),
        "nothing written on error"
    );

    let err = build_report(&dir.path().join("notes.txt"), &dir.path().join("r.html"))
        .expect_err("a file");
    assert!(matches!(err, ReportError::NotADirectory { .. }), "{err}");
}

#[test]
fn truncated_inputs_name_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    common::write_demo_dir(dir.path(), 6.0);
    let out = dir.path().join("r.html");

    let log = dir.path().join("case1/runs/run-0000.json");
    let text = fs::read(&log).expect("read");
    fs::write(&log, &text[..text.len() / 2]).expect("truncate");
    let err = build_report(dir.path(), &out).expect_err("truncated run log");
    assert!(
        matches!(err, ReportError::Schema(SchemaError::Parse { .. })),
        "{err}"
    );
    assert!(err.to_string().contains("run-0000.json"), "{err}");
    fs::write(&log, &text).expect("restore");

    let summary = dir.path().join("table1/summary.json");
    fs::write(&summary, "{\"runs\": 3, \"success_rate_5\": 0.5").expect("truncate");
    let err = build_report(dir.path(), &out).expect_err("truncated summary");
    assert!(err.to_string().contains("table1/summary.json"), "{err}");

    fs::write(&summary, "{}").expect("empty object");
    let err = build_report(dir.path(), &out).expect_err("no Table I keys");
    assert!(err.to_string().contains("missing field"), "{err}");

    // A summary of another schema version is refused, saying which.
    let mut newer: serde_json::Value = serde_json::from_slice(
        &formation_schema::to_json(&common::summary("table1", &[common::run_metrics(1, true)]))
            .expect("json"),
    )
    .expect("json");
    newer["schema_version"] = serde_json::json!(2);
    common::write_json(&summary, &newer);
    let err = build_report(dir.path(), &out).expect_err("another version");
    assert!(
        err.to_string().contains(&format!(
            "{} is a formation evaluation summary of schema version 2; this build reads version 1",
            summary.display()
        )),
        "{err}"
    );

    common::write_file(
        &summary,
        &common::summary("table1", &[common::run_metrics(1, true)]),
    );
    fs::write(
        dir.path().join("policy-loss.csv"),
        "epoch,train_loss\n1,oops\n",
    )
    .expect("csv");
    let err = build_report(dir.path(), &out).expect_err("bad csv");
    assert!(err.to_string().contains("policy-loss.csv line 2"), "{err}");
}

#[test]
fn optional_sections_are_omitted_when_absent() {
    let dir = tempfile::tempdir().expect("tempdir");
    common::write_file(
        &dir.path().join("summary.json"),
        &common::summary(
            "table1",
            &[common::run_metrics(1, true), common::run_metrics(2, false)],
        ),
    );
    let out = dir.path().join("report.html");
    let summary = build_report(dir.path(), &out).expect("report");
    assert_eq!(summary.figures.len(), 1, "Fig. 9 only");
    let html = fs::read_to_string(&out).expect("html");
    assert!(!html.contains("id=\"training\"") && !html.contains("id=\"latency\""));
    assert!(html.contains("No run logs were found"));
    assert!(
        html.contains("<td>50.0 %</td>"),
        "1 of 2 runs succeed at 10 %"
    );
}

#[test]
fn a_scaling_table_gets_its_section_with_the_rows_and_the_figure() {
    use formation_schema::ScalingTable;
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("teams");
    let row = |controller: &str, robots: usize, success: f64| ScalingRow {
        model_input: (controller == "policy").then(|| formation_schema::ModelInput {
            model: "policy-1234".into(),
            occupancy: formation_proto::OccupancySpec::PAPER,
            lidar_beams: 900,
            lidar_max_range_m: 10.0,
            lidar_noise_std_m: None,
            trained_d_star_m: None,
        }),
        ..scaling_row(controller, robots, success)
    };
    let table = ScalingTable {
        scenario: "teams".into(),
        seed: 7,
        duration_s: 60.0,
        rows: vec![
            row("expert", 3, 1.0),
            row("policy", 3, 0.9),
            row("expert", 16, 0.98),
            row("policy", 16, 0.5),
        ],
    };
    let (summary, html) = report_of_one_table(&data, "scaling.json", &table);
    assert!(html.contains("Scaling over team sizes"));
    assert!(html.contains("<td>16</td><td>gabriel</td><td>10</td><td>88.0 %</td><td>98.0 %</td>"));
    assert!(html.contains("policy-1234"));
    assert_eq!(
        html.matches(
            "input of model policy-1234: 50 × 50 cells of 0.1 m (a fixed 5 m window), far hits \
             dropped; 900-beam 10 m LIDAR."
        )
        .count(),
        1,
        "one note per model, not per row"
    );
    let svg = fs::read_to_string(&summary.figures[0]).expect("svg");
    assert!(svg.contains("expert @ 10 %") && svg.contains("policy @ 5 %"));
}

/// A reality ladder (`formation eval --ladder PROFILE --json`) alone makes a report: a section
/// with one row per rung, controller and team size, the policy's refusal where it has no rows,
/// and a figure with a line per controller and team size, broken where a rung has no row.
#[test]
fn a_reality_ladder_gets_its_section_with_the_rows_and_the_figure() {
    use formation_schema::{LadderRung, LadderTable};
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("ladders");
    let rung =
        |name: &str, added: &[&str], rows: Vec<ScalingRow>, refused: Option<&str>| LadderRung {
            rung: name.into(),
            added: added.iter().map(|k| (*k).to_owned()).collect(),
            rows,
            policy_refused: refused.map(Into::into),
        };
    let table = LadderTable {
        profile: "turtlebot3-burger".into(),
        scenario: "table1".into(),
        seed: 7,
        duration_s: 60.0,
        rungs: vec![
            rung(
                "ideal",
                &[],
                vec![scaling_row("expert", 3, 1.0), scaling_row("policy", 3, 0.9)],
                None,
            ),
            rung(
                "lidar geometry",
                &["lidar.beams", "lidar.max_range"],
                vec![scaling_row("expert", 3, 0.8)],
                Some("the model was trained on a 900-beam LIDAR"),
            ),
            rung(
                "latency",
                &["robot.command_latency"],
                vec![scaling_row("expert", 3, 0.7), scaling_row("policy", 3, 0.6)],
                None,
            ),
        ],
    };
    let (summary, html) = report_of_one_table(&data, "ladder-burger.json", &table);
    assert!(html.contains("Reality ladders"));
    assert!(html.contains("The <code>turtlebot3-burger</code> profile on <code>table1</code>"));
    assert!(html.contains(
        "<tr><td>latency<div class=\"detail\"><code>robot.command_latency</code></div></td>\
         <td>expert</td><td>3</td><td>10</td><td>70.0 %</td><td>60.0 %</td>"
    ));
    assert!(html.contains("policy: no rows (the model was trained on a 900-beam LIDAR)"));
    assert!(html.contains("ladder-burger.json"));
    let svg = fs::read_to_string(&summary.figures[0]).expect("svg");
    assert!(svg.contains("expert N=3") && svg.contains("policy N=3"));
    assert!(svg.contains("thick: at 10 %") && svg.contains("thin: at 5 %"));
    assert!(svg.contains("lidar geometry") && svg.contains("latency"));
    // The expert's three lines (success at 10 % and 5 %, convergence) run unbroken over the
    // three rungs; the policy's are broken at the rung it could not drive, one point each side.
    let counts = polyline_point_counts(&svg);
    assert_eq!(counts.iter().filter(|&&c| c == 3).count(), 3, "{counts:?}");
    assert_eq!(counts.iter().filter(|&&c| c == 1).count(), 6, "{counts:?}");
}

/// An eval output whose writer could not write every run log (a full disk): the report builds,
/// says on the page and in its warnings which run logs are missing, and an output whose run logs
/// are all there says nothing of the kind.
#[test]
fn a_partial_eval_output_is_named_with_the_run_logs_it_lacks() {
    let dir = tempfile::tempdir().expect("tempdir");
    let metrics: Vec<_> = (0..3).map(|k| common::run_metrics(k, true)).collect();
    let mut summary = common::summary("case1", &metrics);
    summary.run_logs = vec![0, 1, 2];
    let log = |k: usize| {
        common::run_log(
            k,
            metrics[k].clone(),
            common::trajectory(common::Heading::Constant(3.76), 2.0, 25.0, k as u64),
        )
    };
    common::write_file(&dir.path().join("whole/summary.json"), &summary);
    for k in 0..3 {
        common::write_file(
            &dir.path().join(format!("whole/runs/run-{k:04}.json")),
            &log(k),
        );
    }
    summary.complete = false;
    common::write_file(&dir.path().join("partial/summary.json"), &summary);
    common::write_file(&dir.path().join("partial/runs/run-0000.json"), &log(0));

    let out = dir.path().join("report.html");
    let built = build_report(dir.path(), &out).expect("report");
    assert_eq!(built.warnings.len(), 1, "{:?}", built.warnings);
    let warning = &built.warnings[0];
    assert!(warning.contains("partial/summary.json"), "{warning}");
    assert!(warning.contains("complete: false"), "{warning}");
    assert!(
        warning.contains("2 of the 3 run logs its summary lists are missing")
            && warning.contains("run-0001.json")
            && warning.contains("run-0002.json")
            && !warning.contains("run-0000.json"),
        "{warning}"
    );
    let html = fs::read_to_string(&out).expect("html");
    assert!(html.contains("partial: partial output"), "the page says it");
    assert!(!html.contains("whole: partial output"));
}

/// A median whose rule leaves successful runs out says over how many runs it is, on the page.
#[test]
fn the_page_states_which_runs_the_convergence_median_covers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut metrics: Vec<_> = (0..7).map(|k| common::run_metrics(k, true)).collect();
    for m in &mut metrics[3..] {
        m.convergence_s_10 = None;
    }
    common::write_file(
        &dir.path().join("accel/summary.json"),
        &common::summary("accel", &metrics),
    );
    let out = dir.path().join("report.html");
    build_report(dir.path(), &out).expect("report");
    let html = fs::read_to_string(&out).expect("html");
    assert!(
        html.contains(
            "accel: the convergence median is over 3 of the 7 runs successful at 10 % (4 did not converge"
        ),
        "the page states the median's runs"
    );
}

/// The input each model declares, as the summary records it: a window that scales with d* says
/// its reference d* and its cells over the model's d* range, the paper's fixed window says its
/// size and that far hits are dropped; both in the notes under Table I and in each run's facts,
/// and nothing of the kind for a summary without them.
#[test]
fn the_page_says_what_input_each_model_was_given() {
    use formation_proto::{BeyondWindow, OccupancySpec};
    use formation_schema::ModelInput;
    let dir = tempfile::tempdir().expect("tempdir");
    let metrics: Vec<_> = (0..2).map(|k| common::run_metrics(k, true)).collect();
    let paper = ModelInput {
        model: "policy-paper".into(),
        occupancy: OccupancySpec::PAPER,
        lidar_beams: 900,
        lidar_max_range_m: 10.0,
        lidar_noise_std_m: None,
        trained_d_star_m: None,
    };
    let scaled = ModelInput {
        model: "policy-scaled".into(),
        occupancy: OccupancySpec {
            beyond: BeyondWindow::Border,
            d_star_ref_m: Some(1.5),
            ..OccupancySpec::PAPER
        },
        lidar_noise_std_m: Some(0.01),
        trained_d_star_m: Some([0.8, 2.5]),
        ..paper.clone()
    };
    for (name, input) in [
        ("fixed", Some(&paper)),
        ("scaled", Some(&scaled)),
        ("older", None),
    ] {
        let mut summary = common::summary(name, &metrics);
        summary.models = vec![input.map_or("policy-abc123".into(), |i| i.model.clone()); 3];
        summary.model_inputs = input.into_iter().cloned().collect();
        common::write_file(&dir.path().join(format!("{name}/summary.json")), &summary);
        common::write_file(
            &dir.path().join(format!("{name}/runs/run-0000.json")),
            &common::run_log(
                0,
                metrics[0].clone(),
                common::trajectory(common::Heading::Constant(3.76), 1.5, 25.0, 0),
            ),
        );
    }
    let out = dir.path().join("report.html");
    build_report(dir.path(), &out).expect("report");
    let html = fs::read_to_string(&out).expect("html");
    let fixed_text = "50 × 50 cells of 0.1 m (a fixed 5 m window), far hits dropped; 900-beam \
                      10 m LIDAR";
    let scaled_text = "50 × 50 cells of 0.1 m at d* = 1.5 m (scales with d*: 0.053-0.167 m over \
                       the model&#39;s d* range 0.8-2.5 m), far hits on the border; 900-beam 10 m \
                       LIDAR, noise 0.01 m";
    assert!(
        html.contains(&format!(
            "fixed: input of model policy-paper: {fixed_text}."
        )),
        "the fixed window under Table I: {html}"
    );
    assert!(
        html.contains(&format!(
            "scaled: input of model policy-scaled: {scaled_text}."
        )),
        "the scaled window under Table I"
    );
    assert!(html.contains(&format!("<dt>policy input</dt><dd>{fixed_text}</dd>")));
    assert!(html.contains(&format!("<dt>policy input</dt><dd>{scaled_text}</dd>")));
    assert_eq!(
        html.matches("<dt>policy input</dt>").count(),
        2,
        "none for the older summary"
    );
    assert!(!html.contains("older: input of model"));
}

/// Issue 39: `--out` naming one of the report's own inputs (a summary, a run log, a loss curve)
/// is refused before anything is read or written, and the input is left as it was; a folder
/// given as `--out` is told to name an .html file.
#[test]
fn an_out_that_names_an_input_is_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("demo");
    common::write_demo_dir(&data, 30.0);
    let case = fs::read_dir(&data)
        .expect("read demo")
        .map(|e| e.expect("entry").path())
        .find(|p| p.join("runs/run-0000.json").is_file())
        .expect("an eval with a run log");
    for (out, what) in [
        (data.join("table1/summary.json"), "eval summary"),
        (case.join("runs/run-0000.json"), "run log"),
        (data.join("policy-loss.csv"), "training loss curve"),
        (data.join("new/summary.json"), "eval summary"),
    ] {
        let before = fs::read(&out).ok();
        let err = build_report(&data, &out).expect_err("an input as --out");
        assert!(matches!(err, ReportError::OutIsInput { .. }), "{err}");
        let message = err.to_string();
        assert!(message.contains(what), "{message}");
        assert!(message.contains("report.html"), "{message}");
        assert_eq!(fs::read(&out).ok(), before, "{} was kept", out.display());
        let figures = formation_report::figures_dir_for(&out);
        assert!(!figures.exists(), "{} was made", figures.display());
    }
    assert!(!data.join("new").exists());
    // The report still builds from the same folder afterwards.
    build_report(&data, &dir.path().join("report.html")).expect("report after the refusals");

    let err = build_report(&data, &data).expect_err("a folder as --out");
    let message = err.to_string();
    assert!(
        message.contains(&data.join("report.html").display().to_string()),
        "{message}"
    );
    assert!(!message.contains("out.json"), "{message}");
}

/// The Table I row of the evaluation `name`.
fn table_row<'a>(html: &'a str, name: &str) -> &'a str {
    let start = html
        .find(&format!("<tr><td>{name}<div"))
        .unwrap_or_else(|| panic!("a Table I row for {name}"));
    &html[start..start + html[start..].find("</tr>").expect("row end")]
}

/// The paper evaluates three robots: a three-robot evaluation shows the paper's success rates
/// beside its own, a 16-robot one says the paper has three robots only, and Fig. 9 draws the
/// paper's median only when a three-robot evaluation is there to compare with it.
#[test]
fn only_a_three_robot_team_is_compared_with_the_paper() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    common::write_team_dir(&data, 16, 12.0);
    let team_only = build_report(&data, &dir.path().join("team.html")).expect("report");
    let html = fs::read_to_string(&team_only.html).expect("html");
    let row = table_row(&html, "team");
    assert!(row.contains("16 robots"), "{row}");
    assert!(row.contains("paper: 3 robots only"), "{row}");
    assert!(
        !row.contains("paper: 90 %") && !row.contains("paper: 96 %"),
        "{row}"
    );
    let fig9 = fs::read_to_string(team_only.figures_dir.join("fig9-statistics.svg")).expect("svg");
    assert!(
        !fig9.contains("paper median"),
        "no paper median for 16 robots"
    );
    assert!(
        !html.contains("the dashed line is the paper"),
        "nor in the caption"
    );

    let metrics = common::run_metrics(0, true);
    common::write_file(
        &data.join("case1/summary.json"),
        &common::summary("case1", std::slice::from_ref(&metrics)),
    );
    common::write_file(
        &data.join("case1/runs/run-0000.json"),
        &common::run_log(
            0,
            metrics,
            common::trajectory(common::Heading::Constant(3.76), 2.0, 12.0, 1),
        ),
    );
    let both = build_report(&data, &dir.path().join("both.html")).expect("report");
    let html = fs::read_to_string(&both.html).expect("html");
    let three = table_row(&html, "case1");
    assert!(three.contains("3 robots"), "{three}");
    assert!(
        three.contains("paper: 90 % at 5 %, 96 % at 10 %"),
        "{three}"
    );
    let team = table_row(&html, "team");
    assert!(
        team.contains("paper: 3 robots only") && !team.contains("paper: 90 %"),
        "{team}"
    );
    let fig9 = fs::read_to_string(both.figures_dir.join("fig9-statistics.svg")).expect("svg");
    assert!(fig9.contains("paper median"));
    assert!(
        html.contains(
            "median (of three robots: it compares with the three-robot evaluations only)"
        )
    );
}
