//! An agent's Zenoh link ([`ZenohAgentLink`]): a client of the world's router.
//!
//! The agent connects to the world's endpoint (logging in when it has credentials), waits for
//! the world's liveliness token of its run, greets in its robot's lobby with a proof of the launch
//! secret, and on the world's welcome declares the channels of its incarnation and then its own
//! liveliness token. From then on the world's token tells whether the world is there: when it
//! goes (the world exited, died, or the link dropped) and stays gone for
//! [`super::RECONNECT_GRACE`], the agent's loop ends with a message.
//!
//! A link that drops and comes back costs nothing but time: Zenoh reconnects the session and
//! declares the agent's subscribers and token again, and the world sends again the last scan and
//! the control requests of the episode that the drop may have lost. This link keeps the last
//! command it sent and the control requests it received, so a scan it already answered is
//! answered with the same command again (the pilot never decides twice on one scan, which keeps
//! lockstep runs bit-identical), a repeated begin is answered with the status already given, and
//! a repeated swap request with the status that answered it (its `SwapDone` or `SwapRefused`,
//! which the drop may have lost; the model is not loaded twice).
//! A refusal answering its own incarnation's nonce in the lobby (the world counted the agent gone
//! before it came back) ends the agent's loop with that reason.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ::zenoh::Wait;
use ::zenoh::liveliness::LivelinessToken;
use ::zenoh::pubsub::Subscriber;
use ::zenoh::qos::{CongestionControl, Priority};
use ::zenoh::sample::SampleKind;
use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlMsg, ControlRequest, HelloMsg, LobbyChannel, RobotChannel, RunId,
    ScanMsg, StatusMsg, Welcome, WelcomeMsg, lobby_service_name, message_bytes, message_from_bytes,
    robot_service_name,
};
use formation_runtime::auth::{LaunchSecret, fresh_nonce};

use super::model::split_model;
use super::{Bell, Endpoint, Login, Queue, Ring, SignalWatch, keys, subscribe, watch_liveliness};
use crate::ZenohError;
use formation_runtime::link::{AgentLink, AgentLinkError, Wake};

fn zenoh_error(action: impl Into<String>) -> impl FnOnce(String) -> AgentLinkError {
    let action = action.into();
    move |detail| ZenohError::Refused { action, detail }.into()
}

/// How long an agent waits for the answer to one greeting before greeting again with a fresh
/// nonce (a greeting sent while the world's lobby subscription was still on its way is lost).
const GREETING_RETRY: Duration = Duration::from_secs(1);
/// Queued control requests.
const CONTROL_QUEUE: usize = 64;
/// How many swap answers are kept, to answer a swap request sent again after a reconnection.
const SWAP_ANSWERS_KEPT: usize = 8;

/// How many control requests received are remembered, to recognise one sent again after a
/// reconnection.
const SEEN_CONTROLS: usize = 16;

/// What the world sent, filled by subscriber callbacks.
#[derive(Debug)]
struct Inbox {
    scan: Mutex<Option<ScanMsg>>,
    control: Queue<ControlRequest>,
    welcomes: Queue<(u64, Welcome)>,
    world: Mutex<WorldSeen>,
    /// Swaps refused on arrival (damaged model bytes): request id and reason, to answer.
    refusals: Queue<(u64, String)>,
    /// The control requests received lately (their message bytes), to recognise repeats.
    seen_controls: Mutex<VecDeque<Vec<u8>>>,
    /// A begin came again (after a reconnection): the status that answered it is due again.
    begin_repeated: Mutex<bool>,
    /// Swap requests (their ids) that came again after a reconnection: the statuses that
    /// answered them are due again.
    swaps_repeated: Mutex<Vec<u64>>,
    /// This agent's incarnation, once welcomed.
    incarnation: Mutex<Option<u64>>,
    /// The world's reason, when it answered this incarnation's nonce with a refusal (it counted
    /// the agent gone before the agent came back).
    dismissed: Mutex<Option<String>>,
}

/// Whether the world's liveliness token is seen, and since when it is not.
#[derive(Debug, Default)]
struct WorldSeen {
    present: bool,
    /// When the token went, while it stays gone after having been seen.
    gone_since: Option<Instant>,
}

/// Locks `mutex`, keeping its plain data when a callback panicked while holding it.
fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|e| e.into_inner())
}

impl Inbox {
    /// An inbox with nothing in it yet, the world not seen.
    fn empty() -> Inbox {
        Inbox {
            scan: Mutex::new(None),
            control: Queue::new(CONTROL_QUEUE),
            welcomes: Queue::new(8),
            world: Mutex::default(),
            refusals: Queue::new(CONTROL_QUEUE),
            seen_controls: Mutex::default(),
            begin_repeated: Mutex::new(false),
            swaps_repeated: Mutex::default(),
            incarnation: Mutex::new(None),
            dismissed: Mutex::new(None),
        }
    }

    fn world_present(&self) -> bool {
        lock(&self.world).present
    }

    /// The world's token came (`present`) or went, at `now`; a token gone after being seen is
    /// waited for ([`super::RECONNECT_GRACE`]), and both are logged.
    fn world_seen(&self, present: bool, now: Instant) {
        let mut world = lock(&self.world);
        match (present, world.gone_since) {
            (true, Some(since)) => {
                tracing::warn!(
                    "the world is back after {:.1} s",
                    now.saturating_duration_since(since).as_secs_f64()
                );
                world.gone_since = None;
            }
            (false, None) if world.present => {
                tracing::warn!(
                    "lost the world's liveliness (the link dropped?); waiting up to {:.0} s for \
                     it to come back",
                    super::RECONNECT_GRACE.as_secs_f64()
                );
                world.gone_since = Some(now);
            }
            _ => {}
        }
        world.present = present;
    }

    /// Whether the world is there at `now`, or gone for less than [`super::RECONNECT_GRACE`].
    fn world_alive(&self, now: Instant) -> bool {
        let world = lock(&self.world);
        world.present
            || world
                .gone_since
                .is_some_and(|since| now.saturating_duration_since(since) < super::RECONNECT_GRACE)
    }

    /// Whether the control request `head` (its message bytes) was received before; notes it.
    fn control_seen_before(&self, head: &[u8]) -> bool {
        let mut seen = lock(&self.seen_controls);
        if seen.iter().any(|s| s == head) {
            return true;
        }
        if seen.len() == SEEN_CONTROLS {
            seen.pop_front();
        }
        seen.push_back(head.to_vec());
        false
    }
}

/// The agent's Zenoh session on its own robot's channels.
pub struct ZenohAgentLink {
    bell: Arc<Bell>,
    inbox: Arc<Inbox>,
    session: ::zenoh::Session,
    robot: usize,
    cmd: String,
    status: String,
    /// The last command sent: `(generation, tick)` and its bytes, to answer its scan again.
    last_command: Option<((u64, u64), Vec<u8>)>,
    /// The last status that answered a begin (ready or refused), to answer a repeated begin.
    last_begin_answer: Option<Vec<u8>>,
    /// The statuses that answered the latest swap requests, by request id, to answer a repeated
    /// swap request.
    swap_answers: VecDeque<(u64, Vec<u8>)>,
    _scan: Subscriber<()>,
    _control: Subscriber<()>,
    _world: Subscriber<()>,
    _welcomes: Subscriber<()>,
    _token: LivelinessToken,
    _signals: SignalWatch,
    _models: Arc<ModelFolder>,
}

/// Where an agent keeps the models that came over the network: a folder of its own (0700),
/// removed with the link.
#[derive(Debug)]
struct ModelFolder {
    dir: std::path::PathBuf,
}

impl ModelFolder {
    fn new(pid: u32, incarnation: u64) -> ModelFolder {
        ModelFolder {
            dir: std::env::temp_dir().join(format!("formation-agent-{pid}-{incarnation:016x}")),
        }
    }

    /// Writes request `request_id`'s model, owner-only, and returns its path.
    fn store(&self, request_id: u64, model: &[u8]) -> std::io::Result<std::path::PathBuf> {
        use std::io::Write;
        use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(&self.dir)?;
        let path = self.dir.join(format!("swap-{request_id}.onnx"));
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(0o600)
            .open(&path)?;
        file.write_all(model)?;
        Ok(path)
    }
}

impl Drop for ModelFolder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

enum ControlFailure {
    Malformed(String),
    Refused { request_id: u64, reason: String },
}

/// A control request from its payload; a swap's model bytes, when they follow, are checked and
/// stored, and the request then names the stored file.
fn decode_control(payload: &[u8], models: &ModelFolder) -> Result<ControlRequest, ControlFailure> {
    let size = std::mem::size_of::<ControlMsg>();
    let head = payload.get(..size).unwrap_or(payload);
    let request = message_from_bytes::<ControlMsg>("control", head)
        .and_then(|msg| msg.decode())
        .map_err(|e| ControlFailure::Malformed(e.to_string()))?;
    let ControlRequest::SwapModel {
        request_id,
        at_tick,
        ..
    } = request
    else {
        return Ok(request);
    };
    let refused = |reason: String| ControlFailure::Refused { request_id, reason };
    match split_model(payload, size) {
        Ok((_, None)) => Ok(request),
        Ok((_, Some(model))) => {
            let path = models.store(request_id, model).map_err(|e| {
                refused(format!(
                    "the agent could not store the model in {}: {e}",
                    models.dir.display()
                ))
            })?;
            Ok(ControlRequest::SwapModel {
                request_id,
                at_tick,
                path,
            })
        }
        Err(e) => Err(refused(e.to_string())),
    }
}

impl ZenohAgentLink {
    /// Connects to the world at `endpoint` (logging in with `login` when given), asks to drive
    /// robot `robot` of run `run` proving `secret`, and declares the channels the world then
    /// opened for this agent. Waits up to `timeout` in all; an unreachable endpoint, a world of
    /// another run and a refusal are errors naming the cause.
    pub fn connect(
        endpoint: &Endpoint,
        login: Option<&Login>,
        run: &RunId,
        robot: usize,
        secret: &LaunchSecret,
        timeout: Duration,
    ) -> Result<Self, AgentLinkError> {
        Self::connect_as(
            endpoint,
            login,
            (run, robot),
            secret,
            timeout,
            std::process::id(),
        )
    }

    /// [`ZenohAgentLink::connect`] to robot `robot` of run `run` (`(run, robot)`) for an agent
    /// known as process `pid` (what it proves, its liveliness token, its model folder): this
    /// process's id, except in tests that run several agents of one robot in one process.
    pub fn connect_as(
        endpoint: &Endpoint,
        login: Option<&Login>,
        (run, robot): (&RunId, usize),
        secret: &LaunchSecret,
        timeout: Duration,
        pid: u32,
    ) -> Result<Self, AgentLinkError> {
        let started = Instant::now();
        let deadline = started + timeout;
        let session = open_session(endpoint, login, robot, timeout)?;
        let bell = Arc::new(Bell::default());
        let signals = SignalWatch::start(Arc::clone(&bell))
            .map_err(|e| zenoh_error("watch for SIGINT and SIGTERM")(e.to_string()))?;
        let inbox = Arc::new(Inbox::empty());
        let world = watch_world(&session, run, &inbox, &bell)?;
        let welcomes = subscribe_welcomes(&session, run, robot, &inbox, &bell)?;
        let rendezvous = Rendezvous {
            session: &session,
            inbox: &inbox,
            bell: &bell,
            endpoint,
            run,
            robot,
            started,
            deadline,
        };
        rendezvous.wait_for_world()?;
        let incarnation = rendezvous.greet_until_welcomed(secret, pid)?;
        // The lobby stays subscribed: a refusal answering this incarnation's nonce later says
        // the world counted this agent gone.
        *lock(&inbox.incarnation) = Some(incarnation);
        let name = |channel| robot_service_name(run, robot, incarnation, channel);
        let scan = subscribe_scans(&session, name(RobotChannel::Scan), &inbox, &bell)?;
        let models = Arc::new(ModelFolder::new(pid, incarnation));
        let control = subscribe_control(
            &session,
            name(RobotChannel::Control),
            &inbox,
            &bell,
            &models,
        )?;
        // Plain puts on the full key rather than declared publishers: the world's access control
        // checks each put's key, and a publisher's first put declares a numeric alias for it.
        let cmd = name(RobotChannel::Cmd);
        let status = name(RobotChannel::Status);
        let token = session
            .liveliness()
            .declare_token(keys::agent_token(run, robot, incarnation, pid))
            .wait()
            .map_err(|e| zenoh_error("declare the agent's liveliness token")(e.to_string()))?;
        Ok(ZenohAgentLink {
            session,
            robot,
            bell,
            inbox,
            cmd,
            status,
            last_command: None,
            last_begin_answer: None,
            swap_answers: VecDeque::new(),
            _scan: scan,
            _control: control,
            _world: world,
            _welcomes: welcomes,
            _token: token,
            _signals: signals,
            _models: models,
        })
    }
}

/// Opens robot `robot`'s agent session: a client of the world's router at `endpoint`, logging
/// in with `login` when given, connecting within `timeout`.
fn open_session(
    endpoint: &Endpoint,
    login: Option<&Login>,
    robot: usize,
    timeout: Duration,
) -> Result<::zenoh::Session, AgentLinkError> {
    #[cfg(feature = "tls")]
    super::check_tls_client(endpoint, login, timeout)?;
    let config = super::client_config(endpoint, timeout, login).map_err(zenoh_error(format!(
        "configure the connection to {endpoint}"
    )))?;
    super::open(config).map_err(|detail| {
        ZenohError::Unreachable {
            endpoint: endpoint.to_string(),
            robot,
            detail,
        }
        .into()
    })
}

/// Watches the world's liveliness token of run `run` (with history, so a token declared before
/// is seen): whether the world is there goes to `inbox`, and each change rings `bell`.
fn watch_world(
    session: &::zenoh::Session,
    run: &RunId,
    inbox: &Arc<Inbox>,
    bell: &Arc<Bell>,
) -> Result<Subscriber<()>, AgentLinkError> {
    let inbox = Arc::clone(inbox);
    let bell = Arc::clone(bell);
    watch_liveliness(session, keys::world_token(run), move |sample| {
        inbox.world_seen(sample.kind() == SampleKind::Put, Instant::now());
        bell.ring();
    })
    .map_err(|e| zenoh_error("watch the world's liveliness")(e.to_string()))
}

/// Subscribes to robot `robot`'s welcome channel of run `run`: each well-formed welcome (with
/// the nonce of the greeting it answers) is queued in `inbox` and rings `bell`; malformed ones
/// are logged and dropped.
fn subscribe_welcomes(
    session: &::zenoh::Session,
    run: &RunId,
    robot: usize,
    inbox: &Arc<Inbox>,
    bell: &Arc<Bell>,
) -> Result<Subscriber<()>, AgentLinkError> {
    let welcome_key = lobby_service_name(run, robot, LobbyChannel::Welcome);
    let inbox = Arc::clone(inbox);
    let bell = Arc::clone(bell);
    let subscriber = subscribe(session, welcome_key, move |sample| {
        let decoded = message_from_bytes::<WelcomeMsg>("welcome", &sample.payload().to_bytes())
            .and_then(|msg| Ok((msg.nonce, msg.decode()?)));
        match decoded {
            Ok((nonce, Welcome::Refused(reason))) if *lock(&inbox.incarnation) == Some(nonce) => {
                *lock(&inbox.dismissed) = Some(reason);
                bell.ring();
            }
            Ok(welcome) => {
                inbox.welcomes.push(welcome);
                bell.ring();
            }
            Err(e) => tracing::warn!("ignoring a malformed welcome: {e}"),
        }
    })?;
    Ok(subscriber)
}

/// Subscribes to the incarnation's scan channel `key`: each well-formed scan replaces the one
/// waiting in `inbox` and rings `bell`; malformed ones are logged and dropped.
fn subscribe_scans(
    session: &::zenoh::Session,
    key: String,
    inbox: &Arc<Inbox>,
    bell: &Arc<Bell>,
) -> Result<Subscriber<()>, AgentLinkError> {
    let inbox = Arc::clone(inbox);
    let bell = Arc::clone(bell);
    declare_subscriber(session, key, "subscribe to the scans", move |sample| {
        match message_from_bytes::<ScanMsg>("scan", &sample.payload().to_bytes()) {
            Ok(scan) => {
                *inbox.scan.lock().unwrap_or_else(|e| e.into_inner()) = Some(scan);
                bell.ring();
            }
            Err(e) => tracing::warn!("ignoring a malformed scan: {e}"),
        }
    })
}

/// Subscribes to the incarnation's control channel `key`: requests (a swap's model stored in
/// `models`) are queued in `inbox`, swaps refused on arrival are queued to be answered, and
/// either rings `bell`; malformed requests are logged and dropped.
fn subscribe_control(
    session: &::zenoh::Session,
    key: String,
    inbox: &Arc<Inbox>,
    bell: &Arc<Bell>,
    models: &Arc<ModelFolder>,
) -> Result<Subscriber<()>, AgentLinkError> {
    let inbox = Arc::clone(inbox);
    let bell = Arc::clone(bell);
    let models = Arc::clone(models);
    declare_subscriber(
        session,
        key,
        "subscribe to the control requests",
        move |sample| {
            let payload = sample.payload().to_bytes();
            let head = payload
                .get(..std::mem::size_of::<ControlMsg>())
                .unwrap_or(&payload);
            if inbox.control_seen_before(head) {
                // Sent again after a reconnection: handled already. A begin's or a swap's answer
                // is due again (it may be what the drop lost).
                match message_from_bytes::<ControlMsg>("control", head).and_then(|m| m.decode()) {
                    Ok(ControlRequest::BeginEpisode { .. }) => {
                        *lock(&inbox.begin_repeated) = true;
                        bell.ring();
                    }
                    Ok(ControlRequest::SwapModel { request_id, .. }) => {
                        lock(&inbox.swaps_repeated).push(request_id);
                        bell.ring();
                    }
                    _ => {}
                }
                return;
            }
            match decode_control(&payload, &models) {
                Ok(request) => {
                    tracing::debug!("control request arrived: {request:?}");
                    if !inbox.control.push(request) {
                        tracing::warn!("control requests overflowed; dropped the oldest");
                    }
                }
                Err(ControlFailure::Malformed(e)) => {
                    tracing::warn!("ignoring a malformed control request: {e}");
                    return;
                }
                Err(ControlFailure::Refused { request_id, reason }) => {
                    inbox.refusals.push((request_id, reason));
                }
            }
            bell.ring();
        },
    )
}

/// Declares a subscriber on `key` that hands each sample to `callback`; Zenoh's refusal is its
/// failing to `action`.
fn declare_subscriber(
    session: &::zenoh::Session,
    key: String,
    action: &str,
    callback: impl Fn(::zenoh::sample::Sample) + Send + Sync + 'static,
) -> Result<Subscriber<()>, AgentLinkError> {
    session
        .declare_subscriber(key)
        .callback(callback)
        .wait()
        .map_err(|e| zenoh_error(action)(e.to_string()))
}

/// What an agent needs while it finds the world and greets it: the session, what the
/// subscribers filled, and the time it may take (from `started` to `deadline`).
struct Rendezvous<'a> {
    session: &'a ::zenoh::Session,
    inbox: &'a Inbox,
    bell: &'a Bell,
    endpoint: &'a Endpoint,
    run: &'a RunId,
    robot: usize,
    started: Instant,
    deadline: Instant,
}

impl Rendezvous<'_> {
    /// Blocks until the bell rings or `until` passes; a SIGINT or SIGTERM is an error.
    fn wait_until(&self, until: Instant) -> Result<(), AgentLinkError> {
        let left = until.saturating_duration_since(Instant::now());
        match self.bell.wait(left) {
            Ring::Terminated(signal) => Err(AgentLinkError::Terminated(signal)),
            _ => Ok(()),
        }
    }

    /// Waits until the world's liveliness token of the run is seen, or fails at the deadline
    /// naming the endpoint and run.
    fn wait_for_world(&self) -> Result<(), AgentLinkError> {
        while !self.inbox.world_present() {
            if Instant::now() >= self.deadline {
                return Err(ZenohError::NoWorldAt {
                    endpoint: self.endpoint.to_string(),
                    run: self.run.to_string(),
                    waited_s: self.started.elapsed().as_secs_f64(),
                }
                .into());
            }
            self.wait_until(self.deadline)?;
        }
        Ok(())
    }

    /// Greets in the robot's lobby as process `pid` proving `secret`, with a fresh nonce every
    /// [`GREETING_RETRY`], until a welcome answers one of the greetings sent: returns the
    /// accepted greeting's nonce (the incarnation), or fails on a refusal or at the deadline.
    fn greet_until_welcomed(&self, secret: &LaunchSecret, pid: u32) -> Result<u64, AgentLinkError> {
        let (run, robot) = (self.run, self.robot);
        let hello_key = lobby_service_name(run, robot, LobbyChannel::Hello);
        let mut sent = Vec::new();
        loop {
            let now = Instant::now();
            if now >= self.deadline {
                return Err(AgentLinkError::NoWelcome {
                    robot,
                    run: run.to_string(),
                    waited_s: self.started.elapsed().as_secs_f64(),
                });
            }
            let nonce = fresh_nonce()?;
            let hello = HelloMsg {
                pid,
                reserved: 0,
                nonce,
                proof: secret.prove(run, robot, pid, nonce),
            };
            self.session
                .put(hello_key.clone(), message_bytes(&hello).to_vec())
                .congestion_control(CongestionControl::Block)
                .wait()
                .map_err(|e| zenoh_error("send the greeting")(e.to_string()))?;
            sent.push(nonce);
            let retry_at = (now + GREETING_RETRY).min(self.deadline);
            while Instant::now() < retry_at {
                for (nonce, welcome) in self.inbox.welcomes.drain() {
                    if !sent.contains(&nonce) {
                        continue;
                    }
                    match welcome {
                        Welcome::Accepted => return Ok(nonce),
                        Welcome::Refused(reason) => {
                            return Err(AgentLinkError::Refused { robot, reason });
                        }
                    }
                }
                self.wait_until(retry_at)?;
            }
            tracing::info!("robot {robot}: no answer to the greeting yet; greeting again");
        }
    }
}

impl ZenohAgentLink {
    /// Puts `bytes` on `key` reliably (statuses, and commands sent again).
    fn put_reliably(&self, key: &str, bytes: Vec<u8>, what: &str) -> Result<(), AgentLinkError> {
        self.session
            .put(key, bytes)
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(|e| zenoh_error(format!("send {what}"))(e.to_string()))
    }
}

impl AgentLink for ZenohAgentLink {
    fn wait(&mut self, timeout: Duration) -> Result<Wake, AgentLinkError> {
        let ring = self.bell.wait(timeout);
        if let Some(reason) = lock(&self.inbox.dismissed).take() {
            return Err(AgentLinkError::Refused {
                robot: self.robot,
                reason,
            });
        }
        Ok(Wake::from(ring))
    }

    fn drain_control(
        &mut self,
        sink: &mut dyn FnMut(ControlRequest),
    ) -> Result<(), AgentLinkError> {
        if std::mem::take(&mut *lock(&self.inbox.begin_repeated))
            && let Some(answer) = self.last_begin_answer.clone()
        {
            tracing::info!("the world began the episode again (a reconnection); answering again");
            self.put_reliably(&self.status, answer, "a status again")?;
        }
        let repeated = std::mem::take(&mut *lock(&self.inbox.swaps_repeated));
        for request_id in repeated {
            let answer = self.swap_answers.iter().find(|(id, _)| *id == request_id);
            if let Some((_, answer)) = answer.cloned() {
                tracing::warn!(
                    "the world asked for swap {request_id} again (a reconnection); answering again"
                );
                self.put_reliably(&self.status, answer, "a swap's status again")?;
            }
        }
        for (request_id, reason) in self.inbox.refusals.drain() {
            self.publish_status(&AgentStatus::SwapRefused { request_id, reason })?;
        }
        self.inbox.control.drain().into_iter().for_each(sink);
        Ok(())
    }

    fn newest_scan(&mut self) -> Result<Option<ScanMsg>, AgentLinkError> {
        let Some(scan) = lock(&self.inbox.scan).take() else {
            return Ok(None);
        };
        match &self.last_command {
            Some((answered, bytes)) if *answered == (scan.generation, scan.tick) => {
                // The world sent it again after a reconnection: the answer may be what the drop
                // lost. The same command again, never a second decision.
                tracing::info!(
                    "tick {}: scan sent again; sending its command again",
                    scan.tick
                );
                self.put_reliably(&self.cmd, bytes.clone(), "a command again")?;
                Ok(None)
            }
            _ => Ok(Some(scan)),
        }
    }

    fn publish_command(&mut self, msg: &CmdMsg) -> Result<(), AgentLinkError> {
        let bytes = message_bytes(msg).to_vec();
        self.session
            .put(&self.cmd, bytes.clone())
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::RealTime)
            .express(true)
            .wait()
            .map_err(|e| zenoh_error("send a command")(e.to_string()))?;
        self.last_command = Some(((msg.generation, msg.tick), bytes));
        Ok(())
    }

    fn publish_status(&mut self, status: &AgentStatus) -> Result<(), AgentLinkError> {
        let msg = StatusMsg::encode(status)?;
        let bytes = message_bytes(&msg).to_vec();
        if matches!(
            status,
            AgentStatus::Ready { .. } | AgentStatus::Refused { .. }
        ) {
            self.last_begin_answer = Some(bytes.clone());
        }
        if let AgentStatus::SwapDone { request_id, .. }
        | AgentStatus::SwapRefused { request_id, .. } = status
        {
            if self.swap_answers.len() == SWAP_ANSWERS_KEPT {
                self.swap_answers.pop_front();
            }
            self.swap_answers.push_back((*request_id, bytes.clone()));
        }
        self.put_reliably(&self.status, bytes, "a status")
    }

    fn world_alive(&mut self) -> Result<bool, AgentLinkError> {
        Ok(self.inbox.world_alive(Instant::now()))
    }
}
