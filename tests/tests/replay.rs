//! Issue 24's acceptance tests of `formation replay`: a recorded case-1 run (in-process, and
//! lockstep over processes) replayed with its own model gives every command back bit for bit and
//! exits 0; so does a run whose model was swapped mid-run, each tick with the model active then
//! (the swapped-in model stored in the recording by the world, so no flag is needed);
//! another model, or a renderer changed by one cell, is reported as a divergence with exit 1; a
//! file that is not MCAP, a truncated one and a missing model are each a clear error (exit 2).
//! Real ONNX Runtime, real processes, the real `formation` binary.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use formation_cli::replay::{ReplayOptions, replay_recording};
use formation_onnx::contract::SensorContract;
use formation_proto::{LidarSpec, PolicyInput, PolicyIo};
use formation_robot_agent::decision::{DecisionError, PolicyBackend};
use formation_robot_agent::pilot::{OnnxPilot, OnnxPilots};
use formation_runtime::agent::{BoxError, PilotMaker};
use formation_tests::{
    LiveProcess, ProcessTest, await_connected, binaries, case1_scenario, eval_recorded,
    image_model, mcap_readers, read_json, record_case1_over_processes, replay, repo_root, run,
    shipped_model, test_model, write_tiny_model,
};
use serde_json::Value;

const LIMIT: Duration = Duration::from_secs(300);

/// Case 1 for 10 s with the shipped model, recorded in-process; returns the recording.
fn record_case1(dir: &Path) -> PathBuf {
    record_case1_with(dir, &shipped_model())
}

/// [`record_case1`] with `model` on every robot.
fn record_case1_with(dir: &Path, model: &Path) -> PathBuf {
    let scenario = case1_scenario(dir, 10.0);
    let record = dir.join("rec");
    std::fs::create_dir(&record).unwrap();
    eval_recorded(
        &[
            "--scenario",
            scenario.to_str().unwrap(),
            "--model",
            model.to_str().unwrap(),
        ],
        &record,
        &dir.join("out"),
    )
    .assert_success();
    record.join("run-0000.mcap")
}

/// The report says nothing diverged, with at least `min_compared` fresh steps compared per robot.
fn assert_identical_over(report: &Value, robots: usize, min_compared: u64) {
    assert_eq!(report["format"], "formation-replay", "{report}");
    assert_eq!(report["schema_version"], 1, "{report}");
    assert_eq!(report["diverged"], false, "{report}");
    assert_eq!(report["complete"], true, "{report}");
    let rows = report["robots"].as_array().unwrap();
    assert_eq!(rows.len(), robots, "{report}");
    for row in rows {
        assert!(row["compared"].as_u64().unwrap() >= min_compared, "{row}");
        assert_eq!(row["differing"], 0, "{row}");
        assert_eq!(row["failed"], 0, "{row}");
        assert_eq!(row["max_abs_delta"], 0.0, "{row}");
    }
}

/// The in-process recording replayed with its own model: zero differing commands, exit 0;
/// with the paper's model: a per-robot divergence and exit 1; `--robot` replays one robot and a
/// robot the file does not hold is an error.
#[test]
fn a_case1_recording_replays_bit_identical_and_another_model_diverges() {
    let t = ProcessTest::start("replay_case1", LIMIT);
    let file = record_case1(t.path());

    let json = t.path().join("same.json");
    let same = replay(&file, &[], &json);
    same.assert_exit(0);
    same.assert_stdout_has("identical");
    assert_identical_over(&read_json(&json), 3, 190);

    let paper = repo_root().join("onnx/models/paper/policy.onnx");
    let json = t.path().join("paper.json");
    let other = replay(&file, &["--model", paper.to_str().unwrap()], &json);
    other.assert_exit(1);
    other.assert_stdout_has("DIVERGED");
    other.assert_stderr_has("diverged");
    let report = read_json(&json);
    assert_eq!(report["diverged"], true, "{report}");
    assert_eq!(report["model_override"], true, "{report}");
    for row in report["robots"].as_array().unwrap() {
        assert!(row["differing"].as_u64().unwrap() > 0, "{row}");
        assert!(row["max_abs_delta"].as_f64().unwrap() > 0.0, "{row}");
        assert!(row["p99_abs_delta"].as_f64().unwrap() <= row["max_abs_delta"].as_f64().unwrap());
        assert!(row["first_differing_tick"].is_u64(), "{row}");
    }

    let json = t.path().join("one.json");
    let one = replay(&file, &["--robot", "1"], &json);
    one.assert_exit(0);
    let rows = read_json(&json)["robots"].as_array().unwrap().clone();
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0]["robot"], 1);
    let none = replay(&file, &["--robot", "7"], &t.path().join("none.json"));
    none.assert_exit(2);
    none.assert_stderr_has("--robot 7");
}

/// A run over processes (an agent per robot, the test model stored in the recording as an
/// attachment), recorded by the world with `clock`, replayed in one process: every fresh
/// command bit for bit the agents', with at least `min_compared` compared per robot.
fn replays_a_run_over_processes(name: &'static str, clock: &str, min_compared: u64) {
    let t = ProcessTest::start(name, LIMIT);
    let dir = &t.dir;
    let file = dir.path().join(format!("{clock}.mcap"));
    record_case1_over_processes(dir.path(), "replay", clock, &file);
    let json = dir.path().join(format!("{clock}.json"));
    let replayed = replay(&file, &[], &json);
    replayed.assert_exit(0);
    let report = read_json(&json);
    assert_identical_over(&report, 3, min_compared);
    assert_eq!(report["clock"], clock, "{report}");
    let model = report["models"][0].as_str().unwrap();
    assert_eq!(Path::new(model), test_model(), "{report}");
}

/// Lockstep: every tick's command is fresh and replays bit for bit.
#[test]
fn a_lockstep_run_over_processes_replays_bit_identical() {
    replays_a_run_over_processes("replay_lockstep", "lockstep", 190);
}

/// Realtime: each fresh command is replayed against the scan it answered (`lag_ticks` before
/// its tick), bit for bit. A realtime run's commands depend on timing, so fewer steps may be
/// fresh; every fresh one must match.
#[test]
fn a_realtime_run_over_processes_replays_bit_identical() {
    replays_a_run_over_processes("replay_realtime", "realtime", 100);
}

/// A policy whose input image has one cell flipped: the renderer changed by one pixel.
struct OneCellFlipped(Box<dyn PolicyBackend>);

impl PolicyBackend for OneCellFlipped {
    fn infer(&mut self, input: &PolicyInput<'_>) -> Result<[f32; 2], DecisionError> {
        let mut image = input.image.to_vec();
        // The cell in the middle of the image's first row: beside the robot, within the window.
        let cell = self.0.io().image.size_px / 2;
        image[cell] = 1.0 - image[cell];
        self.0.infer(&PolicyInput {
            image: &image,
            ..*input
        })
    }
    fn io(&self) -> PolicyIo {
        self.0.io()
    }
    fn sensor(&self) -> SensorContract {
        self.0.sensor()
    }
    fn model_id(&self) -> &str {
        self.0.model_id()
    }
    fn envelope(&self) -> formation_onnx::ModelEnvelope {
        self.0.envelope()
    }
}

/// The agent's pilots, with the renderer's output changed by one cell.
struct FlippedPilots;

impl PilotMaker for FlippedPilots {
    type Model = Box<dyn PolicyBackend>;
    type Pilot = OnnxPilot;

    fn load(&self, path: &Path) -> Result<Self::Model, BoxError> {
        Ok(Box::new(OneCellFlipped(OnnxPilots.load(path)?)))
    }
    fn model_id<'m>(&self, model: &'m Self::Model) -> &'m str {
        model.model_id()
    }
    fn pilot(&self, model: Self::Model, lidar: LidarSpec) -> Result<OnnxPilot, BoxError> {
        OnnxPilots.pilot(model, lidar)
    }
}

/// The replay library with a renderer changed by one pixel finds differing commands; with the
/// agent's own pilots it finds none (the control). The run is an image network's (the shipped
/// pair network leaves the image unused).
#[test]
fn a_renderer_changed_by_one_pixel_is_caught() {
    let t = ProcessTest::start("replay_pixel", LIMIT);
    let file = record_case1_with(t.path(), &image_model());
    let scratch = t.path().join("scratch");
    std::fs::create_dir(&scratch).unwrap();
    let options = ReplayOptions::default();
    let control = replay_recording(&file, &options, &OnnxPilots, &scratch).unwrap();
    assert!(!control.report.diverged, "{:?}", control.report);
    let flipped = replay_recording(&file, &options, &FlippedPilots, &scratch).unwrap();
    assert!(flipped.report.diverged, "{:?}", flipped.report);
    let differing: u64 = flipped.report.robots.iter().map(|r| r.differing).sum();
    assert!(differing > 0, "{:?}", flipped.report);
}

/// Where the last chunk of a whole MCAP file begins, found by following its top-level records
/// (an opcode byte and a little-endian u64 length each, after the 8-byte magic).
fn last_chunk_offset(bytes: &[u8]) -> usize {
    let (mut at, mut last) = (8, None);
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        match bytes[at] {
            0x06 => last = Some(at),
            0x0F => break, // the data section ends
            _ => {}
        }
        at += 9 + len;
    }
    last.expect("a chunk")
}

/// Not MCAP, truncated, a missing model: each an error (exit 2) naming the cause and the fix; a
/// truncated recording is replayed up to the cut and its report says so.
#[test]
fn bad_input_gets_a_clear_error() {
    let t = ProcessTest::start("replay_bad", LIMIT);
    let json = t.path().join("bad.json");

    let text = t.path().join("notes.mcap");
    std::fs::write(&text, "not a recording\n").unwrap();
    let refused = replay(&text, &[], &json);
    refused.assert_exit(2);
    refused.assert_stderr_has("not an MCAP file");

    let missing = replay(&t.path().join("absent.mcap"), &[], &json);
    missing.assert_exit(2);
    missing.assert_stderr_has("absent.mcap");

    let file = record_case1(t.path());
    let bytes = std::fs::read(&file).unwrap();
    let cut = t.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 5]).unwrap();
    let json = t.path().join("cut.json");
    let truncated = replay(&cut, &[], &json);
    truncated.assert_exit(2);
    truncated.assert_stderr_has("truncated");
    let report = read_json(&json);
    assert_eq!(report["complete"], false, "{report}");
    assert_eq!(report["diverged"], false, "{report}");
    assert!(
        report["robots"][0]["compared"].as_u64().unwrap() > 0,
        "{report}"
    );

    // Issue 39: 20 bytes that start as an MCAP file does are "too short", not "not MCAP".
    let short = t.path().join("short.mcap");
    std::fs::write(&short, &bytes[..20]).unwrap();
    let too_short = replay(&short, &[], &t.path().join("short.json"));
    too_short.assert_exit(2);
    assert!(
        too_short.stderr().contains("too short")
            && too_short.stderr().contains("truncated")
            && !too_short
                .stderr()
                .contains("does not start with the MCAP magic"),
        "{}",
        too_short.describe()
    );

    // A crash inside a chunk leaves its header with the placeholder length (issue 39): the file
    // replays up to its last whole chunk, names the byte and exits 2.
    let start = last_chunk_offset(&bytes);
    let mut crashed = bytes[..start].to_vec();
    crashed.push(0x06);
    crashed.extend(u64::MAX.to_le_bytes());
    crashed.extend([0u8; 16]);
    crashed.extend(u64::MAX.to_le_bytes());
    crashed.extend(u32::MAX.to_le_bytes());
    crashed.extend(4u32.to_le_bytes());
    crashed.extend(b"zstd");
    crashed.extend(u64::MAX.to_le_bytes());
    crashed.extend(&bytes[start + 53..start + 53 + 100]);
    let unclosed = t.path().join("unclosed.mcap");
    std::fs::write(&unclosed, &crashed).unwrap();
    let json_unclosed = t.path().join("unclosed.json");
    let replayed = replay(&unclosed, &[], &json_unclosed);
    replayed.assert_exit(2);
    assert!(
        replayed
            .stderr()
            .contains(&format!("its last whole chunk ends at byte {start}"))
            && replayed.stderr().contains("never closed")
            && !replayed.stderr().contains("corrupt"),
        "{}",
        replayed.describe()
    );
    let report = read_json(&json_unclosed);
    assert_eq!(report["complete"], false, "{report}");
    assert_eq!(report["bytes_read"], start as u64, "{report}");
    assert_eq!(report["diverged"], false, "{report}");

    let no_model = replay(&file, &["--model", "/nonexistent/model.onnx"], &json);
    no_model.assert_exit(2);
    no_model.assert_stderr_has("/nonexistent/model.onnx");
}

/// Gap 2 of issue 24: a paced lockstep run over processes in which robot 1's model is swapped
/// at tick 120 (`formation swap`) to a model from outside the repository, recorded by the world.
/// Each step of the recording names the model that decided it, and the world stored the
/// swapped-in model as an attachment (its bytes, read back by Python's independent `mcap`
/// reader, are the file's) with the `formation.swapped_model` record that maps its id to it; so
/// the replay, with no flag, decides each tick with the model active then and every command of
/// every robot, before and after the swap, comes back bit for bit. `--swap-model` (for a
/// recording that lacks the model) still works beside it.
#[test]
fn a_run_with_a_mid_run_swap_replays_bit_identical_with_each_ticks_model() {
    const SWAP_TICK: u64 = 120;
    let t = ProcessTest::start("replay_swap", LIMIT);
    let second = t.path().join("second.onnx");
    write_tiny_model(&second, 1);
    let scenario = t.case1(10.0);
    let file = t.path().join("swapped.mcap");
    let mut command = t.formation_run(&scenario, &["--clock", "lockstep", "--pace-ms", "20"]);
    command.arg("--record").arg(&file);
    let mut launch = LiveProcess::spawn(command);
    await_connected(&mut launch);
    let mut swap = Command::new(&binaries().cli);
    swap.args(["swap", "--run", t.run.as_str(), "--robot", "1", "--model"])
        .arg(&second)
        .args(["--at-tick", &SWAP_TICK.to_string()]);
    let swapped = run(swap, LIMIT);
    swapped.assert_success();
    swapped.assert_stdout_has(&format!("from tick {SWAP_TICK}"));
    launch.finish(LIMIT).assert_success();
    t.assert_clean();

    // The world stored the swapped-in model: one attachment, the file's bytes, named by its record.
    let read = mcap_readers(&["attachments".as_ref(), file.as_os_str()]);
    let sha256 = formation_record::models::sha256_file(&second).unwrap();
    let size = std::fs::metadata(&second).unwrap().len();
    let attachments = read["attachments"].as_array().unwrap();
    let name = format!("models/{sha256}.onnx");
    let stored: Vec<&Value> = attachments.iter().filter(|a| a["name"] == name).collect();
    assert_eq!(stored.len(), 1, "{read}");
    assert_eq!(stored[0]["sha256"], sha256.as_str(), "{read}");
    assert_eq!(stored[0]["size"], size, "{read}");
    assert_eq!(stored[0]["media_type"], "application/x-onnx", "{read}");
    let swaps = read["swapped_models"].as_array().unwrap();
    assert_eq!(swaps.len(), 1, "{read}");
    let record = &swaps[0];
    assert_eq!(record["format"], "formation.swapped_model v1", "{read}");
    assert_eq!(record["robot"], "1", "{read}");
    assert_eq!(record["tick"], SWAP_TICK.to_string(), "{read}");
    assert_eq!(record["stored"], format!("attachment {name}"), "{read}");
    assert_eq!(record["sha256"], sha256.as_str(), "{read}");
    assert!(
        record["model_id"].as_str().unwrap().starts_with("second-"),
        "{read}"
    );

    // No flag: every step compared, each with the model that decided its tick.
    let json = t.path().join("stored.json");
    let stored_replay = replay(&file, &[], &json);
    stored_replay.assert_exit(0);
    assert!(
        !stored_replay.stdout().contains("--swap-model"),
        "{}",
        stored_replay.describe()
    );
    let report = read_json(&json);
    assert_every_step_identical(&report);
    assert!(
        report["models"].as_array().unwrap().iter().any(|m| {
            let m = m.as_str().unwrap();
            m.contains("second.onnx") && m.contains("stored in the recording")
        }),
        "{report}"
    );

    // --swap-model beside the stored model: the same model, still every step identical.
    let json = t.path().join("with.json");
    let with = replay(&file, &["--swap-model", second.to_str().unwrap()], &json);
    with.assert_exit(0);
    assert_every_step_identical(&read_json(&json));
}

/// Nothing diverged in a 3-robot, 200-tick run and no step was left undecided.
fn assert_every_step_identical(report: &Value) {
    assert_identical_over(report, 3, 190);
    for row in report["robots"].as_array().unwrap() {
        assert!(
            row["unreplayable"].as_object().is_none_or(|u| u.is_empty()),
            "{row}"
        );
    }
}

/// A step that names a swapped-in model before the model's record in the file (its command
/// overtook the agent's report of the swap, as it can over Zenoh) is held back until the record
/// comes, then replayed with that model: no step is left undecided. The recording is written
/// with formation-record's own writer in that order; real ONNX Runtime decides.
#[test]
fn a_step_that_precedes_its_swap_record_waits_for_it() {
    use formation_proto::SwapDone;
    use formation_proto::model_id::model_id;
    use formation_proto::{Goal, NeighbourRule, Pose, WheelCmd};
    use formation_record::{RecordingFile, SentCommand, TeamSetup, TickRecord};

    let t = ProcessTest::start("replay_held", LIMIT);
    let first = t.path().join("first.onnx");
    write_tiny_model(&first, 0);
    let second = t.path().join("second.onnx");
    write_tiny_model(&second, 1);
    let id = |p: &Path| model_id(p, &std::fs::read(p).unwrap());
    let metadata = [
        ("model.0.path", first.display().to_string()),
        (
            "model.0.sha256",
            formation_record::models::sha256_file(&first).unwrap(),
        ),
        ("model.0.stored", "shipped".into()),
        ("robot_models", "0".into()),
        ("lidar_max_range_m", "10".into()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v))
    .collect();
    let team = TeamSetup {
        n_robots: 1,
        max_range: 10.0,
        wheel_separation: 0.2,
        neighbours: NeighbourRule::AllPairs,
        wheels: formation_proto::WheelLimits::default(),
    };
    let file = t.path().join("held.mcap");
    let mut recording = RecordingFile::create_with_metadata(&file, team, 1.0, metadata).unwrap();
    let tick = |k: u64, model: String| TickRecord {
        tick: k,
        time: k as f64 * 0.05,
        goal: Goal::new(0.0, 1.0, 0.2),
        poses: vec![Pose::new(0.0, 0.0, 0.1)],
        wheel_speeds: vec![WheelCmd::default()],
        scans: vec![vec![2.0; 900]],
        commands: vec![SentCommand::in_process(WheelCmd::default())],
        model_ids: vec![model],
    };
    for k in 0..3 {
        recording.write_tick(&tick(k, id(&first))).unwrap();
    }
    recording.write_tick(&tick(3, id(&second))).unwrap();
    let swap = SwapDone {
        robot: 0,
        tick: 3,
        request_id: 1,
        model_id: id(&second),
        path: Some(second.clone()),
        model: None,
    };
    recording.write_swap(&swap).unwrap();
    recording.write_tick(&tick(4, id(&second))).unwrap();
    recording.finish(None).unwrap();

    let scratch = t.path().join("scratch");
    std::fs::create_dir(&scratch).unwrap();
    let replayed =
        replay_recording(&file, &ReplayOptions::default(), &OnnxPilots, &scratch).unwrap();
    let robot = &replayed.report.robots[0];
    assert_eq!(robot.steps, 5, "{:?}", replayed.report);
    assert_eq!(robot.compared, 5, "{:?}", replayed.report);
    assert!(robot.unreplayable.is_empty(), "{:?}", replayed.report);
    assert!(replayed.notes.is_empty(), "{:?}", replayed.notes);
}
