//! `zenoh-impostor`: a process that speaks Zenoh but is no `formation-agent`, for the access
//! tests across network namespaces (the test process cannot enter the agents' namespace itself,
//! so this runs there with `ip netns exec`).
//!
//! `zenoh-impostor ENDPOINT RUN LOGIN_FILE OWN ROBOTS`:
//!
//! 1. connects to the world at `ENDPOINT` with the login in `LOGIN_FILE` (robot `OWN`'s
//!    `robot-OWN.json`), retrying for up to 60 s while nothing listens yet, and waits for the
//!    world's liveliness token of run `RUN`; prints `login admitted`;
//! 2. tries to connect without a login and prints `no-login refused: REASON` or
//!    `no-login admitted`;
//! 3. counts the samples of robot `OWN`'s scans and of everything under every other robot
//!    `0..ROBOTS`;
//! 4. from a second session with the same login (a session hands its own puts to its own
//!    subscribers) greets as every other robot, and as robot `OWN`, with a well-formed hello of
//!    its own pid whose proof is wrong: the world would refuse each greeting it sees, and say so;
//! 5. prints `ready pid PID`, waits for its standard input to close, then prints
//!    `own scans N` and `robot R: N samples` for every other robot, and exits.

use std::io::Read;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use formation_proto::wire::{HelloMsg, LobbyChannel, RunId, lobby_service_name, message_bytes};
use formation_tests::{count_samples, raw_client, retry_for, tool_exit};
use formation_transport_zenoh::{credentials, keys};
use zenoh::Wait;

fn main() -> ExitCode {
    tool_exit("zenoh-impostor", run())
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [endpoint, run, login_file, own, robots] = args.as_slice() else {
        return Err("usage: zenoh-impostor ENDPOINT RUN LOGIN_FILE OWN ROBOTS".into());
    };
    let run = RunId::new(run).map_err(|e| e.to_string())?;
    let own: usize = own.parse().map_err(|_| format!("OWN {own:?}"))?;
    let robots: usize = robots.parse().map_err(|_| format!("ROBOTS {robots:?}"))?;
    let login =
        credentials::read_login(std::path::Path::new(login_file)).map_err(|e| e.to_string())?;
    let with_login = Some((login.user(), login.password()));

    let deadline = Instant::now() + Duration::from_secs(60);
    let session = retry_for(Duration::from_secs(60), || raw_client(endpoint, with_login))
        .map_err(|e| format!("{} was not admitted: {e}", login.user()))?;
    // The world's token, watched as an agent watches it (robot logins may).
    let world_seen = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let seen = std::sync::Arc::clone(&world_seen);
    let _world = session
        .liveliness()
        .declare_subscriber(keys::world_token(&run))
        .history(true)
        .callback(move |sample| {
            if sample.kind() == zenoh::sample::SampleKind::Put {
                seen.store(true, Ordering::Relaxed);
            }
        })
        .wait()
        .map_err(|e| format!("watching the world's token: {e}"))?;
    while !world_seen.load(Ordering::Relaxed) {
        if Instant::now() >= deadline {
            return Err(format!("no world token of run {run} within 60 s"));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    println!("login admitted");

    match raw_client(endpoint, None) {
        Ok(_) => println!("no-login admitted"),
        Err(e) => println!("no-login refused: {e}"),
    }

    let (_own, own_scans) = count_samples(&session, format!("formation/{run}/robot/{own}/*/scan"));
    let others: Vec<_> = (0..robots)
        .filter(|&r| r != own)
        .map(|r| {
            let (subscriber, count) =
                count_samples(&session, format!("formation/{run}/robot/{r}/**"));
            (r, subscriber, count)
        })
        .collect();

    let forger = raw_client(endpoint, with_login).map_err(|e| e.to_string())?;
    let pid = std::process::id();
    for robot in (0..robots).filter(|&r| r != own).chain([own]) {
        let hello = HelloMsg {
            pid,
            reserved: 0,
            nonce: 0x1bad_f00d_0000_0000 | robot as u64,
            proof: [0x5a; formation_runtime::auth::PROOF_LEN],
        };
        forger
            .put(
                lobby_service_name(&run, robot, LobbyChannel::Hello),
                message_bytes(&hello).to_vec(),
            )
            .wait()
            .map_err(|e| format!("putting a hello for robot {robot}: {e}"))?;
    }
    println!("ready pid {pid}");

    let mut sink = [0u8; 64];
    while matches!(std::io::stdin().read(&mut sink), Ok(n) if n > 0) {}
    println!("own scans {}", own_scans.load(Ordering::Relaxed));
    for (robot, _subscriber, count) in &others {
        println!("robot {robot}: {} samples", count.load(Ordering::Relaxed));
    }
    drop(forger);
    drop(session);
    Ok(())
}
