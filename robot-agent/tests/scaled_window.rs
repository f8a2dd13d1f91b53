//! A shipped model whose occupancy window scales with d* (`onnx/models/scaled/policy.onnx`), run
//! through the agent's decision with ONNX Runtime: the agent reads the scale from the model's
//! metadata and renders each scan for the goal's d*, so a neighbour held at d* lands in the same
//! cell at every spacing, and a goal outside the model's declared d* range is refused.

use std::path::Path;

use formation_proto::{Goal, LidarSpec};
use formation_robot_agent::decision::{Agent, DecisionError};

fn scaled_agent() -> Agent {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/scaled/policy.onnx");
    Agent::from_model_path(&path, LidarSpec::default()).expect("the scaled model loads")
}

/// The cells lit by a scan whose only hit is beam 0 (straight ahead) at `range`.
fn lit_cells(agent: &mut Agent, range: f64, d_star: f64) -> Vec<usize> {
    let lidar = LidarSpec::default();
    let mut scan = vec![lidar.max_range as f32; lidar.beams];
    scan[0] = range as f32;
    let goal = Goal {
        phi_star: 0.0,
        d_star,
        v_star: 0.7,
    };
    let command = agent.act(&scan, 0.0, &goal).expect("decides");
    assert!(command.left.is_finite() && command.right.is_finite());
    let image = agent.image();
    (0..image.len()).filter(|&i| image[i] != 0).collect()
}

#[test]
fn the_scaled_model_sees_a_neighbour_at_d_star_in_one_cell_at_every_spacing() {
    let mut agent = scaled_agent();
    let spec = agent.io().image;
    let reference = spec
        .d_star_ref_m
        .expect("the model declares a window scaled with d*");
    let cells_ahead = (reference / spec.resolution_m).floor() as usize;
    let expected = vec![25 * spec.size_px + 25 + cells_ahead];
    // 2 % beyond d*, a third of a cell, so that no hit sits on a cell boundary.
    for d_star in [0.8, 1.2, 1.9, 2.5] {
        assert_eq!(
            lit_cells(&mut agent, 1.02 * d_star, d_star),
            expected,
            "d* = {d_star}"
        );
    }
    // In metres the same neighbour moves: at 2 d* it is twice as far out.
    assert_ne!(lit_cells(&mut agent, 1.6, 0.8), expected);
}

#[test]
fn a_goal_outside_the_scaled_models_d_star_range_is_refused() {
    let mut agent = scaled_agent();
    let lidar = LidarSpec::default();
    let scan = vec![lidar.max_range as f32; lidar.beams];
    let goal = Goal {
        phi_star: 0.0,
        d_star: 3.0,
        v_star: 0.7,
    };
    let err = agent
        .act(&scan, 0.0, &goal)
        .expect_err("3 m is outside 0.8–2.5 m");
    assert!(
        matches!(err, DecisionError::OutsideEnvelope { .. }),
        "{err}"
    );
}
