//! Scenario TOML (formation-world's `scenario`): a scenario file a user writes or downloads.
//!
//! Case: the file's text, parsed and validated with [`Scenario::from_toml_str`]; then its first
//! run is resolved ([`Scenario::run_spec`]: d* drawn, robots placed), since whatever validation
//! admits must be playable. Bytes that are not UTF-8 are refused as the file reader refuses them.
//! Decoded means the scenario was accepted. The seeds are the shipped scenarios and one that
//! sets every table.

use std::path::Path;

use formation_world::Scenario;

use super::{Refusal, Scratch, Seed, Target, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "scenario",
    about: "scenario TOML: Scenario::from_toml_str, then the first run's spec",
    run,
    seeds,
    tokens: &[
        b"\n[goal]\n",
        b"\n[heading]\n",
        b"\n[init]\n",
        b"\n[formation]\n",
        b"\n[lidar]\n",
        b"\n[robot]\n",
        b"\n[[agent]]\nrobot = 0\nmodel = \"m.onnx\"\n",
        b"d_star_choices = []\n",
        b"d_star_range = [2.0, 1.0]\n",
        b"v_star_range = [0.2, 0.05]\n",
        b"schedule = \"sine\"\n",
        b"neighbours = \"gabriel\"\n",
        b"robots = 1024\n",
        b"min_spacing = 1000\n",
        b"max_wheel_accel = ",
        b" = ",
        b"\"",
        b"[",
        b"]",
        b"#",
        b"\n",
        b"'''",
        b"{a=1}",
    ],
    shape: Shape::Text,
};

fn run(_: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    let text = std::str::from_utf8(case).map_err(|_| Refusal::named("not UTF-8"))?;
    let scenario = Scenario::from_toml_str(text, "case.toml").map_err(Refusal::of)?;
    let spec = scenario.run_spec(scenario.seed(), 0);
    let _ = spec.ticks();
    Ok(())
}

/// A scenario that sets every table.
const EVERYTHING: &str = r#"name = "everything"
robots = 5
duration_s = 2.0
dt = 0.05
seed = 3
runs = 2

[goal]
v_star = 0.5
d_star_range = [1.0, 2.0]

[heading]
schedule = "sine"
omega = 0.5
amplitude = 0.8
phi0 = 0.1

[init]
disc_radius = 4.0
min_spacing = 0.8

[formation]
neighbours = "gabriel"
sensing_range = 8.0
nearest = 2
threshold = 1.3
hysteresis = 0.1

[lidar]
beams = 360
max_range = 10.0
noise_std = 0.01

[robot]
wheel_separation = 0.331
wheel_radius = 0.0975
body_radius = 0.25
max_wheel_speed = 0.9
max_wheel_accel = 2.0

[[agent]]
robot = 1
model = "other.onnx"
"#;

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let mut seeds = vec![("everything.toml".to_owned(), EVERYTHING.as_bytes().to_vec())];
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&dir).map_err(seed_error("scenario"))? {
        let path = entry.map_err(seed_error("scenario"))?.path();
        if path.extension().is_some_and(|e| e == "toml") {
            names.push(path);
        }
    }
    names.sort();
    for path in names {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        seeds.push((name, std::fs::read(&path).map_err(seed_error("scenario"))?));
    }
    Ok(seeds)
}
