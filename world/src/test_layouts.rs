//! Seeded random team layouts shared by the unit tests of the LIDAR and the world.

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
