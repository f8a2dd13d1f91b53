//! The numbers the figures draw, computed from run data without any plotting: formation and
//! orientation errors over time, wheel commands, paths, formation snapshots, equal-aspect ranges
//! and strip-plot jitter (the Fig. 9 quartiles come from `summary.json`). Everything here is pure and unit-tested; `figures` only maps it to pixels.

use std::ops::Range;

use formation_proto::{NeighbourRule, wrap_angle};
use formation_world::neighbours::NeighbourTracker;

use crate::input::Trajectory;

/// One line of a figure: a label and its finite `(x, y)` points, in data order.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points; samples with a non-finite coordinate are left out.
    pub points: Vec<(f64, f64)>,
}

impl Series {
    fn from_samples(label: String, samples: impl Iterator<Item = (f64, f64)>) -> Series {
        Series {
            label,
            points: samples
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect(),
        }
    }
}

/// Which wheel of a differential-drive robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wheel {
    /// The left wheel.
    Left,
    /// The right wheel.
    Right,
}

/// Robot `i` (0-based) as the paper numbers it: `robot 1`, `robot 2`, ...
pub fn robot_label(i: usize) -> String {
    format!("robot {}", i + 1)
}

/// The edge `(i, j)` (0-based) as `e₁₂` (subscript digits, 1-based), or `e(1,12)` when a robot
/// number has more than one digit.
pub fn edge_label(i: usize, j: usize) -> String {
    const SUBSCRIPTS: [char; 10] = ['₀', '₁', '₂', '₃', '₄', '₅', '₆', '₇', '₈', '₉'];
    if i < 9 && j < 9 {
        format!("e{}{}", SUBSCRIPTS[i + 1], SUBSCRIPTS[j + 1])
    } else {
        format!("e({},{})", i + 1, j + 1)
    }
}

/// The formation's edges at every sample: the trajectory's `edges` under all pairs, else the
/// run's neighbour rule applied sample after sample (as the metrics do).
pub fn edges_per_sample(traj: &Trajectory) -> Vec<Vec<(usize, usize)>> {
    match traj.neighbours {
        NeighbourRule::AllPairs => vec![traj.edges.clone(); traj.poses.len()],
        rule => {
            let mut tracker = NeighbourTracker::new(rule, traj.n_robots());
            traj.poses
                .iter()
                .map(|poses| {
                    let positions: Vec<(f64, f64)> = poses.iter().map(|p| (p.x, p.y)).collect();
                    tracker.update(&positions);
                    tracker.edges().to_vec()
                })
                .collect()
        }
    }
}

/// Relative formation error `e_ij(t) = |d_ij(t) - d*| / d*` in percent: one line per edge for the
/// paper's all-pairs formation; for a team whose edges change, two lines that aggregate over the
/// edges of each sample, the median and the maximum edge error.
pub fn formation_error_percent(traj: &Trajectory) -> Vec<Series> {
    if traj.neighbours != NeighbourRule::AllPairs {
        return aggregated_edge_error_percent(traj);
    }
    traj.edges
        .iter()
        .map(|&(i, j)| {
            Series::from_samples(
                edge_label(i, j),
                traj.times.iter().zip(&traj.poses).map(|(&t, poses)| {
                    let (a, b) = (poses[i], poses[j]);
                    (
                        t,
                        100.0 * ((a.x - b.x).hypot(a.y - b.y) - traj.d_star).abs() / traj.d_star,
                    )
                }),
            )
        })
        .collect()
}

/// The median and the maximum over the edges of each sample of the edge error, in percent.
fn aggregated_edge_error_percent(traj: &Trajectory) -> Vec<Series> {
    let edges = edges_per_sample(traj);
    let mut median = Vec::with_capacity(edges.len());
    let mut max = Vec::with_capacity(edges.len());
    for ((&t, poses), edges) in traj.times.iter().zip(&traj.poses).zip(&edges) {
        let mut errors: Vec<f64> = edges
            .iter()
            .map(|&(i, j)| {
                let (a, b) = (poses[i], poses[j]);
                100.0 * ((a.x - b.x).hypot(a.y - b.y) - traj.d_star).abs() / traj.d_star
            })
            .filter(|e| e.is_finite())
            .collect();
        if errors.is_empty() {
            continue;
        }
        errors.sort_by(f64::total_cmp);
        let n = errors.len();
        let mid = if n % 2 == 1 {
            errors[n / 2]
        } else {
            0.5 * (errors[n / 2 - 1] + errors[n / 2])
        };
        median.push((t, mid));
        max.push((t, errors[n - 1]));
    }
    vec![
        Series::from_samples("median edge".to_owned(), median.into_iter()),
        Series::from_samples("worst edge".to_owned(), max.into_iter()),
    ]
}

/// Signed orientation error `wrap(theta_i(t) - phi*(t))` of every robot \[rad\].
pub fn orientation_error(traj: &Trajectory) -> Vec<Series> {
    (0..traj.n_robots())
        .map(|i| {
            Series::from_samples(
                robot_label(i),
                traj.times
                    .iter()
                    .zip(&traj.phi_star)
                    .zip(&traj.poses)
                    .map(|((&t, &phi), poses)| (t, wrap_angle(poses[i].theta - phi))),
            )
        })
        .collect()
}

/// One wheel's applied command of every robot over time \[m/s\]; command `k` is drawn at `t_k`.
pub fn wheel_commands(traj: &Trajectory, wheel: Wheel) -> Vec<Series> {
    (0..traj.n_robots())
        .map(|i| {
            Series::from_samples(
                robot_label(i),
                traj.times.iter().zip(&traj.commands).map(|(&t, cmds)| {
                    let cmd = cmds[i];
                    (
                        t,
                        if wheel == Wheel::Left {
                            cmd.left
                        } else {
                            cmd.right
                        },
                    )
                }),
            )
        })
        .collect()
}

/// Every robot's path `(x, y)` \[m\].
pub fn paths(traj: &Trajectory) -> Vec<Series> {
    (0..traj.n_robots())
        .map(|i| {
            Series::from_samples(
                robot_label(i),
                traj.poses.iter().map(|poses| (poses[i].x, poses[i].y)),
            )
        })
        .collect()
}

/// Indices of the samples at `0, every_s, 2 every_s, ...` (the first sample at or after each
/// instant, within a thousandth of a step), as the paper draws the formation every 3 s.
pub fn snapshot_indices(times: &[f64], every_s: f64) -> Vec<usize> {
    let (Some(&start), Some(&end)) = (times.first(), times.last()) else {
        return Vec::new();
    };
    if !(every_s > 0.0 && start.is_finite() && end.is_finite()) {
        return Vec::new();
    }
    let slack = every_s * 1e-3;
    let mut indices = Vec::new();
    let mut m = 0_u32;
    let mut k = 0;
    loop {
        let instant = start + f64::from(m) * every_s;
        if instant > end + slack {
            break;
        }
        while k < times.len() && times[k] < instant - slack {
            k += 1;
        }
        if k == times.len() {
            break;
        }
        if indices.last() != Some(&k) {
            indices.push(k);
        }
        m += 1;
    }
    indices
}

/// A range covering the finite `values`, padded by `pad` of its span on both sides; `zero_based`
/// starts it at 0 when every value is non-negative. A constant (or empty) input gets a unit span.
pub fn padded_range(
    values: impl IntoIterator<Item = f64>,
    pad: f64,
    zero_based: bool,
) -> Range<f64> {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return 0.0..1.0;
    }
    let (lo, hi) = if hi - lo < 1e-12 {
        (lo - 0.5, hi + 0.5)
    } else {
        (lo, hi)
    };
    let span = hi - lo;
    let lo = if zero_based && lo >= 0.0 {
        0.0
    } else {
        lo - pad * span
    };
    lo..hi + pad * span
}

/// Ranges that show `x` and `y` at the same scale in a plot of `width_px` by `height_px`: the
/// tighter axis is widened about its centre.
pub fn equal_aspect(
    x: Range<f64>,
    y: Range<f64>,
    width_px: f64,
    height_px: f64,
) -> (Range<f64>, Range<f64>) {
    let (w, h) = (x.end - x.start, y.end - y.start);
    let metres_per_px = (w / width_px).max(h / height_px);
    let widen = |r: Range<f64>, px: f64| {
        let centre = 0.5 * (r.start + r.end);
        let half = 0.5 * metres_per_px * px;
        centre - half..centre + half
    };
    (widen(x, width_px), widen(y, height_px))
}

/// Vertices of a triangle marker for a robot at `(x, y)` heading `theta`, `size` long: its tip
/// points along the heading.
pub fn heading_triangle(x: f64, y: f64, theta: f64, size: f64) -> [(f64, f64); 3] {
    let at = |angle: f64, r: f64| (x + r * angle.cos(), y + r * angle.sin());
    let back = std::f64::consts::PI * 0.8;
    [
        at(theta, size * 0.6),
        at(theta + back, size * 0.45),
        at(theta - back, size * 0.45),
    ]
}

/// A deterministic horizontal offset in `[-0.5, 0.5)` for the `i`-th dot of a strip plot (a
/// low-discrepancy sequence, so dots spread evenly and a report is reproducible).
pub fn jitter(i: usize) -> f64 {
    const GOLDEN: f64 = 0.618_033_988_749_895;
    (i as f64 * GOLDEN).fract() - 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::{Pose, WheelCmd};

    /// A team of four under the Gabriel rule: two equilateral triangles of side `scale(k) d*`.
    fn team(scale: impl Fn(usize) -> f64) -> Trajectory {
        let mut t = traj();
        let h = 3f64.sqrt() / 2.0;
        for (k, poses) in t.poses.iter_mut().enumerate() {
            let s = t.d_star * scale(k);
            *poses = [(0.0, 0.0), (s, 0.0), (s / 2.0, s * h), (1.5 * s, s * h)]
                .iter()
                .map(|&(x, y)| Pose { x, y, theta: 0.0 })
                .collect();
        }
        t.commands = vec![vec![WheelCmd::default(); 4]; 2];
        t.neighbours =
            NeighbourRule::Gabriel(formation_world::neighbours::GabrielRule::with_range(10.0));
        t.edges = Vec::new();
        t
    }

    #[test]
    fn a_teams_edge_error_is_drawn_as_its_median_and_worst_edge_over_the_changing_edges() {
        let t = team(|k| [1.1, 1.0, 1.0][k]);
        let edges = edges_per_sample(&t);
        assert_eq!(edges.len(), 3);
        assert_eq!(edges[0], vec![(0, 1), (0, 2), (1, 2), (1, 3), (2, 3)]);
        let series = formation_error_percent(&t);
        let labels: Vec<&str> = series.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(labels, ["median edge", "worst edge"]);
        for s in &series {
            assert!(
                (s.points[0].1 - 10.0).abs() < 1e-9 && s.points[2].1.abs() < 1e-9,
                "{s:?}"
            );
        }
        // All pairs keeps one line per edge.
        assert_eq!(formation_error_percent(&traj()).len(), 3);
    }

    fn traj() -> Trajectory {
        let pose = |x: f64, y: f64, theta: f64| Pose { x, y, theta };
        Trajectory {
            dt: 1.0,
            d_star: 2.0,
            v_star: 0.7,
            edges: vec![(0, 1), (0, 2), (1, 2)],
            neighbours: formation_proto::NeighbourRule::AllPairs,
            times: vec![0.0, 1.0, 2.0],
            phi_star: vec![0.0, 0.0, 3.0],
            poses: vec![
                vec![
                    pose(0.0, 0.0, 0.1),
                    pose(3.0, 0.0, 0.0),
                    pose(0.0, 1.0, 0.0),
                ],
                vec![
                    pose(0.0, 0.0, 0.1),
                    pose(2.0, 0.0, 0.0),
                    pose(0.0, f64::NAN, 0.0),
                ],
                vec![
                    pose(0.0, 0.0, -3.0),
                    pose(2.5, 0.0, 0.0),
                    pose(0.0, 2.0, 0.0),
                ],
            ],
            commands: vec![
                vec![
                    WheelCmd {
                        left: 0.1,
                        right: 0.2
                    };
                    3
                ],
                vec![
                    WheelCmd {
                        left: 0.3,
                        right: f64::NAN
                    };
                    3
                ],
            ],
            collisions: vec![],
        }
    }

    #[test]
    fn formation_error_is_relative_percent_per_edge() {
        let series = formation_error_percent(&traj());
        assert_eq!(series.len(), 3);
        assert_eq!(series[0].label, "e₁₂");
        assert_eq!(series[0].points, vec![(0.0, 50.0), (1.0, 0.0), (2.0, 25.0)]);
        // Edge (0, 2) has a NaN position at t = 1: that sample is left out.
        assert_eq!(series[1].points, vec![(0.0, 50.0), (2.0, 0.0)]);
    }

    #[test]
    fn orientation_error_is_wrapped() {
        let series = orientation_error(&traj());
        assert!((series[0].points[0].1 - 0.1).abs() < 1e-12);
        // theta = -3, phi* = 3: the difference -6 wraps to 2 pi - 6.
        assert!((series[0].points[2].1 - (std::f64::consts::TAU - 6.0)).abs() < 1e-12);
        assert_eq!(series[1].points[2], (2.0, -3.0));
    }

    #[test]
    fn wheel_commands_follow_ticks() {
        let t = traj();
        let left = wheel_commands(&t, Wheel::Left);
        assert_eq!(left[2].points, vec![(0.0, 0.1), (1.0, 0.3)]);
        let right = wheel_commands(&t, Wheel::Right);
        assert_eq!(right[0].points, vec![(0.0, 0.2)], "NaN command left out");
        assert_eq!(
            paths(&t)[1].points,
            vec![(3.0, 0.0), (2.0, 0.0), (2.5, 0.0)]
        );
    }

    #[test]
    fn snapshots_every_three_seconds() {
        let times: Vec<f64> = (0..=200).map(|k| k as f64 * 0.05).collect();
        let idx = snapshot_indices(&times, 3.0);
        assert_eq!(idx, vec![0, 60, 120, 180]);
        // Rounding of k * dt must not skip an instant.
        let times: Vec<f64> = (0..=61).map(|k| k as f64 * 0.05 - 1e-12).collect();
        assert_eq!(snapshot_indices(&times, 3.0), vec![0, 60]);
        assert!(snapshot_indices(&[], 3.0).is_empty());
        assert_eq!(snapshot_indices(&[5.0], 3.0), vec![0]);
    }

    #[test]
    fn ranges() {
        assert_eq!(padded_range([1.0, 3.0], 0.5, false), 0.0..4.0);
        assert_eq!(padded_range([1.0, 3.0, f64::NAN], 0.5, true), 0.0..4.0);
        assert_eq!(padded_range([2.0], 0.0, false), 1.5..2.5);
        assert_eq!(padded_range([], 0.1, false), 0.0..1.0);
        let (x, y) = equal_aspect(0.0..10.0, 0.0..1.0, 500.0, 250.0);
        assert_eq!(x, 0.0..10.0);
        assert!(
            (y.start + 2.0).abs() < 1e-12 && (y.end - 3.0).abs() < 1e-12,
            "{y:?}"
        );
        assert!(((x.end - x.start) / 500.0 - (y.end - y.start) / 250.0).abs() < 1e-12);
    }

    #[test]
    fn triangle_points_along_heading() {
        let [tip, a, b] = heading_triangle(1.0, 1.0, std::f64::consts::FRAC_PI_2, 1.0);
        assert!((tip.0 - 1.0).abs() < 1e-12 && (tip.1 - 1.6).abs() < 1e-12);
        assert!(a.1 < 1.0 && b.1 < 1.0);
    }

    #[test]
    fn jitter_is_bounded_and_spread() {
        let offsets: Vec<f64> = (0..50).map(jitter).collect();
        assert!(offsets.iter().all(|o| (-0.5..0.5).contains(o)));
        assert!(offsets.iter().any(|&o| o < -0.3) && offsets.iter().any(|&o| o > 0.3));
    }
}
