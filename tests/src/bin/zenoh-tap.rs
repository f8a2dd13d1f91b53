//! `zenoh-tap ENDPOINT CREDENTIALS PRINCIPAL KEY...`: a raw Zenoh client (no `formation` code)
//! logged in as `PRINCIPAL` of the team's `CREDENTIALS` folder, with its certificate on a `tls/`
//! endpoint, that prints what it reads, for the TLS tests across network namespaces (the test
//! process cannot enter a namespace itself, so this runs there with `ip netns exec`).
//!
//! It connects, retrying for up to 60 s while nothing listens yet, subscribes to every `KEY`
//! expression, prints `ready`, then prints each sample as `I HEX` (`I` the index of the key
//! expression, `HEX` its payload), at most 400 per key expression, and exits when its standard
//! input closes.

use std::io::Read;
use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use formation_tests::tls::raw_tls_client;
use formation_tests::{retry_for, tool_exit};
use zenoh::Wait;

/// The most samples printed per key expression.
const MOST: usize = 400;

fn main() -> ExitCode {
    tool_exit("zenoh-tap", run())
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [endpoint, credentials, principal, keys @ ..] = args.as_slice() else {
        return Err("usage: zenoh-tap ENDPOINT CREDENTIALS PRINCIPAL KEY...".into());
    };
    let folder = Path::new(credentials);
    let session = retry_for(Duration::from_secs(60), || {
        raw_tls_client(endpoint, folder, principal, Some((folder, principal)))
    })
    .map_err(|e| format!("{principal} could not connect to {endpoint}: {e}"))?;
    let mut subscribers = Vec::new();
    for (index, key) in keys.iter().enumerate() {
        let printed = Arc::new(AtomicUsize::new(0));
        let subscriber = session
            .declare_subscriber(key.as_str())
            .callback(move |sample| {
                if printed.fetch_add(1, Ordering::Relaxed) < MOST {
                    let hex: String = sample
                        .payload()
                        .to_bytes()
                        .iter()
                        .map(|b| format!("{b:02x}"))
                        .collect();
                    println!("{index} {hex}");
                }
            })
            .wait()
            .map_err(|e| format!("subscribing to {key}: {e}"))?;
        subscribers.push(subscriber);
    }
    println!("ready");
    let mut sink = [0u8; 64];
    while matches!(std::io::stdin().read(&mut sink), Ok(n) if n > 0) {}
    drop(subscribers);
    session
        .close()
        .wait()
        .map_err(|e| format!("closing the session: {e}"))
}
