//! What makes a real robot differ from the ideal world, as models the world applies: motors,
//! LIDAR timing and geometry, compass, command latency, and a spread of each robot's parameters.
//!
//! Every model is off in [`RealityModels::IDEAL`] (the default), and an ideal model changes no
//! bit of what the world computes and draws no random number, so every scenario written before
//! these models runs exactly as it did.
//!
//! * **Motors** ([`MotorModel`]): each wheel's speed follows its (saturated) command through a
//!   first-order lag of time constant τ, on top of the acceleration limit of
//!   [`RobotParams::max_wheel_accel`]; the left wheel runs at `1 - a/2` and the right at `1 + a/2`
//!   of its command (gain asymmetry `a`); Gaussian noise is added to each wheel's speed each step.
//! * **LIDAR timing** ([`LidarModel::scan_rate_hz`]): a scan is taken every `1 / (rate dt)` control
//!   ticks and held until the next; each robot's scans start at an offset of its own in that
//!   period (LIDARs are not synchronised), and [`scan_age_ticks`] is how old the held scan is.
//! * **LIDAR geometry** ([`LidarModel`]): beams outside the field of view, ranges below the
//!   minimum range and beams that drop out (each with probability `dropout`) return nothing,
//!   which a scan reports as `max_range`, as for a beam that hits nothing. The beam layout is
//!   unchanged (beam `k` at bearing `2 pi k / beams`), so every scan message and image keeps its shape.
//! * **Compass** ([`CompassModel`]): the heading a robot receives is its true heading plus a
//!   bias and Gaussian noise.
//! * **Latency** ([`RealityModels::command_latency_ticks`]): a command computed at tick `k` drives
//!   the wheels at tick `k + latency`; the wheels brake before the first one arrives.
//! * **Spread** ([`RealityModels::spread`]): each robot's wheel separation, top wheel speed,
//!   acceleration limit, motor lag, wheel gains, speed noise and compass bias and noise are its own,
//!   each the profile's value times `1 + spread * u`, `u` uniform in `[-1, 1]`, drawn per robot.
//!
//! # Randomness
//!
//! Each model draws from a `ChaCha8Rng` stream of its own, seeded from the world's noise seed in a
//! domain of its own ([`RealitySeeds`]), and draws the same count of numbers every tick whatever the
//! other models do; so turning one model on shifts no draw of another, nor the LIDAR's range noise.
//! The per-robot draws (spread, scan offset) come from streams seeded per robot.

use formation_proto::{WheelCmd, wrap_angle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::robot::RobotParams;
use crate::seed_mix::splitmix64;

/// The wheels' imperfections.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotorModel {
    /// Time constant τ \[s\] of each wheel's first-order lag towards its command; 0: none.
    pub tau_s: f64,
    /// Standard deviation \[m/s\] of the Gaussian noise added to each wheel's speed each step.
    pub speed_noise_std: f64,
    /// Right gain minus left gain: the left wheel runs at `1 - a/2`, the right at `1 + a/2` of its
    /// command.
    pub gain_asymmetry: f64,
}

impl MotorModel {
    /// Ideal wheels: no lag, no noise, equal gains.
    pub const IDEAL: MotorModel = MotorModel {
        tau_s: 0.0,
        speed_noise_std: 0.0,
        gain_asymmetry: 0.0,
    };
}

impl Default for MotorModel {
    fn default() -> Self {
        MotorModel::IDEAL
    }
}

/// The LIDAR's timing and geometry beyond its beam count, range and range noise
/// ([`formation_proto::LidarSpec`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LidarModel {
    /// Scans per second; `None`: one scan per control tick.
    pub scan_rate_hz: Option<f64>,
    /// Field of view \[deg\], centred on the robot's heading; beams outside it return nothing.
    pub fov_deg: f64,
    /// Shortest range \[m\] the LIDAR measures; a nearer hit returns nothing.
    pub min_range: f64,
    /// Probability that a beam returns nothing, each beam of each scan on its own.
    pub dropout: f64,
}

impl LidarModel {
    /// The ideal ring: a scan every tick, all around, from zero range, no dropout.
    pub const IDEAL: LidarModel = LidarModel {
        scan_rate_hz: None,
        fov_deg: 360.0,
        min_range: 0.0,
        dropout: 0.0,
    };

    /// Whether the field of view, minimum range or dropout changes a scan.
    pub fn changes_geometry(&self) -> bool {
        self.fov_deg < 360.0 || self.min_range > 0.0 || self.dropout > 0.0
    }

    /// Control ticks between two scans at time step `dt`: `round(1 / (rate dt))`, at least 1.
    pub fn scan_period_ticks(&self, dt: f64) -> u64 {
        match self.scan_rate_hz {
            None => 1,
            Some(rate) => ((1.0 / (rate * dt)).round() as u64).max(1),
        }
    }
}

impl Default for LidarModel {
    fn default() -> Self {
        LidarModel::IDEAL
    }
}

/// The compass's error in the heading a robot receives.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CompassModel {
    /// Standard deviation \[deg\] of the Gaussian noise of each reading.
    pub noise_std_deg: f64,
    /// Constant offset \[deg\] of every reading (counter-clockwise positive).
    pub bias_deg: f64,
}

impl CompassModel {
    /// An exact compass.
    pub const IDEAL: CompassModel = CompassModel {
        noise_std_deg: 0.0,
        bias_deg: 0.0,
    };
}

impl Default for CompassModel {
    fn default() -> Self {
        CompassModel::IDEAL
    }
}

/// Every reality model of a world, all off by default.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RealityModels {
    /// The wheels.
    pub motors: MotorModel,
    /// The LIDAR's timing and geometry.
    pub lidar: LidarModel,
    /// The compass.
    pub compass: CompassModel,
    /// Ticks between a command's computation and the wheels running it.
    pub command_latency_ticks: u32,
    /// Relative spread of each robot's parameters around the nominal ones (0.05: ±5 %).
    pub spread: f64,
}

impl RealityModels {
    /// No model on: the ideal world.
    pub const IDEAL: RealityModels = RealityModels {
        motors: MotorModel::IDEAL,
        lidar: LidarModel::IDEAL,
        compass: CompassModel::IDEAL,
        command_latency_ticks: 0,
        spread: 0.0,
    };

    /// Whether no model is on.
    pub fn is_ideal(&self) -> bool {
        *self == RealityModels::IDEAL
    }
}

impl Default for RealityModels {
    fn default() -> Self {
        RealityModels::IDEAL
    }
}

/// The seeds of the models' random streams, each mixed from the world's noise seed in a domain
/// of its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RealitySeeds {
    /// Wheel speed noise.
    pub motors: u64,
    /// Beam dropout.
    pub dropout: u64,
    /// Compass noise.
    pub compass: u64,
    /// Each robot's spread draws (mixed again with the robot's index).
    pub spread: u64,
    /// Each robot's scan offset (mixed again with the robot's index).
    pub scan_offset: u64,
}

impl RealitySeeds {
    /// The streams of a world whose range noise is seeded with `noise_seed`.
    pub fn from_noise_seed(noise_seed: u64) -> RealitySeeds {
        let domain = |tag: u64| splitmix64(noise_seed ^ tag);
        RealitySeeds {
            motors: domain(0x4D07_0125_0000_0001),
            dropout: domain(0xD209_0007_0000_0002),
            compass: domain(0xC0A5_5000_0000_0003),
            spread: domain(0x5B2E_AD00_0000_0004),
            scan_offset: domain(0x5CA4_0FF5_0000_0005),
        }
    }

    /// The generator of robot `robot` in the per-robot domain `seed`.
    fn robot_stream(seed: u64, robot: usize) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(splitmix64(seed ^ splitmix64(robot as u64)))
    }
}

/// One robot's own parameters: the nominal ones, spread when the models ask for it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotTraits {
    /// Geometry and limits (wheel separation, top speed and acceleration limit spread).
    pub params: RobotParams,
    /// Motor lag time constant \[s\]; 0: none.
    pub tau_s: f64,
    /// Gain of the left wheel on its command.
    pub gain_left: f64,
    /// Gain of the right wheel on its command.
    pub gain_right: f64,
    /// Standard deviation of each wheel's speed noise \[m/s\].
    pub speed_noise_std: f64,
    /// Compass bias \[rad\].
    pub compass_bias: f64,
    /// Compass noise standard deviation \[rad\].
    pub compass_noise_std: f64,
    /// Ticks by which this robot's scan schedule is shifted, `< scan period`.
    pub scan_offset_ticks: u64,
}

impl RobotTraits {
    /// Robot `robot`'s traits: the nominal `params` and `models`, each spread-scaled parameter
    /// times its own factor `1 + spread * u` (drawn in the order the fields are listed, only
    /// when `spread > 0`), and a scan offset uniform in `0..scan_period_ticks` (drawn only when
    /// the period is over one tick).
    pub fn draw(
        params: &RobotParams,
        models: &RealityModels,
        scan_period_ticks: u64,
        seeds: &RealitySeeds,
        robot: usize,
    ) -> RobotTraits {
        let mut factors = [1.0; 8];
        if models.spread > 0.0 {
            let mut rng = RealitySeeds::robot_stream(seeds.spread, robot);
            for factor in &mut factors {
                *factor = 1.0 + models.spread * rng.random_range(-1.0..=1.0);
            }
        }
        let scan_offset_ticks = if scan_period_ticks > 1 {
            RealitySeeds::robot_stream(seeds.scan_offset, robot).random_range(0..scan_period_ticks)
        } else {
            0
        };
        let motors = &models.motors;
        let half_asymmetry = 0.5 * motors.gain_asymmetry;
        RobotTraits {
            params: RobotParams {
                wheel_separation: params.wheel_separation * factors[0],
                max_wheel_speed: params.max_wheel_speed * factors[1],
                max_wheel_accel: params.max_wheel_accel.map(|a| a * factors[2]),
                ..*params
            },
            tau_s: motors.tau_s * factors[3],
            gain_left: (1.0 - half_asymmetry) * factors[4],
            gain_right: (1.0 + half_asymmetry) * factors[5],
            speed_noise_std: motors.speed_noise_std * factors[6],
            compass_bias: models.compass.bias_deg.to_radians() * factors[7],
            compass_noise_std: models.compass.noise_std_deg.to_radians() * factors[7],
            scan_offset_ticks,
        }
    }

    /// The wheel speeds this robot runs for one step of `dt` from `current`, asked for
    /// `requested`, with `noise` standard normal deviations (left, right) for the speed noise.
    ///
    /// A non-finite command brakes; each wheel's target is its gain times its command, saturated
    /// to `±max_wheel_speed`; the speed moves towards it by the fraction `1 - exp(-dt / τ)` of the
    /// gap (the exact step of a first-order lag under a command held over the step), by at most
    /// `max_wheel_accel * dt`; the noise is added and the result saturated again. With ideal
    /// traits this is [`RobotParams::achievable`], bit for bit.
    pub fn drive(
        &self,
        requested: WheelCmd,
        current: WheelCmd,
        dt: f64,
        noise: [f64; 2],
    ) -> WheelCmd {
        let target = if requested.is_finite() {
            requested
        } else {
            WheelCmd::BRAKE
        };
        let lag = if self.tau_s > 0.0 {
            Some(-(-dt / self.tau_s).exp_m1())
        } else {
            None
        };
        let step = self.params.max_wheel_accel.map(|accel| accel * dt);
        let wheel = |command: f64, gain: f64, current: f64, deviation: f64| {
            let limit = self.params.max_wheel_speed;
            let mut speed = (gain * command).clamp(-limit, limit);
            if let Some(fraction) = lag {
                speed = current + fraction * (speed - current);
            }
            if let Some(step) = step {
                speed = speed.clamp(current - step, current + step);
            }
            if self.speed_noise_std > 0.0 {
                speed = (speed + self.speed_noise_std * deviation).clamp(-limit, limit);
            }
            speed
        };
        WheelCmd {
            left: wheel(target.left, self.gain_left, current.left, noise[0]),
            right: wheel(target.right, self.gain_right, current.right, noise[1]),
        }
    }

    /// The heading this robot's compass reads for the true heading `theta`, with `deviation` a
    /// standard normal draw: `wrap(theta + bias + noise_std * deviation)`.
    pub fn compass_reading(&self, theta: f64, deviation: f64) -> f64 {
        wrap_angle(theta + self.compass_bias + self.compass_noise_std * deviation)
    }
}

/// How many ticks old, at tick `tick`, the scan of a robot with scan offset `offset` is when
/// scans come every `period` ticks: `(tick + offset) mod period` (0: taken this tick).
///
/// Before tick 0 the robots stand still, so the scan a robot holds at tick 0 is the one cast at
/// tick 0 whatever its age.
pub fn scan_age_ticks(tick: u64, offset: u64, period: u64) -> u64 {
    (tick + offset) % period.max(1)
}

/// Applies the field of view, minimum range and dropout of `model` to `ranges` (beam `k` at
/// bearing `2 pi k / len`), writing `max_range` for every beam that returns nothing. `uniform`
/// yields one number in `[0, 1)` per beam, in beam order, drawn whether or not the beam is
/// masked otherwise (and only when `dropout > 0`).
pub fn apply_lidar_geometry(
    ranges: &mut [f32],
    max_range: f64,
    model: &LidarModel,
    mut uniform: impl FnMut() -> f64,
) {
    let nothing = max_range as f32;
    let beams = ranges.len();
    let half_fov = 0.5 * model.fov_deg.to_radians();
    let min_range = model.min_range as f32;
    for (k, range) in ranges.iter_mut().enumerate() {
        let dropped = model.dropout > 0.0 && uniform() < model.dropout;
        let outside = model.fov_deg < 360.0 && {
            let bearing = wrap_angle(std::f64::consts::TAU * k as f64 / beams as f64);
            bearing.abs() > half_fov + 1e-12
        };
        if dropped || outside || *range < min_range {
            *range = nothing;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.05;

    fn ideal_traits(params: RobotParams) -> RobotTraits {
        RobotTraits::draw(
            &params,
            &RealityModels::IDEAL,
            1,
            &RealitySeeds::from_noise_seed(1),
            0,
        )
    }

    fn with_motors(motors: MotorModel) -> RobotTraits {
        let models = RealityModels {
            motors,
            ..RealityModels::IDEAL
        };
        RobotTraits::draw(
            &RobotParams::default(),
            &models,
            1,
            &RealitySeeds::from_noise_seed(1),
            0,
        )
    }

    #[test]
    fn a_lagged_wheel_follows_a_step_as_one_minus_exp() {
        let tau = 0.2;
        let traits = with_motors(MotorModel {
            tau_s: tau,
            ..MotorModel::IDEAL
        });
        let step = WheelCmd::new(0.5, 0.5);
        let mut speeds = WheelCmd::BRAKE;
        for k in 1..=40 {
            speeds = traits.drive(step, speeds, DT, [0.0; 2]);
            let expected = 0.5 * (1.0 - (-(k as f64) * DT / tau).exp());
            assert!(
                (speeds.left - expected).abs() < 1e-12,
                "tick {k}: {speeds:?}"
            );
            assert_eq!(speeds.left, speeds.right);
        }
        // One time constant reaches 63 % of the step.
        let mut speeds = WheelCmd::BRAKE;
        for _ in 0..4 {
            speeds = traits.drive(step, speeds, DT, [0.0; 2]);
        }
        assert!((speeds.left / 0.5 - (1.0 - (-1.0_f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn the_lag_sits_on_top_of_the_acceleration_limit() {
        let mut traits = with_motors(MotorModel {
            tau_s: 0.05,
            ..MotorModel::IDEAL
        });
        traits.params.max_wheel_accel = Some(1.0);
        let step = WheelCmd::new(0.8, 0.8);
        // The lag alone would jump 63 % of the way (0.5 m/s) in one tick; the limit allows 0.05.
        let first = traits.drive(step, WheelCmd::BRAKE, DT, [0.0; 2]);
        assert!((first.left - 0.05).abs() < 1e-12, "{first:?}");
    }

    #[test]
    fn ideal_traits_drive_exactly_as_the_wheel_limits_do() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for accel in [None, Some(2.0)] {
            let params = RobotParams {
                max_wheel_accel: accel,
                ..RobotParams::default()
            };
            let traits = ideal_traits(params);
            assert_eq!(traits.params, params);
            for _ in 0..2000 {
                let mut draw = || rng.random_range(-2.0..2.0);
                let requested = WheelCmd {
                    left: draw(),
                    right: draw(),
                };
                let current = WheelCmd {
                    left: draw() * 0.4,
                    right: draw() * 0.4,
                };
                let ours = traits.drive(requested, current, DT, [0.3, -0.7]);
                let theirs = params.achievable(requested, current, DT);
                assert_eq!(ours.left.to_bits(), theirs.left.to_bits());
                assert_eq!(ours.right.to_bits(), theirs.right.to_bits());
            }
            let nan = WheelCmd::new(f64::NAN, 0.1);
            assert_eq!(
                traits.drive(nan, WheelCmd::BRAKE, DT, [0.0; 2]),
                WheelCmd::BRAKE
            );
        }
    }

    #[test]
    fn gain_asymmetry_turns_a_straight_command() {
        let traits = with_motors(MotorModel {
            gain_asymmetry: 0.1,
            ..MotorModel::IDEAL
        });
        let ran = traits.drive(WheelCmd::new(0.5, 0.5), WheelCmd::BRAKE, DT, [0.0; 2]);
        assert!((ran.left - 0.475).abs() < 1e-12 && (ran.right - 0.525).abs() < 1e-12);
    }

    #[test]
    fn speed_noise_is_scaled_and_saturated() {
        let traits = with_motors(MotorModel {
            speed_noise_std: 0.02,
            ..MotorModel::IDEAL
        });
        let ran = traits.drive(WheelCmd::new(0.5, 0.9), WheelCmd::BRAKE, DT, [1.5, 3.0]);
        assert!((ran.left - 0.53).abs() < 1e-12, "{ran:?}");
        assert_eq!(ran.right, traits.params.max_wheel_speed);
    }

    #[test]
    fn a_held_scan_ages_tick_by_tick_until_the_next() {
        // 5 Hz against 20 Hz: a scan every 4 ticks.
        let model = LidarModel {
            scan_rate_hz: Some(5.0),
            ..LidarModel::IDEAL
        };
        let period = model.scan_period_ticks(DT);
        assert_eq!(period, 4);
        let ages: Vec<u64> = (0..9).map(|t| scan_age_ticks(t, 1, period)).collect();
        assert_eq!(ages, [1, 2, 3, 0, 1, 2, 3, 0, 1]);
        assert_eq!(LidarModel::IDEAL.scan_period_ticks(DT), 1);
        assert!((0..50).all(|t| scan_age_ticks(t, 0, 1) == 0));
    }

    #[test]
    fn dropout_rate_lies_within_binomial_bounds() {
        let p = 0.05;
        let model = LidarModel {
            dropout: p,
            ..LidarModel::IDEAL
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let scans = 200;
        let beams = 360;
        let mut dropped = 0;
        for _ in 0..scans {
            let mut ranges = vec![1.0_f32; beams];
            apply_lidar_geometry(&mut ranges, 3.5, &model, || rng.random::<f64>());
            dropped += ranges.iter().filter(|&&r| r == 3.5).count();
        }
        let n = (scans * beams) as f64;
        let sigma = (n * p * (1.0 - p)).sqrt();
        let deviation = (dropped as f64 - n * p).abs();
        assert!(
            deviation < 4.0 * sigma,
            "{dropped} of {n} dropped, {p} expected"
        );
    }

    #[test]
    fn field_of_view_and_minimum_range_return_nothing() {
        let model = LidarModel {
            fov_deg: 180.0,
            min_range: 0.12,
            ..LidarModel::IDEAL
        };
        let mut ranges = vec![1.0_f32; 8];
        ranges[1] = 0.1;
        apply_lidar_geometry(&mut ranges, 3.5, &model, || unreachable!("no dropout"));
        // Bearings 0, 45, ..., 315 degrees: 0, 45, 90, 270, 315 are inside a 180-degree view.
        assert_eq!(ranges, [1.0, 3.5, 1.0, 3.5, 3.5, 3.5, 1.0, 1.0]);
    }

    #[test]
    fn the_compass_bias_is_in_the_reading() {
        let models = RealityModels {
            compass: CompassModel {
                noise_std_deg: 1.0,
                bias_deg: 3.0,
            },
            ..RealityModels::IDEAL
        };
        let traits = RobotTraits::draw(
            &RobotParams::default(),
            &models,
            1,
            &RealitySeeds::from_noise_seed(9),
            2,
        );
        let reading = traits.compass_reading(3.1, 0.0);
        assert!((reading - wrap_angle(3.1 + 3f64.to_radians())).abs() < 1e-12);
        assert!(reading < 0.0, "wrapped past pi");
        let noisy = traits.compass_reading(0.0, -2.0);
        assert!((noisy - (3.0 - 2.0) * 1f64.to_radians()).abs() < 1e-12);
    }

    #[test]
    fn spread_draws_each_robot_its_own_parameters_within_bounds() {
        let models = RealityModels {
            motors: MotorModel {
                tau_s: 0.1,
                ..MotorModel::IDEAL
            },
            spread: 0.05,
            ..RealityModels::IDEAL
        };
        let seeds = RealitySeeds::from_noise_seed(77);
        let params = RobotParams::default();
        let drawn: Vec<RobotTraits> = (0..20)
            .map(|i| RobotTraits::draw(&params, &models, 4, &seeds, i))
            .collect();
        for traits in &drawn {
            let ratio = traits.params.wheel_separation / params.wheel_separation;
            assert!((0.95..=1.05).contains(&ratio), "{ratio}");
            assert!((0.095..=0.105).contains(&traits.tau_s), "{}", traits.tau_s);
            assert!(traits.scan_offset_ticks < 4);
            assert_eq!(traits.params.body_radius, params.body_radius);
        }
        assert_ne!(drawn[0].tau_s, drawn[1].tau_s);
        // Seeded per robot: robot 3 draws the same whatever the team.
        assert_eq!(RobotTraits::draw(&params, &models, 4, &seeds, 3), drawn[3]);
    }
}
