//! The formation's neighbour rule, computed: who holds whom at d*, from positions alone.
//!
//! [`NeighbourTracker`] applies a [`NeighbourRule`] sample after sample (the Gabriel rule may have
//! hysteresis, so it remembers the previous sample's Gabriel edges) and yields, per sample, the
//! formation's edges (what the metrics score) and each robot's own neighbours (what the expert
//! holds at d*). The exact definition is [`GabrielRule`]'s. Everything here is pure: positions
//! in, edges out.
//!
//! Robot `i` can apply the rule from its own LIDAR: every robot that can veto one of its pairs
//! lies within that pair's length of it, so within sensing range, and `i`'s nearest robots are
//! the nearest it senses. The tracker computes all robots' views at once; for each robot the
//! result is what that robot computes from the robots within its range (the Gabriel state of a
//! pair is the same in both robots' views, since both decide it from the same witnesses).
//!
//! Cost per sample: `O(n^2 log n)` to sort each robot's robots in range, plus, per pair in range,
//! the witnesses closer than the pair's length (found nearest first, so a vetoed pair usually
//! stops at its first witness).

pub use formation_proto::{GabrielRule, NeighbourRule};

/// The pairs `(i, j)`, `i < j`, of all `n` robots, in lexicographic order.
pub fn all_pairs(n: usize) -> Vec<(usize, usize)> {
    (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect()
}

/// Applies a [`NeighbourRule`] to successive samples of one run.
#[derive(Debug, Clone)]
pub struct NeighbourTracker {
    rule: NeighbourRule,
    n: usize,
    /// Gabriel edges of the previous sample: `gabriel[i * n + j]`, symmetric.
    gabriel: Vec<bool>,
    /// Scratch for the next sample's Gabriel edges.
    next: Vec<bool>,
    /// Per robot, the robots within sensing range as `(squared distance, index)`, nearest first.
    in_range: Vec<Vec<(f64, usize)>>,
    own: Vec<Vec<usize>>,
    edges: Vec<(usize, usize)>,
    samples: u64,
}

impl NeighbourTracker {
    /// A tracker for a team of `n` robots that has seen no sample yet.
    pub fn new(rule: NeighbourRule, n: usize) -> NeighbourTracker {
        let gabriel = match rule {
            NeighbourRule::AllPairs => Vec::new(),
            NeighbourRule::Gabriel(_) => vec![false; n * n],
        };
        let (own, edges) = match rule {
            NeighbourRule::AllPairs => (
                (0..n)
                    .map(|i| (0..n).filter(|&j| j != i).collect())
                    .collect(),
                all_pairs(n),
            ),
            NeighbourRule::Gabriel(_) => (vec![Vec::new(); n], Vec::new()),
        };
        NeighbourTracker {
            rule,
            n,
            next: gabriel.clone(),
            gabriel,
            in_range: vec![Vec::new(); n],
            own,
            edges,
            samples: 0,
        }
    }

    /// The rule applied.
    pub fn rule(&self) -> &NeighbourRule {
        &self.rule
    }

    /// Team size.
    pub fn n_robots(&self) -> usize {
        self.n
    }

    /// Samples seen since creation or the last [`reset`](Self::reset).
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Forgets every sample: the next one is the first of a run.
    pub fn reset(&mut self) {
        self.gabriel.fill(false);
        self.samples = 0;
        if matches!(self.rule, NeighbourRule::Gabriel(_)) {
            self.edges.clear();
            self.own.iter_mut().for_each(Vec::clear);
        }
    }

    /// Takes the next sample's positions `(x, y)` (one per robot; a team of another size than
    /// the tracker's, or a non-finite position, just has no Gabriel pairs for the robots
    /// concerned) and updates [`edges`](Self::edges) and [`own_neighbours`](Self::own_neighbours).
    pub fn update(&mut self, positions: &[(f64, f64)]) {
        self.samples += 1;
        let NeighbourRule::Gabriel(rule) = self.rule else {
            return;
        };
        let n = self.n.min(positions.len());
        let range_sq = rule.sensing_range * rule.sensing_range;
        // A witness of a pair lies within sqrt(max(threshold, 1)) times the pair's length of both
        // robots: Gabriel pairs are sought only that much inside sensing range, so every witness
        // is sensed.
        let pair_range_sq = range_sq / rule.threshold.max(1.0);
        let d2 = |a: usize, b: usize| {
            let (dx, dy) = (
                positions[a].0 - positions[b].0,
                positions[a].1 - positions[b].1,
            );
            dx * dx + dy * dy
        };
        for i in 0..n {
            let list = &mut self.in_range[i];
            list.clear();
            list.extend(
                (0..n)
                    .filter(|&j| j != i)
                    .map(|j| (d2(i, j), j))
                    .filter(|&(d, _)| d <= range_sq),
            );
            list.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        }
        for i in n..self.n {
            self.in_range[i].clear();
        }

        self.next.fill(false);
        for i in 0..n {
            for &(dij, j) in &self.in_range[i] {
                if j < i || dij > pair_range_sq {
                    continue;
                }
                let was = self.gabriel[i * self.n + j];
                let needed = if was {
                    rule.keep_threshold()
                } else {
                    rule.threshold
                };
                // A witness below `needed` has d_ik^2 < needed d_ij^2: look only at those robots,
                // nearest first.
                let reach = needed.max(1.0) * dij;
                let vetoed = self.in_range[i]
                    .iter()
                    .take_while(|&&(dik, _)| dik < reach)
                    .any(|&(dik, k)| k != j && (dik + d2(j, k)) < needed * dij);
                if !vetoed && dij > 0.0 {
                    self.next[i * self.n + j] = true;
                    self.next[j * self.n + i] = true;
                }
            }
        }
        std::mem::swap(&mut self.gabriel, &mut self.next);

        let mut is_edge = vec![false; self.n * self.n];
        for i in 0..self.n {
            let own = &mut self.own[i];
            own.clear();
            own.extend((0..self.n).filter(|&j| self.gabriel[i * self.n + j]));
            for &(_, j) in self.in_range[i].iter().take(rule.nearest) {
                if !self.gabriel[i * self.n + j] {
                    own.push(j);
                }
            }
            own.sort_unstable();
            for &j in own.iter() {
                is_edge[i.min(j) * self.n + i.max(j)] = true;
            }
        }
        self.edges.clear();
        for i in 0..self.n {
            for j in i + 1..self.n {
                if is_edge[i * self.n + j] {
                    self.edges.push((i, j));
                }
            }
        }
    }

    /// The formation's edges `(i, j)`, `i < j`, lexicographic, at the last sample (all pairs
    /// under [`NeighbourRule::AllPairs`], whether or not a sample was given).
    pub fn edges(&self) -> &[(usize, usize)] {
        &self.edges
    }

    /// The robots robot `i` holds at d* at the last sample, ascending (empty for a robot out of
    /// the team).
    pub fn own_neighbours(&self, i: usize) -> &[usize] {
        self.own.get(i).map_or(&[], Vec::as_slice)
    }
}

/// The edges of a run's first sample under `rule` (a tracker that has seen only these poses).
pub fn first_sample_edges(
    rule: NeighbourRule,
    poses: &[formation_proto::Pose],
) -> Vec<(usize, usize)> {
    let mut tracker = NeighbourTracker::new(rule, poses.len());
    let positions: Vec<(f64, f64)> = poses.iter().map(|p| (p.x, p.y)).collect();
    tracker.update(&positions);
    tracker.edges().to_vec()
}

/// Whether the graph of `n` vertices with these edges is connected (true for `n <= 1`; edges
/// naming a vertex `>= n` are ignored).
pub fn is_connected(n: usize, edges: &[(usize, usize)]) -> bool {
    if n <= 1 {
        return true;
    }
    let mut adjacency = vec![Vec::new(); n];
    for &(i, j) in edges {
        if i < n && j < n {
            adjacency[i].push(j);
            adjacency[j].push(i);
        }
    }
    let mut seen = vec![false; n];
    let mut stack = vec![0];
    seen[0] = true;
    let mut count = 1;
    while let Some(v) = stack.pop() {
        for &w in &adjacency[v] {
            if !seen[w] {
                seen[w] = true;
                count += 1;
                stack.push(w);
            }
        }
    }
    count == n
}

/// Whether the robots at `positions` are connected through sensing range: the graph whose edges
/// join robots at most `range` apart is connected.
pub fn connected_within(positions: &[(f64, f64)], range: f64) -> bool {
    let range_sq = range * range;
    let n = positions.len();
    let edges: Vec<(usize, usize)> = all_pairs(n)
        .into_iter()
        .filter(|&(i, j)| {
            let (dx, dy) = (
                positions[i].0 - positions[j].0,
                positions[i].1 - positions[j].1,
            );
            dx * dx + dy * dy <= range_sq
        })
        .collect();
    is_connected(n, &edges)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gabriel() -> NeighbourRule {
        NeighbourRule::Gabriel(GabrielRule::with_range(10.0))
    }

    fn edges_of(rule: NeighbourRule, positions: &[(f64, f64)]) -> Vec<(usize, usize)> {
        let mut tracker = NeighbourTracker::new(rule, positions.len());
        tracker.update(positions);
        tracker.edges().to_vec()
    }

    /// Triangular lattice patch: rows of `per_row` robots, spacing `d`.
    fn lattice(rows: usize, per_row: usize, d: f64) -> Vec<(f64, f64)> {
        let mut p = Vec::new();
        for r in 0..rows {
            for c in 0..per_row {
                let shift = if r % 2 == 1 { 0.5 } else { 0.0 };
                p.push(((c as f64 + shift) * d, r as f64 * d * 3f64.sqrt() / 2.0));
            }
        }
        p
    }

    #[test]
    fn all_pairs_is_every_pair_whatever_the_positions() {
        let far = [(0.0, 0.0), (100.0, 0.0), (0.0, 100.0), (50.0, 50.0)];
        assert_eq!(
            edges_of(NeighbourRule::AllPairs, &far),
            vec![(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
        );
        let tracker = NeighbourTracker::new(NeighbourRule::AllPairs, 3);
        assert_eq!(tracker.own_neighbours(1), [0, 2]);
    }

    #[test]
    fn an_obtuse_triangle_loses_its_longest_side_but_keeps_it_by_the_nearest_rule() {
        // Robot 1 sits near the middle of 0-2: rho of (0, 2) is 0.5, below every threshold.
        let obtuse = [(0.0, 0.0), (1.0, 0.2), (2.0, 0.0)];
        let mut only_gabriel = GabrielRule::with_range(10.0);
        only_gabriel.nearest = 0;
        assert_eq!(
            edges_of(NeighbourRule::Gabriel(only_gabriel), &obtuse),
            vec![(0, 1), (1, 2)]
        );
        // With 2 nearest, every robot of three holds both others.
        assert_eq!(edges_of(gabriel(), &obtuse), vec![(0, 1), (0, 2), (1, 2)]);
    }

    #[test]
    fn a_formed_triangular_lattice_has_exactly_its_unit_edges() {
        let d = 1.5;
        let p = lattice(4, 4, d);
        let edges = edges_of(gabriel(), &p);
        assert!(!edges.is_empty());
        for &(i, j) in &edges {
            let len = (p[i].0 - p[j].0).hypot(p[i].1 - p[j].1);
            assert!((len - d).abs() < 1e-9, "edge ({i}, {j}) is {len} m long");
        }
        // Every unit-length pair is an edge.
        let unit = all_pairs(p.len())
            .into_iter()
            .filter(|&(i, j)| ((p[i].0 - p[j].0).hypot(p[i].1 - p[j].1) - d).abs() < 1e-9)
            .count();
        assert_eq!(edges.len(), unit);
        assert!(is_connected(p.len(), &edges));
    }

    /// A rhombus of unit sides whose diagonal (1, 3) has witness ratio `rho` (0 and 2 are its
    /// witnesses): short diagonal S with 2 / S^2 = rho, long diagonal L with S^2 + L^2 = 4.
    fn rhombus(rho: f64) -> [(f64, f64); 4] {
        let short = (2.0 / rho).sqrt();
        let long = (4.0 - short * short).sqrt();
        [
            (0.0, 0.0),
            (long / 2.0, -short / 2.0),
            (long, 0.0),
            (long / 2.0, short / 2.0),
        ]
    }

    #[test]
    fn a_square_has_no_diagonal_and_a_folding_rhombus_keeps_its_short_one_by_hysteresis() {
        // A perfect square: rho = 1 for both diagonals, on the Gabriel boundary, below 1.3.
        let square = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
        assert_eq!(
            edges_of(gabriel(), &square),
            vec![(0, 1), (0, 3), (1, 2), (2, 3)]
        );
        // With a hysteresis band of 0.4, the short diagonal becomes an edge at rho >= 1.3 ...
        let banded = NeighbourRule::Gabriel(GabrielRule {
            hysteresis: 0.4,
            ..GabrielRule::with_range(10.0)
        });
        let mut tracker = NeighbourTracker::new(banded, 4);
        tracker.update(&rhombus(1.35));
        assert!(tracker.edges().contains(&(1, 3)));
        // ... stays one down to 0.9 ...
        tracker.update(&rhombus(1.0));
        assert!(tracker.edges().contains(&(1, 3)));
        // ... which a fresh tracker does not add ...
        assert!(!edges_of(gabriel(), &rhombus(1.0)).contains(&(1, 3)));
        // ... and goes below 0.9.
        tracker.update(&rhombus(0.85));
        assert!(!tracker.edges().contains(&(1, 3)), "{:?}", tracker.edges());
        // reset forgets the history.
        tracker.update(&rhombus(1.35));
        tracker.reset();
        tracker.update(&rhombus(1.0));
        assert!(!tracker.edges().contains(&(1, 3)));
        assert_eq!(tracker.samples(), 1);
    }

    #[test]
    fn the_default_rule_is_memoryless_a_samples_edges_follow_from_its_positions_alone() {
        // What one scan cannot show (the past) must not decide an edge: the policy sees one scan.
        let mut tracker = NeighbourTracker::new(gabriel(), 4);
        for rho in [1.35, 1.29, 1.0, 1.31, 2.0, 1.2, 0.85, 1.3] {
            tracker.update(&rhombus(rho));
            assert_eq!(
                tracker.edges(),
                edges_of(gabriel(), &rhombus(rho)),
                "rho {rho}"
            );
            assert_eq!(tracker.edges().contains(&(1, 3)), rho >= 1.3, "rho {rho}");
        }
    }

    #[test]
    fn pairs_beyond_sensing_range_are_not_edges_and_far_robots_are_alone() {
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(2.0));
        let p = [(0.0, 0.0), (1.5, 0.0), (10.0, 0.0)];
        let mut tracker = NeighbourTracker::new(rule, 3);
        tracker.update(&p);
        assert_eq!(tracker.edges(), [(0, 1)]);
        assert!(tracker.own_neighbours(2).is_empty());
        assert!(!is_connected(3, tracker.edges()));
        assert!(!connected_within(&p, 2.0) && connected_within(&p, 8.5));
    }

    #[test]
    fn own_neighbours_are_gabriel_plus_nearest_and_edges_their_symmetric_union() {
        // A tight pair far from a third robot that sees the pair as its two nearest.
        let mut rule = GabrielRule::with_range(10.0);
        rule.nearest = 1;
        let p = [(0.0, 0.0), (0.8, 0.0), (5.0, 0.1), (5.0, 3.0)];
        let mut tracker = NeighbourTracker::new(NeighbourRule::Gabriel(rule), 4);
        tracker.update(&p);
        for i in 0..4 {
            for &j in tracker.own_neighbours(i) {
                assert!(tracker.edges().contains(&(i.min(j), i.max(j))));
            }
        }
        for &(i, j) in tracker.edges() {
            assert!(
                tracker.own_neighbours(i).contains(&j) || tracker.own_neighbours(j).contains(&i)
            );
        }
        // The witness 1 lies inside the circle on 0-2, so 0-2 is no Gabriel edge.
        assert!(!tracker.edges().contains(&(0, 2)));
    }

    #[test]
    fn the_rule_is_local_each_robot_decides_from_the_robots_in_its_range() {
        // Adding a robot beyond everyone's range changes nothing for the others.
        let rule = NeighbourRule::Gabriel(GabrielRule::with_range(4.0));
        let p = lattice(2, 3, 1.5);
        let mut q = p.clone();
        q.push((50.0, 50.0));
        let a = edges_of(rule, &p);
        let b = edges_of(rule, &q);
        assert_eq!(a, b);
    }

    #[test]
    fn non_finite_positions_do_not_panic() {
        let p = [(0.0, 0.0), (f64::NAN, 1.0), (1.0, 0.0)];
        let edges = edges_of(gabriel(), &p);
        assert_eq!(edges, vec![(0, 2)]);
        let mut tracker = NeighbourTracker::new(gabriel(), 5);
        tracker.update(&p);
        assert!(tracker.own_neighbours(4).is_empty() && tracker.own_neighbours(9).is_empty());
    }

    #[test]
    fn connectivity() {
        assert!(is_connected(0, &[]) && is_connected(1, &[]));
        assert!(is_connected(3, &[(0, 1), (1, 2)]));
        assert!(!is_connected(4, &[(0, 1), (2, 3)]));
        assert!(!is_connected(3, &[(0, 1), (1, 7)]));
    }
}
