//! A mirror-averaged policy (`wide/policy.onnx`, the default before issue 22) is exactly
//! symmetric under the task's reflection about the robot's heading axis, as a robot runs it: a
//! scan reflected beam by beam, rendered by the agent's own renderer and run through ONNX Runtime
//! with the heading error negated, gives the same wheel speeds with left and right swapped. The
//! trainer builds that into the graph (`--mirror`: the network's output averaged over the
//! reflection); a network without it, such as the paper's, is not.

use std::path::{Path, PathBuf};

use formation_onnx::OnnxPolicy;
use formation_perception::occupancy::{render, to_f32};
use formation_proto::{LidarSpec, PolicyInput};

fn model(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../onnx/models")
        .join(relative)
}

/// A scan of a few round robots at irregular bearings and distances, with misses elsewhere.
fn scan_of_neighbours(lidar: &LidarSpec) -> Vec<f32> {
    let n = lidar.beams;
    let robots = [
        (0.4_f64, 1.3_f64),
        (1.9, 2.1),
        (3.0, 0.9),
        (4.4, 1.7),
        (5.6, 2.4),
    ];
    (0..n)
        .map(|k| {
            let bearing = std::f64::consts::TAU * k as f64 / n as f64;
            robots
                .iter()
                .filter_map(|&(at, distance)| {
                    let off = (bearing - at + std::f64::consts::PI)
                        .rem_euclid(std::f64::consts::TAU)
                        - std::f64::consts::PI;
                    let lateral = distance * off.sin();
                    (off.abs() < 1.0 && lateral.abs() < 0.25)
                        .then(|| distance * off.cos() - (0.25_f64.powi(2) - lateral.powi(2)).sqrt())
                })
                .fold(None, |nearest: Option<f64>, r| {
                    Some(nearest.map_or(r, |m| m.min(r)))
                })
                .map_or(lidar.max_range as f32, |r| r as f32)
        })
        .collect()
}

/// The largest difference between the policy's wheels on the scan and, swapped, on its reflection.
fn asymmetry(path: &Path) -> f32 {
    let mut policy = OnnxPolicy::load(path).expect("the model loads");
    let spec = policy.metadata().occupancy;
    let lidar = LidarSpec::default();
    let scan = scan_of_neighbours(&lidar);
    let n = scan.len();
    let reflected: Vec<f32> = (0..n).map(|k| scan[(n - k) % n]).collect();
    let cells = spec.size_px * spec.size_px;
    let mut worst = 0.0_f32;
    for (delta_phi, d_star) in [(0.0_f32, 1.5_f32), (0.7, 1.0), (-2.1, 2.2)] {
        let mut wheels = Vec::new();
        for (beams, heading_error) in [(&scan, delta_phi), (&reflected, -delta_phi)] {
            let (mut image, mut input) = (vec![0_u8; cells], vec![0.0_f32; cells]);
            render(beams, &lidar, &spec, &mut image);
            to_f32(&image, &mut input);
            assert!(input.iter().any(|&c| c > 0.0), "the neighbours are drawn");
            wheels.push(
                policy
                    .infer(&PolicyInput::image_and_aux(
                        &input,
                        &[heading_error, d_star],
                    ))
                    .expect("infers"),
            );
        }
        let ([left, right], [mirror_left, mirror_right]) = (wheels[0], wheels[1]);
        worst = worst
            .max((left - mirror_right).abs())
            .max((right - mirror_left).abs());
    }
    worst
}

#[test]
fn the_mirror_averaged_policy_swaps_its_wheels_on_a_reflected_scan() {
    let shipped = model("wide/policy.onnx");
    let policy = OnnxPolicy::load(&shipped).expect("the shipped model loads");
    assert_eq!(
        policy
            .metadata()
            .extra
            .get("formation.policy.mirror_averaged")
            .map(String::as_str),
        Some("true")
    );
    let worst = asymmetry(&shipped);
    assert!(worst < 1e-5, "asymmetry {worst} m/s");
}

#[test]
fn a_network_trained_without_the_mirror_is_not_exactly_symmetric() {
    let worst = asymmetry(&model("paper/policy.onnx"));
    assert!(worst > 1e-3, "asymmetry {worst} m/s");
}
