//! `packet-capture FILE`: every frame of the network namespace it runs in, written to `FILE` as
//! pcap, for the tests that read what crosses the link between two namespaces (no tcpdump is
//! assumed). Run it with `ip netns exec NS` as root. It prints `capturing` once its socket is
//! open and stops when its standard input closes, printing `captured N frames`.
//! See [`formation_tests::capture`].

use std::io::Read;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use formation_tests::capture::{capture_until, packet_socket};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [file] = args.as_slice() else {
        eprintln!("usage: packet-capture FILE");
        return ExitCode::from(2);
    };
    let socket = match packet_socket() {
        Ok(socket) => socket,
        Err(e) => {
            eprintln!("packet-capture: cannot open a packet socket ({e}); it needs root");
            return ExitCode::from(2);
        }
    };
    let out = match std::fs::File::create(file) {
        Ok(out) => out,
        Err(e) => {
            eprintln!("packet-capture: cannot create {file}: {e}");
            return ExitCode::from(2);
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    let stopping = Arc::clone(&stop);
    std::thread::spawn(move || {
        let mut sink = [0u8; 64];
        while matches!(std::io::stdin().read(&mut sink), Ok(n) if n > 0) {}
        stopping.store(true, Ordering::Relaxed);
    });
    println!("capturing");
    match capture_until(&socket, &stop, out) {
        Ok(frames) => {
            println!("captured {frames} frames");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("packet-capture: reading the packet socket: {e}");
            ExitCode::from(2)
        }
    }
}
