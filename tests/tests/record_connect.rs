//! Issue 24, item 3: `formation record --connect` records a live Zenoh team from outside, with
//! the read-only recorder login of `formation credentials`, into the very file the world's own
//! `--record` writes (compared message for message by the independent Python readers of
//! `tests/python/mcap_readers.py`: topics, log times, decoded messages and payload bytes);
//! without that login (none, or an agent's) it is refused with the fix, and the team plays on
//! unaffected; an agent's login that subscribes to the record channel gets nothing. A ROS 2
//! team (`--transport ros2`, no logins) recorded from outside gives its own recording too. The
//! recorder's failure modes: joined late (its file says from which tick), its team's world
//! SIGKILLed (a clear error, exit 2, a finished file up to the last tick), SIGINT (exit 130, a
//! finished file); a file recorded from outside replays with the model at its recorded path.
//!
//! Real processes on 127.0.0.1 with real Zenoh: for a recording from the first tick the run waits
//! while the recorder connects (a remote robot over Zenoh, gated agents over ROS 2); each test
//! has its own run id, port and scratch folder.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use formation_proto::wire::RunId;
use formation_tests::{
    AgentGate, LiveProcess, ProcessTest, assert_none_counted, assert_recorded_from_the_start,
    await_connected, await_recorder_connected, binaries, case1_scenario, count_samples,
    finish_with_remote_agent, formation_run, free_tcp_port, mcap_readers, raw_client, read_json,
    remote_zenoh_agent, run, send_signal, test_model, world_pid, zenoh_credentials,
};

const LIMIT: Duration = Duration::from_secs(240);

/// `formation record --connect ENDPOINT --run-id RUN --out OUT`, with `login` when given.
fn record_connect(
    endpoint: &str,
    run: &str,
    out: &std::path::Path,
    login: Option<&std::path::Path>,
) -> Command {
    let mut command = Command::new(&binaries().cli);
    command
        .args(["record", "--connect", endpoint, "--run-id", run, "--out"])
        .arg(out);
    if let Some(login) = login {
        command.arg("--credentials").arg(login);
    }
    command
}

/// The acceptance: a lockstep case-1 run over Zenoh recorded by the world (`--record A`) and
/// from outside (`formation record --connect ... --out B`, attached before the run starts) gives
/// the same messages; the recorder refuses to start without the recorder login (none, or robot
/// 1's), and robot 1's login subscribing to the record channel receives nothing.
#[test]
fn a_live_team_recorded_from_outside_equals_its_own_recording() {
    let t = ProcessTest::start("record_connect_equal", LIMIT);
    let scenario = t.case1(8.0);
    let creds = zenoh_credentials(t.path(), 3);
    let listen = t.endpoint();
    let own = t.path().join("own.mcap");
    let outside = t.path().join("outside.mcap");
    let own_text = own.to_str().expect("a UTF-8 path");
    let launch = t.launch_awaiting_remote(
        &scenario,
        &listen,
        2,
        &creds,
        &["--clock", "lockstep", "--record", own_text],
    );

    // Refused without the recorder login: none at all, or an agent's.
    let refused = run(
        record_connect(&listen, t.run.as_str(), &outside, None),
        Duration::from_secs(60),
    );
    refused.assert_failure_mentioning("needs the team's recorder login");
    refused.assert_stderr_has("recorder.json");
    let robot1 = creds.join("robot-1.json");
    let refused = run(
        record_connect(&listen, t.run.as_str(), &outside, Some(&robot1)),
        Duration::from_secs(60),
    );
    refused.assert_failure_mentioning("holds the login of robot-1, not the recorder's");
    assert!(!outside.exists(), "a refused recorder writes nothing");
    // The recorder's user with another password (issue 39): refused as a login, not as an
    // unreachable team, well within --timeout-s, and without the build's source paths.
    let mut wrong: serde_json::Value =
        serde_json::from_slice(&std::fs::read(creds.join("recorder.json")).expect("recorder"))
            .expect("recorder.json");
    wrong["password"] = serde_json::Value::String("not-the-teams-password".into());
    let wrong_login = t.path().join("wrong-recorder.json");
    std::fs::write(&wrong_login, wrong.to_string()).expect("write the wrong login");
    let mut command = record_connect(&listen, t.run.as_str(), &outside, Some(&wrong_login));
    command.args(["--timeout-s", "200"]);
    let refused = run(command, Duration::from_secs(200));
    refused.assert_failure_mentioning("refused the login of user recorder");
    let stderr = refused.stderr();
    assert!(
        !stderr.contains(".cargo") && !stderr.contains(".rs:") && !stderr.contains("within 200"),
        "{}",
        refused.describe()
    );
    assert!(!outside.exists(), "a refused recorder writes nothing");
    // Robot 1's login may connect, but the router gives it nothing of the record channel.
    let login = formation_transport_zenoh::credentials::read_login(&robot1).expect("robot 1");
    let impostor = raw_client(&listen, Some((login.user(), login.password())))
        .expect("robot 1's login is a valid login");
    let (_sub, stolen) = count_samples(&impostor, format!("formation/{}/record/**", t.run));

    // The recorder with its login, attached before the run starts.
    let login = creds.join("recorder.json");
    let mut recorder = LiveProcess::spawn(record_connect(
        &listen,
        t.run.as_str(),
        &outside,
        Some(&login),
    ));
    await_recorder_connected(&mut recorder, &t.run);
    // Let the recorder's subscription reach the router before the run begins.
    std::thread::sleep(Duration::from_secs(1));

    let mut agent = remote_zenoh_agent(&listen, &t.run, 2);
    agent.arg("--credentials").arg(creds.join("robot-2.json"));
    finish_with_remote_agent(launch, agent, LIMIT);
    assert_recorded_from_the_start(recorder);

    assert_recorded_alike(&own, &outside);
    assert_none_counted(&[(&stolen, "robot 1's login received the record channel")]);
    drop(impostor);
    t.assert_clean();
}

/// The world's own recording `own` and the one made from outside, `outside`, of the same 8 s
/// lockstep case-1 run: the same ROS 2 messages (compared by the independent readers), the
/// outside one complete from tick 0, the run's metadata alike.
fn assert_recorded_alike(own: &Path, outside: &Path) {
    let compared = mcap_readers(&["compare".as_ref(), own.as_os_str(), outside.as_os_str()]);
    // 8 s at 20 Hz: 160 ticks of 3 robots' scan, odometry, command, TF and more.
    assert!(
        compared["messages"].as_u64().unwrap() > 160 * 3 * 4,
        "{compared}"
    );
    assert_eq!(compared["differing"], 0, "{compared}");
    let theirs = mcap_readers(&["metadata".as_ref(), outside.as_os_str()]);
    let ours = mcap_readers(&["metadata".as_ref(), own.as_os_str()]);
    assert_eq!(theirs["live.first_tick"], "0", "{theirs}");
    assert_eq!(theirs["live.complete_from_start"], "true", "{theirs}");
    for key in [
        "scenario",
        "seed",
        "run_seed",
        "clock",
        "model.0.sha256",
        "robot_models",
    ] {
        assert_eq!(theirs[key], ours[key], "{key}: {theirs} against {ours}");
    }
}

/// Gap 1 of issue 24: a lockstep case-1 run of a ROS 2 team (`formation run --transport ros2`,
/// ROS 2 agents) recorded by its world (`--record A`) and from outside (`formation record
/// --connect --transport ros2 --out B`, attached before the first tick) gives the same messages.
/// A ROS 2 team has no logins: the recorder takes none, and `--credentials` is refused with it.
#[test]
fn a_live_ros2_team_recorded_from_outside_equals_its_own_recording() {
    let t = ProcessTest::start("record_connect_ros2", LIMIT);
    let scenario = t.case1(8.0);
    let listen = t.endpoint();
    let own = t.path().join("own.mcap");
    let outside = t.path().join("outside.mcap");
    // The agents wait at the gate, so the run waits for them while the recorder connects.
    let gate = AgentGate::new(t.path());
    let launch = gate.spawn_recording(
        t.formation_run(
            &scenario,
            &[
                "--transport",
                "ros2",
                "--listen",
                &listen,
                "--clock",
                "lockstep",
            ],
        ),
        &own,
    );

    let mut with_login = record_connect(
        &listen,
        t.run.as_str(),
        &outside,
        Some(&t.path().join("recorder.json")),
    );
    with_login.args(["--transport", "ros2"]);
    let refused = run(with_login, Duration::from_secs(60));
    refused.assert_failure_mentioning("--credentials needs --transport zenoh");

    let mut command = record_connect(&listen, t.run.as_str(), &outside, None);
    command.args(["--transport", "ros2"]);
    let mut recorder = LiveProcess::spawn(command);
    await_recorder_connected(&mut recorder, &t.run);
    // Let the recorder's subscription reach the router before the run begins.
    std::thread::sleep(Duration::from_secs(1));
    gate.open();
    launch.finish(LIMIT).assert_success();
    assert_recorded_from_the_start(recorder);
    assert_recorded_alike(&own, &outside);
    t.assert_clean();
}

/// A paced lockstep case-1 launch of 20 s over Zenoh (fresh credentials in its `out` folder),
/// every robot's agent local; returns it once its agents connected, with its endpoint and the
/// recorder's login. Paced at 20 ms a tick, it plays for at least 8 s, so a recorder can join
/// while it plays; in lockstep every command is fresh, so each recorded step replays.
fn paced_zenoh_team(dir: &Path, run_id: &RunId) -> (LiveProcess, String, PathBuf) {
    let scenario = case1_scenario(dir, 20.0);
    let out = dir.join("out");
    let listen = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let mut launch = LiveProcess::spawn(formation_run(
        run_id,
        &scenario,
        &out,
        &[
            "--transport",
            "zenoh",
            "--listen",
            &listen,
            "--clock",
            "lockstep",
            "--pace-ms",
            "20",
        ],
    ));
    await_connected(&mut launch);
    let login = out
        .join("credentials")
        .join(run_id.as_str())
        .join("recorder.json");
    (launch, listen, login)
}

/// Starts `formation record --connect` on the team at `listen` into `file`, and returns it once
/// it has written its file and recorded for two seconds more.
fn recorder_under_way(listen: &str, run_id: &RunId, file: &Path, login: &Path) -> LiveProcess {
    let mut recorder =
        LiveProcess::spawn(record_connect(listen, run_id.as_str(), file, Some(login)));
    await_recorder_connected(&mut recorder, run_id);
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while !file.exists() {
        recorder.assert_holds(
            std::time::Instant::now() < deadline,
            "no recording within 30 s",
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(2));
    recorder
}

/// What the streaming reader (on a pipe) reads of `file`: it must read it to its end, with at
/// least `min_messages` messages; returns how many.
fn assert_read_to_its_end(file: &Path, min_messages: u64) -> u64 {
    let streamed = mcap_readers(&["stream".as_ref(), file.as_os_str()]);
    assert!(streamed["stopped_by"].is_null(), "{streamed}");
    let messages = streamed["messages"].as_u64().unwrap();
    assert!(messages >= min_messages, "{streamed}");
    messages
}

/// Gap 3 of issue 24: a recorder started while the run plays records from the first tick it
/// received whole and says so (`live.first_tick` > 0, `live.complete_from_start` false, and on
/// its output), and SIGINT finishes its file cleanly: exit 130, a file the streaming reader
/// reads to its end, every command in it the agents' (replayed bit for bit with the run's
/// model). The team plays on to its end, undisturbed.
#[test]
fn a_late_recorder_says_where_it_joined_and_sigint_finishes_its_file() {
    let t = ProcessTest::start("record_connect_late", LIMIT);
    let (launch, listen, login) = paced_zenoh_team(t.path(), &t.run);
    // Join about 40 ticks into the run.
    std::thread::sleep(Duration::from_secs(2));
    let late = t.path().join("late.mcap");
    let recorder = recorder_under_way(&listen, &t.run, &late, &login);
    send_signal(recorder.id(), "INT");
    let recorded = recorder.finish(Duration::from_secs(60));
    recorded
        .assert_exit(130)
        .assert_stdout_has("recorded run 0 to")
        .assert_stdout_has("only: the run did not end while recording");
    launch.finish(LIMIT).assert_success();

    let metadata = mcap_readers(&["metadata".as_ref(), late.as_os_str()]);
    let first: u64 = metadata["live.first_tick"]
        .as_str()
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no live.first_tick: {metadata}"));
    assert!(first > 0, "{metadata}");
    assert_eq!(metadata["live.complete_from_start"], "false", "{metadata}");
    // Two seconds at 20 ms a tick at least: 3 robots' scan, odometry, command and TF a tick.
    assert_read_to_its_end(&late, 50 * 3 * 4);

    // The test model is not a shipped one: the world's own recording would store it, this one
    // names it, and the replay finds it at its path on this host (its hash checked).
    assert!(
        metadata["model.0.stored"]
            .as_str()
            .is_some_and(|v| v.starts_with("not stored")),
        "{metadata}"
    );
    let json = t.path().join("late.json");
    let mut replay = Command::new(&binaries().cli);
    replay.arg("replay").arg(&late).arg("--json").arg(&json);
    run(replay, LIMIT).assert_success();
    let report = read_json(&json);
    assert_eq!(report["models"][0], test_model().display().to_string());
    assert_eq!(report["diverged"], false, "{report}");
    for row in report["robots"].as_array().unwrap() {
        assert!(row["compared"].as_u64().unwrap() >= 50, "{row}");
        assert_eq!(row["differing"], 0, "{row}");
    }
}

/// Gap 3 of issue 24: the team's world SIGKILLed while the recorder records: the recorder ends
/// with exit 2 and an error saying that the team went and where what arrived is kept, in a
/// finished file (the streaming reader reads it to its end) with the run's metadata.
#[test]
fn a_world_killed_mid_recording_ends_the_recorder_with_a_clear_error_and_a_readable_file() {
    let t = ProcessTest::start("record_connect_world_killed", LIMIT);
    let (launch, listen, login) = paced_zenoh_team(t.path(), &t.run);
    let file = t.path().join("cut.mcap");
    let recorder = recorder_under_way(&listen, &t.run, &file, &login);
    let world = world_pid(&t.run).expect("the world runs");
    send_signal(world, "KILL");
    let recorded = recorder.finish(Duration::from_secs(60));
    recorded.assert_exit(2).assert_stderr_has_all(
        &[
            "went before its last run ended",
            &format!("what arrived is kept in {}", file.display()),
        ],
        "the recorder says the world went and where what arrived is kept",
    );
    let launched = launch.finish(LIMIT);
    launched.assert_failed("expected failure");
    assert_read_to_its_end(&file, 50 * 3 * 4);
    let metadata = mcap_readers(&["metadata".as_ref(), file.as_os_str()]);
    assert_eq!(metadata["clock"], "lockstep", "{metadata}");
}
