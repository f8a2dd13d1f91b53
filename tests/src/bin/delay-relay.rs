//! `delay-relay`: a TCP relay that delays every byte by a random delay, for the Zenoh tests
//! across network namespaces (this kernel has no netem).
//!
//! `delay-relay LISTEN UPSTREAM DELAY_MS JITTER_MS SEED` accepts connections on `LISTEN`, opens
//! one to `UPSTREAM` for each, and forwards both directions, each chunk held for `DELAY_MS` ±
//! `JITTER_MS` (uniform) but never overtaking the chunk before it, as a network delay keeps TCP's
//! order. It prints `listening` once it listens and exits when its standard input closes.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [listen, upstream, delay_ms, jitter_ms, seed] = args.as_slice() else {
        eprintln!("usage: delay-relay LISTEN UPSTREAM DELAY_MS JITTER_MS SEED");
        std::process::exit(2);
    };
    let parse = |what: &str, text: &str| -> u64 {
        text.parse().unwrap_or_else(|_| {
            eprintln!("delay-relay: {what} {text:?} is not a number");
            std::process::exit(2)
        })
    };
    let delay = Duration::from_millis(parse("DELAY_MS", delay_ms));
    let jitter = Duration::from_millis(parse("JITTER_MS", jitter_ms));
    let mut seed = parse("SEED", seed);
    let listener = TcpListener::bind(listen).unwrap_or_else(|e| {
        eprintln!("delay-relay: cannot listen on {listen}: {e}");
        std::process::exit(2)
    });
    println!("listening");
    std::thread::spawn(|| {
        // Exit when the test closes our input (or dies).
        let mut sink = [0u8; 64];
        while matches!(std::io::stdin().read(&mut sink), Ok(n) if n > 0) {}
        std::process::exit(0);
    });
    for client in listener.incoming() {
        let Ok(client) = client else { continue };
        let Ok(server) = TcpStream::connect(upstream.as_str()) else {
            let _ = client.shutdown(Shutdown::Both);
            continue;
        };
        let _ = client.set_nodelay(true);
        let _ = server.set_nodelay(true);
        for (from, to) in [
            (client.try_clone(), server.try_clone()),
            (server.try_clone(), client.try_clone()),
        ] {
            if let (Ok(from), Ok(to)) = (from, to) {
                seed += 1;
                pump(from, to, delay, jitter, seed);
            }
        }
    }
}

/// Forwards `from` to `to`, each chunk delayed; ends both when either side closes.
fn pump(mut from: TcpStream, mut to: TcpStream, delay: Duration, jitter: Duration, seed: u64) {
    let (tx, rx) = mpsc::channel::<(Instant, Vec<u8>)>();
    std::thread::spawn(move || {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut last = Instant::now();
        let mut buffer = vec![0u8; 64 << 10];
        loop {
            match from.read(&mut buffer) {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    let spread = jitter.as_secs_f64();
                    let offset = if spread > 0.0 {
                        rng.random_range(-spread..=spread)
                    } else {
                        0.0
                    };
                    let hold = Duration::from_secs_f64((delay.as_secs_f64() + offset).max(0.0));
                    let due = (Instant::now() + hold).max(last);
                    last = due;
                    if tx.send((due, buffer[..n].to_vec())).is_err() {
                        break;
                    }
                }
            }
        }
        let _ = from.shutdown(Shutdown::Read);
    });
    std::thread::spawn(move || {
        for (due, chunk) in rx {
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
            if to.write_all(&chunk).is_err() {
                break;
            }
        }
        let _ = to.shutdown(Shutdown::Write);
    });
}
