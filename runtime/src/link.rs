//! The transport seams: what the world needs from a message bus ([`WorldLink`]) and what an agent
//! needs ([`AgentLink`]), with their errors.
//!
//! The exchange ([`crate::exchange`]) and the agent loop ([`crate::agent`]) talk only to these
//! traits, so a transport is one implementation among others, each in a crate of its own:
//! iceoryx2 shared memory (`formation-transport-iceoryx2`) for the processes of one host, Zenoh
//! (`formation-transport-zenoh`) for agents on other hosts, ROS 2 over rmw_zenoh
//! (`formation-transport-ros2`), and channels in one process ([`crate::memory`]) for tests. A
//! transport's own failures are its crate's typed error (a [`TransportCrateError`]), carried as
//! the source of [`WorldLinkError::Transport`] and [`AgentLinkError::Transport`]. The world watches command ages itself, so its
//! watchdog does not depend on the transport's own liveness reports; those
//! ([`WorldLink::dead_agents`]) only speed up noticing a crashed agent and clean up after it.
//!
//! Per robot the world holds a lobby (hellos in, welcomes out) from the start, and the channels of
//! the robot's current *incarnation* only once the exchange has accepted an agent's proof of the
//! launch secret ([`WorldLink::open_incarnation`]). Until then, and after the agent is gone
//! ([`WorldLink::close_incarnation`]), publishing to the robot is a no-op and nothing arrives
//! from it.

use std::path::PathBuf;
use std::time::Duration;

use crate::auth::SecretError;
use formation_proto::exit::TerminationSignal;
use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlRequest, ScanMsg, SwapReply, SwapRequest, Welcome, WireError,
};

/// A transport's own failure: the typed error of the transport's crate, kept as the source (a
/// caller that needs its details downcasts it).
pub type TransportFailure = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A transport crate's own typed error. `?` carries it into [`WorldLinkError::Transport`] and
/// [`AgentLinkError::Transport`] (boxed as their source), so a transport only declares
/// `impl TransportCrateError for ItsError {}`.
pub trait TransportCrateError: std::error::Error + Send + Sync + 'static {}

impl<E: TransportCrateError> From<E> for WorldLinkError {
    fn from(e: E) -> Self {
        WorldLinkError::Transport(Box::new(e))
    }
}

impl<E: TransportCrateError> From<E> for AgentLinkError {
    fn from(e: E) -> Self {
        AgentLinkError::Transport(Box::new(e))
    }
}

/// A transport's file-system or socket operation that failed: what was being done, on which
/// path, and the operating system's error (`creating /run/user/1000/formation-x: Permission
/// denied`); the `Io` variant of each transport's error.
#[derive(Debug, thiserror::Error)]
#[error("{action} {}: {source}", path.display())]
pub struct PathIoError {
    /// What was being done (`creating`, `sending to`).
    pub action: &'static str,
    /// On what.
    pub path: PathBuf,
    /// The operating system's error.
    #[source]
    pub source: std::io::Error,
}

impl PathIoError {
    /// An `Err` mapper: the failure of `action` on `path` with the error it is given.
    pub fn of(
        action: &'static str,
        path: impl Into<PathBuf>,
    ) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| PathIoError {
            action,
            path,
            source,
        }
    }
}

/// A failure of the world's transport, or a request to stop.
#[derive(Debug, thiserror::Error)]
pub enum WorldLinkError {
    /// The transport failed (its crate's own error).
    #[error(transparent)]
    Transport(TransportFailure),
    /// A message could not be encoded or decoded.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// SIGINT or SIGTERM arrived.
    #[error("stopped by a termination signal ({0})")]
    Terminated(TerminationSignal),
    /// A robot index past the end of the team.
    #[error("there is no robot {robot}: the run has {robots} robots (0 to {last})", last = robots.saturating_sub(1))]
    NoSuchRobot {
        /// The index asked for.
        robot: usize,
        /// How many robots the run has.
        robots: usize,
    },
}

/// What a world link's operations return.
pub type WorldResult<T = ()> = Result<T, WorldLinkError>;

/// `Ok` if `robot` indexes one of a team of `robots`; the one bounds check every link uses.
pub fn check_robot_index(robot: usize, robots: usize) -> WorldResult {
    if robot < robots {
        Ok(())
    } else {
        Err(WorldLinkError::NoSuchRobot { robot, robots })
    }
}

/// Per robot, the world's ends of its current incarnation's channels (`P`), if an agent was
/// admitted and is not gone: what every transport's world link keeps, with the robot index
/// checked once ([`check_robot_index`]).
#[derive(Debug)]
pub struct Incarnations<P> {
    slots: Vec<Option<P>>,
}

impl<P> Incarnations<P> {
    /// None open, for a team of `robots`.
    pub fn new(robots: usize) -> Self {
        Incarnations {
            slots: (0..robots).map(|_| None).collect(),
        }
    }

    /// Robot `robot`'s current incarnation, if one is open.
    pub fn get(&self, robot: usize) -> Result<Option<&P>, WorldLinkError> {
        check_robot_index(robot, self.slots.len())?;
        Ok(self.slots[robot].as_ref())
    }

    /// Robot `robot`'s current incarnation, if one is open, to change.
    pub fn get_mut(&mut self, robot: usize) -> Result<Option<&mut P>, WorldLinkError> {
        check_robot_index(robot, self.slots.len())?;
        Ok(self.slots[robot].as_mut())
    }

    /// Opens robot `robot`'s incarnation with the ends `open` makes, after dropping those of
    /// the previous one (so a new incarnation never meets its predecessor's ports).
    pub fn open(&mut self, robot: usize, open: impl FnOnce() -> WorldResult<P>) -> WorldResult {
        check_robot_index(robot, self.slots.len())?;
        self.slots[robot] = None;
        self.slots[robot] = Some(open()?);
        Ok(())
    }

    /// Drops robot `robot`'s current incarnation's ends, if any.
    pub fn close(&mut self, robot: usize) {
        if let Some(slot) = self.slots.get_mut(robot) {
            *slot = None;
        }
    }

    /// Every open incarnation's ends.
    pub fn open_ones(&self) -> impl Iterator<Item = &P> {
        self.slots.iter().flatten()
    }
}

/// An agent's request to drive a robot, as it arrived in the robot's lobby.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hello {
    /// The pid the candidate gave.
    pub pid: u32,
    /// Its nonce: names the incarnation if accepted.
    pub nonce: u64,
    /// Its proof of the launch secret.
    pub proof: [u8; crate::auth::PROOF_LEN],
}

/// Where a world hands remote recorders what its own recorder gets (`formation record
/// --connect`): the bytes of each live-recording message (`formation_record::live`), in order.
/// A transport without remote recorders has none.
pub trait RecordFeed {
    /// Whether a recorder is listening now: the world encodes nothing otherwise, so a team
    /// nobody records pays nothing.
    fn wanted(&self) -> bool;
    /// A run begins: `setup` is its setup message, sent now (when wanted) and kept for a
    /// recorder that joins while the run plays.
    fn begin_run(&mut self, setup: Vec<u8>) -> WorldResult;
    /// Sends one message (a tick, the run's end) to the recorders, reliably and in order.
    fn publish(&mut self, message: Vec<u8>) -> WorldResult;
}

/// What the world needs from a transport: per-robot channels to and from the agents.
pub trait WorldLink {
    /// Number of robots the link serves.
    fn n_robots(&self) -> usize;
    /// Hands every hello that candidates for robot `robot` sent since the last call to `sink`.
    fn drain_hellos(&mut self, robot: usize, sink: &mut dyn FnMut(Hello)) -> WorldResult;
    /// Answers the hello with `nonce` in robot `robot`'s lobby.
    fn answer_hello(&mut self, robot: usize, nonce: u64, welcome: &Welcome) -> WorldResult;
    /// Creates the channels of robot `robot`'s new incarnation and takes the world's ends,
    /// dropping those of the previous incarnation.
    fn open_incarnation(&mut self, robot: usize, incarnation: u64) -> WorldResult;
    /// Drops the world's ends of robot `robot`'s current incarnation (its agent is gone).
    fn close_incarnation(&mut self, robot: usize);
    /// The link's odometry, if it publishes each robot's like a real robot's driver (the ROS 2
    /// team); agents of the other links see only their scan and heading, so by default none.
    fn odometry(&mut self) -> Option<&mut dyn PublishesOdometry> {
        None
    }
    /// Publishes robot `robot`'s scan and wakes its agent.
    fn publish_scan(&mut self, robot: usize, msg: &ScanMsg) -> WorldResult;
    /// Sends a control request to robot `robot`'s agent and wakes it.
    fn send_control(&mut self, robot: usize, request: &ControlRequest) -> WorldResult;
    /// Blocks until an agent may have sent something, or `timeout` passes. An interrupted wait
    /// (EINTR) returns `Ok`; SIGINT/SIGTERM is [`WorldLinkError::Terminated`].
    fn wait(&mut self, timeout: Duration) -> WorldResult;
    /// Hands every command robot `robot`'s agent sent since the last call to `sink`, oldest
    /// first, at once as it takes each (the exchange stamps its arrival time in `sink`).
    fn drain_commands(&mut self, robot: usize, sink: &mut dyn FnMut(CmdMsg)) -> WorldResult;
    /// Hands every status robot `robot`'s agent sent since the last call to `sink`, oldest first.
    fn drain_statuses(&mut self, robot: usize, sink: &mut dyn FnMut(AgentStatus)) -> WorldResult;
    /// Whether agent process `pid` of robot `robot` is still alive, as far as the transport can
    /// tell (a stopped process is alive).
    fn agent_alive(&mut self, robot: usize, pid: u32) -> WorldResult<bool>;
    /// Whether agent process `pid` of robot `robot` is unreachable now but may come back on its
    /// own: its session dropped and the transport waits for it to reconnect (Zenoh,
    /// `RECONNECT_GRACE`), after which it is either back or among the [`WorldLink::dead_agents`].
    /// Lockstep holds the tick for such an agent. By default never.
    fn agent_reconnecting(&mut self, _robot: usize, _pid: u32) -> WorldResult<bool> {
        Ok(false)
    }
    /// `(robot, pid)` of agent processes the transport knows to be dead; cleans up after them so
    /// a restarted agent can take their place.
    fn dead_agents(&mut self) -> Result<Vec<(usize, u32)>, WorldLinkError>;
    /// Hands every swap request that users sent since the last call to `sink`, oldest first.
    fn drain_swap_requests(&mut self, sink: &mut dyn FnMut(SwapRequest)) -> WorldResult;
    /// Answers a swap request.
    fn publish_swap_reply(&mut self, reply: &SwapReply) -> WorldResult;
    /// The link's forwarded swap models, if a swap request may bring the model's bytes from
    /// another host (Zenoh); by default none: the agent opens the request's path itself.
    fn forwarded_swaps(&mut self) -> Option<&mut dyn ForwardsSwapModels> {
        None
    }
}

/// A capability of a link that publishes odometry like a real robot's driver (the ROS 2 team).
pub trait PublishesOdometry {
    /// Hands the link robot `robot`'s true pose of the tick whose scan comes next and the wheel
    /// speeds it ran over the last step, published with that scan.
    fn publish_odometry(
        &mut self,
        robot: usize,
        pose: &formation_proto::Pose,
        wheels: formation_proto::WheelCmd,
    ) -> WorldResult;
}

/// A capability of a link whose swap requests may bring the model's bytes from another host
/// (Zenoh: the request's path is on the requester's host).
pub trait ForwardsSwapModels {
    /// The model bytes that came with swap request `request_id` and that the last
    /// [`WorldLink::send_control`] forwarded to its agent, for the recording.
    fn take_forwarded_swap_model(&mut self, request_id: u64) -> Option<Vec<u8>>;
}

/// A failure of an agent's transport.
#[derive(Debug, thiserror::Error)]
pub enum AgentLinkError {
    /// The transport failed (its crate's own error: the world not found, a port taken, the
    /// endpoint unreachable, a certificate refused, ...).
    #[error(transparent)]
    Transport(TransportFailure),
    /// SIGINT or SIGTERM arrived while the agent was connecting.
    #[error("stopped by a termination signal ({0}) while connecting to the world")]
    Terminated(TerminationSignal),
    /// The world refused this agent.
    #[error("the world refused to let this agent drive robot {robot}: {reason}")]
    Refused {
        /// The robot.
        robot: usize,
        /// The world's reason.
        reason: String,
    },
    /// The world did not answer the greeting.
    #[error(
        "the world of run {run} did not answer robot {robot}'s greeting within {waited_s:.1} s; \
         is it running (and not stopped)?"
    )]
    NoWelcome {
        /// The robot.
        robot: usize,
        /// The run id.
        run: String,
        /// How long the agent waited.
        waited_s: f64,
    },
    /// A message could not be encoded or decoded.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// No nonce could be drawn.
    #[error(transparent)]
    Secret(#[from] SecretError),
}

/// Why an agent's wait ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// Something may have arrived (or a signal interrupted the wait: look again).
    Activity,
    /// The timeout passed with nothing arriving.
    Idle,
    /// SIGINT or SIGTERM arrived.
    Terminated(TerminationSignal),
}

/// What an agent needs from a transport: its own robot's four channels.
pub trait AgentLink {
    /// Blocks until the world may have sent something, `timeout` passes, or a signal arrives.
    fn wait(&mut self, timeout: Duration) -> Result<Wake, AgentLinkError>;
    /// Every control request since the last call, oldest first.
    fn drain_control(&mut self, sink: &mut dyn FnMut(ControlRequest))
    -> Result<(), AgentLinkError>;
    /// The newest scan since the last call (older ones are dropped: only the newest matters).
    fn newest_scan(&mut self) -> Result<Option<ScanMsg>, AgentLinkError>;
    /// Publishes a command and wakes the world.
    fn publish_command(&mut self, msg: &CmdMsg) -> Result<(), AgentLinkError>;
    /// Publishes a status and wakes the world.
    fn publish_status(&mut self, status: &AgentStatus) -> Result<(), AgentLinkError>;
    /// False once the world process is gone (exited or died).
    fn world_alive(&mut self) -> Result<bool, AgentLinkError>;
    /// Told when the pilot could not decide on the scan of tick `tick` (`why`: the error's whole
    /// chain), just before the loop publishes a brake for it ([`CmdStatus::DECISION_FAILED`]).
    /// By default a warning in the log, since the world's watchdog tells the rest; a link whose
    /// robot has a user of its own to tell (ROS 2's) keeps `why` for the brake it sends.
    ///
    /// [`CmdStatus::DECISION_FAILED`]: formation_proto::wire::CmdStatus::DECISION_FAILED
    fn decision_failed(&mut self, tick: u64, why: &str) {
        tracing::warn!("tick {tick}: cannot decide ({why}); asking for a brake");
    }
}

#[cfg(test)]
mod index_tests {
    use super::*;

    #[test]
    fn a_robot_past_the_team_is_refused_with_the_team_size() {
        assert!(check_robot_index(2, 3).is_ok());
        let err = check_robot_index(3, 3).unwrap_err();
        assert!(matches!(
            err,
            WorldLinkError::NoSuchRobot {
                robot: 3,
                robots: 3
            }
        ));
        assert_eq!(
            err.to_string(),
            "there is no robot 3: the run has 3 robots (0 to 2)"
        );
    }
}
