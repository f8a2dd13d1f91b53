//! Every consumer follows the input a model declares (issue 22, item 3), here the report: the
//! real `formation eval --out` writes the declared input of the shipped scaled-window and
//! paper-window models into `summary.json`, and the real `formation report` says, for each,
//! what the policy was given.

use std::path::Path;
use std::time::Duration;

use formation_tests::{ProcessTest, policy_eval_once, repo_root, report_command, run};

/// The watchdog limit: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

/// `formation eval --controller policy --runs 1 --scenario SCENARIO --model MODEL --out OUT`.
fn eval_out(scenario: &Path, model: &Path, out: &Path) {
    let mut command = policy_eval_once(scenario, model);
    command.arg("--out").arg(out);
    run(command, LIMIT).assert_success();
}

#[test]
fn the_report_says_what_input_the_scaled_and_the_paper_window_models_were_given() {
    let t = ProcessTest::start("model_inputs_report", LIMIT);
    let scenario = t.case1(2.0);
    let evals = t.path().join("evals");
    for name in ["scaled", "paper"] {
        let model = repo_root().join(format!("onnx/models/{name}/policy.onnx"));
        eval_out(&scenario, &model, &evals.join(name));
    }
    let html = t.path().join("report.html");
    run(report_command(&evals, &html), LIMIT).assert_success();
    let page = std::fs::read_to_string(&html).expect("the report");

    for (name, scales, says) in [
        ("scaled", true, "scales with d*"),
        ("paper", false, "fixed"),
    ] {
        let summary = formation_schema::read_summary(&evals.join(name).join("summary.json"))
            .expect("the summary eval wrote");
        let [input] = summary.model_inputs.as_slice() else {
            panic!("{name}: one model, one declared input: {summary:?}");
        };
        assert_eq!(input.model, summary.models[0]);
        assert_eq!(
            input.occupancy.scales_with_d_star(),
            scales,
            "{name}: {input:?}"
        );
        assert_eq!(
            (input.occupancy.size_px, input.lidar_beams),
            (50, 900),
            "{name}: the shipped models take the paper's image and LIDAR"
        );
        let text = input.describe().replace('\'', "&#39;");
        assert!(text.contains(says), "{name}: {text}");
        assert!(
            page.contains(&format!("{name}: input of model {}: {text}.", input.model)),
            "the note under Table I says {name}'s input: {text}"
        );
        assert!(
            page.contains(&format!("<dt>policy input</dt><dd>{text}</dd>")),
            "{name}'s run says what its policy was given: {text}"
        );
    }
}
