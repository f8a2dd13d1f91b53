//! The prologue every multi-process test shares, as one value: [`ProcessTest::start`] takes this
//! test binary's one-at-a-time lock ([`one_at_a_time`]), arms the [`Watchdog`] with the test's
//! limit, and makes the test's isolation: a scratch folder ([`TempDir`]), a run id of its own
//! (so its own iceoryx2 namespace and Zenoh key space) and the [`LeakCheck`] of that run id.
//!
//! Dropping the value releases them in the order the hand-written prologue did: the run's
//! namespace is removed first (never leaking into another test, even after a failure), then the
//! scratch folder, then the watchdog is disarmed and the lock released. Values the test makes
//! after it (its processes) are dropped before it. A test that needs a second run id takes it
//! with its leak check from [`ProcessTest::another_run`]; one that needs a network namespace
//! makes it itself next to this value.
//!
//! The lock is taken before the watchdog is armed, so a test waiting for another test of its
//! binary (under plain `cargo test`) is not counted as hung.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::MutexGuard;
use std::time::Duration;

use formation_proto::wire::RunId;

use crate::{
    Binaries, Finished, LeakCheck, LiveProcess, TempDir, Watchdog, assert_bit_identical,
    await_connected, await_line, binaries, case1_scenario, formation_run, free_tcp_port,
    in_process_run, one_at_a_time, run, unique_run_id,
};

/// One multi-process test's lock, watchdog, scratch folder, run id and leak check.
pub struct ProcessTest {
    /// The leak check of [`ProcessTest::run`]; dropped (removing the namespace) first.
    pub leaks: LeakCheck,
    /// The test's own run id (its own iceoryx2 namespace and Zenoh key space).
    pub run: RunId,
    /// The test's own scratch folder, removed on drop.
    pub dir: TempDir,
    _watchdog: Watchdog,
    _one: MutexGuard<'static, ()>,
}

impl ProcessTest {
    /// The prologue of test `name` (also the tag of its folder and run id), which the watchdog
    /// aborts if it still runs after `limit`.
    pub fn start(name: &'static str, limit: Duration) -> ProcessTest {
        let one = one_at_a_time();
        let watchdog = Watchdog::arm(name, limit);
        let dir = TempDir::new(name);
        let (run, leaks) = own_run(name);
        ProcessTest {
            leaks,
            run,
            dir,
            _watchdog: watchdog,
            _one: one,
        }
    }

    /// Another run id of this test's (tagged `tag`), for a test that launches more than once,
    /// and its leak check: its own iceoryx2 namespace and Zenoh key space, removed when the
    /// check is dropped.
    pub fn another_run(&self, tag: &str) -> (RunId, LeakCheck) {
        own_run(tag)
    }

    /// A folder `name` in the scratch folder, made now, for a test's launch of its own.
    pub fn folder(&self, name: &str) -> PathBuf {
        let folder = self.dir.path().join(name);
        std::fs::create_dir_all(&folder)
            .unwrap_or_else(|e| panic!("creating {}: {e}", folder.display()));
        folder
    }

    /// The scratch folder's path.
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// `out` in the scratch folder, where the tests have their launches write.
    pub fn out(&self) -> PathBuf {
        self.dir.path().join("out")
    }

    /// Case 1 of `duration_s` seconds, written into the scratch folder ([`case1_scenario`]).
    pub fn case1(&self, duration_s: f64) -> PathBuf {
        case1_scenario(self.dir.path(), duration_s)
    }

    /// `formation run` of `scenario` with this test's run id, `extra` flags and the test model,
    /// writing to [`ProcessTest::out`] ([`formation_run`]).
    pub fn formation_run(&self, scenario: &Path, extra: &[&str]) -> Command {
        formation_run(&self.run, scenario, &self.out(), extra)
    }

    /// [`ProcessTest::formation_run`] of case 1 of `duration_s` seconds with `extra` flags,
    /// started now; returns once every agent has connected ([`await_connected`]).
    pub fn connected_launch(&self, duration_s: f64, extra: &[&str]) -> LiveProcess {
        let mut launch = LiveProcess::spawn(self.formation_run(&self.case1(duration_s), extra));
        await_connected(&mut launch);
        launch
    }

    /// [`ProcessTest::formation_run`] of `scenario` over Zenoh, listening on `listen`, with robot
    /// `remote`'s agent left to be started by hand (`--remote`), the credentials folder `creds`
    /// and `extra` flags, started now; returns once the launch says it waits for that agent.
    pub fn launch_awaiting_remote(
        &self,
        scenario: &Path,
        listen: &str,
        remote: usize,
        creds: &Path,
        extra: &[&str],
    ) -> LiveProcess {
        let robot = remote.to_string();
        let mut command = self.formation_run(
            scenario,
            &[
                "--transport",
                "zenoh",
                "--listen",
                listen,
                "--remote",
                &robot,
            ],
        );
        command.args(extra).arg("--credentials").arg(creds);
        let mut launch = LiveProcess::spawn(command);
        await_line(
            &mut launch,
            &format!("waiting for the remote agents of robots [{robot}]"),
        );
        launch
    }

    /// `formation-world --run-id RUN --run-specs SPECS --out OUT`: a world started by hand, with
    /// no launcher, for run 0 of case 1 of `duration_s` seconds (its run spec written into the
    /// scratch folder), writing to `out`. The caller adds its other flags and hands the world
    /// the launch secret.
    pub fn world_by_hand(&self, duration_s: f64, out: &Path) -> Command {
        let scenario =
            formation_world::Scenario::from_path(&self.case1(duration_s)).expect("scenario");
        let specs = self.dir.path().join("run-specs.json");
        let spec = scenario.run_spec(scenario.seed(), 0);
        std::fs::write(&specs, serde_json::to_vec(&[spec]).expect("specs JSON")).expect("specs");
        let mut world = Command::new(&binaries().world);
        world
            .args(["--run-id", self.run.as_str()])
            .arg("--run-specs")
            .arg(&specs)
            .arg("--out")
            .arg(out);
        world
    }

    /// The runtime executables ([`binaries`]; built on first use, outside the watchdog's time).
    pub fn bins(&self) -> &'static Binaries {
        binaries()
    }

    /// A Zenoh endpoint on 127.0.0.1 at a port free now ([`free_tcp_port`]).
    pub fn endpoint(&self) -> String {
        format!("tcp/127.0.0.1:{}", free_tcp_port())
    }

    /// Lockstep case 1 of 10 s over Zenoh, the world listening on `listen` (`tcp/` or `tls/`,
    /// the credentials made by the launcher): the launch must succeed and its run reproduce the
    /// in-process one bit for bit ([`in_process_run`]). Returns the launch's result.
    pub fn lockstep_case1_over_zenoh(&self, listen: &str) -> Finished {
        let scenario_path = self.case1(10.0);
        let scenario = formation_world::Scenario::from_path(&scenario_path).expect("scenario");
        let flags = [
            "--transport",
            "zenoh",
            "--listen",
            listen,
            "--clock",
            "lockstep",
        ];
        let finished = run(
            self.formation_run(&scenario_path, &flags),
            Duration::from_secs(180),
        );
        finished.assert_success();
        let over_zenoh =
            formation_cli::launch::read_trajectory(&self.out().join("runs").join("run-0000.json"))
                .expect("the run log");
        let reference = in_process_run(&scenario, 0);
        assert_eq!(reference.poses.len(), 201, "10 s at 20 Hz");
        assert_bit_identical(&over_zenoh, &reference);
        finished
    }

    /// Panics listing the run's files if any are left (its lock file included).
    pub fn assert_clean(&self) {
        self.leaks.assert_clean();
    }
}

/// A run id of its own tagged `tag`, and its leak check (which asserts the run has no files yet).
fn own_run(tag: &str) -> (RunId, LeakCheck) {
    let run = unique_run_id(tag);
    let leaks = LeakCheck::new(&run);
    (run, leaks)
}
