//! `formation eval --ladder PROFILE` through the real binary: one row per rung with both
//! controllers in its JSON, and an unknown profile refused with the known ones named.

use std::process::Command;
use std::time::Duration;

use formation_tests::{
    ProcessTest, TempDir, binaries, case1_scenario, read_json, run, shipped_model,
};
use formation_world::scenario::RobotProfile;

const LIMIT: Duration = Duration::from_secs(600);

#[test]
fn a_ladder_writes_every_rung_with_the_expert_and_the_policy() {
    let t = ProcessTest::start("ladder", LIMIT);
    let scenario = t.case1(2.0);
    let json = t.path().join("ladder.json");
    let mut command = Command::new(&binaries().cli);
    command
        .args([
            "eval",
            "--ladder",
            "pioneer-p3dx",
            "--runs",
            "2",
            "--robots",
            "3",
        ])
        .arg("--scenario")
        .arg(&scenario)
        .arg("--model")
        .arg(shipped_model())
        .arg("--json")
        .arg(&json);
    let finished = run(command, LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("| spread | expert | 3 | 2 |");

    let table = read_json(&json);
    assert_eq!(table["format"], "formation-ladder");
    assert_eq!(table["schema_version"], 1);
    assert_eq!(table["profile"], "pioneer-p3dx");
    let rungs = table["rungs"].as_array().expect("rungs");
    let names: Vec<&str> = rungs.iter().map(|r| r["rung"].as_str().unwrap()).collect();
    // One rung per effect, in the profile's order (which the world's own tests spell out).
    let ladder: Vec<&str> = RobotProfile::Pioneer3dx
        .ladder()
        .iter()
        .map(|r| r.name)
        .collect();
    assert_eq!(names, ladder);
    assert_eq!((names.first(), names.len()), (Some(&"ideal"), 8));
    for rung in rungs {
        let rows = rung["rows"].as_array().expect("rows");
        let controllers: Vec<&str> = rows
            .iter()
            .map(|r| r["controller"].as_str().unwrap())
            .collect();
        assert_eq!(controllers, ["expert", "policy"], "{rung}");
        for row in rows {
            assert_eq!(
                (row["robots"].as_u64(), row["runs"].as_u64()),
                (Some(3), Some(2))
            );
            let success = row["success_rate_10"].as_f64().expect("success_rate_10");
            assert!((0.0..=1.0).contains(&success), "{row}");
        }
    }
    assert_eq!(rungs[2]["added"][0], "robot.motor_tau");
}

#[test]
fn an_unknown_ladder_profile_is_refused_with_the_known_ones() {
    let dir = TempDir::new("ladder-unknown");
    let scenario = case1_scenario(dir.path(), 2.0);
    let mut command = Command::new(&binaries().cli);
    command
        .args(["eval", "--ladder", "turtlebot4", "--runs", "1"])
        .arg("--scenario")
        .arg(&scenario);
    run(command, Duration::from_secs(120)).assert_failure_mentioning(
        "one of \"ideal\", \"pioneer-p3dx\", \"turtlebot3-burger\" (got \"turtlebot4\")",
    );
}
