//! The live view (`formation run`, `profile` and `demo --foxglove HOST:PORT`): the process that
//! steps the world serves its run over Foxglove's WebSocket protocol (the `foxglove` crate,
//! subprotocol `foxglove.sdk.v1`), with the topics and messages of a recording
//! ([`formation_record::topics`], defined once there) less the replay channels: each robot's
//! scan, odometry and command (at 5 Hz: every `ROBOT_TOPICS_EVERY_TICKS`th tick), `/tf` and
//! `/tf_static`, the goal and the formation's edges, all CDR with their `ros2msg` schemas,
//! stamped and logged at the tick's simulated time.
//!
//! Built with the cargo feature `foxglove` only (the demo's build leaves it out); without it the
//! flag is refused with the build that has it ([`requested`]).
//!
//! It never slows the world's tick. While no client is connected a tick costs one check. With
//! one, the tick thread hands a copy of the tick to the view's own thread through a queue of
//! [`QUEUE_TICKS`] ticks, without waiting: when that thread is behind, the tick is dropped. The
//! view's thread encodes the messages and logs them to the server, which queues them per client
//! ([`client_backlog`] messages, about two seconds of the team's ticks) and drops a slow
//! client's oldest messages when its queue is full. A client that connects late sees the run
//! from then on: the next tick, and each robot's fixed frames (`/tf_static`) within a second.
//! Each new run of the same world starts a new session, so that clients clear the previous
//! run's messages.
//!
//! It listens on loopback unless told otherwise; another address gets a warning
//! ([`exposure_warning`]): the view has no login and no TLS.

use std::net::{IpAddr, SocketAddr, ToSocketAddrs};

/// Ticks queued between the tick thread and the view's thread; more are dropped.
pub const QUEUE_TICKS: usize = 8;

/// Why a live view cannot be served.
#[derive(Debug, thiserror::Error)]
pub enum LiveViewError {
    /// The address is not `HOST:PORT`, or the host is unknown.
    #[error(
        "--foxglove {text}: {reason}; give HOST:PORT, e.g. 127.0.0.1:8765 (this host only) or \
         0.0.0.0:8765 (every interface)"
    )]
    Address {
        /// What was given.
        text: String,
        /// Why it is not an address.
        reason: String,
    },
    /// This build has no live view.
    #[error(
        "--foxglove: this {program} was built without the live view; build it with the feature \
         `foxglove` (`cargo build --release --features foxglove`)"
    )]
    NotBuilt {
        /// The program.
        program: String,
    },
    /// The server could not start (the port is taken, the address is not this host's).
    #[cfg(feature = "foxglove")]
    #[error("the live view could not listen on {address}; is the port taken? Pick another one")]
    Start {
        /// The address.
        address: SocketAddr,
        /// Why.
        #[source]
        source: foxglove::FoxgloveError,
    },
    /// A topic could not be set up.
    #[cfg(feature = "foxglove")]
    #[error("the live view could not set up the topic {topic}")]
    Channel {
        /// The topic.
        topic: String,
        /// Why.
        #[source]
        source: foxglove::FoxgloveError,
    },
    /// The view's thread could not be started.
    #[error("the live view's thread could not be started")]
    Thread(#[source] std::io::Error),
}

/// Parses `HOST:PORT` (a name is resolved; its first address is taken).
pub fn parse_address(text: &str) -> Result<SocketAddr, LiveViewError> {
    let error = |reason: String| LiveViewError::Address {
        text: text.to_owned(),
        reason,
    };
    if let Ok(address) = text.parse::<SocketAddr>() {
        return Ok(address);
    }
    if !text.contains(':') {
        return Err(error("no port".into()));
    }
    let mut addresses = text.to_socket_addrs().map_err(|e| error(e.to_string()))?;
    addresses
        .next()
        .ok_or_else(|| error("the host has no address".into()))
}

/// The warning a live view on `address` gets: `None` on loopback.
pub fn exposure_warning(address: SocketAddr) -> Option<String> {
    if address.ip().is_loopback() {
        return None;
    }
    let local = match address.ip() {
        IpAddr::V4(_) => "127.0.0.1",
        IpAddr::V6(_) => "[::1]",
    };
    Some(format!(
        "warning: the live view on {address} is readable by anyone who reaches that address: it \
         has no login, and TLS is not available for it (ws:// only). To watch from another \
         host, serve it on {local}:{port} and forward the port (ssh -L {port}:localhost:{port})",
        port = address.port()
    ))
}

/// The address `--foxglove` asks for (`None` without the flag), checked: an error when this
/// build has no live view (`program` names the build) or the address is not one. Says the
/// [`exposure_warning`] on stderr when there is one (once: `warn`).
pub fn requested(
    text: Option<&str>,
    program: &str,
    warn: bool,
) -> Result<Option<SocketAddr>, LiveViewError> {
    let Some(text) = text else {
        return Ok(None);
    };
    if !cfg!(feature = "foxglove") {
        return Err(LiveViewError::NotBuilt {
            program: program.to_owned(),
        });
    }
    let address = parse_address(text)?;
    if warn && let Some(warning) = exposure_warning(address) {
        eprintln!("{program}: {warning}");
    }
    Ok(Some(address))
}

#[cfg(not(feature = "foxglove"))]
pub use off::LiveView;
#[cfg(feature = "foxglove")]
pub use server::{LiveView, client_backlog};

/// A build without the feature: a live view that cannot be made, so that its callers need no
/// `cfg` of their own ([`requested`] refuses the flag first).
#[cfg(not(feature = "foxglove"))]
mod off {
    use std::net::SocketAddr;

    use formation_record::{FinalSample, TeamSetup, TickRecord};

    use super::LiveViewError;

    /// No live view: this build has none.
    #[derive(Debug)]
    pub enum LiveView {}

    impl LiveView {
        /// Refused: this build has no live view.
        pub fn start(_address: SocketAddr, _n_robots: usize) -> Result<LiveView, LiveViewError> {
            Err(LiveViewError::NotBuilt {
                program: "program".into(),
            })
        }

        /// Where it listens.
        pub fn address(&self) -> SocketAddr {
            match *self {}
        }

        /// Begins a run.
        pub fn begin_run(&mut self, _team: TeamSetup, _d_star: f64) {
            match *self {}
        }

        /// Whether a tick would be shown.
        pub fn wants_ticks(&self) -> bool {
            match *self {}
        }

        /// Hands a tick on.
        pub fn tick(&mut self, _tick: TickRecord) {
            match *self {}
        }

        /// Ends the run.
        pub fn end_run(&mut self, _last: Option<FinalSample>) {
            match *self {}
        }

        /// Ticks dropped so far.
        pub fn dropped_ticks(&self) -> u64 {
            match *self {}
        }
    }
}

#[cfg(feature = "foxglove")]
mod server {
    use std::cell::Cell;
    use std::convert::Infallible;
    use std::net::SocketAddr;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
    use std::thread::JoinHandle;

    use formation_record::topics::{Replay, Slot, TickMessages, Topics};
    use formation_record::{FinalSample, TeamSetup, TickRecord};
    use foxglove::{
        ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer,
        WebSocketServerHandle,
    };

    use super::{LiveViewError, QUEUE_TICKS};

    /// Each robot's fixed frames are sent again every this many ticks (a second at 20 Hz), for
    /// the clients that joined since.
    const STATIC_EVERY_TICKS: u64 = 20;

    /// Each robot's own topics (its LaserScan, odometry and command) are served every this many
    /// ticks (5 Hz at 20 Hz control, a real LDS-01's scan rate); `/tf`, the goal and the edges
    /// every tick, so the team still moves smoothly. Each message costs the world about the
    /// same whatever its size, and the robots' topics are three messages a robot a tick:
    /// served every tick with one `/tf` a robot, the view cost a 32-robot realtime world 12–19 %
    /// of its work a tick; at 5 Hz with one `/tf` a tick, +4.4 % (median of 5 paired runs,
    /// release: `scripts/measure live-view`, docs/measurements/live-view.json).
    pub const ROBOT_TOPICS_EVERY_TICKS: u64 = 4;

    /// The messages a client's queue holds for a team of `n_robots`: about two seconds of
    /// ticks at 20 Hz (each tick: four per robot, the goal's three and the edges), at least
    /// the crate's default of 1024.
    pub fn client_backlog(n_robots: usize) -> usize {
        (40 * (4 * n_robots + 4)).max(1024)
    }

    enum Job {
        Begin(TeamSetup),
        Tick(Box<TickRecord>),
        End(Option<FinalSample>, f64),
    }

    /// A live view being served.
    #[derive(Debug)]
    pub struct LiveView {
        address: SocketAddr,
        /// Holds the channels (they close with it).
        _context: Arc<Context>,
        server: Option<WebSocketServerHandle>,
        jobs: Option<SyncSender<Job>>,
        thread: Option<JoinHandle<()>>,
        dropped: Arc<AtomicU64>,
        runs: u64,
        d_star: f64,
    }

    impl LiveView {
        /// Listens on `address` (port 0: any free port) for a team of `n_robots`, with every
        /// topic advertised. Must not be called from within an async runtime.
        pub fn start(address: SocketAddr, n_robots: usize) -> Result<LiveView, LiveViewError> {
            let context = Context::new();
            let channels = advertise(&context, n_robots)?;
            let server = WebSocketServer::new()
                .name("formation")
                .context(&context)
                .bind(address.ip().to_string(), address.port())
                .message_backlog_size(client_backlog(n_robots))
                .start_blocking()
                .map_err(|source| LiveViewError::Start { address, source })?;
            let bound = SocketAddr::new(address.ip(), server.port());
            let (jobs, queue) = sync_channel(QUEUE_TICKS);
            let thread = std::thread::Builder::new()
                .name("formation-live-view".into())
                .spawn(move || serve(&channels, &queue))
                .map_err(LiveViewError::Thread)?;
            Ok(LiveView {
                address: bound,
                _context: context,
                server: Some(server),
                jobs: Some(jobs),
                thread: Some(thread),
                dropped: Arc::new(AtomicU64::new(0)),
                runs: 0,
                d_star: 0.0,
            })
        }

        /// Where it listens (the port chosen when 0 was asked for).
        pub fn address(&self) -> SocketAddr {
            self.address
        }

        /// The clients connected now.
        pub fn clients(&self) -> usize {
            self.server
                .as_ref()
                .map_or(0, WebSocketServerHandle::client_count)
        }

        /// Ticks dropped so far because the view's thread was behind.
        pub fn dropped_ticks(&self) -> u64 {
            self.dropped.load(Ordering::Relaxed)
        }

        /// Begins a run of the team `team` at distance `d_star`: a run after the first starts a
        /// new session (clients clear the previous run's messages).
        pub fn begin_run(&mut self, team: TeamSetup, d_star: f64) {
            if self.runs > 0
                && let Some(server) = &self.server
            {
                server.clear_session(None);
            }
            self.runs += 1;
            self.d_star = d_star;
            self.send_waiting(Job::Begin(team));
        }

        /// Whether a tick would be shown: a client is connected.
        pub fn wants_ticks(&self) -> bool {
            self.clients() > 0
        }

        /// Hands `tick` to the view's thread, or drops it when that thread is behind. Never
        /// waits.
        pub fn tick(&mut self, tick: TickRecord) {
            self.send(Job::Tick(Box::new(tick)));
        }

        /// Ends the run, with the state after its last step when it played to its end.
        pub fn end_run(&mut self, last: Option<FinalSample>) {
            self.send_waiting(Job::End(last, self.d_star));
        }

        /// Queues a run's begin or end, waiting for room: the view's thread never waits on a
        /// client, so this waits at most for the ticks queued before it to be encoded.
        fn send_waiting(&mut self, job: Job) {
            if let Some(jobs) = &self.jobs
                && jobs.send(job).is_err()
            {
                self.jobs = None;
            }
        }

        fn send(&mut self, job: Job) {
            let Some(jobs) = &self.jobs else {
                return;
            };
            match jobs.try_send(job) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => {
                    self.dropped.fetch_add(1, Ordering::Relaxed);
                }
                Err(TrySendError::Disconnected(_)) => self.jobs = None,
            }
        }
    }

    impl Drop for LiveView {
        /// Lets the view's thread finish what it has, then stops the server.
        fn drop(&mut self) {
            self.jobs = None;
            if let Some(thread) = self.thread.take() {
                let _ = thread.join();
            }
            if let Some(server) = self.server.take() {
                drop(server.stop());
            }
        }
    }

    /// One channel per topic of a recording, none for the replay channels, in slot order.
    fn advertise(
        context: &Arc<Context>,
        n_robots: usize,
    ) -> Result<Vec<Option<Arc<RawChannel>>>, LiveViewError> {
        Topics::all(n_robots)
            .into_iter()
            .enumerate()
            .map(|(slot, topic)| {
                if Topics::is_replay(slot) {
                    return Ok(None);
                }
                let schema = Schema::new(
                    topic.type_name,
                    "ros2msg",
                    topic.definition.ros2msg().into_bytes(),
                );
                ChannelBuilder::new(topic.name.clone())
                    .context(context)
                    .message_encoding("cdr")
                    .schema(schema)
                    .build_raw()
                    .map(Some)
                    .map_err(|source| LiveViewError::Channel {
                        topic: topic.name,
                        source,
                    })
            })
            .collect()
    }

    /// The view's thread: encodes each queued tick and logs it on its channels (an encoding
    /// failure skips the tick, and is said once).
    fn serve(channels: &[Option<Arc<RawChannel>>], queue: &Receiver<Job>) {
        let mut messages: Option<TickMessages> = None;
        let mut failed = false;
        // Whether this tick's robot topics are served ([`ROBOT_TOPICS_EVERY_TICKS`]); on the
        // other ticks the scans are emptied before encoding and no robot topic is logged.
        let robots_now = Cell::new(true);
        let is_robot_topic = |slot: Slot| slot >= Topics::scan(0);
        let mut log = |slot: Slot, ns: u64, data: &[u8]| -> Result<(), Infallible> {
            if !robots_now.get() && is_robot_topic(slot) {
                return Ok(());
            }
            if let Some(Some(channel)) = channels.get(slot) {
                channel.log_with_meta(data, PartialMetadata::with_log_time(ns));
            }
            Ok(())
        };
        for job in queue.iter() {
            robots_now.set(true);
            let done = match job {
                Job::Begin(team) => {
                    let fresh = TickMessages::new(team, Replay::Left).with_one_tf_message();
                    let sent = fresh.static_frames(&mut log);
                    messages = Some(fresh);
                    sent
                }
                Job::Tick(mut tick) => {
                    let robots = tick.tick.is_multiple_of(ROBOT_TOPICS_EVERY_TICKS);
                    if !robots {
                        tick.scans.iter_mut().for_each(Vec::clear);
                    }
                    robots_now.set(robots);
                    match &mut messages {
                        Some(messages) if tick.tick % STATIC_EVERY_TICKS == 0 => messages
                            .static_frames(&mut log)
                            .and_then(|()| messages.tick(&tick, &mut log)),
                        Some(messages) => messages.tick(&tick, &mut log),
                        None => Ok(()),
                    }
                }
                Job::End(last, d_star) => match (last, messages.take()) {
                    (Some(last), Some(mut messages)) => messages.last(&last, d_star, &mut log),
                    _ => Ok(()),
                },
            };
            if let Err(e) = done
                && !failed
            {
                failed = true;
                eprintln!(
                    "formation: the live view skips a tick: {}",
                    formation_proto::errors::chain_text(&e)
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_are_host_and_port_and_only_loopback_goes_unwarned() {
        let local = parse_address("127.0.0.1:8765").unwrap();
        assert_eq!(local.port(), 8765);
        assert!(exposure_warning(local).is_none());
        assert!(exposure_warning(parse_address("[::1]:9").unwrap()).is_none());
        assert!(parse_address("localhost:8765").unwrap().ip().is_loopback());
        let every = exposure_warning(parse_address("0.0.0.0:8765").unwrap()).unwrap();
        assert!(every.contains("readable by anyone"), "{every}");
        assert!(every.contains("TLS is not available"), "{every}");
        for bad in [
            "8765",
            "127.0.0.1",
            "127.0.0.1:port",
            "no.such.host.invalid:1",
        ] {
            let error = parse_address(bad).unwrap_err().to_string();
            assert!(error.contains("HOST:PORT"), "{bad}: {error}");
        }
    }

    #[test]
    fn no_flag_asks_for_nothing() {
        assert!(requested(None, "formation", true).unwrap().is_none());
    }

    #[cfg(not(feature = "foxglove"))]
    #[test]
    fn a_build_without_the_feature_names_the_one_with_it() {
        let error = requested(Some("127.0.0.1:8765"), "formation", false)
            .unwrap_err()
            .to_string();
        assert!(error.contains("--features foxglove"), "{error}");
    }

    #[cfg(feature = "foxglove")]
    mod served {
        use super::super::*;
        use formation_proto::{Goal, NeighbourRule, Pose, WheelCmd};
        use formation_record::{SentCommand, TeamSetup, TickRecord};

        fn team() -> TeamSetup {
            TeamSetup {
                n_robots: 3,
                max_range: 5.0,
                wheel_separation: 0.331,
                neighbours: NeighbourRule::AllPairs,
                wheels: formation_proto::WheelLimits::default(),
            }
        }

        fn tick(k: u64) -> TickRecord {
            TickRecord {
                tick: k,
                time: k as f64 * 0.05,
                goal: Goal::new(0.0, 1.0, 0.7),
                poses: (0..3)
                    .map(|i| Pose {
                        x: f64::from(i),
                        y: 0.0,
                        theta: 0.0,
                    })
                    .collect(),
                wheel_speeds: vec![WheelCmd::default(); 3],
                scans: vec![vec![1.0; 900]; 3],
                commands: vec![SentCommand::in_process(WheelCmd::default()); 3],
                model_ids: Vec::new(),
            }
        }

        #[test]
        fn a_view_without_clients_takes_no_ticks_and_a_full_queue_drops_them() {
            let address = parse_address("127.0.0.1:0").unwrap();
            let mut view = LiveView::start(address, 3).unwrap();
            assert_ne!(view.address().port(), 0);
            assert!(!view.wants_ticks());
            view.begin_run(team(), 1.0);
            // Many more ticks than the queue holds, at once: none waits, the surplus is
            // dropped or encoded, and the run ends cleanly.
            for k in 0..(50 * QUEUE_TICKS as u64) {
                view.tick(tick(k));
            }
            view.end_run(None);
            assert!(view.dropped_ticks() <= 50 * QUEUE_TICKS as u64);
            drop(view);
        }

        #[test]
        fn a_taken_port_is_refused_with_the_fix() {
            let first = LiveView::start(parse_address("127.0.0.1:0").unwrap(), 3).unwrap();
            let error = LiveView::start(first.address(), 3).unwrap_err();
            assert!(error.to_string().contains("port taken"), "{error}");
        }
    }
}
