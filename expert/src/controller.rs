//! The expert: the distance-based formation controller, a pure function of every robot's pose and the goal.
//!
//! Re-derived from the paper's equations:
//!
//! * **Point offset.** Each robot is controlled through the point `p_i = (x_i + c cos th_i, y_i + c sin th_i)`
//!   a distance `c` ahead of its axle, whose velocity a differential drive can set freely.
//! * **Formation term.** For every other robot `j`, with `p_ij = p_i - p_j` and `r = |p_ij|`, the gradient
//!   of the pair potential `V(r) = (r^2 - d*^2)^2 / r^2` is `tau_ij = 2 (r^4 - d*^4) / r^3 * p_ij / r`; the
//!   potential grows without bound as `r -> 0`, so the term also pushes robots apart at short range.
//!   The formation velocity is `f_i = -K3 sum_j tau_ij`.
//! * **Reference term.** `w = v* (cos phi*, sin phi*)`, its norm saturated to `max_reference_speed`.
//! * **To wheels.** With `u = f_i + w`: `v = cos th u_x + sin th u_y`, `omega = (-sin th u_x + cos th u_y) / c`,
//!   `vL = v - (l/2) omega`, `vR = v + (l/2) omega`, then both wheels scaled by one common factor so that
//!   `max(|vL|, |vR|) <= max_wheel_speed`; a common factor keeps the curvature, so a saturated robot still
//!   turns along the path it asked for, only slower.
//!
//! **Neighbours.** The paper's three robots hold every pair. A larger team holds only each robot's own
//! neighbours under the scenario's [`NeighbourRule`] (the Gabriel rule: its Gabriel pairs among the
//! robots within sensing range, plus its nearest robots; see `formation_world::neighbours`): robot `i`
//! sums `tau_ij` over its own neighbours `j` alone, each found from the robots its LIDAR reaches, so the
//! law is one a policy can learn from the robot's own image. [`ExpertController`] keeps the rule's
//! hysteresis state from tick to tick and starts afresh at tick 0.
//!
//! **What a pair's distance is measured between.** The paper measures `p_ij` between the two
//! robots' offset points, and its three robots keep that law exactly. Under a neighbour graph the
//! expert measures it between the robots' centres ([`PairPoints::Centres`], the default of
//! [`ExpertGains::graph_pair_points`]) and still moves its own offset point: a neighbour's offset
//! point depends on the neighbour's heading, which no LIDAR image shows (a robot looks the same
//! whichever way it faces), so the paper's law gives different labels for the same image whenever
//! headings differ. Measured between centres, the command is a function of what the robot itself
//! senses (its neighbours' centres in its own frame, its heading error and d*). Once the headings
//! agree the two laws are the same, and over 100 runs of 16 robots (`teams-generalist.toml`) the
//! centre law succeeded in 99 % / 99 % of runs at 5 % / 10 % against 97 % / 98 %.
//!
//! **Wheels with an acceleration limit.** The law commands a point velocity as if the wheels reached
//! any speed within one tick. With a limit `a` (`[robot] max_wheel_accel`, which the world applies
//! to each wheel) the controlled point is a double integrator whose acceleration is bounded by about
//! `a` along and across the heading (with `c = l/2` a wheel difference changing at `2a` turns the
//! point sideways at `a`). A velocity law `f = -k x` then overshoots from any distance `x` beyond
//! `2a / k^2` (a few centimetres at the team's stiffness): the point arrives too fast to stop, and
//! under a neighbour graph, whose loop is already underdamped (a pair is measured between centres
//! while the robot steers its offset point, the centre trailing it like a trailer), the overshoots
//! lock the team into a weave: measured over `teams-generalist` at 1.0 m/s² with the team gain 0.5,
//! headings swung by up to ±1.4 rad, the limit bound in 70-85 % of the last 20 s, and strict success
//! at 10 % fell to 64 % (5 robots) and 10 % (32 robots). So under a limit the formation velocity is
//! shaped to one the point can still brake from ([`braking_speed`]): with `k = 8 K` (one pair's
//! stiffness at `d*`, where `d tau / dr = 8`), the point `|f| / k` from its equilibrium may approach
//! at most at `sqrt(2 beta a |f| / k)`, `beta` ([`ExpertGains::braking_share`], 0.25) the share of
//! the limit it spends braking (the rest is left to turning and to the neighbours' motion); smoothly,
//! `|f| / sqrt(1 + k |f| / (2 beta a))`, which is the law itself near the formation (the factor is
//! about `1 - k |f| / (4 beta a)` for small `|f|`). The direction, the
//! distance law and its equilibrium are unchanged, the command stays a function of what the robot
//! senses (no wheel speeds, no memory, so a policy can still learn it), and the team gain needs no
//! cap: over 200 runs of `teams-generalist-accel` the strict success at 10 % rose from the capped
//! gain's 100 / 100 / 98 / 94 / 88 / 80 % (N = 5 / 8 / 13 / 16 / 24 / 32) to the figures in
//! [`ExpertGains::braking_share`]. Without a limit nothing is shaped.
//!
//! The expert sees ground-truth poses of all robots. It exists to generate demonstrations and as the
//! baseline the learned policy is compared with; it never runs inside an agent.

use formation_perception::policy_input::saturate_together;
use formation_proto::{Goal, Pose, WheelCmd};
use formation_trainer_bridge::label_law::LabelLaw;
use formation_world::episode::{Controller, ControllerError, Observation};
use formation_world::neighbours::{NeighbourRule, NeighbourTracker};
use formation_world::reality::RealityModels;
use formation_world::{RobotParams, WorldConfig};

use crate::pair_weights::{WeightedNeighbours, weighted_neighbours};
use serde::{Deserialize, Serialize};

/// Below this distance \[m\] between two offset points the pair's direction is undefined and the pair
/// contributes nothing (the bodies, 0.5 m across, would overlap long before).
const MIN_PAIR_DISTANCE: f64 = 1e-9;

/// The expert's gains.
///
/// The defaults are the paper's `K3 = 0.15`, `c = l/2` for the P3-DX (`l = 0.331 m`) and the paper's
/// 0.7 m/s cap on the reference velocity. They need no tuning: over the 100 runs of 60 s of
/// `scenarios/table1.toml` (noiseless LIDAR, 0.9 m/s wheel limit) the expert succeeds in 100 % of runs
/// at both 5 % and 10 %, converges (10 %) in 2.9 s median (0.7-5.9 s), holds the formation to
/// about 1e-15 relative error and the heading to about 1e-14 rad, without a collision. Reproduce with
/// `cargo run -p formation-expert --release --example expert_table1`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExpertGains {
    /// Formation gain `K3` [1/(m s)]: scales the gradient of the pair potentials into a velocity.
    pub k_formation: f64,
    /// Formation gain [1/(m s)] under a neighbour graph (teams beyond three). Each robot holds
    /// only a few neighbours there, and a stronger pull converges larger teams faster without
    /// collisions: over 100 runs of table1's draws (strict check), 0.5 against the paper's 0.15
    /// took 16 robots from 16.7 s to 8.6 s median convergence and 32 robots from 62 % to 94 %
    /// success at 10 % (`cargo run -p formation-expert --example expert_teams`). Over 200 runs
    /// of `teams-generalist` (d* over 0.8-2.5 m, σ = 3 cm) 1.0 succeeds (strict, 10 %) in 100 /
    /// 100 / 99.5 / 99 / 99 / 98.5 % at N = 5 / 8 / 13 / 16 / 24 / 32, against 0.5's 100 / 99.5 /
    /// 99.5 / 99.5 / 99 / 94 %, and converges faster (median 11.1 s against 14 s at N = 32);
    /// 1.5 weaves even without an acceleration limit (86 % at 32 robots over 50 runs);
    /// `GAINS='{"k_formation_graph": 0.5}' ACCEL=none cargo run -p formation-expert --example
    /// expert_accel -- scenarios/teams-generalist.toml 200 5 8 13 16 24 32`.
    pub k_formation_graph: f64,
    /// Distance `c`, in metres, from the axle centre to the controlled point, along the heading. Must be > 0.
    pub point_offset: f64,
    /// Upper bound \[m/s\] on the norm of the reference velocity `v* (cos phi*, sin phi*)`.
    pub max_reference_speed: f64,
    /// Under a neighbour graph, the points between which a pair's distance and direction are
    /// measured (see the module documentation). The paper's all-pairs law always uses the offset
    /// points.
    pub graph_pair_points: PairPoints,
    /// Share `beta` (in (0, 1]) of the wheel acceleration limit `a` that the formation velocity
    /// may spend braking ([`braking_speed`]); without a limit it plays no part. Over 200 runs of
    /// `teams-generalist` at 1.0 m/s² with the team gain 1.0 and 0.25, strict success at 10 % is
    /// 100 / 99.5 / 98.5 / 98.5 / 97 / 92.5 % at N = 5 / 8 / 13 / 16 / 24 / 32 (the gains capped at
    /// 0.2 s/m² × a before: 100 / 100 / 98 / 94 / 88 / 80 %); most failures left up to 24 robots
    /// are teams split into well-formed sub-teams (`ACCEL=1.0 cargo run -p formation-expert
    /// --example expert_accel -- scenarios/teams-generalist.toml 200 5 8 13 16 24 32`). Other
    /// shares, at 1.0 m/s² (30 runs of 16 / 24 / 32 robots unless said): 0.15: 100 / 100 / 93 %;
    /// 0.2: 100 / 100 / 90 % (over 200 runs, 96.5 / 91 % at N = 24 / 32); 0.3: 100 / 100 / 93 %
    /// (over 200 runs, 97 / 89.5 % at N = 24 / 32); 0.4: 80 % at N = 32 over 200 runs (the limit
    /// binds again in the last 20 s); 1.0: 27 % at N = 16, 13 % at N = 32 (the team weaves)
    /// (`GAINS='{"braking_share": 0.3}'`). Other limits, 50 runs of 5 / 16 / 32 robots, against the
    /// capped gains: 98 / 94 / 90 % against 100 / 90 / 70 % at 0.5 m/s² (`ACCEL=0.5`), 100 / 100 /
    /// 98 % against 100 / 100 / 90 % at 2.0 m/s².
    pub braking_share: f64,
    /// The wheel acceleration limit \[m/s²\] the formation velocity is shaped for
    /// ([`braking_speed`]) whatever the robot's own limit; `None` (the default) shapes for the
    /// robot's own `max_wheel_accel`, and not at all without one. Training data set it so that
    /// the labels are one function of what a robot senses: a robot's limit is not in its image,
    /// and labels shaped for each run's own limit would ask different commands of the same image
    /// (`formation collect|dagger --label-wheel-accel`).
    pub shaping_wheel_accel: Option<f64>,
    /// Under a Gabriel neighbour rule, the witness-ratio band `[low, high]` over which a pair's
    /// weight rises smoothly from 0 to 1 ([`crate::pair_weights`]) instead of the rule's step at
    /// its threshold; `None` (the default) holds exactly the rule's pairs. For teaching: labels
    /// that are one continuous function of what a robot senses. The scored formation's edges
    /// stay the rule's.
    pub pair_weight_band: Option<[f64; 2]>,
    /// Never shape the formation velocity, whatever the robot's limit: the unlimited law's
    /// labels, for a policy that answers a formation velocity, which its agent shapes for its
    /// own wheels (`formation_perception::policy_input::shape_for_wheels`). Not with
    /// [`shaping_wheel_accel`](Self::shaping_wheel_accel).
    pub unshaped: bool,
    /// On one robot's own scan ([`crate::own_scan`]) only: a robot that stands between two of
    /// its detections which would hold each other (each among the other's `nearest`, counting
    /// the robot) but cannot see each other past its body steps aside, perpendicular to their
    /// line, with the pull their pair would feel, weighted from 1 within half a body radius of
    /// the line to 0 at one body radius. Without it a team of three can settle in a line whose
    /// end robots each see only the middle one: over table1's 100 runs the law succeeds in 93 %
    /// without it and 100 % with it; over 50 runs of 32 robots (`teams-generalist`) in 94 / 84 %
    /// (10 / 5 %) without and 94 / 86 % with. The full-view expert sees every robot and never
    /// uses it. Off by default, and absent from the gains' JSON while off.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub unblock_hidden_pairs: bool,
}

/// The points of two robots between which the expert measures their distance and direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PairPoints {
    /// The paper's: each robot's point `c` ahead of its axle, which depends on its heading.
    OffsetPoints,
    /// The robots' centres, which a neighbour's LIDAR image shows whatever its heading.
    Centres,
}

impl Default for ExpertGains {
    fn default() -> Self {
        ExpertGains {
            k_formation: 0.15,
            k_formation_graph: 1.0,
            point_offset: 0.331 / 2.0,
            max_reference_speed: formation_perception::policy_input::MAX_REFERENCE_SPEED,
            graph_pair_points: PairPoints::Centres,
            braking_share: 0.25,
            shaping_wheel_accel: None,
            pair_weight_band: None,
            unshaped: false,
            unblock_hidden_pairs: false,
        }
    }
}

/// Gains that cannot drive a robot.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("expert gain {field} = {value} is invalid: it must be {requirement}")]
pub struct InvalidGains {
    /// The offending field of [`ExpertGains`].
    pub field: &'static str,
    /// Its value.
    pub value: f64,
    /// What it must be instead.
    pub requirement: &'static str,
}

impl ExpertGains {
    /// Checks that every gain is finite and in range: `k_formation >= 0`,
    /// `k_formation_graph >= 0`, `0 < braking_share <= 1`, `point_offset > 0`,
    /// `max_reference_speed >= 0`, `shaping_wheel_accel` absent or `> 0`, `pair_weight_band`
    /// absent or `0 < low < high`.
    pub fn validate(&self) -> Result<(), InvalidGains> {
        let checks = [
            (
                "k_formation",
                self.k_formation,
                self.k_formation >= 0.0,
                "finite and >= 0",
            ),
            (
                "k_formation_graph",
                self.k_formation_graph,
                self.k_formation_graph >= 0.0,
                "finite and >= 0",
            ),
            (
                "braking_share",
                self.braking_share,
                self.braking_share > 0.0 && self.braking_share <= 1.0,
                "finite, > 0 and <= 1",
            ),
            (
                "point_offset",
                self.point_offset,
                self.point_offset > 0.0,
                "finite and > 0",
            ),
            (
                "max_reference_speed",
                self.max_reference_speed,
                self.max_reference_speed >= 0.0,
                "finite and >= 0",
            ),
            (
                "shaping_wheel_accel",
                self.shaping_wheel_accel.unwrap_or(1.0),
                self.shaping_wheel_accel.is_none_or(|a| a > 0.0),
                "absent, or finite and > 0",
            ),
        ];
        let band = self.pair_weight_band.unwrap_or([1.0, 2.0]);
        let band_checks = [(
            "pair_weight_band",
            band[0],
            band[0] > 0.0 && band[1].is_finite() && band[0] < band[1],
            "absent, or [low, high] with 0 < low < high, both finite",
        )];
        if self.unshaped && self.shaping_wheel_accel.is_some() {
            return Err(InvalidGains {
                field: "shaping_wheel_accel",
                value: self.shaping_wheel_accel.unwrap_or_default(),
                requirement: "absent when unshaped is true (unshaped labels are shaped by no limit)",
            });
        }
        for (field, value, in_range, requirement) in checks.into_iter().chain(band_checks) {
            if !(value.is_finite() && in_range) {
                return Err(InvalidGains {
                    field,
                    value,
                    requirement,
                });
            }
        }
        Ok(())
    }
}

/// The team gain [`ExpertGains::k_formation_graph`] under wheels that lag: a motor time constant
/// or a command latency (`[robot] motor_tau`, `command_latency`, which the robot profiles set).
/// The formation error a lagging team holds is the wheels' disturbances (speed noise, a
/// left/right gain asymmetry, a compass bias, each robot's spread) over the gain, and the
/// default 1.0 leaves about 4 % under the `pioneer-p3dx` profile, where strict success at 10 %
/// over 100 runs of table1's goals (v* = 0.7 m/s) at N = 5 / 8 / 16 is 100 / 90 / 68 % (50 runs
/// at 16). 2.0 holds it to about 3 %: 100 / 98 / 88 %. A weaker gain does worse (0.5: 71 / 61
/// % at N = 5 / 8), and 3.0 (100 / 99 / 82 %) and 4.0 (99 / 98 % at N = 5 / 8) gain nothing
/// more (`GAINS='{"k_formation_graph": 2.0}' cargo run -p formation-expert --release --example
/// expert_accel -- SCENARIO 100 5 8 16` on table1 with `[robot] profile = "pioneer-p3dx"`).
pub const LAGGED_K_FORMATION_GRAPH: f64 = 2.0;

impl ExpertGains {
    /// These gains for a world with `reality`'s models: when its wheels lag (a motor time
    /// constant or a command latency) and the team gain is the default's, the team gain
    /// [`LAGGED_K_FORMATION_GRAPH`]; otherwise (the ideal world, every scenario without a
    /// lagging profile, or a team gain set explicitly) the gains unchanged.
    pub fn for_reality(self, reality: &RealityModels) -> ExpertGains {
        let lags = reality.motors.tau_s > 0.0 || reality.command_latency_ticks > 0;
        if lags && self.k_formation_graph == ExpertGains::default().k_formation_graph {
            ExpertGains {
                k_formation_graph: LAGGED_K_FORMATION_GRAPH,
                ..self
            }
        } else {
            self
        }
    }

    /// The labelling law these gains give (what a dataset records of them): the shaping, the
    /// pair weights and the own-scan law's step aside (whether labels come from each robot's own
    /// scan, [`LabelLaw::own_scan`], is the labeller's, not the gains').
    pub fn label_law(&self) -> LabelLaw {
        LabelLaw {
            shaping_wheel_accel: self.shaping_wheel_accel,
            unshaped: self.unshaped,
            pair_weight_band: self.pair_weight_band,
            unblock_hidden_pairs: self.unblock_hidden_pairs,
            ..LabelLaw::default()
        }
    }

    /// These gains labelling by `law` (a dataset's recorded law), every other gain unchanged
    /// ([`LabelLaw::own_scan`] is not a gain: the labeller takes it).
    pub fn with_label_law(self, law: LabelLaw) -> ExpertGains {
        ExpertGains {
            shaping_wheel_accel: law.shaping_wheel_accel,
            unshaped: law.unshaped,
            pair_weight_band: law.pair_weight_band,
            unblock_hidden_pairs: law.unblock_hidden_pairs,
            ..self
        }
    }
}

/// The expert's wheel command for every robot, written to `out[i]` for `poses[i]`.
///
/// Every pair of robots is a formation edge (the paper's complete graph). The formation gain is
/// [`ExpertGains::k_formation`]; when `robot` has an acceleration limit the formation velocity
/// is shaped by [`braking_speed`]. Non-finite poses or goal
/// values give non-finite commands, which the world brakes; [`ExpertController`] refuses them up front.
///
/// # Panics
///
/// If `out.len() != poses.len()`.
pub fn expert_commands(
    poses: &[Pose],
    goal: &Goal,
    gains: &ExpertGains,
    robot: &RobotParams,
    out: &mut [WheelCmd],
) {
    assert_eq!(out.len(), poses.len(), "one output command per robot");
    let n = poses.len();
    commands_among(
        poses,
        goal,
        gains,
        PairPoints::OffsetPoints,
        robot,
        out,
        |i| (0..n).filter(move |&j| j != i).map(|j| (j, 1.0)),
    );
}

/// The expert's wheel command for every robot when robot `i` holds only its own neighbours under
/// `tracker`'s rule, at the sample the tracker last saw (which must be `poses`), with the formation
/// gain [`ExpertGains::k_formation_graph`] (shaped under an acceleration limit by
/// [`braking_speed`]) and pairs measured between
/// [`ExpertGains::graph_pair_points`].
///
/// # Panics
///
/// If `out.len() != poses.len()`.
pub fn expert_commands_among(
    poses: &[Pose],
    goal: &Goal,
    gains: &ExpertGains,
    robot: &RobotParams,
    tracker: &NeighbourTracker,
    out: &mut [WheelCmd],
) {
    graph_commands(poses, goal, gains, robot, out, |i| {
        tracker
            .own_neighbours(i)
            .iter()
            .copied()
            .filter(|&j| j < poses.len())
            .map(|j| (j, 1.0))
    });
}

/// The expert's wheel command for every robot when robot `i` holds each robot `j` of
/// `neighbours[i]` with its weight (`(j, w)`, [`crate::pair_weights`]), with the formation gain
/// [`ExpertGains::k_formation_graph`] (shaped under an acceleration limit by [`braking_speed`])
/// and pairs measured between [`ExpertGains::graph_pair_points`].
///
/// # Panics
///
/// If `out.len() != poses.len()` or `neighbours.len() < poses.len()`.
pub fn expert_commands_weighted(
    poses: &[Pose],
    goal: &Goal,
    gains: &ExpertGains,
    robot: &RobotParams,
    neighbours: &[WeightedNeighbours],
    out: &mut [WheelCmd],
) {
    graph_commands(poses, goal, gains, robot, out, |i| {
        neighbours[i]
            .iter()
            .copied()
            .filter(|&(j, _)| j < poses.len())
    });
}

/// The law under a neighbour graph: the team gain [`ExpertGains::k_formation_graph`], pairs
/// measured between [`ExpertGains::graph_pair_points`], robot `i` holding `neighbours(i)`.
fn graph_commands<I: Iterator<Item = (usize, f64)>>(
    poses: &[Pose],
    goal: &Goal,
    gains: &ExpertGains,
    robot: &RobotParams,
    out: &mut [WheelCmd],
    neighbours: impl Fn(usize) -> I,
) {
    assert_eq!(out.len(), poses.len(), "one output command per robot");
    let gains = ExpertGains {
        k_formation: gains.k_formation_graph,
        ..*gains
    };
    commands_among(
        poses,
        goal,
        &gains,
        gains.graph_pair_points,
        robot,
        out,
        neighbours,
    );
}

/// The distance law of robot `i` summed over `neighbours(i)` (each `(j, weight)`), in the
/// order given, each pair measured between `pair_points`.
fn commands_among<I: Iterator<Item = (usize, f64)>>(
    poses: &[Pose],
    goal: &Goal,
    gains: &ExpertGains,
    pair_points: PairPoints,
    robot: &RobotParams,
    out: &mut [WheelCmd],
    neighbours: impl Fn(usize) -> I,
) {
    let c = gains.point_offset;
    let offset_point = |pose: &Pose| (pose.x + c * pose.theta.cos(), pose.y + c * pose.theta.sin());
    let reference = reference_velocity(goal, gains.max_reference_speed);
    let d4 = goal.d_star.powi(4);

    for (i, (pose, cmd)) in poses.iter().zip(out.iter_mut()).enumerate() {
        let p_i = offset_point(pose);
        let mut gradient = (0.0, 0.0);
        for (j, weight) in neighbours(i) {
            let pair = match pair_points {
                PairPoints::OffsetPoints => {
                    let p_j = offset_point(&poses[j]);
                    (p_i.0 - p_j.0, p_i.1 - p_j.1)
                }
                PairPoints::Centres => (pose.x - poses[j].x, pose.y - poses[j].y),
            };
            add_pair_term(&mut gradient, pair, d4, weight);
        }
        *cmd = command_from_gradient(gradient, pose.theta, reference, gains, robot);
    }
}

/// Adds to `gradient` pair `p_ij = (dx, dy)`'s term `weight * tau_ij`, the gradient of its
/// potential (`d4 = d*^4`); a pair closer than [`MIN_PAIR_DISTANCE`] adds nothing. The one pair
/// law, whether the pair comes from two poses or from one robot's detection
/// ([`crate::own_scan`]).
pub(crate) fn add_pair_term(gradient: &mut (f64, f64), (dx, dy): (f64, f64), d4: f64, weight: f64) {
    let r = dx.hypot(dy);
    if r < MIN_PAIR_DISTANCE {
        return;
    }
    // tau_ij = 2 (r^4 - d*^4) / r^3 * p_ij / r
    let magnitude = weight * 2.0 * (r.powi(4) - d4) / r.powi(3);
    gradient.0 += magnitude * dx / r;
    gradient.1 += magnitude * dy / r;
}

/// One robot's wheel command from the summed gradient of its pair potentials (world frame), its
/// heading `theta` and the reference velocity: the formation velocity `-K gradient` with
/// `K = gains.k_formation`, shaped under an acceleration limit ([`braking_speed`]), plus the
/// reference, turned into wheel speeds at the point `c` ahead of the axle and saturated. The one
/// law after the pairs, whether they come from every pose or from one robot's detections
/// ([`crate::own_scan`]).
pub(crate) fn command_from_gradient(
    gradient: (f64, f64),
    theta: f64,
    reference: (f64, f64),
    gains: &ExpertGains,
    robot: &RobotParams,
) -> WheelCmd {
    let k_formation = gains.k_formation;
    let mut f = (-k_formation * gradient.0, -k_formation * gradient.1);
    let shaping_accel = gains.shaping_wheel_accel.or(robot.max_wheel_accel);
    if let Some(accel) = shaping_accel.filter(|_| !gains.unshaped) {
        let speed = f.0.hypot(f.1);
        if speed > 0.0 {
            let scale = braking_speed(speed, k_formation, gains.braking_share * accel) / speed;
            f = (f.0 * scale, f.1 * scale);
        }
    }
    let u = (reference.0 + f.0, reference.1 + f.1);
    point_velocity_to_wheels(u, theta, gains.point_offset, robot)
}

/// The expert's shaping under an acceleration limit, defined once beside the policies' own
/// (`formation_perception::policy_input`), since an agent whose policy answers a formation
/// velocity shapes it the same way for its own wheels.
pub use formation_perception::policy_input::braking_speed;

/// `v* (cos phi*, sin phi*)` with its norm capped at `max_speed`.
pub(crate) fn reference_velocity(goal: &Goal, max_speed: f64) -> (f64, f64) {
    let speed = goal.v_star.clamp(-max_speed, max_speed);
    (speed * goal.phi_star.cos(), speed * goal.phi_star.sin())
}

/// Inverts the point-offset kinematics: the wheel speeds that move the point `c` ahead of the axle at
/// velocity `u`, then scaled by one common factor into the wheel limit.
fn point_velocity_to_wheels(u: (f64, f64), theta: f64, c: f64, robot: &RobotParams) -> WheelCmd {
    let (sin, cos) = theta.sin_cos();
    let v = cos * u.0 + sin * u.1;
    let omega = (-sin * u.0 + cos * u.1) / c;
    let half_track = robot.wheel_separation / 2.0;
    // Both wheels scaled by one factor into the limit: the one saturation, which an agent
    // applies to its policy's formation velocity too.
    saturate_together(
        WheelCmd {
            left: v - half_track * omega,
            right: v + half_track * omega,
        },
        robot.max_wheel_speed,
    )
}

/// The expert as a [`Controller`]: reads the ground-truth poses and the goal of each observation.
///
/// Under a neighbour rule with hysteresis it remembers the last tick's neighbours; an observation
/// at tick 0, or one that does not follow the last (another run), starts afresh.
#[derive(Debug, Clone)]
pub struct ExpertController {
    gains: ExpertGains,
    robot: RobotParams,
    neighbours: NeighbourRule,
    tracker: Option<NeighbourTracker>,
    next_tick: Option<u64>,
    positions: Vec<(f64, f64)>,
    weighted: Vec<WeightedNeighbours>,
}

impl ExpertController {
    /// An expert with these gains for the robots of `world`, its gains fitted to the world's
    /// reality models ([`ExpertGains::for_reality`]), holding every pair;
    /// [`with_neighbours`](Self::with_neighbours) sets another rule. The same as
    /// [`new`](Self::new) in a world without a lagging robot profile.
    pub fn for_world(gains: ExpertGains, world: &WorldConfig) -> ExpertController {
        ExpertController::new(gains.for_reality(&world.reality), world.robot)
    }

    /// An expert with these gains for robots with these parameters, holding every pair (the
    /// paper's formation); [`with_neighbours`](Self::with_neighbours) sets another rule.
    pub fn new(gains: ExpertGains, robot: RobotParams) -> ExpertController {
        ExpertController {
            gains,
            robot,
            neighbours: NeighbourRule::AllPairs,
            tracker: None,
            next_tick: None,
            positions: Vec::new(),
            weighted: Vec::new(),
        }
    }

    /// The same expert holding each robot's own neighbours under `rule`.
    pub fn with_neighbours(mut self, rule: NeighbourRule) -> ExpertController {
        self.neighbours = rule;
        self.tracker = None;
        self.next_tick = None;
        self
    }

    /// The neighbour rule in use.
    pub fn neighbours(&self) -> &NeighbourRule {
        &self.neighbours
    }

    /// The expert's commands for `poses` at `tick` (no input checks: see [`Controller::commands`]).
    pub(crate) fn compute(&mut self, tick: u64, poses: &[Pose], goal: &Goal, out: &mut [WheelCmd]) {
        if self.neighbours == NeighbourRule::AllPairs {
            expert_commands(poses, goal, &self.gains, &self.robot, out);
            return;
        }
        if let (NeighbourRule::Gabriel(rule), Some(band)) =
            (self.neighbours, self.gains.pair_weight_band)
        {
            self.positions.clear();
            self.positions.extend(poses.iter().map(|p| (p.x, p.y)));
            weighted_neighbours(&self.positions, &rule, band, &mut self.weighted);
            expert_commands_weighted(poses, goal, &self.gains, &self.robot, &self.weighted, out);
            return;
        }
        let n = poses.len();
        let fresh = tick == 0 || self.next_tick != Some(tick);
        let tracker = match &mut self.tracker {
            Some(tracker) if tracker.n_robots() == n && !fresh => tracker,
            slot => slot.insert(NeighbourTracker::new(self.neighbours, n)),
        };
        self.positions.clear();
        self.positions.extend(poses.iter().map(|p| (p.x, p.y)));
        tracker.update(&self.positions);
        expert_commands_among(poses, goal, &self.gains, &self.robot, tracker, out);
        self.next_tick = Some(tick + 1);
    }

    /// The gains in use.
    pub fn gains(&self) -> &ExpertGains {
        &self.gains
    }

    /// The robot parameters in use.
    pub fn robot(&self) -> &RobotParams {
        &self.robot
    }
}

impl Controller for ExpertController {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        check_inputs(obs.poses, &obs.goal, out.len())?;
        self.gains
            .validate()
            .map_err(|e| ControllerError::new(e.to_string()))?;
        self.compute(obs.tick, obs.poses, &obs.goal, out);
        Ok(())
    }
}

/// Refuses what the expert cannot act on, naming the value.
pub(crate) fn check_inputs(
    poses: &[Pose],
    goal: &Goal,
    commands: usize,
) -> Result<(), ControllerError> {
    if commands != poses.len() {
        return Err(ControllerError::new(format!(
            "expert asked for {commands} commands but the observation has {} robots",
            poses.len()
        )));
    }
    if !(goal.d_star.is_finite() && goal.d_star > 0.0) {
        return Err(ControllerError::new(format!(
            "expert needs a finite d* > 0, got {}",
            goal.d_star
        )));
    }
    if !(goal.phi_star.is_finite() && goal.v_star.is_finite()) {
        return Err(ControllerError::new(format!(
            "expert needs a finite goal, got phi* = {}, v* = {}",
            goal.phi_star, goal.v_star
        )));
    }
    if let Some((i, pose)) = poses
        .iter()
        .enumerate()
        .find(|(_, p)| !(p.x.is_finite() && p.y.is_finite() && p.theta.is_finite()))
    {
        return Err(ControllerError::new(format!(
            "expert got a non-finite pose for robot {i}: {pose:?}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{first_tick, goal};
    use formation_proto::wrap_angle;
    use std::f64::consts::PI;

    const DT: f64 = 0.05;

    /// Three robots on an equilateral triangle of side `side`, all heading `theta`.
    fn triangle(side: f64, theta: f64) -> Vec<Pose> {
        (0..3)
            .map(|k| {
                let a = 0.4 + k as f64 * 2.0 * PI / 3.0;
                let radius = side / 3.0_f64.sqrt();
                Pose {
                    x: 1.0 + radius * a.cos(),
                    y: -2.0 + radius * a.sin(),
                    theta,
                }
            })
            .collect()
    }

    /// Unicycle step with the exact arc, so the tests need nothing from the world but its types.
    fn integrate(pose: Pose, cmd: WheelCmd, robot: &RobotParams) -> Pose {
        let v = (cmd.right + cmd.left) / 2.0;
        let omega = (cmd.right - cmd.left) / robot.wheel_separation;
        let theta = pose.theta + omega * DT;
        let (dx, dy) = if omega.abs() < 1e-12 {
            (v * DT * pose.theta.cos(), v * DT * pose.theta.sin())
        } else {
            let radius = v / omega;
            (
                radius * (theta.sin() - pose.theta.sin()),
                -radius * (theta.cos() - pose.theta.cos()),
            )
        };
        Pose::new(pose.x + dx, pose.y + dy, wrap_angle(theta))
    }

    fn step(
        poses: &mut [Pose],
        goal: &Goal,
        gains: &ExpertGains,
        robot: &RobotParams,
    ) -> Vec<WheelCmd> {
        let mut cmds = vec![WheelCmd::BRAKE; poses.len()];
        expert_commands(poses, goal, gains, robot, &mut cmds);
        for (pose, cmd) in poses.iter_mut().zip(&cmds) {
            *pose = integrate(*pose, *cmd, robot);
        }
        cmds
    }

    fn distance(a: &Pose, b: &Pose) -> f64 {
        (a.x - b.x).hypot(a.y - b.y)
    }

    /// The trainer's `--mirror` relies on this symmetry: reflecting the world about a line (here
    /// the x axis: `y -> -y`, `theta -> -theta`, `phi* -> -phi*`) reflects every robot's view, and
    /// the expert answers with the same wheel speeds, left and right swapped.
    #[test]
    fn the_expert_is_symmetric_under_reflection_with_its_wheels_swapped() {
        let (gains, robot) = (ExpertGains::default(), RobotParams::default());
        let poses: Vec<Pose> = (0..5)
            .map(|k| {
                let k = k as f64;
                Pose::new(
                    1.3 * k - 0.4 * k * k,
                    0.7 + 0.9 * (1.7 * k).sin(),
                    0.3 + 1.1 * k,
                )
            })
            .collect();
        let mirrored: Vec<Pose> = poses
            .iter()
            .map(|p| Pose::new(p.x, -p.y, -p.theta))
            .collect();
        let (mut wheels, mut mirror_wheels) =
            (vec![WheelCmd::default(); 5], vec![WheelCmd::default(); 5]);
        expert_commands(&poses, &goal(0.8, 1.4), &gains, &robot, &mut wheels);
        expert_commands(
            &mirrored,
            &goal(-0.8, 1.4),
            &gains,
            &robot,
            &mut mirror_wheels,
        );
        for (i, (a, b)) in wheels.iter().zip(&mirror_wheels).enumerate() {
            assert!(a.left != a.right, "robot {i} turns, so the swap is visible");
            assert!(
                (a.left - b.right).abs() < 1e-12 && (a.right - b.left).abs() < 1e-12,
                "robot {i}: {a:?} vs {b:?}"
            );
        }
    }

    #[test]
    fn a_team_in_formation_drives_straight_at_v_star_and_stays_in_formation() {
        let (gains, robot) = (ExpertGains::default(), RobotParams::default());
        for (d_star, phi) in [(1.0, 0.0), (1.5, 2.0), (2.0, -2.5)] {
            let g = goal(phi, d_star);
            let mut poses = triangle(d_star, phi);
            let mut cmds = vec![WheelCmd::BRAKE; 3];
            expert_commands(&poses, &g, &gains, &robot, &mut cmds);
            for cmd in &cmds {
                assert!(
                    (cmd.left - 0.7).abs() < 1e-9 && (cmd.right - 0.7).abs() < 1e-9,
                    "{cmd:?}"
                );
            }
            for _ in 0..200 {
                step(&mut poses, &g, &gains, &robot);
            }
            for (i, j) in [(0, 1), (0, 2), (1, 2)] {
                let error = (distance(&poses[i], &poses[j]) - d_star).abs() / d_star;
                assert!(error < 0.01, "pair ({i},{j}) error {error} at d* {d_star}");
            }
            assert!(poses.iter().all(|p| wrap_angle(p.theta - phi).abs() < 0.01));
        }
    }

    #[test]
    fn wheel_limits_hold_for_extreme_inputs() {
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let cases = [
            vec![
                Pose::new(0.0, 0.0, 0.0),
                Pose::new(500.0, 10.0, 3.0),
                Pose::new(-80.0, 900.0, -1.0),
            ],
            vec![Pose::new(0.0, 0.0, 1.0), Pose::new(0.01, 0.0, 1.0)],
        ];
        for poses in cases {
            let mut cmds = vec![WheelCmd::BRAKE; poses.len()];
            expert_commands(&poses, &goal(1.0, 2.0), &gains, &robot, &mut cmds);
            for cmd in &cmds {
                assert!(cmd.is_finite(), "{cmd:?}");
                let largest = cmd.left.abs().max(cmd.right.abs());
                assert!(largest <= robot.max_wheel_speed + 1e-12, "{cmd:?}");
                assert!(
                    largest > 0.5 * robot.max_wheel_speed,
                    "far from the goal, a wheel runs near its limit"
                );
            }
        }
    }

    #[test]
    fn saturation_keeps_the_ratio_of_the_wheels() {
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let poses = [Pose::new(0.0, 0.0, 0.3), Pose::new(40.0, 25.0, 0.0)];
        let u = {
            // What robot 0 asks for before saturation, recomputed from the published formulas.
            let c = gains.point_offset;
            let p0 = (c * 0.3_f64.cos(), c * 0.3_f64.sin());
            let (dx, dy) = (p0.0 - (40.0 + c), p0.1 - 25.0);
            let r = dx.hypot(dy);
            let m = 2.0 * (r.powi(4) - 1.5_f64.powi(4)) / r.powi(3);
            let g = goal(0.0, 1.5);
            (
                0.7 * g.phi_star.cos() - gains.k_formation * m * dx / r,
                0.7 * g.phi_star.sin() - gains.k_formation * m * dy / r,
            )
        };
        let (sin, cos) = 0.3_f64.sin_cos();
        let v = cos * u.0 + sin * u.1;
        let omega = (-sin * u.0 + cos * u.1) / gains.point_offset;
        let raw = WheelCmd {
            left: v - robot.wheel_separation / 2.0 * omega,
            right: v + robot.wheel_separation / 2.0 * omega,
        };
        assert!(
            raw.left.abs().max(raw.right.abs()) > robot.max_wheel_speed,
            "the case must saturate"
        );

        let mut cmds = [WheelCmd::BRAKE; 2];
        expert_commands(&poses, &goal(0.0, 1.5), &gains, &robot, &mut cmds);
        let cmd = cmds[0];
        assert!((cmd.left.abs().max(cmd.right.abs()) - robot.max_wheel_speed).abs() < 1e-12);
        assert!(
            (cmd.left / cmd.right - raw.left / raw.right).abs() < 1e-9,
            "{cmd:?} vs {raw:?}"
        );
    }

    #[test]
    fn robots_too_close_are_pushed_apart() {
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let g = goal(0.0, 2.0);
        // Side by side, 0.6 m apart, both heading along phi*.
        let mut poses = vec![Pose::new(0.0, 0.0, 0.0), Pose::new(0.0, 0.6, 0.0)];
        let start = distance(&poses[0], &poses[1]);
        let mut previous = start;
        for _ in 0..10 {
            step(&mut poses, &g, &gains, &robot);
            let now = distance(&poses[0], &poses[1]);
            assert!(now > previous, "distance fell from {previous} to {now}");
            previous = now;
        }
        assert!(
            previous > start + 0.05,
            "pushed apart by only {} m",
            previous - start
        );
    }

    #[test]
    fn a_scattered_team_converges_to_the_formation() {
        let (gains, robot) = (ExpertGains::default(), RobotParams::default());
        let g = goal(2.5, 1.5);
        let mut poses = vec![
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(2.0, 1.0, 3.0),
            Pose::new(-1.0, 2.5, -1.5),
        ];
        for _ in 0..(30.0 / DT) as usize {
            step(&mut poses, &g, &gains, &robot);
        }
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let error = (distance(&poses[i], &poses[j]) - 1.5).abs() / 1.5;
            assert!(error < 0.01, "pair ({i},{j}) error {error}");
        }
    }

    /// What `expert` says refusing `obs`.
    fn refusal(
        expert: &mut ExpertController,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> String {
        expert.commands(obs, out).unwrap_err().message
    }

    #[test]
    fn the_controller_refuses_bad_inputs_and_gains() {
        let poses = triangle(1.0, 0.0);
        let scans: Vec<Vec<f32>> = vec![Vec::new(); 3];
        let mut expert = ExpertController::new(ExpertGains::default(), RobotParams::default());
        let mut out = vec![WheelCmd::BRAKE; 3];
        let bad_goal = first_tick(goal(0.0, 0.0), &poses, &scans);
        let refused = refusal(&mut expert, &bad_goal, &mut out);
        assert!(refused.contains("d*"), "{refused}");
        let ok = Observation {
            goal: goal(0.0, 1.0),
            ..bad_goal
        };
        assert!(expert.commands(&ok, &mut out[..2]).is_err());
        let mut nan_poses = poses.clone();
        nan_poses[2].x = f64::NAN;
        let nan = Observation {
            poses: &nan_poses,
            ..ok
        };
        let refused = refusal(&mut expert, &nan, &mut out);
        assert!(refused.contains("robot 2"), "{refused}");
        expert.commands(&ok, &mut out).expect("valid inputs");

        let mut bad_gains = ExpertController::new(
            ExpertGains {
                point_offset: 0.0,
                ..ExpertGains::default()
            },
            RobotParams::default(),
        );
        let err = bad_gains.commands(&ok, &mut out).unwrap_err();
        assert!(err.message.contains("point_offset"), "{err}");
    }

    fn team_scenario(robots: usize) -> formation_world::Scenario {
        let text = format!(
            "name = \"team\"\nrobots = {robots}\nduration_s = 60.0\nseed = 7\nruns = 3\n\
             [goal]\nv_star = 0.7\nd_star_choices = [1.0, 1.5, 2.0]\n[heading]\nschedule = \"random\"\n"
        );
        formation_world::Scenario::from_toml_str(&text, "team").expect("valid scenario")
    }

    #[test]
    fn a_team_robot_holds_only_its_own_neighbours() {
        use formation_world::neighbours::{GabrielRule, NeighbourRule};
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(5.0));
        let gains = ExpertGains::default();
        let robot = RobotParams::default();
        // Three robots in a row, 1.5 m apart, and a fourth far beyond everyone's range.
        let mut poses: Vec<Pose> = (0..3)
            .map(|k| Pose {
                x: 1.5 * k as f64,
                y: 0.0,
                theta: 0.3,
            })
            .collect();
        let g = goal(0.3, 2.0);
        let mut expert = ExpertController::new(gains, robot).with_neighbours(rule);
        let mut out = vec![WheelCmd::BRAKE; 3];
        let observe = |expert: &mut ExpertController, poses: &[Pose], out: &mut Vec<WheelCmd>| {
            out.resize(poses.len(), WheelCmd::BRAKE);
            let scans = vec![Vec::new(); poses.len()];
            let obs = first_tick(g, poses, &scans);
            expert.commands(&obs, out).expect("valid");
        };
        observe(&mut expert, &poses, &mut out);
        let near = out.clone();
        poses.push(Pose::new(40.0, 0.0, 0.0));
        observe(&mut expert, &poses, &mut out);
        assert_eq!(&out[..3], &near[..], "a robot out of range changes nothing");
        // The end robots' 2 nearest include each other (3 m apart), so all three hold every
        // pair here: the same command as the paper's all-pairs law with the team gain.
        let team_gains = ExpertGains {
            k_formation: gains.k_formation_graph,
            ..gains
        };
        let mut all_pairs = vec![WheelCmd::BRAKE; 3];
        expert_commands(&poses[..3], &g, &team_gains, &robot, &mut all_pairs);
        assert_eq!(near, all_pairs);
        // The far robot, alone, only follows the reference.
        let mut alone = vec![WheelCmd::BRAKE; 1];
        expert_commands(&poses[3..], &g, &team_gains, &robot, &mut alone);
        assert_eq!(out[3], alone[0]);
    }

    #[test]
    fn under_a_neighbour_graph_a_neighbours_heading_changes_nothing_unless_offset_points_are_asked_for()
     {
        use formation_world::neighbours::{GabrielRule, NeighbourRule, NeighbourTracker};
        let robot = RobotParams::default();
        let g = goal(0.3, 1.5);
        let poses = vec![
            Pose::new(0.0, 0.0, 0.3),
            Pose::new(1.2, 0.4, -0.8),
            Pose::new(0.3, 1.6, 2.0),
        ];
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(5.0));
        let mut tracker = NeighbourTracker::new(rule, 3);
        let positions: Vec<(f64, f64)> = poses.iter().map(|p| (p.x, p.y)).collect();
        tracker.update(&positions);
        let commands = |gains: &ExpertGains, poses: &[Pose]| {
            let mut out = vec![WheelCmd::BRAKE; 3];
            expert_commands_among(poses, &g, gains, &robot, &tracker, &mut out);
            out
        };
        // Robots 1 and 2 turn on the spot: their centres stay where they are.
        let mut turned = poses.clone();
        turned[1].theta += 1.1;
        turned[2].theta -= 0.7;
        let centres = ExpertGains::default();
        assert_eq!(centres.graph_pair_points, PairPoints::Centres);
        assert_eq!(
            commands(&centres, &poses)[0],
            commands(&centres, &turned)[0],
            "robot 0's command depends only on what its LIDAR shows"
        );
        let offsets = ExpertGains {
            graph_pair_points: PairPoints::OffsetPoints,
            ..centres
        };
        assert_ne!(
            commands(&offsets, &poses)[0],
            commands(&offsets, &turned)[0],
            "the paper's offset points move with the neighbours' headings"
        );
        // With every heading equal the two laws agree (up to rounding).
        let aligned: Vec<Pose> = poses.iter().map(|p| Pose { theta: 0.3, ..*p }).collect();
        for (a, b) in commands(&centres, &aligned)
            .iter()
            .zip(commands(&offsets, &aligned))
        {
            assert!((a.left - b.left).abs() < 1e-12 && (a.right - b.right).abs() < 1e-12);
        }
    }

    #[test]
    fn teams_of_five_and_eight_form_under_the_gabriel_rule() {
        teams_of_five_and_eight_form_with(ExpertGains::default());
    }

    #[test]
    fn an_agent_shapes_a_formation_velocity_with_the_experts_own_gains() {
        use formation_perception::policy_input::{SHAPING_BRAKING_SHARE, SHAPING_GAIN};
        let gains = ExpertGains::default();
        assert_eq!(gains.k_formation_graph, SHAPING_GAIN);
        assert_eq!(gains.braking_share, SHAPING_BRAKING_SHARE);
        // Unshaped labels under a limit are the unlimited law's; refused beside a fixed limit.
        let robot = RobotParams {
            max_wheel_accel: Some(1.0),
            ..RobotParams::default()
        };
        let poses = triangle(1.3, 0.2);
        let unshaped = ExpertGains {
            unshaped: true,
            ..gains
        };
        let (mut a, mut b) = (vec![WheelCmd::default(); 3], vec![WheelCmd::default(); 3]);
        expert_commands(&poses, &goal(0.1, 1.0), &unshaped, &robot, &mut a);
        expert_commands(
            &poses,
            &goal(0.1, 1.0),
            &gains,
            &RobotParams::default(),
            &mut b,
        );
        assert_eq!(a, b);
        let both = ExpertGains {
            shaping_wheel_accel: Some(1.0),
            ..unshaped
        };
        assert_eq!(both.validate().unwrap_err().field, "shaping_wheel_accel");
    }

    #[test]
    fn teams_of_five_and_eight_form_with_smooth_pair_weights() {
        teams_of_five_and_eight_form_with(ExpertGains {
            pair_weight_band: Some([1.1, 1.5]),
            ..ExpertGains::default()
        });
    }

    #[test]
    fn smooth_pair_weights_give_the_hard_rules_command_far_from_the_band() {
        use formation_world::neighbours::GabrielRule;
        // A triangular lattice patch: every pair in range has witness ratio 2 (an edge, weight
        // 1) or at most 1 (no edge, weight 0), so both laws hold the same pairs.
        // Robot 4 below the lattice's edge 0-1 gives that pair witness ratio
        // 2 (0.25 + 0.35) = 1.2: no edge under the hard rule (threshold 1.3), weight
        // smoothstep(0.25) = 0.156 under the band [1.1, 1.5]. Pair 0-1 is neither robot's nearest.
        let poses: Vec<Pose> = [
            (0.0, 0.0),
            (1.0, 0.0),
            (0.5, 0.866),
            (1.5, 0.866),
            (0.5, -0.35_f64.sqrt()),
        ]
        .iter()
        .map(|&(x, y)| Pose { x, y, theta: 0.3 })
        .collect();
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(5.0));
        let robot = RobotParams::default();
        let band = [1.1, 1.5];
        let mut hard = ExpertController::new(ExpertGains::default(), robot).with_neighbours(rule);
        let mut smooth = ExpertController::new(
            ExpertGains {
                pair_weight_band: Some(band),
                ..ExpertGains::default()
            },
            robot,
        )
        .with_neighbours(rule);
        // d* = 1.2, so that a pair 1 m apart pulls.
        let goal = goal(0.0, 1.2);
        let (mut a, mut b) = (vec![WheelCmd::default(); 5], vec![WheelCmd::default(); 5]);
        // The lattice alone: every pair's witness ratio is 2 (an edge) or at most 1 (none), far
        // from the band, so both laws hold the same pairs with weight 1.
        hard.compute(0, &poses[..4], &goal, &mut a[..4]);
        smooth.compute(0, &poses[..4], &goal, &mut b[..4]);
        for (x, y) in a[..4].iter().zip(&b[..4]) {
            assert!((x.left - y.left).abs() < 1e-12 && (x.right - y.right).abs() < 1e-12);
        }
        // With robot 4, the smooth law holds pair 0-1 partly: robot 0's command changes, and
        // robot 3, whose pairs are all far from the band, keeps the hard law's.
        hard.compute(0, &poses, &goal, &mut a);
        smooth.compute(0, &poses, &goal, &mut b);
        assert!((a[0].left - b[0].left).abs() + (a[0].right - b[0].right).abs() > 1e-6);
        assert!((a[3].left - b[3].left).abs() < 1e-12 && (a[3].right - b[3].right).abs() < 1e-12);
        let weight = crate::pair_weights::pair_weight(1.2, band);
        assert!((weight - 0.15625).abs() < 1e-9, "{weight}");
        // A pair held at weight w adds w times its term: with slow goals, where no wheel
        // saturates, the wheel map is affine in the formation velocity.
        let slow = Goal {
            phi_star: 0.0,
            d_star: 1.05,
            v_star: 0.1,
        };
        let gains = ExpertGains::default();
        let command = |neighbours: Vec<(usize, f64)>| {
            let mut out = vec![WheelCmd::default(); 2];
            expert_commands_weighted(
                &poses[..2],
                &slow,
                &gains,
                &robot,
                &[neighbours, Vec::new()],
                &mut out,
            );
            out[0]
        };
        let (none, full, part) = (
            command(Vec::new()),
            command(vec![(1, 1.0)]),
            command(vec![(1, weight)]),
        );
        assert!((full.left - none.left).abs() > 1e-3, "{full:?} {none:?}");
        assert!((part.left - none.left - weight * (full.left - none.left)).abs() < 1e-12);
        assert!((part.right - none.right - weight * (full.right - none.right)).abs() < 1e-12);
    }

    /// Above the reference cap, an agent adding its reference term to a formation velocity
    /// drives as the expert does: a robot alone (no correction) gets the expert's command from
    /// `formation_velocity_to_wheels`, at goal speeds below, at and above the cap.
    #[test]
    fn the_agents_reference_term_is_the_experts_at_every_goal_speed() {
        use formation_perception::policy_input::{
            MAX_REFERENCE_SPEED, formation_velocity_to_wheels,
        };
        let (gains, robot) = (ExpertGains::default(), RobotParams::default());
        assert_eq!(gains.max_reference_speed, MAX_REFERENCE_SPEED);
        let pose = Pose::new(1.0, -2.0, 0.3);
        for v_star in [0.3, MAX_REFERENCE_SPEED, 0.8, 1.2] {
            let goal = Goal::new(0.5, 1.5, v_star);
            let mut out = [WheelCmd::default()];
            expert_commands_weighted(&[pose], &goal, &gains, &robot, &[Vec::new()], &mut out);
            let delta_phi = formation_proto::wrap_angle(goal.phi_star - pose.theta);
            let agent =
                formation_velocity_to_wheels([0.0, 0.0], delta_phi, v_star, robot.wheel_limits());
            assert!(
                (agent.left - out[0].left).abs() < 1e-12
                    && (agent.right - out[0].right).abs() < 1e-12,
                "v* = {v_star}: agent {agent:?}, expert {:?}",
                out[0]
            );
        }
    }

    fn teams_of_five_and_eight_form_with(gains: ExpertGains) {
        use formation_world::episode::run_episode;
        use formation_world::metrics::{MetricsConfig, run_metrics};
        for robots in [5, 8] {
            let scenario = team_scenario(robots);
            assert_eq!(scenario.neighbours().name(), "gabriel");
            for run in 0..3 {
                let spec = scenario.run_spec(scenario.seed(), run);
                let mut expert =
                    ExpertController::new(gains, spec.world.robot).with_neighbours(spec.neighbours);
                let traj = run_episode(&spec, &mut expert, &mut |_, _| {}).expect("runs");
                let m = run_metrics(&traj, spec.ticks(), &MetricsConfig::default());
                assert!(
                    m.success_5 && m.collisions == 0,
                    "{robots} robots, run {run}: {m:?}"
                );
                let team = m.team.expect("team figures");
                assert!(team.connected && team.anchor_success, "{team:?}");
            }
        }
    }

    #[test]
    fn a_new_run_starts_the_neighbour_state_afresh() {
        let scenario = team_scenario(6);
        let spec = scenario.run_spec(7, 0);
        let scans = vec![Vec::new(); 6];
        let obs = |tick| Observation {
            tick,
            time: 0.0,
            goal: spec.goal_at(0.0),
            poses: &spec.initial,
            wheel_speeds: &[],
            scans: &scans,
        };
        let mut fresh = ExpertController::new(ExpertGains::default(), spec.world.robot)
            .with_neighbours(spec.neighbours);
        let mut a = vec![WheelCmd::BRAKE; 6];
        fresh.commands(&obs(0), &mut a).expect("valid");
        // Another run's history (and a tick that does not follow it) is forgotten.
        let other = scenario.run_spec(7, 1);
        let mut used = fresh.clone();
        let mut b = vec![WheelCmd::BRAKE; 6];
        for tick in 0..5 {
            let o = Observation {
                tick,
                poses: &other.initial,
                ..obs(tick)
            };
            used.commands(&o, &mut b).expect("valid");
        }
        used.commands(&obs(0), &mut b).expect("valid");
        assert_eq!(a, b);
    }

    #[test]
    fn the_braking_speed_is_the_law_near_the_formation_and_bounded_far_from_it() {
        // Small speeds pass almost unchanged, to first order 1 - k v / (4 b).
        let (k, b) = (1.0, 0.25);
        let small = braking_speed(1e-4, k, b);
        assert!(
            (small / 1e-4 - (1.0 - 8.0 * 1e-4 / (4.0 * b))).abs() < 1e-6,
            "{small}"
        );
        // Large ones approach sqrt(2 b v / k_eff) from below.
        for v in [0.5, 2.0, 10.0] {
            let bound = (2.0 * b * v / 8.0_f64).sqrt();
            let shaped = braking_speed(v, k, b);
            assert!(shaped < bound && shaped < v, "{v}: {shaped} vs {bound}");
        }
        assert!(
            (braking_speed(100.0, k, b) / (2.0 * b * 100.0 / 8.0_f64).sqrt() - 1.0).abs() < 0.01
        );
        // Monotone, so a robot asked for more still moves faster; no gain, no shaping.
        let speeds: Vec<f64> = (1..200)
            .map(|i| braking_speed(0.01 * i as f64, k, b))
            .collect();
        assert!(speeds.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(braking_speed(0.3, 0.0, b), 0.3);
    }

    #[test]
    fn an_acceleration_limit_shapes_the_formation_velocity_and_nothing_else() {
        let gains = ExpertGains::default();
        let free = RobotParams::default();
        let limited = |accel| RobotParams {
            max_wheel_accel: Some(accel),
            ..free
        };
        let poses: Vec<Pose> = (0..4)
            .map(|k| {
                let k = k as f64;
                Pose::new(1.1 * k, 0.4 * k * k - 0.5, 0.7 * k - 1.0)
            })
            .collect();
        let g = goal(0.4, 1.2);
        let run = |gains: &ExpertGains, robot: &RobotParams| {
            let mut out = vec![WheelCmd::BRAKE; poses.len()];
            expert_commands(&poses, &g, gains, robot, &mut out);
            out
        };
        // A limit changes the command, a looser one less; a very loose one almost not at all.
        let error = |a: &[WheelCmd], b: &[WheelCmd]| {
            a.iter()
                .zip(b)
                .map(|(a, b)| (a.left - b.left).abs().max((a.right - b.right).abs()))
                .fold(0.0, f64::max)
        };
        let unlimited = run(&gains, &free);
        let tight = error(&run(&gains, &limited(0.5)), &unlimited);
        let loose = error(&run(&gains, &limited(5.0)), &unlimited);
        assert!(tight > loose && loose > 0.0, "{tight} {loose}");
        assert!(error(&run(&gains, &limited(1e9)), &unlimited) < 1e-6);
        // Without a reference the shaped command points the same way as the law's: each robot's
        // formation velocity is only scaled, by braking_speed.
        let still = Goal { v_star: 0.0, ..g };
        let mut shaped = vec![WheelCmd::BRAKE; poses.len()];
        let mut law = vec![WheelCmd::BRAKE; poses.len()];
        let slow = RobotParams {
            max_wheel_speed: 1e6,
            ..limited(1.0)
        };
        let fast = RobotParams {
            max_wheel_speed: 1e6,
            ..free
        };
        expert_commands(&poses, &still, &gains, &slow, &mut shaped);
        expert_commands(&poses, &still, &gains, &fast, &mut law);
        for (s, l) in shaped.iter().zip(&law) {
            let (s_norm, l_norm) = (s.left.hypot(s.right), l.left.hypot(l.right));
            assert!((s.left * l.right - s.right * l.left).abs() < 1e-9 * s_norm * l_norm);
            assert!(s.left * l.left + s.right * l.right > 0.0);
            assert!(s_norm < l_norm);
        }
        // The graph law too; without a limit nothing is shaped.
        use formation_world::neighbours::{GabrielRule, NeighbourRule, NeighbourTracker};
        let mut tracker = NeighbourTracker::new(
            NeighbourRule::Gabriel(GabrielRule::with_range(10.0)),
            poses.len(),
        );
        let positions: Vec<(f64, f64)> = poses.iter().map(|p| (p.x, p.y)).collect();
        tracker.update(&positions);
        let among = |gains: &ExpertGains, robot: &RobotParams| {
            let mut out = vec![WheelCmd::BRAKE; poses.len()];
            expert_commands_among(&poses, &g, gains, robot, &tracker, &mut out);
            out
        };
        assert_ne!(among(&gains, &limited(1.0)), among(&gains, &free));
        let other_share = ExpertGains {
            braking_share: 0.5,
            ..gains
        };
        assert_eq!(among(&gains, &free), among(&other_share, &free));

        for share in [0.0, 1.5, f64::NAN] {
            let bad = ExpertGains {
                braking_share: share,
                ..gains
            };
            assert_eq!(bad.validate().unwrap_err().field, "braking_share");
        }
        // A shaping limit of its own makes the labels the same whatever the robot's limit.
        let shaped_for_one = ExpertGains {
            shaping_wheel_accel: Some(1.0),
            ..gains
        };
        assert_eq!(among(&shaped_for_one, &free), among(&gains, &limited(1.0)));
        assert_eq!(
            among(&shaped_for_one, &limited(3.0)),
            among(&gains, &limited(1.0))
        );
        assert_eq!(run(&shaped_for_one, &free), run(&gains, &limited(1.0)));
        for accel in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let bad = ExpertGains {
                shaping_wheel_accel: Some(accel),
                ..gains
            };
            assert_eq!(bad.validate().unwrap_err().field, "shaping_wheel_accel");
        }
        assert!(shaped_for_one.validate().is_ok());
    }

    /// Five robots whose wheels reach at most 1 m/s²: the shaped law forms the team and holds it
    /// without the world's limit binding in the last 20 s; the same team gain shaped for braking
    /// at the whole limit (`braking_share` 1) weaves, the limit binding through much of the
    /// window and the team failing the strict check.
    #[test]
    fn a_team_of_five_under_an_acceleration_limit_converges_and_stops_straining_its_wheels() {
        use formation_world::episode::run_episode;
        use formation_world::metrics::{MetricsConfig, run_metrics};
        let text = "name = \"accel\"\nrobots = 5\nduration_s = 60.0\nseed = 7\nruns = 3\n\
                    [goal]\nv_star = 0.7\nd_star_range = [0.8, 2.5]\n[heading]\nschedule = \"random\"\n\
                    [robot]\nmax_wheel_accel = 1.0\n";
        let scenario = formation_world::Scenario::from_toml_str(text, "accel").expect("valid");
        // (success at 10 %, share of robot-ticks of the last 20 s at which the limit bound)
        let run = |gains: ExpertGains, index: usize| {
            let spec = scenario.run_spec(scenario.seed(), index);
            let mut expert =
                ExpertController::new(gains, spec.world.robot).with_neighbours(spec.neighbours);
            let mut requested: Vec<Vec<WheelCmd>> = Vec::new();
            let traj = run_episode(&spec, &mut expert, &mut |_, cmds| {
                requested.push(cmds.to_vec())
            })
            .expect("runs");
            let m = run_metrics(&traj, spec.ticks(), &MetricsConfig::default());
            let window = requested.len() - 400;
            let (mut bound, mut total) = (0, 0);
            for (req, applied) in requested[window..].iter().zip(&traj.commands[window..]) {
                for (r, a) in req.iter().zip(applied) {
                    total += 1;
                    bound += usize::from(r != a);
                }
            }
            (
                m.success_10 && m.collisions == 0,
                bound as f64 / total as f64,
            )
        };
        let whole_limit = ExpertGains {
            braking_share: 1.0,
            ..ExpertGains::default()
        };
        let mut weaves = 0;
        for index in 0..3 {
            let (success, bound) = run(ExpertGains::default(), index);
            assert!(success && bound == 0.0, "run {index}: {success}, {bound}");
            let (success, bound) = run(whole_limit, index);
            if !success && bound > 0.3 {
                weaves += 1;
            }
        }
        assert!(
            weaves >= 1,
            "braking at the whole limit was expected to weave"
        );
    }

    #[test]
    fn a_lagging_profile_raises_the_default_team_gain_and_nothing_else() {
        use formation_world::reality::RealityModels;
        use formation_world::scenario::RobotProfile;
        let default = ExpertGains::default();
        // The ideal world, and every scenario without a lagging model: the gains as they are.
        assert_eq!(default.for_reality(&RealityModels::IDEAL), default);
        for profile in [RobotProfile::Pioneer3dx, RobotProfile::Turtlebot3Burger] {
            let reality = profile.settings().reality;
            let fitted = default.for_reality(&reality);
            assert_eq!(fitted.k_formation_graph, LAGGED_K_FORMATION_GRAPH);
            assert_eq!(
                ExpertGains {
                    k_formation_graph: default.k_formation_graph,
                    ..fitted
                },
                default,
                "only the team gain changes"
            );
            // A team gain set explicitly is kept.
            let explicit = ExpertGains {
                k_formation_graph: 0.5,
                ..default
            };
            assert_eq!(explicit.for_reality(&reality), explicit);
        }
        // Latency alone lags too; a compass bias alone does not.
        let latency = RealityModels {
            command_latency_ticks: 1,
            ..RealityModels::IDEAL
        };
        assert_eq!(
            default.for_reality(&latency).k_formation_graph,
            LAGGED_K_FORMATION_GRAPH
        );
        let mut compass = RealityModels::IDEAL;
        compass.compass.bias_deg = 2.0;
        assert_eq!(default.for_reality(&compass), default);
        // The world config's expert is the fitted one.
        let world = profile_world(RobotProfile::Pioneer3dx);
        let expert = ExpertController::for_world(default, &world);
        assert_eq!(expert.gains().k_formation_graph, LAGGED_K_FORMATION_GRAPH);
    }

    fn profile_world(profile: formation_world::scenario::RobotProfile) -> WorldConfig {
        let settings = profile.settings();
        WorldConfig {
            robot: settings.robot,
            lidar: settings.lidar,
            lidar_noise: settings.lidar_noise,
            reality: settings.reality,
            ..WorldConfig::default()
        }
    }
}
