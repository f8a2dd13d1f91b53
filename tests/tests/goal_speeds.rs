//! A v* the model was not trained at is reported, not refused (the reliability issue's "a v*
//! outside the trained ones gets no word at all"): `formation eval` marks it on the terminal
//! before the runs, under the printed Table I and in the JSON it writes, in the team sizes'
//! wording scaled by how far from the model's `formation.v_train` the run is; at the trained v*
//! nothing is said and the JSON has no `goal_speed` key. `formation run` says it too, on the
//! terminal and in its `summary.json`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use formation_tests::{
    ProcessTest, case1_scenario, formation_run_with_model, policy_eval, read_json, run,
    write_tiny_model_with,
};

const LIMIT: Duration = Duration::from_secs(300);

/// Case 1, 2 s long, at goal speed `v_star`.
fn scenario(dir: &Path, v_star: &str) -> PathBuf {
    let case1 = case1_scenario(dir, 2.0);
    let text = std::fs::read_to_string(&case1).expect("case1");
    assert!(text.contains("v_star = 0.7"), "case 1 moved: {text}");
    let path = dir.join(format!("case1-v{v_star}.toml"));
    std::fs::write(
        &path,
        text.replace("v_star = 0.7", &format!("v_star = {v_star}")),
    )
    .expect("writing the scenario");
    path
}

#[test]
fn eval_marks_a_goal_speed_off_the_models_trained_one() {
    let t = ProcessTest::start("goal_speeds_eval", LIMIT);
    // The test model is trained at v* = 0.7 m/s (`formation.v_train`).
    let model = t.path().join("tiny.onnx");
    write_tiny_model_with(&model, 0, &[]);
    let cases = [
        // 0.4 is 1.75x slower than 0.7: far outside, the case.
        (
            "0.4",
            Some((
                "slower",
                "warning: v* = 0.4 m/s, model",
                "far outside its trained v* (1.75x slower): its figures are zero-shot",
            )),
        ),
        // 0.75 is 1.07x faster: a note.
        (
            "0.75",
            Some((
                "faster",
                "note: v* = 0.75 m/s, model",
                "(1.07x faster); its commands are scaled by v*/v_train",
            )),
        ),
        ("0.7", None),
    ];
    for (v_star, mark) in cases {
        let out = t.path().join(format!("eval-{v_star}.json"));
        let finished = run(
            policy_eval(&scenario(t.path(), v_star), &model, &out),
            LIMIT,
        );
        finished.assert_success();
        let written = read_json(&out);
        match mark {
            Some((fit, start, rest)) => {
                // On the terminal before the runs, and under the printed Table I.
                for text in [finished.stderr(), finished.stdout()] {
                    let line = text
                        .lines()
                        .find(|l| l.contains(start))
                        .unwrap_or_else(|| panic!("no v* mark: {}", finished.describe()));
                    assert!(line.contains(rest), "{line}");
                }
                let entry = &written["goal_speed"][0];
                assert_eq!(entry["fit"], fit, "{written}");
                assert_eq!(entry["trained_v_star"], 0.7);
                assert_eq!(entry["v_star"], v_star.parse::<f64>().unwrap());
                let factor = entry["factor"].as_f64().expect("factor");
                assert!(
                    (factor - v_star.parse::<f64>().unwrap() / 0.7).abs() < 1e-12,
                    "{entry}"
                );
            }
            None => {
                assert!(
                    !finished.stderr().contains("v* = ") && !finished.stdout().contains("v* = "),
                    "{}",
                    finished.describe()
                );
                assert!(written.get("goal_speed").is_none(), "{written}");
            }
        }
    }
}

#[test]
fn a_launch_marks_a_goal_speed_off_the_trained_one_on_the_terminal_and_in_its_summary() {
    let t = ProcessTest::start("goal_speeds_run", LIMIT);
    let model = t.path().join("tiny.onnx");
    write_tiny_model_with(&model, 0, &[]);
    let out = t.out();
    let finished = run(
        formation_run_with_model(&t.run, &scenario(t.path(), "0.4"), &model, &out, &[]),
        LIMIT,
    );
    finished.assert_success();
    t.assert_clean();
    finished.assert_stderr_has("far outside its trained v* (1.75x slower)");
    let summary = read_json(&out.join("summary.json"));
    let entry = &summary["goal_speed"][0];
    assert_eq!(entry["model"], summary["models"][0], "{summary}");
    assert_eq!(entry["fit"], "slower", "{summary}");
    assert_eq!(entry["v_star"], 0.4);
}
