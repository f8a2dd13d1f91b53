//! Bad input through the `formation` command line: every case ends in a non-zero exit, a message
//! that names the cause (and the fix), and no panic.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_tests::{TempDir, Watchdog, binaries, repo_root, run, test_model};

const LIMIT: Duration = Duration::from_secs(240);

/// Runs `formation <args>` and checks a clean failure whose stderr contains every needle.
fn fails_cleanly(args: &[&str], env: &[(&str, &str)], needles: &[&str]) {
    let mut command = Command::new(&binaries().cli);
    command.args(args);
    for (key, value) in env {
        command.env(key, value);
    }
    let finished = run(command, LIMIT);
    for needle in needles {
        finished.assert_failure_mentioning(needle);
    }
    assert_ne!(
        finished.output.status.code(),
        Some(101),
        "a panic is not an error message\n{}",
        finished.describe()
    );
    assert!(
        !finished.stderr().contains("panicked"),
        "{}",
        finished.describe()
    );
}

/// case1.toml with `edit` applied to its text, written to `dir/name`.
fn scenario_with(dir: &Path, name: &str, edit: impl Fn(&str) -> String) -> String {
    let text = std::fs::read_to_string(repo_root().join("scenarios/case1.toml")).expect("case1");
    let path = dir.join(name);
    std::fs::write(&path, edit(&text)).expect("writing the scenario");
    path.display().to_string()
}

#[test]
fn bad_scenarios_name_the_field_or_file() {
    let _watchdog = Watchdog::arm("bad_scenarios", LIMIT);
    let dir = TempDir::new("badscen");
    let typo = scenario_with(dir.path(), "typo.toml", |t| {
        t.replace("duration_s", "duraton_s")
    });
    let negative = scenario_with(dir.path(), "neg.toml", |t| {
        t.replace("d_star = 2.0", "d_star = -1.0")
    });
    let nan = scenario_with(dir.path(), "nan.toml", |t| {
        t.replace("phi = 3.76", "phi = nan")
    });
    let empty = scenario_with(dir.path(), "zero.toml", |t| {
        t.replace("robots = 3", "robots = 0")
    });
    for (path, needle) in [
        (&typo, "duraton_s"),
        (&negative, "d_star"),
        (&nan, "phi"),
        (&empty, "robots"),
        (
            &"/no/such/scenario.toml".to_owned(),
            "/no/such/scenario.toml",
        ),
    ] {
        fails_cleanly(
            &["eval", "--controller", "expert", "--scenario", path],
            &[],
            &[needle],
        );
    }
}

#[test]
fn bad_models_and_a_missing_runtime_library_are_explained() {
    let _watchdog = Watchdog::arm("bad_models", LIMIT);
    let dir = TempDir::new("badmodel");
    let case1 = repo_root()
        .join("scenarios/case1.toml")
        .display()
        .to_string();
    let wrong_shape = dir.path().join("wrong-shape.onnx");
    formation_tests::write_tiny_model_with(&wrong_shape, 1, &["--aux-width", "3"]);
    let garbage = dir.path().join("garbage.onnx");
    std::fs::write(&garbage, b"not a model").expect("writing");
    let eval = |model: &Path, env: &[(&str, &str)], needles: &[&str]| {
        let model = model.display().to_string();
        let args = [
            "eval",
            "--scenario",
            case1.as_str(),
            "--model",
            model.as_str(),
        ];
        fails_cleanly(&args, env, needles);
    };
    eval(&dir.path().join("missing.onnx"), &[], &["not found"]);
    eval(&wrong_shape, &[], &["aux"]);
    eval(&garbage, &[], &["garbage.onnx"]);
    eval(
        test_model(),
        &[("ORT_DYLIB_PATH", "/no/such/libonnxruntime.so")],
        &["/no/such/libonnxruntime.so", "ORT_DYLIB_PATH"],
    );
}

#[test]
fn a_truncated_dataset_is_refused_before_training() {
    let _watchdog = Watchdog::arm("truncated_dataset", LIMIT);
    let dir = TempDir::new("truncated");
    let data = dir.path().join("data");
    let data_arg = data.display().to_string();
    let mut collect = Command::new(&binaries().cli);
    collect
        .args(["collect", "--runs", "1", "--out", &data_arg, "--scenario"])
        .arg(repo_root().join("scenarios/collect.toml"));
    run(collect, LIMIT).assert_success();
    let shard = data.join("shard-000000.safetensors");
    let bytes = std::fs::read(&shard).expect("shard");
    std::fs::write(&shard, &bytes[..bytes.len() / 2]).expect("truncating");
    let out = dir.path().join("m/policy.onnx").display().to_string();
    fails_cleanly(
        &["train", "--epochs", "1", "--data", &data_arg, "--out", &out],
        &[],
        &["shard-000000.safetensors"],
    );
    assert!(
        !dir.path().join("m/policy.onnx").exists(),
        "no model from bad data"
    );
}
