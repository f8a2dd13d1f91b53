//! The runtime's settings, defined once: the clock mode and every timeout, shared by the
//! launcher (which writes them) and the world process (which reads them whole).
//!
//! [`RuntimeSettings`] is a serde value with one [`Default`] ([`RuntimeSettings::DEFAULT`]);
//! the command-line flags of `formation run` and of `formation-world` take their defaults from
//! it, and the launcher hands the world one JSON file ([`RuntimeSettings::write`],
//! [`RuntimeSettings::read`]) instead of rebuilding flags by hand.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// How the world paces ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClockMode {
    /// Wait for every live agent's command of this tick (up to a timeout), then step.
    /// Deterministic: equal bit for bit to the in-process loop for the same scenario, seed and
    /// models.
    Lockstep,
    /// Step at the simulation's own rate (20 Hz for dt = 50 ms) on the wall clock, with the
    /// newest fresh command of each robot.
    Realtime,
}

impl ClockMode {
    /// The name used on the command line and in logs.
    pub fn as_str(&self) -> &'static str {
        match self {
            ClockMode::Lockstep => "lockstep",
            ClockMode::Realtime => "realtime",
        }
    }
}

/// Timing and watchdog settings of one launch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RuntimeSettings {
    /// Clock mode.
    pub clock: ClockMode,
    /// Lockstep: how long the world waits for a robot's command before braking it \[ms\].
    pub command_timeout_ms: u64,
    /// Realtime: a command whose scan is older than this brakes its robot \[ms\].
    pub stale_ms: u64,
    /// Lockstep: the least time a tick takes \[ms\] (0: as fast as the agents answer).
    pub pace_ms: u64,
    /// How long the world waits for every agent to connect \[ms\].
    pub startup_timeout_ms: u64,
    /// How long agents may take to get ready for an episode \[ms\].
    pub ready_timeout_ms: u64,
    /// How often the world asks the transport which agents died \[ms\].
    pub liveness_period_ms: u64,
    /// Lockstep: after publishing a tick's scans the world polls for the commands this long
    /// before it blocks \[µs\] (0: block at once). Each poll that finds nothing yields the core
    /// (`sched_yield`), so an agent that is ready to run always runs first: the poll never
    /// starves an agent, and it changes the order of nothing. Polling sees a command in about a
    /// microsecond where a blocking wake-up costs tens (measured on 2 cores, 3 agents: round
    /// trip p50/p99 from about 125/740 µs down to 60/125 µs, and less CPU in all, since fewer
    /// processes sleep and wake).
    #[serde(default = "default_spin_us")]
    pub spin_us: u64,
}

/// The lockstep world's yielding poll before it blocks \[µs\], by default.
pub const DEFAULT_SPIN_US: u64 = 200;

fn default_spin_us() -> u64 {
    DEFAULT_SPIN_US
}

/// Why the settings file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// The file could not be read or written.
    #[error("{action} runtime settings {}", path.display())]
    Io {
        /// "reading" or "writing".
        action: &'static str,
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid settings JSON (a typo in a field name is an error too).
    #[error("parsing runtime settings {}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// serde's error.
        #[source]
        source: serde_json::Error,
    },
}

/// Declares, for each `accessor => field_ms`, the method `accessor` that gives the setting in
/// milliseconds `field_ms` as a [`Duration`].
macro_rules! durations {
    ($($accessor:ident => $field:ident,)*) => {$(
        #[doc = concat!("[`RuntimeSettings::", stringify!($field), "`] as a duration.")]
        pub fn $accessor(&self) -> Duration {
            Duration::from_millis(self.$field)
        }
    )*};
}

impl RuntimeSettings {
    /// The defaults every flag and the launcher start from.
    pub const DEFAULT: RuntimeSettings = RuntimeSettings {
        clock: ClockMode::Lockstep,
        command_timeout_ms: 2000,
        stale_ms: 150,
        pace_ms: 0,
        startup_timeout_ms: 30_000,
        ready_timeout_ms: 10_000,
        liveness_period_ms: 100,
        spin_us: DEFAULT_SPIN_US,
    };

    durations! {
        command_timeout => command_timeout_ms,
        stale_after => stale_ms,
        pace => pace_ms,
        startup_timeout => startup_timeout_ms,
        ready_timeout => ready_timeout_ms,
        liveness_period => liveness_period_ms,
    }

    /// The settings as pretty JSON.
    pub fn to_json(&self) -> String {
        // A struct of integers and a unit enum always serialises.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Reads settings written by [`RuntimeSettings::write`] (every field present, none unknown).
    pub fn read(path: &Path) -> Result<RuntimeSettings, SettingsError> {
        let bytes = std::fs::read(path).map_err(|source| SettingsError::Io {
            action: "reading",
            path: path.to_owned(),
            source,
        })?;
        serde_json::from_slice(&bytes).map_err(|source| SettingsError::Parse {
            path: path.to_owned(),
            source,
        })
    }

    /// Writes the settings as JSON to `path`.
    pub fn write(&self, path: &Path) -> Result<(), SettingsError> {
        formation_proto::files::write_atomic(path, self.to_json().as_bytes()).map_err(|source| {
            SettingsError::Io {
                action: "writing",
                path: path.to_owned(),
                source,
            }
        })
    }
}

impl Default for RuntimeSettings {
    fn default() -> RuntimeSettings {
        RuntimeSettings::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_round_trip_through_their_file_and_refuse_a_typo() {
        let dir = std::env::temp_dir().join(format!("formation-settings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("runtime-settings.json");
        let settings = RuntimeSettings {
            clock: ClockMode::Realtime,
            pace_ms: 20,
            ..RuntimeSettings::default()
        };
        settings.write(&path).unwrap();
        assert_eq!(RuntimeSettings::read(&path).unwrap(), settings);
        std::fs::write(&path, settings.to_json().replace("stale_ms", "stale_msec")).unwrap();
        let error = RuntimeSettings::read(&path).unwrap_err();
        assert!(matches!(error, SettingsError::Parse { .. }), "{error}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
