//! The response gauge: how far a controller moves, against how far the expert asks it to move, on
//! the controller's own states.
//!
//! At every gauged state each robot's command is turned back into the velocity it sets for the
//! robot's controlled point (the point `c` ahead of its axle, the point the expert steers), and the
//! reference term `v* (cos φ*, sin φ*)` (capped as the expert caps it) is taken off: what is left is
//! the robot's *formation velocity*, its correction of the formation. The label is the same quantity
//! from the expert's own command on that state, after the expert's wheel saturation. [`ResponseGauge`]
//! sums, in bins of the label's size ([`RESPONSE_BIN_EDGES`]), what the slope `Σ p·l / Σ |l|²` and
//! the RMS error `sqrt(mean |p - l|²)` need; tallies of several runs add up ([`ResponseTally::merge`]).
//!
//! The gauge needs no training: it plays the controller's own runs and relabels their states, so
//! a change to the teacher or the network shows its effect on the small corrections (edges 1–5 %
//! off d*, labels of 0.05–0.2 m/s) in minutes. Applied to the expert itself it gives slope 1 and
//! zero error in every bin.
//!
//! The expert that labels keeps its neighbour tracker in step with the run: it sees every tick,
//! gauged or not, as the scored expert would.

use formation_proto::{Goal, Pose, WheelCmd};
use formation_schema::{MIN_JUDGED_SAMPLES, RESPONSE_BIN_EDGES, ResponseBin};
use formation_world::RobotParams;
use formation_world::episode::{ControllerError, Observation};
use formation_world::neighbours::NeighbourRule;

use crate::controller::{ExpertController, ExpertGains, check_inputs, reference_velocity};

/// The number of bins of the label's size.
pub const RESPONSE_BINS: usize = RESPONSE_BIN_EDGES.len() - 1;

/// The velocity \[m/s\] that `cmd` sets for the point `c` ahead of the axle of a robot at `pose`:
/// `v (cos θ, sin θ) + c ω (-sin θ, cos θ)` with `v` and `ω` from the wheels.
pub fn point_velocity(
    cmd: WheelCmd,
    pose: &Pose,
    point_offset: f64,
    robot: &RobotParams,
) -> [f64; 2] {
    let v = (cmd.left + cmd.right) / 2.0;
    let omega = (cmd.right - cmd.left) / robot.wheel_separation;
    let (sin, cos) = pose.theta.sin_cos();
    [
        v * cos - point_offset * omega * sin,
        v * sin + point_offset * omega * cos,
    ]
}

/// The formation velocity \[m/s\] of `cmd`: its [`point_velocity`] minus the expert's reference
/// term for `goal`.
pub fn formation_velocity(
    cmd: WheelCmd,
    pose: &Pose,
    goal: &Goal,
    gains: &ExpertGains,
    robot: &RobotParams,
) -> [f64; 2] {
    let point = point_velocity(cmd, pose, gains.point_offset, robot);
    let reference = reference_velocity(goal, gains.max_reference_speed);
    [point[0] - reference.0, point[1] - reference.1]
}

/// The sums of one bin.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BinSums {
    /// Robot-samples in the bin.
    pub samples: u64,
    /// `Σ p·l`.
    pub dot: f64,
    /// `Σ |l|²`.
    pub label_sq: f64,
    /// `Σ |p - l|²`.
    pub error_sq: f64,
}

impl BinSums {
    fn add(&mut self, p: [f64; 2], l: [f64; 2]) {
        let e = [p[0] - l[0], p[1] - l[1]];
        self.samples += 1;
        self.dot += p[0] * l[0] + p[1] * l[1];
        self.label_sq += l[0] * l[0] + l[1] * l[1];
        self.error_sq += e[0] * e[0] + e[1] * e[1];
    }

    /// `Σ p·l / Σ |l|²`, or `None` without samples.
    pub fn slope(&self) -> Option<f64> {
        (self.samples > 0 && self.label_sq > 0.0).then(|| self.dot / self.label_sq)
    }

    /// `sqrt(mean |p - l|²)`, or `None` without samples.
    pub fn rms_error(&self) -> Option<f64> {
        (self.samples > 0).then(|| (self.error_sq / self.samples as f64).sqrt())
    }
}

/// The gauge's sums over some runs: one [`BinSums`] per bin, and the samples in none.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ResponseTally {
    /// The bins, in [`RESPONSE_BIN_EDGES`] order.
    pub bins: [BinSums; RESPONSE_BINS],
    /// Every robot-sample gauged, in a bin or not.
    pub samples: u64,
}

impl ResponseTally {
    /// Adds one robot-sample: the controller's formation velocity `p` against the label `l`.
    pub fn add(&mut self, p: [f64; 2], l: [f64; 2]) {
        self.samples += 1;
        let size = l[0].hypot(l[1]);
        if let Some(bin) = bin_of(size) {
            self.bins[bin].add(p, l);
        }
    }

    /// Adds another tally's sums to this one's.
    pub fn merge(&mut self, other: &ResponseTally) {
        self.samples += other.samples;
        for (mine, theirs) in self.bins.iter_mut().zip(&other.bins) {
            mine.samples += theirs.samples;
            mine.dot += theirs.dot;
            mine.label_sq += theirs.label_sq;
            mine.error_sq += theirs.error_sq;
        }
    }

    /// The bins as the response curve file records them.
    pub fn to_bins(&self) -> Vec<ResponseBin> {
        self.bins
            .iter()
            .enumerate()
            .map(|(i, sums)| ResponseBin {
                label_min: RESPONSE_BIN_EDGES[i],
                label_max: RESPONSE_BIN_EDGES[i + 1],
                samples: sums.samples,
                slope: sums.slope(),
                rms_error: sums.rms_error(),
                judged: sums.samples >= MIN_JUDGED_SAMPLES,
            })
            .collect()
    }
}

/// The bin of a label of this size \[m/s\], or `None` below the first edge or from the last on.
fn bin_of(size: f64) -> Option<usize> {
    RESPONSE_BIN_EDGES
        .windows(2)
        .position(|edges| size >= edges[0] && size < edges[1])
}

/// Relabels a run's states with the expert and tallies a controller's response against it.
///
/// Call [`record`](Self::record) at every tick of one run, in order, with the observation and the
/// commands the gauged controller chose for it (before the world applies any acceleration limit);
/// every `stride`-th tick, from tick 0, is gauged.
#[derive(Debug, Clone)]
pub struct ResponseGauge {
    expert: ExpertController,
    stride: u64,
    labels: Vec<WheelCmd>,
    tally: ResponseTally,
}

impl ResponseGauge {
    /// A gauge labelling with these gains for robots with these parameters under `rule`, gauging
    /// every `stride`-th tick (`stride` 0 counts as 1).
    pub fn new(
        gains: ExpertGains,
        robot: RobotParams,
        rule: NeighbourRule,
        stride: u64,
    ) -> ResponseGauge {
        ResponseGauge {
            expert: ExpertController::new(gains, robot).with_neighbours(rule),
            stride: stride.max(1),
            labels: Vec::new(),
            tally: ResponseTally::default(),
        }
    }

    /// Labels `obs` with the expert (always, so that its neighbour tracker follows the run) and,
    /// on a gauged tick, tallies `commands` against the labels.
    pub fn record(
        &mut self,
        obs: &Observation<'_>,
        commands: &[WheelCmd],
    ) -> Result<(), ControllerError> {
        check_inputs(obs.poses, &obs.goal, commands.len())?;
        self.expert
            .gains()
            .validate()
            .map_err(|e| ControllerError::new(e.to_string()))?;
        self.labels.clear();
        self.labels.resize(obs.poses.len(), WheelCmd::BRAKE);
        self.expert
            .compute(obs.tick, obs.poses, &obs.goal, &mut self.labels);
        if !obs.tick.is_multiple_of(self.stride) {
            return Ok(());
        }
        let (gains, robot) = (*self.expert.gains(), *self.expert.robot());
        for ((pose, cmd), label) in obs.poses.iter().zip(commands).zip(&self.labels) {
            let p = formation_velocity(*cmd, pose, &obs.goal, &gains, &robot);
            let l = formation_velocity(*label, pose, &obs.goal, &gains, &robot);
            self.tally.add(p, l);
        }
        Ok(())
    }

    /// The sums so far.
    pub fn tally(&self) -> &ResponseTally {
        &self.tally
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_world::episode::run_episode;
    use formation_world::{Controller, Scenario};

    fn scenario(robots: usize) -> Scenario {
        let text = format!(
            "name = \"t\"\nrobots = {robots}\nduration_s = 15.0\nseed = 3\nruns = 2\n\
             [goal]\nv_star = 0.7\nd_star = 1.5\n[heading]\nschedule = \"random\"\n\
             [lidar]\nbeams = 90\n"
        );
        Scenario::from_toml_str(&text, "t").unwrap()
    }

    /// Plays run 0 of `scenario` with `controller` and gauges it against the default expert.
    fn gauge(scenario: &Scenario, controller: &mut dyn Controller, scale: f64) -> ResponseTally {
        let spec = scenario.run_spec(scenario.seed(), 0);
        let mut gauge =
            ResponseGauge::new(ExpertGains::default(), spec.world.robot, spec.neighbours, 5);
        let gains = ExpertGains::default();
        let robot = spec.world.robot;
        run_episode(&spec, controller, &mut |obs, cmds| {
            // The gauged controller's commands, their formation velocity scaled by `scale`.
            let scaled: Vec<WheelCmd> = obs
                .poses
                .iter()
                .zip(cmds)
                .map(|(pose, cmd)| scale_formation(*cmd, pose, &obs.goal, &gains, &robot, scale))
                .collect();
            gauge.record(obs, &scaled).unwrap();
        })
        .unwrap();
        *gauge.tally()
    }

    /// The wheel command whose formation velocity is `scale` times `cmd`'s, with the same
    /// reference term (the inverse of [`point_velocity`]).
    fn scale_formation(
        cmd: WheelCmd,
        pose: &Pose,
        goal: &Goal,
        gains: &ExpertGains,
        robot: &RobotParams,
        scale: f64,
    ) -> WheelCmd {
        let f = formation_velocity(cmd, pose, goal, gains, robot);
        let r = reference_velocity(goal, gains.max_reference_speed);
        let u = [r.0 + scale * f[0], r.1 + scale * f[1]];
        let (sin, cos) = pose.theta.sin_cos();
        let v = cos * u[0] + sin * u[1];
        let omega = (-sin * u[0] + cos * u[1]) / gains.point_offset;
        let half = robot.wheel_separation / 2.0;
        WheelCmd::new(v - half * omega, v + half * omega)
    }

    /// Gauges the default expert on a team of `robots`, its formation velocity scaled by `scale`:
    /// the states are the expert's own.
    fn gauge_expert(robots: usize, scale: f64) -> ResponseTally {
        let scenario = scenario(robots);
        let spec = scenario.run_spec(scenario.seed(), 0);
        let mut expert = ExpertController::new(ExpertGains::default(), spec.world.robot)
            .with_neighbours(spec.neighbours);
        gauge(&scenario, &mut expert, scale)
    }

    #[test]
    fn the_expert_gauged_against_itself_has_slope_one_and_no_error_in_every_bin() {
        let tally = gauge_expert(8, 1.0);
        assert!(tally.samples > 0);
        let filled: Vec<&BinSums> = tally.bins.iter().filter(|b| b.samples > 0).collect();
        assert!(
            filled.len() >= 2,
            "the run should fill several bins: {tally:?}"
        );
        for bin in filled {
            let slope = bin.slope().unwrap();
            assert!((slope - 1.0).abs() < 1e-9, "slope {slope}");
            assert!(
                bin.rms_error().unwrap() < 1e-9,
                "error {:?}",
                bin.rms_error()
            );
        }
    }

    #[test]
    fn a_controller_that_moves_a_tenth_as_far_has_slope_a_tenth() {
        // The states are the expert's own; the gauged commands are its formation velocity at a tenth.
        let tally = gauge_expert(5, 0.1);
        for bin in tally.bins.iter().filter(|b| b.samples > 0) {
            let slope = bin.slope().unwrap();
            assert!((slope - 0.1).abs() < 1e-9, "slope {slope}");
            // |p - l| = 0.9 |l| for every sample, so the RMS error is 0.9 RMS |l|.
            let rms_label = (bin.label_sq / bin.samples as f64).sqrt();
            assert!((bin.rms_error().unwrap() - 0.9 * rms_label).abs() < 1e-9);
        }
    }

    #[test]
    fn point_velocity_inverts_the_point_offset_kinematics() {
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let pose = Pose::new(0.3, -1.0, 0.7);
        let goal = Goal {
            phi_star: 0.2,
            d_star: 1.5,
            v_star: 0.5,
        };
        let cmd = scale_formation(WheelCmd::new(0.3, 0.1), &pose, &goal, &gains, &robot, 1.0);
        let f = formation_velocity(cmd, &pose, &goal, &gains, &robot);
        let back = scale_formation(cmd, &pose, &goal, &gains, &robot, 1.0);
        let f_back = formation_velocity(back, &pose, &goal, &gains, &robot);
        assert!((f[0] - f_back[0]).abs() < 1e-12 && (f[1] - f_back[1]).abs() < 1e-12);
        // Straight ahead at v: the point moves at v along the heading.
        let ahead = point_velocity(WheelCmd::new(0.4, 0.4), &pose, gains.point_offset, &robot);
        assert!((ahead[0] - 0.4 * 0.7f64.cos()).abs() < 1e-12);
        assert!((ahead[1] - 0.4 * 0.7f64.sin()).abs() < 1e-12);
    }

    #[test]
    fn labels_outside_the_bins_are_counted_but_not_binned_and_tallies_merge() {
        let mut a = ResponseTally::default();
        a.add([0.0, 0.0], [0.01, 0.0]); // below 0.05
        a.add([1.0, 0.0], [0.9, 0.0]); // from 0.8 on
        a.add([0.03, 0.0], [0.06, 0.0]);
        assert_eq!(a.samples, 3);
        assert_eq!(a.bins[0].samples, 1);
        assert!((a.bins[0].slope().unwrap() - 0.5).abs() < 1e-12);
        let mut b = ResponseTally::default();
        b.add([0.09, 0.0], [0.06, 0.0]);
        a.merge(&b);
        assert_eq!(a.samples, 4);
        assert!((a.bins[0].slope().unwrap() - 1.0).abs() < 1e-12);
        let bins = a.to_bins();
        assert_eq!(bins.len(), RESPONSE_BINS);
        assert_eq!((bins[1].label_min, bins[1].label_max), (0.1, 0.2));
        assert_eq!(bins[1].slope, None);
        assert!(!bins[0].judged);
    }
}
