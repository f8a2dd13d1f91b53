//! SIGINT and SIGTERM as the runtime's links report them: a flag per signal set by signal-hook's
//! handler ([`watch`], the runtime's [`TerminationWatch`]), read by every wait ([`received`]),
//! which then ends with the signal instead of the process dying, so that the world and the agents
//! exit cleanly (130, 143).

use formation_proto::exit::TerminationSignal;
use formation_runtime::process::TerminationWatch;

use crate::error::DatagramError;

/// The flags, once installed (or why they could not be).
static FLAGS: TerminationWatch = TerminationWatch::new();

/// From now on, SIGINT and SIGTERM set their flags instead of ending the process. Idempotent.
pub fn watch() -> Result<(), DatagramError> {
    FLAGS.watch(|| {}).map_err(DatagramError::Signals)
}

/// The termination signal received since [`watch`], if any; SIGTERM when both came.
pub fn received() -> Option<TerminationSignal> {
    FLAGS.received()
}
