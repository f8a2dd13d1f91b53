//! Every consumer follows the output a model declares (issue 34, item 2): a model whose
//! `formation.output` is `formation_velocity` drives through the agent's conversion (the
//! reference term added at the goal's own speed), runs across processes in lockstep bit for bit
//! as in-process, and a model that declares an output no consumer knows is refused by name.

use std::path::Path;
use std::time::Duration;

use formation_onnx::{OnnxPolicy, PolicyOutput};
use formation_perception::policy_input::formation_velocity_to_wheels;
use formation_proto::{Goal, PolicyInput, WheelLimits};
use formation_robot_agent::decision::{Agent, PolicyController};
use formation_tests::{
    ProcessTest, assert_lockstep_equals_in_process, policy_eval_once, run, write_tiny_model_with,
};
use formation_world::{Scenario, run_episode};

/// The watchdog limit: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(180);

/// A tiny model (seeded random weights) that declares `output`.
fn model_declaring(dir: &Path, output: &str) -> std::path::PathBuf {
    let path = dir.join(format!("{output}.onnx"));
    write_tiny_model_with(&path, 5, &["--output", output]);
    path
}

#[test]
fn a_formation_velocity_model_is_turned_into_wheels_with_the_reference_term_at_the_goals_speed() {
    let t = ProcessTest::start("formation_velocity_agent", LIMIT);
    let model = model_declaring(t.path(), "formation_velocity");
    let mut raw = OnnxPolicy::load(&model).expect("the model loads");
    assert_eq!(raw.metadata().output, PolicyOutput::FormationVelocity);
    let lidar = formation_proto::LidarSpec::default();
    let mut agent = Agent::from_model_path(&model, lidar).expect("an agent takes it");
    // A scan with a neighbour ahead-left, and two goal speeds: the correction stays, the
    // reference term follows v*.
    let mut scan = vec![10.0_f32; lidar.beams];
    for beam in &mut scan[100..110] {
        *beam = 1.2;
    }
    for v_star in [0.3, 0.8] {
        let goal = Goal {
            phi_star: 0.4,
            d_star: 1.5,
            v_star,
        };
        let heading = -0.2;
        let command = agent.act(&scan, heading, &goal).expect("a decision");
        let aux = agent.io().aux.values(heading, &goal);
        let image: Vec<f32> = agent.image().iter().map(|&c| f32::from(c)).collect();
        let values = raw
            .infer(&PolicyInput::image_and_aux(&image, &aux))
            .expect("the raw output");
        let untold = WheelLimits::default();
        let expected = formation_velocity_to_wheels(values, f64::from(aux[0]), v_star, untold);
        assert_eq!(command, expected, "v* = {v_star}");
        // A robot whose wheels have an acceleration limit shapes the same output for them.
        let accel = WheelLimits {
            max_speed: None,
            max_accel: Some(1.0),
        };
        agent.set_wheel_limits(accel);
        let limited = agent.act(&scan, heading, &goal).expect("a decision");
        let shaped = formation_velocity_to_wheels(values, f64::from(aux[0]), v_star, accel);
        assert_eq!(limited, shaped, "v* = {v_star}");
        assert_ne!(
            limited, command,
            "the limit shapes a non-zero formation velocity"
        );
        // A top wheel speed below the command scales both wheels into it, keeping the curvature.
        let top = 0.5 * command.left.abs().max(command.right.abs());
        agent.set_wheel_limits(WheelLimits {
            max_speed: Some(top),
            max_accel: None,
        });
        let bounded = agent.act(&scan, heading, &goal).expect("a decision");
        agent.set_wheel_limits(untold);
        assert!(
            (bounded.left.abs().max(bounded.right.abs()) - top).abs() < 1e-12,
            "{bounded:?} within {top}"
        );
        assert!((bounded.left * command.right - bounded.right * command.left).abs() < 1e-12);
    }
}

#[test]
fn a_formation_velocity_team_in_lockstep_over_processes_is_bit_identical_to_in_process() {
    let t = ProcessTest::start("formation_velocity_lockstep", LIMIT);
    let model = model_declaring(t.path(), "formation_velocity");
    // Wheels with an acceleration limit, which each agent is told at the episode's start and
    // shapes its formation velocity for: the same over processes as in-process.
    let short = t.case1(4.0);
    let limited = std::fs::read_to_string(&short).expect("the scenario")
        + "\n[robot]\nmax_wheel_accel = 1.0\n";
    std::fs::write(&short, limited).expect("the limited scenario");
    let scenario = Scenario::from_path(&short).expect("scenario");
    assert_eq!(scenario.world_config().robot.max_wheel_accel, Some(1.0));
    // 4 s at 20 Hz.
    let in_process = assert_lockstep_equals_in_process(&scenario, &model, 81);
    // Unshaped agents drive another run: the limit did reach the agents over processes.
    let spec = scenario.run_spec(scenario.seed(), 0);
    let models = [model.as_path(); 3];
    let mut unshaped = PolicyController::from_model_paths(
        &models,
        spec.world.lidar,
        formation_proto::WheelLimits::default(),
    )
    .expect("in-process agents");
    let unaware = run_episode(&spec, &mut unshaped, &mut |_, _| {}).expect("in-process run");
    assert_ne!(
        unaware.poses, in_process.poses,
        "the limit shapes the team's motion"
    );
}

#[test]
fn a_model_declaring_an_output_no_consumer_knows_is_refused_naming_it() {
    let t = ProcessTest::start("unknown_output_refused", LIMIT);
    let model = model_declaring(t.path(), "torques");
    let scenario = t.case1(2.0);
    let finished = run(policy_eval_once(&scenario, &model), LIMIT);
    finished.assert_failure_mentioning("declares the output \"torques\" (formation.output)");
    finished.assert_exit(2);
    let err = OnnxPolicy::load(&model).unwrap_err().to_string();
    assert!(err.contains("cannot use"), "{err}");
}
