//! The documented limits of every scenario value (the reference is `scenarios/README.md`).
//!
//! They keep a scenario's cost bounded (memory and time grow with robots, ticks and runs) and its
//! numbers inside what the rest of the system carries: every real-valued bound is far inside the
//! `f32` range, so a value that passes stays finite and non-zero through the `f32` conversions of
//! the wire (LIDAR ranges) and the policy input (`d*`).

use std::fmt;

/// Largest scenario file that is read \[bytes\]: 1 MiB (the shipped ones are under 1 KiB).
pub const MAX_FILE_BYTES: u64 = 1 << 20;
/// Longest scenario name \[characters\]; it is echoed into logs, stdout and `summary.json`.
pub const MAX_NAME_CHARS: usize = 128;
/// Fewest robots: a formation needs at least one pair.
pub const MIN_ROBOTS: usize = 2;
/// Most robots. The runtime starts one OS process per robot and every tick ray-casts every
/// robot's LIDAR against every other robot and scores all `n (n - 1) / 2` pairs.
pub const MAX_ROBOTS: usize = 1024;
/// Most runs of one evaluation (the scenario's `runs` and the `--runs` flag).
pub const MAX_RUNS: usize = 10_000;
/// Most `robots x ticks` of one run: a run's trajectory (about 40 bytes per robot and tick) is
/// held in memory and written as a log, so this caps it near 400 MB.
pub const MAX_ROBOT_TICKS: u64 = 10_000_000;
/// Most LIDAR beams: what a scan message carries ([`formation_proto::wire::MAX_BEAMS`]).
pub const MAX_BEAMS: usize = formation_proto::wire::MAX_BEAMS;
/// Most `formation.nearest`.
pub const MAX_NEAREST: usize = 16;
/// `formation.threshold`: at most 1, so every witness lies within sensing range.
pub const GABRIEL_THRESHOLD: Bounds = bounds(0.05, 4.0, "");
/// Fewest LIDAR beams.
pub const MIN_BEAMS: usize = 8;
/// Most entries of `goal.d_star_choices`.
pub const MAX_D_STAR_CHOICES: usize = 256;

/// An inclusive range `[min, max]` of a real-valued setting, with its unit for messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Smallest allowed value.
    pub min: f64,
    /// Largest allowed value.
    pub max: f64,
    /// Unit, e.g. `m`, `s`, `rad/s`.
    pub unit: &'static str,
}

impl fmt::Display for Bounds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}, {}]", Num(self.min), Num(self.max))?;
        if self.unit.is_empty() {
            Ok(())
        } else {
            write!(f, " {}", self.unit)
        }
    }
}

const fn bounds(min: f64, max: f64, unit: &'static str) -> Bounds {
    Bounds { min, max, unit }
}

/// `duration_s`: simulated seconds per run (at most an hour).
pub const DURATION_S: Bounds = bounds(1e-3, 3600.0, "s");
/// `dt`: the simulation step (1 kHz to 1 Hz).
pub const DT: Bounds = bounds(1e-3, 1.0, "s");
/// `goal.d_star` and each of `goal.d_star_choices`.
pub const D_STAR: Bounds = bounds(0.01, 100.0, "m");
/// `heading.phi`, `heading.phi0` and `heading.amplitude`.
pub const ANGLE: Bounds = bounds(-1000.0, 1000.0, "rad");
/// `heading.omega`: the heading's turn rate or angular frequency.
pub const HEADING_RATE: Bounds = bounds(-100.0, 100.0, "rad/s");
/// `init.disc_radius`.
pub const DISC_RADIUS: Bounds = bounds(0.01, 1000.0, "m");
/// `init.min_spacing` (and at least `2 * robot.body_radius`).
pub const MIN_SPACING: Bounds = bounds(0.02, 1000.0, "m");
/// `lidar.max_range`.
pub const MAX_RANGE: Bounds = bounds(0.1, 1000.0, "m");
/// `lidar.noise_std`.
pub const NOISE_STD: Bounds = bounds(0.0, 10.0, "m");
/// `robot.wheel_separation`.
pub const WHEEL_SEPARATION: Bounds = bounds(0.01, 10.0, "m");
/// `robot.wheel_radius`.
pub const WHEEL_RADIUS: Bounds = bounds(0.001, 10.0, "m");
/// `robot.body_radius`.
pub const BODY_RADIUS: Bounds = bounds(0.01, 10.0, "m");
/// `robot.max_wheel_speed` (`goal.v_star` must lie in `[0, max_wheel_speed]`).
pub const MAX_WHEEL_SPEED: Bounds = bounds(0.01, 10.0, "m/s");
/// `robot.max_wheel_accel`.
pub const MAX_WHEEL_ACCEL: Bounds = bounds(0.01, 1000.0, "m/s^2");

/// `robot.motor_tau`: the wheels' lag time constant (0: none).
pub const MOTOR_TAU: Bounds = bounds(0.0, 2.0, "s");
/// `robot.wheel_speed_noise`: the standard deviation of each wheel's speed noise.
pub const WHEEL_SPEED_NOISE: Bounds = bounds(0.0, 1.0, "m/s");
/// `robot.wheel_gain_asymmetry`: right gain minus left gain.
pub const WHEEL_GAIN_ASYMMETRY: Bounds = bounds(-0.5, 0.5, "");
/// `robot.spread`: each robot's parameters drawn within `±spread` of the profile's (relative).
pub const SPREAD: Bounds = bounds(0.0, 0.5, "");
/// Most `robot.command_latency` \[ticks\].
pub const MAX_COMMAND_LATENCY: usize = 20;
/// `lidar.scan_rate_hz` (and at most the control rate `1 / dt`, dividing it into whole ticks).
pub const SCAN_RATE: Bounds = bounds(0.1, 1000.0, "Hz");
/// `lidar.fov_deg`.
pub const FOV: Bounds = bounds(1.0, 360.0, "deg");
/// `lidar.min_range` (and below `lidar.max_range`).
pub const MIN_RANGE: Bounds = bounds(0.0, 1000.0, "m");
/// `lidar.dropout`: the probability that a beam returns nothing.
pub const DROPOUT: Bounds = bounds(0.0, 0.9, "");
/// `compass.noise_std_deg`.
pub const COMPASS_NOISE: Bounds = bounds(0.0, 90.0, "deg");
/// `compass.bias_deg`.
pub const COMPASS_BIAS: Bounds = bounds(-180.0, 180.0, "deg");

/// Every real-valued bound, by the keys it applies to (for tests and documentation).
pub const ALL: [(&str, Bounds); 24] = [
    ("duration_s", DURATION_S),
    ("dt", DT),
    (
        "goal.d_star, goal.d_star_choices, goal.d_star_range",
        D_STAR,
    ),
    ("heading.phi, heading.phi0, heading.amplitude", ANGLE),
    ("heading.omega", HEADING_RATE),
    ("init.disc_radius", DISC_RADIUS),
    ("init.min_spacing", MIN_SPACING),
    ("lidar.max_range", MAX_RANGE),
    ("lidar.noise_std", NOISE_STD),
    ("robot.wheel_separation", WHEEL_SEPARATION),
    ("robot.wheel_radius", WHEEL_RADIUS),
    ("robot.body_radius", BODY_RADIUS),
    ("robot.max_wheel_speed", MAX_WHEEL_SPEED),
    ("robot.max_wheel_accel", MAX_WHEEL_ACCEL),
    ("robot.motor_tau", MOTOR_TAU),
    ("robot.wheel_speed_noise", WHEEL_SPEED_NOISE),
    ("robot.wheel_gain_asymmetry", WHEEL_GAIN_ASYMMETRY),
    ("robot.spread", SPREAD),
    ("lidar.scan_rate_hz", SCAN_RATE),
    ("lidar.fov_deg", FOV),
    ("lidar.min_range", MIN_RANGE),
    ("lidar.dropout", DROPOUT),
    ("compass.noise_std_deg", COMPASS_NOISE),
    ("compass.bias_deg", COMPASS_BIAS),
];

/// A number in messages: plain for everyday magnitudes, scientific for huge or tiny ones (so
/// `1e308` is not printed as 309 digits).
pub(crate) struct Num(pub f64);

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        let magnitude = x.abs();
        if x.is_finite() && x != 0.0 && !(1e-4..1e7).contains(&magnitude) {
            write!(f, "{x:e}")
        } else {
            write!(f, "{x}")
        }
    }
}
