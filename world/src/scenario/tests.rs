//! The scenario tests: parsing, validation messages, placement and the runs' determinism.

use super::plan::*;
use super::*;
use crate::test_scratch::Scratch;

const SHIPPED: [(&str, &str); 5] = [
    ("case1", include_str!("../../../scenarios/case1.toml")),
    ("case2", include_str!("../../../scenarios/case2.toml")),
    ("case3", include_str!("../../../scenarios/case3.toml")),
    ("table1", include_str!("../../../scenarios/table1.toml")),
    ("collect", include_str!("../../../scenarios/collect.toml")),
];

const MINIMAL: &str = r#"
name = "t"
robots = 3
duration_s = 10.0
seed = 5
[goal]
v_star = 0.7
d_star = 2.0
[heading]
schedule = "constant"
phi = 1.0
"#;

fn parse(text: &str) -> Result<Scenario, ScenarioError> {
    Scenario::from_toml_str(text, "scenarios/x.toml")
}

fn error_text(text: &str) -> String {
    match parse(text) {
        Ok(scenario) => panic!("expected an error, parsed {scenario:?}"),
        Err(error) => error.to_string(),
    }
}

/// `MINIMAL` with `old` replaced by `new` (asserting `old` is there).
fn edited(old: &str, new: &str) -> String {
    assert!(MINIMAL.contains(old), "{old:?} not in the minimal scenario");
    MINIMAL.replacen(old, new, 1)
}

#[test]
fn a_d_star_range_draws_every_run_uniformly_within_it() {
    let scenario = parse(&edited("d_star = 2.0", "d_star_range = [0.8, 2.5]")).unwrap();
    assert_eq!(*scenario.d_star(), DStarPlan::Range { min: 0.8, max: 2.5 });
    assert_eq!(scenario.d_star().bounds(), [0.8, 2.5]);
    let draws: Vec<f64> = (0..400).map(|i| scenario.run_spec(9, i).d_star).collect();
    assert!(draws.iter().all(|d| (0.8..=2.5).contains(d)));
    let below_middle = draws.iter().filter(|&&d| d < 1.65).count();
    assert!(
        (150..=250).contains(&below_middle),
        "{below_middle} of 400 below the middle"
    );
    let distinct: std::collections::BTreeSet<u64> = draws.iter().map(|d| d.to_bits()).collect();
    assert_eq!(distinct.len(), 400, "a continuous draw");
    assert_eq!(
        scenario.run_spec(9, 7).d_star,
        draws[7],
        "a pure function of the run"
    );
}

#[test]
fn a_v_star_range_draws_every_run_uniformly_within_it_and_moves_no_other_draw() {
    let fixed = parse(&edited("d_star = 2.0", "d_star_range = [0.8, 2.5]")).unwrap();
    let text = edited("v_star = 0.7", "v_star_range = [0.05, 0.2]")
        .replace("d_star = 2.0", "d_star_range = [0.8, 2.5]");
    let scenario = parse(&text).unwrap();
    assert_eq!(
        scenario.v_star(),
        VStarPlan::Range {
            min: 0.05,
            max: 0.2
        }
    );
    assert_eq!(scenario.v_star().bounds(), [0.05, 0.2]);
    assert_eq!(scenario.v_star().fixed(), None);
    let draws: Vec<f64> = (0..400).map(|i| scenario.run_spec(9, i).v_star).collect();
    assert!(draws.iter().all(|v| (0.05..=0.2).contains(v)));
    let below_middle = draws.iter().filter(|&&v| v < 0.125).count();
    assert!(
        (150..=250).contains(&below_middle),
        "{below_middle} of 400 below the middle"
    );
    let distinct: std::collections::BTreeSet<u64> = draws.iter().map(|v| v.to_bits()).collect();
    assert_eq!(distinct.len(), 400, "a continuous draw");
    for i in [0, 7, 399] {
        // A run replays alone, bit for bit, and goes to every tick's goal.
        let spec = scenario.run_spec(9, i);
        assert_eq!(spec, scenario.run_spec(9, i));
        assert_eq!(spec.v_star.to_bits(), draws[i].to_bits());
        assert_eq!(spec.goal_at(3.0).v_star, spec.v_star);
        // v* has a generator of its own: every other draw is the fixed-v* scenario's.
        let other = fixed.run_spec(9, i);
        assert_eq!((spec.d_star, spec.heading), (other.d_star, other.heading));
        assert_eq!(spec.initial, other.initial);
        assert_eq!(spec.noise_seed, other.noise_seed);
    }
    // Another base seed draws other speeds.
    assert_ne!(scenario.run_spec(10, 0).v_star, draws[0]);
    // A range of one speed is that speed.
    let one = parse(&edited("v_star = 0.7", "v_star_range = [0.3, 0.3]")).unwrap();
    assert!((0..20).all(|i| one.run_spec(1, i).v_star == 0.3));
}

#[test]
fn a_v_star_range_is_checked_against_the_profiles_top_speed() {
    let text = edited("v_star = 0.7", "v_star_range = [0.05, 0.3]").replace(
        "phi = 1.0",
        "phi = 1.0\n[robot]\nprofile = \"turtlebot3-burger\"",
    );
    let (field, problem) = invalid_field(&text);
    assert_eq!(field, "goal.v_star_range[1]");
    assert!(
        problem.contains("0.22, the \"turtlebot3-burger\" profile's"),
        "{problem}"
    );
    let fits = text.replace("0.3]", "0.2]");
    assert!(parse(&fits).is_ok());
}

#[test]
fn a_fixed_v_star_serializes_as_the_number_it_always_was() {
    let scenario = parse(MINIMAL).unwrap();
    let json = serde_json::to_value(&scenario).unwrap();
    assert_eq!(json["v_star"], serde_json::json!(0.7));
    let ranged = parse(&edited("v_star = 0.7", "v_star_range = [0.1, 0.2]")).unwrap();
    let json = serde_json::to_value(&ranged).unwrap();
    assert_eq!(json["v_star"], serde_json::json!({"min": 0.1, "max": 0.2}));
}

#[test]
fn the_farthest_end_of_a_v_star_range_is_the_one_a_speed_note_speaks_of() {
    let range = VStarPlan::Range {
        min: 0.05,
        max: 0.2,
    };
    assert_eq!(range.farthest_from(0.7), 0.05);
    assert_eq!(range.farthest_from(0.04), 0.2);
    assert_eq!(
        range.farthest_from(0.1),
        0.05,
        "a tie (2x either way) takes the slower end"
    );
    assert_eq!(VStarPlan::Fixed(0.3).farthest_from(0.7), 0.3);
}

fn invalid_field(text: &str) -> (String, String) {
    match parse(text) {
        Err(ScenarioError::Invalid {
            origin,
            field,
            problem,
        }) => {
            assert_eq!(origin, "scenarios/x.toml");
            (field, problem)
        }
        other => panic!("expected ScenarioError::Invalid, got {other:?}"),
    }
}

/// Every file in `scenarios/` parses, under the name of its file; the generalisation variants
/// of table1 differ from it only where their names say.
#[test]
fn every_file_in_the_scenarios_folder_parses_under_its_own_name() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let mut parsed = std::collections::BTreeMap::new();
    for entry in std::fs::read_dir(&dir).expect("the scenarios folder") {
        let path = entry.expect("a folder entry").path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .expect("a file name");
        let scenario = Scenario::from_path(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scenario.name(), stem, "{}", path.display());
        parsed.insert(stem.to_owned(), scenario);
    }
    assert!(parsed.len() >= 13, "{:?}", parsed.keys());
    let table1 = &parsed["table1"];
    for (name, d_star, noise) in [
        ("table1-d125", Some(1.25), 0.0),
        ("table1-d175", Some(1.75), 0.0),
        ("table1-noise", None, 0.03),
    ] {
        let variant = &parsed[name];
        assert_eq!(
            variant.world_config().lidar_noise.noise_std,
            noise,
            "{name}"
        );
        match d_star {
            Some(d) => assert_eq!(*variant.d_star(), DStarPlan::Fixed(d), "{name}"),
            None => assert_eq!(variant.d_star(), table1.d_star(), "{name}"),
        }
        assert_eq!(
            (variant.n_robots(), variant.runs(), variant.seed()),
            (table1.n_robots(), table1.runs(), table1.seed()),
            "{name}"
        );
    }
}

#[test]
fn every_shipped_scenario_parses_with_the_papers_settings() {
    for (name, text) in SHIPPED {
        let scenario = Scenario::from_toml_str(text, name).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scenario.name(), name);
        assert_eq!(scenario.n_robots(), 3);
        assert_eq!(scenario.v_star(), VStarPlan::Fixed(0.7));
        assert_eq!(scenario.world_config().dt, DEFAULT_DT);
        assert_eq!(scenario.world_config().lidar, LidarSpec::default());
        assert_eq!(*scenario.initial_conditions(), InitialConditions::default());
    }
    let case1 = parse(SHIPPED[0].1).unwrap();
    assert_eq!(
        *case1.heading(),
        HeadingPlan::Fixed(HeadingSchedule::Constant { phi: 3.76 })
    );
    assert_eq!(*case1.d_star(), DStarPlan::Fixed(2.0));
    assert_eq!((case1.seed(), case1.duration_s()), (1, 60.0));
    let case2 = parse(SHIPPED[1].1).unwrap();
    assert_eq!(
        *case2.heading(),
        HeadingPlan::Fixed(HeadingSchedule::Ramp {
            omega: 0.1,
            phi0: 0.0
        })
    );
    assert_eq!(*case2.d_star(), DStarPlan::Fixed(1.0));
    let case3 = parse(SHIPPED[2].1).unwrap();
    assert_eq!(
        *case3.heading(),
        HeadingPlan::Fixed(HeadingSchedule::Sine {
            omega: 0.2,
            amplitude: 1.0,
            phi0: 0.0
        })
    );
    assert_eq!(*case3.d_star(), DStarPlan::Fixed(1.5));
    let table1 = parse(SHIPPED[3].1).unwrap();
    assert_eq!(
        (table1.runs(), table1.seed(), table1.duration_s()),
        (100, 7, 60.0)
    );
    assert_eq!(*table1.heading(), HeadingPlan::RandomConstant);
    assert_eq!(*table1.d_star(), DStarPlan::Choices(vec![1.0, 1.5, 2.0]));
    let collect = parse(SHIPPED[4].1).unwrap();
    assert_eq!(*collect.heading(), HeadingPlan::RandomConstant);
    assert_eq!(collect.d_star(), table1.d_star());
    assert_ne!(
        collect.seed(),
        table1.seed(),
        "training runs must not replay evaluation runs"
    );
    let spec = collect.run_spec(collect.seed(), 0);
    let samples = collect.runs() as u64 * spec.ticks() * collect.n_robots() as u64;
    assert_eq!(samples, 110_160, "the paper's data set size");
}

#[test]
fn defaults_fill_optional_keys_and_partial_tables() {
    let scenario = parse(&format!(
        "{MINIMAL}[lidar]\nnoise_std = 0.03\n[robot]\nmax_wheel_speed = 0.8\n"
    ))
    .unwrap();
    let (lidar, noise) = (
        scenario.world_config().lidar,
        scenario.world_config().lidar_noise,
    );
    assert_eq!(
        (lidar.beams, lidar.max_range, noise.noise_std),
        (900, 10.0, 0.03)
    );
    let robot = scenario.world_config().robot;
    assert_eq!(robot.max_wheel_speed, 0.8);
    assert_eq!(robot.body_radius, RobotParams::default().body_radius);
    assert_eq!(scenario.runs(), 1);
    assert!(scenario.agent_models().is_empty());
}

#[test]
fn unknown_keys_are_rejected_by_name_at_every_level() {
    let cases = [
        (edited("seed = 5", "seed = 5\nsed = 6"), "sed"),
        (edited("d_star = 2.0", "d_star = 2.0\ndstar = 2.0"), "dstar"),
        (edited("phi = 1.0", "phi = 1.0\nphy = 2.0"), "phy"),
        (
            format!("{MINIMAL}[init]\ndisc_radius = 3.0\nspacing = 1.0\n"),
            "spacing",
        ),
        (format!("{MINIMAL}[lidar]\nbeam = 360\n"), "beam"),
        (format!("{MINIMAL}[robot]\nmax_speed = 1.0\n"), "max_speed"),
        (
            format!("{MINIMAL}[[agent]]\nrobot = 0\nmodel = \"a.onnx\"\nweights = 1\n"),
            "weights",
        ),
        (format!("{MINIMAL}[extra]\nx = 1\n"), "extra"),
    ];
    for (text, key) in cases {
        let error = parse(&text).expect_err(key);
        assert!(
            matches!(error, ScenarioError::Parse { .. }),
            "{key}: {error:?}"
        );
        let message = error.to_string();
        assert!(message.starts_with("scenarios/x.toml: "), "{message}");
        assert!(
            message.contains(&format!("unknown field `{key}`")),
            "{key}: {message}"
        );
    }
}

#[test]
fn unknown_schedule_is_rejected_with_the_valid_names() {
    let message = error_text(&edited("\"constant\"", "\"spiral\""));
    assert!(
        message.contains("spiral") && message.contains("ramp"),
        "{message}"
    );
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "a table of every invalid value and its message, one case per line"
)]
fn invalid_values_name_the_field_and_the_value() {
    let (field, problem) = invalid_field(&edited("d_star = 2.0", "d_star = -1"));
    assert_eq!(
        (field.as_str(), problem.as_str()),
        ("goal.d_star", "must be in [0.01, 100] m (got -1)")
    );
    assert_eq!(
        error_text(&edited("d_star = 2.0", "d_star = -1")),
        "scenarios/x.toml: goal.d_star must be in [0.01, 100] m (got -1)"
    );

    let cases = [
        (
            edited("d_star = 2.0", "d_star = nan"),
            "goal.d_star",
            "finite",
        ),
        (
            edited("d_star = 2.0", "d_star = 0.0"),
            "goal.d_star",
            "[0.01, 100] m",
        ),
        (
            edited("d_star = 2.0", "d_star_choices = [1.0, inf]"),
            "goal.d_star_choices[1]",
            "finite",
        ),
        (
            edited("d_star = 2.0", "d_star_choices = []"),
            "goal.d_star_choices",
            "empty",
        ),
        (
            edited("d_star = 2.0", "d_star = 2.0\nd_star_choices = [1.0]"),
            "goal.d_star",
            "exactly one",
        ),
        (edited("d_star = 2.0", ""), "goal.d_star", "missing"),
        (
            edited("d_star = 2.0", "d_star_range = [2.5, 0.8]"),
            "goal.d_star_range",
            "smallest < largest",
        ),
        (
            edited("d_star = 2.0", "d_star_range = [0.8, nan]"),
            "goal.d_star_range[1]",
            "finite",
        ),
        (
            edited("d_star = 2.0", "d_star_range = [0.8, 2.5]\nd_star = 1.0"),
            "goal.d_star",
            "exactly one",
        ),
        (edited("robots = 3", "robots = 0"), "robots", "(got 0)"),
        (edited("robots = 3", "robots = 1"), "robots", "(got 1)"),
        (
            edited("duration_s = 10.0", "duration_s = inf"),
            "duration_s",
            "finite",
        ),
        (
            edited("duration_s = 10.0", "duration_s = 0.5\ndt = 1.0"),
            "dt",
            "<= duration_s",
        ),
        (
            edited("duration_s = 10.0", "duration_s = 10.0\ndt = 0.3"),
            "dt",
            "whole steps",
        ),
        (
            edited("duration_s = 10.0", "duration_s = 10.0\nruns = 0"),
            "runs",
            "[1, 10000] (got 0)",
        ),
        (
            edited("v_star = 0.7", "v_star = 1.5"),
            "goal.v_star",
            "max_wheel_speed",
        ),
        (
            edited("v_star = 0.7", "v_star = -nan"),
            "goal.v_star",
            "finite",
        ),
        (edited("v_star = 0.7", ""), "goal.v_star", "is missing"),
        (
            edited("v_star = 0.7", "v_star = 0.7\nv_star_range = [0.1, 0.2]"),
            "goal.v_star",
            "given both ways; give exactly one of goal.v_star",
        ),
        (
            edited("v_star = 0.7", "v_star_range = [0.3, 0.2]"),
            "goal.v_star_range",
            "slowest <= fastest (got [0.3, 0.2])",
        ),
        (
            edited("v_star = 0.7", "v_star_range = [-0.1, 0.2]"),
            "goal.v_star_range[0]",
            "(got -0.1)",
        ),
        (
            edited("v_star = 0.7", "v_star_range = [0.1, inf]"),
            "goal.v_star_range[1]",
            "finite",
        ),
        (
            edited("v_star = 0.7", "v_star_range = [0.1, 1.5]"),
            "goal.v_star_range[1]",
            "must be <= robot.max_wheel_speed (0.9)",
        ),
        (edited("phi = 1.0", "phi = nan"), "heading.phi", "finite"),
        (edited("phi = 1.0", ""), "heading.phi", "required"),
        (
            edited("phi = 1.0", "phi = 1.0\nomega = 0.1"),
            "heading.omega",
            "not a parameter",
        ),
        (
            edited("schedule = \"constant\"\nphi = 1.0", "schedule = \"ramp\""),
            "heading.omega",
            "required",
        ),
        (
            edited(
                "schedule = \"constant\"\nphi = 1.0",
                "schedule = \"random\"\nphi = 1.0",
            ),
            "heading.phi",
            "not a parameter",
        ),
        (
            format!("{MINIMAL}[init]\nmin_spacing = 0.3\n"),
            "init.min_spacing",
            "body_radius",
        ),
        (
            format!("{MINIMAL}[init]\ndisc_radius = 0.5\n"),
            "init.disc_radius",
            "too small",
        ),
        (
            format!("{MINIMAL}[lidar]\nbeams = 0\n"),
            "lidar.beams",
            "[8, 900]",
        ),
        (
            format!("{MINIMAL}[lidar]\nnoise_std = -0.1\n"),
            "lidar.noise_std",
            "[0, 10] m",
        ),
        (
            format!("{MINIMAL}[robot]\nmax_wheel_accel = 0.0\n"),
            "robot.max_wheel_accel",
            "[0.01, 1000] m/s^2",
        ),
        (
            format!("{MINIMAL}[robot]\nwheel_separation = nan\n"),
            "robot.wheel_separation",
            "finite",
        ),
        (
            format!("{MINIMAL}[[agent]]\nrobot = 3\nmodel = \"a.onnx\"\n"),
            "agent[0].robot",
            "< robots (3)",
        ),
        (
            format!(
                "{MINIMAL}[[agent]]\nrobot = 1\nmodel = \"a.onnx\"\n[[agent]]\nrobot = 1\nmodel = \"b.onnx\"\n"
            ),
            "agent[1].robot",
            "second time",
        ),
        (
            format!("{MINIMAL}[[agent]]\nrobot = 1\nmodel = \"\"\n"),
            "agent[0].model",
            "empty",
        ),
        (edited("name = \"t\"", "name = \" \""), "name", "empty"),
    ];
    for (text, expected_field, expected_problem) in cases {
        let (field, problem) = invalid_field(&text);
        assert_eq!(field, expected_field, "{problem}");
        assert!(
            problem.contains(expected_problem),
            "{field}: {problem:?} lacks {expected_problem:?}"
        );
    }
}

/// Asserts that `text` is refused at `field` with a problem containing every needle.
fn refused(text: &str, field: &str, needles: &[&str]) {
    let (found, problem) = invalid_field(text);
    assert_eq!(found, field, "{problem}");
    for needle in needles {
        assert!(
            problem.contains(needle),
            "{field}: {problem:?} lacks {needle:?}"
        );
    }
}

#[test]
fn run_size_limits_are_enforced_with_the_allowed_range() {
    // Issue: duration_s = 1e12 was accepted and a run never ended.
    refused(
        &edited("duration_s = 10.0", "duration_s = 1e12"),
        "duration_s",
        &["[0.001, 3600] s", "(got 1e12)"],
    );
    refused(
        &edited("duration_s = 10.0", "duration_s = 3600.5"),
        "duration_s",
        &["[0.001, 3600] s"],
    );
    parse(&edited("duration_s = 10.0", "duration_s = 3600.0")).expect("an hour is allowed");
    refused(
        &edited("duration_s = 10.0", "duration_s = 10.0\ndt = 1e-4"),
        "dt",
        &["[0.001, 1] s", "(got 0.0001)"],
    );
    refused(
        &edited("duration_s = 10.0", "duration_s = 10.0\ndt = 2.0"),
        "dt",
        &["[0.001, 1] s", "(got 2)"],
    );
    refused(
        &edited("robots = 3", "robots = 1025"),
        "robots",
        &["[2, 1024]", "(got 1025)"],
    );
    refused(
        &edited("duration_s = 10.0", "duration_s = 10.0\nruns = 10001"),
        "runs",
        &["[1, 10000]", "(got 10001)"],
    );
    refused(
        &format!("{MINIMAL}[lidar]\nbeams = 901\n"),
        "lidar.beams",
        &["[8, 900]", "(got 901)"],
    );
    refused(
        &format!("{MINIMAL}[lidar]\nbeams = 7\n"),
        "lidar.beams",
        &["[8, 900]"],
    );
    // Each factor within its limit, the product over it: 1000 robots x 72,000 ticks.
    let crowd = edited("robots = 3", "robots = 1000")
        .replace("duration_s = 10.0", "duration_s = 3600.0")
        + "[init]\ndisc_radius = 100.0\n";
    refused(
        &crowd,
        "duration_s",
        &["robots x ticks", "72000000", "10000000"],
    );
    refused(
        &edited(
            "d_star = 2.0",
            &format!("d_star_choices = [{}]", ["1.0"; 257].join(", ")),
        ),
        "goal.d_star_choices",
        &["257 entries", "256"],
    );
}

#[test]
fn numbers_must_fit_their_range_and_an_f32() {
    // Issue: d_star = 1e308 was accepted and overflowed to infinity in the f32 policy input.
    let cases: [(String, &str, &[&str]); 11] = [
        (
            edited("d_star = 2.0", "d_star = 1e308"),
            "goal.d_star",
            &["[0.01, 100] m", "(got 1e308)"],
        ),
        (
            edited("d_star = 2.0", "d_star = 1e-50"),
            "goal.d_star",
            &["[0.01, 100] m", "(got 1e-50)"],
        ),
        (
            edited("d_star = 2.0", "d_star_choices = [1.0, 1e39]"),
            "goal.d_star_choices[1]",
            &["[0.01, 100] m", "(got 1e39)"],
        ),
        (
            edited("v_star = 0.7", "v_star = -0.1"),
            "goal.v_star",
            &["[0, 10] m/s", "(got -0.1)"],
        ),
        (
            edited("phi = 1.0", "phi = 1e20"),
            "heading.phi",
            &["[-1000, 1000] rad", "(got 1e20)"],
        ),
        (
            edited(
                "schedule = \"constant\"\nphi = 1.0",
                "schedule = \"ramp\"\nomega = 1e300",
            ),
            "heading.omega",
            &["[-100, 100] rad/s", "(got 1e300)"],
        ),
        (
            edited(
                "schedule = \"constant\"\nphi = 1.0",
                "schedule = \"sine\"\nomega = 0.2\namplitude = -inf",
            ),
            "heading.amplitude",
            &["finite", "[-1000, 1000] rad", "(got -inf)"],
        ),
        (
            format!("{MINIMAL}[lidar]\nmax_range = 1e-9\n"),
            "lidar.max_range",
            &["[0.1, 1000] m", "(got 1e-9)"],
        ),
        (
            format!("{MINIMAL}[lidar]\nnoise_std = 1e40\n"),
            "lidar.noise_std",
            &["[0, 10] m", "(got 1e40)"],
        ),
        (
            format!("{MINIMAL}[robot]\nbody_radius = 1e-30\n"),
            "robot.body_radius",
            &["[0.01, 10] m"],
        ),
        (
            format!("{MINIMAL}[init]\ndisc_radius = 1e300\n"),
            "init.disc_radius",
            &["[0.01, 1000] m"],
        ),
    ];
    for (text, field, needles) in cases {
        refused(&text, field, needles);
    }
    let message = error_text(&edited("d_star = 2.0", "d_star = 1e308"));
    assert_eq!(
        message,
        "scenarios/x.toml: goal.d_star must be in [0.01, 100] m (got 1e308)"
    );
}

#[test]
fn every_limit_survives_the_f32_conversion() {
    let fits = |x: f64| {
        let narrow = x as f32;
        narrow.is_finite() && (x == 0.0) == (narrow == 0.0)
    };
    for (keys, bounds) in limits::ALL {
        assert!(bounds.min <= bounds.max, "{keys}: {bounds}");
        assert!(
            fits(bounds.min) && fits(bounds.max),
            "{keys}: {bounds} must be finite and keep its sign in f32"
        );
    }
    assert_eq!(limits::MAX_BEAMS, formation_proto::wire::MAX_BEAMS);
}

#[test]
fn names_are_short_and_printable() {
    let named = |name: &str| edited("name = \"t\"", &format!("name = {name:?}"));
    parse(&named(&"n".repeat(limits::MAX_NAME_CHARS))).expect("128 characters are allowed");
    parse(&named("Fall 2026 — table I, ü")).expect("printable Unicode is allowed");
    refused(
        &named(&"n".repeat(limits::MAX_NAME_CHARS + 1)),
        "name",
        &["at most 128 characters", "(got 129)"],
    );
    refused(
        &named("two\nlines"),
        "name",
        &["control characters", "'\\n'"],
    );
    refused(
        &edited("name = \"t\"", "name = \"bell\\u0007\""),
        "name",
        &["control characters"],
    );
    // A huge name is refused without being echoed back.
    let huge = named(&"x".repeat(100_000));
    let message = error_text(&huge);
    assert!(
        message.len() < 300,
        "the name was echoed: {} bytes",
        message.len()
    );
}

#[test]
fn an_oversized_file_is_refused_by_its_size() {
    let dir = Scratch::new("big");
    let path = dir.path().join("big.toml");
    let file = std::fs::File::create(&path).expect("create");
    // Sparse: no disk space used, and a whole read would allocate over a MiB.
    file.set_len(limits::MAX_FILE_BYTES + 1).expect("set_len");
    match Scenario::from_path(&path) {
        Err(ref error @ ScenarioError::TooLarge { size, .. }) => {
            assert_eq!(size, Some(limits::MAX_FILE_BYTES + 1));
            let message = error.to_string();
            assert!(message.contains("big.toml"), "{message}");
            assert!(message.contains("1048577 bytes"), "{message}");
            assert!(message.contains("1048576-byte limit"), "{message}");
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    // Exactly at the limit it is read (and then fails to parse as TOML: all NUL bytes).
    file.set_len(limits::MAX_FILE_BYTES).expect("set_len");
    assert!(matches!(
        Scenario::from_path(&path),
        Err(ScenarioError::Parse { .. })
    ));
}

#[test]
fn devices_directories_and_fifos_are_refused_before_reading() {
    let dir = Scratch::new("kinds");
    let fifo = dir.path().join("pipe.toml");
    formation_test_kit::make_fifo(&fifo);
    for (path, kind) in [
        (Path::new("/dev/zero"), "a character device"),
        (dir.path(), "a directory"),
        (fifo.as_path(), "a FIFO"),
    ] {
        // Reading /dev/zero or opening the FIFO would never return: the refusal must come first.
        match Scenario::from_path(path) {
            Err(ref error @ ScenarioError::NotAFile { kind: found, .. }) => {
                assert!(found.starts_with(kind), "{path:?}: {found}");
                let message = error.to_string();
                assert!(message.contains("not a regular file"), "{message}");
                assert!(message.contains(&path.display().to_string()), "{message}");
            }
            other => panic!("{path:?}: expected NotAFile, got {other:?}"),
        }
    }
}

#[test]
fn a_scenario_file_is_read_and_its_agent_paths_resolved() {
    let dir = Scratch::new("ok");
    let path = dir.path().join("ok.toml");
    std::fs::write(
        &path,
        format!("{MINIMAL}[[agent]]\nrobot = 1\nmodel = \"m/b.onnx\"\n"),
    )
    .expect("write");
    let scenario = Scenario::from_path(&path).expect("valid");
    assert_eq!(
        scenario.agent_models()[0].model,
        dir.path().join("m/b.onnx")
    );
    std::fs::write(&path, b"name = \"\xff\"\n").expect("write");
    assert!(matches!(
        Scenario::from_path(&path),
        Err(ScenarioError::Read { .. })
    ));
}

#[test]
fn missing_file_error_names_the_path() {
    let path = Path::new("scenarios/does-not-exist-7f3a.toml");
    let error = Scenario::from_path(path).expect_err("missing file");
    assert!(matches!(&error, ScenarioError::Read { path: p, .. } if p == path));
    assert!(
        error
            .to_string()
            .contains("scenarios/does-not-exist-7f3a.toml"),
        "{error}"
    );
}

#[test]
fn a_team_model_is_resolved_against_the_file_and_kept_when_resized() {
    let dir = Scratch::new("team-model");
    let path = dir.path().join("team.toml");
    std::fs::write(&path, format!("model = \"m/team.onnx\"\n{MINIMAL}")).expect("write");
    let scenario = Scenario::from_path(&path).expect("valid");
    assert_eq!(
        scenario.model(),
        Some(dir.path().join("m/team.onnx").as_path())
    );
    let resized = scenario.with_robots(8).expect("resized");
    assert_eq!(resized.model(), scenario.model());
    // Absent: the shipped default, and nothing in the serialized record.
    let plain = parse(MINIMAL).expect("valid");
    assert_eq!(plain.model(), None);
    assert!(!serde_json::to_string(&plain).unwrap().contains("\"model\""));
    let empty = error_text(&format!("model = \"\"\n{MINIMAL}"));
    assert!(
        empty.contains("model") && empty.contains("must not be empty"),
        "{empty}"
    );
}

#[test]
fn agent_models_are_exposed() {
    let scenario = parse(&format!(
        "{MINIMAL}[[agent]]\nrobot = 2\nmodel = \"models/b.onnx\"\n"
    ))
    .unwrap();
    assert_eq!(
        scenario.agent_models(),
        [AgentModel {
            robot: 2,
            model: PathBuf::from("models/b.onnx")
        }]
    );
}

#[test]
fn heading_schedules_follow_their_formulas() {
    let ramp = HeadingSchedule::Ramp {
        omega: 0.1,
        phi0: 0.5,
    };
    assert_eq!(ramp.phi_star(0.0), 0.5);
    assert!((ramp.phi_star(40.0) - 4.5).abs() < 1e-12);
    let sine = HeadingSchedule::Sine {
        omega: 0.2,
        amplitude: 1.0,
        phi0: 0.0,
    };
    assert!((sine.phi_star(7.0) - 1.4f64.sin()).abs() < 1e-15);
    assert_eq!(
        HeadingSchedule::Constant { phi: 3.76 }.phi_star(123.0),
        3.76
    );
}

fn pose_bits(spec: &RunSpec) -> Vec<[u64; 3]> {
    spec.initial
        .iter()
        .map(|p| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()])
        .collect()
}

#[test]
fn run_spec_is_a_deterministic_function_of_seed_and_index() {
    let table1 = parse(SHIPPED[3].1).unwrap();
    let a = table1.run_spec(7, 3);
    let b = table1.run_spec(7, 3);
    assert_eq!(a, b);
    assert_eq!(pose_bits(&a), pose_bits(&b));
    assert_eq!(a.d_star.to_bits(), b.d_star.to_bits());
    assert_eq!((a.seed, a.noise_seed, a.index), (b.seed, b.noise_seed, 3));
    assert_ne!(a.seed, a.noise_seed);

    let other_seed = table1.run_spec(8, 3);
    let other_index = table1.run_spec(7, 4);
    for other in [&other_seed, &other_index] {
        assert_ne!(other.seed, a.seed);
        assert_ne!(other.noise_seed, a.noise_seed);
        assert_ne!(pose_bits(other), pose_bits(&a));
    }
}

#[test]
fn run_spec_draws_cover_the_configured_ranges() {
    let table1 = parse(SHIPPED[3].1).unwrap();
    let mut d_seen = [false; 3];
    let mut theta_signs = [false; 2];
    for index in 0..200 {
        let spec = table1.run_spec(table1.seed(), index);
        assert_eq!(spec.initial.len(), 3);
        assert_eq!(spec.neighbours, NeighbourRule::AllPairs);
        assert_eq!(spec.ticks(), 1200);
        let k = [1.0, 1.5, 2.0]
            .iter()
            .position(|&d| d == spec.d_star)
            .expect("d* from the choices");
        d_seen[k] = true;
        let HeadingSchedule::Constant { phi } = spec.heading else {
            panic!("{:?}", spec.heading)
        };
        assert!((0.0..TAU).contains(&phi), "phi* = {phi}");
        assert_eq!(
            spec.goal_at(30.0),
            Goal {
                phi_star: phi,
                d_star: spec.d_star,
                v_star: 0.7
            }
        );
        for (i, pose) in spec.initial.iter().enumerate() {
            assert!(
                pose.x.hypot(pose.y) <= 3.0,
                "robot {i} outside the disc: {pose:?}"
            );
            assert!(pose.theta > -std::f64::consts::PI && pose.theta <= std::f64::consts::PI);
            theta_signs[usize::from(pose.theta >= 0.0)] = true;
            for other in &spec.initial[i + 1..] {
                assert!(
                    (pose.x - other.x).hypot(pose.y - other.y) >= 0.6,
                    "spacing violated"
                );
            }
        }
    }
    assert_eq!(d_seen, [true; 3]);
    assert_eq!(theta_signs, [true; 2]);
}

#[test]
fn crowded_discs_still_place_every_robot_apart() {
    // 19 sites of a 1 m hexagonal lattice fit in a 2 m disc; random draws rarely place 19 robots.
    let text =
        edited("robots = 3", "robots = 19") + "[init]\ndisc_radius = 2.0\nmin_spacing = 1.0\n";
    let scenario = parse(&text).unwrap();
    assert_eq!(lattice_sites(2.0, 1.0, usize::MAX).len(), 19);
    let spec = scenario.run_spec(1, 0);
    assert_eq!(spec.initial.len(), 19);
    for (i, a) in spec.initial.iter().enumerate() {
        assert!(a.x.hypot(a.y) <= 2.0 + 1e-12);
        for b in &spec.initial[i + 1..] {
            assert!((a.x - b.x).hypot(a.y - b.y) >= 1.0 - 1e-9);
        }
    }
    let too_many =
        edited("robots = 3", "robots = 20") + "[init]\ndisc_radius = 2.0\nmin_spacing = 1.0\n";
    assert_eq!(invalid_field(&too_many).0, "init.disc_radius");
}

#[test]
fn eleven_robots_just_work_with_the_gabriel_rule_a_grown_disc_and_a_connected_start() {
    let scenario = parse(&edited("robots = 3", "robots = 11")).unwrap();
    let NeighbourRule::Gabriel(rule) = *scenario.neighbours() else {
        panic!("{:?}", scenario.neighbours())
    };
    assert_eq!(rule, GabrielRule::with_range(10.0));
    let radius = 3.0 * (11.0_f64 / 3.0).sqrt();
    assert_eq!(scenario.initial_conditions().disc_radius, radius);
    for index in 0..20 {
        let spec = scenario.run_spec(5, index);
        assert_eq!(spec.neighbours, *scenario.neighbours());
        let positions: Vec<(f64, f64)> = spec.initial.iter().map(|p| (p.x, p.y)).collect();
        assert!(positions.iter().all(|p| p.0.hypot(p.1) <= radius));
        assert!(connected_within(&positions, rule.sensing_range));
    }
    // The shipped teams scenario is exactly that, for 8 robots.
    let teams = parse(include_str!("../../../scenarios/teams.toml")).unwrap();
    assert_eq!(
        (teams.n_robots(), teams.neighbours().name()),
        (8, "gabriel")
    );
    assert_eq!(
        teams.initial_conditions().disc_radius,
        default_disc_radius(8)
    );
    // Three robots keep the paper's triangle and disc.
    let three = parse(MINIMAL).unwrap();
    assert_eq!(*three.neighbours(), NeighbourRule::AllPairs);
    assert_eq!(three.initial_conditions().disc_radius, 3.0);
}

#[test]
fn the_formation_table_names_its_rule_and_refuses_a_wrong_one_with_the_valid_names() {
    let gabriel3 = parse(&format!(
        "{MINIMAL}[formation]\nneighbours = \"gabriel\"\nsensing_range = 4.0\nnearest = 1\n"
    ))
    .unwrap();
    assert_eq!(
        *gabriel3.neighbours(),
        NeighbourRule::Gabriel(GabrielRule {
            sensing_range: 4.0,
            nearest: 1,
            ..GabrielRule::with_range(4.0)
        })
    );
    let all =
        parse(&(edited("robots = 3", "robots = 6") + "[formation]\nneighbours = \"all_pairs\"\n"))
            .unwrap();
    assert_eq!(*all.neighbours(), NeighbourRule::AllPairs);
    let (field, problem) = invalid_field(&format!(
        "{MINIMAL}[formation]\nneighbours = \"delaunay\"\n"
    ));
    assert_eq!(field, "formation.neighbours");
    assert!(
        problem.contains("\"all_pairs\", \"gabriel\"") && problem.contains("delaunay"),
        "{problem}"
    );
    let (field, problem) = invalid_field(&format!(
        "{MINIMAL}[formation]\nneighbours = \"all_pairs\"\nnearest = 2\n"
    ));
    assert_eq!(field, "formation.nearest");
    assert!(
        problem.contains("only to neighbours = \"gabriel\""),
        "{problem}"
    );
    let (field, _) = invalid_field(&format!(
        "{MINIMAL}[formation]\nneighbours = \"gabriel\"\nsensing_range = 11.0\n"
    ));
    assert_eq!(field, "formation.sensing_range");
    let (field, _) = invalid_field(&format!(
        "{MINIMAL}[formation]\nneighbours = \"gabriel\"\nhysteresis = 1.3\n"
    ));
    assert_eq!(field, "formation.hysteresis");
    assert!(
        error_text(&format!("{MINIMAL}[formation]\nrule = \"gabriel\"\n")).contains("rule"),
        "unknown keys are refused"
    );
}

#[test]
fn a_team_too_large_for_its_disc_or_too_spread_for_its_range_is_a_clear_error() {
    let crowded = edited("robots = 3", "robots = 200") + "[init]\ndisc_radius = 3.0\n";
    let (field, problem) = invalid_field(&crowded);
    assert_eq!(field, "init.disc_radius");
    assert!(
        problem.contains("too small to place 200 robots"),
        "{problem}"
    );
    let spread = MINIMAL.to_owned() + "[lidar]\nmax_range = 1.0\n[init]\nmin_spacing = 1.5\n";
    let (field, problem) = invalid_field(&spread);
    assert_eq!(field, "init.min_spacing");
    assert!(problem.contains("cannot start connected"), "{problem}");
}

#[test]
fn a_wide_disc_with_a_short_range_still_starts_connected_in_bounded_time() {
    // A 30 m disc and a 2 m sensing range: random draws are almost never connected, so the
    // placement ends on the connected lattice patch.
    let text = edited("robots = 3", "robots = 12")
        + "[init]\ndisc_radius = 30.0\nmin_spacing = 1.0\n[lidar]\nmax_range = 2.0\n";
    let scenario = parse(&text).unwrap();
    let spec = scenario.run_spec(1, 0);
    let positions: Vec<(f64, f64)> = spec.initial.iter().map(|p| (p.x, p.y)).collect();
    assert_eq!(positions.len(), 12);
    assert!(connected_within(&positions, 2.0));
    for (i, a) in positions.iter().enumerate() {
        for b in &positions[i + 1..] {
            assert!((a.0 - b.0).hypot(a.1 - b.1) >= 1.0 - 1e-9);
        }
    }
}

#[test]
fn with_robots_keeps_what_the_file_gave_and_resizes_the_rest() {
    let file = edited("robots = 3", "robots = 4") + "[init]\nmin_spacing = 0.8\n";
    let scenario = parse(&file).unwrap();
    let big = scenario.with_robots(16).unwrap();
    assert_eq!(big.n_robots(), 16);
    assert_eq!(big.initial_conditions().min_spacing, 0.8);
    assert_eq!(
        big.initial_conditions().disc_radius,
        default_disc_radius(16)
    );
    assert_eq!(big.neighbours().name(), "gabriel");
    let three = scenario.with_robots(3).unwrap();
    assert_eq!(*three.neighbours(), NeighbourRule::AllPairs);
    assert_eq!(three.initial_conditions().disc_radius, 3.0);
    assert_eq!(three.with_robots(4).unwrap(), scenario);
    let fixed = parse(&(file + "[formation]\nneighbours = \"all_pairs\"\n")).unwrap();
    assert_eq!(
        *fixed.with_robots(8).unwrap().neighbours(),
        NeighbourRule::AllPairs
    );
    assert!(scenario.with_robots(1).is_err() && scenario.with_robots(5000).is_err());
}

#[test]
fn with_duration_keeps_every_other_setting_and_checks_its_bounds() {
    let scenario = parse(&edited("robots = 3", "robots = 4")).unwrap();
    let long = scenario.with_duration(100.0).unwrap();
    assert_eq!(long.duration_s(), 100.0);
    assert_eq!(long.with_duration(scenario.duration_s()).unwrap(), scenario);
    let spec = long.run_spec(long.seed(), 0);
    assert_eq!(spec.ticks(), 2000);
    for bad in [0.0, -1.0, f64::NAN, 1e6] {
        let error = scenario.with_duration(bad).unwrap_err().to_string();
        assert!(error.contains("duration_s"), "{bad}: {error}");
    }
    // Robots x ticks is bounded: a long run of a huge team is refused, naming the fix.
    let huge = scenario.with_robots(1024).unwrap();
    let error = huge.with_duration(3600.0).unwrap_err().to_string();
    assert!(error.contains("shorten duration_s"), "{error}");
}

#[test]
fn overrides_set_keys_before_validation_with_the_files_messages() {
    let path = std::env::temp_dir().join(format!("overrides-{}.toml", std::process::id()));
    std::fs::write(&path, MINIMAL).unwrap();
    let set = |key: &str, value: toml::Value| vec![(key.to_owned(), value)];
    let faster = Scenario::from_path_overridden(&path, &set("goal.v_star", 0.5.into())).unwrap();
    assert_eq!(faster.v_star(), VStarPlan::Fixed(0.5));
    assert_eq!(faster.n_robots(), 3);
    let added = Scenario::from_path_overridden(&path, &set("lidar.beams", 90.into())).unwrap();
    assert_eq!(added.world_config().lidar.beams, 90);
    let unknown = Scenario::from_path_overridden(&path, &set("goal.speed", 1.0.into()))
        .unwrap_err()
        .to_string();
    assert!(unknown.contains("unknown field `speed`"), "{unknown}");
    let bad = Scenario::from_path_overridden(&path, &set("goal.v_star", (-1.0).into()))
        .unwrap_err()
        .to_string();
    let in_file = Scenario::from_toml_str(&edited("v_star = 0.7", "v_star = -1.0"), "x")
        .unwrap_err()
        .to_string();
    assert_eq!(
        bad.split_once(": ").unwrap().1,
        in_file.split_once(": ").unwrap().1
    );
    let into_value = Scenario::from_path_overridden(&path, &set("robots.n", 3.into()))
        .unwrap_err()
        .to_string();
    assert!(
        into_value.contains("`robots` is a value, not a table"),
        "{into_value}"
    );
    assert_eq!(
        Scenario::from_path_overridden(&path, &[]).unwrap(),
        Scenario::from_path(&path).unwrap()
    );
    std::fs::remove_file(&path).unwrap();
}
