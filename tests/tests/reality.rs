//! The reality models across processes (issue 37): a team under every model of the P3-DX
//! profile, and then some (a narrower field of view, a minimum range), each robot its own
//! process in lockstep, reproduces the in-process run bit for bit.

use std::time::Duration;

use formation_robot_agent::decision::PolicyController;
use formation_tests::{
    ProcessTest, assert_bit_identical, lockstep_over_processes, repo_root, shipped_model,
};
use formation_world::{Scenario, run_episode};

const LIMIT: Duration = Duration::from_secs(360);

#[test]
fn every_reality_model_on_in_lockstep_is_bit_identical_to_in_process() {
    let t = ProcessTest::start("reality_lockstep", LIMIT);
    let text = std::fs::read_to_string(repo_root().join("scenarios/teams-generalist.toml"))
        .expect("reading teams-generalist.toml");
    let text = text
        .replace("robots = 8", "robots = 5")
        .replace("duration_s = 60.0", "duration_s = 4.0")
        .replace("runs = 100", "runs = 2")
        .replace(
            "[lidar]\n",
            "[robot]\nprofile = \"pioneer-p3dx\"\n[lidar]\nfov_deg = 300.0\nmin_range = 0.3\n",
        );
    let scenario_path = t.path().join("reality.toml");
    std::fs::write(&scenario_path, text).expect("writing the scenario");
    let scenario = Scenario::from_path(&scenario_path).expect("scenario");
    let reality = scenario.world_config().reality;
    assert!(reality.motors.tau_s > 0.0 && reality.motors.speed_noise_std > 0.0);
    assert!(reality.motors.gain_asymmetry != 0.0 && reality.spread > 0.0);
    assert!(reality.lidar.scan_period_ticks(scenario.world_config().dt) > 1);
    assert!(reality.lidar.dropout > 0.0 && reality.lidar.fov_deg < 360.0);
    assert!(reality.compass.noise_std_deg > 0.0 && reality.compass.bias_deg != 0.0);
    assert!(reality.command_latency_ticks > 0);

    let model = shipped_model();
    let over_processes = lockstep_over_processes(&scenario, 2, &model);
    assert_eq!(over_processes.len(), 2);
    for (index, from_processes) in over_processes.iter().enumerate() {
        let spec = scenario.run_spec(scenario.seed(), index);
        let models = vec![model.as_path(); 5];
        let wheels = spec.world.robot.wheel_limits();
        let mut controller = PolicyController::from_model_paths(&models, spec.world.lidar, wheels)
            .expect("in-process agents");
        let in_process =
            run_episode(&spec, &mut controller, &mut |_, _| {}).expect("in-process run");
        assert_eq!(in_process.poses.len(), 81, "4 s at 20 Hz");
        assert_bit_identical(from_processes, &in_process);
    }
}
