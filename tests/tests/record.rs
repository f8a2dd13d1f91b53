//! Issue 24's acceptance tests of `--record`: recordings opened by independent readers only
//! (`tests/python/mcap_readers.py`: Python's `mcap` with `mcap-ros2-support`, `rosbags`, and
//! Rerun's `rerun mcap convert` with its Python API; none of formation's code), a recording cut
//! short by a SIGKILL read by the streaming reader, the multi-process recording equal to the
//! in-process one, and bad targets refused with the path and the fix.
//!
//! The Python packages come from `tests/python/requirements-record.txt` (`bash .ci/setup-python
//! --test` installs them into `.venv`); without them the tests fail with that fix. The full-disk
//! test mounts a small tmpfs and needs root, as CI has.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use formation_tests::mcap_readers as readers;
use formation_tests::{
    Finished, LiveProcess, ProcessTest, Tmpfs, await_connected, binaries, compared_steps,
    eval_recorded, expert_eval_once, formation_run, read_json, record_case1_over_processes,
    repo_root, run, signal_world, test_model,
};

const LIMIT: Duration = Duration::from_secs(300);
/// `formation eval --controller expert` of `scenario` in-process, recorded into `record`
/// ([`eval_recorded`]).
fn expert_eval_recorded(scenario: &Path, record: &Path, out: &Path) -> Finished {
    eval_recorded(
        &[
            "--controller",
            "expert",
            "--scenario",
            scenario.to_str().unwrap(),
        ],
        record,
        out,
    )
}

fn os(s: &str) -> &std::ffi::OsStr {
    s.as_ref()
}

/// The three readers on `file`, a recording of `robots` robots whose run log is `run_log`.
fn assert_independent_readers_open(file: &Path, run_log: &Path, robots: usize, rrd: &Path) {
    let robots = robots.to_string();
    let decoded = readers(&[
        os("decode"),
        file.as_os_str(),
        run_log.as_os_str(),
        os(&robots),
    ]);
    assert!(
        decoded["max_tf_error_m"].as_f64().unwrap() <= 1e-6,
        "{decoded}"
    );
    let bag = readers(&[os("rosbags"), file.as_os_str(), os(&robots)]);
    assert!(bag["messages"].as_u64().unwrap() > 0, "{bag}");
    let rerun = readers(&[os("rerun"), file.as_os_str(), rrd.as_os_str(), os(&robots)]);
    assert!(rerun["rows"].as_u64().unwrap() > 0, "{rerun}");
}

/// Case 1 with the shipped model, recorded in-process: the mcap readers decode every ROS 2
/// message and place the robots where the run log has them, rosbags reads it as a rosbag2, and
/// Rerun converts it with every robot's entity; the metadata names the run and the shipped model
/// by its hash.
#[test]
fn a_case1_recording_is_read_by_mcap_rosbags_and_rerun() {
    let t = ProcessTest::start("record_case1", LIMIT);
    let record = t.path().join("rec");
    std::fs::create_dir(&record).unwrap();
    let out = t.out();
    let scenario = repo_root().join("scenarios/case1.toml");
    let finished = eval_recorded(&["--scenario", scenario.to_str().unwrap()], &record, &out);
    finished.assert_success();
    let file = record.join("run-0000.mcap");
    finished.assert_stdout_has(&format!("recorded {}", file.display()));
    let run_log = out.join("runs/run-0000.json");
    assert_independent_readers_open(&file, &run_log, 3, &t.path().join("case1.rrd"));
    let meta = readers(&[os("metadata"), file.as_os_str()]);
    assert_eq!(meta["scenario"], "case1", "{meta}");
    assert_eq!(meta["run_index"], "0", "{meta}");
    assert_eq!(meta["model.0.stored"], "shipped", "{meta}");
    assert_eq!(meta["model.0.sha256"].as_str().unwrap().len(), 64, "{meta}");
}

/// A team of 16 (the expert, 10 s): the same three readers.
#[test]
fn a_16_robot_recording_is_read_by_mcap_rosbags_and_rerun() {
    let t = ProcessTest::start("record_team16", LIMIT);
    let text = std::fs::read_to_string(repo_root().join("scenarios/swarm32.toml")).unwrap();
    let text = text
        .replace("robots = 32", "robots = 16")
        .replace("duration_s = 20.0", "duration_s = 10.0");
    let scenario = t.path().join("team16.toml");
    std::fs::write(&scenario, text).unwrap();
    let record = t.path().join("rec");
    std::fs::create_dir(&record).unwrap();
    let out = t.out();
    let finished = expert_eval_recorded(&scenario, &record, &out);
    finished.assert_success();
    assert_independent_readers_open(
        &record.join("run-0000.mcap"),
        &out.join("runs/run-0000.json"),
        16,
        &t.path().join("team16.rrd"),
    );
}

/// A lockstep run over processes, recorded by the world, holds the same ROS 2 messages (and the
/// same replay channel) as the same run recorded in-process: the world is bit-identical in
/// lockstep, and so is its recording. The test model is not a shipped one, so both store it.
#[test]
fn a_lockstep_run_over_processes_records_the_same_messages_as_in_process() {
    let t = ProcessTest::start("record_processes", LIMIT);
    let over_processes = t.path().join("processes.mcap");
    let scenario = record_case1_over_processes(t.path(), "recproc", "lockstep", &over_processes);

    let record = t.path().join("rec");
    std::fs::create_dir(&record).unwrap();
    let model = test_model().to_str().unwrap();
    eval_recorded(
        &["--scenario", scenario.to_str().unwrap(), "--model", model],
        &record,
        &t.path().join("eval-out"),
    )
    .assert_success();
    let in_process = record.join("run-0000.mcap");
    let compared = readers(&[
        os("compare"),
        over_processes.as_os_str(),
        in_process.as_os_str(),
    ]);
    assert!(compared["messages"].as_u64().unwrap() > 0, "{compared}");
    let meta = readers(&[os("metadata"), over_processes.as_os_str()]);
    assert_eq!(meta["clock"], "lockstep", "{meta}");
    assert!(
        meta["model.0.stored"]
            .as_str()
            .unwrap()
            .starts_with("attachment models/"),
        "{meta}"
    );
}

/// The world SIGKILLed about 10 s into a realtime run: the streaming reader (on a pipe, so
/// nothing can be sought) reads at least 9 s of data from what it left.
#[test]
fn a_sigkilled_world_leaves_a_recording_the_streaming_reader_reads_to_its_last_chunk() {
    let t = ProcessTest::start("record_sigkill", LIMIT);
    let file = t.path().join("killed.mcap");
    let scenario = repo_root().join("scenarios/case1.toml");
    let mut command = t.formation_run(&scenario, &["--clock", "realtime"]);
    command.arg("--record").arg(&file);
    let mut launch = LiveProcess::spawn(command);
    await_connected(&mut launch);
    std::thread::sleep(Duration::from_millis(10_500));
    let finished = signal_world(&t.run, launch, "-KILL", LIMIT);
    finished.assert_failed("expected failure");
    t.assert_clean();
    let streamed = readers(&[os("stream"), file.as_os_str()]);
    let latest = streamed["latest_s"].as_f64().unwrap_or(0.0);
    finished.assert_holds(
        latest >= 9.0,
        &format!("the streaming reader read {latest} s of data\n{streamed}"),
    );
    // The run was cut short, so no summary was written: the reader stops at the cut.
    assert!(latest < 30.0, "{streamed}");
    // The launcher says the world was killed; nothing "above" explains it (issue 39).
    assert!(
        finished.stderr().contains("SIGKILL") && !finished.stderr().contains("see its error above"),
        "{}",
        finished.describe()
    );
    // `formation replay` replays it up to its last whole chunk, says where the readable part
    // ends, marks the report incomplete and exits 2 (issue 39).
    let json = t.path().join("killed.replay.json");
    let mut replay = Command::new(&binaries().cli);
    replay.arg("replay").arg(&file).arg("--json").arg(&json);
    let replayed = run(replay, LIMIT);
    replayed.assert_exit(2);
    let report = read_json(&json);
    assert_eq!(report["complete"], false, "{report}");
    let bytes_read = report["bytes_read"].as_u64().unwrap_or(0);
    assert!(bytes_read > 0, "{report}");
    replayed.assert_stderr_has(&format!("the steps before byte {bytes_read} were read"));
    assert!(
        replayed.stdout().contains("identical") && !replayed.stderr().contains("corrupt"),
        "{}",
        replayed.describe()
    );
    let compared = compared_steps(&report);
    // At least 9 of the 10 s played, for 3 robots, were replayed.
    assert!(compared >= 3 * 180, "{report}");
}

/// A target whose folder is missing, a device, or a component that is a file: refused before
/// anything runs, naming the path and the fix.
#[test]
fn bad_record_targets_are_refused_before_anything_runs() {
    let t = ProcessTest::start("record_bad_targets", LIMIT);
    let scenario = t.case1(1.0);
    let missing = t.path().join("no/such/folder");
    let mut eval = expert_eval_once(&scenario, &["--record"]);
    eval.arg(&missing);
    let finished = run(eval, LIMIT);
    finished.assert_failure_mentioning(&format!("{} does not exist", missing.display()));
    finished.assert_failure_mentioning(&format!("mkdir -p {}", missing.display()));
    assert!(
        !finished.stdout().contains("Table I"),
        "{}",
        finished.describe()
    );

    let out = t.out();
    let folder = t.path().join("a-folder");
    std::fs::create_dir(&folder).unwrap();
    for (target, needle) in [
        // A folder where a file is wanted: the fix's example is a recording (issue 39).
        (
            folder.clone(),
            format!(
                "name a file (for example {})",
                folder.join("run.mcap").display()
            ),
        ),
        // The scenario itself (issue 39): never written over.
        (
            scenario.clone(),
            format!("{} is the file --scenario reads", scenario.display()),
        ),
        (
            missing.join("run.mcap"),
            "does not exist: create it first".to_owned(),
        ),
        (
            PathBuf::from("/dev/full"),
            "/dev/full: it is a character device".to_owned(),
        ),
        (
            scenario.join("run.mcap"),
            format!("{} is a file, not a directory", scenario.display()),
        ),
    ] {
        let mut command = t.formation_run(&scenario, &[]);
        command.arg("--record").arg(&target);
        let finished = run(command, LIMIT);
        finished.assert_failure_mentioning(&needle);
        finished.assert_holds(
            !finished.stdout().contains("agents connected"),
            "refused before the launch",
        );
        finished.assert_exit(2);
        // A refusal leaves nothing behind: no --out folder, no run-specs.json (issue 39).
        assert!(
            !out.exists(),
            "{} was created by a refused launch\n{}",
            out.display(),
            finished.describe()
        );
    }
    assert!(std::fs::read_dir(&folder).unwrap().next().is_none());
    assert!(
        std::fs::read_to_string(&scenario)
            .unwrap()
            .contains("robots")
    );
    t.assert_clean();
}

/// A full disk: said before the run when the disk is full already; when the recording fills it
/// mid-run, the recording stops with a message naming the file and the full disk, and the run
/// goes on and writes its other outputs, in-process and over processes.
#[test]
fn a_full_disk_is_said_before_the_run_and_mid_run_stops_only_the_recording() {
    let t = ProcessTest::start("record_full_disk", LIMIT);
    let disk = Tmpfs::mount(&t.path().join("disk"), "256k");
    let scenario = t.case1(20.0);

    // Mid-run, in-process: 20 s of case 1 take about 700 kB.
    let out = t.path().join("eval-out");
    let finished = expert_eval_recorded(&scenario, disk.dir(), &out);
    let file = disk.dir().join("run-0000.mcap");
    finished
        .assert_success()
        .assert_stderr_has_all(
            &[
                "recording stopped",
                &file.display().to_string(),
                "the disk is full",
            ],
            "the recording stopped, naming its file and the full disk",
        )
        .assert_holds(
            out.join("summary.json").is_file(),
            "summary.json is written",
        );
    assert_eq!(read_json(&out.join("runs/run-0000.json"))["complete"], true);
    std::fs::remove_file(&file).unwrap();

    // Mid-run, over processes: the world's recording stops, the run does not.
    let out = t.path().join("run-out");
    let file = disk.dir().join("run.mcap");
    let mut command = formation_run(&t.run, &scenario, &out, &[]);
    command.arg("--record").arg(&file);
    let finished = run(command, LIMIT);
    finished.assert_success().assert_stderr_has_all(
        &["formation-world: recording stopped", "the disk is full"],
        "the world's recording stopped for the full disk",
    );
    assert_eq!(read_json(&out.join("runs/run-0000.json"))["complete"], true);
    finished.assert_holds(
        out.join("summary.json").is_file(),
        "summary.json is written",
    );
    t.assert_clean();

    // Full before the run: fill the disk to its last byte, then record.
    let filler = disk.dir().join("filler");
    let _ = Command::new("dd")
        .arg("if=/dev/zero")
        .arg(format!("of={}", filler.display()))
        .arg("bs=4k")
        .stderr(Stdio::null())
        .status();
    let finished = expert_eval_recorded(&scenario, disk.dir(), &t.path().join("eval-full"));
    finished.assert_failure_mentioning("the disk is full");
    assert!(
        !finished.stdout().contains("Table I"),
        "{}",
        finished.describe()
    );
}
