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
//! Topics (log and publish time = the message's stamp = the tick's simulated time): those of
//! [`crate::topics`], defined there once (the live view serves the same), with the replay
//! channel; `/tf` includes the state after the last step, and `/tf_static` is written once, at 0.

use std::collections::{BTreeMap, HashSet};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use formation_proto::SwapDone;
use formation_proto::files::{FileRefusal, read_bounded};
use mcap::records::{AttachmentHeader, MessageHeader, Metadata};

use crate::error::RecordError;
use crate::model_files::{open_model, read_model, sha256_hex};
use crate::setup::{RecordingSetup, TeamSetup};
use crate::swap::{SWAP_METADATA, SwapStorage, SwappedModel, check_swapped_bytes};
use crate::tick::{FinalSample, RUN_END_METADATA, RunEnd, TickRecord};
use crate::topics::{MessageError, Replay, Slot, TickMessages, Topics, nanos};

pub use crate::model_files::MAX_ATTACHED_MODEL_BYTES;

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

/// The file's writer.
type McapWriter = mcap::Writer<BufWriter<File>>;

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
    mcap: McapWriter,
    d_star: f64,
    /// The messages of each tick.
    messages: TickMessages,
    /// Per topic slot ([`Topics`]): its channel id.
    channels: Vec<u16>,
    /// Per channel id: its next sequence number.
    sequences: Vec<u32>,
    /// The whole second of simulated time the open chunk holds.
    chunk_second: Option<u64>,
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

/// Writes one message's CDR `data` on the channel of topic `slot` at `ns`, with its channel's
/// next sequence number.
fn write_message(
    mcap: &mut McapWriter,
    (channels, sequences): (&[u16], &mut [u32]),
    (slot, ns, data): (Slot, u64, &[u8]),
) -> Result<(), mcap::McapError> {
    let channel = channels[slot];
    let next = &mut sequences[usize::from(channel)];
    let sequence = *next;
    *next = next.wrapping_add(1);
    let header = MessageHeader {
        channel_id: channel,
        sequence,
        log_time: ns,
        publish_time: ns,
    };
    mcap.write_to_known_channel(&header, data)
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
        Ok(RecordingFile {
            path: path.to_path_buf(),
            mcap,
            messages: TickMessages::new(team, Replay::Included),
            channels: Vec::new(),
            sequences: Vec::new(),
            chunk_second: None,
            shipped_models: None,
            attached: HashSet::new(),
            last_tick_ns: 0,
            d_star,
        })
    }

    /// Adds the channels and writes the static frames.
    fn write_channels(&mut self) -> Result<(), RecordError> {
        self.add_channels()?;
        self.emit(|messages, emit| messages.static_frames(emit))?;
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
    pub fn write_swap(&mut self, event: &SwapDone) -> Result<SwappedModel, RecordError> {
        let ns = self.last_tick_ns;
        let (sha256, storage) = match self.read_swapped(event) {
            Err(why) => (String::new(), SwapStorage::NotStored(why)),
            Ok((path, bytes)) => {
                let sha256 = sha256_hex(&bytes);
                let local = event.model.is_none();
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
            robot: u32::try_from(event.robot).unwrap_or(u32::MAX),
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
        event: &'e SwapDone,
    ) -> Result<(&'e Path, std::borrow::Cow<'e, [u8]>), String> {
        let path = event.path.as_deref().unwrap_or(Path::new(""));
        if let Some(bytes) = &event.model {
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

    /// Adds a channel for each topic of the team, in slot order ([`Topics::all`]).
    fn add_channels(&mut self) -> Result<(), RecordError> {
        for topic in Topics::all(self.messages.team().n_robots) {
            let schema = self
                .mcap
                .add_schema(
                    topic.type_name,
                    "ros2msg",
                    topic.definition.ros2msg().as_bytes(),
                )
                .map_err(|e| self.mcap_error(e))?;
            let id = self
                .mcap
                .add_channel(schema, &topic.name, "cdr", &BTreeMap::new())
                .map_err(|e| self.mcap_error(e))?;
            let slot = usize::from(id);
            if self.sequences.len() <= slot {
                self.sequences.resize(slot + 1, 0);
            }
            self.channels.push(id);
        }
        Ok(())
    }

    /// Writes what `write` emits, each message on its topic's channel.
    fn emit(
        &mut self,
        write: impl FnOnce(
            &mut TickMessages,
            &mut crate::topics::Emit<'_, mcap::McapError>,
        ) -> Result<(), MessageError<mcap::McapError>>,
    ) -> Result<(), RecordError> {
        let RecordingFile {
            mcap,
            messages,
            channels,
            sequences,
            path,
            ..
        } = self;
        write(messages, &mut |slot, ns, data| {
            write_message(mcap, (channels, sequences), (slot, ns, data))
        })
        .map_err(|e| message_error(path, e))
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
        self.emit(|messages, emit| messages.tick(tick, emit))
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
            self.start_second(nanos(last.time))?;
            let d_star = self.last_d_star();
            self.emit(|messages, emit| messages.last(last, d_star, emit))?;
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

/// A message that could not be encoded, or written, as the recording `path`'s error.
fn message_error(path: &Path, error: MessageError<mcap::McapError>) -> RecordError {
    match error {
        MessageError::Encode { topic, source } => RecordError::Encode {
            path: path.to_path_buf(),
            topic,
            source,
        },
        MessageError::Sink(e) => RecordError::from_mcap(path, e),
    }
}
