//! The neighbours a robot detects in its own scan, as a model takes them beside its image
//! ([`NeighbourInput`]): each detection's centre in units of d* and whether the robot holds it at
//! d*, by the Gabriel rule applied to itself and its detections.
//!
//! The single computation of the `neighbours` input: collection (`formation_expert::collect`),
//! the running agent (`formation_robot_agent::decision`) and the Python package all call
//! [`NeighbourInputBuilder::fill`], so a policy sees at run time exactly the values it was trained
//! on.
//!
//! The rule ([`own_neighbours`]) is the world's (`formation_world::neighbours::NeighbourTracker`)
//! read from one robot's side, without memory: the robot at the origin, its detections the other
//! robots. A test holds the two equal on random teams.

use formation_proto::{GabrielRule, LidarSpec, NeighbourInput};

use crate::hidden_pairs::{HiddenPair, hidden_pairs};
use crate::neighbours::{DetectedNeighbour, DetectorSettings, NeighbourDetector, SettingsError};

/// Marks in `held` (resized to `neighbours.len()`) the neighbours a robot at the origin holds
/// under `rule` with no hysteresis, given its neighbours' centres `neighbours` (body frame,
/// metres; a non-finite centre is nobody's neighbour):
///
/// * a *Gabriel* neighbour `j`: `0 < |x_j|^2 <= range^2 / max(threshold, 1)` and every other
///   neighbour `k` has witness ratio `(|x_k|^2 + |x_j - x_k|^2) / |x_j|^2 >= threshold`;
/// * plus the `nearest` neighbours within `sensing_range`, ties broken by the lower index.
///
/// `order` is scratch (kept by the caller so nothing is allocated once it has grown).
pub fn own_neighbours(
    neighbours: &[(f64, f64)],
    rule: &GabrielRule,
    order: &mut Vec<(f64, usize)>,
    held: &mut Vec<bool>,
) {
    held.clear();
    held.resize(neighbours.len(), false);
    let range_sq = rule.sensing_range * rule.sensing_range;
    let pair_range_sq = range_sq / rule.threshold.max(1.0);
    order.clear();
    order.extend(
        neighbours
            .iter()
            .enumerate()
            .filter(|(_, (x, y))| x.is_finite() && y.is_finite())
            .map(|(j, (x, y))| (x * x + y * y, j))
            .filter(|&(d, _)| d <= range_sq),
    );
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let d2 = |a: usize, b: usize| {
        let (dx, dy) = (
            neighbours[a].0 - neighbours[b].0,
            neighbours[a].1 - neighbours[b].1,
        );
        dx * dx + dy * dy
    };
    for &(dij, j) in order.iter() {
        if dij > pair_range_sq || dij <= 0.0 {
            continue;
        }
        let reach = rule.threshold.max(1.0) * dij;
        let vetoed = order
            .iter()
            .take_while(|&&(dik, _)| dik < reach)
            .any(|&(dik, k)| k != j && (dik + d2(j, k)) < rule.threshold * dij);
        if !vetoed {
            held[j] = true;
        }
    }
    for &(_, j) in order.iter().take(rule.nearest) {
        held[j] = true;
    }
}

/// Detects a robot's neighbours in its scan and fills the `neighbours` input a model declares;
/// keeps its buffers, so after the first few scans it allocates nothing.
#[derive(Debug, Clone)]
pub struct NeighbourInputBuilder {
    detector: NeighbourDetector,
    detections: Vec<DetectedNeighbour>,
    centres: Vec<(f64, f64)>,
    order: Vec<(f64, usize)>,
    held: Vec<bool>,
    slots: Vec<(bool, f64, usize)>,
    hidden: Vec<HiddenPair>,
    slot_of: Vec<Option<usize>>,
}

impl Default for NeighbourInputBuilder {
    fn default() -> NeighbourInputBuilder {
        NeighbourInputBuilder::new(DetectorSettings::DEFAULT).expect("the default settings hold")
    }
}

impl NeighbourInputBuilder {
    /// A builder whose detector reads scans with `settings`.
    pub fn new(settings: DetectorSettings) -> Result<NeighbourInputBuilder, SettingsError> {
        Ok(NeighbourInputBuilder {
            detector: NeighbourDetector::new(settings)?,
            detections: Vec::new(),
            centres: Vec::new(),
            order: Vec::new(),
            held: Vec::new(),
            slots: Vec::new(),
            hidden: Vec::new(),
            slot_of: Vec::new(),
        })
    }

    /// A builder for robots whose bodies are discs of `body_radius_m`.
    pub fn with_body_radius(body_radius_m: f64) -> Result<NeighbourInputBuilder, SettingsError> {
        NeighbourInputBuilder::new(DetectorSettings::with_body_radius(body_radius_m))
    }

    /// Fills `out` with the `neighbours` input of one scan under the goal spacing `d_star` \[m\]
    /// (see [`NeighbourInput`] for the layout): the scan's detections, the rule `spec` declares
    /// applied at the LIDAR's range, held neighbours first, each group nearest first.
    ///
    /// # Panics
    ///
    /// If `out.len() != spec.len()` or `scan.len() != lidar.beams`: buffers are sized by the
    /// caller from the same settings, and the model's contract is checked against its LIDAR when
    /// it loads, so a mismatch is a programming error, not bad input.
    pub fn fill(
        &mut self,
        scan: &[f32],
        lidar: &LidarSpec,
        spec: &NeighbourInput,
        d_star: f64,
        out: &mut [f32],
    ) {
        assert_eq!(
            out.len(),
            spec.len(),
            "neighbours buffer must hold FEATURES values per slot"
        );
        assert_eq!(
            scan.len(),
            lidar.beams,
            "scan must have one range per configured LIDAR beam"
        );
        self.detector.detect(scan, lidar, &mut self.detections);
        self.centres.clear();
        self.centres
            .extend(self.detections.iter().map(|d| (d.x, d.y)));
        own_neighbours(
            &self.centres,
            &spec.rule(lidar.max_range),
            &mut self.order,
            &mut self.held,
        );
        // Detections come out nearest first; held ones go first, the order kept in each group.
        self.slots.clear();
        self.slots.extend(
            self.detections
                .iter()
                .zip(&self.held)
                .enumerate()
                .map(|(k, (d, &held))| (held, d.x.hypot(d.y), k)),
        );
        self.slots
            .sort_by(|a, b| b.0.cmp(&a.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
        out.fill(0.0);
        let features = spec.features();
        for (slot, &(held, _, k)) in out.chunks_exact_mut(features).zip(&self.slots) {
            let d = &self.detections[k];
            slot[0] = (d.x / d_star) as f32;
            slot[1] = (d.y / d_star) as f32;
            slot[2] = if held { 1.0 } else { 0.0 };
            slot[3] = 1.0;
        }
        if spec.hidden {
            self.fill_hidden_pairs(spec, d_star, out);
        }
    }

    /// Adds to each slot's `(hx, hy)` half the step aside of each hidden pair it is an end of
    /// (see [`NeighbourInput`]), over all the scan's detections, under the rule's `nearest`.
    fn fill_hidden_pairs(&mut self, spec: &NeighbourInput, d_star: f64, out: &mut [f32]) {
        let features = spec.features();
        hidden_pairs(
            &self.centres,
            spec.nearest,
            self.detector.settings().body_radius_m,
            d_star,
            &mut self.hidden,
        );
        self.slot_of.clear();
        self.slot_of.resize(self.detections.len(), None);
        for (slot, &(_, _, k)) in self.slots.iter().enumerate().take(spec.slots) {
            self.slot_of[k] = Some(slot);
        }
        for pair in &self.hidden {
            let half = 0.5 * pair.pull(d_star) / d_star;
            for end in [pair.first, pair.second] {
                if let Some(slot) = self.slot_of[end] {
                    let values = &mut out[slot * features..(slot + 1) * features];
                    values[4] += (half * pair.away.0) as f32;
                    values[5] += (half * pair.away.1) as f32;
                }
            }
        }
    }

    /// The detections of the last [`fill`](Self::fill), nearest first.
    pub fn detections(&self) -> &[DetectedNeighbour] {
        &self.detections
    }
}

#[cfg(test)]
mod tests {
    use formation_proto::{NeighbourRule, Pose};
    use formation_world::RobotParams;
    use formation_world::lidar::cast_scan;
    use formation_world::neighbours::NeighbourTracker;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    #[test]
    fn the_rule_from_one_robots_side_is_the_worlds() {
        let rule = GabrielRule::with_range(6.0);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut order, mut held) = (Vec::new(), Vec::new());
        let mut compared = 0;
        for _ in 0..300 {
            let n = rng.random_range(2..14);
            let positions: Vec<(f64, f64)> = (0..n)
                .map(|_| (rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0)))
                .collect();
            let mut tracker = NeighbourTracker::new(NeighbourRule::Gabriel(rule), n);
            tracker.update(&positions);
            let (x0, y0) = positions[0];
            let relative: Vec<(f64, f64)> = positions[1..]
                .iter()
                .map(|&(x, y)| (x - x0, y - y0))
                .collect();
            own_neighbours(&relative, &rule, &mut order, &mut held);
            let ours: Vec<usize> = (0..relative.len())
                .filter(|&j| held[j])
                .map(|j| j + 1)
                .collect();
            assert_eq!(ours, tracker.own_neighbours(0), "{positions:?}");
            compared += ours.len();
        }
        assert!(
            compared > 300,
            "the teams held too few neighbours to compare: {compared}"
        );
    }

    #[test]
    fn non_finite_and_far_neighbours_are_never_held() {
        let rule = GabrielRule::with_range(3.0);
        let (mut order, mut held) = (Vec::new(), Vec::new());
        own_neighbours(
            &[
                (f64::NAN, 0.0),
                (5.0, 0.0),
                (1.0, 0.0),
                (0.0, f64::INFINITY),
            ],
            &rule,
            &mut order,
            &mut held,
        );
        assert_eq!(held, [false, false, true, false]);
    }

    /// Robot 0's noiseless scan (the world's own exact ray cast) among robots at `positions`,
    /// robot 0 heading `theta`.
    fn scan_of(positions: &[(f64, f64)], theta: f64) -> (Vec<f32>, LidarSpec) {
        let lidar = LidarSpec::default();
        let poses: Vec<Pose> = positions
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| Pose::new(x, y, if i == 0 { theta } else { 0.0 }))
            .collect();
        let mut scan = vec![0.0; lidar.beams];
        cast_scan(&poses, 0, &RobotParams::default(), &lidar, &mut scan);
        (scan, lidar)
    }

    #[test]
    fn the_input_holds_the_detections_in_units_of_d_star_held_first() {
        // Robot 0 at the origin heading +y; a robot 2 m ahead of it (world (0, 2)), one 1.5 m to
        // its right (world (1.5, 0)), and one behind the first (world (0, 4)), which the first
        // hides from view: only two detections.
        let positions = [(0.0, 0.0), (0.0, 2.0), (1.5, 0.0), (0.0, 4.0)];
        let (scan, lidar) = scan_of(&positions, std::f64::consts::FRAC_PI_2);
        let spec = NeighbourInput::with_default_rule(4).unwrap();
        let mut builder = NeighbourInputBuilder::default();
        let mut out = vec![f32::NAN; spec.len()];
        builder.fill(&scan, &lidar, &spec, 2.0, &mut out);
        assert_eq!(builder.detections().len(), 2, "{:?}", builder.detections());
        // Both are held (the two nearest); the nearer first: 1.5 m to the right, body frame
        // (0, -1.5), then (2, 0).
        let expect = [0.0, -0.75, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0];
        for (got, want) in out[..8].iter().zip(expect) {
            assert!((got - want).abs() < 1e-4, "{out:?}");
        }
        assert_eq!(&out[8..], &[0.0; 8]);
    }

    #[test]
    fn held_neighbours_come_before_nearer_ones_the_rule_drops() {
        // Robot 0 at a corner of a unit square: the diagonal (1, 1) is vetoed by the two sides
        // (witness ratio 1 < 1.3); a robot 2.5 m behind has no witness. With `nearest` = 0 only
        // Gabriel pairs are held, so the diagonal comes last although it is nearer.
        let positions = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (-2.5, 0.0)];
        let (scan, lidar) = scan_of(&positions, 0.0);
        let spec = NeighbourInput::new(8, 1.3, 0).unwrap();
        let mut builder = NeighbourInputBuilder::default();
        let mut out = vec![0.0; spec.len()];
        builder.fill(&scan, &lidar, &spec, 1.0, &mut out);
        let slots: Vec<&[f32]> = out.chunks_exact(4).collect();
        // Held: the two sides and the robot 2.5 m behind (nothing between); then the diagonal.
        let held: Vec<f32> = slots.iter().map(|s| s[2]).collect();
        let present: Vec<f32> = slots.iter().map(|s| s[3]).collect();
        assert_eq!(&held[..4], &[1.0, 1.0, 1.0, 0.0], "{out:?}");
        assert_eq!(&present[..5], &[1.0, 1.0, 1.0, 1.0, 0.0], "{out:?}");
        assert!((slots[2][0] + 2.5).abs() < 1e-3, "{out:?}");
        assert!((slots[3][0] - 1.0).abs() < 1e-3 && (slots[3][1] - 1.0).abs() < 1e-3);
    }

    #[test]
    fn a_mirrored_scene_negates_y_and_keeps_the_order_and_flags() {
        let positions = [
            (0.0, 0.0),
            (1.4, 0.3),
            (-0.4, 1.6),
            (0.9, -1.7),
            (-2.2, -0.5),
        ];
        let mirrored: Vec<(f64, f64)> = positions.iter().map(|&(x, y)| (x, -y)).collect();
        let spec = NeighbourInput::with_default_rule(6).unwrap();
        let mut builder = NeighbourInputBuilder::default();
        let (mut a, mut b) = (vec![0.0; spec.len()], vec![0.0; spec.len()]);
        let (scan, lidar) = scan_of(&positions, 0.0);
        builder.fill(&scan, &lidar, &spec, 1.5, &mut a);
        let (scan, lidar) = scan_of(&mirrored, 0.0);
        builder.fill(&scan, &lidar, &spec, 1.5, &mut b);
        for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
            assert!(
                (p[0] - q[0]).abs() < 1e-3 && (p[1] + q[1]).abs() < 1e-3,
                "{a:?} {b:?}"
            );
            assert_eq!((p[2], p[3]), (q[2], q[3]));
        }
        assert_eq!(a.chunks_exact(4).filter(|s| s[3] == 1.0).count(), 4);
    }

    #[test]
    fn the_middle_of_a_line_carries_its_hidden_pairs_step_on_both_ends() {
        // Robot 0 between two robots 1.5 m either side, slightly below their line: it hides them
        // from each other, and each end's slot carries half the step aside, away from the line.
        let d_star = 1.5;
        let positions = [(0.0, -0.05), (-d_star, 0.0), (d_star, 0.0)];
        let (scan, lidar) = scan_of(&positions, 0.0);
        let plain = NeighbourInput::with_default_rule(4).unwrap();
        let spec = plain.with_hidden(true);
        let mut builder = NeighbourInputBuilder::default();
        let mut out = vec![f32::NAN; spec.len()];
        builder.fill(&scan, &lidar, &spec, d_star, &mut out);
        let slots: Vec<&[f32]> = out.chunks_exact(6).collect();
        // rho = 2: each end carries half of 2 (16 - 1) / 8 = 3.75, to -y (away from the line).
        for slot in &slots[..2] {
            assert!(slot[4].abs() < 1e-2, "{out:?}");
            assert!((slot[5] + 1.875).abs() < 2e-2, "{out:?}");
        }
        assert!(slots[2..].iter().all(|s| s.iter().all(|&v| v == 0.0)));
        // The first four numbers of a slot are the plain input's.
        let mut four = vec![0.0; plain.len()];
        builder.fill(&scan, &lidar, &plain, d_star, &mut four);
        for (with, without) in slots.iter().zip(four.chunks_exact(4)) {
            assert_eq!(&with[..4], without);
        }
        // An end robot hides nothing.
        let (scan, lidar) = scan_of(&[(-d_star, 0.0), (0.0, -0.05), (d_star, 0.0)], 0.0);
        builder.fill(&scan, &lidar, &spec, d_star, &mut out);
        assert!(
            out.chunks_exact(6).all(|s| s[4] == 0.0 && s[5] == 0.0),
            "{out:?}"
        );
    }
}
