//! A small run the seeds of the recording and live-recording targets are made of: a scenario of
//! three robots and a few ticks with real scans, commands of every outcome, and a swapped model.

use std::path::PathBuf;

use formation_proto::SwapDone;
use formation_proto::wire::TickOutcome;
use formation_proto::{Goal, Pose, WheelCmd};
use formation_record::{LaunchInfo, RecordingSetup, SentCommand, TickRecord};
use formation_world::{RunSpec, Scenario};

use super::seed_error;
use crate::FuzzError;

/// Robots in the sample run.
pub const ROBOTS: usize = 3;
/// Beams of each scan.
pub const BEAMS: usize = 36;

/// The sample run's spec.
pub fn spec(target: &'static str) -> Result<RunSpec, FuzzError> {
    let text = format!(
        r#"
name = "fuzz-seed"
robots = {ROBOTS}
duration_s = 0.3
seed = 5
[goal]
v_star = 0.3
d_star = 1.5
[heading]
schedule = "ramp"
omega = 0.3
[lidar]
beams = {BEAMS}
noise_std = 0.01
"#
    );
    Ok(Scenario::from_toml_str(&text, "fuzz-seed")
        .map_err(seed_error(target))?
        .run_spec(5, 0))
}

/// The launch the sample run belongs to; `models` are stored in the recording.
pub fn launch(models: Vec<PathBuf>) -> LaunchInfo {
    LaunchInfo {
        scenario: "fuzz-seed".into(),
        base_seed: Some(5),
        clock: "lockstep".into(),
        controller: "policy".into(),
        models,
        shipped_models: None,
    }
}

/// The recording setup of the sample run.
pub fn setup(target: &'static str, models: Vec<PathBuf>) -> Result<RecordingSetup, FuzzError> {
    Ok(RecordingSetup::for_run(&spec(target)?, &launch(models)))
}

/// Tick `k` of the sample run: every outcome occurs among the ticks.
pub fn tick(k: u64) -> TickRecord {
    let time = k as f64 * 0.05;
    let poses: Vec<Pose> = (0..ROBOTS)
        .map(|i| Pose {
            x: i as f64 * 1.5 + time * 0.3,
            y: (i % 2) as f64,
            theta: 0.1 * i as f64,
        })
        .collect();
    let scans = (0..ROBOTS)
        .map(|i| {
            (0..BEAMS)
                .map(|b| {
                    if (b + i) % 5 == 0 {
                        4.0
                    } else {
                        1.0 + b as f32 * 0.05
                    }
                })
                .collect()
        })
        .collect();
    let commands = (0..ROBOTS)
        .map(|i| SentCommand {
            wheels: WheelCmd {
                left: 0.3 + 0.01 * i as f64,
                right: 0.29,
            },
            outcome: TickOutcome::ALL[(k as usize + i) % TickOutcome::ALL.len()],
            lag_ticks: u32::from(i == 2),
        })
        .collect();
    TickRecord {
        tick: k,
        time,
        goal: Goal::new(0.3 * time, 1.5, 0.3),
        poses,
        wheel_speeds: vec![
            WheelCmd {
                left: 0.3,
                right: 0.3
            };
            ROBOTS
        ],
        scans,
        commands,
        model_ids: vec!["policy-3f2a".into(); ROBOTS],
    }
}

/// A model swapped in at tick 3 on robot 1, its bytes sent over the network.
pub fn swap() -> SwapDone {
    SwapDone {
        robot: 1,
        tick: 3,
        request_id: 9,
        model_id: "policy-77c1".into(),
        path: Some(PathBuf::from("/elsewhere/policy.onnx")),
        model: Some(b"not really onnx, but bytes the recording stores".to_vec()),
    }
}
