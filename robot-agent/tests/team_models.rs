//! `check_team_models` on real ONNX files: the launcher's check, before any process starts, that
//! every robot's model loads and fits the scenario's LIDAR (beams, range, window).

use std::path::{Path, PathBuf};

use formation_onnx::{PolicyError, SensorViolation};
use formation_proto::LidarSpec;
use formation_robot_agent::decision::{DecisionError, check_team_models};
use formation_runtime::agent::error_chain;

/// The shipped policy: 900 beams, 10 m.
fn shipped() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/policy.onnx")
}

#[test]
fn the_shipped_model_fits_the_default_lidar_and_is_loaded_once_per_file() {
    let models = vec![shipped(); 3];
    let ids = check_team_models(&models, &LidarSpec::default()).expect("the paper's sensor");
    assert_eq!(ids.len(), 3);
    assert!(
        ids.iter()
            .all(|id| id == &ids[0] && id.starts_with("policy-"))
    );
}

#[test]
fn a_range_mismatch_names_the_robot_the_models_range_and_the_scenarios() {
    let lidar = LidarSpec {
        max_range: 5.0,
        ..LidarSpec::default()
    };
    let err = check_team_models(&[shipped(), shipped()], &lidar).expect_err("5 m is not 10 m");
    assert_eq!(err.robot, 0);
    assert!(
        matches!(
            *err.source,
            DecisionError::Policy(PolicyError::SensorMismatch {
                reason: SensorViolation::MaxRange { trained, actual },
                ..
            }) if trained == 10.0 && actual == 5.0
        ),
        "{err:?}"
    );
    // The error with its causes, as the command line prints it (`error: a: b: c`).
    let chain = error_chain(&err);
    assert!(chain.contains("robot 0"), "{chain}");
    assert!(chain.contains("10 m") && chain.contains("5 m"), "{chain}");
}

#[test]
fn a_directory_as_a_model_is_not_a_regular_file_and_names_its_robot() {
    let dir = std::env::temp_dir();
    let err = check_team_models(&[shipped(), dir.clone()], &LidarSpec::default())
        .expect_err("a directory is no model");
    assert_eq!((err.robot, err.path.as_path()), (1, dir.as_path()));
    assert!(
        matches!(
            *err.source,
            DecisionError::Policy(PolicyError::ModelNotAFile {
                kind: "a directory",
                ..
            })
        ),
        "{err:?}"
    );
}
