//! Bad input through the `formation` command line: every case ends in a non-zero exit, a message
//! that names the cause (and the fix), and no panic.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_tests::{Finished, ProcessTest, binaries, make_fifo, repo_root, run, test_model};

const LIMIT: Duration = Duration::from_secs(240);

/// Runs `formation <args>` and checks a clean failure whose stderr contains every needle.
fn fails_cleanly(args: &[&str], env: &[(&str, &str)], needles: &[&str]) -> Finished {
    let mut command = Command::new(&binaries().cli);
    command.args(args);
    for (key, value) in env {
        command.env(key, value);
    }
    let finished = run(command, LIMIT);
    for needle in needles {
        finished.assert_failure_mentioning(needle);
    }
    finished.assert_no_panic();
    finished
}

/// The shipped scenario `scenarios/NAME.toml`, as an argument.
fn shipped_scenario(name: &str) -> String {
    repo_root()
        .join(format!("scenarios/{name}.toml"))
        .display()
        .to_string()
}

/// `formation swap --run nosuchrun --robot 0 --model MODEL`: a swap of `model` into a run that
/// does not exist.
fn swap_to(model: &str) -> Vec<&str> {
    vec![
        "swap",
        "--run",
        "nosuchrun",
        "--robot",
        "0",
        "--model",
        model,
    ]
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
    let t = ProcessTest::start("bad_scenarios", LIMIT);
    let typo = scenario_with(t.path(), "typo.toml", |t| {
        t.replace("duration_s", "duraton_s")
    });
    let negative = scenario_with(t.path(), "neg.toml", |t| {
        t.replace("d_star = 2.0", "d_star = -1.0")
    });
    let nan = scenario_with(t.path(), "nan.toml", |t| {
        t.replace("phi = 3.76", "phi = nan")
    });
    let empty = scenario_with(t.path(), "zero.toml", |t| {
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
    let t = ProcessTest::start("bad_models", LIMIT);
    let case1 = shipped_scenario("case1");
    let wrong_shape = t.path().join("wrong-shape.onnx");
    formation_tests::write_tiny_model_with(&wrong_shape, 1, &["--aux-width", "3"]);
    let garbage = t.path().join("garbage.onnx");
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
    eval(&t.path().join("missing.onnx"), &[], &["not found"]);
    // A cause that a message already names is printed once, not once per layer of the chain.
    let missing = t.path().join("missing.onnx").display().to_string();
    let nodata = t.path().join("nodata").display().to_string();
    let out = t.path().join("dagger.onnx").display().to_string();
    let scenario = shipped_scenario("collect");
    let eval_scenario = shipped_scenario("table1");
    let args = [
        "dagger",
        "--scenario",
        scenario.as_str(),
        "--eval-scenario",
        eval_scenario.as_str(),
        "--data",
        nodata.as_str(),
        "--init-model",
        missing.as_str(),
        "--out",
        out.as_str(),
    ];
    let finished = fails_cleanly(&args, &[], &["missing.onnx", "not found"]);
    assert_eq!(
        finished.stderr().matches("not found").count(),
        1,
        "{}",
        finished.describe()
    );
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
    let t = ProcessTest::start("truncated_dataset", LIMIT);
    let data = t.path().join("data");
    let data_arg = data.display().to_string();
    let mut collect = Command::new(&binaries().cli);
    collect
        .args(["collect", "--runs", "1", "--out", &data_arg, "--scenario"])
        .arg(repo_root().join("scenarios/collect.toml"));
    run(collect, LIMIT).assert_success();
    let shard = data.join("shard-000000.safetensors");
    let bytes = std::fs::read(&shard).expect("shard");
    std::fs::write(&shard, &bytes[..bytes.len() / 2]).expect("truncating");
    let out = t.path().join("m/policy.onnx").display().to_string();
    fails_cleanly(
        &["train", "--epochs", "1", "--data", &data_arg, "--out", &out],
        &[],
        &["shard-000000.safetensors"],
    );
    assert!(
        !t.path().join("m/policy.onnx").exists(),
        "no model from bad data"
    );
}

/// Issue (bounded inputs): `formation run --scenario /dev/zero` grew to 5.9 GB. A scenario that is
/// not a regular file, or is over 1 MiB, is refused by its metadata before it is read.
#[test]
fn scenarios_that_are_not_small_regular_files_are_refused_before_reading() {
    let t = ProcessTest::start("scenario_files", LIMIT);
    let big = t.path().join("big.toml");
    // Sparse: 2 MiB that take no disk space.
    std::fs::File::create(&big)
        .and_then(|f| f.set_len(2 << 20))
        .expect("a sparse file");
    let big = big.display().to_string();
    let directory = t.path().display().to_string();
    for (path, needles) in [
        (
            "/dev/zero",
            &["/dev/zero", "a character device, not a regular file"][..],
        ),
        (directory.as_str(), &["a directory, not a regular file"][..]),
        (
            big.as_str(),
            &["big.toml", "over the 1048576-byte limit"][..],
        ),
    ] {
        fails_cleanly(&["run", "--scenario", path], &[], needles);
        fails_cleanly(
            &["eval", "--controller", "expert", "--scenario", path],
            &[],
            needles,
        );
    }
}

/// Issue (bounded inputs, f32 range): `duration_s = 1e12` made a run that never ends, and
/// `d_star = 1e308` overflowed to infinity in f32. Out-of-range numbers and an oversized name are
/// refused with the field, the allowed range and the value.
#[test]
fn out_of_range_scenario_values_are_refused_with_the_field_and_the_range() {
    let t = ProcessTest::start("scenario_limits", LIMIT);
    let long_name = "n".repeat(5000);
    let cases = [
        (
            scenario_with(t.path(), "long.toml", |t| {
                t.replace("duration_s = 60.0", "duration_s = 1e12")
            }),
            vec!["duration_s", "[0.001, 3600] s", "(got 1e12)"],
        ),
        (
            scenario_with(t.path(), "far.toml", |t| {
                t.replace("d_star = 2.0", "d_star = 1e308")
            }),
            vec!["goal.d_star", "[0.01, 100] m", "(got 1e308)"],
        ),
        (
            scenario_with(t.path(), "blind.toml", |t| {
                format!("{t}\n[lidar]\nmax_range = 1e-9\n")
            }),
            vec!["lidar.max_range", "[0.1, 1000] m", "(got 1e-9)"],
        ),
        (
            scenario_with(t.path(), "beams.toml", |t| {
                format!("{t}\n[lidar]\nbeams = 4096\n")
            }),
            vec!["lidar.beams", "[8, 900]", "(got 4096)"],
        ),
        (
            scenario_with(t.path(), "name.toml", |t| {
                t.replace("name = \"case1\"", &format!("name = \"{long_name}\""))
            }),
            vec!["name", "at most 128 characters"],
        ),
    ];
    for (path, needles) in &cases {
        for args in [
            vec!["run", "--scenario", path.as_str()],
            vec![
                "eval",
                "--controller",
                "expert",
                "--scenario",
                path.as_str(),
            ],
        ] {
            let finished = fails_cleanly(&args, &[], needles);
            let echoed = finished.stdout() + &finished.stderr();
            finished.assert_holds(!echoed.contains(&long_name[..200]), "the name was echoed");
        }
    }
    let case1 = shipped_scenario("case1");
    for command in ["run", "eval"] {
        fails_cleanly(
            &[command, "--scenario", &case1, "--runs", "1000000000"],
            &[],
            &["--runs", "1 to 10000"],
        );
    }
}

/// Issue (contracts checked): `lidar.max_range` other than the model's ran to rc 0 with 0 %
/// success. The command line loads every robot's model and checks it against the scenario's LIDAR
/// before any process starts, naming the model's range and the scenario's.
#[test]
fn a_lidar_range_the_model_was_not_trained_for_is_refused_before_any_process_starts() {
    let t = ProcessTest::start("range_mismatch", LIMIT);
    let scenario = scenario_with(t.path(), "short-range.toml", |t| {
        format!("{t}\n[lidar]\nmax_range = 5.0\n")
    });
    let model = test_model().display().to_string();
    let needles = ["robot 0", "max_range of 10 m", "max_range 5 m"];

    let out = t.out();
    let out_arg = out.display().to_string();
    let finished = fails_cleanly(
        &[
            "run",
            "--run-id",
            t.run.as_str(),
            "--scenario",
            &scenario,
            "--model",
            &model,
            "--out",
            &out_arg,
        ],
        &[],
        &needles,
    );
    finished.assert_holds(
        !finished.stdout().contains("formation run") && !finished.stdout().contains("connected"),
        "nothing may be launched",
    );
    assert!(!out.exists(), "no run specs or logs may be written");
    t.assert_clean();

    for extra in [&[][..], &["--processes"][..]] {
        let mut args = vec!["eval", "--scenario", &scenario, "--model", &model];
        args.extend_from_slice(extra);
        fails_cleanly(&args, &[], &needles);
    }
}

/// Issue (bounded inputs): a directory, a FIFO or /dev/zero given as a model was reported as "not
/// found", and a 4 GB file given to `formation swap` was read whole before it was refused.
#[test]
fn a_model_that_is_not_a_small_regular_file_is_named_for_what_it_is() {
    let t = ProcessTest::start("model_files", LIMIT);
    let case1 = shipped_scenario("case1");
    let directory = t.path().display().to_string();
    let fifo = t.path().join("model.fifo");
    make_fifo(&fifo);
    // A FIFO with no writer blocks a reader for ever: it must be refused from its metadata.
    let fifo = fifo.display().to_string();
    for model in [directory.as_str(), "/dev/zero", fifo.as_str()] {
        for args in [
            vec!["eval", "--scenario", case1.as_str(), "--model", model],
            vec!["run", "--scenario", case1.as_str(), "--model", model],
            swap_to(model),
        ] {
            let finished = fails_cleanly(&args, &[], &[model, "not a regular file"]);
            finished.assert_stderr_lacks("not found");
        }
    }
    let huge = t.path().join("huge.onnx");
    // Sparse: 4 GiB that take no disk space; the refusal must come from the size, not a read.
    std::fs::File::create(&huge)
        .and_then(|f| f.set_len(4 << 30))
        .expect("a sparse file");
    let huge = huge.display().to_string();
    for args in [
        swap_to(&huge),
        vec![
            "eval",
            "--scenario",
            case1.as_str(),
            "--model",
            huge.as_str(),
        ],
    ] {
        fails_cleanly(&args, &[], &["huge.onnx", "4294967296 bytes", "64 MiB"]);
    }
}

/// A team larger than the host can start (here: more robots than the open-files limit lets the
/// world serve) is refused up front with the reason and the fix, before any process starts.
#[test]
fn a_team_too_large_for_the_hosts_limits_is_refused_before_anything_starts() {
    let t = ProcessTest::start("team_too_large", LIMIT);
    let scenario = t.path().join("swarm.toml");
    let text =
        std::fs::read_to_string(repo_root().join("scenarios/swarm32.toml")).expect("swarm32.toml");
    std::fs::write(&scenario, text).expect("scenario");
    let out = t.out();
    // 32 robots need about 1,900 descriptors in the world; allow 512, hard limit included, so
    // the launcher cannot raise it.
    let mut command = Command::new("bash");
    command
        .arg("-c")
        .arg("ulimit -Sn 512 && ulimit -Hn 512 && exec \"$@\"")
        .arg("bash")
        .arg(&binaries().cli)
        .args(["run", "--run-id", t.run.as_str(), "--scenario"])
        .arg(&scenario)
        .arg("--model")
        .arg(test_model())
        .arg("--out")
        .arg(&out);
    let finished = run(command, LIMIT);
    finished.assert_failure_mentioning("open files in the world process");
    finished.assert_failure_mentioning("limit here is 512");
    assert!(
        !finished.stdout().contains("agents connected"),
        "{}",
        finished.describe()
    );
    t.assert_clean();
}

/// Issue 10: a goal outside the model's trained d* range, a neighbour rule named wrongly and a team
/// too large for its disc are refused before anything runs, each naming the cause and the fix.
#[test]
fn teams_and_envelopes_bad_input_is_refused_with_a_clear_error() {
    let t = ProcessTest::start("teams_bad_input", LIMIT);
    let narrow = t.path().join("narrow.onnx");
    formation_tests::write_tiny_model_with(&narrow, 3, &["--d-star-range", "0.8,1.5"]);
    let narrow_arg = narrow.display().to_string();
    // case1's d* = 2 m is outside [0.8, 1.5] m.
    let case1 = shipped_scenario("case1");
    let needles = ["d* = 2 m", "[0.8, 1.5] m", "robot 0", "narrow.onnx"];
    for extra in [&[][..], &["--processes"][..]] {
        let mut args = vec!["eval", "--scenario", &case1, "--model", &narrow_arg];
        args.extend_from_slice(extra);
        fails_cleanly(&args, &[], &needles);
    }
    fails_cleanly(
        &[
            "run",
            "--run-id",
            t.run.as_str(),
            "--scenario",
            &case1,
            "--model",
            &narrow_arg,
        ],
        &[],
        &needles,
    );
    t.assert_clean();
    // Inside the range the same model is accepted.
    let inside = scenario_with(t.path(), "inside.toml", |t| {
        t.replace("d_star = 2.0", "d_star = 1.5")
            .replace("duration_s = 60.0", "duration_s = 1.0")
    });
    let mut ok = Command::new(&binaries().cli);
    ok.args(["eval", "--scenario", &inside, "--model", &narrow_arg]);
    run(ok, LIMIT).assert_success();

    let wrong_rule = scenario_with(t.path(), "rule.toml", |t| {
        format!("{t}\n[formation]\nneighbours = \"delaunay\"\n")
    });
    fails_cleanly(
        &["eval", "--controller", "expert", "--scenario", &wrong_rule],
        &[],
        &[
            "formation.neighbours",
            "\"all_pairs\", \"gabriel\"",
            "delaunay",
        ],
    );
    let crowded = scenario_with(t.path(), "crowded.toml", |t| {
        format!(
            "{}\n[init]\ndisc_radius = 3.0\n",
            t.replace("robots = 3", "robots = 200")
        )
    });
    fails_cleanly(
        &["eval", "--controller", "expert", "--scenario", &crowded],
        &[],
        &["init.disc_radius", "too small to place 200 robots"],
    );
    fails_cleanly(
        &[
            "eval",
            "--controller",
            "expert",
            "--scenario",
            &case1,
            "--robots",
            "3,1",
        ],
        &[],
        &["team size from 2 to 1024"],
    );
}
