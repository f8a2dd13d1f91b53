//! Round trips, version and format mismatches, and files written before the schema version, for
//! every format.

use std::collections::BTreeMap;

use formation_proto::wire::{RobotTiming, TickOutcome};
use formation_proto::{GabrielRule, NeighbourRule, Pose, WheelCmd};

use super::*;

fn trajectory() -> Trajectory {
    let pose = |x: f64| Pose {
        x,
        y: 0.1 + 0.2,
        theta: -3.0e-300,
    };
    Trajectory {
        dt: 0.05,
        d_star: 2.0,
        v_star: 0.7,
        edges: vec![(0, 1)],
        neighbours: NeighbourRule::AllPairs,
        times: vec![0.0, 0.05],
        phi_star: vec![std::f64::consts::PI, 1.0 / 3.0],
        poses: vec![vec![pose(0.0), pose(2.0)], vec![pose(0.035), pose(2.035)]],
        commands: vec![vec![
            WheelCmd {
                left: 0.7,
                right: 0.7 + f64::EPSILON,
            };
            2
        ]],
        collisions: vec![(1, 0, 1)],
    }
}

fn metrics() -> RunMetrics {
    RunMetrics {
        success_5: false,
        success_10: true,
        convergence_s_5: None,
        convergence_s_10: Some(9.95),
        rel_formation_error: 0.0625,
        max_edge_window_error: 0.07,
        orientation_error_rad: 0.031,
        collisions: 1,
        team: None,
        incomplete: None,
    }
}

fn run_log() -> RunLog {
    RunLog {
        index: 3,
        metrics: metrics(),
        trajectory: trajectory(),
        clock: "lockstep".into(),
        models: vec!["m-1".into(), "m-2".into()],
        complete: false,
        stop_reason: Some("interrupted by Ctrl-C".into()),
        planned_ticks: Some(1200),
    }
}

fn timing_log() -> TimingLog {
    TimingLog {
        index: 3,
        clock: "realtime".into(),
        dt_s: 0.05,
        tick_start_ns: vec![0, 50_000_123],
        robots: vec![RobotTiming {
            model_ids: vec!["m-1".into()],
            model: vec![0, -1],
            outcome: vec![TickOutcome::Fresh, TickOutcome::Stale],
            round_trip_ns: vec![1500, 0],
            uplink_ns: vec![200, 0],
            occupancy_ns: vec![30, 0],
            inference_ns: vec![900, 0],
            downlink_ns: vec![100, 0],
            lag_ticks: vec![0, 0],
        }],
    }
}

fn summary() -> EvalOutput {
    let q = Quantiles {
        min: 9.0,
        q1: 9.25,
        median: 9.5,
        q3: 9.75,
        max: 10.0,
        count: 2,
    };
    EvalOutput {
        controller: "policy".into(),
        models: vec!["m-1".into()],
        scenario: "table1".into(),
        seed: Some(7),
        summary: Summary {
            runs: 2,
            runs_incomplete: 1,
            success_rate_5: 0.5,
            success_rate_10: 1.0,
            median_convergence_s: Some(9.5),
            median_rel_formation_error: None,
            median_orientation_error_rad: Some(0.03),
            medians_over: Some(MediansOver {
                convergence_s: Coverage {
                    rule: "runs successful at 10 % that converged".into(),
                    runs: 1,
                    of: 2,
                },
                rel_formation_error: Coverage {
                    rule: "runs successful at 10 %".into(),
                    runs: 2,
                    of: 2,
                },
                orientation_error_rad: Coverage {
                    rule: "runs successful at 10 %".into(),
                    runs: 2,
                    of: 2,
                },
            }),
            collisions: 1,
            convergence_s: Some(q),
            rel_formation_error: None,
            orientation_error_rad: Some(q),
            anchor_success_rate: Some(1.0),
            connected_rate: None,
        },
        per_run: vec![metrics(), metrics()],
        braked_ticks: vec![BTreeMap::from([("missing".to_owned(), 4)]), BTreeMap::new()],
        incomplete_runs: vec![IncompleteRun {
            index: 1,
            ticks: 80,
            planned_ticks: Some(1200),
            stop_reason: None,
        }],
        team_size: crate::ModelTeamSize::new("policy-1", &[3, 5], 2)
            .into_iter()
            .collect(),
        goal_speed: crate::ModelGoalSpeed::new(
            "policy-1",
            0.7,
            0.4,
            formation_proto::PolicyOutput::Wheels,
        )
        .into_iter()
        .collect(),
        model_inputs: vec![scaled_model_input()],
        run_logs: vec![0, 1],
        complete: false,
    }
}

fn profile() -> LatencyProfile {
    let stats = StageStats {
        count: 600,
        p50_us: 900.0,
        p90_us: 1000.0,
        p99_us: 1500.0,
        max_us: 3000.0,
        histogram: vec![(1024.0, 500), (2048.0, 90), (4096.0, 10)],
    };
    let stages = BTreeMap::from([("round_trip".to_owned(), stats)]);
    LatencyProfile {
        runs: 2,
        clock: "lockstep".into(),
        used_commands: 600,
        braked: BTreeMap::from([("missing".to_owned(), 3)]),
        braked_per_robot: vec![BTreeMap::from([("missing".to_owned(), 3)])],
        stages: stages.clone(),
        per_agent: vec![stages],
        inference_paper_ms: 2.1,
    }
}

/// Writes `value` to a file, reads it back with `read`, and returns the file's text.
fn round_trip<F: SchemaFile + PartialEq + std::fmt::Debug>(
    value: &F,
    read: fn(&Path) -> Result<F, SchemaError>,
) -> String {
    let dir = tempdir("round-trip");
    let path = dir.join("file.json");
    for bytes in [to_json(value).unwrap(), to_json_pretty(value).unwrap()] {
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(&read(&path).unwrap(), value);
    }
    let text = String::from_utf8(to_json(value).unwrap()).unwrap();
    assert!(
        text.starts_with(&format!(
            "{{\"format\":\"{}\",\"schema_version\":{},",
            F::FORMAT,
            F::VERSION
        )),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
    text
}

fn tempdir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "formation-schema-{tag}-{}-{:?}",
        std::process::id(),
        std::thread::current().id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_run_log_reads_back_bit_for_bit() {
    let log = run_log();
    round_trip(&log, read_run_log);
    let read: RunLog = from_json(&to_json(&log).unwrap(), Path::new("r.json")).unwrap();
    let bits = |t: &Trajectory| -> Vec<u64> {
        t.poses
            .iter()
            .flatten()
            .flat_map(|p| [p.x, p.y, p.theta])
            .chain(t.times.iter().chain(&t.phi_star).copied())
            .chain(t.commands.iter().flatten().flat_map(|c| [c.left, c.right]))
            .map(f64::to_bits)
            .collect()
    };
    assert_eq!(bits(&read.trajectory), bits(&log.trajectory));
}

#[test]
fn a_timing_log_a_summary_and_a_profile_read_back() {
    round_trip(&timing_log(), read_timing_log);
    let text = round_trip(&summary(), read_summary);
    assert!(
        text.contains("\"success_rate_5\":0.5"),
        "the summary keys are at the top level: {text}"
    );
    let unknown_seed = EvalOutput {
        seed: None,
        ..summary()
    };
    let text = round_trip(&unknown_seed, read_summary);
    assert!(
        !text.contains("seed"),
        "an unknown seed is left out: {text}"
    );
    round_trip(&profile(), read_profile);
}

#[test]
fn a_version_1_timing_log_still_reads_and_agent_down_reads_back() {
    let mut log = timing_log();
    log.robots[0].outcome[1] = TickOutcome::AgentDown;
    let text = round_trip(&log, read_timing_log);
    assert!(text.contains("\"agent_down\""), "{text}");
    let old = String::from_utf8(to_json(&timing_log()).unwrap())
        .unwrap()
        .replacen("\"schema_version\":2", "\"schema_version\":1", 1);
    let read: TimingLog = from_json(old.as_bytes(), Path::new("timing/run-0003.json")).unwrap();
    assert_eq!(read, timing_log());
}

#[test]
fn nan_is_written_as_null_and_read_back_as_nan() {
    let mut log = run_log();
    log.metrics.rel_formation_error = f64::NAN;
    log.trajectory.poses[1][0].theta = f64::NAN;
    log.trajectory.phi_star[1] = f64::NAN;
    log.trajectory.commands[0][1].left = f64::INFINITY;
    let text = String::from_utf8(to_json(&log).unwrap()).unwrap();
    assert!(text.contains("\"rel_formation_error\":null"), "{text}");
    let read: RunLog = from_json(text.as_bytes(), Path::new("r.json")).unwrap();
    assert!(read.metrics.rel_formation_error.is_nan());
    assert!(read.trajectory.poses[1][0].theta.is_nan());
    assert!(read.trajectory.phi_star[1].is_nan());
    assert!(read.trajectory.commands[0][1].left.is_nan());
    assert_eq!(read.trajectory.poses[1][1], log.trajectory.poses[1][1]);
}

/// The file of `value` with `schema_version` 3 is refused with the message that says so.
fn refuses_another_version<F: SchemaFile + std::fmt::Debug>(value: &F, what: &str) {
    let text = String::from_utf8(to_json(value).unwrap()).unwrap();
    let newer = text.replacen(
        &format!("\"schema_version\":{}", F::VERSION),
        "\"schema_version\":3",
        1,
    );
    assert_ne!(newer, text);
    let dir = tempdir("version");
    let path = dir.join("runs").join("run-0003.json");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(&path, newer).unwrap();
    let err = read::<F>(&path).unwrap_err();
    assert!(
        matches!(err, SchemaError::Version { found: 3, .. }),
        "{err}"
    );
    assert_eq!(
        err.to_string(),
        format!(
            "{} is a {what} of schema version 3; this build reads {}: re-run it or use the matching formation version",
            path.display(),
            versions(F::OLDEST_VERSION, F::VERSION)
        )
    );
    // A version without a format is not this format; a format without a version is refused too.
    let no_format = text.replacen(&format!("\"format\":\"{}\",", F::FORMAT), "", 1);
    assert!(matches!(
        from_json::<F>(no_format.as_bytes(), &path),
        Err(SchemaError::Format { .. })
    ));
    let no_version = text.replacen(&format!("\"schema_version\":{},", F::VERSION), "", 1);
    let err = from_json::<F>(no_version.as_bytes(), &path).unwrap_err();
    assert!(
        matches!(err, SchemaError::Version { found: 0, .. }),
        "{err}"
    );
    assert!(
        err.to_string().contains("without a schema version"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn run_logs_timing_logs_summaries_and_profiles_of_another_version_are_refused() {
    refuses_another_version(&run_log(), "formation run log");
    refuses_another_version(&timing_log(), "formation timing log");
    refuses_another_version(&summary(), "formation evaluation summary");
    refuses_another_version(&profile(), "formation latency profile");
}

#[test]
fn a_file_of_another_format_is_refused_naming_both() {
    let timing = to_json(&timing_log()).unwrap();
    let err = from_json::<RunLog>(&timing, Path::new("runs/run-0003.json")).unwrap_err();
    assert!(matches!(err, SchemaError::Format { .. }), "{err}");
    assert_eq!(
        err.to_string(),
        "runs/run-0003.json is not a formation run log: its format is `formation-timing-log`, expected `formation-run-log`"
    );
}

/// The file of `value` without the two keys, as written before they existed, reads back as
/// `value`.
fn reads_unversioned<F: SchemaFile + PartialEq + std::fmt::Debug>(value: &F) {
    let unversioned = serde_json::to_vec(value).unwrap();
    assert_eq!(
        &from_json::<F>(&unversioned, Path::new("old.json")).unwrap(),
        value
    );
}

#[test]
fn files_written_before_the_schema_version_read_as_version_1() {
    let path = Path::new("old.json");
    reads_unversioned(&run_log());
    reads_unversioned(&timing_log());
    reads_unversioned(&summary());
    reads_unversioned(&profile());
    // The run logs `formation eval --out` wrote had no clock, no models and no `complete`.
    let old_eval_log = serde_json::json!({
        "index": 0, "metrics": metrics(), "trajectory": trajectory()
    });
    let log: RunLog = from_json(old_eval_log.to_string().as_bytes(), path).unwrap();
    assert!(log.complete && log.clock.is_empty() && log.models.is_empty());
    assert_eq!(log.trajectory, trajectory());
}

#[test]
fn broken_and_unreadable_files_are_errors_naming_them() {
    let text = to_json(&summary()).unwrap();
    let err =
        from_json::<EvalOutput>(&text[..text.len() / 2], Path::new("a/summary.json")).unwrap_err();
    assert!(matches!(err, SchemaError::Parse { .. }), "{err}");
    assert!(err.to_string().contains("a/summary.json"), "{err}");
    let dir = tempdir("unreadable");
    let err = read_summary(&dir).unwrap_err();
    assert!(matches!(err, SchemaError::NotAFile { .. }), "{err}");
    assert!(err.to_string().contains("is a directory"), "{err}");
    let err = read_profile(&dir.join("missing.json")).unwrap_err();
    assert!(matches!(err, SchemaError::Read { .. }), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_version_1_run_log_reads_as_the_all_pairs_formation_and_version_2_keeps_its_rule() {
    let path = Path::new("runs/run-0003.json");
    let mut log = run_log();
    // Version 1 had no `neighbours`.
    let text = String::from_utf8(to_json(&log).unwrap()).unwrap();
    assert!(text.contains("\"schema_version\":2,"));
    let v1 = text
        .replacen("\"schema_version\":2,", "\"schema_version\":1,", 1)
        .replacen(",\"neighbours\":\"all_pairs\"", "", 1);
    assert!(!v1.contains("neighbours"), "{v1}");
    assert_eq!(from_json::<RunLog>(v1.as_bytes(), path).unwrap(), log);

    log.trajectory.neighbours = NeighbourRule::Gabriel(GabrielRule::with_range(7.5));
    log.metrics.team = Some(TeamMetrics {
        connected: true,
        edges_scored: 1,
        median_edge_window_error: 0.01,
        final_mean_edge_error: 0.02,
        final_min_distance: 1.9,
        anchor_success: true,
    });
    let read = from_json::<RunLog>(&to_json(&log).unwrap(), path).unwrap();
    assert_eq!(read, log);
    assert_eq!(versions(1, 2), "versions 1 to 2");
    assert_eq!(versions(1, 1), "version 1");
}

fn scaling() -> ScalingTable {
    ScalingTable {
        scenario: "table1".into(),
        seed: 7,
        duration_s: 60.0,
        rows: vec![ScalingRow {
            controller: "expert".into(),
            model: None,
            robots: 5,
            neighbours: "gabriel".into(),
            runs: 10,
            success_rate_5: 0.9,
            success_rate_10: 1.0,
            anchor_success_rate: 1.0,
            convergence_s: None,
            rel_formation_error: None,
            max_edge_window_error: None,
            collisions: 0,
            team_size: None,
            goal_speed: None,
            model_input: None,
        }],
    }
}

#[test]
fn a_scaling_table_round_trips_and_refuses_another_version() {
    let table = scaling();
    let path = Path::new("scaling.json");
    assert_eq!(
        from_json::<ScalingTable>(&to_json_pretty(&table).unwrap(), path).unwrap(),
        table
    );
    refuses_another_version(&table, "formation scaling table");
}

#[test]
fn summaries_and_metrics_before_incomplete_runs_and_median_rules_still_read() {
    let path = Path::new("summary.json");
    let mut old = summary();
    old.summary.runs_incomplete = 0;
    old.summary.medians_over = None;
    old.run_logs = Vec::new();
    old.goal_speed = Vec::new();
    old.complete = true;
    old.per_run[1].incomplete = Some(TicksPlayed {
        ticks: 80,
        planned_ticks: 1200,
    });
    let mut value: serde_json::Value = serde_json::from_slice(&to_json(&old).unwrap()).unwrap();
    // A summary of before: none of the new keys.
    let object = value.as_object_mut().unwrap();
    for key in [
        "runs_incomplete",
        "medians_over",
        "run_logs",
        "complete",
        "goal_speed",
    ] {
        assert!(!object.contains_key(key), "{key} is left out when empty");
    }
    object["per_run"][1]
        .as_object_mut()
        .unwrap()
        .remove("incomplete")
        .expect("an incomplete run's metrics say so");
    let read: EvalOutput = from_json(value.to_string().as_bytes(), path).unwrap();
    assert!(read.complete && read.run_logs.is_empty() && read.goal_speed.is_empty());
    assert_eq!(read.summary.runs_incomplete, 0);
    assert_eq!(read.summary.medians_over, None);
    assert!(read.per_run.iter().all(RunMetrics::is_complete));
    // The new keys round-trip.
    assert_eq!(
        from_json::<EvalOutput>(&to_json(&old).unwrap(), path).unwrap(),
        old
    );
    assert_eq!(
        from_json::<EvalOutput>(&to_json(&summary()).unwrap(), path).unwrap(),
        summary()
    );
}

/// A model's declared input with a window that scales with d* (reference 1.5 m, far hits on the
/// border) over a trained d* range of 0.8-2.5 m, and LIDAR noise of 0.01 m.
pub(crate) fn scaled_model_input() -> crate::ModelInput {
    crate::ModelInput {
        model: "policy-1".into(),
        occupancy: formation_proto::OccupancySpec {
            beyond: formation_proto::BeyondWindow::Border,
            d_star_ref_m: Some(1.5),
            ..formation_proto::OccupancySpec::PAPER
        },
        lidar_beams: 900,
        lidar_max_range_m: 10.0,
        lidar_noise_std_m: Some(0.01),
        trained_d_star_m: Some([0.8, 2.5]),
    }
}

#[test]
fn the_models_declared_inputs_round_trip_and_files_without_them_still_read() {
    let path = Path::new("summary.json");
    let text = round_trip(&summary(), read_summary);
    assert!(
        text.contains(
            "\"model_inputs\":[{\"model\":\"policy-1\",\"occupancy\":{\"size_px\":50,\
             \"resolution_m\":0.1,\"beyond\":\"border\",\"d_star_ref_m\":1.5},\
             \"lidar_beams\":900,\"lidar_max_range_m\":10.0,\"lidar_noise_std_m\":0.01,\
             \"trained_d_star_m\":[0.8,2.5]}]"
        ),
        "{text}"
    );
    // A summary of before (and the expert's): no key, no inputs.
    let mut value: serde_json::Value =
        serde_json::from_slice(&to_json(&summary()).unwrap()).unwrap();
    value.as_object_mut().unwrap().remove("model_inputs");
    let read: EvalOutput = from_json(value.to_string().as_bytes(), path).unwrap();
    assert!(read.model_inputs.is_empty());
    let expert = EvalOutput {
        model_inputs: Vec::new(),
        ..summary()
    };
    assert!(
        !String::from_utf8(to_json(&expert).unwrap())
            .unwrap()
            .contains("model_inputs")
    );
    // A fixed window leaves its reference d* out; a model without an envelope, its range.
    let paper = crate::ModelInput {
        occupancy: formation_proto::OccupancySpec::PAPER,
        lidar_noise_std_m: None,
        trained_d_star_m: None,
        ..scaled_model_input()
    };
    let shard = crate::EvalShard {
        controller: "policy".into(),
        models: vec!["policy-1".into()],
        scenario: "table1".into(),
        seed: 7,
        team_size: Vec::new(),
        goal_speed: Vec::new(),
        model_inputs: vec![paper.clone()],
        first_run: 0,
        per_run: vec![metrics()],
    };
    let text = String::from_utf8(to_json(&shard).unwrap()).unwrap();
    assert!(
        !text.contains("d_star_ref_m") && !text.contains("trained_d_star_m"),
        "{text}"
    );
    assert_eq!(
        from_json::<crate::EvalShard>(text.as_bytes(), path).unwrap(),
        shard
    );
    let mut table = scaling();
    table.rows[0].model_input = Some(paper);
    assert_eq!(
        from_json::<ScalingTable>(&to_json(&table).unwrap(), Path::new("scaling.json")).unwrap(),
        table
    );
}

#[test]
fn a_goal_speed_off_the_trained_one_is_written_beside_the_team_size() {
    let text = String::from_utf8(to_json(&summary()).unwrap()).unwrap();
    assert!(
        text.contains(
            r#""goal_speed":[{"model":"policy-1","trained_v_star":0.7,"v_star":0.4,"factor":0.5714285714285715,"fit":"slower"}]"#
        ),
        "{text}"
    );
    assert_eq!(
        crate::ModelGoalSpeed::new("m", 0.0, 0.4, formation_proto::PolicyOutput::Wheels),
        None
    );
    let trained =
        crate::ModelGoalSpeed::new("m", 0.7, 0.7, formation_proto::PolicyOutput::Wheels).unwrap();
    assert!(!trained.is_outside() && trained.describe().is_none());
}

/// A formation-velocity model is not scaled by v*/v_train: its record says which output it
/// has, and its note says the reference term follows v* (up to the expert's cap), not that its
/// commands are scaled.
#[test]
fn a_formation_velocity_model_off_its_trained_speed_is_not_said_to_be_scaled() {
    let output = formation_proto::PolicyOutput::FormationVelocity;
    let off = crate::ModelGoalSpeed::new("pair", 0.7, 0.75, output).unwrap();
    let text = serde_json::to_string(&off).unwrap();
    assert!(
        text.ends_with(r#""fit":"faster","output":"formation_velocity"}"#),
        "{text}"
    );
    let back: crate::ModelGoalSpeed = serde_json::from_str(&text).unwrap();
    assert_eq!(back, off);
    // Above the expert's reference cap the note says the team moves at the cap.
    let note = off.describe().unwrap();
    assert!(
        note.contains("its reference term is capped at 0.7 m/s as the expert's is")
            && !note.contains("scaled"),
        "{note}"
    );
    let slower = crate::ModelGoalSpeed::new("pair", 0.7, 0.65, output).unwrap();
    let note = slower.describe().unwrap();
    assert!(
        note.ends_with(
            "its reference term follows v* as the expert's does, its corrections are as trained"
        ),
        "{note}"
    );
    let wheels =
        crate::ModelGoalSpeed::new("paper", 0.7, 0.75, formation_proto::PolicyOutput::Wheels)
            .unwrap();
    let note = wheels.describe().unwrap();
    assert!(
        note.ends_with("its commands are scaled by v*/v_train"),
        "{note}"
    );
}
