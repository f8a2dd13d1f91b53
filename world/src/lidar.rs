//! The planar LIDAR ring: noiseless ranges from one robot to the other robots' bodies, ray-cast with
//! parry2d.
//!
//! Beam `k` of `B` leaves the sensor (at the robot's pose) at body-frame bearing `2 pi k / B`,
//! counter-clockwise from the robot's heading, and reads the distance to the first body it meets,
//! or `max_range` when it meets none within range. The robot's own body is never hit.
//!
//! Casting every beam against every body would cost `O(N^2 B)` per tick for `N` robots. Instead,
//! for each other body within reach, only the beams inside the angular interval the body subtends
//! are cast. [`cast_scan`] scans one robot, looking at every other body to find those within reach:
//! `O(N)` per robot, `O(N^2)` per tick. [`TeamScanner`] scans the whole team and finds them in a
//! [`SpatialGrid`], so a tick costs `O(N)` in the number of robots within range of each robot; it
//! gives the very same bits as [`cast_scan`], which stays the reference it is tested against.
//! Measurement noise is not added here: [`crate::World::scan_into`] adds it from the world's RNG.

use std::f64::consts::TAU;

use formation_proto::{LidarSpec, Pose};
use parry2d::math::{Point, Vector};
use parry2d::query::{Ray, RayCast};
use parry2d::shape::Ball;

use crate::grid::{SpatialGrid, floor_to_i64};
use crate::robot::RobotParams;

/// What a scan of one robot's ring starts from, whichever way it finds the bodies.
#[derive(Debug, Clone, Copy)]
struct ScanStart {
    /// The scanning robot's pose.
    sensor: Pose,
    /// `sensor.theta.sin_cos()`.
    sin_heading: f64,
    cos_heading: f64,
    /// The LIDAR's max range \[m\] and beam count.
    max_range: f64,
    beams: usize,
    /// Every body's radius \[m\].
    radius: f64,
}

impl ScanStart {
    /// Checks that `out` holds one range per beam of `lidar` (else panics: `buffer` holds ...
    /// ranges but the LIDAR has ... beams) and fills it with the LIDAR's max range, what a beam
    /// that hits nothing reads. Returns what robot `own`'s scan starts from, or `None` for a
    /// LIDAR without beams, whose scan is then complete.
    #[track_caller]
    fn new(
        poses: &[Pose],
        own: usize,
        params: &RobotParams,
        lidar: &LidarSpec,
        out: &mut [f32],
        buffer: &str,
    ) -> Option<ScanStart> {
        assert_eq!(
            out.len(),
            lidar.beams,
            "{buffer} holds {} ranges but the LIDAR has {} beams",
            out.len(),
            lidar.beams
        );
        out.fill(lidar.max_range as f32);
        let sensor = poses[own];
        if lidar.beams == 0 {
            return None;
        }
        let (sin_heading, cos_heading) = sensor.theta.sin_cos();
        Some(ScanStart {
            sensor,
            sin_heading,
            cos_heading,
            max_range: lidar.max_range,
            beams: lidar.beams,
            radius: params.body_radius,
        })
    }
}

/// Writes the noiseless ranges \[m\] of robot `own`'s LIDAR ring into `out`, given every robot's
/// pose; all bodies are discs of `params.body_radius` centred at their poses.
///
/// Beams that hit nothing within `lidar.max_range` read exactly `lidar.max_range as f32`. If `own`'s
/// sensor lies inside another body (the robots collided), every beam reads 0.
///
/// # Panics
///
/// If `own` is not an index of `poses` or `out.len()` differs from `lidar.beams`: both are
/// programming errors of the caller, never a consequence of scenario input.
pub fn cast_scan(
    poses: &[Pose],
    own: usize,
    params: &RobotParams,
    lidar: &LidarSpec,
    out: &mut [f32],
) {
    let Some(ScanStart {
        sensor,
        sin_heading,
        cos_heading,
        max_range,
        beams,
        radius,
    }) = ScanStart::new(
        poses,
        own,
        params,
        lidar,
        out,
        "cast_scan: the output buffer",
    )
    else {
        return;
    };
    let beam_step = TAU / beams as f64;
    let body = Ball::new(radius as f32);

    for (index, other) in poses.iter().enumerate() {
        if index == own {
            continue;
        }
        // The body's centre in the sensor's frame (x along the heading), computed in f64 so that
        // far-from-origin worlds keep the ranges' precision after the cast to parry's f32.
        let (dx, dy) = (other.x - sensor.x, other.y - sensor.y);
        let forward = cos_heading * dx + sin_heading * dy;
        let left = -sin_heading * dx + cos_heading * dy;
        let distance = forward.hypot(left);
        // False for bodies out of reach and for non-finite poses, which no beam can hit.
        let within_reach = distance - radius < max_range;
        if !within_reach {
            continue;
        }
        if distance <= radius {
            out.fill(0.0);
            return;
        }

        // Only beams within the half-width asin(r / d) of the body's bearing can hit it; one beam of
        // margin on each side absorbs rounding, and the exact cast decides.
        let bearing = left.atan2(forward);
        let half_width = (radius / distance).asin();
        let first = ((bearing - half_width) / beam_step).floor() as i64;
        let last = ((bearing + half_width) / beam_step).ceil() as i64;
        // The body as seen from a ray leaving the origin is the same as a ray leaving `-centre`
        // towards a ball at the origin: parry's local cast, without isometry transforms.
        let origin = Point::new(-forward as f32, -left as f32);
        let (mut sin_beam, mut cos_beam) = (first as f64 * beam_step).sin_cos();
        let (sin_step, cos_step) = beam_step.sin_cos();
        for k in first..=last {
            let ray = Ray::new(origin, Vector::new(cos_beam as f32, sin_beam as f32));
            if let Some(range) = body.cast_local_ray(&ray, max_range as f32, true) {
                // The window spans at most half the ring plus margins, so no beam is visited twice.
                let slot = &mut out[k.rem_euclid(beams as i64) as usize];
                *slot = slot.min(range);
            }
            // Rotate the beam direction by one step (exact to ~1e-15 over a window's few hundred).
            (sin_beam, cos_beam) = (
                sin_beam * cos_step + cos_beam * sin_step,
                cos_beam * cos_step - sin_beam * sin_step,
            );
        }
    }
}

/// A body the grid found near the sensor: its index, its centre's offset from the sensor in the
/// world frame and the offset's squared length.
#[derive(Debug, Clone, Copy)]
struct NearbyBody {
    index: usize,
    dx: f64,
    dy: f64,
    distance_squared: f64,
}

/// Scans every robot of a team, finding the bodies within each sensor's reach in a [`SpatialGrid`]
/// instead of looking at every body, and keeping its buffers from one tick to the next.
///
/// [`TeamScanner::scan_all`] writes, for every robot, exactly the bits [`cast_scan`] writes:
///
/// * the bodies it leaves out are out of reach by a margin far above rounding;
/// * for the others it makes cast_scan's decisions (within reach or not, the window of beams) with
///   cheaper arithmetic where that provably cannot decide otherwise, and with cast_scan's own where
///   it might;
/// * each beam is cast with the very ray cast_scan builds, by the same arithmetic;
/// * each beam's range is the `min` of its casts, and parry's ranges are never NaN nor `-0.0`, so
///   the order in which the grid hands out the bodies does not matter.
#[derive(Debug, Clone, Default)]
pub struct TeamScanner {
    grid: SpatialGrid,
    /// The bodies that may be within reach of the sensor being scanned.
    nearby: Vec<NearbyBody>,
    start_directions: StartDirections,
    window_rays: WindowRays,
}

impl TeamScanner {
    /// A scanner with empty buffers; they grow to the team's size on the first scan.
    pub fn new() -> TeamScanner {
        TeamScanner {
            grid: SpatialGrid::new(),
            ..TeamScanner::default()
        }
    }

    /// Writes every robot's noiseless ranges \[m\]: `out[i]` receives, bit for bit, what
    /// `cast_scan(poses, i, params, lidar, &mut out[i])` would write.
    ///
    /// Costs `O(N)` plus the work on the bodies within each sensor's range, against `O(N^2)` for
    /// [`cast_scan`] robot by robot. Falls back to [`cast_scan`] when `max_range` is not positive and
    /// finite or the body radius not finite and non-negative, where no grid cell side fits.
    ///
    /// # Panics
    ///
    /// If `out.len()` differs from `poses.len()` or a buffer's length from `lidar.beams`.
    pub fn scan_all(
        &mut self,
        poses: &[Pose],
        params: &RobotParams,
        lidar: &LidarSpec,
        out: &mut [Vec<f32>],
    ) {
        assert_eq!(
            out.len(),
            poses.len(),
            "TeamScanner::scan_all: {} scan buffers for {} robots",
            out.len(),
            poses.len()
        );
        let (max_range, radius) = (lidar.max_range, params.body_radius);
        let grid_applies =
            max_range > 0.0 && max_range.is_finite() && radius >= 0.0 && radius.is_finite();
        if !grid_applies {
            for (own, ranges) in out.iter_mut().enumerate() {
                cast_scan(poses, own, params, lidar, ranges);
            }
            return;
        }
        // A body can be hit only if its centre is within `max_range + radius` of the sensor: with
        // cells that wide, a query spans 3 x 3 cells.
        self.grid.rebuild(poses, max_range + radius);
        self.start_directions.prepare(lidar.beams);
        for (own, ranges) in out.iter_mut().enumerate() {
            let buffer = "TeamScanner::scan_all: a buffer";
            if let Some(start) = ScanStart::new(poses, own, params, lidar, ranges, buffer) {
                self.scan_one(start, own, ranges);
            }
        }
    }

    /// Robot `own`'s noiseless scan from `start`, with the grid built from the poses and the table
    /// prepared.
    fn scan_one(&mut self, start: ScanStart, own: usize, out: &mut [f32]) {
        let ScanStart {
            sensor,
            max_range,
            radius,
            ..
        } = start;
        let (sin_heading, cos_heading) = (start.sin_heading, start.cos_heading);

        // The bodies in the grid cells around the sensor, then only those that may be within reach
        // (kept without a branch: a third of them are, at random). The loose bound exceeds the
        // exact test's by far more than rounding (see `SpatialGrid::for_each_near`), so no body
        // within reach is left out; the exact test is made in `beam_window`.
        let nearby = &mut self.nearby;
        nearby.clear();
        self.grid
            .for_each_near(sensor.x, sensor.y, max_range + radius, |index, x, y| {
                let (dx, dy) = (x - sensor.x, y - sensor.y);
                nearby.push(NearbyBody {
                    index,
                    dx,
                    dy,
                    distance_squared: dx * dx + dy * dy,
                });
            });
        let may_reach_squared = squared(loosened(max_range + radius));
        let may_contain_squared = squared(loosened(radius));
        let mut kept = 0;
        let mut sensor_inside_a_body = false;
        for visited in 0..nearby.len() {
            let body = nearby[visited];
            nearby[kept] = body;
            let is_other = body.index != own;
            kept += usize::from(is_other && body.distance_squared < may_reach_squared);
            // Is the sensor inside this body? Then every beam reads 0, whatever else is near.
            if is_other && body.distance_squared <= may_contain_squared {
                let forward = cos_heading * body.dx + sin_heading * body.dy;
                let left = -sin_heading * body.dx + cos_heading * body.dy;
                let distance = forward.hypot(left);
                sensor_inside_a_body |= distance - radius < max_range && distance <= radius;
            }
        }
        nearby.truncate(kept);
        if sensor_inside_a_body {
            out.fill(0.0);
            return;
        }

        let beam_step = TAU / start.beams as f64;
        let (sin_step, cos_step) = beam_step.sin_cos();
        let window_rays = &mut self.window_rays;
        for &NearbyBody {
            dx,
            dy,
            distance_squared,
            ..
        } in &self.nearby
        {
            // cast_scan's centre in the sensor's frame (x along the heading), operation for
            // operation.
            let forward = cos_heading * dx + sin_heading * dy;
            let left = -sin_heading * dx + cos_heading * dy;
            let Some((first, last)) = beam_window(
                forward,
                left,
                distance_squared.sqrt(),
                radius,
                max_range,
                beam_step,
            ) else {
                continue;
            };
            window_rays.cast(
                out,
                self.start_directions.get(first, beam_step),
                (sin_step, cos_step),
                first,
                last,
                [-forward as f32, -left as f32],
                radius as f32,
                max_range as f32,
            );
        }
    }
}

/// `(k as f64 * beam_step).sin_cos()` for `k` in `-beams..=beams`: the direction of the first beam of
/// a body's window, which [`cast_scan`] computes with `sin_cos` for every body.
#[derive(Debug, Clone, Default)]
struct StartDirections {
    /// The beam count the table is for.
    beams: usize,
    /// Beam `k`'s direction at index `k + beams`.
    table: Vec<(f64, f64)>,
}

impl StartDirections {
    /// Tabulates the directions for `beams` beams, unless already done.
    fn prepare(&mut self, beams: usize) {
        if self.beams == beams && !self.table.is_empty() {
            return;
        }
        let beam_step = TAU / beams as f64;
        let span = beams as i64;
        self.table = (-span..=span)
            .map(|k| (k as f64 * beam_step).sin_cos())
            .collect();
        self.beams = beams;
    }

    /// `(first as f64 * beam_step).sin_cos()`, from the table when `first` is in it; `beam_step`
    /// must be `TAU / beams` for the prepared `beams`.
    fn get(&self, first: i64, beam_step: f64) -> (f64, f64) {
        let offset = first + self.beams as i64;
        usize::try_from(offset)
            .ok()
            .and_then(|index| self.table.get(index))
            .copied()
            .unwrap_or_else(|| (first as f64 * beam_step).sin_cos())
    }
}

/// The rays of one body's window, as structure of arrays so that casting them vectorises.
#[derive(Debug, Clone, Default)]
struct WindowRays {
    direction_x: Vec<f32>,
    direction_y: Vec<f32>,
    ranges: Vec<f32>,
}

impl WindowRays {
    /// cast_scan's loop over a body's window, beams `first..=last` (unwrapped): the same rays by
    /// the same arithmetic.
    ///
    /// The beam directions are cast_scan's rotation recurrence from `start_direction` (`(sin, cos)`
    /// of beam `first`) by `step` (`(sin, cos)` of one beam step), each rounded to `f32`; the rays
    /// leave `origin`, the sensor seen from the body's centre. Each range is
    /// [`ball_cast_or_infinity`]'s, and lowers its beam's slot of `out` as cast_scan's
    /// `slot.min(range)` does.
    #[allow(clippy::too_many_arguments)]
    fn cast(
        &mut self,
        out: &mut [f32],
        start_direction: (f64, f64),
        (sin_step, cos_step): (f64, f64),
        first: i64,
        last: i64,
        origin: [f32; 2],
        radius: f32,
        max_range: f32,
    ) {
        let beams = out.len();
        let count = (last - first + 1).max(0) as usize;
        self.direction_x.resize(count, 0.0);
        self.direction_y.resize(count, 0.0);
        let (mut sin_beam, mut cos_beam) = start_direction;
        for (x, y) in self.direction_x.iter_mut().zip(&mut self.direction_y) {
            (*x, *y) = (cos_beam as f32, sin_beam as f32);
            (sin_beam, cos_beam) = (
                sin_beam * cos_step + cos_beam * sin_step,
                cos_beam * cos_step - sin_beam * sin_step,
            );
        }
        self.ranges.resize(count, 0.0);
        for ((range, &x), &y) in self
            .ranges
            .iter_mut()
            .zip(&self.direction_x)
            .zip(&self.direction_y)
        {
            *range = ball_cast_or_infinity(origin, [x, y], radius, max_range);
        }
        // The window's slots, `k.rem_euclid(beams)` for k = first..=last: at most two runs of
        // consecutive slots, or more for a window longer than the ring.
        let mut slot = first.rem_euclid(beams as i64) as usize;
        let mut ranges = &self.ranges[..];
        while !ranges.is_empty() {
            let run = ranges.len().min(beams - slot);
            for (range_so_far, &range) in out[slot..slot + run].iter_mut().zip(&ranges[..run]) {
                *range_so_far = range_so_far.min(range);
            }
            ranges = &ranges[run..];
            slot = 0;
        }
    }
}

/// parry2d's `Ball::cast_local_ray(&Ray::new(origin, direction), max_range, true)` for a ball of
/// `radius` at the origin, operation for operation (its `ray_toi_with_ball`, with nalgebra's
/// two-term dot products), but without branches so that a chunk of casts vectorises: the time of
/// impact where parry gives `Some`, and `+inf` where it gives `None`. Bit for bit, as the test
/// `ball_cast_or_infinity_matches_parry_bit_for_bit` checks.
#[inline(always)]
fn ball_cast_or_infinity(
    origin: [f32; 2],
    direction: [f32; 2],
    radius: f32,
    max_range: f32,
) -> f32 {
    let [ox, oy] = origin;
    let [dx, dy] = direction;
    let a = dx * dx + dy * dy;
    let b = ox * dx + oy * dy;
    let c = (ox * ox + oy * oy) - radius * radius;
    let delta = b * b - a * c;
    let t = (-b - delta.sqrt()) / a;
    // parry: a zero direction hits (at 0) exactly when the origin is not outside the ball.
    // Comparisons are named rather than negated: NaN makes each of them false, as in parry.
    let outside = c > 0.0;
    let leaving = b > 0.0;
    let no_root = delta < 0.0;
    let starts_inside = t <= 0.0;
    let degenerate = a == 0.0;
    let regular_hit = !(outside & leaving) & !no_root;
    let hits = if degenerate { !outside } else { regular_hit };
    let time_of_impact = if degenerate | starts_inside { 0.0 } else { t };
    let within_range = time_of_impact <= max_range;
    if hits & within_range {
        time_of_impact
    } else {
        f32::INFINITY
    }
}

/// Largest error \[rad\] of the approximate window bounds `bearing -+ half_width` that
/// [`beam_window`] computes, with a wide margin: [`approximate_atan2`] is within `1.2e-5`, and the
/// half-width from the approximate distance within `1e-13` for bodies subtending less than 2 x 64 deg.
const WINDOW_BOUND_ERROR: f64 = 3e-5;

/// The beams `first..=last` (unwrapped) that [`cast_scan`] casts at a body whose centre is at
/// `(forward, left)` in the sensor's frame, about `approximate_distance` away (the length of the
/// world-frame offset), and not around the sensor; `None` when cast_scan finds it out of reach.
///
/// cast_scan's decisions are discrete: whether the body is within reach, and two integers, the
/// floor and ceiling of the window's bounds in beam steps. They are made here from the approximate
/// distance and [`approximate_atan2`], without `hypot` and `atan2` (most of the cost of a body), and
/// only where those cannot differ from cast_scan's: when the approximate value lies farther from the
/// decision's threshold (the reach, an integer) than its error bound. Otherwise, about one body in
/// fifty with a 900-beam ring, they are made by cast_scan's own arithmetic ([`exact_beam_window`]).
fn beam_window(
    forward: f64,
    left: f64,
    approximate_distance: f64,
    radius: f64,
    max_range: f64,
    beam_step: f64,
) -> Option<(i64, i64)> {
    let exact = || exact_beam_window(forward, left, radius, max_range, beam_step);
    // cast_scan's distance, the hypot of the rotated offset, is within a few ulps of the
    // approximate one: far inside this margin.
    let reach_margin = 1e-12 * (approximate_distance + radius + max_range);
    let beyond_reach = approximate_distance - radius - max_range;
    if beyond_reach > reach_margin {
        return None;
    }
    // Bodies subtending more than 2 x 64 deg (touching ones, NaN) are left to cast_scan's
    // arithmetic: there the half-width's sensitivity to the distance grows without bound.
    let sine = radius / approximate_distance;
    let subtends_little = sine < 0.9;
    // A non-finite heading makes the centre's frame coordinates NaN, which only cast_scan's
    // arithmetic may judge.
    let in_frame = forward.is_finite() && left.is_finite();
    if beyond_reach >= -reach_margin || !subtends_little || !in_frame {
        return exact();
    }
    let half_width = sine.asin();
    let bearing = approximate_atan2(left, forward);
    let lower = (bearing - half_width) / beam_step;
    let upper = (bearing + half_width) / beam_step;
    let tolerance = WINDOW_BOUND_ERROR / beam_step;
    let near_an_integer = |x: f64| {
        let above = x - floor_to_i64(x) as f64;
        above < tolerance || above > 1.0 - tolerance
    };
    if near_an_integer(lower) || near_an_integer(upper) {
        return exact();
    }
    Some((floor_to_i64(lower), floor_to_i64(upper) + 1))
}

/// [`beam_window`] by cast_scan's arithmetic, operation for operation.
fn exact_beam_window(
    forward: f64,
    left: f64,
    radius: f64,
    max_range: f64,
    beam_step: f64,
) -> Option<(i64, i64)> {
    let distance = forward.hypot(left);
    let within_reach = distance - radius < max_range;
    if !within_reach {
        return None;
    }
    let bearing = left.atan2(forward);
    let half_width = (radius / distance).asin();
    let first = ((bearing - half_width) / beam_step).floor() as i64;
    let last = ((bearing + half_width) / beam_step).ceil() as i64;
    Some((first, last))
}

/// `length` widened by far more than the rounding of any distance computed to compare with it.
fn loosened(length: f64) -> f64 {
    length * (1.0 + 2e-9) + 1e-6
}

fn squared(x: f64) -> f64 {
    x * x
}

/// `atan2(y, x)` within `1.2e-5` rad, on the same branch as `f64::atan2` (the sign of `y` picks the
/// half plane), by Abramowitz and Stegun's polynomial 4.4.49 on the octant.
fn approximate_atan2(y: f64, x: f64) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let (small, large) = if ay <= ax { (ay, ax) } else { (ax, ay) };
    let has_length = large > 0.0;
    if !has_length {
        return 0.0;
    }
    let t = small / large;
    let t2 = t * t;
    let mut angle = t
        * (0.999_866
            + t2 * (-0.330_299_5 + t2 * (0.180_141 + t2 * (-0.085_133 + t2 * 0.020_835_1))));
    if ay > ax {
        angle = std::f64::consts::FRAC_PI_2 - angle;
    }
    if x < 0.0 {
        angle = std::f64::consts::PI - angle;
    }
    if y.is_sign_negative() { -angle } else { angle }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn lidar() -> LidarSpec {
        LidarSpec {
            beams: 900,
            max_range: 10.0,
        }
    }

    /// Asserts that beam `beam` of `ranges` reads `expected` \[m\] (to 1e-4 m).
    #[track_caller]
    fn assert_beam_reads(ranges: &[f32], beam: usize, expected: f32) {
        assert!(
            (ranges[beam] - expected).abs() < 1e-4,
            "beam {beam} reads {}",
            ranges[beam]
        );
    }

    fn scan(poses: &[Pose], own: usize) -> Vec<f32> {
        let lidar = lidar();
        let mut out = vec![f32::NAN; lidar.beams];
        cast_scan(poses, own, &RobotParams::default(), &lidar, &mut out);
        out
    }

    /// Exact range along body bearing `beam_angle` from a sensor to a disc of radius `r` at body-frame
    /// `(fx, fy)`, by the closed-form ray-circle intersection.
    fn closed_form_range(beam_angle: f64, fx: f64, fy: f64, r: f64) -> Option<f64> {
        let (dy, dx) = beam_angle.sin_cos();
        let along = dx * fx + dy * fy;
        let across2 = fx * fx + fy * fy - along * along;
        (along > 0.0 && across2 <= r * r).then(|| along - (r * r - across2).sqrt())
    }

    #[test]
    fn a_body_straight_ahead_is_hit_by_beam_zero_at_its_surface() {
        let poses = [Pose::new(0.0, 0.0, 0.0), Pose::new(3.0, 0.0, 1.0)];
        let ranges = scan(&poses, 0);
        assert_beam_reads(&ranges, 0, 2.75);
        // The body subtends asin(0.25 / 3) = 4.78 deg on each side: 11 beams of 0.4 deg each way.
        let per_side = ((0.25_f64 / 3.0).asin() / (TAU / 900.0)).floor() as usize;
        let hits: Vec<usize> = (0..900).filter(|&k| ranges[k] < 10.0).collect();
        assert_eq!(hits.len(), 2 * per_side + 1, "beams hit: {hits:?}");
        for (k, &range) in ranges.iter().enumerate().take(880).skip(20) {
            assert_eq!(
                range, 10.0,
                "beam {k} far from the body must read max_range"
            );
        }
    }

    #[test]
    fn the_hit_beam_follows_the_sensor_heading() {
        // Body to the world's +y, sensor heading +x rotated by 30 deg: the body is at body bearing
        // 60 deg, which is beam 150.
        let poses = [Pose::new(1.0, 1.0, PI / 6.0), Pose::new(1.0, 5.0, 0.0)];
        let ranges = scan(&poses, 0);
        assert_beam_reads(&ranges, 150, 3.75);
        assert_eq!(ranges[0], 10.0);
        assert_eq!(ranges[375], 10.0);
        // The observed robot sees the sensor robot at world bearing -90 deg, i.e. body beam 675.
        let back = scan(&poses, 1);
        assert_beam_reads(&back, 675, 3.75);
    }

    #[test]
    fn every_beam_matches_closed_form_ray_circle_ranges() {
        let poses = [
            Pose::new(20.0, -7.0, -2.0),
            Pose::new(21.1, -6.2, 0.0),
            Pose::new(17.5, -8.0, 0.0),
            Pose::new(22.0, -11.0, 0.0),
            Pose::new(29.0, -7.0, 0.0),
            Pose::new(40.0, -7.0, 0.0),
        ];
        let ranges = scan(&poses, 0);
        let sensor = poses[0];
        let (s, c) = sensor.theta.sin_cos();
        for (k, &range) in ranges.iter().enumerate() {
            let angle = TAU * k as f64 / 900.0;
            let expected = poses[1..]
                .iter()
                .filter_map(|p| {
                    let (dx, dy) = (p.x - sensor.x, p.y - sensor.y);
                    closed_form_range(angle, c * dx + s * dy, -s * dx + c * dy, 0.25)
                })
                .filter(|&r| r <= 10.0)
                .fold(10.0_f64, f64::min);
            assert!(
                (range as f64 - expected).abs() < 1e-4,
                "beam {k}: {range} vs {expected}"
            );
        }
        // Four bodies are within range; their windows must add up to many hit beams.
        assert!(ranges.iter().filter(|&&r| r < 10.0).count() > 100);
    }

    #[test]
    fn a_nearer_body_occludes_a_farther_one_on_the_same_bearing() {
        let poses = [
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(5.0, 0.0, 0.0),
            Pose::new(2.0, 0.0, 0.0),
        ];
        let ranges = scan(&poses, 0);
        assert_beam_reads(&ranges, 0, 1.75);
    }

    #[test]
    fn a_lone_robot_reads_max_range_everywhere() {
        let ranges = scan(&[Pose::new(1.0, 2.0, 0.3)], 0);
        assert!(ranges.iter().all(|&r| r == 10.0));
    }

    #[test]
    fn bodies_beyond_max_range_are_not_seen() {
        let poses = [Pose::new(0.0, 0.0, 0.0), Pose::new(10.3, 0.0, 0.0)];
        assert!(scan(&poses, 0).iter().all(|&r| r == 10.0));
        let near_limit = [Pose::new(0.0, 0.0, 0.0), Pose::new(10.2, 0.0, 0.0)];
        let ranges = scan(&near_limit, 0);
        assert_beam_reads(&ranges, 0, 9.95);
    }

    #[test]
    fn a_sensor_inside_another_body_reads_zero() {
        let poses = [Pose::new(0.0, 0.0, 0.0), Pose::new(0.1, 0.0, 0.0)];
        assert!(scan(&poses, 0).iter().all(|&r| r == 0.0));
    }

    #[test]
    fn a_body_across_the_beam_zero_seam_hits_beams_on_both_sides() {
        // Slightly below the +x axis: bearing about -1 deg, so the window wraps past beam 0.
        let poses = [Pose::new(0.0, 0.0, 0.0), Pose::new(2.0, -0.035, 0.0)];
        let ranges = scan(&poses, 0);
        assert!(ranges[0] < 10.0 && ranges[3] < 10.0 && ranges[899] < 10.0 && ranges[890] < 10.0);
        assert!(ranges[100..800].iter().all(|&r| r == 10.0));
    }

    /// Seeded random layouts for comparing [`TeamScanner`] with [`cast_scan`], beam by beam.
    mod team_scanner_matches_cast_scan {
        use super::*;
        use crate::test_layouts::{disc_layout, lattice};
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;

        /// Every robot's scan by [`TeamScanner::scan_all`] and by [`cast_scan`] must have the same
        /// bits, beam for beam; returns how many beams hit something, so callers can check that the
        /// layout exercised the casts.
        fn assert_same_bits(poses: &[Pose], params: &RobotParams, lidar: &LidarSpec) -> usize {
            let mut scanner = TeamScanner::new();
            let mut fast = vec![vec![f32::NAN; lidar.beams]; poses.len()];
            scanner.scan_all(poses, params, lidar, &mut fast);
            let mut hits = 0;
            let mut reference = vec![f32::NAN; lidar.beams];
            for (own, fast) in fast.iter().enumerate() {
                cast_scan(poses, own, params, lidar, &mut reference);
                for (beam, (a, b)) in fast.iter().zip(&reference).enumerate() {
                    assert_eq!(
                        a.to_bits(),
                        b.to_bits(),
                        "robot {own} beam {beam}: TeamScanner {a} vs cast_scan {b} \
                         ({} robots, {params:?}, {lidar:?})",
                        poses.len()
                    );
                }
                hits += reference
                    .iter()
                    .filter(|&&r| r < lidar.max_range as f32)
                    .count();
            }
            // A second scan with the same scanner (reused buffers) must give the same bits again.
            let mut again = vec![vec![f32::NAN; lidar.beams]; poses.len()];
            scanner.scan_all(poses, params, lidar, &mut again);
            let bits = |scans: &[Vec<f32>]| -> Vec<u32> {
                scans.iter().flatten().map(|r| r.to_bits()).collect()
            };
            assert_eq!(bits(&fast), bits(&again));
            hits
        }

        /// [`disc_layout`] with headings uniform in [-pi, pi).
        fn centred_disc_layout(
            rng: &mut ChaCha8Rng,
            n: usize,
            centre: (f64, f64),
            radius: f64,
            min_spacing: f64,
        ) -> Vec<Pose> {
            let mut poses = disc_layout(rng, n, centre, radius, min_spacing);
            for pose in &mut poses {
                pose.theta -= PI;
            }
            poses
        }

        #[test]
        fn at_the_papers_density_for_teams_of_2_to_300() {
            let mut rng = ChaCha8Rng::seed_from_u64(1);
            let mut hits = 0;
            for n in [2, 3, 5, 8, 13, 30, 64, 100, 150, 300] {
                let radius = 3.0 * (n as f64 / 3.0).sqrt();
                let poses = centred_disc_layout(&mut rng, n, (0.0, 0.0), radius, 0.6);
                hits += assert_same_bits(&poses, &RobotParams::default(), &lidar());
            }
            assert!(hits > 10_000, "only {hits} hits");
        }

        #[test]
        fn in_dense_and_overlapping_crowds() {
            let mut rng = ChaCha8Rng::seed_from_u64(2);
            let mut zeroed = 0;
            for (n, radius) in [
                (2, 0.3),
                (10, 1.0),
                (40, 2.0),
                (120, 3.0),
                (300, 4.0),
                (250, 9.0),
            ] {
                let poses = centred_disc_layout(&mut rng, n, (3.0, -2.0), radius, 0.0);
                assert_same_bits(&poses, &RobotParams::default(), &lidar());
                let mut scans = vec![vec![0.0; 900]; n];
                TeamScanner::new().scan_all(&poses, &RobotParams::default(), &lidar(), &mut scans);
                zeroed += scans.iter().filter(|scan| scan[0] == 0.0).count();
            }
            assert!(zeroed > 50, "only {zeroed} sensors inside a body");
        }

        #[test]
        fn for_bodies_at_exactly_max_range_and_at_the_edge_of_reach() {
            // Bodies whose centres are max_range + radius away (the edge of reach), a few ulps
            // either side of it, and at max_range exactly, all around a sensor; with wide bodies too.
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            for params in [
                RobotParams::default(),
                RobotParams {
                    body_radius: 1.0,
                    ..RobotParams::default()
                },
            ] {
                let lidar = lidar();
                let reach = lidar.max_range + params.body_radius;
                let mut poses = vec![Pose::new(0.7, -0.3, 0.4)];
                for k in 0..24 {
                    let angle = TAU * k as f64 / 24.0 + 0.01 * rng.random::<f64>();
                    let distance = match k % 6 {
                        0 => reach,
                        1 => f64::from_bits(reach.to_bits() - 1),
                        2 => f64::from_bits(reach.to_bits() + 1),
                        3 => lidar.max_range,
                        4 => reach - 1e-7,
                        _ => reach + 1e-7,
                    };
                    let (s, c) = angle.sin_cos();
                    poses.push(Pose::new(0.7 + distance * c, -0.3 + distance * s, 0.0));
                }
                assert!(assert_same_bits(&poses, &params, &lidar) > 0);
            }
        }

        #[test]
        fn across_grid_cell_boundaries() {
            // Robots a cell side (max_range + radius) apart along both axes, nudged by a few ulps, so
            // that sensor and body fall in neighbouring cells at every distance.
            let cell = 10.25_f64;
            let nudge = |v: f64, k: i64| f64::from_bits((v.to_bits() as i64 + k) as u64);
            let mut poses = Vec::new();
            for (i, j, x, y) in lattice(cell, 3) {
                poses.push(Pose::new(
                    nudge(x, (i + j) % 3),
                    nudge(y, (i - j) % 3),
                    0.3 * i as f64,
                ));
                poses.push(Pose::new(x + 0.6, y - 0.6, 0.1 * j as f64));
            }
            assert!(assert_same_bits(&poses, &RobotParams::default(), &lidar()) > 0);
        }

        #[test]
        fn far_from_the_origin_and_with_non_finite_poses() {
            let mut rng = ChaCha8Rng::seed_from_u64(4);
            for centre in [
                (1e6, -1e6),
                (9.99e8, 3.0),
                (1e9, 1e9),
                (2e9, -5.0),
                (-3e12, 1e12),
            ] {
                let poses = centred_disc_layout(&mut rng, 40, centre, 8.0, 0.3);
                assert_same_bits(&poses, &RobotParams::default(), &lidar());
            }
            // Robots straddling the gridded limit, and robots with NaN or infinite coordinates
            // among ordinary ones.
            let mut poses = centred_disc_layout(&mut rng, 30, (0.0, 0.0), 6.0, 0.5);
            poses.extend(centred_disc_layout(
                &mut rng,
                20,
                (1e9 - 4.0, 0.0),
                8.0,
                0.5,
            ));
            poses.push(Pose::new(f64::NAN, 1.0, 0.0));
            poses.push(Pose::new(1.0, f64::INFINITY, 0.0));
            poses.push(Pose::new(f64::NEG_INFINITY, f64::NAN, 0.0));
            poses.push(Pose::new(0.5, 0.5, f64::NAN));
            poses.push(Pose::new(2.0, -1.0, f64::INFINITY));
            assert!(assert_same_bits(&poses, &RobotParams::default(), &lidar()) > 0);
        }

        #[test]
        fn for_other_rings_ranges_and_radii() {
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let specs = [
                (360, 10.0),
                (1, 10.0),
                (7, 4.0),
                (900, 3.5),
                (900, 0.3),
                (1000, 25.0),
            ];
            for (beams, max_range) in specs {
                for body_radius in [0.25, 0.05, 0.0, 1.5] {
                    let lidar = LidarSpec { beams, max_range };
                    let params = RobotParams {
                        body_radius,
                        ..RobotParams::default()
                    };
                    let poses = centred_disc_layout(&mut rng, 60, (0.0, 0.0), 7.0, 0.0);
                    assert_same_bits(&poses, &params, &lidar);
                }
            }
            // Settings where no grid applies fall back to cast_scan.
            for (max_range, body_radius) in [
                (0.0, 0.25),
                (-1.0, 0.25),
                (f64::INFINITY, 0.25),
                (10.0, -0.1),
                (f64::NAN, 0.25),
            ] {
                let lidar = LidarSpec {
                    beams: 90,
                    max_range,
                };
                let params = RobotParams {
                    body_radius,
                    ..RobotParams::default()
                };
                let poses = centred_disc_layout(&mut rng, 20, (0.0, 0.0), 3.0, 0.0);
                assert_same_bits(&poses, &params, &lidar);
            }
            let no_beams = LidarSpec {
                beams: 0,
                ..lidar()
            };
            assert_same_bits(
                &centred_disc_layout(&mut rng, 5, (0.0, 0.0), 2.0, 0.0),
                &RobotParams::default(),
                &no_beams,
            );
        }

        #[test]
        fn for_a_team_where_far_bodies_hide_behind_near_ones() {
            // Rows of robots along rays from a sensor: most of each row is occluded by its front.
            let mut poses = vec![Pose::new(0.0, 0.0, 0.2)];
            for ray in 0..40 {
                let (s, c) = (TAU * ray as f64 / 40.0).sin_cos();
                for step in 1..=12 {
                    let d = 0.55 * step as f64 + 0.01 * ray as f64;
                    poses.push(Pose::new(d * c, d * s, 0.0));
                }
            }
            assert!(assert_same_bits(&poses, &RobotParams::default(), &lidar()) > 0);
        }
    }

    #[test]
    fn approximate_atan2_is_within_its_stated_error_on_the_same_branch() {
        let mut worst: f64 = 0.0;
        for i in 0..200_000 {
            let angle = -PI + TAU * i as f64 / 200_000.0;
            for scale in [1e-3, 1.0, 7.3, 1e4] {
                let (y, x) = angle.sin_cos();
                let (y, x) = (y * scale, x * scale);
                worst = worst.max((approximate_atan2(y, x) - y.atan2(x)).abs());
            }
        }
        assert!(worst < 1.2e-5, "worst error {worst}");
        for (y, x) in [
            (0.0, -1.0),
            (-0.0, -1.0),
            (1e-300, -1.0),
            (-1e-300, -1.0),
            (0.0, 0.0),
        ] {
            let error = (approximate_atan2(y, x) - f64::atan2(y, x)).abs();
            assert!(error < 1.2e-5, "atan2({y}, {x}): error {error}");
        }
    }

    #[test]
    fn ball_cast_or_infinity_matches_parry_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let special = [
            0.0_f32,
            -0.0,
            1.0,
            -1.0,
            0.25,
            1e-30,
            f32::NAN,
            f32::INFINITY,
            -f32::INFINITY,
            3e38,
        ];
        let mut hits = 0;
        for case in 0..2_000_000 {
            let radius = [0.25_f32, 0.05, 1.5, 0.0][case % 4];
            let max_range = [10.0_f32, 3.5, 0.0][case % 3];
            let (origin, direction) = if case % 50 == 0 {
                // Edge values: zero, signed zeros, NaN, infinities, huge.
                let pick =
                    |rng: &mut rand_chacha::ChaCha8Rng| special[rng.random_range(0..special.len())];
                (
                    [pick(&mut rng), pick(&mut rng)],
                    [pick(&mut rng), pick(&mut rng)],
                )
            } else {
                // A body up to 12 m away, rays at it, grazing it, and past it, as cast_scan makes.
                let distance = rng.random::<f64>() * 12.0;
                let bearing = TAU * rng.random::<f64>();
                let spread = (radius as f64 / distance.max(radius as f64))
                    .min(1.0)
                    .asin()
                    * 1.2;
                let angle = bearing + spread * (2.0 * rng.random::<f64>() - 1.0);
                let (s, c) = angle.sin_cos();
                let (sb, cb) = bearing.sin_cos();
                (
                    [(-distance * cb) as f32, (-distance * sb) as f32],
                    [c as f32, s as f32],
                )
            };
            let parry = Ball::new(radius).cast_local_ray(
                &Ray::new(
                    Point::new(origin[0], origin[1]),
                    Vector::new(direction[0], direction[1]),
                ),
                max_range,
                true,
            );
            let ours = ball_cast_or_infinity(origin, direction, radius, max_range);
            match parry {
                Some(range) => {
                    hits += 1;
                    assert_eq!(
                        range.to_bits(),
                        ours.to_bits(),
                        "{origin:?} {direction:?} r {radius} max {max_range}: parry {range}, ours {ours}"
                    );
                }
                None => assert_eq!(
                    ours,
                    f32::INFINITY,
                    "{origin:?} {direction:?} r {radius} max {max_range}: parry None, ours {ours}"
                ),
            }
        }
        assert!(hits > 300_000, "only {hits} hits");
    }
}
