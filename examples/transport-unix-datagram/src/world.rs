//! The world's link ([`DatagramWorldLink`]): it creates the run's folder and binds the world's
//! socket there, where every agent and swap client sends; it answers a hello at the candidate's
//! own socket, and once the exchange admits an agent it keeps a socket connected to that
//! incarnation's for its scans and control requests. An agent is gone when it says goodbye or
//! nobody listens on its socket any more (its process died); the world removes what a dead
//! agent left, and the whole folder when it goes.

use std::collections::{HashMap, VecDeque};
use std::os::unix::net::UnixDatagram;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlMsg, ControlRequest, HelloMsg, ScanMsg, StatusMsg, SwapReply,
    SwapReplyMsg, SwapRequest, SwapRequestMsg, Welcome, WelcomeMsg, WireError,
};
use formation_runtime::link::{
    Hello, Incarnations, WorldLink, WorldLinkError, WorldResult, check_robot_index,
};
use formation_runtime::plugin::WorldSite;

use crate::error::DatagramError;
use crate::folder::RunFolder;
use crate::frame::{Frame, Kind};
use crate::signals;
use crate::socket::{self, BoundSocket, Inbox, Pump};

/// How long a wait blocks before it looks for a termination signal again.
pub(crate) const SIGNAL_CHECK: Duration = Duration::from_millis(100);
/// How long a control request waits for room in a busy agent's queue before it is dropped.
const CONTROL_PATIENCE: Duration = Duration::from_millis(500);

/// The world's end of one admitted agent (an incarnation).
struct Peer {
    nonce: u64,
    pid: u32,
    path: PathBuf,
    /// Connected to the agent's socket; sends never block.
    outbox: UnixDatagram,
    cmds: VecDeque<CmdMsg>,
    statuses: VecDeque<AgentStatus>,
    /// Whether its death was reported already.
    reported: bool,
}

/// The world's side of a run over Unix datagram sockets.
pub struct DatagramWorldLink {
    folder: RunFolder,
    inbox: Inbox,
    robots: usize,
    hellos: Vec<VecDeque<Hello>>,
    /// Candidates that greeted and were not answered yet: pid by (robot, nonce).
    candidates: HashMap<(usize, u64), u32>,
    incarnations: Incarnations<Peer>,
    swaps: VecDeque<SwapRequest>,
    /// The nonce of each swap request's client, by request id.
    swap_clients: HashMap<u64, u64>,
    /// Agents that said goodbye, not reported yet.
    goodbyes: Vec<(usize, u32)>,
}

impl DatagramWorldLink {
    /// Creates the run's folder and binds the world's socket in it.
    pub fn create(site: &WorldSite<'_>) -> Result<DatagramWorldLink, DatagramError> {
        signals::watch()?;
        let folder = RunFolder::locate(&site.run)?;
        folder.create()?;
        let inbox = match BoundSocket::bind(folder.world_socket()) {
            Ok(inbox) => inbox,
            Err(e) => {
                let _ = folder.remove();
                return Err(e);
            }
        };
        Ok(DatagramWorldLink {
            folder,
            inbox: Inbox::new(inbox),
            robots: site.robots,
            hellos: (0..site.robots).map(|_| VecDeque::new()).collect(),
            candidates: HashMap::new(),
            incarnations: Incarnations::new(site.robots),
            swaps: VecDeque::new(),
            swap_clients: HashMap::new(),
            goodbyes: Vec::new(),
        })
    }

    /// The run's folder.
    pub fn folder(&self) -> &RunFolder {
        &self.folder
    }

    /// Hands `sink` what robot `robot`'s current incarnation has queued in `queue`, after taking
    /// every datagram waiting.
    fn drain_peer<T>(
        &mut self,
        robot: usize,
        queue: impl FnOnce(&mut Peer) -> &mut VecDeque<T>,
        sink: &mut dyn FnMut(T),
    ) -> WorldResult {
        check_robot_index(robot, self.robots)?;
        self.pump(None)?;
        if let Some(peer) = self.incarnations.get_mut(robot)? {
            queue(peer).drain(..).for_each(sink);
        }
        Ok(())
    }

    /// The open incarnation a datagram from an agent belongs to, if it is still the robot's.
    fn peer_of(&mut self, frame: &Frame<'_>) -> Option<&mut Peer> {
        self.incarnations
            .get_mut(frame.robot)
            .ok()
            .flatten()
            .filter(|peer| peer.nonce == frame.incarnation)
    }

    /// Whether the exchange has something to drain.
    fn has_mail(&self) -> bool {
        self.hellos.iter().any(|h| !h.is_empty())
            || !self.swaps.is_empty()
            || self
                .incarnations
                .open_ones()
                .any(|p| !p.cmds.is_empty() || !p.statuses.is_empty())
    }

    /// Sends `bytes` to robot `robot`'s open incarnation, if any; a full queue drops it unless
    /// `patience` lets it wait for room. An agent gone is no error: its death is found apart.
    fn send_to_agent(&mut self, robot: usize, bytes: &[u8], patience: Duration) -> WorldResult {
        let Some(peer) = self.incarnations.get(robot)? else {
            return Ok(());
        };
        let started = Instant::now();
        loop {
            match peer.outbox.send(bytes) {
                Ok(_) => return Ok(()),
                Err(e) if socket::peer_gone(&e) => return Ok(()),
                Err(e) if socket::receiver_full(&e) => {
                    if started.elapsed() >= patience {
                        tracing::debug!("robot {robot}'s agent is not reading: dropped a datagram");
                        return Ok(());
                    }
                    std::thread::sleep(Duration::from_millis(2));
                }
                Err(e) => return Err(DatagramError::io("sending to", &peer.path)(e).into()),
            }
        }
    }
}

impl Pump for DatagramWorldLink {
    fn inbox(&mut self) -> &mut Inbox {
        &mut self.inbox
    }

    fn who(&self) -> String {
        format!("run {}", self.folder.run())
    }

    /// Files one datagram where the exchange drains it.
    fn file(&mut self, frame: Frame<'_>) -> Result<(), WireError> {
        let robot = frame.robot;
        match frame.kind {
            Kind::Hello if robot < self.robots => {
                let hello: HelloMsg = frame.message("hello")?;
                if hello.nonce == frame.incarnation {
                    self.candidates.insert((robot, hello.nonce), hello.pid);
                    self.hellos[robot].push_back(Hello {
                        pid: hello.pid,
                        nonce: hello.nonce,
                        proof: hello.proof,
                    });
                }
            }
            Kind::Command => {
                let cmd: CmdMsg = frame.message("command")?;
                if let Some(peer) = self.peer_of(&frame) {
                    peer.cmds.push_back(cmd);
                }
            }
            Kind::Status => {
                let status = frame.message::<StatusMsg>("status")?.decode()?;
                if let Some(peer) = self.peer_of(&frame) {
                    peer.statuses.push_back(status);
                }
            }
            Kind::SwapRequest => {
                let request = frame.message::<SwapRequestMsg>("swap request")?.decode()?;
                self.swap_clients
                    .insert(request.request_id, frame.incarnation);
                self.swaps.push_back(request);
            }
            Kind::Goodbye => {
                if let Some(peer) = self.peer_of(&frame) {
                    let pid = peer.pid;
                    self.goodbyes.push((robot, pid));
                }
            }
            _ => {}
        }
        Ok(())
    }
}

impl WorldLink for DatagramWorldLink {
    fn n_robots(&self) -> usize {
        self.robots
    }

    fn drain_hellos(&mut self, robot: usize, sink: &mut dyn FnMut(Hello)) -> WorldResult {
        check_robot_index(robot, self.robots)?;
        self.pump(None)?;
        self.hellos[robot].drain(..).for_each(sink);
        Ok(())
    }

    fn answer_hello(&mut self, robot: usize, nonce: u64, welcome: &Welcome) -> WorldResult {
        check_robot_index(robot, self.robots)?;
        self.candidates.remove(&(robot, nonce));
        let bytes = Frame::encode(
            Kind::Welcome,
            robot,
            nonce,
            &WelcomeMsg::encode(nonce, welcome),
        );
        socket::send_once(&self.folder.agent_socket(robot, nonce), &bytes)?;
        Ok(())
    }

    fn open_incarnation(&mut self, robot: usize, incarnation: u64) -> WorldResult {
        let pid = self
            .candidates
            .get(&(robot, incarnation))
            .copied()
            .unwrap_or(0);
        let path = self.folder.agent_socket(robot, incarnation);
        self.incarnations.open(robot, || {
            let outbox =
                socket::connected(&path).map_err(DatagramError::io("connecting to", &path))?;
            Ok(Peer {
                nonce: incarnation,
                pid,
                path,
                outbox,
                cmds: VecDeque::new(),
                statuses: VecDeque::new(),
                reported: false,
            })
        })
    }

    fn close_incarnation(&mut self, robot: usize) {
        if let Ok(Some(peer)) = self.incarnations.get(robot)
            && !socket::listening(&peer.path)
        {
            // What a dead agent left.
            let _ = std::fs::remove_file(&peer.path);
        }
        self.incarnations.close(robot);
    }

    fn publish_scan(&mut self, robot: usize, msg: &ScanMsg) -> WorldResult {
        let Some(nonce) = self.incarnations.get(robot)?.map(|p| p.nonce) else {
            return Ok(());
        };
        let bytes = Frame::encode(Kind::Scan, robot, nonce, msg);
        self.send_to_agent(robot, &bytes, Duration::ZERO)
    }

    fn send_control(&mut self, robot: usize, request: &ControlRequest) -> WorldResult {
        let Some(nonce) = self.incarnations.get(robot)?.map(|p| p.nonce) else {
            return Ok(());
        };
        let bytes = Frame::encode(Kind::Control, robot, nonce, &ControlMsg::encode(request)?);
        self.send_to_agent(robot, &bytes, CONTROL_PATIENCE)
    }

    fn wait(&mut self, timeout: Duration) -> WorldResult {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(signal) = signals::received() {
                return Err(WorldLinkError::Terminated(signal));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            self.pump(None)?;
            if self.has_mail() || left.is_zero() {
                return Ok(());
            }
            if self.pump(Some(left.min(SIGNAL_CHECK)))? {
                return Ok(());
            }
        }
    }

    fn drain_commands(&mut self, robot: usize, sink: &mut dyn FnMut(CmdMsg)) -> WorldResult {
        self.drain_peer(robot, |peer| &mut peer.cmds, sink)
    }

    fn drain_statuses(&mut self, robot: usize, sink: &mut dyn FnMut(AgentStatus)) -> WorldResult {
        self.drain_peer(robot, |peer| &mut peer.statuses, sink)
    }

    fn agent_alive(&mut self, robot: usize, pid: u32) -> WorldResult<bool> {
        check_robot_index(robot, self.robots)?;
        self.pump(None)?;
        if self.goodbyes.contains(&(robot, pid)) {
            return Ok(false);
        }
        let path = match self.incarnations.get(robot)? {
            Some(peer) if peer.pid == pid => peer.path.clone(),
            _ => match self
                .candidates
                .iter()
                .find(|&(&(r, _), &p)| r == robot && p == pid)
            {
                Some((&(_, nonce), _)) => self.folder.agent_socket(robot, nonce),
                // Not an agent this link knows: nothing says it died.
                None => return Ok(true),
            },
        };
        Ok(socket::listening(&path))
    }

    fn dead_agents(&mut self) -> Result<Vec<(usize, u32)>, WorldLinkError> {
        self.pump(None)?;
        let mut dead = std::mem::take(&mut self.goodbyes);
        for robot in 0..self.robots {
            if let Some(peer) = self.incarnations.get_mut(robot)?
                && !peer.reported
                && !socket::listening(&peer.path)
            {
                peer.reported = true;
                dead.push((robot, peer.pid));
            }
        }
        dead.sort_unstable();
        dead.dedup();
        Ok(dead)
    }

    fn drain_swap_requests(&mut self, sink: &mut dyn FnMut(SwapRequest)) -> WorldResult {
        self.pump(None)?;
        self.swaps.drain(..).for_each(sink);
        Ok(())
    }

    fn publish_swap_reply(&mut self, reply: &SwapReply) -> WorldResult {
        let Some(nonce) = self.swap_clients.remove(&reply.request_id) else {
            return Ok(());
        };
        let bytes = Frame::encode(
            Kind::SwapReply,
            reply.robot,
            nonce,
            &SwapReplyMsg::encode(reply)?,
        );
        socket::send_once(&self.folder.swap_socket(nonce), &bytes)?;
        Ok(())
    }
}

impl Drop for DatagramWorldLink {
    fn drop(&mut self) {
        // Tell the agents at once, then take the run's folder with every socket in it.
        for peer in self.incarnations.open_ones() {
            let _ = peer
                .outbox
                .send(&Frame::encode_bare(Kind::Goodbye, 0, peer.nonce));
        }
        if let Err(e) = self.folder.remove() {
            tracing::warn!("{e}");
        }
    }
}
