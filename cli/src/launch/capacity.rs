//! Whether this host can start a team at all, decided before any process starts: every robot is
//! an agent process of about 11 MB, and the world holds about 54 file descriptors per robot (its
//! iceoryx2 ports and their wake-up sockets). A team beyond the open-files limit, the memory or
//! the process limit is refused with the reason and the fix, instead of after a pile of
//! timeouts. The decision ([`check`]) is pure; [`Host::read`] reads the limits from /proc.

/// File descriptors the world holds per robot (measured: 3,418 for 64 robots).
pub const WORLD_FDS_PER_ROBOT: u64 = 56;
/// File descriptors the world holds whatever the team size.
pub const WORLD_FDS_BASE: u64 = 128;
/// Memory an agent process needs (measured PSS: 10.6-16.5 MB), with room to spare \[bytes\].
pub const AGENT_BYTES: u64 = 24 << 20;
/// Memory of the world and the launcher together \[bytes\].
pub const BASE_BYTES: u64 = 256 << 20;

/// What the host allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Host {
    /// The open-files limit the world will run under (the soft limit, after raising it).
    pub open_files: u64,
    /// The hard open-files limit.
    pub open_files_hard: u64,
    /// Memory available now \[bytes\], if known.
    pub available_bytes: Option<u64>,
    /// The per-user process limit, if any.
    pub max_processes: Option<u64>,
}

/// Why a team cannot start here.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CapacityError {
    /// Not enough file descriptors for the world.
    #[error(
        "a team of {robots} robots needs about {needed} open files in the world process, but the \
         limit here is {limit} (hard limit {hard}); raise it (as root: `ulimit -Hn {needed}; \
         ulimit -n {needed}`, or LimitNOFILE= in a systemd unit) or run fewer robots"
    )]
    OpenFiles {
        /// Team size.
        robots: usize,
        /// Descriptors needed.
        needed: u64,
        /// The soft limit.
        limit: u64,
        /// The hard limit.
        hard: u64,
    },
    /// Not enough memory for the agents.
    #[error(
        "a team of {robots} robots needs about {needed_mb} MB of memory (one agent process per \
         robot), but only {available_mb} MB are available; free memory or run fewer robots"
    )]
    Memory {
        /// Team size.
        robots: usize,
        /// Memory needed \[MB\].
        needed_mb: u64,
        /// Memory available \[MB\].
        available_mb: u64,
    },
    /// Not enough processes.
    #[error(
        "a team of {robots} robots needs {needed} processes, but this user may run at most \
         {limit}; raise `ulimit -u` or run fewer robots"
    )]
    Processes {
        /// Team size.
        robots: usize,
        /// Processes needed.
        needed: u64,
        /// The limit.
        limit: u64,
    },
}

/// Whether `host` can start a team of `robots`.
pub fn check(robots: usize, host: &Host) -> Result<(), CapacityError> {
    let n = robots as u64;
    let needed = WORLD_FDS_BASE + WORLD_FDS_PER_ROBOT * n;
    if needed > host.open_files {
        return Err(CapacityError::OpenFiles {
            robots,
            needed,
            limit: host.open_files,
            hard: host.open_files_hard,
        });
    }
    if let Some(available) = host.available_bytes {
        let needed = BASE_BYTES + AGENT_BYTES * n;
        if needed > available {
            return Err(CapacityError::Memory {
                robots,
                needed_mb: needed >> 20,
                available_mb: available >> 20,
            });
        }
    }
    if let Some(limit) = host.max_processes
        && n + 2 > limit
    {
        return Err(CapacityError::Processes {
            robots,
            needed: n + 2,
            limit,
        });
    }
    Ok(())
}

impl Host {
    /// Raises this process's soft open-files limit to the hard one (children inherit it) and
    /// reads what the host allows.
    pub fn read() -> Host {
        let (soft, hard) = rlimit::Resource::NOFILE.get().unwrap_or((1024, 1024));
        let open_files = if soft < hard && rlimit::Resource::NOFILE.set(hard, hard).is_ok() {
            hard
        } else {
            soft
        };
        let (_, nproc) = rlimit::Resource::NPROC
            .get()
            .unwrap_or((u64::MAX, u64::MAX));
        Host {
            open_files,
            open_files_hard: hard,
            available_bytes: mem_available(),
            max_processes: (nproc != rlimit::INFINITY).then_some(nproc),
        }
    }
}

/// `MemAvailable` from /proc/meminfo.
fn mem_available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Local agents per CPU core up to which they rehearse their last decision before each scan.
///
/// A rehearsal (see `formation-agent --rehearse-us`) is one extra decision per tick, run by every
/// agent in the same 2 ms before the scans go out. With a few agents per core it keeps caches warm
/// (realtime case 1 on 2 cores: inference p50 72–88 µs against 140–166 µs cold). With many it is a
/// burst of agents × decision of CPU exactly when the world needs it: 256 agents on 2 cores used
/// 28.5 % of their commands with it and 96.9 % without (issue 22). At 8 agents per core, a burst
/// of decisions of up to 100 µs each fits in 0.8 ms of the 2 ms lead.
pub const MAX_REHEARSING_AGENTS_PER_CORE: usize = 8;

/// Whether agents started on this host should rehearse: only while there are at most
/// [`MAX_REHEARSING_AGENTS_PER_CORE`] of them per core.
pub fn agents_should_rehearse(local_agents: usize, cores: usize) -> bool {
    local_agents <= MAX_REHEARSING_AGENTS_PER_CORE.saturating_mul(cores.max(1))
}

/// Local agents per CPU core up to which they poll for their next scan before blocking.
///
/// The poll (see `formation-agent --spin-us`) acts only while scans come within it of the agent's
/// command, as in an unpaced lockstep run; there it takes the scan without a wake-up, on a core
/// that is awake (case 1, 3 agents on 2 cores: round trip p50 77–92 µs against 143–161 µs, the
/// agents' inference p50 31 µs against 48–68 µs, paired runs). With many agents a core, those
/// served last poll while the world steps: 32 agents on 2 cores answered 8 % slower with it.
pub const MAX_SPINNING_AGENTS_PER_CORE: usize = 2;

/// Whether agents started on this host should poll for their next scan: only while there are at
/// most [`MAX_SPINNING_AGENTS_PER_CORE`] of them per core.
pub fn agents_should_spin(local_agents: usize, cores: usize) -> bool {
    local_agents <= MAX_SPINNING_AGENTS_PER_CORE.saturating_mul(cores.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agents_poll_for_their_scans_only_while_two_or_fewer_share_a_core() {
        assert!(agents_should_spin(3, 2));
        assert!(agents_should_spin(4, 2));
        assert!(!agents_should_spin(5, 2));
        assert!(!agents_should_spin(32, 2));
        assert!(agents_should_spin(32, 16));
        assert!(
            agents_should_spin(2, 0),
            "an unknown core count counts as one"
        );
    }

    #[test]
    fn agents_rehearse_only_while_few_share_a_core() {
        assert!(agents_should_rehearse(3, 2));
        assert!(agents_should_rehearse(16, 2));
        assert!(!agents_should_rehearse(17, 2));
        assert!(!agents_should_rehearse(256, 2));
        assert!(agents_should_rehearse(256, 32));
        assert!(
            agents_should_rehearse(8, 0),
            "an unknown core count counts as one"
        );
    }

    const ROOMY: Host = Host {
        open_files: 20_000,
        open_files_hard: 20_000,
        available_bytes: Some(16 << 30),
        max_processes: Some(10_000),
    };

    #[test]
    fn a_team_that_fits_passes_and_each_limit_is_named() {
        assert_eq!(check(256, &ROOMY), Ok(()));
        let few_files = Host {
            open_files: 1024,
            ..ROOMY
        };
        let err = check(256, &few_files).unwrap_err();
        assert!(
            matches!(err, CapacityError::OpenFiles { limit: 1024, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("ulimit"), "{err}");
        assert_eq!(check(16, &few_files), Ok(()));
        let little_memory = Host {
            available_bytes: Some(1 << 30),
            ..ROOMY
        };
        assert!(matches!(
            check(256, &little_memory),
            Err(CapacityError::Memory { .. })
        ));
        let few_processes = Host {
            max_processes: Some(100),
            ..ROOMY
        };
        assert!(matches!(
            check(256, &few_processes),
            Err(CapacityError::Processes { needed: 258, .. })
        ));
    }
}
