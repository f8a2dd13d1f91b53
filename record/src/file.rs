//! One recording file: an MCAP with the `ros2` profile, written tick by tick.
//!
//! Layout, in file order: the header; the run's metadata record (`formation.run`) and, for a
//! model from outside the shipped folder, the model as an attachment; then the messages in
//! chunks, each chunk holding one second of simulated time at most (a chunk is closed and
//! written out when a tick enters the next second, so a crash loses at most the second under
//! way, and memory holds one chunk); between two chunks, a model swapped in during the run, as an
//! attachment followed by its `formation.swapped_model` record ([`crate::swap`]), written out at
//! once (a crash after it keeps it, and a crash inside it keeps everything before it readable by
//! a streaming reader); at the end how the run ended (the `formation.run_end` metadata record:
//! whether the run played to its last tick, and if not why it stopped, as its run log says) and
//! the summary (schemas, channels, chunk indexes, statistics). What stays in memory until then is the summary's chunk indexes: one per second of
//! run, each with the offset of every channel's message index in its chunk (which `rosbags` and
//! rosbag2 need to find a topic's chunks), about 40 bytes per channel and second: 5 KB per
//! second for 32 robots, under 20 MB for the longest run a scenario allows (an hour).
//!
//! Topics (log and publish time = the message's stamp = the tick's simulated time):
//! `/robot_<i>/scan` (LaserScan), `/robot_<i>/odom` (Odometry), `/robot_<i>/cmd_vel` (Twist),
//! `/robot_<i>/replay` ([`crate::replay`]), `/tf` (one TFMessage per robot and sample, world →
//! `robot_<i>/base_link`, including the state after the last step), `/tf_static` (once, at 0),
//! the goal on `/formation/goal/{heading,distance,speed}` (Float64) and the edges on
//! `/formation/edges` (MarkerArray): the messages of the live ROS 2 team
//! ([`formation_ros2::team`]).

use std::collections::{BTreeMap, HashSet};
use std::fs::File;
use std::io::{BufWriter, Read as _};
use std::path::{Path, PathBuf};

use formation_proto::files::{FileRefusal, read_bounded};
use formation_ros2::msg::Time;
use formation_ros2::schema::MsgDefinition;
use formation_ros2::team::{self, GOAL_TOPICS};
use formation_ros2::{Float64, LaserScan, MarkerArray, Odometry, RosMessage, TfMessage, Twist};
use mcap::records::{AttachmentHeader, MessageHeader, Metadata};

use crate::edges::{self, EdgeMarkers};
use crate::error::RecordError;
use crate::replay::{self, ReplayStep};
use crate::setup::{RecordingSetup, TeamSetup};
use crate::swap::{SWAP_METADATA, SwapEvent, SwapStorage, SwappedModel, check_swapped_bytes};
use crate::tick::{FinalSample, RUN_END_METADATA, RunEnd, TickRecord};

/// The most bytes of a model a recording stores as an attachment.
pub const MAX_ATTACHED_MODEL_BYTES: u64 = 256 << 20;

/// The media type of a model stored as an attachment.
pub const MODEL_MEDIA_TYPE: &str = "application/x-onnx";

/// Uncompressed bytes at which a chunk is closed even within a second (a huge team).
const MAX_CHUNK_BYTES: u64 = 16 << 20;

/// zstd's level: the noisy LIDAR ranges that make up most of a recording compress no better at
/// higher levels (measured on a 16-robot chunk: ratio 9.8 at level 1, 9.85 at 3, 10.2 at 9),
/// while level 1 takes 9 ms per simulated second where 3 takes 12 and 9 takes 68.
const ZSTD_LEVEL: u32 = 1;

/// The output buffer between the MCAP writer and the file.
const FILE_BUFFER: usize = 256 << 10;

/// How much of a model is read at a time, to hash and store it.
const MODEL_PIECE: usize = 64 << 10;

/// What takes a model's bytes piece by piece: a hasher, or the attachment being written.
type PieceSink<'a> = dyn FnMut(&[u8]) -> Result<(), RecordError> + 'a;

/// A robot's channels.
#[derive(Debug, Clone, Copy)]
struct RobotChannels {
    scan: u16,
    odom: u16,
    cmd_vel: u16,
    replay: u16,
}

/// Every channel of a recording.
#[derive(Debug)]
struct Channels {
    robots: Vec<RobotChannels>,
    tf: u16,
    tf_static: u16,
    goal: [u16; 3],
    edges: u16,
}

/// What a finished recording holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingSummary {
    /// The file.
    pub path: PathBuf,
    /// Messages written.
    pub messages: u64,
    /// Chunks written.
    pub chunks: usize,
    /// Its size \[bytes\].
    pub bytes: u64,
}

/// A recording being written.
pub struct RecordingFile {
    path: PathBuf,
    mcap: mcap::Writer<BufWriter<File>>,
    team: TeamSetup,
    d_star: f64,
    channels: Channels,
    /// Per channel id: its topic (for messages) and its next sequence number.
    topics: Vec<(String, u32)>,
    /// The whole second of simulated time the open chunk holds.
    chunk_second: Option<u64>,
    edges: EdgeMarkers,
    model_ids: Vec<String>,
    /// The folder of the shipped models, whose swapped-in models are referenced, not stored.
    shipped_models: Option<PathBuf>,
    /// The names of the models stored so far (each model is stored once).
    attached: HashSet<String>,
    /// The simulated time of the last tick written \[ns\] (a swapped-in model's log time).
    last_tick_ns: u64,
}

impl std::fmt::Debug for RecordingFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingFile")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

/// Simulated time `t` \[s\] in nanoseconds (0 for a negative or non-finite time).
fn nanos(t: f64) -> u64 {
    let ns = (t * 1e9).round();
    if ns.is_finite() && ns > 0.0 {
        ns as u64
    } else {
        0
    }
}

fn stamp(ns: u64) -> Time {
    Time::from_nanos(i64::try_from(ns).unwrap_or(i64::MAX))
}

/// Opens a model to read, refusing one larger than a recording stores (`recording` names the
/// file in errors).
fn open_model(recording: &Path, model: &Path) -> Result<(File, u64), RecordError> {
    let model_error = |source| RecordError::Model {
        path: recording.to_path_buf(),
        model: model.to_path_buf(),
        source,
    };
    let file = File::open(model).map_err(model_error)?;
    let size = file.metadata().map_err(model_error)?.len();
    if size > MAX_ATTACHED_MODEL_BYTES {
        return Err(RecordError::ModelTooLarge {
            path: recording.to_path_buf(),
            model: model.to_path_buf(),
            size,
            limit: MAX_ATTACHED_MODEL_BYTES,
        });
    }
    Ok((file, size))
}

/// Reads `model` piece by piece, handing each piece to `each`; returns the bytes read.
fn read_model(
    recording: &Path,
    model: &Path,
    each: &mut PieceSink<'_>,
) -> Result<u64, RecordError> {
    let (file, size) = open_model(recording, model)?;
    let mut file = file.take(size);
    let mut piece = vec![0u8; MODEL_PIECE];
    let mut total = 0;
    loop {
        let n = file.read(&mut piece).map_err(|source| RecordError::Model {
            path: recording.to_path_buf(),
            model: model.to_path_buf(),
            source,
        })?;
        if n == 0 {
            return Ok(total);
        }
        total += n as u64;
        each(&piece[..n])?;
    }
}

/// The SHA-256 of `model`, as hex (`recording` names the file in errors).
pub(crate) fn hash_model(recording: &Path, model: &Path) -> Result<String, RecordError> {
    use sha2::Digest as _;
    let mut hasher = sha2::Sha256::new();
    read_model(recording, model, &mut |piece| {
        hasher.update(piece);
        Ok(())
    })?;
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

impl RecordingFile {
    /// Creates (or replaces) `path` and writes everything that precedes the first tick: the
    /// metadata, the models, the channels and the static frames.
    pub fn create(path: &Path, setup: RecordingSetup) -> Result<RecordingFile, RecordError> {
        let mut recording = Self::open(path, setup.team.clone(), setup.d_star)?;
        recording
            .shipped_models
            .clone_from(&setup.launch.shipped_models);
        let (metadata, attachments) = setup.metadata_with_models(path)?;
        for (model, name) in &attachments {
            recording.attach_model(model, name)?;
        }
        recording.write_metadata(metadata)?;
        recording.write_channels()?;
        Ok(recording)
    }

    /// Creates (or replaces) `path` for the team `team` with a metadata record made elsewhere
    /// (a recorder of a live team: the world hashed the models, and stores none here), and
    /// writes the channels and the static frames.
    pub fn create_with_metadata(
        path: &Path,
        team: TeamSetup,
        d_star: f64,
        metadata: BTreeMap<String, String>,
    ) -> Result<RecordingFile, RecordError> {
        let mut recording = Self::open(path, team, d_star)?;
        recording.write_metadata(metadata)?;
        recording.write_channels()?;
        Ok(recording)
    }

    /// Creates the file and writes the MCAP header.
    fn open(path: &Path, team: TeamSetup, d_star: f64) -> Result<RecordingFile, RecordError> {
        let file = crate::target::create_file(path)?;
        let options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("formation-record ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(ZSTD_LEVEL)
            .compression_threads(0)
            .chunk_size(Some(MAX_CHUNK_BYTES));
        let mcap = mcap::Writer::with_options(BufWriter::with_capacity(FILE_BUFFER, file), options)
            .map_err(|e| RecordError::from_mcap(path, e))?;
        let edges = EdgeMarkers::new(team.neighbours, team.n_robots);
        Ok(RecordingFile {
            path: path.to_path_buf(),
            mcap,
            channels: Channels {
                robots: Vec::new(),
                tf: 0,
                tf_static: 0,
                goal: [0; 3],
                edges: 0,
            },
            topics: vec![(String::new(), 0)],
            chunk_second: None,
            edges,
            model_ids: Vec::new(),
            shipped_models: None,
            attached: HashSet::new(),
            last_tick_ns: 0,
            team,
            d_star,
        })
    }

    /// Adds the channels and writes the static frames.
    fn write_channels(&mut self) -> Result<(), RecordError> {
        self.add_channels()?;
        for robot in 0..self.team.n_robots {
            let tf = team::static_tf_message(robot, Time::default());
            self.put(self.channels.tf_static, 0, &tf)?;
        }
        self.flush()
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn mcap_error(&self, e: mcap::McapError) -> RecordError {
        RecordError::from_mcap(&self.path, e)
    }

    /// The run's metadata record.
    fn write_metadata(&mut self, metadata: BTreeMap<String, String>) -> Result<(), RecordError> {
        self.mcap
            .write_metadata(&Metadata {
                name: "formation.run".into(),
                metadata,
            })
            .map_err(|e| self.mcap_error(e))
    }

    /// Starts the model attachment `name` of `size` bytes, logged at `ns`.
    fn start_model_attachment(
        &mut self,
        name: &str,
        size: u64,
        ns: u64,
    ) -> Result<(), RecordError> {
        let header = AttachmentHeader {
            log_time: ns,
            create_time: ns,
            name: name.to_owned(),
            media_type: MODEL_MEDIA_TYPE.into(),
        };
        self.attached.insert(name.to_owned());
        self.mcap
            .start_attachment(size, header)
            .map_err(|e| self.mcap_error(e))
    }

    /// Stores `model` as the attachment `name`, streamed in pieces.
    fn attach_model(&mut self, model: &Path, name: &str) -> Result<(), RecordError> {
        let (_, size) = open_model(&self.path, model)?;
        self.start_model_attachment(name, size, 0)?;
        let recording = self.path.clone();
        let written = read_model(&recording, model, &mut |piece| {
            self.mcap
                .put_attachment_bytes(piece)
                .map_err(|e| RecordError::from_mcap(&recording, e))
        })?;
        if written != size {
            return Err(RecordError::Model {
                path: self.path.clone(),
                model: model.to_path_buf(),
                source: std::io::Error::other(format!(
                    "it changed while it was stored ({size} bytes, then {written})"
                )),
            });
        }
        self.mcap
            .finish_attachment()
            .map_err(|e| self.mcap_error(e))
    }

    /// Records a model swapped in during the run (see [`crate::swap`]): the model file stored as
    /// an attachment (once; a shipped one is referenced) when its bytes are the ones the agent
    /// loaded, else recorded as not stored with the reason; then the record that maps the model
    /// id to it, and everything is handed to the operating system. Only a failed write is an
    /// error.
    pub fn write_swap(&mut self, event: &SwapEvent) -> Result<SwappedModel, RecordError> {
        let ns = self.last_tick_ns;
        let (sha256, storage) = match self.read_swapped(event) {
            Err(why) => (String::new(), SwapStorage::NotStored(why)),
            Ok((path, bytes)) => {
                let sha256 = crate::models::sha256_hex(&bytes);
                let local = event.bytes.is_none();
                let shipped_models = self.shipped_models.as_deref();
                let storage = if local && crate::setup::is_shipped_in(shipped_models, path) {
                    SwapStorage::Shipped
                } else {
                    let name = format!("models/{sha256}.onnx");
                    if !self.attached.contains(&name) {
                        self.start_model_attachment(&name, bytes.len() as u64, ns)?;
                        self.mcap
                            .put_attachment_bytes(&bytes)
                            .map_err(|e| self.mcap_error(e))?;
                        self.mcap
                            .finish_attachment()
                            .map_err(|e| self.mcap_error(e))?;
                    }
                    SwapStorage::Attachment(name)
                };
                (sha256, storage)
            }
        };
        let swapped = SwappedModel {
            robot: event.robot,
            tick: event.tick,
            request_id: event.request_id,
            model_id: event.model_id.clone(),
            path: event.path.clone().unwrap_or_default(),
            sha256,
            storage,
        };
        self.mcap
            .write_metadata(&Metadata {
                name: SWAP_METADATA.into(),
                metadata: swapped.to_metadata(),
            })
            .map_err(|e| self.mcap_error(e))?;
        self.flush()?;
        Ok(swapped)
    }

    /// The swapped-in model's file and bytes when they are the ones the agent loaded, else why
    /// not (bounded by [`MAX_ATTACHED_MODEL_BYTES`]): the bytes that came with the request, or
    /// the file's.
    fn read_swapped<'e>(
        &self,
        event: &'e SwapEvent,
    ) -> Result<(&'e Path, std::borrow::Cow<'e, [u8]>), String> {
        let path = event.path.as_deref().unwrap_or(Path::new(""));
        if let Some(bytes) = &event.bytes {
            if bytes.len() as u64 > MAX_ATTACHED_MODEL_BYTES {
                return Err(format!(
                    "the model sent with the request is larger than the \
                     {MAX_ATTACHED_MODEL_BYTES} bytes a recording stores"
                ));
            }
            check_swapped_bytes(&event.model_id, bytes)?;
            return Ok((path, std::borrow::Cow::Borrowed(bytes)));
        }
        if event.path.is_none() {
            return Err("the world does not know the file the swap request named".into());
        }
        let bytes = read_bounded(path, MAX_ATTACHED_MODEL_BYTES).map_err(|refusal| {
            let why = match refusal {
                FileRefusal::NotAFile { kind } => format!("it is {kind}"),
                FileRefusal::TooLarge { .. } => format!(
                    "it is larger than the {MAX_ATTACHED_MODEL_BYTES} bytes a recording stores"
                ),
                FileRefusal::Io(e) => e.to_string(),
            };
            format!("cannot read {} on the world's host: {why}", path.display())
        })?;
        check_swapped_bytes(&event.model_id, &bytes)
            .map_err(|why| format!("{}: {why}", path.display()))?;
        Ok((path, std::borrow::Cow::Owned(bytes)))
    }

    /// Adds a channel of message type `M` on `topic`.
    fn channel<M: RosMessage>(&mut self, topic: &str) -> Result<u16, RecordError> {
        self.channel_of(topic, M::ROS_NAME, M::DEFINITION)
    }

    fn channel_of(
        &mut self,
        topic: &str,
        type_name: &str,
        definition: &'static MsgDefinition,
    ) -> Result<u16, RecordError> {
        let schema = self
            .mcap
            .add_schema(type_name, "ros2msg", definition.ros2msg().as_bytes())
            .map_err(|e| self.mcap_error(e))?;
        let id = self
            .mcap
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .map_err(|e| self.mcap_error(e))?;
        let slot = usize::from(id);
        if self.topics.len() <= slot {
            self.topics.resize(slot + 1, (String::new(), 0));
        }
        self.topics[slot] = (topic.to_owned(), 0);
        Ok(id)
    }

    fn add_channels(&mut self) -> Result<(), RecordError> {
        self.channels.tf = self.channel::<TfMessage>("/tf")?;
        self.channels.tf_static = self.channel::<TfMessage>("/tf_static")?;
        for (slot, topic) in GOAL_TOPICS.iter().enumerate() {
            self.channels.goal[slot] = self.channel::<Float64>(topic)?;
        }
        self.channels.edges = self.channel::<MarkerArray>(edges::TOPIC)?;
        for robot in 0..self.team.n_robots {
            let channels = RobotChannels {
                scan: self.channel::<LaserScan>(&team::robot_topic(robot, "scan"))?,
                odom: self.channel::<Odometry>(&team::robot_topic(robot, "odom"))?,
                cmd_vel: self.channel::<Twist>(&team::robot_topic(robot, "cmd_vel"))?,
                replay: self.channel_of(
                    &replay::topic(robot),
                    replay::TYPE_NAME,
                    &replay::REPLAY_STEP,
                )?,
            };
            self.channels.robots.push(channels);
        }
        Ok(())
    }

    /// Writes one message's CDR `data` on `channel` at `ns`.
    fn put_bytes(&mut self, channel: u16, ns: u64, data: &[u8]) -> Result<(), RecordError> {
        let slot = &mut self.topics[usize::from(channel)];
        let sequence = slot.1;
        slot.1 = slot.1.wrapping_add(1);
        let header = MessageHeader {
            channel_id: channel,
            sequence,
            log_time: ns,
            publish_time: ns,
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_error(e))
    }

    /// Writes `msg` on `channel` at `ns`.
    fn put<M: RosMessage>(&mut self, channel: u16, ns: u64, msg: &M) -> Result<(), RecordError> {
        let data = msg.to_cdr().map_err(|source| RecordError::Encode {
            path: self.path.clone(),
            topic: self.topics[usize::from(channel)].0.clone(),
            source,
        })?;
        self.put_bytes(channel, ns, &data)
    }

    /// Closes the open chunk when `ns` lies in a later second than it, so that no chunk spans
    /// more than one second of simulated time.
    fn start_second(&mut self, ns: u64) -> Result<(), RecordError> {
        let second = ns / 1_000_000_000;
        if self.chunk_second.is_some_and(|open| open != second) {
            self.flush()?;
        }
        self.chunk_second = Some(second);
        Ok(())
    }

    /// Closes the open chunk and hands everything written to the operating system, so that a
    /// crash from here on leaves a file a streaming reader reads up to this point.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.mcap.flush().map_err(|e| self.mcap_error(e))
    }

    /// Writes one tick: the goal, each robot's `/tf`, odometry, scan, command and replay step,
    /// and the edges.
    pub fn write_tick(&mut self, tick: &TickRecord) -> Result<(), RecordError> {
        let ns = nanos(tick.time);
        self.start_second(ns)?;
        self.last_tick_ns = ns;
        let at = stamp(ns);
        let goal = [tick.goal.phi_star, tick.goal.d_star, tick.goal.v_star];
        for (slot, data) in goal.into_iter().enumerate() {
            self.put(self.channels.goal[slot], ns, &Float64 { data })?;
        }
        let n = self.team.n_robots.min(tick.poses.len());
        for robot in 0..n {
            self.write_robot(robot, tick, ns, at)?;
        }
        let markers = self.edges.next(at, &tick.poses, tick.goal.d_star);
        self.put(self.channels.edges, ns, &markers)
    }

    fn write_robot(
        &mut self,
        robot: usize,
        tick: &TickRecord,
        ns: u64,
        at: Time,
    ) -> Result<(), RecordError> {
        let channels = self.channels.robots[robot];
        let pose = tick.poses[robot];
        let separation = self.team.wheel_separation;
        let max_range = self.team.max_range;
        self.put(
            self.channels.tf,
            ns,
            &team::tf_message(robot, at, pose.x, pose.y, pose.theta),
        )?;
        let speeds = tick.wheel_speeds.get(robot).copied().unwrap_or_default();
        let wheels = team::Wheels {
            left: speeds.left,
            right: speeds.right,
            separation,
        };
        let odom = team::odometry_message(robot, at, (pose.x, pose.y), pose.theta, wheels);
        self.put(channels.odom, ns, &odom)?;
        let ranges: &[f32] = tick.scans.get(robot).map_or(&[], Vec::as_slice);
        let scan = team::laser_scan_message(robot, at, ranges, max_range);
        self.put(channels.scan, ns, &scan)?;
        let sent = tick.commands.get(robot).copied();
        let command = sent.map_or_else(Default::default, |c| c.wheels);
        let cmd_vel = team::Wheels {
            left: command.left,
            right: command.right,
            separation,
        };
        self.put(channels.cmd_vel, ns, &cmd_vel.twist())?;
        self.write_replay(robot, tick, ns)
    }

    fn write_replay(
        &mut self,
        robot: usize,
        tick: &TickRecord,
        ns: u64,
    ) -> Result<(), RecordError> {
        let sent = tick
            .commands
            .get(robot)
            .copied()
            .unwrap_or_else(|| crate::tick::SentCommand::in_process(Default::default()));
        if let Some(id) = tick.model_ids.get(robot) {
            if self.model_ids.len() <= robot {
                self.model_ids.resize(robot + 1, String::new());
            }
            if self.model_ids[robot] != *id {
                self.model_ids[robot].clone_from(id);
            }
        }
        let step = ReplayStep {
            robot: u32::try_from(robot).unwrap_or(u32::MAX),
            tick: tick.tick,
            time: tick.time,
            heading: tick.poses[robot].theta,
            goal: tick.goal,
            max_range: self.team.max_range as f32,
            ranges: tick.scans.get(robot).cloned().unwrap_or_default(),
            command: sent.wheels,
            outcome: sent.outcome,
            lag_ticks: sent.lag_ticks,
            model_id: self.model_ids.get(robot).cloned().unwrap_or_default(),
        };
        let channel = self.channels.robots[robot].replay;
        let data = step.to_cdr().map_err(|source| RecordError::Encode {
            path: self.path.clone(),
            topic: replay::topic(robot),
            source,
        })?;
        self.put_bytes(channel, ns, &data)
    }

    /// Writes the state after the last step (each robot's `/tf` and the edges) and the summary,
    /// and closes the file. With `last` the run played to its end; without it the recording
    /// says it stopped early ([`RecordingFile::finish_stopped`] says why).
    pub fn finish(self, last: Option<&FinalSample>) -> Result<RecordingSummary, RecordError> {
        let end = match last {
            Some(_) => RunEnd::complete(),
            None => RunEnd::stopped(RunEnd::UNKNOWN_REASON),
        };
        self.finish_with(last, &end)
    }

    /// Closes the file of a run that stopped before its end, for `reason` (the run log's stop
    /// reason: "interrupted by Ctrl-C", an agent that stopped answering, ...).
    pub fn finish_stopped(self, reason: &str) -> Result<RecordingSummary, RecordError> {
        self.finish_with(None, &RunEnd::stopped(reason))
    }

    /// Writes the state after the last step (when given), how the run ended, the summary, and
    /// closes the file.
    fn finish_with(
        mut self,
        last: Option<&FinalSample>,
        end: &RunEnd,
    ) -> Result<RecordingSummary, RecordError> {
        if let Some(last) = last {
            let ns = nanos(last.time);
            self.start_second(ns)?;
            let at = stamp(ns);
            for (robot, pose) in last.poses.iter().enumerate() {
                let tf = team::tf_message(robot, at, pose.x, pose.y, pose.theta);
                self.put(self.channels.tf, ns, &tf)?;
            }
            let d_star = self.last_d_star();
            let markers = self.edges.next(at, &last.poses, d_star);
            self.put(self.channels.edges, ns, &markers)?;
        }
        self.mcap
            .write_metadata(&Metadata {
                name: RUN_END_METADATA.into(),
                metadata: end.to_metadata(),
            })
            .map_err(|e| self.mcap_error(e))?;
        let summary = self.mcap.finish().map_err(|e| self.mcap_error(e))?;
        let messages = summary.stats.as_ref().map_or(0, |s| s.message_count);
        let chunks = summary.chunk_indexes.len();
        let file = self.mcap.into_inner();
        let file = file
            .into_inner()
            .map_err(|e| RecordError::from_mcap(&self.path, e.into_error().into()))?;
        file.sync_all()
            .map_err(|e| RecordError::from_mcap(&self.path, e.into()))?;
        let bytes = file.metadata().map(|m| m.len()).unwrap_or(0);
        Ok(RecordingSummary {
            path: self.path.clone(),
            messages,
            chunks,
            bytes,
        })
    }

    /// The run's d* (a run's goal keeps it).
    fn last_d_star(&self) -> f64 {
        self.d_star
    }
}
