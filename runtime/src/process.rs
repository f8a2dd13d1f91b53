//! What the world and agent processes share beyond the link: noticing that the launcher is gone.

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
