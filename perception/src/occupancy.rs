//! The occupancy image a robot renders from its own raw LIDAR scan.
//!
//! This is the single source of truth for the pixels: the demonstration collector
//! (`formation_expert::collect`) and the running agent (`formation_robot_agent::decision`) both
//! call [`render`], so a policy sees at run time exactly the images it was trained on.
//!
//! # Geometry
//!
//! The image is `size_px x size_px` cells of `resolution_m` metres, centred on the robot, in its body
//! frame (x forward, y left), stored row-major. With `W = size_px * resolution_m`, the body point
//! `(x, y)` falls in
//!
//! ```text
//! col = floor((x + W/2) / res)      (col 0 at the rear edge, growing forward)
//! row = floor((W/2 - y) / res)      (row 0 at the left edge, growing to the right)
//! ```
//!
//! so for the paper's 50 x 50 cells of 0.1 m the robot sits at the corner of cells (24..=25, 24..=25),
//! a point 1 m ahead falls in row 25, col 35 and a point 1 m to the left in row 15, col 25. The
//! formula is evaluated as `x / res + size_px / 2`, which equals it in exact arithmetic.
//!
//! Beam `k` of a scan points at body-frame bearing `2 pi k / beams`; its end point is `range` metres
//! along it. Beams that hit nothing (`range >= max_range`) and invalid ranges (negative, NaN,
//! infinite) draw nothing. A hit outside the window is dropped or drawn on the border according to
//! [`BeyondWindow`].

use formation_proto::{BeyondWindow, LidarSpec, OccupancySpec};

/// Value of a cell where at least one scan end point falls.
pub const OCCUPIED: u8 = 1;

/// Renders one raw scan into an occupancy image (`1` = occupied, `0` = free or unknown).
///
/// `scan[k]` is the range of beam `k`, at body-frame bearing `2 pi k / lidar.beams`. `out` is
/// overwritten entirely. Hits beyond the window follow `spec.beyond`: [`BeyondWindow::Drop`] skips
/// them, [`BeyondWindow::Border`] moves the point along its bearing onto the window's edge and lights
/// the cell just inside it, so a neighbour outside the window stays visible in its true direction.
///
/// # Panics
///
/// If `out.len() != spec.size_px * spec.size_px` or `scan.len() != lidar.beams`: buffers are sized
/// by the caller from the same settings, so a mismatch is a programming error, not bad input.
pub fn render(scan: &[f32], lidar: &LidarSpec, spec: &OccupancySpec, out: &mut [u8]) {
    assert_eq!(
        out.len(),
        spec.size_px * spec.size_px,
        "occupancy buffer must hold size_px * size_px = {} cells",
        spec.size_px * spec.size_px
    );
    assert_eq!(
        scan.len(),
        lidar.beams,
        "scan must have one range per configured LIDAR beam"
    );
    out.fill(0);
    let beam_step = std::f64::consts::TAU / lidar.beams as f64;
    for (k, &range) in scan.iter().enumerate() {
        let range = f64::from(range);
        // Written so that NaN fails the test too.
        if !(range >= 0.0 && range < lidar.max_range) {
            continue;
        }
        let (sin, cos) = (k as f64 * beam_step).sin_cos();
        let (x, y) = (range * cos, range * sin);
        let cell = match spec.beyond {
            BeyondWindow::Drop => cell_of(x, y, spec),
            BeyondWindow::Border => cell_of(x, y, spec).or_else(|| border_cell_of(x, y, spec)),
        };
        if let Some((row, col)) = cell {
            out[row * spec.size_px + col] = OCCUPIED;
        }
    }
}

/// Renders one raw scan for a goal spacing `d_star` \[m\]: [`render`] with the window
/// [`OccupancySpec::at_d_star`] gives, which is `spec` itself unless the window scales with d*.
/// Collection and agents render through this, so both scale the window the same way.
///
/// # Panics
///
/// As [`render`].
pub fn render_at(
    scan: &[f32],
    lidar: &LidarSpec,
    spec: &OccupancySpec,
    d_star: f64,
    out: &mut [u8],
) {
    render(scan, lidar, &spec.at_d_star(d_star), out);
}

/// The `(row, col)` of the cell holding the body-frame point `(x, y)`, in metres, or `None` if the point lies
/// outside the window (or is not finite). See the module documentation for the formula.
pub fn cell_of(x: f64, y: f64, spec: &OccupancySpec) -> Option<(usize, usize)> {
    let half = spec.size_px as f64 / 2.0;
    let col = x / spec.resolution_m + half;
    let row = half - y / spec.resolution_m;
    let size = spec.size_px as f64;
    // Negated comparisons so that NaN is rejected as well.
    if !(col >= 0.0 && col < size && row >= 0.0 && row < size) {
        return None;
    }
    // In range, so the truncating casts are exact floors.
    Some((row as usize, col as usize))
}

/// The border cell in the bearing of a point outside the window: the point is scaled along its ray
/// onto the window's square edge, and the cell just inside that edge is returned. `None` for a point
/// at the origin, a non-finite point or an empty window.
fn border_cell_of(x: f64, y: f64, spec: &OccupancySpec) -> Option<(usize, usize)> {
    let reach = x.abs().max(y.abs());
    if spec.size_px == 0 || !(reach.is_finite() && reach > 0.0) {
        return None;
    }
    let half = spec.size_px as f64 / 2.0;
    let last = (spec.size_px - 1) as f64;
    // In cell units, the edge is `half` cells from the centre along the larger coordinate.
    let scale = half / (reach / spec.resolution_m);
    let col = (x / spec.resolution_m * scale + half)
        .floor()
        .clamp(0.0, last);
    let row = (half - y / spec.resolution_m * scale)
        .floor()
        .clamp(0.0, last);
    if !(col.is_finite() && row.is_finite()) {
        return None;
    }
    Some((row as usize, col as usize))
}

/// Converts a rendered image to the `f32` cells a policy takes (`0.0` / `1.0`).
///
/// # Panics
///
/// If the two slices differ in length.
pub fn to_f32(image: &[u8], out: &mut [f32]) {
    assert_eq!(
        image.len(),
        out.len(),
        "image and f32 buffer must have the same number of cells"
    );
    for (dst, &src) in out.iter_mut().zip(image) {
        *dst = f32::from(src);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(beyond: BeyondWindow) -> OccupancySpec {
        OccupancySpec {
            beyond,
            ..OccupancySpec::PAPER
        }
    }

    fn no_hits(lidar: &LidarSpec) -> Vec<f32> {
        vec![lidar.max_range as f32; lidar.beams]
    }

    fn occupied_cells(image: &[u8], spec: &OccupancySpec) -> Vec<(usize, usize)> {
        image
            .iter()
            .enumerate()
            .filter(|&(_, &v)| v != 0)
            .map(|(i, _)| (i / spec.size_px, i % spec.size_px))
            .collect()
    }

    /// Renders a scan whose only hit is beam `beam` at `range`.
    fn render_single(beam: usize, range: f32, spec: &OccupancySpec) -> Vec<(usize, usize)> {
        let lidar = LidarSpec::default();
        let mut scan = no_hits(&lidar);
        scan[beam] = range;
        let mut image = vec![7; spec.size_px * spec.size_px];
        render(&scan, &lidar, spec, &mut image);
        occupied_cells(&image, spec)
    }

    /// A neighbour held at d* lands the same number of cells ahead at every spacing when the
    /// window scales with d*, and at a fixed distance in metres when it does not.
    #[test]
    fn a_scaled_window_puts_a_neighbour_at_d_star_in_the_same_cell() {
        let lidar = LidarSpec::default();
        let scaled = OccupancySpec {
            d_star_ref_m: Some(1.0),
            ..spec(BeyondWindow::Border)
        };
        let cells_at = |spec: &OccupancySpec, d_star: f64| {
            let mut scan = no_hits(&lidar);
            scan[0] = d_star as f32;
            let mut image = vec![0; spec.size_px * spec.size_px];
            render_at(&scan, &lidar, spec, d_star, &mut image);
            occupied_cells(&image, spec)
        };
        for d_star in [0.8, 1.0, 1.7, 2.5] {
            assert_eq!(cells_at(&scaled, d_star), vec![(25, 35)], "d* = {d_star}");
        }
        assert_eq!(cells_at(&OccupancySpec::PAPER, 0.8), vec![(25, 33)]);
        assert_eq!(cells_at(&OccupancySpec::PAPER, 2.0), vec![(25, 45)]);
    }

    #[test]
    fn body_frame_points_land_in_the_documented_cells() {
        let s = OccupancySpec::PAPER;
        assert_eq!(cell_of(1.0, 0.0, &s), Some((25, 35)), "1 m ahead");
        assert_eq!(cell_of(0.0, 1.0, &s), Some((15, 25)), "1 m to the left");
        assert_eq!(cell_of(-1.0, 0.0, &s), Some((25, 15)), "1 m behind");
        assert_eq!(cell_of(0.0, -1.0, &s), Some((35, 25)), "1 m to the right");
        assert_eq!(cell_of(-2.5, 2.5, &s), Some((0, 0)), "rear-left corner");
        assert_eq!(
            cell_of(2.49, -2.49, &s),
            Some((49, 49)),
            "front-right corner"
        );
        assert_eq!(
            cell_of(2.5, 0.0, &s),
            None,
            "the front edge itself is outside"
        );
        assert_eq!(
            cell_of(0.0, -2.5, &s),
            None,
            "the right edge itself is outside"
        );
        assert_eq!(cell_of(f64::NAN, 0.0, &s), None);
    }

    /// The trainer's `--mirror` (`formation_trainer.train.mirror_batch`) relies on this: the scan
    /// reflected about the heading axis (beam `k` becomes beam `n - k`) renders the same image with
    /// its rows in reverse order, in both window modes. The two beams at exactly +-90 degrees are
    /// the exception: their end points lie on the column boundary `x = 0`, where the sign of the
    /// rounding error of `cos(pi / 2)` (positive) and `cos(3 pi / 2)` (negative) picks the column.
    #[test]
    fn a_scan_reflected_about_the_heading_axis_renders_the_rows_reversed() {
        let lidar = LidarSpec::default();
        let n = lidar.beams;
        // Irregular ranges, some beyond the window, some misses: robots, walls and nothing.
        let scan: Vec<f32> = (0..n)
            .map(|k| match k % 7 {
                _ if 4 * k == n || 4 * k == 3 * n => lidar.max_range as f32,
                0 => lidar.max_range as f32,
                _ => 0.4 + ((k * 37) % 101) as f32 * 0.043,
            })
            .collect();
        let reflected: Vec<f32> = (0..n).map(|k| scan[(n - k) % n]).collect();
        for beyond in [BeyondWindow::Drop, BeyondWindow::Border] {
            let spec = spec(beyond);
            let side = spec.size_px;
            let (mut image, mut mirror) = (vec![0; side * side], vec![0; side * side]);
            render(&scan, &lidar, &spec, &mut image);
            render(&reflected, &lidar, &spec, &mut mirror);
            assert!(image.iter().filter(|&&c| c == OCCUPIED).count() > 100);
            for row in 0..side {
                assert_eq!(
                    &mirror[row * side..(row + 1) * side],
                    &image[(side - 1 - row) * side..(side - row) * side],
                    "{beyond:?}: row {row} of the reflection is not row {} of the image",
                    side - 1 - row
                );
            }
        }
    }

    #[test]
    fn a_single_hit_at_ninety_degrees_lights_exactly_its_cell() {
        // Beam 225 of 900 points at 90 degrees, i.e. straight left.
        let cells = render_single(225, 1.0, &spec(BeyondWindow::Drop));
        assert_eq!(cells, vec![(15, 25)]);
        let cells = render_single(0, 1.0, &spec(BeyondWindow::Drop));
        assert_eq!(cells, vec![(25, 35)], "beam 0 points forward");
    }

    #[test]
    fn a_scan_without_hits_renders_all_zeros_and_clears_the_buffer() {
        let lidar = LidarSpec::default();
        for beyond in [BeyondWindow::Drop, BeyondWindow::Border] {
            let mut image = vec![1; 2500];
            render(&no_hits(&lidar), &lidar, &spec(beyond), &mut image);
            assert!(image.iter().all(|&v| v == 0), "{beyond:?}");
        }
    }

    #[test]
    fn invalid_ranges_draw_nothing() {
        for range in [f32::NAN, f32::INFINITY, -0.5, 10.0, 12.0] {
            assert!(
                render_single(100, range, &spec(BeyondWindow::Border)).is_empty(),
                "{range}"
            );
        }
    }

    #[test]
    fn hits_beyond_the_window_are_dropped_in_drop_mode() {
        assert!(render_single(0, 4.0, &spec(BeyondWindow::Drop)).is_empty());
        assert!(render_single(100, 6.0, &spec(BeyondWindow::Drop)).is_empty());
    }

    #[test]
    fn hits_beyond_the_window_land_on_the_border_in_their_bearing() {
        let s = spec(BeyondWindow::Border);
        // Exactly behind or to the right, the ray runs along a cell edge and rounding picks the side,
        // so the last two use beams 4 degrees off the axis: 2.5 tan 4 deg = 0.175 m, 1.75 cells off.
        for (beam, range, cell, what) in [
            (0, 4.0, (25, 49), "ahead: front edge"),
            (225, 4.0, (0, 25), "left: left edge"),
            (460, 9.0, (26, 0), "behind, slightly right: rear edge"),
            (685, 3.0, (49, 26), "right, slightly ahead: right edge"),
        ] {
            assert_eq!(render_single(beam, range, &s), vec![cell], "{what}");
        }
        // 45 degrees (beam 112.5 does not exist; beam 112 is at 44.8 degrees): the front-left corner region.
        let cells = render_single(112, 8.0, &s);
        assert_eq!(cells.len(), 1);
        let (row, col) = cells[0];
        assert!(row == 0 || col == 49, "on the border: {cells:?}");
        assert!(
            row <= 1 && col >= 48,
            "near the front-left corner: {cells:?}"
        );
        // A hit inside the window is unaffected by the mode.
        assert_eq!(render_single(0, 1.0, &s), vec![(25, 35)]);
    }

    #[test]
    fn border_cells_follow_the_bearing_off_axis() {
        let s = spec(BeyondWindow::Border);
        // 30 degrees, 5 m: the ray crosses the front edge (x = 2.5) at y = 2.5 tan 30 = 1.443 m.
        let bearing = 30.0_f64.to_radians();
        let (x, y) = (5.0 * bearing.cos(), 5.0 * bearing.sin());
        assert_eq!(cell_of(x, y, &s), None);
        let expected_row = (25.0 - 2.5 * bearing.tan() / 0.1).floor() as usize;
        assert_eq!(border_cell_of(x, y, &s), Some((expected_row, 49)));
    }

    #[test]
    fn to_f32_maps_cells_to_zero_and_one() {
        let mut out = [9.0_f32; 3];
        to_f32(&[0, 1, 0], &mut out);
        assert_eq!(out, [0.0, 1.0, 0.0]);
    }
}
