//! Smooth pair weights: the Gabriel rule's yes-or-no made continuous in a pair's witness ratio.
//!
//! The scored neighbour rule ([`GabrielRule`]) makes a pair an edge when its witness ratio
//! `rho_ij = min_k (d_ik² + d_jk²) / d_ij²` reaches the rule's threshold (1.3 by default). A
//! teacher that holds exactly those pairs gives two very different labels to two images that
//! differ by a centimetre across the threshold, and a network trained on both learns their
//! average. Weighted, robot `i` holds each pair in range with
//! `w(rho) = smoothstep((rho - low) / (high - low))` (0 below `low`, 1 above `high`, continuous
//! with its slope), so the label is one continuous function of the positions the robot senses.
//! A triangular lattice's edge (`rho = 2`) and a square's diagonal (`rho = 1`) keep their
//! weights 1 and 0 for any band inside (1, 2), so the formation the law converges to is the
//! hard rule's.
//!
//! As under the hard rule, robot `i` decides from the robots within the rule's sensing range,
//! pairs are sought only where every witness that could lower their weight is sensed, and its
//! `nearest` robots in range are always held with weight 1. Everything here is pure: positions
//! in, weights out.

use formation_proto::GabrielRule;

/// Robot `i`'s weighted neighbours: `(j, w)` with `0 < w <= 1`, ascending in `j`.
pub type WeightedNeighbours = Vec<(usize, f64)>;

/// `3t² - 2t³` on `t` clamped to [0, 1].
fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The weight of a pair with witness ratio `rho` over the band `[low, high]` (`low < high`).
pub fn pair_weight(rho: f64, [low, high]: [f64; 2]) -> f64 {
    smoothstep((rho - low) / (high - low))
}

/// Every robot's weighted neighbours under `rule` with the weight band `band`, for positions
/// `(x, y)` (a non-finite position gets no neighbour and is no one's neighbour), into `out`
/// (resized to one entry per robot).
pub fn weighted_neighbours(
    positions: &[(f64, f64)],
    rule: &GabrielRule,
    band: [f64; 2],
    out: &mut Vec<WeightedNeighbours>,
) {
    let n = positions.len();
    out.resize_with(n, Vec::new);
    out.iter_mut().for_each(Vec::clear);
    let range_sq = rule.sensing_range * rule.sensing_range;
    // Every witness of weight-lowering ratio (< high) lies within sqrt(high) times the pair's
    // length of both robots: pairs are weighed only that far inside sensing range.
    let pair_range_sq = range_sq / band[1].max(1.0);
    let finite = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let d2 = |a: usize, b: usize| {
        let (dx, dy) = (
            positions[a].0 - positions[b].0,
            positions[a].1 - positions[b].1,
        );
        dx * dx + dy * dy
    };
    let mut in_range: Vec<(f64, usize)> = Vec::with_capacity(n);
    for i in 0..n {
        if !finite(&positions[i]) {
            continue;
        }
        in_range.clear();
        in_range.extend(
            (0..n)
                .filter(|&j| j != i && finite(&positions[j]))
                .map(|j| (d2(i, j), j))
                .filter(|&(d, _)| d <= range_sq),
        );
        in_range.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let own = &mut out[i];
        for (rank, &(dij, j)) in in_range.iter().enumerate() {
            let weight = if rank < rule.nearest {
                1.0
            } else if dij > pair_range_sq || dij <= 0.0 {
                0.0
            } else {
                let rho = in_range
                    .iter()
                    .filter(|&&(_, k)| k != j)
                    .map(|&(dik, k)| (dik + d2(j, k)) / dij)
                    .fold(f64::INFINITY, f64::min);
                pair_weight(rho, band)
            };
            if weight > 0.0 {
                own.push((j, weight));
            }
        }
        own.sort_unstable_by_key(|&(j, _)| j);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule() -> GabrielRule {
        GabrielRule::with_range(10.0)
    }

    /// A rhombus of unit sides whose diagonal (1, 3) has witness ratio `rho` (0 and 2 are its
    /// witnesses): short diagonal S with 2 / S² = rho, long diagonal L with S² + L² = 4.
    fn rhombus(rho: f64) -> Vec<(f64, f64)> {
        let s = (2.0 / rho).sqrt();
        let l = (4.0 - s * s).sqrt();
        vec![
            (0.0, l / 2.0),
            (-s / 2.0, 0.0),
            (0.0, -l / 2.0),
            (s / 2.0, 0.0),
        ]
    }

    fn weight_of(out: &[WeightedNeighbours], i: usize, j: usize) -> f64 {
        out[i]
            .iter()
            .find(|&&(k, _)| k == j)
            .map_or(0.0, |&(_, w)| w)
    }

    #[test]
    fn the_weight_is_zero_below_the_band_one_above_and_smooth_between() {
        let band = [1.1, 1.5];
        assert_eq!(pair_weight(1.0, band), 0.0);
        assert_eq!(pair_weight(1.1, band), 0.0);
        assert_eq!(pair_weight(1.5, band), 1.0);
        assert_eq!(pair_weight(2.0, band), 1.0);
        assert!((pair_weight(1.3, band) - 0.5).abs() < 1e-12);
        // Monotone and continuous: no step larger than the slope allows.
        let samples: Vec<f64> = (0..=400)
            .map(|i| pair_weight(1.0 + i as f64 * 0.0025, band))
            .collect();
        assert!(
            samples
                .windows(2)
                .all(|w| w[1] >= w[0] && w[1] - w[0] < 0.01)
        );
    }

    #[test]
    fn a_diagonal_weighs_by_its_witness_ratio_and_the_sides_weigh_one() {
        let rule = GabrielRule {
            nearest: 0,
            ..rule()
        };
        let band = [1.1, 1.5];
        let mut out = Vec::new();
        for rho in [1.0, 1.2, 1.3, 1.45, 1.9] {
            weighted_neighbours(&rhombus(rho), &rule, band, &mut out);
            let expected = pair_weight(rho, band);
            assert!((weight_of(&out, 1, 3) - expected).abs() < 1e-9, "rho {rho}");
            assert!(
                (weight_of(&out, 3, 1) - expected).abs() < 1e-9,
                "symmetric at rho {rho}"
            );
            // The long diagonal (0, 2) has the short one's ends as witnesses inside its circle.
            assert_eq!(weight_of(&out, 0, 2), 0.0, "rho {rho}");
            // A side's witness ratio is 1 + min(S², L²) = 1 + 2 / rho >= 2 for rho <= 2.
            for (i, j) in [(0, 1), (1, 2), (2, 3), (3, 0)] {
                assert_eq!(weight_of(&out, i, j), 1.0, "side {i}-{j} at rho {rho}");
            }
        }
    }

    #[test]
    fn the_nearest_robots_are_held_whatever_their_ratio_and_far_robots_are_not() {
        let band = [1.1, 1.5];
        let mut out = Vec::new();
        // Three robots on a line: the middle one vetoes the outer pair (rho = 0.5).
        let line = [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)];
        let strict = GabrielRule {
            nearest: 0,
            ..rule()
        };
        weighted_neighbours(&line, &strict, band, &mut out);
        assert_eq!(weight_of(&out, 0, 2), 0.0);
        let two_nearest = rule();
        weighted_neighbours(&line, &two_nearest, band, &mut out);
        assert_eq!(weight_of(&out, 0, 2), 1.0);
        // Out of sensing range: no neighbour at all, and a NaN position is no one's neighbour.
        let far = [(0.0, 0.0), (20.0, 0.0), (f64::NAN, 0.0)];
        weighted_neighbours(&far, &two_nearest, band, &mut out);
        assert!(out.iter().all(Vec::is_empty));
    }
}
