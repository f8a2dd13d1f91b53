//! The Zenoh links: the world's ([`ZenohWorldLink`]) and an agent's ([`ZenohAgentLink`]), for
//! agents on other hosts.
//!
//! The world listens on one TCP endpoint as a Zenoh router (`--listen tcp/ADDR:PORT`) and every
//! agent connects to it as a client (`--connect tcp/ADDR:PORT`): a star, since Zenoh 1.9 peers no
//! longer relay for each other. Multicast scouting and Zenoh's own shared memory are off, so
//! every byte travels over the network, also between network namespaces of one host.
//!
//! The channels are those of the iceoryx2 link, under the run's key space ([`keys`]): each
//! robot's lobby (hello, welcome), the four channels of each admitted agent's incarnation (scan,
//! command, control, status) and the run's swap channel. Each message is the bytes of its
//! `#[repr(C)]` wire value ([`formation_proto::wire::message_bytes`]). Scans and commands are
//! express, of real-time priority and dropped under congestion (a late one is worthless and the
//! world's watchdog brakes its robot); lobby, control, status and swap messages are reliable and
//! block under congestion (they are rare and must arrive).
//!
//! Liveliness tokens tell who is there: the world declares `formation/<run>/world` once its
//! subscribers exist (an agent greets only when it sees it, and exits when it stays gone), and each
//! agent declares `formation/<run>/robot/<i>/<n>/agent/<pid>` for its incarnation (the world
//! counts it dead when the token stays gone). A cut link is seen by liveliness only after the
//! link lease (10 s and more), so the world's command-age watchdog, not liveliness, brakes the
//! robots.
//!
//! A dropped session comes back. When a link resets, or stays silent past the lease (a loaded
//! host, a stopped process, Wi-Fi gone for a while), Zenoh closes the session's transport and the
//! other end's tokens vanish; the agent's client reconnects on its own and declares its
//! subscribers and its token again. Both ends therefore wait [`RECONNECT_GRACE`] (5 s) for a
//! token that went to come back before counting its owner gone:
//!
//! - the world keeps a vanished agent's place (a successor proving the launch secret still takes
//!   it at once); when the token comes back it logs `robot I: agent pid P reconnected after X s`
//!   and sends the agent again the last scan and the control requests of its episode that the
//!   drop may have lost, and in lockstep it holds the tick for the agent meanwhile, so no tick
//!   is lost or doubled and the run stays bit-identical; a token gone for the whole grace is a
//!   dead agent, as before (`robot I: agent pid P has been unreachable for 5 s; counting it
//!   gone`);
//! - the agent logs `lost the world's liveliness (the link dropped?); waiting up to 5 s for it
//!   to come back` and, when it does, `the world is back after X s`; it answers a scan it already
//!   answered with the same command again (never deciding twice), and a repeated control
//!   request with the status it already gave; it exits as the world gone only when the world's
//!   token stayed away for the whole grace. An agent that comes back after the world counted
//!   it gone is told so in its lobby and exits saying to start it again.
//!
//! Subscriber callbacks run on Zenoh's threads: they decode, queue (bounded) and ring a bell (a condition variable);
//! a link's `wait` blocks on the bell's condition variable, which SIGINT/SIGTERM ring too.
//!
//! Who may connect, and which keys each may use, is Zenoh's own user/password authentication
//! and access control ([`access`]).

pub mod access;
mod agent;
pub mod credentials;
pub mod error;
pub mod keys;
pub mod model;
pub mod record;
pub mod swap;
#[cfg(feature = "tls")]
pub mod tls;
mod world;

use std::collections::VecDeque;
use std::fmt;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use ::zenoh::Wait;
use ::zenoh::config::EndPoint;
use formation_proto::exit::TerminationSignal;

pub use access::{AccessError, Login, WorldAccess};
pub use agent::ZenohAgentLink;
pub use error::ZenohError;
pub use record::{RecorderAccess, RecorderEvent, RecorderLink, RecorderLinkError, ZenohRecordFeed};
pub use world::ZenohWorldLink;

/// The most bytes one Zenoh message may carry here (a model sent for a swap is the largest).
pub const MAX_MESSAGE_BYTES: usize = 64 << 20;

/// The link lease: a peer silent this long is dropped (Zenoh's default).
pub const LINK_LEASE: Duration = Duration::from_secs(10);

/// How long either end waits for the other's liveliness token to come back before it counts the
/// other gone. A session whose link dropped (reset, or silent past [`LINK_LEASE`]) reconnects on
/// its own (Zenoh retries every 0.1 s to 1 s) and declares its subscribers and tokens again, so a
/// token that went and came back within this time is the same agent (or world) on the same
/// channels: the world keeps the agent's place, and the agent keeps driving. A process that was
/// killed is counted gone this long after its link closed (its successor is admitted at once).
pub const RECONNECT_GRACE: Duration = Duration::from_secs(5);

/// A Zenoh endpoint, `tcp/HOST:PORT` or (feature `tls`) `tls/HOST:PORT`, checked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint(String);

/// An endpoint that is not `tcp/HOST:PORT` or `tls/HOST:PORT`.
#[derive(Debug, thiserror::Error)]
#[error(
    "{given:?} is not a Zenoh TCP endpoint (tcp/ or tls/): {reason}; write tcp/HOST:PORT, e.g. \
     tcp/192.168.1.10:7447 or tcp/[::1]:7447, or tls/HOST:PORT for mutual TLS"
)]
pub struct EndpointError {
    /// What was given.
    pub given: String,
    /// What is wrong with it.
    pub reason: String,
}

impl Endpoint {
    /// Checks `text` is `tcp/HOST:PORT` or `tls/HOST:PORT` with a port from 1 to 65535; `tls/`
    /// only in a build with the feature `tls`.
    pub fn parse(text: &str) -> Result<Endpoint, EndpointError> {
        let fail = |reason: &str| EndpointError {
            given: text.to_string(),
            reason: reason.to_string(),
        };
        let address = match (text.strip_prefix("tcp/"), text.strip_prefix("tls/")) {
            (Some(address), _) => address,
            (None, Some(address)) if cfg!(feature = "tls") => address,
            (None, Some(_)) => {
                return Err(fail(
                    "this build has no TLS: build with `--features tls` (cargo build \
                     --features tls)",
                ));
            }
            (None, None) => return Err(fail("only tcp/ and tls/ are built in")),
        };
        let (host, port) = address
            .rsplit_once(':')
            .ok_or_else(|| fail("the port is missing"))?;
        if host.is_empty() {
            return Err(fail("the host is missing"));
        }
        match port.parse::<u16>() {
            Ok(p) if p > 0 => {}
            _ => return Err(fail("the port must be a number from 1 to 65535")),
        }
        EndPoint::try_from(text.to_string()).map_err(|e| fail(&e.to_string()))?;
        Ok(Endpoint(text.to_string()))
    }

    /// The endpoint as Zenoh writes it.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether it is a mutual-TLS endpoint (`tls/`).
    pub fn is_tls(&self) -> bool {
        self.0.starts_with("tls/")
    }

    /// `HOST:PORT`, without the protocol.
    pub fn address(&self) -> &str {
        self.0.split_once('/').map_or(self.0.as_str(), |(_, a)| a)
    }

    /// Whether its host is a loopback address (`127.0.0.0/8`, `::1`, `localhost`): traffic that
    /// never leaves this host.
    pub fn is_loopback(&self) -> bool {
        let host = self
            .address()
            .rsplit_once(':')
            .map_or(self.address(), |(host, _)| host);
        let host = host.trim_start_matches('[').trim_end_matches(']');
        host.eq_ignore_ascii_case("localhost")
            || host
                .parse::<std::net::IpAddr>()
                .is_ok_and(|ip| ip.is_loopback())
    }

    /// The warning a router listening here gets: `None` on loopback or TLS.
    pub fn clear_text_warning(&self) -> Option<String> {
        if self.is_tls() || self.is_loopback() {
            return None;
        }
        Some(format!(
            "warning: {self} carries the team in clear text: whoever is on the path reads every \
             scan and command; use tls/{} with the certificates of `formation credentials --tls` \
             (a build with --features tls)",
            self.address()
        ))
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::str::FromStr for Endpoint {
    type Err = EndpointError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Endpoint::parse(s)
    }
}

/// Settings both ends share: no scouting, no shared memory, bounded messages.
pub fn base_config(mode: &str) -> Result<::zenoh::Config, String> {
    let mut config = ::zenoh::Config::default();
    let entries = [
        ("mode", format!("{mode:?}")),
        ("scouting/multicast/enabled", "false".into()),
        ("scouting/gossip/enabled", "false".into()),
        ("transport/shared_memory/enabled", "false".into()),
        (
            "transport/link/rx/max_message_size",
            MAX_MESSAGE_BYTES.to_string(),
        ),
        (
            "transport/link/tx/lease",
            LINK_LEASE.as_millis().to_string(),
        ),
        ("adminspace/enabled", "false".into()),
    ];
    for (key, value) in entries {
        config
            .insert_json5(key, &value)
            .map_err(|e| format!("setting {key} = {value}: {e}"))?;
    }
    Ok(config)
}

/// The world's configuration: a router listening on `listen`, checking logins and key
/// permissions when `access` is given; on a `tls/` endpoint also the certificates of `access`'s
/// folder (the world's own is checked first). A plain `tcp/` endpoint off loopback is warned
/// about once.
pub fn world_config(
    listen: &Endpoint,
    access: Option<&WorldAccess>,
) -> Result<::zenoh::Config, String> {
    let mut config = base_config("router")?;
    config
        .insert_json5("listen/endpoints", &format!("[{:?}]", listen.as_str()))
        .map_err(|e| format!("listening on {listen}: {e}"))?;
    if let Some(warning) = listen.clear_text_warning() {
        static WARNED: std::sync::Once = std::sync::Once::new();
        WARNED.call_once(|| eprintln!("formation-world: {warning}"));
    }
    if listen.is_tls() {
        let access = access.ok_or_else(|| {
            format!(
                "{listen} needs the team's credentials: pass --credentials DIR, a folder written \
                 by `formation credentials --tls`"
            )
        })?;
        apply_world_tls(&mut config, access)?;
    }
    if let Some(access) = access {
        access.apply(&mut config, listen.is_tls())?;
    }
    Ok(config)
}

/// The world's certificate (checked) and the team's authority, from `access`'s folder.
#[cfg(feature = "tls")]
fn apply_world_tls(config: &mut ::zenoh::Config, access: &WorldAccess) -> Result<(), String> {
    let identity = tls::TlsIdentity::in_folder(&access.folder(), tls::WORLD_PRINCIPAL);
    identity
        .load_checked(std::time::SystemTime::now())
        .map_err(|e| e.to_string())?;
    identity.apply_listen(config)
}

/// No TLS in this build ([`Endpoint::parse`] refuses `tls/` already).
#[cfg(not(feature = "tls"))]
fn apply_world_tls(_: &mut ::zenoh::Config, _: &WorldAccess) -> Result<(), String> {
    Err("this build has no TLS: build with `--features tls`".into())
}

/// An agent's (or a tool's) configuration: a client of the world's router at `connect`, within
/// `timeout`, logging in when `login` is given.
pub fn client_config(
    connect: &Endpoint,
    timeout: Duration,
    login: Option<&Login>,
) -> Result<::zenoh::Config, String> {
    let mut config = connection_config(connect, timeout)?;
    if let Some(login) = login {
        login.apply(&mut config)?;
    }
    if connect.is_tls() {
        if login.is_none()
            && let Some(node) = ros2_node_config(connect, &config)?
        {
            return Ok(node);
        }
        client_tls_identity(connect, login)?.apply_connect(&mut config)?;
    }
    Ok(config)
}

/// A client of a ROS 2 team's router on `tls/` known by `login`'s certificate alone (the
/// recorder's, `formation record --connect --transport ros2`): that router names its principals
/// by certificate and has no logins, so the password is not sent.
#[cfg(feature = "tls")]
pub fn certificate_client_config(
    connect: &Endpoint,
    timeout: Duration,
    login: &Login,
) -> Result<::zenoh::Config, String> {
    let mut config = connection_config(connect, timeout)?;
    client_tls_identity(connect, Some(login))?.apply_connect(&mut config)?;
    Ok(config)
}

/// No TLS in this build ([`Endpoint::parse`] refuses `tls/` already).
#[cfg(not(feature = "tls"))]
pub fn certificate_client_config(
    connect: &Endpoint,
    _: Duration,
    _: &Login,
) -> Result<::zenoh::Config, String> {
    Err(format!(
        "{connect}: this build has no TLS: build with `--features tls`"
    ))
}

/// A client's connection to the world's router at `connect`, within `timeout`: no login, no
/// certificate yet.
fn connection_config(connect: &Endpoint, timeout: Duration) -> Result<::zenoh::Config, String> {
    let mut config = base_config("client")?;
    let timeout_ms = timeout.as_millis().clamp(1, i64::MAX as u128);
    let entries = [
        ("connect/endpoints", format!("[{:?}]", connect.as_str())),
        ("connect/timeout_ms", timeout_ms.to_string()),
        ("connect/exit_on_failure", "true".into()),
        (
            "connect/retry",
            "{ period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2 }".into(),
        ),
    ];
    for (key, value) in entries {
        config
            .insert_json5(key, &value)
            .map_err(|e| format!("setting {key} = {value}: {e}"))?;
    }
    Ok(config)
}

/// A ROS 2 node's session on a `tls/` endpoint (no login): the configuration file named by
/// [`SESSION_CONFIG_ENV`], as rmw_zenoh reads it (the ROS 2 team's security module writes it), connecting to
/// `connect` with `base`'s settings of the connection; `None` when the variable is unset.
#[cfg(feature = "tls")]
fn ros2_node_config(
    connect: &Endpoint,
    base: &::zenoh::Config,
) -> Result<Option<::zenoh::Config>, String> {
    let Some(mut config) = session_config_from_env().map_err(|e| e.to_string())? else {
        return Ok(None);
    };
    for key in [
        "connect/timeout_ms",
        "connect/exit_on_failure",
        "connect/retry",
    ] {
        let value = base
            .get_json(key)
            .map_err(|e| format!("reading {key}: {e}"))?;
        config
            .insert_json5(key, &value)
            .map_err(|e| format!("setting {key} = {value}: {e}"))?;
    }
    config
        .insert_json5("connect/endpoints", &format!("[{:?}]", connect.as_str()))
        .map_err(|e| format!("connecting to {connect}: {e}"))?;
    Ok(Some(config))
}

/// No TLS in this build.
#[cfg(not(feature = "tls"))]
fn ros2_node_config(
    _connect: &Endpoint,
    _base: &::zenoh::Config,
) -> Result<Option<::zenoh::Config>, String> {
    Ok(None)
}

/// The certificate files of `login`'s principal, in the folder its login file came from.
#[cfg(feature = "tls")]
fn client_tls_identity(
    connect: &Endpoint,
    login: Option<&Login>,
) -> Result<tls::TlsIdentity, String> {
    let missing = || {
        format!(
            "{connect} needs a certificate: pass --credentials with the login file of a folder \
             written by `formation credentials --tls` (its NAME.pem and NAME.key.pem and ca.pem \
             beside it)"
        )
    };
    let login = login.ok_or_else(missing)?;
    let folder = login.folder().ok_or_else(missing)?;
    Ok(tls::TlsIdentity::in_folder(folder, login.user()))
}

/// No TLS in this build.
#[cfg(not(feature = "tls"))]
fn client_tls_identity(connect: &Endpoint, _: Option<&Login>) -> Result<Never, String> {
    Err(format!(
        "{connect}: this build has no TLS: build with `--features tls`"
    ))
}

/// Stands in for the identity a build without TLS never has.
#[cfg(not(feature = "tls"))]
enum Never {}

#[cfg(not(feature = "tls"))]
impl Never {
    fn apply_connect(&self, _: &mut ::zenoh::Config) -> Result<(), String> {
        match *self {}
    }
}

/// Before a client connects to a `tls/` endpoint: its own certificate is checked against the
/// team's authority, its dates and its name, then one handshake of its own with the world
/// ([`tls::probe`]) names a refusal, within `timeout`. Nothing to do on `tcp/`.
#[cfg(feature = "tls")]
pub fn check_tls_client(
    connect: &Endpoint,
    login: Option<&Login>,
    timeout: Duration,
) -> Result<(), tls::TlsError> {
    if !connect.is_tls() {
        return Ok(());
    }
    let identity = client_tls_identity(connect, login).map_err(|detail| tls::TlsError::Read {
        what: "the certificate".into(),
        path: std::path::PathBuf::from(connect.as_str()),
        source: std::io::Error::other(detail),
    })?;
    let loaded = identity.load_checked(std::time::SystemTime::now())?;
    tls::probe::probe_world(connect.as_str(), &loaded, &identity.principal, timeout)?;
    Ok(())
}

/// Opens a session, mapping Zenoh's error to text (without the source locations Zenoh appends).
pub fn open(config: ::zenoh::Config) -> Result<::zenoh::Session, String> {
    ::zenoh::open(config)
        .wait()
        .map_err(|e| without_source_locations(&e.to_string()))
}

/// Zenoh's error text without the ` at /path/to/zenoh-x.y/src/file.rs:123.` it appends (paths
/// of the build machine's cargo registry, which mean nothing to a user).
pub fn without_source_locations(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find(" at /") {
        let after = &rest[at + 4..];
        let Some(rs) = after.find(".rs:") else {
            break;
        };
        let tail = &after[rs + 4..];
        let digits = tail.len() - tail.trim_start_matches(|c: char| c.is_ascii_digit()).len();
        if digits == 0 || after[..rs].contains(char::is_whitespace) {
            out.push_str(&rest[..at + 4]);
            rest = after;
            continue;
        }
        out.push_str(&rest[..at]);
        rest = tail[digits..].strip_prefix('.').unwrap_or(&tail[digits..]);
    }
    out.push_str(rest);
    out.trim().to_owned()
}

/// How long a client with a login waits for the router once its TCP port accepts: a router
/// answers a login at once, so a session not open by then was refused (a wrong password).
pub const LOGIN_ANSWER: Duration = Duration::from_secs(10);

/// Whether something accepts TCP connections at `endpoint`, within `within`.
pub fn accepts_tcp(endpoint: &Endpoint, within: Duration) -> bool {
    use std::net::ToSocketAddrs as _;
    let Ok(addresses) = endpoint.address().to_socket_addrs() else {
        return false;
    };
    addresses
        .into_iter()
        .any(|a| std::net::TcpStream::connect_timeout(&a, within).is_ok())
}

/// What a link's waits block on: rung by subscriber callbacks (something arrived) and by
/// SIGINT/SIGTERM.
#[derive(Debug, Default)]
pub struct Bell {
    state: Mutex<BellState>,
    rung: Condvar,
}

#[derive(Debug, Default)]
struct BellState {
    pending: bool,
    terminated: Option<TerminationSignal>,
}

/// How a wait on a [`Bell`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ring {
    Activity,
    Idle,
    Terminated(TerminationSignal),
}

impl From<Ring> for formation_runtime::link::Wake {
    /// A bell's ring as an agent link's wait answers it.
    fn from(ring: Ring) -> Self {
        use formation_runtime::link::Wake;
        match ring {
            Ring::Activity => Wake::Activity,
            Ring::Idle => Wake::Idle,
            Ring::Terminated(signal) => Wake::Terminated(signal),
        }
    }
}

impl Bell {
    fn lock(&self) -> MutexGuard<'_, BellState> {
        // A callback that panicked while holding the lock left plain flags behind: keep going.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Something arrived.
    pub fn ring(&self) {
        self.lock().pending = true;
        self.rung.notify_all();
    }

    /// SIGINT or SIGTERM arrived (the first one stands).
    fn terminate(&self, signal: TerminationSignal) {
        self.lock().terminated.get_or_insert(signal);
        self.rung.notify_all();
    }

    /// Blocks until the bell rings or `timeout` passes; a ring that came since the last wait
    /// ends it at once.
    pub fn wait(&self, timeout: Duration) -> Ring {
        let guard = self.lock();
        let (mut guard, _) = self
            .rung
            .wait_timeout_while(guard, timeout, |s| !s.pending && s.terminated.is_none())
            .unwrap_or_else(|e| e.into_inner());
        if let Some(signal) = guard.terminated {
            return Ring::Terminated(signal);
        }
        if std::mem::take(&mut guard.pending) {
            Ring::Activity
        } else {
            Ring::Idle
        }
    }
}

impl Bell {
    /// A world link's wait ([`formation_runtime::link::WorldLink::wait`]): `Ok` when something arrived or
    /// the time passed, [`formation_runtime::link::WorldLinkError::Terminated`] on SIGINT/SIGTERM.
    pub fn world_wait(
        &self,
        timeout: Duration,
    ) -> Result<(), formation_runtime::link::WorldLinkError> {
        match self.wait(timeout) {
            Ring::Terminated(signal) => {
                Err(formation_runtime::link::WorldLinkError::Terminated(signal))
            }
            Ring::Activity | Ring::Idle => Ok(()),
        }
    }
}

/// Rings a [`Bell`] as terminated on SIGINT and SIGTERM, on a thread of its own, until dropped.
/// Stray signals whose default action would end the process (SIGUSR1, SIGUSR2, SIGALRM) are
/// caught and ignored, as the iceoryx2 processes ignore them: a harmless signal never ends a
/// Zenoh or ROS 2 process.
pub struct SignalWatch {
    handle: signal_hook::iterator::Handle,
}

impl SignalWatch {
    pub fn start(bell: Arc<Bell>) -> std::io::Result<SignalWatch> {
        use signal_hook::consts::{SIGALRM, SIGINT, SIGTERM, SIGUSR1, SIGUSR2};
        let mut signals =
            signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGUSR1, SIGUSR2, SIGALRM])?;
        let handle = signals.handle();
        std::thread::Builder::new()
            .name("formation-signals".into())
            .spawn(move || {
                for signal in signals.forever() {
                    if let Some(termination) = TerminationSignal::from_number(signal) {
                        bell.terminate(termination);
                        break;
                    }
                    tracing::debug!("ignoring signal {signal}");
                }
            })?;
        Ok(SignalWatch { handle })
    }
}

impl Drop for SignalWatch {
    fn drop(&mut self) {
        self.handle.close();
    }
}

/// A bounded first-in-first-out queue filled by a subscriber callback: when full, the oldest
/// entry goes (and is counted), so a flooding publisher costs bounded memory.
#[derive(Debug)]
pub struct Queue<T> {
    items: Mutex<VecDeque<T>>,
    capacity: usize,
}

impl<T> Queue<T> {
    pub fn new(capacity: usize) -> Self {
        Queue {
            items: Mutex::new(VecDeque::with_capacity(capacity.min(64))),
            capacity,
        }
    }

    fn lock(&self) -> MutexGuard<'_, VecDeque<T>> {
        self.items.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Adds `item`; returns false when the oldest entry had to go to make room.
    pub fn push(&self, item: T) -> bool {
        let mut items = self.lock();
        let room = items.len() < self.capacity;
        if !room {
            items.pop_front();
        }
        items.push_back(item);
        room
    }

    /// Takes every entry, oldest first.
    pub fn drain(&self) -> VecDeque<T> {
        std::mem::take(&mut *self.lock())
    }
}

/// The environment variable rmw_zenoh reads a node's session configuration from (a path or a
/// `file://` URI); `formation-agent --transport ros2` reads it on a `tls/` endpoint too.
pub const SESSION_CONFIG_ENV: &str = "ZENOH_SESSION_CONFIG_URI";

/// Why the session configuration [`SESSION_CONFIG_ENV`] names cannot be used.
#[cfg(feature = "tls")]
#[derive(Debug, thiserror::Error)]
pub enum SessionConfigError {
    /// No file there.
    #[error(
        "{path} (from {SESSION_CONFIG_ENV}): no such file; point it at the file formation wrote \
         in the credentials folder's ros2/"
    )]
    Missing {
        /// The file.
        path: std::path::PathBuf,
    },
    /// The file is not a Zenoh configuration.
    #[error(
        "{path} (from {SESSION_CONFIG_ENV}) is not a Zenoh configuration: {detail}; use the file \
         formation wrote in the credentials folder's ros2/"
    )]
    NotAConfig {
        /// The file.
        path: std::path::PathBuf,
        /// Zenoh's error.
        detail: String,
    },
}

/// The session configuration file [`SESSION_CONFIG_ENV`] names (a path or a `file://` URI), as
/// rmw_zenoh reads it; `None` when the variable is unset.
#[cfg(feature = "tls")]
fn session_config_from_env() -> Result<Option<::zenoh::Config>, SessionConfigError> {
    let Some(uri) = std::env::var_os(SESSION_CONFIG_ENV) else {
        return Ok(None);
    };
    let text = uri.to_string_lossy();
    let path = std::path::PathBuf::from(text.strip_prefix("file://").unwrap_or(&text));
    if !path.is_file() {
        return Err(SessionConfigError::Missing { path });
    }
    ::zenoh::Config::from_file(&path)
        .map(Some)
        .map_err(|e| SessionConfigError::NotAConfig {
            path,
            detail: e.to_string(),
        })
}

/// Why the endpoint flag of a network transport (`--listen`, `--connect`) gives no endpoint.
#[derive(Debug, thiserror::Error)]
pub enum EndpointFlagError {
    /// The flag is missing.
    #[error(transparent)]
    Missing(#[from] formation_runtime::transport::TransportError),
    /// The flag's value is not `tcp/HOST:PORT`.
    #[error(transparent)]
    Invalid(#[from] EndpointError),
}

/// The Zenoh endpoint that `transport` needs from `flag` (`--listen` or `--connect`), given as
/// `given`: missing, it is [`formation_runtime::transport::TransportError::MissingEndpoint`]
/// naming the flag; given, it must parse as `tcp/HOST:PORT`. One reading for the world's and the
/// agent's processes, over Zenoh and ROS 2.
pub fn required_endpoint(
    given: Option<&str>,
    flag: &'static str,
    transport: formation_runtime::transport::Transport,
) -> Result<Endpoint, EndpointFlagError> {
    let text = given
        .ok_or(formation_runtime::transport::TransportError::MissingEndpoint { flag, transport })?;
    Ok(Endpoint::parse(text)?)
}

/// Declares a subscriber on `key` that hands each sample to `callback`; Zenoh's refusal is a
/// [`ZenohError::Refused`] naming the key.
pub(crate) fn subscribe(
    session: &::zenoh::Session,
    key: String,
    callback: impl Fn(::zenoh::sample::Sample) + Send + Sync + 'static,
) -> Result<::zenoh::pubsub::Subscriber<()>, ZenohError> {
    session
        .declare_subscriber(key.clone())
        .callback(callback)
        .wait()
        .map_err(|e| ZenohError::Refused {
            action: format!("subscribe to {key}"),
            detail: e.to_string(),
        })
}

/// Declares a liveliness subscriber on `key` that hands each sample to `callback`, with history:
/// the tokens declared before it come too, as puts.
pub fn watch_liveliness(
    session: &::zenoh::Session,
    key: String,
    callback: impl Fn(::zenoh::sample::Sample) + Send + Sync + 'static,
) -> ::zenoh::Result<::zenoh::pubsub::Subscriber<()>> {
    session
        .liveliness()
        .declare_subscriber(key)
        .history(true)
        .callback(callback)
        .wait()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 39: Zenoh's errors lose the build machine's source paths, and keep their words.
    #[test]
    fn zenoh_errors_lose_their_source_locations() {
        let text = "Unable to connect to any of [tcp/127.0.0.1:7447]!  at \
                    /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-1.10.0/src/\
                    net/runtime/orchestrator.rs:1000. at /x/y.rs:2";
        assert_eq!(
            without_source_locations(text),
            "Unable to connect to any of [tcp/127.0.0.1:7447]!"
        );
        assert_eq!(
            without_source_locations("look at /etc/hosts"),
            "look at /etc/hosts"
        );
    }

    #[test]
    fn endpoints_must_be_tcp_host_and_port() {
        for good in [
            "tcp/127.0.0.1:7447",
            "tcp/[::1]:1",
            "tcp/robot-host.local:65535",
        ] {
            assert_eq!(Endpoint::parse(good).unwrap().as_str(), good);
        }
        for (bad, why) in [
            ("127.0.0.1:7447", "only tcp/ and tls/"),
            ("udp/127.0.0.1:7447", "only tcp/ and tls/"),
            ("tcp/127.0.0.1", "port is missing"),
            ("tcp/:7447", "host is missing"),
            ("tcp/127.0.0.1:0", "from 1 to 65535"),
            ("tcp/127.0.0.1:99999", "from 1 to 65535"),
        ] {
            let e = Endpoint::parse(bad).unwrap_err().to_string();
            assert!(e.contains(why) && e.contains("tcp/HOST:PORT"), "{bad}: {e}");
        }
    }

    /// Issue 36: a plain endpoint off loopback is warned about, naming `--tls`; loopback and
    /// TLS are not.
    #[test]
    fn clear_text_off_loopback_is_warned_about() {
        let warning = |text: &str| Endpoint::parse(text).unwrap().clear_text_warning();
        for quiet in ["tcp/127.0.0.1:7447", "tcp/[::1]:7447", "tcp/localhost:7447"] {
            assert_eq!(warning(quiet), None, "{quiet}");
        }
        let loud = warning("tcp/0.0.0.0:7447").expect("a warning");
        assert!(
            loud.contains("clear text") && loud.contains("--tls"),
            "{loud}"
        );
        assert!(loud.contains("tls/0.0.0.0:7447"), "{loud}");
        assert!(warning("tcp/robot-host.local:7447").is_some());
        let tls = Endpoint::parse("tls/0.0.0.0:7447");
        if cfg!(feature = "tls") {
            let tls = tls.unwrap();
            assert!(tls.is_tls() && tls.clear_text_warning().is_none());
            assert_eq!(tls.address(), "0.0.0.0:7447");
        } else {
            let e = tls.unwrap_err().to_string();
            assert!(e.contains("--features tls"), "{e}");
        }
    }

    #[test]
    fn a_bell_wakes_a_wait_once_per_ring_and_a_full_queue_drops_the_oldest() {
        let bell = Arc::new(Bell::default());
        assert_eq!(bell.wait(Duration::from_millis(1)), Ring::Idle);
        bell.ring();
        assert_eq!(bell.wait(Duration::from_secs(60)), Ring::Activity);
        assert_eq!(bell.wait(Duration::from_millis(1)), Ring::Idle);
        let ringer = Arc::clone(&bell);
        let thread = std::thread::spawn(move || ringer.ring());
        assert_eq!(bell.wait(Duration::from_secs(60)), Ring::Activity);
        thread.join().unwrap();
        bell.terminate(TerminationSignal::Terminate);
        bell.terminate(TerminationSignal::Interrupt);
        assert_eq!(
            bell.wait(Duration::from_secs(60)),
            Ring::Terminated(TerminationSignal::Terminate),
            "the first signal stands"
        );

        let queue = Queue::new(2);
        assert!(queue.push(1) && queue.push(2));
        assert!(!queue.push(3), "full: the oldest goes");
        assert_eq!(queue.drain(), [2, 3]);
        assert!(queue.drain().is_empty());
    }
}
