//! [`World`]: the state of every robot, advanced one fixed time step at a time by [`World::step`].
//!
//! The world takes wheel commands and hands out LIDAR scans and compass headings; it has no clock
//! and does no I/O, so the in-process episode loop and the multi-process runtime drive the very same
//! code. Everything random in it (the LIDAR's range noise, and the [`reality`](crate::reality)
//! models' draws, each from a stream of its own) comes from ChaCha8 generators seeded at
//! construction, drawn in a fixed order, so the same initial state, seed and commands always give
//! the same bits.

use std::collections::VecDeque;

use formation_proto::{LidarNoise, LidarSpec, Pose, SimulatedLidar, WheelCmd};
use parry2d::math::Point;
use parry2d::query::details::intersection_test_ball_ball;
use parry2d::shape::Ball;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::grid::SpatialGrid;
use crate::lidar::{TeamScanner, cast_scan};
use crate::lidar_noise::add_range_noise;
use crate::reality::{
    RealityModels, RealitySeeds, RobotTraits, apply_lidar_geometry, scan_age_ticks,
};
use crate::robot::{RobotParams, integrate};

/// Control period of the paper's setting: 20 Hz.
pub const DEFAULT_DT: f64 = 0.05;

/// Everything that fixes a world's physics and sensing, shared by all its robots.
///
/// Serialised as before the LIDAR's contract and noise were apart: `lidar` is one object
/// `{beams, max_range, noise_std}` ([`SimulatedLidar`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "WorldConfigFile", into = "WorldConfigFile")]
pub struct WorldConfig {
    /// Body, wheel and limit parameters of every robot.
    pub robot: RobotParams,
    /// The LIDAR ring every robot carries, as its agent and model must agree on it.
    pub lidar: LidarSpec,
    /// The noise the world adds to every LIDAR's ranges ([`crate::lidar_noise`]); no agent
    /// sees it.
    pub lidar_noise: LidarNoise,
    /// Time step \[s\] of one [`World::step`].
    pub dt: f64,
    /// Motor, LIDAR timing and geometry, compass, latency and spread models; all off by default
    /// (and then absent from the serialized form, which stays as it was before the models).
    pub reality: RealityModels,
}

impl WorldConfig {
    /// The LIDAR as a world simulates it: the contract and the noise.
    pub fn simulated_lidar(&self) -> SimulatedLidar {
        SimulatedLidar {
            spec: self.lidar,
            noise: self.lidar_noise,
        }
    }
}

/// [`WorldConfig`] as files hold it.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldConfigFile {
    robot: RobotParams,
    lidar: SimulatedLidar,
    dt: f64,
    #[serde(default, skip_serializing_if = "RealityModels::is_ideal")]
    reality: RealityModels,
}

impl From<WorldConfigFile> for WorldConfig {
    fn from(file: WorldConfigFile) -> WorldConfig {
        WorldConfig {
            robot: file.robot,
            lidar: file.lidar.spec,
            lidar_noise: file.lidar.noise,
            dt: file.dt,
            reality: file.reality,
        }
    }
}

impl From<WorldConfig> for WorldConfigFile {
    fn from(config: WorldConfig) -> WorldConfigFile {
        WorldConfigFile {
            robot: config.robot,
            lidar: config.simulated_lidar(),
            dt: config.dt,
            reality: config.reality,
        }
    }
}

impl Default for WorldConfig {
    /// P3-DX robots, a 900-beam 10 m noiseless ring and a 20 Hz step.
    fn default() -> Self {
        WorldConfig {
            robot: RobotParams::default(),
            lidar: LidarSpec::default(),
            lidar_noise: LidarNoise::NONE,
            dt: DEFAULT_DT,
            reality: RealityModels::IDEAL,
        }
    }
}

/// What one [`World::step`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct StepReport {
    /// Pairs `(i, j)`, `i < j` in increasing order, whose bodies overlap or touch after the step.
    pub collisions: Vec<(usize, usize)>,
    /// The wheel speeds each robot actually ran during the step, after braking non-finite commands
    /// and applying the wheel limits.
    pub applied: Vec<WheelCmd>,
}

/// The simulated robots: their poses, current wheel speeds, the tick counter and the noise source.
#[derive(Debug, Clone)]
pub struct World {
    config: WorldConfig,
    poses: Vec<Pose>,
    wheel_speeds: Vec<WheelCmd>,
    tick: u64,
    noise_rng: ChaCha8Rng,
    collisions_total: u64,
    /// Buffers reused from tick to tick; they hold no state that outlives a call.
    scanner: TeamScanner,
    contact_grid: SpatialGrid,
    contact_partners: Vec<usize>,
    /// The reality models' state: each robot's traits, held scans, queued commands, streams.
    reality: RealityState,
}

/// What the [`reality`](crate::reality) models keep from tick to tick.
#[derive(Debug, Clone)]
struct RealityState {
    /// Each robot's own parameters (the nominal ones when nothing is spread).
    traits: Vec<RobotTraits>,
    /// Control ticks between two scans (1: a scan every tick).
    scan_period_ticks: u64,
    /// Each robot's last scan taken, when scans are held (`scan_period_ticks > 1`).
    held_scans: Vec<Vec<f32>>,
    /// Each robot's commands not yet applied, oldest first (`command_latency_ticks` of them).
    pending: Vec<VecDeque<WheelCmd>>,
    /// Each robot's pose with the heading its compass read this tick (compass model on).
    compass_poses: Vec<Pose>,
    motor_rng: ChaCha8Rng,
    dropout_rng: ChaCha8Rng,
    compass_rng: ChaCha8Rng,
}

impl RealityState {
    fn new(config: &WorldConfig, poses: &[Pose], noise_seed: u64) -> RealityState {
        let models = &config.reality;
        let seeds = RealitySeeds::from_noise_seed(noise_seed);
        let scan_period_ticks = models.lidar.scan_period_ticks(config.dt);
        let traits = (0..poses.len())
            .map(|robot| RobotTraits::draw(&config.robot, models, scan_period_ticks, &seeds, robot))
            .collect();
        let latency = models.command_latency_ticks as usize;
        RealityState {
            traits,
            scan_period_ticks,
            held_scans: Vec::new(),
            pending: vec![VecDeque::from(vec![WheelCmd::BRAKE; latency]); poses.len()],
            compass_poses: if models.compass == crate::reality::CompassModel::IDEAL {
                Vec::new()
            } else {
                poses.to_vec()
            },
            motor_rng: ChaCha8Rng::seed_from_u64(seeds.motors),
            dropout_rng: ChaCha8Rng::seed_from_u64(seeds.dropout),
            compass_rng: ChaCha8Rng::seed_from_u64(seeds.compass),
        }
    }
}

impl World {
    /// A world at tick 0 with the robots at `poses`, standing still, and sensor noise drawn from a
    /// generator seeded with `noise_seed`.
    pub fn new(config: WorldConfig, poses: Vec<Pose>, noise_seed: u64) -> World {
        let wheel_speeds = vec![WheelCmd::BRAKE; poses.len()];
        let reality = RealityState::new(&config, &poses, noise_seed);
        World {
            config,
            poses,
            wheel_speeds,
            tick: 0,
            noise_rng: ChaCha8Rng::seed_from_u64(noise_seed),
            collisions_total: 0,
            scanner: TeamScanner::new(),
            contact_grid: SpatialGrid::new(),
            contact_partners: Vec::new(),
            reality,
        }
    }

    /// The physics and sensor settings.
    pub fn config(&self) -> &WorldConfig {
        &self.config
    }

    /// Every robot's current pose, in robot order.
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    /// The wheel speeds each robot ran during the last step (all zero before the first).
    pub fn wheel_speeds(&self) -> &[WheelCmd] {
        &self.wheel_speeds
    }

    /// Number of robots.
    pub fn n_robots(&self) -> usize {
        self.poses.len()
    }

    /// Steps taken so far.
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// Simulated time \[s\]: `tick * dt`.
    pub fn time(&self) -> f64 {
        self.tick as f64 * self.config.dt
    }

    /// Colliding pairs summed over all steps so far: a pair that stays in contact for `k` steps
    /// counts `k` times.
    pub fn collisions_total(&self) -> u64 {
        self.collisions_total
    }

    /// Writes robot `robot`'s LIDAR ranges into `out` (one per beam): the noiseless ray cast plus,
    /// the world's LIDAR noise ([`crate::lidar_noise`]), e.g. Gaussian noise from the world's generator on every beam that hit
    /// something, clamped to `[0, max_range]`, and then the LIDAR model's field of view, minimum
    /// range and dropout. Beams that hit nothing read exactly `max_range`. This is the scan cast
    /// now: holding scans between a slower LIDAR's scans is [`World::scan_all`]'s.
    ///
    /// # Panics
    ///
    /// If `robot >= n_robots()` or `out.len()` differs from the configured beam count.
    pub fn scan_into(&mut self, robot: usize, out: &mut [f32]) {
        let lidar = self.config.lidar;
        cast_scan(&self.poses, robot, &self.config.robot, &lidar, out);
        add_range_noise(
            out,
            lidar.max_range,
            &self.config.lidar_noise,
            &mut self.noise_rng,
        );
        self.apply_lidar_model(out);
    }

    /// The LIDAR model's field of view, minimum range and dropout on one scan (nothing, and no
    /// draw, for the ideal ring).
    fn apply_lidar_model(&mut self, ranges: &mut [f32]) {
        let model = self.config.reality.lidar;
        if model.changes_geometry() {
            let rng = &mut self.reality.dropout_rng;
            apply_lidar_geometry(ranges, self.config.lidar.max_range, &model, || {
                rng.random::<f64>()
            });
        }
    }

    /// Scans every robot in order `0..n_robots()` (which fixes the order noise is drawn in), each into
    /// `out[i]`, resized to the beam count: the same bits as [`World::scan_into`] robot after robot,
    /// but looking only at the bodies within each robot's range (see [`TeamScanner`]), so a tick
    /// costs `O(N)` rather than `O(N^2)` in the team's size. With a LIDAR slower than the control
    /// rate (`reality.lidar.scan_rate_hz`), a robot whose scan is not due this tick gets its last
    /// scan again ([`World::scan_age`] says how old); every scan is still cast and noised, so no
    /// stream's draws depend on the scan rate.
    ///
    /// # Panics
    ///
    /// If `out.len()` differs from `n_robots()`.
    pub fn scan_all(&mut self, out: &mut [Vec<f32>]) {
        assert_eq!(
            out.len(),
            self.n_robots(),
            "scan_all: {} scan buffers for {} robots",
            out.len(),
            self.n_robots()
        );
        let lidar = self.config.lidar;
        for scan in out.iter_mut() {
            scan.resize(lidar.beams, 0.0);
        }
        self.scanner
            .scan_all(&self.poses, &self.config.robot, &lidar, out);
        // The noiseless casts draw nothing, so adding each robot's noise after all the casts draws
        // the same numbers in the same order as scanning and noising robot after robot.
        for scan in out.iter_mut() {
            add_range_noise(
                scan,
                lidar.max_range,
                &self.config.lidar_noise,
                &mut self.noise_rng,
            );
        }
        for scan in out.iter_mut() {
            self.apply_lidar_model(scan);
        }
        self.hold_scans(out);
    }

    /// With a LIDAR slower than the control rate, replaces each scan of `out` that is not due this
    /// tick by the robot's last scan taken, and keeps each one taken. Every scan is cast and noised
    /// anyway, so the noise streams advance the same whatever the scan rate.
    fn hold_scans(&mut self, out: &mut [Vec<f32>]) {
        let period = self.reality.scan_period_ticks;
        if period <= 1 {
            return;
        }
        if self.reality.held_scans.len() != out.len() {
            self.reality.held_scans = out.to_vec();
        }
        for (robot, (scan, held)) in out.iter_mut().zip(&mut self.reality.held_scans).enumerate() {
            let offset = self.reality.traits[robot].scan_offset_ticks;
            if self.tick == 0 || scan_age_ticks(self.tick, offset, period) == 0 {
                held.copy_from_slice(scan);
            } else {
                scan.copy_from_slice(held);
            }
        }
    }

    /// How many seconds old robot `robot`'s scan of this tick is (as [`World::scan_all`] hands it
    /// out): 0 when the LIDAR scans every tick.
    ///
    /// # Panics
    ///
    /// If `robot >= n_robots()`.
    pub fn scan_age(&self, robot: usize) -> f64 {
        self.scan_age_ticks(robot) as f64 * self.config.dt
    }

    /// [`World::scan_age`] in control ticks.
    ///
    /// # Panics
    ///
    /// If `robot >= n_robots()`.
    pub fn scan_age_ticks(&self, robot: usize) -> u64 {
        let offset = self.reality.traits[robot].scan_offset_ticks;
        scan_age_ticks(self.tick, offset, self.reality.scan_period_ticks)
    }

    /// Each robot's own parameters, drawn around the nominal ones when the models spread them.
    pub fn robot_traits(&self) -> &[RobotTraits] {
        &self.reality.traits
    }

    /// Reads every robot's compass for this tick (robot order, one draw per robot whose compass
    /// is noisy); [`World::observed_poses`] then hands the readings out. Draws nothing with an
    /// exact compass.
    pub fn read_compasses(&mut self) {
        if self.reality.compass_poses.is_empty() {
            return;
        }
        for ((reading, pose), traits) in self
            .reality
            .compass_poses
            .iter_mut()
            .zip(&self.poses)
            .zip(&self.reality.traits)
        {
            let deviation = if traits.compass_noise_std > 0.0 {
                StandardNormal.sample(&mut self.reality.compass_rng)
            } else {
                0.0
            };
            *reading = Pose {
                theta: traits.compass_reading(pose.theta, deviation),
                ..*pose
            };
        }
    }

    /// Every robot's pose as a controller observes it: the true position with the heading its
    /// compass read at the last [`World::read_compasses`] (the true pose with an exact compass).
    pub fn observed_poses(&self) -> &[Pose] {
        if self.reality.compass_poses.is_empty() {
            &self.poses
        } else {
            &self.reality.compass_poses
        }
    }

    /// Advances the world by one time step with `cmds[i]` for robot `i`.
    ///
    /// With a command latency of `k` ticks, the commands run are those given `k` steps ago (a
    /// brake before the first). A command with a non-finite wheel speed brakes its robot; each
    /// wheel is saturated to `±max_wheel_speed` and, when set, limited in acceleration (see
    /// [`RobotParams::achievable`]), through the motor model when it is on
    /// ([`RobotTraits::drive`]). Every robot then moves along its exact arc for `dt`; afterwards
    /// the pairs of overlapping bodies are reported and added to [`World::collisions_total`]. Bodies
    /// pass through each other: the world reports collisions, it does not resolve them.
    ///
    /// # Panics
    ///
    /// If `cmds.len()` differs from `n_robots()`.
    pub fn step(&mut self, cmds: &[WheelCmd]) -> StepReport {
        assert_eq!(
            cmds.len(),
            self.n_robots(),
            "World::step: {} commands for {} robots",
            cmds.len(),
            self.n_robots()
        );
        let WorldConfig { robot, dt, .. } = self.config;
        let mut applied = Vec::with_capacity(cmds.len());
        let reality = &mut self.reality;
        for (((pose, speeds), &given), (traits, pending)) in self
            .poses
            .iter_mut()
            .zip(&mut self.wheel_speeds)
            .zip(cmds)
            .zip(reality.traits.iter().zip(&mut reality.pending))
        {
            let requested = match pending.pop_front() {
                Some(due) => {
                    pending.push_back(given);
                    due
                }
                None => given,
            };
            let mut noise = [0.0; 2];
            if traits.speed_noise_std > 0.0 {
                for deviation in &mut noise {
                    *deviation = StandardNormal.sample(&mut reality.motor_rng);
                }
            }
            *speeds = traits.drive(requested, *speeds, dt, noise);
            *pose = integrate(*pose, *speeds, &traits.params, dt);
            applied.push(*speeds);
        }
        let collisions = overlapping_pairs_in_grid(
            &mut self.contact_grid,
            &mut self.contact_partners,
            &self.poses,
            robot.body_radius,
        );
        self.collisions_total += collisions.len() as u64;
        self.tick += 1;
        StepReport {
            collisions,
            applied,
        }
    }
}

/// [`overlapping_pairs`], finding each robot's possible partners in `grid` (rebuilt here, cells of
/// one body diameter) instead of testing all pairs: the same pairs in the same order, in `O(N)` for a
/// team without crowds. `partners` is scratch.
fn overlapping_pairs_in_grid(
    grid: &mut SpatialGrid,
    partners: &mut Vec<usize>,
    poses: &[Pose],
    body_radius: f64,
) -> Vec<(usize, usize)> {
    let body = Ball::new(body_radius as f32);
    let reach = 2.0 * body_radius;
    grid.rebuild(poses, reach);
    let mut pairs = Vec::new();
    for (i, a) in poses.iter().enumerate() {
        partners.clear();
        // The grid visits every robot whose offsets are within `reach`, which the box test below
        // requires (a NaN offset passes the box test but never parry's ball test).
        grid.for_each_near(a.x, a.y, reach, |j, b_x, b_y| {
            if j <= i {
                return;
            }
            // From here on, overlapping_pairs's test, operation for operation.
            let (dx, dy) = (b_x - a.x, b_y - a.y);
            if dx.abs() > reach || dy.abs() > reach {
                return;
            }
            if intersection_test_ball_ball(&Point::new(dx as f32, dy as f32), &body, &body) {
                partners.push(j);
            }
        });
        partners.sort_unstable();
        pairs.extend(partners.iter().map(|&j| (i, j)));
    }
    pairs
}

/// Pairs `(i, j)`, `i < j`, of discs of radius `body_radius` centred at `poses` that overlap or
/// touch, in increasing order. A cheap box test in f64 culls far pairs before parry's ball test,
/// which gets the centres' offset computed in f64. Tests all pairs: the reference
/// [`World::step`]'s grid search is checked against.
#[cfg(test)]
fn overlapping_pairs(poses: &[Pose], body_radius: f64) -> Vec<(usize, usize)> {
    let body = Ball::new(body_radius as f32);
    let reach = 2.0 * body_radius;
    let mut pairs = Vec::new();
    for (i, a) in poses.iter().enumerate() {
        for (j, b) in poses.iter().enumerate().skip(i + 1) {
            let (dx, dy) = (b.x - a.x, b.y - a.y);
            if dx.abs() > reach || dy.abs() > reach {
                continue;
            }
            if intersection_test_ball_ball(&Point::new(dx as f32, dy as f32), &body, &body) {
                pairs.push((i, j));
            }
        }
    }
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_layouts::disc_layout;
    use formation_proto::wrap_angle;

    fn noisy_config(noise_std: f64) -> WorldConfig {
        WorldConfig {
            lidar_noise: LidarNoise { noise_std },
            ..WorldConfig::default()
        }
    }

    #[test]
    fn step_saturates_wheels_and_moves_by_the_applied_speeds() {
        let mut world = World::new(WorldConfig::default(), vec![Pose::new(0.0, 0.0, 0.0)], 1);
        let report = world.step(&[WheelCmd::new(3.0, 3.0)]);
        let limit = world.config().robot.max_wheel_speed;
        assert_eq!(
            report.applied,
            vec![WheelCmd {
                left: limit,
                right: limit
            }]
        );
        assert!((world.poses()[0].x - limit * DEFAULT_DT).abs() < 1e-12);
        assert_eq!(world.tick(), 1);
        assert!((world.time() - DEFAULT_DT).abs() < 1e-15);
    }

    #[test]
    fn a_non_finite_command_brakes_only_its_robot() {
        let poses = vec![Pose::new(0.0, 0.0, 0.0), Pose::new(5.0, 0.0, 0.0)];
        let mut world = World::new(WorldConfig::default(), poses, 1);
        world.step(&[WheelCmd::new(0.5, 0.5); 2]);
        let before = world.poses().to_vec();
        let cmds = [WheelCmd::new(f64::NAN, 0.5), WheelCmd::new(0.5, 0.5)];
        let report = world.step(&cmds);
        assert_eq!(report.applied[0], WheelCmd::BRAKE);
        assert_eq!(world.poses()[0], before[0]);
        assert!(world.poses()[1].x > before[1].x);
        assert!(
            world
                .poses()
                .iter()
                .all(|p| p.x.is_finite() && p.y.is_finite())
        );
    }

    #[test]
    fn the_acceleration_limit_ramps_wheel_speeds_up_across_steps() {
        let config = WorldConfig {
            robot: RobotParams {
                max_wheel_accel: Some(2.0),
                ..RobotParams::default()
            },
            ..WorldConfig::default()
        };
        let mut world = World::new(config, vec![Pose::new(0.0, 0.0, 0.0)], 1);
        let cmd = [WheelCmd::new(0.5, 0.5)];
        let speeds: Vec<f64> = (0..7).map(|_| world.step(&cmd).applied[0].left).collect();
        let expected = [0.1, 0.2, 0.3, 0.4, 0.5, 0.5, 0.5];
        for (got, want) in speeds.iter().zip(expected) {
            assert!((got - want).abs() < 1e-12, "{speeds:?}");
        }
    }

    #[test]
    fn overlapping_robots_collide_and_separated_ones_do_not() {
        let poses = vec![
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(0.45, 0.0, 0.0),
            Pose::new(3.0, 3.0, 0.0),
            Pose::new(3.6, 3.0, 0.0),
        ];
        let mut world = World::new(WorldConfig::default(), poses, 1);
        let report = world.step(&[WheelCmd::BRAKE; 4]);
        assert_eq!(report.collisions, vec![(0, 1)]);
        world.step(&[WheelCmd::BRAKE; 4]);
        assert_eq!(world.collisions_total(), 2);
    }

    #[test]
    fn robots_driving_head_on_collide_when_their_bodies_meet() {
        // 1.02 m apart closing at 1 m/s: the gap reaches 0.5 m after 0.52 s, so at the 11th step.
        let poses = vec![
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(1.02, 0.0, std::f64::consts::PI),
        ];
        let mut world = World::new(WorldConfig::default(), poses, 1);
        let cmds = [WheelCmd::new(0.5, 0.5); 2];
        let first = (1..=20).find(|_| !world.step(&cmds).collisions.is_empty());
        assert_eq!(first, Some(11));
    }

    /// Robot `own`'s scan of `poses` without noise, by the default robot's default LIDAR.
    fn exact_scan(poses: &[Pose], own: usize) -> Vec<f32> {
        let lidar = LidarSpec::default();
        let mut scan = vec![0.0; lidar.beams];
        cast_scan(poses, own, &RobotParams::default(), &lidar, &mut scan);
        scan
    }

    #[test]
    fn scan_into_matches_the_noiseless_cast_without_noise() {
        let poses = vec![Pose::new(0.0, 0.0, 0.0), Pose::new(3.0, 0.0, 0.0)];
        let mut world = World::new(WorldConfig::default(), poses.clone(), 1);
        let mut from_world = vec![0.0; 900];
        world.scan_into(0, &mut from_world);
        let direct = exact_scan(&poses, 0);
        assert_eq!(from_world, direct);
        assert!((from_world[0] - 2.75).abs() < 1e-4);
    }

    #[test]
    fn noise_perturbs_hits_only_with_the_configured_spread() {
        let poses = vec![Pose::new(0.0, 0.0, 0.0), Pose::new(3.0, 0.0, 0.0)];
        let mut world = World::new(noisy_config(0.03), poses.clone(), 7);
        let clean = exact_scan(&poses, 0);
        let mut scan = vec![0.0; 900];
        let mut errors = Vec::new();
        for _ in 0..200 {
            world.scan_into(0, &mut scan);
            for (noisy, exact) in scan.iter().zip(&clean) {
                if *exact == 10.0 {
                    assert_eq!(*noisy, 10.0, "a beam without a hit must stay at max_range");
                } else {
                    assert!((0.0..=10.0).contains(noisy));
                    errors.push(*noisy as f64 - *exact as f64);
                }
            }
        }
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let std = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        assert!(mean.abs() < 0.003, "mean error {mean}");
        assert!((std - 0.03).abs() < 0.003, "error spread {std}");
    }

    #[test]
    fn noise_is_clamped_to_the_sensor_range() {
        // A body almost touching the sensor and a huge noise: many draws fall below 0.
        let poses = vec![Pose::new(0.0, 0.0, 0.0), Pose::new(0.52, 0.0, 0.0)];
        let mut world = World::new(noisy_config(1.0), poses, 3);
        let mut scan = vec![0.0; 900];
        world.scan_into(0, &mut scan);
        assert!(scan.iter().all(|r| (0.0..=10.0).contains(r)));
        assert!(scan.contains(&0.0), "some negative draws must clamp to 0");
    }

    /// Runs a 6-robot world for 500 ticks with commands that depend on the noisy scans, returning
    /// the final poses and the last scans.
    fn closed_loop_run(noise_seed: u64) -> (Vec<Pose>, Vec<Vec<f32>>) {
        let poses = (0..6)
            .map(|i| Pose::new(i as f64 * 0.9, (i % 2) as f64 * 0.7, i as f64))
            .collect();
        let mut world = World::new(noisy_config(0.03), poses, noise_seed);
        let mut scans = vec![Vec::new(); world.n_robots()];
        let mut cmds = vec![WheelCmd::BRAKE; world.n_robots()];
        for _ in 0..500 {
            world.scan_all(&mut scans);
            for (cmd, scan) in cmds.iter_mut().zip(&scans) {
                let nearest = scan.iter().copied().fold(f32::INFINITY, f32::min) as f64;
                let turn = if nearest < 1.0 { 0.3 } else { -0.05 };
                *cmd = WheelCmd::new(0.4 - turn + 0.01 * nearest, 0.4 + turn);
            }
            world.step(&cmds);
        }
        (world.poses().to_vec(), scans)
    }

    fn bits(poses: &[Pose]) -> Vec<[u64; 3]> {
        poses
            .iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()])
            .collect()
    }

    #[test]
    fn same_seed_and_commands_give_the_same_bits() {
        let (poses_a, scans_a) = closed_loop_run(42);
        let (poses_b, scans_b) = closed_loop_run(42);
        assert_eq!(bits(&poses_a), bits(&poses_b));
        let scan_bits = |scans: &[Vec<f32>]| -> Vec<u32> {
            scans.iter().flatten().map(|r| r.to_bits()).collect()
        };
        assert_eq!(scan_bits(&scans_a), scan_bits(&scans_b));
    }

    #[test]
    fn a_different_noise_seed_gives_different_scans() {
        let poses = vec![Pose::new(0.0, 0.0, 0.0), Pose::new(2.0, 0.5, 0.0)];
        let scan_with = |seed| {
            let mut world = World::new(noisy_config(0.03), poses.clone(), seed);
            let mut scan = vec![0.0; 900];
            world.scan_into(0, &mut scan);
            scan
        };
        assert_eq!(scan_with(1), scan_with(1));
        assert_ne!(scan_with(1), scan_with(2));
    }

    #[test]
    fn config_round_trips_through_json_and_rejects_unknown_fields() {
        let config = noisy_config(0.02);
        let text = serde_json::to_string(&config).expect("serialisable");
        let back: WorldConfig = serde_json::from_str(&text).expect("readable");
        assert_eq!(back, config);
        let extra = text.replacen('{', "{\"gravity\":9.81,", 1);
        assert!(serde_json::from_str::<WorldConfig>(&extra).is_err());
    }

    /// Layouts for the equivalence tests: the paper's density for teams of 2 to 300, dense crowds
    /// with overlapping bodies, and a team far from the origin.
    fn equivalence_layouts() -> Vec<Vec<Pose>> {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut layouts = Vec::new();
        for n in [2, 3, 7, 20, 64, 150, 300] {
            let radius = 3.0 * (n as f64 / 3.0).sqrt();
            layouts.push(disc_layout(&mut rng, n, (0.0, 0.0), radius, 0.6));
        }
        for (n, radius) in [(5, 0.4), (60, 2.0), (200, 4.0), (300, 12.0)] {
            layouts.push(disc_layout(&mut rng, n, (-4.0, 9.0), radius, 0.0));
        }
        layouts.push(disc_layout(&mut rng, 80, (5e8, -5e8), 6.0, 0.0));
        layouts
    }

    fn scan_bits(scans: &[Vec<f32>]) -> Vec<u32> {
        scans.iter().flatten().map(|r| r.to_bits()).collect()
    }

    #[test]
    fn scan_all_gives_the_bits_of_scan_into_robot_by_robot_with_and_without_noise() {
        for noise_std in [0.0, 0.03, 2.0] {
            for poses in equivalence_layouts() {
                let n = poses.len();
                let mut grid_world = World::new(noisy_config(noise_std), poses.clone(), 5);
                let mut reference_world = World::new(noisy_config(noise_std), poses, 5);
                // Two rounds: the second checks that both consumed the noise stream alike.
                for _ in 0..2 {
                    let mut from_scan_all = vec![Vec::new(); n];
                    grid_world.scan_all(&mut from_scan_all);
                    let from_scan_into: Vec<Vec<f32>> = (0..n)
                        .map(|robot| {
                            let mut scan = vec![0.0; 900];
                            reference_world.scan_into(robot, &mut scan);
                            scan
                        })
                        .collect();
                    assert_eq!(
                        scan_bits(&from_scan_all),
                        scan_bits(&from_scan_into),
                        "{n} robots, noise {noise_std}"
                    );
                }
            }
        }
    }

    #[test]
    fn grid_collisions_are_the_all_pairs_collisions() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let mut grid = SpatialGrid::new();
        let mut partners = Vec::new();
        let mut layouts = equivalence_layouts();
        // Bodies exactly touching (centres one diameter apart), a few ulps either side of it, on
        // both axes and diagonally, across cell boundaries (cells are one diameter wide).
        let diameter = 2.0 * RobotParams::default().body_radius;
        let mut touching = Vec::new();
        for k in 0..40_i64 {
            let (x, y) = (k as f64 * 3.0 * diameter, (k % 5) as f64 * diameter);
            let nudged = f64::from_bits((diameter.to_bits() as i64 + k % 3 - 1) as u64);
            touching.push(Pose::new(x, y, 0.0));
            touching.push(Pose::new(x + nudged, y, 0.0));
            touching.push(Pose::new(x, y + diameter, 0.0));
            touching.push(Pose::new(
                x + diameter * 0.5_f64.sqrt(),
                y - diameter * 0.5_f64.sqrt(),
                0.0,
            ));
        }
        layouts.push(touching);
        // Non-finite and huge coordinates among ordinary robots.
        let mut odd = disc_layout(&mut rng, 50, (0.0, 0.0), 2.0, 0.0);
        odd.extend([
            Pose::new(f64::NAN, 0.0, 0.0),
            Pose::new(f64::NAN, 0.0, 0.0),
            Pose::new(f64::INFINITY, 1.0, 0.0),
            Pose::new(f64::INFINITY, 1.0, 0.0),
            Pose::new(2e9, 0.0, 0.0),
            Pose::new(2e9 + 0.3, 0.0, 0.0),
            Pose::new(1e9 - 0.1, 0.0, 0.0),
            Pose::new(1e9 + 0.1, 0.0, 0.0),
        ]);
        layouts.push(odd);
        let mut pairs_seen = 0;
        for poses in &layouts {
            for body_radius in [0.25, 0.05, 1.0, 0.0, -0.1, f64::NAN] {
                let expected = overlapping_pairs(poses, body_radius);
                let found = overlapping_pairs_in_grid(&mut grid, &mut partners, poses, body_radius);
                assert_eq!(
                    found,
                    expected,
                    "{} robots, radius {body_radius}",
                    poses.len()
                );
                pairs_seen += expected.len();
            }
        }
        assert!(pairs_seen > 1000, "only {pairs_seen} colliding pairs");
    }

    #[test]
    fn a_moving_crowd_scans_and_collides_as_the_reference_does_tick_after_tick() {
        // 120 robots in a 6 m disc driving with scan-dependent commands for 60 ticks: each tick's
        // scans must match scan_into robot by robot, and each step's collisions the all-pairs test.
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let poses = disc_layout(&mut rng, 120, (1.0, 1.0), 6.0, 0.0);
        let n = poses.len();
        let mut world = World::new(noisy_config(0.03), poses.clone(), 9);
        let mut reference = World::new(noisy_config(0.03), poses, 9);
        let mut scans = vec![Vec::new(); n];
        let mut reference_scan = vec![0.0; 900];
        let mut cmds = vec![WheelCmd::BRAKE; n];
        let mut collisions = 0;
        for tick in 0..60 {
            world.scan_all(&mut scans);
            for (robot, scan) in scans.iter().enumerate() {
                reference.scan_into(robot, &mut reference_scan);
                let same = scan
                    .iter()
                    .zip(&reference_scan)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "tick {tick}, robot {robot}");
            }
            for (cmd, scan) in cmds.iter_mut().zip(&scans) {
                let ahead = scan[..40]
                    .iter()
                    .chain(&scan[860..])
                    .copied()
                    .fold(10.0, f32::min);
                let turn = if ahead < 1.0 { 0.4 } else { 0.0 };
                *cmd = WheelCmd::new(0.5 - turn, 0.5 + turn);
            }
            let report = world.step(&cmds);
            let reference_report = reference.step(&cmds);
            assert_eq!(report, reference_report);
            assert_eq!(
                report.collisions,
                overlapping_pairs(world.poses(), world.config().robot.body_radius)
            );
            collisions += report.collisions.len();
        }
        assert!(collisions > 0);
        assert_eq!(world.collisions_total(), reference.collisions_total());
    }

    fn with_reality(reality: RealityModels) -> WorldConfig {
        WorldConfig {
            reality,
            ..noisy_config(0.03)
        }
    }

    #[test]
    fn a_slow_lidar_holds_each_scan_and_reports_its_age() {
        use crate::reality::LidarModel;
        let config = with_reality(RealityModels {
            lidar: LidarModel {
                scan_rate_hz: Some(5.0),
                ..LidarModel::IDEAL
            },
            ..RealityModels::IDEAL
        });
        let poses = vec![
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(1.5, 0.3, 0.0),
            Pose::new(-1.0, 1.0, 2.0),
        ];
        let mut world = World::new(config, poses, 4);
        let cmds = [WheelCmd::new(0.3, 0.5); 3];
        let mut scans = vec![Vec::new(); 3];
        let mut previous: Option<Vec<Vec<f32>>> = None;
        for tick in 0..16 {
            world.scan_all(&mut scans);
            for robot in 0..3 {
                let age = world.scan_age_ticks(robot);
                assert!(age < 4);
                assert_eq!(world.scan_age(robot), age as f64 * DEFAULT_DT);
                if let Some(previous) = &previous {
                    // A held scan is the same bits; a fresh one differs (the robots move).
                    assert_eq!(
                        age != 0,
                        scans[robot] == previous[robot],
                        "tick {tick}, robot {robot}, age {age}"
                    );
                }
            }
            previous = Some(scans.clone());
            world.step(&cmds);
        }
        // The robots' scans are not in step with each other.
        let offsets: Vec<u64> = world
            .robot_traits()
            .iter()
            .map(|t| t.scan_offset_ticks)
            .collect();
        assert!(offsets.iter().any(|&o| o != offsets[0]), "{offsets:?}");
    }

    #[test]
    fn a_command_runs_after_the_latency() {
        let config = with_reality(RealityModels {
            command_latency_ticks: 2,
            ..RealityModels::IDEAL
        });
        let mut world = World::new(config, vec![Pose::new(0.0, 0.0, 0.0)], 1);
        let go = WheelCmd::new(0.4, 0.4);
        let ran: Vec<WheelCmd> = [go, WheelCmd::BRAKE, go, go, WheelCmd::BRAKE]
            .iter()
            .map(|&cmd| world.step(&[cmd]).applied[0])
            .collect();
        assert_eq!(
            ran,
            [WheelCmd::BRAKE, WheelCmd::BRAKE, go, WheelCmd::BRAKE, go]
        );
    }

    #[test]
    fn the_compass_reads_bias_and_noise_and_leaves_the_true_pose_alone() {
        use crate::reality::CompassModel;
        let config = with_reality(RealityModels {
            compass: CompassModel {
                noise_std_deg: 2.0,
                bias_deg: 5.0,
            },
            ..RealityModels::IDEAL
        });
        let mut world = World::new(
            config,
            vec![Pose::new(1.0, 2.0, 0.5), Pose::new(3.0, 2.0, -0.5)],
            8,
        );
        let mut errors = Vec::new();
        for _ in 0..400 {
            world.read_compasses();
            for (seen, truth) in world.observed_poses().iter().zip(world.poses()) {
                assert_eq!((seen.x, seen.y), (truth.x, truth.y));
                errors.push(wrap_angle(seen.theta - truth.theta).to_degrees());
            }
            world.step(&[WheelCmd::BRAKE; 2]);
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let std =
            (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / errors.len() as f64).sqrt();
        // 800 readings: the mean's standard error is 2 / sqrt(800) = 0.07 degrees.
        assert!((mean - 5.0).abs() < 0.3, "mean error {mean}");
        assert!((std - 2.0).abs() < 0.3, "spread {std}");
        assert_eq!(world.poses()[0], Pose::new(1.0, 2.0, 0.5));
    }

    #[test]
    fn turning_models_on_shifts_no_range_noise_draw() {
        use crate::reality::{CompassModel, MotorModel};
        // Braking robots stay put under lag, latency and compass noise, so their scans must be
        // the same bits as in the ideal world: those models draw from streams of their own.
        let poses = vec![
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(1.2, 0.4, 1.0),
            Pose::new(-0.8, 0.9, 2.0),
        ];
        let mut ideal = World::new(noisy_config(0.03), poses.clone(), 21);
        let mut real = World::new(
            with_reality(RealityModels {
                motors: MotorModel {
                    tau_s: 0.2,
                    gain_asymmetry: 0.1,
                    ..MotorModel::IDEAL
                },
                compass: CompassModel {
                    noise_std_deg: 3.0,
                    bias_deg: 1.0,
                },
                command_latency_ticks: 3,
                ..RealityModels::IDEAL
            }),
            poses,
            21,
        );
        let (mut a, mut b) = (vec![Vec::new(); 3], vec![Vec::new(); 3]);
        for _ in 0..10 {
            ideal.scan_all(&mut a);
            real.scan_all(&mut b);
            real.read_compasses();
            assert_eq!(a, b);
            ideal.step(&[WheelCmd::BRAKE; 3]);
            real.step(&[WheelCmd::BRAKE; 3]);
        }
    }

    #[test]
    fn every_model_on_replays_bit_for_bit_from_its_seed() {
        use crate::reality::{CompassModel, LidarModel, MotorModel};
        let config = with_reality(RealityModels {
            motors: MotorModel {
                tau_s: 0.1,
                speed_noise_std: 0.01,
                gain_asymmetry: 0.02,
            },
            lidar: LidarModel {
                scan_rate_hz: Some(10.0),
                fov_deg: 270.0,
                min_range: 0.12,
                dropout: 0.02,
            },
            compass: CompassModel {
                noise_std_deg: 1.0,
                bias_deg: 2.0,
            },
            command_latency_ticks: 1,
            spread: 0.05,
        });
        let run = |seed: u64| {
            let poses = vec![
                Pose::new(0.0, 0.0, 0.0),
                Pose::new(1.2, 0.4, 1.0),
                Pose::new(-0.8, 0.9, 2.0),
            ];
            let mut world = World::new(config, poses, seed);
            let mut scans = vec![Vec::new(); 3];
            let mut bits = Vec::new();
            for tick in 0..30 {
                world.scan_all(&mut scans);
                world.read_compasses();
                bits.extend(scans.iter().flatten().map(|r| u64::from(r.to_bits())));
                bits.extend(world.observed_poses().iter().map(|p| p.theta.to_bits()));
                let turn = if tick % 7 < 3 { 0.2 } else { -0.1 };
                world.step(&[WheelCmd::new(0.5 - turn, 0.5 + turn); 3]);
                bits.extend(
                    world
                        .poses()
                        .iter()
                        .flat_map(|p| [p.x.to_bits(), p.y.to_bits()]),
                );
            }
            bits
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }
}
