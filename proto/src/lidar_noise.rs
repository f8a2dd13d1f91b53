//! What the world's LIDAR simulates beyond the sensor contract: its noise model.
//!
//! [`LidarSpec`] is the sensor contract, what an agent and its model must agree on (beams and
//! maximum range). [`LidarNoise`] is what a simulated world adds to the ranges it casts; an agent
//! never sees it. [`SimulatedLidar`] is the two together as the files a world writes record them
//! (scenario, run log, recording, dataset): one flat object `{beams, max_range, noise_std}`, the
//! same bytes as before the two were apart.
//!
//! A new noise model is a field of [`LidarNoise`] (absent from files while off, so that their
//! bytes and ids stay), its key in [`SimulatedLidar`]'s flat form, and its application in the
//! world (`formation_world::lidar_noise`).

use serde::{Deserialize, Serialize};

use crate::types::LidarSpec;

/// The noise a simulated LIDAR adds to the ranges it casts; none by default.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LidarNoise {
    /// Standard deviation \[m\] of additive Gaussian range noise on beams that hit something.
    pub noise_std: f64,
}

impl LidarNoise {
    /// No noise: the world's ranges are the ray cast's.
    pub const NONE: LidarNoise = LidarNoise { noise_std: 0.0 };

    /// Whether this model changes no range (a spread that is not a positive number adds none).
    pub fn is_none(&self) -> bool {
        let adds = self.noise_std > 0.0; // false for NaN too
        !adds
    }

    /// Hands each setting's bytes to `field`, in a fixed order, for a settings hash (a dataset's
    /// id). A setting that a later model adds is handed over only while on, so that the id of a
    /// dataset collected without it stays.
    pub fn hash_fields(&self, field: &mut dyn FnMut(&[u8])) {
        field(&self.noise_std.to_le_bytes());
    }
}

/// A simulated LIDAR: the sensor contract an agent sees and the noise the world adds.
///
/// Serialised flat, as `{"beams": …, "max_range": …, "noise_std": …}`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(from = "FlatLidar", into = "FlatLidar")]
pub struct SimulatedLidar {
    /// What an agent and its model must agree on.
    pub spec: LidarSpec,
    /// What the world adds to the ranges.
    pub noise: LidarNoise,
}

/// [`SimulatedLidar`]'s flat form in files.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FlatLidar {
    beams: usize,
    max_range: f64,
    noise_std: f64,
}

impl From<FlatLidar> for SimulatedLidar {
    fn from(flat: FlatLidar) -> SimulatedLidar {
        SimulatedLidar {
            spec: LidarSpec {
                beams: flat.beams,
                max_range: flat.max_range,
            },
            noise: LidarNoise {
                noise_std: flat.noise_std,
            },
        }
    }
}

impl From<SimulatedLidar> for FlatLidar {
    fn from(lidar: SimulatedLidar) -> FlatLidar {
        FlatLidar {
            beams: lidar.spec.beams,
            max_range: lidar.spec.max_range,
            noise_std: lidar.noise.noise_std,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_simulated_lidar_is_written_flat_as_before_the_split() {
        let lidar = SimulatedLidar {
            spec: LidarSpec::default(),
            noise: LidarNoise { noise_std: 0.03 },
        };
        let text = serde_json::to_string(&lidar).unwrap();
        assert_eq!(text, r#"{"beams":900,"max_range":10.0,"noise_std":0.03}"#);
        assert_eq!(
            serde_json::from_str::<SimulatedLidar>(&text).unwrap(),
            lidar
        );
        assert!(
            serde_json::from_str::<SimulatedLidar>(r#"{"beams":900,"max_range":10.0}"#).is_err(),
            "the noise is required, as it was"
        );
    }

    #[test]
    fn no_noise_is_none_and_a_nan_spread_adds_none() {
        assert!(LidarNoise::NONE.is_none());
        assert!(
            LidarNoise {
                noise_std: f64::NAN
            }
            .is_none()
        );
        assert!(!LidarNoise { noise_std: 0.01 }.is_none());
    }
}
