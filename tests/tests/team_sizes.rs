//! A team size the model never saw is reported, not refused (the reliability issue's "a team
//! size the model never saw passes without a word"): `formation eval` (one size and the scaling
//! table) and `formation run` flag it on the terminal and in the JSON they write, and a team
//! smaller than every trained one gets a warning.

use std::path::{Path, PathBuf};
use std::time::Duration;

use formation_tests::{
    Finished, ProcessTest, case1_scenario, formation_run_with_model, policy_eval, read_json, run,
    write_tiny_model_with,
};

const LIMIT: Duration = Duration::from_secs(300);

/// Case 1, 2 s long, with `robots` robots.
fn scenario(dir: &Path, robots: usize) -> PathBuf {
    let case1 = case1_scenario(dir, 2.0);
    let text = std::fs::read_to_string(&case1)
        .expect("case1")
        .replace("robots = 3", &format!("robots = {robots}"));
    let path = dir.join(format!("case1-{robots}.toml"));
    std::fs::write(&path, text).expect("writing the scenario");
    path
}

/// A tiny model whose envelope records teams of 3 and 5.
fn model_of_3_and_5(dir: &Path) -> PathBuf {
    let path = dir.join("tiny-3-5.onnx");
    write_tiny_model_with(&path, 0, &["--team-sizes", "3,5"]);
    path
}

fn eval(scenario: &Path, model: &Path, json: &Path, extra: &[&str]) -> Finished {
    let mut command = policy_eval(scenario, model, json);
    command.args(extra);
    let finished = run(command, LIMIT);
    finished.assert_success();
    finished
}

#[test]
fn eval_flags_sizes_outside_the_trained_ones_and_warns_below_them() {
    let t = ProcessTest::start("team_sizes_eval", LIMIT);
    let model = model_of_3_and_5(t.path());
    let cases = [
        // One wording, scaled by how far outside the trained sizes (issue 39): 2 is 1.5x below
        // the smallest, 6 is 1.2x above the largest, 4 lies between them.
        (
            2,
            "below_trained",
            true,
            Some("warning: 2 robots is zero-shot for model"),
        ),
        (3, "trained", false, None),
        (4, "zero_shot", true, Some("note: 4 robots is zero-shot")),
        (
            6,
            "above_trained",
            true,
            Some("warning: 6 robots is zero-shot for model"),
        ),
    ];
    for (robots, fit, zero_shot, line) in cases {
        let out = t.path().join(format!("eval-{robots}.json"));
        let finished = eval(&scenario(t.path(), robots), &model, &out, &[]);
        match line {
            // On the terminal before the runs, and under the printed Table I.
            Some(line) => assert!(
                finished.stderr().contains(line) && finished.stdout().contains(line),
                "{}",
                finished.describe()
            ),
            None => assert!(
                !finished.stderr().contains("zero-shot") && !finished.stderr().contains("fewer"),
                "{}",
                finished.describe()
            ),
        }
        let written = read_json(&out);
        let entry = &written["team_size"][0];
        assert_eq!(entry["fit"], fit, "{robots} robots: {written}");
        assert_eq!(entry["zero_shot"], zero_shot, "{robots} robots");
        assert_eq!(entry["trained_team_sizes"], serde_json::json!([3, 5]));
        assert_eq!(entry["robots"], robots);
    }

    let table = t.path().join("scaling.json");
    let finished = eval(&scenario(t.path(), 3), &model, &table, &["--robots", "3,4"]);
    assert!(
        finished.stdout().contains("(zero-shot) | 4 |")
            && !finished.stdout().contains("(zero-shot) | 3 |"),
        "{}",
        finished.describe()
    );
    let rows = read_json(&table)["rows"].as_array().cloned().expect("rows");
    let policy: Vec<_> = rows
        .iter()
        .filter(|r| r["controller"] == "policy")
        .collect();
    assert_eq!(policy.len(), 2);
    assert_eq!(policy[0]["team_size"]["zero_shot"], false);
    assert_eq!(policy[1]["team_size"]["zero_shot"], true);
    assert!(
        rows.iter()
            .filter(|r| r["controller"] == "expert")
            .all(|r| r.get("team_size").is_none())
    );
}

#[test]
fn a_launch_flags_a_zero_shot_team_on_the_terminal_and_in_its_summary() {
    let t = ProcessTest::start("team_sizes_run", LIMIT);
    let model = model_of_3_and_5(t.path());
    let out = t.out();
    let finished = run(
        formation_run_with_model(&t.run, &scenario(t.path(), 4), &model, &out, &[]),
        LIMIT,
    );
    finished.assert_success();
    t.assert_clean();
    finished.assert_stderr_has("note: 4 robots is zero-shot");
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["team_size"][0]["zero_shot"], true, "{summary}");
    assert_eq!(summary["team_size"][0]["fit"], "zero_shot");
    // The launch's summary records what its model declares, as the in-process eval's does.
    let input = &summary["model_inputs"][0];
    assert_eq!(input["model"], summary["models"][0], "{summary}");
    assert!(
        input["occupancy"]["size_px"]
            .as_u64()
            .is_some_and(|n| n > 0),
        "{input}"
    );
    assert!(
        input["lidar_beams"].as_u64().is_some_and(|n| n > 0),
        "{input}"
    );
}
