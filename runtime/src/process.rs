//! What the world and agent processes share beyond the link: noticing that the launcher is gone,
//! which termination signal came ([`TerminationWatch`], for links whose waits a signal ends
//! without saying which), and their log lines ([`init_tracing`], the `formation` command's too).

use std::io::Read;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use formation_proto::exit::TerminationSignal;

/// Starts a thread that reads standard input to its end and then sets the returned flag: the
/// launcher closed the pipe (it exited, or is shutting the launch down). Only end of file (or a
/// real error) counts: a read that a signal interrupted (EINTR) is simply retried.
pub fn flag_when_stdin_closes() -> Arc<AtomicBool> {
    let closed = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&closed);
    std::thread::spawn(move || {
        let mut sink = [0u8; 256];
        let mut stdin = std::io::stdin();
        loop {
            match stdin.read(&mut sink) {
                Ok(0) => break,
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
        flag.store(true, Ordering::Relaxed);
    });
    closed
}

/// Logs to stderr with `FORMATION_LOG`'s filter, else at the level `verbose` asks for (0: warn,
/// 1: info, more: debug). The `formation` command and both runtime processes start with it.
/// By default Zenoh's own lines are off: it logs every retry of a refused connection with its
/// source paths, and formation says what failed and the fix itself (`-v` or `FORMATION_LOG`
/// shows them).
pub fn init_tracing(verbose: u8) {
    let level = match verbose {
        0 => "warn,zenoh=off",
        1 => "info",
        _ => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_env("FORMATION_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    // Colour only for a terminal: a log file or a pipe gets plain text.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// One flag per termination signal, set by signal-hook's handler.
#[derive(Debug)]
struct TerminationFlags {
    interrupt: Arc<AtomicBool>,
    terminate: Arc<AtomicBool>,
}

/// SIGINT and SIGTERM recorded each in a flag of its own by signal-hook's handler, which chains to
/// the handler it finds, so that a wait can end with the signal (130, 143) instead of the process
/// dying. A link keeps one in a `static` ([`TerminationWatch::new`] is `const`).
#[derive(Debug)]
pub struct TerminationWatch {
    /// The flags, once installed (or why they could not be).
    flags: OnceLock<Result<TerminationFlags, Arc<std::io::Error>>>,
}

impl TerminationWatch {
    /// A watch that records nothing until [`TerminationWatch::watch`].
    pub const fn new() -> TerminationWatch {
        TerminationWatch {
            flags: OnceLock::new(),
        }
    }

    /// From now on, SIGINT and SIGTERM set their flags. The first call runs `before` (what must
    /// install its own handlers first) and installs; it is idempotent: later calls report what
    /// the first did.
    pub fn watch(&self, before: impl FnOnce()) -> Result<(), Arc<std::io::Error>> {
        let install = || -> std::io::Result<TerminationFlags> {
            before();
            let flags = TerminationFlags {
                interrupt: Arc::new(AtomicBool::new(false)),
                terminate: Arc::new(AtomicBool::new(false)),
            };
            signal_hook::flag::register(signal_hook::consts::SIGINT, Arc::clone(&flags.interrupt))?;
            signal_hook::flag::register(
                signal_hook::consts::SIGTERM,
                Arc::clone(&flags.terminate),
            )?;
            Ok(flags)
        };
        match self.flags.get_or_init(|| install().map_err(Arc::new)) {
            Ok(_) => Ok(()),
            Err(e) => Err(Arc::clone(e)),
        }
    }

    /// The termination signal received since [`TerminationWatch::watch`], if any; SIGTERM when
    /// both came.
    pub fn received(&self) -> Option<TerminationSignal> {
        let Some(Ok(flags)) = self.flags.get() else {
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
}

impl Default for TerminationWatch {
    fn default() -> TerminationWatch {
        TerminationWatch::new()
    }
}
