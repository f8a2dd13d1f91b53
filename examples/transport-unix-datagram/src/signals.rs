//! SIGINT and SIGTERM as the runtime's links report them: a flag per signal set by signal-hook's
//! handler ([`watch`]), read by every wait ([`received`]), which then ends with the signal
//! instead of the process dying, so that the world and the agents exit cleanly (130, 143).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use formation_proto::exit::TerminationSignal;

use crate::error::DatagramError;

/// One flag per termination signal.
struct Flags {
    interrupt: Arc<AtomicBool>,
    terminate: Arc<AtomicBool>,
}

/// The flags, once installed (or why they could not be).
static FLAGS: OnceLock<Result<Flags, Arc<std::io::Error>>> = OnceLock::new();

fn install() -> std::io::Result<Flags> {
    let flags = Flags {
        interrupt: Arc::new(AtomicBool::new(false)),
        terminate: Arc::new(AtomicBool::new(false)),
    };
    signal_hook::flag::register(signal_hook::consts::SIGINT, Arc::clone(&flags.interrupt))?;
    signal_hook::flag::register(signal_hook::consts::SIGTERM, Arc::clone(&flags.terminate))?;
    Ok(flags)
}

/// From now on, SIGINT and SIGTERM set their flags instead of ending the process. Idempotent.
pub fn watch() -> Result<(), DatagramError> {
    match FLAGS.get_or_init(|| install().map_err(Arc::new)) {
        Ok(_) => Ok(()),
        Err(e) => Err(DatagramError::Signals(Arc::clone(e))),
    }
}

/// The termination signal received since [`watch`], if any; SIGTERM when both came.
pub fn received() -> Option<TerminationSignal> {
    let Some(Ok(flags)) = FLAGS.get() else {
        return None;
    };
    if flags.terminate.load(Ordering::Relaxed) {
        Some(TerminationSignal::Terminate)
    } else if flags.interrupt.load(Ordering::Relaxed) {
        Some(TerminationSignal::Interrupt)
    } else {
        None
    }
}
