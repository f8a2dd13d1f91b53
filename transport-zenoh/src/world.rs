//! The world's Zenoh link ([`ZenohWorldLink`]): a router listening on one endpoint, holding the
//! world's ends of every channel of the run (see the crate's [`WorldLink`] for what each does).
//!
//! Each robot's lobby subscriber and welcome publisher exist from the start, then the swap
//! channel, then the world's liveliness token (so an agent that sees the token can greet). An
//! incarnation's publishers (scan, control) and subscribers (command, status) are declared when
//! the exchange admits an agent and undeclared when it is gone; what its subscribers receive
//! goes to queues of that incarnation only, so a predecessor's late messages never count.
//!
//! An agent whose liveliness token goes is not dead at once: its session may have dropped and be
//! reconnecting ([`super::RECONNECT_GRACE`]). Until the token comes back the agent is
//! *unreachable*: a successor may take its place, and [`WorldLink::dead_agents`] reports it only
//! once the grace has passed. When it comes back, the link sends it again what the drop may have
//! lost: its incarnation's last scan and the control requests since its episode began (the
//! agent's link answers repeats without deciding again). An agent counted dead whose token comes
//! back later is told in its lobby (a refusal answering its incarnation's nonce), so it exits
//! instead of waiting for scans that never come.

use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ::zenoh::Wait;
use ::zenoh::liveliness::LivelinessToken;
use ::zenoh::pubsub::{Publisher, Subscriber};
use ::zenoh::qos::{CongestionControl, Priority};
use ::zenoh::sample::{Sample, SampleKind};
use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlMsg, ControlRequest, HelloMsg, LobbyChannel, RobotChannel, RunId,
    ScanMsg, StatusMsg, SwapChannel, SwapReply, SwapReplyMsg, SwapRequest, SwapRequestMsg, Welcome,
    WelcomeMsg, lobby_service_name, message_bytes, message_from_bytes, robot_service_name,
    swap_service_name,
};

use super::model::split_model;
use super::{Bell, Endpoint, Queue, SignalWatch, WorldAccess, keys, subscribe, watch_liveliness};
use crate::ZenohError;
use formation_runtime::link::{
    ForwardsSwapModels, Hello, Incarnations, WorldLink, WorldLinkError, WorldResult,
    check_robot_index,
};
use formation_runtime::reconnect::ReconnectGrace;

fn zenoh_error(action: impl Into<String>) -> impl FnOnce(String) -> WorldLinkError {
    let action = action.into();
    move |detail| ZenohError::Refused { action, detail }.into()
}

/// Queued hellos per robot (as many as iceoryx2's hello service buffers).
const HELLO_QUEUE: usize = 8;
/// Queued commands and statuses per incarnation: far more than a tick produces.
const AGENT_QUEUE: usize = 64;
/// Queued swap requests.
const SWAP_QUEUE: usize = 8;
/// The most control requests an incarnation keeps to send again after a reconnection (those
/// since its episode began: a begin and the swaps forwarded since).
const RESEND_CONTROLS: usize = 8;

/// One robot's lobby on the world side.
struct Lobby {
    hellos: Arc<Queue<Hello>>,
    _subscriber: Subscriber<()>,
    welcome: Publisher<'static>,
}

/// The world's ends of one admitted agent's channels.
struct Incarnation {
    /// The incarnation (the accepted nonce).
    id: u64,
    scan: Publisher<'static>,
    control: Publisher<'static>,
    /// The last scan published, to send again when the agent reconnects.
    last_scan: Option<Vec<u8>>,
    /// The control requests since the episode began (a begin first), to send again when the
    /// agent reconnects.
    controls: Vec<Vec<u8>>,
    commands: Arc<Queue<CmdMsg>>,
    statuses: Arc<Queue<AgentStatus>>,
    _cmd: Subscriber<()>,
    _status: Subscriber<()>,
}

/// An agent's token: `(robot, incarnation, pid)`.
type AgentKey = (usize, u64, u32);

/// What the agents' liveliness tokens said.
#[derive(Debug)]
struct Liveness {
    /// Agents whose token went and has not come back: unreachable, counted dead once
    /// [`super::RECONNECT_GRACE`] has passed.
    vanished: ReconnectGrace<AgentKey, ()>,
    /// Agents counted dead (reported by `dead_agents`).
    counted_dead: HashSet<AgentKey>,
    /// `(robot, pid)` of agents whose token went (and no token of that robot and pid came since).
    gone: HashSet<(usize, u32)>,
    /// Agents whose token came back within the grace, not yet handled (sent again what the drop
    /// may have lost).
    returned: Vec<AgentKey>,
    /// Agents counted dead whose token came back, not yet told.
    dismissed: Vec<AgentKey>,
}

impl Liveness {
    /// No token seen yet.
    fn new() -> Self {
        Liveness {
            vanished: ReconnectGrace::new(super::RECONNECT_GRACE),
            counted_dead: HashSet::new(),
            gone: HashSet::new(),
            returned: Vec::new(),
            dismissed: Vec::new(),
        }
    }

    /// Agent `key`'s token came at `now`: back from a drop, a newcomer, or one counted dead.
    fn came(&mut self, key: AgentKey, now: Instant) {
        let (robot, incarnation, pid) = key;
        self.gone.remove(&(robot, pid));
        // An older incarnation of the same robot and pid (tests run several agents in one
        // process) was replaced: its death, if pending, is no longer news.
        self.vanished
            .retain(|&(r, i, p), _| !(r == robot && p == pid && i != incarnation));
        if self.vanished.came_back(&key, now).is_some() {
            self.returned.push(key);
        } else if self.counted_dead.contains(&key) {
            tracing::warn!(
                "robot {robot}: agent pid {pid} came back after it was counted gone; telling it \
                 to start again"
            );
            self.dismissed.push(key);
        }
    }

    /// Agent `key`'s token went at `now`.
    fn went(&mut self, key: AgentKey, now: Instant) {
        let (robot, _, pid) = key;
        self.gone.insert((robot, pid));
        if self.counted_dead.contains(&key) {
            // Counted dead already (and told so when it came back): nothing to wait for.
            return;
        }
        self.vanished.went(
            key,
            (),
            format!("robot {robot}: agent pid {pid}"),
            "its liveliness token went",
            now,
        );
    }

    /// Agents unreachable for the whole grace at `now`: counted dead from now on.
    fn take_dead(&mut self, now: Instant) -> Vec<AgentKey> {
        let dead: Vec<AgentKey> = self
            .vanished
            .expire(now)
            .into_iter()
            .map(|(key, ())| key)
            .collect();
        self.counted_dead.extend(dead.iter().copied());
        dead
    }
}

/// The world's Zenoh session and its ends of every channel of the run.
pub struct ZenohWorldLink {
    session: ::zenoh::Session,
    run: RunId,
    bell: Arc<Bell>,
    lobbies: Vec<Lobby>,
    robots: Incarnations<Incarnation>,
    swap_requests: Arc<Queue<SwapRequest>>,
    /// Swap requests refused on arrival (damaged model bytes), to answer.
    swap_refusals: Arc<Queue<SwapReply>>,
    /// Model bytes that came with a swap request, by request id, until forwarded to the agent.
    swap_models: Arc<Mutex<HashMap<u64, Vec<u8>>>>,
    /// The model bytes the last swap request forwarded to an agent carried, until the exchange
    /// takes them for the recording.
    forwarded_model: Option<(u64, Vec<u8>)>,
    _swap_subscriber: Subscriber<()>,
    swap_replies: Publisher<'static>,
    liveness: Arc<Mutex<Liveness>>,
    _agents: Subscriber<()>,
    _token: LivelinessToken,
    _signals: SignalWatch,
}

/// A subscriber on `key` whose samples `decode` turns into items of `queue`, ringing `bell`.
fn queue_subscriber<T: Send + Sync + 'static>(
    session: &::zenoh::Session,
    key: String,
    bell: &Arc<Bell>,
    queue: &Arc<Queue<T>>,
    decode: impl Fn(&Sample) -> Result<T, String> + Send + Sync + 'static,
) -> Result<Subscriber<()>, WorldLinkError> {
    let bell = Arc::clone(bell);
    let queue = Arc::clone(queue);
    let what = key.clone();
    let subscriber = subscribe(session, key, move |sample| match decode(&sample) {
        Ok(item) => {
            if !queue.push(item) {
                tracing::warn!("{what}: the world fell behind; dropped the oldest message");
            }
            bell.ring();
        }
        Err(e) => tracing::warn!("{what}: ignoring a malformed message: {e}"),
    })?;
    Ok(subscriber)
}

/// A publisher on `key`: scans are express, real-time and dropped under congestion; the rest
/// blocks under congestion.
fn publisher(
    session: &::zenoh::Session,
    key: String,
    realtime: bool,
) -> Result<Publisher<'static>, WorldLinkError> {
    let builder = session.declare_publisher(key.clone());
    let builder = if realtime {
        builder
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::RealTime)
            .express(true)
    } else {
        builder.congestion_control(CongestionControl::Block)
    };
    builder
        .wait()
        .map_err(|e| zenoh_error(format!("declare a publisher on {key}"))(e.to_string()))
}

fn bytes(sample: &Sample) -> std::borrow::Cow<'_, [u8]> {
    sample.payload().to_bytes()
}

/// Model bytes that came with swap requests, by request id, until forwarded to the agent.
type SwapModels = Arc<Mutex<HashMap<u64, Vec<u8>>>>;

impl Lobby {
    /// Declares robot `robot`'s lobby of run `run`: the subscriber queueing its hellos (ringing
    /// `bell`) and the publisher of its welcomes.
    fn declare(
        session: &::zenoh::Session,
        run: &RunId,
        robot: usize,
        bell: &Arc<Bell>,
    ) -> WorldResult<Lobby> {
        let hellos = Arc::new(Queue::new(HELLO_QUEUE));
        let subscriber = queue_subscriber(
            session,
            lobby_service_name(run, robot, LobbyChannel::Hello),
            bell,
            &hellos,
            |sample| {
                let msg: HelloMsg =
                    message_from_bytes("hello", &bytes(sample)).map_err(|e| e.to_string())?;
                Ok(Hello {
                    pid: msg.pid,
                    nonce: msg.nonce,
                    proof: msg.proof,
                })
            },
        )?;
        let welcome = publisher(
            session,
            lobby_service_name(run, robot, LobbyChannel::Welcome),
            false,
        )?;
        Ok(Lobby {
            hellos,
            _subscriber: subscriber,
            welcome,
        })
    }
}

/// Files one swap request's `payload`: a well-formed request goes to `requests` (its model
/// bytes, when they follow, to `models`, which keeps at most [`SWAP_QUEUE`] of them), one whose
/// model bytes are damaged to `refusals`. Returns false for a malformed request (logged and
/// dropped), which is not worth a ring.
fn file_swap_request(
    payload: &[u8],
    requests: &Queue<SwapRequest>,
    refusals: &Queue<SwapReply>,
    models: &Mutex<HashMap<u64, Vec<u8>>>,
) -> bool {
    let size = std::mem::size_of::<SwapRequestMsg>();
    let head = payload.get(..size).unwrap_or(payload);
    let request = match message_from_bytes::<SwapRequestMsg>("swap request", head)
        .and_then(|msg| msg.decode())
    {
        Ok(request) => request,
        Err(e) => {
            tracing::warn!("ignoring a malformed swap request: {e}");
            return false;
        }
    };
    match split_model(payload, size) {
        Ok((_, Some(model))) => {
            let mut models = models.lock().unwrap_or_else(|e| e.into_inner());
            if models.len() >= SWAP_QUEUE {
                // Requests forwarded long ago whose agent never took them.
                let oldest = models.keys().min().copied();
                if let Some(oldest) = oldest {
                    models.remove(&oldest);
                }
            }
            models.insert(request.request_id, model.to_vec());
            drop(models);
            requests.push(request);
        }
        Ok((_, None)) => {
            requests.push(request);
        }
        Err(e) => {
            refusals.push(SwapReply {
                request_id: request.request_id,
                robot: request.robot,
                outcome: formation_proto::wire::SwapOutcome::Refused {
                    reason: e.to_string(),
                },
            });
        }
    }
    true
}

/// Subscribes to run `run`'s swap requests: each is filed ([`file_swap_request`]) and a
/// well-formed one rings `bell`.
fn subscribe_swap_requests(
    session: &::zenoh::Session,
    run: &RunId,
    bell: &Arc<Bell>,
    requests: &Arc<Queue<SwapRequest>>,
    refusals: &Arc<Queue<SwapReply>>,
    models: &SwapModels,
) -> Result<Subscriber<()>, WorldLinkError> {
    let key = swap_service_name(run, SwapChannel::Request);
    let (bell, requests, refusals, models) = (
        Arc::clone(bell),
        Arc::clone(requests),
        Arc::clone(refusals),
        Arc::clone(models),
    );
    let subscriber = subscribe(session, key, move |sample| {
        let payload = bytes(&sample);
        if file_swap_request(&payload, &requests, &refusals, &models) {
            bell.ring();
        }
    })?;
    Ok(subscriber)
}

/// Watches the agents' liveliness tokens of run `run` (with history) into `liveness`
/// ([`Liveness::came`], [`Liveness::went`]), ringing `bell` on each.
fn watch_agents(
    session: &::zenoh::Session,
    run: &RunId,
    liveness: &Arc<Mutex<Liveness>>,
    bell: &Arc<Bell>,
) -> Result<Subscriber<()>, WorldLinkError> {
    let liveness = Arc::clone(liveness);
    let bell = Arc::clone(bell);
    let run = run.clone();
    watch_liveliness(session, keys::agent_tokens(&run), move |sample| {
        let Some(key) = keys::parse_agent_token(&run, sample.key_expr().as_str()) else {
            return;
        };
        let mut liveness = liveness.lock().unwrap_or_else(|e| e.into_inner());
        match sample.kind() {
            SampleKind::Put => liveness.came(key, Instant::now()),
            SampleKind::Delete => liveness.went(key, Instant::now()),
        }
        drop(liveness);
        bell.ring();
    })
    .map_err(|e| zenoh_error("watch the agents' liveliness")(e.to_string()))
}

impl ZenohWorldLink {
    /// Listens on `listen` as a Zenoh router (checking logins and key permissions when `access`
    /// is given), declares every robot's lobby and the swap channel, and then the world's
    /// liveliness token.
    pub fn create(
        run: &RunId,
        n_robots: usize,
        listen: &Endpoint,
        access: Option<&WorldAccess>,
    ) -> WorldResult<Self> {
        let config = super::world_config(listen, access).map_err(zenoh_error(format!(
            "configure the world's router on {listen}"
        )))?;
        let session = super::open(config).map_err(|e| {
            zenoh_error(format!(
                "listen on {listen} (is the port free, and is the address one of this host's?)"
            ))(e)
        })?;
        let bell = Arc::new(Bell::default());
        let signals = SignalWatch::start(Arc::clone(&bell))
            .map_err(|e| zenoh_error("watch for SIGINT and SIGTERM")(e.to_string()))?;
        let mut lobbies = Vec::with_capacity(n_robots);
        for robot in 0..n_robots {
            lobbies.push(Lobby::declare(&session, run, robot, &bell)?);
        }
        let swap_requests = Arc::new(Queue::new(SWAP_QUEUE));
        let swap_refusals = Arc::new(Queue::new(SWAP_QUEUE));
        let swap_models: SwapModels = Arc::default();
        let swap_subscriber = subscribe_swap_requests(
            &session,
            run,
            &bell,
            &swap_requests,
            &swap_refusals,
            &swap_models,
        )?;
        let swap_replies = publisher(&session, swap_service_name(run, SwapChannel::Reply), false)?;
        let liveness = Arc::new(Mutex::new(Liveness::new()));
        let agents = watch_agents(&session, run, &liveness, &bell)?;
        let token = session
            .liveliness()
            .declare_token(keys::world_token(run))
            .wait()
            .map_err(|e| zenoh_error("declare the world's liveliness token")(e.to_string()))?;
        Ok(ZenohWorldLink {
            session,
            run: run.clone(),
            bell,
            lobbies,
            robots: Incarnations::new(n_robots),
            swap_requests,
            swap_refusals,
            swap_models,
            forwarded_model: None,
            _swap_subscriber: swap_subscriber,
            swap_replies,
            liveness,
            _agents: agents,
            _token: token,
            _signals: signals,
        })
    }

    /// The run's record channel for remote recorders (`formation record --connect`), on this
    /// world's session.
    pub fn record_feed(&self) -> WorldResult<super::ZenohRecordFeed> {
        super::ZenohRecordFeed::declare(&self.session, &self.run)
    }

    fn check_robot(&self, robot: usize) -> WorldResult {
        check_robot_index(robot, self.lobbies.len())
    }

    /// Sends agents back from a drop what it may have lost, and tells agents counted gone that
    /// came back that their place is lost (a refusal answering their incarnation's nonce).
    fn heal(&mut self) -> WorldResult {
        let (returned, dismissed) = {
            let mut liveness = self.liveness.lock().unwrap_or_else(|e| e.into_inner());
            (
                std::mem::take(&mut liveness.returned),
                std::mem::take(&mut liveness.dismissed),
            )
        };
        for (robot, incarnation, _) in returned {
            if let Some(ports) = self.robots.get(robot).ok().flatten()
                && ports.id == incarnation
            {
                ports.resend(robot)?;
            }
        }
        for (robot, incarnation, pid) in dismissed {
            if robot >= self.lobbies.len() {
                continue;
            }
            let reason = format!(
                "robot {robot}'s agent pid {pid} was unreachable for more than {:.0} s, so the \
                 world counted it gone and its robot brakes until an agent rejoins; start this \
                 agent again, with the same command, and it rejoins",
                super::RECONNECT_GRACE.as_secs_f64()
            );
            let msg = WelcomeMsg::encode(incarnation, &Welcome::Refused(reason));
            Self::put(&self.lobbies[robot].welcome, message_bytes(&msg), || {
                format!("tell robot {robot}'s former agent it was counted gone")
            })?;
        }
        Ok(())
    }

    fn put(
        publisher: &Publisher<'static>,
        bytes: &[u8],
        what: impl FnOnce() -> String,
    ) -> WorldResult {
        publisher
            .put(bytes.to_vec())
            .wait()
            .map_err(|e| zenoh_error(what())(e.to_string()))
    }
}

impl Incarnation {
    /// Keeps control request `request` (sent as `payload`) to send again after a reconnection:
    /// a begin starts the list afresh.
    fn keep_control(&mut self, request: &ControlRequest, payload: Vec<u8>) {
        if matches!(request, ControlRequest::BeginEpisode { .. }) {
            self.controls.clear();
        }
        if self.controls.len() == RESEND_CONTROLS {
            self.controls.remove(1.min(self.controls.len() - 1));
        }
        self.controls.push(payload);
    }

    /// Sends robot `robot`'s agent, back from a drop, its episode's control requests and its
    /// last scan again (its link answers what it already answered without deciding again).
    fn resend(&self, robot: usize) -> WorldResult {
        for payload in &self.controls {
            ZenohWorldLink::put(&self.control, payload, || {
                format!("send robot {robot}'s control request again")
            })?;
        }
        if let Some(scan) = &self.last_scan {
            ZenohWorldLink::put(&self.scan, scan, || {
                format!("send robot {robot}'s scan again")
            })?;
        }
        Ok(())
    }

    /// The world's ends of incarnation `incarnation` of robot `robot` (`(robot, incarnation)`)
    /// of run `run` on `session`: subscribers of its commands and statuses that queue them and
    /// ring `bell`, publishers of its scans and control requests.
    fn open(
        session: &::zenoh::Session,
        run: &RunId,
        bell: &Arc<Bell>,
        (robot, incarnation): (usize, u64),
    ) -> WorldResult<Incarnation> {
        let name = |channel| robot_service_name(run, robot, incarnation, channel);
        let commands = Arc::new(Queue::new(AGENT_QUEUE));
        let statuses = Arc::new(Queue::new(AGENT_QUEUE));
        let cmd = queue_subscriber(
            session,
            name(RobotChannel::Cmd),
            bell,
            &commands,
            |sample| {
                message_from_bytes::<CmdMsg>("command", &bytes(sample)).map_err(|e| e.to_string())
            },
        )?;
        let status = queue_subscriber(
            session,
            name(RobotChannel::Status),
            bell,
            &statuses,
            |sample| {
                let msg: StatusMsg =
                    message_from_bytes("status", &bytes(sample)).map_err(|e| e.to_string())?;
                msg.decode().map_err(|e| e.to_string())
            },
        )?;
        Ok(Incarnation {
            id: incarnation,
            scan: publisher(session, name(RobotChannel::Scan), true)?,
            control: publisher(session, name(RobotChannel::Control), false)?,
            last_scan: None,
            controls: Vec::new(),
            commands,
            statuses,
            _cmd: cmd,
            _status: status,
        })
    }
}

impl WorldLink for ZenohWorldLink {
    fn n_robots(&self) -> usize {
        self.lobbies.len()
    }

    fn drain_hellos(&mut self, robot: usize, sink: &mut dyn FnMut(Hello)) -> WorldResult {
        self.check_robot(robot)?;
        self.lobbies[robot]
            .hellos
            .drain()
            .into_iter()
            .for_each(sink);
        Ok(())
    }

    fn answer_hello(&mut self, robot: usize, nonce: u64, welcome: &Welcome) -> WorldResult {
        self.check_robot(robot)?;
        let msg = WelcomeMsg::encode(nonce, welcome);
        Self::put(&self.lobbies[robot].welcome, message_bytes(&msg), || {
            format!("answer a hello for robot {robot}")
        })
    }

    fn open_incarnation(&mut self, robot: usize, incarnation: u64) -> WorldResult {
        let (session, run, bell) = (&self.session, &self.run, &self.bell);
        self.robots.open(robot, || {
            Incarnation::open(session, run, bell, (robot, incarnation))
        })
    }

    fn close_incarnation(&mut self, robot: usize) {
        self.robots.close(robot);
    }

    fn publish_scan(&mut self, robot: usize, msg: &ScanMsg) -> WorldResult {
        let Some(ports) = self.robots.get_mut(robot)? else {
            return Ok(());
        };
        let bytes = message_bytes(msg).to_vec();
        ports
            .scan
            .put(bytes.clone())
            .wait()
            .map_err(|e| zenoh_error(format!("send robot {robot}'s scan"))(e.to_string()))?;
        ports.last_scan = Some(bytes);
        Ok(())
    }

    fn send_control(&mut self, robot: usize, request: &ControlRequest) -> WorldResult {
        let msg = ControlMsg::encode(request)?;
        let model = match request {
            ControlRequest::SwapModel { request_id, .. } => self
                .swap_models
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .remove(request_id)
                .map(|model| (*request_id, model)),
            _ => None,
        };
        let Some(ports) = self.robots.get_mut(robot)? else {
            return Ok(());
        };
        let mut payload = message_bytes(&msg).to_vec();
        if let Some((request_id, model)) = model {
            super::model::append_model(&mut payload, &model).map_err(|e| {
                zenoh_error(format!("forward robot {robot}'s swap model"))(e.to_string())
            })?;
            self.forwarded_model = Some((request_id, model));
        }
        Self::put(&ports.control, &payload, || {
            format!("send robot {robot}'s control request")
        })?;
        ports.keep_control(request, payload);
        Ok(())
    }

    fn wait(&mut self, timeout: Duration) -> WorldResult {
        self.heal()?;
        self.bell.world_wait(timeout)
    }

    fn drain_commands(&mut self, robot: usize, sink: &mut dyn FnMut(CmdMsg)) -> WorldResult {
        if let Some(ports) = self.robots.get(robot)? {
            ports.commands.drain().into_iter().for_each(sink);
        }
        Ok(())
    }

    fn drain_statuses(&mut self, robot: usize, sink: &mut dyn FnMut(AgentStatus)) -> WorldResult {
        if let Some(ports) = self.robots.get(robot)? {
            ports.statuses.drain().into_iter().for_each(sink);
        }
        Ok(())
    }

    fn agent_alive(&mut self, robot: usize, pid: u32) -> WorldResult<bool> {
        // An agent is alive until its token goes: one admitted a moment ago may not have
        // declared it yet.
        let liveness = self.liveness.lock().unwrap_or_else(|e| e.into_inner());
        Ok(!liveness.gone.contains(&(robot, pid)))
    }

    fn agent_reconnecting(&mut self, robot: usize, pid: u32) -> WorldResult<bool> {
        let liveness = self.liveness.lock().unwrap_or_else(|e| e.into_inner());
        Ok(liveness
            .vanished
            .any(|&(r, _, p), ()| r == robot && p == pid))
    }

    fn dead_agents(&mut self) -> Result<Vec<(usize, u32)>, WorldLinkError> {
        self.heal()?;
        let n_robots = self.lobbies.len();
        let mut dead: Vec<(usize, u32)> = self
            .liveness
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take_dead(Instant::now())
            .into_iter()
            .map(|(robot, _, pid)| (robot, pid))
            .filter(|&(robot, _)| robot < n_robots)
            .collect();
        dead.sort_unstable();
        dead.dedup();
        Ok(dead)
    }

    fn drain_swap_requests(&mut self, sink: &mut dyn FnMut(SwapRequest)) -> WorldResult {
        for refusal in self.swap_refusals.drain() {
            self.publish_swap_reply(&refusal)?;
        }
        self.swap_requests.drain().into_iter().for_each(sink);
        Ok(())
    }

    fn publish_swap_reply(&mut self, reply: &SwapReply) -> WorldResult {
        let msg = SwapReplyMsg::encode(reply)?;
        Self::put(&self.swap_replies, message_bytes(&msg), || {
            "send a swap reply".to_string()
        })
    }

    fn forwarded_swaps(&mut self) -> Option<&mut dyn ForwardsSwapModels> {
        Some(self)
    }
}

impl ForwardsSwapModels for ZenohWorldLink {
    fn take_forwarded_swap_model(&mut self, request_id: u64) -> Option<Vec<u8>> {
        match self.forwarded_model.take() {
            Some((id, model)) if id == request_id => Some(model),
            _ => None,
        }
    }
}
