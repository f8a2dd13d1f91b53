//! The world process's pure parts: reading the launcher's run specs, what a recording knows of
//! the launch, and how a run's end becomes the process's exit.

use std::path::Path;

use formation_proto::exit::ProcessExit;
use formation_runtime::exchange::StopReason;
use formation_runtime::{ClockMode, RuntimeSettings};
use formation_world::{RunSpec, Scenario};

use super::{Ended, exit_for, launch_info, parse_run_specs};

/// Run `index` of the paper's case 1, with `robots` robots.
fn spec(index: usize, robots: usize) -> RunSpec {
    let text = include_str!("../../scenarios/case1.toml");
    let scenario = Scenario::from_toml_str(text, "case1.toml").expect("case 1 parses");
    let mut spec = scenario.run_spec(1, index);
    spec.n_robots = robots;
    spec
}

fn specs_json(specs: &[RunSpec]) -> Vec<u8> {
    serde_json::to_vec(specs).expect("run specs serialise")
}

#[test]
fn run_specs_of_one_team_size_are_read_in_order() {
    let written = [spec(0, 3), spec(1, 3)];
    let read = parse_run_specs(&specs_json(&written), Path::new("runs.json")).unwrap();
    assert_eq!(read.len(), 2);
    assert_eq!((read[0].index, read[1].index), (0, 1));
    assert_eq!(read[0].n_robots, 3);
}

#[test]
fn run_specs_without_runs_or_with_mixed_teams_are_refused_with_the_file_named() {
    let none = parse_run_specs(b"[]", Path::new("runs.json")).unwrap_err();
    assert_eq!(none.to_string(), "runs.json holds no runs");

    let mixed = parse_run_specs(
        &specs_json(&[spec(0, 3), spec(1, 4)]),
        Path::new("runs.json"),
    )
    .unwrap_err();
    assert!(
        mixed
            .to_string()
            .contains("run 1 has 4 robots but run 0 has 3"),
        "{mixed}"
    );

    let empty_team =
        parse_run_specs(&specs_json(&[spec(0, 0)]), Path::new("runs.json")).unwrap_err();
    assert!(
        empty_team.to_string().contains("has 0 robots"),
        "{empty_team}"
    );

    let garbage = parse_run_specs(b"{", Path::new("runs.json")).unwrap_err();
    assert_eq!(garbage.to_string(), "parsing run specs runs.json");
}

#[test]
fn without_settings_or_a_file_a_recording_knows_the_clock_and_a_policy() {
    use clap::Parser as _;
    let args = super::Args::try_parse_from([
        "formation-world",
        "--run-id",
        "r1",
        "--run-specs",
        "runs.json",
        "--out",
        "out",
    ])
    .unwrap();
    let runtime = RuntimeSettings {
        clock: ClockMode::Realtime,
        ..RuntimeSettings::DEFAULT
    };
    let launch = launch_info(&args, None, &runtime).unwrap();
    assert_eq!(launch.clock, ClockMode::Realtime.as_str());
    assert_eq!(launch.controller, "policy");
    assert!(launch.models.is_empty() && launch.scenario.is_empty());
}

#[test]
fn each_ending_has_its_exit_code() {
    assert_eq!(exit_for(Ok(Ended::Finished)), ProcessExit::Success);
    assert_eq!(exit_for(Ok(Ended::Failed)), ProcessExit::Failure);
    assert_eq!(
        exit_for(Ok(Ended::Stopped(StopReason::ParentGone))),
        ProcessExit::Interrupted
    );
    assert_eq!(
        exit_for(Err(anyhow::anyhow!("no such file"))),
        ProcessExit::Failure
    );
}
