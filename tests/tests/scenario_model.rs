//! A scenario names its team's model (`model`, issue 37: `scenarios/turtlebot3.toml` runs the
//! TurtleBot3 model): the real `formation eval` drives the scenario's model where the command line
//! names none, `--model` still overrides it, and a scenario whose model is missing is refused by
//! `eval` and `run` with the key and the path named, before anything runs.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use formation_tests::{ProcessTest, binaries, case1_scenario, repo_root, run, shipped_model};

/// The watchdog limit: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

/// Case 1 shortened to 2 s, in `dir`, naming `model` as its team's model.
fn case1_with_model(dir: &Path, model: &str) -> PathBuf {
    let short = case1_scenario(dir, 2.0);
    let text = std::fs::read_to_string(&short).expect("the short case 1");
    let path = dir.join("case1-with-model.toml");
    std::fs::write(&path, format!("model = {model:?}\n{text}")).expect("writing the scenario");
    path
}

/// `formation eval --controller policy --runs 1 --scenario SCENARIO`.
fn eval_policy_once(scenario: &Path) -> Command {
    let mut command = Command::new(&binaries().cli);
    let args = ["eval", "--controller", "policy", "--runs", "1"];
    command.args(args).arg("--scenario").arg(scenario);
    command
}

/// The model ids `formation eval --runs 1 --scenario SCENARIO [--model MODEL]` drove, from the
/// `summary.json` it wrote into `out`.
fn models_driven(scenario: &Path, model: Option<&Path>, out: &Path) -> Vec<String> {
    let mut command = eval_policy_once(scenario);
    command.arg("--out").arg(out);
    if let Some(model) = model {
        command.arg("--model").arg(model);
    }
    run(command, LIMIT).assert_success();
    formation_schema::read_summary(&out.join("summary.json"))
        .expect("the summary eval wrote")
        .models
}

#[test]
fn eval_drives_the_scenarios_model_unless_the_command_line_names_one() {
    let t = ProcessTest::start("scenario_model_eval", LIMIT);
    // A model beside the scenario, named by a path relative to the scenario file (with the
    // same file name, so that its model id is the same as the one given by --model).
    std::fs::create_dir_all(t.path().join("models")).expect("models folder");
    let scaled = repo_root().join("onnx/models/scaled/policy.onnx");
    std::fs::copy(&scaled, t.path().join("models/policy.onnx")).expect("copying the model");
    let scenario = case1_with_model(t.path(), "models/policy.onnx");

    let named = models_driven(&scenario, None, &t.path().join("named"));
    let given = models_driven(&scenario, Some(&scaled), &t.path().join("given"));
    assert_eq!(
        named, given,
        "without --model, eval drives the scenario's model (the scaled one)"
    );
    let shipped = shipped_model();
    let overridden = models_driven(&scenario, Some(&shipped), &t.path().join("overridden"));
    assert_ne!(
        overridden, named,
        "--model overrides the scenario's model: {overridden:?}"
    );
}

#[test]
fn a_scenario_whose_model_is_missing_is_refused_with_the_key_named() {
    let t = ProcessTest::start("scenario_model_missing", LIMIT);
    let scenario = case1_with_model(t.path(), "models/absent.onnx");
    let missing = t.path().join("models/absent.onnx");
    run(eval_policy_once(&scenario), LIMIT)
        .assert_failure_mentioning("`model` key")
        .assert_failure_mentioning(&missing.display().to_string())
        .assert_no_panic();

    let mut launch = Command::new(&binaries().cli);
    launch
        .args(["run", "--runs", "1", "--scenario"])
        .arg(&scenario)
        .arg("--out")
        .arg(t.out());
    run(launch, LIMIT)
        .assert_failure_mentioning(&missing.display().to_string())
        .assert_no_panic();
    assert!(!t.out().exists(), "a refused run writes nothing");
}
