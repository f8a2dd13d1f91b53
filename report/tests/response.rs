//! The response gauge's curve (`formation gauge --json`, `response*.json`) in the report: read
//! with its one definition, drawn as a figure with one line per controller and team size, and
//! listed among the inputs; a response curve alone is enough for a report.

use std::fs;

use formation_report::build_report;
use formation_schema::{ResponseBin, ResponseCurve, ResponseRow, to_json_pretty};

fn row(controller: &str, robots: usize, slopes: [f64; 4], samples: u64) -> ResponseRow {
    let edges = formation_schema::RESPONSE_BIN_EDGES;
    ResponseRow {
        controller: controller.to_owned(),
        model: (controller == "policy").then(|| "policy-0123abcd".to_owned()),
        robots,
        runs: 20,
        success_rate_10: 0.9,
        samples: 4 * samples,
        bins: slopes
            .iter()
            .enumerate()
            .map(|(i, &slope)| ResponseBin {
                label_min: edges[i],
                label_max: edges[i + 1],
                samples,
                slope: Some(slope),
                rms_error: Some(0.1),
                judged: samples >= formation_schema::MIN_JUDGED_SAMPLES,
            })
            .collect(),
    }
}

#[test]
fn a_response_curve_is_drawn_with_a_line_per_controller_and_team_size() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("gauge");
    fs::create_dir_all(&data).unwrap();
    let curve = ResponseCurve {
        scenario: "teams-generalist".into(),
        seed: 7,
        duration_s: 120.0,
        stride: 5,
        expert_gains: serde_json::json!({}),
        rows: vec![
            row("expert", 16, [0.67, 0.67, 0.47, 0.37], 2000),
            row("policy", 16, [0.05, 0.06, 0.11, 0.26], 30000),
            row("policy", 32, [0.06, 0.08, 0.11, 0.22], 100),
        ],
    };
    fs::write(data.join("response.json"), to_json_pretty(&curve).unwrap()).unwrap();
    let out = dir.path().join("report.html");
    let summary = build_report(&data, &out).expect("a report from a response curve alone");
    let html = fs::read_to_string(&out).unwrap();
    assert!(html.contains("<section id=\"response\">"), "the section");
    assert!(html.contains("Response to formation errors"));
    assert!(html.contains("response.json"), "listed among the inputs");
    let [figure] = summary.figures.as_slice() else {
        panic!("one figure: {:?}", summary.figures);
    };
    let svg = fs::read_to_string(figure).unwrap();
    for label in ["expert N = 16", "policy N = 16", "policy N = 32"] {
        assert!(svg.contains(label), "legend {label}");
    }
    // Three lines of four points each (the slope-1 reference line has two).
    let lines = svg.matches("<polyline").count();
    assert!(lines >= 4, "{lines} polylines");
}

#[test]
fn a_response_curve_of_another_format_is_refused_with_its_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("gauge");
    fs::create_dir_all(&data).unwrap();
    fs::write(
        data.join("response.json"),
        r#"{"format": "formation-scaling-table", "schema_version": 1}"#,
    )
    .unwrap();
    let err = build_report(&data, &dir.path().join("r.html")).unwrap_err();
    let message = formation_proto::errors::chain_text(&err);
    assert!(message.contains("formation response curve"), "{message}");
}
