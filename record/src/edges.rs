//! The formation's edges as markers a viewer draws: one line per edge, coloured by how far its
//! length is from d*, and its error as text at its middle.
//!
//! The edges follow the run's neighbour rule tick after tick ([`NeighbourTracker`], the rule the
//! metrics score), measured between the robots' centres; the error of edge `(i, j)` is
//! `(|p_i − p_j| − d*) / d*`. Each tick's array first deletes the previous one's markers, so an
//! edge that went away leaves no text behind.

use formation_proto::{NeighbourRule, Pose};
use formation_ros2::msg::{Header, Pose as RosPose, Time, Vector3};
use formation_ros2::team::WORLD_FRAME;
use formation_ros2::visualization::{marker_action, marker_type};
use formation_ros2::{ColorRgba, Marker, MarkerArray};
use formation_world::neighbours::NeighbourTracker;

/// The topic of the edge markers.
pub const TOPIC: &str = "/formation/edges";

/// A relative error at which an edge is drawn fully red (green at 0).
const RED_AT: f64 = 0.10;

/// Line width of the edges \[m\].
const LINE_WIDTH: f64 = 0.03;

/// Height of the error text \[m\].
const TEXT_HEIGHT: f64 = 0.15;

/// The edges of one run, tick after tick.
#[derive(Debug)]
pub struct EdgeMarkers {
    tracker: NeighbourTracker,
    positions: Vec<(f64, f64)>,
}

impl EdgeMarkers {
    /// For a team of `n` robots under `rule`, before its first sample.
    pub fn new(rule: NeighbourRule, n: usize) -> EdgeMarkers {
        EdgeMarkers {
            tracker: NeighbourTracker::new(rule, n),
            positions: Vec::with_capacity(n),
        }
    }

    /// The next sample's markers at `stamp`, for the poses `poses` and the distance `d_star`.
    pub fn next(&mut self, stamp: Time, poses: &[Pose], d_star: f64) -> MarkerArray {
        self.positions.clear();
        self.positions.extend(poses.iter().map(|p| (p.x, p.y)));
        self.tracker.update(&self.positions);
        let header = Header {
            stamp,
            frame_id: WORLD_FRAME.to_owned(),
        };
        let edges = self.tracker.edges();
        let mut markers = Vec::with_capacity(edges.len() + 2);
        markers.push(Marker {
            header: header.clone(),
            action: marker_action::DELETEALL,
            ..Marker::default()
        });
        let mut lines = Marker {
            header: header.clone(),
            ns: "edges".into(),
            kind: marker_type::LINE_LIST,
            action: marker_action::ADD,
            scale: Vector3 {
                x: LINE_WIDTH,
                y: 0.0,
                z: 0.0,
            },
            color: colour(0.0),
            ..Marker::default()
        };
        for (k, &(i, j)) in edges.iter().enumerate() {
            let (Some(a), Some(b)) = (poses.get(i), poses.get(j)) else {
                continue;
            };
            let error = ((a.x - b.x).hypot(a.y - b.y) - d_star) / d_star;
            let c = colour(error);
            lines.points.push(point(a.x, a.y));
            lines.points.push(point(b.x, b.y));
            lines.colors.extend([c, c]);
            markers.push(Marker {
                header: header.clone(),
                ns: "edge_errors".into(),
                id: i32::try_from(k).unwrap_or(i32::MAX),
                kind: marker_type::TEXT_VIEW_FACING,
                action: marker_action::ADD,
                pose: RosPose {
                    position: point((a.x + b.x) / 2.0, (a.y + b.y) / 2.0),
                    ..RosPose::default()
                },
                scale: Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: TEXT_HEIGHT,
                },
                color: c,
                text: format!("{i}-{j} {:+.1}%", 100.0 * error),
                ..Marker::default()
            });
        }
        markers.insert(1, lines);
        MarkerArray { markers }
    }
}

fn point(x: f64, y: f64) -> Vector3 {
    Vector3 { x, y, z: 0.0 }
}

/// Green at no error, yellow at half of [`RED_AT`], red from it on (opaque).
fn colour(error: f64) -> ColorRgba {
    let c = (error.abs() / RED_AT).clamp(0.0, 1.0) as f32;
    let c = if c.is_nan() { 1.0 } else { c };
    ColorRgba {
        r: (2.0 * c).min(1.0),
        g: (2.0 * (1.0 - c)).min(1.0),
        b: 0.0,
        a: 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_triangle_draws_three_edges_with_their_errors() {
        let mut edges = EdgeMarkers::new(NeighbourRule::AllPairs, 3);
        let poses = [
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(2.0, 0.0, 0.0),
            Pose::new(0.0, 1.0, 0.0),
        ];
        let array = edges.next(Time::default(), &poses, 2.0);
        assert_eq!(array.markers[0].action, marker_action::DELETEALL);
        let lines = &array.markers[1];
        assert_eq!(lines.kind, marker_type::LINE_LIST);
        assert_eq!(lines.points.len(), 6);
        assert_eq!(lines.colors.len(), 6);
        let texts: Vec<&str> = array.markers[2..].iter().map(|m| m.text.as_str()).collect();
        assert_eq!(texts, ["0-1 +0.0%", "0-2 -50.0%", "1-2 +11.8%"]);
        // On target: green; 50 % off: red.
        assert_eq!((lines.colors[0].r, lines.colors[0].g), (0.0, 1.0));
        assert_eq!((lines.colors[2].r, lines.colors[2].g), (1.0, 0.0));
    }
}
