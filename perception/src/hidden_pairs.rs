//! Pairs of detections that a robot hides from each other: two robots it sees on either side of
//! its own body, which cannot see each other past it.
//!
//! A robot's scan shows only what no other body shadows. Where three robots stand in a line, each
//! end robot sees only the middle one and holds it at d*, and the team rests there, though by the
//! neighbour rule the ends would hold each other. The middle robot is the one that sees it: both
//! ends are in its scan, with its own body on their line. [`hidden_pairs`] finds such pairs among
//! one robot's detections, with the side the robot should step to; the expert's law on one
//! robot's own scan (`formation_expert::own_scan`, gain `unblock_hidden_pairs`) steps aside along
//! it, so that a policy learning that law can be given the same computation.
//!
//! A pair counts when:
//! * both detections are finite and farther apart than d*;
//! * the robot's foot on their line falls between them, within one body radius of the line;
//! * each would hold the other by the rule's `nearest` (counting the robot and every detection,
//!   the pair's other end excepted): each has fewer than `nearest` others nearer than the pair's
//!   distance.
//!
//! Its weight is 1 within half a body radius of the line, falling linearly to 0 at one body
//! radius, so that what a robot is asked to do is continuous in what it sees.

/// One pair of detections the robot hides from each other.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HiddenPair {
    /// The pair's earlier detection (its index in the detections given).
    pub first: usize,
    /// The pair's later detection.
    pub second: usize,
    /// The pair's distance apart \[m\].
    pub distance: f64,
    /// Unit vector perpendicular to the pair's line, pointing from the line to the robot: where
    /// the robot steps to let them see each other. A robot exactly on the line steps to the left
    /// of `first -> second`.
    pub away: (f64, f64),
    /// From 1 (within half a body radius of the line) to 0 (one body radius from it).
    pub weight: f64,
}

impl HiddenPair {
    /// How hard the pair asks the robot to step aside along [`away`](Self::away) \[m\]: the
    /// pull the pair would feel under the expert's pair law, `weight * 2 (r⁴ - d*⁴) / r³` with
    /// `r` its distance.
    pub fn pull(&self, d_star: f64) -> f64 {
        let r = self.distance;
        self.weight * 2.0 * (r.powi(4) - d_star.powi(4)) / r.powi(3)
    }
}

/// Writes into `out` (cleared first) the pairs of `neighbours` (detected centres in the robot's
/// body frame, the robot at the origin) that the robot hides from each other, for bodies of
/// `body_radius` and a goal distance `d_star`, under a neighbour rule that always holds the
/// `nearest` nearest (`usize::MAX`: every pair is held, the paper's all-pairs rule). See the
/// module documentation for when a pair counts. Pairs come in order of `(first, second)`.
pub fn hidden_pairs(
    neighbours: &[(f64, f64)],
    nearest: usize,
    body_radius: f64,
    d_star: f64,
    out: &mut Vec<HiddenPair>,
) {
    out.clear();
    let finite = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite();
    let dist2 = |p: (f64, f64), q: (f64, f64)| (p.0 - q.0).powi(2) + (p.1 - q.1).powi(2);
    // How many of the others (the robot at the origin included, `other` excepted) lie within
    // `sqrt(reach2)` of detection `p`.
    let nearer = |p: usize, other: usize, reach2: f64| {
        let robot = usize::from(dist2(neighbours[p], (0.0, 0.0)) < reach2);
        robot
            + neighbours
                .iter()
                .enumerate()
                .filter(|&(k, q)| {
                    k != p && k != other && finite(q) && dist2(neighbours[p], *q) < reach2
                })
                .count()
    };
    let d_star2 = d_star * d_star;
    for (first, &pa) in neighbours.iter().enumerate() {
        if !finite(&pa) {
            continue;
        }
        for (second, &pc) in neighbours.iter().enumerate().skip(first + 1) {
            if !finite(&pc) {
                continue;
            }
            let e = (pc.0 - pa.0, pc.1 - pa.1);
            let l2 = e.0 * e.0 + e.1 * e.1;
            if l2 <= d_star2 {
                continue;
            }
            // The robot's foot on the line first -> second, as a share of the way, and its
            // signed distance from the line (positive to the left).
            let t = -(pa.0 * e.0 + pa.1 * e.1) / l2;
            if t <= 0.0 || t >= 1.0 {
                continue;
            }
            let distance = l2.sqrt();
            let side = (e.1 * pa.0 - e.0 * pa.1) / distance;
            let weight = ((body_radius - side.abs()) / (0.5 * body_radius)).clamp(0.0, 1.0);
            if weight == 0.0 {
                continue;
            }
            if nearer(first, second, l2) >= nearest || nearer(second, first, l2) >= nearest {
                continue;
            }
            let sign = if side >= 0.0 { 1.0 } else { -1.0 };
            out.push(HiddenPair {
                first,
                second,
                distance,
                away: (-e.1 / distance * sign, e.0 / distance * sign),
                weight,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const D: f64 = 1.5;
    const BODY: f64 = 0.25;

    fn pairs(neighbours: &[(f64, f64)], nearest: usize) -> Vec<HiddenPair> {
        let mut out = vec![HiddenPair {
            first: 9,
            second: 9,
            distance: 0.0,
            away: (0.0, 0.0),
            weight: 0.0,
        }];
        hidden_pairs(neighbours, nearest, BODY, D, &mut out);
        out
    }

    #[test]
    fn the_middle_of_a_line_of_three_hides_its_ends_and_steps_to_the_left() {
        let found = pairs(&[(-D, 0.0), (D, 0.0)], 2);
        assert_eq!(
            found,
            vec![HiddenPair {
                first: 0,
                second: 1,
                distance: 2.0 * D,
                away: (0.0, 1.0),
                weight: 1.0,
            }]
        );
        // The other order: the left of the other direction.
        assert_eq!(pairs(&[(D, 0.0), (-D, 0.0)], 2)[0].away, (-0.0, -1.0));
        // Off the line, away from it; the weight falls from half a body radius to one.
        let below = pairs(&[(-D, -0.1), (D, -0.1)], 2);
        assert_eq!((below[0].away, below[0].weight), ((0.0, 1.0), 1.0));
        let above = pairs(&[(-D, 0.1875), (D, 0.1875)], 2);
        assert_eq!(above[0].away, (-0.0, -1.0));
        assert!((above[0].weight - 0.5).abs() < 1e-12);
        assert!(pairs(&[(-D, BODY), (D, BODY)], 2).is_empty());
    }

    #[test]
    fn ends_beside_or_near_or_seen_hide_nothing() {
        // An end robot (both on one side), a triangle, a pair at d*, a non-finite detection.
        assert!(pairs(&[(D, 0.0), (2.0 * D, 0.0)], 2).is_empty());
        let h = D * 3f64.sqrt() / 2.0;
        assert!(pairs(&[(h, D / 2.0), (h, -D / 2.0)], 2).is_empty());
        assert!(pairs(&[(-D / 2.0, 0.0), (D / 2.0, 0.0)], 2).is_empty());
        assert!(pairs(&[(f64::NAN, 0.0), (D, 0.0)], 2).is_empty());
        assert!(pairs(&[], 2).is_empty());
    }

    #[test]
    fn a_pair_with_nearer_neighbours_of_its_own_is_not_held_through_the_robot() {
        // Each end has a neighbour of its own nearer than the other end (2 d*).
        let team = [(-D, 0.0), (D, 0.0), (-1.5 * D, 0.8 * D), (1.5 * D, 0.8 * D)];
        assert!(pairs(&team, 2).is_empty());
        // Under all pairs they are held whatever is nearer.
        assert_eq!(pairs(&team, usize::MAX).len(), 1);
        // One end with a nearer neighbour of its own: only the other would hold it.
        assert!(pairs(&team[..3], 2).is_empty());
        // A lattice's robot between two opposite neighbours: each has nearer ones of its own.
        let h = D * 3f64.sqrt() / 2.0;
        let lattice = [
            (D, 0.0),
            (-D, 0.0),
            (D / 2.0, h),
            (-D / 2.0, h),
            (D / 2.0, -h),
            (-D / 2.0, -h),
        ];
        assert!(pairs(&lattice, 2).is_empty());
    }
}
