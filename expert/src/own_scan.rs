//! The expert's law on what one robot sees: its command from the neighbours it detects in its
//! own scan, its own heading and the goal, and nothing else.
//!
//! The expert ([`crate::controller`]) reads every robot's pose. This is the same law with the
//! other input a robot has:
//!
//! 1. **Detections.** The robot's own scan goes through
//!    [`formation_perception::neighbours::NeighbourDetector`], which gives each neighbour's centre
//!    in the robot's body frame (x ahead, y to the left), the robot itself at the origin.
//! 2. **The neighbour rule** is the scenario's [`NeighbourRule`], the world's rule read from the
//!    robot's side by [`own_neighbours`] (the agent's own, held equal to the world's
//!    `NeighbourTracker` by its tests): its Gabriel pairs (witness ratio at or above
//!    [`GabrielRule::threshold`](formation_proto::GabrielRule::threshold)) among the robots within
//!    sensing range, plus its `nearest` robots; with [`ExpertGains::pair_weight_band`], the same
//!    smooth weights as the expert's ([`crate::pair_weights::weighted_neighbours`]). Detections
//!    carry no identity from one scan to the next, so the rule is applied afresh at every scan:
//!    with a rule's hysteresis (none by default) an edge is kept only while its ratio stays at the
//!    threshold. Under [`NeighbourRule::AllPairs`] the robot holds every detection.
//! 3. **The pair law, the reference term and the wheels** are the expert's own
//!    (`controller::add_pair_term`, `controller::command_from_gradient`): each held neighbour
//!    adds `tau` for the pair measured between centres, summed in the body frame and turned into
//!    the world frame by the robot's heading; then the team gain
//!    ([`ExpertGains::k_formation_graph`]; the paper's [`ExpertGains::k_formation`] under all
//!    pairs), the shaping under an acceleration limit, the reference `v* (cos phi*, sin phi*)`
//!    and the saturated wheel conversion. A scan shows a neighbour's centre, not its offset point,
//!    so pairs are always measured between centres (the expert's default under a graph).
//!
//! 4. **Hidden pairs** (with [`ExpertGains::unblock_hidden_pairs`], off by default): a robot that
//!    stands between two detections which would hold each other steps aside, so that they see
//!    each other; the expert, which sees every robot, needs no such term.
//!
//! With every neighbour detected exactly, the command is the expert's (to rounding; a test holds
//! it to 1e-6 m/s). A robot that detects nobody drives the reference velocity.
//!
//! [`OwnView`] is the law on given detections (pure, keeps only scratch buffers);
//! [`OwnScanPilot`] is a [`Pilot`] that runs it on one robot's scan with its own detector, and
//! [`own_scan_team`] the in-process team of them, a [`Decentralised`] controller: robot `i` is
//! handed its own scan, heading and the goal, and nothing else.

use formation_perception::hidden_pairs::{HiddenPair, hidden_pairs};
use formation_perception::neighbour_input::own_neighbours;
use formation_perception::neighbours::{
    DetectedNeighbour, DetectorSettings, NeighbourDetector, SettingsError,
};
use formation_proto::robot::{BoxError, CheckedGoal, Decentralised, Pilot};
use formation_proto::{Goal, LidarSpec, WheelCmd, WheelLimits};
use formation_world::neighbours::NeighbourRule;
use formation_world::{RobotParams, WorldConfig};

use crate::controller::{
    ExpertGains, InvalidGains, add_pair_term, command_from_gradient, reference_velocity,
};
use crate::pair_weights::{WeightedNeighbours, weighted_neighbours};

/// The model id an own-scan pilot reports (and `formation eval --controller expert-own-scan`
/// names its rows with).
pub const OWN_SCAN_ID: &str = "expert-own-scan";

/// Why the expert's law cannot run on a robot's own scan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OwnScanError {
    /// The expert's gains are invalid.
    #[error("the expert's own-scan law: {0}")]
    Gains(#[from] InvalidGains),
    /// The neighbour detector's settings (from the robot's body radius) are unusable.
    #[error("the expert's own-scan law cannot detect neighbours: {0}")]
    Detector(#[from] SettingsError),
    /// A scan of another length than the LIDAR's beam count.
    #[error(
        "the expert's own-scan law got a scan of {got} ranges but the robot's LIDAR has {beams} \
         beams: give one range per beam"
    )]
    ScanLength {
        /// Ranges given.
        got: usize,
        /// The LIDAR's beams.
        beams: usize,
    },
    /// The heading is not finite.
    #[error("the expert's own-scan law needs a finite heading, got {0}")]
    Heading(f64),
}

/// The expert's law on one robot's detections, with the scratch buffers it needs (kept from one
/// call to the next, so that after a few calls it allocates nothing).
#[derive(Debug, Clone, Default)]
pub struct OwnView {
    /// The robot (index 0, at the origin) and its detections (index `k + 1` for detection `k`),
    /// for the smooth pair weights.
    positions: Vec<(f64, f64)>,
    weighted: Vec<WeightedNeighbours>,
    /// Scratch of [`own_neighbours`]: detections in range, nearest first.
    order: Vec<(f64, usize)>,
    /// Which detections the rule holds.
    flags: Vec<bool>,
    /// The neighbours held at the last call: `(detection index, weight)`.
    held: Vec<(usize, f64)>,
    /// The pairs of detections the robot hides from each other, with `unblock_hidden_pairs`.
    hidden: Vec<HiddenPair>,
}

impl OwnView {
    /// A view with empty buffers.
    pub fn new() -> OwnView {
        OwnView::default()
    }

    /// The wheel command of a robot heading `heading` \[rad\] that sees its neighbours' centres
    /// at `neighbours` (body frame, metres), under `goal`, by the expert's law with `gains` for a
    /// robot with `robot`'s wheels, holding the neighbours `rule` gives it (see the module
    /// documentation). The caller checks the goal and the heading; a non-finite detection is
    /// nobody's neighbour.
    pub fn command(
        &mut self,
        neighbours: &[(f64, f64)],
        heading: f64,
        goal: &Goal,
        gains: &ExpertGains,
        robot: &RobotParams,
        rule: &NeighbourRule,
    ) -> WheelCmd {
        self.hold(neighbours, rule, gains.pair_weight_band);
        let gains = match rule {
            NeighbourRule::AllPairs => *gains,
            NeighbourRule::Gabriel(_) => ExpertGains {
                k_formation: gains.k_formation_graph,
                ..*gains
            },
        };
        let d4 = goal.d_star.powi(4);
        // p_ij = p_i - p_j: from the neighbour to the robot, in the body frame.
        let mut body = (0.0, 0.0);
        for &(k, weight) in &self.held {
            let (x, y) = neighbours[k];
            add_pair_term(&mut body, (-x, -y), d4, weight);
        }
        if gains.unblock_hidden_pairs {
            // Under all pairs every two robots hold each other.
            let nearest = match rule {
                NeighbourRule::AllPairs => usize::MAX,
                NeighbourRule::Gabriel(gabriel) => gabriel.nearest,
            };
            hidden_pairs(
                neighbours,
                nearest,
                robot.body_radius,
                goal.d_star,
                &mut self.hidden,
            );
            add_unblocking_term(&mut body, &self.hidden, goal.d_star);
        }
        let (sin, cos) = heading.sin_cos();
        let world = (cos * body.0 - sin * body.1, sin * body.0 + cos * body.1);
        let reference = reference_velocity(goal, gains.max_reference_speed);
        command_from_gradient(world, heading, reference, &gains, robot)
    }

    /// The neighbours held at the last [`command`](Self::command): `(index into its
    /// neighbours, weight)`, ascending.
    pub fn held(&self) -> &[(usize, f64)] {
        &self.held
    }

    /// Applies `rule` (or its smooth weights over `band`) to the robot and `neighbours`.
    fn hold(&mut self, neighbours: &[(f64, f64)], rule: &NeighbourRule, band: Option<[f64; 2]>) {
        self.held.clear();
        let finite = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite();
        let gabriel = match rule {
            NeighbourRule::AllPairs => {
                self.held.extend(
                    (0..neighbours.len())
                        .filter(|&k| finite(&neighbours[k]))
                        .map(|k| (k, 1.0)),
                );
                return;
            }
            NeighbourRule::Gabriel(gabriel) => gabriel,
        };
        if let Some(band) = band {
            self.positions.clear();
            self.positions.push((0.0, 0.0));
            self.positions.extend_from_slice(neighbours);
            weighted_neighbours(&self.positions, gabriel, band, &mut self.weighted);
            if let Some(own) = self.weighted.first() {
                self.held.extend(own.iter().map(|&(j, w)| (j - 1, w)));
            }
            return;
        }
        // Memoryless, the world's rule read from the robot's side: detections have no identity
        // from one scan to the next.
        own_neighbours(neighbours, gabriel, &mut self.order, &mut self.flags);
        self.held.extend(
            self.flags
                .iter()
                .enumerate()
                .filter(|&(_, &held)| held)
                .map(|(k, _)| (k, 1.0)),
        );
    }
}

/// Adds to `gradient` (body frame) the step aside of a robot from the pairs it hides
/// ([`ExpertGains::unblock_hidden_pairs`], [`hidden_pairs`]): for each, a push along its `away`,
/// as strong as the pull `2 (r^4 - d*^4) / r^3` its pair would feel, times its weight.
fn add_unblocking_term(gradient: &mut (f64, f64), hidden: &[HiddenPair], d_star: f64) {
    for pair in hidden {
        let pull = pair.pull(d_star);
        gradient.0 -= pull * pair.away.0;
        gradient.1 -= pull * pair.away.1;
    }
}

/// One robot driven by the expert's law on its own scan: a [`Pilot`] with its own
/// [`NeighbourDetector`] and buffers. Its "model" is the expert's gains.
#[derive(Debug, Clone)]
pub struct OwnScanPilot {
    gains: ExpertGains,
    robot: RobotParams,
    rule: NeighbourRule,
    lidar: LidarSpec,
    detector: NeighbourDetector,
    detections: Vec<DetectedNeighbour>,
    centres: Vec<(f64, f64)>,
    view: OwnView,
}

impl OwnScanPilot {
    /// A pilot for a robot with `robot`'s body and wheels and this LIDAR, holding the
    /// neighbours `rule` gives it, with these gains (checked).
    pub fn new(
        gains: ExpertGains,
        robot: RobotParams,
        lidar: LidarSpec,
        rule: NeighbourRule,
    ) -> Result<OwnScanPilot, OwnScanError> {
        gains.validate()?;
        let detector =
            NeighbourDetector::new(DetectorSettings::with_body_radius(robot.body_radius))?;
        Ok(OwnScanPilot {
            gains,
            robot,
            rule,
            lidar,
            detector,
            detections: Vec::new(),
            centres: Vec::new(),
            view: OwnView::new(),
        })
    }

    /// The neighbours detected in the last perceived scan, nearest first.
    pub fn detections(&self) -> &[DetectedNeighbour] {
        &self.detections
    }

    /// The neighbours held at the last decision: `(index into`
    /// [`detections`](Self::detections)`, weight)`.
    pub fn held(&self) -> &[(usize, f64)] {
        self.view.held()
    }

    /// The gains in use.
    pub fn gains(&self) -> &ExpertGains {
        &self.gains
    }
}

impl Pilot for OwnScanPilot {
    type Model = ExpertGains;

    fn model_id(&self) -> &str {
        OWN_SCAN_ID
    }

    fn perceive(&mut self, ranges: &[f32], goal: &Goal) -> Result<(), BoxError> {
        CheckedGoal::new(*goal)?;
        if ranges.len() != self.lidar.beams {
            return Err(OwnScanError::ScanLength {
                got: ranges.len(),
                beams: self.lidar.beams,
            }
            .into());
        }
        self.detector
            .detect(ranges, &self.lidar, &mut self.detections);
        self.centres.clear();
        self.centres
            .extend(self.detections.iter().map(|d| (d.x, d.y)));
        Ok(())
    }

    fn decide(&mut self, heading: f64, goal: &Goal) -> Result<WheelCmd, BoxError> {
        let goal = CheckedGoal::new(*goal)?;
        if !heading.is_finite() {
            return Err(OwnScanError::Heading(heading).into());
        }
        Ok(self.view.command(
            &self.centres,
            heading,
            goal.goal(),
            &self.gains,
            &self.robot,
            &self.rule,
        ))
    }

    fn swap(&mut self, model: ExpertGains) -> Result<(), BoxError> {
        model.validate()?;
        self.gains = model;
        Ok(())
    }

    fn set_wheel_limits(&mut self, wheels: WheelLimits) {
        self.robot.max_wheel_accel = wheels.max_accel;
        if let Some(speed) = wheels.max_speed {
            self.robot.max_wheel_speed = speed;
        }
    }
}

/// The in-process team of `robots` robots of `world`, each driven by the expert's law on its own
/// scan under `rule` (a scenario's [`neighbours`](formation_world::Scenario::neighbours)): one
/// [`OwnScanPilot`], with its own detector, per robot. The gains are fitted to the world's
/// reality models as the expert's are ([`ExpertGains::for_reality`]).
pub fn own_scan_team(
    gains: ExpertGains,
    world: &WorldConfig,
    rule: NeighbourRule,
    robots: usize,
) -> Result<Decentralised<OwnScanPilot>, OwnScanError> {
    let gains = gains.for_reality(&world.reality);
    let pilot = OwnScanPilot::new(gains, world.robot, world.lidar, rule)?;
    Ok(Decentralised::new(vec![pilot; robots]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::{expert_commands, expert_commands_among, expert_commands_weighted};
    use crate::test_support::{first_tick, goal};
    use formation_proto::Pose;
    use formation_proto::control::Controller;
    use formation_world::neighbours::{GabrielRule, NeighbourTracker};

    /// Seven robots off a lattice, with assorted headings: some pairs vetoed, some held.
    fn team() -> Vec<Pose> {
        [
            (0.0, 0.0, 0.3),
            (1.3, 0.2, -1.0),
            (0.5, 1.4, 2.0),
            (-1.1, 0.9, -2.8),
            (-0.7, -1.3, 1.1),
            (0.9, -1.2, 0.0),
            (2.4, 1.5, -0.4),
        ]
        .into_iter()
        .map(|(x, y, t)| Pose::new(x, y, t))
        .collect()
    }

    /// Robot `i`'s exact view: every other robot's centre in its body frame.
    fn exact_view(poses: &[Pose], i: usize) -> Vec<(f64, f64)> {
        let me = poses[i];
        let (sin, cos) = me.theta.sin_cos();
        poses
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, p)| {
                let (dx, dy) = (p.x - me.x, p.y - me.y);
                (cos * dx + sin * dy, -sin * dx + cos * dy)
            })
            .collect()
    }

    /// `view`'s command for robot `i` of `poses` from its [`exact_view`] and its own heading.
    fn exact_command(
        view: &mut OwnView,
        poses: &[Pose],
        i: usize,
        goal: &Goal,
        gains: &ExpertGains,
        robot: &RobotParams,
        rule: &NeighbourRule,
    ) -> WheelCmd {
        view.command(
            &exact_view(poses, i),
            poses[i].theta,
            goal,
            gains,
            robot,
            rule,
        )
    }

    fn close(a: &WheelCmd, b: &WheelCmd, tolerance: f64) -> bool {
        (a.left - b.left).abs() < tolerance && (a.right - b.right).abs() < tolerance
    }

    fn limited(accel: Option<f64>) -> RobotParams {
        RobotParams {
            max_wheel_accel: accel,
            ..RobotParams::default()
        }
    }

    #[test]
    fn with_every_neighbour_seen_exactly_the_command_is_the_experts() {
        let poses = team();
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(10.0));
        let mut tracker = NeighbourTracker::new(rule, poses.len());
        let positions: Vec<(f64, f64)> = poses.iter().map(|p| (p.x, p.y)).collect();
        tracker.update(&positions);
        let band = ExpertGains {
            pair_weight_band: Some([1.2, 1.6]),
            ..ExpertGains::default()
        };
        let unshaped = ExpertGains {
            unshaped: true,
            ..ExpertGains::default()
        };
        for (gains, accel) in [
            (ExpertGains::default(), None),
            (ExpertGains::default(), Some(1.0)),
            (unshaped, Some(1.0)),
            (band, None),
        ] {
            let robot = limited(accel);
            for g in [goal(0.4, 1.2), goal(-2.0, 0.9), goal(3.0, 2.5)] {
                let mut expert = vec![WheelCmd::BRAKE; poses.len()];
                if let Some(b) = gains.pair_weight_band {
                    let NeighbourRule::Gabriel(gabriel) = rule else {
                        unreachable!()
                    };
                    let mut weighted = Vec::new();
                    weighted_neighbours(&positions, &gabriel, b, &mut weighted);
                    expert_commands_weighted(&poses, &g, &gains, &robot, &weighted, &mut expert);
                } else {
                    expert_commands_among(&poses, &g, &gains, &robot, &tracker, &mut expert);
                }
                let mut view = OwnView::new();
                for (i, wanted) in expert.iter().enumerate() {
                    let own = exact_command(&mut view, &poses, i, &g, &gains, &robot, &rule);
                    assert!(
                        close(&own, wanted, 1e-6),
                        "robot {i}, {gains:?}: {own:?} against {wanted:?}"
                    );
                    if gains.pair_weight_band.is_none() {
                        // The same neighbours, in detection indices.
                        let held: Vec<usize> = view
                            .held()
                            .iter()
                            .map(|&(k, _)| if k < i { k } else { k + 1 })
                            .collect();
                        let mut sorted = held.clone();
                        sorted.sort_unstable();
                        assert_eq!(sorted, tracker.own_neighbours(i), "robot {i}");
                    }
                }
            }
        }
        // Some pairs are vetoed, so the rule matters here.
        assert!((0..poses.len()).any(|i| tracker.own_neighbours(i).len() < poses.len() - 1));
    }

    #[test]
    fn the_middle_of_a_line_of_three_steps_aside_with_the_pull_of_the_ends_pair() {
        let d: f64 = 1.5;
        let mut hidden = Vec::new();
        let mut step = |neighbours: &[(f64, f64)]| {
            hidden_pairs(neighbours, 2, 0.25, d, &mut hidden);
            let mut gradient = (0.0, 0.0);
            add_unblocking_term(&mut gradient, &hidden, d);
            gradient
        };
        // The pull of a pair at 2 d*: 2 ((2d)^4 - d^4) / (2d)^3 = 3.75 d, to the left of the
        // line from the first detection to the second (+y), so the gradient is -y.
        let (gx, gy) = step(&[(-d, 0.0), (d, 0.0)]);
        assert!(
            gx.abs() < 1e-12 && (gy + 3.75 * d).abs() < 1e-9,
            "{gx} {gy}"
        );
        // Half the weight, half the step; an end robot does not step.
        let (_, gy) = step(&[(-d, 0.1875), (d, 0.1875)]);
        assert!((gy - 0.5 * 3.75 * d).abs() < 1e-9, "{gy}");
        assert_eq!(step(&[(d, 0.0), (2.0 * d, 0.0)]), (0.0, 0.0));
    }

    #[test]
    fn stepping_aside_is_off_by_default_and_out_of_the_gains_json_while_off() {
        assert!(!ExpertGains::default().unblock_hidden_pairs);
        let json = serde_json::to_string(&ExpertGains::default()).expect("serializes");
        assert!(!json.contains("unblock_hidden_pairs"), "{json}");
        let on = ExpertGains {
            unblock_hidden_pairs: true,
            ..ExpertGains::default()
        };
        let json = serde_json::to_string(&on).expect("serializes");
        let back: ExpertGains = serde_json::from_str(&json).expect("parses");
        assert_eq!(back, on);
        // On, the middle of a line of three turns off its heading; off, it drives straight.
        let robot = limited(None);
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(10.0));
        let line = [(-1.5, 0.0), (1.5, 0.0)];
        let mut view = OwnView::new();
        let straight = view.command(
            &line,
            0.0,
            &goal(0.0, 1.5),
            &ExpertGains::default(),
            &robot,
            &rule,
        );
        assert!(
            (straight.left - straight.right).abs() < 1e-9,
            "{straight:?}"
        );
        let aside = view.command(&line, 0.0, &goal(0.0, 1.5), &on, &robot, &rule);
        assert!(aside.right > aside.left + 0.1, "{aside:?}");
    }

    #[test]
    fn under_all_pairs_it_holds_every_detection_at_the_papers_gain() {
        // Three robots with one heading: offset points and centres differ by one vector, so
        // the paper's law and the law between centres agree.
        let poses: Vec<Pose> = [(0.0, 0.0), (1.1, 0.3), (0.4, 1.2)]
            .into_iter()
            .map(|(x, y)| Pose::new(x, y, 0.7))
            .collect();
        let g = goal(0.2, 1.0);
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let mut expert = vec![WheelCmd::BRAKE; 3];
        expert_commands(&poses, &g, &gains, &robot, &mut expert);
        let mut view = OwnView::new();
        for (i, wanted) in expert.iter().enumerate() {
            let rule = NeighbourRule::AllPairs;
            let own = exact_command(&mut view, &poses, i, &g, &gains, &robot, &rule);
            assert!(close(&own, wanted, 1e-9), "{own:?} {wanted:?}");
            assert_eq!(view.held().len(), 2);
        }
    }

    #[test]
    fn a_robot_that_sees_nobody_drives_the_reference_velocity() {
        let robot = RobotParams::default();
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(10.0));
        for (heading, phi_star) in [(0.0, 0.0), (1.0, -0.5), (-2.5, 3.0)] {
            let g = goal(phi_star, 1.5);
            let alone = [Pose::new(3.0, -1.0, heading)];
            let mut expert = [WheelCmd::BRAKE];
            expert_commands(&alone, &g, &ExpertGains::default(), &robot, &mut expert);
            let mut view = OwnView::new();
            let own = view.command(&[], heading, &g, &ExpertGains::default(), &robot, &rule);
            assert_eq!(own, expert[0]);
            // The reference velocity, v* toward phi*, at the point c ahead of the axle.
            let c = ExpertGains::default().point_offset;
            let delta = phi_star - heading;
            let (v, omega) = (0.7 * delta.cos(), 0.7 * delta.sin() / c);
            let half = robot.wheel_separation / 2.0;
            let (left, right) = (v - half * omega, v + half * omega);
            let scale = (robot.max_wheel_speed / left.abs().max(right.abs())).min(1.0);
            assert!(
                close(
                    &own,
                    &WheelCmd {
                        left: left * scale,
                        right: right * scale
                    },
                    1e-12
                ),
                "{own:?}"
            );
        }
    }

    #[test]
    fn through_its_own_noiseless_scan_each_robot_commands_about_what_the_expert_does() {
        use formation_world::lidar::cast_scan;
        // Five robots near a pentagon's corners, so that no robot hides another (seen from one
        // corner, the others are 36 degrees apart and subtend at most 16).
        let poses: Vec<Pose> = [
            (0.05, 0.3),
            (-0.04, -1.0),
            (0.03, 2.0),
            (-0.02, -2.8),
            (0.0, 1.1),
        ]
        .into_iter()
        .enumerate()
        .map(|(k, (jitter, theta))| {
            let a = 0.2 + k as f64 * std::f64::consts::TAU / 5.0;
            let radius = 1.5 + jitter;
            Pose::new(radius * a.cos(), radius * a.sin(), theta)
        })
        .collect();
        let world = WorldConfig::default();
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(world.lidar.max_range));
        let g = goal(0.4, 1.4);
        let scans: Vec<Vec<f32>> = (0..poses.len())
            .map(|i| {
                let mut scan = vec![0.0; world.lidar.beams];
                cast_scan(&poses, i, &world.robot, &world.lidar, &mut scan);
                scan
            })
            .collect();
        let mut team =
            own_scan_team(ExpertGains::default(), &world, rule, poses.len()).expect("valid");
        let mut own = vec![WheelCmd::BRAKE; poses.len()];
        let obs = first_tick(g, &poses, &scans);
        team.commands(&obs, &mut own).expect("valid");
        let mut tracker = NeighbourTracker::new(rule, poses.len());
        tracker.update(&poses.iter().map(|p| (p.x, p.y)).collect::<Vec<_>>());
        let mut expert = vec![WheelCmd::BRAKE; poses.len()];
        expert_commands_among(
            &poses,
            &g,
            &ExpertGains::default(),
            &world.robot,
            &tracker,
            &mut expert,
        );
        for (i, (a, b)) in own.iter().zip(&expert).enumerate() {
            assert_eq!(team.pilots_mut()[i].detections().len(), poses.len() - 1);
            // The detector puts noiseless centres within 0.1 mm.
            assert!(close(a, b, 1e-3), "robot {i}: {a:?} against {b:?}");
        }
    }

    #[test]
    fn a_pilot_refuses_what_it_cannot_act_on_and_swaps_gains() {
        let world = WorldConfig::default();
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(10.0));
        let mut pilot =
            OwnScanPilot::new(ExpertGains::default(), world.robot, world.lidar, rule).expect("ok");
        assert_eq!(pilot.model_id(), OWN_SCAN_ID);
        let short = vec![10.0_f32; 10];
        let err = pilot.perceive(&short, &goal(0.0, 1.0)).unwrap_err();
        assert!(err.to_string().contains("10 ranges"), "{err}");
        let empty = vec![world.lidar.max_range as f32; world.lidar.beams];
        assert!(pilot.perceive(&empty, &goal(0.0, 0.0)).is_err());
        pilot.perceive(&empty, &goal(0.0, 1.0)).expect("valid");
        assert!(pilot.detections().is_empty());
        assert!(pilot.decide(f64::NAN, &goal(0.0, 1.0)).is_err());
        let bad = ExpertGains {
            point_offset: 0.0,
            ..ExpertGains::default()
        };
        assert!(pilot.swap(bad).is_err());
        assert!(OwnScanPilot::new(bad, world.robot, world.lidar, rule).is_err());
        let slower = ExpertGains {
            max_reference_speed: 0.1,
            ..ExpertGains::default()
        };
        let before = pilot.decide(0.0, &goal(0.0, 1.0)).expect("valid");
        pilot.swap(slower).expect("valid");
        let after = pilot.decide(0.0, &goal(0.0, 1.0)).expect("valid");
        assert!(after.left < before.left && (after.left - 0.1).abs() < 1e-12);
    }
}
