//! An agent's Zenoh link ([`ZenohAgentLink`]): a client of the world's router.
//!
//! The agent connects to the world's endpoint (logging in when it has credentials), waits for
//! the world's liveliness token of its run, greets in its robot's lobby with a proof of the launch
//! secret, and on the world's welcome declares the channels of its incarnation and then its own
//! liveliness token. From then on the world's token tells whether the world is there: when it
//! goes (the world exited, died, or its link was silent past the lease), the agent's loop ends
//! with a message.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::auth::{LaunchSecret, fresh_nonce};
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

use super::model::split_model;
use super::{Bell, Endpoint, Login, Queue, Ring, SignalWatch, keys};
use crate::link::{AgentLink, AgentLinkError, Wake};

fn zenoh_error(action: impl Into<String>) -> impl FnOnce(String) -> AgentLinkError {
    let action = action.into();
    move |detail| AgentLinkError::Zenoh { action, detail }
}

/// How long an agent waits for the answer to one greeting before greeting again with a fresh
/// nonce (a greeting sent while the world's lobby subscription was still on its way is lost).
const GREETING_RETRY: Duration = Duration::from_secs(1);
/// Queued control requests.
const CONTROL_QUEUE: usize = 64;

/// What the world sent, filled by subscriber callbacks.
#[derive(Debug)]
struct Inbox {
    scan: Mutex<Option<ScanMsg>>,
    control: Queue<ControlRequest>,
    welcomes: Queue<(u64, Welcome)>,
    world_present: Mutex<bool>,
    /// Swaps refused on arrival (damaged model bytes): request id and reason, to answer.
    refusals: Queue<(u64, String)>,
}

impl Inbox {
    /// An inbox with nothing in it yet, the world not seen.
    fn empty() -> Inbox {
        Inbox {
            scan: Mutex::new(None),
            control: Queue::new(CONTROL_QUEUE),
            welcomes: Queue::new(8),
            world_present: Mutex::new(false),
            refusals: Queue::new(CONTROL_QUEUE),
        }
    }

    fn world_present(&self) -> bool {
        *self.world_present.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The agent's Zenoh session on its own robot's channels.
pub struct ZenohAgentLink {
    bell: Arc<Bell>,
    inbox: Arc<Inbox>,
    session: ::zenoh::Session,
    cmd: String,
    status: String,
    _scan: Subscriber<()>,
    _control: Subscriber<()>,
    _world: Subscriber<()>,
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
        drop(welcomes);
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
            bell,
            inbox,
            cmd,
            status,
            _scan: scan,
            _control: control,
            _world: world,
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
    super::open(config).map_err(|detail| AgentLinkError::Unreachable {
        endpoint: endpoint.to_string(),
        robot,
        detail,
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
    session
        .liveliness()
        .declare_subscriber(keys::world_token(run))
        .history(true)
        .callback(move |sample| {
            *inbox
                .world_present
                .lock()
                .unwrap_or_else(|e| e.into_inner()) = sample.kind() == SampleKind::Put;
            bell.ring();
        })
        .wait()
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
    session
        .declare_subscriber(welcome_key.clone())
        .callback(move |sample| {
            let decoded = message_from_bytes::<WelcomeMsg>("welcome", &sample.payload().to_bytes())
                .and_then(|msg| Ok((msg.nonce, msg.decode()?)));
            match decoded {
                Ok(welcome) => {
                    inbox.welcomes.push(welcome);
                    bell.ring();
                }
                Err(e) => tracing::warn!("ignoring a malformed welcome: {e}"),
            }
        })
        .wait()
        .map_err(|e| zenoh_error(format!("subscribe to {welcome_key}"))(e.to_string()))
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
    session
        .declare_subscriber(key)
        .callback(move |sample| {
            match message_from_bytes::<ScanMsg>("scan", &sample.payload().to_bytes()) {
                Ok(scan) => {
                    *inbox.scan.lock().unwrap_or_else(|e| e.into_inner()) = Some(scan);
                    bell.ring();
                }
                Err(e) => tracing::warn!("ignoring a malformed scan: {e}"),
            }
        })
        .wait()
        .map_err(|e| zenoh_error("subscribe to the scans")(e.to_string()))
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
    session
        .declare_subscriber(key)
        .callback(move |sample| {
            let payload = sample.payload().to_bytes();
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
        })
        .wait()
        .map_err(|e| zenoh_error("subscribe to the control requests")(e.to_string()))
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
                return Err(AgentLinkError::NoWorldAt {
                    endpoint: self.endpoint.to_string(),
                    run: self.run.to_string(),
                    waited_s: self.started.elapsed().as_secs_f64(),
                });
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

impl AgentLink for ZenohAgentLink {
    fn wait(&mut self, timeout: Duration) -> Result<Wake, AgentLinkError> {
        Ok(match self.bell.wait(timeout) {
            Ring::Activity => Wake::Activity,
            Ring::Idle => Wake::Idle,
            Ring::Terminated(signal) => Wake::Terminated(signal),
        })
    }

    fn drain_control(
        &mut self,
        sink: &mut dyn FnMut(ControlRequest),
    ) -> Result<(), AgentLinkError> {
        for (request_id, reason) in self.inbox.refusals.drain() {
            self.publish_status(&AgentStatus::SwapRefused { request_id, reason })?;
        }
        self.inbox.control.drain().into_iter().for_each(sink);
        Ok(())
    }

    fn newest_scan(&mut self) -> Result<Option<ScanMsg>, AgentLinkError> {
        Ok(self
            .inbox
            .scan
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take())
    }

    fn publish_command(&mut self, msg: &CmdMsg) -> Result<(), AgentLinkError> {
        self.session
            .put(&self.cmd, message_bytes(msg).to_vec())
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::RealTime)
            .express(true)
            .wait()
            .map_err(|e| zenoh_error("send a command")(e.to_string()))
    }

    fn publish_status(&mut self, status: &AgentStatus) -> Result<(), AgentLinkError> {
        let msg = StatusMsg::encode(status)?;
        self.session
            .put(&self.status, message_bytes(&msg).to_vec())
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(|e| zenoh_error("send a status")(e.to_string()))
    }

    fn world_alive(&mut self) -> Result<bool, AgentLinkError> {
        Ok(self.inbox.world_present())
    }
}
