//! Recording a live Zenoh or ROS 2 team from outside: the world's record channel
//! ([`ZenohRecordFeed`]) and the recorder's client ([`RecorderLink`]), carrying the
//! live-recording messages of `formation_record::live` as opaque bytes. A ROS 2 world declares
//! the same channel and token on its own session (`formation_transport_ros2::Ros2WorldLink::record_feed`).
//!
//! The world publishes each message on `formation/<run>/record/live` ([`keys::record_live`])
//! reliably and blocking under congestion, so a lockstep run waits for a slow recorder rather
//! than losing a tick, and only while a subscriber matches: nobody recording costs nothing. The
//! setup of the run under way also answers queries on `formation/<run>/record/setup`, for a
//! recorder that joins while a run plays. On a Zenoh team only the `recorder` login may subscribe
//! and query there ([`super::access`]); a ROS 2 team has no logins, so its recorder connects
//! without one.
//!
//! The recorder subscribes first, then watches the world's liveliness token (its going ends
//! the recording: the team ended, or the link was lost), then asks for the setup; SIGINT and
//! SIGTERM end it too. Its subscriber hands messages over a bounded queue whose sender blocks,
//! so a recorder that falls behind slows the world down instead of dropping ticks.

use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ::zenoh::Wait;
use ::zenoh::pubsub::{Publisher, Subscriber};
use ::zenoh::qos::CongestionControl;
use ::zenoh::query::Queryable;
use ::zenoh::sample::SampleKind;
use formation_proto::exit::TerminationSignal;
use formation_proto::wire::RunId;

use super::{Bell, Endpoint, Login, Ring, SignalWatch, keys, watch_liveliness};
use crate::ZenohError;
use formation_runtime::link::{RecordFeed, WorldLinkError, WorldResult};

/// Messages queued between the recorder's subscriber and its writer before the subscriber
/// waits (and with it, through Zenoh's reliable channel, the world).
const RECORDER_QUEUE: usize = 256;

/// How long a recorder waits for the world's answer to its setup query.
const SETUP_QUERY_TIMEOUT: Duration = Duration::from_secs(5);

fn zenoh_error(action: impl Into<String>) -> impl FnOnce(String) -> WorldLinkError {
    let action = action.into();
    move |detail| ZenohError::Refused { action, detail }.into()
}

/// The world's record channel.
pub struct ZenohRecordFeed {
    publisher: Publisher<'static>,
    setup: Arc<Mutex<Option<Vec<u8>>>>,
    _queryable: Queryable<()>,
}

impl ZenohRecordFeed {
    /// Declares run `run`'s record channel and setup queryable on the world's `session`.
    pub fn declare(session: &::zenoh::Session, run: &RunId) -> WorldResult<Self> {
        let live = keys::record_live(run);
        let publisher = session
            .declare_publisher(live.clone())
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(|e| zenoh_error(format!("declare a publisher on {live}"))(e.to_string()))?;
        let setup: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
        let served = Arc::clone(&setup);
        let setup_key = keys::record_setup(run);
        let answer_key = setup_key.clone();
        let queryable = session
            .declare_queryable(setup_key.clone())
            .callback(move |query| {
                let bytes = served.lock().unwrap_or_else(|e| e.into_inner()).clone();
                if let Some(bytes) = bytes
                    && let Err(e) = query.reply(answer_key.clone(), bytes).wait()
                {
                    tracing::warn!("could not answer a recorder's setup query: {e}");
                }
            })
            .wait()
            .map_err(|e| {
                zenoh_error(format!("declare a queryable on {setup_key}"))(e.to_string())
            })?;
        Ok(ZenohRecordFeed {
            publisher,
            setup,
            _queryable: queryable,
        })
    }
}

impl RecordFeed for ZenohRecordFeed {
    fn wanted(&self) -> bool {
        self.publisher
            .matching_status()
            .wait()
            .is_ok_and(|status| status.matching())
    }

    fn begin_run(&mut self, setup: Vec<u8>) -> WorldResult {
        *self.setup.lock().unwrap_or_else(|e| e.into_inner()) = Some(setup.clone());
        if self.wanted() {
            self.publish(setup)?;
        }
        Ok(())
    }

    fn publish(&mut self, message: Vec<u8>) -> WorldResult {
        self.publisher
            .put(message)
            .wait()
            .map_err(|e| zenoh_error("publish on the record channel")(e.to_string()))
    }
}

/// What a recorder's link delivers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RecorderEvent {
    /// One live-recording message, in the world's order.
    Message(Vec<u8>),
    /// The world's liveliness token went: the team ended, or the link to it was lost.
    WorldGone,
    /// SIGINT or SIGTERM.
    Stopped(TerminationSignal),
}

/// Why a recorder could not connect.
#[derive(Debug, thiserror::Error)]
pub enum RecorderLinkError {
    /// The recorder's TLS certificate is not usable, or the world refused it (feature `tls`).
    #[cfg(feature = "tls")]
    #[error(transparent)]
    Tls(#[from] super::tls::TlsError),
    /// The world's endpoint could not be reached, or its router refused the login.
    #[error(
        "cannot reach the team at {endpoint}, or its router refused the recorder's login: \
         {detail}; is the team listening there, and (a Zenoh team) is --credentials the \
         recorder.json of this team's credentials folder?"
    )]
    Unreachable {
        /// The endpoint.
        endpoint: String,
        /// Zenoh's error.
        detail: String,
    },
    /// The router accepted the TCP connection but not the login: the password is not the one
    /// the team was launched with.
    #[error(
        "the router at {endpoint} accepted the connection but refused the login of user {user} \
         (no session within {waited_s:.1} s of connecting): --credentials holds another \
         password than the team's; pass the recorder.json of the credentials folder the team \
         was launched with (Zenoh said: {detail})"
    )]
    LoginRefused {
        /// The endpoint.
        endpoint: String,
        /// The user the login named.
        user: String,
        /// How long the login was given \[s\].
        waited_s: f64,
        /// Zenoh's error.
        detail: String,
    },
    /// No world of this run answered in time.
    #[error(
        "no world of run {run} at {endpoint} within {waited_s:.1} s: check --run-id (formation \
         run prints it) and --connect"
    )]
    NoWorld {
        /// The run.
        run: String,
        /// The endpoint.
        endpoint: String,
        /// How long it waited.
        waited_s: f64,
    },
    /// Zenoh refused an operation.
    #[error("zenoh could not {action} ({detail})")]
    Zenoh {
        /// What was being done.
        action: String,
        /// Zenoh's error.
        detail: String,
    },
}

/// How the recorder shows itself to the team it records.
#[derive(Debug, Clone, Copy)]
pub enum RecorderAccess<'a> {
    /// A Zenoh team: the recorder's login, with its certificate beside it on `tls/`.
    Login(&'a Login),
    /// A ROS 2 team on `tls/`: the recorder's certificate, from the folder of this login file;
    /// the team's router names its principals by certificate and has no logins.
    Certificate(&'a Login),
    /// A ROS 2 team on `tcp/`, which has no logins: nothing.
    Open,
}

/// A recorder's connection to a live team.
pub struct RecorderLink {
    session: ::zenoh::Session,
    setup_key: String,
    events: Receiver<RecorderEvent>,
    bell: Arc<Bell>,
    _live: Subscriber<()>,
    _world: Subscriber<()>,
    _signals: SignalWatch,
}

impl RecorderLink {
    /// Connects to run `run`'s world at `endpoint` as `access` says (a Zenoh team's recorder
    /// login; a ROS 2 team's recorder certificate on `tls/`, or nothing on `tcp/`), subscribes
    /// to its record channel, and waits up to `timeout` for the world to be there.
    pub fn connect(
        endpoint: &Endpoint,
        access: RecorderAccess<'_>,
        run: &RunId,
        timeout: Duration,
    ) -> Result<Self, RecorderLinkError> {
        let started = Instant::now();
        let zenoh =
            |action: String| move |e: String| RecorderLinkError::Zenoh { action, detail: e };
        let session = open_session(endpoint, access, timeout)?;
        let bell = Arc::new(Bell::default());
        let signals = SignalWatch::start(Arc::clone(&bell))
            .map_err(|e| zenoh("watch for SIGINT and SIGTERM".into())(e.to_string()))?;
        let (sender, events) = sync_channel(RECORDER_QUEUE);
        let live_key = keys::record_live(run);
        let to_writer = sender.clone();
        let ringer = Arc::clone(&bell);
        let live = session
            .declare_subscriber(live_key.clone())
            .callback(move |sample| {
                // Blocks while the writer is behind: Zenoh's reliable channel then holds the
                // world back rather than dropping a tick.
                let _ = to_writer.send(RecorderEvent::Message(sample.payload().to_bytes().into()));
                ringer.ring();
            })
            .wait()
            .map_err(|e| zenoh(format!("subscribe to {live_key}"))(e.to_string()))?;
        let (world, present) = watch_world(&session, run, sender, &bell)
            .map_err(|e| zenoh("watch the world's liveliness".into())(e))?;
        let link = RecorderLink {
            session,
            setup_key: keys::record_setup(run),
            events,
            bell,
            _live: live,
            _world: world,
            _signals: signals,
        };
        link.await_world(&present, started, timeout)
            .map_err(|waited_s| RecorderLinkError::NoWorld {
                run: run.to_string(),
                endpoint: endpoint.to_string(),
                waited_s,
            })?;
        Ok(link)
    }

    /// Waits until the world's token is seen; `Err(seconds waited)` when it is not in time.
    fn await_world(
        &self,
        present: &Mutex<bool>,
        started: Instant,
        timeout: Duration,
    ) -> Result<(), f64> {
        loop {
            if *present.lock().unwrap_or_else(|e| e.into_inner()) {
                return Ok(());
            }
            let left = timeout.saturating_sub(started.elapsed());
            if left.is_zero() {
                return Err(started.elapsed().as_secs_f64());
            }
            if let Ring::Terminated(_) = self.bell.wait(left.min(Duration::from_millis(100))) {
                return Err(started.elapsed().as_secs_f64());
            }
        }
    }

    /// Asks the world for the setup of the run under way (for a recorder that joined while it
    /// plays); `None` when no run plays or no answer came.
    pub fn ask_setup(&self) -> Option<Vec<u8>> {
        let replies = self
            .session
            .get(self.setup_key.clone())
            .timeout(SETUP_QUERY_TIMEOUT)
            .wait()
            .ok()?;
        while let Ok(reply) = replies.recv() {
            if let Ok(sample) = reply.result() {
                return Some(sample.payload().to_bytes().into());
            }
        }
        None
    }

    /// The next event, waiting up to `timeout` (`None`: nothing came). SIGINT and SIGTERM come
    /// before anything queued.
    pub fn next(&self, timeout: Duration) -> Option<RecorderEvent> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Ring::Terminated(signal) = self.bell.wait(Duration::ZERO) {
                return Some(RecorderEvent::Stopped(signal));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self
                .events
                .recv_timeout(left.min(Duration::from_millis(50)))
            {
                Ok(event) => return Some(event),
                Err(RecvTimeoutError::Timeout) if !left.is_zero() => {}
                Err(_) => return None,
            }
        }
    }
}

/// Opens the recorder's session at `endpoint` within `timeout`. On `tls/` its certificate is
/// checked and shown to the world first (a refusal is named at once). With a login, it then
/// waits for the router's TCP port and gives the login [`super::LOGIN_ANSWER`]: a session that
/// does not open by then was refused by the router (a wrong password), which is said at once
/// rather than after the whole timeout as if the team were not there.
fn open_session(
    endpoint: &Endpoint,
    access: RecorderAccess<'_>,
    timeout: Duration,
) -> Result<::zenoh::Session, RecorderLinkError> {
    let started = Instant::now();
    let (login, password) = match access {
        RecorderAccess::Login(login) => (Some(login), true),
        RecorderAccess::Certificate(login) => (Some(login), false),
        RecorderAccess::Open => (None, false),
    };
    #[cfg(feature = "tls")]
    super::check_tls_client(endpoint, login, timeout)?;
    let configure = |within: Duration| {
        match access {
            RecorderAccess::Certificate(login) => {
                super::certificate_client_config(endpoint, within, login)
            }
            _ => super::client_config(endpoint, within, login),
        }
        .map_err(|detail| RecorderLinkError::Zenoh {
            action: format!("configure the connection to {endpoint}"),
            detail,
        })
    };
    let unreachable = |detail: String| RecorderLinkError::Unreachable {
        endpoint: endpoint.to_string(),
        detail,
    };
    let Some(login) = login.filter(|_| password) else {
        return super::open(configure(timeout)?).map_err(unreachable);
    };
    while !super::accepts_tcp(endpoint, Duration::from_secs(1)) {
        if started.elapsed() >= timeout {
            return Err(unreachable(format!(
                "nothing accepted a TCP connection there within {:.1} s",
                started.elapsed().as_secs_f64()
            )));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    let left = timeout.saturating_sub(started.elapsed());
    let within = left.min(super::LOGIN_ANSWER).max(Duration::from_millis(1));
    super::open(configure(within)?).map_err(|detail| RecorderLinkError::LoginRefused {
        endpoint: endpoint.to_string(),
        user: login.user().to_owned(),
        waited_s: within.as_secs_f64(),
        detail,
    })
}

/// Watches run `run`'s world token (with history): whether it is there goes to the returned
/// flag, and its going is sent to the writer as [`RecorderEvent::WorldGone`].
fn watch_world(
    session: &::zenoh::Session,
    run: &RunId,
    sender: SyncSender<RecorderEvent>,
    bell: &Arc<Bell>,
) -> Result<(Subscriber<()>, Arc<Mutex<bool>>), String> {
    let present = Arc::new(Mutex::new(false));
    let seen = Arc::clone(&present);
    let bell = Arc::clone(bell);
    let subscriber = watch_liveliness(session, keys::world_token(run), move |sample| {
        let put = sample.kind() == SampleKind::Put;
        *seen.lock().unwrap_or_else(|e| e.into_inner()) = put;
        if !put {
            let _ = sender.send(RecorderEvent::WorldGone);
        }
        bell.ring();
    })
    .map_err(|e| e.to_string())?;
    Ok((subscriber, present))
}
