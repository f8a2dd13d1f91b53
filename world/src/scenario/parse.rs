//! The first phase of reading a scenario: the file's text, read within its size limit, and the
//! TOML schema it is parsed into before validation ([`super::validate`]). Every table rejects
//! unknown keys, so a typo is an error that names the key.

use super::*;

/// The text of the scenario file at `path`, read only if it is a regular file of at most
/// [`limits::MAX_FILE_BYTES`].
///
/// The file's metadata is checked before it is opened (so a FIFO is never opened and `/dev/zero`
/// never read), checked again on the opened file (it may have been replaced in between), and the
/// read stops one byte past the limit whatever the metadata said.
pub fn read_scenario_text(path: &Path) -> Result<String, ScenarioError> {
    let bytes = read_bounded(path, limits::MAX_FILE_BYTES).map_err(|refusal| {
        let path = path.to_path_buf();
        match refusal {
            FileRefusal::NotAFile { kind } => ScenarioError::NotAFile { path, kind },
            FileRefusal::TooLarge { size } => ScenarioError::TooLarge { path, size },
            FileRefusal::Io(source) => ScenarioError::Read { path, source },
        }
    })?;
    String::from_utf8(bytes).map_err(|e| ScenarioError::Read {
        path: path.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
    })
}

/// A byte count in messages: the number, or "more than the limit" when it is not known.
pub(super) struct FileSize(pub(super) Option<u64>);

impl fmt::Display for FileSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(size) => write!(f, "{size}"),
            None => write!(f, "more than {}", limits::MAX_FILE_BYTES),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ScenarioToml {
    pub(super) name: String,
    pub(super) robots: usize,
    pub(super) duration_s: f64,
    #[serde(default = "default_dt")]
    pub(super) dt: f64,
    pub(super) seed: u64,
    #[serde(default = "default_runs")]
    pub(super) runs: usize,
    pub(super) goal: GoalToml,
    pub(super) heading: HeadingToml,
    #[serde(default)]
    pub(super) init: InitToml,
    #[serde(default)]
    pub(super) formation: FormationToml,
    #[serde(default)]
    pub(super) lidar: LidarToml,
    #[serde(default)]
    pub(super) robot: RobotToml,
    #[serde(default)]
    pub(super) compass: CompassToml,
    #[serde(default)]
    pub(super) agent: Vec<AgentModel>,
    pub(super) model: Option<PathBuf>,
}

pub(super) fn default_dt() -> f64 {
    DEFAULT_DT
}

pub(super) fn default_runs() -> usize {
    1
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct InitToml {
    pub(super) disc_radius: Option<f64>,
    pub(super) min_spacing: Option<f64>,
}

#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct FormationToml {
    pub(super) neighbours: Option<String>,
    pub(super) sensing_range: Option<f64>,
    pub(super) nearest: Option<usize>,
    pub(super) threshold: Option<f64>,
    pub(super) hysteresis: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GoalToml {
    pub(super) v_star: Option<f64>,
    pub(super) v_star_range: Option<[f64; 2]>,
    pub(super) d_star: Option<f64>,
    pub(super) d_star_choices: Option<Vec<f64>>,
    pub(super) d_star_range: Option<[f64; 2]>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum ScheduleKind {
    Constant,
    Random,
    Ramp,
    Sine,
}

impl ScheduleKind {
    pub(super) fn as_str(self) -> &'static str {
        match self {
            ScheduleKind::Constant => "constant",
            ScheduleKind::Random => "random",
            ScheduleKind::Ramp => "ramp",
            ScheduleKind::Sine => "sine",
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct HeadingToml {
    pub(super) schedule: ScheduleKind,
    pub(super) phi: Option<f64>,
    pub(super) omega: Option<f64>,
    pub(super) amplitude: Option<f64>,
    pub(super) phi0: Option<f64>,
}

/// The `[lidar]` table: each key absent takes the robot profile's value.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LidarToml {
    pub(super) beams: Option<usize>,
    pub(super) max_range: Option<f64>,
    pub(super) noise_std: Option<f64>,
    pub(super) scan_rate_hz: Option<f64>,
    pub(super) fov_deg: Option<f64>,
    pub(super) min_range: Option<f64>,
    pub(super) dropout: Option<f64>,
}

/// The `[robot]` table: a profile, and each key absent takes the profile's value.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RobotToml {
    pub(super) profile: Option<String>,
    pub(super) wheel_separation: Option<f64>,
    pub(super) wheel_radius: Option<f64>,
    pub(super) body_radius: Option<f64>,
    pub(super) max_wheel_speed: Option<f64>,
    pub(super) max_wheel_accel: Option<f64>,
    pub(super) motor_tau: Option<f64>,
    pub(super) wheel_speed_noise: Option<f64>,
    pub(super) wheel_gain_asymmetry: Option<f64>,
    pub(super) command_latency: Option<i64>,
    pub(super) spread: Option<f64>,
}

/// The `[compass]` table: each key absent takes the robot profile's value.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct CompassToml {
    pub(super) noise_std_deg: Option<f64>,
    pub(super) bias_deg: Option<f64>,
}
