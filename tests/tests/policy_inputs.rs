//! A model that takes a tensor beside its image (issue 34) drives as every other model does:
//! the scan's ranges (`formation.ranges`) and the neighbours its robot detects in its own scan
//! (`formation.neighbours`), each across processes in lockstep bit for bit as in-process,
//! recorded and replayed bit for bit, and a replay with a model that does not take the input
//! diverges.

use std::path::{Path, PathBuf};
use std::time::Duration;

use formation_onnx::OnnxPolicy;
use formation_proto::PolicyIo;
use formation_tests::{
    ProcessTest, assert_lockstep_equals_in_process, eval_recorded, read_json, replay,
    write_tiny_model_with,
};
use formation_world::Scenario;

/// The watchdog limit: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(240);

/// One input beside the image: the tiny model's flags that give it, and what its metadata then
/// declares.
struct Input {
    name: &'static str,
    /// The two tests' names, as `ProcessTest::start` takes them.
    tests: [&'static str; 2],
    flags: [&'static str; 2],
    declared: fn(&PolicyIo) -> Option<String>,
    expected: &'static str,
}

const RANGES: Input = Input {
    name: "ranges",
    tests: ["ranges_lockstep", "ranges_replay"],
    flags: ["--ranges-sectors", "100"],
    declared: |io| io.ranges.map(|r| r.to_string()),
    expected: "sectors=100,clip=3",
};

const NEIGHBOURS: Input = Input {
    name: "neighbours",
    tests: ["neighbours_lockstep", "neighbours_replay"],
    flags: ["--neighbour-slots", "4"],
    declared: |io| io.neighbours.map(|n| n.to_string()),
    expected: "slots=4,threshold=1.3,nearest=2",
};

/// A tiny model (seeded random weights) that takes `input` and answers a formation velocity.
fn model_taking(input: &Input, dir: &Path) -> PathBuf {
    let path = dir.join(format!("{}.onnx", input.name));
    let [flag, value] = input.flags;
    write_tiny_model_with(&path, 5, &["--output", "formation_velocity", flag, value]);
    path
}

fn lockstep_is_bit_identical_to_in_process(input: &Input) {
    let t = ProcessTest::start(input.tests[0], LIMIT);
    let model = model_taking(input, t.path());
    let io = OnnxPolicy::load(&model)
        .expect("the model loads")
        .metadata()
        .io();
    assert_eq!((input.declared)(&io).as_deref(), Some(input.expected));
    let scenario = Scenario::from_path(&t.case1(4.0)).expect("scenario");
    // 4 s at 20 Hz.
    assert_lockstep_equals_in_process(&scenario, &model, 81);
}

fn replays_bit_identical_and_a_model_without_it_diverges(input: &Input) {
    let t = ProcessTest::start(input.tests[1], LIMIT);
    let model = model_taking(input, t.path());
    let scenario = t.case1(5.0);
    let record = t.path().join("rec");
    std::fs::create_dir(&record).expect("record folder");
    eval_recorded(
        &[
            "--scenario",
            scenario.to_str().expect("utf-8"),
            "--model",
            model.to_str().expect("utf-8"),
        ],
        &record,
        &t.path().join("out"),
    )
    .assert_success();
    let file = record.join("run-0000.mcap");

    let json = t.path().join("same.json");
    replay(&file, &[], &json).assert_success();
    let report = read_json(&json);
    assert_eq!(report["diverged"], false, "{report}");
    for row in report["robots"].as_array().expect("robots") {
        assert!(row["compared"].as_u64().expect("compared") >= 90, "{row}");
        assert_eq!(row["differing"], 0, "{row}");
    }

    // A model without the input answers otherwise: the input reached this one.
    let plain = t.path().join("plain.onnx");
    write_tiny_model_with(&plain, 5, &["--output", "formation_velocity"]);
    let json = t.path().join("plain.json");
    let other = replay(&file, &["--model", plain.to_str().expect("utf-8")], &json);
    other.assert_exit(1);
    assert_eq!(read_json(&json)["diverged"], true);
}

#[test]
fn a_ranges_team_in_lockstep_over_processes_is_bit_identical_to_in_process() {
    lockstep_is_bit_identical_to_in_process(&RANGES);
}

#[test]
fn a_ranges_run_replays_bit_identical_and_a_model_without_ranges_diverges() {
    replays_bit_identical_and_a_model_without_it_diverges(&RANGES);
}

#[test]
fn a_neighbours_team_in_lockstep_over_processes_is_bit_identical_to_in_process() {
    lockstep_is_bit_identical_to_in_process(&NEIGHBOURS);
}

#[test]
fn a_neighbours_run_replays_bit_identical_and_a_model_without_neighbours_diverges() {
    replays_bit_identical_and_a_model_without_it_diverges(&NEIGHBOURS);
}
