//! The Rust writer and the Python trainer agree: a dataset written by `DatasetWriter` trains
//! through `train()` into an ONNX model, a checkpoint and a loss curve.
//!
//! Needs the trainer's Python environment (`bash .ci/setup-python --train`); without PyTorch the test
//! says so and passes, since the Rust side's own behaviour is covered by the unit tests.

use formation_proto::{OccupancySpec, RangeInput, SimulatedLidar};
use formation_trainer_bridge::dataset::{DatasetHeader, DatasetReader, DatasetWriter, Sample};
use formation_trainer_bridge::train::{TrainError, TrainOptions, train};

fn sample(i: u32, iteration: u32) -> Sample {
    let mut occupancy = vec![0_u8; 2500];
    for k in 0..40 {
        occupancy[(i as usize * 37 + k * 61) % 2500] = 1;
    }
    let delta_phi = ((i % 60) as f32 - 30.0) / 10.0;
    Sample {
        occupancy,
        delta_phi,
        d_star: 1.5,
        wheels: [0.3 * delta_phi.sin(), 0.3 * delta_phi.cos()],
        ranges: Vec::new(),
        neighbours: Vec::new(),
        iteration,
        run: i / 20,
        robot: (i % 3) as u8,
    }
}

/// The settings of every dataset these tests write: the paper's images, the default LIDAR,
/// v* 0.7 m/s, seed 3, scenario "e2e".
fn e2e_header() -> DatasetHeader {
    DatasetHeader::new(
        OccupancySpec::PAPER,
        SimulatedLidar::default(),
        0.7,
        3,
        "e2e",
    )
}

#[test]
fn a_rust_written_dataset_trains_into_an_onnx_model() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let data = tmp.path().join("data");
    let header = e2e_header();
    let mut writer = DatasetWriter::create(&data, header)
        .expect("create")
        .with_shard_size(64)
        .expect("shard size");
    for i in 0..150 {
        writer.push(sample(i, 0)).expect("push");
    }
    writer.finish().expect("finish");
    let mut dagger = DatasetWriter::append(&data, 1).expect("append");
    for i in 0..40 {
        dagger.push(sample(1000 + i, 1)).expect("push");
    }
    let manifest = dagger.finish().expect("finish");
    assert_eq!(DatasetReader::open(&data).expect("open").samples(), 190);

    let out = tmp.path().join("models").join("bc.onnx");
    let mut lines = Vec::new();
    let result = train(
        &TrainOptions {
            data: vec![data.clone()],
            out: out.clone(),
            epochs: 2,
            batch_size: 16,
            lr: 1e-3,
            device: "cpu".into(),
            ..TrainOptions::default()
        },
        &mut |line| lines.push(line.to_owned()),
    );
    // A missing Python environment fails here with the fix in its message.
    let report = result.expect("training succeeds");
    assert_eq!(report.epochs, 2);
    assert_eq!(report.samples, 190);
    assert_eq!(report.train_samples + report.val_samples, 190);
    assert!(report.val_samples > 0, "whole runs are held out");
    assert_eq!(
        report.samples_per_epoch, report.train_samples,
        "every sample, unless capped"
    );
    assert_eq!(report.dataset_id, manifest.dataset_id);
    assert_eq!(report.ranges, None);
    assert!(report.final_train_loss.is_finite() && report.final_val_loss.is_finite());
    assert!(report.parity_max_abs_diff <= 1e-4);
    for path in [
        &report.model,
        &report.checkpoint,
        &report.loss_csv,
        &report.loss_png,
    ] {
        assert!(path.is_file(), "{} missing", path.display());
    }
    assert_eq!(report.checkpoint, out.with_extension("pt"));
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("epoch ")).count(),
        2,
        "{lines:?}"
    );
    assert!(
        !lines
            .iter()
            .any(|l| l.starts_with("FORMATION_TRAIN_REPORT"))
    );
}

#[test]
fn a_dataset_with_ranges_trains_a_model_that_declares_them() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let data = tmp.path().join("data");
    let ranges = RangeInput::parse("sectors=100,clip=3").expect("ranges");
    let header = e2e_header().with_ranges(Some(ranges));
    let mut writer = DatasetWriter::create(&data, header).expect("create");
    for i in 0..120 {
        let mut s = sample(i, 0);
        s.ranges = (0..100)
            .map(|k| (0.03 * (k as f32 + i as f32)) % 3.0)
            .collect();
        s.wheels[0] += 0.1 * s.ranges[1];
        writer.push(s).expect("push");
    }
    writer.finish().expect("finish");

    let out = tmp.path().join("ranges.onnx");
    let parity = tmp.path().join("parity.json");
    let mut lines = Vec::new();
    let report = train(
        &TrainOptions {
            data: vec![data],
            out: out.clone(),
            epochs: 1,
            batch_size: 16,
            lr: 1e-3,
            device: "cpu".into(),
            parity_out: Some(parity.clone()),
            ..TrainOptions::default()
        },
        &mut |line| lines.push(line.to_owned()),
    )
    .expect("training succeeds");
    assert_eq!(report.ranges, Some(ranges));
    assert!(report.parity_max_abs_diff <= 1e-4, "{report:?}");
    assert!(
        lines
            .iter()
            .any(|l| l.contains("ranges sectors=100,clip=3")),
        "{lines:?}"
    );
    // The metadata strings are stored as they are in the ONNX protobuf.
    let model = std::fs::read(&out).expect("model");
    let holds = |needle: &[u8]| model.windows(needle.len()).any(|w| w == needle);
    assert!(holds(b"formation.ranges") && holds(b"sectors=100,clip=3"));
    let cases: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&parity).expect("parity")).expect("json");
    assert_eq!(
        cases["cases"][0]["ranges"].as_array().map(Vec::len),
        Some(100)
    );
}

#[test]
fn a_python_failure_carries_its_last_messages() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let data = tmp.path().join("data");
    let header = e2e_header();
    let mut writer = DatasetWriter::create(&data, header).expect("create");
    writer.push(sample(0, 0)).expect("push");
    writer.finish().expect("finish");
    // A checkpoint that is not one: the trainer refuses it after loading the data.
    let bogus = tmp.path().join("bogus.pt");
    std::fs::write(&bogus, b"not a checkpoint").expect("write");
    let result = train(
        &TrainOptions {
            data: vec![data],
            out: tmp.path().join("m.onnx"),
            epochs: 1,
            device: "cpu".into(),
            init_from: Some(bogus),
            ..TrainOptions::default()
        },
        &mut |_| {},
    );
    match result {
        Err(TrainError::Failed { stderr_tail, .. }) => {
            assert!(
                stderr_tail.contains("bogus.pt is not a readable checkpoint"),
                "{stderr_tail}"
            );
        }
        other => panic!("expected a trainer failure, got {other:?}"),
    }
}
