//! The Zenoh transport (issue 13) with real processes and real Zenoh on 127.0.0.1: lockstep over
//! Zenoh equals in-process bit for bit (`formation run` and `formation eval --processes`), remote
//! agents join a launch with their credentials, an impostor without them gets nothing, and bad
//! input (an unreachable endpoint, a remote robot the scenario lacks, a flag of another transport,
//! wrong or missing credentials, a swap over the size limit, a binary built without Zenoh) ends
//! in a clear error.
//!
//! Every test uses its own run id, its own free TCP port and its own scratch folder, and runs
//! alone within this binary ([`one_at_a_time`]).

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_tests::{
    LiveProcess, ProcessTest, assert_none_counted, await_connected, binaries, count_samples,
    finish_with_remote_agent, formation_run, launch_secret, policy_eval, raw_client, read_json,
    remote_zenoh_agent, run, run_with_input, test_model, zenoh_credentials,
};

const LIMIT: Duration = Duration::from_secs(180);

fn endpoint(port: u16) -> String {
    format!("tcp/127.0.0.1:{port}")
}

/// Issue 13: lockstep case 1 over Zenoh (world, three agents, 127.0.0.1, credentials made by the
/// launcher) reproduces the in-process run bit for bit.
#[test]
fn lockstep_case1_over_zenoh_is_bit_identical_to_in_process() {
    let t = ProcessTest::start("zenoh_lockstep_bit_identical", LIMIT);
    let finished = t.lockstep_case1_over_zenoh(&t.endpoint());
    let out = t.out();
    let credentials = out.join("credentials").join(t.run.as_str());
    finished.assert_holds(
        credentials.join("robot-0.json").is_file(),
        "the launcher made the run's credentials",
    );
    t.assert_clean();
}

/// Issue 13 (`--transport` on `formation eval`): one lockstep run of case 1 with
/// `formation eval --processes --transport zenoh --listen E` (the world listening on E, three
/// local agents connecting with fresh credentials) writes the same `--json` as in-process
/// `formation eval`, key for key; the same evaluation with E's port taken fails to listen there
/// (so the flags are used); and the evaluations leave nothing in their temporary folder
/// (`TMPDIR`, where the work folder, its credentials and the run's lock live).
#[test]
fn eval_over_zenoh_writes_the_same_json_as_in_process() {
    let t = ProcessTest::start("zenoh_eval_json", LIMIT);
    let scenario = t.case1(10.0);
    let tmp = t.path().join("tmp");
    std::fs::create_dir_all(&tmp).expect("the evaluation's TMPDIR");
    let listen = t.endpoint();
    let eval = |extra: &[&str], json: &Path| {
        let mut command = policy_eval(&scenario, test_model(), json);
        command.env("TMPDIR", &tmp).args(extra);
        run(command, LIMIT)
    };
    let in_process_json = t.path().join("in-process.json");
    eval(&[], &in_process_json).assert_success();
    let zenoh_json = t.path().join("zenoh.json");
    let over_zenoh = eval(
        &["--processes", "--transport", "zenoh", "--listen", &listen],
        &zenoh_json,
    );
    over_zenoh.assert_success();
    let in_process = read_json(&in_process_json);
    let over = read_json(&zenoh_json);
    let keys = in_process.as_object().expect("eval JSON is an object");
    assert!(keys.contains_key("per_run") && keys.contains_key("success_rate_5"));
    assert_eq!(
        in_process["per_run"].as_array().map(Vec::len),
        Some(1),
        "one run"
    );
    for (key, value) in keys {
        assert_eq!(
            &over[key],
            value,
            "{key} differs between Zenoh and in-process\n{}",
            over_zenoh.describe()
        );
    }
    // The flags are not ignored: with its port taken, the same evaluation cannot listen there.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("binding a port");
    let busy = endpoint(taken.local_addr().expect("its address").port());
    eval(
        &["--processes", "--transport", "zenoh", "--listen", &busy],
        &t.path().join("busy.json"),
    )
    .assert_failure_mentioning(&format!("zenoh could not listen on {busy}"));
    drop(taken);
    let over_keys: Vec<&String> = over.as_object().expect("an object").keys().collect();
    assert_eq!(
        over_keys,
        keys.keys().collect::<Vec<_>>(),
        "the same keys in both"
    );
    // What is left: at most the folder that holds every run's iceoryx2 root and lock, which
    // stays, empty.
    let files_in = |dir: &Path| -> Vec<std::path::PathBuf> {
        std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
            .flatten()
            .map(|entry| entry.path())
            .collect()
    };
    let base = tmp.join("iceoryx2-formation");
    let mut left: Vec<_> = files_in(&tmp).into_iter().filter(|p| *p != base).collect();
    if base.is_dir() {
        left.extend(files_in(&base));
    }
    assert!(
        left.is_empty(),
        "the evaluation left files behind: {left:?}"
    );
}

/// An agent pointed at an endpoint where nothing listens fails, naming the endpoint.
#[test]
fn an_agent_with_an_unreachable_endpoint_names_it() {
    let t = ProcessTest::start("zenoh_unreachable", LIMIT);
    let nowhere = t.endpoint();
    let mut agent = remote_zenoh_agent(&nowhere, &t.run, 0);
    agent.args(["--connect-timeout-ms", "1500"]);
    run_with_input(agent, Some(&launch_secret().to_line()), LIMIT)
        .assert_failure_mentioning(&format!("cannot reach the world at {nowhere}"));
}

/// `--remote` naming a robot the scenario lacks is refused before anything starts; so are Zenoh's
/// flags on the iceoryx2 transport and an endpoint that is not tcp/HOST:PORT; `formation eval`
/// refuses `--transport zenoh` without `--processes`, `--listen` without `--transport zenoh`,
/// and Zenoh without `--listen`.
#[test]
fn bad_zenoh_flags_are_refused_with_the_reason() {
    let t = ProcessTest::start("zenoh_bad_flags", LIMIT);
    let scenario = t.case1(1.0);
    let out = t.out();
    let listen = t.endpoint();
    let cases: [(&[&str], &str); 4] = [
        (
            &[
                "--transport",
                "zenoh",
                "--listen",
                &listen,
                "--remote",
                "1,7",
            ],
            "--remote 7: the scenario has 3 robots",
        ),
        (&["--remote", "1"], "--remote needs --transport zenoh"),
        (
            &["--transport", "zenoh"],
            "--transport zenoh needs --listen",
        ),
        (
            &[
                "--transport",
                "zenoh",
                "--listen",
                "127.0.0.1:7447",
                "--remote",
                "1",
            ],
            "not a Zenoh TCP endpoint",
        ),
    ];
    for (flags, needle) in cases {
        let (run_id, _leaks) = t.another_run("zflag");
        run(formation_run(&run_id, &scenario, &out, flags), LIMIT)
            .assert_failure_mentioning(needle);
    }
    let eval_cases: [(&[&str], &str); 3] = [
        (
            &["--transport", "zenoh", "--listen", &listen],
            "--transport zenoh joins the world and agent processes, and an evaluation without \
             --processes runs every robot in this process: add --processes",
        ),
        (
            &["--processes", "--listen", &listen],
            "--listen needs --transport zenoh or ros2 (the transport is iceoryx2)",
        ),
        (
            &["--processes", "--transport", "zenoh"],
            "--transport zenoh needs --listen",
        ),
    ];
    for (flags, needle) in eval_cases {
        let mut eval = Command::new(&binaries().cli);
        eval.args(["eval", "--runs", "1", "--scenario"])
            .arg(&scenario)
            .arg("--model")
            .arg(test_model())
            .args(flags);
        run(eval, LIMIT).assert_failure_mentioning(needle);
    }
    let mut agent = Command::new(&binaries().agent);
    agent
        .args([
            "--connect",
            &listen,
            "--run-id",
            "x1",
            "--robot",
            "0",
            "--model",
        ])
        .arg(test_model());
    run(agent, LIMIT).assert_failure_mentioning("--connect needs --transport zenoh");
}

/// Issue 13 (remote agents, access control): with `formation credentials`, a launch whose robot 2
/// is remote waits for it; meanwhile a client without a login is refused, and a client holding
/// robot 1's login receives robot 1's scans but none of robot 2's and cannot greet as robot 2;
/// then the remote agent, started by hand with robot-2.json, joins and the run completes.
#[test]
fn a_remote_agent_joins_with_its_credentials_and_an_impostor_gets_nothing() {
    use std::sync::atomic::Ordering;
    use zenoh::Wait;
    let t = ProcessTest::start("zenoh_remote_and_impostor", LIMIT);
    let scenario = t.case1(4.0);
    let creds = zenoh_credentials(t.path(), 3);
    let listen = t.endpoint();
    let launch = t.launch_awaiting_remote(&scenario, &listen, 2, &creds, &["--clock", "realtime"]);
    // Robots 0 and 1 are local and connect; give them time to be admitted.
    std::thread::sleep(Duration::from_secs(3));

    // No login: the router refuses the connection.
    assert!(
        raw_client(&listen, None).is_err(),
        "a client without credentials must be refused"
    );
    // Robot 1's login: its own robot's keys only.
    let robot1 = formation_transport_zenoh::credentials::read_login(&creds.join("robot-1.json"))
        .expect("robot 1's login");
    let impostor = raw_client(&listen, Some((robot1.user(), robot1.password())))
        .expect("robot 1's login is a valid login");
    let (_own, own_scans) = count_samples(&impostor, format!("formation/{}/robot/1/*/scan", t.run));
    let (_other, others) = count_samples(&impostor, format!("formation/{}/robot/2/**", t.run));
    let (_all, everything) = count_samples(&impostor, format!("formation/{}/robot/0/**", t.run));
    // A greeting for robot 2 from robot 1's login, from a session of its own (a session hands
    // its own puts to its own subscribers): the router drops it, so the world never even
    // refuses it.
    let forger = raw_client(&listen, Some((robot1.user(), robot1.password())))
        .expect("robot 1's login is a valid login");
    forger
        .put(format!("formation/{}/robot/2/hello", t.run), vec![0u8; 48])
        .wait()
        .expect("the put leaves the client");

    // The remote agent, started by hand as on another host, with robot 2's credentials only.
    let mut agent = remote_zenoh_agent(&listen, &t.run, 2);
    agent.arg("--credentials").arg(creds.join("robot-2.json"));
    let finished = finish_with_remote_agent(launch, agent, LIMIT);
    finished.assert_holds(
        own_scans.load(Ordering::Relaxed) > 0,
        "robot 1's login may read robot 1's scans (so the subscription works)",
    );
    assert_none_counted(&[
        (&others, "robot 1's login received robot 2's traffic"),
        (&everything, "robot 1's login received robot 0's traffic"),
    ]);
    finished.assert_holds(
        !finished.stderr().contains("refused process"),
        "nobody greeted as robot 2 but its agent",
    );
    drop((impostor, forger));
    t.assert_clean();
}

/// Issue 13 (bad input: wrong or missing credentials): against a launch whose robot 2 is remote,
/// an agent for robot 2 without `--credentials`, or with another run's robot-2.json, is refused
/// by the world's router and says it cannot reach the world, naming the endpoint and the
/// credentials file to use; robot 1's file is refused naming the right one; a missing file is
/// named. Then the agent with the run's robot-2.json joins and the run completes, so the world
/// was reachable all along and the refusals were the logins'.
#[test]
fn an_agent_with_wrong_or_missing_credentials_is_refused_with_the_reason() {
    let t = ProcessTest::start("zenoh_bad_credentials", LIMIT);
    let scenario = t.case1(2.0);
    let creds = zenoh_credentials(t.path(), 3);
    let other_run = t.path().join("other-run");
    let others = zenoh_credentials(&other_run, 3);
    let listen = t.endpoint();
    let launch = t.launch_awaiting_remote(
        &scenario,
        &listen,
        2,
        &creds,
        &["--clock", "lockstep", "--remote-timeout-s", "120"],
    );
    let agent = |credentials: Option<&Path>| {
        let mut agent = remote_zenoh_agent(&listen, &t.run, 2);
        agent.args(["--connect-timeout-ms", "5000"]);
        match credentials {
            Some(file) => {
                agent.arg("--credentials").arg(file);
                agent
            }
            None => agent,
        }
    };
    let unreachable = format!("cannot reach the world at {listen}");
    let use_robot2 = "is --credentials this run's robot-2.json?";
    // No login (the launch secret on standard input, as a local agent gets it).
    run_with_input(agent(None), Some(&launch_secret().to_line()), LIMIT)
        .assert_failure_mentioning(&unreachable)
        .assert_failure_mentioning(use_robot2);
    // Another run's login for robot 2: its password is not in this world's dictionary.
    run(agent(Some(&others.join("robot-2.json"))), LIMIT)
        .assert_failure_mentioning(&unreachable)
        .assert_failure_mentioning(use_robot2);
    // Robot 1's file for robot 2.
    let robot1 = creds.join("robot-1.json");
    run(agent(Some(&robot1)), LIMIT).assert_failure_mentioning(&format!(
        "{} holds the credentials of robot-1, not of robot 2: use robot-2.json",
        robot1.display()
    ));
    // A file that is not there.
    let missing = creds.join("robot-7.json");
    run(agent(Some(&missing)), LIMIT).assert_failure_mentioning(&format!(
        "cannot read credentials file {}",
        missing.display()
    ));
    // The run's own file: the agent joins and the run completes.
    let finished =
        finish_with_remote_agent(launch, agent(Some(&creds.join("robot-2.json"))), LIMIT);
    finished.assert_holds(
        !finished.stderr().contains("refused process"),
        "the refused logins never reached the world",
    );
    t.assert_clean();
}

/// A remote robot whose agent never comes is named when the wait runs out.
#[test]
fn a_remote_agent_that_never_comes_is_named() {
    let t = ProcessTest::start("zenoh_remote_missing", LIMIT);
    let scenario = t.case1(2.0);
    let listen = t.endpoint();
    let flags = [
        "--transport",
        "zenoh",
        "--listen",
        &listen,
        "--remote",
        "1",
        "--remote-timeout-s",
        "8",
    ];
    run(t.formation_run(&scenario, &flags), LIMIT)
        .assert_failure_mentioning("remote agents of robots [1] did not connect");
    t.assert_clean();
}

/// Issue 13 (swap over the network): `formation swap --transport zenoh` sends the model's bytes
/// (as user operator) and the agent drives with it; a model that is not ONNX is refused by the
/// agent and the old one keeps driving; a model over the 32 MiB limit is refused before it is
/// sent; the operator's credentials are needed. The world's recording stores the model from the
/// bytes that came (its path is the sender's), so the run replays bit for bit with no flag.
#[test]
fn a_swap_over_zenoh_sends_the_model_and_a_refusal_keeps_the_old_one() {
    let t = ProcessTest::start("zenoh_swap", LIMIT);
    let scenario = t.case1(8.0);
    let out = t.out();
    let creds = zenoh_credentials(t.path(), 3);
    let listen = t.endpoint();
    let mut command = t.formation_run(
        &scenario,
        &[
            "--transport",
            "zenoh",
            "--listen",
            &listen,
            "--clock",
            "realtime",
        ],
    );
    command.arg("--credentials").arg(&creds);
    let recording = t.path().join("swapped.mcap");
    command.arg("--record").arg(&recording);
    let mut launch = LiveProcess::spawn(command);
    await_connected(&mut launch);

    let swap = |model: &Path, login: Option<&Path>| {
        let mut command = Command::new(&t.bins().cli);
        command
            .args(["swap", "--transport", "zenoh", "--connect", &listen])
            .args(["--run", t.run.as_str(), "--robot", "1", "--timeout-s", "30"])
            .arg("--model")
            .arg(model);
        if let Some(login) = login {
            command.arg("--credentials").arg(login);
        }
        run(command, LIMIT)
    };
    let operator = creds.join("operator.json");
    let other = t.path().join("other.onnx");
    formation_tests::write_tiny_model(&other, 99);
    let done = swap(&other, Some(&operator));
    done.assert_success();
    assert!(
        done.stdout().contains("robot 1 of run") && done.stdout().contains("drives with model"),
        "{}",
        done.describe()
    );
    let junk = t.path().join("junk.onnx");
    std::fs::write(&junk, b"this is not an ONNX model").unwrap();
    swap(&junk, Some(&operator)).assert_failure_mentioning("swap refused for robot 1");
    let huge = t.path().join("huge.onnx");
    std::fs::File::create(&huge)
        .and_then(|f| f.set_len(33 << 20))
        .expect("a sparse 33 MiB file");
    swap(&huge, Some(&operator)).assert_failure_mentioning("at most 33554432 bytes (32 MiB)");
    swap(&other, None).assert_failure_mentioning("cannot reach the world at");

    let finished = launch.finish(LIMIT);
    finished.assert_success();
    let robot1 = formation_tests::RobotLog::read(&out, 1);
    let models: std::collections::BTreeSet<&String> = robot1.models.iter().collect();
    assert!(
        models.len() >= 2,
        "robot 1 drove with the old model, then the one sent over the network: {models:?}"
    );
    t.assert_clean();
    assert_replays_with_the_stored_swap_model(&recording, t.path());
}

/// `formation replay RECORDING` with no flag: nothing diverged and no step was left undecided,
/// the model swapped in during the run taken from the recording.
fn assert_replays_with_the_stored_swap_model(recording: &Path, dir: &Path) {
    let json = dir.join("replay.json");
    let mut replay = Command::new(&binaries().cli);
    replay.arg("replay").arg(recording).arg("--json").arg(&json);
    run(replay, LIMIT).assert_success();
    let report = read_json(&json);
    assert_eq!(report["diverged"], false, "{report}");
    for row in report["robots"].as_array().unwrap() {
        assert!(row["compared"].as_u64().unwrap() > 0, "{row}");
        assert!(
            row["unreplayable"].as_object().is_none_or(|u| u.is_empty()),
            "{row}"
        );
    }
    assert!(
        report["models"]
            .as_array()
            .unwrap()
            .iter()
            .any(|m| m.as_str().unwrap().contains("stored in the recording")),
        "{report}"
    );
}

/// A `formation-agent` built without the `zenoh` feature (the demo's build), asked for
/// `--transport zenoh`, names the transport and how to build it. The test builds that agent
/// (cargo keeps both builds' artifacts apart by their features) and then restores the tests'
/// build, with Zenoh, in `target/`.
#[test]
fn an_agent_built_without_zenoh_says_how_to_build_it() {
    let t = ProcessTest::start("zenoh_not_built", Duration::from_secs(900));
    let profile = t
        .bins()
        .agent
        .parent()
        .and_then(Path::file_name)
        .and_then(|n| n.to_str())
        .unwrap_or("debug")
        .to_string();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    // The agent as the demo builds it (its package's default features: no Zenoh), then the
    // tests' build again (`cargo runtime-bins`, with Zenoh), which the other tests run.
    let build = |demo: bool| -> Option<std::path::PathBuf> {
        let mut command = Command::new(&cargo);
        command.current_dir(formation_tests::repo_root());
        if demo {
            command
                .args([
                    "build",
                    "-p",
                    "formation-agent-node",
                    "--bin",
                    "formation-agent",
                ])
                .args(["--message-format", "json-render-diagnostics"]);
        } else {
            command.arg("runtime-bins");
        }
        match profile.as_str() {
            "debug" => {}
            "release" => {
                command.arg("--release");
            }
            other => {
                command.args(["--profile", other]);
            }
        }
        let output = command.output().expect("running cargo build");
        assert!(
            output.status.success(),
            "building formation-agent failed:\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
        String::from_utf8_lossy(&output.stdout)
            .lines()
            .filter_map(|line| serde_json::from_str::<serde_json::Value>(line).ok())
            .filter_map(|message| message["executable"].as_str().map(Into::into))
            .next_back()
    };
    let without = build(true).expect("cargo names the executable it built");
    // Cargo's copy in target/<profile>/ is now the build without Zenoh; keep a copy of that
    // one and put the tests' one back before anything else runs an agent.
    let agent = t.path().join("formation-agent");
    std::fs::copy(&without, &agent).expect("copying the agent built without zenoh");
    build(false);
    let mut command = Command::new(&agent);
    command
        .args(["--transport", "zenoh", "--connect", "tcp/127.0.0.1:9"])
        .args(["--run-id", "x1", "--robot", "0", "--model"])
        .arg(test_model());
    run_with_input(command, Some(&launch_secret().to_line()), LIMIT)
        .assert_failure_mentioning("built without the zenoh transport")
        .assert_failure_mentioning("--features zenoh");
}
