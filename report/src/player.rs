//! The data of a run's player: the robots' poses, the neighbour graph and each edge's error over
//! time, decimated to at most [`MAX_PLAYER_FRAMES`] frames and written as compact JSON that the
//! page embeds (`<script type="application/json">`) and the page's inline player script draws on
//! a `<canvas>`.
//!
//! The edges are the run's own: every pair under all pairs, else the world's neighbour rule
//! (`formation_world::neighbours`) applied to every recorded sample, as the metrics do
//! ([`crate::series::edges_per_sample`]), before the frames are picked. Pure: no I/O.

use std::fmt::Write as _;

use formation_proto::Pose;

use crate::figures::ROBOT_COLORS;
use crate::input::Trajectory;
use crate::series::edges_per_sample;

/// At most this many frames of a run are embedded (a 60 s run at 20 Hz keeps every 4th sample:
/// 0.2 s apart; the player interpolates the poses between them).
pub const MAX_PLAYER_FRAMES: usize = 400;

/// Version of the embedded JSON (read by the page's own script only).
pub const PLAYER_DATA_VERSION: u32 = 1;

/// One frame: a sample of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayerFrame {
    /// Sample time \[s\].
    pub time: f64,
    /// The robots' poses.
    pub poses: Vec<Pose>,
    /// The formation's edges at this sample, `(i, j, error)` with the relative error
    /// `|d_ij - d*| / d*` in percent (NaN when a pose is not finite).
    pub edges: Vec<(usize, usize, f64)>,
}

/// What the player of one run shows.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayerData {
    /// Robots in the team.
    pub robots: usize,
    /// Desired distance \[m\].
    pub d_star: f64,
    /// Every `stride`-th sample is a frame (1: every sample).
    pub stride: usize,
    /// Samples in the run log.
    pub samples: usize,
    /// The frames, in time order; the run's last sample is always the last frame.
    pub frames: Vec<PlayerFrame>,
}

/// The stride that keeps at most `max_frames` of `samples` (the last sample is added when the
/// stride skips it, hence the `- 1`).
pub fn frame_stride(samples: usize, max_frames: usize) -> usize {
    if samples <= max_frames || max_frames < 2 {
        1
    } else {
        (samples - 1).div_ceil(max_frames - 1)
    }
}

/// The relative edge error `|d_ij - d*| / d*` in percent.
fn edge_error_percent(a: Pose, b: Pose, d_star: f64) -> f64 {
    100.0 * ((a.x - b.x).hypot(a.y - b.y) - d_star).abs() / d_star
}

/// The player data of `traj`: at most [`MAX_PLAYER_FRAMES`] frames, first and last sample kept.
pub fn player_data(traj: &Trajectory) -> PlayerData {
    let samples = traj.poses.len().min(traj.times.len());
    let stride = frame_stride(samples, MAX_PLAYER_FRAMES);
    let edges = edges_per_sample(traj);
    let mut picked: Vec<usize> = (0..samples).step_by(stride).collect();
    if samples > 0 && picked.last() != Some(&(samples - 1)) {
        picked.push(samples - 1);
    }
    let frames = picked
        .into_iter()
        .map(|k| {
            let poses = traj.poses[k].clone();
            let frame_edges = edges
                .get(k)
                .map(|edges| {
                    edges
                        .iter()
                        .filter(|&&(i, j)| i < poses.len() && j < poses.len())
                        .map(|&(i, j)| (i, j, edge_error_percent(poses[i], poses[j], traj.d_star)))
                        .collect()
                })
                .unwrap_or_default();
            PlayerFrame {
                time: traj.times[k],
                poses,
                edges: frame_edges,
            }
        })
        .collect();
    PlayerData {
        robots: traj.n_robots(),
        d_star: traj.d_star,
        stride,
        samples,
        frames,
    }
}

/// `value` with `decimals` decimals and no trailing zeros, or `null` when it is not finite (JSON
/// has no NaN).
fn json_number(out: &mut String, value: f64, decimals: usize) {
    if !value.is_finite() {
        out.push_str("null");
        return;
    }
    let text = format!("{value:.decimals$}");
    let text = if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.')
    } else {
        &text
    };
    out.push_str(if text == "-0" { "0" } else { text });
}

/// The JSON the page embeds: `{"version", "robots", "d_star", "stride", "samples", "colors",
/// "t": [times], "pose": [[x, y, θ, x, y, θ, ...] per frame], "edges": [[i, j, error %, ...] per
/// frame]}`; positions in mm precision, headings in mrad, errors in 0.1 %. Numbers only (and
/// fixed keys), so it cannot close its `<script>` element.
pub fn player_json(data: &PlayerData) -> String {
    let mut out = String::with_capacity(64 + data.frames.len() * data.robots * 30);
    let _ = write!(
        out,
        "{{\"version\":{PLAYER_DATA_VERSION},\"robots\":{},\"stride\":{},\"samples\":{},\"d_star\":",
        data.robots, data.stride, data.samples
    );
    json_number(&mut out, data.d_star, 4);
    out.push_str(",\"colors\":[");
    for (k, c) in ROBOT_COLORS.iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        let _ = write!(out, "\"#{:02x}{:02x}{:02x}\"", c.0, c.1, c.2);
    }
    out.push_str("],\"t\":[");
    for (k, frame) in data.frames.iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        json_number(&mut out, frame.time, 3);
    }
    out.push_str("],\"pose\":[");
    for (k, frame) in data.frames.iter().enumerate() {
        out.push_str(if k > 0 { ",[" } else { "[" });
        for (r, pose) in frame.poses.iter().enumerate() {
            if r > 0 {
                out.push(',');
            }
            json_number(&mut out, pose.x, 3);
            out.push(',');
            json_number(&mut out, pose.y, 3);
            out.push(',');
            json_number(&mut out, pose.theta, 3);
        }
        out.push(']');
    }
    out.push_str("],\"edges\":[");
    for (k, frame) in data.frames.iter().enumerate() {
        out.push_str(if k > 0 { ",[" } else { "[" });
        for (e, &(i, j, error)) in frame.edges.iter().enumerate() {
            if e > 0 {
                out.push(',');
            }
            let _ = write!(out, "{i},{j},");
            json_number(&mut out, error, 1);
        }
        out.push(']');
    }
    out.push_str("]}");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::NeighbourRule;
    use formation_world::neighbours::GabrielRule;

    fn line_of_robots(n: usize, samples: usize) -> Trajectory {
        let times: Vec<f64> = (0..samples).map(|k| k as f64 * 0.05).collect();
        let poses = times
            .iter()
            .map(|&t| {
                (0..n)
                    .map(|i| Pose {
                        x: i as f64 + 0.1 * t,
                        // A zigzag, so that no robot lies on a Gabriel circle's rim.
                        y: if i % 2 == 1 { 0.05 } else { 0.0 },
                        theta: 0.5,
                    })
                    .collect()
            })
            .collect();
        Trajectory {
            dt: 0.05,
            d_star: 1.0,
            v_star: 0.1,
            edges: Vec::new(),
            neighbours: NeighbourRule::Gabriel(GabrielRule::with_range(10.0)),
            phi_star: vec![0.0; samples],
            times,
            poses,
            commands: Vec::new(),
            collisions: Vec::new(),
        }
    }

    #[test]
    fn the_stride_keeps_at_most_the_cap_with_the_last_sample() {
        assert_eq!(frame_stride(10, 400), 1);
        assert_eq!(frame_stride(400, 400), 1);
        assert_eq!(frame_stride(1201, 400), 4);
        let traj = line_of_robots(3, 1201);
        let data = player_data(&traj);
        assert!(
            data.frames.len() <= MAX_PLAYER_FRAMES,
            "{}",
            data.frames.len()
        );
        assert_eq!(data.stride, 4);
        assert_eq!(data.samples, 1201);
        assert_eq!(data.frames[0].time, 0.0);
        assert!((data.frames.last().unwrap().time - 60.0).abs() < 1e-9);
        assert!((data.frames[1].time - 0.2).abs() < 1e-9);
    }

    #[test]
    fn the_edges_are_the_neighbour_rules_with_their_errors() {
        // Robots along a zigzag about 1 m apart, the last one moving off at the third sample.
        let mut traj = line_of_robots(4, 3);
        traj.poses[2][3].x = 3.5;
        let data = player_data(&traj);
        let rule = edges_per_sample(&traj);
        for (k, frame) in data.frames.iter().enumerate() {
            let pairs: Vec<(usize, usize)> = frame.edges.iter().map(|&(i, j, _)| (i, j)).collect();
            assert_eq!(pairs, rule[k], "frame {k}");
        }
        assert!(rule[2].contains(&(2, 3)) && !rule[2].contains(&(0, 3)));
        let expected = 100.0 * ((3.5 - 2.01f64).hypot(0.05) - 1.0); // robot 2 has moved 1 cm
        let last = data.frames[2]
            .edges
            .iter()
            .find(|e| (e.0, e.1) == (2, 3))
            .expect("edge 2-3")
            .2;
        assert!((last - expected).abs() < 1e-9, "{last} against {expected}");
    }

    #[test]
    fn the_json_is_compact_numbers_with_nulls_for_missing_values() {
        let mut traj = line_of_robots(2, 2);
        traj.neighbours = NeighbourRule::AllPairs;
        traj.edges = vec![(0, 1)];
        traj.poses[1][1].y = f64::NAN;
        let json = player_json(&player_data(&traj));
        assert!(
            json.starts_with(
                "{\"version\":1,\"robots\":2,\"stride\":1,\"samples\":2,\"d_star\":1,"
            ),
            "{json}"
        );
        assert!(json.contains("\"t\":[0,0.05]"), "{json}");
        assert!(
            json.contains("\"pose\":[[0,0,0.5,1,0.05,0.5],[0.005,0,0.5,1.005,null,0.5]]"),
            "{json}"
        );
        assert!(json.contains("\"edges\":[[0,1,0.1],[0,1,null]]"), "{json}");
        assert!(json.contains("\"colors\":[\"#1f77b4\""), "{json}");
        assert!(!json.contains('<'));
    }
}
