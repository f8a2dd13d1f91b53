//! What every test of the workspace needs, whatever it tests: a run id of its own
//! ([`unique_run_id`]), a scratch folder ([`TempDir`]), a FIFO to refuse ([`make_fifo`]), a
//! watchdog that aborts a hung test ([`Watchdog`]), the one-at-a-time guard for wall-clock tests
//! ([`one_at_a_time`]) and free loopback ports ([`free_tcp_port`], [`assert_port_free`]).
//!
//! Light on purpose (it builds only `formation-proto`), so that the transport conformance suite
//! and each transport crate's tests use it without building the rest of the workspace;
//! `formation-tests` re-exports it.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use formation_proto::wire::RunId;

/// A run id no other test (in this or a parallel test process) uses.
pub fn unique_run_id(tag: &str) -> RunId {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tag: String = tag
        .chars()
        .filter(|c| c.is_ascii_alphanumeric())
        .take(6)
        .collect();
    let id = format!("t{tag}{}x{n}", std::process::id());
    RunId::new(&id).unwrap_or_else(|e| panic!("test run id {id:?}: {e}"))
}

/// A scratch directory removed on drop.
pub struct TempDir(PathBuf);

impl TempDir {
    /// A fresh directory under the system temp directory.
    pub fn new(tag: &str) -> TempDir {
        let id = unique_run_id(tag);
        let dir = std::env::temp_dir().join(format!("formation-tests-{id}"));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("creating {}: {e}", dir.display()));
        TempDir(dir)
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Makes a FIFO (named pipe) at `path` with `mkfifo`, for the tests that a file reader refuses
/// one from its metadata (opening a FIFO that has no writer blocks for ever). Panics, naming
/// `path`, when `mkfifo` cannot be run or fails.
pub fn make_fifo(path: &Path) {
    let status = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .unwrap_or_else(|e| panic!("running mkfifo {}: {e}", path.display()));
    assert!(
        status.success(),
        "mkfifo {} failed ({status})",
        path.display()
    );
}

/// Aborts the whole test process if the guarded test is still running after `limit`: a hung
/// multi-process test must fail loudly instead of blocking the suite. Time spent in the one-time
/// shared setup ([`SharedSetup`]: `formation_tests::binaries`, `test_model`) while the watchdog
/// is armed is added to the limit.
pub struct Watchdog {
    done: mpsc::Sender<()>,
}

impl Watchdog {
    /// Arms the watchdog for test `name`.
    pub fn arm(name: &'static str, limit: Duration) -> Watchdog {
        let (done, rx) = mpsc::channel::<()>();
        let armed = Instant::now();
        let setup_before = SharedSetup::time_spent();
        std::thread::spawn(move || {
            loop {
                let deadline =
                    armed + limit + SharedSetup::time_spent().saturating_sub(setup_before);
                let wait = if SharedSetup::running() {
                    Duration::from_secs(1)
                } else {
                    deadline.saturating_duration_since(Instant::now())
                };
                match rx.recv_timeout(wait) {
                    Err(mpsc::RecvTimeoutError::Timeout) => {
                        if SharedSetup::running() || Instant::now() < deadline {
                            continue;
                        }
                        eprintln!(
                            "watchdog: test {name} still running after {limit:?} (not counting \
                             the shared setup); aborting the test process"
                        );
                        std::process::abort();
                    }
                    // Done, or the test's thread is gone.
                    _ => return,
                }
            }
        });
        Watchdog { done }
    }
}

/// The one-time setup that every test of a process waits for (building the runtime binaries,
/// writing the test model): how many are running now, and how long the finished ones took. A
/// [`Watchdog`] does not count the time spent in it.
pub struct SharedSetup {
    started: Instant,
}

static SHARED_SETUP_RUNNING: AtomicUsize = AtomicUsize::new(0);
static SHARED_SETUP_MILLIS: AtomicU64 = AtomicU64::new(0);

impl SharedSetup {
    /// Marks a setup step as running until the returned guard is dropped (also on a panic).
    pub fn begin() -> SharedSetup {
        SHARED_SETUP_RUNNING.fetch_add(1, Ordering::SeqCst);
        SharedSetup {
            started: Instant::now(),
        }
    }

    fn running() -> bool {
        SHARED_SETUP_RUNNING.load(Ordering::SeqCst) > 0
    }

    fn time_spent() -> Duration {
        Duration::from_millis(SHARED_SETUP_MILLIS.load(Ordering::SeqCst))
    }
}

impl Drop for SharedSetup {
    fn drop(&mut self) {
        let millis = u64::try_from(self.started.elapsed().as_millis()).unwrap_or(u64::MAX);
        SHARED_SETUP_MILLIS.fetch_add(millis, Ordering::SeqCst);
        SHARED_SETUP_RUNNING.fetch_sub(1, Ordering::SeqCst);
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        let _ = self.done.send(());
    }
}

/// Multi-process tests time real processes against the wall clock; under plain `cargo test`,
/// holding this guard runs them one at a time within a test binary, so a 2-core machine never
/// starves one test's agents with another's. (`scripts/test-all` runs each test in a process of
/// its own with nextest, two at a time; there the guard has nothing to wait for.)
pub fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A TCP port on 127.0.0.1 that nothing listens on right now: the operating system picks a free
/// one for a listener that is closed at once, so every Zenoh test gets a port of its own.
pub fn free_tcp_port() -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("binding 127.0.0.1:0");
    listener.local_addr().expect("the bound address").port()
}

/// Panics unless nothing listens on `address` (`HOST:PORT`) within a few seconds: a world's
/// router closes its listener on a thread of its own after it is dropped.
pub fn assert_port_free(address: &str) {
    let deadline = Instant::now() + Duration::from_secs(5);
    while std::net::TcpListener::bind(address).is_err() {
        assert!(
            Instant::now() < deadline,
            "{address} is still taken after the world went"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A test that waits for a slow one-time setup (a cold `cargo build`) longer than its limit
    /// is not hung: its watchdog must not abort the process (which would fail this test binary).
    #[test]
    fn the_watchdog_does_not_count_time_spent_in_the_shared_setup() {
        let limit = Duration::from_millis(200);
        let watchdog = Watchdog::arm("shared_setup", limit);
        {
            let _setup = SharedSetup::begin();
            std::thread::sleep(limit * 3);
        }
        std::thread::sleep(limit / 2);
        drop(watchdog);
        assert!(SharedSetup::time_spent() >= limit * 3);
        assert!(!SharedSetup::running());
    }

    #[test]
    fn run_ids_are_unique_and_valid() {
        let a = unique_run_id("same");
        let b = unique_run_id("same");
        assert_ne!(a, b);
        assert!(RunId::new(a.as_str()).is_ok());
    }

    #[test]
    fn a_fifo_is_made_where_asked_and_a_failure_names_the_path() {
        use std::os::unix::fs::FileTypeExt;
        let dir = TempDir::new("fifo");
        let fifo = dir.path().join("pipe");
        make_fifo(&fifo);
        let kind = std::fs::symlink_metadata(&fifo)
            .expect("the FIFO")
            .file_type();
        assert!(kind.is_fifo(), "{kind:?}");
        let taken = std::panic::catch_unwind(|| make_fifo(&fifo)).expect_err("the path is taken");
        let message = taken.downcast_ref::<String>().expect("a formatted message");
        assert!(message.contains(&fifo.display().to_string()), "{message}");
    }

    #[test]
    fn a_free_port_is_free_and_a_taken_one_is_not_until_released() {
        let port = free_tcp_port();
        let address = format!("127.0.0.1:{port}");
        assert_port_free(&address);
        let listener = std::net::TcpListener::bind(&address).expect("binding the free port");
        assert!(std::net::TcpListener::bind(&address).is_err());
        drop(listener);
        assert_port_free(&address);
    }
}
