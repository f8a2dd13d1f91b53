//! ONNX Runtime through `OnnxPolicy` against PyTorch on the same random network, and the
//! contract refusals on real ONNX files.

mod common;

use std::path::Path;

use formation_onnx::contract::keys;
use formation_onnx::{ContractViolation, OnnxPolicy, PolicyError, SensorViolation};
use formation_proto::{LidarSpec, OccupancySpec, PolicyInput};

use common::{CASES, SECTORS, SIZE_PX, SLOTS, fixtures};

/// Largest allowed |onnxruntime - torch| per wheel.
const TOLERANCE: f32 = 1e-4;

/// Asserts that ONNX Runtime's wheels `ours` of case `i` are torch's within [`TOLERANCE`].
fn assert_matches_torch(i: usize, ours: [f32; 2], torch: &[f32; 2]) {
    for wheel in 0..2 {
        assert!(
            (ours[wheel] - torch[wheel]).abs() <= TOLERANCE,
            "case {i} wheel {wheel}: ort {} vs torch {}",
            ours[wheel],
            torch[wheel]
        );
    }
}

#[test]
fn outputs_match_torch_and_metadata_is_read() {
    let fx = fixtures("parity");
    let mut policy =
        OnnxPolicy::load(&fx.model("policy.onnx")).expect("fixture follows the contract");

    let meta = policy.metadata();
    assert_eq!(meta.occupancy, OccupancySpec::PAPER, "the paper's images");
    assert_eq!((meta.beams, meta.max_range, meta.v_train), (900, 10.0, 0.7));
    assert_eq!(meta.dataset_id, "parity-fixture");
    assert_eq!(
        meta.extra
            .get("formation.dagger.iteration")
            .map(String::as_str),
        Some("0")
    );
    assert!(
        !meta.extra.contains_key(keys::V_TRAIN),
        "parsed keys are not repeated in extra"
    );
    assert!(
        policy.model_id().starts_with("policy-"),
        "{}",
        policy.model_id()
    );
    assert_eq!(policy.model_id().len(), "policy-".len() + 8);

    let cases = fx.cases();
    assert_eq!(cases.len(), CASES);
    let mut largest_output = 0.0_f32;
    for (i, (image, aux, torch)) in cases.iter().enumerate() {
        let ours = policy
            .infer(&PolicyInput::image_and_aux(image, aux))
            .expect("inference");
        for wheel in 0..2 {
            let diff = (ours[wheel] - torch[wheel]).abs();
            assert!(
                diff <= TOLERANCE,
                "case {i} wheel {wheel}: ort {} vs torch {} (|diff| {diff})",
                ours[wheel],
                torch[wheel]
            );
            largest_output = largest_output.max(torch[wheel].abs());
        }
    }
    assert!(
        largest_output > 1e-3,
        "the reference outputs are not all ~0, so the comparison means something"
    );
}

#[test]
fn repeated_inference_is_deterministic_and_buffers_do_not_leak_between_calls() {
    let fx = fixtures("parity");
    let mut policy = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    let cases = fx.cases();
    let (first_image, first_aux, _) = &cases[0];
    let first = policy
        .infer(&PolicyInput::image_and_aux(first_image, first_aux))
        .expect("infer");
    let (other_image, other_aux, _) = &cases[1];
    let other = policy
        .infer(&PolicyInput::image_and_aux(other_image, other_aux))
        .expect("infer");
    assert_ne!(first, other, "different inputs give different outputs");
    assert_eq!(
        policy
            .infer(&PolicyInput::image_and_aux(first_image, first_aux))
            .expect("infer"),
        first
    );
}

#[test]
fn policy_moves_to_another_thread() {
    let fx = fixtures("parity");
    let mut policy = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    let (image, aux, torch) = fx.cases().swap_remove(2);
    let ours = std::thread::spawn(move || policy.infer(&PolicyInput::image_and_aux(&image, &aux)))
        .join()
        .expect("thread")
        .expect("infer");
    assert!((ours[0] - torch[0]).abs() <= TOLERANCE && (ours[1] - torch[1]).abs() <= TOLERANCE);
}

fn contract_violation(path: &Path) -> (ContractViolation, String) {
    match OnnxPolicy::load(path) {
        Err(err @ PolicyError::Contract { .. }) => {
            let message = err.to_string();
            assert!(
                message.contains("formation train"),
                "the message says how to fix it: {message}"
            );
            let PolicyError::Contract { reason, .. } = err else {
                unreachable!()
            };
            (reason, message)
        }
        other => panic!(
            "{}: expected a contract error, got {other:?}",
            path.display()
        ),
    }
}

#[test]
fn wrong_input_name_is_refused_naming_it() {
    let fx = fixtures("parity");
    let (reason, message) = contract_violation(&fx.model("wrong_name.onnx"));
    assert!(
        matches!(reason, ContractViolation::InputNames { ref found, .. } if found.contains(&"image".to_owned()))
    );
    assert!(
        message.contains("image") && message.contains("[occupancy, aux]"),
        "{message}"
    );
}

/// An image side other than `formation.size_px`, and metadata without its format key: each
/// refused with its reason, the message naming what is wrong.
#[test]
fn a_wrong_image_side_or_missing_metadata_is_refused_naming_it() {
    let fx = fixtures("parity");
    for (file, expected, named) in [
        (
            "small_image.onnx",
            ContractViolation::Shape {
                name: "occupancy".into(),
                expected: "[batch (dynamic), 1, 50, 50]".into(),
                found: vec![-1, 1, 40, 40],
            },
            "[batch, 1, 40, 40]",
        ),
        (
            "no_metadata.onnx",
            ContractViolation::MissingMetadata { key: keys::FORMAT },
            "formation.format",
        ),
    ] {
        let (reason, message) = contract_violation(&fx.model(file));
        assert_eq!(reason, expected, "{file}");
        assert!(message.contains(named), "{file}: {message}");
    }
}

#[test]
fn non_finite_output_is_an_error() {
    let fx = fixtures("parity");
    let mut policy =
        OnnxPolicy::load(&fx.model("nan_output.onnx")).expect("the contract itself is fine");
    let (image, aux, _) = fx.cases().swap_remove(0);
    assert!(
        matches!(policy.infer(&PolicyInput::image_and_aux(&image, &aux)), Err(PolicyError::NonFiniteOutput { left, right, .. }) if left.is_nan() && right.is_nan())
    );
}

#[test]
fn wrong_image_length_is_an_error() {
    let fx = fixtures("parity");
    let mut policy = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    let short = vec![0.0; 40 * 40];
    match policy.infer(&PolicyInput::image_and_aux(&short, &[0.0, 1.0])) {
        Err(PolicyError::InputLength {
            expected, actual, ..
        }) => assert_eq!((expected, actual), (SIZE_PX * SIZE_PX, 1600)),
        other => panic!("expected InputLength, got {other:?}"),
    }
    policy
        .infer(&PolicyInput::image_and_aux(
            &vec![0.0; SIZE_PX * SIZE_PX],
            &[0.0, 1.0],
        ))
        .expect("still usable after a refused call");
}

/// The scalars beside the image must be as many as the model declares (`formation.aux`).
#[test]
fn wrong_aux_width_is_an_error_naming_the_declared_inputs() {
    let fx = fixtures("parity");
    let mut policy = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    let image = vec![0.0; SIZE_PX * SIZE_PX];
    match policy.infer(&PolicyInput::image_and_aux(&image, &[0.0, 1.0, 2.0])) {
        Err(err @ PolicyError::AuxLength { actual: 3, .. }) => {
            assert!(err.to_string().contains("delta_phi,d_star"), "{err}");
        }
        other => panic!("expected AuxLength, got {other:?}"),
    }
    policy
        .infer(&PolicyInput::image_and_aux(&image, &[0.0, 1.0]))
        .expect("still usable after a refused call");
}

#[test]
fn sensor_check_compares_beams_and_range() {
    let fx = fixtures("parity");
    let policy = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    policy
        .check_sensor(&LidarSpec::default())
        .expect("trained with the default 900-beam, 10 m LIDAR");
    let fewer_beams = LidarSpec {
        beams: 360,
        ..LidarSpec::default()
    };
    assert!(matches!(
        policy.check_sensor(&fewer_beams),
        Err(PolicyError::SensorMismatch {
            reason: SensorViolation::Beams {
                trained: 900,
                actual: 360
            },
            ..
        })
    ));
    let longer = LidarSpec {
        max_range: 20.0,
        ..LidarSpec::default()
    };
    let err = policy.check_sensor(&longer).expect_err("another range");
    assert!(
        matches!(
            err,
            PolicyError::SensorMismatch {
                reason: SensorViolation::MaxRange { .. },
                ..
            }
        ),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(
        message.contains("10 m") && message.contains("20 m"),
        "{message}"
    );
}

#[test]
fn missing_model_file_is_reported_with_the_fix() {
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join("no-such-model.onnx");
    let err = OnnxPolicy::load(&path).expect_err("no file");
    assert!(matches!(err, PolicyError::ModelNotFound { path: ref p } if *p == path));
    assert!(err.to_string().contains("formation train"), "{err}");
}

#[test]
fn a_file_that_is_not_onnx_is_a_session_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("garbage.onnx");
    std::fs::write(&path, b"this is not a protobuf").expect("write");
    match OnnxPolicy::load(&path) {
        Err(PolicyError::Session { path: p, reason }) => {
            assert_eq!(p, path);
            assert!(!reason.is_empty());
        }
        other => panic!("expected a Session error, got {other:?}"),
    }
}

/// A model with a range input (`formation.ranges`): ONNX Runtime gives torch's outputs on the
/// three inputs, and the ranges must be one value a sector.
#[test]
fn a_range_input_model_matches_torch_and_checks_its_sectors() {
    let fx = fixtures("parity");
    let mut policy = OnnxPolicy::load(&fx.model("ranges.onnx")).expect("loads");
    let declared = policy.metadata().ranges.expect("declares its ranges");
    assert_eq!((declared.sectors, declared.clip), (SECTORS, 3.0));
    assert_eq!(policy.metadata().io().ranges, Some(declared));
    let cases = fx.ranges_cases();
    assert_eq!(cases.len(), CASES);
    for (i, (image, aux, ranges, torch)) in cases.iter().enumerate() {
        let ours = policy
            .infer(&PolicyInput {
                image,
                aux,
                ranges,
                neighbours: &[],
            })
            .expect("inference");
        assert_matches_torch(i, ours, torch);
    }
    // The ranges reach the network: other ranges, another answer.
    let (image, aux, ranges, _) = &cases[0];
    let closer: Vec<f32> = ranges.iter().map(|r| r * 0.5).collect();
    let first = policy
        .infer(&PolicyInput {
            image,
            aux,
            ranges,
            neighbours: &[],
        })
        .unwrap();
    let moved = policy
        .infer(&PolicyInput {
            image,
            aux,
            ranges: &closer,
            neighbours: &[],
        })
        .unwrap();
    assert_ne!(first, moved);
    match policy.infer(&PolicyInput::image_and_aux(image, aux)) {
        Err(err @ PolicyError::RangesLength { actual: 0, .. }) => {
            assert!(err.to_string().contains("sectors=100,clip=3"), "{err}");
        }
        other => panic!("expected RangesLength, got {other:?}"),
    }
    // A model without ranges refuses them.
    let mut plain = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    match plain.infer(&PolicyInput {
        image,
        aux,
        ranges,
        neighbours: &[],
    }) {
        Err(err @ PolicyError::RangesLength { actual: 100, .. }) => {
            assert!(err.to_string().contains("no range input"), "{err}");
        }
        other => panic!("expected RangesLength, got {other:?}"),
    }
}

/// The `ranges` and `neighbours` inputs and their metadata (`formation.ranges`,
/// `formation.neighbours`) come together or not at all.
#[test]
fn an_extra_input_without_its_declaration_or_the_other_way_round_is_refused() {
    let fx = fixtures("parity");
    for (file, named) in [
        (
            "ranges_undeclared.onnx",
            &["declares no `formation.ranges`"][..],
        ),
        (
            "ranges_missing.onnx",
            &["expected exactly [occupancy, aux, ranges]"],
        ),
        (
            "neighbours_undeclared.onnx",
            &["declares no `formation.neighbours`", "neighbours"],
        ),
        (
            "neighbours_missing.onnx",
            &[
                "expected exactly [occupancy, aux, neighbours]",
                "neighbours",
            ],
        ),
    ] {
        let (_, message) = contract_violation(&fx.model(file));
        for words in named {
            assert!(message.contains(words), "{file}: {words:?} in {message}");
        }
    }
}

/// A model with a neighbour input (`formation.neighbours`): ONNX Runtime gives torch's outputs on
/// the three inputs, the output moves when one slot moves, and the neighbours must be four values
/// a slot.
#[test]
fn a_neighbour_input_model_matches_torch_and_checks_its_slots() {
    let fx = fixtures("parity");
    let mut policy = OnnxPolicy::load(&fx.model("neighbours.onnx")).expect("loads");
    let declared = policy
        .metadata()
        .neighbours
        .expect("declares its neighbours");
    assert_eq!(
        (declared.slots, declared.threshold, declared.nearest),
        (SLOTS, 1.3, 2)
    );
    assert_eq!(policy.metadata().io().neighbours, Some(declared));
    assert_eq!(policy.metadata().io().ranges, None);
    let cases = fx.neighbours_cases();
    assert_eq!(cases.len(), CASES);
    let infer = |policy: &mut OnnxPolicy, image: &[f32], aux: &[f32], neighbours: &[f32]| {
        policy.infer(&PolicyInput {
            image,
            aux,
            ranges: &[],
            neighbours,
        })
    };
    for (i, (image, aux, neighbours, torch)) in cases.iter().enumerate() {
        let ours = infer(&mut policy, image, aux, neighbours).expect("inference");
        assert_matches_torch(i, ours, torch);
    }
    // The neighbours reach the network: one slot moved, another answer, and back again.
    let (image, aux, neighbours, _) = &cases[0];
    let first = infer(&mut policy, image, aux, neighbours).unwrap();
    let mut moved = neighbours.clone();
    moved[0] += 0.5;
    moved[1] -= 0.25;
    let after = infer(&mut policy, image, aux, &moved).unwrap();
    assert_ne!(first, after, "moving slot 0 moves the output");
    let mut last_slot = neighbours.clone();
    last_slot[(SLOTS - 1) * 4..].copy_from_slice(&[0.8, -0.6, 1.0, 1.0]);
    assert_ne!(
        infer(&mut policy, image, aux, &last_slot).unwrap(),
        first,
        "the last slot reaches the network too"
    );
    assert_eq!(infer(&mut policy, image, aux, neighbours).unwrap(), first);

    match policy.infer(&PolicyInput::image_and_aux(image, aux)) {
        Err(err @ PolicyError::NeighboursLength { actual: 0, .. }) => {
            let message = err.to_string();
            assert!(
                message.contains("slots=8,threshold=1.3,nearest=2")
                    && message.contains("formation.neighbours"),
                "{message}"
            );
        }
        other => panic!("expected NeighboursLength, got {other:?}"),
    }
    match infer(&mut policy, image, aux, &neighbours[..SLOTS * 4 - 1]) {
        Err(PolicyError::NeighboursLength { actual, .. }) => assert_eq!(actual, SLOTS * 4 - 1),
        other => panic!("expected NeighboursLength, got {other:?}"),
    }
    // A model without neighbours refuses them.
    let mut plain = OnnxPolicy::load(&fx.model("policy.onnx")).expect("loads");
    match infer(&mut plain, image, aux, neighbours) {
        Err(err @ PolicyError::NeighboursLength { actual: 32, .. }) => {
            assert!(err.to_string().contains("no neighbour input"), "{err}");
        }
        other => panic!("expected NeighboursLength, got {other:?}"),
    }
}
