//! An agent's link ([`DatagramAgentLink`]): it waits for the world's socket, binds a socket of
//! its own named by its robot and a fresh nonce, greets the world proving the launch secret,
//! and once welcomed receives its scans and control requests there and sends its commands and
//! statuses to the world's socket. Dropping it says goodbye and unlinks its socket.

use std::collections::VecDeque;
use std::os::unix::net::UnixDatagram;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlMsg, ControlRequest, HelloMsg, ScanMsg, StatusMsg, Welcome,
    WelcomeMsg, WireError,
};
use formation_runtime::auth::fresh_nonce;
use formation_runtime::link::{AgentLink, AgentLinkError, Wake};
use formation_runtime::plugin::AgentSite;

use crate::error::DatagramError;
use crate::folder::RunFolder;
use crate::frame::{Frame, Kind};
use crate::signals;
use crate::socket::{self, BoundSocket, Inbox, Pump};
use crate::world::SIGNAL_CHECK;

/// How long a send waits for room in the world's queue before the datagram is dropped.
const SEND_PATIENCE: Duration = Duration::from_millis(500);
/// How often a connecting agent looks for the world's socket.
const RETRY_PERIOD: Duration = Duration::from_millis(20);

/// One agent's end of its robot's incarnation.
pub struct DatagramAgentLink {
    inbox: Inbox,
    /// Connected to the world's socket.
    outbox: UnixDatagram,
    world: PathBuf,
    robot: usize,
    nonce: u64,
    scan: Option<ScanMsg>,
    control: VecDeque<ControlRequest>,
    welcome: Option<Welcome>,
    world_left: bool,
}

impl DatagramAgentLink {
    /// Waits for the world of `site`'s run, greets it as robot `site.robot`'s agent and returns
    /// the link once welcomed; a refusal is [`AgentLinkError::Refused`].
    pub fn connect(site: &AgentSite<'_>) -> Result<DatagramAgentLink, AgentLinkError> {
        signals::watch()?;
        let started = Instant::now();
        let deadline = started + site.connect_timeout;
        let folder = RunFolder::locate(&site.run)?;
        let world = folder.world_socket();
        while !socket::listening(&world) {
            if let Some(signal) = signals::received() {
                return Err(AgentLinkError::Terminated(signal));
            }
            if Instant::now() >= deadline {
                return Err(DatagramError::WorldNotFound {
                    run: folder.run().to_string(),
                    dir: folder.dir().to_path_buf(),
                    waited_s: started.elapsed().as_secs_f64(),
                }
                .into());
            }
            std::thread::sleep(RETRY_PERIOD);
        }
        let nonce = fresh_nonce()?;
        let inbox = BoundSocket::bind(folder.agent_socket(site.robot, nonce))?;
        let outbox = UnixDatagram::unbound()
            .and_then(|s| s.connect(&world).map(|()| s))
            .and_then(|s| s.set_write_timeout(Some(SEND_PATIENCE)).map(|()| s))
            .map_err(DatagramError::io("connecting to", &world))?;
        let mut link = DatagramAgentLink {
            inbox: Inbox::new(inbox),
            outbox,
            world,
            robot: site.robot,
            nonce,
            scan: None,
            control: VecDeque::new(),
            welcome: None,
            world_left: false,
        };
        let hello = HelloMsg {
            pid: site.pid,
            reserved: 0,
            nonce,
            proof: site.secret.prove(site.run.run, site.robot, site.pid, nonce),
        };
        link.send(&Frame::encode(Kind::Hello, site.robot, nonce, &hello))?;
        match link.await_welcome(deadline)? {
            Some(Welcome::Accepted) => Ok(link),
            Some(Welcome::Refused(reason)) => Err(AgentLinkError::Refused {
                robot: site.robot,
                reason,
            }),
            None => Err(AgentLinkError::NoWelcome {
                robot: site.robot,
                run: folder.run().to_string(),
                waited_s: started.elapsed().as_secs_f64(),
            }),
        }
    }

    /// The world's answer to our hello, waiting for it until `deadline`.
    fn await_welcome(&mut self, deadline: Instant) -> Result<Option<Welcome>, AgentLinkError> {
        loop {
            if let Some(welcome) = self.welcome.take() {
                return Ok(Some(welcome));
            }
            if let Some(signal) = signals::received() {
                return Err(AgentLinkError::Terminated(signal));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.pump(Some(left.min(SIGNAL_CHECK)))?;
        }
    }

    /// Sends one datagram to the world; one the world has no room for, or that finds it gone,
    /// is dropped (the world brakes the robot; the agent finds the world gone when it checks).
    fn send(&self, bytes: &[u8]) -> Result<(), DatagramError> {
        match self.outbox.send(bytes) {
            Ok(_) => Ok(()),
            Err(e) if socket::peer_gone(&e) || socket::receiver_full(&e) => {
                tracing::debug!("robot {}: a datagram to the world dropped: {e}", self.robot);
                Ok(())
            }
            Err(e) => Err(DatagramError::io("sending to", &self.world)(e)),
        }
    }

    fn has_mail(&self) -> bool {
        self.scan.is_some() || !self.control.is_empty()
    }
}

impl Pump for DatagramAgentLink {
    fn inbox(&mut self) -> &mut Inbox {
        &mut self.inbox
    }

    fn who(&self) -> String {
        format!("robot {}", self.robot)
    }

    fn file(&mut self, frame: Frame<'_>) -> Result<(), WireError> {
        if frame.incarnation != self.nonce {
            return Ok(());
        }
        match frame.kind {
            Kind::Welcome => self.welcome = Some(frame.message::<WelcomeMsg>("welcome")?.decode()?),
            Kind::Scan => self.scan = Some(frame.message("scan")?),
            Kind::Control => self
                .control
                .push_back(frame.message::<ControlMsg>("control request")?.decode()?),
            Kind::Goodbye => self.world_left = true,
            _ => {}
        }
        Ok(())
    }
}

impl AgentLink for DatagramAgentLink {
    fn wait(&mut self, timeout: Duration) -> Result<Wake, AgentLinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(signal) = signals::received() {
                return Ok(Wake::Terminated(signal));
            }
            self.pump(None)?;
            if self.has_mail() {
                return Ok(Wake::Activity);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(Wake::Idle);
            }
            if self.pump(Some(left.min(SIGNAL_CHECK)))? {
                return Ok(Wake::Activity);
            }
        }
    }

    fn drain_control(
        &mut self,
        sink: &mut dyn FnMut(ControlRequest),
    ) -> Result<(), AgentLinkError> {
        self.pump(None)?;
        self.control.drain(..).for_each(sink);
        Ok(())
    }

    fn newest_scan(&mut self) -> Result<Option<ScanMsg>, AgentLinkError> {
        self.pump(None)?;
        Ok(self.scan.take())
    }

    fn publish_command(&mut self, msg: &CmdMsg) -> Result<(), AgentLinkError> {
        Ok(self.send(&Frame::encode(Kind::Command, self.robot, self.nonce, msg))?)
    }

    fn publish_status(&mut self, status: &AgentStatus) -> Result<(), AgentLinkError> {
        let msg = StatusMsg::encode(status)?;
        Ok(self.send(&Frame::encode(Kind::Status, self.robot, self.nonce, &msg))?)
    }

    fn world_alive(&mut self) -> Result<bool, AgentLinkError> {
        self.pump(None)?;
        Ok(!self.world_left && socket::listening(&self.world))
    }
}

impl Drop for DatagramAgentLink {
    fn drop(&mut self) {
        // Tell the world at once (it would find the socket gone anyway); never wait for it.
        let _ = self.outbox.set_nonblocking(true);
        let _ = self
            .outbox
            .send(&Frame::encode_bare(Kind::Goodbye, self.robot, self.nonce));
    }
}
