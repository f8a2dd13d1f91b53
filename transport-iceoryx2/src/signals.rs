//! Which termination signal, SIGINT or SIGTERM, stopped a process whose waits iceoryx2 ends.
//!
//! iceoryx2 catches both alike and ends a wait with one `TerminationRequest` that does not say
//! which signal came, yet a process must exit 130 on SIGINT and 143 on SIGTERM
//! ([`formation_proto::exit`]). [`watch_termination_signals`] therefore records each signal in a
//! flag of its own with signal-hook, and [`received`] reads them.
//!
//! The order of installation matters: iceoryx2 installs its handlers once, when its signal
//! handler is first used, and replaces whatever handler was there without calling it. So the
//! watch first makes iceoryx2 install its own, then registers signal-hook's, which chains to the
//! handler it finds: a signal runs iceoryx2's handler (its waits still end) and then sets the flag.
//! The Zenoh and ROS 2 links do not use this: their signal thread (signal-hook's iterator) is told
//! the signal itself.

use std::sync::Arc;

use formation_proto::exit::TerminationSignal;
use formation_runtime::process::TerminationWatch;

/// The flags, once installed (or why they could not be).
static FLAGS: TerminationWatch = TerminationWatch::new();

/// The signal flags could not be installed: a SIGINT and a SIGTERM then both read as SIGINT.
#[derive(Debug, Clone, thiserror::Error)]
#[error("could not watch for SIGINT and SIGTERM")]
pub struct SignalWatchError {
    /// The operating system's error.
    #[source]
    pub source: Arc<std::io::Error>,
}

/// From now on, records SIGINT and SIGTERM for [`received`], beside iceoryx2's own handling.
/// Idempotent: the first call installs, later ones report what it did.
pub fn watch_termination_signals() -> Result<(), SignalWatchError> {
    // Makes iceoryx2 install its handlers first (its signal handler is created on first use), so
    // it never replaces signal-hook's later; the call only reads (and clears) the last signal, and
    // no signal can be pending yet: before this, SIGINT and SIGTERM had their default action.
    FLAGS
        .watch(|| {
            let _ = iceoryx2_bb_posix::signal::SignalHandler::last_signal();
        })
        .map_err(|source| SignalWatchError { source })
}

/// The termination signal received since [`watch_termination_signals`], if any; SIGTERM when
/// both came.
pub fn received() -> Option<TerminationSignal> {
    FLAGS.received()
}

/// The signal that made iceoryx2 end a wait with a termination request: the one recorded, or
/// SIGINT when none was (the watch could not be installed).
pub fn termination_requested() -> TerminationSignal {
    received().unwrap_or(TerminationSignal::Interrupt)
}
