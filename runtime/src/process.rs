//! What the world and agent processes share beyond the link: noticing that the launcher is gone,
//! and their log lines ([`init_tracing`], the `formation` command's too).

use std::io::Read;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

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
