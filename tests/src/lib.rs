//! Helpers shared by the multi-process integration tests: unique iceoryx2 namespaces, a
//! shared-memory leak check, a watchdog against hung tests, the runtime executables, a test
//! model, and a process fixture that prints the command, stdout and stderr when a check fails.
//!
//! How the tests get the executables: integration tests can only name binaries of their own
//! package (`CARGO_BIN_EXE_*`), and `formation`, `formation-world` and `formation-agent` live in
//! packages of their own (`formation-cli`, `formation-world-node`, `formation-agent-node`, the
//! workspace's default members: `cargo build` builds the three). [`binaries`] therefore builds
//! them once per test process, in the same profile as the test itself (a no-op when they are up
//! to date), and takes them from `target/<profile>/`, the directory above the test executable.
//! Set `FORMATION_TESTS_NO_BUILD=1` to skip the build (e.g. when the binaries were built
//! beforehand). The build is `cargo runtime-bins`, an alias in `.cargo/config.toml`: the same
//! three binaries, with every transport and the live view (formation-tests turns on
//! formation-cli's features, which turn on the processes' own), built as part
//! of what `cargo test --workspace` builds, test targets included, because only with the
//! dev-dependencies in the build are features resolved as the tests resolve them (`cargo build
//! --features zenoh` alone gives `bitflags`, `zerocopy` and `regex-automata` other features and
//! compiles much of the dependency graph, Zenoh included, a second time). After `cargo test --workspace` it is a no-op; from a single test on a
//! stale target it compiles the other test targets too. `scripts/test-all` runs it first, and no
//! [`Watchdog`] counts the time a test waits for this one-time setup (or for the test model): a
//! slow build is not a hung test.
//!
//! [`netns`] makes network namespaces for the Zenoh tests across a network; the `delay-relay`
//! binary of this package delays TCP between them, and [`capture`] with the `packet-capture`
//! binary reads what crosses the link (no tcpdump needed); [`tls`] is the raw Zenoh client of a
//! TLS team that the `zenoh-tap` binary and the TLS tests use. [`ros2`] is what the ROS 2 tests
//! share: the agent's decision computed in the test's process, the scans they send, the client's
//! JSON.
//!
//! How the tests get a model: `FORMATION_TEST_MODEL` if set; else `tests/fixtures/tiny_policy.py`
//! writes a contract-conforming ONNX model with seeded random weights, run with
//! `FORMATION_PYTHON` or `<repo>/.venv/bin/python` (it needs the `onnx` package only), into
//! `target/formation-test-models/` under a name taken from the script's bytes, so that every test
//! process of a build shares one model.
//!
//! How the tests share the machine: `scripts/test-all` runs them with cargo-nextest, one process
//! per test, two at a time on two cores, with the tests that rebuild the binaries alone
//! (`.config/nextest.toml`). Under plain `cargo test`, [`one_at_a_time`] still runs a binary's
//! multi-process tests one by one.

pub mod capture;
pub mod netns;
pub mod process_test;
pub mod relay;
pub mod ros2;
pub mod tls;

pub use process_test::ProcessTest;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use formation_proto::wire::RunId;
pub use formation_runtime::auth::LaunchSecret;
pub use formation_test_kit::{
    SharedSetup, TempDir, Watchdog, assert_port_free, free_tcp_port, make_fifo, one_at_a_time,
    unique_run_id,
};
use formation_transport_iceoryx2::naming::RunNamespace;
use formation_world::Trajectory;

/// The repository root (the parent of this crate's directory).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// The shipped default model (`onnx/models/policy.onnx`): the pair network of issue 34,
/// detected neighbours in, a formation velocity out; it reads no image.
pub fn shipped_model() -> PathBuf {
    repo_root().join("onnx/models/policy.onnx")
}

/// The previous default (issue 22), kept for what only an image network covers: an image
/// network that answers wheel speeds (`onnx/models/wide-head/policy.onnx`).
pub fn image_model() -> PathBuf {
    repo_root().join("onnx/models/wide-head/policy.onnx")
}

/// Checks that a run leaves no iceoryx2 files behind: asserts nothing of the run exists when
/// created, and [`LeakCheck::assert_clean`] asserts the same at the end. The check is exact
/// because every file of a run carries the run's own prefix or lives under its own root.
pub struct LeakCheck {
    namespace: RunNamespace,
}

impl LeakCheck {
    /// Starts the check for `run`.
    pub fn new(run: &RunId) -> LeakCheck {
        let namespace = RunNamespace::new(run);
        let before = namespace.leftovers();
        assert!(
            before.is_empty(),
            "run {run} has files before it started: {before:?}"
        );
        LeakCheck { namespace }
    }

    /// The run's namespace.
    pub fn namespace(&self) -> &RunNamespace {
        &self.namespace
    }

    /// What the run has left now.
    pub fn leftovers(&self) -> Vec<PathBuf> {
        self.namespace.leftovers()
    }

    /// Panics listing the run's shared-memory files if any exist but iceoryx2's management
    /// segment of the namespace, which stays after every node of the run closed cleanly (by
    /// design, across nodes) until the launcher removes the namespace.
    pub fn assert_only_management_left(&self) {
        let shm = self.namespace.shared_memory_but_management();
        assert!(
            shm.is_empty(),
            "shared memory left after a clean exit: {shm:#?}"
        );
    }

    /// Panics listing the run's files if any exist (its lock file included).
    pub fn assert_clean(&self) {
        let mut left = self.leftovers();
        let lock = self.namespace.lock_path();
        if lock.exists() {
            left.push(lock);
        }
        assert!(
            left.is_empty(),
            "run {} left files behind: {left:#?}",
            self.namespace.run()
        );
    }
}

impl Drop for LeakCheck {
    fn drop(&mut self) {
        // Never leak into other tests, even when this one failed.
        let _ = self.namespace.remove_all();
    }
}

/// Paths of the three executables the runtime tests start.
#[derive(Debug, Clone)]
pub struct Binaries {
    /// `formation`.
    pub cli: PathBuf,
    /// `formation-world`.
    pub world: PathBuf,
    /// `formation-agent`.
    pub agent: PathBuf,
}

/// The executables, built once per test process (see the module docs).
pub fn binaries() -> &'static Binaries {
    static BINARIES: OnceLock<Binaries> = OnceLock::new();
    BINARIES.get_or_init(|| {
        let _setup = SharedSetup::begin();
        let exe = std::env::current_exe().expect("test executable path");
        let deps = exe.parent().expect("test executable directory");
        let profile_dir = deps
            .parent()
            .expect("target/<profile> directory")
            .to_path_buf();
        if std::env::var_os("FORMATION_TESTS_NO_BUILD").is_none() {
            build_binaries(&profile_dir);
        }
        let bin = |name: &str| {
            let path = profile_dir.join(name);
            assert!(
                path.is_file(),
                "{} is missing: build it with `cargo runtime-bins`",
                path.display()
            );
            path
        };
        Binaries {
            cli: bin("formation"),
            world: bin("formation-world"),
            agent: bin("formation-agent"),
        }
    })
}

fn build_binaries(profile_dir: &Path) {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let profile = profile_dir
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("debug");
    let mut command = Command::new(cargo);
    // The alias is defined in `.cargo/config.toml`, shared with scripts/test-all.
    command.current_dir(repo_root()).arg("runtime-bins");
    match profile {
        "debug" => {}
        "release" => {
            command.arg("--release");
        }
        other => {
            command.args(["--profile", other]);
        }
    }
    let output = command
        .output()
        .expect("running cargo build for the runtime binaries");
    assert!(
        output.status.success(),
        "building the runtime binaries failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The ONNX model the runtime tests use (see the module docs), written once per test build.
pub fn test_model() -> &'static Path {
    static MODEL: OnceLock<PathBuf> = OnceLock::new();
    MODEL.get_or_init(|| {
        if let Some(path) = std::env::var_os("FORMATION_TEST_MODEL") {
            return PathBuf::from(path);
        }
        let exe = std::env::current_exe().expect("test executable path");
        let target = exe
            .ancestors()
            .nth(3)
            .map(Path::to_path_buf)
            .unwrap_or_else(std::env::temp_dir);
        let dir = target.join("formation-test-models");
        std::fs::create_dir_all(&dir).expect("creating the test model directory");
        // Named after the script's bytes: test processes (nextest runs one per test) share the
        // model its current version writes, and an edited script writes a new one.
        let script = std::fs::read(repo_root().join(TINY_POLICY_SCRIPT))
            .expect("reading the tiny policy script");
        let path = dir.join(format!("tiny-seed0-{:016x}.onnx", content_key(&script)));
        if !path.is_file() {
            let _setup = SharedSetup::begin();
            write_tiny_model(&path, 0);
        }
        path
    })
}

/// The script that writes the tests' ONNX models, relative to the repository root.
const TINY_POLICY_SCRIPT: &str = "tests/fixtures/tiny_policy.py";

/// A key of `bytes` that is stable within one build of the tests (std's SipHash, fixed keys).
fn content_key(bytes: &[u8]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::hash::DefaultHasher::new();
    bytes.hash(&mut hasher);
    hasher.finish()
}

/// Writes a contract-conforming ONNX model with seeded random weights to `path`.
pub fn write_tiny_model(path: &Path, seed: u64) {
    write_tiny_model_with(path, seed, &[]);
}

/// Like [`write_tiny_model`], with extra arguments for `tiny_policy.py` (e.g. `--aux-width 3`
/// for a model of the wrong input shape, `--beams 450` for one made for another sensor).
pub fn write_tiny_model_with(path: &Path, seed: u64, extra: &[&str]) {
    let python = python();
    let script = repo_root().join(TINY_POLICY_SCRIPT);
    let tmp = path.with_extension(format!("tmp-{}.onnx", std::process::id()));
    let output = Command::new(&python)
        .arg(&script)
        .arg(&tmp)
        .arg("--seed")
        .arg(seed.to_string())
        .args(extra)
        .output()
        .unwrap_or_else(|e| panic!("running {} {}: {e}", python.display(), script.display()));
    assert!(
        output.status.success(),
        "writing the test model failed ({}):\n{}\nset FORMATION_PYTHON to a python with the `onnx` \
         package, or FORMATION_TEST_MODEL to an ONNX policy",
        python.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    std::fs::rename(&tmp, path).expect("moving the test model into place");
}

/// The interpreter the tests run Python with: `FORMATION_PYTHON`, else `<repo>/.venv/bin/python`,
/// else `python3`.
pub fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("FORMATION_PYTHON") {
        return PathBuf::from(p);
    }
    let venv = repo_root().join(".venv/bin/python");
    if venv.is_file() {
        venv
    } else {
        PathBuf::from("python3")
    }
}

/// The exit status of the independent Python tools (`tests/python/*.py`) for a missing package.
pub const PYTHON_MISSING_PACKAGE: i32 = 3;

/// The JSON an independent Python tool printed on stdout, once `finished`; fails the test with
/// its words (and the fix, for a missing package). `tool` names it in the messages.
pub fn printed_json(finished: &Finished, tool: &str) -> serde_json::Value {
    assert_ne!(
        finished.output.status.code(),
        Some(PYTHON_MISSING_PACKAGE),
        "{tool} lacks a package: run `bash .ci/setup-python --test`\n{}",
        finished.describe()
    );
    finished.assert_success();
    serde_json::from_str(finished.stdout().trim())
        .unwrap_or_else(|e| panic!("{tool} printed no JSON ({e})\n{}", finished.describe()))
}

/// Runs the independent MCAP readers, `tests/python/mcap_readers.py ARGS` (Python's `mcap` with
/// `mcap-ros2-support`, `rosbags`, Rerun; none of formation's code), and returns the JSON they
/// print; fails the test with the readers' words (and the fix, for a missing package).
pub fn mcap_readers(args: &[&std::ffi::OsStr]) -> serde_json::Value {
    let mut command = Command::new(python());
    command
        .arg(repo_root().join("tests/python/mcap_readers.py"))
        .args(args);
    printed_json(
        &run(command, Duration::from_secs(300)),
        "the independent MCAP readers",
    )
}

/// The paper's case 1 shortened to `duration_s`, as a scenario file in `dir`.
pub fn case1_scenario(dir: &Path, duration_s: f64) -> PathBuf {
    let text = std::fs::read_to_string(repo_root().join("scenarios/case1.toml"))
        .expect("reading case1.toml");
    let text: String = text
        .lines()
        .map(|line| {
            if line.trim_start().starts_with("duration_s") {
                format!("duration_s = {duration_s:?}")
            } else {
                line.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let path = dir.join("case1-short.toml");
    std::fs::write(&path, text).expect("writing the scenario");
    path
}

/// `formation-agent --transport zenoh --connect LISTEN --run-id RUN --robot ROBOT --model
/// <test model>`: robot `robot`'s agent started by hand, as on another host (the caller adds
/// its credentials and any other flag).
pub fn remote_zenoh_agent(listen: &str, run: &RunId, robot: usize) -> Command {
    let mut agent = Command::new(&binaries().agent);
    agent
        .args(["--transport", "zenoh", "--connect", listen])
        .args(["--run-id", run.as_str(), "--robot", &robot.to_string()])
        .arg("--model")
        .arg(test_model());
    agent
}

/// Holds a launch before its first tick until the test says go: an agent executable (a shell
/// script) that waits until the file `gate` exists and then becomes the real `formation-agent`
/// (`exec`, so the launcher's pid and pipes are the agent's). A launch whose
/// `FORMATION_AGENT_BIN` is [`AgentGate::bin`] waits for its agents, as it does for remote ones
/// (`--remote`), until [`AgentGate::open`]: how a test attaches something (a recorder) to a team
/// whose transport has no remote agents (ROS 2) before it plays.
pub struct AgentGate {
    script: PathBuf,
    gate: PathBuf,
}

impl AgentGate {
    /// The gated agent's script in `dir`, the gate closed.
    pub fn new(dir: &Path) -> AgentGate {
        use std::os::unix::fs::PermissionsExt;
        let script = dir.join("gated-agent.sh");
        let gate = dir.join("agent-gate-open");
        let text = format!(
            "#!/bin/sh\nwhile [ ! -e '{}' ]; do sleep 0.05; done\nexec '{}' \"$@\"\n",
            gate.display(),
            binaries().agent.display()
        );
        std::fs::write(&script, text).expect("writing the gated agent's script");
        std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755))
            .expect("making the gated agent's script executable");
        AgentGate { script, gate }
    }

    /// The executable to give the launcher as `FORMATION_AGENT_BIN`.
    pub fn bin(&self) -> &Path {
        &self.script
    }

    /// Lets the agents start.
    pub fn open(&self) {
        std::fs::write(&self.gate, "").expect("opening the agents' gate");
    }

    /// Starts the launch `command` with its agents held at this gate (`FORMATION_AGENT_BIN`, then
    /// `--record RECORDING`: the world's own recording of the run).
    pub fn spawn_recording(&self, mut command: Command, recording: &Path) -> LiveProcess {
        command
            .arg("--record")
            .arg(recording)
            .env("FORMATION_AGENT_BIN", &self.script);
        LiveProcess::spawn(command)
    }
}

/// Waits for `formation record --connect` to say that it connected to run `run`.
pub fn await_recorder_connected(recorder: &mut LiveProcess, run: &RunId) {
    await_line(recorder, &format!("connected to run {run}"));
}

/// Waits (60 s) for a recorder attached before the first tick to end successfully, having
/// recorded run 0 from its start (not "joined late").
pub fn assert_recorded_from_the_start(recorder: LiveProcess) {
    let recorded = recorder.finish(Duration::from_secs(60));
    recorded.assert_success();
    assert!(
        recorded.stdout().contains("recorded run 0 to")
            && !recorded.stdout().contains("joined late"),
        "{}",
        recorded.describe()
    );
}

/// A 10 s case-1 `formation run --clock CLOCK --record FILE` over processes (the test model's
/// agents), in `dir` under a run id tagged `tag`; fails the test unless it succeeds and leaves
/// no shared memory behind. Returns the scenario file it ran.
pub fn record_case1_over_processes(dir: &Path, tag: &str, clock: &str, file: &Path) -> PathBuf {
    let scenario = case1_scenario(dir, 10.0);
    let run_id = unique_run_id(tag);
    let leaks = LeakCheck::new(&run_id);
    let mut command = formation_run(
        &run_id,
        &scenario,
        &dir.join(format!("{tag}-out")),
        &["--clock", clock],
    );
    command.arg("--record").arg(file);
    run(command, std::time::Duration::from_secs(300)).assert_success();
    leaks.assert_clean();
    scenario
}

/// `formation replay FILE ARGS --json JSON`, run to completion.
pub fn replay(file: &Path, args: &[&str], json: &Path) -> Finished {
    let mut command = Command::new(&binaries().cli);
    command
        .arg("replay")
        .arg(file)
        .args(args)
        .arg("--json")
        .arg(json);
    run(command, Duration::from_secs(300))
}

/// `formation report FOLDER --out HTML`: the report of the eval or run outputs in `folder`.
pub fn report_command(folder: &Path, html: &Path) -> Command {
    let mut command = Command::new(&binaries().cli);
    command.arg("report").arg(folder).arg("--out").arg(html);
    command
}

/// The steps a replay report ([`replay`]'s JSON) compared, over all its robots.
pub fn compared_steps(report: &serde_json::Value) -> u64 {
    report["robots"]
        .as_array()
        .map_or(0, |r| r.iter().filter_map(|r| r["compared"].as_u64()).sum())
}

/// `formation eval` in-process with `args` (one run, its trajectory kept), recording into the
/// folder `record` and writing its outputs to `out`.
pub fn eval_recorded(args: &[&str], record: &Path, out: &Path) -> Finished {
    let mut command = Command::new(&binaries().cli);
    command
        .arg("eval")
        .args(args)
        .args(["--runs", "1", "--save-trajectories", "1"])
        .arg("--record")
        .arg(record)
        .arg("--out")
        .arg(out);
    run(command, Duration::from_secs(300))
}

/// A finished child process, with what it printed.
pub struct Finished {
    /// The command line, for messages.
    pub command: String,
    /// Its output.
    pub output: Output,
    /// How long it ran.
    pub elapsed: Duration,
}

impl Finished {
    /// Its stdout as text.
    pub fn stdout(&self) -> String {
        String::from_utf8_lossy(&self.output.stdout).into_owned()
    }

    /// Its stderr as text.
    pub fn stderr(&self) -> String {
        String::from_utf8_lossy(&self.output.stderr).into_owned()
    }

    /// Everything needed to understand a failure.
    pub fn describe(&self) -> String {
        format!(
            "command: {}\nstatus: {} after {:.2} s\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.command,
            self.output.status,
            self.elapsed.as_secs_f64(),
            self.stdout(),
            self.stderr()
        )
    }

    /// Panics with [`Finished::describe`] unless it exited with success.
    pub fn assert_success(&self) -> &Self {
        assert!(
            self.output.status.success(),
            "expected success\n{}",
            self.describe()
        );
        self
    }

    /// Panics with `why` and [`Finished::describe`] unless `holds`: a check of what it did.
    #[track_caller]
    pub fn assert_holds(&self, holds: bool, why: &str) -> &Self {
        assert!(holds, "{why}\n{}", self.describe());
        self
    }

    /// Panics with `why` and [`Finished::describe`] if it exited with success.
    #[track_caller]
    pub fn assert_failed(&self, why: &str) -> &Self {
        self.assert_holds(!self.output.status.success(), why)
    }

    /// Panics with [`Finished::describe`] unless it failed with stderr containing `needle`.
    pub fn assert_failure_mentioning(&self, needle: &str) -> &Self {
        self.assert_failed("expected failure");
        assert!(
            self.stderr().contains(needle),
            "stderr should mention {needle:?}\n{}",
            self.describe()
        );
        self
    }

    /// Panics with [`Finished::describe`] unless its stdout contains `needle`.
    pub fn assert_stdout_has(&self, needle: &str) -> &Self {
        assert!(self.stdout().contains(needle), "{}", self.describe());
        self
    }

    /// Panics with [`Finished::describe`] unless its stderr contains `needle`.
    pub fn assert_stderr_has(&self, needle: &str) -> &Self {
        assert!(self.stderr().contains(needle), "{}", self.describe());
        self
    }

    /// Panics with `why` and [`Finished::describe`] unless its stderr contains every one of
    /// `needles`.
    #[track_caller]
    pub fn assert_stderr_has_all(&self, needles: &[&str], why: &str) -> &Self {
        let stderr = self.stderr();
        self.assert_holds(needles.iter().all(|needle| stderr.contains(needle)), why)
    }

    /// Panics with [`Finished::describe`] if its stderr contains `needle`.
    pub fn assert_stderr_lacks(&self, needle: &str) -> &Self {
        assert!(!self.stderr().contains(needle), "{}", self.describe());
        self
    }

    /// Panics with [`Finished::describe`] unless it exited with `code`.
    pub fn assert_exit(&self, code: i32) -> &Self {
        assert_eq!(self.output.status.code(), Some(code), "{}", self.describe());
        self
    }

    /// Panics with [`Finished::describe`] if it panicked: exit code 101, or `panicked` on stderr.
    /// A panic is never an error message.
    pub fn assert_no_panic(&self) -> &Self {
        assert_ne!(
            self.output.status.code(),
            Some(101),
            "a panic is not an error message\n{}",
            self.describe()
        );
        self.assert_stderr_lacks("panicked")
    }
}

/// `formation eval --controller expert --runs 1 --scenario SCENARIO EXTRA`: one expert run of
/// `scenario`.
pub fn expert_eval_once(scenario: &Path, extra: &[&str]) -> Command {
    let mut command = Command::new(&binaries().cli);
    command
        .args([
            "eval",
            "--controller",
            "expert",
            "--runs",
            "1",
            "--scenario",
        ])
        .arg(scenario)
        .args(extra);
    command
}

/// Runs `command` to completion (killing it after `limit`) and captures its output.
pub fn run(command: Command, limit: Duration) -> Finished {
    run_with_input(command, None, limit)
}

/// `attempt()` every 200 ms until it succeeds or `limit` has passed (a server that does not
/// listen yet): its success, or its last error.
pub fn retry_for<T, E>(limit: Duration, mut attempt: impl FnMut() -> Result<T, E>) -> Result<T, E> {
    let deadline = Instant::now() + limit;
    loop {
        match attempt() {
            Ok(value) => return Ok(value),
            Err(e) if Instant::now() >= deadline => return Err(e),
            Err(_) => std::thread::sleep(Duration::from_millis(200)),
        }
    }
}

/// The exit of this package's helper binary `tool` from what it ran: success, or its error on
/// stderr (`TOOL: ERROR`) and exit status 2.
pub fn tool_exit(tool: &str, result: Result<(), String>) -> std::process::ExitCode {
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{tool}: {e}");
            std::process::ExitCode::from(2)
        }
    }
}

/// A launch secret for tests that start `formation-world` or `formation-agent` by hand: write
/// [`LaunchSecret::to_line`] as the first line of their standard input.
pub fn launch_secret() -> LaunchSecret {
    LaunchSecret::generate().expect("a launch secret")
}

/// Starts `command` with stdout and stderr piped, and stdin piped when `piped_input` (else
/// empty); returns its command line, for messages, and the child. Panics if it cannot start.
fn spawn_captured(command: &mut Command, piped_input: bool) -> (String, std::process::Child) {
    let text = format!("{command:?}");
    command
        .stdin(if piped_input {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let child = command
        .spawn()
        .unwrap_or_else(|e| panic!("starting {text}: {e}"));
    (text, child)
}

/// [`run`] with `input` written to the command's standard input (then closed).
pub fn run_with_input(mut command: Command, input: Option<&str>, limit: Duration) -> Finished {
    use std::io::Write;
    let started = Instant::now();
    let (text, mut child) = spawn_captured(&mut command, input.is_some());
    if let (Some(input), Some(mut stdin)) = (input, child.stdin.take()) {
        let _ = stdin.write_all(input.as_bytes());
    }
    let id = child.id();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    let output = match rx.recv_timeout(limit) {
        Ok(result) => result.unwrap_or_else(|e| panic!("waiting for {text}: {e}")),
        Err(_) => {
            let _ = Command::new("kill")
                .arg("-KILL")
                .arg(id.to_string())
                .status();
            let output = rx
                .recv()
                .expect("reaping the killed child")
                .expect("child output");
            panic!(
                "{}",
                Finished {
                    command: text,
                    output,
                    elapsed: started.elapsed()
                }
                .describe()
                    + &format!("\n(killed after {limit:?})")
            );
        }
    };
    Finished {
        command: text,
        output,
        elapsed: started.elapsed(),
    }
}

/// Panics unless two trajectories agree bit for bit: every pose, every command, the collisions.
pub fn assert_bit_identical(a: &Trajectory, b: &Trajectory) {
    assert_eq!(a.poses.len(), b.poses.len(), "sample counts differ");
    for (k, (pa, pb)) in a.poses.iter().zip(&b.poses).enumerate() {
        for (i, (x, y)) in pa.iter().zip(pb).enumerate() {
            let bits =
                |p: &formation_proto::Pose| (p.x.to_bits(), p.y.to_bits(), p.theta.to_bits());
            assert_eq!(
                bits(x),
                bits(y),
                "pose of robot {i} at sample {k}: {x:?} vs {y:?}"
            );
        }
    }
    let cmd_bits = |c: &formation_proto::WheelCmd| (c.left.to_bits(), c.right.to_bits());
    for (k, (ca, cb)) in a.commands.iter().zip(&b.commands).enumerate() {
        let (ca, cb): (Vec<_>, Vec<_>) = (
            ca.iter().map(cmd_bits).collect(),
            cb.iter().map(cmd_bits).collect(),
        );
        assert_eq!(ca, cb, "commands at tick {k}");
    }
    assert_eq!(a.collisions, b.collisions);
}

/// A child process whose stdout lines are read as they come, for tests that act on a running
/// launch (kill an agent once it has joined, swap a model once the agents are connected).
pub struct LiveProcess {
    command: String,
    child: std::process::Child,
    /// Kept open (when piped) so the process does not see its input end.
    stdin: Option<std::process::ChildStdin>,
    lines: mpsc::Receiver<String>,
    seen: Vec<String>,
    stderr: std::sync::Arc<std::sync::Mutex<String>>,
    started: Instant,
}

impl LiveProcess {
    /// Starts `command` with stdout and stderr captured and no input.
    pub fn spawn(command: Command) -> LiveProcess {
        LiveProcess::spawn_with_input(command, None)
    }

    /// Starts `command` with `secret` as the first line of its standard input, which then stays
    /// open until [`LiveProcess::close_input`] or the end: how the launcher starts the world
    /// and the agents.
    pub fn spawn_with_secret(command: Command, secret: &LaunchSecret) -> LiveProcess {
        LiveProcess::spawn_with_input(command, Some(&secret.to_line()))
    }

    /// Starts `command` with `input` (if any) written to its standard input, kept open.
    pub fn spawn_with_input(mut command: Command, input: Option<&str>) -> LiveProcess {
        use std::io::{BufRead, BufReader, Read, Write};
        let (text, mut child) = spawn_captured(&mut command, input.is_some());
        let mut stdin = child.stdin.take();
        if let (Some(input), Some(pipe)) = (input, stdin.as_mut()) {
            let _ = pipe.write_all(input.as_bytes());
            let _ = pipe.flush();
        }
        let stdout = child.stdout.take().expect("piped stdout");
        let mut stderr_pipe = child.stderr.take().expect("piped stderr");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let stderr = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let sink = std::sync::Arc::clone(&stderr);
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = stderr_pipe.read(&mut buf) {
                if n == 0 {
                    break;
                }
                if let Ok(mut text) = sink.lock() {
                    text.push_str(&String::from_utf8_lossy(&buf[..n]));
                }
            }
        });
        LiveProcess {
            command: text,
            child,
            stdin,
            lines,
            seen: Vec::new(),
            stderr,
            started: Instant::now(),
        }
    }

    /// The process id.
    pub fn id(&self) -> u32 {
        self.child.id()
    }

    /// Closes the process's standard input (a launcher that goes away).
    pub fn close_input(&mut self) {
        self.stdin = None;
    }

    /// Waits up to `limit` for a stdout line for which `matches` is true and returns it; `None`
    /// when the output ended or the time ran out first.
    pub fn wait_for_line(
        &mut self,
        limit: Duration,
        mut matches: impl FnMut(&str) -> bool,
    ) -> Option<String> {
        let deadline = Instant::now() + limit;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    self.seen.push(line.clone());
                    if matches(&line) {
                        return Some(line);
                    }
                }
                Err(_) => return None,
            }
        }
    }

    /// Panics with `why` and [`LiveProcess::describe`] unless `holds`: a check made while it
    /// runs.
    #[track_caller]
    pub fn assert_holds(&mut self, holds: bool, why: &str) {
        if !holds {
            panic!("{why}\n{}", self.describe());
        }
    }

    /// Everything printed so far, for failure messages.
    pub fn describe(&mut self) -> String {
        while let Ok(line) = self.lines.try_recv() {
            self.seen.push(line);
        }
        format!(
            "command: {}\nrunning for {:.2} s\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.command,
            self.started.elapsed().as_secs_f64(),
            self.seen.join("\n"),
            self.stderr.lock().map(|s| s.clone()).unwrap_or_default()
        )
    }

    /// Waits up to `limit` for the process to exit (killing it past that) and returns what it
    /// printed, including the lines already read.
    pub fn finish(mut self, limit: Duration) -> Finished {
        let deadline = Instant::now() + limit;
        let status = loop {
            match self.child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(20));
                }
                _ => {
                    let _ = self.child.kill();
                    let status = self.child.wait().expect("reaping the killed child");
                    let text = self.describe();
                    panic!("{text}\n(killed after {limit:?}, status {status})");
                }
            }
        };
        // The reader threads end with the pipes; collect the rest.
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.seen.push(line);
        }
        let stdout = self.seen.join("\n") + "\n";
        let stderr = self.stderr.lock().map(|s| s.clone()).unwrap_or_default();
        Finished {
            command: self.command.clone(),
            output: Output {
                status,
                stdout: stdout.into_bytes(),
                stderr: stderr.into_bytes(),
            },
            elapsed: self.started.elapsed(),
        }
    }
}

impl Drop for LiveProcess {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Process ids of the running `formation-agent` processes of run `run` serving robot `robot`,
/// found through /proc.
pub fn agent_pids(run: &RunId, robot: usize) -> Vec<u32> {
    pids_of("formation-agent", run, Some(robot))
}

/// The pid of the one `formation-agent` of run `run` serving robot `robot` now; panics with
/// `launch`'s output unless exactly one runs.
pub fn the_agent(run: &RunId, robot: usize, launch: &mut LiveProcess) -> u32 {
    let pids = agent_pids(run, robot);
    assert_eq!(
        pids.len(),
        1,
        "exactly one agent of robot {robot} should run: {pids:?}\n{}",
        launch.describe()
    );
    pids[0]
}

/// The pid of run `run`'s `formation-world` process, found through /proc.
pub fn world_pid(run: &RunId) -> Option<u32> {
    pids_of("formation-world", run, None).first().copied()
}

/// Sends `signal` (as [`send_signal`] takes it) to the world process of `launch`, the launch of
/// run `run`, and waits up to `limit` for the launch to end; panics with the launch's output if
/// no world process runs.
pub fn signal_world(
    run: &RunId,
    mut launch: LiveProcess,
    signal: &str,
    limit: Duration,
) -> Finished {
    let Some(world) = world_pid(run) else {
        panic!("no world process\n{}", launch.describe());
    };
    send_signal(world, signal);
    launch.finish(limit)
}

/// Running processes of executable `exe` whose command line has `--run-id <run>` (and
/// `--robot <robot>` when given).
fn pids_of(exe: &str, run: &RunId, robot: Option<usize>) -> Vec<u32> {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    let robot = robot.map(|r| r.to_string());
    entries
        .flatten()
        .filter_map(|entry| {
            let pid: u32 = entry.file_name().to_str()?.parse().ok()?;
            let raw = std::fs::read(entry.path().join("cmdline")).ok()?;
            let args: Vec<&[u8]> = raw.split(|&b| b == 0).collect();
            let has = |flag: &str, value: &str| {
                args.windows(2)
                    .any(|w| w[0] == flag.as_bytes() && w[1] == value.as_bytes())
            };
            let ours = args.first()?.ends_with(exe.as_bytes())
                && has("--run-id", run.as_str())
                && robot.as_deref().is_none_or(|r| has("--robot", r));
            ours.then_some(pid)
        })
        .collect()
}

/// One robot's per-tick columns of run 0 of a `formation run` output directory: the watchdog's
/// outcome, the command applied and the model that decided (`<none>` when none was used).
pub struct RobotLog {
    /// Per tick: `fresh`, `missing`, `stale`, `non_finite`, `agent_failed` or `agent_down`.
    pub outcomes: Vec<String>,
    /// Per tick: the (left, right) command the world applied.
    pub commands: Vec<(f64, f64)>,
    /// Per tick: the id of the model whose command was applied.
    pub models: Vec<String>,
}

impl RobotLog {
    /// Reads robot `robot`'s columns from `out/timing/run-0000.json` and `out/runs/run-0000.json`.
    pub fn read(out: &Path, robot: usize) -> RobotLog {
        let read = |path: PathBuf| -> serde_json::Value {
            let text = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
            serde_json::from_str(&text).expect("JSON log")
        };
        let timing = read(out.join("timing/run-0000.json"));
        let runlog = read(out.join("runs/run-0000.json"));
        let column = |name: &str| -> Vec<serde_json::Value> {
            timing["robots"][robot][name]
                .as_array()
                .unwrap_or_else(|| panic!("{name} column"))
                .clone()
        };
        let outcomes = column("outcome")
            .iter()
            .map(|v| v.as_str().unwrap_or_default().to_owned())
            .collect();
        let ids: Vec<String> = column("model_ids")
            .iter()
            .map(|v| v.as_str().unwrap_or_default().to_owned())
            .collect();
        let models = column("model")
            .iter()
            .map(|v| {
                usize::try_from(v.as_i64().expect("model index"))
                    .ok()
                    .and_then(|i| ids.get(i).cloned())
                    .unwrap_or_else(|| "<none>".into())
            })
            .collect();
        let commands = runlog["trajectory"]["commands"]
            .as_array()
            .expect("commands")
            .iter()
            .map(|tick| {
                let c = &tick[robot];
                (
                    c["left"].as_f64().expect("left"),
                    c["right"].as_f64().expect("right"),
                )
            })
            .collect();
        RobotLog {
            outcomes,
            commands,
            models,
        }
    }

    /// Maximal runs of ticks whose command was not applied, as (first, last) tick.
    pub fn braked_stretches(&self) -> Vec<(usize, usize)> {
        let mut stretches = Vec::new();
        let mut start = None;
        for (tick, outcome) in self.outcomes.iter().enumerate() {
            match (outcome == "fresh", start) {
                (false, None) => start = Some(tick),
                (true, Some(first)) => {
                    stretches.push((first, tick - 1));
                    start = None;
                }
                _ => {}
            }
        }
        if let Some(first) = start {
            stretches.push((first, self.outcomes.len() - 1));
        }
        stretches
    }

    /// Panics unless every tick the watchdog refused is a full brake.
    pub fn assert_braked_whenever_refused(&self, robot: usize) {
        for (tick, (outcome, cmd)) in self.outcomes.iter().zip(&self.commands).enumerate() {
            if outcome != "fresh" {
                assert_eq!(
                    *cmd,
                    (0.0, 0.0),
                    "robot {robot} tick {tick} ({outcome}) must be braked"
                );
            }
        }
    }
}

/// Runs `runs` runs of `scenario` (from its seed) over processes in lockstep, `model` on every
/// robot, iceoryx2 between them, and returns their trajectories.
pub fn lockstep_over_processes(
    scenario: &formation_world::Scenario,
    runs: usize,
    model: &Path,
) -> Vec<Trajectory> {
    use formation_cli::launch::{ClockMode, NetworkFlags, ProcessEvalRuns, eval_over_processes};
    let evaluation = ProcessEvalRuns {
        scenario,
        base_seed: scenario.seed(),
        runs,
        default_model: model,
        clock: ClockMode::Lockstep,
        network: &NetworkFlags::default(),
    };
    eval_over_processes(&evaluation, &mut |_| {})
        .expect("runs over processes")
        .trajectories
}

/// Run `index` of `scenario` (from its seed) in-process, the test model on each of its three
/// robots: the reference a run over processes must equal bit for bit.
pub fn in_process_run(scenario: &formation_world::Scenario, index: usize) -> Trajectory {
    use formation_robot_agent::decision::PolicyController;
    let spec = scenario.run_spec(scenario.seed(), index);
    let model = test_model();
    let mut controller = PolicyController::from_model_paths(
        &[model, model, model],
        spec.world.lidar,
        spec.world.robot.wheel_limits(),
    )
    .expect("in-process agents");
    formation_world::run_episode(&spec, &mut controller, &mut |_, _| {}).expect("in-process run")
}

/// Run 0 of `scenario` over processes in lockstep ([`lockstep_over_processes`]) and in-process,
/// `model` on every robot, each robot told its wheels in-process as the world tells every agent
/// over processes: panics unless the in-process run has `samples` samples and the two agree bit
/// for bit. Returns the in-process run.
pub fn assert_lockstep_equals_in_process(
    scenario: &formation_world::Scenario,
    model: &Path,
    samples: usize,
) -> Trajectory {
    use formation_robot_agent::decision::PolicyController;
    let over_processes = lockstep_over_processes(scenario, 1, model);
    let spec = scenario.run_spec(scenario.seed(), 0);
    let models = vec![model; scenario.n_robots()];
    let mut controller = PolicyController::from_model_paths(
        &models,
        spec.world.lidar,
        spec.world.robot.wheel_limits(),
    )
    .expect("in-process agents");
    let in_process = formation_world::run_episode(&spec, &mut controller, &mut |_, _| {})
        .expect("in-process run");
    assert_eq!(
        in_process.poses.len(),
        samples,
        "samples of the in-process run"
    );
    assert_bit_identical(&over_processes[0], &in_process);
    in_process
}

/// `formation run --run-id RUN EXTRA --scenario SCENARIO --model <test model> --out OUT`.
pub fn formation_run(run: &RunId, scenario: &Path, out: &Path, extra: &[&str]) -> Command {
    formation_run_with_model(run, scenario, test_model(), out, extra)
}

/// `formation run --run-id RUN EXTRA --scenario SCENARIO --model MODEL --out OUT`.
pub fn formation_run_with_model(
    run: &RunId,
    scenario: &Path,
    model: &Path,
    out: &Path,
    extra: &[&str],
) -> Command {
    let mut command = Command::new(&binaries().cli);
    formation_run_args(&mut command, run, (scenario, model, out), extra);
    command
}

/// Adds `run --run-id RUN EXTRA --scenario SCENARIO --model MODEL --out OUT` to `command` (the
/// `formation` binary, or a command that runs it, in a network namespace for example).
pub fn formation_run_args(
    command: &mut Command,
    run: &RunId,
    (scenario, model, out): (&Path, &Path, &Path),
    extra: &[&str],
) {
    command
        .args(["run", "--run-id", run.as_str()])
        .args(extra)
        .arg("--scenario")
        .arg(scenario)
        .arg("--model")
        .arg(model)
        .arg("--out")
        .arg(out);
}

/// `formation eval --controller policy --runs 1 --scenario SCENARIO --model MODEL`: the first
/// run of a scenario, evaluated in-process unless more flags are added.
pub fn policy_eval_once(scenario: &Path, model: &Path) -> Command {
    let mut command = Command::new(&binaries().cli);
    command
        .args(["eval", "--controller", "policy", "--runs", "1"])
        .arg("--scenario")
        .arg(scenario)
        .arg("--model")
        .arg(model);
    command
}

/// [`policy_eval_once`] with `--json JSON`.
pub fn policy_eval(scenario: &Path, model: &Path, json: &Path) -> Command {
    let mut command = policy_eval_once(scenario, model);
    command.arg("--json").arg(json);
    command
}

/// Sends signal `name` (`KILL`, `STOP`, `USR1`, ...) to process `pid` with kill(1).
pub fn send_signal(pid: u32, name: &str) {
    let status = Command::new("kill")
        .args([
            &format!("-{}", name.trim_start_matches('-')),
            &pid.to_string(),
        ])
        .status()
        .expect("running kill");
    assert!(status.success(), "kill -{name} {pid}");
}

/// Waits until a launch prints that all its agents connected.
pub fn await_connected(launch: &mut LiveProcess) {
    let line = launch.wait_for_line(Duration::from_secs(120), |l| l.contains("agents connected"));
    assert!(line.is_some(), "{}", launch.describe());
}

/// Waits up to 60 s for a line of `launch` that contains `needle` (a launch announcing that it
/// waits for its remote agents, a recorder that connected), or fails with its output.
pub fn await_line(launch: &mut LiveProcess, needle: &str) {
    let line = launch.wait_for_line(Duration::from_secs(60), |l| l.contains(needle));
    assert!(line.is_some(), "{}", launch.describe());
}

/// Starts `agent` (a remote agent, by hand), then waits for `launch` to end successfully within
/// `limit` and for the agent to end successfully within 30 s; returns the launch's result.
pub fn finish_with_remote_agent(launch: LiveProcess, agent: Command, limit: Duration) -> Finished {
    let remote = LiveProcess::spawn_with_input(agent, None);
    let finished = launch.finish(limit);
    finished.assert_success();
    let remote = remote.finish(Duration::from_secs(30));
    assert!(remote.output.status.success(), "{}", remote.describe());
    finished
}

/// Asserts that every counter (of [`count_samples`], say) counted nothing: `(counter, what it
/// would mean)`.
pub fn assert_none_counted(counters: &[(&std::sync::atomic::AtomicUsize, &str)]) {
    for (counter, meaning) in counters {
        assert_eq!(
            counter.load(std::sync::atomic::Ordering::Relaxed),
            0,
            "{meaning}"
        );
    }
}

/// Waits for the launcher to report that a new agent (not `old_pid`) of `robot` rejoined, and
/// returns the first tick it drove.
pub fn await_rejoin(launch: &mut LiveProcess, robot: usize, old_pid: u32) -> usize {
    let prefix = format!("robot {robot}: agent pid ");
    let line = launch.wait_for_line(Duration::from_secs(60), |line| {
        line.starts_with(&prefix) && line.contains("rejoined")
    });
    let Some(line) = line else {
        panic!(
            "robot {robot}'s agent did not rejoin after a kill\n{}",
            launch.describe()
        );
    };
    assert!(
        !line.contains(&format!("pid {old_pid} ")),
        "the killed agent cannot rejoin: {line}"
    );
    line.rsplit(' ')
        .next()
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no tick in {line:?}"))
}

/// The incarnations (16-hex-digit nonces) whose services exist for robot `robot` of `run`, in no
/// particular order: how a test finds the services the world made for an accepted agent.
pub fn incarnations(run: &RunId, robot: usize) -> Vec<u64> {
    use iceoryx2::prelude::*;
    let Ok(config) = RunNamespace::new(run).iceoryx_config() else {
        return Vec::new();
    };
    let prefix = format!("formation/{run}/robot/{robot}/");
    let mut found = Vec::new();
    let _ = ipc::Service::list(&config, |details| {
        let name = details.static_details.name().to_string();
        if let Some(rest) = name.strip_prefix(&prefix)
            && let Some(hex) = rest.strip_suffix("/scan")
            && hex.len() == 16
            && let Ok(n) = u64::from_str_radix(hex, 16)
            && !found.contains(&n)
        {
            found.push(n);
        }
        CallbackProgression::Continue
    });
    found
}

/// The configuration of a raw Zenoh client of `endpoint` (no scouting, a 3 s connect timeout
/// that ends the attempt), before its login and TLS settings.
pub fn raw_client_config(endpoint: &str) -> zenoh::Result<zenoh::Config> {
    let mut config = zenoh::Config::default();
    config.insert_json5("mode", "\"client\"")?;
    config.insert_json5("scouting/multicast/enabled", "false")?;
    config.insert_json5("connect/endpoints", &format!("[{endpoint:?}]"))?;
    config.insert_json5("connect/timeout_ms", "3000")?;
    config.insert_json5("connect/exit_on_failure", "true")?;
    Ok(config)
}

/// A raw Zenoh client of the world at `endpoint`, logged in as `login` (`None`: no login): an
/// impostor that speaks Zenoh but is no `formation-agent`. Its connection is refused when the
/// router does not admit the login (within the 3 s connect timeout).
pub fn raw_client(endpoint: &str, login: Option<(&str, &str)>) -> zenoh::Result<zenoh::Session> {
    use zenoh::Wait;
    let mut config = raw_client_config(endpoint)?;
    if let Some((user, password)) = login {
        config.insert_json5(
            "transport/auth/usrpwd",
            &format!("{{ user: {user:?}, password: {password:?} }}"),
        )?;
    }
    zenoh::open(config).wait()
}

/// A subscriber of `session` on `key` that counts the samples it receives: keep the
/// subscriber alive while counting.
pub fn count_samples(
    session: &zenoh::Session,
    key: String,
) -> (
    zenoh::pubsub::Subscriber<()>,
    std::sync::Arc<std::sync::atomic::AtomicUsize>,
) {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use zenoh::Wait;
    let count = std::sync::Arc::new(AtomicUsize::new(0));
    let seen = std::sync::Arc::clone(&count);
    let subscriber = session
        .declare_subscriber(key)
        .callback(move |_| {
            seen.fetch_add(1, Ordering::Relaxed);
        })
        .wait()
        .expect("declaring a subscriber");
    (subscriber, count)
}

/// A small tmpfs mounted for one test: a disk of known size that a test fills, unmounted when
/// dropped (also when the test fails). Mounting needs root, which CI has; without it the test
/// fails, saying so, rather than passing unchecked.
pub struct Tmpfs {
    dir: PathBuf,
}

impl Tmpfs {
    /// Mounts a tmpfs of `size` (e.g. `256k`) on `dir`, created if needed.
    pub fn mount(dir: &Path, size: &str) -> Tmpfs {
        std::fs::create_dir_all(dir).expect("mount point");
        let output = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir)
            .output()
            .unwrap_or_else(|e| panic!("cannot run mount ({e}); a full disk is tested on a tmpfs"));
        assert!(
            output.status.success(),
            "cannot mount a {size} tmpfs on {} ({}): this test fills a small disk and needs root, as CI has",
            dir.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        );
        Tmpfs {
            dir: dir.to_path_buf(),
        }
    }

    /// Where it is mounted.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let unmounted = Command::new("umount")
            .arg(&self.dir)
            .status()
            .is_ok_and(|s| s.success());
        if !unmounted {
            // Still busy (a straggler holds a file): detach it now, it goes when released.
            let _ = Command::new("umount").arg("-l").arg(&self.dir).status();
        }
    }
}

/// `formation credentials --robots ROBOTS --out DIR/creds`: a Zenoh team's logins and launch
/// secret, made by the launcher's own command; returns the folder.
pub fn zenoh_credentials(dir: &Path, robots: usize) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap_or_else(|e| panic!("creating {}: {e}", dir.display()));
    credentials(&dir.join("creds"), &[], robots)
}

/// `formation credentials --tls --valid-days 30 --robots ROBOTS --out DIR/NAME`: a team's logins
/// with certificates of its own authority; returns the folder.
pub fn tls_credentials(dir: &Path, name: &str, robots: usize) -> PathBuf {
    credentials(&dir.join(name), &["--tls", "--valid-days", "30"], robots)
}

/// `formation credentials FLAGS --robots ROBOTS --out CREDS`, which must succeed.
fn credentials(creds: &Path, flags: &[&str], robots: usize) -> PathBuf {
    let mut command = Command::new(&binaries().cli);
    command
        .arg("credentials")
        .args(flags)
        .args(["--robots", &robots.to_string(), "--out"])
        .arg(creds);
    run(command, Duration::from_secs(120)).assert_success();
    creds.to_path_buf()
}

/// Starts the `delay-relay` of `command` (its arguments given) and waits until it listens.
pub fn start_relay(command: Command) -> LiveProcess {
    let mut relay = LiveProcess::spawn_with_input(command, Some(""));
    assert!(
        relay
            .wait_for_line(Duration::from_secs(10), |l| l == "listening")
            .is_some(),
        "{}",
        relay.describe()
    );
    relay
}

/// The JSON file at `path`, parsed; a missing or malformed file fails the test naming it.
pub fn read_json(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("parsing {}: {e}", path.display()))
}

/// Every file under `dir`, recursively, sorted.
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let path = entry.path();
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leak_check_sees_and_removes_a_runs_files() {
        let run = unique_run_id("leak");
        let check = LeakCheck::new(&run);
        std::fs::create_dir_all(check.namespace().root_dir()).unwrap();
        assert_eq!(check.leftovers().len(), 1);
        drop(check);
        assert!(RunNamespace::new(&run).leftovers().is_empty());
    }

    #[test]
    fn run_captures_output_and_status() {
        let mut command = Command::new("sh");
        command.args(["-c", "echo out; echo err >&2; exit 3"]);
        let finished = run(command, Duration::from_secs(10));
        assert_eq!(finished.output.status.code(), Some(3));
        assert_eq!(finished.stdout(), "out\n");
        assert!(finished.describe().contains("err"));
    }
}
