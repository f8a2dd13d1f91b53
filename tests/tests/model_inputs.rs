//! Every consumer follows the input a model declares (issue 22, item 3), here the report: the
//! real `formation eval --out` writes the declared input of the shipped scaled-window and
//! paper-window models into `summary.json`, and the real `formation report` says, for each,
//! what the policy was given.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_tests::{TempDir, Watchdog, binaries, case1_scenario, read_json, repo_root, run};

/// The watchdog limit: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

/// `formation eval --controller policy --runs 1 --scenario SCENARIO --model MODEL --out OUT`.
fn eval_out(scenario: &Path, model: &Path, out: &Path) {
    let mut command = Command::new(&binaries().cli);
    command
        .args(["eval", "--controller", "policy", "--runs", "1"])
        .arg("--scenario")
        .arg(scenario)
        .arg("--model")
        .arg(model)
        .arg("--out")
        .arg(out);
    run(command, LIMIT).assert_success();
}

#[test]
fn the_report_says_what_input_the_scaled_and_the_paper_window_models_were_given() {
    let _watchdog = Watchdog::arm("model_inputs_report", LIMIT);
    let dir = TempDir::new("model-inputs");
    let scenario = case1_scenario(dir.path(), 2.0);
    let evals = dir.path().join("evals");
    for name in ["scaled", "paper"] {
        let model = repo_root().join(format!("onnx/models/{name}/policy.onnx"));
        eval_out(&scenario, &model, &evals.join(name));
    }

    let scaled = read_json(&evals.join("scaled/summary.json"));
    let input = &scaled["model_inputs"][0];
    assert_eq!(input["model"], scaled["models"][0], "{scaled}");
    assert_eq!(input["occupancy"]["size_px"], 50, "{input}");
    assert_eq!(input["occupancy"]["d_star_ref_m"], 1.5, "{input}");
    assert_eq!(input["trained_d_star_m"], serde_json::json!([0.8, 2.5]));
    assert_eq!(input["lidar_beams"], 900);
    let paper = read_json(&evals.join("paper/summary.json"));
    let input = &paper["model_inputs"][0];
    assert!(input["occupancy"].get("d_star_ref_m").is_none(), "{input}");
    assert_eq!(paper["model_inputs"].as_array().map(Vec::len), Some(1));

    let html = dir.path().join("report.html");
    let mut report = Command::new(&binaries().cli);
    report.arg("report").arg(&evals).arg("--out").arg(&html);
    run(report, LIMIT).assert_success();
    let page = std::fs::read_to_string(&html).expect("the report");
    let scaled_text = "50 × 50 cells of 0.1 m at d* = 1.5 m (scales with d*: 0.053-0.167 m over \
                       the model&#39;s d* range 0.8-2.5 m), far hits on the border; 900-beam 10 m \
                       LIDAR, noise 0.03 m";
    let paper_text = "50 × 50 cells of 0.1 m (a fixed 5 m window), far hits on the border; \
                      900-beam 10 m LIDAR, no noise";
    for (name, text, id) in [
        ("scaled", scaled_text, &scaled["models"][0]),
        ("paper", paper_text, &paper["models"][0]),
    ] {
        let id = id.as_str().expect("a model id");
        assert!(
            page.contains(&format!("{name}: input of model {id}: {text}.")),
            "the note under Table I names {name}'s input"
        );
        assert!(
            page.contains(&format!("<dt>policy input</dt><dd>{text}</dd>")),
            "{name}'s run says what its policy was given"
        );
    }
}
