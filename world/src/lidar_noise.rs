//! The world's LIDAR noise models: what a simulated LIDAR adds to the ranges it casts
//! ([`LidarNoise`]), beyond the sensor contract an agent sees ([`formation_proto::LidarSpec`]).
//!
//! A new noise model is a setting of [`LidarNoise`] (`proto/src/lidar_noise.rs`), its
//! application here, and its scenario key (`scenario/parse.rs`, `scenario/validate.rs`,
//! `scenario/limits.rs`).

use formation_proto::LidarNoise;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Adds `noise` to `ranges` (of a LIDAR reaching `max_range`) with draws from `rng`, in beam
/// order: Gaussian noise of `noise_std` on every range that hit something (below `max_range`),
/// clamped to `[0, max_range]`. Draws nothing when no model is on.
pub fn add_range_noise(
    ranges: &mut [f32],
    max_range: f64,
    noise: &LidarNoise,
    rng: &mut ChaCha8Rng,
) {
    if noise.is_none() {
        return;
    }
    let no_hit = max_range as f32;
    for range in ranges.iter_mut().filter(|range| **range < no_hit) {
        let deviation: f64 = StandardNormal.sample(rng);
        let noisy = *range as f64 + noise.noise_std * deviation;
        *range = noisy.clamp(0.0, max_range) as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn noise_moves_only_the_hits_and_stays_within_range() {
        let mut ranges = vec![1.0_f32, 10.0, 0.01, 9.99];
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        add_range_noise(&mut ranges, 10.0, &LidarNoise { noise_std: 0.5 }, &mut rng);
        assert_eq!(ranges[1], 10.0, "a beam that hit nothing keeps max_range");
        assert!(ranges.iter().all(|r| (0.0..=10.0).contains(r)));
        assert_ne!(ranges[0], 1.0);
    }

    #[test]
    fn no_model_draws_nothing() {
        let mut ranges = vec![1.0_f32; 4];
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let before = rng.clone();
        add_range_noise(&mut ranges, 10.0, &LidarNoise::NONE, &mut rng);
        assert_eq!((ranges, rng), (vec![1.0_f32; 4], before));
    }
}
