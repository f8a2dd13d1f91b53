//! The shipped TurtleBot3 model (issue 37): `scenarios/turtlebot3.toml` names it, the real
//! `formation eval` drives it there without `--model`, under every effect of the
//! `turtlebot3-burger` profile, and the summary says the input it declares (the LDS-01's 360 beams
//! and 3.5 m, its range sectors) and that its team formed.

use std::process::Command;
use std::time::Duration;

use formation_tests::{ProcessTest, binaries, repo_root, run};

/// The watchdog limit: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

#[test]
fn the_turtlebot3_scenario_drives_its_own_model_with_its_declared_input() {
    let t = ProcessTest::start("turtlebot3_model", LIMIT);
    let out = t.path().join("eval");
    let mut eval = Command::new(&binaries().cli);
    eval.args([
        "eval",
        "--controller",
        "policy",
        "--robots",
        "3",
        "--runs",
        "2",
    ])
    .arg("--scenario")
    .arg(repo_root().join("scenarios/turtlebot3.toml"))
    .arg("--out")
    .arg(&out);
    run(eval, LIMIT).assert_success().assert_no_panic();

    let summary = formation_schema::read_summary(&out.join("summary.json")).expect("the summary");
    let [input] = summary.model_inputs.as_slice() else {
        panic!("one model, one declared input: {summary:?}");
    };
    assert_eq!(
        (input.lidar_beams, input.occupancy.size_px),
        (360, 50),
        "the TurtleBot3 model takes the LDS-01's ring: {input:?}"
    );
    assert!(
        input.describe().contains("360"),
        "the summary says its input: {}",
        input.describe()
    );
    assert!(
        summary.models.iter().all(|id| id == &input.model),
        "every robot drove the scenario's model: {:?}",
        summary.models
    );
    assert!(
        summary.summary.success_rate_10 > 0.0,
        "two runs of three TurtleBot3s under the full profile form at 10 %: {summary:?}"
    );
}
