//! The world's iceoryx2 link ([`IceoryxWorldLink`]): it creates every service of the run in its
//! namespace and holds the world's ends (see the crate's [`WorldLink`] for what each does).
//!
//! Each robot's lobby exists from the start; an incarnation's four services (scan, command,
//! control, status) are created when the exchange admits an agent, and dropped when it is gone.
//! Every publish-subscribe service is paired with an event service of the same name, because
//! publishing wakes nobody in iceoryx2. The world's listeners stay attached to its wait set from
//! one wait to the next (`AttachedListeners`): the lobbies' and the swap channel's for the whole
//! run, an incarnation's from when it opens until it is dropped.

use std::rc::Rc;
use std::time::Duration;

use crate::naming::{
    RunNamespace, ServiceLimits, WORLD_NODE_NAME, parse_agent_node_name, swap_limits,
};
use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlMsg, ControlRequest, HelloMsg, LobbyChannel, RobotChannel, ScanMsg,
    StatusMsg, SwapChannel, SwapReply, SwapReplyMsg, SwapRequest, SwapRequestMsg, Welcome,
    WelcomeMsg, lobby_service_name, robot_service_name, swap_service_name,
};
use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;

use super::services::{
    self, Access, EventService, PubSubService, ServiceError, drain_decoded, run_node, subscriber,
};
use super::watch_termination_signals;
use crate::error::{iox, iox_lazy};
use crate::signals;
use crate::wakes::{AttachedListeners, Fired, wait_collecting};
use formation_runtime::link::{
    Hello, Incarnations, WorldLink, WorldLinkError, WorldResult, check_robot_index,
};

/// One robot's ports on the world side.
struct RobotPorts {
    scan: Publisher<ipc::Service, ScanMsg, ()>,
    scan_wake: Notifier<ipc::Service>,
    control: Publisher<ipc::Service, ControlMsg, ()>,
    control_wake: Notifier<ipc::Service>,
    cmd: Subscriber<ipc::Service, CmdMsg, ()>,
    status: Subscriber<ipc::Service, StatusMsg, ()>,
    /// The command and status listeners, attached to the world's wait set while the
    /// incarnation lives.
    wakes: AttachedListeners,
}

/// One robot's lobby on the world side.
struct LobbyPorts {
    hellos: Subscriber<ipc::Service, HelloMsg, ()>,
    welcome: Publisher<ipc::Service, WelcomeMsg, ()>,
}

/// The world's ends of the run's swap channel.
struct SwapPorts {
    requests: Subscriber<ipc::Service, SwapRequestMsg, ()>,
    replies: Publisher<ipc::Service, SwapReplyMsg, ()>,
    reply_wake: Notifier<ipc::Service>,
}

/// The world's iceoryx2 ports: it creates every service of the run and holds the world's ends.
pub struct IceoryxWorldLink {
    node: Node<ipc::Service>,
    namespace: RunNamespace,
    lobbies: Vec<LobbyPorts>,
    /// Per robot: its current incarnation's ports, if an agent was accepted and is not gone.
    robots: Incarnations<RobotPorts>,
    swap: SwapPorts,
    waitset: Rc<WaitSet<ipc::Service>>,
    /// The swap channel's request listener and every lobby's hello listener.
    run_wakes: AttachedListeners,
    /// The attachments the last wait woke on (kept to reuse its allocation).
    fired: Fired,
}

impl IceoryxWorldLink {
    /// Creates the world's node, every robot's lobby and the swap channel in `namespace`, and
    /// makes the run's files private to this user.
    pub fn create(namespace: &RunNamespace, n_robots: usize) -> WorldResult<Self> {
        watch_termination_signals();
        namespace.prepare()?;
        let config = namespace.iceoryx_config()?;
        let node = run_node(&config, WORLD_NODE_NAME)?;
        // iceoryx2 makes its node-management segment world-writable: close it at once.
        namespace.restrict_permissions()?;
        let (lobbies, hello_wakes): (Vec<_>, Vec<_>) = (0..n_robots)
            .map(|robot| create_lobby_ports(&node, namespace, robot))
            .collect::<Result<Vec<_>, _>>()?
            .into_iter()
            .unzip();
        let (swap, request_wake) = create_swap_ports(&node, namespace)?;
        let waitset = Rc::new(
            WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
                .create::<ipc::Service>()
                .map_err(iox("create the world's wait set"))?,
        );
        let run_wakes = AttachedListeners::attach(
            &waitset,
            std::iter::once(request_wake).chain(hello_wakes).collect(),
        )?;
        Ok(IceoryxWorldLink {
            node,
            namespace: namespace.clone(),
            lobbies,
            robots: Incarnations::new(n_robots),
            swap,
            waitset,
            run_wakes,
            fired: Fired::new(),
        })
    }

    fn check_robot(&self, robot: usize) -> WorldResult {
        check_robot_index(robot, self.lobbies.len())
    }
}

/// The world creates every service of the run ([`Access::Create`]).
fn pubsub_service<T: std::fmt::Debug + ZeroCopySend + IceoryxSend>(
    node: &Node<ipc::Service>,
    name: &str,
    limits: ServiceLimits,
) -> Result<PubSubService<T>, WorldLinkError> {
    services::pubsub_service(node, name, limits, Access::Create).map_err(create_failed)
}

/// The event service paired with the publish-subscribe service `name` of `limits`, created.
fn event_service(
    node: &Node<ipc::Service>,
    name: &str,
    limits: ServiceLimits,
) -> WorldResult<EventService> {
    services::event_service(node, name, limits, Access::Create).map_err(create_failed)
}

fn create_failed(e: ServiceError) -> WorldLinkError {
    e.create_failed().into()
}

/// Robot `robot`'s lobby ports and its hello listener.
fn create_lobby_ports(
    node: &Node<ipc::Service>,
    namespace: &RunNamespace,
    robot: usize,
) -> Result<(LobbyPorts, Listener<ipc::Service>), WorldLinkError> {
    let hello_name = lobby_service_name(namespace.run(), robot, LobbyChannel::Hello);
    let welcome_name = lobby_service_name(namespace.run(), robot, LobbyChannel::Welcome);
    let what = |port: &str| format!("create the world's {port} port of robot {robot}");
    let hello_limits = ServiceLimits::HELLO;
    let ports = LobbyPorts {
        hellos: subscriber(
            &pubsub_service::<HelloMsg>(node, &hello_name, hello_limits)?,
            hello_limits,
        )
        .map_err(iox(what("hello")))?,
        welcome: pubsub_service::<WelcomeMsg>(node, &welcome_name, ServiceLimits::WELCOME)?
            .publisher_builder()
            .create()
            .map_err(iox(what("welcome")))?,
    };
    let hello_wake = event_service(node, &hello_name, hello_limits)?
        .listener_builder()
        .create()
        .map_err(iox(what("hello event")))?;
    Ok((ports, hello_wake))
}

fn create_robot_ports(
    node: &Node<ipc::Service>,
    waitset: &Rc<WaitSet<ipc::Service>>,
    namespace: &RunNamespace,
    robot: usize,
    incarnation: u64,
) -> WorldResult<RobotPorts> {
    let limits = ServiceLimits::ROBOT;
    let name = |channel| robot_service_name(namespace.run(), robot, incarnation, channel);
    let event = |channel| event_service(node, &name(channel), limits);
    macro_rules! pubsub_service {
        ($payload:ty, $channel:expr) => {
            pubsub_service::<$payload>(node, &name($channel), limits)?
        };
    }
    let scan = pubsub_service!(ScanMsg, RobotChannel::Scan);
    let cmd = pubsub_service!(CmdMsg, RobotChannel::Cmd);
    let control = pubsub_service!(ControlMsg, RobotChannel::Control);
    let status = pubsub_service!(StatusMsg, RobotChannel::Status);
    let what = |port: &str| format!("create the world's {port} port of robot {robot}");
    let notifier = |channel, port| -> WorldResult<Notifier<ipc::Service>> {
        Ok(event(channel)?
            .notifier_builder()
            .create()
            .map_err(iox(what(port)))?)
    };
    let listener = |channel, port| -> WorldResult<Listener<ipc::Service>> {
        Ok(event(channel)?
            .listener_builder()
            .create()
            .map_err(iox(what(port)))?)
    };
    Ok(RobotPorts {
        scan: scan
            .publisher_builder()
            .create()
            .map_err(iox(what("scan")))?,
        scan_wake: notifier(RobotChannel::Scan, "scan event")?,
        control: control
            .publisher_builder()
            .create()
            .map_err(iox(what("control")))?,
        control_wake: notifier(RobotChannel::Control, "control event")?,
        cmd: subscriber(&cmd, limits).map_err(iox(what("cmd")))?,
        status: subscriber(&status, limits).map_err(iox(what("status")))?,
        wakes: AttachedListeners::attach(
            waitset,
            vec![
                listener(RobotChannel::Cmd, "cmd event")?,
                listener(RobotChannel::Status, "status event")?,
            ],
        )?,
    })
}

/// The world's swap ports and the swap requests' listener.
fn create_swap_ports(
    node: &Node<ipc::Service>,
    namespace: &RunNamespace,
) -> Result<(SwapPorts, Listener<ipc::Service>), WorldLinkError> {
    let name = |channel| swap_service_name(namespace.run(), channel);
    let event = |channel: SwapChannel| event_service(node, &name(channel), swap_limits(channel));
    macro_rules! pubsub_service {
        ($payload:ty, $channel:expr) => {
            pubsub_service::<$payload>(node, &name($channel), swap_limits($channel))?
        };
    }
    let requests = pubsub_service!(SwapRequestMsg, SwapChannel::Request);
    let replies = pubsub_service!(SwapReplyMsg, SwapChannel::Reply);
    let what = |port: &str| format!("create the world's swap {port} port");
    let request_wake = event(SwapChannel::Request)?
        .listener_builder()
        .create()
        .map_err(iox(what("request event")))?;
    let ports = SwapPorts {
        requests: subscriber(&requests, swap_limits(SwapChannel::Request))
            .map_err(iox(what("request")))?,
        replies: replies
            .publisher_builder()
            .create()
            .map_err(iox(what("reply")))?,
        reply_wake: event(SwapChannel::Reply)?
            .notifier_builder()
            .create()
            .map_err(iox(what("reply event")))?,
    };
    Ok((ports, request_wake))
}

impl WorldLink for IceoryxWorldLink {
    fn n_robots(&self) -> usize {
        self.lobbies.len()
    }

    fn drain_hellos(&mut self, robot: usize, sink: &mut dyn FnMut(Hello)) -> WorldResult {
        self.check_robot(robot)?;
        while let Some(sample) = self.lobbies[robot]
            .hellos
            .receive()
            .map_err(iox_lazy(|| format!("receive a hello for robot {robot}")))?
        {
            let msg = sample.payload();
            sink(Hello {
                pid: msg.pid,
                nonce: msg.nonce,
                proof: msg.proof,
            });
        }
        Ok(())
    }

    fn answer_hello(&mut self, robot: usize, nonce: u64, welcome: &Welcome) -> WorldResult {
        self.check_robot(robot)?;
        self.lobbies[robot]
            .welcome
            .send_copy(WelcomeMsg::encode(nonce, welcome))
            .map_err(iox(format!("answer a hello for robot {robot}")))?;
        Ok(())
    }

    fn open_incarnation(&mut self, robot: usize, incarnation: u64) -> WorldResult {
        let (node, waitset, namespace) = (&self.node, &self.waitset, &self.namespace);
        self.robots.open(robot, || {
            create_robot_ports(node, waitset, namespace, robot, incarnation)
        })
    }

    fn close_incarnation(&mut self, robot: usize) {
        self.robots.close(robot);
    }

    fn publish_scan(&mut self, robot: usize, msg: &ScanMsg) -> WorldResult {
        let Some(ports) = self.robots.get(robot)? else {
            return Ok(());
        };
        ports
            .scan
            .send_copy(*msg)
            .map_err(iox_lazy(|| format!("send robot {robot}'s scan")))?;
        // A wake-up nobody listens to (agent restarting) is not an error.
        let _ = ports.scan_wake.notify();
        Ok(())
    }

    fn send_control(&mut self, robot: usize, request: &ControlRequest) -> WorldResult {
        let msg = ControlMsg::encode(request)?;
        let Some(ports) = self.robots.get(robot)? else {
            return Ok(());
        };
        ports
            .control
            .send_copy(msg)
            .map_err(iox(format!("send robot {robot}'s control request")))?;
        let _ = ports.control_wake.notify();
        Ok(())
    }

    fn wait(&mut self, timeout: Duration) -> WorldResult {
        // Every listener is already attached: the lobbies' and the swap channel's since the run
        // began, each incarnation's since it opened.
        let result = wait_collecting(&self.waitset, timeout, &mut self.fired)
            .map_err(iox("wait for the agents"))?;
        self.run_wakes.consume(&self.fired);
        for ports in self.robots.open_ones() {
            ports.wakes.consume(&self.fired);
        }
        if let Some(signal) = signals::received() {
            return Err(WorldLinkError::Terminated(signal));
        }
        match result {
            WaitSetRunResult::TerminationRequest => {
                Err(WorldLinkError::Terminated(signals::termination_requested()))
            }
            // An interrupted wait (EINTR: SIGCONT after a stop, SIGUSR1, SIGURG, ...) is not a
            // termination; the caller simply looks again.
            _ => Ok(()),
        }
    }

    fn drain_commands(&mut self, robot: usize, sink: &mut dyn FnMut(CmdMsg)) -> WorldResult {
        let Some(ports) = self.robots.get(robot)? else {
            return Ok(());
        };
        while let Some(sample) = ports
            .cmd
            .receive()
            .map_err(iox_lazy(|| format!("receive robot {robot}'s command")))?
        {
            sink(*sample.payload());
        }
        Ok(())
    }

    fn drain_statuses(&mut self, robot: usize, sink: &mut dyn FnMut(AgentStatus)) -> WorldResult {
        let Some(ports) = self.robots.get(robot)? else {
            return Ok(());
        };
        Ok(drain_decoded(
            &ports.status,
            &format_args!("status of robot {robot}"),
            StatusMsg::decode,
            sink,
        )?)
    }

    fn agent_alive(&mut self, robot: usize, pid: u32) -> WorldResult<bool> {
        let wanted = crate::naming::agent_node_name(robot, pid);
        Ok(crate::services::alive_node(&self.node, &wanted)?.is_some())
    }

    fn dead_agents(&mut self) -> Result<Vec<(usize, u32)>, WorldLinkError> {
        let n_robots = self.lobbies.len();
        let mut dead = Vec::new();
        Node::<ipc::Service>::list(self.node.config(), |state| {
            if let NodeState::Dead(view) = &state
                && let Some(details) = view.details()
                && let Some((robot, pid)) = parse_agent_node_name(details.name().as_str())
                && robot < n_robots
            {
                dead.push((robot, pid));
            }
            CallbackProgression::Continue
        })
        .map_err(iox("list the run's nodes"))?;
        if !dead.is_empty() {
            let cleaned = self.node.try_cleanup_dead_nodes();
            tracing::info!(
                "agents of robots {dead:?} died; cleaned up {} dead node(s)",
                cleaned.cleanups
            );
            for ports in self.robots.open_ones() {
                let _ = ports.scan.update_connections();
                let _ = ports.control.update_connections();
                let _ = ports.cmd.update_connections();
                let _ = ports.status.update_connections();
            }
        }
        dead.sort_unstable();
        dead.dedup();
        Ok(dead)
    }

    fn drain_swap_requests(&mut self, sink: &mut dyn FnMut(SwapRequest)) -> WorldResult {
        let decode = SwapRequestMsg::decode;
        Ok(drain_decoded(
            &self.swap.requests,
            &"swap request",
            decode,
            sink,
        )?)
    }

    fn publish_swap_reply(&mut self, reply: &SwapReply) -> WorldResult {
        let msg = SwapReplyMsg::encode(reply)?;
        self.swap
            .replies
            .send_copy(msg)
            .map_err(iox("send a swap reply"))?;
        let _ = self.swap.reply_wake.notify();
        Ok(())
    }
}
