//! An agent's iceoryx2 link ([`IceoryxAgentLink`]).
//!
//! An agent first asks in its robot's lobby to drive the robot, proving with the launch secret
//! that its own launch started it; the world then creates the services of this agent's
//! *incarnation* (named by the agent's fresh nonce) and the agent opens only those. They have
//! room for one subscriber on the scan and one publisher on the command, so while this agent runs
//! no other process can read its scan or command its robot.

use std::rc::Rc;
use std::time::{Duration, Instant};

use crate::naming::{RunNamespace, ServiceLimits, WORLD_NODE_NAME, agent_node_name};
use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlMsg, ControlRequest, HelloMsg, LobbyChannel, RobotChannel, ScanMsg,
    StatusMsg, Welcome, WelcomeMsg, lobby_service_name, robot_service_name,
};
use formation_runtime::auth::{LaunchSecret, fresh_nonce};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;

use super::services::{
    Access, ServiceError, ServiceErrorKind, drain_decoded, event_service, pubsub_service, run_node,
    subscriber,
};
use super::watch_termination_signals;
use crate::error::{IceoryxCause, IceoryxError, iox};
use crate::signals;
use crate::wakes::{AttachedListeners, Fired, wait_collecting};
use formation_runtime::link::{AgentLink, AgentLinkError, Wake};

/// The agent's iceoryx2 ports on its own robot's services.
pub struct IceoryxAgentLink {
    node: Node<ipc::Service>,
    scan: Subscriber<ipc::Service, ScanMsg, ()>,
    control: Subscriber<ipc::Service, ControlMsg, ()>,
    cmd: Publisher<ipc::Service, CmdMsg, ()>,
    cmd_wake: Notifier<ipc::Service>,
    status: Publisher<ipc::Service, StatusMsg, ()>,
    status_wake: Notifier<ipc::Service>,
    waitset: Rc<WaitSet<ipc::Service>>,
    /// The scan and control wake-ups, attached to `waitset` for the link's life.
    wakes: AttachedListeners,
    /// The attachments the last wait woke on (kept to reuse its allocation).
    fired: Fired,
    /// The world's process, once found: watched through /proc, so that checking it costs the
    /// same whatever the team size (listing every node of a 256-robot run from every idle agent
    /// four times a second would keep two cores busy).
    world: Option<ProcessWatch>,
}

/// A process known by its pid and its start time (which tells a reused pid from the original).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct ProcessWatch {
    pid: i32,
    started: u64,
}

impl ProcessWatch {
    /// The process `pid` as it runs now; `None` when it does not exist or has exited (a zombie).
    fn of(pid: i32) -> Option<ProcessWatch> {
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
        // The command name (field 2) may hold spaces and parentheses: fields after it follow
        // the last ')'. Field 3 is the state, field 22 the start time.
        let rest = stat.get(stat.rfind(')')? + 1..)?;
        let mut fields = rest.split_whitespace();
        let state = fields.next()?;
        if state == "Z" || state == "X" {
            return None;
        }
        let started = fields.nth(18)?.parse().ok()?;
        Some(ProcessWatch { pid, started })
    }

    /// Whether the same process still runs (a stopped one does).
    fn alive(&self) -> bool {
        ProcessWatch::of(self.pid) == Some(*self)
    }
}

const RETRY_PERIOD: Duration = Duration::from_millis(20);

impl IceoryxAgentLink {
    /// Asks to drive robot `robot` of the run in `namespace`, proving `secret`, and opens the
    /// services the world then creates for this agent. Waits up to `timeout` for the world's
    /// lobby to exist and for its answer; a refusal (the robot is taken, the proof is wrong) is
    /// an error at once.
    pub fn connect(
        namespace: &RunNamespace,
        robot: usize,
        secret: &LaunchSecret,
        timeout: Duration,
    ) -> Result<Self, AgentLinkError> {
        Self::connect_as(namespace, robot, secret, timeout, std::process::id())
    }

    /// [`IceoryxAgentLink::connect`] for an agent known as process `pid` (its node's name, what
    /// it proves and how the world tells whether it lives): this process's id, except in tests
    /// that run several agents of one robot in one process, one after another.
    pub fn connect_as(
        namespace: &RunNamespace,
        robot: usize,
        secret: &LaunchSecret,
        timeout: Duration,
        pid: u32,
    ) -> Result<Self, AgentLinkError> {
        watch_termination_signals();
        namespace.prepare()?;
        let config = namespace.iceoryx_config()?;
        let node = run_node(&config, &agent_node_name(robot, pid))?;
        // iceoryx2 makes its node-management segment world-writable (this agent may be the first
        // process of the run to create it): close it at once.
        namespace.restrict_permissions()?;
        let started = Instant::now();
        let deadline = started + timeout;
        let not_found = || -> AgentLinkError {
            IceoryxError::WorldNotFound {
                robot,
                run: namespace.run().to_string(),
                waited_s: started.elapsed().as_secs_f64(),
            }
            .into()
        };
        let lobby = loop {
            if let Some(signal) = signals::received() {
                return Err(AgentLinkError::Terminated(signal));
            }
            match open_lobby(&node, namespace, robot) {
                Ok(lobby) => break lobby,
                Err(OpenFailure::Fatal(e)) => return Err(e),
                Err(_) if Instant::now() >= deadline => return Err(not_found()),
                Err(_) => std::thread::sleep(RETRY_PERIOD),
            }
        };
        // A squatter may race us to the new services; a fresh greeting gets fresh ones.
        const ATTEMPTS: usize = 3;
        let mut last_taken = None;
        for _ in 0..ATTEMPTS {
            let nonce = fresh_nonce()?;
            let hello = HelloMsg {
                pid,
                reserved: 0,
                nonce,
                proof: secret.prove(namespace.run(), robot, pid, nonce),
            };
            lobby
                .hello
                .send_copy(hello)
                .map_err(iox("send the greeting"))?;
            let _ = lobby.hello_wake.notify();
            match await_welcome(&lobby, nonce, deadline)? {
                None => {
                    return Err(AgentLinkError::NoWelcome {
                        robot,
                        run: namespace.run().to_string(),
                        waited_s: started.elapsed().as_secs_f64(),
                    });
                }
                Some(Welcome::Refused(reason)) => {
                    return Err(AgentLinkError::Refused { robot, reason });
                }
                Some(Welcome::Accepted) => {}
            }
            match try_open(&node, namespace, robot, nonce) {
                Ok(ports) => return IceoryxAgentLink::from_ports(node, ports),
                Err(OpenFailure::Fatal(e)) => return Err(e),
                Err(OpenFailure::NotYet) => return Err(not_found()),
                Err(OpenFailure::Taken { port, source }) => {
                    tracing::warn!(
                        "robot {robot}: another process took this agent's new {port} port; \
                         greeting again"
                    );
                    last_taken = Some((port, source));
                }
            }
        }
        let (port, source) =
            last_taken.map_or(("scan", None), |(port, source)| (port, Some(source)));
        Err(IceoryxError::PortTaken {
            robot,
            port,
            source,
        }
        .into())
    }

    fn from_ports(node: Node<ipc::Service>, ports: Ports) -> Result<Self, AgentLinkError> {
        let waitset = Rc::new(
            WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
                .create::<ipc::Service>()
                .map_err(iox("create the agent's wait set"))?,
        );
        let (scan, scan_wake, control, control_wake, cmd, cmd_wake, status, status_wake) = ports;
        let wakes = AttachedListeners::attach(&waitset, vec![scan_wake, control_wake])?;
        Ok(IceoryxAgentLink {
            node,
            scan,
            control,
            cmd,
            cmd_wake,
            status,
            status_wake,
            waitset,
            wakes,
            fired: Fired::new(),
            world: None,
        })
    }

    /// Lists the run's nodes: whether the world's is alive, and its process when it is.
    fn find_world(&self) -> Result<Option<ProcessWatch>, AgentLinkError> {
        let found = crate::services::alive_node(&self.node, WORLD_NODE_NAME)?;
        // Alive, but its process could not be read: list the nodes again next time.
        Ok(found.map(|pid| {
            pid.and_then(ProcessWatch::of)
                .unwrap_or(ProcessWatch::UNKNOWN)
        }))
    }
}

impl ProcessWatch {
    /// A live world whose process could not be read: checked by listing nodes each time.
    const UNKNOWN: ProcessWatch = ProcessWatch { pid: 0, started: 0 };
}

/// The candidate's ends of a robot's lobby.
struct Lobby {
    hello: Publisher<ipc::Service, HelloMsg, ()>,
    hello_wake: Notifier<ipc::Service>,
    welcome: Subscriber<ipc::Service, WelcomeMsg, ()>,
}

/// A service opened with [`Access::Open`]: one the world has not created yet is
/// [`OpenFailure::NotYet`].
fn opened<T>(result: Result<T, ServiceError>) -> Result<T, OpenFailure> {
    result.map_err(|e| match e.kind {
        ServiceErrorKind::Name => OpenFailure::Fatal(e.open_failed().into()),
        ServiceErrorKind::Unavailable => OpenFailure::NotYet,
    })
}

/// A port this agent needs is held by someone else.
fn taken<E: std::error::Error + Send + Sync + 'static>(
    port: &'static str,
) -> impl FnOnce(E) -> OpenFailure {
    move |e| OpenFailure::Taken {
        port,
        source: Box::new(e),
    }
}

fn open_lobby(
    node: &Node<ipc::Service>,
    namespace: &RunNamespace,
    robot: usize,
) -> Result<Lobby, OpenFailure> {
    let name = |channel| lobby_service_name(namespace.run(), robot, channel);
    let hello_name = name(LobbyChannel::Hello);
    let hello_limits = ServiceLimits::HELLO;
    let welcome_limits = ServiceLimits::WELCOME;
    // The subscriber exists before the greeting goes out, so the answer cannot be missed.
    let welcome = subscriber(
        &opened(pubsub_service::<WelcomeMsg>(
            node,
            &name(LobbyChannel::Welcome),
            welcome_limits,
            Access::Open,
        ))?,
        welcome_limits,
    )
    .map_err(taken("welcome"))?;
    let hello = opened(pubsub_service::<HelloMsg>(
        node,
        &hello_name,
        hello_limits,
        Access::Open,
    ))?
    .publisher_builder()
    .create()
    .map_err(taken("hello"))?;
    let hello_wake = opened(event_service(node, &hello_name, hello_limits, Access::Open))?
        .notifier_builder()
        .create()
        .map_err(taken("hello event"))?;
    Ok(Lobby {
        hello,
        hello_wake,
        welcome,
    })
}

/// Polls the welcome service for the answer to `nonce` until `deadline`.
fn await_welcome(
    lobby: &Lobby,
    nonce: u64,
    deadline: Instant,
) -> Result<Option<Welcome>, AgentLinkError> {
    const POLL: Duration = Duration::from_millis(2);
    loop {
        while let Some(sample) = lobby
            .welcome
            .receive()
            .map_err(iox("receive the world's answer"))?
        {
            if sample.payload().nonce == nonce {
                return Ok(Some(sample.payload().decode()?));
            }
        }
        if let Some(signal) = signals::received() {
            return Err(AgentLinkError::Terminated(signal));
        }
        if Instant::now() >= deadline {
            return Ok(None);
        }
        std::thread::sleep(POLL);
    }
}

enum OpenFailure {
    /// The world has not created the services yet.
    NotYet,
    /// A port this agent needs is held by someone else.
    Taken {
        port: &'static str,
        source: IceoryxCause,
    },
    Fatal(AgentLinkError),
}

type Ports = (
    Subscriber<ipc::Service, ScanMsg, ()>,
    Listener<ipc::Service>,
    Subscriber<ipc::Service, ControlMsg, ()>,
    Listener<ipc::Service>,
    Publisher<ipc::Service, CmdMsg, ()>,
    Notifier<ipc::Service>,
    Publisher<ipc::Service, StatusMsg, ()>,
    Notifier<ipc::Service>,
);

fn try_open(
    node: &Node<ipc::Service>,
    namespace: &RunNamespace,
    robot: usize,
    incarnation: u64,
) -> Result<Ports, OpenFailure> {
    let limits = ServiceLimits::ROBOT;
    let name = |channel| robot_service_name(namespace.run(), robot, incarnation, channel);
    let event = |channel| opened(event_service(node, &name(channel), limits, Access::Open));
    macro_rules! open_pubsub {
        ($payload:ty, $channel:expr) => {
            opened(pubsub_service::<$payload>(
                node,
                &name($channel),
                limits,
                Access::Open,
            ))?
        };
    }
    let scan = open_pubsub!(ScanMsg, RobotChannel::Scan);
    let control = open_pubsub!(ControlMsg, RobotChannel::Control);
    let cmd = open_pubsub!(CmdMsg, RobotChannel::Cmd);
    let status = open_pubsub!(StatusMsg, RobotChannel::Status);
    let listener = |channel, port| -> Result<Listener<ipc::Service>, OpenFailure> {
        event(channel)?
            .listener_builder()
            .create()
            .map_err(taken(port))
    };
    let notifier = |channel, port| -> Result<Notifier<ipc::Service>, OpenFailure> {
        event(channel)?
            .notifier_builder()
            .create()
            .map_err(taken(port))
    };
    Ok((
        subscriber(&scan, limits).map_err(taken("scan"))?,
        listener(RobotChannel::Scan, "scan event")?,
        subscriber(&control, limits).map_err(taken("control"))?,
        listener(RobotChannel::Control, "control event")?,
        cmd.publisher_builder().create().map_err(taken("command"))?,
        notifier(RobotChannel::Cmd, "command event")?,
        status
            .publisher_builder()
            .create()
            .map_err(taken("status"))?,
        notifier(RobotChannel::Status, "status event")?,
    ))
}

impl AgentLink for IceoryxAgentLink {
    fn wait(&mut self, timeout: Duration) -> Result<Wake, AgentLinkError> {
        let result = wait_collecting(&self.waitset, timeout, &mut self.fired)
            .map_err(iox("wait for the world"))?;
        self.wakes.consume(&self.fired);
        let activity = !self.fired.is_empty();
        if let Some(signal) = signals::received() {
            return Ok(Wake::Terminated(signal));
        }
        Ok(match result {
            WaitSetRunResult::TerminationRequest => {
                Wake::Terminated(signals::termination_requested())
            }
            // An interrupted wait (EINTR: SIGCONT after a stop, SIGUSR1, SIGURG, ...) is not a
            // termination: look again.
            WaitSetRunResult::Interrupt => Wake::Activity,
            _ if activity => Wake::Activity,
            _ => Wake::Idle,
        })
    }

    fn drain_control(
        &mut self,
        sink: &mut dyn FnMut(ControlRequest),
    ) -> Result<(), AgentLinkError> {
        let decode = ControlMsg::decode;
        Ok(drain_decoded(
            &self.control,
            &"control request",
            decode,
            sink,
        )?)
    }

    fn newest_scan(&mut self) -> Result<Option<ScanMsg>, AgentLinkError> {
        let mut newest = None;
        while let Some(sample) = self.scan.receive().map_err(iox("receive a scan"))? {
            newest = Some(*sample.payload());
        }
        Ok(newest)
    }

    fn publish_command(&mut self, msg: &CmdMsg) -> Result<(), AgentLinkError> {
        self.cmd.send_copy(*msg).map_err(iox("send a command"))?;
        let _ = self.cmd_wake.notify();
        Ok(())
    }

    fn publish_status(&mut self, status: &AgentStatus) -> Result<(), AgentLinkError> {
        let msg = StatusMsg::encode(status)?;
        self.status.send_copy(msg).map_err(iox("send a status"))?;
        let _ = self.status_wake.notify();
        Ok(())
    }

    fn world_alive(&mut self) -> Result<bool, AgentLinkError> {
        if let Some(world) = self.world
            && world != ProcessWatch::UNKNOWN
            && world.alive()
        {
            return Ok(true);
        }
        // First check, or the watched process is gone: iceoryx2's node list decides.
        self.world = self.find_world()?;
        let alive = self.world.is_some();
        if !alive {
            // The world died without cleaning up: release what it left, so the last process of
            // the run leaves nothing behind.
            let _ = self.node.try_cleanup_dead_nodes();
        }
        Ok(alive)
    }
}

#[cfg(test)]
mod tests {
    use super::ProcessWatch;

    #[test]
    fn a_process_is_watched_by_pid_and_start_time() {
        let me = ProcessWatch::of(std::process::id() as i32).expect("this process");
        assert!(me.alive());
        let reused = ProcessWatch {
            started: me.started + 1,
            ..me
        };
        assert!(
            !reused.alive(),
            "a pid whose start time differs is another process"
        );
        assert!(ProcessWatch::of(i32::MAX).is_none(), "no such process");
    }
}
