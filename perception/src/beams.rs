//! The unit direction of each beam of a LIDAR ring, computed once and kept: beam `k` of `n` at
//! bearing `2 π k / n`, counter-clockwise from the robot's +x axis, as
//! [`formation_proto::LidarSpec`] defines them. The neighbour detector and the stopping governor
//! read a scan's returns through it.

/// `(cos, sin)` of each beam's bearing.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BeamDirections {
    cos_sin: Vec<(f64, f64)>,
}

impl BeamDirections {
    /// The directions of a ring of `beams` beams.
    pub fn new(beams: usize) -> BeamDirections {
        let mut directions = BeamDirections::default();
        directions.fit(beams);
        directions
    }

    /// Makes these the directions of a ring of `beams` beams; nothing is computed or allocated
    /// when they already are.
    pub fn fit(&mut self, beams: usize) {
        if self.cos_sin.len() == beams {
            return;
        }
        let step = std::f64::consts::TAU / beams as f64;
        self.cos_sin.clear();
        self.cos_sin.extend((0..beams).map(|k| {
            let (sin, cos) = (k as f64 * step).sin_cos();
            (cos, sin)
        }));
    }

    /// `(cos, sin)` of each beam's bearing, beam 0 first.
    pub fn as_slice(&self) -> &[(f64, f64)] {
        &self.cos_sin
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beam_k_of_n_points_at_two_pi_k_over_n_counter_clockwise() {
        let mut ring = BeamDirections::new(4);
        let expected = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)];
        for (&(cos, sin), (ec, es)) in ring.as_slice().iter().zip(expected) {
            assert!((cos - ec).abs() < 1e-12 && (sin - es).abs() < 1e-12);
        }
        // Fitted again to the same ring, it keeps what it has; to another, it follows it.
        let kept = ring.as_slice().as_ptr();
        ring.fit(4);
        assert_eq!(ring.as_slice().as_ptr(), kept);
        ring.fit(8);
        assert_eq!(ring.as_slice().len(), 8);
        assert!((ring.as_slice()[2].1 - 1.0).abs() < 1e-12);
    }
}
