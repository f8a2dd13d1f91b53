//! Plain values shared across crates: poses, wheel commands, goals and sensor settings.

use serde::{Deserialize, Serialize};

/// Planar pose of a robot's wheel-axle centre in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// x position \[m\].
    pub x: f64,
    /// y position \[m\].
    pub y: f64,
    /// Heading \[rad\], counter-clockwise from +x. Kept wrapped to (-pi, pi].
    pub theta: f64,
}

impl Pose {
    /// The pose at (`x`, `y`) heading `theta` \[rad\], taken as given (not wrapped).
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }
}

/// Left and right wheel rim speeds \[m/s\] of a differential-drive robot.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct WheelCmd {
    /// Left wheel rim speed \[m/s\].
    pub left: f64,
    /// Right wheel rim speed \[m/s\].
    pub right: f64,
}

impl WheelCmd {
    /// The command of rim speeds `left` and `right` \[m/s\], taken as given (not limited).
    pub const fn new(left: f64, right: f64) -> Self {
        Self { left, right }
    }

    /// Both wheels stopped: what the watchdog applies to a robot without a valid command.
    pub const BRAKE: WheelCmd = WheelCmd::new(0.0, 0.0);

    /// True when both wheel speeds are finite numbers.
    pub fn is_finite(&self) -> bool {
        self.left.is_finite() && self.right.is_finite()
    }
}

/// The goal every robot is given at one instant: common heading, speed and pairwise distance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Goal {
    /// Desired common heading phi* \[rad\] at this instant.
    pub phi_star: f64,
    /// Desired pairwise distance d* \[m\].
    pub d_star: f64,
    /// Desired speed v* \[m/s\].
    pub v_star: f64,
}

impl Goal {
    /// The goal of common heading `phi_star` \[rad\], pairwise distance `d_star` \[m\] and speed
    /// `v_star` \[m/s\].
    pub const fn new(phi_star: f64, d_star: f64, v_star: f64) -> Goal {
        Goal {
            phi_star,
            d_star,
            v_star,
        }
    }
}

/// Radius \[m\] of the disc that stands for a robot's body: a Pioneer P3-DX's, the world's default
/// (`formation_world::RobotParams::body_radius`), which its LIDAR casts and its collision test
/// uses, and what a robot's neighbour detector (`formation_perception::neighbours`) assumes of
/// the bodies it sees unless told otherwise.
pub const DEFAULT_BODY_RADIUS_M: f64 = 0.25;

/// Distance \[m\] between a robot's wheels: a Pioneer P3-DX's, the world's default
/// (`formation_world::RobotParams::wheel_separation`), and what an agent's stopping governor
/// (`formation_perception::stopping`) assumes to turn a wheel command into the arc it drives.
pub const DEFAULT_WHEEL_SEPARATION_M: f64 = 0.331;

/// The planar LIDAR ring as a robot's agent and its model must agree on it: the sensor contract.
/// What a simulated world adds to the ranges is its own ([`crate::LidarNoise`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LidarSpec {
    /// Number of beams evenly spread over 360 degrees, beam 0 pointing along the robot's +x axis
    /// and beams advancing counter-clockwise.
    pub beams: usize,
    /// Maximum range \[m\]; a beam that hits nothing reports this value.
    pub max_range: f64,
}

impl Default for LidarSpec {
    fn default() -> Self {
        LidarSpec {
            beams: 900,
            max_range: 10.0,
        }
    }
}

/// What a robot knows of its own wheels, told to its agent at the start of each episode: a
/// policy that answers a formation velocity turns it into wheel speeds within them, as the
/// expert that taught it does (`formation_perception::policy_input::formation_velocity_to_wheels`).
/// A real robot knows its own wheels; the world applies its limits to any command regardless.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelLimits {
    /// The largest wheel speed \[m/s\] (`None`: not told; both wheels are then sent as computed
    /// and the world clips each on its own).
    pub max_speed: Option<f64>,
    /// The largest wheel acceleration \[m/s²\] (`None`: none), for which a formation velocity
    /// is shaped.
    pub max_accel: Option<f64>,
}

impl WheelLimits {
    /// Whether each limit given is a finite number > 0.
    pub fn is_valid(&self) -> bool {
        [self.max_speed, self.max_accel]
            .into_iter()
            .flatten()
            .all(|limit| limit.is_finite() && limit > 0.0)
    }
}

/// What the occupancy renderer does with a LIDAR hit that falls outside the image window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BeyondWindow {
    /// Discard it (the paper's setting).
    Drop,
    /// Draw it on the window's border cell in its true bearing, so a far neighbour stays visible.
    Border,
}

impl BeyondWindow {
    /// Stable name used in dataset headers and model metadata.
    pub fn as_str(&self) -> &'static str {
        match self {
            BeyondWindow::Drop => "drop",
            BeyondWindow::Border => "border",
        }
    }

    /// Parses the name written by [`BeyondWindow::as_str`].
    pub fn parse(s: &str) -> Option<BeyondWindow> {
        match s {
            "drop" => Some(BeyondWindow::Drop),
            "border" => Some(BeyondWindow::Border),
            _ => None,
        }
    }
}

/// Settings of the occupancy image a robot renders from its own scan.
///
/// The image is `size_px x size_px`, centred on the robot, in its body frame (x forward, y left),
/// covering `size_px * resolution_m` metres on a side. These settings travel in dataset headers
/// and model metadata so an agent renders exactly what its model was trained on.
///
/// With `d_star_ref_m` set, the window scales with the goal's spacing d*: at d* the cells are
/// `resolution_m * d* / d_star_ref_m` wide ([`OccupancySpec::at_d_star`]), so a neighbour held at
/// d* lies the same number of cells away at every spacing, and the image keeps the same precision
/// relative to d* (the paper's fixed 0.1 m cell is 12.5 % of d* = 0.8 m and 4 % of 2.5 m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OccupancySpec {
    /// Cells on a side. The paper's network needs 50.
    pub size_px: usize,
    /// Cell edge length \[m\] (at `d* = d_star_ref_m` when the window scales with d*).
    pub resolution_m: f64,
    /// What happens to hits beyond the window.
    pub beyond: BeyondWindow,
    /// When set, the spacing d* \[m\] at which cells are `resolution_m` wide; the window scales
    /// linearly with d* from there. `None`: a fixed window, as in the paper.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub d_star_ref_m: Option<f64>,
}

impl OccupancySpec {
    /// The paper's exact setting: 50 x 50 cells of 0.1 m (5 x 5 m), hits beyond dropped.
    pub const PAPER: OccupancySpec = OccupancySpec {
        size_px: 50,
        resolution_m: 0.1,
        beyond: BeyondWindow::Drop,
        d_star_ref_m: None,
    };

    /// Side length of the window \[m\] (at `d* = d_star_ref_m` for a window that scales).
    pub fn window_m(&self) -> f64 {
        self.size_px as f64 * self.resolution_m
    }

    /// The fixed window an image is rendered with for a goal spacing `d_star`: this window itself
    /// when it does not scale, else the one whose cells are `resolution_m * d_star /
    /// d_star_ref_m` wide.
    pub fn at_d_star(&self, d_star: f64) -> OccupancySpec {
        match self.d_star_ref_m {
            None => *self,
            Some(reference) => OccupancySpec {
                resolution_m: self.resolution_m * (d_star / reference),
                d_star_ref_m: None,
                ..*self
            },
        }
    }

    /// Whether the window scales with d*.
    pub fn scales_with_d_star(&self) -> bool {
        self.d_star_ref_m.is_some()
    }

    /// The largest window side \[m\] over goal spacings up to `d_star_max`: the window itself
    /// when it is fixed.
    pub fn widest_window_m(&self, d_star_max: f64) -> f64 {
        self.at_d_star(d_star_max).window_m()
    }
}

impl Default for OccupancySpec {
    fn default() -> Self {
        OccupancySpec::PAPER
    }
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::PI;
    let mut r = a.rem_euclid(2.0 * PI);
    if r > PI {
        r -= 2.0 * PI;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn wrap_angle_stays_in_half_open_interval() {
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(0.5) - 0.5).abs() < 1e-15);
        assert!((wrap_angle(-0.5 - 4.0 * PI) + 0.5).abs() < 1e-12);
    }

    #[test]
    fn beyond_window_names_round_trip() {
        for b in [BeyondWindow::Drop, BeyondWindow::Border] {
            assert_eq!(BeyondWindow::parse(b.as_str()), Some(b));
        }
        assert_eq!(BeyondWindow::parse("clamp"), None);
    }

    #[test]
    fn a_scaled_window_keeps_its_cells_per_d_star() {
        let scaled = OccupancySpec {
            d_star_ref_m: Some(1.25),
            ..OccupancySpec::PAPER
        };
        for d_star in [0.8, 1.25, 2.5] {
            let at = scaled.at_d_star(d_star);
            assert_eq!(at.d_star_ref_m, None);
            assert!(
                (d_star / at.resolution_m - 12.5).abs() < 1e-12,
                "d* = {d_star}"
            );
        }
        assert_eq!(scaled.at_d_star(1.25).resolution_m, 0.1);
        assert_eq!(OccupancySpec::PAPER.at_d_star(0.8), OccupancySpec::PAPER);
        assert!((scaled.widest_window_m(2.5) - 10.0).abs() < 1e-12);
    }

    #[test]
    fn a_fixed_window_serialises_as_before() {
        let text = serde_json::to_string(&OccupancySpec::PAPER).unwrap();
        assert_eq!(text, r#"{"size_px":50,"resolution_m":0.1,"beyond":"drop"}"#);
        let back: OccupancySpec = serde_json::from_str(&text).unwrap();
        assert_eq!(back, OccupancySpec::PAPER);
    }
}
