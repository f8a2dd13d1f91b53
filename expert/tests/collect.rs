//! Demonstration collection end to end: an expert-driven scenario written to a dataset on disk and
//! read back.

use formation_expert::collect::{CollectError, CollectOptions, collect};
use formation_proto::{BeyondWindow, OccupancySpec};
use formation_trainer_bridge::dataset::{DatasetHeader, DatasetReader, DatasetWriter};
use formation_world::Scenario;

const TINY: &str = r#"
    name = "tiny"
    robots = 3
    duration_s = 2.0
    seed = 11
    runs = 2
    [goal]
    v_star = 0.7
    d_star_choices = [1.0, 2.0]
    [heading]
    schedule = "random"
"#;

fn tiny() -> Scenario {
    Scenario::from_toml_str(TINY, "tiny.toml").expect("valid test scenario")
}

fn header_for(scenario: &Scenario, opts: &CollectOptions<'_>) -> DatasetHeader {
    let spec = scenario.run_spec(opts.base_seed, 0);
    DatasetHeader::new(
        opts.occupancy,
        spec.world.simulated_lidar(),
        spec.v_star,
        opts.base_seed,
        scenario.name(),
    )
}

#[test]
fn collected_demonstrations_round_trip_through_the_dataset() {
    let scenario = tiny();
    let opts = CollectOptions {
        record_every: 2,
        ..CollectOptions::for_scenario(&scenario)
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("demo");
    let mut writer = DatasetWriter::create(&path, header_for(&scenario, &opts)).expect("create");
    let mut progress = Vec::new();
    let report = collect(&opts, &mut writer, &mut |runs, samples| {
        progress.push((runs, samples))
    })
    .expect("collects");
    writer.finish().expect("finish");

    // 2 runs x 40 ticks recorded every 2nd tick x 3 robots.
    assert_eq!(report.runs, 2);
    assert_eq!(report.samples, 2 * 20 * 3);
    assert_eq!(progress, vec![(1, 60), (2, 120)]);
    assert!(report.samples_per_sec > 0.0);

    let samples = DatasetReader::open(&path)
        .expect("open")
        .load_all()
        .expect("read");
    assert_eq!(samples.len(), 120);
    assert!(samples[..60].iter().all(|s| s.run == 0) && samples[60..].iter().all(|s| s.run == 1));
    for sample in &samples {
        assert_eq!(sample.iteration, 0);
        assert!(sample.d_star == 1.0 || sample.d_star == 2.0);
        assert!(sample.wheels.iter().all(|w| w.abs() <= 0.9 + 1e-6));
        assert!(
            sample.delta_phi > -std::f32::consts::PI - 1e-6
                && sample.delta_phi <= std::f32::consts::PI + 1e-6
        );
    }
    // With neighbours 0.6-6 m away, most robots see someone in their 5 x 5 m window.
    let with_neighbours = samples.iter().filter(|s| s.occupancy.contains(&1)).count();
    assert!(
        with_neighbours > samples.len() / 2,
        "{with_neighbours} of {} images show a neighbour",
        samples.len()
    );
}

/// Collecting with `opts` into `writer` is refused before anything is written, because the
/// dataset's header records other `what`.
fn assert_refused_as_mismatch(opts: &CollectOptions<'_>, writer: &mut DatasetWriter, what: &str) {
    let err = collect(opts, writer, &mut |_, _| {}).expect_err("the header disagrees");
    assert!(
        matches!(err, CollectError::WriterMismatch { what: found, .. } if found == what),
        "{err}"
    );
    assert_eq!(writer.samples(), 0, "nothing written on refusal");
}

#[test]
fn collection_refuses_bad_options_and_a_mismatched_dataset() {
    let scenario = tiny();
    let opts = CollectOptions::for_scenario(&scenario);
    let dir = tempfile::tempdir().expect("temp dir");

    let mut writer =
        DatasetWriter::create(&dir.path().join("a"), header_for(&scenario, &opts)).expect("create");
    let zero = CollectOptions {
        record_every: 0,
        ..opts
    };
    assert!(matches!(
        collect(&zero, &mut writer, &mut |_, _| {}),
        Err(CollectError::RecordEveryZero)
    ));

    let border = CollectOptions {
        occupancy: OccupancySpec {
            beyond: BeyondWindow::Border,
            ..opts.occupancy
        },
        ..opts
    };
    assert_refused_as_mismatch(&border, &mut writer, "occupancy settings");

    // Labels of another law than the dataset records would mix two laws in one dataset.
    let mut unshaped = opts;
    unshaped.gains.unshaped = true;
    assert_refused_as_mismatch(&unshaped, &mut writer, "label law");

    // A v* drawn per run has no one v_train to record: refused before any run, naming the key.
    let drawn = Scenario::from_toml_str(
        &TINY.replace("v_star = 0.7", "v_star_range = [0.3, 0.7]"),
        "drawn.toml",
    )
    .expect("valid");
    let drawn_opts = CollectOptions::for_scenario(&drawn);
    let err = collect(&drawn_opts, &mut writer, &mut |_, _| {}).expect_err("v* per run");
    assert!(
        matches!(err, CollectError::VStarPerRun { min: 0.3, max: 0.7 }),
        "{err}"
    );
    assert!(err.to_string().contains("goal.v_star_range"), "{err}");
    assert_eq!(writer.samples(), 0, "nothing written on refusal");
}
