//! The multi-process runtime against its promises: lockstep equals in-process bit for bit,
//! decentralisation is enforced by the transport, nothing is left in shared memory, and bad input
//! ends in a clear error and a clean shutdown.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use formation_cli::launch::{ClockMode, NetworkFlags, ProcessEvalRuns, eval_over_processes};
use formation_proto::wire::{CmdMsg, RobotChannel, ScanMsg, robot_service_name};
use formation_robot_agent::decision::PolicyController;
use formation_tests::{
    ProcessTest, RobotLog, assert_bit_identical, formation_run_with_model, incarnations,
    launch_secret, lockstep_over_processes, repo_root, report_command, run, run_with_input,
    shipped_model, test_model,
};
use formation_transport_iceoryx2::naming::ServiceLimits;
use formation_world::{Scenario, run_episode};
use iceoryx2::prelude::*;

const LIMIT: Duration = Duration::from_secs(120);

/// Issue 4 (a): world + 3 agents in lockstep on case 1 with a real ONNX model reproduce the
/// in-process run bit for bit (and the run id's files are gone afterwards).
#[test]
fn lockstep_over_processes_is_bit_identical_to_in_process() {
    let t = ProcessTest::start("lockstep_equals_in_process", LIMIT);
    let scenario_path = t.case1(10.0);
    let scenario = Scenario::from_path(&scenario_path).expect("scenario");
    let model = test_model();

    // The launcher finds the runtime binaries next to the current executable; a test binary lives
    // in target/<profile>/deps, and the launcher also searches the directory above it.
    assert!(t.bins().world.is_file() && t.bins().agent.is_file());
    let mut progress = Vec::new();
    let evaluation = ProcessEvalRuns {
        scenario: &scenario,
        base_seed: scenario.seed(),
        runs: 2,
        default_model: model,
        clock: ClockMode::Lockstep,
        network: &NetworkFlags::default(),
    };
    let over_processes = eval_over_processes(&evaluation, &mut |n| progress.push(n))
        .expect("runs over processes")
        .trajectories;
    assert_eq!(progress, vec![1, 2]);
    assert_eq!(over_processes.len(), 2);

    for (index, from_processes) in over_processes.iter().enumerate() {
        let spec = scenario.run_spec(scenario.seed(), index);
        let lidar = spec.world.lidar;
        let wheels = spec.world.robot.wheel_limits();
        let mut controller =
            PolicyController::from_model_paths(&[model, model, model], lidar, wheels)
                .expect("in-process agents");
        let in_process =
            run_episode(&spec, &mut controller, &mut |_, _| {}).expect("in-process run");
        assert_eq!(in_process.poses.len(), 201, "10 s at 20 Hz");
        assert_bit_identical(from_processes, &in_process);
    }
}

/// Issue 10: a team of 16 robots of the shipped teams policy (Gabriel neighbour rule, LIDAR noise
/// σ = 3 cm, d* drawn from the declared range), every robot its own process, in lockstep
/// reproduces the in-process run bit for bit.
#[test]
fn a_sixteen_robot_team_of_the_shipped_policy_in_lockstep_is_bit_identical_to_in_process() {
    let t = ProcessTest::start("sixteen_robots_lockstep", 3 * LIMIT);
    let text = std::fs::read_to_string(repo_root().join("scenarios/teams-generalist.toml"))
        .expect("reading teams-generalist.toml");
    let text = text
        .replace("robots = 8", "robots = 16")
        .replace("duration_s = 60.0", "duration_s = 4.0")
        .replace("runs = 100", "runs = 1");
    let scenario_path = t.path().join("team16.toml");
    std::fs::write(&scenario_path, text).expect("writing the scenario");
    let scenario = Scenario::from_path(&scenario_path).expect("scenario");
    assert_eq!(scenario.n_robots(), 16);
    let model = shipped_model();
    let over_processes = lockstep_over_processes(&scenario, 1, &model);
    let spec = scenario.run_spec(scenario.seed(), 0);
    assert!(spec.world.lidar_noise.noise_std > 0.0, "a noisy LIDAR");
    let models = vec![model.as_path(); 16];
    let mut controller = PolicyController::from_model_paths(
        &models,
        spec.world.lidar,
        spec.world.robot.wheel_limits(),
    )
    .expect("in-process agents");
    let in_process = run_episode(&spec, &mut controller, &mut |_, _| {}).expect("in-process run");
    assert_eq!(in_process.poses.len(), 81, "4 s at 20 Hz");
    assert_eq!(in_process.poses[0].len(), 16);
    assert_bit_identical(&over_processes[0], &in_process);
}

/// Issue 4 (b): with an agent on robot 0, nobody else can read robot 0's scan or command robot 0
/// (that another agent of the launch is refused the robot is the conformance suite's admission).
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "one scripted scenario over real iceoryx2 services: its steps read in order"
)]
fn a_second_scan_reader_or_command_writer_is_refused() {
    let t = ProcessTest::start("decentralisation", LIMIT);
    let mut world = t
        .world_by_hand(5.0, &t.out())
        .args(["--exit-on-stdin-close", "--startup-timeout-ms", "60000"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("starting the world");
    let secret = launch_secret();
    let hand_secret = |child: &mut std::process::Child| {
        use std::io::Write;
        let stdin = child.stdin.as_mut().expect("piped stdin");
        stdin.write_all(secret.to_line().as_bytes()).unwrap();
        stdin.flush().unwrap();
    };
    hand_secret(&mut world);
    let mut world_out = BufReader::new(world.stdout.take().unwrap());
    let mut line = String::new();
    world_out.read_line(&mut line).unwrap();
    assert!(line.contains("listening"), "world said {line:?}");
    let mut agent = Command::new(&t.bins().agent)
        .args([
            "--run-id",
            t.run.as_str(),
            "--robot",
            "0",
            "--exit-on-stdin-close",
        ])
        .arg("--model")
        .arg(test_model())
        .stdin(Stdio::piped())
        .spawn()
        .expect("starting agent 0");
    hand_secret(&mut agent);

    let config = t.leaks.namespace().iceoryx_config().unwrap();
    let node = NodeBuilder::new()
        .config(&config)
        .create::<ipc::Service>()
        .unwrap();
    let limits = ServiceLimits::ROBOT;
    // The world makes robot 0's services once it accepted the agent's proof.
    let deadline = Instant::now() + Duration::from_secs(30);
    let incarnation = loop {
        match incarnations(&t.run, 0).as_slice() {
            [one] => break *one,
            [] if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            other => panic!("robot 0 should have exactly one incarnation, found {other:x?}"),
        }
    };
    let open =
        |channel| ServiceName::new(&robot_service_name(&t.run, 0, incarnation, channel)).unwrap();
    // The service is listed as soon as the world starts creating it, but opens only once the
    // world has finished: retry until then.
    let deadline = Instant::now() + Duration::from_secs(30);
    let (scan, cmd) = loop {
        let scan = node
            .service_builder(&open(RobotChannel::Scan))
            .publish_subscribe::<ScanMsg>()
            .open();
        let cmd = node
            .service_builder(&open(RobotChannel::Cmd))
            .publish_subscribe::<CmdMsg>()
            .open();
        match (scan, cmd) {
            (Ok(scan), Ok(cmd)) => break (scan, cmd),
            (scan, cmd) if Instant::now() >= deadline => {
                panic!(
                    "robot 0's services never opened: scan {:?}, cmd {:?}",
                    scan.err(),
                    cmd.err()
                )
            }
            _ => std::thread::sleep(Duration::from_millis(20)),
        }
    };
    // Wait until agent 0 holds its ports.
    let deadline = Instant::now() + Duration::from_secs(30);
    while (scan.dynamic_config().number_of_subscribers() < 1
        || cmd.dynamic_config().number_of_publishers() < 1)
        && Instant::now() < deadline
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(
        scan.dynamic_config().number_of_subscribers(),
        limits.max_subscribers
    );
    let second_reader = scan.subscriber_builder().create();
    assert!(
        second_reader.is_err(),
        "a second subscriber on robot 0's scan was admitted"
    );
    let second_writer = cmd.publisher_builder().create();
    assert!(
        second_writer.is_err(),
        "a second publisher on robot 0's commands was admitted"
    );
    drop((second_reader, second_writer, scan, cmd, node));

    drop(agent.stdin.take());
    drop(world.stdin.take());
    let started = Instant::now();
    assert!(agent.wait().unwrap().success());
    assert!(world.wait().is_ok());
    assert!(
        started.elapsed() < Duration::from_secs(5),
        "shutdown took {:?}",
        started.elapsed()
    );
    // Both exited cleanly: iceoryx2 removed every service and port segment itself.
    t.leaks.assert_only_management_left();
}

/// Issue 4 (c): `formation run` leaves nothing in /dev/shm or iceoryx2's directory.
#[test]
fn formation_run_leaves_no_shared_memory_behind() {
    let t = ProcessTest::start("no_leaks", LIMIT);
    let command = t.formation_run(&t.case1(2.0), &["--clock", "lockstep", "--pace-ms", "10"]);
    let finished = run(command, LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("round_trip");
    assert!(t.path().join("out/runs/run-0000.json").is_file());
    t.assert_clean();

    // The run directory holds what the report needs (issue 6): its Table I summary, the run log,
    // the latency profile and its plot; `formation report` reads it as it is.
    let out = t.out();
    for file in ["summary.json", "profile.json", "profile.svg"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let profile: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("profile.json")).expect("profile"))
            .expect("profile JSON");
    assert_eq!(profile["per_agent"].as_array().map(Vec::len), Some(3));
    assert_eq!(
        profile["stages"]["tick"]["count"].as_u64(),
        Some(39),
        "40 ticks"
    );
    // `--pace-ms 10`: the median tick takes at least 10 ms and even the shortest lands in the
    // histogram bucket (8.192, 16.384] ms (unpaced, ticks take well under 1 ms).
    let tick = &profile["stages"]["tick"];
    assert!(
        tick["p50_us"].as_f64() >= Some(10_000.0)
            && tick["histogram"][0][0].as_f64() >= Some(16_000.0),
        "{tick}"
    );
    run(report_command(&out, &t.path().join("report.html")), LIMIT).assert_success();
    assert!(t.path().join("report.html").is_file());
}

/// Issue 4 (d): a missing model is refused before anything starts.
#[test]
fn a_missing_model_is_a_clear_error() {
    let t = ProcessTest::start("missing_model", LIMIT);
    let missing = Path::new("/nonexistent/policy.onnx");
    let command = formation_run_with_model(&t.run, &t.case1(1.0), missing, &t.out(), &[]);
    run(command, LIMIT).assert_failure_mentioning("/nonexistent/policy.onnx");
    t.assert_clean();
}

/// Issue 4 (d): an agent that exits at start ends the launch with the robot and status named,
/// quickly, with every process reaped and nothing left behind.
#[test]
fn an_agent_that_exits_at_start_stops_the_launch_cleanly() {
    let t = ProcessTest::start("agent_exits", LIMIT);
    let mut command = t.formation_run(&t.case1(1.0), &["--restarts", "0"]);
    command.env("FORMATION_AGENT_BIN", "/bin/false");
    let finished = run(command, LIMIT);
    finished.assert_failure_mentioning("exit code 1");
    finished.assert_stderr_has("restart budget");
    assert!(
        finished.elapsed < Duration::from_secs(15),
        "{}",
        finished.describe()
    );
    t.assert_clean();
}

/// Issue 4 (d): a robot index the world does not serve, and a scenario assigning a model to a
/// robot it does not have, are both clear errors.
#[test]
fn robot_indices_out_of_range_are_clear_errors() {
    let t = ProcessTest::start("robot_out_of_range", LIMIT);
    // A lone agent leaves iceoryx2's global management segment of its namespace behind (no
    // launcher runs to remove it); its own run id keeps that out of the launcher check below.
    let (lone_run, _lone_cleanup) = t.another_run("lone");
    let mut agent = Command::new(&t.bins().agent);
    agent
        .args([
            "--run-id",
            lone_run.as_str(),
            "--robot",
            "7",
            "--connect-timeout-ms",
            "300",
        ])
        .arg("--model")
        .arg(test_model());
    let secret = launch_secret().to_line();
    run_with_input(agent, Some(&secret), LIMIT)
        .assert_failure_mentioning("robot 7's services do not exist");

    let scenario = t.case1(1.0);
    let mut text = std::fs::read_to_string(&scenario).unwrap();
    text.push_str(&format!(
        "\n[[agent]]\nrobot = 5\nmodel = {:?}\n",
        test_model().display().to_string()
    ));
    std::fs::write(&scenario, text).unwrap();
    let mut command = Command::new(&t.bins().cli);
    command
        .args(["run", "--run-id", t.run.as_str()])
        .arg("--scenario")
        .arg(&scenario)
        .arg("--out")
        .arg(t.out());
    run(command, LIMIT).assert_failure_mentioning("robot");
    t.assert_clean();
}

/// Issue 5 (fault injection): an agent that crashes mid-run in lockstep is braked, restarted by
/// the launcher and rejoins; the run completes and leaves nothing behind.
#[test]
fn a_crashed_agent_is_braked_restarted_and_rejoins() {
    let t = ProcessTest::start("crash_rejoin", LIMIT);
    let out = t.out();
    let command = t.formation_run(
        &t.case1(5.0),
        &[
            "--restarts",
            "1",
            "--timeout-ms",
            "500",
            "--fault",
            "1:crash-after=40",
        ],
    );
    let finished = run(command, LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("1 agent restart(s)");
    let robot1 = RobotLog::read(&out, 1).outcomes;
    assert_eq!(robot1.len(), 100);
    assert!(robot1[..40].iter().all(|o| o == "fresh"), "{robot1:?}");
    assert!(
        robot1[40] != "fresh",
        "the tick after the crash must be braked: {robot1:?}"
    );
    assert_eq!(
        robot1.last().map(String::as_str),
        Some("fresh"),
        "the restarted agent rejoined: {robot1:?}"
    );
    assert!(
        RobotLog::read(&out, 0)
            .outcomes
            .iter()
            .all(|o| o == "fresh")
    );
    t.assert_clean();
}

/// Issue 5 (fault injection): NaN commands are braked by the world's watchdog, tick by tick.
#[test]
fn nan_commands_are_braked() {
    let t = ProcessTest::start("nan_braked", LIMIT);
    let out = t.out();
    let command = t.formation_run(&t.case1(2.0), &["--fault", "2:nan-after=10"]);
    run(command, LIMIT).assert_success();
    let robot2 = RobotLog::read(&out, 2);
    assert!(
        robot2.outcomes[..10].iter().all(|o| o == "fresh")
            && robot2.outcomes[10..].iter().all(|o| o == "non_finite"),
        "{:?}",
        robot2.outcomes
    );
    for tick in 10..40 {
        assert_eq!(robot2.commands[tick], (0.0, 0.0), "tick {tick}");
    }
    t.assert_clean();
}

/// Issue 4: `formation eval --processes` and in-process `formation eval` write byte-identical JSON
/// for the same scenario, seed and models, here for a mixed team (robot 1 runs another model,
/// assigned in the scenario).
#[test]
fn eval_over_processes_writes_the_same_json_as_in_process_for_a_mixed_team() {
    let t = ProcessTest::start("eval_json_identical", LIMIT);
    let other = t.path().join("other.onnx");
    formation_tests::write_tiny_model(&other, 5);
    let base = std::fs::read_to_string(t.case1(4.0)).expect("scenario");
    let scenario = t.path().join("mixed.toml");
    std::fs::write(
        &scenario,
        format!(
            "{base}\n\n[[agent]]\nrobot = 1\nmodel = {:?}\n",
            other.display().to_string()
        ),
    )
    .expect("writing the scenario");
    let eval = |processes: bool, json: &str| {
        let mut command = Command::new(&t.bins().cli);
        command
            .args([
                "eval",
                "--controller",
                "policy",
                "--runs",
                "2",
                "--seed",
                "11",
            ])
            .arg("--scenario")
            .arg(&scenario)
            .arg("--model")
            .arg(test_model())
            .arg("--json")
            .arg(t.path().join(json));
        if processes {
            command.arg("--processes");
        }
        run(command, LIMIT).assert_success();
        std::fs::read(t.path().join(json)).expect("eval JSON")
    };
    let in_process = eval(false, "in-process.json");
    let over_processes = eval(true, "processes.json");
    assert!(
        in_process == over_processes,
        "JSON differs:\n{}\n---\n{}",
        String::from_utf8_lossy(&in_process),
        String::from_utf8_lossy(&over_processes)
    );
    let summary: serde_json::Value = serde_json::from_slice(&in_process).expect("JSON");
    let models = summary["models"].as_array().expect("models per robot");
    assert_eq!(models.len(), 3);
    assert_ne!(models[0], models[1], "robot 1 runs its own model");
    assert_eq!(models[0], models[2]);
}
