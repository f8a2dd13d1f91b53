//! Uniform grid hashing of the robots' positions: which robots may lie within a given distance of a
//! point, in time proportional to how many are near rather than to how many there are.
//!
//! The plane is cut into square cells of a fixed side; each robot is filed under the cell holding its
//! centre, and the cells live in a hash table of about two buckets per robot, so the grid costs `O(N)`
//! to build whatever the world's extent. A query visits the cells overlapping the square around the
//! point, and within them only the robots filed under exactly those cells, so each robot is visited at
//! most once per query.
//!
//! The grid only narrows down candidates, it decides nothing: callers apply their own exact test to
//! each visited robot. Its one promise is that it never leaves out a robot the caller's test could
//! accept (see [`SpatialGrid::for_each_near`]). Robots with a coordinate beyond [`GRIDDED_LIMIT`] or
//! not finite, and every robot of a grid whose cell side is unusable, are kept on a side list that every
//! query visits, which keeps the promise without any reasoning about rounding far from the origin.

use formation_proto::Pose;

/// Largest absolute coordinate \[m\] of a robot filed in a cell; farther (or non-finite) robots are
/// visited by every query. At `1e9` m a coordinate still resolves `1.2e-7` m, well inside the slack
/// that queries add to their reach.
pub const GRIDDED_LIMIT: f64 = 1e9;

/// Cell sides \[m\] the grid accepts: from these, cell coordinates of gridded robots fit an `i64` and a
/// query spans few cells. A grid asked for another side files every robot on the side list.
const USABLE_CELL_SIDES: std::ops::RangeInclusive<f64> = 1e-6..=1e12;

/// One filed robot: its cell (unused on the side list), its index among the poses, and its position
/// (kept here so that a query reads memory in bucket order, not in robot order).
#[derive(Debug, Clone, Copy)]
struct Entry {
    cell: (i64, i64),
    index: usize,
    x: f64,
    y: f64,
}

/// The robots' positions hashed into square cells. Build it with [`SpatialGrid::rebuild`] (which reuses
/// the buffers of the previous build) and query it with [`SpatialGrid::for_each_near`].
#[derive(Clone, Default)]
pub struct SpatialGrid {
    /// Side of a cell \[m\]; `NaN` before the first build.
    cell_side: f64,
    /// `log2` of the number of buckets.
    bucket_bits: u32,
    /// `entries[bucket_starts[b]..bucket_starts[b + 1]]` are the robots of bucket `b`, in increasing
    /// robot index.
    bucket_starts: Vec<usize>,
    entries: Vec<Entry>,
    /// The bucket of each robot during a build (`usize::MAX` for side-listed robots).
    bucket_of_robot: Vec<usize>,
    /// Robots no query can rule out: beyond [`GRIDDED_LIMIT`], non-finite, or all of them when the cell
    /// side is unusable. In increasing robot index.
    side_list: Vec<Entry>,
}

impl std::fmt::Debug for SpatialGrid {
    /// The grid's shape, not its contents (thousands of entries in a large team).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpatialGrid")
            .field("cell_side", &self.cell_side)
            .field("buckets", &self.bucket_starts.len().saturating_sub(1))
            .field("gridded", &self.entries.len())
            .field("side_listed", &self.side_list.len())
            .finish()
    }
}

impl SpatialGrid {
    /// An empty grid; [`SpatialGrid::rebuild`] fills it.
    pub fn new() -> SpatialGrid {
        SpatialGrid {
            cell_side: f64::NAN,
            ..SpatialGrid::default()
        }
    }

    /// Files the positions of `poses` (robot `i` is `poses[i]`) in cells of side `cell_side` \[m\],
    /// replacing whatever the grid held. `O(N)`; allocates only when the team grew.
    pub fn rebuild(&mut self, poses: &[Pose], cell_side: f64) {
        self.cell_side = cell_side;
        self.entries.clear();
        self.side_list.clear();
        self.bucket_of_robot.clear();
        let usable = USABLE_CELL_SIDES.contains(&cell_side);
        // About two buckets per robot keeps buckets short without a sparse table.
        self.bucket_bits = (2 * poses.len())
            .max(1)
            .next_power_of_two()
            .trailing_zeros();
        let buckets = 1_usize << self.bucket_bits;
        self.bucket_starts.clear();
        self.bucket_starts.resize(buckets + 1, 0);

        // Counting sort by bucket: count, prefix-sum, then place in robot order so that each bucket
        // lists its robots in increasing index.
        for (index, pose) in poses.iter().enumerate() {
            let bucket = if usable && is_gridded(pose.x, pose.y) {
                let bucket = self.bucket(self.cell_of(pose.x, pose.y));
                self.bucket_starts[bucket + 1] += 1;
                bucket
            } else {
                self.side_list.push(Entry {
                    cell: (0, 0),
                    index,
                    x: pose.x,
                    y: pose.y,
                });
                usize::MAX
            };
            self.bucket_of_robot.push(bucket);
        }
        for b in 0..buckets {
            self.bucket_starts[b + 1] += self.bucket_starts[b];
        }
        let gridded = self.bucket_starts[buckets];
        let placeholder = Entry {
            cell: (0, 0),
            index: usize::MAX,
            x: f64::NAN,
            y: f64::NAN,
        };
        self.entries.resize(gridded, placeholder);
        // `bucket_starts[b]` serves as the fill cursor of bucket `b`, then is shifted back below.
        for (index, (pose, &bucket)) in poses.iter().zip(&self.bucket_of_robot).enumerate() {
            if bucket == usize::MAX {
                continue;
            }
            let slot = self.bucket_starts[bucket];
            self.entries[slot] = Entry {
                cell: self.cell_of(pose.x, pose.y),
                index,
                x: pose.x,
                y: pose.y,
            };
            self.bucket_starts[bucket] += 1;
        }
        // Each cursor now sits at the next bucket's start: shift them back by one bucket.
        for b in (1..=buckets).rev() {
            self.bucket_starts[b] = self.bucket_starts[b - 1];
        }
        self.bucket_starts[0] = 0;
    }

    /// Calls `visit(index, x, y)` for every robot filed by the last [`SpatialGrid::rebuild`] whose
    /// position could have `|x - px| <= reach` and `|y - py| <= reach`, each exactly once, in no
    /// particular order; it may call it for farther robots too, which the caller's own test rejects.
    /// `x, y` are the robot's pose coordinates, bit for bit.
    ///
    /// The promise, for a finite `reach >= 0`: every robot whose offsets `x - px` and `y - py`, as
    /// computed in `f64`, are both at most `reach * (1 + 1e-9) + 1e-7` in absolute value is visited.
    /// When `(px, py)` itself is not gridded (beyond [`GRIDDED_LIMIT`] or not finite), every robot is.
    ///
    /// A query spans about `(2 reach / cell_side + 2)^2` cells, so grids are built with a cell side
    /// near the reach they are queried with; when the span would exceed the number of robots, the
    /// query visits every robot instead.
    pub fn for_each_near(
        &self,
        px: f64,
        py: f64,
        reach: f64,
        mut visit: impl FnMut(usize, f64, f64),
    ) {
        for entry in &self.side_list {
            visit(entry.index, entry.x, entry.y);
        }
        // Slack over the promised `reach * (1 + 1e-9) + 1e-7`: the offsets, and `px -+ slack_reach`
        // below, are rounded by at most an ulp of `GRIDDED_LIMIT + slack_reach` (2.2e-7 m plus
        // 2.2e-16 of the reach), so a robot within the promised reach lies inside the rounded square,
        // and division and `floor`, being monotone, keep it inside the square's range of cells.
        let slack_reach = reach * (1.0 + 2e-9) + 1e-6;
        let cells_per_side = 2.0 * slack_reach / self.cell_side + 2.0;
        let query_is_local = is_gridded(px, py)
            && USABLE_CELL_SIDES.contains(&self.cell_side)
            && cells_per_side * cells_per_side <= self.entries.len() as f64;
        if !query_is_local {
            for entry in &self.entries {
                visit(entry.index, entry.x, entry.y);
            }
            return;
        }
        let (low_x, low_y) = self.cell_of(px - slack_reach, py - slack_reach);
        let (high_x, high_y) = self.cell_of(px + slack_reach, py + slack_reach);
        for cell_y in low_y..=high_y {
            for cell_x in low_x..=high_x {
                let cell = (cell_x, cell_y);
                let bucket = self.bucket(cell);
                let in_bucket =
                    &self.entries[self.bucket_starts[bucket]..self.bucket_starts[bucket + 1]];
                for entry in in_bucket.iter().filter(|entry| entry.cell == cell) {
                    visit(entry.index, entry.x, entry.y);
                }
            }
        }
    }

    /// The cell holding `(x, y)`; monotone in each coordinate.
    fn cell_of(&self, x: f64, y: f64) -> (i64, i64) {
        (
            floor_to_i64(x / self.cell_side),
            floor_to_i64(y / self.cell_side),
        )
    }

    /// The bucket of `cell`: a multiplicative hash of both coordinates, top bits.
    fn bucket(&self, (cell_x, cell_y): (i64, i64)) -> usize {
        if self.bucket_bits == 0 {
            return 0;
        }
        let mixed = (cell_x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (cell_y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        (mixed.wrapping_mul(0xFF51_AFD7_ED55_8CCD) >> (64 - self.bucket_bits)) as usize
    }
}

/// `x.floor() as i64` for `|x| < 2^62`, without a libm call on targets lacking a rounding
/// instruction (x86-64 before SSE4.1); saturating and monotone beyond, 0 for NaN.
pub(crate) fn floor_to_i64(x: f64) -> i64 {
    let truncated = x as i64;
    if truncated as f64 > x {
        truncated.saturating_sub(1)
    } else {
        truncated
    }
}

/// Whether a robot at `(x, y)` is filed in a cell: both coordinates finite and within
/// [`GRIDDED_LIMIT`].
fn is_gridded(x: f64, y: f64) -> bool {
    x.abs() <= GRIDDED_LIMIT && y.abs() <= GRIDDED_LIMIT
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_layouts::lattice;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn pose(x: f64, y: f64) -> Pose {
        Pose { x, y, theta: 0.0 }
    }

    /// Every robot a query visits, sorted, after checking that none is visited twice and that the
    /// positions handed out are the poses' bits.
    fn visited(grid: &SpatialGrid, poses: &[Pose], (px, py): (f64, f64), reach: f64) -> Vec<usize> {
        let mut seen = Vec::new();
        grid.for_each_near(px, py, reach, |index, x, y| {
            assert_eq!(x.to_bits(), poses[index].x.to_bits());
            assert_eq!(y.to_bits(), poses[index].y.to_bits());
            seen.push(index);
        });
        seen.sort_unstable();
        let count = seen.len();
        seen.dedup();
        assert_eq!(seen.len(), count, "a robot was visited twice");
        seen
    }

    /// The robots the promise of `for_each_near` covers.
    fn promised(poses: &[Pose], (px, py): (f64, f64), reach: f64) -> Vec<usize> {
        let bound = reach * (1.0 + 1e-9) + 1e-7;
        (0..poses.len())
            .filter(|&i| (poses[i].x - px).abs() <= bound && (poses[i].y - py).abs() <= bound)
            .collect()
    }

    fn assert_keeps_its_promise(
        poses: &[Pose],
        cell_side: f64,
        queries: &[(f64, f64)],
        reach: f64,
    ) {
        let mut grid = SpatialGrid::new();
        grid.rebuild(poses, cell_side);
        for &query in queries {
            let seen = visited(&grid, poses, query, reach);
            for index in promised(poses, query, reach) {
                assert!(
                    seen.binary_search(&index).is_ok(),
                    "robot {index} at {:?} missed by a query at {query:?}, reach {reach}, cells {cell_side}",
                    poses[index]
                );
            }
        }
    }

    #[test]
    fn a_query_visits_every_robot_within_reach_once() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for (n, spread, cell_side, reach) in [
            (1, 5.0, 10.25, 10.25),
            (50, 5.0, 10.25, 10.25),
            (500, 60.0, 10.25, 10.25),
            (500, 60.0, 5.0, 10.25),
            (300, 3.0, 0.5, 0.5),
            (300, 30.0, 0.5, 0.5),
        ] {
            let poses: Vec<Pose> = (0..n)
                .map(|_| {
                    pose(
                        spread * (2.0 * rng.random::<f64>() - 1.0),
                        spread * (2.0 * rng.random::<f64>() - 1.0),
                    )
                })
                .collect();
            let mut queries: Vec<(f64, f64)> = poses.iter().map(|p| (p.x, p.y)).collect();
            queries.extend((0..50).map(|_| {
                (
                    spread * (2.0 * rng.random::<f64>() - 1.0),
                    spread * rng.random::<f64>(),
                )
            }));
            assert_keeps_its_promise(&poses, cell_side, &queries, reach);
        }
    }

    #[test]
    fn robots_at_exactly_the_reach_and_on_cell_boundaries_are_visited() {
        // Robots at multiples of the cell side, and one cell side plus or minus an ulp from a query.
        let cell = 10.25_f64;
        let mut poses = Vec::new();
        for (_, _, x, y) in lattice(cell, 4) {
            poses.push(pose(x, y));
            poses.push(pose(f64::from_bits(x.to_bits() + 1), y));
            poses.push(pose(x, f64::from_bits(y.to_bits().wrapping_sub(1))));
        }
        let queries: Vec<(f64, f64)> = poses
            .iter()
            .map(|p| (p.x, p.y))
            .chain([(0.5 * cell, 0.5 * cell), (3.3, -7.1)])
            .collect();
        assert_keeps_its_promise(&poses, cell, &queries, cell);
        assert_keeps_its_promise(&poses, cell, &queries, 0.0);
    }

    #[test]
    fn far_and_non_finite_robots_are_visited_by_every_query() {
        let mut poses = vec![
            pose(0.0, 0.0),
            pose(2e9, 0.0),
            pose(1e9, -1e9),
            pose(f64::NAN, 1.0),
            pose(f64::INFINITY, f64::NEG_INFINITY),
            pose(3.0, 4.0),
            pose(1e9 + 1.0, 0.0),
        ];
        // Enough robots elsewhere that queries stay local rather than visiting everyone.
        poses.extend((0..40).map(|i| pose(500.0 + i as f64, 500.0)));
        let mut grid = SpatialGrid::new();
        grid.rebuild(&poses, 10.0);
        // 2e9, NaN, infinite and 1e9 + 1 are side-listed; 1e9 is gridded (at the limit).
        assert_eq!(
            visited(&grid, &poses, (0.0, 0.0), 10.0),
            vec![0, 1, 3, 4, 5, 6]
        );
        assert_eq!(
            visited(&grid, &poses, (1e9, -1e9), 10.0),
            vec![1, 2, 3, 4, 6]
        );
        // A query from a non-gridded point visits everyone.
        let everyone: Vec<usize> = (0..poses.len()).collect();
        assert_eq!(visited(&grid, &poses, (f64::NAN, 0.0), 10.0), everyone);
        assert_eq!(visited(&grid, &poses, (5e9, 0.0), 10.0), everyone);
    }

    #[test]
    fn an_unusable_cell_side_or_a_huge_reach_visits_everyone() {
        let poses: Vec<Pose> = (0..20).map(|i| pose(i as f64 * 100.0, 0.0)).collect();
        let everyone: Vec<usize> = (0..20).collect();
        for cell_side in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e-9, 1e13] {
            let mut grid = SpatialGrid::new();
            grid.rebuild(&poses, cell_side);
            assert_eq!(
                visited(&grid, &poses, (0.0, 0.0), 1.0),
                everyone,
                "cells {cell_side}"
            );
        }
        let mut grid = SpatialGrid::new();
        grid.rebuild(&poses, 1.0);
        assert_eq!(visited(&grid, &poses, (0.0, 0.0), 1e300), everyone);
        assert_eq!(visited(&grid, &poses, (0.0, 0.0), 1.0), vec![0]);
    }

    #[test]
    fn rebuilding_replaces_the_previous_contents() {
        let spread_out = |offset: f64| -> Vec<Pose> {
            (0..40)
                .map(|i| pose(offset + 100.0 * i as f64, 0.0))
                .collect()
        };
        let mut grid = SpatialGrid::new();
        let before = spread_out(0.0);
        grid.rebuild(&before, 5.0);
        assert_eq!(visited(&grid, &before, (0.0, 0.0), 5.0), vec![0]);
        let after = spread_out(50.0);
        grid.rebuild(&after, 5.0);
        assert!(visited(&grid, &after, (0.0, 0.0), 5.0).is_empty());
        assert_eq!(visited(&grid, &after, (150.0, 0.0), 5.0), vec![1]);
        grid.rebuild(&[], 5.0);
        assert!(visited(&grid, &[], (0.0, 0.0), 5.0).is_empty());
    }

    #[test]
    fn floor_to_i64_is_floor_and_saturates_monotonically() {
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.9999999,
            -2.0000001,
            1e15 + 0.5,
            -1e15 - 0.5,
        ] {
            assert_eq!(floor_to_i64(x), x.floor() as i64, "{x}");
        }
        assert_eq!(floor_to_i64(f64::NAN), 0);
        assert_eq!(floor_to_i64(1e300), i64::MAX);
        assert_eq!(floor_to_i64(-1e300), i64::MIN);
        assert_eq!(floor_to_i64(f64::NEG_INFINITY), i64::MIN);
    }
}
