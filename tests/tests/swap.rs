//! ONNX hot swap on real processes: `formation swap` changes one running robot's model at a tick
//! boundary, bad swaps are refused with the reason while the old model keeps driving, and a swap
//! to an unknown robot, an unknown run or a missing file is a clear error that disturbs nothing.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_cli::launch::read_trajectory;
use formation_robot_agent::decision::{Agent, PolicyController};
use formation_tests::{
    LiveProcess, ProcessTest, RobotLog, assert_bit_identical, await_connected, binaries, run,
    test_model, write_tiny_model, write_tiny_model_with,
};
use formation_world::episode::{Controller, ControllerError, Observation};
use formation_world::{Scenario, run_episode};

const LIMIT: Duration = Duration::from_secs(240);
const SWAP_TICK: u64 = 400;
const SWAPPED_ROBOT: usize = 1;

/// The in-process reference: every robot runs `first`, and robot `robot` switches to `second`
/// from tick `at` on, exactly as the agent process does.
struct SwapAt {
    inner: PolicyController,
    robot: usize,
    at: u64,
    second: Option<Agent>,
}

impl Controller for SwapAt {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [formation_proto::WheelCmd],
    ) -> Result<(), ControllerError> {
        if obs.tick == self.at
            && let Some(agent) = self.second.take()
        {
            self.inner.agents_mut()[self.robot] = agent;
        }
        self.inner.commands(obs, out)
    }
}

fn swap(run_id: &str, robot: &str, model: &Path, extra: &[&str]) -> formation_tests::Finished {
    let mut command = Command::new(&binaries().cli);
    command
        .args(["swap", "--run", run_id, "--robot", robot, "--model"])
        .arg(model)
        .args(extra);
    run(command, LIMIT)
}

/// Issue 5: in lockstep, bad swaps are refused (the old model keeps driving), then a good swap at
/// tick 400 makes every later command of that robot exactly what the new model gives in-process.
#[test]
fn a_lockstep_swap_matches_the_new_model_in_process_and_bad_swaps_are_refused() {
    let t = ProcessTest::start("swap_lockstep", LIMIT);
    let first = test_model();
    let second = t.path().join("second.onnx");
    write_tiny_model(&second, 1);
    let wrong_shape = t.path().join("wrong-shape.onnx");
    write_tiny_model_with(&wrong_shape, 2, &["--aux-width", "3"]);
    let wrong_sensor = t.path().join("wrong-sensor.onnx");
    write_tiny_model_with(&wrong_sensor, 3, &["--beams", "450"]);
    let not_onnx = t.path().join("not-a-model.onnx");
    std::fs::write(&not_onnx, b"this is not an ONNX file").expect("writing a bad file");

    let scenario_path = t.case1(30.0);
    let out = t.out();
    let launch = launch_connected(&t, &scenario_path);

    let robot = SWAPPED_ROBOT.to_string();
    for (bad, why) in [
        (&wrong_shape, "aux"),
        (&wrong_sensor, "450"),
        (&not_onnx, "not-a-model.onnx"),
    ] {
        swap(t.run.as_str(), &robot, bad, &[])
            .assert_failure_mentioning("refused")
            .assert_failure_mentioning(why)
            .assert_failure_mentioning("old model keeps driving");
    }
    swap(t.run.as_str(), "7", &second, &[]).assert_failure_mentioning("robot 7 does not exist");
    swap(t.run.as_str(), &robot, &t.path().join("missing.onnx"), &[])
        .assert_failure_mentioning("not found");
    swap("no-such-run", &robot, &second, &[]).assert_failure_mentioning("no run");

    let done = swap(
        t.run.as_str(),
        &robot,
        &second,
        &["--at-tick", &SWAP_TICK.to_string()],
    );
    done.assert_success();
    done.assert_stdout_has(&format!("from tick {SWAP_TICK}"));
    let finished = launch.finish(LIMIT);
    finished.assert_success();

    // The command log says which model decided each tick.
    let models = RobotLog::read(&out, SWAPPED_ROBOT).models;
    assert_eq!(models.len(), 600);
    let swap_tick = usize::try_from(SWAP_TICK).expect("tick");
    assert!(models[..swap_tick].iter().all(|m| *m == models[0]));
    assert!(models[swap_tick..].iter().all(|m| *m == models[swap_tick]));
    assert_ne!(
        models[0], models[swap_tick],
        "the model id changed at the swap"
    );
    for other in [0, 2] {
        let theirs = RobotLog::read(&out, other).models;
        assert!(theirs.iter().all(|m| *m == models[0]), "robot {other}");
    }

    // Bit for bit what the two models give in-process, with the swap at the same tick.
    let scenario = Scenario::from_path(&scenario_path).expect("scenario");
    let spec = scenario.run_spec(scenario.seed(), 0);
    let lidar = spec.world.lidar;
    let wheels = spec.world.robot.wheel_limits();
    let mut reference = SwapAt {
        inner: PolicyController::from_model_paths(&[first, first, first], lidar, wheels)
            .expect("agents"),
        robot: SWAPPED_ROBOT,
        at: SWAP_TICK,
        second: Some({
            let mut agent = Agent::from_model_path(&second, lidar).expect("second model");
            agent.set_wheel_limits(wheels);
            agent
        }),
    };
    let in_process = run_episode(&spec, &mut reference, &mut |_, _| {}).expect("in-process run");
    let over_processes = read_trajectory(&out.join("runs/run-0000.json")).expect("run log");
    assert_bit_identical(&over_processes, &in_process);

    // And the swap mattered: without it robot 1's later commands differ.
    let mut unswapped =
        PolicyController::from_model_paths(&[first, first, first], lidar, wheels).expect("agents");
    let without = run_episode(&spec, &mut unswapped, &mut |_, _| {}).expect("in-process run");
    assert_eq!(
        without.commands[..swap_tick],
        in_process.commands[..swap_tick]
    );
    assert_ne!(
        without.commands[swap_tick][SWAPPED_ROBOT],
        in_process.commands[swap_tick][SWAPPED_ROBOT]
    );
    t.assert_clean();
}

/// Issue (contracts checked): a model whose output is NaN passed swap validation and then braked
/// its robot every tick. The agent runs the candidate once on its last observation and refuses it;
/// the robot keeps driving with the old model, every tick.
/// `formation run` of `scenario` with the test model (the first model), paced at 10 ms a tick,
/// started and connected.
fn launch_connected(t: &ProcessTest, scenario: &Path) -> LiveProcess {
    let mut launch = LiveProcess::spawn(t.formation_run(scenario, &["--pace-ms", "10"]));
    await_connected(&mut launch);
    launch
}

#[test]
fn a_swap_to_a_model_with_nan_output_is_refused_and_the_old_model_keeps_driving() {
    let t = ProcessTest::start("swap_nan", LIMIT);
    let nan = t.path().join("nan-output.onnx");
    write_tiny_model_with(&nan, 4, &["--nan-output"]);

    let scenario_path = t.case1(30.0);
    let out = t.out();
    let launch = launch_connected(&t, &scenario_path);

    let robot = SWAPPED_ROBOT.to_string();
    swap(t.run.as_str(), &robot, &nan, &[])
        .assert_failure_mentioning("refused")
        .assert_failure_mentioning("non-finite")
        .assert_failure_mentioning("nan-output")
        .assert_failure_mentioning("old model keeps driving");
    let finished = launch.finish(LIMIT);
    finished.assert_success();

    // Every tick of the robot was decided by the old model and applied: never braked.
    let log = RobotLog::read(&out, SWAPPED_ROBOT);
    assert_eq!(log.models.len(), 600);
    let reference = RobotLog::read(&out, 0).models[0].clone();
    assert!(
        log.models.iter().all(|m| *m == reference),
        "only the old model may decide: {:?}",
        log.models.iter().find(|m| **m != reference)
    );
    assert!(
        log.outcomes.iter().all(|o| o == "fresh"),
        "the robot was braked: {:?}",
        log.braked_stretches()
    );
    assert!(
        log.commands
            .iter()
            .all(|&(l, r)| l.is_finite() && r.is_finite()),
        "every applied command is finite"
    );
    assert!(
        log.commands.iter().any(|&c| c != (0.0, 0.0)),
        "the robot drove"
    );
    t.assert_clean();
}
