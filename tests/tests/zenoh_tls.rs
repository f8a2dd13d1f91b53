//! Zenoh over mutual TLS (issue 36) with real processes and real Zenoh: a team on `tls/` runs
//! lockstep bit for bit as in-process (and, with the world and its agents in two network
//! namespaces, with the in-process Table I JSON); an agent with no certificate, another team's,
//! an expired one or another robot's is refused within seconds, naming the cause, and raw Zenoh
//! clients with such certificates receive nothing; the recorder's certificate reads the run and
//! publishes nothing; and a packet capture of the veth between a robot's namespace and its
//! world's finds no scan or command in clear on `tls/` (and finds them on `tcp/`).
//!
//! Every test uses its own run id, its own free TCP port, its own scratch folder and, across
//! namespaces, its own pair of namespaces (which needs root: where it cannot be made, the test
//! fails with the fix, as in `zenoh_netns.rs`), and runs alone within this binary
//! ([`one_at_a_time`]).

use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, SystemTime};

use formation_cli::launch::read_trajectory;
use formation_proto::wire::{RunId, ScanMsg};
use formation_tests::capture::{PacketCapture, TcpStream as CapturedStream, TcpStreams};
use formation_tests::netns::{AGENTS_IP, NetPair, WORLD_IP};
use formation_tests::tls::raw_tls_client;
use formation_tests::{
    LiveProcess, ProcessTest, TempDir, assert_bit_identical, assert_none_counted, await_line,
    binaries, case1_scenario, finish_with_remote_agent, formation_run_args, free_tcp_port,
    in_process_run, policy_eval, read_json, remote_zenoh_agent, run, test_model, tls_credentials,
};
use formation_transport_zenoh::tls::issue::{Authority, issue_for};
use formation_transport_zenoh::tls::{certificate_file, key_file};
use formation_world::Scenario;
use zenoh::Wait;

const LIMIT: Duration = Duration::from_secs(180);
/// A refused process must end within this (issue 36): the watchdog of each refusal.
const REFUSAL_LIMIT: Duration = Duration::from_secs(10);

fn endpoint(port: u16) -> String {
    format!("tls/127.0.0.1:{port}")
}

/// A folder holding `principal`'s login file from `logins`, and the TLS files given
/// (`(file name, source path)`), for an agent or a raw client made to fail one way.
fn folder_with(
    dir: &Path,
    name: &str,
    principal: &str,
    logins: &Path,
    files: &[(&str, PathBuf)],
) -> PathBuf {
    let folder = dir.join(name);
    std::fs::create_dir_all(&folder).expect("the folder");
    let login = format!("{principal}.json");
    std::fs::copy(logins.join(&login), folder.join(&login)).expect("the login file");
    for (file, source) in files {
        std::fs::copy(source, folder.join(file)).expect("a TLS file");
    }
    folder
}

/// A subscriber of `session` on `key` counting samples whose key contains `marker` (every
/// sample when empty).
fn count_keys(
    session: &zenoh::Session,
    key: String,
    marker: &'static str,
) -> (zenoh::pubsub::Subscriber<()>, Arc<AtomicUsize>) {
    let count = Arc::new(AtomicUsize::new(0));
    let seen = Arc::clone(&count);
    let subscriber = session
        .declare_subscriber(key)
        .callback(move |sample| {
            if sample.key_expr().as_str().contains(marker) {
                seen.fetch_add(1, Ordering::Relaxed);
            }
        })
        .wait()
        .expect("declaring a subscriber");
    (subscriber, count)
}

/// Issue 36: lockstep case 1 over Zenoh on `tls/` (credentials with certificates made by the
/// launcher) reproduces the in-process run bit for bit.
#[test]
fn a_tls_team_runs_lockstep_bit_identical_to_in_process() {
    let t = ProcessTest::start("zenoh_tls_lockstep", LIMIT);
    let finished = t.lockstep_case1_over_zenoh(&endpoint(free_tcp_port()));
    let out = t.out();
    let credentials = out.join("credentials").join(t.run.as_str());
    finished.assert_holds(
        credentials.join("ca.pem").is_file() && credentials.join("world.key.pem").is_file(),
        "the launcher made certificates for a tls/ launch",
    );
    finished.assert_holds(
        !finished.stderr().contains("clear text"),
        "no clear-text warning on TLS",
    );
    t.assert_clean();
}

/// Issue 36: against a TLS team whose robot 1 is remote, an agent for robot 1 with no
/// certificate, another team's credentials, an expired certificate or robot 2's certificate
/// ends within 10 s (the watchdog of `run`) with a non-zero exit naming the cause; raw Zenoh
/// clients with no certificate, another team's, an expired one, or robot 2's on robot 1's keys
/// receive nothing of robot 1; the recorder's certificate reads scans and commands and what it
/// publishes reaches nobody. Then robot 1's own agent joins and the run completes.
#[test]
fn refusals_name_their_cause_within_seconds_and_deliver_nothing() {
    let t = ProcessTest::start("zenoh_tls_refusals", LIMIT);
    let (dir, run_id) = (&t.dir, &t.run);
    let scenario = t.case1(6.0);
    let creds = tls_credentials(dir.path(), "creds", 3);
    let other = tls_credentials(dir.path(), "other", 3);
    let listen = endpoint(free_tcp_port());
    // A robot whose agent never gets through (or is lost) fails the run within the watchdog,
    // with every process's output, rather than leaving the world waiting.
    let launch = t.launch_awaiting_remote(
        &scenario,
        &listen,
        1,
        &creds,
        &["--clock", "realtime", "--remote-timeout-s", "60"],
    );

    // An expired certificate of the team's own authority.
    let now = SystemTime::now();
    let authority = Authority::read(&creds).expect("the team's authority");
    let (expired_pem, expired_key) = issue_for(
        &authority,
        "robot-1",
        now - Duration::from_secs(10 * 86_400),
        1,
    )
    .expect("an expired certificate");
    let expired = folder_with(
        dir.path(),
        "expired",
        "robot-1",
        &creds,
        &[("ca.pem", creds.join("ca.pem"))],
    );
    std::fs::write(expired.join("robot-1.pem"), expired_pem).expect("writing");
    std::fs::write(expired.join("robot-1.key.pem"), expired_key).expect("writing");
    let no_certificate = folder_with(dir.path(), "bare", "robot-1", &creds, &[]);
    let wrong_name = folder_with(
        dir.path(),
        "robot2",
        "robot-1",
        &creds,
        &[
            ("ca.pem", creds.join("ca.pem")),
            ("robot-1.pem", creds.join("robot-2.pem")),
            ("robot-1.key.pem", creds.join("robot-2.key.pem")),
        ],
    );
    let cases: [(&str, &Path, &str); 4] = [
        (
            "no certificate",
            &no_certificate,
            "cannot read the certificate authority",
        ),
        ("another team's", &other, "is not this team's world"),
        ("expired", &expired, "expired on"),
        (
            "robot 2's",
            &wrong_name,
            "this is the certificate of robot-2, not of robot-1",
        ),
    ];
    for (case, folder, cause) in cases {
        let mut agent = remote_zenoh_agent(&listen, run_id, 1);
        agent.arg("--credentials").arg(folder.join("robot-1.json"));
        let refused = run(agent, REFUSAL_LIMIT);
        assert!(
            !refused.output.status.success(),
            "{case}: {}",
            refused.describe()
        );
        refused.assert_holds(
            refused.stderr().contains(cause),
            &format!("{case}: expected {cause:?}"),
        );
    }

    // Raw clients: the world's own refusals, and robot 2's certificate on robot 1's keys.
    let robot1_keys = format!("formation/{run_id}/robot/1/**");
    // A refused client gets no session, or (Zenoh retrying) a session that receives nothing.
    let refused_clients: Vec<_> = [
        ("no certificate", None),
        (
            "another team's certificate",
            Some((other.as_path(), "robot-1")),
        ),
        (
            "an expired certificate",
            Some((expired.as_path(), "robot-1")),
        ),
    ]
    .into_iter()
    .filter_map(|(case, tls)| {
        let session = raw_tls_client(&listen, &creds, "robot-1", tls).ok()?;
        let (subscriber, count) = count_keys(&session, robot1_keys.clone(), "");
        Some((case, session, subscriber, count))
    })
    .collect();
    let robot2 = raw_tls_client(&listen, &creds, "robot-2", Some((&creds, "robot-2")))
        .expect("robot 2's own certificate and login");
    let (_r2, robot2_sees) = count_keys(&robot2, robot1_keys.clone(), "");
    // Robot 2's certificate with robot 1's login: the rules need both to be robot 1's.
    let mixed = raw_tls_client(&listen, &creds, "robot-1", Some((&creds, "robot-2")));
    let mixed_sees = mixed
        .as_ref()
        .ok()
        .map(|s| count_keys(s, robot1_keys.clone(), ""));
    let recorder = raw_tls_client(&listen, &creds, "recorder", Some((&creds, "recorder")))
        .expect("the recorder's certificate and login");
    let (_scans, recorder_scans) =
        count_keys(&recorder, format!("formation/{run_id}/robot/*/*/scan"), "");
    let (_forged, forged_seen) = count_keys(
        &recorder,
        format!("formation/{run_id}/robot/0/*/cmd"),
        "/999999/",
    );
    let publisher = raw_tls_client(&listen, &creds, "recorder", Some((&creds, "recorder")))
        .expect("a second recorder session");
    for _ in 0..20 {
        publisher
            .put(
                format!("formation/{run_id}/robot/0/999999/cmd"),
                vec![0u8; 24],
            )
            .wait()
            .expect("the put leaves the client");
        std::thread::sleep(Duration::from_millis(50));
    }

    let mut agent = remote_zenoh_agent(&listen, run_id, 1);
    agent.arg("--credentials").arg(creds.join("robot-1.json"));
    let finished = finish_with_remote_agent(launch, agent, LIMIT);
    finished.assert_holds(
        recorder_scans.load(Ordering::Relaxed) > 0,
        "the recorder reads scans",
    );
    assert_none_counted(&[
        (&forged_seen, "the recorder published a command"),
        (&robot2_sees, "robot 2's certificate read robot 1's keys"),
    ]);
    for (case, _, _, count) in &refused_clients {
        assert_none_counted(&[(count, &format!("{case} received robot 1's traffic"))]);
    }
    if let Some((_s, count)) = &mixed_sees {
        assert_none_counted(&[(count, "robot 2's certificate with robot 1's login")]);
    }
    drop((
        robot2,
        mixed_sees,
        mixed,
        recorder,
        publisher,
        refused_clients,
    ));
    t.assert_clean();
}

/// Issue 36: `formation credentials --tls` writes private keys in a private folder, and
/// `--renew robot-1` replaces robot 1's certificate only.
#[test]
fn credentials_with_tls_are_private_and_renew_one_principal() {
    use std::os::unix::fs::PermissionsExt;
    let dir = TempDir::new("ztcred");
    let creds = tls_credentials(dir.path(), "creds", 2);
    let mode = |p: &Path| std::fs::metadata(p).expect("a file").permissions().mode() & 0o777;
    assert_eq!(mode(&creds), 0o700);
    for principal in ["world", "robot-0", "robot-1", "operator", "recorder", "ca"] {
        assert_eq!(mode(&key_file(&creds, principal)), 0o600, "{principal}");
        assert!(certificate_file(&creds, principal).is_file(), "{principal}");
    }
    let before = |p: &str| std::fs::read(certificate_file(&creds, p)).expect("a certificate");
    let (world, robot0, robot1) = (before("world"), before("robot-0"), before("robot-1"));
    let mut renew = Command::new(&binaries().cli);
    renew
        .args([
            "credentials",
            "--tls",
            "--renew",
            "robot-1",
            "--valid-days",
            "7",
            "--out",
        ])
        .arg(&creds);
    let renewed = run(renew, Duration::from_secs(60));
    renewed.assert_success();
    assert!(
        renewed.stdout().contains("renewed"),
        "{}",
        renewed.describe()
    );
    assert_ne!(before("robot-1"), robot1);
    assert_eq!(before("world"), world);
    assert_eq!(before("robot-0"), robot0);
    let mut unknown = Command::new(&binaries().cli);
    unknown
        .args(["credentials", "--tls", "--renew", "robot-x", "--out"])
        .arg(&creds);
    run(unknown, Duration::from_secs(60)).assert_failure_mentioning("no principal of a team");
}

/// A distinctive 16-byte window of `scan`'s ranges (four finite ranges, not all equal), if it
/// has one.
fn range_window(scan: &[u8]) -> Option<Vec<u8>> {
    let at = std::mem::offset_of!(ScanMsg, n_beams);
    let beams = u32::from_ne_bytes(scan.get(at..at + 4)?.try_into().ok()?) as usize;
    let ranges = scan.get(std::mem::offset_of!(ScanMsg, ranges)..)?;
    let ranges = ranges.get(..beams * 4)?;
    ranges
        .chunks_exact(4)
        .collect::<Vec<_>>()
        .windows(4)
        .find(|four| {
            let values: Vec<f32> = four
                .iter()
                .map(|b| f32::from_ne_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            values.iter().all(|v| v.is_finite()) && values.iter().any(|v| *v != values[0])
        })
        .map(<[&[u8]]>::concat)
}

/// Robot 1's scans and commands as the recorder read them, and what an eavesdropper on the veth
/// between robot 1's agent and the world read, of one lockstep run on `tcp/` or `tls/`.
struct Eavesdropped {
    streams: TcpStreams,
    scan_windows: Vec<Vec<u8>>,
    commands: Vec<Vec<u8>>,
}

impl Eavesdropped {
    /// The TCP streams that crossed the veth toward the world (`to_world`) or toward the agent.
    fn toward(&self, to_world: bool) -> impl Iterator<Item = &CapturedStream> {
        let (world, agents) = (ipv4(WORLD_IP), ipv4(AGENTS_IP));
        let (from, to) = if to_world {
            (agents, world)
        } else {
            (world, agents)
        };
        self.streams.from_to(from, to)
    }

    /// Whether `pattern` crossed the veth toward the world (`to_world`) or toward the agent.
    fn carried(&self, to_world: bool, pattern: &[u8]) -> bool {
        self.toward(to_world).any(|stream| stream.holds(pattern))
    }

    /// Every payload byte that crossed the veth, both directions, and the capture's gaps.
    fn bytes_and_gaps(&self) -> (usize, usize) {
        self.toward(true)
            .chain(self.toward(false))
            .fold((0, 0), |(bytes, gaps), s| {
                (bytes + s.bytes.len(), gaps + s.gaps)
            })
    }
}

fn ipv4(text: &str) -> Ipv4Addr {
    text.parse().expect("an IPv4 address")
}

/// The bytes of a hexadecimal line of `zenoh-tap`.
fn from_hex(hex: &str) -> Vec<u8> {
    (0..hex.len())
        .step_by(2)
        .map(|at| u8::from_str_radix(&hex[at..at + 2], 16).expect("hexadecimal"))
        .collect()
}

/// A lockstep case 1 of 3 s on `protocol` (`tcp` or `tls`) with the world (and robots 0 and 2)
/// in one network namespace and robot 1's agent in another, joined by a veth: the recorder's
/// certificate reads robot 1's scans and commands from the world's namespace (its own link does
/// not cross the veth), and `packet-capture` records the veth in the agent's.
fn eavesdrop(t: &ProcessTest, protocol: &str, creds: &Path) -> Eavesdropped {
    let pair = namespaces();
    let (run_id, leaks) = t.another_run(&format!("zt{protocol}"));
    let folder = t.folder(protocol);
    let scenario = case1_scenario(&folder, 3.0);
    let out = folder.join("out");
    let (mut launch, listen) = launch_in_world(
        &pair,
        &run_id,
        (&scenario, &out),
        (protocol, "1"),
        // An agent that never gets through fails the run within the watchdog, with its output.
        &["--clock", "lockstep", "--remote-timeout-s", "40"],
        creds,
    );
    await_line(&mut launch, "waiting for the remote agents of robots [1]");
    let robot1 = format!("formation/{run_id}/robot/1/*");
    let mut tap = pair.in_world(Path::new(env!("CARGO_BIN_EXE_zenoh-tap")));
    tap.arg(&listen)
        .arg(creds)
        .arg("recorder")
        .args([format!("{robot1}/scan"), format!("{robot1}/cmd")]);
    let mut tap = LiveProcess::spawn_with_input(tap, Some(""));
    let ready = tap.wait_for_line(Duration::from_secs(60), |l| l == "ready");
    assert!(ready.is_some(), "{}", tap.describe());
    let capture = PacketCapture::start(
        pair.in_agents(Path::new(env!("CARGO_BIN_EXE_packet-capture"))),
        &folder.join("veth.pcap"),
    );
    let mut agent = pair.in_agents(&binaries().agent);
    agent
        .args(["--transport", "zenoh", "--connect", &listen])
        .args(["--run-id", run_id.as_str(), "--robot", "1"])
        .args(["--connect-timeout-ms", "60000", "--model"])
        .arg(test_model())
        .arg("--credentials")
        .arg(creds.join("robot-1.json"));
    let agent = LiveProcess::spawn(agent);
    let finished = launch.finish(Duration::from_secs(80));
    let agent = agent.finish(Duration::from_secs(30));
    assert!(
        finished.output.status.success() && agent.output.status.success(),
        "{protocol}/ across the namespaces\n{}\n{}",
        finished.describe(),
        agent.describe()
    );
    tap.close_input();
    let tapped = tap.finish(Duration::from_secs(30));
    tapped.assert_success();
    let (streams, _) = capture.finish();
    drop(pair);
    leaks.assert_clean();
    let read = |index: &str| -> Vec<Vec<u8>> {
        tapped
            .stdout()
            .lines()
            .filter_map(|line| line.split_once(' '))
            .filter(|(i, _)| *i == index)
            .map(|(_, hex)| from_hex(hex))
            .collect()
    };
    let scan_windows: Vec<_> = read("0")
        .iter()
        .filter_map(|scan| range_window(scan))
        .take(10)
        .collect();
    let commands: Vec<_> = read("1").into_iter().take(10).collect();
    assert!(
        scan_windows.len() >= 5 && commands.len() >= 5,
        "the recorder read {} scan windows and {} commands of robot 1\n{}",
        scan_windows.len(),
        commands.len(),
        tapped.describe()
    );
    Eavesdropped {
        streams,
        scan_windows,
        commands,
    }
}

/// Two network namespaces joined by a veth, or the test fails with the fix (CI runs as root).
fn namespaces() -> NetPair {
    NetPair::create().unwrap_or_else(|reason| {
        panic!(
            "network namespaces are unavailable here ({reason}); run the tests as root with \
             iproute2 and nftables (`bash scripts/setup-system` installs them)"
        )
    })
}

/// `formation run` of `scenario` (run `run_id`, the test model, writing to `out`) started in
/// `pair`'s world namespace over Zenoh on `protocol` (`tcp` or `tls`) at the world's address,
/// the robots `remote` remote, with `extra` flags and the team's credentials in `creds`.
/// Returns the launch and the endpoint it listens on.
fn launch_in_world(
    pair: &NetPair,
    run_id: &RunId,
    (scenario, out): (&Path, &Path),
    (protocol, remote): (&str, &str),
    extra: &[&str],
    creds: &Path,
) -> (LiveProcess, String) {
    let listen = format!("{protocol}/{WORLD_IP}:{}", free_tcp_port());
    let creds_text = creds.to_string_lossy();
    let mut flags = vec![
        "--transport",
        "zenoh",
        "--listen",
        &listen,
        "--remote",
        remote,
    ];
    flags.extend_from_slice(extra);
    flags.extend_from_slice(&["--credentials", &creds_text]);
    let mut command = pair.in_world(&binaries().cli);
    formation_run_args(&mut command, run_id, (scenario, test_model(), out), &flags);
    (LiveProcess::spawn(command), listen)
}

/// Waits for `launch` (in `pair`'s world namespace) to wait for its remote agents, starts the
/// agents of robots 0, 1 and 2 in the agents' namespace (with `extra` flags and their
/// credentials from `creds`), and waits for the launch and then each agent to end successfully.
fn run_team_across(
    pair: &NetPair,
    mut launch: LiveProcess,
    listen: &str,
    run_id: &RunId,
    creds: &Path,
    extra: &[&str],
) {
    await_line(&mut launch, "waiting for the remote agents");
    let agents: Vec<_> = (0..3)
        .map(|robot| {
            let mut agent = pair.in_agents(&binaries().agent);
            agent
                .args(["--transport", "zenoh", "--connect", listen])
                .args(["--run-id", run_id.as_str(), "--robot", &robot.to_string()])
                .args(extra)
                .arg("--model")
                .arg(test_model())
                .arg("--credentials")
                .arg(creds.join(format!("robot-{robot}.json")));
            LiveProcess::spawn(agent)
        })
        .collect();
    launch.finish(LIMIT).assert_success();
    for agent in agents {
        let agent = agent.finish(Duration::from_secs(30));
        agent.assert_success();
    }
}

/// Issue 36 acceptance: a capture of the veth between a robot's agent and its world, in two
/// network namespaces, holds no scan's range bytes and no command in clear on `tls/`; the same
/// capture of a `tcp/` link finds them all (so the check can fail), and both captures are whole
/// (no gap in any TCP stream). Needs root (CI runs as root).
#[test]
fn a_capture_of_a_tls_link_holds_no_scan_or_command_in_clear() {
    let t = ProcessTest::start("zenoh_tls_capture", LIMIT);
    let creds = tls_credentials(t.path(), "creds", 3);

    let plain = eavesdrop(&t, "tcp", &creds);
    let (carried, gaps) = plain.bytes_and_gaps();
    eprintln!("tcp/: {carried} bytes crossed the veth");
    assert_eq!(gaps, 0, "the tcp/ capture is whole");
    for (k, window) in plain.scan_windows.iter().enumerate() {
        assert!(
            plain.carried(false, window),
            "tcp/: scan window {k} in clear"
        );
    }
    for (k, command) in plain.commands.iter().enumerate() {
        assert!(plain.carried(true, command), "tcp/: command {k} in clear");
    }

    let sealed = eavesdrop(&t, "tls", &creds);
    let (carried, gaps) = sealed.bytes_and_gaps();
    eprintln!("tls/: {carried} bytes crossed the veth");
    assert_eq!(gaps, 0, "the tls/ capture is whole");
    let scan_bytes = std::mem::size_of::<ScanMsg>() * sealed.scan_windows.len();
    assert!(
        carried > scan_bytes,
        "the tls/ link carried the run across the veth ({carried} bytes)"
    );
    for (k, window) in sealed.scan_windows.iter().enumerate() {
        for to_world in [false, true] {
            assert!(
                !sealed.carried(to_world, window),
                "tls/: scan window {k} in clear"
            );
        }
    }
    for (k, command) in sealed.commands.iter().enumerate() {
        for to_world in [false, true] {
            assert!(
                !sealed.carried(to_world, command),
                "tls/: command {k} in clear"
            );
        }
    }
}

/// Issue 36 acceptance: a TLS team across two network namespaces (the world in one, its three
/// agents in the other, joined only by a veth pair) runs case 1 in lockstep with the same
/// Table I JSON as `formation eval` in-process, and the same trajectory bit for bit. Needs root
/// (CI runs as root).
#[test]
fn a_tls_team_across_namespaces_gives_the_in_process_table() {
    let t = ProcessTest::start("zenoh_tls_netns", LIMIT);
    let pair = namespaces();
    let creds = tls_credentials(t.path(), "creds", 3);
    let scenario_path = t.case1(6.0);
    let out = t.out();
    let (launch, listen) = launch_in_world(
        &pair,
        &t.run,
        (&scenario_path, &out),
        ("tls", "0,1,2"),
        &["--remote-timeout-s", "120", "--clock", "lockstep"],
        &creds,
    );
    run_team_across(
        &pair,
        launch,
        &listen,
        &t.run,
        &creds,
        &["--connect-timeout-ms", "60000"],
    );
    let eval_json = t.path().join("in-process.json");
    run(policy_eval(&scenario_path, test_model(), &eval_json), LIMIT).assert_success();
    let in_process = read_json(&eval_json);
    let over_tls = read_json(&out.join("summary.json"));
    let keys = in_process.as_object().expect("eval JSON is an object");
    assert!(keys.contains_key("per_run") && keys.contains_key("success_rate_5"));
    for (key, value) in keys {
        assert_eq!(
            &over_tls[key], value,
            "{key} differs between TLS across namespaces and in-process"
        );
    }
    let scenario = Scenario::from_path(&scenario_path).expect("scenario");
    let reference = in_process_run(&scenario, 0);
    let over_tls = read_trajectory(&out.join("runs").join("run-0000.json")).expect("the run log");
    assert_bit_identical(&over_tls, &reference);
    drop(pair);
    t.assert_clean();
}

/// Issue 36's cost of TLS, measured (not a test: it asserts no time, and runs only when asked,
/// as root): a realtime case 1 of 20 s with the world in one network namespace and its three
/// agents in another, on `tcp/` and on `tls/` in turn, twice each; prints the world's round trip
/// (scan published to command received) p50 and p99 of each run.
///
/// `cargo test -p formation-tests --test zenoh_tls -- --ignored --nocapture round_trip`
#[test]
#[ignore = "a measurement: run it by name with --ignored --nocapture"]
fn tls_round_trip_against_plain_tcp_across_namespaces() {
    // Four realtime runs of 20 s.
    let t = ProcessTest::start("ztrtt", 4 * LIMIT);
    let pair = namespaces();
    let creds = tls_credentials(t.path(), "creds", 3);
    let scenario = t.case1(20.0);
    for round in 0..2 {
        for protocol in ["tcp", "tls"] {
            let (run_id, _leaks) = t.another_run(&format!("rtt{protocol}"));
            let out = t.path().join(format!("{protocol}-{round}"));
            let (launch, listen) = launch_in_world(
                &pair,
                &run_id,
                (&scenario, &out),
                (protocol, "0,1,2"),
                &["--clock", "realtime"],
                &creds,
            );
            run_team_across(&pair, launch, &listen, &run_id, &creds, &[]);
            let profile = read_json(&out.join("profile.json"));
            let round_trip = &profile["stages"]["round_trip"];
            eprintln!(
                "round {round} {protocol}/: round trip p50 {} us, p99 {} us",
                round_trip["p50_us"], round_trip["p99_us"]
            );
        }
    }
}
