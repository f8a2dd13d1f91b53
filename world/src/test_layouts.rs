//! Team layouts shared by the unit tests of the LIDAR, the spatial grid and the world: seeded
//! random discs and the points of a square lattice.

use formation_proto::Pose;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::TAU;

/// `n` robots uniform in a disc of `radius` around `(cx, cy)`, at least `min_spacing` apart
/// (0 allows overlaps), headings uniform in [0, 2 pi).
pub(crate) fn disc_layout(
    rng: &mut ChaCha8Rng,
    n: usize,
    (cx, cy): (f64, f64),
    radius: f64,
    min_spacing: f64,
) -> Vec<Pose> {
    let mut poses: Vec<Pose> = Vec::with_capacity(n);
    while poses.len() < n {
        let r = radius * rng.random::<f64>().sqrt();
        let (s, c) = (TAU * rng.random::<f64>()).sin_cos();
        let (x, y) = (cx + r * c, cy + r * s);
        if poses
            .iter()
            .all(|p| (p.x - x).hypot(p.y - y) >= min_spacing)
        {
            poses.push(Pose::new(x, y, TAU * rng.random::<f64>()));
        }
    }
    poses
}

/// The points of the square lattice of side `cell` from `-half` to `half` cells along both axes,
/// row by row: `(i, j, i * cell, j * cell)`.
pub(crate) fn lattice(cell: f64, half: i64) -> impl Iterator<Item = (i64, i64, f64, f64)> {
    (-half..=half)
        .flat_map(move |i| (-half..=half).map(move |j| (i, j, i as f64 * cell, j as f64 * cell)))
}
