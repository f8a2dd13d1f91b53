//! A transport registered by name (issue 35), across real processes: `formation run --transport
//! unix-datagram` (the example crate `examples/transport-unix-datagram/`, registered in one line
//! of each binary package's `TRANSPORT_PLUGINS`) starts the world and the agents over it and
//! ends in the same `summary.json` as over iceoryx2 for the same seed, byte for byte, leaving
//! nothing in its socket folder; an unknown transport is refused naming the ones there are.
//!
//! The run uses the test's own run id and scratch folder (the endpoint, `--listen FOLDER`), and
//! runs alone within this binary ([`formation_tests::one_at_a_time`]).

use std::path::Path;
use std::time::Duration;

use formation_tests::{ProcessTest, formation_run, run};

const LIMIT: Duration = Duration::from_secs(180);

/// `summary.json` of a lockstep `formation run` of `scenario` into `out` with `extra` flags.
fn lockstep_summary(t: &ProcessTest, scenario: &Path, out: &Path, extra: &[&str]) -> Vec<u8> {
    let mut flags = vec!["--clock", "lockstep"];
    flags.extend_from_slice(extra);
    let finished = run(formation_run(&t.run, scenario, out, &flags), LIMIT);
    finished.assert_success();
    std::fs::read(out.join("summary.json"))
        .unwrap_or_else(|e| panic!("{e}: no summary.json\n{}", finished.describe()))
}

#[test]
fn a_run_over_a_registered_transport_ends_as_over_iceoryx2() {
    let t = ProcessTest::start("registered_transport", LIMIT);
    let scenario = t.case1(5.0);
    let over_iceoryx2 = lockstep_summary(&t, &scenario, &t.path().join("iceoryx2"), &[]);
    let sockets = t.path().join("sockets");
    let endpoint = sockets.display().to_string();
    let over_datagrams = lockstep_summary(
        &t,
        &scenario,
        &t.path().join("unix-datagram"),
        &["--transport", "unix-datagram", "--listen", &endpoint],
    );
    assert_eq!(
        String::from_utf8_lossy(&over_datagrams),
        String::from_utf8_lossy(&over_iceoryx2),
        "the same runs over unix-datagram and iceoryx2"
    );
    // The world made its run's folder in the user's private folder under the endpoint, and
    // took it with it.
    let user_folders: Vec<_> = std::fs::read_dir(&sockets)
        .expect("the endpoint holds the user's folder")
        .flatten()
        .map(|e| e.path())
        .collect();
    assert_eq!(user_folders.len(), 1, "{user_folders:?}");
    let left: Vec<_> = std::fs::read_dir(&user_folders[0])
        .expect("the user's folder")
        .flatten()
        .map(|e| e.path())
        .collect();
    assert!(left.is_empty(), "the run left {left:?}");
    t.assert_clean();
}

#[test]
fn an_unknown_transport_is_refused_naming_the_registered_ones() {
    let t = ProcessTest::start("unknown_transport", LIMIT);
    let scenario = t.case1(1.0);
    let finished = run(
        formation_run(
            &t.run,
            &scenario,
            &t.out(),
            &["--transport", "carrier-pigeon"],
        ),
        LIMIT,
    );
    finished.assert_failure_mentioning("invalid value 'carrier-pigeon' for '--transport");
    finished.assert_failure_mentioning("iceoryx2, zenoh, ros2, unix-datagram");
}
